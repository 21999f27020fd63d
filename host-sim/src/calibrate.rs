//! `host-sim calibrate`: recorded drops (CSVs as [`crate::recording`] reads them) in, a
//! weighing configuration out, through the core's [`estimator_core::tuning::tune`] (the same
//! call the firmware can make); and [`configured_estimator`], which builds a
//! configured method exactly as the firmware does ([`WeighingEstimator`]). The file itself
//! ([`to_toml`] writes it, [`load_config`] reads it back into the core's [`WeighingConfig`],
//! [`rust_const`] prints it as the firmware's constant) lives in `weighing_file`.
//!
//! What this module must never do: choose anything itself (the choice is the core's), or
//! write a configuration the core did not return.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use estimator_core::sensor::IdentifyError;
use estimator_core::tuning::{
    self, CandidateGrid, CandidateScore, DropError, RunSlot, Tuned, TuningError, TuningSettings,
};
use estimator_core::weighing::{
    LoadScene, LoadScore, Prediction, WeighingConfig, WeighingEstimator, WeighingMethod,
};
use estimator_core::Real;

use crate::method::{BoxedEstimator, InF32, Method};
use crate::montecarlo::{Precision, Setup, CAPACITY};
use crate::recording::{self, Layout};
use crate::sensor::STATES;

// The weighing configuration file: written here, read by `estimate --config` and the
// firmware's build.
pub use crate::weighing_file::{
    config_toml, firmware_constants, load_config, parse_config, rust_const, to_toml, FORMAT,
    FORMAT_CALIBRATION_MASS_ONLY,
};

/// The most candidates a configured bank has on the host (the core's bank is a const
/// generic, and holds any size up to it): room for
/// [`estimator_core::weighing::BankCandidate::CALIBRATED_U`]'s 65; calibration's bank,
/// [`estimator_core::weighing::BankCandidate::REFERENCE`], has 33.
pub const BANK_CANDIDATES: usize = 65;

/// What `host-sim calibrate` is asked to do.
#[derive(Clone, Debug)]
pub struct Options {
    /// The recorded drops.
    pub drops: Vec<PathBuf>,
    /// Where the drops' samples are (every drop alike).
    pub layout: Layout,
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
    /// Also score least squares with forgetting (λ < 1). Off by default: its readings
    /// state no uncertainty, so a board running it never shows a reading final.
    pub forgetting: bool,
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
    /// Drops of `mass_g` (a column `y` under a header) on the reference chain: 100 ms, 0.1%, 4 kHz, 100 Hz, 16 bits, 400
    /// runs, seed 1, f32, orders up to 8.
    pub fn new(drops: Vec<PathBuf>, mass_g: f64) -> Self {
        Self {
            drops,
            layout: Layout::default(),
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
            forgetting: false,
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

/// The samples of a recorded drop laid out as `layout`. Calibration needs every sample: an
/// empty or non-numeric cell is an error naming the line.
pub fn read_drop(path: &Path, layout: &Layout) -> Result<Vec<f64>> {
    Ok(recording::read(path, layout)?.every_sample()?)
}

/// The candidates calibration scores: the core's standard grid up to `max_order`, least
/// squares with forgetting only with [`Options::forgetting`]. A reading with λ < 1 states
/// no uncertainty (the core's `u` covers the growing window only), so it is never final:
/// a QEMU board uploaded with `step:n=5,D=16,lambda=0.923`, which calibration had chosen
/// from three of its recorded drops, showed no final reading on any drop.
pub fn grid(options: &Options) -> CandidateGrid<'static> {
    let standard = CandidateGrid::standard(options.readout_s);
    CandidateGrid {
        max_order: options.max_order,
        forgetting_memory_s: standard.forgetting_memory_s.filter(|_| options.forgetting),
        ..standard
    }
}

/// Calibrate on drops already in memory (raw codes), `names` naming them in errors.
pub fn calibrate_samples(
    drops: &[Vec<f64>],
    names: &[String],
    options: &Options,
    mut progress: impl FnMut(&CandidateScore),
) -> Result<Outcome> {
    let settings = options.settings();
    let grid = grid(options);
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
        .map(|p| read_drop(p, &options.layout))
        .collect::<Result<Vec<_>>>()?;
    let names: Vec<String> = options
        .drops
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    calibrate_samples(&drops, &names, options, progress)
}

/// A percentage with enough digits for the targets in use.
pub(crate) fn percent(relative: f64) -> String {
    format!("{:.4}%", relative * 100.0)
}

/// A scene in words: `50 g at 1.23x f_n`.
pub fn scene_name(scene: &LoadScene) -> String {
    format!("{:.4} g at {:.3}x f_n", scene.mass_g, scene.frequency_ratio)
}

/// Why a candidate is never chosen whatever it scores, in words: outside the valid region,
/// or no `u` on a board.
fn passed_over(score: &CandidateScore) -> Option<String> {
    match (&score.outside_region, score.states_no_uncertainty) {
        (Some(region), _) => Some(format!("outside the valid region: {region}")),
        (None, true) => {
            Some("states no u on a board, so its scale never shows a reading stable".to_string())
        }
        (None, false) => None,
    }
}

/// One line per scored candidate, for the log.
pub fn score_line(score: &CandidateScore, mass_g: f64, target_relative: f64) -> String {
    let p = &score.prediction;
    let scored = score.loads.iter().flatten().count();
    let verdict = if score.meets {
        format!("MEETS at all {scored} loads")
    } else if let (Some(why), None, Some(check)) =
        (passed_over(score), &score.failed_load, &score.recorded)
    {
        if check.failing == 0 {
            format!("met the target, but {why}")
        } else {
            format!(
                "recorded drop {} outside ({:+.4} g); {why}",
                check.worst_drop, check.errors_g[check.worst_drop as usize]
            )
        }
    } else if let Some(failed) = &score.failed_load {
        let f = &failed.prediction;
        if failed.scene.mass_g == mass_g && failed.scene.frequency_ratio == 1.0 {
            if f.runs < f.planned_runs {
                cannot_meet(f)
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
        cannot_meet(p)
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

/// A candidate whose Monte Carlo stopped early: enough runs missed the target that it cannot
/// meet it.
fn cannot_meet(p: &Prediction) -> String {
    format!(
        "no ({} of {} runs outside the target: cannot meet it)",
        p.runs - p.within_target_runs,
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
            let what = describe_drop_error(error, options.adc_bits);
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
        } => describe_none_meets_target(
            best,
            prediction,
            failed_load,
            recorded_failing,
            *evaluated,
            options,
        ),
    }
}

/// Why the core refused a drop, in words.
fn describe_drop_error(error: &DropError, adc_bits: u32) -> String {
    match error {
        DropError::TooShort { samples, needed } => format!(
            "too short: {samples} samples, {needed} needed (the empty stretch, the onset and the readout after it)"
        ),
        DropError::NonFinite { sample } => {
            format!("sample {sample} is not a finite number")
        }
        DropError::Saturated { sample } => format!(
            "sample {sample} is at a rail of the {}-bit converter (saturated)",
            adc_bits
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
    }
}

/// The best candidate, and where it missed the target, when none meets it.
fn describe_none_meets_target(
    best: &WeighingMethod,
    prediction: &Prediction,
    failed_load: &Option<LoadScore>,
    recorded_failing: &Option<u32>,
    evaluated: usize,
    options: &Options,
) -> String {
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
            interpolation,
            whitening,
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
            interpolation,
            whitening,
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
    checked_configured_estimator(config, precision, zero_counts, None)
}

/// [`configured_estimator`] checking its fit against the noise variance `noise` (raw units²
/// at the method's D, known exactly): a fit whose residuals exceed what that noise explains
/// is flagged `invalid_model_mismatch` (the consistency check; a bank of three or more
/// candidates does not flag). `None`: no check.
pub fn checked_configured_estimator(
    config: &WeighingConfig,
    precision: Precision,
    zero_counts: f64,
    noise: Option<f64>,
) -> Result<BoxedEstimator> {
    use estimator_core::{Estimator, NoiseReference};
    let named =
        |e: estimator_core::ConfigError| anyhow!("configured method {}: {e}", config.method);
    Ok(match precision {
        Precision::F64 => {
            let mut estimator = WeighingEstimator::<f64, CAPACITY, STATES, BANK_CANDIDATES>::new(
                config,
                zero_counts,
            )
            .map_err(named)?;
            estimator
                .set_noise_reference(noise.map(|variance| NoiseReference::new(variance, 0)))
                .map_err(named)?;
            estimator.reset();
            Box::new(estimator)
        }
        Precision::F32 => {
            let mut estimator = WeighingEstimator::<f32, CAPACITY, STATES, BANK_CANDIDATES>::new(
                config,
                zero_counts,
            )
            .map_err(named)?;
            estimator
                .set_noise_reference(noise.map(|variance| NoiseReference::new(variance as f32, 0)))
                .map_err(named)?;
            estimator.reset();
            Box::new(InF32(Box::new(estimator)))
        }
    })
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
