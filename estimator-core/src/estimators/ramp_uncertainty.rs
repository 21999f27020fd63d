//! The standard uncertainty of the ramp estimator's reading, the line `c₀ + c₁·τ` at the
//! reading's time.
//!
//! The ramp regression is least squares, so this is the step estimator's sandwich
//! (`crate::estimators::step_uncertainty`) with three changes:
//!
//! - the reading is the combination `vᵀ·θ` with `v = [0 … 0, τ, 1]` over the trailing
//!   columns `[t, 1]`, so the weights of the rows' equation errors are `z = P·v` and the
//!   lag-0 term is `vᵀ·P·v = z_t·τ + z_1`: the variances of intercept and slope and their
//!   covariance, together;
//! - the regressors are second differences, so the equation error
//!   `ε(k) = e(k) − Σ ℓ_i·Δ²e(k−n+1+i)` is a moving average of order `n + 1`
//!   (`crate::estimators::consistency`'s coefficients), and the lag sums take the time column
//!   as one more leading entry of the row (`n + 1` of them, the constant implied): its
//!   lagged products enter the sandwich like any regressor's;
//! - the first-order errors-in-variables bias is that of the second-difference stencil
//!   `(1, −2, 1)`: `E[φ_i·ε] = s²·Σ_t stencil_t·c_{i+t}`, none on `t` and the constant.
//!
//! The `u` is that of the line at the block's last sample; until the next block the
//! reading moves along the line by less than a block, which changes `u` by a fraction of
//! `D / rows` (the readings at a block's end are exact). The regression assumes an LTI
//! sensor; on a conveyor the load itself changes the dynamics (thesis eq. 6.1), a model
//! error this `u` does not contain. Only the growing window (λ = 1); lag sums for `L ≥ n + 1`
//! (`RampEstimator<T, N, L>`, `L = 0` by default: no `u`), O(n³) per decimated row, as for
//! the step estimator.

use crate::estimators::consistency::coefficient;
use crate::estimators::step_uncertainty::{
    stated, with_bias, LagSums, NoiseFloor, NoiseModel, Quadratic,
};
use crate::numerics::real::Real;

/// What the ramp estimator keeps for its reading's `u`, for orders up to `L − 1`.
#[derive(Clone, Debug)]
pub(crate) struct RampUncertainty<T: Real, const L: usize> {
    /// Lag sums of the rows `[Δ²x …, t]` (the constant implied), and their residuals.
    lags: LagSums<T, L, L>,
}

impl<T: Real, const L: usize> RampUncertainty<T, L> {
    pub(crate) fn new() -> Self {
        Self {
            lags: LagSums::new(),
        }
    }

    /// Whether order `n` is covered: the rows have `n + 1` leading entries.
    pub(crate) fn covers(n: usize) -> bool {
        L > n
    }

    /// One regression row: second differences `window[..n]` at time `t`.
    pub(crate) fn push_row(&mut self, window: &[T], t: T, n: usize) {
        if !Self::covers(n) {
            return;
        }
        let mut row = [T::ZERO; L];
        row[..n].copy_from_slice(&window[..n]);
        row[n] = t;
        self.lags.push_row(&row, n + 1);
    }

    /// The a-priori residual of a row folded into a determined problem, and its weight.
    pub(crate) fn push_residual(&mut self, residual: T, weight: T, n: usize) {
        if Self::covers(n) {
            self.lags.push_residual(residual, weight, n + 1);
        }
    }

    /// The reading's `u` and degrees of freedom: `lead` the current `ℓ`, `(z_lead, z_tail)`
    /// = `P·v` for `v = [0 …, combination]` (`combination = [τ, 1]`).
    pub(crate) fn uncertainty(
        &self,
        n: usize,
        lead: &[T],
        z_lead: &[T],
        z_tail: [T; 2],
        combination: [T; 2],
        block_noise_floor: Option<NoiseFloor<T>>,
    ) -> Option<(T, u32)> {
        if !Self::covers(n) {
            return None;
        }
        // h_m = c_{n+1−m}: the coefficients run oldest first.
        let mut noise_model = NoiseModel {
            h: [T::ZERO; L],
            h_last: coefficient::<T, 2>(lead, n, 0),
        };
        for (m, value) in noise_model.h[..=n].iter_mut().enumerate() {
            *value = coefficient::<T, 2>(lead, n, n + 1 - m);
        }
        let mut z = [T::ZERO; L];
        z[..n].copy_from_slice(&z_lead[..n]);
        z[n] = z_tail[0];
        let quadratic = Quadratic {
            z: &z,
            z_level: z_tail[1],
            lag0: z_tail[0] * combination[0] + z_tail[1] * combination[1],
        };
        let (variance, noise, degrees) = self.lags.variance(
            n + 1,
            &noise_model,
            quadratic,
            self.lags.residual_sum(),
            block_noise_floor,
        )?;
        // E[φ_i·ε]/s² = Σ_t stencil_t·c_{i+t}, stencil (1, −2, 1).
        let mut bias = T::ZERO;
        for (i, &zi) in z_lead[..n].iter().enumerate() {
            let c = |m: usize| coefficient::<T, 2>(lead, n, m);
            bias += zi * (c(i) - T::from_f64(2.0) * c(i + 1) + c(i + 2));
        }
        bias *= T::from_u32(self.lags.rows()) * noise;
        stated(with_bias(variance, bias)?, degrees)
    }
}
