//! The loads a calibration scores a method at: a scale lives with every load from a small
//! item to the most its converter can take, not only with the calibration mass.
//!
//! ## Which loads
//! The calibration mass `M_c` always (the recorded drops confirm the method there, and the
//! config's `prediction` is this scene's), and `J` loads spaced geometrically over a range
//! (both ends included). The default range is 0.3×–3× the calibration mass, the span the
//! reference model bank ([`super::BankCandidate::REFERENCE`]) was designed to cover, with its
//! top clipped to the heaviest load whose landing stays inside the converter's rails (the
//! crate-private `saturation_limit`): a heavier drop overshoots into a rail (nearly 2× the
//! load on a lightly damped cell) and the scale flags it instead of weighing it. A given
//! range is widened to hold `M_c`.
//!
//! ## At which resonance: the physical law, and the platform mass nobody gave us
//! With the cell's stiffness `k` and damping `c` fixed, a load `M` on a platform whose moving
//! mass is `m_p` rings at `r = √((m_p + M_c)/(m_p + M))` times the calibrated frequency, with
//! `r` times the calibrated damping ratio ([`crate::LoadCellModel::with_frequency_ratio`]).
//! One calibration mass identifies `ω² = k/(m_p + M_c)` but not `m_p`. So:
//! - **known `m_p`** (weighed, or identified from drops of a second mass with
//!   [`platform_mass_from_resonances`]): each load is scored at its `r`;
//! - **unknown `m_p`** (the default): each load is scored at both ends of what physics allows,
//!   `m_p → 0` (`r = √(M_c/M)`, the largest change of the dynamics) and `m_p → ∞` (`r = 1`,
//!   the calibrated dynamics under another load). Any real platform lies between the two.
//!
//! ## What "meets" means over the range
//! The target is relative: `|error| ≤ target·M` at every load. A method meets it when the
//! 95%/95% bound of [`super::synthetic`] holds **at every scored scene**, each scene with its
//! own runs. Not pooled: a pooled 95th percentile lets the loads a method is good at hide
//! the ones it is not (a method can meet the bound at the calibration mass and miss it
//! often at a light load). Requiring every scene keeps each claim at its 95% confidence:
//! a method whose true 95th percentile misses the target at one scene is accepted with
//! probability at most 5% (that scene's bound alone must pass), whatever the other scenes.
//!
//! ## The noise floor
//! Each scene also gets the error no method can beat there: the Cramér–Rao bound of the
//! known model with the onset known (`σ²/Σ ∂y/∂M²` over the samples up to the readout), plus
//! the variance of the tare from the empty stretch. It says whether a miss at a light load is
//! the method's or the sensor's: where 1.96 times the floor exceeds the target at a load, no
//! method can meet it there at its 95th percentile.

use crate::reading::ConfigError;
use crate::sensor::LoadCellModel;

use super::synthetic::Synthetic;
use crate::weighing::{LoadScene, MAX_LOADS, MAX_SCENES};

/// Loads spaced over the range unless asked otherwise.
pub const DEFAULT_LOADS: usize = 4;
/// The default range, relative to the calibration mass.
pub const DEFAULT_RANGE_RELATIVE: (f64, f64) = (0.3, 3.0);
/// Headroom kept below a rail at the noise-free peak of a drop, in noise standard deviations
/// (a sample beyond 5σ: about 3 in 10⁷).
pub const SATURATION_MARGIN_SIGMA: f64 = 5.0;

/// The frequency ratio of a load `mass_g` for a platform of `platform_mass_g` (infinite:
/// 1, the dynamics do not change).
fn ratio_for(calibration_mass_g: f64, platform_mass_g: f64, mass_g: f64) -> f64 {
    if platform_mass_g.is_infinite() {
        1.0
    } else {
        LoadCellModel::frequency_ratio_for_mass(calibration_mass_g, platform_mass_g, mass_g)
    }
}

/// The platform masses a load is scored at: the known one, or both ends of the unknown's.
fn platform_ends(platform_mass_g: Option<f64>) -> ([f64; 2], usize) {
    match platform_mass_g {
        Some(known) => ([known, known], 1),
        None => ([f64::INFINITY, 0.0], 2),
    }
}

/// The scenes to score, by mass then ratio (duplicates removed), and the order to score
/// them in.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Plan {
    pub scenes: [LoadScene; MAX_SCENES],
    pub count: usize,
    /// Indices into `scenes`: the calibration mass first, then the loads farthest from it
    /// (in log) first, at each the slower resonance first: where a method is likeliest to
    /// fail, so that a failing one is stopped early.
    pub order: [usize; MAX_SCENES],
    pub calibration: usize,
}

impl Plan {
    /// `loads` loads over `[min_g, max_g]` (widened to hold `calibration_mass_g`), each at
    /// the resonances of [`platform_ends`].
    pub fn new(
        calibration_mass_g: f64,
        min_g: f64,
        max_g: f64,
        loads: usize,
        platform_mass_g: Option<f64>,
    ) -> Self {
        let mut scenes = [LoadScene {
            mass_g: calibration_mass_g,
            frequency_ratio: 1.0,
        }; MAX_SCENES];
        let mut count = 1;
        let (ends, end_count) = platform_ends(platform_mass_g);
        let span = libm::log(max_g / min_g);
        for i in 0..loads.min(MAX_LOADS) {
            let mass_g = if loads == 1 {
                libm::sqrt(min_g * max_g)
            } else {
                min_g * libm::exp(span * i as f64 / (loads - 1) as f64)
            };
            for &platform in &ends[..end_count] {
                let scene = LoadScene {
                    mass_g,
                    frequency_ratio: ratio_for(calibration_mass_g, platform, mass_g),
                };
                let duplicate = scenes[..count].iter().any(|s| {
                    libm::fabs(s.mass_g / scene.mass_g - 1.0) < 1e-9
                        && libm::fabs(s.frequency_ratio / scene.frequency_ratio - 1.0) < 1e-9
                });
                if !duplicate {
                    scenes[count] = scene;
                    count += 1;
                }
            }
        }
        // By mass, then ratio (insertion sort: at most 17).
        for i in 1..count {
            let mut j = i;
            while j > 0 && key(&scenes[j]) < key(&scenes[j - 1]) {
                scenes.swap(j, j - 1);
                j -= 1;
            }
        }
        let calibration = scenes[..count]
            .iter()
            .position(|s| s.mass_g == calibration_mass_g && s.frequency_ratio == 1.0)
            .unwrap_or(0);
        let mut order = [0usize; MAX_SCENES];
        for (slot, index) in order.iter_mut().zip(0..count) {
            *slot = index;
        }
        let distance = |s: &LoadScene| libm::fabs(libm::log(s.mass_g / calibration_mass_g));
        let difficulty = |index: usize| {
            let s = &scenes[index];
            // Calibration first; then the farthest loads; at a load the slower resonance.
            let first = if index == calibration { 0.0 } else { 1.0 };
            (first, -distance(s), s.mass_g, s.frequency_ratio)
        };
        for i in 1..count {
            let mut j = i;
            while j > 0 && difficulty(order[j]) < difficulty(order[j - 1]) {
                order.swap(j, j - 1);
                j -= 1;
            }
        }
        Self {
            scenes,
            count,
            order,
            calibration,
        }
    }
}

fn key(scene: &LoadScene) -> (f64, f64) {
    (scene.mass_g, scene.frequency_ratio)
}

/// The heaviest load in `[mass_g, 3·mass_g]` (or `high_g` if lower) whose landing keeps the
/// noise-free response `SATURATION_MARGIN_SIGMA` noise standard deviations inside the rails
/// `(rail_low, rail_high)` around `zero` (raw units), for every platform end scored. The
/// response is followed for the readout or two periods of the slowest resonance, whichever
/// is longer (the first overshoot comes within one period). `S` states.
#[allow(clippy::too_many_arguments)]
pub(crate) fn saturation_limit<const S: usize>(
    model: &LoadCellModel,
    calibration_mass_g: f64,
    high_g: f64,
    platform_mass_g: Option<f64>,
    zero: f64,
    rails: (f64, f64),
    sigma: f64,
    readout_samples: usize,
) -> Result<f64, ConfigError> {
    let margin = SATURATION_MARGIN_SIGMA * sigma;
    let (ends, end_count) = platform_ends(platform_mass_g);
    let fits = |mass_g: f64| -> Result<bool, ConfigError> {
        for &platform in &ends[..end_count] {
            let ratio = ratio_for(calibration_mass_g, platform, mass_g);
            let moved = model.with_frequency_ratio(ratio);
            let periods = 2.0 * model.sample_rate_hz / moved.natural_frequency_hz;
            let length = readout_samples.max(libm::ceil(periods) as usize) + 1;
            let clean = Synthetic {
                model: moved.sensor_model::<f64, S>()?,
                mass_g,
                sigma: 0.0,
                empty: 0,
                length,
            };
            let (mut low, mut high) = (0.0f64, 0.0f64);
            for y in clean.samples(0, 0) {
                low = low.min(y);
                high = high.max(y);
            }
            if !(zero + high + margin < rails.1 && zero + low - margin > rails.0) {
                return Ok(false);
            }
        }
        Ok(true)
    };
    let top = high_g.max(calibration_mass_g);
    if fits(top)? {
        return Ok(top);
    }
    // The calibration drops did not saturate; bisect between them and the top.
    let (mut good, mut bad) = (calibration_mass_g, top);
    while bad / good - 1.0 > 1e-4 {
        let middle = libm::sqrt(good * bad);
        if fits(middle)? {
            good = middle;
        } else {
            bad = middle;
        }
    }
    Ok(good)
}

/// The RMS error floor at a scene (see the module docs): `σ²/Σ (∂y/∂M)²` over the samples
/// from the landing to the readout, plus the tare's `σ²/(G²·tare_samples)`, in g.
pub(crate) fn noise_floor_g<const S: usize>(
    synthetic: &Synthetic<S>,
    readout_samples: usize,
    tare_samples: usize,
    counts_per_gram: f64,
) -> f64 {
    let clean = Synthetic {
        sigma: 0.0,
        empty: 0,
        length: readout_samples + 1,
        ..*synthetic
    };
    let mut information = 0.0;
    for y in clean.samples(0, 0) {
        let sensitivity = y / synthetic.mass_g;
        information += sensitivity * sensitivity;
    }
    let variance = synthetic.sigma * synthetic.sigma;
    let tare = variance / (counts_per_gram * counts_per_gram * tare_samples.max(1) as f64);
    libm::sqrt(variance / information + tare)
}

/// The platform's moving mass from the resonances identified with two known masses, by the
/// physical law `f² ∝ 1/(m_p + M)`: `m_p = (M_a − ρ·M_b)/(ρ − 1)` with `ρ = (f_b/f_a)²`.
/// `None` when the masses are equal or not positive, a frequency is not positive, or the
/// data contradict the law (the heavier mass does not ring slower, or `m_p < 0`).
pub fn platform_mass_from_resonances(
    mass_a_g: f64,
    frequency_a_hz: f64,
    mass_b_g: f64,
    frequency_b_hz: f64,
) -> Option<f64> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(positive(mass_a_g)
        && positive(mass_b_g)
        && positive(frequency_a_hz)
        && positive(frequency_b_hz))
        || mass_a_g == mass_b_g
    {
        return None;
    }
    let rho = (frequency_b_hz / frequency_a_hz) * (frequency_b_hz / frequency_a_hz);
    // The heavier mass must ring slower.
    if (mass_b_g > mass_a_g) != (rho < 1.0) {
        return None;
    }
    let platform = (mass_a_g - rho * mass_b_g) / (rho - 1.0);
    (platform.is_finite() && platform >= 0.0).then_some(platform)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell() -> LoadCellModel {
        crate::sensor::reference_cell()
    }

    #[test]
    fn the_plan_holds_the_calibration_mass_and_both_ends_of_an_unknown_platform() {
        let plan = Plan::new(138.32, 41.496, 344.0, 4, None);
        // 4 loads × 2 ends + the calibration mass.
        assert_eq!(plan.count, 9);
        let scenes = &plan.scenes[..plan.count];
        for pair in scenes.windows(2) {
            assert!(key(&pair[0]) < key(&pair[1]));
        }
        assert_eq!(scenes[plan.calibration].mass_g, 138.32);
        assert_eq!(plan.order[0], plan.calibration);
        // The lightest load at m_p → 0 rings √(138.32/41.496) faster; at m_p → ∞ as calibrated.
        assert!((scenes[0].frequency_ratio - 1.0).abs() < 1e-15);
        assert!((scenes[1].frequency_ratio - (138.32f64 / 41.496).sqrt()).abs() < 1e-12);
        // After the calibration mass: the farthest load (344 g is 2.49× away, 41.5 g 3.33×),
        // its slower resonance first.
        assert_eq!(scenes[plan.order[1]].mass_g, 41.496);
        assert_eq!(scenes[plan.order[1]].frequency_ratio, 1.0);
        // Every scene is scored once.
        let mut seen = [false; MAX_SCENES];
        for &index in &plan.order[..plan.count] {
            assert!(!seen[index]);
            seen[index] = true;
        }
        // A known platform: one resonance per load; a load equal to the calibration mass is
        // not scored twice.
        let plan = Plan::new(138.32, 138.32, 400.0, 2, Some(120.0));
        assert_eq!(plan.count, 2);
        assert!(
            (plan.scenes[1].frequency_ratio - (258.32f64 / 520.0).sqrt()).abs() < 1e-12,
            "{:?}",
            plan.scenes[1]
        );
    }

    #[test]
    fn the_saturation_limit_is_where_the_overshoot_meets_the_rail() {
        let model = cell();
        let sigma = 32.6;
        // No rails: the top asked for.
        let top = saturation_limit::<5>(
            &model,
            138.32,
            415.0,
            Some(120.0),
            16_764.76,
            (f64::NEG_INFINITY, f64::INFINITY),
            sigma,
            400,
        )
        .unwrap();
        assert_eq!(top, 415.0);
        // 16 bits: the peak at the limit is within 5σ + 1e-4 relative of the rail, and a 1%
        // heavier load crosses it.
        let rails = (0.0, 65_535.0);
        let limit =
            saturation_limit::<5>(&model, 138.32, 415.0, None, 16_764.76, rails, sigma, 400)
                .unwrap();
        assert!(limit > 138.32 && limit < 415.0, "{limit}");
        let peak = |mass_g: f64, platform: f64| {
            let moved = model.with_frequency_ratio(ratio_for(138.32, platform, mass_g));
            let clean = Synthetic {
                model: moved.sensor_model::<f64, 5>().unwrap(),
                mass_g,
                sigma: 0.0,
                empty: 0,
                length: 2000,
            };
            clean.samples(0, 0).fold(0.0f64, f64::max)
        };
        let worst = |mass_g: f64| peak(mass_g, 0.0).max(peak(mass_g, f64::INFINITY));
        let headroom = 65_535.0 - 16_764.76 - 5.0 * sigma;
        assert!(worst(limit) <= headroom && worst(limit) > headroom * (1.0 - 2e-4));
        assert!(worst(limit * 1.01) > headroom);
        // The lightly damped cell overshoots to nearly twice the load.
        assert!(worst(limit) / (limit * 73.25) > 1.85);
    }

    #[test]
    fn the_noise_floor_is_the_bound_of_a_constant_sensitivity_when_the_response_is_a_step() {
        // A model whose response is the step itself from the first sample (a = 0, b = 1,
        // c = G): Σ (∂y/∂M)² = (N + 1)·G², so the floor is σ/G·√(1/(N + 1) + 1/tare).
        let synthetic = Synthetic {
            model: crate::estimators::model::SensorModel {
                a: [[0.0]],
                b: [1.0],
                c: [2.0],
            },
            mass_g: 10.0,
            sigma: 3.0,
            empty: 0,
            length: 1,
        };
        let floor = noise_floor_g(&synthetic, 99, 400, 2.0);
        // y(0) = 0 (the state starts at rest), then G·M: 99 samples of sensitivity G.
        let expected = 1.5 * (1.0 / 99.0 + 1.0 / 400.0f64).sqrt();
        assert!((floor / expected - 1.0).abs() < 1e-12, "{floor} {expected}");
    }

    #[test]
    fn the_platform_mass_follows_from_two_resonances() {
        // The reference cell: m_p = 120 g, 25 Hz with 138.32 g.
        let k = 258.32 * 25.0f64 * 25.0;
        let f = |mass_g: f64| (k / (120.0 + mass_g)).sqrt();
        let platform = platform_mass_from_resonances(138.32, f(138.32), 250.0, f(250.0)).unwrap();
        assert!((platform - 120.0).abs() < 1e-9, "{platform}");
        // Either order.
        let platform = platform_mass_from_resonances(250.0, f(250.0), 138.32, f(138.32)).unwrap();
        assert!((platform - 120.0).abs() < 1e-9, "{platform}");
        // Against the law, or nothing to learn from.
        assert_eq!(
            platform_mass_from_resonances(138.32, 25.0, 250.0, 26.0),
            None
        );
        assert_eq!(
            platform_mass_from_resonances(138.32, 25.0, 138.32, 25.0),
            None
        );
        // Faster than m_p = 0 allows (f ∝ 1/√M at most): a negative mass.
        assert_eq!(
            platform_mass_from_resonances(100.0, 25.0, 400.0, 10.0),
            None
        );
        assert_eq!(
            platform_mass_from_resonances(f64::NAN, 25.0, 400.0, 20.0),
            None
        );
    }
}
