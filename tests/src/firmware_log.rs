//! The firmware's log lines as the host replays write them (`e2e::host_replay`,
//! `commands::host_replay`): the firmware's own defmt format strings (those of
//! `firmware::pipeline` and the QEMU board's end line), rendered here with the arguments the
//! replay computed.
//!
//! Why the format strings and not a second `format!` per line: the firmware formats on the
//! host through defmt's decoder, so its format strings are the one description of each
//! line. `cargo xtask test` checks that every string here is in the firmware image's defmt
//! table ([`missing_from_image`]), so a replay cannot drift from what QEMU prints. Nothing
//! here judges a line; the checkers parse what this writes exactly as they parse QEMU's.

use std::fmt::Write as _;

use anyhow::{anyhow, Context, Result};
use estimator_core::weighing::{
    Calibration, CalibrationFailure, CalibrationSource, Command, CommandOutcome, CommandRefusal,
    MethodRefusal, ScaleReading, WeighingMethod,
};

/// `pipeline::log_readout` with a mass and its standard uncertainty.
pub const READOUT: &str =
    "readout sample={=u32} mass_g={=f32} u_g={=f32} state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final={=u8}";
/// `pipeline::log_readout` with a mass whose method states no uncertainty.
pub const READOUT_NO_UNCERTAINTY: &str =
    "readout sample={=u32} mass_g={=f32} u_g=none state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final=0";
/// `pipeline::log_readout` without a mass.
pub const READOUT_NO_MASS: &str =
    "readout sample={=u32} mass_g=none u_g=none state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final=0";
/// `pipeline::log_final`: a run's final reading, the moment it is reached.
pub const FINAL: &str =
    "final sample={=u32} mass_g={=f32} u_g={=f32} state={} since={=u32} changes={=u32} cal={=str}";
/// `pipeline::log_command`, a tare taken.
pub const TARED: &str = "command sample={=u32} tare=ok tare_g={=f32}";
/// `pipeline::log_command`, the tare cleared.
pub const TARE_CLEARED: &str = "command sample={=u32} untare=ok";
/// `pipeline::log_command`, the zero set.
pub const ZEROED: &str = "command sample={=u32} zero=ok";
/// `pipeline::log_command`, a calibration's zero taken.
pub const CALIBRATION_STARTED: &str = "command sample={=u32} calibrate=zero_taken zero_counts={=f32} known_mass_g={=f32} (put the mass on)";
/// `pipeline::log_command`, a calibration cancelled.
pub const CALIBRATION_CANCELLED: &str = "command sample={=u32} cancel=ok";
/// `pipeline::log_command`, any command refused.
pub const REFUSED: &str = "command sample={=u32} {=str}=refused ({})";
/// `pipeline::finish_calibration`, the measurement failed.
pub const CALIBRATION_FAILED: &str = "command sample={=u32} calibrate=failed ({})";
/// `pipeline::finish_calibration`, the store failed.
pub const STORE_FAILED: &str = "command sample={=u32} calibrate=failed (Store({}))";
/// `pipeline::finish_calibration`, stored, read back and applied.
pub const CALIBRATION_DONE: &str = "command sample={=u32} calibrate=done counts_per_gram={=f32} zero_counts={=f32} (stored, read back, applied)";
/// `pipeline::log_calibration`: the calibration booted with.
pub const BOOT_CALIBRATION: &str =
    "calibration counts_per_gram={=f32} zero_counts={=f32} source={}";
/// `pipeline::log_method`, a method the console set.
pub const METHOD_SET: &str = "method sample={=u32} spec={=str} outcome=ok";
/// `pipeline::log_method`, a method the console asked for and the board refused.
pub const METHOD_REFUSED: &str = "method sample={=u32} spec={=str} outcome=refused ({})";
/// The QEMU board's end of the scene.
pub const END: &str = "end samples={=u32} dropped={=u32}";

/// Every format string above.
pub const ALL: [&str; 17] = [
    READOUT,
    FINAL,
    READOUT_NO_UNCERTAINTY,
    READOUT_NO_MASS,
    TARED,
    TARE_CLEARED,
    ZEROED,
    CALIBRATION_STARTED,
    CALIBRATION_CANCELLED,
    REFUSED,
    CALIBRATION_FAILED,
    STORE_FAILED,
    CALIBRATION_DONE,
    BOOT_CALIBRATION,
    METHOD_SET,
    METHOD_REFUSED,
    END,
];

/// One argument of a line, by the type its parameter names.
#[derive(Clone, Debug)]
pub enum Arg {
    /// `{=u32}`.
    U32(u32),
    /// `{=f32}`.
    F32(f32),
    /// `{=u8}`.
    U8(u8),
    /// `{=str}`.
    Str(&'static str),
    /// `{}`: a value the firmware logs through its `defmt::Format`, which for these enums
    /// prints what `Debug` prints.
    Format(String),
}

/// `format` with `args` in its parameters, as the host writes numbers (Rust's shortest
/// `f32` form; the checkers parse any).
///
/// # Panics
/// If `format` is not a defmt format string or lacks an argument: a bug in this module.
pub fn render(format: &str, args: &[Arg]) -> String {
    let fragments = defmt_parser::parse(format, defmt_parser::ParserMode::Strict)
        .unwrap_or_else(|error| panic!("{format:?} is no defmt format string: {error:?}"));
    let mut line = String::new();
    for fragment in fragments {
        match fragment {
            defmt_parser::Fragment::Literal(text) => line.push_str(&text),
            defmt_parser::Fragment::Parameter(parameter) => {
                let _ = match &args[parameter.index] {
                    Arg::U32(value) => write!(line, "{value}"),
                    Arg::F32(value) => write!(line, "{value}"),
                    Arg::U8(value) => write!(line, "{value}"),
                    Arg::Str(text) => write!(line, "{text}"),
                    Arg::Format(text) => write!(line, "{text}"),
                };
            }
        }
    }
    line
}

/// `pipeline::log_readout`: one readout line, converted with the calibration from `source`.
pub fn readout(
    sample: u32,
    reading: &ScaleReading,
    dropped: u32,
    source: &CalibrationSource,
) -> String {
    let tail = [
        Arg::Format(format!("{:?}", reading.state)),
        Arg::U32(reading.samples_since_change),
        Arg::U32(dropped),
        Arg::U32(reading.load_changes),
        Arg::Str(source.label()),
    ];
    match (reading.mass_g, reading.uncertainty_g) {
        (Some(mass_g), Some(u_g)) => {
            let mut args = vec![Arg::U32(sample), Arg::F32(mass_g), Arg::F32(u_g)];
            args.extend(tail);
            args.push(Arg::U8(u8::from(reading.is_final)));
            render(READOUT, &args)
        }
        (Some(mass_g), None) => {
            let mut args = vec![Arg::U32(sample), Arg::F32(mass_g)];
            args.extend(tail);
            render(READOUT_NO_UNCERTAINTY, &args)
        }
        (None, _) => {
            let mut args = vec![Arg::U32(sample)];
            args.extend(tail);
            render(READOUT_NO_MASS, &args)
        }
    }
}

/// `pipeline::log_final`: a run's final reading (`None` when it has no mass or `u`, as the
/// firmware then prints nothing).
pub fn final_line(
    sample: u32,
    reading: &ScaleReading,
    source: &CalibrationSource,
) -> Option<String> {
    let (mass_g, u_g) = (reading.mass_g?, reading.uncertainty_g?);
    Some(render(
        FINAL,
        &[
            Arg::U32(sample),
            Arg::F32(mass_g),
            Arg::F32(u_g),
            Arg::Format(format!("{:?}", reading.state)),
            Arg::U32(reading.samples_since_change),
            Arg::U32(reading.load_changes),
            Arg::Str(source.label()),
        ],
    ))
}

/// `pipeline::log_command`: one command's outcome.
pub fn command(
    sample: u32,
    command: Command,
    result: &Result<CommandOutcome, CommandRefusal>,
) -> String {
    let action = match command {
        Command::Tare => "tare",
        Command::ClearTare => "untare",
        Command::Zero => "zero",
        Command::Calibrate { .. } => "calibrate",
        Command::CancelCalibration => "cancel",
    };
    let at = Arg::U32(sample);
    match result {
        Ok(CommandOutcome::Tared { tare_g }) => render(TARED, &[at, Arg::F32(*tare_g)]),
        Ok(CommandOutcome::TareCleared) => render(TARE_CLEARED, &[at]),
        Ok(CommandOutcome::Zeroed) => render(ZEROED, &[at]),
        Ok(CommandOutcome::CalibrationStarted {
            zero_counts,
            known_mass_g,
        }) => render(
            CALIBRATION_STARTED,
            &[at, Arg::F32(*zero_counts), Arg::F32(*known_mass_g)],
        ),
        Ok(CommandOutcome::CalibrationCancelled) => render(CALIBRATION_CANCELLED, &[at]),
        Err(refusal) => render(
            REFUSED,
            &[at, Arg::Str(action), Arg::Format(format!("{refusal:?}"))],
        ),
    }
}

/// `pipeline::finish_calibration`'s lines: the measurement failed.
pub fn calibration_failed(sample: u32, failure: &CalibrationFailure) -> String {
    render(
        CALIBRATION_FAILED,
        &[Arg::U32(sample), Arg::Format(format!("{failure:?}"))],
    )
}

/// `pipeline::finish_calibration`'s lines: the store failed (`failure` as `Debug` prints it).
pub fn store_failed(sample: u32, failure: &impl std::fmt::Debug) -> String {
    render(
        STORE_FAILED,
        &[Arg::U32(sample), Arg::Format(format!("{failure:?}"))],
    )
}

/// `pipeline::finish_calibration`'s lines: `stored` applied.
pub fn calibration_done(sample: u32, stored: &Calibration) -> String {
    render(
        CALIBRATION_DONE,
        &[
            Arg::U32(sample),
            Arg::F32(stored.counts_per_gram),
            Arg::F32(stored.zero_counts),
        ],
    )
}

/// `pipeline::log_calibration`: the calibration in use and where it came from.
pub fn boot_calibration(calibration: &Calibration, source: &CalibrationSource) -> String {
    render(
        BOOT_CALIBRATION,
        &[
            Arg::F32(calibration.counts_per_gram),
            Arg::F32(calibration.zero_counts),
            Arg::Format(format!("{source:?}")),
        ],
    )
}

/// `pipeline::log_method`: a method asked for on the console, set or refused.
pub fn method(sample: u32, method: &WeighingMethod, result: &Result<(), MethodRefusal>) -> String {
    let spec = Arg::Format(method.spec().to_string());
    match result {
        Ok(()) => render(METHOD_SET, &[Arg::U32(sample), spec]),
        Err(refusal) => render(
            METHOD_REFUSED,
            &[Arg::U32(sample), spec, Arg::Format(format!("{refusal:?}"))],
        ),
    }
}

/// The end of the scene.
pub fn end(samples: u32, dropped: u32) -> String {
    render(END, &[Arg::U32(samples), Arg::U32(dropped)])
}

/// The format strings here that the firmware image `elf` does not log: each must be one of
/// its defmt table's strings, letter for letter.
pub fn missing_from_image(elf: &[u8]) -> Result<Vec<&'static str>> {
    let table = defmt_decoder::Table::parse(elf)
        .context("reading the defmt table")?
        .ok_or_else(|| anyhow!("the image has no defmt data"))?;
    // Each raw symbol is a JSON object whose `data` is the format string, quoted.
    Ok(ALL
        .into_iter()
        .filter(|format| {
            let quoted = format!("\"{format}\"");
            !table.raw_symbols().any(|symbol| symbol.contains(&quoted))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_format_string_parses_and_renders_its_arguments() {
        for format in ALL {
            defmt_parser::parse(format, defmt_parser::ParserMode::Strict)
                .unwrap_or_else(|error| panic!("{format:?}: {error:?}"));
        }
        assert_eq!(
            render(TARED, &[Arg::U32(1800), Arg::F32(139.70123)]),
            "command sample=1800 tare=ok tare_g=139.70123"
        );
        assert_eq!(
            render(
                REFUSED,
                &[
                    Arg::U32(5),
                    Arg::Str("tare"),
                    Arg::Format("Invalid(Saturated)".into())
                ]
            ),
            "command sample=5 tare=refused (Invalid(Saturated))"
        );
    }

    /// A board without a valid record says so on every readout line, not only at boot.
    #[test]
    fn a_readout_on_the_nominal_calibration_says_so() {
        use estimator_core::weighing::{CalibrationError, CountsScale, StepScale};
        let calibration = CountsScale {
            counts_per_gram: 50.0,
            zero_counts: 30_000.0,
        };
        let reading = StepScale::<8>::step_default(4000.0, calibration)
            .expect("the default scale")
            .reading();
        let nominal = CalibrationSource::Defaults(CalibrationError::BadCrc);
        let line = readout(2000, &reading, 0, &nominal);
        assert!(line.contains(" cal=nominal "), "{line}");
        let line = readout(2000, &reading, 0, &CalibrationSource::Stored);
        assert!(line.contains(" cal=stored "), "{line}");
    }
}
