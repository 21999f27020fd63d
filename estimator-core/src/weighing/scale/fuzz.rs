//! Property tests (proptest, stable Rust) of the scale over arbitrary sample streams, with
//! console commands mixed in, and of building a scale from an arbitrary configuration.
//!
//! Properties: nothing panics; a reading shown `Stable` (or `Empty`) carries a finite mass;
//! an `Invalid` reading carries none; the load-change count never falls, and the run's
//! sample count rises by one per sample unless a load change restarted the run.

extern crate std;
use std::vec::Vec;

use proptest::prelude::*;

use super::test_scene::{calibration, CPG, LIMITS, ZERO};
use super::{RawSample, Scale, ScaleConfig, ScaleReading, ScaleState, StepScale};
use crate::weighing::command::{Command, CommandConfig, Commands};

/// A stretch of the stream: a noisy constant load (grams), arbitrary codes, rails, losses.
#[derive(Clone, Debug)]
enum Segment {
    Load {
        grams: f32,
        noise_g: f32,
        samples: u16,
    },
    Codes(Vec<i32>),
    Saturated(u16),
    Lost(u16),
    Command {
        byte: u8,
        known_mass_g: f32,
    },
}

fn segment() -> impl Strategy<Value = Segment> {
    prop_oneof![
        4 => (-50.0f32..800.0, 0.0f32..2.0, 1u16..3000)
            .prop_map(|(grams, noise_g, samples)| Segment::Load { grams, noise_g, samples }),
        2 => proptest::collection::vec(any::<i32>(), 1..200).prop_map(Segment::Codes),
        1 => (1u16..50).prop_map(Segment::Saturated),
        1 => (1u16..50).prop_map(Segment::Lost),
        2 => (any::<u8>(), any::<f32>())
            .prop_map(|(byte, known_mass_g)| Segment::Command { byte, known_mass_g }),
    ]
}

/// A cheap deterministic noise in [−1, 1).
fn noise(state: &mut u64) -> f32 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
}

fn check(previous: &ScaleReading, reading: &ScaleReading) -> Result<(), TestCaseError> {
    match reading.state {
        ScaleState::Invalid(_) => prop_assert_eq!(reading.mass_g, None, "{:?}", reading),
        ScaleState::Stable | ScaleState::Empty => {
            prop_assert!(reading.mass_g.is_some_and(f32::is_finite), "{:?}", reading)
        }
        ScaleState::Estimating => {
            prop_assert!(reading.mass_g.is_none_or(f32::is_finite), "{:?}", reading)
        }
    }
    // A final reading is a mass with a finite uncertainty; u never comes without a mass.
    if reading.is_final {
        prop_assert!(reading.mass_g.is_some_and(f32::is_finite), "{:?}", reading);
        prop_assert!(
            reading.uncertainty_g.is_some_and(f32::is_finite),
            "{:?}",
            reading
        );
    }
    prop_assert!(reading.mass_g.is_some() || reading.uncertainty_g.is_none());
    prop_assert!(reading.load_changes >= previous.load_changes);
    if reading.load_changes == previous.load_changes {
        prop_assert!(
            reading.samples_since_change >= previous.samples_since_change,
            "{:?} after {:?}",
            reading,
            previous
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5000))]

    #[test]
    fn arbitrary_streams_and_commands_keep_every_reading_honest(
        segments in proptest::collection::vec(segment(), 1..12),
        seed in any::<u64>(),
    ) {
        let mut scale = StepScale::<8>::step_default(4000.0, calibration()).unwrap();
        let mut commands = Commands::new(CommandConfig::weighing_default(4000.0, LIMITS));
        let mut state = seed;
        let mut previous = scale.reading();
        let mut now = 0u32;
        for segment in segments {
            let samples: Vec<RawSample> = match segment {
                Segment::Load { grams, noise_g, samples } => (0..samples)
                    .map(|_| {
                        let g = grams + noise_g * noise(&mut state);
                        RawSample::Counts((ZERO + g * CPG) as i32)
                    })
                    .collect(),
                Segment::Codes(codes) => codes.into_iter().map(RawSample::Counts).collect(),
                Segment::Saturated(n) => (0..n).map(|_| RawSample::Saturated).collect(),
                Segment::Lost(n) => (0..n).map(|_| RawSample::Lost).collect(),
                Segment::Command { byte, known_mass_g } => {
                    if let Some(command) = Command::from_byte(byte, known_mass_g) {
                        let _ = commands.handle(command, &mut scale, now);
                    }
                    Vec::new()
                }
            };
            for sample in samples {
                now = now.wrapping_add(1);
                let reading = scale.push(sample);
                let _ = commands.poll(&mut scale, now);
                check(&previous, &reading)?;
                previous = reading;
            }
        }
    }

    #[test]
    fn an_arbitrary_configuration_builds_or_is_refused(
        values in proptest::collection::vec(
            prop_oneof![any::<f32>(), -10.0f32..1000.0, Just(f32::NAN), Just(0.0)],
            20,
        ),
        counts in proptest::collection::vec(any::<u32>(), 8),
        codes in proptest::collection::vec(any::<i32>(), 0..500),
    ) {
        let config = ScaleConfig {
            sample_rate_hz: values[0],
            empty_band_g: values[1],
            stable_band_g: values[2],
            stable_band_relative: values[3],
            residual_drift_g: values[4],
            residual_threshold_g: values[5],
            raw_drift_g: values[6],
            raw_threshold_g: values[7],
            capacity_g: values[8],
            scale_interval_g: values[9],
            zero_tracking_band_g: values[10],
            zero_tracking_rate_g_per_s: values[11],
            zero_tracking_range_g: values[12],
            block_drift_g: values[13],
            block_threshold_g: values[14],
            final_target_g: values[15],
            accuracy_target_relative: values[16],
            accuracy_target_mass_g: values[17],
            ringing_min_hz: values[18],
            zero_drift_g_per_s: values[19],
            block_samples: counts[6] % 10_000,
            stable_hold_samples: counts[0],
            residual_arm_samples: counts[1],
            raw_arm_samples: counts[2] % 100_000,
            restless_fit_samples: counts[7] % 100_000,
            flag_restart_samples: counts[3],
            noise_window_samples: counts[4],
            noise_guard_samples: counts[5],
            consistency_check: counts[0] % 2 == 0,
        };
        let estimator = StepScale::<8>::step_estimator(7, 16, 1.0).unwrap();
        if let Ok(mut scale) = Scale::new(config, estimator, calibration()) {
            prop_assert_eq!(config.validate(), Ok(()));
            let mut previous = scale.reading();
            for code in codes {
                let reading = scale.push(RawSample::Counts(code));
                check(&previous, &reading)?;
                previous = reading;
            }
        } else {
            prop_assert!(config.validate().is_err());
        }
    }
}
