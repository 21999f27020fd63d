//! The configured method as one estimator: the enum the scale runs.

use crate::estimators::bias_compensated::{BiasCompensatedConfig, BiasCompensatedStepEstimator};
use crate::estimators::consistency::NoiseReference;
use crate::estimators::iv::{IvConfig, IvStepEstimator};
use crate::estimators::model::{
    InitialState, Interpolation, ModelBank, ModelConfig, WHITENING_ORDER,
};
use crate::estimators::noise_meter::Autocovariance;
use crate::estimators::step::{StepConfig, StepEstimator};
use crate::numerics::real::Real;
use crate::reading::{ConfigError, Estimator, Reading};
use crate::sensor::LoadCellModel;

use super::{WeighingConfig, WeighingMethod};

/// The configured step method states its uncertainty up to this order (the lag sums take
/// `6L² + 3L` numbers: 1.6 KB in f32 at 8); tuning's orders above it read with no `u`, which
/// the scale never shows stable. Instrumental variables and bias compensation are built
/// without lag sums: on the load cell neither could state a `u` (weak instruments; a
/// compensation never resolved five times over, `estimators::iv_uncertainty`,
/// `bc_uncertainty`), and the sums would cost IV a third more per sample (`cargo xtask
/// bench iv` with them built in: 1,299 against 970 instructions at n = 5, D = 24) and each
/// 3 KB, for readings the scale shows as estimating either way.
pub const UNCERTAINTY_ORDERS: usize = 8;

/// The lags over which the configured step method's `u` rests on the empty pan's metered
/// noise colour ([`StepEstimator`]'s `C`, `crate::estimators::metered_noise`): three times
/// the lags it keeps (144 ms at D = 24), what `host-sim study coverage --runs 1000 --seed 1`
/// measured in the rig's noise, whose vibration near the resonance stays correlated for
/// longer than a drop's first rows: 8 lags under-covered it; with 16, ±2u held 92.6–93.9 %
/// 200–400 ms after the landing at 60–70 dB (RMS error/u up to 1.11); with 24, 94.2–97.1 %
/// (RMS at most 1.02); 40 did no better. The meter keeps the order's lags beyond them
/// ([`crate::AUTOCOVARIANCE_LAGS`] = 32).
pub const COLOUR_LAGS: usize = 3 * UNCERTAINTY_ORDERS;

/// The largest data-driven order a board's estimator is built to hold whatever its
/// configured method: a method uploaded over the console up to this order runs without a
/// rebuild, and states its `u` ([`UNCERTAINTY_ORDERS`]).
pub const UPLOAD_ORDER_CAPACITY: usize = UNCERTAINTY_ORDERS;

/// The configured method as one estimator over samples with the zero removed, answering in
/// grams. Capacity `N` for the data-driven methods, `S` states and `K` candidates for the
/// bank (`K` must equal the configured candidate count).
#[derive(Clone, Debug)]
// One per scale, built once: the bank variant's size is the point of choosing a smaller one.
#[allow(clippy::large_enum_variant)]
// The tag a byte of its own, the bank's 0: [`Self::UNCONFIGURED`] is then zero bits by
// construction, not by where the niche layout would put the tag, so a board's `static` of
// it is in `.bss` whichever variant is the largest.
#[repr(u8)]
pub enum WeighingEstimator<T: Real, const N: usize, const S: usize, const K: usize> {
    /// [`WeighingMethod::Step`].
    Step(StepEstimator<T, N, UNCERTAINTY_ORDERS, COLOUR_LAGS>) = 1,
    /// [`WeighingMethod::BiasCompensated`].
    BiasCompensated(BiasCompensatedStepEstimator<T, N>) = 2,
    /// [`WeighingMethod::InstrumentalVariable`].
    InstrumentalVariable(IvStepEstimator<T, N>) = 3,
    /// [`WeighingMethod::ModelBank`].
    ModelBank(ModelBank<T, S, K>) = 0,
}

impl<T: Real, const N: usize, const S: usize, const K: usize> WeighingEstimator<T, N, S, K> {
    /// The configured method for samples `code − zero_counts`; codes at or beyond the
    /// config's rails (`onset.rail_low`, `onset.rail_high`) are flagged `OutOfRange`.
    ///
    /// A configuration outside the valid region ([`WeighingConfig::check_region`], which
    /// says why) is refused as [`ConfigError::OutsideValidRegion`].
    pub fn new(config: &WeighingConfig, zero_counts: f64) -> Result<Self, ConfigError> {
        config
            .check_region()
            .map_err(|_| ConfigError::OutsideValidRegion)?;
        Self::with_method(config, &config.method, zero_counts)
    }

    /// The configured method as a scale runs it ([`crate::weighing::ScaleEstimator`]): for
    /// samples in counts with the zero removed, answering in counts (gain 1, so a new
    /// calibration of the scale does not rebuild it), with no range limit (the scale's ADC
    /// flags its rails as saturated samples itself, and its zero moves with tracking). The
    /// bias-compensated method keeps the configured noise variance: counts², which the gain
    /// does not change.
    pub fn in_counts(config: &WeighingConfig) -> Result<Self, ConfigError> {
        Plan::in_counts(config)?.build()
    }

    /// Check every run after the next [`Estimator::reset`] against the noise of `reference`
    /// (`None`: no check): the configured method flags a fit whose residuals exceed what
    /// that noise explains (`Invalid(ModelMismatch)`; a model bank of three or more
    /// candidates neither checks nor flags, see [`crate::ModelBank`]).
    pub fn set_noise_reference(
        &mut self,
        reference: Option<NoiseReference<T>>,
    ) -> Result<(), ConfigError> {
        match self {
            Self::Step(e) => e.set_noise_reference(reference),
            Self::BiasCompensated(e) => e.set_noise_reference(reference),
            Self::InstrumentalVariable(e) => e.set_noise_reference(reference),
            Self::ModelBank(e) => e.set_noise_reference(reference),
        }
    }

    /// Take the raw samples' white noise, `white` per sample over its sample-to-sample
    /// differences (`None`: not known), from the next [`Estimator::reset`] on: the step
    /// method's `u` never rests on less (see [`crate::StepEstimator::set_white_noise`]),
    /// nor a model bank's while it does not whiten ([`crate::ModelBank::set_white_noise`]);
    /// the other methods state no `u` from the same residuals and take nothing.
    pub fn set_white_noise(&mut self, white: Option<NoiseReference<T>>) -> Result<(), ConfigError> {
        match self {
            Self::Step(e) => e.set_white_noise(white),
            // `K ≥ 3`, known when built: no code of it in an image without a grid.
            Self::ModelBank(e) if K >= 3 => e.set_white_noise(white),
            Self::BiasCompensated(_) | Self::InstrumentalVariable(_) | Self::ModelBank(_) => Ok(()),
        }
    }

    /// Rest the `u` on the empty pan's metered noise colour from now on (see
    /// [`crate::StepEstimator::set_noise_autocovariance`]): the step method takes it, and a
    /// model bank that whitens its block means with it
    /// ([`crate::ModelBank::set_noise_autocovariance`]); the others state no `u` from the
    /// same sandwich, or rest it on their model, and take nothing.
    pub fn set_noise_autocovariance(
        &mut self,
        autocovariance: Option<&Autocovariance<T>>,
    ) -> Result<(), ConfigError> {
        match self {
            Self::Step(e) => e.set_noise_autocovariance(autocovariance),
            // `K ≥ 3`, known when built: no code of it in an image without a grid.
            Self::ModelBank(e) if K >= 3 && e.whitening_order() > 0 => {
                e.set_noise_autocovariance(autocovariance)
            }
            Self::BiasCompensated(_) | Self::InstrumentalVariable(_) | Self::ModelBank(_) => Ok(()),
        }
    }

    /// The level, in the estimate's unit, a pan at rest with nothing on it reads at: a model
    /// bank reads its empty pan against it ([`crate::ModelBank::set_rest_level`]); the
    /// others take nothing. Refused, and nothing changes, when not finite.
    pub fn set_rest_level(&mut self, level: T) -> Result<(), ConfigError> {
        match self {
            // `K ≥ 3`, known when built: no code of it in an image without a grid.
            Self::ModelBank(e) if K >= 3 => e.set_rest_level(level),
            Self::Step(_)
            | Self::BiasCompensated(_)
            | Self::InstrumentalVariable(_)
            | Self::ModelBank(_) => Ok(()),
        }
    }

    /// Any method with the constants of `config` (calibration uses it to try candidates),
    /// without the valid-region check.
    pub fn with_method(
        config: &WeighingConfig,
        method: &WeighingMethod,
        zero_counts: f64,
    ) -> Result<Self, ConfigError> {
        Plan::new(config, method, zero_counts)?.build()
    }

    /// An estimator that holds no method yet: what a board's `static` estimator starts as,
    /// built at link time, to become the configured method where it lives
    /// ([`Self::configure_in_counts`]). It flags every sample given to it before then.
    pub const UNCONFIGURED: Self = Self::ModelBank(ModelBank::UNCONFIGURED);

    /// Become [`Self::in_counts`] where it stands: a model bank over a bank (the
    /// [`Self::UNCONFIGURED`] estimator is one) is configured in place, candidate by
    /// candidate, so no copy of its candidates (20 KB for K = 33) is ever on the stack
    /// ([`crate::weighing::Scale::configured_in`]); any other method is written over it.
    /// Every check is made first: on an error it is as it was.
    pub fn configure_in_counts(&mut self, config: &WeighingConfig) -> Result<(), ConfigError> {
        // One arm per method, none of which builds a bank by value: the frame of a match
        // holds every arm's temporaries, and one bank built by value (`Plan::build`) in it
        // took 69 KB of the QEMU bank image's stack whichever arm ran.
        match Plan::<T, N, S, K>::in_counts(config)? {
            Plan::Step(e) => *self = Self::Step(e),
            Plan::BiasCompensated(e) => *self = Self::BiasCompensated(e),
            Plan::InstrumentalVariable(e) => *self = Self::InstrumentalVariable(e),
            Plan::ModelBank(plan) => {
                if !matches!(self, Self::ModelBank(_)) {
                    // Checked before the method it holds is given up.
                    plan.check::<S>()?;
                    self.become_unconfigured_bank();
                }
                if let Self::ModelBank(bank) = self {
                    plan.configure(bank)?;
                }
            }
        }
        Ok(())
    }

    /// Become an unconfigured bank. In a frame of its own, never inlined: the compiler may
    /// build the bank on the stack before writing it (K = 65: 45 KB, more than a board's
    /// stack beside it), and a board's estimator starts as one, so never comes here.
    #[inline(never)]
    #[cold]
    fn become_unconfigured_bank(&mut self) {
        *self = Self::ModelBank(ModelBank::UNCONFIGURED);
    }
}

/// The configured method checked and ready to build: the data-driven estimators built
/// (a few KB at most), a model bank's candidates as a plan that gives them one at a time.
enum Plan<T: Real, const N: usize, const S: usize, const K: usize> {
    Step(StepEstimator<T, N, UNCERTAINTY_ORDERS, COLOUR_LAGS>),
    BiasCompensated(BiasCompensatedStepEstimator<T, N>),
    InstrumentalVariable(IvStepEstimator<T, N>),
    ModelBank(BankPlan<T, K>),
}

impl<T: Real, const N: usize, const S: usize, const K: usize> Plan<T, N, S, K> {
    /// [`WeighingEstimator::in_counts`]'s checks and configuration.
    fn in_counts(config: &WeighingConfig) -> Result<Self, ConfigError> {
        config
            .check_region()
            .map_err(|_| ConfigError::OutsideValidRegion)?;
        let mut in_counts = *config;
        in_counts.counts_per_gram = 1.0;
        in_counts.onset.rail_low = f64::NEG_INFINITY;
        in_counts.onset.rail_high = f64::INFINITY;
        Self::new(&in_counts, &config.method, 0.0)
    }

    /// [`WeighingEstimator::with_method`]'s checks and configuration.
    fn new(
        config: &WeighingConfig,
        method: &WeighingMethod,
        zero_counts: f64,
    ) -> Result<Self, ConfigError> {
        if !zero_counts.is_finite() {
            return Err(ConfigError::Range);
        }
        // Integer codes: a code strictly between the rails is at least half a code inside.
        let (low, high) = (
            T::from_f64(config.onset.rail_low + 0.5 - zero_counts),
            T::from_f64(config.onset.rail_high - 0.5 - zero_counts),
        );
        let gain = T::from_f64(config.counts_per_gram);
        let step = |order: usize, decimation: u16, forgetting: f64| {
            StepConfig::new(order, gain)
                .with_decimation(decimation)
                .with_forgetting(T::from_f64(forgetting))
                .with_valid_range(low, high)
        };
        Ok(match *method {
            WeighingMethod::Step {
                order,
                decimation,
                forgetting,
            } => Self::Step(StepEstimator::new(step(order, decimation, forgetting))?),
            WeighingMethod::BiasCompensated { order, decimation } => Self::BiasCompensated(
                BiasCompensatedStepEstimator::new(BiasCompensatedConfig::new(
                    step(order, decimation, 1.0),
                    T::from_f64(config.noise_variance_counts2),
                ))?,
            ),
            WeighingMethod::InstrumentalVariable { order, decimation } => {
                Self::InstrumentalVariable(IvStepEstimator::new(IvConfig::new(step(
                    order, decimation, 1.0,
                )))?)
            }
            WeighingMethod::ModelBank {
                decimation,
                candidates,
                ratio_min,
                ratio_max,
                interpolation,
                whitening,
            } => {
                // Any size up to the type's room (a host's one type for every bank).
                if candidates == 0 || candidates > K {
                    return Err(ConfigError::Model);
                }
                let mut model = config.model;
                model.counts_per_gram = config.counts_per_gram;
                Self::ModelBank(BankPlan {
                    model,
                    count: candidates,
                    span: (ratio_min, ratio_max),
                    decimation,
                    valid: (low, high),
                    interpolation,
                    whitening,
                })
            }
        })
    }

    /// The estimator (a model bank's candidates checked as it is built).
    #[inline(always)]
    fn build(self) -> Result<WeighingEstimator<T, N, S, K>, ConfigError> {
        Ok(match self {
            Self::Step(e) => WeighingEstimator::Step(e),
            Self::BiasCompensated(e) => WeighingEstimator::BiasCompensated(e),
            Self::InstrumentalVariable(e) => WeighingEstimator::InstrumentalVariable(e),
            Self::ModelBank(plan) => {
                let mut bank = ModelBank::UNCONFIGURED;
                plan.configure(&mut bank)?;
                WeighingEstimator::ModelBank(bank)
            }
        })
    }
}

/// A model bank's candidates as the configured method gives them: the identified model
/// (in counts) at each frequency ratio, by the physical law
/// ([`LoadCellModel::bank_configs`]' candidates, one at a time).
struct BankPlan<T, const K: usize> {
    model: LoadCellModel,
    count: usize,
    span: (f64, f64),
    decimation: u16,
    valid: (T, T),
    interpolation: Interpolation,
    whitening: usize,
}

impl<T: Real, const K: usize> BankPlan<T, K> {
    /// Make `bank` this plan's bank where it stands (checked first: on an error it is as
    /// it was; `ModelBank::configure` checks the candidates).
    fn configure<const S: usize>(&self, bank: &mut ModelBank<T, S, K>) -> Result<(), ConfigError> {
        self.check_whitening()?;
        bank.configure(self.count, |k| self.candidate(k))?;
        bank.set_interpolation(self.interpolation);
        bank.set_whitening(self.whitening)
    }

    /// Every check [`Self::configure`] makes.
    fn check<const S: usize>(&self) -> Result<(), ConfigError> {
        self.check_whitening()?;
        ModelBank::<T, S, K>::check(self.count, &|k| self.candidate(k)).map(|_| ())
    }

    fn check_whitening(&self) -> Result<(), ConfigError> {
        if self.whitening > WHITENING_ORDER {
            return Err(ConfigError::Filter("whitening order"));
        }
        Ok(())
    }

    /// Candidate `k`'s configuration.
    fn candidate<const S: usize>(&self, k: usize) -> Result<ModelConfig<T, S>, ConfigError> {
        let ratio = LoadCellModel::frequency_ratio(self.span.0, self.span.1, self.count, k)?;
        Ok(self
            .model
            .bank_config::<T, S>(ratio, self.decimation, InitialState::Unknown)?
            .with_valid_range(self.valid.0, self.valid.1))
    }
}

impl<T: Real, const N: usize, const S: usize, const K: usize> Estimator<T>
    for WeighingEstimator<T, N, S, K>
{
    fn push(&mut self, sample: T) -> Reading<T> {
        match self {
            Self::Step(e) => e.push(sample),
            Self::BiasCompensated(e) => e.push(sample),
            Self::InstrumentalVariable(e) => e.push(sample),
            Self::ModelBank(e) => e.push(sample),
        }
    }

    fn push_missing(&mut self) -> Reading<T> {
        match self {
            Self::Step(e) => e.push_missing(),
            Self::BiasCompensated(e) => e.push_missing(),
            Self::InstrumentalVariable(e) => e.push_missing(),
            Self::ModelBank(e) => e.push_missing(),
        }
    }

    fn reset(&mut self) {
        match self {
            Self::Step(e) => e.reset(),
            Self::BiasCompensated(e) => e.reset(),
            Self::InstrumentalVariable(e) => e.reset(),
            Self::ModelBank(e) => e.reset(),
        }
    }
}
