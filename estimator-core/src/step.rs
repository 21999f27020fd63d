//! The data-driven step-input estimator (Markovsky 2015; Quintana-Carapia 2020, ch. 3).
//!
//! For a step input `u` on an LTI sensor of order `n` with static gain `G`, every sample
//! after the first `n` satisfies
//!
//! ```text
//! y(k) = G·u + Σ_{i=1..n} ℓ_i · Δy(k−n+i−1),     Δy(j) = y(j+1) − y(j)
//! ```
//!
//! (thesis eq. 3.15). We divide by `G` first, so the unknowns are `[ℓ'; u]` with the
//! constant column equal to one and `u` in the caller's unit, and solve the growing (or
//! exponentially weighted) least-squares problem recursively.
//!
//! ## The recursive form
//! The thesis uses the textbook covariance RLS (eq. 3.24), initialised by inverting the
//! first `(n+1)×(n+1)` block. In `f32` that form loses positive definiteness on the
//! ill-conditioned Hankel data of a fast-sampled sensor. We instead keep the *information*
//! square root `R = D^{1/2}·U` (unit upper-triangular `U`, diagonal `D`) and fold each new
//! row in with Gentleman's square-root-free Givens rotations (Gentleman 1973, Miller's
//! AS 274). Why this form:
//! - it is a QR factorisation of the weighted regression matrix, so it is backward stable
//!   and needs no prior: starting from `D = 0` the first `n+1` rows give the exact
//!   least-squares solution, and every later estimate equals the batch solution;
//! - no square roots (the M4F's `VSQRT` is out of reach of safe `no_std` code, and a
//!   software square root would cost more than the whole update);
//! - the step level is the *last* unknown, so with a unit triangular factor it is read off
//!   directly (`θ_u`), without a back substitution;
//! - forgetting scales only the `n+1` diagonal weights;
//! - the row left over after the rotations is the a-priori residual, for free.

use crate::reading::{ConfigError, Estimator, InvalidReason, Reading, State};
use crate::real::Real;

/// The largest block length the decimator accepts.
pub const MAX_DECIMATION: u16 = 1024;

/// Configuration of a [`StepEstimator`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepConfig<T> {
    /// Model order `n` used by the regression (1 ≤ n ≤ capacity).
    pub order: usize,
    /// Static gain `G`: raw units per unit of the estimate (e.g. counts per gram).
    pub gain: T,
    /// Forgetting factor λ ∈ (0, 1]; 1 keeps a growing window.
    pub forgetting: T,
    /// Block-average this many raw samples before each regression update (1 = full rate).
    pub decimation: u16,
    /// Raw samples outside `[min, max]` invalidate the reading (saturation, wiring faults).
    pub valid_min: T,
    /// See `valid_min`.
    pub valid_max: T,
}

impl<T: Real> StepConfig<T> {
    /// Order `n`, gain `G`, growing window, full rate, no range limit.
    pub fn new(order: usize, gain: T) -> Self {
        Self {
            order,
            gain,
            forgetting: T::ONE,
            decimation: 1,
            valid_min: T::from_f64(f64::NEG_INFINITY),
            valid_max: T::from_f64(f64::INFINITY),
        }
    }

    /// Set the forgetting factor λ.
    pub fn with_forgetting(mut self, forgetting: T) -> Self {
        self.forgetting = forgetting;
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

    /// Check the configuration against an estimator capacity.
    pub fn validate(&self, capacity: usize) -> Result<(), ConfigError> {
        if self.order == 0 || self.order > capacity {
            return Err(ConfigError::Order {
                requested: self.order,
                capacity,
            });
        }
        if !self.gain.is_finite() || self.gain == T::ZERO {
            return Err(ConfigError::Gain);
        }
        // Written so that NaN fails too.
        if !(self.forgetting > T::ZERO && self.forgetting <= T::ONE) {
            return Err(ConfigError::Forgetting);
        }
        if self.decimation == 0 || self.decimation > MAX_DECIMATION {
            return Err(ConfigError::Decimation);
        }
        if !(self.valid_min < self.valid_max) {
            return Err(ConfigError::Range);
        }
        Ok(())
    }
}

/// The data-driven step-input estimator with capacity for orders up to `N`.
///
/// Fixed size, no allocation, never panics on data. See the module docs for the method.
#[derive(Clone, Debug)]
pub struct StepEstimator<T: Real, const N: usize> {
    config: StepConfig<T>,
    inv_gain: T,
    inv_decimation: T,
    /// Strict upper triangle of the unit triangular factor among the difference columns.
    coupling: [[T; N]; N],
    /// Column of the unit triangular factor that couples each difference column to `u`.
    coupling_u: [T; N],
    /// Diagonal weights `D` of the difference columns.
    weight: [T; N],
    /// Diagonal weight of the constant column: the squared norm of its part orthogonal to
    /// the difference columns.
    weight_u: T,
    /// Transformed right-hand side; its last entry is the estimate of `u`.
    rhs: [T; N],
    rhs_u: T,
    /// The last `n` differences, oldest first: the regressor of the next row.
    deltas: [T; N],
    previous: T,
    /// Decimated samples seen (saturating), which tells when the regressor is full.
    decimated_samples: u32,
    /// Regression rows folded in (saturating).
    rows: u32,
    /// Exponentially weighted row count, the scale for the conditioning test.
    effective_rows: T,
    block_sum: T,
    block_len: u16,
    samples: u32,
    /// A fault that broke the data stream or the state; latched until `reset()`.
    fault: Option<InvalidReason>,
    state: State,
    estimate: Option<T>,
    residual: Option<T>,
}

impl<T: Real, const N: usize> StepEstimator<T, N> {
    /// A new estimator, or the reason the configuration is impossible.
    pub fn new(config: StepConfig<T>) -> Result<Self, ConfigError> {
        config.validate(N)?;
        Ok(Self {
            config,
            inv_gain: T::ONE / config.gain,
            inv_decimation: T::ONE / T::from_u32(config.decimation as u32),
            coupling: [[T::ZERO; N]; N],
            coupling_u: [T::ZERO; N],
            weight: [T::ZERO; N],
            weight_u: T::ZERO,
            rhs: [T::ZERO; N],
            rhs_u: T::ZERO,
            deltas: [T::ZERO; N],
            previous: T::ZERO,
            decimated_samples: 0,
            rows: 0,
            effective_rows: T::ZERO,
            block_sum: T::ZERO,
            block_len: 0,
            samples: 0,
            fault: None,
            state: State::WarmingUp,
            estimate: None,
            residual: None,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &StepConfig<T> {
        &self.config
    }

    /// The capacity `N`: the largest order this instance accepts.
    pub const fn capacity() -> usize {
        N
    }

    /// How well the step level is identified: the squared sine of the angle between the
    /// constant column and the span of the difference columns, in (0, 1]. It is the factor
    /// by which noise on the data is amplified into the estimate (as 1/√·); the estimator
    /// flags [`InvalidReason::IllConditioned`] when it falls to the rounding level of `T`.
    pub fn identifiability(&self) -> T {
        if self.effective_rows > T::ZERO {
            self.weight_u / self.effective_rows
        } else {
            T::ZERO
        }
    }

    /// Samples needed (at the raw rate) before the first estimate: `(2n+1)·D`.
    pub fn warm_up_samples(&self) -> u32 {
        (2 * self.config.order as u32 + 1) * self.config.decimation as u32
    }

    /// Push an integer ADC reading: the zero offset is removed in integer arithmetic
    /// before the conversion to `T`, so no precision is lost to a large offset.
    pub fn push_counts(&mut self, counts: i32, zero_counts: i32) -> Reading<T> {
        let centred = counts.saturating_sub(zero_counts);
        self.push(T::from_i32(centred))
    }

    fn reading(&self) -> Reading<T> {
        Reading {
            estimate: self.estimate,
            samples: self.samples,
            state: self.state,
            residual: self.residual,
        }
    }

    /// Mark the current reading invalid; the next determined update may clear it.
    fn invalidate(&mut self, reason: InvalidReason) -> Reading<T> {
        self.state = State::Invalid(reason);
        self.estimate = None;
        self.residual = None;
        self.reading()
    }

    /// Invalidate and stay invalid until `reset()`: the data stream or the state is broken.
    fn latch(&mut self, reason: InvalidReason) -> Reading<T> {
        self.fault = Some(reason);
        self.invalidate(reason)
    }

    /// One decimated sample `x` (in the estimate's unit) into the regression.
    fn update(&mut self, x: T) {
        let n = self.config.order;
        let k = self.decimated_samples;
        self.decimated_samples = k.saturating_add(1);
        if k == 0 {
            self.previous = x;
            return;
        }
        // Shift the new difference Δx(k−1) into the regressor.
        let delta = x - self.previous;
        self.previous = x;
        self.deltas.copy_within(1..n, 0);
        self.deltas[n - 1] = delta;
        if (k as usize) < n {
            return;
        }

        let lambda = self.config.forgetting;
        if lambda < T::ONE {
            for d in self.weight[..n].iter_mut() {
                *d *= lambda;
            }
            self.weight_u *= lambda;
        }
        self.effective_rows = self.effective_rows * lambda + T::ONE;

        // Fold the row [Δ…, 1 | x] into (D, U, rhs) with square-root-free Givens rotations.
        let mut row = self.deltas;
        let mut row_u = T::ONE;
        let mut target = x;
        let mut row_weight = T::ONE;
        for i in 0..n {
            let xi = row[i];
            if xi == T::ZERO {
                continue;
            }
            let di = self.weight[i];
            let wx = row_weight * xi;
            let new_d = di + wx * xi;
            let cbar = di / new_d;
            let sbar = wx / new_d;
            row_weight *= cbar;
            self.weight[i] = new_d;
            let coupling = &mut self.coupling[i];
            for j in (i + 1)..n {
                let xj = row[j];
                row[j] = xj - xi * coupling[j];
                coupling[j] = cbar * coupling[j] + sbar * xj;
            }
            let xu = row_u;
            row_u = xu - xi * self.coupling_u[i];
            self.coupling_u[i] = cbar * self.coupling_u[i] + sbar * xu;
            let t = target;
            target = t - xi * self.rhs[i];
            self.rhs[i] = cbar * self.rhs[i] + sbar * t;
            if row_weight == T::ZERO {
                // Column i had no weight yet: the whole row now defines it.
                break;
            }
        }
        let had_estimate = self.estimate.is_some();
        if row_u != T::ZERO && row_weight != T::ZERO {
            let wx = row_weight * row_u;
            let new_d = self.weight_u + wx * row_u;
            let cbar = self.weight_u / new_d;
            let sbar = wx / new_d;
            row_weight *= cbar;
            self.weight_u = new_d;
            let t = target;
            target = t - row_u * self.rhs_u;
            self.rhs_u = cbar * self.rhs_u + sbar * t;
        }
        self.rows = self.rows.saturating_add(1);

        if !(self.rhs_u.is_finite() && self.weight_u.is_finite() && row_weight.is_finite()) {
            self.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < n + 1 {
            return;
        }
        // weight_u / effective_rows is the squared sine of the angle between the constant
        // column and the span of the difference columns; near zero, u is not identifiable.
        // Not latched: right after warm-up a fast-sampled Hankel system can be too
        // ill-conditioned for the precision, and more rows cure that (the factorisation is
        // backward stable, so the early rounding does not persist).
        let threshold = T::from_f64(100.0) * T::EPSILON * self.effective_rows;
        if !(self.weight_u > threshold) {
            self.invalidate(InvalidReason::IllConditioned);
            return;
        }
        self.residual = if had_estimate { Some(target) } else { None };
        self.state = State::Estimating;
        self.estimate = Some(self.rhs_u);
    }
}

impl<T: Real, const N: usize> Estimator<T> for StepEstimator<T, N> {
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
        if self.config.decimation == 1 {
            self.update(x);
        } else {
            self.block_sum += x;
            self.block_len += 1;
            if self.block_len == self.config.decimation {
                let mean = self.block_sum * self.inv_decimation;
                self.block_sum = T::ZERO;
                self.block_len = 0;
                self.update(mean);
            }
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
        let config = self.config;
        // The configuration was validated in `new`, so this cannot fail.
        if let Ok(fresh) = Self::new(config) {
            *self = fresh;
        }
    }
}
