//! Pole-zero compensation of the cell's mode: zeros on the cell's lightly damped pole pair,
//! a faster, well-damped pair in its place, unit gain at DC:
//!
//! `C(z) = g·D(z)/P(z)`, `D` the cell's pair, `P` the placed pair, `g = P(1)/D(1)`.
//!
//! With the zeros on the unit circle (`damping_ratio = 0`) and the placed pair at the same
//! frequency, `C` is the classic notch (`s² + ω²` over `s² + 2ζ_p·ω·s + ω²`).
//!
//! ## The form it runs in
//! Not the direct form on the load: its output is `x + e`, where the correction `e` obeys
//! `P(z)·e = (g·D − P)(z)·x`. The right side has no DC term (`g·D(1) = P(1)` by the choice
//! of `g`), so it is written in the differences `∇x` and `∇²x` alone. A constant input thus
//! passes with a gain of exactly one whatever the coefficients' rounding, and `e` holds only
//! the transient, so its rounding does not scale with the load.
//!
//! The recursion on `e` runs in the same differences (the delta operator): its state is
//! `e` and `∇e`, and each sample adds `∇²e = u − P(1)·e − P₁·∇e` (the ∇ coefficients of
//! `P` sum to one), whose coefficients are small near z = 1. In the direct form
//! (`e = u − a1·e₋₁ − a2·e₋₂`, `a1 ≈ −2`) the rounding of the two products of a transient
//! the size of the load is amplified by the placed pair's gain: in `f32` it put 1e-5 of the
//! load between `f32` and `f64` on the ringing step of `f32_follows_f64`, fifty times what the
//! delta form leaves.
//!
//! What must never happen: a constant input coming out changed, or a configuration with an
//! unstable or out-of-band pair accepted.

use super::mode::CellMode;
use super::Prefilter;
use crate::numerics::real::Real;
use crate::reading::ConfigError;

/// Where the compensation puts the cell's mode.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CompensatorConfig {
    /// The cell's mode, cancelled by the zeros.
    pub cell: CellMode,
    /// The placed pair's natural frequency, Hz (below the Nyquist frequency).
    pub placed_frequency_hz: f64,
    /// The placed pair's damping ratio (positive; 1 or more: two real poles).
    pub placed_damping_ratio: f64,
}

impl CompensatorConfig {
    /// The classic notch at the cell's frequency: zeros on the unit circle, poles at the
    /// same frequency with damping `width_damping_ratio` (the notch's relative width).
    pub fn notch(
        frequency_hz: f64,
        width_damping_ratio: f64,
        sample_rate_hz: f64,
    ) -> CompensatorConfig {
        CompensatorConfig {
            cell: CellMode {
                natural_frequency_hz: frequency_hz,
                damping_ratio: 0.0,
                sample_rate_hz,
            },
            placed_frequency_hz: frequency_hz,
            placed_damping_ratio: width_damping_ratio,
        }
    }
}

/// The compensation filter (see the module docs).
#[derive(Clone, Debug)]
pub struct Compensator<T> {
    /// Coefficients of `∇x` and `∇²x` on the right side.
    difference: [T; 2],
    /// The placed pair's ∇ coefficients `P(1)` and `P₁`.
    placed: [T; 2],
    /// The previous sample and its difference; `None` before the first sample.
    previous: Option<(T, T)>,
    /// The correction `e` and its difference `∇e` at the previous sample.
    correction: (T, T),
}

impl<T: Real> Compensator<T> {
    /// The filter, or the field that is out of its domain.
    pub fn new(config: CompensatorConfig) -> Result<Self, ConfigError> {
        config.cell.validate(true)?;
        let placed = CellMode {
            natural_frequency_hz: config.placed_frequency_hz,
            damping_ratio: config.placed_damping_ratio,
            sample_rate_hz: config.cell.sample_rate_hz,
        };
        // The rate is the cell's, checked above: a refusal names the placed pair's field.
        placed.validate(false).map_err(|error| match error {
            ConfigError::Filter("natural_frequency_hz") => {
                ConfigError::Filter("placed_frequency_hz")
            }
            _ => ConfigError::Filter("placed_damping_ratio"),
        })?;
        if placed.damping_ratio == 0.0 {
            return Err(ConfigError::Filter("placed_damping_ratio"));
        }
        let (cell, placed) = (config.cell.discrete_pair(), placed.discrete_pair());
        let gain = placed.dc / cell.dc;
        Ok(Self {
            difference: [
                T::from_f64(gain * cell.first - placed.first),
                T::from_f64(gain * cell.second - placed.second),
            ],
            placed: [T::from_f64(placed.dc), T::from_f64(placed.first)],
            previous: None,
            correction: (T::ZERO, T::ZERO),
        })
    }
}

impl<T: Real> Prefilter<T> for Compensator<T> {
    #[inline]
    fn filter(&mut self, x: T) -> T {
        // Before the first sample the pan rested at it: no difference yet.
        let (previous, previous_difference) = self.previous.unwrap_or((x, T::ZERO));
        let difference = x - previous;
        let second_difference = difference - previous_difference;
        let drive = self.difference[0] * difference + self.difference[1] * second_difference;
        let (level, slope) = self.correction;
        // P(1)·e + P₁·∇e + P₂·∇²e = drive at this sample, with P(1) + P₁ + P₂ = 1.
        let curvature = drive - self.placed[0] * (level + slope) - self.placed[1] * slope;
        let slope = slope + curvature;
        let level = level + slope;
        self.correction = (level, slope);
        self.previous = Some((x, difference));
        x + level
    }

    fn restart(&mut self) {
        self.previous = None;
        self.correction = (T::ZERO, T::ZERO);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: f64 = 4000.0;

    fn cell() -> CellMode {
        CellMode {
            natural_frequency_hz: 25.0,
            damping_ratio: 0.03,
            sample_rate_hz: RATE,
        }
    }

    fn config(placed_frequency_hz: f64, placed_damping_ratio: f64) -> CompensatorConfig {
        CompensatorConfig {
            cell: cell(),
            placed_frequency_hz,
            placed_damping_ratio,
        }
    }

    /// The cell's discrete mode driven by a step of `level` from rest: what the filter sees.
    fn ringing_step(level: f64, samples: usize) -> impl Iterator<Item = f64> {
        let pair = cell().discrete_pair();
        // The direct form of dc + first·∇ + second·∇².
        let (a1, a2) = (-(pair.first + 2.0 * pair.second), pair.second);
        let gain = pair.dc;
        let (mut y1, mut y2) = (0.0, 0.0);
        (0..samples).map(move |k| {
            let input = if k == 0 { 0.0 } else { level };
            let y = gain * input - a1 * y1 - a2 * y2;
            (y2, y1) = (y1, y);
            y
        })
    }

    #[test]
    fn a_constant_passes_with_exactly_unit_gain() {
        for value in [138.32f32, -0.001, 0.0, 3.0e5] {
            let mut filter = Compensator::<f32>::new(config(50.0, 1.0)).unwrap();
            for _ in 0..1000 {
                assert_eq!(filter.filter(value), value);
            }
        }
    }

    /// The cancelled ring: after the placed pair has settled (1 % of a 50 Hz critically
    /// damped pair is 21 ms; 60 ms is ample), the compensated step is within 1e-6 of the level
    /// while the cell itself still rings by three quarters of the load (e^(−ζω·0.06 s)).
    #[test]
    fn the_cells_ring_is_cancelled() {
        let level = 138.32;
        let mut filter = Compensator::<f64>::new(config(50.0, 1.0)).unwrap();
        let (mut worst_after, mut cell_after) = (0.0f64, 0.0f64);
        for (k, x) in ringing_step(level, 4000).enumerate() {
            let y = filter.filter(x);
            if k >= 240 {
                worst_after = worst_after.max((y - level).abs());
                cell_after = cell_after.max((x - level).abs());
            }
        }
        assert!(worst_after < 1e-6 * level, "compensated: {worst_after}");
        assert!(cell_after > 0.2 * level, "the cell alone: {cell_after}");
    }

    /// The notch removes a sinusoid at its frequency and passes DC: after its transient (the
    /// 0.1-damped pair at 25 Hz: e^(−ζω·t) below 1e-4 from 0.6 s), at most 1e-3 of the
    /// amplitude is left.
    #[test]
    fn the_notch_removes_its_frequency_and_passes_dc() {
        let mut notch = Compensator::<f64>::new(CompensatorConfig::notch(25.0, 0.1, RATE)).unwrap();
        let mut worst = 0.0f64;
        for k in 0..8000 {
            let t = k as f64 / RATE;
            let x = 10.0 + 5.0 * (2.0 * core::f64::consts::PI * 25.0 * t).sin();
            let y = notch.filter(x);
            if k >= 2400 {
                worst = worst.max((y - 10.0).abs());
            }
        }
        assert!(worst < 5e-3, "{worst}");
    }

    /// `f32` against `f64` on the same ringing step: within 1e-6 of the load (2e-7 measured).
    /// The ∇ form keeps the constant out of the recursion, so what is left is the rounding of
    /// the samples themselves (138 g in `f32`: 7.6e-6 g a sample) and of the transient; the
    /// direct form of the placed pair left 1e-5 (the module docs).
    #[test]
    fn f32_follows_f64() {
        let mut wide = Compensator::<f64>::new(config(40.0, 0.8)).unwrap();
        let mut narrow = Compensator::<f32>::new(config(40.0, 0.8)).unwrap();
        let mut worst = 0.0f64;
        for x in ringing_step(138.32, 6000) {
            let difference = f64::from(narrow.filter(x as f32)) - wide.filter(x);
            worst = worst.max(difference.abs());
        }
        assert!(worst < 1e-6 * 138.32, "{worst}");
    }

    #[test]
    fn impossible_configurations_name_their_field() {
        let refused = |config: CompensatorConfig| Compensator::<f32>::new(config).err();
        let with_cell = |cell: CellMode| CompensatorConfig {
            cell,
            ..config(50.0, 1.0)
        };
        let field = |name| Some(ConfigError::Filter(name));
        assert_eq!(
            refused(with_cell(CellMode {
                sample_rate_hz: 0.0,
                ..cell()
            })),
            field("sample_rate_hz")
        );
        assert_eq!(
            refused(with_cell(CellMode {
                natural_frequency_hz: 2000.0,
                ..cell()
            })),
            field("natural_frequency_hz")
        );
        assert_eq!(
            refused(with_cell(CellMode {
                damping_ratio: 1.0,
                ..cell()
            })),
            field("damping_ratio")
        );
        assert_eq!(
            refused(with_cell(CellMode {
                damping_ratio: f64::NAN,
                ..cell()
            })),
            field("damping_ratio")
        );
        assert_eq!(refused(config(f64::NAN, 1.0)), field("placed_frequency_hz"));
        assert_eq!(refused(config(2500.0, 1.0)), field("placed_frequency_hz"));
        assert_eq!(refused(config(50.0, 0.0)), field("placed_damping_ratio"));
        assert_eq!(refused(config(50.0, -0.5)), field("placed_damping_ratio"));
        assert_eq!(refused(config(50.0, 2.0)), None);
    }
}
