//! Bad input to the IV and BCLS estimators and to the noise meter gets a typed answer: never
//! a panic, never a non-finite value reported valid, latched faults until `reset()`; and the
//! noise meter measures the variance it promises.

mod support;

use estimator_core::{
    max_instrument_delay, BiasCompensatedConfig, BiasCompensatedStepEstimator, ConfigError,
    Estimator, InvalidReason, IvConfig, IvStepEstimator, NoiseMeter, Reading, State, StepConfig,
};
use proptest::prelude::*;
use support::*;

fn iv(config: StepConfig<f64>) -> IvStepEstimator<f64, 4> {
    IvStepEstimator::new(IvConfig::new(config)).unwrap()
}

fn bc(config: StepConfig<f64>, variance: f64) -> BiasCompensatedStepEstimator<f64, 4> {
    BiasCompensatedStepEstimator::new(BiasCompensatedConfig::new(config, variance)).unwrap()
}

#[test]
fn impossible_configurations_are_refused() {
    let step = StepConfig::<f32>::new(3, 2.0);
    let ok = IvConfig::new(step);
    assert_eq!(ok.instrument_delay, 4, "default delay n + 1");
    assert!(IvStepEstimator::<f32, 7>::new(ok).is_ok());
    let too_long = max_instrument_delay(7, 3) + 1;
    for (config, expected) in [
        (ok.with_instrument_delay(3), ConfigError::Model),
        (ok.with_instrument_delay(too_long), ConfigError::Model),
        (ok.with_min_identifiability(1.0), ConfigError::Model),
        (ok.with_min_identifiability(-0.1), ConfigError::Model),
        (ok.with_min_identifiability(f32::NAN), ConfigError::Model),
        (
            IvConfig::new(StepConfig::new(8, 2.0)),
            ConfigError::Order {
                requested: 8,
                capacity: 7,
            },
        ),
        (
            IvConfig::new(step.with_forgetting(0.0)),
            ConfigError::Forgetting,
        ),
    ] {
        assert_eq!(
            IvStepEstimator::<f32, 7>::new(config).err(),
            Some(expected),
            "{config:?}"
        );
    }
    assert!(IvStepEstimator::<f32, 7>::new(ok.with_instrument_delay(too_long - 1)).is_ok());
    for (variance, expected) in [
        (-1.0, Some(ConfigError::Model)),
        (f32::NAN, Some(ConfigError::Model)),
        (f32::INFINITY, Some(ConfigError::Model)),
        (0.0, None),
        (4.0, None),
    ] {
        let config = BiasCompensatedConfig::new(step, variance);
        assert_eq!(
            BiasCompensatedStepEstimator::<f32, 7>::new(config).err(),
            expected
        );
    }
    // A variance that overflows once divided by a tiny gain squared.
    let config = BiasCompensatedConfig::new(StepConfig::new(3, 1e-30), 1e30);
    assert_eq!(
        BiasCompensatedStepEstimator::<f32, 7>::new(config).err(),
        Some(ConfigError::Model)
    );
    assert_eq!(
        NoiseMeter::<f32>::new(0).err(),
        Some(ConfigError::Decimation)
    );
}

/// Push `y` and check every reading's invariants; returns the last reading.
fn run<E: Estimator<f64> + ?Sized>(estimator: &mut E, y: &[f64]) -> Reading<f64> {
    let mut last = None;
    for &s in y {
        let r = estimator.push(s);
        assert_eq!(r.estimate.is_some(), r.state == State::Estimating);
        last = Some(r);
    }
    last.unwrap()
}

#[test]
fn bad_samples_latch_a_typed_reason_until_reset() {
    let sensor = mass_spring_damper();
    let g = sensor.static_gain();
    let y = sensor.step_response(2.0, 60);
    let step = StepConfig::new(2, g).with_valid_range(-100.0, 100.0);
    for (bad, reason) in [
        (Some(f64::NAN), InvalidReason::NonFiniteInput),
        (Some(f64::INFINITY), InvalidReason::NonFiniteInput),
        (Some(-f64::INFINITY), InvalidReason::NonFiniteInput),
        (Some(1e9), InvalidReason::OutOfRange),
        (None, InvalidReason::MissingSample),
    ] {
        let mut estimators: [Box<dyn Estimator<f64>>; 2] =
            [Box::new(iv(step)), Box::new(bc(step, 0.0))];
        for est in estimators.iter_mut() {
            run(est.as_mut(), &y[..30]);
            let r = match bad {
                Some(sample) => est.push(sample),
                None => est.push_missing(),
            };
            assert_eq!(r.state, State::Invalid(reason));
            assert_eq!(r.samples, 31);
            for &s in &y[30..] {
                let r = est.push(s);
                assert_eq!((r.state, r.estimate), (State::Invalid(reason), None));
            }
            est.reset();
            let last = run(est.as_mut(), &y);
            assert!(
                (last.estimate.unwrap() - 2.0).abs() < 1e-9,
                "works after reset"
            );
        }
    }
}

#[test]
fn overflowing_data_is_caught_as_a_non_finite_update() {
    let step = StepConfig::<f32>::new(2, 1.0);
    let mut a = IvStepEstimator::<f32, 4>::new(IvConfig::new(step)).unwrap();
    let mut b =
        BiasCompensatedStepEstimator::<f32, 4>::new(BiasCompensatedConfig::new(step, 1.0)).unwrap();
    let (mut sa, mut sb) = (State::WarmingUp, State::WarmingUp);
    for k in 0..40 {
        // Finite samples whose products overflow f32.
        let s = if k % 2 == 0 { 3e38 } else { -3e38 };
        let (ra, rb) = (a.push(s), b.push(s));
        assert!(ra.estimate.is_none_or(f32::is_finite));
        assert!(rb.estimate.is_none_or(f32::is_finite));
        (sa, sb) = (ra.state, rb.state);
    }
    assert_eq!(sa, State::Invalid(InvalidReason::NonFiniteUpdate));
    assert_eq!(sb, State::Invalid(InvalidReason::NonFiniteUpdate));
}

#[test]
fn a_ramp_is_ill_conditioned_for_both() {
    // Constant differences: the constant column is in their span, u is not identifiable.
    let ramp: Vec<f64> = (0..80).map(|k| 0.5 * k as f64).collect();
    let step = StepConfig::new(1, 1.0);
    assert_eq!(
        run(&mut iv(step), &ramp).state,
        State::Invalid(InvalidReason::IllConditioned)
    );
    assert_eq!(
        run(&mut bc(step, 0.01), &ramp).state,
        State::Invalid(InvalidReason::IllConditioned)
    );
}

#[test]
fn noise_larger_than_the_signal_is_flagged_by_bcls_not_reported() {
    // A configured variance far above the data's: the compensated matrix is indefinite.
    let sensor = mass_spring_damper();
    let g = sensor.static_gain();
    let y = sensor.step_response(2.0, 60);
    let last = run(&mut bc(StepConfig::new(2, g), 1e6), &y);
    assert_eq!(last.state, State::Invalid(InvalidReason::IllConditioned));
    assert_eq!(last.estimate, None);
}

#[test]
fn the_first_estimates_come_after_the_documented_warm_up() {
    let sensor = mass_spring_damper();
    let g = sensor.static_gain();
    let y = sensor.step_response(2.0, 200);
    for decimation in [1u16, 3] {
        let step = StepConfig::new(2, g).with_decimation(decimation);
        for delay in [3, 6] {
            let config = IvConfig::new(step)
                .with_instrument_delay(delay)
                .with_min_identifiability(0.0);
            let mut est = IvStepEstimator::<f64, 4>::new(config).unwrap();
            let first = y
                .iter()
                .position(|&s| est.push(s).state != State::WarmingUp);
            assert_eq!(first.map(|k| k as u32 + 1), Some(est.warm_up_samples()));
            assert_eq!(
                est.warm_up_samples(),
                (2 * 2 + delay as u32 + 1) * decimation as u32
            );
        }
        let mut est = bc(step, 0.0);
        let first = y
            .iter()
            .position(|&s| est.push(s).state != State::WarmingUp);
        assert_eq!(first.map(|k| k as u32 + 1), Some(est.warm_up_samples()));
    }
}

#[test]
fn sizes_of_the_order_7_f32_estimators() {
    let iv = core::mem::size_of::<IvStepEstimator<f32, 7>>();
    let bc = core::mem::size_of::<BiasCompensatedStepEstimator<f32, 7>>();
    let meter = core::mem::size_of::<NoiseMeter<f32>>();
    println!("size_of::<IvStepEstimator<f32, 7>>() = {iv} bytes");
    println!("size_of::<BiasCompensatedStepEstimator<f32, 7>>() = {bc} bytes");
    println!("size_of::<NoiseMeter<f32>>() = {meter} bytes");
    // StepEstimator<f32, 7> is ≤ 512 bytes; IV carries the (n+1)² system and a 4N history;
    // every estimator's intake holds the reading's uncertainty (`Option<f32>`, 8 B) and its
    // degrees of freedom (`u32`, 8 B with padding), which took the bias-compensated one
    // from 512 to 528 B; its own `u` (`bc_uncertainty`) keeps the lag sums' counters and
    // the least-squares residual sum even without lag sums (`L = 0`): 24 B more, 552 B;
    // and the white-noise floor's degrees of freedom (stop 49), 560 B.
    assert!(iv <= 1024 && bc <= 560 && meter <= 64, "{iv} {bc} {meter}");
}

// ---------------------------------------------------------------------------------------
// The noise meter
// ---------------------------------------------------------------------------------------

#[test]
fn the_noise_meter_is_unbiased_and_ignores_offset_and_drift() {
    // σ = 3 raw units on an offset of 1e4 with a drift of 0.01 per sample (10 over the
    // record, ≫ σ/√M): 400 records of 1,200 samples. Each estimate has a relative standard
    // error √(3/M) (M differences); the mean of 400 is tested at 4 of its standard errors,
    // and the spread of the estimates against √(3/M) within 15% (the spread's own relative
    // error over 400 records is ~3.5%).
    for decimation in [1u16, 12] {
        let (sigma, records, samples) = (3.0, 400, 1200);
        let mut noise = Gaussian::new(decimation as u64);
        let mut estimates = Vec::new();
        let mut predicted_se = 0.0;
        for _ in 0..records {
            let mut meter = NoiseMeter::<f64>::new(decimation).unwrap();
            for k in 0..samples {
                meter
                    .push(1e4 + 0.01 * k as f64 + sigma * noise.sample())
                    .unwrap();
            }
            estimates.push(meter.noise_variance().unwrap() / (sigma * sigma));
            predicted_se = meter.relative_standard_error().unwrap();
        }
        let n = estimates.len() as f64;
        let mean = estimates.iter().sum::<f64>() / n;
        let sd = (estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        println!(
            "D={decimation}: mean σ̂²/σ² = {mean:.4}, spread {sd:.4}, predicted {predicted_se:.4}"
        );
        assert!(
            (mean - 1.0).abs() < 4.0 * predicted_se / n.sqrt(),
            "D={decimation}: {mean}"
        );
        assert!(
            (sd / predicted_se - 1.0).abs() < 0.15,
            "D={decimation}: {sd} vs {predicted_se}"
        );
    }
}

#[test]
fn the_noise_meter_refuses_bad_samples_and_agrees_in_f32() {
    let mut meter = NoiseMeter::<f32>::new(1).unwrap();
    assert_eq!(meter.noise_variance(), None, "nothing measured yet");
    let mut noise = Gaussian::new(3);
    let data: Vec<f64> = (0..4000).map(|_| 2.0 * noise.sample()).collect();
    let mut reference = NoiseMeter::<f64>::new(1).unwrap();
    for &s in &data {
        meter.push(s as f32).unwrap();
        reference.push(s as f32 as f64).unwrap();
    }
    let (v32, v64) = (
        meter.noise_variance().unwrap() as f64,
        reference.noise_variance().unwrap(),
    );
    // Welford's update in f32 over 4,000 O(σ) differences: relative error ~ ε·√M ≈ 1e-5.
    assert!((v32 - v64).abs() / v64 < 1e-4, "{v32} vs {v64}");
    assert_eq!(meter.push(f32::NAN), Err(InvalidReason::NonFiniteInput));
    assert_eq!(
        meter.push(1.0),
        Err(InvalidReason::NonFiniteInput),
        "latched"
    );
    assert_eq!(meter.noise_variance(), None);
    meter.reset();
    assert_eq!(meter.push(1.0), Ok(()));
}

// ---------------------------------------------------------------------------------------
// Property: never panics, every valid reading finite
// ---------------------------------------------------------------------------------------

fn check<T: Copy + PartialEq + core::fmt::Debug>(
    r: &Reading<T>,
    finite: impl Fn(T) -> bool,
) -> Result<(), TestCaseError> {
    prop_assert_eq!(r.estimate.is_some(), r.state == State::Estimating);
    prop_assert!(r.estimate.is_none_or(&finite));
    prop_assert!(r.residual.is_none_or(&finite));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(192))]

    #[test]
    fn never_panics_and_every_valid_reading_is_finite(
        poles in prop::collection::vec((0.0f64..0.999, prop_oneof![Just(0.0), 0.001f64..3.1]), 1..6),
        order in 1usize..=8,
        gain in prop_oneof![1e-6f64..1e-3, 0.1f64..10.0, 1e3f64..1e6],
        u in -1e3f64..1e3,
        snr_db in prop_oneof![Just(f64::INFINITY), 0.0f64..120.0],
        variance_factor in prop_oneof![Just(0.0), 0.0f64..4.0, 1e3f64..1e9],
        forgetting in prop_oneof![Just(1.0f64), 0.8f64..1.0],
        decimation in 1u16..8,
        delay_extra in 0usize..8,
        floor in prop_oneof![Just(0.0f64), Just(0.1), 0.0f64..0.9],
        seed in any::<u64>(),
        poison_at in prop::option::of(0usize..300),
    ) {
        let samples = 300;
        let clean = stable_sensor_response(&poles, gain, u, samples);
        let (mut y, sigma) = if snr_db.is_finite() {
            add_noise(&clean, gain * u, snr_db, seed)
        } else {
            (clean, (gain * u).abs() * 1e-3)
        };
        if let Some(k) = poison_at {
            y[k] = f64::NAN;
        }
        let variance = variance_factor * sigma * sigma;
        let delay = order + 1 + delay_extra;
        let step64 = StepConfig::new(order, gain).with_forgetting(forgetting).with_decimation(decimation);
        let step32 = StepConfig::new(order, gain as f32).with_forgetting(forgetting as f32).with_decimation(decimation);
        let mut iv64 = IvStepEstimator::<f64, 8>::new(IvConfig::new(step64).with_instrument_delay(delay).with_min_identifiability(floor)).unwrap();
        let mut iv32 = IvStepEstimator::<f32, 8>::new(IvConfig::new(step32).with_instrument_delay(delay).with_min_identifiability(floor as f32)).unwrap();
        let bc64 = BiasCompensatedStepEstimator::<f64, 8>::new(BiasCompensatedConfig::new(step64, variance));
        let bc32 = BiasCompensatedStepEstimator::<f32, 8>::new(BiasCompensatedConfig::new(step32, variance as f32));
        // A variance that overflows in f32 after division by G² is refused, not used.
        let (mut bc64, mut bc32) = (bc64.ok(), bc32.ok());
        prop_assert!(bc64.is_some());
        for (k, &s) in y.iter().enumerate() {
            let readings = [iv64.push(s), bc64.as_mut().map(|e| e.push(s)).unwrap()];
            for r in &readings {
                prop_assert_eq!(r.samples as usize, k + 1);
                check(r, f64::is_finite)?;
                if poison_at.is_some_and(|p| k >= p) {
                    prop_assert_eq!(r.state, State::Invalid(InvalidReason::NonFiniteInput));
                }
            }
            check(&iv32.push(s as f32), f32::is_finite)?;
            if let Some(e) = bc32.as_mut() {
                check(&e.push(s as f32), f32::is_finite)?;
            }
        }
    }
}
