//! Issue 5, item 8: the stability map of every estimator. Where each method works, and
//! whether, outside that region, the core *flags* the reading (`Invalid(reason)`) or gives a
//! *silent* wrong number.
//!
//! The full Cartesian product (SNR × order × precision × noise × off-calibration × run length)
//! would be ~10⁵ cells; the map runs four slices, each answering one question:
//!
//! - **A, order × SNR**: 10–80 dB × orders 1–40, white noise, f32 and f64, for every
//!   estimator where an order applies: `step` at the firmware's D = 16 and at D = 1,
//!   `covariance`, `iv` and `bc` at D = 16, on the reference scene.
//! - **B, noise type × SNR**: white, vibration near the resonance, 50 Hz mains, every method
//!   at its default configuration (incl. the model bank, the baselines and the ramp).
//! - **C, off-calibration**: the load, and with it the resonance, moved 0.67–1.5× the one at
//!   the 200 g calibration, physically (through the moving mass), for the model-based methods
//!   and, to confirm they do not care, the data-driven ones.
//! - **D, long runs**: up to 10⁷ samples of a steady load at 50 dB with λ = 1, 0.9999, 0.999
//!   (at the decimated rate), f32 and f64, one run per cell.
//!
//! Every Monte Carlo cell is classified at two readouts (100 ms and the end of the 1.5 s
//! window) by what its runs did there ([`Class`]): ok; not yet determined; refused (most runs
//! flagged); over 10× the Cramér–Rao bound; lost positive definiteness (an oracle outside the
//! core: a Cholesky factorisation of the covariance form's Ψ, or a non-positive weight of the
//! factored form); non-finite; diverged (a valid reading 10× the load away). A failure is
//! *silent* when a run failing it still carried a valid reading.
//!
//! What this module must never do: compute an estimate itself (every reading comes from the
//! core), judge a method on runs or seeds its rivals did not get (one record per run feeds
//! every method of a slice), or report a cell as valid on the strength of its flagged runs.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use estimator_core::sensor::AdcSource;
use estimator_core::{
    CovarianceStepEstimator, Estimator, InvalidReason, Reading, State, StepEstimator,
};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use rayon::prelude::*;

use crate::chart;
use crate::crlb;
use crate::estimate::state_name;
use crate::method::{ranged, referenced, step_config, BoxedEstimator, BuildContext, Method};
use crate::montecarlo::{self, tare_record, Precision, CAPACITY};
use crate::scene::Scene;
use crate::simulated::{run_seed, LoadEvent, Script};

/// SNRs of slices A and B, dB (thesis eq. 4.39).
pub const SNRS_DB: [f64; 8] = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0];
/// Orders of slice A.
pub const ORDERS: [usize; 15] = [1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 16, 20, 25, 30, 40];
/// The firmware's block length (firmware/README.md: n = 7, D = 16).
pub const FIRMWARE_DECIMATION: u16 = 16;
/// The readouts of the Monte Carlo slices, s: the firmware's readout, and the end of the
/// window (the last sample of 1.5 s).
pub const READOUTS_S: [f64; 2] = [0.1, 1.5];
/// A cell whose valid readings' RMS exceeds this many CRLBs fails.
pub const BOUND_FACTOR: f64 = 10.0;
/// A valid reading further than this many loads from the truth has diverged.
pub const DIVERGED_FACTOR: f64 = 10.0;
/// The goal: f32 RMS within this fraction of the f64 RMS in the valid region.
pub const F32_TOLERANCE: f64 = 0.10;
/// Resonance over the one at the 200 g calibration, slice C: 0.7–1.3 is the model bank's
/// span; 0.67 is the cell's 600 g capacity, 1.4 and 1.5 lie beyond the span (44 g, 22 g).
pub const RESONANCE_RATIOS: [f64; 10] = [0.67, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5];
/// The calibration mass of the model-based methods, g.
pub const CALIBRATION_G: f64 = 200.0;
/// White-noise levels of slice C, given as the SNR they have on the reference scene (the noise
/// is physical: it does not change with the load), dB.
pub const OFF_CALIBRATION_SNRS_DB: [f64; 2] = [50.0, 70.0];
/// Forgetting factors of slice D, at the decimated rate.
pub const LONG_FORGETTING: [f64; 3] = [1.0, 0.9999, 0.999];
/// Block lengths of slice D.
pub const LONG_DECIMATIONS: [u16; 2] = [1, 16];
/// The default length of the long runs, samples (2,500 s at 4 kHz).
pub const LONG_SAMPLES: usize = 10_000_000;
/// The steady load of slice D, g.
pub const LONG_LOAD_G: f64 = 138.32;

/// What kind of noise a cell has besides the white noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Noise {
    /// White noise only (and the amplifier's own, and quantisation, as everywhere).
    White,
    /// Plus a narrow-band force at 24 Hz, 1 Hz wide, near the loaded resonance (25 Hz), with
    /// the same RMS at the output as the white noise.
    Vibration,
    /// Plus 50 Hz mains pickup with the same RMS as the white noise.
    Mains,
}

impl Noise {
    /// Name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Noise::White => "white",
            Noise::Vibration => "vibration",
            Noise::Mains => "mains",
        }
    }
}

/// Which of the four questions a cell answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slice {
    /// A: order × SNR.
    OrderSnr,
    /// B: noise type × SNR.
    NoiseType,
    /// C: off-calibration.
    OffCalibration,
}

impl Slice {
    /// Name in tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Slice::OrderSnr => "order_snr",
            Slice::NoiseType => "noise_type",
            Slice::OffCalibration => "off_calibration",
        }
    }
}

/// One method in the map.
#[derive(Clone, Debug)]
pub struct Probe {
    /// The panel or row it belongs to (e.g. `step D=16`, `model bank`).
    pub family: String,
    /// The method.
    pub method: Method,
    /// Its order, where one applies (slice A's x axis).
    pub order: Option<usize>,
    /// For an f32 probe, the index of the same method in f64.
    pub twin: Option<usize>,
}

fn parse(spec: &str) -> Method {
    spec.parse()
        .unwrap_or_else(|e| panic!("the map's own spec `{spec}` parses: {e}"))
}

fn in_f32(spec: &str) -> String {
    if spec.contains(':') {
        format!("{spec},precision=f32")
    } else {
        format!("{spec}:precision=f32")
    }
}

/// Push `spec` in f64 and in f32 (the f32 one knowing its twin).
fn push_pair(probes: &mut Vec<Probe>, family: &str, spec: &str, order: Option<usize>) {
    let twin = probes.len();
    probes.push(Probe {
        family: family.to_string(),
        method: parse(spec),
        order,
        twin: None,
    });
    probes.push(Probe {
        family: family.to_string(),
        method: parse(&in_f32(spec)),
        order,
        twin: Some(twin),
    });
}

/// Slice A's probes: every family where an order applies, at every order, f64 and f32.
pub fn order_probes(orders: &[usize]) -> Vec<Probe> {
    let d = FIRMWARE_DECIMATION;
    let families: [(String, String); 5] = [
        (format!("step D={d}"), format!("step:D={d}")),
        ("step D=1".into(), "step:D=1".into()),
        (format!("covariance D={d}"), format!("covariance:D={d}")),
        (format!("iv D={d}"), format!("iv:D={d}")),
        (format!("bc D={d}"), format!("bc:D={d}")),
    ];
    let mut probes = Vec::new();
    for (family, base) in &families {
        for &order in orders {
            push_pair(
                &mut probes,
                family,
                &format!("{base},n={order}"),
                Some(order),
            );
        }
    }
    probes
}

/// Slices B and C: every method at its default configuration (the speed study's), f64 and
/// f32.
pub fn default_probes() -> Vec<Probe> {
    let mut probes = Vec::new();
    for (family, spec) in [
        ("step n=7 D=16 (firmware)", "step:n=7,D=16"),
        ("step n=7 D=1 (thesis)", "step:n=7,D=1"),
        ("covariance n=7 D=16", "covariance:n=7,D=16"),
        ("iv n=7 D=16", "iv:n=7,D=16"),
        ("bc n=7 D=16", "bc:n=7,D=16"),
        ("ramp n=5 D=16", "ramp:n=5,D=16"),
        ("model bank (K=33, ±30%)", "model"),
        ("model at calibration (K=1)", "model:K=1,span=0.5-2"),
        ("settled average", "settled"),
        ("moving average", "moving"),
    ] {
        push_pair(&mut probes, family, spec, None);
    }
    probes
}

/// One condition of a Monte Carlo slice: a scene and where it sits on the slice's axes.
#[derive(Clone, Debug)]
pub struct Condition {
    /// The slice.
    pub slice: Slice,
    /// The extra noise.
    pub noise: Noise,
    /// SNR of the white noise, dB (slice C: on the reference scene).
    pub snr_db: f64,
    /// Resonance with the load over the one at the calibration mass.
    pub resonance_ratio: f64,
    /// The step, g.
    pub truth_g: f64,
    /// The scene simulated.
    pub scene: Scene,
    /// The CRLB at each readout, g.
    pub crlb_g: [f64; 2],
}

/// The reference scene at `snr_db` with `noise` added at the same RMS as the white noise.
/// `vibration_gain` is the output RMS per unit of force RMS ([`vibration_gain`]).
pub fn noisy_scene(base: &Scene, snr_db: f64, noise: Noise, vibration_gain: f64) -> Scene {
    let mut scene = base.with_snr_db(snr_db);
    let sigma = scene.disturbances.white_noise_g;
    match noise {
        Noise::White => {}
        Noise::Vibration => {
            scene.disturbances.vibration_rms_g = sigma / vibration_gain;
            scene.disturbances.vibration_hz = 24.0;
            scene.disturbances.vibration_bandwidth_hz = 1.0;
        }
        Noise::Mains => {
            scene.disturbances.mains_amplitude_g = sigma * std::f64::consts::SQRT_2;
            scene.disturbances.mains_hz = 50.0;
        }
    }
    scene
}

/// The RMS of the vibration at the output per gram of force RMS, over the 1.5 s window after
/// the reference drop (the response to the disturbance alone: the same seed with and
/// without it, the system being linear), averaged over 16 seeds.
pub fn vibration_gain(base: &Scene) -> f64 {
    let mut quiet = base.clone();
    quiet.disturbances = crate::simulated::Disturbances::none();
    let mut shaken = quiet.clone();
    shaken.disturbances.vibration_rms_g = 1.0;
    shaken.disturbances.vibration_hz = 24.0;
    shaken.disturbances.vibration_bandwidth_hz = 1.0;
    let samples = base.studied_window();
    let gain = base.chain.counts_per_gram();
    let (mut energy, mut count) = (0.0, 0.0);
    for seed in 0..16 {
        let mut a = quiet.adc(seed);
        let mut b = shaken.adc(seed);
        for _ in 0..samples {
            let difference = (b.read_analog() - a.read_analog()) / gain;
            energy += difference * difference;
            count += 1.0;
        }
    }
    (energy / count).sqrt()
}

/// The known-model CRLB of `scene`'s first step at the readouts, g: white noise (here the
/// scene's white noise plus `extra_variance_g2`, the disturbance's power treated as white),
/// quantisation and the amplifier's coloured noise, as `montecarlo` computes it.
fn crlb_at_readouts(scene: &Scene, extra_variance_g2: f64, readouts: [usize; 2]) -> [f64; 2] {
    let mut judged = scene.clone();
    let white = scene.disturbances.white_noise_g;
    judged.disturbances.white_noise_g = (white * white + extra_variance_g2).sqrt();
    judged.disturbances.vibration_rms_g = 0.0;
    judged.disturbances.mains_amplitude_g = 0.0;
    let (_, truth_g, _) = judged.studied_step();
    let samples = readouts[1] + 1;
    let bound = montecarlo::crlb_g2(&judged, truth_g, samples);
    readouts.map(|k| bound[k].sqrt())
}

/// The readout sample indices of a window of `samples`: the one `study speed` calls 100 ms
/// (round(t·rate)) and the last.
pub fn readout_indices(scene: &Scene) -> [usize; 2] {
    let samples = scene.studied_window();
    let first = (READOUTS_S[0] * scene.chain.sample_rate_hz).round() as usize;
    [first.min(samples - 1), samples - 1]
}

/// The conditions of slice A (`snrs_db`, white noise).
pub fn order_conditions(base: &Scene, snrs_db: &[f64]) -> Vec<Condition> {
    let readouts = readout_indices(base);
    snrs_db
        .iter()
        .map(|&snr_db| {
            let scene = base.with_snr_db(snr_db);
            Condition {
                slice: Slice::OrderSnr,
                noise: Noise::White,
                snr_db,
                resonance_ratio: resonance_ratio(&scene, scene.studied_step().1),
                truth_g: scene.studied_step().1,
                crlb_g: crlb_at_readouts(&scene, 0.0, readouts),
                scene,
            }
        })
        .collect()
}

/// The conditions of slice B: every noise type at every SNR.
pub fn noise_conditions(base: &Scene, snrs_db: &[f64]) -> Vec<Condition> {
    let readouts = readout_indices(base);
    let gain = vibration_gain(base);
    let mut conditions = Vec::new();
    for noise in [Noise::White, Noise::Vibration, Noise::Mains] {
        for &snr_db in snrs_db {
            let scene = noisy_scene(base, snr_db, noise, gain);
            let white = scene.disturbances.white_noise_g;
            // Judged against the white-noise bound at the same total noise power.
            let extra = if noise == Noise::White {
                0.0
            } else {
                white * white
            };
            conditions.push(Condition {
                slice: Slice::NoiseType,
                noise,
                snr_db,
                resonance_ratio: resonance_ratio(&scene, scene.studied_step().1),
                truth_g: scene.studied_step().1,
                crlb_g: crlb_at_readouts(&scene, extra, readouts),
                scene,
            });
        }
    }
    conditions
}

/// The resonance with `mass_g` over the one at the calibration mass.
pub fn resonance_ratio(scene: &Scene, mass_g: f64) -> f64 {
    let cell = &scene.chain.cell;
    cell.natural_frequency_rad_s(mass_g) / cell.natural_frequency_rad_s(CALIBRATION_G)
}

/// The load whose resonance is `ratio` times the one at the calibration mass:
/// ω ∝ 1/√(m_platform + M).
pub fn mass_for_ratio(scene: &Scene, ratio: f64) -> f64 {
    let platform_kg = scene.chain.cell.platform_mass_kg;
    ((platform_kg + CALIBRATION_G * 1e-3) / (ratio * ratio) - platform_kg) * 1e3
}

/// The conditions of slice C: the reference scene with the step moved to the mass of each
/// resonance ratio, the white noise held at the level `snr_db` gives on the reference scene.
pub fn off_calibration_conditions(base: &Scene, snrs_db: &[f64]) -> Result<Vec<Condition>> {
    let readouts = readout_indices(base);
    let mut conditions = Vec::new();
    for &snr_db in snrs_db {
        let reference = base.with_snr_db(snr_db);
        for &ratio in &RESONANCE_RATIOS {
            let mass_g = mass_for_ratio(base, ratio);
            let mut scene = reference.clone();
            let mut script = Script::new(base.script.end_s());
            script
                .push(LoadEvent::step(0.0, mass_g))
                .map_err(|e| anyhow!("slice C: {mass_g} g: {e:?}"))?;
            scene.script = script;
            conditions.push(Condition {
                slice: Slice::OffCalibration,
                noise: Noise::White,
                snr_db,
                resonance_ratio: ratio,
                truth_g: mass_g,
                crlb_g: crlb_at_readouts(&scene, 0.0, readouts),
                scene,
            });
        }
    }
    Ok(conditions)
}

// ---------------------------------------------------------------------------------------
// Running one method on one record, with the oracle.

/// An estimator under test, with what the oracle needs to see of its state.
enum Tracked {
    Step64(Box<StepEstimator<f64, CAPACITY>>),
    Step32(Box<StepEstimator<f32, CAPACITY>>),
    Covariance64(
        Box<CovarianceStepEstimator<f64, CAPACITY, { CAPACITY + 1 }>>,
        usize,
    ),
    Covariance32(
        Box<CovarianceStepEstimator<f32, CAPACITY, { CAPACITY + 1 }>>,
        usize,
    ),
    Other(BoxedEstimator),
}

fn widen(reading: Reading<f32>) -> Reading<f64> {
    Reading {
        estimate: reading.estimate.map(f64::from),
        samples: reading.samples,
        state: reading.state,
        residual: reading.residual.map(f64::from),
    }
}

/// Cholesky of the leading `size × size` block in f64: true when every pivot is positive.
fn cholesky_positive<T: Copy + Into<f64>, const P: usize>(
    matrix: &[[T; P]; P],
    size: usize,
) -> bool {
    let mut l = [[0.0f64; P]; P];
    for i in 0..size {
        for j in 0..=i {
            let mut sum: f64 = matrix[i][j].into();
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(sum > 0.0) || !sum.is_finite() {
                    return false;
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    true
}

impl Tracked {
    fn new(method: &Method, context: &BuildContext) -> Result<Self> {
        let named = |e: estimator_core::ConfigError| anyhow!("method `{method}`: {e}");
        Ok(match method {
            Method::Step(setup) => match setup.precision {
                Precision::F64 => Tracked::Step64(Box::new(
                    StepEstimator::new(referenced(
                        ranged(step_config(setup, context.gain), context),
                        context,
                    ))
                    .map_err(named)?,
                )),
                Precision::F32 => Tracked::Step32(Box::new(
                    StepEstimator::new(referenced(
                        ranged(step_config(setup, context.gain as f32), context),
                        context,
                    ))
                    .map_err(named)?,
                )),
            },
            Method::Covariance {
                setup,
                prior_information,
            } => match setup.precision {
                Precision::F64 => Tracked::Covariance64(
                    Box::new(
                        CovarianceStepEstimator::new(
                            referenced(ranged(step_config(setup, context.gain), context), context),
                            *prior_information,
                        )
                        .map_err(named)?,
                    ),
                    setup.order,
                ),
                Precision::F32 => Tracked::Covariance32(
                    Box::new(
                        CovarianceStepEstimator::new(
                            referenced(
                                ranged(step_config(setup, context.gain as f32), context),
                                context,
                            ),
                            *prior_information as f32,
                        )
                        .map_err(named)?,
                    ),
                    setup.order,
                ),
            },
            other => Tracked::Other(other.build(context)?),
        })
    }

    fn push(&mut self, sample: f64) -> Reading<f64> {
        match self {
            Tracked::Step64(e) => e.push(sample),
            Tracked::Step32(e) => widen(e.push(sample as f32)),
            Tracked::Covariance64(e, _) => e.push(sample),
            Tracked::Covariance32(e, _) => widen(e.push(sample as f32)),
            Tracked::Other(e) => e.push(sample),
        }
    }

    /// The oracle: is the state still positive definite? Ψ by Cholesky for the covariance
    /// form; the factored form's weight of the step column (positive by construction unless
    /// it underflowed or was corrupted) once it has been determined. Not applicable (true)
    /// to the others: their factor weights only grow, and `bc` refuses its own indefinite
    /// downdates (flagged).
    fn definite(&self, determined: bool) -> bool {
        match self {
            Tracked::Step64(e) => !determined || e.identifiability() > 0.0,
            Tracked::Step32(e) => !determined || e.identifiability() > 0.0,
            Tracked::Covariance64(e, order) => {
                cholesky_positive(e.inverse_information(), order + 1)
            }
            Tracked::Covariance32(e, order) => {
                cholesky_positive(e.inverse_information(), order + 1)
            }
            Tracked::Other(_) => true,
        }
    }
}

/// What a run's reading was at a readout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Not yet determined.
    WarmingUp,
    /// Flagged.
    Flagged(InvalidReason),
    /// Valid, with this error, g.
    Valid(f64),
}

/// One run of one method, seen at the readouts.
#[derive(Clone, Copy, Debug)]
pub struct RunOutcome {
    /// The reading at each readout.
    pub at: [Outcome; 2],
    /// The oracle saw the state lose positive definiteness by each readout.
    pub lost_definiteness_by: [bool; 2],
    /// A valid reading further than [`DIVERGED_FACTOR`] loads from the truth, from the first
    /// readout up to each readout.
    pub diverged_by: [bool; 2],
    /// A valid reading that was not finite, up to each readout.
    pub non_finite_by: [bool; 2],
}

/// The sample period the oracle is consulted at: every decimated update of a step or
/// covariance estimator.
fn oracle_period(method: &Method) -> usize {
    match method {
        Method::Step(setup) | Method::Covariance { setup, .. } => usize::from(setup.decimation),
        _ => usize::MAX,
    }
}

fn run_probe(
    method: &Method,
    context: &BuildContext,
    record: &[f64],
    truth_g: f64,
    readouts: [usize; 2],
) -> Result<RunOutcome> {
    let mut estimator = Tracked::new(method, context)?;
    let period = oracle_period(method);
    let mut outcome = RunOutcome {
        at: [Outcome::WarmingUp; 2],
        lost_definiteness_by: [false; 2],
        diverged_by: [false; 2],
        non_finite_by: [false; 2],
    };
    let (mut lost, mut diverged, mut non_finite, mut determined) = (false, false, false, false);
    for (k, &sample) in record.iter().enumerate().take(readouts[1] + 1) {
        let reading = estimator.push(sample);
        if let Some(estimate) = reading.estimate {
            determined = true;
            if !estimate.is_finite() {
                non_finite = true;
            } else if k >= readouts[0] && (estimate - truth_g).abs() > DIVERGED_FACTOR * truth_g {
                diverged = true;
            }
        }
        if period != usize::MAX && (k + 1) % period == 0 && !lost {
            lost = !estimator.definite(determined);
        }
        for (r, &index) in readouts.iter().enumerate() {
            if k == index {
                outcome.at[r] = match (reading.state, reading.estimate) {
                    (State::Invalid(reason), _) => Outcome::Flagged(reason),
                    (_, Some(estimate)) => Outcome::Valid(estimate - truth_g),
                    (_, None) => Outcome::WarmingUp,
                };
                outcome.lost_definiteness_by[r] = lost;
                outcome.diverged_by[r] = diverged;
                outcome.non_finite_by[r] = non_finite;
            }
        }
    }
    Ok(outcome)
}

// ---------------------------------------------------------------------------------------
// Cells and their classes.

/// Every reason the core flags, in a fixed order (for counts and columns).
pub const REASONS: [InvalidReason; 8] = [
    InvalidReason::NonFiniteInput,
    InvalidReason::OutOfRange,
    InvalidReason::IllConditioned,
    InvalidReason::NonFiniteUpdate,
    InvalidReason::MissingSample,
    InvalidReason::LostDefiniteness,
    InvalidReason::OutsideModelRange,
    InvalidReason::ModelMismatch,
];

fn reason_index(reason: InvalidReason) -> usize {
    // Exhaustive, so a new reason cannot be miscounted silently.
    match reason {
        InvalidReason::NonFiniteInput => 0,
        InvalidReason::OutOfRange => 1,
        InvalidReason::IllConditioned => 2,
        InvalidReason::NonFiniteUpdate => 3,
        InvalidReason::MissingSample => 4,
        InvalidReason::LostDefiniteness => 5,
        InvalidReason::OutsideModelRange => 6,
        InvalidReason::ModelMismatch => 7,
    }
}

/// What a cell's runs did at one readout.
#[derive(Clone, Debug, Default)]
pub struct Cell {
    /// Runs.
    pub runs: u32,
    /// Runs with a valid, finite reading.
    pub valid: u32,
    /// Runs not yet determined.
    pub warming: u32,
    /// Flagged runs, by reason ([`REASONS`]).
    pub flagged: [u32; REASONS.len()],
    /// Σ error² over the valid runs, g².
    pub sum_squared_g2: f64,
    /// Largest |error| of a valid run, g.
    pub max_error_g: f64,
    /// Runs that gave a non-finite valid reading by the readout.
    pub non_finite: u32,
    /// Runs that gave a valid reading 10 loads off between 100 ms and the readout.
    pub diverged: u32,
    /// Runs whose state lost positive definiteness by the readout.
    pub lost_definiteness: u32,
    /// Of those, runs with a valid reading at the readout (silent).
    pub lost_definiteness_valid: u32,
    /// f32 probes: Σ error² of this probe and of its f64 twin over the runs valid in both.
    pub paired_g2: (f64, f64),
    /// Runs valid in both.
    pub paired: u32,
    /// The CRLB at the readout, g.
    pub crlb_g: f64,
}

/// A cell's class at a readout (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Every run valid and the RMS within 10× the CRLB.
    Ok,
    /// Within 10× the CRLB on the valid runs; some runs flagged or not yet determined.
    OkPartly,
    /// No run determined yet.
    NotYet,
    /// Most runs flagged: the method refuses here (safe).
    Refused,
    /// The valid readings' RMS is above 10× the CRLB.
    OverBound,
    /// The state lost positive definiteness in some run.
    LostDefiniteness,
    /// A non-finite value: a valid reading (silent) or a latched `NonFiniteUpdate` (flagged).
    NonFinite,
    /// A valid reading 10 loads off.
    Diverged,
}

impl Class {
    /// Name in tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Class::Ok => "ok",
            Class::OkPartly => "ok_partly_flagged",
            Class::NotYet => "not_yet",
            Class::Refused => "refused",
            Class::OverBound => "over_10x_crlb",
            Class::LostDefiniteness => "lost_definiteness",
            Class::NonFinite => "non_finite",
            Class::Diverged => "diverged",
        }
    }

    /// Inside the valid region (the method works here, possibly refusing some runs).
    pub fn is_valid(self) -> bool {
        matches!(self, Class::Ok | Class::OkPartly)
    }
}

impl Cell {
    fn add(&mut self, outcome: &RunOutcome, r: usize, truth_g: f64) {
        let _ = truth_g;
        self.runs += 1;
        match outcome.at[r] {
            Outcome::WarmingUp => self.warming += 1,
            Outcome::Flagged(reason) => self.flagged[reason_index(reason)] += 1,
            Outcome::Valid(error) if error.is_finite() => {
                self.valid += 1;
                self.sum_squared_g2 += error * error;
                self.max_error_g = self.max_error_g.max(error.abs());
            }
            Outcome::Valid(_) => {}
        }
        self.non_finite += u32::from(outcome.non_finite_by[r]);
        self.diverged += u32::from(outcome.diverged_by[r]);
        if outcome.lost_definiteness_by[r] {
            self.lost_definiteness += 1;
            if matches!(outcome.at[r], Outcome::Valid(_)) {
                self.lost_definiteness_valid += 1;
            }
        }
    }

    /// Flagged runs, every reason.
    pub fn flagged_total(&self) -> u32 {
        self.flagged.iter().sum()
    }

    /// RMS error of the valid runs, g (NaN without).
    pub fn rms_g(&self) -> f64 {
        (self.sum_squared_g2 / f64::from(self.valid)).sqrt()
    }

    /// RMS over CRLB (NaN without valid runs).
    pub fn ratio(&self) -> f64 {
        self.rms_g() / self.crlb_g
    }

    /// f32 RMS over f64 RMS on the runs valid in both (f32 probes only).
    pub fn f32_over_f64(&self) -> Option<f64> {
        (self.paired > 0).then(|| (self.paired_g2.0 / self.paired_g2.1).sqrt())
    }

    /// The class, and whether a failure was silent (a run failing it gave a valid reading).
    pub fn class(&self) -> (Class, bool) {
        let non_finite_flagged = self.flagged[reason_index(InvalidReason::NonFiniteUpdate)];
        if self.non_finite > 0 {
            return (Class::NonFinite, true);
        }
        if self.diverged > 0 {
            return (Class::Diverged, true);
        }
        if self.lost_definiteness > 0 {
            return (Class::LostDefiniteness, self.lost_definiteness_valid > 0);
        }
        if non_finite_flagged > 0 {
            return (Class::NonFinite, false);
        }
        if self.valid == 0 {
            return if self.warming == self.runs {
                (Class::NotYet, false)
            } else {
                (Class::Refused, false)
            };
        }
        if self.ratio() > BOUND_FACTOR {
            return (Class::OverBound, true);
        }
        if 2 * self.flagged_total() > self.runs {
            return (Class::Refused, false);
        }
        if self.valid < self.runs {
            return (Class::OkPartly, false);
        }
        (Class::Ok, false)
    }

    /// A short text for tables: the RMS/CRLB ratio and a mark of the class.
    pub fn text(&self) -> String {
        let (class, silent) = self.class();
        let ratio = ratio_text(self.ratio());
        let share = |count: u32| format!("{:.0}%", 100.0 * f64::from(count) / f64::from(self.runs));
        match class {
            Class::Ok => ratio,
            Class::OkPartly => format!("{ratio} ({} valid)", share(self.valid)),
            Class::NotYet => "·".into(),
            Class::Refused => format!("F {}", share(self.flagged_total())),
            Class::OverBound => format!("**{ratio}** S"),
            Class::LostDefiniteness if silent => format!("**PD!** {ratio}"),
            Class::LostDefiniteness => "PD F".into(),
            Class::NonFinite if silent => "**NaN!**".into(),
            Class::NonFinite => "NaN F".into(),
            Class::Diverged => format!("**DIV!** {}", share(self.diverged)),
        }
    }
}

fn ratio_text(ratio: f64) -> String {
    if !ratio.is_finite() {
        "–".into()
    } else if ratio >= 1e4 {
        format!("{ratio:.0e}")
    } else if ratio >= 100.0 {
        format!("{ratio:.0}")
    } else if ratio >= 10.0 {
        format!("{ratio:.1}")
    } else {
        format!("{ratio:.2}")
    }
}

/// A Monte Carlo slice's results: `cells[condition][probe][readout]`.
pub struct SliceResult {
    /// The conditions.
    pub conditions: Vec<Condition>,
    /// The probes.
    pub probes: Vec<Probe>,
    /// The cells.
    pub cells: Vec<Vec<[Cell; 2]>>,
    /// Runs per cell.
    pub runs: usize,
}

/// Run a Monte Carlo slice: `runs` records per condition (seeded as `montecarlo` seeds them),
/// every probe on every record; parallel over (condition, run), accumulated in order.
pub fn run_slice(
    conditions: Vec<Condition>,
    probes: Vec<Probe>,
    runs: usize,
    seed: u64,
) -> Result<SliceResult> {
    // Every method with residuals checks them against its own tare (the consistency check,
    // `estimator_core`'s `InvalidReason::ModelMismatch`), metered at its own D.
    let needs_tare = probes
        .iter()
        .any(|p| p.method.reference_decimation().is_some());
    let contexts: Vec<BuildContext> = conditions
        .iter()
        .map(|c| BuildContext {
            noise_check: true,
            ..BuildContext::new(c.scene.chain, c.scene.chain.counts_per_gram())
                .with_adc_rails(c.scene.chain.zero_code())
        })
        .collect();
    // Refuse impossible methods before spending time (validated with a variance of 1).
    for probe in &probes {
        let context = BuildContext {
            tare_noise_variance: Some(1.0),
            ..contexts[0]
        };
        Tracked::new(&probe.method, &context)?;
    }
    let items: Vec<(usize, usize)> = (0..conditions.len())
        .flat_map(|c| (0..runs).map(move |run| (c, run)))
        .collect();
    let progress = montecarlo::progress_bar(items.len() as u64);
    let outcomes: Vec<Result<Vec<RunOutcome>>> = items
        .par_iter()
        .map(|&(c, run)| {
            let condition = &conditions[c];
            let scene = &condition.scene;
            let readouts = readout_indices(scene);
            let zero = scene.chain.zero_code();
            let mut adc = scene.adc(run_seed(seed, run as u64));
            let record: Vec<f64> = (0..=readouts[1])
                .map(|_| {
                    adc.read()
                        .map(|code| f64::from(code) - zero)
                        .unwrap_or(f64::NAN)
                })
                .collect();
            let tare = needs_tare.then(|| tare_record(scene, seed, run as u64));
            let result = probes
                .iter()
                .map(|probe| {
                    let context = match (probe.method.reference_decimation(), &tare) {
                        (Some(decimation), Some(tare)) => contexts[c].with_tare(tare, decimation),
                        _ => contexts[c],
                    };
                    run_probe(
                        &probe.method,
                        &context,
                        &record,
                        condition.truth_g,
                        readouts,
                    )
                })
                .collect();
            progress.inc(1);
            result
        })
        .collect();
    progress.finish_and_clear();
    let mut cells: Vec<Vec<[Cell; 2]>> = conditions
        .iter()
        .map(|c| {
            probes
                .iter()
                .map(|_| {
                    c.crlb_g.map(|crlb_g| Cell {
                        crlb_g,
                        ..Cell::default()
                    })
                })
                .collect()
        })
        .collect();
    for (&(c, _), outcome) in items.iter().zip(outcomes) {
        let outcome = outcome?;
        let truth_g = conditions[c].truth_g;
        for (p, probe) in probes.iter().enumerate() {
            for r in 0..2 {
                cells[c][p][r].add(&outcome[p], r, truth_g);
                if let Some(twin) = probe.twin {
                    if let (Outcome::Valid(mine), Outcome::Valid(theirs)) =
                        (outcome[p].at[r], outcome[twin].at[r])
                    {
                        if mine.is_finite() && theirs.is_finite() {
                            let cell = &mut cells[c][p][r];
                            cell.paired += 1;
                            cell.paired_g2.0 += mine * mine;
                            cell.paired_g2.1 += theirs * theirs;
                        }
                    }
                }
            }
        }
    }
    Ok(SliceResult {
        conditions,
        probes,
        cells,
        runs,
    })
}

// ---------------------------------------------------------------------------------------
// Slice D: long runs.

/// Bins per decade of the long runs' log-spaced statistics.
pub const BINS_PER_DECADE: usize = 10;
/// The long runs' statistics start at 10³ samples.
pub const FIRST_DECADE: u32 = 3;

/// Slice D's probes: step, covariance, iv and bc at n = 7, every block length and forgetting
/// factor, f64 and f32.
pub fn long_probes() -> Vec<Probe> {
    let mut probes = Vec::new();
    for decimation in LONG_DECIMATIONS {
        for lambda in LONG_FORGETTING {
            for family in ["step", "covariance", "iv", "bc"] {
                push_pair(
                    &mut probes,
                    &format!("{family} D={decimation} λ={lambda}"),
                    &format!("{family}:n=7,D={decimation},lambda={lambda}"),
                    Some(7),
                );
            }
        }
    }
    probes
}

/// Statistics of one log-spaced bin of a long run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Bin {
    /// Readings in the bin.
    pub readings: u64,
    /// Valid, finite readings.
    pub valid: u64,
    /// Flagged readings.
    pub flagged: u64,
    /// Σ (error / bound)² over the valid readings.
    pub sum_normalised: f64,
    /// Largest |error| of a valid reading, g.
    pub max_error_g: f64,
    /// Valid readings after the oracle saw positive definiteness lost.
    pub valid_after_loss: u64,
    /// Valid readings that were not finite.
    pub non_finite: u64,
    /// Valid readings 10 loads off.
    pub diverged: u64,
}

/// One long run of one method.
#[derive(Clone, Debug)]
pub struct LongRun {
    /// The probe.
    pub probe: Probe,
    /// Bins from 10³ samples on, [`BINS_PER_DECADE`] a decade.
    pub bins: Vec<Bin>,
    /// The first flag: sample count and reason.
    pub first_flag: Option<(usize, InvalidReason)>,
    /// The sample count at which the oracle first saw positive definiteness lost.
    pub lost_definiteness_at: Option<usize>,
    /// The state and error at the end.
    pub last: Outcome,
    /// The steady-state bound at the end, g.
    pub bound_end_g: f64,
    /// CPU seconds.
    pub cpu_s: f64,
}

fn bin_of(count: usize) -> Option<usize> {
    let position = (count as f64).log10() - f64::from(FIRST_DECADE);
    (position >= 0.0).then(|| (position * BINS_PER_DECADE as f64 + 1e-9).floor() as usize)
}

/// The noise floor of a steady load estimated with forgetting λ over `rows` decimated rows of
/// variance `block_variance_g2` each: the variance of the exponentially weighted mean,
/// `σ²_D·(1−λ)(1+λ^m)/((1+λ)(1−λ^m))` (→ σ²_D/m at λ = 1), g. A constant in white noise has
/// no better unbiased estimate from those weights; the data-driven estimators also fit `ℓ`.
pub fn steady_bound_g(block_variance_g2: f64, lambda: f64, rows: f64) -> f64 {
    if rows < 1.0 {
        return f64::NAN;
    }
    let factor = if lambda >= 1.0 {
        1.0 / rows
    } else {
        let power = lambda.powf(rows);
        (1.0 - lambda) * (1.0 + power) / ((1.0 + lambda) * (1.0 - power))
    };
    (block_variance_g2 * factor).sqrt()
}

fn run_long(
    probe: &Probe,
    context: &BuildContext,
    codes: &[u16],
    zero: f64,
    raw_variance_g2: f64,
) -> Result<LongRun> {
    let start = Instant::now();
    let (decimation, lambda) = match probe.method {
        Method::Step(s)
        | Method::Covariance { setup: s, .. }
        | Method::BiasCompensated { setup: s, .. } => (s.decimation, s.forgetting),
        Method::InstrumentalVariable { setup, .. } => (setup.decimation, setup.forgetting),
        _ => (1, 1.0),
    };
    let block_variance = raw_variance_g2 / f64::from(decimation);
    let mut estimator = Tracked::new(&probe.method, context)?;
    let period = match probe.method {
        Method::Step(_) | Method::Covariance { .. } => usize::from(decimation),
        _ => usize::MAX,
    };
    let bins_total = bin_of(codes.len()).unwrap_or(0) + 1;
    let mut bins = vec![Bin::default(); bins_total];
    let mut run = LongRun {
        probe: probe.clone(),
        bins: Vec::new(),
        first_flag: None,
        lost_definiteness_at: None,
        last: Outcome::WarmingUp,
        bound_end_g: f64::NAN,
        cpu_s: 0.0,
    };
    let mut determined = false;
    // The bound changes slowly: refresh it once per decimated row.
    let mut bound = f64::NAN;
    for (k, &code) in codes.iter().enumerate() {
        let count = k + 1;
        let reading = estimator.push(f64::from(code) - zero);
        if period != usize::MAX
            && count % period == 0
            && run.lost_definiteness_at.is_none()
            && !estimator.definite(determined)
        {
            run.lost_definiteness_at = Some(count);
        }
        if let (State::Invalid(reason), None) = (reading.state, run.first_flag) {
            run.first_flag = Some((count, reason));
        }
        if count % usize::from(decimation) == 0 {
            bound = steady_bound_g(
                block_variance,
                lambda,
                (count / usize::from(decimation)) as f64,
            );
        }
        determined |= reading.estimate.is_some();
        let Some(bin) = bin_of(count) else {
            continue;
        };
        let bin = &mut bins[bin];
        bin.readings += 1;
        match (reading.state, reading.estimate) {
            (State::Invalid(_), _) => bin.flagged += 1,
            (_, Some(estimate)) => {
                let error = estimate - LONG_LOAD_G;
                if !estimate.is_finite() {
                    bin.non_finite += 1;
                } else {
                    bin.valid += 1;
                    bin.sum_normalised += (error / bound) * (error / bound);
                    bin.max_error_g = bin.max_error_g.max(error.abs());
                    if error.abs() > DIVERGED_FACTOR * LONG_LOAD_G {
                        bin.diverged += 1;
                    }
                    if run.lost_definiteness_at.is_some() {
                        bin.valid_after_loss += 1;
                    }
                }
            }
            _ => {}
        }
        if count == codes.len() {
            run.last = match (reading.state, reading.estimate) {
                (State::Invalid(reason), _) => Outcome::Flagged(reason),
                (_, Some(estimate)) => Outcome::Valid(estimate - LONG_LOAD_G),
                (_, None) => Outcome::WarmingUp,
            };
            run.bound_end_g = bound;
        }
    }
    run.bins = bins;
    run.cpu_s = start.elapsed().as_secs_f64();
    Ok(run)
}

/// Slice D's results.
pub struct LongResult {
    /// One run per probe.
    pub runs: Vec<LongRun>,
    /// Samples per run.
    pub samples: usize,
    /// Raw-sample noise variance the bounds use, g².
    pub raw_variance_g2: f64,
}

/// Run slice D: one record of `samples` samples (the reference load at 50 dB, steady after
/// the drop), every long probe on it, in parallel over probes.
pub fn run_long_slice(base: &Scene, samples: usize, seed: u64) -> Result<LongResult> {
    let mut scene = base.with_snr_db(50.0);
    let mut script = Script::new(samples as f64 / scene.chain.sample_rate_hz);
    script
        .push(LoadEvent::step(0.0, LONG_LOAD_G))
        .map_err(|e| anyhow!("slice D: {e:?}"))?;
    scene.script = script;
    let mut adc = scene.adc(run_seed(seed, 0));
    // A 16-bit code fits; the record of 10⁷ samples takes 20 MB.
    let codes: Vec<u16> = (0..samples)
        .map(|_| {
            adc.read()
                .map(|c| c.min(u32::from(u16::MAX)) as u16)
                .unwrap_or(0)
        })
        .collect();
    let chain = scene.chain;
    let gain = chain.counts_per_gram();
    let lsb_g = 1.0 / gain;
    let white = scene.disturbances.white_noise_g;
    // The amplifier's noise at the filter output (lag 0); coloured, but 1/65 of the white.
    let amplifier_g2 = crlb::amplifier_autocovariance_g2(&chain, 1)[0];
    let raw_variance_g2 = white * white + lsb_g * lsb_g / 12.0 + amplifier_g2;
    let tare = tare_record(&scene, seed, 0);
    let probes = long_probes();
    let progress = montecarlo::progress_bar(probes.len() as u64);
    let runs: Vec<Result<LongRun>> = probes
        .par_iter()
        .map(|probe| {
            let base = BuildContext {
                noise_check: true,
                ..BuildContext::new(chain, gain).with_adc_rails(chain.zero_code())
            };
            let context = match probe.method.reference_decimation() {
                Some(decimation) => base.with_tare(&tare, decimation),
                None => base,
            };
            let run = run_long(probe, &context, &codes, chain.zero_code(), raw_variance_g2);
            progress.inc(1);
            run
        })
        .collect();
    progress.finish_and_clear();
    Ok(LongResult {
        runs: runs.into_iter().collect::<Result<_>>()?,
        samples,
        raw_variance_g2,
    })
}

impl LongRun {
    /// The decade `[10^j, 10^{j+1})` (the last one closed), aggregated; `None` beyond the run
    /// or when the run covers less than half of it.
    pub fn decade(&self, j: u32) -> Option<Bin> {
        if j < FIRST_DECADE
            || ((self.bins.len() as f64 - 1.0) / BINS_PER_DECADE as f64)
                < f64::from(j - FIRST_DECADE) + 0.5
        {
            return None;
        }
        let first = (j - FIRST_DECADE) as usize * BINS_PER_DECADE;
        let bins = self.bins.get(first..)?;
        if bins.is_empty() {
            return None;
        }
        let mut total = Bin::default();
        for bin in bins.iter().take(BINS_PER_DECADE + 1) {
            total.readings += bin.readings;
            total.valid += bin.valid;
            total.flagged += bin.flagged;
            total.sum_normalised += bin.sum_normalised;
            total.max_error_g = total.max_error_g.max(bin.max_error_g);
            total.valid_after_loss += bin.valid_after_loss;
            total.non_finite += bin.non_finite;
            total.diverged += bin.diverged;
        }
        Some(total)
    }
}

impl Bin {
    /// RMS of error / bound over the valid readings.
    pub fn normalised_rms(&self) -> f64 {
        (self.sum_normalised / self.valid as f64).sqrt()
    }

    /// The class of a long-run stretch, and whether a failure was silent.
    pub fn class(&self, lost_before_end: bool, non_finite_flagged: bool) -> (Class, bool) {
        if self.non_finite > 0 {
            return (Class::NonFinite, true);
        }
        if self.diverged > 0 {
            return (Class::Diverged, true);
        }
        if lost_before_end {
            return (Class::LostDefiniteness, self.valid_after_loss > 0);
        }
        if non_finite_flagged {
            return (Class::NonFinite, false);
        }
        if self.valid == 0 {
            return (Class::Refused, false);
        }
        if self.normalised_rms() > BOUND_FACTOR {
            return (Class::OverBound, true);
        }
        if 2 * self.flagged > self.readings {
            return (Class::Refused, false);
        }
        if self.flagged > 0 {
            return (Class::OkPartly, false);
        }
        (Class::Ok, false)
    }
}

// ---------------------------------------------------------------------------------------
// Reports.

fn condition_axes(condition: &Condition) -> String {
    format!(
        "{},{},{},{:.4},{:.3}",
        condition.slice.name(),
        condition.noise.name(),
        condition.snr_db,
        condition.resonance_ratio,
        condition.truth_g
    )
}

fn precision_name(method: &Method) -> &'static str {
    match method.precision() {
        Precision::F32 => "f32",
        Precision::F64 => "f64",
    }
}

/// Write every Monte Carlo cell: one line per slice, condition, probe and readout.
pub fn write_csv(slices: &[SliceResult], out: &mut impl Write) -> Result<()> {
    write!(
        out,
        "slice,noise,snr_db,resonance_ratio,mass_g,family,spec,precision,order,readout_s,runs,valid,warming,flagged"
    )?;
    for reason in REASONS {
        write!(out, ",flagged_{}", &state_name(State::Invalid(reason))[8..])?;
    }
    writeln!(
        out,
        ",rms_g,max_error_g,crlb_g,rms_over_crlb,non_finite,diverged,lost_definiteness,lost_definiteness_valid,class,silent,f32_over_f64"
    )?;
    for slice in slices {
        for (condition, cells) in slice.conditions.iter().zip(&slice.cells) {
            for (probe, pair) in slice.probes.iter().zip(cells) {
                for (r, cell) in pair.iter().enumerate() {
                    let (class, silent) = cell.class();
                    write!(
                        out,
                        "{},{},{},{},{},{},{},{},{},{}",
                        condition_axes(condition),
                        probe.family.replace(',', ";"),
                        probe.method.to_string().replace(',', " "),
                        precision_name(&probe.method),
                        probe.order.map(|n| n.to_string()).unwrap_or_default(),
                        READOUTS_S[r],
                        cell.runs,
                        cell.valid,
                        cell.warming,
                        cell.flagged_total(),
                    )?;
                    for count in cell.flagged {
                        write!(out, ",{count}")?;
                    }
                    writeln!(
                        out,
                        ",{:.6e},{:.6e},{:.6e},{:.4},{},{},{},{},{},{},{}",
                        cell.rms_g(),
                        cell.max_error_g,
                        cell.crlb_g,
                        cell.ratio(),
                        cell.non_finite,
                        cell.diverged,
                        cell.lost_definiteness,
                        cell.lost_definiteness_valid,
                        class.name(),
                        silent,
                        cell.f32_over_f64()
                            .map(|v| format!("{v:.5}"))
                            .unwrap_or_default()
                    )?;
                }
            }
        }
    }
    Ok(())
}

/// A cell's colour on the heat maps, by class and whether the failure was silent.
fn colour(class: Class, silent: bool) -> RGBColor {
    match (class, silent) {
        (Class::Ok, _) => RGBColor(44, 160, 44),
        (Class::OkPartly, _) => RGBColor(161, 217, 155),
        (Class::NotYet, _) => RGBColor(215, 215, 215),
        (Class::Refused, _) => RGBColor(158, 202, 225),
        (Class::OverBound, _) => RGBColor(253, 141, 60),
        (Class::LostDefiniteness | Class::NonFinite | Class::Diverged, false) => {
            RGBColor(49, 130, 189)
        }
        (_, true) => RGBColor(203, 24, 29),
    }
}

/// The legend of the heat maps: colour and meaning.
const LEGEND: [(Class, bool, &str); 8] = [
    (Class::Ok, false, "ok (≤ 10× CRLB, all runs valid)"),
    (Class::OkPartly, false, "ok, some runs flagged / not yet"),
    (Class::NotYet, false, "not yet determined"),
    (Class::Refused, false, "flagged: most runs refused"),
    (
        Class::LostDefiniteness,
        false,
        "flagged failure (lost PD, non-finite)",
    ),
    (Class::OverBound, true, "SILENT: > 10× CRLB"),
    (
        Class::Diverged,
        true,
        "SILENT: diverged / lost PD / non-finite",
    ),
    (Class::NotYet, false, ""),
];

/// One panel of a heat map: `cells[y][x]`.
pub struct Panel {
    /// Panel title.
    pub title: String,
    /// Column labels.
    pub x_labels: Vec<String>,
    /// Row labels, bottom up.
    pub y_labels: Vec<String>,
    /// x axis name.
    pub x_name: String,
    /// (class, silent, text) per cell.
    pub cells: Vec<Vec<(Class, bool, String)>>,
}

/// A grid of heat-map panels, written as SVG and PNG.
pub struct HeatMap {
    /// Figure title.
    pub title: String,
    /// Panels, row-major in a grid of `columns`.
    pub panels: Vec<Panel>,
    /// Panels per row.
    pub columns: usize,
    /// Pixels per panel (width, height).
    pub panel_size: (u32, u32),
    /// Width of the row-label area, px.
    pub label_width: u32,
}

impl HeatMap {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
        root.fill(&WHITE).map_err(error)?;
        let (width, height) = root.dim_in_pixel();
        let (top, rest) = root.split_vertically(40);
        top.draw(&Text::new(
            self.title.clone(),
            (10, 10),
            ("sans-serif", 20).into_font(),
        ))
        .map_err(error)?;
        let (body, legend) = rest.split_vertically(height - 40 - 36);
        let rows = self.panels.len().div_ceil(self.columns);
        let areas = body.split_evenly((rows, self.columns));
        for (panel, area) in self.panels.iter().zip(areas.iter()) {
            let nx = panel.x_labels.len() as i32;
            let ny = panel.y_labels.len() as i32;
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, ("sans-serif", 15))
                .margin(6)
                .x_label_area_size(38)
                .y_label_area_size(self.label_width)
                .build_cartesian_2d((0..nx).into_segmented(), (0..ny).into_segmented())
                .map_err(error)?;
            let x_labels = panel.x_labels.clone();
            let y_labels = panel.y_labels.clone();
            chart
                .configure_mesh()
                .disable_mesh()
                .x_labels(nx as usize + 1)
                .y_labels(ny as usize + 1)
                .x_desc(panel.x_name.as_str())
                .label_style(("sans-serif", 12))
                .x_label_formatter(&|v| match v {
                    SegmentValue::CenterOf(i) => {
                        x_labels.get(*i as usize).cloned().unwrap_or_default()
                    }
                    _ => String::new(),
                })
                .y_label_formatter(&|v| match v {
                    SegmentValue::CenterOf(i) => {
                        y_labels.get(*i as usize).cloned().unwrap_or_default()
                    }
                    _ => String::new(),
                })
                .draw()
                .map_err(error)?;
            for (j, row) in panel.cells.iter().enumerate() {
                for (i, (class, silent, text)) in row.iter().enumerate() {
                    let (i, j) = (i as i32, j as i32);
                    let fill = colour(*class, *silent);
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [
                                (SegmentValue::Exact(i), SegmentValue::Exact(j)),
                                (SegmentValue::Exact(i + 1), SegmentValue::Exact(j + 1)),
                            ],
                            fill.filled(),
                        )))
                        .map_err(error)?;
                    let ink = if *silent && *class != Class::OverBound {
                        WHITE
                    } else {
                        BLACK
                    };
                    let style = TextStyle::from(("sans-serif", 10).into_font())
                        .color(&ink)
                        .pos(Pos::new(HPos::Center, VPos::Center));
                    chart
                        .draw_series(std::iter::once(Text::new(
                            text.clone(),
                            (SegmentValue::CenterOf(i), SegmentValue::CenterOf(j)),
                            style,
                        )))
                        .map_err(error)?;
                }
            }
        }
        let mut x = 10i32;
        for (class, silent, text) in LEGEND.iter().filter(|l| !l.2.is_empty()) {
            legend
                .draw(&Rectangle::new(
                    [(x, 8), (x + 18, 26)],
                    colour(*class, *silent).filled(),
                ))
                .map_err(error)?;
            legend
                .draw(&Text::new(
                    text.to_string(),
                    (x + 24, 10),
                    ("sans-serif", 13).into_font(),
                ))
                .map_err(error)?;
            x += 24 + 8 * text.chars().count() as i32 + 24;
        }
        let _ = width;
        root.present().map_err(error)?;
        Ok(())
    }

    /// Write `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<()> {
        chart::register_font()?;
        let rows = self.panels.len().div_ceil(self.columns) as u32;
        let size = (
            self.panel_size.0 * self.columns as u32,
            self.panel_size.1 * rows + 40 + 36,
        );
        let svg = base.with_extension("svg");
        self.draw(&SVGBackend::new(&svg, size).into_drawing_area())?;
        let png = base.with_extension("png");
        self.draw(&BitMapBackend::new(&png, size).into_drawing_area())?;
        Ok(())
    }
}

fn cell_mark(cell: &Cell) -> (Class, bool, String) {
    let (class, silent) = cell.class();
    let text = match class {
        Class::NotYet => "·".into(),
        Class::Refused => "F".into(),
        Class::LostDefiniteness | Class::NonFinite if !silent => "F".into(),
        Class::Diverged => "DIV".into(),
        _ => compact(cell.ratio()),
    };
    (class, silent, text)
}

/// A ratio in at most four characters.
fn compact(ratio: f64) -> String {
    if !ratio.is_finite() {
        "–".into()
    } else if ratio >= 1000.0 {
        format!(
            "{:.0}e{}",
            ratio / 10f64.powi(ratio.log10().floor() as i32),
            ratio.log10().floor()
        )
    } else if ratio >= 10.0 {
        format!("{ratio:.0}")
    } else {
        format!("{ratio:.1}")
    }
}

/// Slice A's heat map at readout `r`: a panel per family and precision, SNR against order.
pub fn order_heat_map(slice: &SliceResult, r: usize) -> HeatMap {
    let mut families: Vec<String> = Vec::new();
    for probe in &slice.probes {
        if !families.contains(&probe.family) {
            families.push(probe.family.clone());
        }
    }
    let orders: Vec<usize> = {
        let mut o: Vec<usize> = slice.probes.iter().filter_map(|p| p.order).collect();
        o.dedup();
        o.sort_unstable();
        o.dedup();
        o
    };
    let mut panels = Vec::new();
    for precision in [Precision::F64, Precision::F32] {
        for family in &families {
            let cells = slice
                .conditions
                .iter()
                .enumerate()
                .map(|(c, _)| {
                    orders
                        .iter()
                        .map(|&order| {
                            slice
                                .probes
                                .iter()
                                .position(|p| {
                                    p.family == *family
                                        && p.order == Some(order)
                                        && p.method.precision() == precision
                                })
                                .map(|p| cell_mark(&slice.cells[c][p][r]))
                                .unwrap_or((Class::NotYet, false, String::new()))
                        })
                        .collect()
                })
                .collect();
            panels.push(Panel {
                title: format!(
                    "{family}, {}",
                    if precision == Precision::F32 {
                        "f32"
                    } else {
                        "f64"
                    }
                ),
                x_labels: orders.iter().map(|o| o.to_string()).collect(),
                y_labels: slice
                    .conditions
                    .iter()
                    .map(|c| format!("{} dB", c.snr_db))
                    .collect(),
                x_name: "order n".into(),
                cells,
            });
        }
    }
    HeatMap {
        title: format!(
            "Stability map A: RMS at {} over the CRLB, white noise, reference drop ({} runs a cell; cell text: RMS/CRLB)",
            readout_name(r),
            slice.runs
        ),
        columns: families.len(),
        panels,
        panel_size: (560, 330),
        label_width: 55,
    }
}

fn readout_name(r: usize) -> &'static str {
    if r == 0 {
        "100 ms"
    } else {
        "1.5 s"
    }
}

fn probe_label(probe: &Probe) -> String {
    format!(
        "{} {}",
        probe.family,
        if probe.method.precision() == Precision::F32 {
            "f32"
        } else {
            "f64"
        }
    )
}

/// Slices B and C: a panel per (readout, group of conditions), probes against the conditions.
pub fn probe_heat_map(
    slice: &SliceResult,
    title: &str,
    group: impl Fn(&Condition) -> String,
    x_label: impl Fn(&Condition) -> String,
    x_name: &str,
) -> HeatMap {
    let mut groups: Vec<String> = Vec::new();
    for condition in &slice.conditions {
        let g = group(condition);
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    let mut panels = Vec::new();
    for r in 0..2 {
        for g in &groups {
            let members: Vec<usize> = (0..slice.conditions.len())
                .filter(|&c| group(&slice.conditions[c]) == *g)
                .collect();
            let cells = (0..slice.probes.len())
                .rev()
                .map(|p| {
                    members
                        .iter()
                        .map(|&c| cell_mark(&slice.cells[c][p][r]))
                        .collect()
                })
                .collect();
            panels.push(Panel {
                title: format!("{g}, at {}", readout_name(r)),
                x_labels: members
                    .iter()
                    .map(|&c| x_label(&slice.conditions[c]))
                    .collect(),
                y_labels: slice.probes.iter().rev().map(probe_label).collect(),
                x_name: x_name.into(),
                cells,
            });
        }
    }
    HeatMap {
        title: format!("{title} ({} runs a cell; cell text: RMS/CRLB)", slice.runs),
        columns: groups.len(),
        panels,
        panel_size: (660, 560),
        label_width: 230,
    }
}

/// The long runs' chart for block length `decimation`: RMS of error over the steady-state
/// bound per log-spaced bin, step and covariance forms, f64 and f32.
pub fn long_chart(long: &LongResult, decimation: u16) -> chart::Chart {
    let mut series = Vec::new();
    for run in &long.runs {
        let (family, d, lambda) = match run.probe.method {
            Method::Step(s) => ("step", s.decimation, s.forgetting),
            Method::Covariance { setup, .. } => ("covariance", setup.decimation, setup.forgetting),
            _ => continue,
        };
        if d != decimation || lambda == 0.999 {
            continue;
        }
        let points = run
            .bins
            .iter()
            .enumerate()
            .filter(|(_, b)| b.valid > 0)
            .map(|(i, b)| {
                (
                    f64::from(FIRST_DECADE) + (i as f64 + 0.5) / BINS_PER_DECADE as f64,
                    b.normalised_rms(),
                )
            })
            .collect();
        series.push(chart::Series {
            name: format!(
                "{family} λ={lambda} {}{}",
                precision_name(&run.probe.method),
                match run.first_flag {
                    Some((at, InvalidReason::LostDefiniteness)) =>
                        format!(": flagged lost PD at {at}"),
                    _ => String::new(),
                }
            ),
            points,
            reference: false,
        });
    }
    let last = (long.samples as f64).log10();
    series.push(chart::Series {
        name: "10× the bound".into(),
        points: vec![(f64::from(FIRST_DECADE), 10.0), (last, 10.0)],
        reference: true,
    });
    chart::Chart {
        title: format!(
            "Stability map D: a steady 138.32 g at 50 dB, n = 7, D = {decimation}, one run of {:.0e} samples",
            long.samples as f64
        ),
        x_label: "log10(samples since the drop) (4 kHz)".into(),
        y_label: "RMS error / steady-state bound, per bin".into(),
        series,
    }
}

/// An f32 cell that fails the goal: f32 RMS more than 10% above the f64 RMS, or not valid,
/// where the f64 twin is valid.
#[derive(Clone, Debug)]
pub struct F32Failure {
    /// Where.
    pub what: String,
    /// f32 RMS over f64 RMS (runs valid in both), if any.
    pub ratio: Option<f64>,
    /// The f32 cell's class.
    pub class: Class,
}

/// The f32 goal over the Monte Carlo slices: per family, the cells checked and the failures.
pub fn f32_goal(slices: &[SliceResult]) -> Vec<(String, usize, Vec<F32Failure>)> {
    let mut out: Vec<(String, usize, Vec<F32Failure>)> = Vec::new();
    for slice in slices {
        for (c, condition) in slice.conditions.iter().enumerate() {
            for (p, probe) in slice.probes.iter().enumerate() {
                let Some(twin) = probe.twin else { continue };
                for r in 0..2 {
                    let reference = &slice.cells[c][twin][r];
                    if !reference.class().0.is_valid() {
                        continue;
                    }
                    let cell = &slice.cells[c][p][r];
                    let index = match out.iter().position(|o| o.0 == probe.family) {
                        Some(i) => i,
                        None => {
                            out.push((probe.family.clone(), 0, Vec::new()));
                            out.len() - 1
                        }
                    };
                    out[index].1 += 1;
                    let ratio = cell.f32_over_f64();
                    let (class, _) = cell.class();
                    let fails = !class.is_valid() || ratio.is_none_or(|v| v > 1.0 + F32_TOLERANCE);
                    if fails {
                        out[index].2.push(F32Failure {
                            what: format!(
                                "{} {} dB{}{} at {}",
                                condition.noise.name(),
                                condition.snr_db,
                                probe.order.map(|n| format!(", n={n}")).unwrap_or_default(),
                                if condition.slice == Slice::OffCalibration {
                                    format!(", f_n ×{}", condition.resonance_ratio)
                                } else {
                                    String::new()
                                },
                                readout_name(r)
                            ),
                            ratio,
                            class,
                        });
                    }
                }
            }
        }
    }
    out
}

/// A family and its count of failing cells per (class, silent).
pub type FamilyFailures = (String, Vec<((Class, bool), usize)>);

/// Table rows: a name and the (condition, probe) of each column.
type TableRows = Vec<(String, Vec<(usize, usize)>)>;

/// Counts of (class, silent) per family over every Monte Carlo cell and readout.
pub fn failure_summary(slices: &[SliceResult]) -> Vec<FamilyFailures> {
    let mut out: Vec<FamilyFailures> = Vec::new();
    for slice in slices {
        for cells in &slice.cells {
            for (probe, pair) in slice.probes.iter().zip(cells) {
                for cell in pair {
                    let key = cell.class();
                    if key.0.is_valid() || key.0 == Class::NotYet {
                        continue;
                    }
                    let family = format!("{} ({})", probe.family, slice.conditions[0].slice.name());
                    let index = match out.iter().position(|o| o.0 == family) {
                        Some(i) => i,
                        None => {
                            out.push((family, Vec::new()));
                            out.len() - 1
                        }
                    };
                    match out[index].1.iter_mut().find(|(k, _)| *k == key) {
                        Some((_, count)) => *count += 1,
                        None => out[index].1.push((key, 1)),
                    }
                }
            }
        }
    }
    out
}

fn markdown_slice(
    slice: &SliceResult,
    out: &mut impl Write,
    rows_of: &dyn Fn(&SliceResult) -> TableRows,
    columns: &[String],
) -> Result<()> {
    for r in 0..2 {
        writeln!(out, "\nAt {}:\n", readout_name(r))?;
        write!(out, "| |")?;
        for column in columns {
            write!(out, " {column} |")?;
        }
        writeln!(out)?;
        writeln!(out, "|---|{}", "---|".repeat(columns.len()))?;
        for (name, cells) in rows_of(slice) {
            write!(out, "| {name} |")?;
            for (c, p) in cells {
                write!(out, " {} |", slice.cells[c][p][r].text())?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}

fn long_rows(long: &LongResult, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "| method | first flag (sample, reason) | oracle: PD lost at | 10³–10⁴ | 10⁴–10⁵ | 10⁵–10⁶ | 10⁶–10⁷ | at the end |"
    )?;
    writeln!(out, "|---|---|---|---|---|---|---|---|")?;
    for run in &long.runs {
        write!(
            out,
            "| `{}` | {} | {} |",
            run.probe.method,
            run.first_flag
                .map(|(k, reason)| format!("{k}, {}", &state_name(State::Invalid(reason))[8..]))
                .unwrap_or_else(|| "none".into()),
            run.lost_definiteness_at
                .map(|k| k.to_string())
                .unwrap_or_else(|| "–".into())
        )?;
        for j in FIRST_DECADE..7 {
            match run.decade(j) {
                Some(d) if d.readings > 0 => {
                    let non_finite = run
                        .first_flag
                        .is_some_and(|(_, r)| r == InvalidReason::NonFiniteUpdate);
                    let lost = run.lost_definiteness_at.is_some();
                    let (class, silent) = d.class(lost, non_finite);
                    let flagged = 100.0 * d.flagged as f64 / d.readings as f64;
                    let mark = match (class, silent) {
                        (Class::Ok, _) => String::new(),
                        (Class::OkPartly, _) => format!(" ({flagged:.0}% flagged)"),
                        (Class::Refused, _) => " F".into(),
                        (_, true) => format!(" **{}, silent**", class.name()),
                        (_, false) => format!(" {} F", class.name()),
                    };
                    if d.valid > 0 {
                        write!(out, " {:.2}{mark} |", d.normalised_rms())?;
                    } else {
                        write!(out, "{mark} |")?;
                    }
                }
                _ => write!(out, " |")?,
            }
        }
        match run.last {
            Outcome::Valid(error) => {
                writeln!(out, " {error:+.2e} g (bound {:.1e}) |", run.bound_end_g)?
            }
            Outcome::Flagged(reason) => writeln!(out, " {} |", state_name(State::Invalid(reason)))?,
            Outcome::WarmingUp => writeln!(out, " warming up |")?,
        }
    }
    Ok(())
}

/// The long runs' f32 check: in every decade from 10⁴ on where the f64 run is valid, the f32
/// run's RMS/bound within 10% of the f64 one's.
pub fn long_f32_goal(long: &LongResult) -> Vec<String> {
    let mut failures = Vec::new();
    for (p, run) in long.runs.iter().enumerate() {
        let Some(twin) = run.probe.twin else { continue };
        let reference = &long.runs[twin];
        for j in FIRST_DECADE + 1..7 {
            let (Some(mine), Some(theirs)) = (run.decade(j), reference.decade(j)) else {
                continue;
            };
            if theirs.readings == 0
                || !theirs
                    .class(reference.lost_definiteness_at.is_some(), false)
                    .0
                    .is_valid()
            {
                continue;
            }
            let ratio = mine.normalised_rms() / theirs.normalised_rms();
            let (class, _) = mine.class(run.lost_definiteness_at.is_some(), false);
            if !class.is_valid() || !(ratio <= 1.0 + F32_TOLERANCE) {
                failures.push(format!(
                    "`{}` 10^{j}–10^{}: {} (f32/f64 {ratio:.2})",
                    long.runs[p].probe.method,
                    j + 1,
                    class.name()
                ));
            }
        }
    }
    failures
}

/// Write the markdown report.
#[allow(clippy::too_many_arguments)]
pub fn write_markdown(
    slices: &[SliceResult],
    long: Option<&LongResult>,
    command: &str,
    wall_s: f64,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(out, "# Stability map\n")?;
    writeln!(
        out,
        "`{command}`: {} runs a Monte Carlo cell, {wall_s:.0} s wall on {} threads. Cell text: RMS error of the valid runs over the CRLB (known model, onset, tare), then a mark: `S` silent > 10× CRLB; `F` most runs flagged; `·` not yet determined; `(x% valid)` some runs flagged or not yet; **PD!**/**NaN!**/**DIV!** silent loss of definiteness, non-finite value, divergence (`PD F`, `NaN F`: the same, flagged).\n",
        slices.first().map(|s| s.runs).unwrap_or(0),
        rayon::current_num_threads()
    )?;
    writeln!(
        out,
        "## Failure modes found (cells × readouts, every slice)\n"
    )?;
    writeln!(out, "| family (slice) | cells |")?;
    writeln!(out, "|---|---|")?;
    for (family, counts) in failure_summary(slices) {
        let text: Vec<String> = counts
            .iter()
            .map(|((class, silent), n)| {
                format!(
                    "{n} {}{}",
                    class.name(),
                    if *silent { " (SILENT)" } else { " (flagged)" }
                )
            })
            .collect();
        writeln!(out, "| {family} | {} |", text.join(", "))?;
    }
    writeln!(
        out,
        "\n## f32 against f64 (goal: f32 RMS within 10% of f64 where f64 is valid)\n"
    )?;
    for (family, checked, failures) in f32_goal(slices) {
        if failures.is_empty() {
            writeln!(out, "- PASS {family}: {checked} cells")?;
        } else {
            let list: Vec<String> = failures
                .iter()
                .take(12)
                .map(|f| {
                    format!(
                        "{} ({}{})",
                        f.what,
                        f.class.name(),
                        f.ratio.map(|r| format!(", {r:.2}")).unwrap_or_default()
                    )
                })
                .collect();
            writeln!(
                out,
                "- FAIL {family}: {} of {checked} cells: {}{}",
                failures.len(),
                list.join("; "),
                if failures.len() > 12 { "; …" } else { "" }
            )?;
        }
    }
    if let Some(long) = long {
        let failures = long_f32_goal(long);
        if failures.is_empty() {
            writeln!(out, "- PASS long runs: every decade from 10⁴ samples on")?;
        } else {
            writeln!(out, "- FAIL long runs: {}", failures.join("; "))?;
        }
    }
    for slice in slices {
        match slice.conditions.first().map(|c| c.slice) {
            Some(Slice::OrderSnr) => {
                writeln!(out, "\n## A: order × SNR (white noise)")?;
                let mut families: Vec<(String, Precision)> = Vec::new();
                for probe in &slice.probes {
                    let key = (probe.family.clone(), probe.method.precision());
                    if !families.contains(&key) {
                        families.push(key);
                    }
                }
                let mut orders: Vec<usize> = slice.probes.iter().filter_map(|p| p.order).collect();
                orders.sort_unstable();
                orders.dedup();
                for (family, precision) in families {
                    writeln!(
                        out,
                        "\n### {family}, {}",
                        if precision == Precision::F32 {
                            "f32"
                        } else {
                            "f64"
                        }
                    )?;
                    let columns: Vec<String> = orders.iter().map(|n| format!("n={n}")).collect();
                    let rows = |s: &SliceResult| -> TableRows {
                        s.conditions
                            .iter()
                            .enumerate()
                            .map(|(c, condition)| {
                                (
                                    format!("{} dB", condition.snr_db),
                                    orders
                                        .iter()
                                        .filter_map(|&n| {
                                            s.probes
                                                .iter()
                                                .position(|p| {
                                                    p.family == family
                                                        && p.order == Some(n)
                                                        && p.method.precision() == precision
                                                })
                                                .map(|p| (c, p))
                                        })
                                        .collect(),
                                )
                            })
                            .collect()
                    };
                    markdown_slice(slice, out, &rows, &columns)?;
                }
            }
            Some(kind) => {
                type Grouping = Box<dyn Fn(&Condition) -> String>;
                let (title, group): (&str, Grouping) = match kind {
                    Slice::NoiseType => (
                        "B: noise type × SNR (the disturbance has the white noise's RMS; judged against the white-noise CRLB at the total power)",
                        Box::new(|c: &Condition| c.noise.name().to_string()),
                    ),
                    _ => (
                        "C: off-calibration (resonance with the load over the one at the 200 g calibration; the white noise held at the reference scene's SNR)",
                        Box::new(|c: &Condition| format!("{} dB", c.snr_db)),
                    ),
                };
                writeln!(out, "\n## {title}")?;
                let mut groups: Vec<String> = Vec::new();
                for condition in &slice.conditions {
                    let g = group(condition);
                    if !groups.contains(&g) {
                        groups.push(g);
                    }
                }
                for g in groups {
                    writeln!(out, "\n### {g}")?;
                    let members: Vec<usize> = (0..slice.conditions.len())
                        .filter(|&c| group(&slice.conditions[c]) == g)
                        .collect();
                    let columns: Vec<String> = members
                        .iter()
                        .map(|&c| {
                            let condition = &slice.conditions[c];
                            match kind {
                                Slice::NoiseType => format!("{} dB", condition.snr_db),
                                _ => format!(
                                    "×{} ({:.0} g)",
                                    condition.resonance_ratio, condition.truth_g
                                ),
                            }
                        })
                        .collect();
                    let rows = |s: &SliceResult| -> TableRows {
                        s.probes
                            .iter()
                            .enumerate()
                            .map(|(p, probe)| {
                                (
                                    format!("{} (`{}`)", probe_label(probe), probe.method),
                                    members.iter().map(|&c| (c, p)).collect(),
                                )
                            })
                            .collect()
                    };
                    markdown_slice(slice, out, &rows, &columns)?;
                }
            }
            None => {}
        }
    }
    if let Some(long) = long {
        writeln!(
            out,
            "\n## D: long runs (one run of {} samples a cell, a steady 138.32 g at 50 dB)\n",
            long.samples
        )?;
        writeln!(
            out,
            "RMS error over the steady-state bound `σ²/D·(1−λ)(1+λᵐ)/((1+λ)(1−λᵐ))` (m decimated rows; σ² = {:.4} g², white + quantisation + amplifier) of the valid readings in each decade of samples; the first decade holds the drop's transient, where this bound does not apply.\n",
            long.raw_variance_g2
        )?;
        long_rows(long, out)?;
    }
    Ok(())
}

fn create(path: &Path) -> Result<std::io::BufWriter<std::fs::File>> {
    Ok(std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
    ))
}

/// `host-sim study stability`: run the four slices, write the CSVs, the markdown and the
/// charts into `out`, print the verdicts and the wall time.
pub fn stability_command(
    runs: usize,
    seed: u64,
    snrs_db: &[f64],
    orders: &[usize],
    long_samples: usize,
    out: &Path,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let start = Instant::now();
    let base = Scene::load("reference-step")?;
    eprintln!("slice A: order × SNR");
    let a = run_slice(
        order_conditions(&base, snrs_db),
        order_probes(orders),
        runs,
        seed,
    )?;
    eprintln!("slice B: noise type × SNR");
    let b = run_slice(
        noise_conditions(&base, snrs_db),
        default_probes(),
        runs,
        seed,
    )?;
    eprintln!("slice C: off-calibration");
    // Its own two noise levels, or those of them the caller's SNRs keep (a quick look).
    let mut off_snrs: Vec<f64> = OFF_CALIBRATION_SNRS_DB
        .iter()
        .copied()
        .filter(|s| snrs_db.contains(s))
        .collect();
    if off_snrs.is_empty() {
        off_snrs = OFF_CALIBRATION_SNRS_DB.to_vec();
    }
    let c = run_slice(
        off_calibration_conditions(&base, &off_snrs)?,
        default_probes(),
        runs,
        seed,
    )?;
    let slices = [a, b, c];
    let long = if long_samples > 0 {
        eprintln!("slice D: long runs");
        Some(run_long_slice(&base, long_samples, seed)?)
    } else {
        None
    };
    let wall_s = start.elapsed().as_secs_f64();
    let mut csv = create(&out.join("stability-map.csv"))?;
    write_csv(&slices, &mut csv)?;
    csv.flush()?;
    let text = |v: &[String]| v.join(",");
    let command = format!(
        "host-sim study stability --runs {runs} --seed {seed} --snr-db {} --orders {} --long-samples {long_samples}",
        text(&snrs_db.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
        text(&orders.iter().map(|s| s.to_string()).collect::<Vec<_>>())
    );
    let mut markdown = create(&out.join("stability-map.md"))?;
    write_markdown(&slices, long.as_ref(), &command, wall_s, &mut markdown)?;
    markdown.flush()?;
    for r in 0..2 {
        order_heat_map(&slices[0], r).write(&out.join(format!(
            "g-stability-order-snr-{}",
            if r == 0 { "100ms" } else { "1500ms" }
        )))?;
    }
    probe_heat_map(
        &slices[1],
        "Stability map B: noise type × SNR",
        |c| c.noise.name().to_string(),
        |c| format!("{}", c.snr_db),
        "SNR of the white part, dB",
    )
    .write(&out.join("h-stability-noise"))?;
    probe_heat_map(
        &slices[2],
        "Stability map C: the load's resonance off the 200 g calibration",
        |c| format!("white noise of {} dB on the reference drop", c.snr_db),
        |c| format!("{}", c.resonance_ratio),
        "resonance / resonance at 200 g",
    )
    .write(&out.join("i-stability-off-calibration"))?;
    if let Some(long) = &long {
        let mut csv = create(&out.join("stability-long-runs.csv"))?;
        writeln!(
            csv,
            "spec,bin_first_sample,bin_last_sample,readings,valid,flagged,rms_over_bound,max_error_g,valid_after_lost_definiteness,first_flag_sample,first_flag_reason,lost_definiteness_at"
        )?;
        for run in &long.runs {
            for (i, bin) in run.bins.iter().enumerate() {
                let edge = |i: usize| {
                    10f64
                        .powf(f64::from(FIRST_DECADE) + i as f64 / BINS_PER_DECADE as f64)
                        .round()
                };
                writeln!(
                    csv,
                    "{},{},{},{},{},{},{:.4},{:.4e},{},{},{},{}",
                    run.probe.method.to_string().replace(',', " "),
                    edge(i),
                    edge(i + 1) - 1.0,
                    bin.readings,
                    bin.valid,
                    bin.flagged,
                    bin.normalised_rms(),
                    bin.max_error_g,
                    bin.valid_after_loss,
                    run.first_flag.map(|f| f.0.to_string()).unwrap_or_default(),
                    run.first_flag
                        .map(|f| state_name(State::Invalid(f.1)).to_string())
                        .unwrap_or_default(),
                    run.lost_definiteness_at
                        .map(|k| k.to_string())
                        .unwrap_or_default()
                )?;
            }
        }
        csv.flush()?;
        for decimation in LONG_DECIMATIONS {
            long_chart(long, decimation)
                .write(&out.join(format!("j-stability-long-runs-d{decimation}")))?;
        }
    }
    // The verdicts on stdout.
    println!("stability map: {runs} runs a Monte Carlo cell, seed {seed}");
    for (family, counts) in failure_summary(&slices) {
        let text: Vec<String> = counts
            .iter()
            .map(|((class, silent), n)| {
                format!(
                    "{n} {}{}",
                    class.name(),
                    if *silent { " SILENT" } else { " flagged" }
                )
            })
            .collect();
        println!("  {family}: {}", text.join(", "));
    }
    for (family, checked, failures) in f32_goal(&slices) {
        println!(
            "  f32 goal {}: {family} ({} of {checked} valid f64 cells fail)",
            if failures.is_empty() { "PASS" } else { "FAIL" },
            failures.len()
        );
    }
    if let Some(long) = &long {
        let failures = long_f32_goal(long);
        println!(
            "  f32 goal {}: long runs{}",
            if failures.is_empty() { "PASS" } else { "FAIL" },
            if failures.is_empty() {
                String::new()
            } else {
                format!(" ({})", failures.join("; "))
            }
        );
    }
    println!(
        "{wall_s:.1} s wall on {} threads; wrote {}/stability-map.{{csv,md}}, stability-long-runs.csv, g-/h-/i-/j-stability-*.{{svg,png}}",
        rayon::current_num_threads(),
        out.display()
    );
    Ok(())
}
