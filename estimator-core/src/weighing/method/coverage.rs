//! What a configured method was scored at: the loads of its range and its figures at each.

use super::Prediction;

/// The most loads spaced over a range.
pub const MAX_LOADS: usize = 8;
/// The most scenes scored: the calibration mass and two resonances at each load.
pub const MAX_SCENES: usize = 1 + 2 * MAX_LOADS;

/// One synthetic scene: a load and the resonance it rings at.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadScene {
    /// The load dropped, g.
    pub mass_g: f64,
    /// Its resonance relative to the calibrated one (damping ratio scaled alike).
    pub frequency_ratio: f64,
}

/// A method's figures at one scene.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadScore {
    /// The scene.
    pub scene: LoadScene,
    /// The RMS error no method can beat there (see the module docs), g.
    pub noise_floor_g: f64,
    /// The Monte Carlo's figures at the readout.
    pub prediction: Prediction,
}

impl LoadScore {
    /// The 95%/95% bound over the target at this load (≤ 1: met).
    pub fn bound_over_target(&self, target_relative: f64) -> f64 {
        self.prediction.p95_upper_g / (target_relative * self.scene.mass_g)
    }

    /// The 95th percentile over the target at this load.
    pub fn p95_over_target(&self, target_relative: f64) -> f64 {
        self.prediction.p95_g / (target_relative * self.scene.mass_g)
    }
}

/// The loads a configuration was scored at, and what it did at each.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadCoverage {
    /// Lightest load of the range, g.
    pub min_g: f64,
    /// Heaviest load of the range, g.
    pub max_g: f64,
    /// Loads spaced over it (besides the calibration mass).
    pub loads: u32,
    /// The platform's moving mass, g; `None`: unknown, both ends scored.
    pub platform_mass_g: Option<f64>,
    /// Every scene scored, by mass then ratio (the first `scene_count`).
    pub scores: [Option<LoadScore>; MAX_SCENES],
}

impl LoadCoverage {
    /// Only the calibration mass (a configuration scored before load ranges existed).
    pub fn calibration_mass_only(mass_g: f64, prediction: Prediction) -> Self {
        let mut scores = [None; MAX_SCENES];
        scores[0] = Some(LoadScore {
            scene: LoadScene {
                mass_g,
                frequency_ratio: 1.0,
            },
            noise_floor_g: 0.0,
            prediction,
        });
        Self {
            min_g: mass_g,
            max_g: mass_g,
            loads: 1,
            platform_mass_g: None,
            scores,
        }
    }

    /// The scene with the largest 95th percentile relative to its target.
    pub fn worst(&self, target_relative: f64) -> Option<LoadScore> {
        self.scores.iter().flatten().copied().reduce(|a, b| {
            if b.p95_over_target(target_relative) > a.p95_over_target(target_relative) {
                b
            } else {
                a
            }
        })
    }
}
