//! Affine (ramp) input estimation for conveyor weighing (Quintana-Carapia 2020, ch. 6).
//!
//! A mass sliding onto a conveyor scale at constant speed is an input `u(t) = a·t + b`. The
//! thesis tracks `û(k)` with the exponentially weighted step estimator and fits a line to
//! it afterwards (eq. 6.3–6.6); but a ramp makes the constant column collinear with the
//! first differences (they tend to the constant `G·a`), and the tracked estimate lags.
//! We instead put the input model into the regression itself: second differences remove
//! both the constant and the slope from the response, so for an order-`n` sensor
//!
//! ```text
//! y(k)/G = c₀ + c₁·t_k + Σ ℓ_i · Δ²y(k−n+i−2)/G,      c₁ = a,  c₀ = b − a·τ
//! ```
//!
//! with τ the sensor's steady-state ramp lag. The slope is estimated without bias on an
//! LTI sensor; the intercept needs τ, calibrated with a reference mass (`lag_s`). The same
//! recursive engine as the step estimator solves it, with `[t, 1]` as trailing columns.
//!
//! With lag sums for orders up to `L − 1` (`RampEstimator<T, N, L>`, `L = 0` by default)
//! each reading states the standard uncertainty of the line at its time
//! (`crate::estimators::ramp_uncertainty`).

use crate::estimators::consistency::ResidualCheck;
use crate::estimators::input::DifferenceWindow;
use crate::estimators::intake::{estimator_via_intake, Intake};
use crate::estimators::ramp_uncertainty::RampUncertainty;
use crate::estimators::step::StepConfig;
use crate::numerics::factor::Factor;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason, Reading};

/// Configuration of a [`RampEstimator`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RampConfig<T> {
    /// Order, gain, forgetting, decimation, valid range and noise reference, as for the step
    /// estimator (the consistency check on second differences, `crate::estimators::consistency`).
    pub regression: StepConfig<T>,
    /// Time between raw samples, in seconds: the slope is per second.
    pub sample_period_s: T,
    /// The sensor's steady-state ramp lag τ (calibrated): `b = c₀ + a·τ`.
    pub lag_s: T,
}

/// The data-driven affine-input estimator, capacity order `N`, stating the standard
/// uncertainty of its readings for orders below `L` (the default 0 states none).
#[derive(Clone, Debug)]
pub struct RampEstimator<T: Real, const N: usize, const L: usize = 0> {
    config: RampConfig<T>,
    /// Its estimate is the line's intercept `b`; the reading moves it along `slope`.
    intake: Intake<T>,
    decimated_period_s: T,
    differences: DifferenceWindow<T, N, 2>,
    /// Leading: second differences; trailing: `[t, 1]`.
    factor: Factor<T, N, 2>,
    decimated_samples: u32,
    rows: u32,
    effective_rows: T,
    /// The consistency check, when configured with a noise reference.
    check: Option<ResidualCheck<T>>,
    /// `Σc²` of the latest solution (second differences).
    noise_gain: T,
    /// The line's slope `a`, valid while the intake has an intercept.
    slope: T,
    /// What the readings' standard uncertainty needs.
    uncertainty: RampUncertainty<T, L>,
}

impl<T: Real, const N: usize, const L: usize> RampEstimator<T, N, L> {
    /// A new ramp estimator, or why the configuration is impossible.
    pub fn new(config: RampConfig<T>) -> Result<Self, ConfigError> {
        config.regression.validate(N)?;
        if !(config.sample_period_s > T::ZERO)
            || !config.sample_period_s.is_finite()
            || !config.lag_s.is_finite()
        {
            return Err(ConfigError::Model);
        }
        let decimation = config.regression.decimation;
        Ok(Self {
            config,
            intake: config.regression.intake(),
            decimated_period_s: config.sample_period_s * T::from_u32(decimation as u32),
            differences: DifferenceWindow::new(),
            factor: Factor::new(),
            decimated_samples: 0,
            rows: 0,
            effective_rows: T::ZERO,
            check: config.regression.residual_check(),
            noise_gain: T::ONE,
            slope: T::ZERO,
            uncertainty: RampUncertainty::new(),
        })
    }

    /// The input line: slope `a` (estimate's unit per second) and intercept `b` (at the
    /// first raw sample after reset), once determined.
    pub fn line(&self) -> Option<(T, T)> {
        self.intake
            .estimate()
            .map(|intercept| (self.slope, intercept))
    }

    /// The intake's reading with the line evaluated at the latest raw sample.
    fn reading(&self) -> Reading<T> {
        let reading = self.intake.reading();
        let t = T::from_u32(reading.samples.saturating_sub(1)) * self.config.sample_period_s;
        Reading {
            estimate: reading.estimate.map(|b| self.slope * t + b),
            ..reading
        }
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        Self::new(self.config)
    }

    fn update(&mut self, x: T) {
        let n = self.config.regression.order;
        // The block mean sits at the middle of its block.
        let block_centre = T::from_f64(0.5 * (self.config.regression.decimation as f64 - 1.0))
            * self.config.sample_period_s;
        let t = T::from_u32(self.decimated_samples) * self.decimated_period_s + block_centre;
        self.decimated_samples = self.decimated_samples.saturating_add(1);
        if !self.differences.push(x, n) {
            return;
        }
        let lambda = self.config.regression.forgetting;
        if lambda < T::ONE {
            self.factor.forget(n, lambda);
        }
        self.effective_rows = self.effective_rows * lambda + T::ONE;
        let determined_before = self.rows as usize > n + 1;
        let window = self.differences.window();
        let growing = lambda == T::ONE;
        if growing {
            self.uncertainty.push_row(&window, t, n);
        }
        let folded = self.factor.fold(n, window, [t, T::ONE], x);
        self.rows = self.rows.saturating_add(1);
        let [slope, c0] = self.factor.tail_solution();
        if !(slope.is_finite() && c0.is_finite() && folded.row_weight.is_finite()) {
            self.intake.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < n + 2 {
            return;
        }
        if growing && determined_before {
            self.uncertainty
                .push_residual(folded.residual, folded.row_weight, n);
        }
        let mismatch = match self.check.as_mut() {
            Some(check) => {
                let residual = folded.residual;
                let standardised =
                    determined_before.then(|| folded.row_weight * residual * residual);
                let (lead, _) = self.factor.solution(n);
                check.push_a_priori_row::<2>(standardised, &mut self.noise_gain, &lead, n)
            }
            None => false,
        };
        let threshold = T::from_f64(100.0) * T::EPSILON * self.effective_rows;
        let [w_t, w_1] = self.factor.tail_weight();
        // The time column's weight grows like rows·t², so compare it on that scale.
        let t_scale = t * t;
        if !(w_1 > threshold && w_t > threshold * t_scale) {
            self.intake.invalidate(InvalidReason::IllConditioned);
            return;
        }
        if mismatch {
            // Not latched, as in `StepEstimator`.
            self.intake.invalidate(InvalidReason::ModelMismatch);
            return;
        }
        self.slope = slope;
        self.intake.estimating(c0 + slope * self.config.lag_s, None);
        if growing {
            self.intake.state_uncertainty(self.line_uncertainty(n));
        }
    }

    /// The standard uncertainty of the line at the latest raw sample, the block's last
    /// (`crate::estimators::ramp_uncertainty`); `None` for `L ≤ n` or too few rows.
    fn line_uncertainty(&self, n: usize) -> Option<(T, u32)> {
        if !RampUncertainty::<T, L>::covers(n) {
            return None;
        }
        let latest = T::from_u32(self.intake.reading().samples.saturating_sub(1));
        let combination = [
            latest * self.config.sample_period_s + self.config.lag_s,
            T::ONE,
        ];
        let (z_lead, z_tail) = self.factor.tail_influence(n, combination)?;
        let (lead, _) = self.factor.solution(n);
        self.uncertainty.uncertainty(
            n,
            &lead,
            &z_lead,
            z_tail,
            combination,
            self.check.as_ref().and_then(ResidualCheck::noise_floor),
        )
    }
}

estimator_via_intake!(RampEstimator<T, const N, const L>, reading: Self::reading);
