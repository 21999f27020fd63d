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
use estimator_core::sensor::LoadCellModel;
use estimator_core::weighing::{OnsetConfig, WeighingMethod};
use estimator_core::Interpolation;

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

/// The keys of `[method]` after its kind, in the file's order; `float` spells the float
/// values (the file and the Rust constant spell them differently).
fn method_keys(
    method: &WeighingMethod,
    float: fn(f64) -> String,
    interpolation_value: fn(Interpolation) -> String,
) -> Vec<(&'static str, String)> {
    let mut keys = Vec::new();
    if let Some(order) = method.order() {
        keys.push(("order", order.to_string()));
    }
    keys.push(("decimation", method.decimation().to_string()));
    match *method {
        WeighingMethod::Step { forgetting, .. } => keys.push(("forgetting", float(forgetting))),
        WeighingMethod::ModelBank {
            candidates,
            ratio_min,
            ratio_max,
            interpolation,
            whitening,
            ..
        } => keys.extend([
            ("candidates", candidates.to_string()),
            ("ratio_min", float(ratio_min)),
            ("ratio_max", float(ratio_max)),
            ("interpolation", interpolation_value(interpolation)),
            ("whitening", whitening.to_string()),
        ]),
        WeighingMethod::BiasCompensated { .. } | WeighingMethod::InstrumentalVariable { .. } => {}
    }
    keys
}

/// A bank's interpolation as the file spells it (`interpolation = "five_point"`).
fn interpolation_name(interpolation: Interpolation) -> &'static str {
    match interpolation {
        Interpolation::ThreePoint => "three_point",
        Interpolation::FivePoint => "five_point",
    }
}

/// The keys of `[onset]`, in the file's order (the Rust constant's too); `float` as for
/// [`method_keys`].
fn onset_keys(onset: &OnsetConfig, float: fn(f64) -> String) -> Vec<(&'static str, String)> {
    vec![
        ("min_empty_samples", onset.min_empty_samples.to_string()),
        ("drift_sigma", float(onset.drift_sigma)),
        ("threshold_sigma", float(onset.threshold_sigma)),
        ("guard_samples", onset.guard_samples.to_string()),
        ("min_step_sigma", float(onset.min_step_sigma)),
        ("min_noise_rms", float(onset.min_noise_rms)),
        ("rail_low", float(onset.rail_low)),
        ("rail_high", float(onset.rail_high)),
    ]
}

/// The keys of `[model]`, in the file's order (its gain is `[scale]`'s); `float` as for
/// [`method_keys`].
fn model_keys(model: &LoadCellModel, float: fn(f64) -> String) -> Vec<(&'static str, String)> {
    vec![
        ("natural_frequency_hz", float(model.natural_frequency_hz)),
        ("damping_ratio", float(model.damping_ratio)),
        ("filter_order", model.filter_order.to_string()),
        ("filter_cutoff_hz", float(model.filter_cutoff_hz)),
        ("sample_rate_hz", float(model.sample_rate_hz)),
    ]
}
