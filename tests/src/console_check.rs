//! The serial console end to end: what the QEMU board wrote on UART 0 while the harness
//! typed the command scene's lines ([`crate::commands::CommandScript`]), judged against
//! the protocol (`estimator_core::weighing::console`) and against the board's own log.
//!
//! What the transcript must show:
//! - the banner, then one answer per typed line, in the order typed: `help` (its `H` lines),
//!   `OK unit kg`, `OK rate 50`, `ERR rate bad_value; …` (3 Hz is not offered), two
//!   methods refused (`too_large`: n = 12 is more than the board's estimator holds;
//!   `outside_valid_region`: D = 1), `OK method step:n=7,D=16`,
//!   `OK config set capacity_g 620`, `config show` (every key once, capacity_g=620, the
//!   method uploaded), the
//!   tare (`OK tare <mass> kg`, the log's tare to the display's resolution), the tare
//!   refused while the load moves (`ERR tare unstable; …`), the calibration
//!   (`OK cal zero_taken; …`, then `OK cal done …` with the values the log says were
//!   stored);
//! - reading lines that parse, 20 a second until `OK rate 50` and 50 a second after it
//!   (final readings may come between), in kg after `OK unit kg`, each agreeing with the
//!   log's readout line of the same sample (state, mass and `u` to their printed digits).

use estimator_core::weighing::ScaleConfig;
use host_sim::monitor::parse::parse_line;

use crate::commands::{CommandLine, CommandReport};
use crate::e2e::{ReadoutLine, RunLog, SAMPLE_RATE_HZ};

/// The answers expected, in order: (what the line starts with, what it stands for).
const ANSWERS: [(&str, &str); 14] = [
    ("OK help", "help"),
    ("OK unit kg", "unit kg"),
    ("OK rate 50", "rate 50"),
    ("ERR rate bad_value; expected", "rate 3 (refused)"),
    (
        "ERR method too_large; expected n from 1 to 8",
        "method step:n=12,D=16 (refused)",
    ),
    (
        "ERR method outside_valid_region; expected D of at least",
        "method step:n=7,D=1 (refused)",
    ),
    (
        "ERR method no_uncertainty; expected least squares with lambda=1",
        "method iv:n=7,D=16 (refused)",
    ),
    ("OK method step:n=7,D=16", "method step:n=7,D=16"),
    ("OK config set capacity_g 620", "config set capacity_g 620"),
    ("OK config show", "config show"),
    ("OK tare ", "tare (stable)"),
    (
        "ERR tare unstable; expected",
        "tare (sliding load, refused)",
    ),
    ("OK cal zero_taken; put 200 g on the pan", "cal 200 (zero)"),
    ("OK cal done ", "cal 200 (done)"),
];

/// Judge the console `transcript` of a command-scene run whose log is `run`.
pub fn check(transcript: &[String], run: &RunLog) -> CommandReport {
    let mut report = CommandReport::default();
    let failures = &mut report.failures;
    if !transcript
        .first()
        .is_some_and(|line| line.starts_with("# fast-weighing console"))
    {
        failures.push("the console's first line is not its banner".into());
    }
    let answers: Vec<(usize, &String)> = transcript
        .iter()
        .enumerate()
        .filter(|(_, line)| line.starts_with("OK ") || line.starts_with("ERR "))
        .collect();
    if answers.len() != ANSWERS.len() {
        failures.push(format!(
            "{} answer lines, expected {} (one per typed line): {:?}",
            answers.len(),
            ANSWERS.len(),
            answers.iter().map(|(_, line)| line).collect::<Vec<_>>()
        ));
    }
    let at = |index: usize| {
        answers
            .get(index)
            .map(|&(position, line)| (position, line.as_str()))
    };
    for (index, (start, what)) in ANSWERS.iter().enumerate() {
        match at(index) {
            Some((_, line)) if line.starts_with(start) => {}
            other => failures.push(format!(
                "answer {} to `{what}` is {:?}, expected a line starting `{start}`",
                index + 1,
                other.map(|(_, line)| line)
            )),
        }
    }
    let position = |start: &str| {
        answers
            .iter()
            .find(|(_, line)| line.starts_with(start))
            .map(|&(position, _)| position)
    };
    if let Some(line) = run
        .lines
        .iter()
        .find(|line| line.contains("console lost_bytes="))
    {
        failures.push(format!("the board's console port gave bytes up: {line}"));
    }
    check_help(transcript, position("OK help"), failures);
    check_config_show(transcript, position("OK config show"), failures);
    check_tare(transcript, run, failures);
    check_calibration(transcript, run, failures);
    let (count, compared) = check_readings(
        transcript,
        run,
        position("OK unit kg"),
        position("OK rate 50"),
        failures,
    );
    report.figures.push(format!(
        "console: {} lines, {} answers, {count} reading lines, {compared} compared with the log's readout",
        transcript.len(),
        answers.len()
    ));
    report
}

/// `help`'s `H` lines just before its `OK help`.
fn check_help(transcript: &[String], ok: Option<usize>, failures: &mut Vec<String>) {
    let Some(ok) = ok else { return };
    let listed = transcript[..ok]
        .iter()
        .rev()
        .take_while(|line| line.starts_with("H ") || line.starts_with("R "))
        .filter(|line| line.starts_with("H "))
        .count();
    if listed < 11 {
        failures.push(format!(
            "help listed {listed} commands before OK help, expected 11"
        ));
    }
}

/// `config show`: every key once, with the value set before it.
fn check_config_show(transcript: &[String], ok: Option<usize>, failures: &mut Vec<String>) {
    let Some(ok) = ok else { return };
    let shown: Vec<&str> = transcript[..ok]
        .iter()
        .rev()
        .take_while(|line| line.starts_with("C ") || line.starts_with("R "))
        .filter_map(|line| line.strip_prefix("C "))
        .collect();
    for field in ScaleConfig::FIELDS {
        let count = shown
            .iter()
            .filter(|line| {
                line.split_once('=')
                    .is_some_and(|(key, _)| key == field.name)
            })
            .count();
        if count != 1 {
            failures.push(format!("config show listed {} {count} times", field.name));
        }
    }
    if !shown.contains(&"capacity_g=620") {
        failures.push("config show does not list capacity_g=620 after config set".into());
    }
    let method = format!("method={}", crate::commands::UPLOADED_METHOD);
    if !shown.contains(&method.as_str()) {
        failures.push(format!(
            "config show does not list {method} after the method was uploaded"
        ));
    }
}

/// The numeric `key=value` fields of the log's command line for `action=outcome`.
fn logged(run: &RunLog, action: &str, outcome: &str) -> Option<CommandLine> {
    run.lines
        .iter()
        .filter_map(|line| CommandLine::parse(line))
        .find(|line| line.action == action && line.outcome == outcome)
}

/// `OK tare <mass> kg` is the log's `tare_g` to the display's resolution (0.0001 kg).
fn check_tare(transcript: &[String], run: &RunLog, failures: &mut Vec<String>) {
    let shown = transcript.iter().find_map(|line| {
        let rest = line.strip_prefix("OK tare ")?;
        let (value, unit) = rest.split_once(' ')?;
        Some((value.parse::<f64>().ok()?, unit.to_string()))
    });
    let tare_g = logged(run, "tare", "ok").and_then(|line| line.field("tare_g"));
    match (shown, tare_g) {
        (Some((kg, unit)), Some(tare_g)) if unit == "kg" => {
            if (kg - tare_g / 1000.0).abs() > 0.5e-4 + 1e-9 {
                failures.push(format!(
                    "OK tare says {kg} kg, the log's tare is {tare_g} g"
                ));
            }
        }
        other => failures.push(format!(
            "no OK tare in kg with a logged tare to compare: {other:?}"
        )),
    }
}

/// `OK cal done counts_per_g=… zero_counts=…` are the values the log says were stored.
fn check_calibration(transcript: &[String], run: &RunLog, failures: &mut Vec<String>) {
    let shown = transcript.iter().find_map(|line| {
        let rest = line.strip_prefix("OK cal done ")?;
        let mut values = rest.split(' ').filter_map(|field| field.split_once('='));
        let gain = values
            .next()
            .filter(|(k, _)| *k == "counts_per_g")?
            .1
            .parse::<f64>()
            .ok()?;
        let zero = values
            .next()
            .filter(|(k, _)| *k == "zero_counts")?
            .1
            .parse::<f64>()
            .ok()?;
        Some((gain, zero))
    });
    let stored = logged(run, "calibrate", "done")
        .and_then(|line| Some((line.field("counts_per_gram")?, line.field("zero_counts")?)));
    match (shown, stored) {
        (Some((gain, zero)), Some((stored_gain, stored_zero))) => {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * b.abs().max(1.0);
            if !(close(gain, stored_gain) && close(zero, stored_zero)) {
                failures.push(format!(
                    "OK cal done says {gain} counts/g, zero {zero}; the log stored {stored_gain}, {stored_zero}"
                ));
            }
        }
        other => failures.push(format!(
            "no OK cal done with a stored calibration in the log to compare: {other:?}"
        )),
    }
}

/// Reading lines: their cadence, unit, and agreement with the log's readout of the same
/// sample. Returns (reading lines, lines compared).
fn check_readings(
    transcript: &[String],
    run: &RunLog,
    unit_at: Option<usize>,
    rate_at: Option<usize>,
    failures: &mut Vec<String>,
) -> (usize, usize) {
    let log: Vec<ReadoutLine> = run.readouts();
    let mut count = 0;
    let mut compared = 0;
    let mut previous_tick: Option<f64> = None;
    let mut problems = Vec::new();
    for (position, line) in transcript.iter().enumerate() {
        if !line.starts_with("R ") {
            continue;
        }
        // The monitor's reader, which takes the console's lines in any unit (in grams).
        let Some(reading) = parse_line(line, SAMPLE_RATE_HZ) else {
            problems.push(format!("a malformed reading line: {line}"));
            continue;
        };
        count += 1;
        let in_kg = unit_at.is_some_and(|at| position > at);
        let expected_unit = if in_kg { " unit=kg " } else { " unit=g " };
        if !line.contains(expected_unit) {
            problems.push(format!("{line}: expected{expected_unit}"));
        }
        let period = if rate_at.is_some_and(|at| position > at) {
            0.02
        } else {
            0.05
        };
        let on_grid = ((reading.t_s / period).round() * period - reading.t_s).abs() < 1e-6;
        if on_grid {
            if let Some(previous) = previous_tick {
                // The first line at the new rate may follow an old-rate one sooner.
                if reading.t_s - previous > period + 1e-6 {
                    problems.push(format!(
                        "{line}: {:.3} s after the previous line",
                        reading.t_s - previous
                    ));
                }
            }
            previous_tick = Some(reading.t_s);
        } else if !reading.is_final {
            problems.push(format!(
                "{line}: off the {period} s grid and not a final reading"
            ));
        }
        let sample = (reading.t_s * SAMPLE_RATE_HZ).round() as u32;
        let Some(logged) = log.iter().find(|readout| readout.sample == sample) else {
            continue;
        };
        compared += 1;
        // Masses to 0.1 g (e), u to one digit more: half a printed step, and the f32 noise.
        let agrees = |shown: Option<f64>, logged: Option<f64>, step_g: f64| match (shown, logged) {
            (None, None) => true,
            (Some(shown), Some(logged)) => (shown - logged).abs() <= 0.5 * step_g + 1e-4,
            _ => false,
        };
        let state = logged.state.to_ascii_lowercase();
        let same_state = reading.state == state
            || (reading.state.starts_with("invalid:") && state.starts_with("invalid"));
        if !(same_state
            && agrees(reading.mass_g, logged.mass_g, 0.1)
            && agrees(reading.u_g, logged.u_g, 0.01))
        {
            problems.push(format!(
                "{line} disagrees with the log at sample {sample}: mass {:?} g, u {:?} g, {}",
                logged.mass_g, logged.u_g, logged.state
            ));
        }
    }
    if count < 100 {
        problems.push(format!("only {count} reading lines"));
    }
    // At 50 lines a second one line in five falls on a sample of the log's 20 Hz readout.
    if compared < count / 6 {
        problems.push(format!(
            "only {compared} of {count} reading lines compared with the log"
        ));
    }
    failures.extend(problems.into_iter().take(10));
    (count, compared)
}

/// What a reset must keep: a run booting on the flash the command-scene run `before` left
/// (`after`, the `boot` scene) finds the calibration that run stored and the settings its
/// console changed (`unit kg`, `rate 50`, the uploaded method, `config set capacity_g 620`), and does not
/// calibrate at "the factory" over them; `before` itself booted on the compiled-in settings.
pub fn check_reset(before: &RunLog, after: &RunLog) -> CommandReport {
    let mut report = CommandReport::default();
    let failures = &mut report.failures;
    let has = |run: &RunLog, start: &str| run.lines.iter().any(|line| line.starts_with(start));
    if !has(before, "settings compiled-in (Missing)") {
        failures.push("the first run did not boot on the compiled-in settings".into());
    }
    if !after.exited_successfully {
        failures.push("the run after the reset did not end with status 0".into());
    }
    if !has(
        after,
        "factory calibration: the flash image holds a record already",
    ) {
        failures.push("the run after the reset calibrated at the factory again".into());
    }
    // `settings stored capacity_g=620 e_g=0.1 rate_hz=50 unit=kg`, numbers as defmt prints
    // them.
    let settings = after
        .lines
        .iter()
        .find(|line| line.starts_with("settings "))
        .cloned()
        .unwrap_or_default();
    let field = |key: &str| {
        settings
            .split_whitespace()
            .find_map(|word| word.strip_prefix(key)?.strip_prefix('='))
            .map(str::to_string)
    };
    let number = |key: &str| field(key).and_then(|value| value.parse::<f64>().ok());
    let kept = settings.starts_with("settings stored ")
        && number("capacity_g") == Some(620.0)
        && number("e_g").is_some_and(|e| (e - 0.1).abs() < 1e-6)
        && number("rate_hz") == Some(50.0)
        && field("unit").as_deref() == Some("kg")
        && field("method").as_deref() == Some(crate::commands::UPLOADED_METHOD);
    if !kept {
        failures.push(format!(
            "the run after the reset logs `{settings}`, expected the settings stored capacity_g=620 e_g=0.1 rate_hz=50 unit=kg method={}",
            crate::commands::UPLOADED_METHOD
        ));
    }
    let stored = logged(before, "calibrate", "done")
        .and_then(|line| Some((line.field("counts_per_gram")?, line.field("zero_counts")?)));
    let booted = after.lines.iter().find_map(|line| {
        let rest = line.strip_prefix("calibration counts_per_gram=")?;
        let (gain, rest) = rest.split_once(" zero_counts=")?;
        let (zero, source) = rest.split_once(" source=")?;
        Some((
            gain.parse::<f64>().ok()?,
            zero.parse::<f64>().ok()?,
            source.to_string(),
        ))
    });
    match (stored, booted) {
        (Some((gain, zero)), Some((booted_gain, booted_zero, source))) => {
            if gain != booted_gain || zero != booted_zero || source != "Stored" {
                failures.push(format!(
                    "stored {gain} counts/g, zero {zero}; booted on {booted_gain}, {booted_zero} ({source})"
                ));
            }
            report.figures.push(format!(
                "reset: booted on the stored calibration {booted_gain} counts/g, zero {booted_zero}, and `{settings}`"
            ));
        }
        other => failures.push(format!(
            "no stored calibration to compare with the one booted: {other:?}"
        )),
    }
    let readouts = after.readouts();
    if readouts.is_empty() || readouts.iter().any(|line| line.calibration != "stored") {
        failures.push("the run after the reset does not read with cal=stored throughout".into());
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 120 reading lines at 20 Hz and the log's readout of the same samples.
    fn readings(mass: impl Fn(u32) -> f64) -> (Vec<String>, RunLog) {
        let mut transcript = Vec::new();
        let mut lines = Vec::new();
        for tick in 1..=120u32 {
            let sample = 200 * tick;
            transcript.push(format!(
                "R t={:.3} mass={:.1} u=0.01 unit=g state=stable final=0",
                f64::from(sample) / SAMPLE_RATE_HZ,
                mass(tick)
            ));
            lines.push(format!(
                "readout sample={sample} mass_g=138.32 u_g=0.012 state=Stable since={sample} dropped=0 changes=1 cal=stored final=0"
            ));
        }
        let run = RunLog {
            lines,
            exited_successfully: true,
        };
        (transcript, run)
    }

    #[test]
    fn reading_lines_must_agree_with_the_log() {
        let (transcript, run) = readings(|_| 138.3);
        let mut failures = Vec::new();
        assert_eq!(
            check_readings(&transcript, &run, None, None, &mut failures),
            (120, 120)
        );
        assert!(failures.is_empty(), "{failures:?}");
        // One line 0.2 g off the log, one missing (a gap in the 20 Hz cadence).
        let (mut transcript, run) = readings(|tick| if tick == 50 { 138.5 } else { 138.3 });
        transcript.remove(80);
        check_readings(&transcript, &run, None, None, &mut failures);
        assert_eq!(failures.len(), 2, "{failures:?}");
        assert!(
            failures[0].contains("disagrees with the log at sample 10000"),
            "{failures:?}"
        );
        assert!(
            failures[1].contains("0.100 s after the previous line"),
            "{failures:?}"
        );
    }

    #[test]
    fn a_reset_that_kept_nothing_fails() {
        let before = RunLog {
            lines: vec![
                "settings compiled-in (Missing)".into(),
                "command sample=20000 calibrate=done counts_per_gram=73.97919 zero_counts=16853.697 (stored, read back, applied)".into(),
            ],
            exited_successfully: true,
        };
        let after = RunLog {
            lines: vec![
                "factory calibration: 6 s of the simulated cell, empty then 200 g...".into(),
                "calibration counts_per_gram=73.2 zero_counts=16850 source=Stored".into(),
                "settings compiled-in (Missing)".into(),
            ],
            exited_successfully: true,
        };
        let report = check_reset(&before, &after);
        assert!(
            report.failures[1].contains("logs `settings compiled-in (Missing)`"),
            "{:?}",
            report.failures
        );
        assert_eq!(report.failures.len(), 4, "{:?}", report.failures);
        // The same reset keeping both passes.
        let kept = RunLog {
            lines: vec![
                "factory calibration: the flash image holds a record already".into(),
                "calibration counts_per_gram=73.97919 zero_counts=16853.697 source=Stored".into(),
                "settings stored capacity_g=620.0 e_g=0.1 rate_hz=50 unit=kg method=step:n=7,D=16"
                    .into(),
                "readout sample=200 mass_g=0.01 u_g=0.02 state=Empty since=200 dropped=0 changes=0 cal=stored final=0".into(),
            ],
            exited_successfully: true,
        };
        let report = check_reset(&before, &kept);
        assert!(report.failures.is_empty(), "{:?}", report.failures);
    }

    #[test]
    fn an_empty_transcript_fails_every_criterion() {
        let run = RunLog {
            lines: Vec::new(),
            exited_successfully: true,
        };
        let report = check(&[], &run);
        assert!(report.failures.len() >= 5, "{:?}", report.failures);
    }
}
