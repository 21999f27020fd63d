//! The scene the weighing decisions are tested on: a second-order cell with known truth
//! and deterministic pseudo-noise, and a scale calibrated for it.

extern crate std;
use std::vec::Vec;

use super::{CountsScale, RawSample, Scale, ScaleEstimator, ScaleReading, StepScale};

pub(crate) const FS: f32 = 4000.0;
/// The calibration the scale starts with.
pub(crate) const CPG: f32 = 50.0;
pub(crate) const ZERO: f32 = 30_000.0;

pub(crate) fn calibration() -> CountsScale {
    CountsScale {
        counts_per_gram: CPG,
        zero_counts: ZERO,
    }
}

/// The test cell's board: nominal gain and zero those of [`calibration`], the front
/// end's default tolerances on a 600 g cell, a 16-bit converter.
pub(crate) const LIMITS: crate::weighing::CalibrationLimits = crate::weighing::CalibrationLimits {
    nominal: crate::weighing::Calibration {
        counts_per_gram: CPG,
        zero_counts: ZERO,
    },
    gain_tolerance: 0.15,
    zero_tolerance_counts: 0.4 * CPG * 600.0,
    max_code: 65_535,
};

/// A second-order cell (25 Hz, ζ = 0.03 loaded) with deterministic pseudo-noise: the
/// decisions are tested on a scene with known truth, not on constants.
pub(crate) struct Cell {
    position_g: f64,
    velocity: f64,
    pub(crate) load_g: f64,
    noise_state: u64,
    noise_g: f64,
    pub(crate) offset_counts: f64,
    /// The cell's true gain over the scale's calibration (a replaced cell when not 1).
    gain_factor: f64,
    /// Its mode: natural frequency (Hz) and damping ratio.
    ring_hz: f64,
    damping: f64,
    /// A floor vibrating under the pan: RMS (g), centre frequency and bandwidth (Hz) of a
    /// narrow band of noise on the reading (a resonant second-order filter driven by the
    /// cell's own noise stream), and that filter's last two outputs.
    pub(crate) vibration: (f64, f64, f64),
    vibration_state: (f64, f64),
}

impl Cell {
    pub(crate) fn new(noise_g: f64) -> Self {
        Self {
            position_g: 0.0,
            velocity: 0.0,
            load_g: 0.0,
            noise_state: 0x9E37_79B9_7F4A_7C15,
            noise_g,
            offset_counts: ZERO as f64,
            gain_factor: 1.0,
            ring_hz: 25.0,
            damping: 0.03,
            vibration: (0.0, 0.0, 0.0),
            vibration_state: (0.0, 0.0),
        }
    }

    /// The cell with a heavy load on: the reference cell's mode at 400 g of its 600 g
    /// (25 Hz at 138 g, frequency ∝ 1/√mass: about 13 Hz, the same ζ), so a load's ringing
    /// takes twice as long to die down.
    pub(crate) fn heavy(noise_g: f64, seed: u64) -> Self {
        Self {
            ring_hz: 13.0,
            ..Self::seeded(noise_g, seed)
        }
    }

    /// A cell whose true gain is `gain_factor` times the scale's calibration, with noise of
    /// its own.
    pub(crate) fn replaced(noise_g: f64, gain_factor: f64) -> Self {
        Self {
            noise_state: 0x2545_F491_4F6C_DD1D,
            gain_factor,
            ..Self::new(noise_g)
        }
    }

    /// A cell with noise from its own `seed` (a different realisation per seed).
    pub(crate) fn seeded(noise_g: f64, seed: u64) -> Self {
        Self {
            noise_state: 0x9E37_79B9_7F4A_7C15 ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03),
            ..Self::new(noise_g)
        }
    }

    fn noise(&mut self) -> f64 {
        unit_noise(&mut self.noise_state)
    }

    /// The floor's vibration now (0 without one): `x(k) = 2r·cos θ·x(k−1) − r²·x(k−2) +
    /// e(k)`, its poles at radius `r = exp(−π·bandwidth/fs)` and angle `θ = 2π·f/fs`, `e`
    /// scaled so that `x` has the configured RMS (the filter's stationary variance).
    fn vibrate(&mut self) -> f64 {
        let (rms, hz, bandwidth) = self.vibration;
        if rms == 0.0 {
            return 0.0;
        }
        let fs = FS as f64;
        let r = (-std::f64::consts::PI * bandwidth / fs).exp();
        let c = (2.0 * std::f64::consts::PI * hz / fs).cos();
        let (a1, a2) = (2.0 * r * c, -r * r);
        // Var x / Var e for the AR(2) x(k) = a1 x(k-1) + a2 x(k-2) + e(k).
        let gain = (1.0 - a2) / ((1.0 + a2) * ((1.0 - a2) * (1.0 - a2) - a1 * a1));
        let e = rms / gain.sqrt() * self.noise();
        let (x1, x2) = self.vibration_state;
        let x = a1 * x1 + a2 * x2 + e;
        self.vibration_state = (x, x1);
        x
    }

    pub(crate) fn sample(&mut self) -> RawSample {
        let omega = 2.0 * std::f64::consts::PI * self.ring_hz;
        let dt = 1.0 / FS as f64;
        // Semi-implicit Euler is plenty for a decision test.
        for _ in 0..4 {
            let accel = omega * omega * (self.load_g - self.position_g)
                - 2.0 * self.damping * omega * self.velocity;
            self.velocity += accel * dt / 4.0;
            self.position_g += self.velocity * dt / 4.0;
        }
        let floor_g = self.vibrate();
        let grams = self.position_g + self.noise_g * self.noise() + floor_g;
        let counts = self.offset_counts + grams * self.gain_factor * CPG as f64;
        RawSample::Counts(counts.round() as i32)
    }
}

/// Deterministic pseudo-noise from `state`: a sum of 4 uniforms, near-Gaussian, unit
/// variance.
pub(crate) fn unit_noise(state: &mut u64) -> f64 {
    let mut sum = 0.0;
    for _ in 0..4 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        sum += (*state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
    }
    sum * (3.0f64).sqrt()
}

pub(crate) fn run<E: ScaleEstimator>(
    scale: &mut Scale<E>,
    cell: &mut Cell,
    samples: usize,
) -> Vec<ScaleReading> {
    (0..samples).map(|_| scale.push(cell.sample())).collect()
}

/// The default scale (step estimator, n = 7, D = 16) calibrated for the cell.
pub(crate) fn new_scale() -> StepScale<8> {
    Scale::step_default(FS, calibration()).unwrap()
}

/// The default scale and the cell with `noise_g` of noise, the pan empty.
pub(crate) fn scene(noise_g: f64) -> (StepScale<8>, Cell) {
    (new_scale(), Cell::new(noise_g))
}
