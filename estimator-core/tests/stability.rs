//! Regression tests for the failure modes the stability map found (host-sim `study
//! stability`, host-sim/README.md "Stability map"). Each reproduces its failure at small
//! size, asserts that the core now flags it (or no longer fails), and that no silent wrong
//! number is reported instead. (The ADC clipping of heavy drops is tested in
//! host-sim/tests/stability.rs, where the simulator supplies the rails.)

mod support;

use estimator_core::sensor::LoadCellModel;
use estimator_core::weighing::{
    LoadCoverage, OnsetConfig, Prediction, RegionError, WeighingConfig, WeighingMethod,
};
use estimator_core::{
    Baseline, BaselineConfig, BaselineMode, BiasCompensatedConfig, BiasCompensatedStepEstimator,
    CovarianceStepEstimator, Estimator, InvalidReason, IvConfig, IvStepEstimator, ModelBank,
    ModelConfig, ModelEstimator, NoiseMeter, NoiseReference, Real, SensorModel, State, StepConfig,
    StepEstimator, MIN_IDENTIFIABILITY,
};
use nalgebra::DMatrix;
use support::*;

const MASS_G: f64 = 138.32;
/// Counts per gram of the reference chain (host-sim: 73.2547).
const COUNTS_PER_GRAM: f64 = 73.25;

/// The load cell's drop in counts, `samples` long, then steady.
fn drop_counts(samples: usize) -> Vec<f64> {
    let sensor = load_cell();
    let g = sensor.static_gain();
    let transient = sensor.step_response(MASS_G, samples.min(8000));
    (0..samples)
        .map(|k| transient.get(k).copied().unwrap_or(g * MASS_G) / g * COUNTS_PER_GRAM)
        .collect()
}

/// White noise at `snr_db` relative to the steady level (support::add_noise).
fn noisy(clean: &[f64], snr_db: f64, seed: u64) -> (Vec<f64>, f64) {
    add_noise(clean, MASS_G * COUNTS_PER_GRAM, snr_db, seed)
}

/// Positive definite by an f64 Cholesky of the leading `size × size` block (nalgebra).
fn cholesky_positive<T: Copy + Into<f64>, const P: usize>(
    matrix: &[[T; P]; P],
    size: usize,
) -> bool {
    let m = DMatrix::<f64>::from_fn(size, size, |i, j| matrix[i][j].into());
    m.cholesky().is_some()
}

#[test]
fn the_covariance_form_in_f32_flags_its_loss_of_definiteness() {
    // The map: in f32, Ψ of the covariance form stopped being positive definite within the
    // drop at every SNR and order tried; its readings went on, up to 10⁴× the CRLB off.
    // Here: n = 7, D = 16 at 70 dB on the load cell, 8 seeds of 0.3 s. An f64 Cholesky of Ψ
    // (nalgebra) is the oracle, consulted after every regression row. The core must flag
    // `LostDefiniteness` no later than the oracle sees it, and report nothing after.
    let order = 7;
    let decimation = 16;
    let clean = drop_counts(1200);
    let mut reproduced = 0;
    for seed in 0..8 {
        let (y, _) = noisy(&clean, 70.0, 100 + seed);
        let config32 = StepConfig::new(order, COUNTS_PER_GRAM as f32).with_decimation(decimation);
        let config64 = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
        let mut f32_form = CovarianceStepEstimator::<f32, 8, 9>::new(config32, 1e-6).unwrap();
        let mut f64_form = CovarianceStepEstimator::<f64, 8, 9>::new(config64, 1e-6).unwrap();
        let (mut oracle_lost, mut flagged) = (None, None);
        for (k, &sample) in y.iter().enumerate() {
            let reading = f32_form.push(sample as f32);
            let reference = f64_form.push(sample);
            assert_ne!(
                reference.state,
                State::Invalid(InvalidReason::LostDefiniteness),
                "seed {seed} k={k}: the f64 form must keep Ψ definite here"
            );
            if (k + 1) % usize::from(decimation) == 0 {
                assert!(cholesky_positive(f64_form.inverse_information(), order + 1));
                if oracle_lost.is_none()
                    && !cholesky_positive(f32_form.inverse_information(), order + 1)
                {
                    oracle_lost = Some(k);
                }
            }
            if reading.state == State::Invalid(InvalidReason::LostDefiniteness) {
                flagged.get_or_insert(k);
            }
            if flagged.is_some() {
                // Latched: no silent number after the flag.
                assert_eq!(reading.estimate, None, "seed {seed} k={k}");
                assert_eq!(
                    reading.state,
                    State::Invalid(InvalidReason::LostDefiniteness)
                );
            }
        }
        if let Some(lost) = oracle_lost {
            reproduced += 1;
            let flagged = flagged.expect("the core flags what the oracle sees");
            assert!(
                flagged <= lost,
                "seed {seed}: oracle at {lost}, flag at {flagged}"
            );
        }
        println!(
            "seed {seed}: oracle lost definiteness at {oracle_lost:?}, core flagged at {flagged:?}"
        );
    }
    assert!(reproduced > 0, "the f32 covariance form kept Ψ definite");
}

#[test]
fn barely_determined_readings_are_flagged_not_reported() {
    // The map: right where the fit becomes determined (n + 1 rows), a reading's noise gain
    // can be orders of magnitude above a mean's (at n = 7, D = 16, 50 dB the first reading
    // was 0.9 g RMS and up to 12 g off over 200 runs, against 0.039 g one row later).
    // Readings at identifiability ≤ MIN_IDENTIFIABILITY are now IllConditioned. Here, 200
    // seeds: the flags must occur (the failure reproduces), the least-squares solution they
    // withhold must be far off (batch solve, support), and every valid reading must be
    // within 6 of its own standard deviations, σ_D/√(N·identifiability), of the truth.
    let (order, decimation) = (7usize, 16u16);
    let clean = drop_counts((2 * order + 5) * usize::from(decimation));
    let d = usize::from(decimation);
    let (mut flagged, mut worst_withheld, mut worst_valid_sigmas) = (0, 0.0f64, 0.0f64);
    for seed in 0..200 {
        let (y, sigma_counts) = noisy(&clean, 50.0, 7000 + seed);
        let sigma_block_g = sigma_counts / COUNTS_PER_GRAM / (decimation as f64).sqrt();
        let config = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
        let mut estimator = StepEstimator::<f64, 8>::new(config).unwrap();
        let block_means: Vec<f64> = y
            .chunks(d)
            .map(|block| block.iter().sum::<f64>() / d as f64 / COUNTS_PER_GRAM)
            .collect();
        for (k, &sample) in y.iter().enumerate() {
            let reading = estimator.push(sample);
            if (k + 1) % d != 0 {
                continue;
            }
            let blocks = (k + 1) / d;
            let rows = blocks.saturating_sub(order + 1) + 1;
            match (reading.state, reading.estimate) {
                (State::Invalid(InvalidReason::IllConditioned), _) => {
                    assert!(estimator.identifiability() <= MIN_IDENTIFIABILITY);
                    flagged += 1;
                    let (k_mat, rhs) = hankel_system(&block_means, order, 1.0, blocks);
                    let withheld = batch_solve(&k_mat, &rhs).theta[order];
                    worst_withheld = worst_withheld.max((withheld - MASS_G).abs());
                }
                (State::Estimating, Some(estimate)) => {
                    let identifiability = estimator.identifiability();
                    assert!(identifiability > MIN_IDENTIFIABILITY);
                    let sigma = sigma_block_g / (rows as f64 * identifiability).sqrt();
                    worst_valid_sigmas = worst_valid_sigmas.max((estimate - MASS_G).abs() / sigma);
                }
                (State::WarmingUp, None) => assert!(blocks < 2 * order + 1),
                other => panic!("seed {seed} k={k}: {other:?}"),
            }
        }
    }
    println!(
        "{flagged} flagged readings; the LS solution they withheld was up to {worst_withheld:.2} g off; valid readings within {worst_valid_sigmas:.2} of their standard deviations"
    );
    assert!(flagged > 0, "no barely determined reading was flagged");
    // 1 g is 25× the RMS one row after determination (0.039 g): a number worth withholding.
    assert!(worst_withheld > 1.0, "{worst_withheld}");
    assert!(worst_valid_sigmas < 6.0, "{worst_valid_sigmas}");
}

/// The load cell with its resonance scaled by `ratio` and its damping ratio scaled by `ratio`
/// too (stiffness and damper fixed, the moving mass changed: the physics of another load).
fn load_cell_at(ratio: f64) -> SensorModel<f64, 5> {
    let mut sensor = load_cell();
    sensor.a[(1, 0)] *= ratio * ratio;
    sensor.a[(1, 1)] *= ratio * ratio;
    sensor.b[1] *= ratio * ratio;
    let (ad, bd) = sensor.discretise();
    SensorModel {
        a: core::array::from_fn(|i| core::array::from_fn(|j| ad[(i, j)])),
        b: core::array::from_fn(|i| bd[i]),
        c: core::array::from_fn(|i| sensor.c[i]),
    }
}

#[test]
fn a_model_bank_flags_a_resonance_outside_its_span() {
    // The map: with the load's resonance 1.4× and 1.5× the calibrated one, beyond a ±30%
    // bank, the bank reported its edge candidate's estimate, 74× and 31× the CRLB off at
    // 100 ms (50 dB). Now a best fit at the edge is `OutsideModelRange`. Here a bank of 17
    // over 0.85–1.15 (1.9% apart, as dense as model_based.rs's), noise-free: at 1.3× and 0.75× every reading after 0.25 s is flagged,
    // and the edge candidate alone (what the bank used to report) is biased by more than
    // the bank's own ±0.05% inside its span; at 1.0× no reading after 0.25 s is flagged.
    const K: usize = 17;
    let ratios: [f64; K] =
        core::array::from_fn(|i| 0.85 * (1.15f64 / 0.85).powf(i as f64 / (K - 1) as f64));
    let config = |model| ModelConfig::new(model).with_decimation(8);
    let configs = ratios.map(|r| config(load_cell_at(r)));
    for (truth, edge) in [(1.3, K - 1), (0.75, 0), (1.0, usize::MAX)] {
        let model = load_cell_at(truth);
        let y = model_drop(&model, 2000);
        let mut bank = ModelBank::new(configs).unwrap();
        for (k, &sample) in y.iter().enumerate() {
            let reading = bank.push(sample);
            if k < 1000 {
                continue;
            }
            if edge == usize::MAX {
                assert_eq!(reading.state, State::Estimating, "inside the span, k={k}");
                let error = (reading.estimate.unwrap() - MASS_G).abs() / MASS_G;
                assert!(error < 5e-4, "inside the span: {error:e}");
            } else {
                assert_eq!(
                    (reading.state, reading.estimate),
                    (State::Invalid(InvalidReason::OutsideModelRange), None),
                    "resonance ×{truth}, k={k}"
                );
            }
        }
        if edge != usize::MAX {
            assert_eq!(bank.best(), edge);
            let mut alone = ModelEstimator::new(configs[edge]).unwrap();
            let last = y.iter().map(|&s| alone.push(s)).last().unwrap();
            let bias = (last.estimate.unwrap() - MASS_G).abs() / MASS_G;
            println!("resonance ×{truth}: edge candidate alone off by {bias:.2e} (relative)");
            assert!(
                bias > 5e-4,
                "×{truth}: the edge candidate is not biased ({bias:e})"
            );
        }
    }
}

#[test]
fn the_step_level_does_not_stall_in_f32_over_long_runs() {
    // The map (slice D, before the fix): with forgetting, the f32 step level stalled,
    // because a value of 138 g moves in steps of 1.5e-5 g and the updates of 1/N_eff of a
    // deviation fell below that: at λ = 0.9999, 10⁵–10⁶ samples, RMS error / steady-state
    // bound 15 (D = 1) and 5–12 (D = 16) in f32 against 1.0–2.6 in f64, for the step, iv
    // and bc estimators alike. The estimators now keep the step level relative to an origin
    // that follows the estimate. Here: 4·10⁵ samples of a steady load at 50 dB, λ = 0.9999;
    // over the second half the RMS difference f32 − f64 must be below a tenth of the f64
    // RMS error (single precision adds < 0.5% to the error), for all three.
    let samples = 400_000;
    let (y, _) = noisy(&drop_counts(samples), 50.0, 42);
    let lambda = 0.9999;
    let step = |d: u16| {
        (
            StepConfig::new(7, COUNTS_PER_GRAM)
                .with_decimation(d)
                .with_forgetting(lambda),
            StepConfig::new(7, COUNTS_PER_GRAM as f32)
                .with_decimation(d)
                .with_forgetting(lambda as f32),
        )
    };
    let (s64, s32) = step(1);
    let (i64c, i32c) = step(16);
    type Pair = (
        &'static str,
        Box<dyn Estimator<f64>>,
        Box<dyn Estimator<f32>>,
    );
    let cases: Vec<Pair> = vec![
        (
            "step D=1",
            Box::new(StepEstimator::<f64, 8>::new(s64).unwrap()),
            Box::new(StepEstimator::<f32, 8>::new(s32).unwrap()),
        ),
        (
            "iv D=16",
            Box::new(IvStepEstimator::<f64, 8>::new(IvConfig::new(i64c)).unwrap()),
            Box::new(IvStepEstimator::<f32, 8>::new(IvConfig::new(i32c)).unwrap()),
        ),
        (
            "bc D=16",
            Box::new(
                BiasCompensatedStepEstimator::<f64, 8>::new(BiasCompensatedConfig::new(i64c, 1e-3))
                    .unwrap(),
            ),
            Box::new(
                BiasCompensatedStepEstimator::<f32, 8>::new(BiasCompensatedConfig::new(i32c, 1e-3))
                    .unwrap(),
            ),
        ),
    ];
    for (name, mut e64, mut e32) in cases {
        let (mut error2, mut difference2, mut count) = (0.0, 0.0, 0.0);
        for (k, &sample) in y.iter().enumerate() {
            let (a, b) = (e64.push(sample), e32.push(sample as f32));
            if k >= samples / 2 {
                if let (Some(a), Some(b)) = (a.estimate, b.estimate) {
                    error2 += (a - MASS_G).powi(2);
                    difference2 += (f64::from(b) - a).powi(2);
                    count += 1.0;
                }
            }
        }
        assert!(
            count > 0.9 * (samples / 2) as f64,
            "{name}: {count} readings"
        );
        let (error, difference) = ((error2 / count).sqrt(), (difference2 / count).sqrt());
        println!("{name}: f64 RMS error {error:.2e} g, RMS |f32 − f64| {difference:.2e} g");
        assert!(
            difference < 0.1 * error,
            "{name}: {difference:e} vs {error:e}"
        );
    }
}

#[test]
fn the_settled_average_in_f32_keeps_the_precision_of_its_deviations() {
    // The map: the f32 settled average, summing the load itself, was 11% worse than f64 at
    // 70 dB (1.5 s). It now sums deviations from its first stable mean. Here: 20 s of a
    // steady load at 70 dB: the f32 reading must equal the f64 one to within a tenth of the
    // statistical error of the f64 average, σ/√N.
    let samples = 80_000;
    let steady = vec![MASS_G * COUNTS_PER_GRAM; samples];
    let (y, sigma_counts) = noisy(&steady, 70.0, 5);
    let mut a = Baseline::<f64, 10>::new(BaselineConfig {
        mode: BaselineMode::SettledAverage,
        gain: COUNTS_PER_GRAM,
        block: 80,
        stable_band: 0.5,
        noise_reference: None,
    })
    .unwrap();
    let mut b = Baseline::<f32, 10>::new(BaselineConfig {
        mode: BaselineMode::SettledAverage,
        gain: COUNTS_PER_GRAM as f32,
        block: 80,
        stable_band: 0.5,
        noise_reference: None,
    })
    .unwrap();
    let (mut last64, mut last32) = (None, None);
    for &sample in &y {
        last64 = a.push(sample).estimate;
        last32 = b.push(sample as f32).estimate;
    }
    let (last64, last32) = (last64.unwrap(), f64::from(last32.unwrap()));
    let statistical = sigma_counts / COUNTS_PER_GRAM / (samples as f64).sqrt();
    println!("f64 {last64:.7} g, f32 {last32:.7} g, statistical error {statistical:.2e} g");
    assert!((last32 - last64).abs() < 0.1 * statistical);
}

// ---------------------------------------------------------------------------------------
// The consistency check against the noise metered at tare (`InvalidReason::ModelMismatch`,
// `NoiseReference`) and the valid region (`WeighingConfig::check_region`): the silent modes
// of the map. host-sim/tests/stability.rs holds the valid region's false-alarm test (with
// vibration and mains) and the modes that stay silent.

/// The noise of an empty pan at `snr_db` (the drop's σ), metered by `NoiseMeter` at `D`
/// over 1,200 samples (0.3 s, as host-sim's studies and a tare meter it).
fn tare_reference<T: Real>(snr_db: f64, decimation: u16, seed: u64) -> NoiseReference<T> {
    let (empty, _) = noisy(&vec![0.0; 1200], snr_db, seed);
    let mut meter = NoiseMeter::<f64>::new(decimation).unwrap();
    for sample in empty {
        meter.push(sample).unwrap();
    }
    NoiseReference::new(
        T::from_f64(meter.noise_variance().unwrap()),
        meter.differences(),
    )
}

fn is_mismatch<T>(reading: &estimator_core::Reading<T>) -> bool {
    reading.state == State::Invalid(InvalidReason::ModelMismatch)
}

#[test]
fn an_order_below_the_sensors_is_flagged_model_mismatch() {
    // The map: n = 1 from 30 dB and n = 2 from 50 dB at D = 16 gave valid readings 21–4,000×
    // the Cramér–Rao bound, silently. With the tare's noise as the reference, at 60 dB, 8
    // seeds of 1.5 s: every reading from 100 ms to the end is ModelMismatch, in f64 and in
    // f32 alike; the unchecked estimator on the same data is more than 10× off the error
    // of n = 7 (the map's valid order), which the check leaves alone.
    let clean = drop_counts(6000);
    let (snr_db, decimation, at_100_ms) = (60.0, 16u16, 400);
    let mut squared = [0.0f64; 3];
    for seed in 0..8u64 {
        let (y, _) = noisy(&clean, snr_db, 300 + seed);
        for (slot, order) in [1usize, 2, 7].into_iter().enumerate() {
            let config = |reference| {
                StepConfig::new(order, COUNTS_PER_GRAM)
                    .with_decimation(decimation)
                    .with_noise_reference(reference)
            };
            let mut checked =
                StepEstimator::<f64, 8>::new(config(tare_reference(snr_db, decimation, seed)))
                    .unwrap();
            let config32 = StepConfig::new(order, COUNTS_PER_GRAM as f32)
                .with_decimation(decimation)
                .with_noise_reference(tare_reference::<f32>(snr_db, decimation, seed));
            let mut single = StepEstimator::<f32, 8>::new(config32).unwrap();
            let mut unchecked = StepEstimator::<f64, 8>::new(
                StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation),
            )
            .unwrap();
            for (k, &sample) in y.iter().enumerate() {
                let (a, b, c) = (
                    checked.push(sample),
                    single.push(sample as f32),
                    unchecked.push(sample),
                );
                assert_eq!(
                    is_mismatch(&a),
                    is_mismatch(&b),
                    "n={order} seed {seed} k={k}"
                );
                if k >= at_100_ms {
                    assert_eq!(
                        is_mismatch(&a),
                        order < 3,
                        "n={order} seed {seed} k={k}: {:?}, ratio {:?}",
                        a.state,
                        checked.residual_ratio()
                    );
                }
                if k == at_100_ms {
                    squared[slot] += (c.estimate.unwrap() - MASS_G).powi(2);
                }
            }
        }
    }
    let rms = squared.map(|s| (s / 8.0).sqrt());
    println!("RMS error at 100 ms, unchecked, n = 1, 2, 7: {rms:?} g");
    assert!(rms[0] > 10.0 * rms[2] && rms[1] > 10.0 * rms[2], "{rms:?}");
}

#[test]
fn a_single_model_off_its_load_is_flagged_model_mismatch() {
    // The map: one model at the calibration mass (K = 1) used at another load, ×0.9–×1.5 of
    // its resonance, from 50 dB: 13–10⁴× the bound, silent. Here the model of resonance
    // ratio 1 at D = 8, 50 dB, 8 seeds: on drops at 0.9 and 1.1 every reading from 100 ms on
    // is ModelMismatch; on its own load not one in 1.5 s (the check's design, white block
    // means: 8 runs × 750 readings × 1e-5 = 0.06 expected).
    let model = load_cell_at(1.0);
    let gain = model_gain(&model);
    for (truth, off) in [(0.9, true), (1.1, true), (1.0, false)] {
        let clean = model_drop(&load_cell_at(truth), 6000);
        for seed in 0..8u64 {
            let (y, _) = add_noise(&clean, gain * MASS_G, 50.0, 500 + seed);
            let (empty, _) = add_noise(&[0.0; 1200], gain * MASS_G, 50.0, 900 + seed);
            let mut meter = NoiseMeter::<f64>::new(8).unwrap();
            empty.iter().for_each(|&s| meter.push(s).unwrap());
            let reference =
                NoiseReference::new(meter.noise_variance().unwrap(), meter.differences());
            let config = ModelConfig::new(model)
                .with_decimation(8)
                .with_noise_reference(reference);
            let mut estimator = ModelEstimator::new(config).unwrap();
            for (k, &sample) in y.iter().enumerate() {
                let reading = estimator.push(sample);
                if off && k >= 400 {
                    assert!(is_mismatch(&reading), "×{truth} seed {seed} k={k}");
                }
                if !off {
                    assert!(!is_mismatch(&reading), "×{truth} seed {seed} k={k}");
                }
            }
            println!(
                "×{truth} seed {seed}: residual ratio at 1.5 s {:.3e}",
                estimator.residual_ratio().unwrap()
            );
        }
    }
}

/// The static gain of a discrete model: its settled response to `MASS_G`, per gram (the
/// slowest pole decays as e^(−ζω t), 0.21 s: 15 s are settled to 1e-31).
fn model_gain(model: &SensorModel<f64, 5>) -> f64 {
    *model_drop(model, 60_000).last().unwrap() / MASS_G
}

/// The noise-free response of `model` to a step of `MASS_G` from rest.
fn model_drop(model: &SensorModel<f64, 5>, samples: usize) -> Vec<f64> {
    let mut state = [0.0; 5];
    (0..samples)
        .map(|_| {
            let out: f64 = (0..5).map(|i| model.c[i] * state[i]).sum();
            let next: [f64; 5] = core::array::from_fn(|i| {
                (0..5).map(|j| model.a[i][j] * state[j]).sum::<f64>() + model.b[i] * MASS_G
            });
            state = next;
            out
        })
        .collect()
}

#[test]
fn a_full_rate_regression_is_refused_by_configuration() {
    // The map: at D = 1 least squares is biased by errors in variables, > 10× the bound
    // from 20 dB (215× at n = 7, 50 dB), silently. Its residuals stay near the noise once
    // the transient is over (host-sim's test of the silent modes: flagged at 100 ms, not at
    // 1.5 s), so a configuration with D below what the model's bandwidth needs is refused
    // instead. Here, 60 dB, 4 seeds: at 1.5 s the checked D = 1 reading is valid and its
    // error more than 10× that of D = 16 on the same data; `check_region` refuses D = 1
    // for the load cell (100 Hz filter, 4 kHz: D ≥ 8) and accepts D = 16.
    let clean = drop_counts(6000);
    let mut squared = [0.0f64; 2];
    for seed in 0..4u64 {
        let (y, _) = noisy(&clean, 60.0, 700 + seed);
        for (slot, decimation) in [1u16, 16].into_iter().enumerate() {
            let mut estimator = StepEstimator::<f64, 8>::new(
                StepConfig::new(7, COUNTS_PER_GRAM)
                    .with_decimation(decimation)
                    .with_noise_reference(tare_reference(60.0, decimation, seed)),
            )
            .unwrap();
            let last = y.iter().map(|&s| estimator.push(s)).last().unwrap();
            assert_eq!(
                last.state,
                State::Estimating,
                "D = {decimation} seed {seed}"
            );
            squared[slot] += (last.estimate.unwrap() - MASS_G).powi(2);
        }
    }
    let rms = squared.map(|s| (s / 4.0).sqrt());
    println!("RMS error at 1.5 s, D = 1 and D = 16, both checked: {rms:?} g");
    assert!(rms[0] > 10.0 * rms[1], "{rms:?}");

    let config = |decimation| {
        weighing_config(WeighingMethod::Step {
            order: 7,
            decimation,
            forgetting: 1.0,
        })
    };
    assert_eq!(
        config(1).check_region(),
        Err(RegionError::Decimation {
            decimation: 1,
            minimum: 8
        })
    );
    assert_eq!(config(16).check_region(), Ok(()));
    let low_order = weighing_config(WeighingMethod::Step {
        order: 2,
        decimation: 16,
        forgetting: 1.0,
    });
    assert_eq!(
        low_order.check_region(),
        Err(RegionError::Order {
            order: 2,
            minimum: 3
        })
    );
}

/// A weighing configuration of `method` for the load cell of `support` (4 kHz, 25 Hz,
/// 100 Hz 3rd-order Butterworth), the calibration mass its only load.
fn weighing_config(method: WeighingMethod) -> WeighingConfig {
    let prediction = Prediction::default();
    WeighingConfig {
        method,
        counts_per_gram: COUNTS_PER_GRAM,
        zero_counts: 0.0,
        noise_variance_counts2: 1.0,
        raw_noise_variance_counts2: 1.0,
        onset: OnsetConfig::new(4000.0),
        detection_lag_samples: 0.0,
        model: LoadCellModel {
            natural_frequency_hz: 25.0,
            damping_ratio: 0.03,
            filter_order: 3,
            filter_cutoff_hz: 100.0,
            counts_per_gram: COUNTS_PER_GRAM,
            sample_rate_hz: 4000.0,
        },
        identified_counts_per_gram: COUNTS_PER_GRAM,
        calibration_mass_g: MASS_G,
        readout_s: 0.1,
        target_relative: 0.001,
        prediction,
        recorded_drops: 0,
        recorded_worst_error_g: 0.0,
        capacity_g: estimator_core::weighing::WeighingConfig::REFERENCE_CAPACITY_G,
        scale_interval_g: estimator_core::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        final_target_g: estimator_core::weighing::WeighingConfig::FINAL_TARGET_E
            * estimator_core::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        loads: LoadCoverage::calibration_mass_only(MASS_G, prediction),
    }
}

#[test]
fn a_baseline_that_calls_a_ringing_pan_stable_is_flagged() {
    // The map: the settled average's 0.5 g band at 80 dB is 300 block-mean standard
    // deviations, so it settles while the pan still rings and keeps the ring in its average
    // (13–14× the bound at 1.5 s), silently. With the tare's noise as the reference the block
    // means must also be consistent with a constant load. 80 dB, 6 seeds of 4 s: at 1.5 s
    // the unchecked average is valid and the checked one is not (ModelMismatch, or not yet
    // stable); by 4 s the ring is below the noise and the checked average reads, closer to
    // the truth than the unchecked one.
    let clean = drop_counts(16_000);
    let config = |reference| BaselineConfig {
        mode: BaselineMode::SettledAverage,
        gain: COUNTS_PER_GRAM,
        block: 80,
        stable_band: 0.5,
        noise_reference: reference,
    };
    let (mut checked_error2, mut unchecked_error2) = (0.0, 0.0);
    for seed in 0..6u64 {
        let (y, _) = noisy(&clean, 80.0, 1100 + seed);
        let mut checked =
            Baseline::<f64, 10>::new(config(Some(tare_reference(80.0, 80, seed)))).unwrap();
        let mut unchecked = Baseline::<f64, 10>::new(config(None)).unwrap();
        let mut flagged = false;
        for (k, &sample) in y.iter().enumerate() {
            let (a, b) = (checked.push(sample), unchecked.push(sample));
            flagged |= is_mismatch(&a);
            if k == 5999 {
                assert!(b.estimate.is_some(), "seed {seed}: unchecked not stable");
                assert_eq!(a.estimate, None, "seed {seed}: checked valid at 1.5 s");
            }
            if k + 1 == y.len() {
                checked_error2 += (a.estimate.expect("stable by 4 s") - MASS_G).powi(2);
                unchecked_error2 += (b.estimate.unwrap() - MASS_G).powi(2);
            }
        }
        assert!(flagged, "seed {seed}: never flagged");
    }
    let (checked, unchecked) = (
        (checked_error2 / 6.0).sqrt(),
        (unchecked_error2 / 6.0).sqrt(),
    );
    println!("settled average at 4 s, 80 dB: checked {checked:.2e} g, unchecked {unchecked:.2e} g");
    assert!(checked < unchecked, "{checked} vs {unchecked}");
}
