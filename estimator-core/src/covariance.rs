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

use crate::reading::{ConfigError, Estimator, InvalidReason, Reading, State};
use crate::real::Real;
use crate::step::StepConfig;

/// Covariance-form RLS for the data-driven step estimator, capacity `N` (order ≤ N).
/// `P` must be `N + 1` (the number of unknowns); checked at construction.
#[derive(Clone, Debug)]
pub struct CovarianceStepEstimator<T: Real, const N: usize, const P: usize> {
    config: StepConfig<T>,
    inv_gain: T,
    prior: T,
    psi: [[T; P]; P],
    theta: [T; P],
    deltas: [T; N],
    previous: T,
    decimated_samples: u32,
    rows: u32,
    samples: u32,
    block_sum: T,
    block_len: u16,
    fault: Option<InvalidReason>,
    state: State,
    estimate: Option<T>,
    residual: Option<T>,
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
            inv_gain: T::ONE / config.gain,
            prior: prior_information,
            psi,
            theta: [T::ZERO; P],
            deltas: [T::ZERO; N],
            previous: T::ZERO,
            decimated_samples: 0,
            rows: 0,
            samples: 0,
            block_sum: T::ZERO,
            block_len: 0,
            fault: None,
            state: State::WarmingUp,
            estimate: None,
            residual: None,
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

    fn reading(&self) -> Reading<T> {
        Reading {
            estimate: self.estimate,
            samples: self.samples,
            state: self.state,
            residual: self.residual,
        }
    }

    fn latch(&mut self, reason: InvalidReason) -> Reading<T> {
        self.fault = Some(reason);
        self.state = State::Invalid(reason);
        self.estimate = None;
        self.residual = None;
        self.reading()
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
        let error = x - prediction;
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
        let u = self.theta[n];
        if !(u.is_finite() && denom.is_finite() && self.psi[n][n].is_finite()) {
            self.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < p {
            return;
        }
        self.state = State::Estimating;
        self.residual = self.estimate.map(|_| error);
        self.estimate = Some(u);
    }
}

impl<T: Real, const N: usize, const P: usize> Estimator<T> for CovarianceStepEstimator<T, N, P> {
    fn push(&mut self, sample: T) -> Reading<T> {
        self.samples = self.samples.saturating_add(1);
        if self.fault.is_some() {
            return self.reading();
        }
        if !sample.is_finite() {
            return self.latch(InvalidReason::NonFiniteInput);
        }
        if !(sample >= self.config.valid_min && sample <= self.config.valid_max) {
            return self.latch(InvalidReason::OutOfRange);
        }
        let x = sample * self.inv_gain;
        self.block_sum += x;
        self.block_len += 1;
        if self.block_len == self.config.decimation {
            let mean = self.block_sum / T::from_u32(self.config.decimation as u32);
            self.block_sum = T::ZERO;
            self.block_len = 0;
            self.update(mean);
        }
        self.reading()
    }

    fn push_missing(&mut self) -> Reading<T> {
        self.samples = self.samples.saturating_add(1);
        if self.fault.is_some() {
            return self.reading();
        }
        self.latch(InvalidReason::MissingSample)
    }

    fn reset(&mut self) {
        if let Ok(fresh) = Self::new(self.config, self.prior) {
            *self = fresh;
        }
    }
}
