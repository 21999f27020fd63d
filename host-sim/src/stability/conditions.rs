//! The grid of conditions: the scenes of slices A (order × SNR), B (noise type × SNR) and C
//! (off-calibration), each with its truth and its Cramér–Rao bound at the two readouts. The
//! noise of a condition is physical: a slice must never rescale it with the load.

use anyhow::{anyhow, Result};

use crate::montecarlo;
use crate::scene::Scene;
use crate::simulated::{LoadEvent, Script};

/// SNRs of slices A and B, dB (thesis eq. 4.39).
pub const SNRS_DB: [f64; 8] = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0];
/// Orders of slice A.
pub const ORDERS: [usize; 15] = [1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 16, 20, 25, 30, 40];
/// The block length slice A maps the orders at (the firmware's before calibration chose
/// n = 5, D = 24; that one is among the default probes of slices B and C).
pub const ORDER_MAP_DECIMATION: u16 = 16;
/// The readouts of the Monte Carlo slices, s: the firmware's readout, and the end of the
/// window (the last sample of 1.5 s).
pub const READOUTS_S: [f64; 2] = [0.1, 1.5];

/// Resonance over the one at the 200 g calibration, slice C: 0.7–1.3 is the model bank's
/// span; 0.67 is the cell's 600 g capacity, 1.4 and 1.5 lie beyond the span (44 g, 22 g).
pub const RESONANCE_RATIOS: [f64; 10] = [0.67, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5];
/// The calibration mass of the model-based methods, g.
pub const CALIBRATION_G: f64 = 200.0;
/// White-noise levels of slice C, given as the SNR they have on the reference scene (the noise
/// is physical: it does not change with the load), dB.
pub const OFF_CALIBRATION_SNRS_DB: [f64; 2] = [50.0, 70.0];

/// What kind of noise a cell has besides the white noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Noise {
    /// White noise only (and the amplifier's own, and quantisation, as everywhere).
    White,
    /// Plus a narrow-band force at 24 Hz, 1 Hz wide, near the loaded resonance (25 Hz), with
    /// the same RMS at the output as the white noise.
    Vibration,
    /// Plus 50 Hz mains pickup with the same RMS as the white noise.
    Mains,
}

impl Noise {
    /// Name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Noise::White => "white",
            Noise::Vibration => "vibration",
            Noise::Mains => "mains",
        }
    }
}

/// Which of the four questions a cell answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slice {
    /// A: order × SNR.
    OrderSnr,
    /// B: noise type × SNR.
    NoiseType,
    /// C: off-calibration.
    OffCalibration,
}

impl Slice {
    /// Name in tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Slice::OrderSnr => "order_snr",
            Slice::NoiseType => "noise_type",
            Slice::OffCalibration => "off_calibration",
        }
    }
}

/// One condition of a Monte Carlo slice: a scene and where it sits on the slice's axes.
#[derive(Clone, Debug)]
pub struct Condition {
    /// The slice.
    pub slice: Slice,
    /// The extra noise.
    pub noise: Noise,
    /// SNR of the white noise, dB (slice C: on the reference scene).
    pub snr_db: f64,
    /// Resonance with the load over the one at the calibration mass.
    pub resonance_ratio: f64,
    /// The step, g.
    pub truth_g: f64,
    /// The scene simulated.
    pub scene: Scene,
    /// The CRLB at each readout, g.
    pub crlb_g: [f64; 2],
}

/// The reference scene at `snr_db` with `noise` added at the same RMS as the white noise.
/// `vibration_gain` is the output RMS per unit of force RMS ([`vibration_gain`]).
pub fn noisy_scene(base: &Scene, snr_db: f64, noise: Noise, vibration_gain: f64) -> Scene {
    let mut scene = base.with_snr_db(snr_db);
    let sigma = scene.disturbances.white_noise_g;
    match noise {
        Noise::White => {}
        Noise::Vibration => {
            scene.disturbances.vibration_rms_g = sigma / vibration_gain;
            scene.disturbances.vibration_hz = 24.0;
            scene.disturbances.vibration_bandwidth_hz = 1.0;
        }
        Noise::Mains => {
            scene.disturbances.mains_amplitude_g = sigma * std::f64::consts::SQRT_2;
            scene.disturbances.mains_hz = 50.0;
        }
    }
    scene
}

/// The RMS of the vibration at the output per gram of force RMS, over the 1.5 s window after
/// the reference drop (the response to the disturbance alone: the same seed with and
/// without it, the system being linear), averaged over 16 seeds.
pub fn vibration_gain(base: &Scene) -> f64 {
    let mut quiet = base.clone();
    quiet.disturbances = crate::simulated::Disturbances::none();
    let mut shaken = quiet.clone();
    shaken.disturbances.vibration_rms_g = 1.0;
    shaken.disturbances.vibration_hz = 24.0;
    shaken.disturbances.vibration_bandwidth_hz = 1.0;
    let samples = base.studied_window();
    let gain = base.chain.counts_per_gram();
    let (mut energy, mut count) = (0.0, 0.0);
    for seed in 0..16 {
        let mut a = quiet.adc(seed);
        let mut b = shaken.adc(seed);
        for _ in 0..samples {
            let difference = (b.read_analog() - a.read_analog()) / gain;
            energy += difference * difference;
            count += 1.0;
        }
    }
    (energy / count).sqrt()
}

/// The known-model CRLB of `scene`'s first step at the readouts, g: white noise (here the
/// scene's white noise plus `extra_variance_g2`, the disturbance's power treated as white),
/// quantisation and the amplifier's coloured noise, as `montecarlo` computes it.
fn crlb_at_readouts(scene: &Scene, extra_variance_g2: f64, readouts: [usize; 2]) -> [f64; 2] {
    let mut judged = scene.clone();
    let white = scene.disturbances.white_noise_g;
    judged.disturbances.white_noise_g = (white * white + extra_variance_g2).sqrt();
    judged.disturbances.vibration_rms_g = 0.0;
    judged.disturbances.mains_amplitude_g = 0.0;
    let (_, truth_g, _) = judged.studied_step();
    let samples = readouts[1] + 1;
    let bound = montecarlo::crlb_g2(&judged, truth_g, samples);
    readouts.map(|k| bound[k].sqrt())
}

/// The readout sample indices of a window of `samples`: the one `study speed` calls 100 ms
/// (round(t·rate)) and the last.
pub fn readout_indices(scene: &Scene) -> [usize; 2] {
    let samples = scene.studied_window();
    let first = (READOUTS_S[0] * scene.chain.sample_rate_hz).round() as usize;
    [first.min(samples - 1), samples - 1]
}

/// The conditions of slice A (`snrs_db`, white noise).
pub fn order_conditions(base: &Scene, snrs_db: &[f64]) -> Vec<Condition> {
    let readouts = readout_indices(base);
    snrs_db
        .iter()
        .map(|&snr_db| {
            let scene = base.with_snr_db(snr_db);
            Condition {
                slice: Slice::OrderSnr,
                noise: Noise::White,
                snr_db,
                resonance_ratio: resonance_ratio(&scene, scene.studied_step().1),
                truth_g: scene.studied_step().1,
                crlb_g: crlb_at_readouts(&scene, 0.0, readouts),
                scene,
            }
        })
        .collect()
}

/// The conditions of slice B: every noise type at every SNR.
pub fn noise_conditions(base: &Scene, snrs_db: &[f64]) -> Vec<Condition> {
    let readouts = readout_indices(base);
    let gain = vibration_gain(base);
    let mut conditions = Vec::new();
    for noise in [Noise::White, Noise::Vibration, Noise::Mains] {
        for &snr_db in snrs_db {
            let scene = noisy_scene(base, snr_db, noise, gain);
            let white = scene.disturbances.white_noise_g;
            // Judged against the white-noise bound at the same total noise power.
            let extra = if noise == Noise::White {
                0.0
            } else {
                white * white
            };
            conditions.push(Condition {
                slice: Slice::NoiseType,
                noise,
                snr_db,
                resonance_ratio: resonance_ratio(&scene, scene.studied_step().1),
                truth_g: scene.studied_step().1,
                crlb_g: crlb_at_readouts(&scene, extra, readouts),
                scene,
            });
        }
    }
    conditions
}

/// The resonance with `mass_g` over the one at the calibration mass.
pub fn resonance_ratio(scene: &Scene, mass_g: f64) -> f64 {
    let cell = &scene.chain.cell;
    cell.natural_frequency_rad_s(mass_g) / cell.natural_frequency_rad_s(CALIBRATION_G)
}

/// The load whose resonance is `ratio` times the one at the calibration mass:
/// ω ∝ 1/√(m_platform + M).
pub fn mass_for_ratio(scene: &Scene, ratio: f64) -> f64 {
    let platform_kg = scene.chain.cell.platform_mass_kg;
    ((platform_kg + CALIBRATION_G * 1e-3) / (ratio * ratio) - platform_kg) * 1e3
}

/// The conditions of slice C: the reference scene with the step moved to the mass of each
/// resonance ratio, the white noise held at the level `snr_db` gives on the reference scene.
pub fn off_calibration_conditions(base: &Scene, snrs_db: &[f64]) -> Result<Vec<Condition>> {
    let readouts = readout_indices(base);
    let mut conditions = Vec::new();
    for &snr_db in snrs_db {
        let reference = base.with_snr_db(snr_db);
        for &ratio in &RESONANCE_RATIOS {
            let mass_g = mass_for_ratio(base, ratio);
            let mut scene = reference.clone();
            let mut script = Script::new(base.script.end_s());
            script
                .push(LoadEvent::step(0.0, mass_g))
                .map_err(|e| anyhow!("slice C: {mass_g} g: {e:?}"))?;
            scene.script = script;
            conditions.push(Condition {
                slice: Slice::OffCalibration,
                noise: Noise::White,
                snr_db,
                resonance_ratio: ratio,
                truth_g: mass_g,
                crlb_g: crlb_at_readouts(&scene, 0.0, readouts),
                scene,
            });
        }
    }
    Ok(conditions)
}

/// The name of readout `r` in titles and tables.
pub(super) fn readout_name(r: usize) -> &'static str {
    if r == 0 {
        "100 ms"
    } else {
        "1.5 s"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_off_calibration_masses_move_the_resonance_by_their_ratio() {
        let scene = Scene::load("reference-step").unwrap();
        assert!((mass_for_ratio(&scene, 1.0) - CALIBRATION_G).abs() < 1e-9);
        for ratio in RESONANCE_RATIOS {
            let mass_g = mass_for_ratio(&scene, ratio);
            assert!(
                (resonance_ratio(&scene, mass_g) - ratio).abs() < 1e-9,
                "{ratio}"
            );
        }
        // Heavier loads ring lower: the ratios ascend as the masses descend.
        assert!(mass_for_ratio(&scene, 0.67) > mass_for_ratio(&scene, 1.5));
    }

    #[test]
    fn the_readouts_are_100_ms_and_the_last_sample_of_the_window() {
        let scene = Scene::load("reference-step").unwrap();
        let window = scene.studied_window();
        assert_eq!(readout_indices(&scene), [400, window - 1]);
        assert_eq!(readout_name(0), "100 ms");
        assert_eq!(readout_name(1), "1.5 s");
    }

    #[test]
    fn the_disturbances_carry_the_white_noise_power() {
        let scene = Scene::load("reference-step").unwrap();
        let white = noisy_scene(&scene, 40.0, Noise::White, 2.0);
        let sigma = white.disturbances.white_noise_g;
        assert_eq!(white.disturbances.mains_amplitude_g, 0.0);
        assert_eq!(white.disturbances.vibration_rms_g, 0.0);
        let mains = noisy_scene(&scene, 40.0, Noise::Mains, 2.0);
        assert_eq!(mains.disturbances.white_noise_g, sigma);
        // A sine of amplitude √2·σ has RMS σ.
        assert!((mains.disturbances.mains_amplitude_g - sigma * 2f64.sqrt()).abs() < 1e-15);
        let vibration = noisy_scene(&scene, 40.0, Noise::Vibration, 2.0);
        assert_eq!(vibration.disturbances.vibration_rms_g, sigma / 2.0);
        assert_eq!(vibration.disturbances.vibration_hz, 24.0);
    }
}
