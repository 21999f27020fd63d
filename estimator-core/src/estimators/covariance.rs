//! The textbook covariance-form RLS of the thesis (eq. 3.24), kept as a reference.
//!
//! It solves the same regression as [`crate::StepEstimator`] but propagates the inverse
//! information matrix `Ψ` directly. In `f64` on short runs it agrees with the factored form;
//! in `f32`, on the ill-conditioned Hankel data of a fast-sampled sensor and over long runs
//! with forgetting, `Ψ` loses symmetry and positive definiteness and the estimate drifts or
//! blows up. It exists to show that, in tests and studies; firmware does not use it.
//!
//! Initialisation: instead of inverting the first `(n+1)×(n+1)` block, `Ψ(0) = I/δ` with a
//! tiny δ (a regularised prior), the usual practical choice; the prior's weight decays
//! with forgetting and is negligible against the data after a few rows.
//!
//! ## Flags (found by the stability map, host-sim `study stability`)
//! - In `f32` Ψ loses positive definiteness within the first rows of the reference drop at
//!   every SNR and order the map tried, its readings then off by orders of magnitude beyond
//!   the Cramér–Rao bound. Each update therefore factors Ψ (LDLᵀ in `f64`, `(n+1)³/6`
//!   multiply–adds, more than the update itself: a reference may pay that) and latches
//!   [`InvalidReason::LostDefiniteness`] at a pivot not above the rounding of its diagonal
//!   entry, or at a gain denominator `λ + φᵀΨφ` below λ (φᵀΨφ < 0 proves Ψ indefinite).
//! - Readings whose identifiability `1/(Ψ_uu·(N_eff + δλ^k))` is not above
//!   [`crate::MIN_IDENTIFIABILITY`] are `Invalid(IllConditioned)`, as in `StepEstimator`.
//! - As in `StepEstimator`, the step level is kept relative to an origin that follows the
//!   estimate (`offset`): kept as the load itself, in `f32` it stalled over long runs.

use crate::estimators::consistency::{
    difference_correlation, difference_noise_gain, ResidualCheck,
};
use crate::estimators::input::Decimator;
use crate::estimators::intake::{estimator_via_intake, Intake};
use crate::estimators::step::{identifiability_floor, StepConfig};
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// Covariance-form RLS for the data-driven step estimator, capacity `N` (order ≤ N).
/// `P` must be `N + 1` (the number of unknowns); checked at construction.
#[derive(Clone, Debug)]
pub struct CovarianceStepEstimator<T: Real, const N: usize, const P: usize> {
    config: StepConfig<T>,
    /// Block means as `sum / D`, the textbook rule this reference keeps.
    intake: Intake<T>,
    prior: T,
    psi: [[T; P]; P],
    theta: [T; P],
    deltas: [T; N],
    previous: T,
    decimated_samples: u32,
    rows: u32,
    /// Exponentially weighted row count: the information the data put on the constant column.
    effective_rows: T,
    /// The prior's information δ, decayed by λ per row.
    prior_weight: T,
    /// The origin of the targets: `theta[n]` is the step level minus this.
    offset: T,
    /// The consistency check, when configured with a noise reference.
    check: Option<ResidualCheck<T>>,
}

impl<T: Real, const N: usize, const P: usize> CovarianceStepEstimator<T, N, P> {
    /// A new estimator with prior `Ψ(0) = I/δ`, δ = `prior_information`.
    pub fn new(config: StepConfig<T>, prior_information: T) -> Result<Self, ConfigError> {
        config.validate(N)?;
        if P != N + 1 || !(prior_information > T::ZERO) || !prior_information.is_finite() {
            return Err(ConfigError::Model);
        }
        let mut psi = [[T::ZERO; P]; P];
        for (i, row) in psi.iter_mut().enumerate() {
            row[i] = T::ONE / prior_information;
        }
        Ok(Self {
            config,
            intake: Intake::new(
                T::ONE / config.gain,
                config.valid_min,
                config.valid_max,
                Decimator::dividing(config.decimation),
            ),
            prior: prior_information,
            psi,
            theta: [T::ZERO; P],
            deltas: [T::ZERO; N],
            previous: T::ZERO,
            decimated_samples: 0,
            rows: 0,
            effective_rows: T::ZERO,
            prior_weight: prior_information,
            offset: T::ZERO,
            check: config.residual_check(),
        })
    }

    /// The smallest diagonal entry of Ψ: negative means positive definiteness is lost.
    pub fn min_psi_diagonal(&self) -> T {
        let n = self.config.order + 1;
        let mut min = self.psi[0][0];
        for i in 1..n {
            if self.psi[i][i] < min {
                min = self.psi[i][i];
            }
        }
        min
    }

    /// Ψ, the inverse information matrix (its leading `(n+1)×(n+1)` block is in use), for
    /// studies that test it for positive definiteness.
    pub fn inverse_information(&self) -> &[[T; P]; P] {
        &self.psi
    }

    /// `1 / (Ψ_uu·(N_eff + δ·λ^rows))`, the analogue of `StepEstimator::identifiability`:
    /// the information on `u` is at most that of the constant column, `N_eff` plus the
    /// decayed prior, so in exact arithmetic this lies in (0, 1]. Outside, Ψ no longer is the
    /// inverse of any information matrix of these data.
    pub fn identifiability(&self) -> T {
        let n = self.config.order;
        let information = self.effective_rows + self.prior_weight;
        T::ONE / (self.psi[n][n] * information)
    }

    /// True when the leading `(n+1)×(n+1)` block of Ψ, as stored, has an LDLᵀ factorisation
    /// whose pivots are positive beyond the rounding of their diagonal entries in `T`,
    /// `(n+1)·ε_T·Ψ_ii`: Ψ is positive definite as stored. Computed in `f64` whatever `T`:
    /// in `f32` the factorisation cannot resolve the indefiniteness it must find (the map
    /// found runs that an `f32` LDLᵀ passed and an `f64` Cholesky did not). This form is a
    /// host reference, so the cost is accepted.
    fn positive_definite(&self) -> bool {
        let p = self.config.order + 1;
        let rounding = p as f64 * T::EPSILON.to_f64();
        // L (unit lower, strictly below the diagonal) and the pivots, row by row.
        let mut l = [[0.0f64; P]; P];
        let mut pivots = [0.0f64; P];
        for i in 0..p {
            for j in 0..i {
                let mut value = self.psi[i][j].to_f64();
                for k in 0..j {
                    value -= l[i][k] * l[j][k] * pivots[k];
                }
                l[i][j] = value / pivots[j];
            }
            let diagonal = self.psi[i][i].to_f64();
            let mut pivot = diagonal;
            for k in 0..i {
                pivot -= l[i][k] * l[i][k] * pivots[k];
            }
            if !(pivot > rounding * diagonal) || !pivot.is_finite() {
                return false;
            }
            pivots[i] = pivot;
        }
        true
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        Self::new(self.config, self.prior)
    }

    fn update(&mut self, x: T) {
        let n = self.config.order;
        let p = n + 1;
        let k = self.decimated_samples;
        self.decimated_samples = k.saturating_add(1);
        if k == 0 {
            self.previous = x;
            return;
        }
        let delta = x - self.previous;
        self.previous = x;
        self.deltas.copy_within(1..n, 0);
        self.deltas[n - 1] = delta;
        if (k as usize) < n {
            return;
        }
        // Regressor φ = [Δ…, 1]; unknowns θ = [ℓ; u] as in the factored form.
        let mut phi = [T::ZERO; P];
        phi[..n].copy_from_slice(&self.deltas[..n]);
        phi[n] = T::ONE;
        let lambda = self.config.forgetting;
        let mut psi_phi = [T::ZERO; P];
        for i in 0..p {
            let mut acc = T::ZERO;
            for j in 0..p {
                acc += self.psi[i][j] * phi[j];
            }
            psi_phi[i] = acc;
        }
        let mut denom = lambda;
        let mut prediction = T::ZERO;
        for i in 0..p {
            denom += phi[i] * psi_phi[i];
            prediction += phi[i] * self.theta[i];
        }
        let error = (x - self.offset) - prediction;
        if let (Some(check), true) = (self.check.as_mut(), self.rows as usize >= p) {
            // λ/(λ + φᵀΨφ)·e² is the row's increment of the weighted residual sum of squares
            // (the factored form's w·e²); ℓ before the update, as the residual used it.
            let noise_gain = difference_noise_gain::<T, 1>(&self.theta[..n], n);
            check.push(lambda / denom * error * error, noise_gain);
        }
        for i in 0..p {
            self.theta[i] += psi_phi[i] / denom * error;
        }
        let inv_lambda = T::ONE / lambda;
        for i in 0..p {
            for j in 0..p {
                self.psi[i][j] = (self.psi[i][j] - psi_phi[i] * psi_phi[j] / denom) * inv_lambda;
            }
        }
        self.rows = self.rows.saturating_add(1);
        self.effective_rows = self.effective_rows * lambda + T::ONE;
        self.prior_weight *= lambda;
        let u = self.offset + self.theta[n];
        if !(u.is_finite() && denom.is_finite() && self.psi[n][n].is_finite()) {
            self.intake.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        // φᵀΨφ < 0 (a denominator below λ) proves the Ψ this row used indefinite; the LDLᵀ
        // test checks the Ψ the next row will use.
        if !(denom >= lambda) || !self.positive_definite() {
            self.intake.latch(InvalidReason::LostDefiniteness);
            return;
        }
        if (self.rows as usize) < p {
            return;
        }
        if !(self.identifiability() > identifiability_floor::<T>()) {
            self.intake.invalidate(InvalidReason::IllConditioned);
            return;
        }
        let theta = self.theta;
        let mismatch = self
            .check
            .as_ref()
            .is_some_and(|check| check.mismatch(|| difference_correlation::<T, 1>(&theta[..n], n)));
        let had_estimate = self.intake.estimate().is_some();
        // Move the origin to the estimate (exact difference of the stored origins, as in
        // `step::recentre`); only the step unknown changes.
        let origin = self.offset + (u - self.offset);
        let applied = origin - self.offset;
        self.theta[n] -= applied;
        self.offset = origin;
        if mismatch {
            // Not latched, as in `StepEstimator`.
            self.intake.invalidate(InvalidReason::ModelMismatch);
            return;
        }
        self.intake.estimating(u, had_estimate.then_some(error));
    }
}

estimator_via_intake!(CovarianceStepEstimator<T, const N, const P>);
