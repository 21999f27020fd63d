//! Fuzzing of everything host-sim reads from outside (on stable Rust, with proptest): the
//! recording reader (`estimate`, `replay`, `calibrate` take their CSV files through it), the
//! weighing configuration reader (`--config`, and the firmware's constants are generated from
//! what it accepts) and the scene reader. Arbitrary bytes and mutations of the shipped files
//! must give a value or an error naming the file, never a panic; well-formed recordings must
//! read back exactly the samples written.
//!
//! Cases per property: `PROPTEST_CASES` (default below); `cargo test --release -p host-sim
//! --test reader_fuzz` runs them in seconds.

use std::path::Path;

use host_sim::calibrate::{parse_config, rust_const};
use host_sim::recording::{parse, Layout};
use host_sim::scene::{shipped_scene, Scene, SHIPPED_SCENES};
use proptest::prelude::*;

const CASES: u32 = 4096;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|cases| cases.parse().ok())
            .unwrap_or(CASES),
        ..ProptestConfig::default()
    }
}

/// The layouts a user can ask for.
fn layout() -> impl Strategy<Value = Layout> {
    prop_oneof![
        Just(Layout::default()),
        Just(Layout {
            column: Some("mass".into()),
            no_header: false
        }),
        Just(Layout {
            column: None,
            no_header: true
        }),
        (0usize..4).prop_map(|index| Layout {
            column: Some(index.to_string()),
            no_header: true
        }),
    ]
}

/// Bytes that look a little like a recording: separators, digits, signs, quotes, line ends,
/// a BOM, and anything else.
fn recording_bytes() -> impl Strategy<Value = Vec<u8>> {
    let byte = prop_oneof![
        4 => prop::sample::select(b"0123456789.-+eE,;\t\"\r\n yNaninf".to_vec()),
        1 => any::<u8>(),
    ];
    (any::<bool>(), prop::collection::vec(byte, 0..600)).prop_map(|(bom, mut bytes)| {
        if bom {
            bytes.splice(0..0, b"\xEF\xBB\xBF".iter().copied());
        }
        bytes
    })
}

proptest! {
    #![proptest_config(config())]

    /// Any bytes: a recording or an error naming the file, never a panic; the rows of a
    /// recording are in file order.
    #[test]
    fn any_bytes_read_or_fail_naming_the_file(bytes in recording_bytes(), layout in layout()) {
        match parse(&bytes, "fuzz.csv", &layout) {
            Ok(recording) => {
                let lines: Vec<u64> = recording.rows.iter().map(|row| row.line).collect();
                prop_assert!(lines.windows(2).all(|pair| pair[0] < pair[1]), "{lines:?}");
                prop_assert!(lines.first().is_none_or(|&line| line >= 1));
            }
            Err(error) => prop_assert!(error.to_string().contains("fuzz.csv"), "{error}"),
        }
    }

    /// A well-formed recording, as spreadsheets and loggers write them (any separator,
    /// quoted or bare header, a BOM, extra columns, lost samples as empty cells, CRLF):
    /// every sample reads back exactly, on its line.
    #[test]
    fn well_formed_recordings_read_back_exactly(
        samples in prop::collection::vec(prop::option::weighted(0.95, -1e7f64..1e7), 1..200),
        separator in prop::sample::select(vec![",", ";", "\t"]),
        quoted in any::<bool>(),
        bom in any::<bool>(),
        crlf in any::<bool>(),
        before in 0usize..3,
    ) {
        let end = if crlf { "\r\n" } else { "\n" };
        let name = |n: &str| if quoted { format!("\"{n}\"") } else { n.to_string() };
        let mut header: Vec<String> = (0..before).map(|i| name(&format!("c{i}"))).collect();
        header.push(name("y"));
        header.push(name("t"));
        let mut text = String::new();
        if bom {
            text.push('\u{feff}');
        }
        text.push_str(&header.join(separator));
        text.push_str(end);
        for (k, sample) in samples.iter().enumerate() {
            let mut cells: Vec<String> = (0..before).map(|i| i.to_string()).collect();
            cells.push(sample.map_or(String::new(), |s| s.to_string()));
            cells.push(k.to_string());
            text.push_str(&cells.join(separator));
            text.push_str(end);
        }
        let recording = parse(text.as_bytes(), "well-formed.csv", &Layout::default())
            .map_err(|error| TestCaseError::fail(error.to_string()))?;
        let read: Vec<Option<f64>> = recording.rows.iter().map(|row| row.sample).collect();
        prop_assert_eq!(read, samples);
        for (k, row) in recording.rows.iter().enumerate() {
            prop_assert_eq!(row.line, k as u64 + 2);
        }
    }

    /// Any text as a weighing configuration: a configuration or an error, never a panic; a
    /// configuration it accepts can be turned into the firmware's constants.
    #[test]
    fn any_text_as_a_weighing_configuration(text in ".{0,400}") {
        if let Ok((config, _)) = parse_config(Path::new("fuzz.toml"), &text) {
            let _ = config.check_region();
            let _ = rust_const(&config);
        }
    }

    /// The shipped configuration with one value replaced by an arbitrary one (a number of any
    /// size or sign, NaN, a string, an array): accepted or refused, never a panic, and what
    /// is accepted can be built into the firmware.
    #[test]
    fn the_shipped_configuration_with_one_value_mutated(
        line in any::<prop::sample::Index>(),
        value in mutated_value(),
    ) {
        let shipped = host_sim::replay::SHIPPED_CONFIG;
        let text = mutate_one_value(shipped, line, &value);
        if let Ok((config, _)) = parse_config(Path::new("mutated.toml"), &text) {
            let _ = config.check_region();
            let _ = rust_const(&config);
        }
    }

    /// Every shipped scene with one value replaced: a scene or an error naming the file,
    /// never a panic.
    #[test]
    fn the_shipped_scenes_with_one_value_mutated(
        scene in any::<prop::sample::Index>(),
        line in any::<prop::sample::Index>(),
        value in mutated_value(),
    ) {
        let (name, _) = SHIPPED_SCENES[scene.index(SHIPPED_SCENES.len())];
        let text = mutate_one_value(shipped_scene(name).unwrap(), line, &value);
        if let Err(error) = Scene::parse(Path::new("mutated-scene.toml"), &text) {
            prop_assert!(format!("{error:#}").contains("mutated-scene.toml"), "{error:#}");
        }
    }
}

/// Values a hand-edited file could hold where a number was.
fn mutated_value() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        Just("nan".to_string()),
        Just("-inf".to_string()),
        Just("0".to_string()),
        Just("-0.0".to_string()),
        Just("1e39".to_string()),
        Just("\"text\"".to_string()),
        Just("[]".to_string()),
        Just("true".to_string()),
        "[a-z0-9.\\-+\" ]{0,12}",
    ]
}

/// `text` with the value of its `line`-th `key = value` line replaced by `value`.
fn mutate_one_value(text: &str, line: prop::sample::Index, value: &str) -> String {
    let assignments: Vec<usize> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#') && l.contains(" = "))
        .map(|(i, _)| i)
        .collect();
    if assignments.is_empty() {
        return text.to_string();
    }
    let target = assignments[line.index(assignments.len())];
    text.lines()
        .enumerate()
        .map(|(i, l)| {
            if i == target {
                let key = &l[..l.find(" = ").unwrap()];
                format!("{key} = {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What the fuzzing found, kept as plain cases: a TOML error whose position fell inside a
/// multi-byte character panicked the error message's line search.
#[test]
fn a_toml_error_inside_a_multibyte_character_is_an_error() {
    let error = parse_config(Path::new("fuzz.toml"), "\t \u{800}").unwrap_err();
    assert!(error.to_string().contains("fuzz.toml"), "{error}");
}

/// ... and a file with old Mac line ends (a lone `\r`) had every row on line 1.
#[test]
fn lone_carriage_returns_end_lines() {
    let recording = parse(b"y\r1\r\r2\r", "mac.csv", &Layout::default()).unwrap();
    let lines: Vec<u64> = recording.rows.iter().map(|row| row.line).collect();
    assert_eq!(lines, [2, 4]);
    let error = parse(b"y\r1\rx\r", "mac.csv", &Layout::default()).unwrap_err();
    assert!(error.to_string().contains("line 3"), "{error}");
}
