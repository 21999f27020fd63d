//! The parametric load-cell model ([`LoadCellModel`]) against independent discretisations
//! (nalgebra's matrix exponential of textbook companion forms), the at-rest variant of the
//! model-based estimator against its closed-form least squares, and bad input to the
//! model-based estimators and the bank. Host-sim's `model_based` tests hold the studies
//! against the simulator (identification, Cramér–Rao bound, bias across loads).
// Index loops mirror the matrix algebra, as in the crates.
#![allow(clippy::needless_range_loop)]

mod support;

use estimator_core::{
    ConfigError, Estimator, InitialState, InvalidReason, ModelBank, ModelConfig, ModelEstimator,
    State,
};

use estimator_core::sensor::LoadCellModel;
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use support::*;

fn model(order: u8) -> LoadCellModel {
    LoadCellModel {
        natural_frequency_hz: 25.0,
        damping_ratio: 0.03,
        filter_order: order,
        filter_cutoff_hz: 100.0,
        counts_per_gram: 1e-3,
        sample_rate_hz: 4000.0,
    }
}

/// Step response (input 1) of a discrete model, `samples` long, output before each step.
fn discrete_step<const S: usize>(
    m: &estimator_core::SensorModel<f64, S>,
    samples: usize,
) -> Vec<f64> {
    let mut x = [0.0; S];
    let mut y = Vec::with_capacity(samples);
    for _ in 0..samples {
        y.push((0..S).map(|i| m.c[i] * x[i]).sum());
        let mut next = m.b;
        for r in 0..S {
            for c in 0..S {
                next[r] += m.a[r][c] * x[c];
            }
        }
        x = next;
    }
    y
}

/// The mechanics in series with the Butterworth whose denominator (monic, normalised to
/// ω_c = 1) has the coefficients `poly` (highest power first, leading 1 left out), in
/// controllable companion form: an independent route to the same transfer function.
fn companion_sensor(poly: &[f64]) -> Sensor {
    let order = poly.len();
    let n = 2 + order;
    let wn = 2.0 * core::f64::consts::PI * 25.0;
    let wc = 2.0 * core::f64::consts::PI * 100.0;
    let zeta = 0.03;
    let mut a = DMatrix::<f64>::zeros(n, n);
    a[(0, 1)] = 1.0;
    a[(1, 0)] = -wn * wn;
    a[(1, 1)] = -2.0 * zeta * wn;
    // Filter states z, ż, …: z^(N) = wc^N·(p − z) − Σ a_i wc^(N−i) z^(N−i).
    for i in 0..order.saturating_sub(1) {
        a[(2 + i, 3 + i)] = 1.0;
    }
    if order > 0 {
        let last = 2 + order - 1;
        a[(last, 0)] += wc.powi(order as i32);
        for (i, coefficient) in poly.iter().enumerate() {
            // poly[i] multiplies s^(N−1−i): the derivative of order N−1−i.
            let derivative = order - 1 - i;
            a[(last, 2 + derivative)] -= coefficient * wc.powi((i + 1) as i32);
        }
    }
    let mut b = DVector::<f64>::zeros(n);
    b[1] = wn * wn * 1e-3;
    let mut c = DVector::<f64>::zeros(n);
    c[if order == 0 { 0 } else { 2 }] = 1.0;
    Sensor {
        name: "companion",
        order: n,
        a,
        b,
        c,
        sample_time_s: 1.0 / 4000.0,
    }
}

#[test]
fn the_reference_cell_matches_the_companion_form() {
    // support::load_cell() is the 25 Hz, ζ = 0.03 cell with the 3rd-order 100 Hz Butterworth
    // at 4 kHz in companion form, discretised with nalgebra's expm. Both are exact ZOH:
    // they agree to rounding (1e-10 of the static gain over 1 s).
    let reference = load_cell().step_response(1.0, 4000);
    let ours = discrete_step(&model(3).sensor_model::<f64, 5>().unwrap(), 4000);
    for (k, (a, b)) in reference.iter().zip(&ours).enumerate() {
        assert!((a - b).abs() < 1e-13, "k = {k}: {a} vs {b}");
    }
}

#[test]
fn every_butterworth_order_matches_its_polynomial() {
    // Butterworth denominators B_N(s) (ω_c = 1), leading coefficient left out.
    let s2 = core::f64::consts::SQRT_2;
    let cases: [(u8, Vec<f64>); 4] = [
        (1, vec![1.0]),
        (2, vec![s2, 1.0]),
        (3, vec![2.0, 2.0, 1.0]),
        (
            4,
            vec![
                2.613_125_929_752_753,
                3.414_213_562_373_095,
                2.613_125_929_752_753,
                1.0,
            ],
        ),
    ];
    for (order, poly) in cases {
        let reference = companion_sensor(&poly).step_response(1.0, 2000);
        let ours = match order {
            1 => discrete_step(&model(1).sensor_model::<f64, 3>().unwrap(), 2000),
            2 => discrete_step(&model(2).sensor_model::<f64, 4>().unwrap(), 2000),
            3 => discrete_step(&model(3).sensor_model::<f64, 5>().unwrap(), 2000),
            _ => discrete_step(&model(4).sensor_model::<f64, 6>().unwrap(), 2000),
        };
        for (k, (a, b)) in reference.iter().zip(&ours).enumerate() {
            // The companion form's entries reach wc⁴ = 2.5e11: allow its rounding, 1e-11 of
            // the static gain (1e-3).
            assert!((a - b).abs() < 1e-14, "order {order}, k = {k}: {a} vs {b}");
        }
    }
}

#[test]
fn at_rest_is_the_one_unknown_least_squares_solution() {
    // With x₀ = 0 the estimate after m blocks is Σ s̄·ȳ / Σ s̄² over block means s̄, ȳ.
    let m = model(3).sensor_model::<f64, 5>().unwrap();
    let unit = discrete_step(&m, 800);
    let (noisy, _) = add_noise(
        &unit.iter().map(|v| v * 138.0).collect::<Vec<_>>(),
        0.138,
        40.0,
        3,
    );
    for decimation in [1u16, 4] {
        let d = usize::from(decimation);
        let mut estimator = ModelEstimator::new(
            ModelConfig::new(m)
                .with_decimation(decimation)
                .with_initial_state(InitialState::AtRest),
        )
        .unwrap();
        let (mut sy, mut ss) = (0.0, 0.0);
        for (k, &y) in noisy.iter().enumerate() {
            let reading = estimator.push(y);
            if (k + 1) % d != 0 {
                continue;
            }
            let block = (k + 1 - d)..=k;
            let s_mean: f64 = unit[block.clone()].iter().sum::<f64>() / d as f64;
            let y_mean: f64 = noisy[block].iter().sum::<f64>() / d as f64;
            sy += s_mean * y_mean;
            ss += s_mean * s_mean;
            if let Some(u) = reading.estimate {
                let want = sy / ss;
                assert!(
                    (u - want).abs() <= 1e-9 * want.abs(),
                    "D = {decimation}, k = {k}: {u} vs {want}"
                );
            } else {
                // Only the first (all-zero) regressor leaves u undetermined.
                assert!(ss == 0.0 || k < d, "k = {k}: {reading:?}");
            }
        }
    }
}

#[test]
fn impossible_models_and_banks_are_refused() {
    assert_eq!(model(3).sensor_model::<f64, 4>(), Err(ConfigError::Model));
    for broken in [
        LoadCellModel {
            natural_frequency_hz: 0.0,
            ..model(3)
        },
        LoadCellModel {
            damping_ratio: -0.1,
            ..model(3)
        },
        LoadCellModel {
            damping_ratio: 11.0,
            ..model(3)
        },
        LoadCellModel {
            filter_cutoff_hz: f64::INFINITY,
            ..model(3)
        },
        LoadCellModel {
            sample_rate_hz: f64::NAN,
            ..model(3)
        },
        LoadCellModel {
            counts_per_gram: 0.0,
            ..model(3)
        },
    ] {
        assert_eq!(
            broken.sensor_model::<f32, 5>(),
            Err(ConfigError::Model),
            "{broken:?}"
        );
        assert!(broken
            .bank_configs::<f32, 5, 3>(0.9, 1.1, 8, InitialState::Unknown)
            .is_err());
    }
    assert_eq!(
        model(3)
            .bank_configs::<f32, 5, 3>(1.1, 0.9, 8, InitialState::Unknown)
            .err(),
        Some(ConfigError::Model)
    );
    let configs = model(3)
        .bank_configs::<f32, 5, 3>(0.9, 1.1, 0, InitialState::Unknown)
        .unwrap();
    assert_eq!(ModelBank::new(configs).err(), Some(ConfigError::Decimation));
}

fn banks(initial_state: InitialState) -> (ModelBank<f64, 5, 5>, ModelBank<f32, 5, 5>) {
    let cell = LoadCellModel {
        counts_per_gram: 73.0,
        ..model(3)
    };
    let c64 = cell
        .bank_configs::<f64, 5, 5>(0.9, 1.1, 4, initial_state)
        .unwrap()
        .map(|c| c.with_valid_range(-1e5, 1e5));
    let c32 = cell
        .bank_configs::<f32, 5, 5>(0.9, 1.1, 4, initial_state)
        .unwrap()
        .map(|c| c.with_valid_range(-1e5, 1e5));
    (ModelBank::new(c64).unwrap(), ModelBank::new(c32).unwrap())
}

#[test]
fn bad_samples_latch_with_their_reason_until_reset() {
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        for (bad, reason) in [
            (f64::NAN, InvalidReason::NonFiniteInput),
            (f64::INFINITY, InvalidReason::NonFiniteInput),
            (f64::NEG_INFINITY, InvalidReason::NonFiniteInput),
            (2e5, InvalidReason::OutOfRange),
        ] {
            let (mut b64, mut b32) = banks(initial_state);
            for k in 0..200 {
                b64.push(10.0 * k as f64);
                b32.push(10.0 * k as f32);
            }
            assert_eq!(b64.push(bad).state, State::Invalid(reason));
            assert_eq!(b32.push(bad as f32).state, State::Invalid(reason));
            // Latched: good samples do not bring a number back.
            for _ in 0..50 {
                let (r64, r32) = (b64.push(1.0), b32.push(1.0));
                assert_eq!((r64.state, r64.estimate), (State::Invalid(reason), None));
                assert_eq!((r32.state, r32.estimate), (State::Invalid(reason), None));
            }
            b64.reset();
            let first = b64.push(0.0);
            assert_eq!((first.samples, first.state), (1, State::WarmingUp));
        }
        let (mut b64, _) = banks(initial_state);
        b64.push(0.0);
        assert_eq!(
            b64.push_missing().state,
            State::Invalid(InvalidReason::MissingSample)
        );
        assert!(b64.push(1.0).is_invalid());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn never_panics_and_every_valid_reading_is_finite(
        samples in prop::collection::vec(
            prop_oneof![
                8 => -2e4f64..2e4,
                1 => Just(f64::NAN),
                1 => prop_oneof![Just(1e30), Just(-1e30), Just(0.0), Just(f64::MIN_POSITIVE)],
            ],
            1..400,
        ),
        at_rest in any::<bool>(),
        missing_at in prop::option::of(0usize..400),
    ) {
        let initial_state = if at_rest { InitialState::AtRest } else { InitialState::Unknown };
        let cell = LoadCellModel { counts_per_gram: 73.0, ..model(3) };
        let c64 = cell.bank_configs::<f64, 5, 5>(0.9, 1.1, 4, initial_state).unwrap();
        let c32 = cell.bank_configs::<f32, 5, 5>(0.9, 1.1, 4, initial_state).unwrap();
        let (mut b64, mut b32) = (ModelBank::new(c64).unwrap(), ModelBank::new(c32).unwrap());
        for (k, &s) in samples.iter().enumerate() {
            let (r64, r32) = if missing_at == Some(k) {
                (b64.push_missing(), b32.push_missing())
            } else {
                (b64.push(s), b32.push(s as f32))
            };
            prop_assert_eq!(r64.samples as usize, k + 1);
            prop_assert!(well_formed(&r64), "{:?}", r64);
            prop_assert!(well_formed(&r32), "{:?}", r32);
        }
    }
}
