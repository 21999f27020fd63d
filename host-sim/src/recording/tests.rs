use super::*;

fn samples(text: &str, layout: &Layout) -> Vec<Option<f64>> {
    parse(text.as_bytes(), "r.csv", layout)
        .unwrap_or_else(|e| panic!("{e}"))
        .rows
        .iter()
        .map(|row| row.sample)
        .collect()
}

fn problem(text: &[u8], layout: &Layout) -> Problem {
    parse(text, "r.csv", layout).unwrap_err().problem
}

fn column(name: &str) -> Layout {
    Layout {
        column: Some(name.to_string()),
        no_header: false,
    }
}

fn bare(column: Option<&str>) -> Layout {
    Layout {
        column: column.map(str::to_string),
        no_header: true,
    }
}

#[test]
fn simulate_output_reads_as_before() {
    let rows = parse(
        b"t,y,truth\n0,1,0\n\n0.1,,0\n  \n\r\n0.2, 3 ,0\n",
        "r.csv",
        &Layout::default(),
    )
    .unwrap()
    .rows;
    let lines: Vec<u64> = rows.iter().map(|row| row.line).collect();
    assert_eq!(lines, [2, 4, 7]);
    let samples: Vec<Option<f64>> = rows.iter().map(|row| row.sample).collect();
    assert_eq!(samples, [Some(1.0), None, Some(3.0)]);
}

#[test]
fn bom_quotes_and_each_separator_read_alike() {
    let expected = [Some(16764.0), Some(16800.5)];
    for text in [
        "\u{feff}t,y\n0,16764\n1,16800.5\n",
        "\"t\";\"y\"\r\n0,0;16764\r\n0,25;16800.5\r\n",
        "\u{feff}t\t\"y\"\n0\t16764\n1\t\"16800.5\"\n",
    ] {
        assert_eq!(samples(text, &Layout::default()), expected, "{text:?}");
    }
}

#[test]
fn a_column_is_chosen_by_name_or_without_a_header_by_index() {
    let text = "time,code,load\n0,5,0\n1,6,0\n";
    assert_eq!(samples(text, &column("code")), [Some(5.0), Some(6.0)]);
    assert_eq!(samples("7\n8\n", &bare(None)), [Some(7.0), Some(8.0)]);
    assert_eq!(
        samples("0;7\n1;8\n", &bare(Some("1"))),
        [Some(7.0), Some(8.0)]
    );
}

#[test]
fn non_finite_cells_are_passed_on_for_the_command_to_judge() {
    let read = samples("y\nNaN\ninf\n-inf\n", &Layout::default());
    assert!(read[0].unwrap().is_nan());
    assert_eq!(read[1..], [Some(f64::INFINITY), Some(f64::NEG_INFINITY)]);
}

#[test]
fn every_sample_refuses_an_empty_cell_by_line() {
    let recording = parse(b"t,y\n0,1\n1,\n", "r.csv", &Layout::default()).unwrap();
    let error = recording.every_sample().unwrap_err();
    assert_eq!(
        error.problem,
        Problem::EmptyCell {
            line: 3,
            column: "`y`".to_string()
        }
    );
    assert!(
        error.to_string().starts_with("r.csv: line 3: column `y`"),
        "{error}"
    );
}

#[test]
fn bad_files_are_errors_naming_the_line_and_what_was_expected() {
    assert!(matches!(
        problem(b"", &Layout::default()),
        Problem::Empty { .. }
    ));
    assert!(matches!(
        problem(b"\xEF\xBB\xBF\n \n", &bare(None)),
        Problem::Empty { .. }
    ));
    assert_eq!(
        problem(b"t,x\n0,1\n", &Layout::default()),
        Problem::UnknownColumn {
            line: 1,
            wanted: "y".to_string(),
            found: vec!["t".to_string(), "x".to_string()],
        }
    );
    assert_eq!(
        problem(b"t,y\n0,1\n1,abc\n", &Layout::default()),
        Problem::NotANumber {
            line: 3,
            column: "`y`".to_string(),
            value: "abc".to_string(),
        }
    );
    assert_eq!(
        problem(b"1,2\n", &bare(None)),
        Problem::SeveralColumns { line: 1, fields: 2 }
    );
    assert_eq!(
        problem(b"1,2\n", &bare(Some("y"))),
        Problem::ColumnNotAnIndex {
            given: "y".to_string()
        }
    );
    assert_eq!(
        problem(b"1,2\n", &bare(Some("2"))),
        Problem::IndexBeyondLine {
            line: 1,
            index: 2,
            fields: 2
        }
    );
    assert_eq!(
        problem(b"y\n1\n\n\r\n\xFF\n", &Layout::default()),
        Problem::NotText { line: 5 }
    );
}
