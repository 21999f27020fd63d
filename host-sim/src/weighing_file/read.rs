//! Reading the file: every table into the core's type it describes, in one pass, then the
//! checks the method must pass (its `spec`, the valid region, that it builds).

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use estimator_core::sensor::LoadCellModel;
use estimator_core::weighing::{
    LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, RegionError, WeighingConfig,
    WeighingMethod, MAX_SCENES,
};
use estimator_core::{Interpolation, WHITENING_ORDER};
use serde::Deserialize;

use super::{FORMAT, FORMAT_CALIBRATION_MASS_ONLY, KINDS};
use crate::calibrate::{configured_estimator, method_spec};
use crate::montecarlo::Precision;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    format: u32,
    method: MethodFile,
    scale: ScaleFile,
    model: ModelFile,
    target: TargetFile,
    onset: OnsetFile,
    measured: MeasuredFile,
    #[serde(default)]
    range: Option<RangeFile>,
    #[serde(default)]
    load: Vec<LoadFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RangeFile {
    min_g: f64,
    max_g: f64,
    loads: u32,
    #[serde(default)]
    platform_mass_g: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MethodFile {
    kind: String,
    precision: String,
    #[serde(default)]
    spec: Option<String>,
    order: Option<usize>,
    decimation: u16,
    forgetting: Option<f64>,
    candidates: Option<usize>,
    ratio_min: Option<f64>,
    ratio_max: Option<f64>,
    /// The bank's combination; files written before it was a key: three-point.
    #[serde(default)]
    interpolation: Option<String>,
    /// The bank's whitening order; files written before it was a key: 0 (none).
    #[serde(default)]
    whitening: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScaleFile {
    counts_per_gram: f64,
    identified_counts_per_gram: f64,
    zero_counts: f64,
    noise_variance_counts2: f64,
    raw_noise_variance_counts2: f64,
    /// Capacity Max, g; files written before it was a key load the reference cell's.
    #[serde(default = "default_capacity_g")]
    capacity_g: f64,
    /// Scale interval e, g; files written before it was a key load the reference cell's.
    #[serde(default = "default_scale_interval_g")]
    scale_interval_g: f64,
    /// A reading is final once 2u is at or below this, g; or in scale intervals with
    /// `final_target_e`; files with neither read 0.5 e.
    final_target_g: Option<f64>,
    final_target_e: Option<f64>,
}

fn default_capacity_g() -> f64 {
    estimator_core::weighing::WeighingConfig::REFERENCE_CAPACITY_G
}

fn default_scale_interval_g() -> f64 {
    estimator_core::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G
}

/// `[scale] final_target_g`, or `final_target_e` times e, or 0.5 e; positive either way.
fn final_target_g(path: &Path, scale: &ScaleFile) -> Result<f64> {
    let target = match (scale.final_target_g, scale.final_target_e) {
        (Some(_), Some(_)) => bail!(
            "{}: [scale]: give final_target_g or final_target_e, not both",
            path.display()
        ),
        (Some(grams), None) => grams,
        (None, Some(intervals)) => intervals * scale.scale_interval_g,
        (None, None) => WeighingConfig::FINAL_TARGET_E * scale.scale_interval_g,
    };
    if !(target.is_finite() && target > 0.0) {
        bail!(
            "{}: [scale]: the final target must be a positive number of grams (or e), found {target}",
            path.display()
        );
    }
    Ok(target)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OnsetFile {
    min_empty_samples: usize,
    drift_sigma: f64,
    threshold_sigma: f64,
    guard_samples: usize,
    min_step_sigma: f64,
    min_noise_rms: f64,
    rail_low: f64,
    rail_high: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    natural_frequency_hz: f64,
    damping_ratio: f64,
    filter_order: u8,
    filter_cutoff_hz: f64,
    sample_rate_hz: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TargetFile {
    calibration_mass_g: f64,
    readout_s: f64,
    target_relative: f64,
}

/// A table that holds a prediction's keys between its own (`[measured]`, each `[[load]]`),
/// and its [`Prediction`]. The keys stay in the file's order: toml lists them in that order
/// when it refuses an unknown one.
macro_rules! prediction_table {
    ($name:ident { $($before:ident: $b:ty,)* } { $($after:ident: $a:ty,)* }) => {
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct $name {
            $($before: $b,)*
            runs: u32,
            planned_runs: u32,
            valid_runs: u32,
            within_target_runs: u32,
            detection_failures: u32,
            bias_g: f64,
            rms_g: f64,
            p95_g: f64,
            p95_upper_g: f64,
            $($after: $a,)*
        }

        impl $name {
            fn prediction(&self) -> Prediction {
                Prediction {
                    runs: self.runs,
                    planned_runs: self.planned_runs,
                    valid_runs: self.valid_runs,
                    within_target_runs: self.within_target_runs,
                    detection_failures: self.detection_failures,
                    bias_g: self.bias_g,
                    rms_g: self.rms_g,
                    p95_g: self.p95_g,
                    p95_upper_g: self.p95_upper_g,
                }
            }
        }
    };
}

// `[measured]`: the prediction at the calibration mass.
prediction_table!(MeasuredFile {} {
    recorded_drops: u32,
    detection_lag_samples: f64,
    recorded_worst_error_g: f64,
});

// One `[[load]]`: a scene of the range and its prediction.
prediction_table!(LoadFile {
    mass_g: f64,
    frequency_ratio: f64,
    noise_floor_g: f64,
} {});

/// A refusal naming the file, the key and what was expected.
fn bad(path: &Path, key: &str, expected: &str) -> anyhow::Error {
    anyhow!(
        "weighing config {}: key `{key}`: expected {expected}",
        path.display()
    )
}

/// Read a configuration; every field is required, an unknown one is refused, and the
/// values are checked by building the configured method.
pub fn parse_config(path: &Path, text: &str) -> Result<(WeighingConfig, Precision)> {
    let file: ConfigFile =
        toml::from_str(text).map_err(|e| anyhow!("{}", describe_toml_error(path, text, &e)))?;
    if file.format != FORMAT && file.format != FORMAT_CALIBRATION_MASS_ONLY {
        return Err(bad(
            path,
            "format",
            &format!(
                "{FORMAT} (or {FORMAT_CALIBRATION_MASS_ONLY}), found {}",
                file.format
            ),
        ));
    }
    let (method, precision) = file.method.read(path)?;
    let prediction = file.measured.prediction();
    let scale = &file.scale;
    let target = &file.target;
    let config = WeighingConfig {
        method,
        counts_per_gram: scale.counts_per_gram,
        zero_counts: scale.zero_counts,
        noise_variance_counts2: scale.noise_variance_counts2,
        raw_noise_variance_counts2: scale.raw_noise_variance_counts2,
        onset: file.onset.read(),
        detection_lag_samples: file.measured.detection_lag_samples,
        model: file.model.read(scale.counts_per_gram),
        identified_counts_per_gram: scale.identified_counts_per_gram,
        calibration_mass_g: target.calibration_mass_g,
        readout_s: target.readout_s,
        target_relative: target.target_relative,
        prediction,
        recorded_drops: file.measured.recorded_drops,
        recorded_worst_error_g: file.measured.recorded_worst_error_g,
        loads: file.coverage(path, prediction)?,
        capacity_g: scale.capacity_g,
        scale_interval_g: scale.scale_interval_g,
        final_target_g: final_target_g(path, scale)?,
    };
    check_method(path, &file.method, &config, precision)?;
    Ok((config, precision))
}

impl MethodFile {
    /// `[method]`: the method and the arithmetic it was scored in.
    fn read(&self, path: &Path) -> Result<(WeighingMethod, Precision)> {
        let precision: Precision = self
            .precision
            .parse()
            .map_err(|_| bad(path, "method.precision", "f32 or f64"))?;
        let order = || {
            self.order
                .ok_or_else(|| bad(path, "method.order", "an order n"))
        };
        let decimation = self.decimation;
        let method = match self.kind.as_str() {
            "step" => WeighingMethod::Step {
                order: order()?,
                decimation,
                forgetting: self.forgetting.unwrap_or(1.0),
            },
            "bias_compensated" => WeighingMethod::BiasCompensated {
                order: order()?,
                decimation,
            },
            "instrumental_variable" => WeighingMethod::InstrumentalVariable {
                order: order()?,
                decimation,
            },
            "model_bank" => WeighingMethod::ModelBank {
                decimation,
                candidates: self
                    .candidates
                    .ok_or_else(|| bad(path, "method.candidates", "the bank's size K"))?,
                ratio_min: self
                    .ratio_min
                    .ok_or_else(|| bad(path, "method.ratio_min", "a frequency ratio"))?,
                ratio_max: self
                    .ratio_max
                    .ok_or_else(|| bad(path, "method.ratio_max", "a frequency ratio"))?,
                interpolation: match self.interpolation.as_deref() {
                    None | Some("three_point") => Interpolation::ThreePoint,
                    Some("five_point") => Interpolation::FivePoint,
                    Some(other) => {
                        return Err(bad(
                            path,
                            "method.interpolation",
                            &format!("\"three_point\" or \"five_point\", found \"{other}\""),
                        ))
                    }
                },
                whitening: match self.whitening.unwrap_or(0) {
                    order if order <= WHITENING_ORDER => order,
                    order => {
                        return Err(bad(
                            path,
                            "method.whitening",
                            &format!("a whitening order of 0 to {WHITENING_ORDER}, found {order}"),
                        ))
                    }
                },
            },
            other => {
                return Err(bad(
                    path,
                    "method.kind",
                    &format!("one of {KINDS}, found `{other}`"),
                ))
            }
        };
        Ok((method, precision))
    }
}

impl OnsetFile {
    /// `[onset]`: how the scale finds the landing.
    fn read(&self) -> OnsetConfig {
        OnsetConfig {
            min_empty_samples: self.min_empty_samples,
            drift_sigma: self.drift_sigma,
            threshold_sigma: self.threshold_sigma,
            guard_samples: self.guard_samples,
            min_step_sigma: self.min_step_sigma,
            min_noise_rms: self.min_noise_rms,
            rail_low: self.rail_low,
            rail_high: self.rail_high,
        }
    }
}

impl ModelFile {
    /// `[model]`: the identified load-cell model, at the gain of `[scale]`.
    fn read(&self, counts_per_gram: f64) -> LoadCellModel {
        LoadCellModel {
            natural_frequency_hz: self.natural_frequency_hz,
            damping_ratio: self.damping_ratio,
            filter_order: self.filter_order,
            filter_cutoff_hz: self.filter_cutoff_hz,
            counts_per_gram,
            sample_rate_hz: self.sample_rate_hz,
        }
    }
}

impl LoadFile {
    /// One `[[load]]`: a scene of the range and its score.
    fn score(&self) -> LoadScore {
        LoadScore {
            scene: LoadScene {
                mass_g: self.mass_g,
                frequency_ratio: self.frequency_ratio,
            },
            noise_floor_g: self.noise_floor_g,
            prediction: self.prediction(),
        }
    }
}

impl ConfigFile {
    /// `[range]` with its `[[load]]` tables (format 2), or the calibration mass only, scored
    /// as `prediction` says (format 1, which has neither).
    fn coverage(&self, path: &Path, prediction: Prediction) -> Result<LoadCoverage> {
        let calibration_mass_g = self.target.calibration_mass_g;
        if self.format != FORMAT {
            if self.range.is_some() || !self.load.is_empty() {
                return Err(bad(
                    path,
                    "format",
                    "2 for a file with [range] and [[load]] tables, found 1",
                ));
            }
            return Ok(LoadCoverage::calibration_mass_only(
                calibration_mass_g,
                prediction,
            ));
        }
        let range = self
            .range
            .as_ref()
            .ok_or_else(|| bad(path, "range", "a [range] table (format 2)"))?;
        if self.load.is_empty() || self.load.len() > MAX_SCENES {
            return Err(bad(
                path,
                "load",
                &format!(
                    "1 to {MAX_SCENES} [[load]] tables, found {}",
                    self.load.len()
                ),
            ));
        }
        let mut scores = [None; MAX_SCENES];
        for (slot, load) in scores.iter_mut().zip(&self.load) {
            *slot = Some(load.score());
        }
        Ok(LoadCoverage {
            min_g: range.min_g,
            max_g: range.max_g,
            loads: range.loads,
            platform_mass_g: range.platform_mass_g,
            scores,
        })
    }
}

/// The configured method must agree with its `spec` (when given), lie inside the stability
/// map's valid region (a failure outside it is not flagged at run time: estimator-core
/// `WeighingConfig::check_region`), and build.
fn check_method(
    path: &Path,
    method: &MethodFile,
    config: &WeighingConfig,
    precision: Precision,
) -> Result<()> {
    if let Some(spec) = &method.spec {
        let written = method_spec(config, precision).to_string();
        if spec.trim() != written {
            return Err(bad(
                path,
                "method.spec",
                &format!("`{written}` (what the other method keys say), found `{spec}`"),
            ));
        }
    }
    if let Err(region) = config.check_region() {
        let key = match region {
            RegionError::Decimation { .. } => "method.decimation",
            RegionError::Order { .. } => "method.order",
            RegionError::BankSpan { .. } => "method.ratio_min",
            RegionError::Model => "model",
        };
        return Err(anyhow!(
            "weighing config {}: key `{key}`: outside the valid region: {region}",
            path.display()
        ));
    }
    configured_estimator(config, precision, config.zero_counts)
        .map_err(|e| anyhow!("weighing config {}: {e}", path.display()))?;
    Ok(())
}

/// A TOML error of the config as `weighing config <file>: line L: key `table.key`: <what
/// toml says, with what it expected>`, then toml's own excerpt. The key is found from the
/// error's position: the key on that line, or for a missing key the table header toml
/// points at and the field it names.
fn describe_toml_error(path: &Path, text: &str, error: &toml::de::Error) -> String {
    let message = error.message().trim();
    let Some(span) = error.span() else {
        return format!("weighing config {}: {message}", path.display());
    };
    // On a character boundary, whatever toml's span says (slicing inside a character
    // panicked on a file of arbitrary text, found by tests/reader_fuzz.rs).
    let mut start = span.start.min(text.len());
    while !text.is_char_boundary(start) {
        start -= 1;
    }
    let line_number = text[..start].matches('\n').count() + 1;
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let raw_line = text[line_start..].lines().next().unwrap_or("");
    let line = raw_line.trim();
    // The table the position is in: the last header at or before its line.
    let table = text[..line_start + raw_line.len()]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('[') && l.ends_with(']'))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    let missing = message
        .strip_prefix("missing field `")
        .and_then(|rest| rest.split('`').next());
    let key = match (missing, line.split_once('=')) {
        (Some(field), _) => Some(field.to_string()),
        (None, Some((key, _))) if !line.starts_with('[') => Some(key.trim().to_string()),
        _ => None,
    };
    let key = match (&table, key) {
        (Some(table), Some(key)) => format!("key `{table}.{key}`"),
        (None, Some(key)) => format!("key `{key}`"),
        (Some(table), None) => format!("table `[{table}]`"),
        (None, None) => "the file".into(),
    };
    let what = match missing {
        Some(_) => format!("{message} (every key is required: expected it in this table, as `host-sim calibrate` writes it)"),
        None => message.to_string(),
    };
    format!(
        "weighing config {}: line {line_number}: {key}: {what}\n{error}",
        path.display()
    )
}

/// Read a configuration file.
pub fn load_config(path: &Path) -> Result<(WeighingConfig, Precision)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read weighing config {}", path.display()))?;
    parse_config(path, &text)
}
