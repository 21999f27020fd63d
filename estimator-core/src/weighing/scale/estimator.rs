//! What the scale needs of an estimator beyond [`Estimator`]: when its residual is new, and
//! where the metered noise goes.
//!
//! The estimator is fed ADC counts with the zero removed (in integer arithmetic) and answers
//! **in counts** (it is built with a gain of 1); the scale converts to grams. So a new
//! calibration only resets the estimator instead of rebuilding it, and what the estimator
//! sees does not depend on the gain.

use crate::estimators::bias_compensated::BiasCompensatedStepEstimator;
use crate::estimators::consistency::NoiseReference;
use crate::estimators::iv::IvStepEstimator;
use crate::estimators::model::ModelBank;
use crate::estimators::noise_meter::Autocovariance;
use crate::estimators::step::StepEstimator;
use crate::reading::{ConfigError, Estimator};
use crate::weighing::method::WeighingEstimator;

/// An estimator the scale can run: fed ADC counts with the zero removed, answering in
/// counts (built with a gain of 1), its residual a-priori and in counts.
pub trait ScaleEstimator: Estimator<f32> {
    /// Raw samples per regression update (the decimation `D`): the residual is new once
    /// every this many samples after a reset.
    fn samples_per_update(&self) -> u32;

    /// Check the runs after the next reset against the noise `reference` in counts², at
    /// this estimator's `D` (`None`: no check; see `crate::estimators::consistency`). A reference that
    /// is not finite and positive is refused and nothing changes. Allocation-free.
    fn set_noise_reference(
        &mut self,
        reference: Option<NoiseReference<f32>>,
    ) -> Result<(), ConfigError>;

    /// Take the raw samples' white noise, `white` in counts² per sample over its
    /// sample-to-sample differences (`None`: not known), from the next reset on, for an
    /// estimator whose `u` rests on its residuals (see
    /// [`crate::StepEstimator::set_white_noise`]); the default takes nothing. A variance
    /// that is not finite and non-negative is refused and nothing changes.
    fn set_white_noise(&mut self, white: Option<NoiseReference<f32>>) -> Result<(), ConfigError> {
        let _ = white;
        Ok(())
    }

    /// Rest the `u` on the empty pan's metered noise colour, `autocovariance` of block means
    /// at this estimator's `D` in counts² (`None`: not known), from now on and after every
    /// reset, for an estimator whose `u` can (see
    /// [`crate::StepEstimator::set_noise_autocovariance`]); the default takes nothing. One
    /// that is no autocovariance is refused and nothing changes.
    fn set_noise_autocovariance(
        &mut self,
        autocovariance: Option<&Autocovariance<f32>>,
    ) -> Result<(), ConfigError> {
        let _ = autocovariance;
        Ok(())
    }

    /// The level, in counts, the scale's empty pan reads at in the runs from now on (the
    /// tracked zero's fraction of a count beyond the whole counts removed), for an
    /// estimator that reads a pan at rest against it (see
    /// [`crate::ModelBank::set_rest_level`]); the default takes nothing. One that is not
    /// finite is refused and nothing changes.
    fn set_rest_level(&mut self, level: f32) -> Result<(), ConfigError> {
        let _ = level;
        Ok(())
    }
}

impl<E: ScaleEstimator + ?Sized> ScaleEstimator for &mut E {
    fn samples_per_update(&self) -> u32 {
        (**self).samples_per_update()
    }

    fn set_noise_reference(
        &mut self,
        reference: Option<NoiseReference<f32>>,
    ) -> Result<(), ConfigError> {
        (**self).set_noise_reference(reference)
    }

    fn set_white_noise(&mut self, white: Option<NoiseReference<f32>>) -> Result<(), ConfigError> {
        (**self).set_white_noise(white)
    }

    fn set_noise_autocovariance(
        &mut self,
        autocovariance: Option<&Autocovariance<f32>>,
    ) -> Result<(), ConfigError> {
        (**self).set_noise_autocovariance(autocovariance)
    }

    fn set_rest_level(&mut self, level: f32) -> Result<(), ConfigError> {
        (**self).set_rest_level(level)
    }
}

/// `ScaleEstimator` for the estimators of this crate: `samples_per_update` is the
/// decimation `$decimation` reads off the estimator `$e`; the noise reference goes to the
/// estimator's own `set_noise_reference`. (A macro, not a trait default: the decimation
/// sits in each estimator's own configuration, which no shared trait exposes.)
macro_rules! scale_estimator {
    ($([$($generics:tt)*] $estimator:ty => |$e:ident| $decimation:expr $(, $white:ident, $colour:ident)?;)*) => {$(
        impl<$($generics)*> ScaleEstimator for $estimator {
            fn samples_per_update(&self) -> u32 {
                let $e = self;
                u32::from($decimation)
            }

            fn set_noise_reference(
                &mut self,
                reference: Option<NoiseReference<f32>>,
            ) -> Result<(), ConfigError> {
                Self::set_noise_reference(self, reference)
            }

            $(
                fn $white(
                    &mut self,
                    white: Option<NoiseReference<f32>>,
                ) -> Result<(), ConfigError> {
                    Self::$white(self, white)
                }

                fn $colour(
                    &mut self,
                    autocovariance: Option<&Autocovariance<f32>>,
                ) -> Result<(), ConfigError> {
                    Self::$colour(self, autocovariance)
                }
            )?
        }
    )*};
}

scale_estimator! {
    [const N: usize, const L: usize, const C: usize] StepEstimator<f32, N, L, C> => |e| e.config().decimation,
        set_white_noise, set_noise_autocovariance;
    [const N: usize, const L: usize] BiasCompensatedStepEstimator<f32, N, L> => |e| e.config().step.decimation;
    [const N: usize, const L: usize] IvStepEstimator<f32, N, L> => |e| e.config().step.decimation;
    [const S: usize, const K: usize] ModelBank<f32, S, K> => |e| e.decimation();
}

impl<const N: usize, const S: usize, const K: usize> ScaleEstimator
    for WeighingEstimator<f32, N, S, K>
{
    fn samples_per_update(&self) -> u32 {
        match self {
            Self::Step(e) => e.samples_per_update(),
            Self::BiasCompensated(e) => e.samples_per_update(),
            Self::InstrumentalVariable(e) => e.samples_per_update(),
            Self::ModelBank(e) => e.samples_per_update(),
        }
    }

    fn set_noise_reference(
        &mut self,
        reference: Option<NoiseReference<f32>>,
    ) -> Result<(), ConfigError> {
        WeighingEstimator::set_noise_reference(self, reference)
    }

    fn set_white_noise(&mut self, white: Option<NoiseReference<f32>>) -> Result<(), ConfigError> {
        WeighingEstimator::set_white_noise(self, white)
    }

    fn set_noise_autocovariance(
        &mut self,
        autocovariance: Option<&Autocovariance<f32>>,
    ) -> Result<(), ConfigError> {
        WeighingEstimator::set_noise_autocovariance(self, autocovariance)
    }

    fn set_rest_level(&mut self, level: f32) -> Result<(), ConfigError> {
        WeighingEstimator::set_rest_level(self, level)
    }
}
