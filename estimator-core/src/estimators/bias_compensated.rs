//! Bias-compensated least squares (BCLS, thesis eq. 4.33) for the data-driven step
//! estimator: the least-squares normal equations with the expected contribution of the
//! measurement noise subtracted, the noise variance measured at tare ([`crate::NoiseMeter`]).
//!
//! ## The noise contribution, exactly
//! The regression row of sample `k` (in the estimate's unit, `x = y/G`) is
//! `φ(k) = [Δx(k−n) … Δx(k−1), 1]` with target `x(k)`, `Δx(j) = x(j+1) − x(j)`. With white
//! noise `e` of variance `s²` on the (decimated) samples, the row's noise is `J·w` with
//! `w = [e(k−n) … e(k)]` and `J` the `n × (n+1)` difference operator (`−1` on the diagonal,
//! `+1` above it), and the target's noise is `e(k)`, the last entry of `w`. Hence
//!
//! ```text
//! E[η ηᵀ]    = s²·J Jᵀ:   2s² on the diagonal, −s² beside it (adjacent Δx share a sample)
//! E[η e(k)]  = s²·e_n:    only Δx(k−1) = x(k) − x(k−1) contains the target's noise
//! ```
//!
//! and nothing on the constant column. Summed over the (exponentially weighted) rows,
//! `E[Σ φ̃φ̃ᵀ] = Σ φφᵀ + N_eff·S` and `E[Σ φ̃x̃] = Σ φx + N_eff·r`, `N_eff = Σ λ^{t−k}`, so
//! `(Σ φ̃φ̃ᵀ − N_eff·S) θ = Σ φ̃x̃ − N_eff·r` has the true θ as the solution of its expected
//! value: the compensated equations are consistent (the LS ones are not). With decimation `D`
//! the rows are block means, whose noise is white with variance `σ²/D` (σ² the raw-rate
//! variance), so `s² = σ²/(G²·D)`.
//!
//! ## How it is solved
//! `S` and `r` are exactly the information of `n + 1` rows: for each noise sample `e(k−n+j)`
//! the row `[J_{·,j}ᵀ, 0]` with target `δ_{j,n}`. So the compensated equations are the LS
//! factor (the `StepEstimator` engine, `factor.rs`) *downdated* by those rows with weight
//! `−N_eff·s²`: Gentleman's square-root-free rotations with a negative row weight (hyperbolic
//! rotations). The running factor is never changed; each reading downdates a copy, so the
//! compensation always uses the current `N_eff`.
//!
//! ## When the compensation is refused
//! Each downdated pivot over its LS value is the share of that direction's energy that the
//! noise model leaves to the signal (these shares are exactly the pivots of the compensated
//! matrix's LDLᵀ in the LS basis). The noise's own energy over `N_eff` rows fluctuates by
//! about `√(2/N_eff)` of itself, so a share at or below `max(√(2/N_eff), 100·ε)` is not
//! resolved from zero (at or below zero the compensated matrix is indefinite): the reading
//! is `Invalid(IllConditioned)`, not latched. Without this test the readings kept on the
//! load cell were unbounded. The step level's
//! identifiability is the downdated trailing pivot over `N_eff`, with `StepEstimator`'s
//! rounding-level test.
//!
//! Cost per decimated sample: the LS fold (as `StepEstimator`) plus the downdate,
//! `Σ_j (n+2−j)²/2 ≈ (n+1)³/6` rotation applications (≈ 85 at n = 7) and an `O(n²)` back
//! substitution for the a-priori residual: roughly 3× `StepEstimator`.
//! Memory: `tests/eiv_bad_input.rs` prints the sizes.
//!
//! With `noise_variance = 0` it is the least-squares estimator, estimate for estimate.
//!
//! ## The standard uncertainty
//! With lag sums for orders up to `L` (`BiasCompensatedStepEstimator<T, N, L>`, `L = 0` by
//! default) a reading states the level's `u` (`crate::estimators::bc_uncertainty`) where
//! every share is resolved at least [`RESOLVED_FOR_UNCERTAINTY`] times its floor; not with
//! forgetting, nor without a noise variance (no compensation).
//!
//! ## LS vs IV vs BCLS, and the verdict
//! `cargo test --release -p estimator-core --test eiv -- --ignored --nocapture study_table`
//! prints the comparison on the load cell of `tests/support`; `tests/eiv.rs` pins each of
//! these statements.
//!
//! - **Thesis scene (eq. 4.38, second order, low SNR): both win.** IV and BCLS remove the
//!   LS bias at the same variance, every reading valid; BCLS with σ² metered at tare does as
//!   well.
//! - **Load cell at D = 1: LS carries the errors-in-variables bias.** IV removes most of it
//!   and, with its weak-instrument floor, beats LS in RMS, but stays far above the CRLB.
//!   BCLS is refused in most runs (noise-only directions in the regressor space); what it
//!   keeps still carries most of the bias.
//! - **Load cell at D ≈ 12: LS is near the CRLB with no resolved bias: both lose.** IV adds
//!   variance; BCLS is refused in most runs and matches LS where it is kept.
//! - **Verdict:** for the load cell, decimated LS (`StepEstimator`, D ≈ 12) is far better
//!   than either variant at full rate; keep IV and BCLS for well-excited, low-order sensors
//!   like the thesis scene, or as a bias check.
use crate::estimators::bc_uncertainty::{BcUncertainty, Compensated, RESOLVED_FOR_UNCERTAINTY};
use crate::estimators::consistency::{
    difference_correlation, difference_noise_gain, NoiseReference, ResidualCheck,
};
use crate::estimators::input::{row_residual, DifferenceWindow};
use crate::estimators::intake::{estimator_via_intake, step_wrapper_accessors, Intake};
use crate::estimators::step::{identifiability_floor, recentre, StepConfig};
use crate::numerics::factor::Factor;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// Configuration of a [`BiasCompensatedStepEstimator`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BiasCompensatedConfig<T> {
    /// Order, gain, forgetting, decimation and valid range, exactly as for `StepEstimator`.
    pub step: StepConfig<T>,
    /// Variance σ² of the white noise on one raw sample, in raw units² (e.g. counts²), as
    /// measured at tare by [`crate::NoiseMeter`]. Zero turns the compensation off.
    pub noise_variance: T,
}

impl<T: Real> BiasCompensatedConfig<T> {
    /// The given step configuration and raw-sample noise variance.
    pub fn new(step: StepConfig<T>, noise_variance: T) -> Self {
        Self {
            step,
            noise_variance,
        }
    }

    /// Check against a capacity; a negative or non-finite variance is [`ConfigError::Model`].
    pub fn validate(&self, capacity: usize) -> Result<(), ConfigError> {
        self.step.validate(capacity)?;
        if !(self.noise_variance >= T::ZERO && self.noise_variance.is_finite()) {
            return Err(ConfigError::Model);
        }
        Ok(())
    }
}

/// The bias-compensated data-driven step estimator with capacity for orders up to `N`,
/// stating the standard uncertainty of its level for orders up to `L` (the default 0 states
/// none; see `crate::estimators::bc_uncertainty`).
///
/// Same reading semantics as [`crate::StepEstimator`]; see the module docs.
#[derive(Clone, Debug)]
pub struct BiasCompensatedStepEstimator<T: Real, const N: usize, const L: usize = 0> {
    config: BiasCompensatedConfig<T>,
    intake: Intake<T>,
    /// s² in the estimate's unit at the decimated rate: σ²/(G²·D).
    decimated_variance: T,
    differences: DifferenceWindow<T, N, 1>,
    /// The uncompensated least-squares factor, exactly as in `StepEstimator`.
    factor: Factor<T, N, 1>,
    rows: u32,
    effective_rows: T,
    /// The origin of the targets in `factor`, as in `StepEstimator` (the compensation is
    /// shift-equivariant: the noise rows carry nothing on the constant column).
    offset: T,
    /// The latest compensated solution `(ℓ, u)`, for the next row's a-priori residual.
    solution: Option<([T; N], T)>,
    identifiability: T,
    /// The consistency check, when configured with a noise reference (on the compensated
    /// fit's a-posteriori residuals).
    check: Option<ResidualCheck<T>>,
    /// What the level's standard uncertainty needs.
    uncertainty: BcUncertainty<T, N, L>,
}

impl<T: Real, const N: usize, const L: usize> BiasCompensatedStepEstimator<T, N, L> {
    /// A new estimator, or the reason the configuration is impossible.
    pub fn new(config: BiasCompensatedConfig<T>) -> Result<Self, ConfigError> {
        config.validate(N)?;
        let step = config.step;
        let inv_gain = T::ONE / step.gain;
        let decimated_variance =
            config.noise_variance * inv_gain * inv_gain / T::from_u32(step.decimation as u32);
        if !decimated_variance.is_finite() {
            return Err(ConfigError::Model);
        }
        Ok(Self {
            config,
            intake: step.intake(),
            decimated_variance,
            differences: DifferenceWindow::new(),
            factor: Factor::new(),
            rows: 0,
            effective_rows: T::ZERO,
            offset: T::ZERO,
            solution: None,
            identifiability: T::ZERO,
            check: step.residual_check(),
            uncertainty: BcUncertainty::new(),
        })
    }

    step_wrapper_accessors!(BiasCompensatedConfig);

    /// The compensated trailing pivot over the weighted row count at the latest reading, in
    /// (0, 1]; zero before the first. How well the compensated equations determine the step
    /// level (the analogue of `StepEstimator::identifiability`).
    pub fn identifiability(&self) -> T {
        self.identifiability
    }

    /// Samples needed (at the raw rate) before the first estimate: `(2n+1)·D`.
    pub fn warm_up_samples(&self) -> u32 {
        (2 * self.config.step.order as u32 + 1) * self.config.step.decimation as u32
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        Self::new(self.config)
    }

    /// Mark the current reading invalid; the solution goes with the estimate.
    fn invalidate(&mut self, reason: InvalidReason) {
        self.solution = None;
        self.intake.invalidate(reason);
    }

    /// Invalidate and stay invalid until the reset.
    fn latch(&mut self, reason: InvalidReason) {
        self.solution = None;
        self.intake.latch(reason);
    }

    /// The LS factor downdated by the expected noise information and the smallest share
    /// over the floor, or `None` when a pivot keeps no more than `max(√(2/N_eff), 100·ε)`
    /// of its uncompensated value (the signal's share of that direction is not resolved
    /// from the noise's; ≤ 0: indefinite). Without a noise variance the share is zero: no
    /// compensation, nothing resolved.
    fn compensated(&self, n: usize) -> Option<(Factor<T, N, 1>, T)> {
        let mut factor = self.factor.clone();
        let weight = -(self.effective_rows * self.decimated_variance);
        if weight == T::ZERO {
            return Some((factor, T::ZERO));
        }
        let lead_before = factor.lead_weight();
        let [tail_before] = factor.tail_weight();
        for j in 0..=n {
            // Noise sample e(k−n+j): +1 in Δx(k−n+j−1), −1 in Δx(k−n+j), and it is the
            // target's own noise when j = n.
            let mut lead = [T::ZERO; N];
            if j >= 1 {
                lead[j - 1] = T::ONE;
            }
            if j < n {
                lead[j] = -T::ONE;
            }
            let target = if j == n { T::ONE } else { T::ZERO };
            factor.fold_weighted(n, lead, [T::ZERO], target, weight);
        }
        // Each downdated pivot over its LS value is the share of that direction's energy the
        // noise model leaves to the signal. The noise's own energy over N_eff rows fluctuates
        // by about √(2/N_eff) of itself (a χ² with N_eff degrees of freedom), so a share
        // below that is not resolved from zero: the compensation there is noise, and its
        // inverse (the estimate) is unbounded. It also covers the rounding level.
        let rounding = T::from_f64(100.0) * T::EPSILON;
        let resolved = (T::from_f64(2.0) / self.effective_rows).sqrt();
        let floor = if resolved > rounding {
            resolved
        } else {
            rounding
        };
        let lead_after = factor.lead_weight();
        let [tail_after] = factor.tail_weight();
        let mut margin = tail_after / (floor * tail_before);
        for i in 0..n {
            if !(lead_after[i] > floor * lead_before[i]) {
                return None;
            }
            let share = lead_after[i] / (floor * lead_before[i]);
            if share < margin {
                margin = share;
            }
        }
        if !(tail_after > floor * tail_before) {
            return None;
        }
        Some((factor, margin))
    }

    fn update(&mut self, x: T) {
        let n = self.config.step.order;
        if !self.differences.push(x, n) {
            return;
        }
        let phi = self.differences.window();
        let prior_residual = self
            .solution
            .map(|(lead, step)| row_residual(x, &phi, &lead, step, n));
        let lambda = self.config.step.forgetting;
        if lambda < T::ONE {
            self.factor.forget(n, lambda);
        }
        self.effective_rows = self.effective_rows * lambda + T::ONE;
        let growing = lambda == T::ONE;
        if growing {
            self.uncertainty.push_row(&phi, n);
        }
        let folded = self.factor.fold(n, phi, [T::ONE], x - self.offset);
        if growing {
            self.uncertainty
                .push_residual(folded.residual, folded.row_weight);
        }
        self.rows = self.rows.saturating_add(1);
        let [ls_deviation] = self.factor.tail_solution();
        let ls_step = self.offset + ls_deviation;
        let [ls_weight] = self.factor.tail_weight();
        if !(ls_step.is_finite() && ls_weight.is_finite() && folded.row_weight.is_finite()) {
            self.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < n + 1 {
            return;
        }
        let compensated = self.compensated(n);
        // Where `StepEstimator` would read this least-squares step level, move the factor's
        // origin to it as that does (σ² = 0 stays least squares bit for bit); the
        // compensated copy above is in the old origin.
        let origin = self.offset;
        if ls_weight > identifiability_floor::<T>() * self.effective_rows {
            self.offset = recentre(&mut self.factor, n, self.offset, ls_step);
        }
        let Some((compensated, margin)) = compensated else {
            self.identifiability = T::ZERO;
            self.invalidate(InvalidReason::IllConditioned);
            return;
        };
        let [weight] = compensated.tail_weight();
        self.identifiability = weight / self.effective_rows;
        let threshold = identifiability_floor::<T>() * self.effective_rows;
        let (lead, [deviation]) = compensated.solution(n);
        let step = origin + deviation;
        // A compensated copy is discarded after each reading, so a non-finite value here is a
        // property of the current data, not a corrupted state: flag, don't latch.
        if !(weight > threshold) || !step.is_finite() || !lead[..n].iter().all(|v| v.is_finite()) {
            self.invalidate(InvalidReason::IllConditioned);
            return;
        }
        // The consistency check on what the compensated fit leaves of this row (a-posteriori,
        // as in `IvStepEstimator`: no standardising weight for the compensated equations).
        let mismatch = match self.check.as_mut() {
            Some(check) => {
                let residual = row_residual(x, &phi, &lead, step, n);
                check.push(residual * residual, difference_noise_gain::<T, 1>(&lead, n));
                check.mismatch(|| difference_correlation::<T, 1>(&lead, n))
            }
            None => false,
        };
        if mismatch {
            // Not latched.
            self.invalidate(InvalidReason::ModelMismatch);
            return;
        }
        self.solution = Some((lead, step));
        self.intake.estimating(step, prior_residual);
        // The first-order `u` only where every share is resolved well beyond the floor
        // (`crate::estimators::bc_uncertainty`).
        let resolved = margin >= T::from_f64(RESOLVED_FOR_UNCERTAINTY);
        if growing && resolved && BcUncertainty::<T, N, L>::covers(n) {
            let (least_squares_lead, _) = self.factor.solution(n);
            let compensated = Compensated {
                factor: &compensated,
                lead: &lead,
                level: step,
                least_squares_lead: &least_squares_lead,
                least_squares_level: ls_step,
            };
            let u =
                self.uncertainty
                    .uncertainty(n, compensated, &self.factor, self.decimated_variance);
            self.intake.state_uncertainty(u);
        }
    }
}

estimator_via_intake!(BiasCompensatedStepEstimator<T, const N, const L>);
