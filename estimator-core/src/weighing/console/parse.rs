//! A console line into a [`Request`], or a [`ConsoleError`] that says what was expected.

use super::unit::Unit;
use crate::weighing::command::Command;

/// What a console line asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request<'a> {
    /// `tare`.
    Tare,
    /// `untare`.
    ClearTare,
    /// `zero`.
    Zero,
    /// `cal <mass_g>`.
    Calibrate {
        /// The reference mass the operator will put on, g (finite, positive).
        known_mass_g: f32,
    },
    /// `cancel`: abandon a calibration in progress.
    CancelCalibration,
    /// `unit g|kg|lb|oz`.
    Unit(Unit),
    /// `rate <Hz>`: reading lines per second (1–1000; the board says whether it can).
    Rate {
        /// Lines per second.
        hz: u16,
    },
    /// `raw on|off`.
    Raw(bool),
    /// `record`.
    Record,
    /// `config show`.
    ConfigShow,
    /// `config set <key> <value>`: the board knows its keys and their ranges.
    ConfigSet {
        /// The key as typed (lower case on the wire is the board's documented form).
        key: &'a str,
        /// The value (finite).
        value: f32,
    },
    /// `method` (show the method in use) or `method <spec>` (run this one: a spec as
    /// [`crate::weighing::WeighingMethod::parse_spec`] reads, e.g. `step:n=5,D=24`).
    Method {
        /// The spec as typed; `None` asks for the method in use.
        spec: Option<&'a str>,
    },
    /// `help`.
    Help,
}

impl Request<'_> {
    /// The operator command of the scale's command state machine this request is, if any.
    pub fn command(&self) -> Option<Command> {
        match *self {
            Request::Tare => Some(Command::Tare),
            Request::ClearTare => Some(Command::ClearTare),
            Request::Zero => Some(Command::Zero),
            Request::Calibrate { known_mass_g } => Some(Command::Calibrate { known_mass_g }),
            Request::CancelCalibration => Some(Command::CancelCalibration),
            _ => None,
        }
    }
}

/// Why a line was refused; nothing was done.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConsoleError {
    /// The line is not valid UTF-8 text.
    NotText,
    /// The first word is no command.
    UnknownCommand,
    /// A word is missing.
    Missing {
        /// What was expected there.
        expected: &'static str,
    },
    /// A word is not what the command takes.
    BadValue {
        /// What was expected there.
        expected: &'static str,
    },
    /// Words after a complete command.
    Extra,
    /// The line was longer than the console takes.
    TooLong,
    /// A command this board does not offer (yet), and what it offers instead.
    Unavailable {
        /// What the board offers instead.
        expected: &'static str,
    },
}

impl ConsoleError {
    /// What was expected, for the `ERR … ; expected …` line.
    pub fn expected(&self) -> &'static str {
        match self {
            ConsoleError::NotText => "a line of ASCII text",
            ConsoleError::UnknownCommand => {
                "one of tare, untare, zero, cal, cancel, unit, rate, raw, record, config, method, help"
            }
            ConsoleError::Missing { expected }
            | ConsoleError::BadValue { expected }
            | ConsoleError::Unavailable { expected } => expected,
            ConsoleError::Extra => "nothing after the command's arguments",
            ConsoleError::TooLong => "a line of at most 64 bytes",
        }
    }

    /// The reason in one word.
    pub fn reason(&self) -> &'static str {
        match self {
            ConsoleError::NotText => "not_text",
            ConsoleError::UnknownCommand => "unknown_command",
            ConsoleError::Missing { .. } => "missing_argument",
            ConsoleError::BadValue { .. } => "bad_value",
            ConsoleError::Extra => "extra_argument",
            ConsoleError::TooLong => "too_long",
            ConsoleError::Unavailable { .. } => "unavailable",
        }
    }
}

const MASS: &str = "a reference mass in grams, a positive number (cal 200)";
const UNIT: &str = "g, kg, lb or oz";
const RATE: &str = "a whole number of lines per second, 1 to 1000";
const ON_OFF: &str = "on or off";
const CONFIG: &str = "show, or set <key> <value>";
const KEY: &str = "a configuration key (config show lists them)";
const VALUE: &str = "a finite number";

/// Parse one console line (without its end).
pub fn parse_line(line: &[u8]) -> Result<Request<'_>, ConsoleError> {
    let text = core::str::from_utf8(line).map_err(|_| ConsoleError::NotText)?;
    let mut words = text.split_ascii_whitespace();
    let Some(command) = words.next() else {
        return Err(ConsoleError::UnknownCommand);
    };
    let is = |name: &str| command.eq_ignore_ascii_case(name);
    let request = if is("tare") {
        Request::Tare
    } else if is("untare") {
        Request::ClearTare
    } else if is("zero") {
        Request::Zero
    } else if is("cancel") {
        Request::CancelCalibration
    } else if is("record") {
        Request::Record
    } else if is("help") {
        Request::Help
    } else if is("cal") {
        let known_mass_g = number(words.next(), MASS)?;
        if known_mass_g <= 0.0 {
            return Err(ConsoleError::BadValue { expected: MASS });
        }
        Request::Calibrate { known_mass_g }
    } else if is("unit") {
        let word = words
            .next()
            .ok_or(ConsoleError::Missing { expected: UNIT })?;
        Request::Unit(Unit::from_name(word).ok_or(ConsoleError::BadValue { expected: UNIT })?)
    } else if is("rate") {
        let word = words
            .next()
            .ok_or(ConsoleError::Missing { expected: RATE })?;
        match word.parse::<u16>() {
            Ok(hz) if (1..=1000).contains(&hz) => Request::Rate { hz },
            _ => return Err(ConsoleError::BadValue { expected: RATE }),
        }
    } else if is("raw") {
        let word = words
            .next()
            .ok_or(ConsoleError::Missing { expected: ON_OFF })?;
        if word.eq_ignore_ascii_case("on") {
            Request::Raw(true)
        } else if word.eq_ignore_ascii_case("off") {
            Request::Raw(false)
        } else {
            return Err(ConsoleError::BadValue { expected: ON_OFF });
        }
    } else if is("method") {
        Request::Method { spec: words.next() }
    } else if is("config") {
        let word = words
            .next()
            .ok_or(ConsoleError::Missing { expected: CONFIG })?;
        if word.eq_ignore_ascii_case("show") {
            Request::ConfigShow
        } else if word.eq_ignore_ascii_case("set") {
            let key = words
                .next()
                .ok_or(ConsoleError::Missing { expected: KEY })?;
            let value = number(words.next(), VALUE)?;
            Request::ConfigSet { key, value }
        } else {
            return Err(ConsoleError::BadValue { expected: CONFIG });
        }
    } else {
        return Err(ConsoleError::UnknownCommand);
    };
    match words.next() {
        Some(_) => Err(ConsoleError::Extra),
        None => Ok(request),
    }
}

/// A finite number, or why not.
fn number(word: Option<&str>, expected: &'static str) -> Result<f32, ConsoleError> {
    let word = word.ok_or(ConsoleError::Missing { expected })?;
    match word.parse::<f32>() {
        Ok(value) if value.is_finite() => Ok(value),
        _ => Err(ConsoleError::BadValue { expected }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_command_parses_in_any_case_with_any_spacing() {
        assert_eq!(parse_line(b"tare"), Ok(Request::Tare));
        assert_eq!(parse_line(b"  TARE \t"), Ok(Request::Tare));
        assert_eq!(parse_line(b"untare"), Ok(Request::ClearTare));
        assert_eq!(parse_line(b"zero"), Ok(Request::Zero));
        assert_eq!(
            parse_line(b"cal 200"),
            Ok(Request::Calibrate {
                known_mass_g: 200.0
            })
        );
        assert_eq!(
            parse_line(b"Cal\t138.32"),
            Ok(Request::Calibrate {
                known_mass_g: 138.32
            })
        );
        assert_eq!(parse_line(b"cancel"), Ok(Request::CancelCalibration));
        assert_eq!(parse_line(b"unit kg"), Ok(Request::Unit(Unit::Kg)));
        assert_eq!(parse_line(b"unit OZ"), Ok(Request::Unit(Unit::Oz)));
        assert_eq!(parse_line(b"rate 50"), Ok(Request::Rate { hz: 50 }));
        assert_eq!(parse_line(b"raw on"), Ok(Request::Raw(true)));
        assert_eq!(parse_line(b"raw OFF"), Ok(Request::Raw(false)));
        assert_eq!(parse_line(b"record"), Ok(Request::Record));
        assert_eq!(parse_line(b"config show"), Ok(Request::ConfigShow));
        assert_eq!(
            parse_line(b"config set e_g 0.05"),
            Ok(Request::ConfigSet {
                key: "e_g",
                value: 0.05
            })
        );
        assert_eq!(parse_line(b"help"), Ok(Request::Help));
        assert_eq!(parse_line(b"method"), Ok(Request::Method { spec: None }));
        assert_eq!(
            parse_line(b"METHOD step:n=5,D=24"),
            Ok(Request::Method {
                spec: Some("step:n=5,D=24")
            })
        );
    }

    #[test]
    fn refusals_say_what_was_expected() {
        assert_eq!(parse_line(b"weigh"), Err(ConsoleError::UnknownCommand));
        assert_eq!(parse_line(b""), Err(ConsoleError::UnknownCommand));
        assert_eq!(
            parse_line(b"cal"),
            Err(ConsoleError::Missing { expected: MASS })
        );
        for bad in [&b"cal -5"[..], b"cal 0", b"cal nan", b"cal inf", b"cal 2OO"] {
            assert_eq!(
                parse_line(bad),
                Err(ConsoleError::BadValue { expected: MASS }),
                "{bad:?}"
            );
        }
        assert_eq!(
            parse_line(b"unit stone"),
            Err(ConsoleError::BadValue { expected: UNIT })
        );
        assert_eq!(
            parse_line(b"rate 0"),
            Err(ConsoleError::BadValue { expected: RATE })
        );
        assert_eq!(
            parse_line(b"rate 2.5"),
            Err(ConsoleError::BadValue { expected: RATE })
        );
        assert_eq!(
            parse_line(b"raw maybe"),
            Err(ConsoleError::BadValue { expected: ON_OFF })
        );
        assert_eq!(
            parse_line(b"config"),
            Err(ConsoleError::Missing { expected: CONFIG })
        );
        assert_eq!(
            parse_line(b"config set e_g"),
            Err(ConsoleError::Missing { expected: VALUE })
        );
        assert_eq!(parse_line(b"tare now"), Err(ConsoleError::Extra));
        assert_eq!(
            parse_line(b"method step:n=5, D=24"),
            Err(ConsoleError::Extra)
        );
        assert_eq!(parse_line(&[0xff, 0xfe]), Err(ConsoleError::NotText));
        assert!(ConsoleError::UnknownCommand.expected().contains("tare"));
    }

    #[test]
    fn requests_that_are_scale_commands_map_to_them() {
        assert_eq!(Request::Tare.command(), Some(Command::Tare));
        assert_eq!(
            Request::Calibrate {
                known_mass_g: 200.0
            }
            .command(),
            Some(Command::Calibrate {
                known_mass_g: 200.0
            })
        );
        assert_eq!(Request::Unit(Unit::G).command(), None);
    }
}
