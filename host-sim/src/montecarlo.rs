//! Monte Carlo studies of `estimator-core` on a scene: seeded, reproducible on any number
//! of threads (each run's seed comes from the study seed and the run index), parallel with
//! rayon, with a progress bar.
//!
//! A study estimates the scene's first step from its onset, with the tare known (the
//! noise-free zero code, as a calibrated scale knows it), and records for every sample
//! index after the onset the bias, standard deviation and RMS error of each estimator
//! configuration, the CRLB, and for each run the time the estimate reaches and stays
//! within 0.5%, 0.1% and 0.05%. Methods that need the noise variance at tare (`bc`) get it
//! measured: `estimator_core::NoiseMeter` over 0.3 s of simulated empty pan before each run
//! ([`tare_record`], on a noise stream of its own so other methods' records do not change).
//!
//! What it must never do: let a figure depend on the thread count (runs are accumulated in
//! fixed chunks, merged in order), or give one method runs or seeds its rivals did not get.

use std::fmt;
use std::io::Write;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{bail, Result};
use estimator_core::{Estimator, State, StepConfig, StepEstimator};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::crlb;
use crate::method::{measured_tare_variance, BuildContext, Method};
use crate::scene::Scene;
use crate::simulated::{run_seed, Script, SimulatedAdc};
use estimator_core::sensor::AdcSource;

/// The largest order the host tools accept.
pub const CAPACITY: usize = 40;
/// Tolerances of the "time to reach and stay within" figures (relative).
pub const TOLERANCES: [f64; 3] = [0.005, 0.001, 0.0005];
/// Runs accumulated together before merging (fixed, so results do not depend on threads).
const RUNS_PER_CHUNK: usize = 16;

/// Arithmetic of the estimator under test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// Single precision, as on the Cortex-M4F.
    F32,
    /// Double precision.
    F64,
}

impl FromStr for Precision {
    type Err = anyhow::Error;
    fn from_str(text: &str) -> Result<Self> {
        match text {
            "f32" => Ok(Self::F32),
            "f64" => Ok(Self::F64),
            other => bail!("precision must be f32 or f64, found `{other}`"),
        }
    }
}

/// One configuration of the step estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setup {
    /// Order n.
    pub order: usize,
    /// Decimation D.
    pub decimation: u16,
    /// Forgetting factor λ.
    pub forgetting: f64,
    /// Arithmetic.
    pub precision: Precision,
}

impl Setup {
    /// Order n, decimation D, λ = 1, f64.
    pub fn new(order: usize, decimation: u16) -> Self {
        Self {
            order,
            decimation,
            forgetting: 1.0,
            precision: Precision::F64,
        }
    }
}

impl FromStr for Setup {
    type Err = anyhow::Error;
    /// `n=7,D=16[,lambda=0.999][,precision=f32]`: the step method's spec (see
    /// [`crate::method`]), with or without `step:`.
    fn from_str(text: &str) -> Result<Self> {
        match text.parse::<Method>()? {
            Method::Step(setup) => Ok(setup),
            other => bail!(
                "configuration `{text}`: `--config` takes a step configuration (n=..,D=..); give `{other}` with --method"
            ),
        }
    }
}

impl fmt::Display for Setup {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "n={} D={}", self.order, self.decimation)?;
        if self.forgetting != 1.0 {
            write!(f, " lambda={}", self.forgetting)?;
        }
        if self.precision == Precision::F32 {
            write!(f, " f32")?;
        }
        Ok(())
    }
}

/// The core's step estimator in the precision a setup asks for.
#[derive(Clone, Debug)]
// One per run and configuration, kept on the stack; the f64 one is just twice the f32 one.
#[allow(clippy::large_enum_variant)]
pub enum CoreEstimator {
    /// f32.
    F32(StepEstimator<f32, CAPACITY>),
    /// f64.
    F64(StepEstimator<f64, CAPACITY>),
}

impl CoreEstimator {
    /// The estimator for `setup` with static gain `gain` (raw units per gram).
    pub fn new(setup: &Setup, gain: f64) -> Result<Self> {
        Ok(match setup.precision {
            Precision::F32 => Self::F32(
                StepEstimator::new(
                    StepConfig::new(setup.order, gain as f32)
                        .with_forgetting(setup.forgetting as f32)
                        .with_decimation(setup.decimation),
                )
                .map_err(|e| anyhow::anyhow!("{setup}: {e}"))?,
            ),
            Precision::F64 => Self::F64(
                StepEstimator::new(
                    StepConfig::new(setup.order, gain)
                        .with_forgetting(setup.forgetting)
                        .with_decimation(setup.decimation),
                )
                .map_err(|e| anyhow::anyhow!("{setup}: {e}"))?,
            ),
        })
    }

    /// Push one raw sample (offset removed, in f64: converted to f32 after the subtraction).
    pub fn push(&mut self, sample: f64) -> (Option<f64>, State) {
        match self {
            Self::F32(estimator) => {
                let reading = estimator.push(sample as f32);
                (reading.estimate.map(f64::from), reading.state)
            }
            Self::F64(estimator) => {
                let reading = estimator.push(sample);
                (reading.estimate, reading.state)
            }
        }
    }

    /// A lost sample.
    pub fn push_missing(&mut self) -> (Option<f64>, State) {
        match self {
            Self::F32(estimator) => {
                let reading = estimator.push_missing();
                (reading.estimate.map(f64::from), reading.state)
            }
            Self::F64(estimator) => {
                let reading = estimator.push_missing();
                (reading.estimate, reading.state)
            }
        }
    }
}

/// What a study measures for one method.
#[derive(Clone, Debug)]
pub struct SetupStats {
    /// The method (a step configuration for `--config`).
    pub setup: Method,
    /// Per sample index: Σ error, Σ error² over the runs with a valid estimate, g and g².
    pub sum_error: Vec<f64>,
    /// See `sum_error`.
    pub sum_squared: Vec<f64>,
    /// Per sample index: runs with a valid estimate.
    pub valid: Vec<u32>,
    /// Per tolerance in [`TOLERANCES`], per run: the time the estimate reached and stayed
    /// within the tolerance, s (infinite if it never did within the window).
    pub settle_s: [Vec<f64>; 3],
    /// Per run, with a final target ([`Study::final_target_g`]): the time of the first
    /// reading final by the estimator's own rule (twice `u` at its upper 95 % bound within
    /// the target), s, and that reading's error, g; `(∞, NaN)` for a run never final
    /// within the window. Empty without a target.
    pub finals: Vec<(f64, f64)>,
    /// Runs in which the method stated a `u` at least once (with a target).
    pub runs_with_u: usize,
}

impl SetupStats {
    fn new(setup: Method, samples: usize) -> Self {
        Self {
            setup,
            sum_error: vec![0.0; samples],
            sum_squared: vec![0.0; samples],
            valid: vec![0; samples],
            settle_s: [Vec::new(), Vec::new(), Vec::new()],
            finals: Vec::new(),
            runs_with_u: 0,
        }
    }

    fn merge(&mut self, other: Self) {
        for k in 0..self.valid.len() {
            self.sum_error[k] += other.sum_error[k];
            self.sum_squared[k] += other.sum_squared[k];
            self.valid[k] += other.valid[k];
        }
        for (mine, theirs) in self.settle_s.iter_mut().zip(other.settle_s) {
            mine.extend(theirs);
        }
        self.finals.extend(other.finals);
        self.runs_with_u += other.runs_with_u;
    }

    /// Bias at sample index k, g (NaN without valid runs).
    pub fn bias(&self, k: usize) -> f64 {
        self.sum_error[k] / f64::from(self.valid[k])
    }

    /// RMS error at sample index k, g.
    pub fn rms(&self, k: usize) -> f64 {
        (self.sum_squared[k] / f64::from(self.valid[k])).sqrt()
    }

    /// Standard deviation at sample index k, g.
    pub fn std(&self, k: usize) -> f64 {
        let n = f64::from(self.valid[k]);
        let mean = self.bias(k);
        ((self.sum_squared[k] - n * mean * mean) / (n - 1.0))
            .max(0.0)
            .sqrt()
    }

    /// The `quantile` (0..1) of the settle times for tolerance index `tolerance`, s.
    pub fn settle_quantile(&self, tolerance: usize, quantile: f64) -> f64 {
        let mut times = self.settle_s[tolerance].clone();
        times.sort_by(f64::total_cmp);
        if times.is_empty() {
            return f64::NAN;
        }
        let index = ((times.len() as f64 * quantile).ceil() as usize).clamp(1, times.len()) - 1;
        times[index]
    }

    /// The `quantile` (0..1) of the time to the first final reading over all runs, s
    /// (infinite when fewer runs than that became final; NaN without a target).
    pub fn final_quantile(&self, quantile: f64) -> f64 {
        finals_quantile(&self.finals, quantile)
    }

    /// The share of runs whose first final reading came by `time_s` and lay within
    /// `tolerance_g` of the truth (NaN without a target).
    pub fn final_within_by(&self, time_s: f64, tolerance_g: f64) -> f64 {
        finals_within_by(&self.finals, time_s, tolerance_g)
    }

    /// The share of runs whose first final reading lay further than `tolerance_g` from the
    /// truth (NaN without a target).
    pub fn finals_beyond(&self, tolerance_g: f64) -> f64 {
        finals_beyond(&self.finals, tolerance_g)
    }
}

/// Of runs' first final readings `(time s, error g)`, one per run (`(∞, NaN)`: never
/// final): the `quantile` of the time (NaN without runs; infinite when fewer runs than
/// that were final).
pub fn finals_quantile(finals: &[(f64, f64)], quantile: f64) -> f64 {
    let mut times: Vec<f64> = finals.iter().map(|(t, _)| *t).collect();
    times.sort_by(f64::total_cmp);
    if times.is_empty() {
        return f64::NAN;
    }
    let index = ((times.len() as f64 * quantile).ceil() as usize).clamp(1, times.len()) - 1;
    times[index]
}

/// The share of runs final by `time_s` with their first final reading within
/// `tolerance_g` of the truth (NaN without runs).
pub fn finals_within_by(finals: &[(f64, f64)], time_s: f64, tolerance_g: f64) -> f64 {
    let hits = finals
        .iter()
        .filter(|(t, e)| *t <= time_s && e.abs() <= tolerance_g)
        .count();
    hits as f64 / finals.len() as f64
}

/// The share of runs whose first final reading lay further than `tolerance_g` from the
/// truth (NaN without runs).
pub fn finals_beyond(finals: &[(f64, f64)], tolerance_g: f64) -> f64 {
    let beyond = finals
        .iter()
        .filter(|(t, e)| t.is_finite() && !(e.abs() <= tolerance_g))
        .count();
    beyond as f64 / finals.len() as f64
}

/// A finished study at one SNR.
#[derive(Clone, Debug)]
pub struct StudyResult {
    /// The scene's name.
    pub scene: String,
    /// The SNR, dB.
    pub snr_db: f64,
    /// Runs.
    pub runs: usize,
    /// The study's seed.
    pub seed: u64,
    /// The true step, g.
    pub truth_g: f64,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Per configuration.
    pub setups: Vec<SetupStats>,
    /// CRLB (known model, onset and tare; white noise, quantisation and, when the scene has
    /// it, the amplifier's coloured noise) per sample index, g².
    pub crlb_g2: Vec<f64>,
    /// The same with the tare unknown (centred form), g².
    pub crlb_unknown_tare_g2: Vec<f64>,
    /// The study's final target, g ([`Study::final_target_g`]).
    pub final_target_g: Option<f64>,
    /// The noise-free sensor's own time to reach and stay within each tolerance, s.
    pub sensor_settle_s: [f64; 3],
    /// One run's relative errors per configuration (run 0), for chart (a).
    pub example_relative_error: Vec<Vec<f64>>,
}

/// The parameters of a study.
#[derive(Clone, Debug)]
pub struct Study {
    /// The scene.
    pub scene: Scene,
    /// The methods under test (`Method::from(setup)` for a step configuration).
    pub setups: Vec<Method>,
    /// Runs.
    pub runs: usize,
    /// Seed.
    pub seed: u64,
    /// Samples after the onset to study (at most the scene's window).
    pub samples: usize,
    /// With a target, g: each run's first final reading is recorded
    /// ([`SetupStats::finals`]).
    pub final_target_g: Option<f64>,
}

/// Samples of empty pan metered before each run for the methods that take the tare noise
/// (`bc`): 0.3 s at 4 kHz, the empty stretch the firmware demo has before its first drop.
pub const TARE_SAMPLES: usize = 1200;

/// A salt for the tare's noise stream, so that adding a tare to a study leaves every other
/// method's record (and figures) unchanged.
const TARE_STREAM: u64 = 0x7a5e_0000_7a5e_0000;

/// Run `run`'s empty-pan record before the drop, tare removed (ADC codes minus the
/// noise-free zero): the scene's chain and disturbances on its own noise stream.
pub fn tare_record(scene: &Scene, seed: u64, run: u64) -> Vec<f64> {
    let end_s = TARE_SAMPLES as f64 / scene.chain.sample_rate_hz;
    let mut adc = SimulatedAdc::new(
        scene.chain,
        Script::<1>::new(end_s),
        scene.disturbances,
        run_seed(seed ^ TARE_STREAM, run),
    );
    centred_record(&mut adc, scene.chain.zero_code(), TARE_SAMPLES)
}

/// The last index after which `|error|/truth` stays within `tolerance`, as a time.
fn settle_time(errors: &[Option<f64>], truth: f64, tolerance: f64, rate: f64) -> f64 {
    let mut last_outside: Option<usize> = None;
    for (k, error) in errors.iter().enumerate() {
        let inside = matches!(error, Some(e) if (e / truth).abs() <= tolerance);
        if !inside {
            last_outside = Some(k);
        }
    }
    match last_outside {
        None => 0.0,
        Some(k) if k + 1 >= errors.len() => f64::INFINITY,
        Some(k) => (k + 1) as f64 / rate,
    }
}

/// The time the noise-free response of the scene's sensor reaches and stays within each
/// tolerance of its final value, s.
pub fn sensor_settle_s(scene: &Scene, truth_g: f64) -> [f64; 3] {
    TOLERANCES.map(|t| sensor_settle_time_s(scene, truth_g, t))
}

/// The time the noise-free step response of the scene's sensor to `truth_g` reaches and
/// stays within `tolerance` (relative) of its final value, s (10 s of response examined).
pub fn sensor_settle_time_s(scene: &Scene, truth_g: f64, tolerance: f64) -> f64 {
    let response = crlb::unit_step_response(&scene.chain, truth_g, 40_000);
    let errors: Vec<Option<f64>> = response.iter().map(|s| Some(s - 1.0)).collect();
    settle_time(&errors, 1.0, tolerance, scene.chain.sample_rate_hz)
}

impl Study {
    /// Run the study at the scene's SNR, with a progress bar.
    pub fn run(&self, progress: &ProgressBar) -> Result<StudyResult> {
        let scene = &self.scene;
        let chain = scene.chain;
        let (onset, truth_g, _) = scene.studied_step();
        let samples = self.samples.min(scene.studied_window()).max(1);
        let gain = chain.counts_per_gram();
        let noise_variance = raw_noise_variance(scene);
        let context = self.validated_context(noise_variance)?;
        let rate = chain.sample_rate_hz;
        let run_one = |run: usize| -> Vec<RunTrace> {
            let traces = self.run_errors(run, &context, onset, samples, truth_g);
            progress.inc(1);
            traces
        };
        let empty = || -> Vec<SetupStats> {
            self.setups
                .iter()
                .map(|method| SetupStats::new(*method, samples))
                .collect()
        };
        // Fixed chunks of runs, each accumulated in run order and merged in chunk order:
        // the sums are bit-identical on any number of threads.
        let chunks: Vec<Vec<SetupStats>> = (0..self.runs.div_ceil(RUNS_PER_CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let mut stats = empty();
                let first = chunk * RUNS_PER_CHUNK;
                for run in first..(first + RUNS_PER_CHUNK).min(self.runs) {
                    accumulate(
                        &mut stats,
                        &run_one(run),
                        truth_g,
                        rate,
                        self.final_target_g,
                    );
                }
                stats
            })
            .collect();
        let mut stats = empty();
        for chunk in chunks {
            for (mine, theirs) in stats.iter_mut().zip(chunk) {
                mine.merge(theirs);
            }
        }
        let example_relative_error = run_one(0)
            .iter()
            .map(|trace| {
                trace
                    .errors
                    .iter()
                    .map(|e| e.map(|e| e / truth_g).unwrap_or(f64::NAN))
                    .collect()
            })
            .collect();
        progress.dec(1);
        let unit_step = crlb::unit_step_response(&chain, truth_g, samples);
        Ok(StudyResult {
            scene: scene.name.clone(),
            snr_db: scene.snr_db.unwrap_or(f64::INFINITY),
            runs: self.runs,
            seed: self.seed,
            truth_g,
            sample_rate_hz: rate,
            setups: stats,
            crlb_g2: crlb_g2(scene, truth_g, samples),
            crlb_unknown_tare_g2: crlb::white_unknown_tare(&unit_step, gain, noise_variance),
            final_target_g: self.final_target_g,
            sensor_settle_s: sensor_settle_s(scene, truth_g),
            example_relative_error,
        })
    }

    /// The study's build context, every method refused here if it cannot be built (before
    /// any time is spent).
    fn validated_context(&self, noise_variance: f64) -> Result<BuildContext> {
        let scene = &self.scene;
        let chain = scene.chain;
        let gain = chain.counts_per_gram();
        let context = BuildContext {
            // The modelled variance (white part, quantisation, the amplifier's noise at lag
            // 0) only to validate the methods below; every run measures its own tare.
            tare_noise_variance: Some(
                noise_variance
                    + if scene.disturbances.amplifier_noise {
                        crlb::amplifier_autocovariance_g2(&chain, 1)[0] * gain * gain
                    } else {
                        0.0
                    },
            ),
            // A drop whose overshoot clips the ADC is refused by the estimators, as the
            // firmware refuses a saturated sample.
            ..BuildContext::new(chain, gain).with_adc_rails(chain.zero_code())
        };
        for method in &self.setups {
            method.build(&context)?;
            if let Some(decimation) = method.tare_decimation() {
                if TARE_SAMPLES / usize::from(decimation) < 3 {
                    bail!("method `{method}`: a tare of {TARE_SAMPLES} samples is too short to meter the noise at D = {decimation}");
                }
            }
        }
        Ok(context)
    }

    /// One run: every method on the same record from the onset, its error per sample
    /// (`None` while not valid), g, and its first final reading. Each method with a tare
    /// meter gets the run's own tare.
    fn run_errors(
        &self,
        run: usize,
        context: &BuildContext,
        onset: usize,
        samples: usize,
        truth_g: f64,
    ) -> Vec<RunTrace> {
        let scene = &self.scene;
        let needs_tare = self.setups.iter().any(|m| m.tare_decimation().is_some());
        let mut adc = scene.adc(run_seed(self.seed, run as u64));
        for _ in 0..onset {
            let _ = adc.read();
        }
        let record = centred_record(&mut adc, scene.chain.zero_code(), samples);
        let tare = needs_tare.then(|| tare_record(scene, self.seed, run as u64));
        self.setups
            .iter()
            .map(|method| {
                let context = match (method.tare_decimation(), &tare) {
                    (Some(decimation), Some(tare)) => BuildContext {
                        tare_noise_variance: measured_tare_variance(tare, decimation),
                        ..*context
                    },
                    _ => *context,
                };
                // Validated above (the tare is long enough for the meter's D).
                let mut estimator = method.build(&context).expect("validated");
                let mut first_final = None;
                let mut stated_u = false;
                let errors = record
                    .iter()
                    .enumerate()
                    .map(|(k, &sample)| {
                        let reading = estimator.push(sample);
                        let error = reading.estimate.map(|e| e - truth_g);
                        stated_u |= error.is_some() && reading.uncertainty.is_some();
                        if let (None, Some(target), Some(error), Some(bound)) = (
                            first_final,
                            self.final_target_g,
                            error,
                            reading.uncertainty_bound(),
                        ) {
                            if 2.0 * bound <= target {
                                first_final = Some((k, error));
                            }
                        }
                        error
                    })
                    .collect();
                RunTrace {
                    errors,
                    first_final,
                    stated_u,
                }
            })
            .collect()
    }
}

/// One method's run: its error per sample index (`None` while not valid), g, and the
/// sample index and error of its first final reading (with the study's target).
struct RunTrace {
    errors: Vec<Option<f64>>,
    first_final: Option<(usize, f64)>,
    stated_u: bool,
}

/// The raw-sample noise variance of the scene's white noise and quantisation (LSB²/12 per
/// conversion), summed over the oversampled conversions, counts².
fn raw_noise_variance(scene: &Scene) -> f64 {
    let chain = scene.chain;
    let oversampling = f64::from(chain.adc.oversampling.max(1));
    let white_counts =
        scene.disturbances.white_noise_g * chain.volts_per_gram() / chain.adc.volts_per_code();
    oversampling * (white_counts * white_counts + 1.0 / 12.0)
}

/// Add one run's errors to the statistics: sums per sample index, the settling times and,
/// with a final target, the first final reading.
fn accumulate(
    stats: &mut [SetupStats],
    traces: &[RunTrace],
    truth_g: f64,
    rate: f64,
    final_target_g: Option<f64>,
) {
    for (stat, trace) in stats.iter_mut().zip(traces) {
        let errors = &trace.errors;
        for (k, error) in errors.iter().enumerate() {
            if let Some(e) = error {
                stat.sum_error[k] += e;
                stat.sum_squared[k] += e * e;
                stat.valid[k] += 1;
            }
        }
        for (t, tolerance) in TOLERANCES.iter().enumerate() {
            stat.settle_s[t].push(settle_time(errors, truth_g, *tolerance, rate));
        }
        if final_target_g.is_some() {
            stat.runs_with_u += usize::from(trace.stated_u);
            // Sample index k is the (k + 1)-th sample after the onset, as in `settle_time`.
            stat.finals.push(match trace.first_final {
                Some((k, error)) => ((k + 1) as f64 / rate, error),
                None => (f64::INFINITY, f64::NAN),
            });
        }
    }
}

/// The earliest time after the onset at which twice the CRLB is within `target_g`: no
/// estimator whose `u` is honest (at least its own standard deviation, which the bound
/// bounds) can call a reading final sooner, s (infinite: not within the window).
pub fn crlb_final_s(result: &StudyResult, target_g: f64) -> f64 {
    result
        .crlb_g2
        .iter()
        .position(|v| 2.0 * v.sqrt() <= target_g)
        .map_or(f64::INFINITY, |k| (k + 1) as f64 / result.sample_rate_hz)
}

/// The next `samples` conversions of `adc` with `zero` removed, counts; a failed conversion
/// is NaN (the estimators flag it).
pub(crate) fn centred_record<const E: usize>(
    adc: &mut SimulatedAdc<E>,
    zero: f64,
    samples: usize,
) -> Vec<f64> {
    (0..samples)
        .map(|_| {
            adc.read()
                .map(|code| f64::from(code) - zero)
                .unwrap_or(f64::NAN)
        })
        .collect()
}

/// The known-model, known-tare CRLB of a step of `truth_g` on `scene` at every sample index
/// up to `samples`, g²: white noise, quantisation (LSB²/12 per conversion, summed over the
/// oversampled ones) and, when the scene has it and does not oversample, the amplifier's
/// noise coloured by the filter (the coloured bound).
pub fn crlb_g2(scene: &Scene, truth_g: f64, samples: usize) -> Vec<f64> {
    crlb_with_state(scene, truth_g, samples, false)
}

/// As [`crlb_g2`] with the sensor's initial state unknown (profiled out): the bound of an
/// estimator that fits the state with the step, as the model bank does (g², per prefix).
pub fn crlb_unknown_state_g2(scene: &Scene, truth_g: f64, samples: usize) -> Vec<f64> {
    crlb_with_state(scene, truth_g, samples, true)
}

fn crlb_with_state(scene: &Scene, truth_g: f64, samples: usize, unknown_state: bool) -> Vec<f64> {
    let chain = scene.chain;
    let gain = chain.counts_per_gram();
    let oversampling = f64::from(chain.adc.oversampling.max(1));
    let white_counts =
        scene.disturbances.white_noise_g * chain.volts_per_gram() / chain.adc.volts_per_code();
    let noise_variance = oversampling * (white_counts * white_counts + 1.0 / 12.0);
    let unit_step = crlb::unit_step_response(&chain, truth_g, samples);
    if scene.disturbances.amplifier_noise && oversampling == 1.0 {
        // The INA114's noise is coloured by the anti-alias filter: add its
        // autocovariance and use the coloured bound.
        let mut autocovariance: Vec<f64> = crlb::amplifier_autocovariance_g2(&chain, samples)
            .iter()
            .map(|r| r * gain * gain)
            .collect();
        autocovariance[0] += noise_variance;
        if unknown_state {
            let nuisance = crlb::free_responses(&chain, truth_g, samples);
            crlb::coloured_unknown_state(&unit_step, &nuisance, gain, &autocovariance)
        } else {
            crlb::coloured_known_tare(&unit_step, gain, &autocovariance)
        }
    } else if unknown_state {
        let nuisance = crlb::free_responses(&chain, truth_g, samples);
        let mut white = vec![0.0; samples];
        if let Some(first) = white.first_mut() {
            *first = noise_variance;
        }
        crlb::coloured_unknown_state(&unit_step, &nuisance, gain, &white)
    } else {
        crlb::white_known_tare(&unit_step, gain, noise_variance)
    }
}

/// A progress bar for `total` runs (drawn on stderr only when it is a terminal).
pub fn progress_bar(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} runs ({eta} left)")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// Run a study for each SNR.
pub fn run_studies(base: &Study, snrs_db: &[f64]) -> Result<Vec<StudyResult>> {
    let progress = progress_bar((base.runs * snrs_db.len().max(1)) as u64);
    let mut results = Vec::new();
    if snrs_db.is_empty() {
        results.push(base.run(&progress)?);
    }
    for &snr in snrs_db {
        let study = Study {
            scene: base.scene.with_snr_db(snr),
            ..base.clone()
        };
        results.push(study.run(&progress)?);
    }
    progress.finish_and_clear();
    Ok(results)
}

/// Write the per-sample-index CSV.
pub fn write_csv(results: &[StudyResult], out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "snr_db,config,k,t_s,valid_runs,bias_g,std_g,rms_g,rms_rel,crlb_g,mse_over_crlb"
    )?;
    for result in results {
        for stats in &result.setups {
            for k in 0..stats.valid.len() {
                let crlb = result.crlb_g2[k];
                let (bias, std, rms) = if stats.valid[k] > 1 {
                    (stats.bias(k), stats.std(k), stats.rms(k))
                } else {
                    (f64::NAN, f64::NAN, f64::NAN)
                };
                writeln!(
                    out,
                    "{},{},{},{:.6},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}",
                    result.snr_db,
                    stats.setup.label(),
                    k,
                    k as f64 / result.sample_rate_hz,
                    stats.valid[k],
                    bias,
                    std,
                    rms,
                    rms / result.truth_g,
                    crlb.sqrt(),
                    rms * rms / crlb
                )?;
            }
        }
    }
    Ok(())
}

/// The headline figures of a study for each configuration at `readout_s` after the onset.
pub fn summary(results: &[StudyResult], readout_s: f64, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "scene,snr_db,runs,seed,config,rms_g_at_readout,rms_rel_at_readout,rms_over_crlb,median_time_0.1pct_s,p95_time_0.1pct_s,share_within_0.1pct_at_readout"
    )?;
    for result in results {
        let k = ((readout_s * result.sample_rate_hz).round() as usize)
            .min(result.crlb_g2.len().saturating_sub(1));
        for stats in &result.setups {
            let within = stats.settle_s[1]
                .iter()
                .filter(|t| **t <= readout_s)
                .count() as f64
                / stats.settle_s[1].len().max(1) as f64;
            let time = |t: f64| {
                if t.is_finite() {
                    format!("{t:.4}")
                } else {
                    "never".to_string()
                }
            };
            // An estimate not yet valid in every run at the readout has no RMS there.
            let (rms, rel, ratio) = if stats.valid[k] as usize == result.runs {
                let rms = stats.rms(k);
                (
                    format!("{rms:.4e}"),
                    format!("{:.4e}", rms / result.truth_g),
                    format!("{:.2}", rms / result.crlb_g2[k].sqrt()),
                )
            } else {
                let na = || "not_valid".to_string();
                (na(), na(), na())
            };
            writeln!(
                out,
                "{},{},{},{},{},{rms},{rel},{ratio},{},{},{:.3}",
                result.scene,
                result.snr_db,
                result.runs,
                result.seed,
                stats.setup.label(),
                time(stats.settle_quantile(1, 0.5)),
                time(stats.settle_quantile(1, 0.95)),
                within
            )?;
        }
    }
    Ok(())
}

/// Figures of the Monte Carlo benchmark.
#[derive(Clone, Copy, Debug)]
pub struct BenchFigures {
    /// Estimator updates in all.
    pub updates: u64,
    /// Seconds spent in the estimator, summed over threads.
    pub estimator_cpu_s: f64,
    /// Wall-clock seconds of the whole benchmark (simulation and estimation).
    pub wall_s: f64,
    /// Threads used.
    pub threads: usize,
    /// A checksum of the final estimates, so the work cannot be optimised away.
    pub checksum: f64,
}

/// Estimator updates per second measured on each of `threads` thread counts, in one run:
/// `records` recordings of `samples` samples are simulated first, then `runs` estimator
/// passes over them (run `r` takes record `r % records`) are timed by the wall clock in a
/// pool of exactly that many threads. Each figure is its own measurement, never one
/// thread's scaled. Returns `(threads, updates per second)` in the order given.
pub fn throughput(
    scene: &Scene,
    setup: &Setup,
    runs: usize,
    samples: usize,
    seed: u64,
    threads: &[usize],
) -> Result<Vec<(usize, f64)>> {
    let chain = scene.chain;
    let gain = chain.counts_per_gram();
    let zero = chain.zero_code();
    CoreEstimator::new(setup, gain)?;
    let records: Vec<Vec<f64>> = (0..64.min(runs.max(1)))
        .map(|run| centred_record(&mut scene.adc(run_seed(seed, run as u64)), zero, samples))
        .collect();
    let mut figures = Vec::with_capacity(threads.len());
    for &count in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(count.max(1))
            .build()
            .map_err(|e| anyhow::anyhow!("cannot start {count} threads: {e}"))?;
        let start = Instant::now();
        let checksum: f64 = pool.install(|| {
            (0..runs)
                .into_par_iter()
                .map(|run| {
                    let mut estimator = CoreEstimator::new(setup, gain).expect("validated");
                    let mut last = 0.0;
                    for &sample in &records[run % records.len()] {
                        if let (Some(estimate), _) = estimator.push(sample) {
                            last = estimate;
                        }
                    }
                    std::hint::black_box(last)
                })
                .sum()
        });
        let wall_s = start.elapsed().as_secs_f64();
        std::hint::black_box(checksum);
        figures.push((count.max(1), (runs * samples) as f64 / wall_s));
    }
    Ok(figures)
}

/// `runs` × `samples` updates of `setup` on the reference scene at its SNR.
pub fn bench(
    scene: &Scene,
    setup: &Setup,
    runs: usize,
    samples: usize,
    seed: u64,
) -> Result<BenchFigures> {
    let chain = scene.chain;
    let gain = chain.counts_per_gram();
    let zero = chain.zero_code();
    CoreEstimator::new(setup, gain)?;
    let progress = progress_bar(runs as u64);
    let start = Instant::now();
    let (cpu, checksum) = (0..runs)
        .into_par_iter()
        .map(|run| {
            let mut adc = scene.adc(run_seed(seed, run as u64));
            let record = centred_record(&mut adc, zero, samples);
            let mut estimator = CoreEstimator::new(setup, gain).expect("validated");
            let timer = Instant::now();
            let mut last = 0.0;
            for &sample in &record {
                if let (Some(estimate), _) = estimator.push(sample) {
                    last = estimate;
                }
            }
            let elapsed = timer.elapsed().as_secs_f64();
            progress.inc(1);
            (elapsed, std::hint::black_box(last))
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    progress.finish_and_clear();
    Ok(BenchFigures {
        updates: (runs * samples) as u64,
        estimator_cpu_s: cpu,
        wall_s: start.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
        checksum,
    })
}
