//! Every estimator of `estimator-core` behind one short text spec and one reading interface,
//! so `host-sim estimate`, `montecarlo` and `study` can run any of them on the same data.
//!
//! ```text
//! step:n=7,D=16[,lambda=0.999][,precision=f32]     the data-driven estimator (also bare: n=7,D=16)
//! covariance:n=7,D=16[,lambda=..][,precision=..][,prior=1e-6]   textbook covariance RLS (reference)
//! model[:D=8][,K=33][,span=0.7-1.3][,cal_g=200][,interp=3][,whiten=0][,precision=..]  ModelBank over candidate resonances
//! settled[:block=80][,K=10][,band_g=0.5][,precision=..]          wait until stable, then average
//! moving[:block=80][,K=10][,band_g=0.5][,precision=..]           boxcar mean while stable
//! compensated:fn_hz=25,zeta=0.03[,ratio=2][,placed_zeta=1][,average=moving][,block..]  pole-zero compensation first
//! shaped:fn_hz=25,zeta=0.03[,shaper=zvd][,average=moving][,block..]                    input-shaper FIR first
//! ramp:n=5,D=16[,lambda=..][,lag_s=0][,precision=..]            affine-input estimator
//! iv:n=7,D=16[,delay=n+1][,lambda=..][,precision=..]            instrumental variables
//! bc:n=7,D=16[,lambda=..][,noise_var=..][,precision=..]         bias-compensated LS, σ² from the tare
//! model:D=8,K=33,span=0.68-1.3,fn_hz=25.0,zeta=0.03[,filter_hz=100]  bank on an identified model
//! ```
//!
//! A bank's `interp` is how it combines the candidates around its best fit: 3 (the parabola
//! through three, the default) or 5 (the quartic through five, `estimator_core::Interpolation`);
//! `whiten=P` (0, the default: never) fits its block means whitened by the order-`P`
//! prediction-error filter of the empty pan's metered colour, which the context must hold
//! (`ModelBank::set_noise_autocovariance`; `study coverage` meters it for such a bank;
//! without one the spec is refused: the bank would state a white-noise `u` in coloured
//! noise).
//!
//! A spec is checked when it is parsed: an unknown method, key or value is an error that
//! names the spec, the key and what was expected. Building a method gives a boxed
//! [`Estimator<f64>`]; with `precision=f32` the core's `f32` type does the arithmetic and
//! only the samples and readings are converted at the boundary.
//!
//! What this module must never do: compute an estimate itself (every number comes from the
//! core), or quietly change a spec (a value the core would refuse is refused here, by name).
//!
//! ## The `model` method until the identified model lands
//! Its candidates are host-sim's own [`SensorChain`], exact, discretised at the calibration
//! mass `cal_g` and with the moving mass changed so that the resonance is `r` times the
//! calibrated one, `r` spread geometrically over `span`. With the cell's stiffness k and
//! damping c fixed, `ω = √(k/m)` and `ζ = c/(2√(k·m)) = c·ω/(2k)`: a candidate with frequency
//! ratio r has damping ratio r·ζ, as a change of load gives. It is therefore "the true model
//! at calibration": the best case for a model-based estimator, to be replaced by the model
//! identified from calibration drops. The default calibration mass is 200 g, the known mass
//! the firmware's factory calibration uses, so on the reference scene (138.32 g) the bank
//! has to find a resonance 11% below the calibrated one.
//!
//! ## The `model` method on an identified model
//! With `fn_hz` and `zeta` (what calibration identified, [`estimator_core::sensor::identify()`]), the
//! candidates are the core's [`LoadCellModel`] (the mechanical mode in series with the known
//! 3rd-order Butterworth at `filter_hz`, default the chain's) built by the physical law over
//! `span` ([`LoadCellModel::bank_configs`]), initial state estimated: exactly the bank the
//! firmware runs from a weighing config. `cal_g` does not apply (the identified model is
//! already the one at the calibration mass).
//!
//! ## `bc` and its noise variance
//! `noise_var` is the white-noise variance of one raw sample in raw units² as measured at
//! tare ([`estimator_core::NoiseMeter`] at the method's D); without it the build context's
//! `tare_noise_variance` is used, and without that the spec is refused.
//!
//! ## The consistency check
//! With [`BuildContext::noise_check`] and a tare variance, every method that has residuals
//! (step, covariance, iv, bc, ramp, model, and the baselines' block means) gets the tare as
//! its [`NoiseReference`] and flags `invalid_model_mismatch` when its fit leaves more than
//! that noise explains (`estimator_core`'s `consistency` module). The tare must then be
//! metered at the method's own D ([`Method::reference_decimation`]), as the stability map
//! does; `montecarlo` and `study speed` run the methods without it (they measure accuracy,
//! the map measures flags).

use std::fmt;
use std::str::FromStr;

use anyhow::{anyhow, bail, Result};
use estimator_core::sensor::LoadCellModel;
use estimator_core::weighing::UNCERTAINTY_ORDERS;
use estimator_core::{
    max_instrument_delay, Autocovariance, Baseline, BaselineConfig, BaselineMode,
    BiasCompensatedConfig, BiasCompensatedStepEstimator, CovarianceStepEstimator, Estimator,
    InitialState, Interpolation, IvConfig, IvStepEstimator, ModelBank, ModelConfig, NoiseMeter,
    NoiseReference, Prefilter, RampConfig, RampEstimator, Reading, Real, SensorModel, ShaperKind,
    StepConfig, StepEstimator, Unfiltered, MAX_DECIMATION,
};

mod filtered;

pub use filtered::{FilteredSpec, Prefiltering, SHAPER_CAPACITY};

use crate::montecarlo::{Precision, Setup, CAPACITY};
use crate::sensor::{SensorChain, OUTPUT_STATE, STATES};

/// An estimator over `f64` samples, whatever precision it computes in.
pub type BoxedEstimator = Box<dyn Estimator<f64> + Send>;

/// Candidate counts a `model` bank may have (the bank's size is a const generic in the core;
/// 2^j + 1 so that a grid can be refined by halving its steps).
pub const MODEL_CANDIDATES: [usize; 7] = [1, 3, 5, 9, 17, 33, 65];
/// The keys every baseline takes.
const BASELINE_KEYS: [&str; 4] = ["block", "K", "band_g", "precision"];

/// Block counts a `settled` or `moving` baseline may keep (a const generic in the core).
pub const BASELINE_BLOCKS: [usize; 11] = [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 32];

/// The `model` method's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelSpec {
    /// Block length D of the fitted block means.
    pub decimation: u16,
    /// Number of candidate resonances K (one of [`MODEL_CANDIDATES`]).
    pub candidates: usize,
    /// Lowest and highest resonance, relative to the calibrated one.
    pub span: (f64, f64),
    /// The mass the candidates are calibrated at, g.
    pub calibration_g: f64,
    /// Arithmetic.
    pub precision: Precision,
    /// The model identified at calibration; `None`: the true model (host-sim's own chain).
    pub identified: Option<IdentifiedModel>,
    /// How the bank combines the candidates around its best fit (`interp=3|5`).
    pub interpolation: Interpolation,
    /// The order of the prediction-error filter that whitens the block means once a noise
    /// colour is known (`whiten=P`; 0: never).
    pub whitening: usize,
}

/// The identified mechanical mode a `model` bank is built from (the spec's `fn_hz`, `zeta`,
/// `filter_hz`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifiedModel {
    /// Natural frequency with the calibration mass on, Hz.
    pub natural_frequency_hz: f64,
    /// Damping ratio with the calibration mass on.
    pub damping_ratio: f64,
    /// Cut-off of the known 3rd-order Butterworth, Hz.
    pub filter_cutoff_hz: f64,
}

impl Default for ModelSpec {
    /// D = 8, K = 33 over 0.7–1.3 (the core's bank test: ±30%, 1.6% apart, at about the cost
    /// of four full-rate models), calibrated at 200 g.
    fn default() -> Self {
        Self {
            decimation: 8,
            candidates: 33,
            span: (0.7, 1.3),
            calibration_g: 200.0,
            precision: Precision::F64,
            identified: None,
            interpolation: Interpolation::ThreePoint,
            whitening: 0,
        }
    }
}

impl ModelSpec {
    /// The candidates' resonance ratios, geometrically spaced over the span (the middle one
    /// alone for K = 1).
    pub fn ratios(&self) -> Vec<f64> {
        let (low, high) = self.span;
        if self.candidates == 1 {
            return vec![(low * high).sqrt()];
        }
        (0..self.candidates)
            .map(|i| low * (high / low).powf(i as f64 / (self.candidates - 1) as f64))
            .collect()
    }
}

/// The baselines' parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaselineSpec {
    /// Raw samples per block.
    pub block: u16,
    /// Block means kept, K (one of [`BASELINE_BLOCKS`]).
    pub blocks: usize,
    /// Largest spread of the K block means that counts as stable, g.
    pub band_g: f64,
    /// Arithmetic.
    pub precision: Precision,
}

impl BaselineSpec {
    /// `block=..,K=..,band_g=..[,precision=f32]`, as every baseline's spec ends.
    fn write_fields(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "block={},K={},band_g={}",
            self.block, self.blocks, self.band_g
        )?;
        write_precision(f, self.precision)
    }
}

impl Default for BaselineSpec {
    /// What a scale maker would pick: blocks of 80 samples (20 ms, one 50 Hz mains period,
    /// so pickup averages out of every block), K = 10 (a 200 ms stability window, the usual
    /// "motion detection" time), stable within 0.5 g: ten times the standard deviation of a
    /// block mean at 50 dB (0.445 g/√80 = 0.05 g), so that noise alone is never taken for
    /// motion. A band of two 0.1 g display divisions (0.2 g) is too tight for that noise
    /// (host-sim/README.md gives the measured figure).
    /// On the reference scene the 200 ms window happens to span exactly five periods of the
    /// 25 Hz ring, which flatters the moving average's value (not its stability test).
    fn default() -> Self {
        Self {
            block: 80,
            blocks: 10,
            band_g: 0.5,
            precision: Precision::F64,
        }
    }
}

/// The `ramp` method's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RampSpec {
    /// Order, decimation, forgetting and precision, as for the step estimator.
    pub setup: Setup,
    /// The sensor's steady-state ramp lag τ, s.
    pub lag_s: f64,
}

/// Default prior information δ of the covariance form, `Ψ(0) = I/δ` (the core's long-run
/// test uses the same).
pub const DEFAULT_PRIOR_INFORMATION: f64 = 1e-6;

/// An estimator and its parameters: what `--method SPEC` names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// `StepEstimator`: square-root information RLS of the data-driven estimator.
    Step(Setup),
    /// `CovarianceStepEstimator`: the same regression in the textbook covariance form.
    Covariance {
        /// Order, decimation, forgetting and precision.
        setup: Setup,
        /// δ in `Ψ(0) = I/δ`.
        prior_information: f64,
    },
    /// `ModelBank` over candidate models (see the module docs).
    Model(ModelSpec),
    /// `Baseline` in `SettledAverage` mode.
    Settled(BaselineSpec),
    /// `Baseline` in `MovingAverage` mode.
    Moving(BaselineSpec),
    /// `Baseline` behind a pre-filter tuned to the cell (`compensated`, `shaped`).
    Filtered(FilteredSpec),
    /// `RampEstimator`.
    Ramp(RampSpec),
    /// `IvStepEstimator`: instrumental variables, instruments delayed by `delay` decimated
    /// rows (`None`: the core's default, `n + 1`), the default identifiability floor.
    InstrumentalVariable {
        /// Order, decimation, forgetting and precision.
        setup: Setup,
        /// Instrument delay in decimated rows.
        delay: Option<usize>,
    },
    /// `BiasCompensatedStepEstimator`.
    BiasCompensated {
        /// Order, decimation, forgetting and precision.
        setup: Setup,
        /// Raw-sample noise variance, raw units²; `None`: the build context's (measured at
        /// tare, [`BuildContext::tare_noise_variance`]).
        noise_variance: Option<f64>,
    },
}

/// The lags over which a step method's `u` rests on the empty pan's metered noise colour:
/// the firmware's ([`estimator_core::weighing::COLOUR_LAGS`]).
pub use estimator_core::weighing::COLOUR_LAGS;

/// What building a method needs to know about the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildContext {
    /// Static gain: raw units per gram.
    pub gain: f64,
    /// The sensor chain, for the methods that use a model of it (`model`).
    pub chain: SensorChain,
    /// Noise variance of one raw sample as measured at tare, raw units² (for
    /// bias-compensated methods, and the consistency check's reference with `noise_check`;
    /// `None` when no tare was measured).
    pub tare_noise_variance: Option<f64>,
    /// The differences of block means `tare_noise_variance` was metered over
    /// ([`NoiseMeter::differences`]): the reference's own uncertainty; 0: known exactly.
    pub tare_differences: u32,
    /// Give every method with residuals the tare as its consistency check's reference
    /// (see the module docs); without a tare variance there is no check.
    pub noise_check: bool,
    /// Samples (tare removed) outside this range are refused as `OutOfRange`: the ADC's
    /// rails, where a drop's overshoot clips (`None`: no range, e.g. recorded data of
    /// unknown origin). The baselines take no range.
    pub valid_range: Option<(f64, f64)>,
    /// The empty pan's block-mean autocovariance at the step method's `D` (raw units²,
    /// [`estimator_core::AutocovarianceMeter`]): the step estimator's `u` rests on it
    /// (`StepEstimator::set_noise_autocovariance`); `None`: not metered.
    pub noise_autocovariance: Option<Autocovariance<f64>>,
}

impl BuildContext {
    /// The context of recorded data from `chain` with static gain `gain`.
    pub fn new(chain: SensorChain, gain: f64) -> Self {
        Self {
            gain,
            chain,
            tare_noise_variance: None,
            tare_differences: 0,
            noise_check: false,
            valid_range: None,
            noise_autocovariance: None,
        }
    }

    /// The same with the empty pan's block-mean autocovariance (see `noise_autocovariance`).
    pub fn with_noise_autocovariance(self, autocovariance: Option<Autocovariance<f64>>) -> Self {
        Self {
            noise_autocovariance: autocovariance,
            ..self
        }
    }

    /// The consistency check's reference, when the context asks for the check and has a tare.
    pub fn noise_reference<T: Real>(&self) -> Option<NoiseReference<T>> {
        match (self.noise_check, self.tare_noise_variance) {
            (true, Some(variance)) => Some(NoiseReference::new(
                T::from_f64(variance),
                self.tare_differences,
            )),
            _ => None,
        }
    }

    /// The same with the tare metered over `record` at block length `decimation`
    /// ([`measured_tare_reference`]; no tare when the record is too short).
    pub fn with_tare(self, record: &[f64], decimation: u16) -> Self {
        let measured = measured_tare_reference(record, decimation);
        Self {
            tare_noise_variance: measured.map(|(variance, _)| variance),
            tare_differences: measured.map_or(0, |(_, differences)| differences),
            ..self
        }
    }

    /// The same with the chain's ADC rails as the valid range, for samples with the tare
    /// `zero` (raw units) removed: a code at 0 or at the full-scale code is clipped.
    pub fn with_adc_rails(self, zero: f64) -> Self {
        let top = f64::from(self.chain.adc.max_code());
        Self {
            valid_range: Some((0.5 - zero, top - 0.5 - zero)),
            ..self
        }
    }
}

impl Method {
    /// The arithmetic the method computes in.
    pub fn precision(&self) -> Precision {
        match self {
            Method::Step(setup)
            | Method::Covariance { setup, .. }
            | Method::InstrumentalVariable { setup, .. }
            | Method::BiasCompensated { setup, .. } => setup.precision,
            Method::Ramp(spec) => spec.setup.precision,
            Method::Model(spec) => spec.precision,
            Method::Settled(spec) | Method::Moving(spec) => spec.precision,
            Method::Filtered(spec) => spec.baseline.precision,
        }
    }

    /// The step estimator's configuration, for the step method only.
    pub fn step_setup(&self) -> Option<&Setup> {
        match self {
            Method::Step(setup) => Some(setup),
            _ => None,
        }
    }

    /// The block length a tare measurement must be metered at for this method (the
    /// bias-compensated estimator's `D`; see `estimator_core::NoiseMeter`), `None` for the
    /// methods that take no tare noise.
    pub fn tare_decimation(&self) -> Option<u16> {
        match self {
            Method::BiasCompensated { setup, .. } => Some(setup.decimation),
            _ => None,
        }
    }

    /// The block length a tare must be metered at to be this method's consistency-check
    /// reference (its `D`, or a baseline's block), `None` for none (every method has one).
    pub fn reference_decimation(&self) -> Option<u16> {
        match self {
            Method::Step(setup)
            | Method::Covariance { setup, .. }
            | Method::InstrumentalVariable { setup, .. }
            | Method::BiasCompensated { setup, .. } => Some(setup.decimation),
            Method::Ramp(spec) => Some(spec.setup.decimation),
            Method::Model(spec) => Some(spec.decimation),
            Method::Settled(spec) | Method::Moving(spec) => Some(spec.block),
            Method::Filtered(spec) => Some(spec.baseline.block),
        }
    }

    /// A comma-free name for CSV columns and legends: a step method as the `--config` form
    /// always printed (`n=7 D=12 f32`), the others as their spec with spaces for commas.
    pub fn label(&self) -> String {
        match self {
            Method::Step(setup) => setup.to_string(),
            other => other.to_string().replace(',', " "),
        }
    }

    /// The estimator, over `f64` samples with the tare removed, answering in grams.
    pub fn build(&self, context: &BuildContext) -> Result<BoxedEstimator> {
        let named = |e: anyhow::Error| anyhow!("method `{self}`: {e}");
        Ok(match self.precision() {
            Precision::F64 => self.build_in::<f64>(context).map_err(named)?,
            Precision::F32 => Box::new(InF32(self.build_in::<f32>(context).map_err(named)?)),
        })
    }

    fn build_in<T: Real + Send + 'static>(
        &self,
        context: &BuildContext,
    ) -> Result<Box<dyn Estimator<T> + Send>> {
        let gain = T::from_f64(context.gain);
        let core = |e: estimator_core::ConfigError| anyhow!("{e}");
        let step_config =
            |setup: &Setup, gain: T| referenced(ranged(step_config(setup, gain), context), context);
        let reference = context.noise_reference::<T>();
        Ok(match self {
            Method::Step(setup) => {
                let mut estimator =
                    StepEstimator::<T, CAPACITY, UNCERTAINTY_ORDERS, COLOUR_LAGS>::new(
                        step_config(setup, gain),
                    )
                    .map_err(core)?;
                let autocovariance = context.noise_autocovariance.map(|metered| Autocovariance {
                    lags: metered.lags.map(T::from_f64),
                    blocks: metered.blocks,
                });
                estimator
                    .set_noise_autocovariance(autocovariance.as_ref())
                    .map_err(core)?;
                Box::new(estimator)
            }
            Method::Covariance {
                setup,
                prior_information,
            } => Box::new(
                CovarianceStepEstimator::<T, CAPACITY, { CAPACITY + 1 }>::new(
                    step_config(setup, gain),
                    T::from_f64(*prior_information),
                )
                .map_err(core)?,
            ),
            Method::Ramp(spec) => Box::new(
                RampEstimator::<T, CAPACITY, UNCERTAINTY_ORDERS>::new(RampConfig {
                    regression: step_config(&spec.setup, gain),
                    sample_period_s: T::from_f64(1.0 / context.chain.sample_rate_hz),
                    lag_s: T::from_f64(spec.lag_s),
                })
                .map_err(core)?,
            ),
            Method::InstrumentalVariable { setup, delay } => {
                let mut config = IvConfig::new(step_config(setup, gain));
                if let Some(delay) = delay {
                    config = config.with_instrument_delay(*delay);
                }
                Box::new(
                    IvStepEstimator::<T, CAPACITY, UNCERTAINTY_ORDERS>::new(config)
                        .map_err(core)?,
                )
            }
            Method::BiasCompensated {
                setup,
                noise_variance,
            } => {
                let Some(variance) = noise_variance.or(context.tare_noise_variance) else {
                    bail!("needs the noise variance measured at tare (raw units²), and none was given (`noise_var` in the spec, or `estimate --tare-variance V`)");
                };
                Box::new(
                    BiasCompensatedStepEstimator::<T, CAPACITY, UNCERTAINTY_ORDERS>::new(
                        BiasCompensatedConfig::new(step_config(setup, gain), T::from_f64(variance)),
                    )
                    .map_err(core)?,
                )
            }
            Method::Settled(spec) => baseline(
                spec,
                BaselineMode::SettledAverage,
                gain,
                reference,
                Unfiltered,
            )?,
            Method::Moving(spec) => baseline(
                spec,
                BaselineMode::MovingAverage,
                gain,
                reference,
                Unfiltered,
            )?,
            Method::Filtered(spec) => spec.build(gain, context.chain.sample_rate_hz, reference)?,
            Method::Model(spec) => build_model::<T>(spec, context)?,
        })
    }
}

/// The model-based estimator: a bank around an identified model's resonance, or a bank of
/// the true chain's models around the calibration mass.
fn build_model<T: Real + Send + 'static>(
    spec: &ModelSpec,
    context: &BuildContext,
) -> Result<Box<dyn Estimator<T> + Send>> {
    let reference = context.noise_reference::<T>();
    let colour = context.noise_autocovariance.map(|metered| Autocovariance {
        lags: metered.lags.map(T::from_f64),
        blocks: metered.blocks,
    });
    if let Some(identified) = &spec.identified {
        let model = LoadCellModel {
            natural_frequency_hz: identified.natural_frequency_hz,
            damping_ratio: identified.damping_ratio,
            filter_order: (STATES - 2) as u8,
            filter_cutoff_hz: identified.filter_cutoff_hz,
            counts_per_gram: context.gain,
            sample_rate_hz: context.chain.sample_rate_hz,
        };
        return identified_bank::<T>(&model, spec, reference, colour.as_ref());
    }
    let (valid_min, valid_max) = context
        .valid_range
        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let configs: Vec<ModelConfig<T, STATES>> =
        model_candidates(&context.chain, context.gain, spec)?
            .iter()
            .map(|model| {
                let config = ModelConfig::new(convert_model(model))
                    .with_decimation(spec.decimation)
                    .with_valid_range(T::from_f64(valid_min), T::from_f64(valid_max));
                match reference {
                    Some(reference) => config.with_noise_reference(reference),
                    None => config,
                }
            })
            .collect();
    model_bank::<T>(
        &configs,
        spec.interpolation,
        spec.whitening,
        colour.as_ref(),
    )
}

/// The raw-rate noise variance (raw units²) that `NoiseMeter` measures over an empty-pan
/// `record` (tare removed or not) at block length `decimation`, as the firmware meters it
/// before a weighing; `None` when the record is too short for two differences.
pub fn measured_tare_variance(record: &[f64], decimation: u16) -> Option<f64> {
    measured_tare_reference(record, decimation).map(|(variance, _)| variance)
}

/// [`measured_tare_variance`] and the differences of block means it was metered over (its
/// uncertainty, for the consistency check's [`NoiseReference`]).
pub fn measured_tare_reference(record: &[f64], decimation: u16) -> Option<(f64, u32)> {
    let mut meter = NoiseMeter::<f64>::new(decimation).ok()?;
    for &sample in record {
        meter.push(sample).ok()?;
    }
    Some((meter.noise_variance()?, meter.differences()))
}

/// `config` with the context's consistency-check reference, if it asks for one.
pub(crate) fn referenced<T: Real>(config: StepConfig<T>, context: &BuildContext) -> StepConfig<T> {
    match context.noise_reference() {
        Some(reference) => config.with_noise_reference(reference),
        None => config,
    }
}

/// `config` with the context's valid range, if it has one.
pub(crate) fn ranged<T: Real>(config: StepConfig<T>, context: &BuildContext) -> StepConfig<T> {
    match context.valid_range {
        Some((low, high)) => config.with_valid_range(T::from_f64(low), T::from_f64(high)),
        None => config,
    }
}

pub(crate) fn step_config<T: Real>(setup: &Setup, gain: T) -> StepConfig<T> {
    StepConfig::new(setup.order, gain)
        .with_forgetting(T::from_f64(setup.forgetting))
        .with_decimation(setup.decimation)
}

/// Expands to a `match` over the allowed values of a const generic, one arm each.
macro_rules! dispatch_const {
    ($value:expr, [$($k:literal),*], $what:literal, |$K:ident| $body:expr) => {
        match $value {
            $($k => {
                const $K: usize = $k;
                $body
            })*
            other => bail!("{} {other} is not one of {:?}", $what, [$($k),*]),
        }
    };
}

fn baseline<T: Real + Send + 'static, F: Prefilter<T> + Send + 'static>(
    spec: &BaselineSpec,
    mode: BaselineMode,
    gain: T,
    noise_reference: Option<NoiseReference<T>>,
    prefilter: F,
) -> Result<Box<dyn Estimator<T> + Send>> {
    let config = BaselineConfig {
        mode,
        gain,
        block: spec.block,
        stable_band: T::from_f64(spec.band_g),
        noise_reference,
    };
    let core = |e: estimator_core::ConfigError| anyhow!("{e}");
    Ok(dispatch_const!(
        spec.blocks,
        [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 32],
        "block count K",
        |K| Box::new(Baseline::<T, K, F>::with_prefilter(config, prefilter).map_err(core)?)
    ))
}

fn model_bank<T: Real + Send + 'static>(
    configs: &[ModelConfig<T, STATES>],
    interpolation: Interpolation,
    whitening: usize,
    colour: Option<&Autocovariance<T>>,
) -> Result<Box<dyn Estimator<T> + Send>> {
    Ok(dispatch_const!(
        configs.len(),
        [1, 3, 5, 9, 17, 33, 65],
        "candidate count K",
        |K| {
            let array: [ModelConfig<T, STATES>; K] = core::array::from_fn(|i| configs[i]);
            Box::new(bank_with_options(array, interpolation, whitening, colour)?)
        }
    ))
}

/// The core's physical bank of the spec's candidates over its span from an identified
/// model.
fn identified_bank<T: Real + Send + 'static>(
    model: &LoadCellModel,
    spec: &ModelSpec,
    noise_reference: Option<NoiseReference<T>>,
    colour: Option<&Autocovariance<T>>,
) -> Result<Box<dyn Estimator<T> + Send>> {
    let core = |e: estimator_core::ConfigError| anyhow!("{e}");
    let (span, decimation) = (spec.span, spec.decimation);
    Ok(dispatch_const!(
        spec.candidates,
        [1, 3, 5, 9, 17, 33, 65],
        "candidate count K",
        |K| {
            let configs = model
                .bank_configs::<T, STATES, K>(span.0, span.1, decimation, InitialState::Unknown)
                .map_err(core)?
                .map(|config| match noise_reference {
                    Some(reference) => config.with_noise_reference(reference),
                    None => config,
                });
            Box::new(bank_with_options(
                configs,
                spec.interpolation,
                spec.whitening,
                colour,
            )?)
        }
    ))
}

/// The bank over `configs` with a spec's options: its interpolation, and its whitening with
/// the context's metered colour. A bank asked to whiten (`whiten=P`) that has no metered
/// colour to whiten with (a context without one, as `host-sim estimate`'s, or fewer than
/// `MIN_METERED_BLOCKS` block means) is refused: it would fit coloured noise as white and
/// state an over-confident `u`.
fn bank_with_options<T: Real, const K: usize>(
    configs: [ModelConfig<T, STATES>; K],
    interpolation: Interpolation,
    whitening: usize,
    colour: Option<&Autocovariance<T>>,
) -> Result<ModelBank<T, STATES, K>> {
    let core = |e: estimator_core::ConfigError| anyhow!("{e}");
    let mut bank = ModelBank::new(configs)
        .map_err(core)?
        .with_interpolation(interpolation)
        .with_whitening(whitening)
        .map_err(core)?;
    bank.set_noise_autocovariance(colour).map_err(core)?;
    anyhow::ensure!(
        whitening == 0 || bank.whitens(),
        "whiten={whitening}: no metered noise colour of the empty pan to whiten with here (at least {} block means at the bank's D; `host-sim study coverage` meters one, `host-sim estimate` does not); without it the bank would fit coloured noise as white and state an over-confident u",
        estimator_core::MIN_METERED_BLOCKS
    );
    Ok(bank)
}

fn convert_model<T: Real>(model: &SensorModel<f64, STATES>) -> SensorModel<T, STATES> {
    SensorModel {
        a: model.a.map(|row| row.map(T::from_f64)),
        b: model.b.map(T::from_f64),
        c: model.c.map(T::from_f64),
    }
}

/// The chain as it would be with the resonance at `ratio` times the one it has carrying
/// `calibration_g`, the cell's stiffness and damping unchanged: the moving mass becomes
/// `m/ratio²`, so ω scales by `ratio` and ζ = c·ω/(2k) by `ratio` too. Discretise the result
/// at `calibration_g`. The platform mass may come out negative for ratios above the empty
/// pan's resonance; only the sum (the moving mass) enters the dynamics, and it stays positive.
pub fn candidate_chain(chain: &SensorChain, calibration_g: f64, ratio: f64) -> SensorChain {
    let load_kg = calibration_g.max(0.0) * 1e-3;
    let moving_kg = chain.cell.platform_mass_kg + load_kg;
    let mut candidate = *chain;
    candidate.cell.platform_mass_kg = moving_kg / (ratio * ratio) - load_kg;
    candidate
}

/// The `model` method's candidate models, in raw units (`C` carries the static gain), in
/// the order of [`ModelSpec::ratios`].
pub fn model_candidates(
    chain: &SensorChain,
    gain: f64,
    spec: &ModelSpec,
) -> Result<Vec<SensorModel<f64, STATES>>> {
    if chain.adc.oversampling > 1 {
        bail!("the model of an oversampled ADC (codes summed over conversions) is not built");
    }
    Ok(spec
        .ratios()
        .iter()
        .map(|&ratio| {
            let discrete =
                candidate_chain(chain, spec.calibration_g, ratio).discretise(spec.calibration_g);
            let mut c = [0.0; STATES];
            c[OUTPUT_STATE] = gain;
            SensorModel {
                a: discrete.transition,
                b: discrete.input.map(|row| row[0]),
                c,
            }
        })
        .collect())
}

/// A core estimator computing in `f32` behind the `f64` interface: the sample is rounded to
/// `f32` (after the caller removed the tare in `f64`), the reading widened exactly.
pub(crate) struct InF32(pub(crate) Box<dyn Estimator<f32> + Send>);

/// An `f32` reading as the `f64` interface gives it (exact).
pub(crate) fn widen(reading: Reading<f32>) -> Reading<f64> {
    Reading {
        estimate: reading.estimate.map(f64::from),
        samples: reading.samples,
        state: reading.state,
        residual: reading.residual.map(f64::from),
        uncertainty: reading.uncertainty.map(f64::from),
        degrees_of_freedom: reading.degrees_of_freedom,
    }
}

impl Estimator<f64> for InF32 {
    fn push(&mut self, sample: f64) -> Reading<f64> {
        widen(self.0.push(sample as f32))
    }
    fn push_missing(&mut self) -> Reading<f64> {
        widen(self.0.push_missing())
    }
    fn reset(&mut self) {
        self.0.reset();
    }
}

// ---------------------------------------------------------------------------------------
// The text form.

/// Method names, for error messages.
const METHODS: &str = "step, covariance, model, settled, moving, compensated, shaped, ramp, iv, bc";

/// Every key any method knows, parsed and range-checked; a family then refuses the keys it
/// does not take.
#[derive(Default)]
struct Fields {
    order: Option<usize>,
    decimation: Option<u16>,
    forgetting: Option<f64>,
    precision: Option<Precision>,
    prior: Option<f64>,
    lag_s: Option<f64>,
    count: Option<usize>,
    span: Option<(f64, f64)>,
    interpolation: Option<Interpolation>,
    whitening: Option<usize>,
    calibration_g: Option<f64>,
    block: Option<u16>,
    band_g: Option<f64>,
    noise_variance: Option<f64>,
    natural_frequency_hz: Option<f64>,
    damping_ratio: Option<f64>,
    filter_cutoff_hz: Option<f64>,
    delay: Option<usize>,
    ratio: Option<f64>,
    placed_zeta: Option<f64>,
    shaper: Option<ShaperKind>,
    average: Option<BaselineMode>,
    /// Canonical names of the keys given, in order.
    given: Vec<&'static str>,
}

fn positive_finite(value: f64) -> bool {
    value.is_finite() && value > 0.0
}

/// `value` as a `T` that passes `within`; otherwise `bad(expected)`.
fn checked<T: FromStr + Copy>(
    value: &str,
    expected: &str,
    within: impl Fn(T) -> bool,
    bad: &dyn Fn(&str) -> anyhow::Error,
) -> Result<T> {
    let number: T = value.parse().map_err(|_| bad(expected))?;
    if !within(number) {
        return Err(bad(expected));
    }
    Ok(number)
}

/// A span of resonance ratios `low-high`, `0 < low < high`.
fn span(value: &str, bad: &dyn Fn(&str) -> anyhow::Error) -> Result<(f64, f64)> {
    let expected = "two resonance ratios low-high, 0 < low < high (e.g. 0.7-1.3)";
    let (low, high) = value.split_once('-').ok_or_else(|| bad(expected))?;
    let low: f64 = low.trim().parse().map_err(|_| bad(expected))?;
    let high: f64 = high.trim().parse().map_err(|_| bad(expected))?;
    if !(positive_finite(low) && positive_finite(high) && low < high) {
        return Err(bad(expected));
    }
    Ok((low, high))
}

impl Fields {
    fn parse(spec: &str, params: &str) -> Result<Self> {
        let mut fields = Fields::default();
        if params.trim().is_empty() {
            return Ok(fields);
        }
        for part in params.split(',') {
            let Some((key, value)) = part.split_once('=') else {
                bail!("method `{spec}`: expected key=value, found `{part}`");
            };
            let (key, value) = (key.trim(), value.trim());
            let canonical = fields.set(spec, key, value)?;
            if fields.given.contains(&canonical) {
                bail!("method `{spec}`: key `{key}` given twice");
            }
            fields.given.push(canonical);
        }
        Ok(fields)
    }

    /// Set `key` from its text; the key's canonical name.
    fn set(&mut self, spec: &str, key: &str, value: &str) -> Result<&'static str> {
        let bad = |expected: &str| {
            anyhow!("method `{spec}`: key `{key}`: expected {expected}, found `{value}`")
        };
        if let Some((slot, canonical, expected)) = self.positive_slot(key) {
            *slot = Some(checked(value, expected, positive_finite, &bad)?);
            return Ok(canonical);
        }
        Ok(match key {
            "n" | "order" => {
                let expected = format!("an order from 1 to {CAPACITY}");
                let order = checked(value, &expected, |n| (1..=CAPACITY).contains(&n), &bad)?;
                self.order = Some(order);
                "n"
            }
            "D" | "d" | "decimation" => {
                let expected = format!("a decimation from 1 to {MAX_DECIMATION}");
                let within = |d| (1..=MAX_DECIMATION).contains(&d);
                self.decimation = Some(checked(value, &expected, within, &bad)?);
                "D"
            }
            "lambda" | "forgetting" => {
                let expected = "a forgetting factor in (0, 1]";
                let within = |lambda: f64| lambda > 0.0 && lambda <= 1.0;
                self.forgetting = Some(checked(value, expected, within, &bad)?);
                "lambda"
            }
            "precision" => {
                self.precision = Some(value.parse().map_err(|_| bad("f32 or f64"))?);
                "precision"
            }
            "lag_s" => {
                let expected = "the ramp lag in seconds, a finite number";
                self.lag_s = Some(checked(value, expected, f64::is_finite, &bad)?);
                "lag_s"
            }
            "K" | "k" => {
                self.count = Some(value.parse().map_err(|_| bad("a whole number"))?);
                "K"
            }
            "span" => {
                self.span = Some(span(value, &bad)?);
                "span"
            }
            "interp" => {
                self.interpolation = Some(
                    value
                        .parse()
                        .ok()
                        .and_then(Interpolation::with_points)
                        .ok_or_else(|| bad("3 or 5 (the candidates interpolated through)"))?,
                );
                "interp"
            }
            "whiten" => {
                let expected = format!(
                    "the whitening filter's order, 0 to {}",
                    estimator_core::WHITENING_ORDER
                );
                let within = |order: usize| order <= estimator_core::WHITENING_ORDER;
                self.whitening = Some(checked(value, &expected, within, &bad)?);
                "whiten"
            }
            "block" => {
                let expected = "raw samples per block, 1 to 65535";
                self.block = Some(checked(value, expected, |block| block != 0, &bad)?);
                "block"
            }
            "noise_var" => {
                let expected =
                    "the raw-sample noise variance in raw units², finite and not negative";
                let within = |variance: f64| variance.is_finite() && variance >= 0.0;
                self.noise_variance = Some(checked(value, expected, within, &bad)?);
                "noise_var"
            }
            "delay" => {
                let expected = "an instrument delay in decimated rows, at least n + 1";
                self.delay = Some(value.parse().map_err(|_| bad(expected))?);
                "delay"
            }
            "shaper" => {
                let kinds = [ShaperKind::Zv, ShaperKind::Zvd, ShaperKind::Zvdd];
                let kind = kinds
                    .into_iter()
                    .find(|&k| filtered::shaper_name(k) == value);
                self.shaper = Some(kind.ok_or_else(|| bad("zv, zvd or zvdd"))?);
                "shaper"
            }
            "average" => {
                let modes = [BaselineMode::MovingAverage, BaselineMode::SettledAverage];
                let mode = modes
                    .into_iter()
                    .find(|&m| filtered::average_name(m) == value);
                self.average = Some(mode.ok_or_else(|| bad("moving or settled"))?);
                "average"
            }
            other => bail!("method `{spec}`: unknown key `{other}`"),
        })
    }

    /// The keys that take a positive, finite number: the field, the canonical name and what
    /// is expected.
    fn positive_slot(
        &mut self,
        key: &str,
    ) -> Option<(&mut Option<f64>, &'static str, &'static str)> {
        Some(match key {
            "prior" => (
                &mut self.prior,
                "prior",
                "a positive prior information δ (Ψ(0) = I/δ)",
            ),
            "cal_g" => (
                &mut self.calibration_g,
                "cal_g",
                "the calibration mass in grams, positive",
            ),
            "band_g" => (
                &mut self.band_g,
                "band_g",
                "the stability band in grams, positive",
            ),
            "fn_hz" => (
                &mut self.natural_frequency_hz,
                "fn_hz",
                "the identified natural frequency in Hz, positive",
            ),
            "zeta" => (
                &mut self.damping_ratio,
                "zeta",
                "the identified damping ratio, positive",
            ),
            "filter_hz" => (
                &mut self.filter_cutoff_hz,
                "filter_hz",
                "the filter cut-off in Hz, positive",
            ),
            "ratio" => (
                &mut self.ratio,
                "ratio",
                "the placed pair's frequency over the cell's, positive",
            ),
            "placed_zeta" => (
                &mut self.placed_zeta,
                "placed_zeta",
                "the placed pair's damping ratio, positive",
            ),
            _ => return None,
        })
    }

    /// Refuse any key outside `allowed`, naming the method's keys.
    fn only(&self, spec: &str, family: &str, allowed: &[&str]) -> Result<()> {
        if let Some(key) = self.given.iter().find(|k| !allowed.contains(k)) {
            bail!(
                "method `{spec}`: key `{key}` does not apply to `{family}` (expected {})",
                allowed.join(", ")
            );
        }
        Ok(())
    }

    fn setup(&self, spec: &str, family: &str) -> Result<Setup> {
        let Some(order) = self.order else {
            bail!("method `{spec}`: key `n` is required for `{family}` (expected an order from 1 to {CAPACITY})");
        };
        Ok(Setup {
            order,
            decimation: self.decimation.unwrap_or(1),
            forgetting: self.forgetting.unwrap_or(1.0),
            precision: self.precision.unwrap_or(Precision::F64),
        })
    }

    /// `model`: the bank (or one model) around the calibration, or an identified model.
    fn model(&self, spec: &str, family: &str) -> Result<ModelSpec> {
        self.only(
            spec,
            family,
            &[
                "D",
                "K",
                "span",
                "interp",
                "whiten",
                "cal_g",
                "precision",
                "fn_hz",
                "zeta",
                "filter_hz",
            ],
        )?;
        let default = ModelSpec::default();
        let candidates = self.count.unwrap_or(default.candidates);
        if !MODEL_CANDIDATES.contains(&candidates) {
            bail!("method `{spec}`: key `K`: expected one of {MODEL_CANDIDATES:?} (candidate models), found `{candidates}`");
        }
        let identified = match (self.natural_frequency_hz, self.damping_ratio) {
            (Some(natural_frequency_hz), Some(damping_ratio)) => {
                if self.calibration_g.is_some() {
                    bail!("method `{spec}`: key `cal_g` does not apply to an identified model (fn_hz, zeta): it is the true model's calibration mass");
                }
                Some(IdentifiedModel {
                    natural_frequency_hz,
                    damping_ratio,
                    filter_cutoff_hz: self
                        .filter_cutoff_hz
                        .unwrap_or(crate::sensor::SensorChain::reference().filter_cutoff_hz),
                })
            }
            (None, None) if self.filter_cutoff_hz.is_none() => None,
            _ => bail!("method `{spec}`: keys `fn_hz` and `zeta` go together (the identified model; `filter_hz` only with them)"),
        };
        Ok(ModelSpec {
            decimation: self.decimation.unwrap_or(default.decimation),
            candidates,
            span: self.span.unwrap_or(default.span),
            calibration_g: self.calibration_g.unwrap_or(default.calibration_g),
            precision: self.precision.unwrap_or(default.precision),
            identified,
            interpolation: self.interpolation.unwrap_or(default.interpolation),
            whitening: self.whitening.unwrap_or(default.whitening),
        })
    }

    /// `iv`: the step regression with delayed instruments, the delay within the core's range.
    fn instrumental_variable(&self, spec: &str, family: &str) -> Result<Method> {
        self.only(spec, family, &["n", "D", "lambda", "precision", "delay"])?;
        let setup = self.setup(spec, family)?;
        if let Some(delay) = self.delay {
            // The core's range (iv.rs): no shared noise sample from n + 1 rows on; the
            // history ring bounds it above.
            let (low, high) = (setup.order + 1, max_instrument_delay(CAPACITY, setup.order));
            if !(low..=high).contains(&delay) {
                bail!("method `{spec}`: key `delay`: expected an instrument delay from {low} (n + 1) to {high} decimated rows, found `{delay}`");
            }
        }
        Ok(Method::InstrumentalVariable {
            setup,
            delay: self.delay,
        })
    }

    /// `compensated` and `shaped`: the cell's mode, the filter, the averaging and a baseline.
    fn filtered(&self, spec: &str, family: &str) -> Result<FilteredSpec> {
        let filter_keys: &[&str] = if family == "compensated" {
            &["ratio", "placed_zeta"]
        } else {
            &["shaper"]
        };
        let mut allowed = vec!["fn_hz", "zeta", "average"];
        allowed.extend_from_slice(filter_keys);
        allowed.extend_from_slice(&BASELINE_KEYS);
        self.only(spec, family, &allowed)?;
        let (Some(natural_frequency_hz), Some(damping_ratio)) =
            (self.natural_frequency_hz, self.damping_ratio)
        else {
            bail!("method `{spec}`: keys `fn_hz` and `zeta` are required for `{family}` (the cell's mode the filter is tuned to)");
        };
        let filter = if family == "compensated" {
            Prefiltering::Compensation {
                ratio: self.ratio.unwrap_or(2.0),
                placed_zeta: self.placed_zeta.unwrap_or(1.0),
            }
        } else {
            Prefiltering::Shaper(self.shaper.unwrap_or(ShaperKind::Zvd))
        };
        Ok(FilteredSpec {
            natural_frequency_hz,
            damping_ratio,
            filter,
            average: self.average.unwrap_or(BaselineMode::MovingAverage),
            baseline: self.baseline_fields(spec)?,
        })
    }

    fn baseline(&self, spec: &str, family: &str) -> Result<BaselineSpec> {
        self.only(spec, family, &BASELINE_KEYS)?;
        self.baseline_fields(spec)
    }

    /// The block, K, band and precision of any baseline.
    fn baseline_fields(&self, spec: &str) -> Result<BaselineSpec> {
        let default = BaselineSpec::default();
        let blocks = self.count.unwrap_or(default.blocks);
        if !BASELINE_BLOCKS.contains(&blocks) {
            bail!("method `{spec}`: key `K`: expected one of {BASELINE_BLOCKS:?} (block means kept), found `{blocks}`");
        }
        Ok(BaselineSpec {
            block: self.block.unwrap_or(default.block),
            blocks,
            band_g: self.band_g.unwrap_or(default.band_g),
            precision: self.precision.unwrap_or(default.precision),
        })
    }
}

impl FromStr for Method {
    type Err = anyhow::Error;

    /// Parse a spec (see the module docs); a spec without `name:` is a step configuration.
    fn from_str(spec: &str) -> Result<Self> {
        let spec = spec.trim();
        let (family, params) = match spec.split_once(':') {
            Some((family, params)) => (family.trim(), params),
            // A bare name (`model`, `settled`) takes every default; bare keys are a step.
            None if !spec.contains('=') => (spec, ""),
            None => ("step", spec),
        };
        if ![
            "step",
            "covariance",
            "model",
            "settled",
            "moving",
            "compensated",
            "shaped",
            "ramp",
            "iv",
            "bc",
        ]
        .contains(&family)
        {
            bail!("method `{spec}`: unknown method `{family}` (expected one of {METHODS})");
        }
        let fields = Fields::parse(spec, params)?;
        let step_keys = ["n", "D", "lambda", "precision"];
        Ok(match family {
            "step" => {
                fields.only(spec, family, &step_keys)?;
                Method::Step(fields.setup(spec, family)?)
            }
            "covariance" => {
                fields.only(spec, family, &["n", "D", "lambda", "precision", "prior"])?;
                Method::Covariance {
                    setup: fields.setup(spec, family)?,
                    prior_information: fields.prior.unwrap_or(DEFAULT_PRIOR_INFORMATION),
                }
            }
            "ramp" => {
                fields.only(spec, family, &["n", "D", "lambda", "precision", "lag_s"])?;
                Method::Ramp(RampSpec {
                    setup: fields.setup(spec, family)?,
                    lag_s: fields.lag_s.unwrap_or(0.0),
                })
            }
            "bc" => {
                fields.only(
                    spec,
                    family,
                    &["n", "D", "lambda", "precision", "noise_var"],
                )?;
                Method::BiasCompensated {
                    setup: fields.setup(spec, family)?,
                    noise_variance: fields.noise_variance,
                }
            }
            "model" => Method::Model(fields.model(spec, family)?),
            "iv" => fields.instrumental_variable(spec, family)?,
            "settled" => Method::Settled(fields.baseline(spec, family)?),
            "moving" => Method::Moving(fields.baseline(spec, family)?),
            "compensated" | "shaped" => Method::Filtered(fields.filtered(spec, family)?),
            _ => unreachable!("family checked above"),
        })
    }
}

fn write_setup(f: &mut fmt::Formatter<'_>, setup: &Setup) -> fmt::Result {
    write!(f, "n={},D={}", setup.order, setup.decimation)?;
    if setup.forgetting != 1.0 {
        write!(f, ",lambda={}", setup.forgetting)?;
    }
    write_precision(f, setup.precision)
}

fn write_precision(f: &mut fmt::Formatter<'_>, precision: Precision) -> fmt::Result {
    match precision {
        Precision::F32 => f.write_str(",precision=f32"),
        Precision::F64 => Ok(()),
    }
}

impl fmt::Display for Method {
    /// The spec, every parameter that differs from its default written out; it parses back
    /// to the same method.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Method::Step(setup) => {
                f.write_str("step:")?;
                write_setup(f, setup)
            }
            Method::Covariance {
                setup,
                prior_information,
            } => {
                f.write_str("covariance:")?;
                write_setup(f, setup)?;
                if *prior_information != DEFAULT_PRIOR_INFORMATION {
                    write!(f, ",prior={prior_information}")?;
                }
                Ok(())
            }
            Method::Ramp(spec) => {
                f.write_str("ramp:")?;
                write_setup(f, &spec.setup)?;
                if spec.lag_s != 0.0 {
                    write!(f, ",lag_s={}", spec.lag_s)?;
                }
                Ok(())
            }
            Method::InstrumentalVariable { setup, delay } => {
                f.write_str("iv:")?;
                write_setup(f, setup)?;
                if let Some(delay) = delay {
                    write!(f, ",delay={delay}")?;
                }
                Ok(())
            }
            Method::Model(spec) => {
                write!(
                    f,
                    "model:D={},K={},span={}-{}",
                    spec.decimation, spec.candidates, spec.span.0, spec.span.1
                )?;
                match spec.identified {
                    Some(identified) => {
                        write!(
                            f,
                            ",fn_hz={},zeta={}",
                            identified.natural_frequency_hz, identified.damping_ratio
                        )?;
                        if identified.filter_cutoff_hz
                            != crate::sensor::SensorChain::reference().filter_cutoff_hz
                        {
                            write!(f, ",filter_hz={}", identified.filter_cutoff_hz)?;
                        }
                    }
                    None => write!(f, ",cal_g={}", spec.calibration_g)?,
                }
                if spec.interpolation != Interpolation::default() {
                    write!(f, ",interp={}", spec.interpolation.points())?;
                }
                if spec.whitening > 0 {
                    write!(f, ",whiten={}", spec.whitening)?;
                }
                write_precision(f, spec.precision)
            }
            Method::BiasCompensated {
                setup,
                noise_variance,
            } => {
                f.write_str("bc:")?;
                write_setup(f, setup)?;
                if let Some(variance) = noise_variance {
                    write!(f, ",noise_var={variance}")?;
                }
                Ok(())
            }
            Method::Settled(spec) | Method::Moving(spec) => {
                let family = if matches!(self, Method::Settled(_)) {
                    "settled"
                } else {
                    "moving"
                };
                write!(f, "{family}:")?;
                spec.write_fields(f)
            }
            Method::Filtered(spec) => spec.fmt(f),
        }
    }
}

impl From<Setup> for Method {
    fn from(setup: Setup) -> Self {
        Method::Step(setup)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(spec: &str) -> Method {
        spec.parse()
            .unwrap_or_else(|e| panic!("`{spec}` should parse: {e}"))
    }

    fn error(spec: &str) -> String {
        match spec.parse::<Method>() {
            Ok(method) => panic!("`{spec}` should be refused, parsed as {method:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn specs_round_trip_through_their_text() {
        for spec in [
            "step:n=7,D=16",
            "step:n=7,D=16,lambda=0.999,precision=f32",
            "covariance:n=7,D=16,precision=f32",
            "covariance:n=3,D=1,prior=0.001",
            "model:D=8,K=33,span=0.7-1.3,cal_g=200",
            "model:D=4,K=9,span=0.85-1.15,cal_g=138.32,precision=f32",
            "settled:block=80,K=10,band_g=0.2",
            "moving:block=40,K=20,band_g=0.05,precision=f32",
            "ramp:n=5,D=16,lag_s=0.0125",
            "iv:n=4,D=12,precision=f32",
            "bc:n=3,D=16,noise_var=1049.25",
            "bc:n=3,D=16,lambda=0.99",
            "model:D=8,K=33,span=0.68-1.3,fn_hz=25.00031,zeta=0.030001",
            "model:D=8,K=65,span=0.84-1.15,fn_hz=25,zeta=0.03,interp=5,precision=f32",
            "model:D=8,K=33,span=0.7-1.3,cal_g=200,interp=5",
            "model:D=8,K=33,span=0.68-1.3,fn_hz=25,zeta=0.03,interp=5,whiten=32,precision=f32",
            "model:D=4,K=9,span=0.9-1.1,fn_hz=20,zeta=0.05,filter_hz=50,precision=f32",
            "iv:n=7,D=16",
            "iv:n=5,D=1,lambda=0.999,precision=f32,delay=11",
            "bc:n=7,D=12,precision=f32",
            "compensated:fn_hz=25,zeta=0.03,ratio=2,placed_zeta=1,average=moving,block=80,K=10,band_g=0.5",
            "shaped:fn_hz=25.000156487736767,zeta=0.0300060250982748,shaper=zvdd,average=settled,block=40,K=4,band_g=0.2,precision=f32",
        ] {
            let method = parse(spec);
            assert_eq!(method.to_string(), spec);
            assert_eq!(parse(&method.to_string()), method);
        }
    }

    #[test]
    fn the_bare_step_form_and_defaults() {
        assert_eq!(parse("n=7,D=16"), Method::Step(Setup::new(7, 16)));
        assert_eq!(parse("step:order=7,decimation=16"), parse("n=7,D=16"));
        assert_eq!(parse("model"), Method::Model(ModelSpec::default()));
        assert_eq!(parse("settled"), Method::Settled(BaselineSpec::default()));
        assert_eq!(parse("moving:"), Method::Moving(BaselineSpec::default()));
        assert_eq!(
            parse("covariance:n=7"),
            Method::Covariance {
                setup: Setup::new(7, 1),
                prior_information: DEFAULT_PRIOR_INFORMATION
            }
        );
        // The label keeps the `--config` form of the CSV columns.
        assert_eq!(parse("n=7,D=12").label(), "n=7 D=12");
        assert_eq!(parse("settled").label(), "settled:block=80 K=10 band_g=0.5");
    }

    #[test]
    fn bad_specs_name_the_spec_the_key_and_what_was_expected() {
        let cases = [
            ("kalman:n=3", ["kalman", "expected one of step"]),
            ("step:n=7,D=0", ["`D`", "decimation from 1 to 1024"]),
            ("step:D=16", ["`n` is required", "order from 1 to 40"]),
            ("step:n=41", ["`n`", "order from 1 to 40"]),
            ("step:n=7,lambda=1.5", ["`lambda`", "(0, 1]"]),
            ("step:n=7,precision=f16", ["`precision`", "f32 or f64"]),
            ("step:n=7,K=3", ["`K`", "expected n, D, lambda, precision"]),
            ("model:K=4", ["`K`", "[1, 3, 5, 9, 17, 33, 65]"]),
            ("model:span=1.3-0.7", ["`span`", "0 < low < high"]),
            (
                "model:n=7",
                [
                    "`n`",
                    "expected D, K, span, interp, whiten, cal_g, precision",
                ],
            ),
            ("model:D=8,interp=4", ["`interp`", "3 or 5"]),
            ("model:D=8,whiten=33", ["`whiten`", "0 to 32"]),
            ("settled:band_g=-1", ["`band_g`", "positive"]),
            ("moving:K=7", ["`K`", "block means kept"]),
            ("step:n=7,n=5", ["`n`", "twice"]),
            ("step:n=7,foo=1", ["`foo`", "unknown key"]),
            ("step:n=7,D", ["key=value", "`D`"]),
            ("model:fn_hz=25", ["`fn_hz` and `zeta`", "go together"]),
            (
                "model:fn_hz=25,zeta=0.03,cal_g=200",
                ["`cal_g`", "does not apply"],
            ),
            ("model:fn_hz=-1,zeta=0.03", ["`fn_hz`", "positive"]),
            ("bc:n=3,noise_var=-1", ["`noise_var`", "not negative"]),
            (
                "iv:n=3,noise_var=1",
                ["`noise_var`", "expected n, D, lambda, precision"],
            ),
            ("iv:n=7,D=16,delay=7", ["`delay`", "from 8 (n + 1) to 153"]),
            ("iv:n=7,delay=x", ["`delay`", "at least n + 1"]),
            (
                "bc:n=7,delay=9",
                ["`delay`", "expected n, D, lambda, precision"],
            ),
            ("iv:D=16", ["`n` is required", "order from 1 to 40"]),
            (
                "shaped:zeta=0.03",
                ["`fn_hz` and `zeta` are required", "tuned"],
            ),
            (
                "shaped:fn_hz=25,zeta=0.03,shaper=zz",
                ["`shaper`", "zv, zvd or zvdd"],
            ),
            (
                "compensated:fn_hz=25,zeta=0.03,shaper=zv",
                ["`shaper`", "does not apply"],
            ),
            (
                "compensated:fn_hz=25,zeta=0.03,average=boxcar",
                ["`average`", "moving or settled"],
            ),
            (
                "compensated:fn_hz=25,zeta=0.03,ratio=0",
                ["`ratio`", "positive"],
            ),
        ];
        for (spec, needles) in cases {
            let message = error(spec);
            assert!(message.contains(&format!("`{spec}`")), "{message}");
            for needle in needles {
                assert!(message.contains(needle), "{spec}: {message}");
            }
        }
    }

    #[test]
    fn every_listed_size_builds_in_both_precisions() {
        // The const-generic sizes are listed twice (the constants for parsing, the
        // dispatch macro for building): every listed value must build.
        let context = BuildContext::new(SensorChain::reference(), 73.25);
        for precision in ["f64", "f32"] {
            for k in MODEL_CANDIDATES {
                let spec = format!("model:K={k},precision={precision}");
                let built = parse(&spec).build(&context);
                assert!(built.is_ok(), "{spec}: {:?}", built.err());
            }
            for k in BASELINE_BLOCKS {
                for family in [
                    "moving:",
                    "compensated:fn_hz=25,zeta=0.03,",
                    "shaped:fn_hz=25,zeta=0.03,",
                ] {
                    let spec = format!("{family}K={k},precision={precision}");
                    let built = parse(&spec).build(&context);
                    assert!(built.is_ok(), "{spec}: {:?}", built.err());
                }
            }
        }
        // A mode the core's filters refuse is an error naming the method and the field.
        for spec in [
            "compensated:fn_hz=25,zeta=1.5",
            "shaped:fn_hz=2500,zeta=0.03",
        ] {
            let message = parse(spec).build(&context).err().unwrap().to_string();
            assert!(
                message.contains(spec) && message.contains("pre-filter field"),
                "{message}"
            );
        }
        // A value the core refuses is an error naming the method, not a panic.
        let zero_gain = BuildContext::new(SensorChain::reference(), 0.0);
        let message = parse("step:n=3")
            .build(&zero_gain)
            .err()
            .unwrap()
            .to_string();
        assert!(
            message.contains("step:n=3,D=1") && message.contains("gain"),
            "{message}"
        );
    }

    #[test]
    fn a_bank_asked_to_whiten_needs_a_metered_colour() {
        use estimator_core::{AutocovarianceMeter, MIN_METERED_BLOCKS};
        let context = BuildContext::new(SensorChain::reference(), 73.25);
        for spec in [
            "model:D=8,K=33,interp=5,whiten=32",
            "model:D=8,K=33,span=0.68-1.3,fn_hz=25,zeta=0.03,whiten=8",
        ] {
            // None in the context (as `host-sim estimate` builds it): refused, by name.
            let message = parse(spec).build(&context).err().unwrap().to_string();
            assert!(
                message.contains("whiten=") && message.contains("over-confident"),
                "{spec}: {message}"
            );
            // A colour metered over too few block means: refused too.
            // AR(1) noise from a linear congruential generator.
            let (mut meter, mut state, mut noise) =
                (AutocovarianceMeter::<f64>::new(8).unwrap(), 1u64, 0.0);
            let mut blocks = |meter: &mut AutocovarianceMeter<f64>, count: u32| {
                for _ in 0..count * 8 {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    noise = 0.5 * noise + (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                    meter.push(noise).unwrap();
                }
            };
            blocks(&mut meter, MIN_METERED_BLOCKS / 2);
            let short = context.with_noise_autocovariance(meter.sums().autocovariance());
            assert!(parse(spec).build(&short).is_err(), "{spec}");
            // Enough of it: built, and whitening.
            blocks(&mut meter, MIN_METERED_BLOCKS);
            let metered = context.with_noise_autocovariance(meter.sums().autocovariance());
            let built = parse(spec).build(&metered);
            assert!(built.is_ok(), "{spec}: {:?}", built.err());
        }
        // Without whitening nothing is asked of the context.
        assert!(parse("model:D=8,K=33,interp=5").build(&context).is_ok());
    }

    #[test]
    fn bc_needs_the_tare_variance_and_iv_takes_its_delay() {
        let mut context = BuildContext::new(SensorChain::reference(), 73.25);
        let message = parse("bc:n=7,D=16")
            .build(&context)
            .err()
            .unwrap()
            .to_string();
        assert!(
            message.contains("bc:n=7,D=16") && message.contains("tare"),
            "{message}"
        );
        context.tare_noise_variance = Some(1000.0);
        for spec in [
            "bc:n=7,D=16",
            "bc:n=40,D=1,precision=f32",
            "iv:n=7,D=16",
            "iv:n=7,D=1,delay=153",
        ] {
            let built = parse(spec).build(&context);
            assert!(built.is_ok(), "{spec}: {:?}", built.err());
        }
        // The core refuses a negative variance; the error names the method.
        context.tare_noise_variance = Some(-1.0);
        assert!(parse("bc:n=7").build(&context).is_err());
        assert_eq!(parse("bc:n=7").tare_decimation(), Some(1));
        assert_eq!(parse("iv:n=7,D=16").tare_decimation(), None);
    }

    #[test]
    fn candidates_follow_the_physics_of_a_changed_load() {
        // A candidate must be exactly the chain carrying another load: same k and c, so
        // ω ∝ 1/√m and ζ ∝ ω.
        let chain = SensorChain::reference();
        let spec = ModelSpec::default();
        let calibrated_omega = chain.cell.natural_frequency_rad_s(spec.calibration_g);
        let calibrated_zeta = chain.cell.damping_ratio(spec.calibration_g);
        for ratio in spec.ratios() {
            let candidate = candidate_chain(&chain, spec.calibration_g, ratio);
            let omega = candidate.cell.natural_frequency_rad_s(spec.calibration_g);
            let zeta = candidate.cell.damping_ratio(spec.calibration_g);
            assert!((omega / calibrated_omega / ratio - 1.0).abs() < 1e-12);
            assert!((zeta / calibrated_zeta / ratio - 1.0).abs() < 1e-12);
        }
        // Independently of the cell's formulas: the discrete models' mechanical poles
        // (z = e^{s·h}, the lightly damped pair) give ω = |s| and ζ = −Re(s)/|s|, and the
        // static gain C(I − A)⁻¹B is the gain asked for. 1e-9: the matrix exponential and
        // the eigen-solver are accurate to ~1e-12 here; a wrong law (ζ ∝ 1/r) is 30% off.
        let gain = 73.25;
        let rate = chain.sample_rate_hz;
        for (ratio, model) in spec
            .ratios()
            .iter()
            .zip(model_candidates(&chain, gain, &spec).unwrap())
            .step_by(8)
        {
            let a = nalgebra::SMatrix::<f64, 5, 5>::from_fn(|i, j| model.a[i][j]);
            let mechanical = a
                .complex_eigenvalues()
                .iter()
                .map(|z| z.ln() * rate)
                .filter(|s| s.im > 0.0)
                .min_by(|x, y| (-x.re / x.norm()).total_cmp(&(-y.re / y.norm())))
                .unwrap();
            let omega = mechanical.norm();
            let zeta = -mechanical.re / omega;
            assert!(
                (omega / calibrated_omega / ratio - 1.0).abs() < 1e-9,
                "{ratio}: ω {omega}"
            );
            assert!(
                (zeta / calibrated_zeta / ratio - 1.0).abs() < 1e-9,
                "{ratio}: ζ {zeta}"
            );
            let b = nalgebra::SVector::<f64, 5>::from_column_slice(&model.b);
            let c = nalgebra::SVector::<f64, 5>::from_column_slice(&model.c);
            let static_gain = c.dot(&((nalgebra::SMatrix::identity() - a).lu().solve(&b).unwrap()));
            assert!((static_gain / gain - 1.0).abs() < 1e-9, "{static_gain}");
        }
        // The ratio that the reference scene's load gives sits inside the default span.
        let truth = chain.cell.natural_frequency_rad_s(138.32) / calibrated_omega;
        assert!((1.10..1.12).contains(&truth), "{truth}");
        let ratios = spec.ratios();
        assert!(ratios[0] == 0.7 && (ratios[32] - 1.3).abs() < 1e-12);
    }
}
