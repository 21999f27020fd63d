//! The serial console takes bytes from anyone: whatever arrives, the line buffer and the
//! parser answer with a line, a request or a typed refusal, never a panic, and every
//! request they accept writes back to a line that parses to the same request.
//!
//! Run with more cases: `PROPTEST_CASES=1000000 cargo test --release -p estimator-core --test console_fuzz`.

use estimator_core::weighing::console::{
    parse_line, write_error, write_reading, ConsoleError, LineBuffer, LineEnd, ReadingLine,
    Request, Unit, MAX_LINE,
};
use estimator_core::weighing::{ScaleState, WeighingMethod};
use proptest::prelude::*;

/// The line a request is typed as.
fn typed(request: &Request<'_>) -> String {
    match request {
        Request::Tare => "tare".into(),
        Request::ClearTare => "untare".into(),
        Request::Zero => "zero".into(),
        Request::Calibrate { known_mass_g } => format!("cal {known_mass_g}"),
        Request::CancelCalibration => "cancel".into(),
        Request::Unit(unit) => format!("unit {}", unit.name()),
        Request::Rate { hz } => format!("rate {hz}"),
        Request::Raw(on) => format!("raw {}", if *on { "on" } else { "off" }),
        Request::Record => "record".into(),
        Request::ConfigShow => "config show".into(),
        Request::ConfigSet { key, value } => format!("config set {key} {value}"),
        Request::Method { spec: None } => "method".into(),
        Request::Method { spec: Some(spec) } => format!("method {spec}"),
        Request::Help => "help".into(),
    }
}

/// 20,000 cases a property unless `PROPTEST_CASES` says otherwise.
fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|cases| cases.parse().ok())
        .unwrap_or(20_000)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn any_bytes_give_lines_requests_or_refusals(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut buffer = LineBuffer::new();
        for byte in bytes {
            if let Some(end) = buffer.push(byte) {
                match end {
                    LineEnd::Line(line) => {
                        prop_assert!(!line.is_empty() && line.len() <= MAX_LINE);
                        prop_assert!(!line.contains(&b'\r') && !line.contains(&b'\n'));
                        match parse_line(line) {
                            Ok(request) => {
                                // What was accepted reads back as itself.
                                let again = typed(&request);
                                prop_assert_eq!(parse_line(again.as_bytes()), Ok(request));
                            }
                            Err(error) => {
                                let mut out = String::new();
                                write_error(&mut out, "line", &error).unwrap();
                                prop_assert!(out.starts_with("ERR line ") && out.ends_with("\r\n"));
                            }
                        }
                    }
                    LineEnd::TooLong => {}
                }
            }
        }
    }

    #[test]
    fn command_words_with_any_argument_never_panic(
        command in prop::sample::select(vec!["tare", "cal", "unit", "rate", "raw", "config", "config set", "help", "zero", "method"]),
        argument in "\\PC{0,20}",
        more in "\\PC{0,20}",
    ) {
        let line = format!("{command} {argument} {more}");
        if let Ok(request) = parse_line(line.as_bytes()) {
            // A calibration mass is finite and positive; a rate within 1–1000.
            match request {
                Request::Calibrate { known_mass_g } => prop_assert!(known_mass_g.is_finite() && known_mass_g > 0.0),
                Request::Rate { hz } => prop_assert!((1..=1000).contains(&hz)),
                Request::ConfigSet { value, .. } => prop_assert!(value.is_finite()),
                _ => {}
            }
        }
    }

    /// A method spec from anyone (`method <spec>`): refused with a reason, or a method
    /// whose numbers are in their domain and whose own spec reads back as the same method.
    #[test]
    fn any_method_spec_is_refused_or_reads_back(
        family in prop::sample::select(vec!["step:", "bc:", "iv:", "model:", "", "x:"]),
        keys in proptest::collection::vec(
            (prop::sample::select(vec!["n", "D", "lambda", "K", "span", "precision", "delay", ""]),
             "[-0-9.ef]{0,8}|f32|f64|0.68-1.3"),
            0..5,
        ),
    ) {
        let pairs: Vec<String> = keys.iter().map(|(key, value)| format!("{key}={value}")).collect();
        let spec = format!("{family}{}", pairs.join(","));
        match WeighingMethod::parse_spec(&spec) {
            Ok(method) => {
                prop_assert!(method.decimation() >= 1);
                if let WeighingMethod::Step { forgetting, .. } = method {
                    prop_assert!(forgetting > 0.0 && forgetting <= 1.0, "{}", spec);
                }
                let again = method.spec().to_string();
                prop_assert_eq!(WeighingMethod::parse_spec(&again), Ok(method), "{} -> {}", spec, again);
            }
            Err(error) => prop_assert!(!error.expected().is_empty()),
        }
    }

    #[test]
    fn a_reading_line_never_carries_a_non_finite_number(
        mass in prop::option::of(any::<f32>()),
        u in prop::option::of(any::<f32>()),
        t in any::<f32>(),
        decimals in 0usize..8,
    ) {
        for unit in Unit::ALL {
            let mut out = String::new();
            let line = ReadingLine { t_s: t, mass_g: mass, u_g: u, state: ScaleState::Stable, is_final: false };
            write_reading(&mut out, &line, unit, decimals).unwrap();
            prop_assert!(out.starts_with("R t=") && out.ends_with("\r\n"));
            let lower = out.to_ascii_lowercase();
            prop_assert!(!lower.contains("nan") && !lower.contains("inf"), "{}", out);
        }
    }
}

#[test]
fn an_overlong_line_is_one_refusal() {
    let mut buffer = LineBuffer::new();
    let mut ends = Vec::new();
    for byte in "cal 200 ".repeat(20).bytes().chain(*b"\n") {
        if let Some(end) = buffer.push(byte) {
            ends.push(end == LineEnd::TooLong);
        }
    }
    assert_eq!(ends, [true]);
    assert_eq!(ConsoleError::TooLong.reason(), "too_long");
}
