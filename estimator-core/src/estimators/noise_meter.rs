//! Measures the white-noise variance of the raw samples on an empty pan (at tare), for the
//! bias-compensated estimator ([`crate::BiasCompensatedStepEstimator`]).
//!
//! It works on first differences of block means, with their mean removed: a constant offset
//! cancels in the differences, and a slow linear drift only shifts their mean, so neither
//! inflates the variance. For block means `x̄(m)` of white noise with variance `v` the
//! differences `δ(m) = x̄(m+1) − x̄(m)` have variance `2v` and adjacent ones correlate by
//! `−v`; with `M` differences, `E[Σ(δ − δ̄)²] = 2v·M − 2v/M` (because `δ̄ = (x̄(M) − x̄(0))/M`),
//! so `v̂ = Σ(δ − δ̄)²·M / (2(M² − 1))` is unbiased. Its relative standard error is
//! `√(3/M)` (the differences are MA(1): `var Σδ² ≈ 2M(γ₀² + 2γ₁²) = 12M·v²`): 1,200 raw
//! samples (0.3 s at 4 kHz) at `D = 1` give 5%.
//!
//! The meter reports `D·v̂` in raw units², the raw-rate variance the estimator's
//! configuration takes (it divides by `D` again). Measuring at the estimator's own block
//! length `D` makes that value right for the block means even when the raw noise is not
//! white (e.g. amplifier noise coloured by the anti-alias filter), which is what the
//! compensation needs. It must never be fed samples with a load on the pan: a load step
//! is not a slow drift.

use crate::estimators::input::{check_sample, Decimator};
use crate::estimators::step::MAX_DECIMATION;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// A running, allocation-free noise-variance meter. See the module docs.
#[derive(Clone, Debug)]
pub struct NoiseMeter<T> {
    decimation: u16,
    decimator: Decimator<T>,
    previous: Option<T>,
    differences: u32,
    /// Running mean and sum of squared deviations of the differences (Welford).
    mean: T,
    sum_squares: T,
    fault: Option<InvalidReason>,
}

impl<T: Real> NoiseMeter<T> {
    /// A meter over block means of `decimation` raw samples (use the estimator's `D`).
    pub fn new(decimation: u16) -> Result<Self, ConfigError> {
        if decimation == 0 || decimation > MAX_DECIMATION {
            return Err(ConfigError::Decimation);
        }
        Ok(Self {
            decimation,
            decimator: Decimator::new(decimation),
            previous: None,
            differences: 0,
            mean: T::ZERO,
            sum_squares: T::ZERO,
            fault: None,
        })
    }

    /// Feed one raw empty-pan sample (offset removed or not). A NaN or infinite sample is
    /// refused, and latched: the meter reports no variance until `reset()`.
    pub fn push(&mut self, sample: T) -> Result<(), InvalidReason> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        let inf = T::from_f64(f64::INFINITY);
        let sample = match check_sample(sample, -inf, inf) {
            Ok(sample) => sample,
            Err(reason) => {
                self.fault = Some(reason);
                return Err(reason);
            }
        };
        let Some(mean) = self.decimator.push(sample) else {
            return Ok(());
        };
        if let Some(previous) = self.previous {
            let difference = mean - previous;
            self.differences = self.differences.saturating_add(1);
            let delta = difference - self.mean;
            self.mean += delta / T::from_u32(self.differences);
            self.sum_squares += delta * (difference - self.mean);
            if !(self.sum_squares.is_finite() && self.mean.is_finite()) {
                self.fault = Some(InvalidReason::NonFiniteUpdate);
                return Err(InvalidReason::NonFiniteUpdate);
            }
        }
        self.previous = Some(mean);
        Ok(())
    }

    /// Tell the meter a sample was lost: the block it falls in is broken, so start the
    /// differences afresh (what was measured so far is kept).
    pub fn push_missing(&mut self) {
        self.decimator = Decimator::new(self.decimation);
        self.previous = None;
    }

    /// The raw-sample noise variance `D·v̂` in raw units², once at least two differences were
    /// seen and no fault latched.
    pub fn noise_variance(&self) -> Option<T> {
        if self.fault.is_some() || self.differences < 2 {
            return None;
        }
        let m = T::from_u32(self.differences);
        let v = self.sum_squares * m / (T::from_f64(2.0) * (m * m - T::ONE));
        Some(v * T::from_u32(self.decimation as u32))
    }

    /// Relative standard error of [`Self::noise_variance`] for white noise, `√(3/M)`.
    pub fn relative_standard_error(&self) -> Option<T> {
        if self.differences < 2 {
            return None;
        }
        Some((T::from_f64(3.0) / T::from_u32(self.differences)).sqrt())
    }

    /// Differences of block means seen so far.
    pub fn differences(&self) -> u32 {
        self.differences
    }

    /// The block length `D`.
    pub fn decimation(&self) -> u16 {
        self.decimation
    }

    /// Forget everything (e.g. before a new tare).
    pub fn reset(&mut self) {
        *self = Self {
            decimation: self.decimation,
            decimator: Decimator::new(self.decimation),
            previous: None,
            differences: 0,
            mean: T::ZERO,
            sum_squares: T::ZERO,
            fault: None,
        };
    }
}
