//! `host-sim calibrate`: recorded drops (CSVs with a column `y`, as `simulate` writes them)
//! in, a weighing configuration (TOML) out, through the core's
//! [`estimator_core::tuning::tune`] (the same call the firmware can make). And the way
//! back: [`load_config`] reads the TOML into the core's [`WeighingConfig`], and
//! [`configured_estimator`] builds the configured method exactly as the firmware does
//! ([`WeighingEstimator`]).
//!
//! What this module must never do: choose anything itself (the choice is the core's), or
//! write a configuration the core did not return.
//!
//! ## The TOML
//! Plain tables of numbers and names that map one to one onto the fields of the core's
//! `WeighingConfig`, so that a build script can turn the file into a `const` (see
//! [`rust_const`], which prints that constant); comments say what was measured and how.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use estimator_core::sensor::{IdentifyError, LoadCellModel};
use estimator_core::tuning::{
    self, CandidateGrid, CandidateScore, DropError, RunSlot, Tuned, TuningError, TuningSettings,
};
use estimator_core::weighing::{
    LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, RegionError, WeighingConfig,
    WeighingEstimator, WeighingMethod, MAX_SCENES,
};
use estimator_core::Real;
use serde::Deserialize;

use crate::method::{BoxedEstimator, InF32, Method};
use crate::montecarlo::{Precision, Setup, CAPACITY};
use crate::sensor::STATES;

/// The bank size calibration offers (the core's bank is a const generic):
/// [`tuning::BankCandidate::REFERENCE`].
pub const BANK_CANDIDATES: usize = 33;

/// The version of the TOML layout this module writes and reads.
pub const FORMAT: u32 = 2;
/// The layout before load ranges (no `[range]`, no `[[load]]`): still read, as a
/// configuration scored at the calibration mass only.
pub const FORMAT_CALIBRATION_MASS_ONLY: u32 = 1;

/// What `host-sim calibrate` is asked to do.
#[derive(Clone, Debug)]
pub struct Options {
    /// The recorded drops.
    pub drops: Vec<PathBuf>,
    /// The known mass, g.
    pub mass_g: f64,
    /// Readout time after the landing, s.
    pub readout_s: f64,
    /// Target at the readout, relative.
    pub target_relative: f64,
    /// The gain to use; `None`: the one the drops show.
    pub counts_per_gram: Option<f64>,
    /// Sample rate of the recordings, Hz.
    pub sample_rate_hz: f64,
    /// Cut-off of the known 3rd-order Butterworth, Hz.
    pub filter_cutoff_hz: f64,
    /// Converter resolution (its rails are 0 and 2^bits − 1).
    pub adc_bits: u32,
    /// Monte Carlo runs.
    pub runs: usize,
    /// Monte Carlo seed.
    pub seed: u64,
    /// Arithmetic of the candidates (the firmware runs f32).
    pub precision: Precision,
    /// Score every candidate.
    pub evaluate_all: bool,
    /// Largest order n tried.
    pub max_order: usize,
    /// The lightest load the target must hold at, g; `None`: the core's default (0.3× the
    /// mass).
    pub min_load_g: Option<f64>,
    /// The heaviest, g; `None`: the core's default (3× the mass, clipped to what the
    /// converter takes).
    pub max_load_g: Option<f64>,
    /// Loads spaced over the range.
    pub loads: usize,
    /// The platform's moving mass, g, if known.
    pub platform_mass_g: Option<f64>,
}

impl Options {
    /// Drops of `mass_g` on the reference chain: 100 ms, 0.1%, 4 kHz, 100 Hz, 16 bits, 400
    /// runs, seed 1, f32, orders up to 8.
    pub fn new(drops: Vec<PathBuf>, mass_g: f64) -> Self {
        Self {
            drops,
            mass_g,
            readout_s: 0.1,
            target_relative: 0.001,
            counts_per_gram: None,
            sample_rate_hz: 4000.0,
            filter_cutoff_hz: 100.0,
            adc_bits: 16,
            runs: 400,
            seed: 1,
            precision: Precision::F32,
            evaluate_all: false,
            max_order: 8,
            min_load_g: None,
            max_load_g: None,
            loads: tuning::DEFAULT_LOADS,
            platform_mass_g: None,
        }
    }

    /// The core's settings for these options.
    pub fn settings(&self) -> TuningSettings {
        let mut settings = TuningSettings::new(
            self.mass_g,
            self.readout_s,
            self.target_relative,
            self.sample_rate_hz,
            (STATES - 2) as u8,
            self.filter_cutoff_hz,
        );
        settings.counts_per_gram = self.counts_per_gram;
        settings.seed = self.seed;
        settings.evaluate_all = self.evaluate_all;
        settings.min_load_g = self.min_load_g;
        settings.max_load_g = self.max_load_g;
        settings.loads = self.loads;
        settings.platform_mass_g = self.platform_mass_g;
        let high = (1u64 << self.adc_bits.clamp(1, 32)) - 1;
        settings.onset = settings.onset.with_rails(0.0, high as f64);
        settings
    }
}

/// What calibration returned, with every candidate it scored and the time it took.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The core's result.
    pub calibrated: Tuned,
    /// Every candidate scored, in order.
    pub scores: Vec<CandidateScore>,
    /// Wall time of the core's call, s.
    pub elapsed_s: f64,
    /// The arithmetic the candidates were scored in.
    pub precision: Precision,
}

/// The platform's moving mass from drops of a second known mass (see
/// [`platform_mass_from_drops`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlatformFit {
    /// The platform's moving mass, g.
    pub platform_mass_g: f64,
    /// The calibration mass and what identification found with it on: g, Hz, ζ.
    pub first: (f64, f64, f64),
    /// The second mass and what identification found with it on: g, Hz, ζ.
    pub second: (f64, f64, f64),
}

impl PlatformFit {
    /// The physical law also fixes the damping: ζ scales like the frequency (c fixed). This is
    /// `(ζ₂/ζ₁)/(f₂/f₁) − 1`, the law's misfit in the damping (0 for a cell that obeys it).
    pub fn damping_law_misfit(&self) -> f64 {
        (self.second.2 / self.first.2) / (self.second.1 / self.first.1) - 1.0
    }
}

/// Identify the resonance with each mass on (the core's `tuning::identify_drops`, f64) and
/// the platform mass that explains both (`tuning::platform_mass_from_resonances`).
pub fn platform_mass_from_drops(
    first: &[Vec<f64>],
    first_names: &[String],
    second: &[Vec<f64>],
    second_names: &[String],
    second_mass_g: f64,
    options: &Options,
) -> Result<PlatformFit> {
    let identify = |drops: &[Vec<f64>], names: &[String], mass_g: f64| -> Result<(f64, f64, f64)> {
        let o = Options {
            mass_g,
            ..options.clone()
        };
        let settings = o.settings();
        let mut data: Vec<Vec<f64>> = drops.to_vec();
        let mut slices: Vec<&mut [f64]> = data.iter_mut().map(|d| d.as_mut_slice()).collect();
        let (identified, _) = tuning::identify_drops::<f64, STATES>(&mut slices, &settings)
            .map_err(|e| anyhow!("{}", describe_error(&e, names, &o)))?;
        let m = identified.model;
        Ok((mass_g, m.natural_frequency_hz, m.damping_ratio))
    };
    let first = identify(first, first_names, options.mass_g)?;
    let second = identify(second, second_names, second_mass_g)?;
    let platform_mass_g =
        tuning::platform_mass_from_resonances(first.0, first.1, second.0, second.1).ok_or_else(
            || {
                anyhow!(
                    "platform mass: {} g rings at {:.4} Hz and {} g at {:.4} Hz; by the physical law (f² ∝ 1/(m_p + M)) no platform mass m_p ≥ 0 explains both",
                    first.0, first.1, second.0, second.1
                )
            },
        )?;
    Ok(PlatformFit {
        platform_mass_g,
        first,
        second,
    })
}

/// The `y` column of a recorded drop. Calibration needs every sample: an empty or
/// non-numeric `y` is an error naming the line.
pub fn read_drop(path: &Path) -> Result<Vec<f64>> {
    let file = std::fs::File::open(path)
        .with_context(|| format!("cannot open drop {}", path.display()))?;
    let name = path.display();
    let mut lines = BufReader::new(file).lines();
    let header = match lines.next() {
        Some(line) => line.with_context(|| format!("{name}: cannot read the header"))?,
        None => bail!("{name}: empty file, expected a header with a column `y`"),
    };
    let column = header
        .split(',')
        .position(|field| field.trim() == "y")
        .with_context(|| format!("{name}: line 1: expected a column `y` in `{header}`"))?;
    let mut samples = Vec::new();
    for (index, line) in lines.enumerate() {
        let line_number = index + 2;
        let line = line.with_context(|| format!("{name}: line {line_number}: cannot read"))?;
        if line.trim().is_empty() {
            continue;
        }
        let field = line.split(',').nth(column).map(str::trim).unwrap_or("");
        let value: f64 = field.parse().map_err(|_| {
            anyhow!("{name}: line {line_number}: column `y`: expected a number (calibration needs every sample), found `{field}`")
        })?;
        samples.push(value);
    }
    Ok(samples)
}

/// Calibrate on drops already in memory (raw codes), `names` naming them in errors.
pub fn calibrate_samples(
    drops: &[Vec<f64>],
    names: &[String],
    options: &Options,
    mut progress: impl FnMut(&CandidateScore),
) -> Result<Outcome> {
    let settings = options.settings();
    let grid = CandidateGrid {
        max_order: options.max_order,
        ..CandidateGrid::standard(options.readout_s)
    };
    // `runs` synthetic drops at each scene.
    let mut runs = vec![RunSlot::EMPTY; options.runs * settings.max_scenes()];
    let mut scores = Vec::new();
    let started = Instant::now();
    let result = match options.precision {
        Precision::F64 => {
            let mut data: Vec<Vec<f64>> = drops.to_vec();
            run::<f64>(&mut data, &settings, &grid, &mut runs, |s| {
                progress(s);
                scores.push(*s);
            })
        }
        Precision::F32 => {
            let mut data: Vec<Vec<f32>> = drops
                .iter()
                .map(|d| d.iter().map(|&v| v as f32).collect())
                .collect();
            run::<f32>(&mut data, &settings, &grid, &mut runs, |s| {
                progress(s);
                scores.push(*s);
            })
        }
    };
    let elapsed_s = started.elapsed().as_secs_f64();
    let calibrated = result.map_err(|e| anyhow!("{}", describe_error(&e, names, options)))?;
    Ok(Outcome {
        calibrated,
        scores,
        elapsed_s,
        precision: options.precision,
    })
}

// The core's error, passed straight on (its size is the core's choice: no heap there).
#[allow(clippy::result_large_err)]
fn run<T: Real>(
    data: &mut [Vec<T>],
    settings: &TuningSettings,
    grid: &CandidateGrid<'_>,
    runs: &mut [RunSlot],
    report: impl FnMut(&CandidateScore),
) -> Result<Tuned, TuningError> {
    let mut slices: Vec<&mut [T]> = data.iter_mut().map(|d| d.as_mut_slice()).collect();
    tuning::tune::<T, CAPACITY, STATES, BANK_CANDIDATES>(&mut slices, settings, grid, runs, report)
}

/// Calibrate on the CSVs the options name.
pub fn calibrate_files(
    options: &Options,
    progress: impl FnMut(&CandidateScore),
) -> Result<Outcome> {
    let drops = options
        .drops
        .iter()
        .map(|p| read_drop(p))
        .collect::<Result<Vec<_>>>()?;
    let names: Vec<String> = options
        .drops
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    calibrate_samples(&drops, &names, options, progress)
}

/// A percentage with enough digits for the targets in use.
fn percent(relative: f64) -> String {
    format!("{:.4}%", relative * 100.0)
}

/// A scene in words: `50 g at 1.23x f_n`.
pub fn scene_name(scene: &LoadScene) -> String {
    format!("{:.4} g at {:.3}x f_n", scene.mass_g, scene.frequency_ratio)
}

/// One line per scored candidate, for the log.
pub fn score_line(score: &CandidateScore, mass_g: f64, target_relative: f64) -> String {
    let p = &score.prediction;
    let scored = score.loads.iter().flatten().count();
    let verdict = if score.meets {
        format!("MEETS at all {scored} loads")
    } else if let (Some(region), None, Some(check)) =
        (&score.outside_region, &score.failed_load, &score.recorded)
    {
        if check.failing == 0 {
            format!("met the target, but outside the valid region: {region}")
        } else {
            format!(
                "recorded drop {} outside ({:+.4} g); outside the valid region: {region}",
                check.worst_drop, check.errors_g[check.worst_drop as usize]
            )
        }
    } else if let Some(failed) = &score.failed_load {
        let f = &failed.prediction;
        if failed.scene.mass_g == mass_g && failed.scene.frequency_ratio == 1.0 {
            if f.runs < f.planned_runs {
                format!(
                    "no ({} of {} runs outside the target: cannot meet it)",
                    f.runs - f.within_target_runs,
                    f.runs
                )
            } else {
                "no (95th-percentile bound above the target)".into()
            }
        } else {
            format!(
                "no at {} (p95 {} of the load, {} of {} runs outside; floor {}), after {} loads met",
                scene_name(&failed.scene),
                percent(f.p95_g / failed.scene.mass_g),
                f.runs - f.within_target_runs,
                f.runs,
                percent(failed.noise_floor_g / failed.scene.mass_g),
                score.loads_met
            )
        }
    } else if p.p95_upper_g <= target_relative * mass_g {
        match &score.recorded {
            Some(check) => format!(
                "recorded drop {} outside ({:+.4} g)",
                check.worst_drop, check.errors_g[check.worst_drop as usize]
            ),
            None => "recorded check missing".into(),
        }
    } else if p.runs < p.planned_runs {
        format!(
            "no ({} of {} runs outside the target: cannot meet it)",
            p.runs - p.within_target_runs,
            p.runs
        )
    } else {
        "no".into()
    };
    format!(
        "{:>3} {:<42} p95 {:>9} (bound {:>9}) rms {:>9} valid {}/{}  {verdict}",
        score.index,
        score.method.to_string(),
        percent(p.p95_g / mass_g),
        if p.p95_upper_g.is_finite() {
            percent(p.p95_upper_g / mass_g)
        } else {
            "-".into()
        },
        percent(p.rms_g / mass_g),
        p.valid_runs,
        p.runs
    )
}

/// The core's refusal in words, naming the drop files.
pub fn describe_error(error: &TuningError, names: &[String], options: &Options) -> String {
    let name = |drop: &usize| {
        names
            .get(*drop)
            .cloned()
            .unwrap_or_else(|| format!("drop {drop}"))
    };
    match error {
        TuningError::Settings(e) => format!("calibration settings: {e}"),
        TuningError::NoDrops => "no drops given".into(),
        TuningError::TooManyDrops { drops } => {
            format!(
                "{drops} drops given, at most {} are taken",
                tuning::MAX_DROPS
            )
        }
        TuningError::Drop { drop, error } => {
            let what = match error {
                DropError::TooShort { samples, needed } => format!(
                    "too short: {samples} samples, {needed} needed (the empty stretch, the onset and the readout after it)"
                ),
                DropError::NonFinite { sample } => {
                    format!("sample {sample} is not a finite number")
                }
                DropError::Saturated { sample } => format!(
                    "sample {sample} is at a rail of the {}-bit converter (saturated)",
                    options.adc_bits
                ),
                DropError::NoEmptyStretch {
                    empty_samples,
                    needed,
                } => format!(
                    "no empty-pan stretch: {empty_samples} samples before the onset, {needed} needed (start the recording before the mass lands)"
                ),
                DropError::NoStep => {
                    "no step: the pan does not change from its empty level by more than 10 noise standard deviations".into()
                }
            };
            format!("drop {}: {what}", name(drop))
        }
        TuningError::Identify(e) => match e {
            IdentifyError::TooShort {
                drop,
                samples,
                needed,
            } => format!(
                "drop {}: {samples} samples after the onset, identification needs {needed}",
                name(drop)
            ),
            other => format!("the drops do not identify the load cell's model: {other:?}"),
        },
        TuningError::TooFewRuns { runs, needed } => {
            let scenes = options.settings().max_scenes().max(1);
            format!(
                "{} Monte Carlo runs per scene ({scenes} scenes): at least {} are needed for the 95%/95% bound",
                runs / scenes,
                needed / scenes
            )
        }
        TuningError::NoCandidates => "no candidate methods".into(),
        TuningError::Candidate { method, error } => {
            format!("candidate {method} cannot be built: {error}")
        }
        TuningError::LoadSaturates { mass_g, limit_g } => format!(
            "load range: a drop of {mass_g} g overshoots into a rail of the {}-bit converter; the heaviest load it takes is {limit_g:.1} g",
            options.adc_bits
        ),
        TuningError::NoneMeetsTarget {
            best,
            prediction,
            failed_load,
            recorded_failing,
            evaluated,
        } => {
            let recorded = match recorded_failing {
                Some(failing) => format!("; {failing} recorded drops outside the target"),
                None => String::new(),
            };
            // Where the best one failed: the calibration mass, or a load of the range.
            let (where_, p, mass, floor) = match failed_load {
                Some(load) => (
                    format!(" at {}", scene_name(&load.scene)),
                    load.prediction,
                    load.scene.mass_g,
                    Some(load.noise_floor_g),
                ),
                None => (String::new(), *prediction, options.mass_g, None),
            };
            // A method at the floor, unbiased and Gaussian, has its 95th percentile of
            // |error| at 1.96 times it.
            let floor = match floor {
                Some(floor) => format!(
                    "; no method beats an RMS of {floor:.4} g ({}) there (the noise floor: Cramér–Rao bound with the tare), whose 95th percentile is {} of the load",
                    percent(floor / mass),
                    percent(1.96 * floor / mass)
                ),
                None => String::new(),
            };
            format!(
                "no candidate meets the target of {} at {} ms ({evaluated} evaluated); best is {best} with a 95th percentile{where_} of {} ({:.4} g, from {} runs), RMS {}, valid in {} of {} runs{floor}{recorded}",
                percent(options.target_relative),
                options.readout_s * 1e3,
                percent(p.p95_g / mass),
                p.p95_g,
                p.runs,
                percent(p.rms_g / mass),
                p.valid_runs,
                p.runs
            )
        }
    }
}

// ---------------------------------------------------------------------------------------
// The configured method.

/// The method layer's spec of a configured method (for `--method`, and the TOML's `spec`).
pub fn method_spec(config: &WeighingConfig, precision: Precision) -> Method {
    let setup = |order: usize, decimation: u16, forgetting: f64| Setup {
        order,
        decimation,
        forgetting,
        precision,
    };
    match config.method {
        WeighingMethod::Step {
            order,
            decimation,
            forgetting,
        } => Method::Step(setup(order, decimation, forgetting)),
        WeighingMethod::BiasCompensated { order, decimation } => Method::BiasCompensated {
            setup: setup(order, decimation, 1.0),
            noise_variance: Some(config.noise_variance_counts2),
        },
        WeighingMethod::InstrumentalVariable { order, decimation } => {
            Method::InstrumentalVariable {
                setup: setup(order, decimation, 1.0),
                delay: None,
            }
        }
        WeighingMethod::ModelBank {
            decimation,
            candidates,
            ratio_min,
            ratio_max,
        } => Method::Model(crate::method::ModelSpec {
            decimation,
            candidates,
            span: (ratio_min, ratio_max),
            calibration_g: config.calibration_mass_g,
            precision,
            identified: Some(crate::method::IdentifiedModel {
                natural_frequency_hz: config.model.natural_frequency_hz,
                damping_ratio: config.model.damping_ratio,
                filter_cutoff_hz: config.model.filter_cutoff_hz,
            }),
        }),
    }
}

/// The configured method as the firmware builds it (the core's [`WeighingEstimator`]), for
/// samples `code − zero_counts`, behind the `f64` interface.
pub fn configured_estimator(
    config: &WeighingConfig,
    precision: Precision,
    zero_counts: f64,
) -> Result<BoxedEstimator> {
    let named =
        |e: estimator_core::ConfigError| anyhow!("configured method {}: {e}", config.method);
    Ok(match precision {
        Precision::F64 => Box::new(
            WeighingEstimator::<f64, CAPACITY, STATES, BANK_CANDIDATES>::new(config, zero_counts)
                .map_err(named)?,
        ),
        Precision::F32 => Box::new(InF32(Box::new(
            WeighingEstimator::<f32, CAPACITY, STATES, BANK_CANDIDATES>::new(config, zero_counts)
                .map_err(named)?,
        ))),
    })
}

// ---------------------------------------------------------------------------------------
// The TOML.

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
struct LoadFile {
    mass_g: f64,
    frequency_ratio: f64,
    noise_floor_g: f64,
    runs: u32,
    planned_runs: u32,
    valid_runs: u32,
    within_target_runs: u32,
    detection_failures: u32,
    bias_g: f64,
    rms_g: f64,
    p95_g: f64,
    p95_upper_g: f64,
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
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScaleFile {
    counts_per_gram: f64,
    identified_counts_per_gram: f64,
    zero_counts: f64,
    noise_variance_counts2: f64,
    raw_noise_variance_counts2: f64,
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MeasuredFile {
    runs: u32,
    planned_runs: u32,
    valid_runs: u32,
    within_target_runs: u32,
    detection_failures: u32,
    bias_g: f64,
    rms_g: f64,
    p95_g: f64,
    p95_upper_g: f64,
    recorded_drops: u32,
    detection_lag_samples: f64,
    recorded_worst_error_g: f64,
}

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

/// A float as TOML writes it: shortest round-trip form, `inf`/`-inf`/`nan` spelled out.
fn number(value: f64) -> String {
    if value.is_nan() {
        "nan".into()
    } else if value.is_infinite() {
        if value > 0.0 { "inf" } else { "-inf" }.into()
    } else if value == value.trunc() && value.abs() < 1e15 {
        // `1` would read back as an integer, which a float field refuses.
        format!("{value:.1}")
    } else {
        format!("{value}")
    }
}

/// The configuration as TOML, with comments that say what was measured. `command` is the
/// command line that produced it, `names` the drop files.
pub fn to_toml(outcome: &Outcome, names: &[String], command: &str) -> String {
    let c = &outcome.calibrated;
    let config = &c.config;
    write_toml(
        config,
        outcome.precision,
        Some(Provenance {
            calibrated: c,
            scores: &outcome.scores,
            names,
            command,
            elapsed_s: outcome.elapsed_s,
        }),
    )
}

struct Provenance<'a> {
    calibrated: &'a Tuned,
    scores: &'a [CandidateScore],
    names: &'a [String],
    command: &'a str,
    elapsed_s: f64,
}

fn write_toml(
    config: &WeighingConfig,
    precision: Precision,
    provenance: Option<Provenance<'_>>,
) -> String {
    let mut s = String::new();
    let mass = config.calibration_mass_g;
    let target_g = config.target_relative * mass;
    let p = &config.prediction;
    let w = &mut s;
    // Writing to a String cannot fail.
    let _ = writeln!(
        w,
        "# Weighing configuration, written by `host-sim calibrate` (estimator-core tuning::tune)."
    );
    if let Some(prov) = &provenance {
        let _ = writeln!(w, "# Command: {}", prov.command);
        let _ = writeln!(
            w,
            "# From {} drops of {} g: {}. Calibration took {:.2} s ({} candidates scored).",
            prov.names.len(),
            mass,
            prov.names.join(", "),
            prov.elapsed_s,
            prov.calibrated.evaluated
        );
    }
    let _ = writeln!(w, "format = {FORMAT}\n");

    let _ = writeln!(w, "[method]");
    let _ = writeln!(
        w,
        "# The smallest candidate (model order n first, then the solver: least squares, with"
    );
    let _ = writeln!(w, "# forgetting, bias-compensated, instrumental variables; then the largest D; the model bank");
    let _ = writeln!(
        w,
        "# last) whose 95th-percentile |error| at the readout is within the target with 95%"
    );
    let _ = writeln!(w, "# confidence over the Monte Carlo below, and that is within the target on every recorded drop.");
    if let Some(prov) = &provenance {
        let smaller: Vec<&CandidateScore> = prov
            .scores
            .iter()
            .filter(|s| s.index < prov.calibrated.chosen.index)
            .collect();
        if !smaller.is_empty() {
            let _ = writeln!(
                w,
                "# {} smaller candidates did not meet the target (the run log lists each).",
                smaller.len()
            );
        }
    }
    let _ = writeln!(
        w,
        "kind = \"{}\"   # one of {KINDS}",
        kind_name(&config.method)
    );
    let _ = writeln!(
        w,
        "precision = \"{}\"   # the arithmetic it was scored in",
        precision_name(precision)
    );
    let _ = writeln!(
        w,
        "spec = \"{}\"   # the same as host-sim's --method spec",
        method_spec(config, precision)
    );
    match config.method {
        WeighingMethod::Step {
            order,
            decimation,
            forgetting,
        } => {
            let _ = writeln!(
                w,
                "order = {order}\ndecimation = {decimation}\nforgetting = {}",
                number(forgetting)
            );
        }
        WeighingMethod::BiasCompensated { order, decimation }
        | WeighingMethod::InstrumentalVariable { order, decimation } => {
            let _ = writeln!(w, "order = {order}\ndecimation = {decimation}");
        }
        WeighingMethod::ModelBank {
            decimation,
            candidates,
            ratio_min,
            ratio_max,
        } => {
            let _ = writeln!(
                w,
                "decimation = {decimation}\ncandidates = {candidates}\nratio_min = {}\nratio_max = {}",
                number(ratio_min),
                number(ratio_max)
            );
        }
    }

    let _ = writeln!(w, "\n[scale]");
    let derived = (config.counts_per_gram - config.identified_counts_per_gram).abs()
        <= 1e-12 * config.counts_per_gram.abs();
    if derived {
        let _ = writeln!(
            w,
            "# Gain derived from the drops: the identified model's fitted step over the known mass"
        );
        let _ = writeln!(
            w,
            "# (the level the fitted transient settles to), mean over the drops."
        );
    } else {
        let _ = writeln!(
            w,
            "# Gain given on the command line; the drops showed {} counts/g ({:+.4}%).",
            config.identified_counts_per_gram,
            (config.identified_counts_per_gram / config.counts_per_gram - 1.0) * 100.0
        );
    }
    let _ = writeln!(w, "counts_per_gram = {}", number(config.counts_per_gram));
    let _ = writeln!(
        w,
        "identified_counts_per_gram = {}",
        number(config.identified_counts_per_gram)
    );
    let _ = writeln!(
        w,
        "# Mean of the empty-pan stretches before the onsets (re-tare before weighing)."
    );
    let _ = writeln!(w, "zero_counts = {}", number(config.zero_counts));
    let _ = writeln!(
        w,
        "# White noise of one sample on the empty stretches (NoiseMeter), at the method's D: sigma = {:.3} counts = {:.4} g.",
        config.noise_variance_counts2.sqrt(),
        config.noise_variance_counts2.sqrt() / config.counts_per_gram
    );
    let _ = writeln!(
        w,
        "noise_variance_counts2 = {}",
        number(config.noise_variance_counts2)
    );
    let _ = writeln!(
        w,
        "# The same at D = 1: sigma = {:.3} counts = {:.4} g.",
        config.raw_noise_variance_counts2.sqrt(),
        config.raw_noise_variance_counts2.sqrt() / config.counts_per_gram
    );
    let _ = writeln!(
        w,
        "raw_noise_variance_counts2 = {}",
        number(config.raw_noise_variance_counts2)
    );

    let o = &config.onset;
    let _ = writeln!(w, "\n[onset]");
    let _ = writeln!(
        w,
        "# How the scale must find the landing (estimator-core tuning::onset): two-sided CUSUM on"
    );
    let _ = writeln!(w, "# the deviation from the zero in noise standard deviations, backed off to the start of the");
    let _ = writeln!(
        w,
        "# excursion. The method was scored started there AND at the landing itself: start it"
    );
    let _ = writeln!(
        w,
        "# anywhere in between (not before the landing). A code at or beyond a rail is saturated."
    );
    let _ = writeln!(w, "min_empty_samples = {}", o.min_empty_samples);
    let _ = writeln!(w, "drift_sigma = {}", number(o.drift_sigma));
    let _ = writeln!(w, "threshold_sigma = {}", number(o.threshold_sigma));
    let _ = writeln!(w, "guard_samples = {}", o.guard_samples);
    let _ = writeln!(w, "min_step_sigma = {}", number(o.min_step_sigma));
    let _ = writeln!(w, "min_noise_rms = {}", number(o.min_noise_rms));
    let _ = writeln!(w, "rail_low = {}", number(o.rail_low));
    let _ = writeln!(w, "rail_high = {}", number(o.rail_high));

    let _ = writeln!(w, "\n[model]");
    let _ = writeln!(w, "# Identified from the drops (estimator-core identify): the mechanical mode with the load on,");
    let _ = writeln!(w, "# in series with the known Butterworth low-pass.");
    if let Some(prov) = &provenance {
        let i = &prov.calibrated.identified;
        let _ = writeln!(
            w,
            "# Fit: {} model evaluations, residual {:.3} counts per raw sample.",
            i.evaluations, i.noise_rms
        );
    }
    let m = &config.model;
    let _ = writeln!(
        w,
        "natural_frequency_hz = {}",
        number(m.natural_frequency_hz)
    );
    let _ = writeln!(w, "damping_ratio = {}", number(m.damping_ratio));
    let _ = writeln!(w, "filter_order = {}", m.filter_order);
    let _ = writeln!(w, "filter_cutoff_hz = {}", number(m.filter_cutoff_hz));
    let _ = writeln!(w, "sample_rate_hz = {}", number(m.sample_rate_hz));

    let _ = writeln!(w, "\n[target]");
    let _ = writeln!(
        w,
        "# {} of {} g = {:.4} g, {} ms after the mass lands.",
        percent(config.target_relative),
        mass,
        target_g,
        config.readout_s * 1e3
    );
    let _ = writeln!(w, "calibration_mass_g = {}", number(mass));
    let _ = writeln!(w, "readout_s = {}", number(config.readout_s));
    let _ = writeln!(w, "target_relative = {}", number(config.target_relative));

    let _ = writeln!(w, "\n[measured]");
    let _ = writeln!(
        w,
        "# Monte Carlo: {} synthetic drops of the identified model at the gain the drops showed,",
        p.planned_runs
    );
    let _ = writeln!(w, "# white noise at the upper confidence value of the measured variance, each through the same");
    let _ = writeln!(
        w,
        "# onset detection and tare, read {} ms after the landing.",
        config.readout_s * 1e3
    );
    if let Some(prov) = &provenance {
        let c = prov.calibrated;
        let _ = writeln!(
            w,
            "# Noise used: sigma = {:.3} counts (measured {:.3}, relative standard error of the variance {:.1}%); {} empty samples before each drop.",
            c.monte_carlo_noise_variance_counts2.sqrt(),
            config.raw_noise_variance_counts2.sqrt(),
            c.noise_relative_standard_error * 100.0,
            c.synthetic_empty_samples
        );
    }
    let _ = writeln!(
        w,
        "# Predicted at the readout: RMS {:.4} g ({}), 95th percentile {:.4} g ({}), its 95% upper bound {:.4} g ({}).",
        p.rms_g,
        percent(p.rms_g / mass),
        p.p95_g,
        percent(p.p95_g / mass),
        p.p95_upper_g,
        percent(p.p95_upper_g / mass)
    );
    let _ = writeln!(w, "runs = {}\nplanned_runs = {}\nvalid_runs = {}\nwithin_target_runs = {}\ndetection_failures = {}",
        p.runs, p.planned_runs, p.valid_runs, p.within_target_runs, p.detection_failures);
    let _ = writeln!(
        w,
        "bias_g = {}\nrms_g = {}\np95_g = {}\np95_upper_g = {}",
        number(p.bias_g),
        number(p.rms_g),
        number(p.p95_g),
        number(p.p95_upper_g)
    );
    if let Some(prov) = &provenance {
        if let Some(check) = &prov.calibrated.chosen.recorded {
            let each: Vec<String> = prov
                .names
                .iter()
                .zip(check.errors_g.iter())
                .map(|(name, e)| format!("{name} {e:+.4} g"))
                .collect();
            let _ = writeln!(
                w,
                "# Confirmed on the recorded drops (the larger error of the two starts): {}.",
                each.join(", ")
            );
        }
    }
    let _ = writeln!(
        w,
        "# Mean lag of the detected onset behind the landing in the synthetic drops, samples."
    );
    let _ = writeln!(
        w,
        "detection_lag_samples = {}",
        number(config.detection_lag_samples)
    );
    let _ = writeln!(w, "recorded_drops = {}", config.recorded_drops);
    let _ = writeln!(
        w,
        "recorded_worst_error_g = {}",
        number(config.recorded_worst_error_g)
    );

    let loads = &config.loads;
    let _ = writeln!(w, "\n[range]");
    let _ = writeln!(
        w,
        "# The target holds, relative to the load ({} of it), at every scene below: the calibration",
        percent(config.target_relative)
    );
    let _ = writeln!(w, "# mass and `loads` loads spaced geometrically over [min_g, max_g], each with its own synthetic");
    let _ = writeln!(w, "# drops of the identified model moved to that load by the physical law (stiffness and damping");
    match loads.platform_mass_g {
        Some(platform) => {
            let _ = writeln!(w, "# fixed) with the platform's moving mass {platform} g.");
        }
        None => {
            let _ = writeln!(w, "# fixed). The platform's moving mass is unknown: each load was scored at both ends of what");
            let _ = writeln!(w, "# physics allows, as calibrated (mass -> infinity) and sqrt(calibration mass / load) times");
            let _ = writeln!(
                w,
                "# faster (mass -> 0). `platform_mass_g` absent: unknown."
            );
        }
    }
    let _ = writeln!(w, "min_g = {}", number(loads.min_g));
    let _ = writeln!(w, "max_g = {}", number(loads.max_g));
    let _ = writeln!(w, "loads = {}", loads.loads);
    if let Some(platform) = loads.platform_mass_g {
        let _ = writeln!(w, "platform_mass_g = {}", number(platform));
    }
    for score in loads.scores.iter().flatten() {
        let p = &score.prediction;
        let mass = score.scene.mass_g;
        let _ = writeln!(w, "\n[[load]]");
        let _ = writeln!(
            w,
            "# {}: RMS {:.4} g ({}), 95th percentile {:.4} g ({}), bound {:.4} g ({}) <= {:.4} g; noise floor {:.4} g ({}).",
            scene_name(&score.scene),
            p.rms_g,
            percent(p.rms_g / mass),
            p.p95_g,
            percent(p.p95_g / mass),
            p.p95_upper_g,
            percent(p.p95_upper_g / mass),
            config.target_relative * mass,
            score.noise_floor_g,
            percent(score.noise_floor_g / mass)
        );
        let _ = writeln!(w, "mass_g = {}", number(mass));
        let _ = writeln!(
            w,
            "frequency_ratio = {}",
            number(score.scene.frequency_ratio)
        );
        let _ = writeln!(w, "noise_floor_g = {}", number(score.noise_floor_g));
        let _ = writeln!(w, "runs = {}\nplanned_runs = {}\nvalid_runs = {}\nwithin_target_runs = {}\ndetection_failures = {}",
            p.runs, p.planned_runs, p.valid_runs, p.within_target_runs, p.detection_failures);
        let _ = writeln!(
            w,
            "bias_g = {}\nrms_g = {}\np95_g = {}\np95_upper_g = {}",
            number(p.bias_g),
            number(p.rms_g),
            number(p.p95_g),
            number(p.p95_upper_g)
        );
    }
    s
}

/// The configuration as TOML without the provenance comments (for tests and round trips).
pub fn config_toml(config: &WeighingConfig, precision: Precision) -> String {
    write_toml(config, precision, None)
}

/// Read a configuration; every field is required, an unknown one is refused, and the
/// values are checked by building the configured method.
pub fn parse_config(path: &Path, text: &str) -> Result<(WeighingConfig, Precision)> {
    let file: ConfigFile =
        toml::from_str(text).map_err(|e| anyhow!("{}", describe_toml_error(path, text, &e)))?;
    let bad = |key: &str, expected: &str| {
        anyhow!(
            "weighing config {}: key `{key}`: expected {expected}",
            path.display()
        )
    };
    if file.format != FORMAT && file.format != FORMAT_CALIBRATION_MASS_ONLY {
        return Err(bad(
            "format",
            &format!(
                "{FORMAT} (or {FORMAT_CALIBRATION_MASS_ONLY}), found {}",
                file.format
            ),
        ));
    }
    let m = &file.method;
    let precision: Precision = m
        .precision
        .parse()
        .map_err(|_| bad("method.precision", "f32 or f64"))?;
    let order = || m.order.ok_or_else(|| bad("method.order", "an order n"));
    let method = match m.kind.as_str() {
        "step" => WeighingMethod::Step {
            order: order()?,
            decimation: m.decimation,
            forgetting: m.forgetting.unwrap_or(1.0),
        },
        "bias_compensated" => WeighingMethod::BiasCompensated {
            order: order()?,
            decimation: m.decimation,
        },
        "instrumental_variable" => WeighingMethod::InstrumentalVariable {
            order: order()?,
            decimation: m.decimation,
        },
        "model_bank" => WeighingMethod::ModelBank {
            decimation: m.decimation,
            candidates: m
                .candidates
                .ok_or_else(|| bad("method.candidates", "the bank's size K"))?,
            ratio_min: m
                .ratio_min
                .ok_or_else(|| bad("method.ratio_min", "a frequency ratio"))?,
            ratio_max: m
                .ratio_max
                .ok_or_else(|| bad("method.ratio_max", "a frequency ratio"))?,
        },
        other => {
            return Err(bad(
                "method.kind",
                &format!("one of {KINDS}, found `{other}`"),
            ))
        }
    };
    let config = WeighingConfig {
        method,
        counts_per_gram: file.scale.counts_per_gram,
        zero_counts: file.scale.zero_counts,
        noise_variance_counts2: file.scale.noise_variance_counts2,
        raw_noise_variance_counts2: file.scale.raw_noise_variance_counts2,
        onset: OnsetConfig {
            min_empty_samples: file.onset.min_empty_samples,
            drift_sigma: file.onset.drift_sigma,
            threshold_sigma: file.onset.threshold_sigma,
            guard_samples: file.onset.guard_samples,
            min_step_sigma: file.onset.min_step_sigma,
            min_noise_rms: file.onset.min_noise_rms,
            rail_low: file.onset.rail_low,
            rail_high: file.onset.rail_high,
        },
        detection_lag_samples: file.measured.detection_lag_samples,
        model: LoadCellModel {
            natural_frequency_hz: file.model.natural_frequency_hz,
            damping_ratio: file.model.damping_ratio,
            filter_order: file.model.filter_order,
            filter_cutoff_hz: file.model.filter_cutoff_hz,
            counts_per_gram: file.scale.counts_per_gram,
            sample_rate_hz: file.model.sample_rate_hz,
        },
        identified_counts_per_gram: file.scale.identified_counts_per_gram,
        calibration_mass_g: file.target.calibration_mass_g,
        readout_s: file.target.readout_s,
        target_relative: file.target.target_relative,
        prediction: Prediction {
            runs: file.measured.runs,
            planned_runs: file.measured.planned_runs,
            valid_runs: file.measured.valid_runs,
            within_target_runs: file.measured.within_target_runs,
            detection_failures: file.measured.detection_failures,
            bias_g: file.measured.bias_g,
            rms_g: file.measured.rms_g,
            p95_g: file.measured.p95_g,
            p95_upper_g: file.measured.p95_upper_g,
        },
        recorded_drops: file.measured.recorded_drops,
        recorded_worst_error_g: file.measured.recorded_worst_error_g,
        loads: LoadCoverage::calibration_mass_only(
            file.target.calibration_mass_g,
            Prediction {
                runs: file.measured.runs,
                planned_runs: file.measured.planned_runs,
                valid_runs: file.measured.valid_runs,
                within_target_runs: file.measured.within_target_runs,
                detection_failures: file.measured.detection_failures,
                bias_g: file.measured.bias_g,
                rms_g: file.measured.rms_g,
                p95_g: file.measured.p95_g,
                p95_upper_g: file.measured.p95_upper_g,
            },
        ),
    };
    let mut config = config;
    if file.format == FORMAT {
        let range = file
            .range
            .as_ref()
            .ok_or_else(|| bad("range", "a [range] table (format 2)"))?;
        if file.load.is_empty() || file.load.len() > MAX_SCENES {
            return Err(bad(
                "load",
                &format!(
                    "1 to {MAX_SCENES} [[load]] tables, found {}",
                    file.load.len()
                ),
            ));
        }
        let mut scores = [None; MAX_SCENES];
        for (slot, load) in scores.iter_mut().zip(&file.load) {
            *slot = Some(LoadScore {
                scene: LoadScene {
                    mass_g: load.mass_g,
                    frequency_ratio: load.frequency_ratio,
                },
                noise_floor_g: load.noise_floor_g,
                prediction: Prediction {
                    runs: load.runs,
                    planned_runs: load.planned_runs,
                    valid_runs: load.valid_runs,
                    within_target_runs: load.within_target_runs,
                    detection_failures: load.detection_failures,
                    bias_g: load.bias_g,
                    rms_g: load.rms_g,
                    p95_g: load.p95_g,
                    p95_upper_g: load.p95_upper_g,
                },
            });
        }
        config.loads = LoadCoverage {
            min_g: range.min_g,
            max_g: range.max_g,
            loads: range.loads,
            platform_mass_g: range.platform_mass_g,
            scores,
        };
    } else if file.range.is_some() || !file.load.is_empty() {
        return Err(bad(
            "format",
            "2 for a file with [range] and [[load]] tables, found 1",
        ));
    }
    if let Some(spec) = &m.spec {
        let written = method_spec(&config, precision).to_string();
        if spec.trim() != written {
            return Err(bad(
                "method.spec",
                &format!("`{written}` (what the other method keys say), found `{spec}`"),
            ));
        }
    }
    // Inside the stability map's valid region: a failure outside it is not flagged at run
    // time (estimator-core `WeighingConfig::check_region`).
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
    // The values must make the configured method.
    configured_estimator(&config, precision, config.zero_counts)
        .map_err(|e| anyhow!("weighing config {}: {e}", path.display()))?;
    Ok((config, precision))
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
    let start = span.start.min(text.len());
    let line_number = text[..start].matches('\n').count() + 1;
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next().unwrap_or("").trim();
    // The table the position is in: the last header at or before its line.
    let table = text[..line_start + line.len()]
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

/// What the firmware's build script (`firmware/build.rs`) generates from the text of its
/// weighing config `path`: the parsed, checked configuration as [`rust_const`], and the
/// sizes the firmware's estimator type takes from it (`ORDER_CAPACITY`: the configured
/// order, 1 for the bank; `MODEL_STATES`: the identified model's states; `BANK_CANDIDATES`:
/// the bank's K, 1 for the data-driven methods), so the image holds exactly the configured
/// method.
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
        WeighingMethod::ModelBank { candidates, .. } => (1, candidates),
        method => (method.order().unwrap_or(1), 1),
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
    let _ = writeln!(
        out,
        "/// Largest model order the estimator holds: the configured order (1 for the bank)."
    );
    let _ = writeln!(out, "pub const ORDER_CAPACITY: usize = {order_capacity};");
    let _ = writeln!(
        out,
        "/// States of the identified model (the bank's candidates): 2 + the filter's order."
    );
    let _ = writeln!(out, "pub const MODEL_STATES: usize = {model_states};");
    let _ = writeln!(
        out,
        "/// Candidates of the model bank (1 for the data-driven methods)."
    );
    let _ = writeln!(out, "pub const BANK_CANDIDATES: usize = {bank_candidates};");
    Ok(out)
}

/// The configuration as a Rust constant, `pub const WEIGHING: WeighingConfig = ...;`, for a
/// firmware build script (paths assume `use estimator_core::tuning::*` and
/// `estimator_core::sensor::LoadCellModel` in scope).
pub fn rust_const(config: &WeighingConfig) -> String {
    let f = |v: f64| -> String {
        if v.is_infinite() {
            if v > 0.0 {
                "f64::INFINITY"
            } else {
                "f64::NEG_INFINITY"
            }
            .into()
        } else if v.is_nan() {
            "f64::NAN".into()
        } else {
            format!("{v:?}")
        }
    };
    let method = match config.method {
        WeighingMethod::Step {
            order,
            decimation,
            forgetting,
        } => format!(
            "WeighingMethod::Step {{ order: {order}, decimation: {decimation}, forgetting: {} }}",
            f(forgetting)
        ),
        WeighingMethod::BiasCompensated { order, decimation } => format!(
            "WeighingMethod::BiasCompensated {{ order: {order}, decimation: {decimation} }}"
        ),
        WeighingMethod::InstrumentalVariable { order, decimation } => format!(
            "WeighingMethod::InstrumentalVariable {{ order: {order}, decimation: {decimation} }}"
        ),
        WeighingMethod::ModelBank {
            decimation,
            candidates,
            ratio_min,
            ratio_max,
        } => format!(
            "WeighingMethod::ModelBank {{ decimation: {decimation}, candidates: {candidates}, ratio_min: {}, ratio_max: {} }}",
            f(ratio_min),
            f(ratio_max)
        ),
    };
    let prediction = |p: &Prediction| {
        format!(
            "Prediction {{ runs: {}, planned_runs: {}, valid_runs: {}, within_target_runs: {}, detection_failures: {}, bias_g: {}, rms_g: {}, p95_g: {}, p95_upper_g: {} }}",
            p.runs,
            p.planned_runs,
            p.valid_runs,
            p.within_target_runs,
            p.detection_failures,
            f(p.bias_g),
            f(p.rms_g),
            f(p.p95_g),
            f(p.p95_upper_g)
        )
    };
    let c = &config.loads;
    let scores: Vec<String> = c
        .scores
        .iter()
        .map(|score| match score {
            Some(s) => format!(
                "Some(LoadScore {{ scene: LoadScene {{ mass_g: {}, frequency_ratio: {} }}, noise_floor_g: {}, prediction: {} }})",
                f(s.scene.mass_g),
                f(s.scene.frequency_ratio),
                f(s.noise_floor_g),
                prediction(&s.prediction)
            ),
            None => "None".into(),
        })
        .collect();
    let loads = format!(
        "LoadCoverage {{\n        min_g: {},\n        max_g: {},\n        loads: {},\n        platform_mass_g: {},\n        scores: [\n            {},\n        ],\n    }}",
        f(c.min_g),
        f(c.max_g),
        c.loads,
        match c.platform_mass_g {
            Some(m) => format!("Some({})", f(m)),
            None => "None".into(),
        },
        scores.join(",\n            ")
    );
    let m = &config.model;
    let p = &config.prediction;
    format!(
        "pub const WEIGHING: WeighingConfig = WeighingConfig {{\n    method: {method},\n    counts_per_gram: {},\n    zero_counts: {},\n    noise_variance_counts2: {},\n    raw_noise_variance_counts2: {},\n    onset: OnsetConfig {{ min_empty_samples: {}, drift_sigma: {}, threshold_sigma: {}, guard_samples: {}, min_step_sigma: {}, min_noise_rms: {}, rail_low: {}, rail_high: {} }},\n    detection_lag_samples: {},\n    model: LoadCellModel {{ natural_frequency_hz: {}, damping_ratio: {}, filter_order: {}, filter_cutoff_hz: {}, counts_per_gram: {}, sample_rate_hz: {} }},\n    identified_counts_per_gram: {},\n    calibration_mass_g: {},\n    readout_s: {},\n    target_relative: {},\n    prediction: Prediction {{ runs: {}, planned_runs: {}, valid_runs: {}, within_target_runs: {}, detection_failures: {}, bias_g: {}, rms_g: {}, p95_g: {}, p95_upper_g: {} }},\n    recorded_drops: {},\n    recorded_worst_error_g: {},\n    loads: {loads},\n}};\n",
        f(config.counts_per_gram),
        f(config.zero_counts),
        f(config.noise_variance_counts2),
        f(config.raw_noise_variance_counts2),
        config.onset.min_empty_samples,
        f(config.onset.drift_sigma),
        f(config.onset.threshold_sigma),
        config.onset.guard_samples,
        f(config.onset.min_step_sigma),
        f(config.onset.min_noise_rms),
        f(config.onset.rail_low),
        f(config.onset.rail_high),
        f(config.detection_lag_samples),
        f(m.natural_frequency_hz),
        f(m.damping_ratio),
        m.filter_order,
        f(m.filter_cutoff_hz),
        f(m.counts_per_gram),
        f(m.sample_rate_hz),
        f(config.identified_counts_per_gram),
        f(config.calibration_mass_g),
        f(config.readout_s),
        f(config.target_relative),
        p.runs,
        p.planned_runs,
        p.valid_runs,
        p.within_target_runs,
        p.detection_failures,
        f(p.bias_g),
        f(p.rms_g),
        f(p.p95_g),
        f(p.p95_upper_g),
        config.recorded_drops,
        f(config.recorded_worst_error_g),
    )
}

/// Write `text` to `path`, creating its directory.
pub fn write_file(path: &Path, text: &str) -> Result<()> {
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
    }
    let mut file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    file.write_all(text.as_bytes())?;
    Ok(())
}
