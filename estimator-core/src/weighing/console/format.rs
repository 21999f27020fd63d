//! The lines the board writes: readings and refusals.

use core::fmt::{self, Write};

use super::parse::ConsoleError;
use super::unit::Unit;
use crate::weighing::{ScaleFault, ScaleState};

/// One reading as the console writes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadingLine {
    /// Time since boot, s.
    pub t_s: f32,
    /// The mass shown, g (`None`: none).
    pub mass_g: Option<f32>,
    /// Its standard uncertainty, g (`None`: none).
    pub u_g: Option<f32>,
    /// The state shown.
    pub state: ScaleState,
    /// The reading is final.
    pub is_final: bool,
}

/// The state as a console word: `empty`, `estimating`, `stable`, `invalid:<reason>`.
pub struct StateWord(pub ScaleState);

impl fmt::Display for StateWord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            ScaleState::Empty => f.write_str("empty"),
            ScaleState::Estimating => f.write_str("estimating"),
            ScaleState::Stable => f.write_str("stable"),
            ScaleState::Invalid(fault) => write!(f, "invalid:{}", fault_name(fault)),
        }
    }
}

/// A fault's name on the console.
pub fn fault_name(fault: ScaleFault) -> &'static str {
    match fault {
        ScaleFault::Saturated => "saturated",
        ScaleFault::SampleLost => "sample_lost",
        ScaleFault::Uncalibrated => "uncalibrated",
        ScaleFault::Overload => "overload",
        ScaleFault::Estimator(reason) => reason.name(),
    }
}

/// A value in `unit` with `decimals`, or `-` when there is none (or it is not finite).
struct Value(Option<f32>, Unit, usize);

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0.map(|grams| self.1.from_grams(grams)) {
            Some(value) if value.is_finite() => write!(f, "{value:.*}", self.2),
            _ => f.write_str("-"),
        }
    }
}

/// `R t=<s> mass=<value> u=<value> unit=<unit> state=<state> final=<0|1>`, masses in
/// `unit` with `decimals` (see [`Unit::decimals`]; `u` gets one more), and a line end.
pub fn write_reading(
    out: &mut impl Write,
    line: &ReadingLine,
    unit: Unit,
    decimals: usize,
) -> fmt::Result {
    let t_s = if line.t_s.is_finite() { line.t_s } else { 0.0 };
    write!(
        out,
        "R t={t_s:.3} mass={} u={} unit={} state={} final={}\r\n",
        Value(line.mass_g, unit, decimals),
        Value(line.u_g, unit, decimals + 1),
        unit.name(),
        StateWord(line.state),
        u8::from(line.is_final)
    )
}

/// `ERR <what> <reason>; expected <what was expected>` and a line end.
pub fn write_error(out: &mut impl Write, what: &str, error: &ConsoleError) -> fmt::Result {
    write!(
        out,
        "ERR {what} {}; expected {}\r\n",
        error.reason(),
        error.expected()
    )
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::String;

    use super::*;
    use crate::reading::InvalidReason;

    fn reading(state: ScaleState, mass_g: Option<f32>, u_g: Option<f32>) -> ReadingLine {
        ReadingLine {
            t_s: 1.25,
            mass_g,
            u_g,
            state,
            is_final: false,
        }
    }

    #[test]
    fn a_reading_line_in_each_unit_and_state() {
        let mut out = String::new();
        let line = ReadingLine {
            is_final: true,
            ..reading(ScaleState::Stable, Some(138.32), Some(0.0123))
        };
        write_reading(&mut out, &line, Unit::G, 2).unwrap();
        assert_eq!(
            out,
            "R t=1.250 mass=138.32 u=0.012 unit=g state=stable final=1\r\n"
        );
        out.clear();
        write_reading(&mut out, &line, Unit::Kg, 5).unwrap();
        assert_eq!(
            out,
            "R t=1.250 mass=0.13832 u=0.000012 unit=kg state=stable final=1\r\n"
        );
        out.clear();
        let invalid = reading(
            ScaleState::Invalid(ScaleFault::Estimator(InvalidReason::IllConditioned)),
            None,
            None,
        );
        write_reading(&mut out, &invalid, Unit::G, 2).unwrap();
        assert_eq!(
            out,
            "R t=1.250 mass=- u=- unit=g state=invalid:ill_conditioned final=0\r\n"
        );
        out.clear();
        // Never a non-finite number on the wire.
        let nan = reading(ScaleState::Estimating, Some(f32::NAN), Some(f32::INFINITY));
        write_reading(&mut out, &nan, Unit::G, 2).unwrap();
        assert_eq!(
            out,
            "R t=1.250 mass=- u=- unit=g state=estimating final=0\r\n"
        );
    }

    #[test]
    fn an_error_line_names_the_reason_and_what_was_expected() {
        let mut out = String::new();
        write_error(
            &mut out,
            "cal",
            &ConsoleError::Missing { expected: "a mass" },
        )
        .unwrap();
        assert_eq!(out, "ERR cal missing_argument; expected a mass\r\n");
    }
}
