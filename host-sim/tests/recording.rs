//! Recordings as users bring them: every command that reads one (`estimate`, `replay`,
//! `calibrate`) takes a UTF-8 BOM, `,` `;` or tab separators, a quoted header, `--column NAME`
//! and `--no-header` files of bare numbers, and reads them exactly as the file `simulate`
//! writes; a bad file is refused naming its line and what was expected there.

mod support;
use std::path::PathBuf;

use support::{host_sim, run_ok, run_refused};

fn temp(name: &str) -> PathBuf {
    support::scratch("recording", name)
}

/// `simulate SCENE --seed SEED` into `name`: the recording (`t,y,truth`) and its path.
fn simulated(scene: &str, seed: u64, name: &str) -> (PathBuf, String) {
    let path = temp(name);
    run_ok(
        host_sim()
            .args(["simulate", scene, "--seed", &seed.to_string(), "--out"])
            .arg(&path),
    );
    let text = std::fs::read_to_string(&path).unwrap();
    (path, text)
}

/// The recording rewritten as a spreadsheet might: a BOM, `separator`, CRLF, a quoted header
/// with the sample column named `ADC code`.
fn spreadsheet(text: &str, separator: &str) -> String {
    let mut lines = text.lines();
    let header = lines.next().unwrap().replace('y', "ADC code");
    let quoted: Vec<String> = header
        .split(',')
        .map(|name| format!("\"{name}\""))
        .collect();
    let mut out = format!("\u{feff}{}\r\n", quoted.join(separator));
    for line in lines {
        out.push_str(&line.replace(',', separator));
        out.push_str("\r\n");
    }
    out
}

/// The sample column alone, one bare number a line.
fn bare_samples(text: &str) -> String {
    text.lines()
        .skip(1)
        .map(|line| format!("{}\n", line.split(',').nth(1).unwrap()))
        .collect()
}

fn write(name: &str, text: &str) -> PathBuf {
    let path = temp(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn estimate(input: &PathBuf, layout: &[&str]) -> String {
    run_ok(
        host_sim()
            .args([
                "estimate",
                "--method",
                "step:n=5,D=8",
                "--gain",
                "73.254684",
            ])
            .args(["--zero", "16764.764", "--input"])
            .arg(input)
            .args(layout),
    )
}

#[test]
fn estimate_reads_every_layout_as_the_simulated_file() {
    let (original, text) = simulated("reference-step", 3, "estimate.csv");
    let expected = estimate(&original, &[]);
    assert!(expected.lines().count() > 1000, "{expected}");
    for (name, separator) in [
        ("semicolon.csv", ";"),
        ("tab.tsv", "\t"),
        ("comma.csv", ","),
    ] {
        let relaid = write(name, &spreadsheet(&text, separator));
        assert_eq!(
            estimate(&relaid, &["--column", "ADC code"]),
            expected,
            "{name}"
        );
    }
    let bare = write("bare.txt", &bare_samples(&text));
    assert_eq!(estimate(&bare, &["--no-header"]), expected);
    // Without a header a column is chosen by its 0-based index.
    let headless = write("headless.csv", text.split_once('\n').unwrap().1);
    assert_eq!(
        estimate(&headless, &["--no-header", "--column", "1"]),
        expected
    );
}

#[test]
fn replay_reads_a_bare_recording_as_the_simulated_file() {
    let (original, text) = simulated("calibration-drop", 5, "replay.csv");
    let expected = run_ok(host_sim().arg("replay").arg("--input").arg(&original));
    assert!(expected.lines().count() > 5, "{expected}");
    let bare = write("replay-bare.txt", &bare_samples(&text));
    let replayed = run_ok(
        host_sim()
            .arg("replay")
            .arg("--input")
            .arg(&bare)
            .arg("--no-header"),
    );
    assert_eq!(replayed, expected);
    let relaid = write("replay.tsv", &spreadsheet(&text, "\t"));
    let replayed = run_ok(
        host_sim()
            .arg("replay")
            .arg("--input")
            .arg(&relaid)
            .args(["--column", "ADC code"]),
    );
    assert_eq!(replayed, expected);
}

/// What `calibrate` found and chose (its stdout less the file written and the time taken).
fn calibrated(drops: &[PathBuf], layout: &[&str], out: &str) -> String {
    let mut command = host_sim();
    command
        .args(["calibrate", "--mass-g", "138.32", "--min-load-g", "80"])
        .args([
            "--runs",
            "59",
            "--max-order",
            "3",
            "--target-pct",
            "0.3",
            "--out",
        ])
        .arg(temp(out))
        .args(layout);
    for drop in drops {
        command.arg("--drop").arg(drop);
    }
    let stdout = run_ok(&mut command);
    assert!(stdout.contains("chosen: "), "{stdout}");
    stdout
        .lines()
        .filter(|line| !line.starts_with("wrote "))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn calibrate_reads_its_drops_in_any_layout() {
    let simulated: Vec<(PathBuf, String)> = [1, 2]
        .iter()
        .map(|seed| simulated("calibration-drop", *seed, &format!("drop{seed}.csv")))
        .collect();
    let originals: Vec<PathBuf> = simulated.iter().map(|(path, _)| path.clone()).collect();
    let expected = calibrated(&originals, &[], "original.toml");
    let relaid: Vec<PathBuf> = simulated
        .iter()
        .enumerate()
        .map(|(index, (_, text))| write(&format!("drop{index}.ssv"), &spreadsheet(text, ";")))
        .collect();
    assert_eq!(
        calibrated(&relaid, &["--column", "ADC code"], "relaid.toml"),
        expected
    );
}

#[test]
fn a_bad_recording_is_refused_naming_its_line_and_what_was_expected() {
    let refused = |text: &str, layout: &[&str]| -> String {
        let input = write("bad.csv", text);
        let stderr = run_refused(
            host_sim()
                .args(["estimate", "--order", "1", "--gain", "1", "--input"])
                .arg(&input)
                .args(layout),
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
        stderr
    };
    let stderr = refused("", &[]);
    assert!(stderr.contains("empty file, expected a header"), "{stderr}");
    let stderr = refused("time;code\n0;1\n", &[]);
    assert!(
        stderr.contains("line 1: expected a column `y`") && stderr.contains("`time`, `code`"),
        "{stderr}"
    );
    let stderr = refused("t;code\n0;1\n\n2;1,5\n", &["--column", "code"]);
    assert!(
        stderr.contains("line 4: column `code`: expected a number, found `1,5`"),
        "{stderr}"
    );
    let stderr = refused("1\n2\n", &[]);
    assert!(stderr.contains("--no-header"), "{stderr}");
    let stderr = refused("0,1\n", &["--no-header"]);
    assert!(
        stderr.contains("line 1: 2 fields and no header: expected --column INDEX"),
        "{stderr}"
    );
    let stderr = refused("0,1\n", &["--no-header", "--column", "y"]);
    assert!(stderr.contains("0-based index, found `y`"), "{stderr}");
    // Calibration needs every sample: an empty cell is refused by its line.
    let drop = write("gap.csv", "0,7\n1,\n2,9\n");
    let stderr = run_refused(
        host_sim()
            .args([
                "calibrate",
                "--mass-g",
                "100",
                "--no-header",
                "--column",
                "1",
            ])
            .arg("--out")
            .arg(temp("gap.toml"))
            .arg("--drop")
            .arg(&drop),
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("gap.csv: line 2: column 1: expected a number"),
        "{stderr}"
    );
}

#[test]
fn non_finite_samples_are_flagged_as_before() {
    // The estimator flags a non-finite sample; the reader passes it on.
    let input = write("nan.csv", "y\n1\nNaN\ninf\n");
    let stdout = run_ok(
        host_sim()
            .args(["estimate", "--order", "1", "--gain", "1", "--input"])
            .arg(&input),
    );
    let states: Vec<&str> = stdout
        .lines()
        .skip(1)
        .map(|line| line.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(
        states[1..],
        ["invalid_non_finite_input", "invalid_non_finite_input"],
        "{stdout}"
    );
}
