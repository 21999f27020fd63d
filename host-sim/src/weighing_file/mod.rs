//! The weighing configuration as a file: the TOML `host-sim calibrate` writes and
//! `estimate --config`, `cargo xtask` and the firmware's constants read (`read`), its
//! writing (`write`), and the Rust constant the firmware is built with (`rust_consts`).
//!
//! Plain tables of numbers and names that map one to one onto the fields of the core's
//! `WeighingConfig`; comments say what was measured and how. Each table of the file is read
//! by one function and written by one.
//!
//! What must never happen: a configuration that reads back other than it was written, a
//! key the reader ignores (an unknown one is refused, a missing one named), or a file
//! accepted whose method the core would not build.

use crate::montecarlo::Precision;
use estimator_core::weighing::WeighingMethod;

mod read;
mod rust_consts;
mod write;

pub use read::{load_config, parse_config};
pub use rust_consts::{firmware_constants, rust_const};
pub use write::{config_toml, to_toml};

/// The version of the TOML layout this module writes and reads.
pub const FORMAT: u32 = 2;
/// The layout before load ranges (no `[range]`, no `[[load]]`): still read, as a
/// configuration scored at the calibration mass only.
pub const FORMAT_CALIBRATION_MASS_ONLY: u32 = 1;

const KINDS: &str = "step, bias_compensated, instrumental_variable, model_bank";

fn kind_name(method: &WeighingMethod) -> &'static str {
    match method {
        WeighingMethod::Step { .. } => "step",
        WeighingMethod::BiasCompensated { .. } => "bias_compensated",
        WeighingMethod::InstrumentalVariable { .. } => "instrumental_variable",
        WeighingMethod::ModelBank { .. } => "model_bank",
    }
}

fn precision_name(precision: Precision) -> &'static str {
    match precision {
        Precision::F32 => "f32",
        Precision::F64 => "f64",
    }
}
