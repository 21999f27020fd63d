//! Bad input gets a typed answer: never a panic, never a non-finite value reported valid,
//! and the estimator works again after `reset()`.

mod support;

use estimator_core::{
    ConfigError, Estimator, InvalidReason, NoiseReference, State, StepConfig, StepEstimator,
    MAX_DECIMATION,
};
use proptest::prelude::*;
use support::*;

fn msd_response(samples: usize) -> (Vec<f64>, f64) {
    let sensor = mass_spring_damper();
    (sensor.step_response(2.0, samples), sensor.static_gain())
}

#[test]
fn impossible_configurations_are_refused_with_the_field() {
    let ok = StepConfig::<f32>::new(3, 2.0);
    assert!(StepEstimator::<f32, 7>::new(ok).is_ok());
    let cases: [(StepConfig<f32>, ConfigError); 9] = [
        (
            StepConfig::new(0, 2.0),
            ConfigError::Order {
                requested: 0,
                capacity: 7,
            },
        ),
        (
            StepConfig::new(8, 2.0),
            ConfigError::Order {
                requested: 8,
                capacity: 7,
            },
        ),
        (StepConfig::new(3, 0.0), ConfigError::Gain),
        (StepConfig::new(3, f32::NAN), ConfigError::Gain),
        (ok.with_forgetting(0.0), ConfigError::Forgetting),
        (ok.with_forgetting(1.01), ConfigError::Forgetting),
        (ok.with_forgetting(f32::NAN), ConfigError::Forgetting),
        (
            ok.with_decimation(MAX_DECIMATION + 1),
            ConfigError::Decimation,
        ),
        (ok.with_valid_range(5.0, 5.0), ConfigError::Range),
    ];
    for (cfg, expected) in cases {
        assert_eq!(
            StepEstimator::<f32, 7>::new(cfg).err(),
            Some(expected),
            "{cfg:?}"
        );
    }
    assert_eq!(
        StepEstimator::<f32, 7>::new(ok.with_decimation(0)).err(),
        Some(ConfigError::Decimation)
    );
    // A white-noise floor that is not finite and non-negative is refused, and the one set
    // before stays, over a reset too.
    let mut est = StepEstimator::<f32, 7>::new(ok.with_decimation(4)).unwrap();
    assert_eq!(
        est.set_white_noise(Some(NoiseReference::new(2.0, 400))),
        Ok(())
    );
    for bad in [-1.0, f32::NAN, f32::INFINITY] {
        assert_eq!(
            est.set_white_noise(Some(NoiseReference::new(bad, 400))),
            Err(ConfigError::NoiseReference)
        );
    }
    est.reset();
    assert_eq!(est.white_noise_variance(), Some(2.0));
    assert_eq!(est.set_white_noise(None), Ok(()));
    assert_eq!(est.white_noise_variance(), None);
}

#[test]
fn non_finite_and_out_of_range_samples_latch_a_typed_reason_until_reset() {
    let (y, g) = msd_response(40);
    for (bad, reason) in [
        (f64::NAN, InvalidReason::NonFiniteInput),
        (f64::INFINITY, InvalidReason::NonFiniteInput),
        (f64::NEG_INFINITY, InvalidReason::NonFiniteInput),
        (1e9, InvalidReason::OutOfRange),
    ] {
        let cfg = StepConfig::new(2, g).with_valid_range(-100.0, 100.0);
        let mut est = StepEstimator::<f64, 4>::new(cfg).unwrap();
        for &s in &y[..20] {
            assert!(!est.push(s).is_invalid());
        }
        let r = est.push(bad);
        assert_eq!(r.state, State::Invalid(reason));
        assert_eq!(r.estimate, None);
        // Latched: good samples after a gap in the stream do not bring it back silently.
        for &s in &y[20..] {
            let r = est.push(s);
            assert_eq!(r.state, State::Invalid(reason));
            assert_eq!(r.estimate, None);
        }
        est.reset();
        let mut last = None;
        for &s in &y {
            last = est.push(s).estimate;
        }
        assert!(
            (last.unwrap() - 2.0).abs() < 1e-9,
            "works again after reset"
        );
    }
}

#[test]
fn a_missing_sample_is_flagged() {
    let (y, g) = msd_response(30);
    let mut est = StepEstimator::<f32, 4>::new(StepConfig::new(2, g as f32)).unwrap();
    for &s in &y[..10] {
        est.push(s as f32);
    }
    let r = est.push_missing();
    assert_eq!(r.state, State::Invalid(InvalidReason::MissingSample));
    assert_eq!(r.samples, 11, "the lost sample is counted");
}

#[test]
fn overflowing_data_is_caught_as_a_non_finite_update() {
    let mut est = StepEstimator::<f32, 4>::new(StepConfig::new(2, 1.0)).unwrap();
    let mut state = State::WarmingUp;
    for k in 0..20 {
        // Finite samples whose squares overflow f32.
        let s = if k % 2 == 0 { 3e38 } else { -3e38 };
        let r = est.push(s);
        assert!(r.estimate.is_none_or(f32::is_finite));
        state = r.state;
    }
    assert_eq!(state, State::Invalid(InvalidReason::NonFiniteUpdate));
}

#[test]
fn a_constant_column_in_the_span_of_the_differences_is_ill_conditioned() {
    // A ramp has constant differences: the constant column is in their span, so the step
    // level is not identifiable and must not be reported.
    let mut est = StepEstimator::<f64, 4>::new(StepConfig::new(1, 1.0)).unwrap();
    let mut last = State::WarmingUp;
    for k in 0..50 {
        let r = est.push(0.5 * k as f64);
        assert_eq!(r.estimate.is_some(), r.state == State::Estimating);
        last = r.state;
    }
    assert_eq!(last, State::Invalid(InvalidReason::IllConditioned));
}

#[test]
fn size_of_the_order_7_f32_estimator_is_within_512_bytes() {
    let size = core::mem::size_of::<StepEstimator<f32, 7>>();
    println!("size_of::<StepEstimator<f32, 7>>() = {size} bytes");
    assert!(size <= 512, "{size} bytes");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn never_panics_and_every_valid_reading_is_finite(
        poles in prop::collection::vec((0.0f64..0.999, prop_oneof![Just(0.0), 0.001f64..3.1]), 1..6),
        order in 1usize..=12,
        gain in prop_oneof![1e-6f64..1e-3, 0.1f64..10.0, 1e3f64..1e6],
        u in -1e3f64..1e3,
        snr_db in prop_oneof![Just(f64::INFINITY), 0.0f64..120.0],
        forgetting in prop_oneof![Just(1.0f64), 0.8f64..1.0],
        decimation in 1u16..20,
        seed in any::<u64>(),
        poison_at in prop::option::of(0usize..300),
    ) {
        let samples = 300;
        let clean = stable_sensor_response(&poles, gain, u, samples);
        let mut y = if snr_db.is_finite() {
            add_noise(&clean, gain * u, snr_db, seed).0
        } else {
            clean
        };
        if let Some(k) = poison_at {
            y[k] = f64::NAN;
        }
        let cfg64 = StepConfig::new(order, gain).with_forgetting(forgetting).with_decimation(decimation);
        let cfg32 = StepConfig::new(order, gain as f32).with_forgetting(forgetting as f32).with_decimation(decimation);
        let mut e64 = StepEstimator::<f64, 12>::new(cfg64).unwrap();
        let mut e32 = StepEstimator::<f32, 12>::new(cfg32).unwrap();
        for (k, &s) in y.iter().enumerate() {
            let r64 = e64.push(s);
            let r32 = e32.push(s as f32);
            prop_assert_eq!(r64.samples as usize, k + 1);
            prop_assert!(well_formed(&r64), "{:?}", r64);
            prop_assert!(well_formed(&r32), "{:?}", r32);
            if poison_at.is_some_and(|p| k >= p) {
                prop_assert_eq!(r64.state, State::Invalid(InvalidReason::NonFiniteInput));
            }
        }
    }
}
