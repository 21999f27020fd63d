//! The cell's oscillatory mode a pre-filter is tuned to, and its poles in discrete time.
//!
//! Why `f64`: at 4 kHz the 25 Hz mode of the reference cell lies 1.2e-3 from z = 1, so the
//! polynomial coefficients that place zeros on it lose three digits to cancellation; rounded
//! to `f32` they would move the cancelled pair by a fifth of its damping. The design runs
//! once, at configuration, in `f64` (software on the Cortex-M4F); only the filter runs in `T`.

use crate::reading::ConfigError;

/// A second-order mode `s² + 2ζω·s + ω²`: the natural frequency and damping ratio the
/// calibration identified with the load on, and the rate it is sampled at.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CellMode {
    /// Natural frequency, Hz.
    pub natural_frequency_hz: f64,
    /// Damping ratio ζ (0 for a mode on the unit circle).
    pub damping_ratio: f64,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
}

/// A pair of discrete poles (or zeros) `r1, r2`: the polynomial `(1 − r1·z⁻¹)(1 − r2·z⁻¹)`
/// in the backward difference `∇ = 1 − z⁻¹`, `dc + first·∇ + second·∇²` (the three sum to
/// one), each coefficient computed without the cancellation the direct form
/// `1 + a1·z⁻¹ + a2·z⁻²` suffers near z = 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct DiscretePair {
    /// `(1 − r1)(1 − r2)`, the polynomial at z = 1.
    pub(super) dc: f64,
    /// `r1 + r2 − 2·r1·r2`.
    pub(super) first: f64,
    /// `r1·r2`.
    pub(super) second: f64,
}

impl CellMode {
    /// The mode, or the name of the field that is out of its domain: a finite, positive rate;
    /// a frequency below the Nyquist frequency; `0 ≤ ζ` (and `ζ < 1` where `oscillatory`).
    pub(super) fn validate(&self, oscillatory: bool) -> Result<(), ConfigError> {
        if !(self.sample_rate_hz.is_finite() && self.sample_rate_hz > 0.0) {
            return Err(ConfigError::Filter("sample_rate_hz"));
        }
        let nyquist = 0.5 * self.sample_rate_hz;
        if !(self.natural_frequency_hz > 0.0 && self.natural_frequency_hz < nyquist) {
            return Err(ConfigError::Filter("natural_frequency_hz"));
        }
        let limit = if oscillatory { 1.0 } else { f64::INFINITY };
        if !(self.damping_ratio >= 0.0 && self.damping_ratio < limit) {
            return Err(ConfigError::Filter("damping_ratio"));
        }
        Ok(())
    }

    /// ω·h, the natural frequency in radians per sample.
    pub(super) fn omega_h(&self) -> f64 {
        2.0 * core::f64::consts::PI * self.natural_frequency_hz / self.sample_rate_hz
    }

    /// The upper discrete pole `ρ·e^{jθ}` of an oscillatory mode (`ζ < 1`) as `(ρ, θ)`.
    pub(super) fn pole(&self) -> (f64, f64) {
        let omega_h = self.omega_h();
        let zeta = self.damping_ratio;
        (
            libm::exp(-zeta * omega_h),
            omega_h * libm::sqrt(1.0 - zeta * zeta),
        )
    }

    /// The mode's two discrete poles `e^{s·h}` (a real pair from ζ ≥ 1 on).
    pub(super) fn discrete_pair(&self) -> DiscretePair {
        let omega_h = self.omega_h();
        let zeta = self.damping_ratio;
        if zeta < 1.0 {
            let (rho, theta) = self.pole();
            // 1 − ρ and 1 − cos θ = 2 sin²(θ/2), each without cancellation.
            let one_minus_rho = -libm::expm1(-zeta * omega_h);
            let half_sine = libm::sin(0.5 * theta);
            let one_minus_cos = 2.0 * half_sine * half_sine;
            DiscretePair {
                dc: one_minus_rho * one_minus_rho + 2.0 * rho * one_minus_cos,
                first: 2.0 * rho * (one_minus_rho - one_minus_cos),
                second: rho * rho,
            }
        } else {
            let root = libm::sqrt(zeta * zeta - 1.0);
            let (sigma1, sigma2) = (-(zeta - root) * omega_h, -(zeta + root) * omega_h);
            let (m1, m2) = (libm::expm1(sigma1), libm::expm1(sigma2));
            let (r1, r2) = (1.0 + m1, 1.0 + m2);
            DiscretePair {
                dc: m1 * m2,
                first: -(r1 * m2 + r2 * m1),
                second: r1 * r2,
            }
        }
    }
}
