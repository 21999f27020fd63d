//! What every estimator answers with, and the ways a configuration or a sample is refused.

use crate::numerics::real::Real;

/// Why a reading cannot be trusted. A reading with one of these never carries an estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InvalidReason {
    /// The estimator holds no method yet (`ModelBank::UNCONFIGURED`, what a board's
    /// `static` estimator starts as until it is configured where it lives); latches until
    /// the estimator is configured. First, so that it is the all-zero value: a `static`
    /// that starts unconfigured is zero bits, in `.bss`, not a copy in flash.
    Unconfigured,
    /// A sample was NaN or infinite.
    NonFiniteInput,
    /// A sample lay outside the configured valid range (for example a saturated ADC).
    OutOfRange,
    /// The step level is not identifiable from the data: the constant column is (numerically)
    /// in the span of the difference columns, so the estimate would be noise amplified.
    IllConditioned,
    /// The recursive update produced a non-finite number (overflow or a corrupted state).
    NonFiniteUpdate,
    /// A sample was reported missing by the caller; the Hankel structure is broken.
    MissingSample,
    /// A bank of models fits best with a candidate on its edge (or on the edge of the
    /// candidates it still fits, see [`crate::ModelBank`]): the sensor's dynamics (the load)
    /// may lie outside the range the candidates cover, so the estimate would be biased. Like ill-conditioning it is a property of the data so far and clears when the
    /// best fit moves inside.
    OutsideModelRange,
    /// The covariance form's inverse information matrix Ψ is no longer positive definite
    /// (single-precision rounding on ill-conditioned data): its gain and estimate are no
    /// longer those of any least-squares problem. Found by the stability map; latches.
    LostDefiniteness,
    /// What the fit leaves unexplained is more than the noise measured at tare can explain
    /// ([`crate::NoiseReference`], opt-in): the model does not describe the data (an order
    /// below the sensor's, a model off its load, a pan still moving), so the estimate may be
    /// biased far beyond its noise. Like ill-conditioning it describes the data so far and
    /// clears when the fit explains them again; not latched.
    ModelMismatch,
}

impl InvalidReason {
    /// The reason in one word, as the console and host-sim write it (`ill_conditioned`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Unconfigured => "unconfigured",
            Self::NonFiniteInput => "non_finite_input",
            Self::OutOfRange => "out_of_range",
            Self::IllConditioned => "ill_conditioned",
            Self::NonFiniteUpdate => "non_finite_update",
            Self::MissingSample => "missing_sample",
            Self::OutsideModelRange => "outside_model_range",
            Self::LostDefiniteness => "lost_definiteness",
            Self::ModelMismatch => "model_mismatch",
        }
    }

    /// True for the faults that latch until `reset()`: all but [`Self::IllConditioned`],
    /// [`Self::OutsideModelRange`] and [`Self::ModelMismatch`], which describe the data so
    /// far and may clear.
    pub fn latches(self) -> bool {
        !matches!(
            self,
            Self::IllConditioned | Self::OutsideModelRange | Self::ModelMismatch
        )
    }
}

/// The state a reading is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum State {
    /// Not enough samples yet for the least-squares problem to be determined.
    WarmingUp,
    /// The estimate is the least-squares solution of the data so far.
    Estimating,
    /// The reading cannot be trusted. Faults of the data stream or of the state latch until
    /// `reset()` ([`InvalidReason::latches`]); ill-conditioning and a best fit on a bank's
    /// edge are properties of the data so far and clear when more data resolve them.
    Invalid(InvalidReason),
}

/// One answer per raw sample pushed.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading<T> {
    /// The estimated input (step level) in the caller's unit; `Some` only while estimating.
    pub estimate: Option<T>,
    /// Raw samples pushed since the last reset (saturating).
    pub samples: u32,
    /// Whether `estimate` can be used, and if not, why.
    pub state: State,
    /// The a-priori residual of the latest regression row, in the estimate's unit; `Some`
    /// only when the previous update was already determined.
    pub residual: Option<T>,
    /// The estimate's standard uncertainty (GUM), in its unit, stated so that ±2u is a
    /// 95 % interval; `Some` only with an estimate, and only from estimators that can state
    /// it: the step, instrumental-variable, bias-compensated and ramp estimators with their
    /// lag sums (`L > 0`; see `estimators::step_uncertainty`, `iv_uncertainty`,
    /// `bc_uncertainty`, `ramp_uncertainty`, each of which says where it states none: with
    /// forgetting, weak instruments, barely resolved compensation), and the model-based
    /// estimators. `None` is not zero: it means no `u` is known to hold.
    pub uncertainty: Option<T>,
    /// The degrees of freedom the noise level in `uncertainty` rests on (0 without one):
    /// what [`Reading::uncertainty_bound`] needs.
    pub degrees_of_freedom: u32,
}

impl<T: Real> Reading<T> {
    /// An upper 95 % confidence bound of `uncertainty`: the noise level it rests on is
    /// itself estimated from `degrees_of_freedom` residuals, so `u` scaled by
    /// `sqrt(ν / χ²_{0.05}(ν))` (Wilson–Hilferty's χ² quantile). A decision that `u` is small
    /// enough — a final reading — takes this, not `u`: the first moment a fluctuating `u`
    /// meets a target is biased towards runs whose residuals happened to be small (a
    /// stopping rule; at 40 dB a quarter of such first finals lay beyond the permissible
    /// error). `None` without `u` or below 3 degrees of freedom.
    pub fn uncertainty_bound(&self) -> Option<T> {
        let u = self.uncertainty?;
        if self.degrees_of_freedom < 3 {
            return None;
        }
        let a = T::from_f64(2.0) / (T::from_f64(9.0) * T::from_u32(self.degrees_of_freedom));
        let base = T::ONE - a - T::from_f64(1.644_854) * a.sqrt();
        if !(base > T::from_f64(0.05)) {
            return None;
        }
        let bound = u / (base * base.sqrt());
        bound.is_finite().then_some(bound)
    }
}

impl<T: Copy> Reading<T> {
    /// The estimate if the reading is valid.
    pub fn value(&self) -> Option<T> {
        self.estimate
    }

    /// True when the estimator has latched an error.
    pub fn is_invalid(&self) -> bool {
        matches!(self.state, State::Invalid(_))
    }
}

/// A configuration the estimator refuses, with the offending field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The order is 0 or above the estimator's capacity.
    Order {
        /// The order asked for.
        requested: usize,
        /// The largest order this estimator type holds.
        capacity: usize,
    },
    /// The static gain is zero, NaN or infinite.
    Gain,
    /// The forgetting factor is not in (0, 1].
    Forgetting,
    /// The decimation factor is 0 or above [`crate::MAX_DECIMATION`].
    Decimation,
    /// The valid range is empty or contains NaN.
    Range,
    /// A model parameter (other estimators) is outside its domain.
    Model,
    /// The noise reference of the consistency check is not a finite, positive variance.
    NoiseReference,
    /// A weighing configuration outside the valid region the stability map measured
    /// (`tuning::WeighingConfig::check_region` says why).
    OutsideValidRegion,
    /// A field of the weighing decisions' configuration (`ScaleConfig`, named here) is NaN,
    /// infinite where it must be finite, negative, or zero where it must be positive.
    ScaleField(&'static str),
    /// A field of a pre-filter (named here: a baseline's cell mode, placed pair or delay
    /// line's capacity; a model bank's whitening order) is out of its domain.
    Filter(&'static str),
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::Order {
                requested,
                capacity,
            } => write!(f, "order {requested} is not in 1..={capacity}"),
            ConfigError::Gain => f.write_str("static gain must be finite and non-zero"),
            ConfigError::Forgetting => f.write_str("forgetting factor must be in (0, 1]"),
            ConfigError::Decimation => {
                write!(f, "decimation must be in 1..={}", crate::MAX_DECIMATION)
            }
            ConfigError::Range => f.write_str("valid range must be non-empty and not NaN"),
            ConfigError::Model => f.write_str("model parameter outside its domain"),
            ConfigError::NoiseReference => {
                f.write_str("noise reference must be a finite, positive variance")
            }
            ConfigError::OutsideValidRegion => {
                f.write_str("configuration outside the valid region of the stability map")
            }
            ConfigError::Filter(field) => {
                write!(f, "pre-filter field `{field}` is out of its domain")
            }
            ConfigError::ScaleField(field) => {
                write!(
                    f,
                    "scale configuration field `{field}` is out of its domain"
                )
            }
        }
    }
}

/// What every estimator in this crate offers: push one raw sample, get one reading.
pub trait Estimator<T> {
    /// Feed the next raw sample (in the caller's raw unit, offset already removed).
    fn push(&mut self, sample: T) -> Reading<T>;
    /// Tell the estimator a sample was lost; it answers with an invalid reading.
    fn push_missing(&mut self) -> Reading<T>;
    /// Forget everything and start over for a new load.
    fn reset(&mut self);

    /// Push an integer ADC reading: the zero offset is removed in integer arithmetic before
    /// the conversion to `T`, so no precision is lost to a large offset.
    fn push_counts(&mut self, counts: i32, zero_counts: i32) -> Reading<T>
    where
        T: Real,
    {
        self.push(T::from_i32(counts.saturating_sub(zero_counts)))
    }
}

/// An estimator behind a mutable reference is one too: the owner may keep a large one (a
/// model bank is 20 KB) in a `static` and hand the user a reference, instead of moving it.
impl<T, E: Estimator<T> + ?Sized> Estimator<T> for &mut E {
    fn push(&mut self, sample: T) -> Reading<T> {
        (**self).push(sample)
    }

    fn push_missing(&mut self) -> Reading<T> {
        (**self).push_missing()
    }

    fn reset(&mut self) {
        (**self).reset()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(u: f64, degrees_of_freedom: u32) -> Reading<f64> {
        Reading {
            estimate: Some(1.0),
            samples: 100,
            state: State::Estimating,
            residual: None,
            uncertainty: Some(u),
            degrees_of_freedom,
        }
    }

    /// `sqrt(ν / χ²_{0.05}(ν))` against the tables: χ²_{0.05}(10) = 3.940, (30) = 18.493,
    /// (100) = 77.929; at ν = 3 (0.352) Wilson–Hilferty is 4 % high, on the safe side.
    #[test]
    fn the_bound_follows_the_chi_square_tables() {
        for (dof, chi2) in [(10, 3.940), (30, 18.493), (100, 77.929)] {
            let bound = with(1.0, dof).uncertainty_bound().unwrap();
            let exact = (f64::from(dof) / chi2).sqrt();
            assert!(
                (bound / exact - 1.0).abs() < 0.01,
                "{dof}: {bound} vs {exact}"
            );
        }
        let at_three = with(1.0, 3).uncertainty_bound().unwrap();
        let exact = (3.0f64 / 0.3518).sqrt();
        assert!(at_three >= exact && at_three < 1.05 * exact, "{at_three}");
        assert_eq!(with(1.0, 2).uncertainty_bound(), None);
        assert_eq!(
            Reading {
                uncertainty: None,
                ..with(1.0, 10)
            }
            .uncertainty_bound(),
            None
        );
    }
}
