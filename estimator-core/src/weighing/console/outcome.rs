//! The outcome lines of the operator commands: `OK <command>[ <details>]`, or
//! `ERR <command> <reason>; expected <what would have worked>`.

use core::fmt::{self, Write};

use super::format::fault_name;
use super::unit::Unit;
use crate::weighing::calibration::CalibrationError;
use crate::weighing::command::{CalibrationFailure, CommandOutcome, CommandRefusal};
use crate::weighing::method::{RegionError, SpecError};
use crate::weighing::scale::MethodRefusal;
use crate::ConfigError;

/// `OK …` for an accepted command; masses in `unit` with `decimals`.
pub fn write_outcome(
    out: &mut impl Write,
    outcome: &CommandOutcome,
    unit: Unit,
    decimals: usize,
) -> fmt::Result {
    match *outcome {
        CommandOutcome::Tared { tare_g } => write!(
            out,
            "OK tare {:.*} {}\r\n",
            decimals,
            unit.from_grams(tare_g),
            unit.name()
        ),
        CommandOutcome::TareCleared => out.write_str("OK untare\r\n"),
        CommandOutcome::Zeroed => out.write_str("OK zero\r\n"),
        CommandOutcome::CalibrationStarted { known_mass_g, .. } => write!(
            out,
            "OK cal zero_taken; put {known_mass_g} g on the pan\r\n"
        ),
        CommandOutcome::CalibrationCancelled => out.write_str("OK cancel\r\n"),
    }
}

/// `ERR <command> <reason>; expected …` for a refused command.
pub fn write_refusal(out: &mut impl Write, command: &str, refusal: &CommandRefusal) -> fmt::Result {
    let expected = match refusal {
        CommandRefusal::Unstable => "a stable reading (state=stable or empty)",
        CommandRefusal::Uncertain => "a reading known to a quarter of e: try again in a moment",
        CommandRefusal::Invalid(_) => "a valid reading",
        CommandRefusal::NotEmpty => "an empty pan for the calibration's zero",
        CommandRefusal::CalibrationInProgress => "the reference mass on the pan, or cancel",
        CommandRefusal::NotCalibrating => "a calibration in progress (cal <mass_g>)",
        CommandRefusal::BadKnownMass => "a reference mass in grams, a positive number",
        CommandRefusal::Implausible(_) => "an empty pan and a sound front end",
        CommandRefusal::OutOfZeroRange => {
            "a gross reading within 2 % of Max of the calibrated zero"
        }
        CommandRefusal::Tared => "no tare in use (untare first)",
    };
    write!(out, "ERR {command} ")?;
    match refusal {
        CommandRefusal::Unstable => out.write_str("unstable")?,
        CommandRefusal::Uncertain => out.write_str("uncertain")?,
        CommandRefusal::Invalid(fault) => write!(out, "invalid:{}", fault_name(*fault))?,
        CommandRefusal::NotEmpty => out.write_str("not_empty")?,
        CommandRefusal::CalibrationInProgress => out.write_str("calibrating")?,
        CommandRefusal::NotCalibrating => out.write_str("not_calibrating")?,
        CommandRefusal::BadKnownMass => out.write_str("bad_mass")?,
        CommandRefusal::Implausible(error) => write_calibration_error(out, error)?,
        CommandRefusal::OutOfZeroRange => out.write_str("out_of_zero_range")?,
        CommandRefusal::Tared => out.write_str("tared")?,
    }
    write!(out, "; expected {expected}\r\n")
}

/// `ERR cal <reason>; expected …` for a calibration that ended without a result.
pub fn write_calibration_failure(
    out: &mut impl Write,
    failure: &CalibrationFailure,
) -> fmt::Result {
    out.write_str("ERR cal ")?;
    let expected = match failure {
        CalibrationFailure::NoSpan => {
            out.write_str("no_span")?;
            "the reference mass on the pan"
        }
        CalibrationFailure::Implausible(error) => {
            write_calibration_error(out, error)?;
            "the mass typed in cal on the pan, and a sound front end"
        }
        CalibrationFailure::TimedOut => {
            out.write_str("timed_out")?;
            "the reference mass on the pan and left to settle"
        }
        CalibrationFailure::MassRemoved => {
            out.write_str("mass_removed")?;
            "the reference mass left on the pan until cal says done"
        }
    };
    write!(out, "; expected {expected}\r\n")
}

/// A calibration's failure in one word, with its figure where it has one
/// (`gain_off_nominal:+30%`, `zero_off_nominal:-512`).
fn write_calibration_error(out: &mut impl Write, error: &CalibrationError) -> fmt::Result {
    match error {
        CalibrationError::Missing => out.write_str("missing"),
        CalibrationError::BadMagic => out.write_str("bad_magic"),
        CalibrationError::UnsupportedVersion(version) => {
            write!(out, "unsupported_version:{version}")
        }
        CalibrationError::BadCrc => out.write_str("bad_crc"),
        CalibrationError::OutOfDomain => out.write_str("out_of_domain"),
        CalibrationError::NoSpan => out.write_str("no_span"),
        CalibrationError::GainOffNominal { percent } => {
            write!(out, "gain_off_nominal:{percent:+}%")
        }
        CalibrationError::ZeroOffNominal { counts } => write!(out, "zero_off_nominal:{counts:+}"),
        CalibrationError::ZeroOutsideConverter => out.write_str("zero_outside_converter"),
        CalibrationError::Unreadable => out.write_str("unreadable"),
    }
}

/// `ERR method bad_spec; expected …` for a spec that does not parse.
pub fn write_spec_error(out: &mut impl Write, error: &SpecError) -> fmt::Result {
    write!(
        out,
        "ERR method bad_spec; expected {}\r\n",
        error.expected()
    )
}

/// `ERR method <reason>; expected …` for a method the board cannot run: outside the valid
/// region of its model (`outside_valid_region`), more than its estimator holds
/// (`too_large`, `not_built`), or one it could never show stable (`no_uncertainty`).
pub fn write_method_refusal(out: &mut impl Write, refusal: &MethodRefusal) -> fmt::Result {
    out.write_str("ERR method ")?;
    match *refusal {
        MethodRefusal::Region(RegionError::Decimation { minimum, .. }) => write!(
            out,
            "outside_valid_region; expected D of at least {minimum} (below it least squares is biased by errors in variables)"
        ),
        MethodRefusal::Region(RegionError::Order { minimum, .. }) => write!(
            out,
            "outside_valid_region; expected n of at least {minimum} (the cell with its filter)"
        ),
        MethodRefusal::Region(RegionError::BankSpan { needed, .. }) => write!(
            out,
            "outside_valid_region; expected a span covering ratios {:.3}-{:.3} with a candidate to spare",
            needed.0, needed.1
        ),
        MethodRefusal::Region(RegionError::Model) => out.write_str(
            "outside_valid_region; expected a board model with a finite, positive rate and bandwidth",
        ),
        MethodRefusal::Estimator(ConfigError::Order { capacity, .. }) => write!(
            out,
            "too_large; expected n from 1 to {capacity} (what this board's estimator holds)"
        ),
        MethodRefusal::Estimator(ConfigError::Model) => out.write_str(
            "not_built; expected the model bank of the size this board was built with",
        ),
        MethodRefusal::Estimator(error) => write!(out, "refused; expected {error}"),
        MethodRefusal::Fixed => out.write_str(
            "fixed; expected a data-driven method, on an image built with one (a model bank is built at boot only, from the compiled-in weighing.toml)",
        ),
        MethodRefusal::NoUncertainty => out.write_str(
            "no_uncertainty; expected least squares with lambda=1 (forgetting, bc and iv state no u on a board: never shown stable)",
        ),
    }?;
    out.write_str("\r\n")
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::String;

    use super::*;
    use crate::weighing::ScaleFault;

    #[test]
    fn every_outcome_is_one_ok_line() {
        let mut out = String::new();
        write_outcome(
            &mut out,
            &CommandOutcome::Tared { tare_g: 138.3249 },
            Unit::G,
            2,
        )
        .unwrap();
        assert_eq!(out, "OK tare 138.32 g\r\n");
        out.clear();
        let started = CommandOutcome::CalibrationStarted {
            zero_counts: 2048.0,
            known_mass_g: 200.0,
        };
        write_outcome(&mut out, &started, Unit::Kg, 5).unwrap();
        assert_eq!(out, "OK cal zero_taken; put 200 g on the pan\r\n");
    }

    #[test]
    fn a_refusal_says_why_and_what_would_work() {
        let mut out = String::new();
        write_refusal(&mut out, "tare", &CommandRefusal::Unstable).unwrap();
        assert_eq!(
            out,
            "ERR tare unstable; expected a stable reading (state=stable or empty)\r\n"
        );
        out.clear();
        write_refusal(
            &mut out,
            "tare",
            &CommandRefusal::Invalid(ScaleFault::Overload),
        )
        .unwrap();
        assert!(
            out.starts_with("ERR tare invalid:overload; expected"),
            "{out}"
        );
        out.clear();
        let off = CalibrationFailure::Implausible(CalibrationError::GainOffNominal { percent: 30 });
        write_calibration_failure(&mut out, &off).unwrap();
        assert!(
            out.starts_with("ERR cal gain_off_nominal:+30%; expected"),
            "{out}"
        );
        assert!(out.ends_with("\r\n") && out.matches("\r\n").count() == 1);
    }

    #[test]
    fn a_refused_method_says_what_the_board_takes() {
        let mut out = String::new();
        write_method_refusal(
            &mut out,
            &MethodRefusal::Region(RegionError::Decimation {
                decimation: 2,
                minimum: 9,
            }),
        )
        .unwrap();
        assert!(
            out.starts_with("ERR method outside_valid_region; expected D of at least 9 "),
            "{out}"
        );
        out.clear();
        let too_large = MethodRefusal::Estimator(ConfigError::Order {
            requested: 12,
            capacity: 8,
        });
        write_method_refusal(&mut out, &too_large).unwrap();
        assert_eq!(
            out,
            "ERR method too_large; expected n from 1 to 8 (what this board's estimator holds)\r\n"
        );
        out.clear();
        write_spec_error(&mut out, &SpecError::Missing { key: "D" }).unwrap();
        assert_eq!(
            out,
            "ERR method bad_spec; expected the block length D (D=24)\r\n"
        );
    }
}
