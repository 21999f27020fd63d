//! The sample intake every estimator shares: it counts the raw samples, refuses the bad ones
//! (not finite, outside the valid range, missing) by latching a fault, scales the rest into
//! the estimate's unit, decimates them, and holds the reading the estimator answers with.
//!
//! Why one type: the latching rules and the reading an invalid sample gets are part of the
//! [`crate::Estimator`] contract, so every estimator must apply them the same way.
//!
//! What must never happen: a latched intake passing a sample on, a reading with an estimate
//! while it is invalid, or a change in the arithmetic (`sample · (1/G)` before the block
//! mean) that would move any estimator's readings by a rounding.

use crate::estimators::input::{check_sample, Decimator};
use crate::numerics::real::Real;
use crate::reading::{InvalidReason, Reading, State};

/// Sample count, fault latch, valid range, inverse gain and decimator, and the reading state.
#[derive(Clone, Debug)]
pub(crate) struct Intake<T> {
    /// Raw samples pushed since the reset (saturating), missing ones included.
    samples: u32,
    /// A fault that broke the data stream or the state; latched until the reset.
    fault: Option<InvalidReason>,
    valid_min: T,
    valid_max: T,
    /// `1/G`: raw units to the estimate's unit.
    inv_gain: T,
    decimator: Decimator<T>,
    state: State,
    estimate: Option<T>,
    residual: Option<T>,
    uncertainty: Option<T>,
    degrees_of_freedom: u32,
}

impl<T: Real> Intake<T> {
    /// The intake of an estimator not yet configured: [`InvalidReason::Unconfigured`]
    /// latched, so every sample it is given is flagged (see `ModelBank::UNCONFIGURED`);
    /// after a reset its valid range takes exactly zero. Zero bits throughout.
    pub(crate) const UNCONFIGURED: Self = Self {
        samples: 0,
        fault: Some(InvalidReason::Unconfigured),
        valid_min: T::ZERO,
        valid_max: T::ZERO,
        inv_gain: T::ZERO,
        decimator: Decimator::PASS_THROUGH,
        state: State::Invalid(InvalidReason::Unconfigured),
        estimate: None,
        residual: None,
        uncertainty: None,
        degrees_of_freedom: 0,
    };

    pub(crate) fn new(inv_gain: T, valid_min: T, valid_max: T, decimator: Decimator<T>) -> Self {
        Self {
            samples: 0,
            fault: None,
            valid_min,
            valid_max,
            inv_gain,
            decimator,
            state: State::WarmingUp,
            estimate: None,
            residual: None,
            uncertainty: None,
            degrees_of_freedom: 0,
        }
    }

    /// Count one raw sample; the block mean in the estimate's unit when it completes a block.
    /// A sample that is not finite or out of range latches its fault; once latched, nothing
    /// passes until the reset.
    #[inline]
    pub(crate) fn take(&mut self, sample: T) -> Option<T> {
        self.samples = self.samples.saturating_add(1);
        if self.fault.is_some() {
            return None;
        }
        match check_sample(sample, self.valid_min, self.valid_max) {
            Ok(sample) => self.decimator.push(sample * self.inv_gain),
            Err(reason) => {
                self.latch(reason);
                None
            }
        }
    }

    /// Count a sample the caller lost: the Hankel structure (or the model's time base) is
    /// broken, so this latches [`InvalidReason::MissingSample`] unless a fault already is.
    pub(crate) fn take_missing(&mut self) {
        self.samples = self.samples.saturating_add(1);
        if self.fault.is_none() {
            self.latch(InvalidReason::MissingSample);
        }
    }

    /// Whether a fault is latched: nothing passes until the reset.
    pub(crate) fn latched(&self) -> bool {
        self.fault.is_some()
    }

    /// The current estimate (`Some` only while estimating).
    pub(crate) fn estimate(&self) -> Option<T> {
        self.estimate
    }

    /// A valid reading: `estimate`, with the a-priori `residual` of the row that gave it.
    pub(crate) fn estimating(&mut self, estimate: T, residual: Option<T>) {
        self.state = State::Estimating;
        self.estimate = Some(estimate);
        self.residual = residual;
        self.uncertainty = None;
        self.degrees_of_freedom = 0;
    }

    /// State the standard uncertainty of the estimate just set by [`Self::estimating`], and
    /// the degrees of freedom its noise level rests on.
    pub(crate) fn state_uncertainty(&mut self, uncertainty: Option<(T, u32)>) {
        if self.estimate.is_some() {
            self.uncertainty = uncertainty.map(|(u, _)| u);
            self.degrees_of_freedom = uncertainty.map_or(0, |(_, dof)| dof);
        }
    }

    /// No estimate yet: back to warming up (a baseline that is not stable).
    pub(crate) fn warm_up(&mut self) {
        self.state = State::WarmingUp;
        self.estimate = None;
        self.residual = None;
        self.uncertainty = None;
        self.degrees_of_freedom = 0;
    }

    /// Mark the current reading invalid; a later valid update may clear it.
    pub(crate) fn invalidate(&mut self, reason: InvalidReason) {
        self.state = State::Invalid(reason);
        self.estimate = None;
        self.residual = None;
        self.uncertainty = None;
        self.degrees_of_freedom = 0;
    }

    /// Invalidate and stay invalid until the reset: the data stream or the state is broken.
    pub(crate) fn latch(&mut self, reason: InvalidReason) {
        self.fault = Some(reason);
        self.invalidate(reason);
    }

    /// The reading as it stands.
    pub(crate) fn reading(&self) -> Reading<T> {
        Reading {
            estimate: self.estimate,
            samples: self.samples,
            state: self.state,
            residual: self.residual,
            uncertainty: self.uncertainty,
            degrees_of_freedom: self.degrees_of_freedom,
        }
    }
}

/// Implements [`crate::Estimator`] for an estimator built on an [`Intake`], written once:
/// `push` hands each block mean the intake passes to the estimator's `update`, `push_missing`
/// only counts and latches, and `reset` replaces the estimator by `fresh()` (a new one with
/// the same configuration, which was validated when it was built, so it cannot fail). Both
/// answer with the intake's reading, or with `reading: f` for an estimator that adds to it.
///
/// The estimator provides a field `intake: Intake<T>` and the inherent methods
/// `update(&mut self, x: T)` and `fresh(&self) -> Result<Self, ConfigError>`.
/// Use: `estimator_via_intake!(Name<T, const N>);`, or with a trailing type parameter and
/// its bound, `estimator_via_intake!(Name<T, const K, type F: Bound<T>>);`.
macro_rules! estimator_via_intake {
    ($name:ident<T $(, const $size:ident)* $(, type $param:ident: $bound:path)?>) => {
        $crate::estimators::intake::estimator_via_intake!(
            $name<T $(, const $size)* $(, type $param: $bound)?>,
            reading: |estimator: &Self| estimator.intake.reading()
        );
    };
    ($name:ident<T $(, const $size:ident)* $(, type $param:ident: $bound:path)?>,
        reading: $reading:expr) => {
        impl<T: Real $(, const $size: usize)* $(, $param: $bound)?> $crate::reading::Estimator<T>
            for $name<T $(, $size)* $(, $param)?>
        {
            fn push(&mut self, sample: T) -> $crate::reading::Reading<T> {
                if let Some(x) = self.intake.take(sample) {
                    self.update(x);
                }
                ($reading)(self)
            }

            fn push_missing(&mut self) -> $crate::reading::Reading<T> {
                self.intake.take_missing();
                ($reading)(self)
            }

            fn reset(&mut self) {
                if let Ok(fresh) = self.fresh() {
                    *self = fresh;
                }
            }
        }
    };
}

pub(crate) use estimator_via_intake;

/// The builder methods of the intake's settings, written once for every configuration that
/// holds them (fields `noise_reference`, `decimation`, `valid_min`, `valid_max`).
macro_rules! intake_config_builders {
    () => {
        /// Check the fit's residuals against the noise metered at tare (raw units², at this
        /// configuration's `D`; see [`NoiseReference`]).
        pub fn with_noise_reference(mut self, reference: NoiseReference<T>) -> Self {
            self.noise_reference = Some(reference);
            self
        }

        /// Set the block length D of the decimator.
        pub fn with_decimation(mut self, decimation: u16) -> Self {
            self.decimation = decimation;
            self
        }

        /// Set the range of valid raw samples.
        pub fn with_valid_range(mut self, min: T, max: T) -> Self {
            self.valid_min = min;
            self.valid_max = max;
            self
        }
    };
}

pub(crate) use intake_config_builders;

/// The accessors of an estimator whose configuration wraps a [`crate::StepConfig`] in its
/// field `step` (instrumental variables, bias compensation): written once for both.
macro_rules! step_wrapper_accessors {
    ($config:ident) => {
        /// The configuration in use.
        pub fn config(&self) -> &$config<T> {
            &self.config
        }

        /// Check the runs after the next [`crate::Estimator::reset`] against `reference`
        /// (`None`: no check), as [`crate::StepEstimator::set_noise_reference`].
        pub fn set_noise_reference(
            &mut self,
            reference: Option<NoiseReference<T>>,
        ) -> Result<(), ConfigError> {
            NoiseReference::replace(&mut self.config.step.noise_reference, reference)
        }

        /// The capacity `N`: the largest order this instance accepts.
        pub const fn capacity() -> usize {
            N
        }
    };
}

pub(crate) use step_wrapper_accessors;
