//! The configuration as Rust source: the constant a firmware build takes instead of the
//! file, and the sizes of the estimator type that holds exactly the configured method.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Result};
use estimator_core::weighing::{
    LoadCoverage, LoadScore, Prediction, WeighingConfig, WeighingMethod, UPLOAD_ORDER_CAPACITY,
};

use super::{method_keys, model_keys, onset_keys, parse_config, precision_name};
use crate::montecarlo::Precision;

/// What the firmware's build script (`firmware/build.rs`) generates from the text of its
/// weighing config `path`: the parsed, checked configuration as [`rust_const`], and the
/// sizes the firmware's estimator type takes from it (`ORDER_CAPACITY`: the configured
/// order or [`UPLOAD_ORDER_CAPACITY`], the larger, so a data-driven method of up to that
/// order can be uploaded over the console without a rebuild; 1 for the bank; `MODEL_STATES`: the identified
/// model's states; `BANK_CANDIDATES`: the bank's K, 0 for the data-driven methods), so the
/// image holds the configured method and the methods a console may choose, and no more: a
/// data-driven image has no room for a bank, so none of the bank's code is linked into it
/// (a console cannot choose a bank, which is built at boot only). With room for one
/// candidate, as before stop 54, the STM32F411 image took 258,908 B, leaving 3.2 KB of the
/// 256 KiB program area; without, 228,428 B, 33.7 KB (`cargo xtask test`'s flash check).
///
/// One parser: this is [`parse_config`], the same that `estimate --config` uses, so the
/// file the firmware accepts is the file host-sim accepts. On top of it the firmware asks
/// for `precision = "f32"` (its FPU is single precision: a method scored in `f64` was not
/// scored in the arithmetic it would run). Every refusal names the file, the key and what
/// was expected.
pub fn firmware_constants(path: &Path, text: &str) -> Result<String> {
    let (config, precision) = parse_config(path, text)?;
    if precision != Precision::F32 {
        bail!(
            "weighing config {}: key `method.precision`: expected \"f32\" (the firmware runs single precision; calibrate with --precision f32), found \"{}\"",
            path.display(),
            precision_name(precision)
        );
    }
    let (order_capacity, bank_candidates) = match config.method {
        // A bank image keeps order 1: its method is fixed (no console upload).
        WeighingMethod::ModelBank { candidates, .. } => (1, candidates),
        // No room for a bank, so no bank code in the image (see above).
        method => (method.order().unwrap_or(1).max(UPLOAD_ORDER_CAPACITY), 0),
    };
    let model_states = usize::from(config.model.filter_order) + 2;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "// Generated from {} by host_sim::calibrate::firmware_constants; do not edit.",
        path.display()
    );
    let _ = writeln!(
        out,
        "/// The weighing configuration the firmware runs (written by `host-sim calibrate`)."
    );
    out.push_str(&rust_const(&config));
    let sizes = [
        (
            "Largest model order the estimator holds: the configured one or the largest a console may upload (1 for the bank).",
            "ORDER_CAPACITY",
            order_capacity,
        ),
        (
            "States of the identified model (the bank's candidates): 2 + the filter's order.",
            "MODEL_STATES",
            model_states,
        ),
        (
            "Candidates of the model bank (0 for the data-driven methods: no bank code in the image).",
            "BANK_CANDIDATES",
            bank_candidates,
        ),
    ];
    for (doc, name, value) in sizes {
        let _ = writeln!(out, "/// {doc}\npub const {name}: usize = {value};");
    }
    Ok(out)
}

/// The configuration as a Rust constant, `pub const WEIGHING: WeighingConfig = ...;`, for a
/// firmware build script (paths assume `use estimator_core::tuning::*` and
/// `estimator_core::sensor::LoadCellModel` in scope).
pub fn rust_const(config: &WeighingConfig) -> String {
    let onset = literal("OnsetConfig", &onset_keys(&config.onset, float));
    // The constant's model holds its gain, before the sample rate.
    let mut model_fields = model_keys(&config.model, float);
    model_fields.insert(4, ("counts_per_gram", float(config.model.counts_per_gram)));
    let model = literal("LoadCellModel", &model_fields);
    let fields = [
        ("method", method(&config.method)),
        ("counts_per_gram", float(config.counts_per_gram)),
        ("zero_counts", float(config.zero_counts)),
        (
            "noise_variance_counts2",
            float(config.noise_variance_counts2),
        ),
        (
            "raw_noise_variance_counts2",
            float(config.raw_noise_variance_counts2),
        ),
        ("onset", onset),
        ("detection_lag_samples", float(config.detection_lag_samples)),
        ("model", model),
        (
            "identified_counts_per_gram",
            float(config.identified_counts_per_gram),
        ),
        ("calibration_mass_g", float(config.calibration_mass_g)),
        ("readout_s", float(config.readout_s)),
        ("target_relative", float(config.target_relative)),
        ("prediction", prediction(&config.prediction)),
        ("recorded_drops", config.recorded_drops.to_string()),
        (
            "recorded_worst_error_g",
            float(config.recorded_worst_error_g),
        ),
        ("loads", coverage(&config.loads)),
        ("capacity_g", float(config.capacity_g)),
        ("scale_interval_g", float(config.scale_interval_g)),
        ("final_target_g", float(config.final_target_g)),
    ];
    let mut out = String::from("pub const WEIGHING: WeighingConfig = WeighingConfig {\n");
    for (field, value) in fields {
        let _ = writeln!(out, "    {field}: {value},");
    }
    out.push_str("};\n");
    out
}

/// A float as a Rust expression (`{:?}` round-trips; the non-finite values by name).
fn float(value: f64) -> String {
    if value.is_infinite() {
        if value > 0.0 {
            "f64::INFINITY"
        } else {
            "f64::NEG_INFINITY"
        }
        .into()
    } else if value.is_nan() {
        "f64::NAN".into()
    } else {
        format!("{value:?}")
    }
}

/// A struct (or struct variant) literal on one line: `Type { field: value, ... }`.
fn literal(type_name: &str, fields: &[(&str, String)]) -> String {
    let fields: Vec<String> = fields
        .iter()
        .map(|(field, value)| format!("{field}: {value}"))
        .collect();
    format!("{type_name} {{ {} }}", fields.join(", "))
}

fn method(method: &WeighingMethod) -> String {
    let variant = match method {
        WeighingMethod::Step { .. } => "Step",
        WeighingMethod::BiasCompensated { .. } => "BiasCompensated",
        WeighingMethod::InstrumentalVariable { .. } => "InstrumentalVariable",
        WeighingMethod::ModelBank { .. } => "ModelBank",
    };
    literal(
        &format!("WeighingMethod::{variant}"),
        &method_keys(method, float, |interpolation| {
            format!("Interpolation::{interpolation:?}")
        }),
    )
}

fn prediction(p: &Prediction) -> String {
    literal(
        "Prediction",
        &[
            ("runs", p.runs.to_string()),
            ("planned_runs", p.planned_runs.to_string()),
            ("valid_runs", p.valid_runs.to_string()),
            ("within_target_runs", p.within_target_runs.to_string()),
            ("detection_failures", p.detection_failures.to_string()),
            ("bias_g", float(p.bias_g)),
            ("rms_g", float(p.rms_g)),
            ("p95_g", float(p.p95_g)),
            ("p95_upper_g", float(p.p95_upper_g)),
        ],
    )
}

fn load_score(score: &LoadScore) -> String {
    let scene = literal(
        "LoadScene",
        &[
            ("mass_g", float(score.scene.mass_g)),
            ("frequency_ratio", float(score.scene.frequency_ratio)),
        ],
    );
    let score = literal(
        "LoadScore",
        &[
            ("scene", scene),
            ("noise_floor_g", float(score.noise_floor_g)),
            ("prediction", prediction(&score.prediction)),
        ],
    );
    format!("Some({score})")
}

/// The load coverage, one field and one scene a line.
fn coverage(c: &LoadCoverage) -> String {
    let scores: Vec<String> = c
        .scores
        .iter()
        .map(|score| score.as_ref().map_or_else(|| "None".into(), load_score))
        .collect();
    let platform_mass_g = match c.platform_mass_g {
        Some(m) => format!("Some({})", float(m)),
        None => "None".into(),
    };
    format!(
        "LoadCoverage {{\n        min_g: {},\n        max_g: {},\n        loads: {},\n        platform_mass_g: {platform_mass_g},\n        scores: [\n            {},\n        ],\n    }}",
        float(c.min_g),
        float(c.max_g),
        c.loads,
        scores.join(",\n            ")
    )
}
