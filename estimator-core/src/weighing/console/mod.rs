//! The serial console's protocol: plain lines a terminal, a script or a PLC can read and
//! type, the same on every board (a UART on the QEMU board, USB CDC or a UART on hardware).
//!
//! The board only moves bytes: each received byte goes into a [`LineBuffer`], a completed
//! line is parsed into a [`Request`] (or a [`ConsoleError`] that says what was expected),
//! and every reading and every outcome goes out as one line written here.
//!
//! ## Host → board: one command per line
//! A line ends with CR or LF (either, or both), is at most [`MAX_LINE`] bytes, words are
//! separated by spaces or tabs and case does not matter:
//!
//! | line | does |
//! |---|---|
//! | `tare` / `untare` | take the current gross mass as tare / clear it |
//! | `zero` | set the zero (empty pan, within the zero-setting range) |
//! | `cal <mass_g>` | calibrate: the empty pan now, then `<mass_g>` grams put on |
//! | `cancel` | abandon a calibration in progress |
//! | `unit g\|kg\|lb\|oz` | the unit of the reading lines |
//! | `rate <Hz>` | reading lines per second |
//! | `raw on\|off` | also stream raw samples |
//! | `record` | dump the raw samples around the last load change |
//! | `config show` / `config set <key> <value>` | the weighing configuration |
//! | `method` / `method <spec>` | the weighing method in use / run another (`step:n=5,D=24`, the `spec` of `weighing.toml`) |
//! | `help` | list the commands |
//!
//! ## Board → host
//! - a reading: `R t=<s> mass=<value> u=<value> unit=<unit> state=<state> final=<0|1>`,
//!   `mass` and `u` are `-` when there is none; `state` is `empty`, `estimating`,
//!   `stable` or `invalid:<reason>`;
//! - an outcome: `OK <command>[ <details>]`, or `ERR <command|line> <reason>; expected
//!   <what>`.
//!
//! What it must never do: panic or allocate on any input, accept a line with a word it did
//! not understand, or write a number that is not finite.

mod format;
mod line;
mod outcome;
mod parse;
mod unit;

pub use format::{fault_name, write_error, write_reading, ReadingLine, StateWord};
pub use line::{LineBuffer, LineEnd, MAX_LINE};
pub use outcome::{
    write_calibration_failure, write_method_refusal, write_outcome, write_refusal, write_spec_error,
};
pub use parse::{parse_line, ConsoleError, Request};
pub use unit::Unit;
