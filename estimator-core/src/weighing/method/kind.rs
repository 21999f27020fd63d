//! What a weighing method is: the estimator family, its order and decimation, or the model
//! bank over a range of resonances.

use core::fmt;

use crate::estimators::model::Interpolation;

/// A fully specified weighing method (what [`super::WeighingConfig`] records).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WeighingMethod {
    /// The data-driven estimator, least squares ([`crate::StepEstimator`]).
    Step {
        /// Model order n.
        order: usize,
        /// Block length D.
        decimation: u16,
        /// Forgetting factor λ at the decimated rate; 1 keeps a growing window.
        forgetting: f64,
    },
    /// Bias-compensated least squares ([`crate::BiasCompensatedStepEstimator`]), with the
    /// noise variance of [`super::WeighingConfig::noise_variance_counts2`].
    BiasCompensated {
        /// Model order n.
        order: usize,
        /// Block length D.
        decimation: u16,
    },
    /// Instrumental variables ([`crate::IvStepEstimator`]), delay `n + 1`, default floor.
    InstrumentalVariable {
        /// Model order n.
        order: usize,
        /// Block length D.
        decimation: u16,
    },
    /// A [`crate::ModelBank`] of `candidates` models built by the physical law from the
    /// identified model ([`crate::sensor::LoadCellModel::bank_configs`]), initial state estimated.
    ModelBank {
        /// Block length D of the fitted block means.
        decimation: u16,
        /// Number of candidate models K (the bank's const generic must equal it).
        candidates: usize,
        /// Lowest resonance, relative to the identified one.
        ratio_min: f64,
        /// Highest resonance, relative to the identified one.
        ratio_max: f64,
        /// How the candidates around the best fit are combined ([`Interpolation`]).
        interpolation: Interpolation,
        /// Order of the prediction-error filter the block means are whitened with once the
        /// scale has metered the empty pan's noise colour (0: never; at most
        /// [`crate::WHITENING_ORDER`]; [`crate::ModelBank::with_whitening`]).
        whitening: usize,
    },
}

impl WeighingMethod {
    /// Model order n of a data-driven method; `None` for the bank.
    pub fn order(&self) -> Option<usize> {
        match *self {
            WeighingMethod::Step { order, .. }
            | WeighingMethod::BiasCompensated { order, .. }
            | WeighingMethod::InstrumentalVariable { order, .. } => Some(order),
            WeighingMethod::ModelBank { .. } => None,
        }
    }

    /// Whether a board's scale can ever show this method's readings stable, empty or
    /// final: only with a stated `u` ([`crate::weighing::Scale`]). The step estimator states
    /// one with a growing window up to [`super::UNCERTAINTY_ORDERS`], the model bank from
    /// its model; with forgetting (λ < 1) the step states none, and a board builds bias
    /// compensation and instrumental variables without the lag sums their `u` needs
    /// ([`super::WeighingEstimator`]): they run, shown as estimating only. Calibration never
    /// chooses a method without it.
    pub fn states_uncertainty_on_board(&self) -> bool {
        match *self {
            WeighingMethod::Step {
                order, forgetting, ..
            } => forgetting == 1.0 && order <= super::UNCERTAINTY_ORDERS,
            WeighingMethod::BiasCompensated { .. }
            | WeighingMethod::InstrumentalVariable { .. } => false,
            WeighingMethod::ModelBank { .. } => true,
        }
    }

    /// Block length D.
    pub fn decimation(&self) -> u16 {
        match *self {
            WeighingMethod::Step { decimation, .. }
            | WeighingMethod::BiasCompensated { decimation, .. }
            | WeighingMethod::InstrumentalVariable { decimation, .. }
            | WeighingMethod::ModelBank { decimation, .. } => decimation,
        }
    }
}

impl fmt::Display for WeighingMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            WeighingMethod::Step {
                order,
                decimation,
                forgetting,
            } => {
                write!(f, "step n={order} D={decimation}")?;
                if forgetting != 1.0 {
                    write!(f, " lambda={forgetting}")?;
                }
                Ok(())
            }
            WeighingMethod::BiasCompensated { order, decimation } => {
                write!(f, "bias-compensated n={order} D={decimation}")
            }
            WeighingMethod::InstrumentalVariable { order, decimation } => {
                write!(f, "instrumental-variable n={order} D={decimation}")
            }
            WeighingMethod::ModelBank {
                decimation,
                candidates,
                ratio_min,
                ratio_max,
                interpolation,
                whitening,
            } => {
                write!(
                    f,
                    "model bank D={decimation} K={candidates} ratios {ratio_min}-{ratio_max}"
                )?;
                if interpolation == Interpolation::FivePoint {
                    write!(f, " five-point")?;
                }
                if whitening > 0 {
                    write!(f, " whitened (order {whitening})")?;
                }
                Ok(())
            }
        }
    }
}

/// The model bank a grid ends with.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BankCandidate {
    /// Block length D.
    pub decimation: u16,
    /// Number of candidate models K.
    pub candidates: usize,
    /// Lowest and highest resonance relative to the identified one.
    pub ratio_min: f64,
    /// See `ratio_min`.
    pub ratio_max: f64,
    /// How the candidates around the best fit are combined.
    pub interpolation: Interpolation,
    /// Order of the whitening filter (0: none).
    pub whitening: usize,
}

impl BankCandidate {
    /// The configured method this bank is.
    pub const fn method(self) -> WeighingMethod {
        WeighingMethod::ModelBank {
            decimation: self.decimation,
            candidates: self.candidates,
            ratio_min: self.ratio_min,
            ratio_max: self.ratio_max,
            interpolation: self.interpolation,
            whitening: self.whitening,
        }
    }

    /// The bank host-sim's model-based study settled on: D = 8, 33 candidates 2% apart over
    /// frequency ratios 0.68–1.30, which covers 0.3×–3× the calibration mass on the
    /// reference cell with a candidate to spare at each end.
    pub const REFERENCE: Self = Self {
        decimation: 8,
        candidates: 33,
        ratio_min: 0.68,
        ratio_max: 1.30,
        interpolation: Interpolation::ThreePoint,
        whitening: 0,
    };

    /// The bank `host-sim study coverage` found to state a `u` that holds in coloured noise
    /// (README, "Uncertainty"): twice [`Self::REFERENCE`]'s grid (65 candidates 1 % apart
    /// over the same span), five-point interpolation, its block means whitened by a filter
    /// of order 32 on the empty pan's metered colour.
    pub const CALIBRATED_U: Self = Self {
        decimation: 8,
        candidates: 65,
        ratio_min: 0.68,
        ratio_max: 1.30,
        interpolation: Interpolation::FivePoint,
        whitening: 32,
    };
}
