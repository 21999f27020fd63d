//! One estimator under test with the oracle beside it: the oracle looks at the state from
//! outside the core (a Cholesky factorisation of Ψ, the factored form's weight) to tell when
//! positive definiteness was lost. It must never change what the estimator computes.

use anyhow::{anyhow, Result};
use estimator_core::{CovarianceStepEstimator, Estimator, Reading, StepEstimator};

use crate::method::{ranged, referenced, step_config, widen, BoxedEstimator, BuildContext, Method};
use crate::montecarlo::{Precision, CAPACITY};

/// An estimator under test, with what the oracle needs to see of its state.
pub(super) enum Tracked {
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
    pub(super) fn new(method: &Method, context: &BuildContext) -> Result<Self> {
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

    pub(super) fn push(&mut self, sample: f64) -> Reading<f64> {
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
    pub(super) fn definite(&self, determined: bool) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_tells_a_positive_definite_block_from_an_indefinite_one() {
        let definite = [[4.0f64, 2.0, 0.0], [2.0, 3.0, 0.0], [0.0, 0.0, -1.0]];
        assert!(cholesky_positive(&definite, 2));
        assert!(!cholesky_positive(&definite, 3));
        let indefinite = [[1.0f32, 2.0], [2.0, 1.0]];
        assert!(!cholesky_positive(&indefinite, 2));
        let not_finite = [[f64::NAN]];
        assert!(!cholesky_positive(&not_finite, 1));
    }
}
