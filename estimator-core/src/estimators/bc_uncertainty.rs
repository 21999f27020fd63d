//! The standard uncertainty of the bias-compensated estimator's level.
//!
//! The compensated equations `A·θ = Kᵀx − N·r`, `A = KᵀK − N·S`, subtract from the
//! normal equations exactly the expectation of what the noise adds (module docs of
//! `crate::estimators::bias_compensated`), so with the equation error `ε = x − K·θ`
//! (noisy `K`) the error is `A·(θ̂ − θ) = Kᵀε − E[Kᵀε]`: zero-mean to first order, and the
//! level's is `zᵀ·(Kᵀε − E[Kᵀε])` with `z = A⁻¹·e_u`, the compensated factor's influence
//! row. `ε` is the moving average of order `n` of `crate::estimators::step_uncertainty`,
//! and the variance is its sandwich over the lagged cross-products of the (noisy)
//! regression rows, as for least squares, with `zᵀ·KᵀK·z = ‖R·z‖²` (the least-squares
//! factor) at lag 0 and no errors-in-variables bias added: the compensation removed it.
//! Left out is the fourth-moment term `Σ E[φ_k·ε_j]·E[φ_jᵀ·ε_k]` over `|k − j| ≤ 2n`, of the
//! order of the rows' noise times the equation error's, which the noisy rows' own lag
//! sums carry in part.
//!
//! The noise level is the mean square of the compensated fit's own residuals,
//! `RSS_LS + ‖R·(θ̂ − θ_LS)‖²` over `rows − (n + 1)`, never below the configured noise
//! variance (metered at tare); with the t-factor of `step_uncertainty`. As the
//! compensation itself, the `u` assumes white noise on the block means (the step
//! estimator's autocovariance guard is not kept).
//!
//! ## Where it is stated
//! The expansion is first order in the compensation's own error: the noise energy it
//! subtracts is itself uncertain by `√(2/N_eff)` of itself, and the inverse amplifies that
//! by one over the smallest share of a direction's energy left to the signal. Where that
//! share is unresolved the estimator refuses the reading; where it is resolved but only
//! just, the estimate is kept and the first-order `u` is not: on the load cell the readings
//! kept have shares 1–3.5 times the floor and their `u` covered 0–2 % of the errors at
//! D = 1 (the readings kept are those whose noise happened to leave a share, and they
//! carry most of the least-squares bias). So a `u` is stated only where every share is at
//! least [`RESOLVED_FOR_UNCERTAINTY`] times its floor (the compensation's error at most a
//! fifth of the signal's share): 6–7 times on the thesis scene at 200 samples. Without a
//! noise variance there is no compensation (least squares), and no `u` here.
//!
//! Only the growing window (λ = 1); lag sums for orders up to `L`
//! (`BiasCompensatedStepEstimator<T, N, L>`, `L = 0` by default: no `u`), O(n³) per row,
//! as the downdate per reading.

use crate::estimators::step_uncertainty::{stated, LagSums, NoiseFloor, Quadratic};
use crate::numerics::factor::Factor;
use crate::numerics::real::Real;

/// The smallest share of a direction's energy left to the signal, over its resolution
/// floor `√(2/N_eff)`, below which the compensated level states no `u` (module docs).
pub(crate) const RESOLVED_FOR_UNCERTAINTY: f64 = 5.0;

/// What the bias-compensated estimator keeps for its level's `u`, for orders up to `L`.
#[derive(Clone, Debug)]
pub(crate) struct BcUncertainty<T: Real, const N: usize, const L: usize> {
    /// The regression rows' lagged cross-products.
    lags: LagSums<T, N, L>,
    /// The least-squares residual sum of squares.
    least_squares_sum: T,
}

/// The compensated solution and what it is compared with, in absolute levels.
pub(crate) struct Compensated<'a, T: Real, const N: usize> {
    /// The compensated factor (`A = UᵀDU`).
    pub factor: &'a Factor<T, N, 1>,
    /// Its `ℓ` and level.
    pub lead: &'a [T; N],
    pub level: T,
    /// The least-squares `ℓ` and level of the same rows.
    pub least_squares_lead: &'a [T; N],
    pub least_squares_level: T,
}

impl<T: Real, const N: usize, const L: usize> BcUncertainty<T, N, L> {
    pub(crate) fn new() -> Self {
        Self {
            lags: LagSums::new(),
            least_squares_sum: T::ZERO,
        }
    }

    /// Whether orders up to `n` are kept.
    pub(crate) fn covers(n: usize) -> bool {
        L > 0 && L >= n
    }

    /// One regression row's differences `window[..n]`, before it is folded.
    pub(crate) fn push_row(&mut self, window: &[T; N], n: usize) {
        if Self::covers(n) {
            self.lags.push_row(window, n);
        }
    }

    /// The least-squares fold of that row: its a-priori residual and weight.
    pub(crate) fn push_residual(&mut self, residual: T, weight: T) {
        self.least_squares_sum += weight * residual * residual;
    }

    /// The level's `u` and degrees of freedom, `least_squares` the running factor and
    /// `noise_variance` the configured block-mean noise variance (a floor).
    pub(crate) fn uncertainty(
        &self,
        n: usize,
        compensated: Compensated<'_, T, N>,
        least_squares: &Factor<T, N, 1>,
        noise_variance: T,
    ) -> Option<(T, u32)> {
        if !Self::covers(n) {
            return None;
        }
        let (z, [z_level]) = compensated.factor.last_unknown_influence(n)?;
        let lag0 = least_squares.weighted_norm2(n, &z, &[z_level]);
        let mut delta = [T::ZERO; N];
        for (i, value) in delta[..n].iter_mut().enumerate() {
            *value = compensated.lead[i] - compensated.least_squares_lead[i];
        }
        let level = compensated.level - compensated.least_squares_level;
        let excess = least_squares.weighted_norm2(n, &delta, &[level]);
        let quadratic = Quadratic {
            z: &z,
            z_level,
            lag0,
        };
        let (variance, _, degrees) = self.lags.consistent_variance(
            n,
            quadratic,
            compensated.lead,
            self.least_squares_sum + excess,
            NoiseFloor::new(noise_variance, None),
        )?;
        stated(variance, degrees)
    }
}
