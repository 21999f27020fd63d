//! The QEMU board's simulated load cell and the scenes it plays: the reference chain
//! (load cell, INA114, 3rd-order Butterworth, 16-bit ADC) as [`SimulatedAdc`], scripted
//! with the demo, the checked demo and the command scene, plus the factory calibration the
//! board stores at boot.
//!
//! It is here, in the `no_std` part, so the QEMU firmware plays these scenes and the host
//! tests replay exactly the same ones through the same code. It must never depend on a
//! board, allocate, or draw noise from anything but the fixed seeds below.

use crate::simulated::{REFERENCE_SNR_DB, REFERENCE_STEP_G, SNR_WINDOW_SAMPLES};
use crate::{white_noise_for_snr, Disturbances, LoadEvent, Script, SensorChain, SimulatedAdc};
use estimator_core::sensor::AdcSource;
use estimator_core::weighing::{Calibration, CalibrationError, CalibrationLimits, FrontEnd};

/// The simulated cell with room for sixteen scripted load changes (the command scene
/// pours a load on in portions).
pub type LoadCell = SimulatedAdc<16>;

/// Noise seed of the demo scene (fixed, so a run is reproducible; not chosen by result).
pub const DEMO_SEED: u64 = 1;
/// Noise seed of the factory calibration run (a different cell session).
pub const CALIBRATION_SEED: u64 = 0x00ca_1b7a;
/// The known mass of the factory calibration.
pub const CALIBRATION_MASS_G: f64 = 200.0;

/// The command scene's cell is this much more sensitive than the factory-calibrated one: a
/// replacement cell, fitted after the factory calibration, so every mass reads 1 % high
/// (and the empty pan about 1.2 g, the platform's dead load through the more sensitive
/// cell) until the operator calibrates. Makes the calibration's effect visible.
pub const COMMAND_SCENE_GAIN_ERROR: f64 = 0.01;
/// The first mass of the command scene, dropped at 0.3 s (tare it once stable and known
/// to a quarter of e: 1.4 s leaves time for that on every noise seed).
pub const COMMAND_SCENE_FIRST_MASS_G: f64 = 138.32;
/// From 1.8 s, 50 g is poured on in ten 5 g portions 80 ms apart (a tare then is
/// refused): each portion is a load change before the estimate can be stable for 50 ms.
/// 1.5 s after the drop: the harness tares the first mass once 3u ≤ 0.25 e, 0.9–1.5 s
/// after the drop at 50 dB over ten noise seeds, and the checker needs 5 readout lines
/// after it (from 1.7 s, the tare on seed 2 left exactly 5, and a `u` that tapers the
/// residuals' autocovariance to 8 lags left 4 on seed 6).
/// Portions rather than a ramp, because the simulated chain re-discretises its model at
/// every change of load, which a ramp would make every sample: far too slow for QEMU.
pub const COMMAND_SCENE_POUR_START_S: f64 = 1.8;
/// Portions poured.
pub const COMMAND_SCENE_POUR_PORTIONS: usize = 10;
/// Mass of one portion.
pub const COMMAND_SCENE_POUR_PORTION_G: f64 = 5.0;
/// Time between portions.
pub const COMMAND_SCENE_POUR_INTERVAL_S: f64 = 0.08;
/// Everything is lifted off at 3.1 s (calibrate: the empty-pan zero).
pub const COMMAND_SCENE_REMOVAL_S: f64 = 3.1;
/// The 200 g reference mass is dropped at 4.5 s.
pub const COMMAND_SCENE_KNOWN_MASS_S: f64 = 4.5;
/// The command scene ends at 6.0 s: 1.5 s of the reference mass, of which the calibration
/// needs its 0.5 s settling and the rest shows the calibrated readout.
pub const COMMAND_SCENE_END_S: f64 = 6.0;

/// The command scene's load changes, in time order.
pub const COMMAND_SCENE_EVENTS: [LoadEvent; COMMAND_SCENE_POUR_PORTIONS + 3] = {
    let mut events =
        [LoadEvent::step(0.3, COMMAND_SCENE_FIRST_MASS_G); COMMAND_SCENE_POUR_PORTIONS + 3];
    let mut portion = 0;
    while portion < COMMAND_SCENE_POUR_PORTIONS {
        let poured = (portion + 1) as f64;
        events[portion + 1] = LoadEvent::step(
            COMMAND_SCENE_POUR_START_S + portion as f64 * COMMAND_SCENE_POUR_INTERVAL_S,
            COMMAND_SCENE_FIRST_MASS_G + poured * COMMAND_SCENE_POUR_PORTION_G,
        );
        portion += 1;
    }
    events[COMMAND_SCENE_POUR_PORTIONS + 1] = LoadEvent::step(COMMAND_SCENE_REMOVAL_S, 0.0);
    events[COMMAND_SCENE_POUR_PORTIONS + 2] =
        LoadEvent::step(COMMAND_SCENE_KNOWN_MASS_S, CALIBRATION_MASS_G);
    events
};

/// White noise at the demo's 50 dB SNR (thesis eq. 4.39, on the reference chain and its
/// 138.32 g step) plus the INA114's own noise, as `SimulatedAdc::reference_demo` has them.
fn reference_disturbances() -> Disturbances {
    let mut disturbances = Disturbances::white(white_noise_for_snr(
        &SensorChain::reference(),
        REFERENCE_STEP_G,
        REFERENCE_SNR_DB,
        SNR_WINDOW_SAMPLES,
    ));
    disturbances.amplifier_noise = true;
    disturbances
}

/// The command scene (QEMU end-to-end test of the command path): the reference chain with
/// a cell [`COMMAND_SCENE_GAIN_ERROR`] more sensitive, 50 dB SNR as the demo, the demo's
/// noise seed.
pub fn command_scene() -> LoadCell {
    command_scene_with_seed(DEMO_SEED)
}

/// The command scene with another noise seed (host replays over many seeds).
pub fn command_scene_with_seed(seed: u64) -> LoadCell {
    let mut chain = SensorChain::reference();
    chain.cell.rated_output_mv_per_v *= 1.0 + COMMAND_SCENE_GAIN_ERROR;
    let mut script = Script::new(COMMAND_SCENE_END_S);
    for event in COMMAND_SCENE_EVENTS {
        // Thirteen events in time order within the scene fit in sixteen slots.
        let _ = script.push(event);
    }
    SimulatedAdc::new(chain, script, reference_disturbances(), seed)
}

/// Noise seed of the record scene (its own cell session: the drops a method is chosen
/// from are not the demo's that judge it).
pub const RECORD_SEED: u64 = 0x2ec0_4d5e;
/// The record scene's mass, dropped three times (the mass `host-sim calibrate` is told).
pub const RECORD_SCENE_MASS_G: f64 = 138.32;
/// The record scene's drops land at these times; each is lifted off 1.6 s later, so a
/// recording (1.25 s from 0.25 s before the landing) holds the mass alone.
pub const RECORD_SCENE_DROPS_S: [f64; 3] = [1.0, 4.0, 7.0];
/// How long each drop stays on.
pub const RECORD_SCENE_HOLD_S: f64 = 1.6;
/// The record scene ends 2 s after its last drop: the last recording complete (1 s after
/// the landing) and written out (0.5 s on QEMU), with time to spare.
pub const RECORD_SCENE_END_S: f64 = 9.0;

/// The record scene: the reference chain and the demo's noise level, empty for 1 s, then
/// [`RECORD_SCENE_MASS_G`] dropped at each of [`RECORD_SCENE_DROPS_S`] and lifted off
/// [`RECORD_SCENE_HOLD_S`] later (the last stays on). The harness arms `record` on the
/// settled empty pan before each drop (`tests::recording`).
pub fn record_scene() -> LoadCell {
    let mut script = Script::new(RECORD_SCENE_END_S);
    for (index, drop_s) in RECORD_SCENE_DROPS_S.into_iter().enumerate() {
        // Five events in time order fit in sixteen slots.
        let _ = script.push(LoadEvent::step(drop_s, RECORD_SCENE_MASS_G));
        if index + 1 < RECORD_SCENE_DROPS_S.len() {
            let _ = script.push(LoadEvent::step(drop_s + RECORD_SCENE_HOLD_S, 0.0));
        }
    }
    SimulatedAdc::new(
        SensorChain::reference(),
        script,
        reference_disturbances(),
        RECORD_SEED,
    )
}

/// The demo scene: empty 0.3 s, 138.32 g, removed at 2.0 s, 250 g at 2.5 s, end at 4.0 s,
/// 50 dB SNR. Built as `SimulatedAdc::reference_demo` builds it, in the larger script
/// (`tests::commands` checks that the codes are the same).
pub fn demo_scene() -> LoadCell {
    demo_scene_with_empty_start(0.0)
}

/// How much longer the checked demo holds the empty pan before the demo's events, s: the
/// scale's noise metering needs the pan empty and at rest (four `u` within 0.5 e), 1.5 s
/// settled, a 0.3 s window and its 50 ms guard, so the consistency check is live from the
/// first drop on. 2.0 s sufficed while two `u` did (metered at sample 7,800); with four the
/// pan was metered only at the drop itself (sample 9,200), and `cargo xtask bench` refused
/// to time the check. The bench plays it after its restart measurement has left a restless
/// pan, whose fit vouches only from 1 s of age (`a_once_restless_pan_at_rest_is_metered`).
pub const CHECKED_DEMO_EMPTY_S: f64 = 3.0;

/// How much longer the coloured demo holds the empty pan, s: the scale rests the step
/// method's `u` on the empty pan's noise colour once its metered windows hold
/// `estimator_core::MIN_METERED_BLOCKS` block means (3,000 of 24 samples: 18 s of windows
/// after 1.5 s of settling), so the bench can time the runs that do.
pub const COLOURED_DEMO_EMPTY_S: f64 = 24.0;

/// The checked demo: the demo after [`CHECKED_DEMO_EMPTY_S`] more of empty pan.
pub fn checked_demo_scene() -> LoadCell {
    demo_scene_with_empty_start(CHECKED_DEMO_EMPTY_S)
}

/// The demo scene with the empty pan held `empty_s` longer at the start: the first drop
/// then lands after a metered empty period, so the consistency check is live on the runs
/// after it (the bench's figure for it).
pub fn demo_scene_with_empty_start(empty_s: f64) -> LoadCell {
    SimulatedAdc::new(
        SensorChain::reference(),
        crate::simulated::reference_demo_script(empty_s),
        reference_disturbances(),
        DEMO_SEED,
    )
}

/// The chain's nominal gain and zero: the fallback if the stored record is unusable.
pub fn nominal_calibration() -> Calibration {
    let chain = SensorChain::reference();
    Calibration {
        counts_per_gram: chain.counts_per_gram() as f32,
        zero_counts: chain.zero_code() as f32,
    }
}

/// The window a calibration of the QEMU board must fall in: the chain's nominal values with
/// the hardware front end's tolerances ([`FrontEnd::GAIN_TOLERANCE`],
/// [`FrontEnd::ZERO_TOLERANCE_OF_SPAN`] of the cell's capacity), the converter's rails.
pub fn calibration_limits() -> CalibrationLimits {
    let chain = SensorChain::reference();
    let nominal = nominal_calibration();
    CalibrationLimits {
        nominal,
        gain_tolerance: FrontEnd::GAIN_TOLERANCE,
        zero_tolerance_counts: FrontEnd::ZERO_TOLERANCE_OF_SPAN
            * nominal.counts_per_gram
            * chain.cell.capacity_g as f32,
        max_code: chain.adc.max_code(),
    }
}

/// The factory procedure on a simulated cell with the demo's noise: the mean code of
/// the empty pan over 0.5–2.0 s, then the mean with the known mass over 4.0–6.0 s (the
/// cell has settled far below the noise by then), and `Calibration::from_known_mass`.
pub fn factory_calibration() -> Result<Calibration, CalibrationError> {
    const RATE: u32 = 4000;
    let chain = SensorChain::reference();
    let mut script = Script::<8>::new(6.0);
    script
        .push(LoadEvent::step(2.0, CALIBRATION_MASS_G))
        .map_err(|_| CalibrationError::NoSpan)?;
    let mut cell = SimulatedAdc::new(chain, script, reference_disturbances(), CALIBRATION_SEED);
    let (mut empty_sum, mut empty_count) = (0u64, 0u32);
    let (mut loaded_sum, mut loaded_count) = (0u64, 0u32);
    for sample in 0..6 * RATE {
        let code = match cell.read() {
            Ok(code) if !cell.is_saturated(code) => code as u64,
            _ => return Err(CalibrationError::NoSpan),
        };
        if (RATE / 2..2 * RATE).contains(&sample) {
            empty_sum += code;
            empty_count += 1;
        } else if sample >= 4 * RATE {
            loaded_sum += code;
            loaded_count += 1;
        }
    }
    let empty = empty_sum as f64 / empty_count as f64;
    let loaded = loaded_sum as f64 / loaded_count as f64;
    Calibration::from_known_mass(empty as f32, loaded as f32, CALIBRATION_MASS_G as f32)
}
