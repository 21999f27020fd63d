//! The model-based estimator with a model identified at calibration, with host-sim's
//! simulator as the truth (the goals: "≤ 1.2× CRLB at 100 ms at the calibration mass; bias
//! ≤ 0.05% from 0.3× to 3× the calibration mass; f32 within 10% of f64").
//!
//! Every study here calibrates first: [`estimator_core::sensor::identify`] finds `(f_n, ζ)` and the
//! gain from three simulated drops of the calibration mass (seeds apart from the Monte Carlo
//! seeds), and the estimators then run on that identified model, never on the true one.
//!
//! The figures (1,000-run studies over decimations, initial states, masses and onset
//! errors; memory; operations per sample) are printed by
//! `cargo test --release -p host-sim --test model_based -- --ignored --nocapture`.
// Index loops mirror the matrix algebra, as in the crates.
#![allow(clippy::needless_range_loop)]

use std::cell::Cell;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use estimator_core::sensor::AdcSource;
use estimator_core::sensor::{identify, Identified, IdentifyConfig, IdentifyError, LoadCellModel};
use estimator_core::{
    Estimator, InitialState, InvalidReason, ModelBank, ModelConfig, ModelEstimator, Real, State,
};
use host_sim::crlb;
use host_sim::simulated::{REFERENCE_STEP_G, SNR_WINDOW_SAMPLES};
use host_sim::{
    run_seed, white_noise_for_snr, Disturbances, LoadEvent, Script, SensorChain, SimulatedAdc,
};
use nalgebra::{DMatrix, DVector};

/// The readout: the reading after sample index 400 (100 ms at 4 kHz), as in host-sim's
/// Monte Carlo summary.
const READOUT: usize = 400;
/// Drops recorded at calibration, and their length (1.5 s).
const CALIBRATION_DROPS: u64 = 3;
const CALIBRATION_SAMPLES: usize = 6000;
/// The masses of the load-dependence goal (bias ≤ 0.05% from 0.3× to 3× the calibration
/// mass), as multiples of the calibration mass.
const MASS_FACTORS: [f64; 5] = [0.3, 0.5, 1.0, 2.0, 3.0];
/// The bank the firmware should run: 33 candidates 2% apart over frequency ratios
/// 0.68–1.30, which covers 0.3×–3× the calibration mass on the reference cell (ratios
/// 1.265–0.695) with one candidate to spare at each end (a best fit on the edge is flagged).
const BANK: usize = 33;
const RATIO_MIN: f64 = 0.68;
const RATIO_MAX: f64 = 1.30;
const DECIMATION: u16 = 8;
/// Seed of the Monte Carlo runs (the calibration drops use other seeds).
const SEED: u64 = 7;

fn chain() -> SensorChain {
    SensorChain::reference()
}

/// White noise of the reference scene: 50 dB (thesis eq. 4.39) for the 138.32 g step,
/// 0.445 g. The same at every mass: the noise is the electronics', not the load's.
fn sigma_g() -> f64 {
    white_noise_for_snr(&chain(), REFERENCE_STEP_G, 50.0, SNR_WINDOW_SAMPLES)
}

/// The true model of the reference chain carrying `mass_g`.
fn true_model(mass_g: f64) -> LoadCellModel {
    let chain = chain();
    LoadCellModel {
        natural_frequency_hz: chain.cell.natural_frequency_rad_s(mass_g)
            / (2.0 * std::f64::consts::PI),
        damping_ratio: chain.cell.damping_ratio(mass_g),
        filter_order: 3,
        filter_cutoff_hz: chain.filter_cutoff_hz,
        counts_per_gram: chain.counts_per_gram(),
        sample_rate_hz: chain.sample_rate_hz,
    }
}

/// Codes (tare removed) from the onset of a drop of `mass_g` onto the empty, settled pan,
/// white noise `white_g` plus the INA114's noise (none at all when `white_g` is 0: the
/// noise-free case), quantised to whole codes. The reference 16-bit ADC would clip the
/// overshoot at 3× the calibration mass; these codes are not clipped, so the estimator's own
/// bias is measured there (clipping is tested apart: `saturated_overshoot_is_flagged_not_estimated`).
/// Where nothing clips they equal the ADC's codes.
fn record(mass_g: f64, white_g: f64, seed: u64, samples: usize) -> Vec<f64> {
    let zero = chain().zero_code();
    let mut adc = adc(mass_g, white_g, seed, samples);
    (0..samples)
        .map(|_| adc.read_analog().round() - zero)
        .collect()
}

fn adc(mass_g: f64, white_g: f64, seed: u64, samples: usize) -> SimulatedAdc<2> {
    let chain = chain();
    let mut script = Script::new(samples as f64 / chain.sample_rate_hz + 1.0);
    script.push(LoadEvent::step(0.0, mass_g)).unwrap();
    let mut disturbances = Disturbances::white(white_g);
    disturbances.amplifier_noise = white_g > 0.0;
    SimulatedAdc::new(chain, script, disturbances, seed)
}

/// The three 1.5 s drops of the calibration mass at 50 dB that calibration records (seeds
/// apart from the Monte Carlo seeds).
fn calibration_drops() -> Vec<Vec<f64>> {
    (0..CALIBRATION_DROPS)
        .map(|i| {
            record(
                REFERENCE_STEP_G,
                sigma_g(),
                run_seed(1000, i),
                CALIBRATION_SAMPLES,
            )
        })
        .collect()
}

/// Calibrate: identify the model from three 1.5 s drops of the calibration mass at 50 dB.
fn calibrate() -> Identified {
    let drops = calibration_drops();
    let slices: Vec<&[f64]> = drops.iter().map(|d| d.as_slice()).collect();
    identify::<f64, 5>(&slices, &identify_config()).expect("the reference drops identify")
}

fn identify_config() -> IdentifyConfig {
    let chain = chain();
    IdentifyConfig::new(
        REFERENCE_STEP_G,
        3,
        chain.filter_cutoff_hz,
        chain.sample_rate_hz,
    )
}

/// Host-sim's bound at the readout (known model, onset and tare): white noise plus
/// quantisation (LSB²/12) plus the INA114's noise coloured by the filter, as the Monte Carlo
/// command computes it.
fn crlb_g(mass_g: f64) -> f64 {
    let chain = chain();
    let gain = chain.counts_per_gram();
    let white = sigma_g() * gain;
    let samples = READOUT + 1;
    let unit_step = crlb::unit_step_response(&chain, mass_g, samples);
    let mut autocovariance: Vec<f64> = crlb::amplifier_autocovariance_g2(&chain, samples)
        .iter()
        .map(|r| r * gain * gain)
        .collect();
    autocovariance[0] += white * white + 1.0 / 12.0;
    crlb::coloured_known_tare(&unit_step, gain, &autocovariance)[READOUT].sqrt()
}

/// The bound of the problem the `Unknown` variant solves (initial state and step unknown,
/// known model and tare, white noise and quantisation): σ²·[(ΦᵀΦ)⁻¹]_uu with rows
/// `[C·A^k, s(k)]`, from the simulator's own discretisation.
fn unknown_state_crlb_g(mass_g: f64) -> f64 {
    let chain = chain();
    let gain = chain.counts_per_gram();
    let sensor = chain.discretise(mass_g);
    let mut phi = DMatrix::<f64>::zeros(READOUT + 1, 6);
    let mut row = [0.0; 5];
    row[host_sim::sensor::OUTPUT_STATE] = gain;
    let mut step = 0.0;
    for k in 0..=READOUT {
        for j in 0..5 {
            phi[(k, j)] = row[j];
        }
        phi[(k, 5)] = step;
        step += (0..5).map(|j| row[j] * sensor.input[j][0]).sum::<f64>();
        let mut next = [0.0; 5];
        for j in 0..5 {
            next[j] = (0..5).map(|i| row[i] * sensor.transition[i][j]).sum();
        }
        row = next;
    }
    let variance = (sigma_g() * gain).powi(2) + 1.0 / 12.0;
    let information = phi.transpose() * &phi;
    (variance * information.try_inverse().expect("identifiable")[(5, 5)]).sqrt()
}

/// Error statistics at the readout over `runs` Monte Carlo runs.
#[derive(Clone, Copy, Debug)]
struct Errors {
    bias_g: f64,
    rms_g: f64,
    /// Runs whose reading at the readout was valid.
    valid: u64,
    runs: u64,
}

/// Run `make()` on `runs` noisy drops of `mass_g` (the first `late` samples after the onset
/// skipped; or, for `late < 0`, `−late` samples of the empty pan pushed first).
fn monte_carlo<T: Real, E: Estimator<T>>(
    make: &dyn Fn() -> E,
    mass_g: f64,
    runs: u64,
    late: i64,
) -> Errors {
    let (mut sum, mut sum_sq, mut valid) = (0.0, 0.0, 0);
    let skip = late.max(0) as usize;
    let early = (-late).max(0) as usize;
    for run in 0..runs {
        let data = record(mass_g, sigma_g(), run_seed(SEED, run), READOUT + 1 + skip);
        let mut estimator = make();
        for _ in 0..early {
            estimator.push(T::ZERO);
        }
        let mut last = None;
        for &y in &data[skip..data.len() - early] {
            last = estimator.push(T::from_f64(y)).estimate;
        }
        if let Some(estimate) = last {
            let error = estimate.to_f64() - mass_g;
            sum += error;
            sum_sq += error * error;
            valid += 1;
        }
    }
    let n = valid.max(1) as f64;
    Errors {
        bias_g: sum / n,
        rms_g: (sum_sq / n).sqrt(),
        valid,
        runs,
    }
}

/// [`monte_carlo`] at the calibration mass, read on time.
fn at_calibration_mass<T: Real, E: Estimator<T>>(make: &dyn Fn() -> E, runs: u64) -> Errors {
    monte_carlo(make, REFERENCE_STEP_G, runs, 0)
}

fn single<T: Real>(
    model: &LoadCellModel,
    initial_state: InitialState,
    decimation: u16,
) -> ModelEstimator<T, 5> {
    let config = ModelConfig::new(model.sensor_model::<T, 5>().unwrap())
        .with_decimation(decimation)
        .with_initial_state(initial_state);
    ModelEstimator::new(config).unwrap()
}

fn bank<T: Real>(
    model: &LoadCellModel,
    initial_state: InitialState,
    decimation: u16,
) -> ModelBank<T, 5, BANK> {
    let configs = model
        .bank_configs::<T, 5, BANK>(RATIO_MIN, RATIO_MAX, decimation, initial_state)
        .unwrap();
    ModelBank::new(configs).unwrap()
}

/// The noise-free estimate at the readout.
fn noise_free<E: Estimator<f64>>(estimator: &mut E, mass_g: f64) -> Option<f64> {
    let mut last = None;
    for y in record(mass_g, 0.0, 0, READOUT + 1) {
        last = estimator.push(y).estimate;
    }
    last
}

#[test]
fn the_parametric_model_is_the_simulators_sensor_at_every_load() {
    // The physical law applied to the calibration model gives, at each mass, the simulator's
    // own discretisation (different state coordinates, same transfer function): step
    // responses agree to 1e-9 of the step (both exact ZOH; the rest is rounding).
    let calibration = true_model(REFERENCE_STEP_G);
    let chain = chain();
    let platform_g = chain.cell.platform_mass_kg * 1e3;
    for factor in MASS_FACTORS {
        let mass_g = factor * REFERENCE_STEP_G;
        let ratio = LoadCellModel::frequency_ratio_for_mass(REFERENCE_STEP_G, platform_g, mass_g);
        let model = calibration
            .with_frequency_ratio(ratio)
            .sensor_model::<f64, 5>()
            .unwrap();
        let truth = record(mass_g, 0.0, 0, 4000);
        let mut state = [0.0; 5];
        for (k, want) in host_sim::StepResponse::new(&chain, mass_g)
            .take(4000)
            .enumerate()
        {
            let got: f64 = (0..5).map(|i| model.c[i] * state[i]).sum::<f64>() * mass_g;
            let want = want * chain.counts_per_gram();
            assert!(
                (got - want).abs() < 1e-9 * mass_g * chain.counts_per_gram(),
                "×{factor}, k = {k}: {got} vs {want}"
            );
            // The noise-free record is this response from the onset, rounded to codes (plus
            // the zero code's fraction, which the rounding moves by less than one code).
            assert!((truth[k] - want).abs() <= 1.0, "×{factor}, k = {k}");
            let mut next = model.b;
            for r in 0..5 {
                for c in 0..5 {
                    next[r] += model.a[r][c] * state[c];
                }
            }
            state = next;
        }
    }
}

/// Standard deviations of (f_n, ζ, gain) by the Cramér–Rao bound for `drops` drops of the
/// calibration mass, each with its own unknown initial state and step (what identification
/// estimates), white noise and quantisation. Jacobian by central differences of the model.
fn identification_bound(drops: usize) -> [f64; 3] {
    let truth = true_model(REFERENCE_STEP_G);
    let n = CALIBRATION_SAMPLES;
    // The output for a 1 g step from rest, and the rows C·A^k, of a model.
    let response = |model: &LoadCellModel| -> (Vec<f64>, Vec<[f64; 5]>) {
        let m = model.sensor_model::<f64, 5>().unwrap();
        let (mut state, mut row) = ([0.0; 5], m.c);
        let (mut y, mut rows) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for _ in 0..n {
            y.push((0..5).map(|i| m.c[i] * state[i]).sum::<f64>());
            rows.push(row);
            let mut next = m.b;
            let mut next_row = [0.0; 5];
            for r in 0..5 {
                for c in 0..5 {
                    next[r] += m.a[r][c] * state[c];
                    next_row[c] += row[r] * m.a[r][c];
                }
            }
            state = next;
            row = next_row;
        }
        (y, rows)
    };
    // d(counts)/d(parameter) for the drop of the calibration mass.
    let derivative = |change: &dyn Fn(f64) -> LoadCellModel, step: f64| -> Vec<f64> {
        let (up, _) = response(&change(step));
        let (down, _) = response(&change(-step));
        up.iter()
            .zip(&down)
            .map(|(a, b)| (a - b) / (2.0 * step) * REFERENCE_STEP_G)
            .collect()
    };
    let d_frequency = derivative(
        &|h| LoadCellModel {
            natural_frequency_hz: truth.natural_frequency_hz + h,
            ..truth
        },
        1e-5,
    );
    let d_damping = derivative(
        &|h| LoadCellModel {
            damping_ratio: truth.damping_ratio + h,
            ..truth
        },
        1e-7,
    );
    // With unit gain: y = C·A^k·x₀ + s(k)·u with the step u in counts (u = gain × mass).
    let (unit_step, rows) = response(&LoadCellModel {
        counts_per_gram: 1.0,
        ..truth
    });
    let unknowns = 2 + 6 * drops;
    let mut jacobian = DMatrix::<f64>::zeros(n * drops, unknowns);
    for d in 0..drops {
        for k in 0..n {
            let r = d * n + k;
            jacobian[(r, 0)] = d_frequency[k];
            jacobian[(r, 1)] = d_damping[k];
            for j in 0..5 {
                jacobian[(r, 2 + 6 * d + j)] = rows[k][j];
            }
            jacobian[(r, 2 + 6 * d + 5)] = unit_step[k];
        }
    }
    // White noise and quantisation; the INA114's noise (0.0068 g against 0.445 g) adds 0.02%
    // to the variance and is left out.
    let variance = (sigma_g() * truth.counts_per_gram).powi(2) + 1.0 / 12.0;
    let covariance = (jacobian.transpose() * &jacobian)
        .try_inverse()
        .expect("identifiable")
        * variance;
    // The gain is the mean step over the drops divided by the mass.
    let mut mean = DVector::<f64>::zeros(unknowns);
    for d in 0..drops {
        mean[2 + 6 * d + 5] = 1.0 / (drops as f64 * REFERENCE_STEP_G);
    }
    let gain_variance = (mean.transpose() * &covariance * &mean)[(0, 0)];
    [
        covariance[(0, 0)].sqrt(),
        covariance[(1, 1)].sqrt(),
        gain_variance.sqrt(),
    ]
}

#[test]
fn identification_recovers_the_reference_cell_within_its_bound() {
    let truth = true_model(REFERENCE_STEP_G);
    let identified = calibrate();
    let [sd_f, sd_zeta, sd_gain] = identification_bound(CALIBRATION_DROPS as usize);
    let model = identified.model;
    let errors = [
        model.natural_frequency_hz - truth.natural_frequency_hz,
        model.damping_ratio - truth.damping_ratio,
        model.counts_per_gram - truth.counts_per_gram,
    ];
    println!(
        "identified f_n {:.6} Hz (error {:+.2e}, bound {sd_f:.2e}), ζ {:.6} ({:+.2e}, {sd_zeta:.2e}), gain {:.5} counts/g ({:+.2e}, {sd_gain:.2e}); noise {:.2} counts; {} fits",
        model.natural_frequency_hz, errors[0], model.damping_ratio, errors[1], model.counts_per_gram, errors[2], identified.noise_rms, identified.evaluations
    );
    // The bound is for full-rate data; the fit uses block means of 8, which lose a little
    // (less than 15% in RMS for the step, estimator-core's model_based test): allow 1.2×
    // the bound, and 5 of those standard deviations (a 6e-7 chance for an efficient
    // estimator). The golden-section tolerance (1e-7 relative) is far below these.
    for (error, sd, name) in [
        (errors[0], sd_f, "frequency"),
        (errors[1], sd_zeta, "damping ratio"),
        (errors[2], sd_gain, "gain"),
    ] {
        assert!(
            error.abs() < 5.0 * 1.2 * sd,
            "{name}: error {error:e}, bound {sd:e}"
        );
    }
    // The implied noise per sample: white (32.6 counts) plus quantisation and the
    // amplifier's noise, from 2,250 block residuals: relative standard error 1.5%.
    let white = sigma_g() * truth.counts_per_gram;
    assert!(
        (identified.noise_rms / white - 1.0).abs() < 0.06,
        "{} vs {white}",
        identified.noise_rms
    );
}

#[test]
fn identification_refuses_flat_short_and_non_finite_drops() {
    let config = identify_config();
    // Flat: the pan stays empty (noise only).
    let flat = record(0.0, sigma_g(), 1, CALIBRATION_SAMPLES);
    assert_eq!(
        identify::<f64, 5>(&[&flat], &config),
        Err(IdentifyError::Flat { drop: 0 })
    );
    // Exactly constant data too (no noise at all).
    let zeros = vec![0.0f32; CALIBRATION_SAMPLES];
    assert_eq!(
        identify::<f32, 5>(&[&zeros], &config),
        Err(IdentifyError::Flat { drop: 0 })
    );
    let good = record(REFERENCE_STEP_G, sigma_g(), 2, CALIBRATION_SAMPLES);
    // Short: 20 ms, less than two periods of the lowest frequency searched (5 Hz).
    assert!(matches!(
        identify::<f64, 5>(&[&good, &good[..80]], &config),
        Err(IdentifyError::TooShort {
            drop: 1,
            samples: 80,
            ..
        })
    ));
    let mut broken = good.clone();
    broken[1234] = f64::NAN;
    assert_eq!(
        identify::<f64, 5>(&[&broken], &config),
        Err(IdentifyError::NonFinite {
            drop: 0,
            sample: 1234
        })
    );
    broken[1234] = f64::INFINITY;
    assert!(matches!(
        identify::<f64, 5>(&[&broken], &config),
        Err(IdentifyError::NonFinite { .. })
    ));
    assert_eq!(identify::<f64, 5>(&[], &config), Err(IdentifyError::NoData));
    // A search range that excludes the truth (25 Hz): the best fit sits on its edge.
    let mut narrow = config;
    narrow.frequency_min_hz = 30.0;
    assert_eq!(
        identify::<f64, 5>(&[&good], &narrow),
        Err(IdentifyError::AtRangeEdge)
    );
    // Impossible configurations.
    let mut bad = config;
    bad.mass_g = 0.0;
    assert!(matches!(
        identify::<f64, 5>(&[&good], &bad),
        Err(IdentifyError::Config(_))
    ));
    assert!(matches!(
        identify::<f64, 4>(&[&good], &config),
        Err(IdentifyError::Config(_))
    ));
    let mut bad = config;
    bad.damping_max = f64::NAN;
    assert!(matches!(
        identify::<f64, 5>(&[&good], &bad),
        Err(IdentifyError::Config(_))
    ));
}

#[test]
fn identified_model_at_the_calibration_mass_against_the_bound() {
    // 1,000 runs: an RMS over 1,000 runs has a relative standard error of 1/√2000 = 2.2%.
    let model = calibrate().model;
    let bound = crlb_g(REFERENCE_STEP_G);
    let unknown_bound = unknown_state_crlb_g(REFERENCE_STEP_G);
    let runs = 1000;
    let at_rest = at_calibration_mass(
        &|| single::<f64>(&model, InitialState::AtRest, DECIMATION),
        runs,
    );
    let unknown = at_calibration_mass(
        &|| bank::<f64>(&model, InitialState::Unknown, DECIMATION),
        runs,
    );
    println!(
        "calibration mass, 100 ms, {runs} runs: host-sim CRLB {bound:.4} g; [x0; u] bound {unknown_bound:.4} g ({:.3}×); \
         at rest (single model) RMS {:.4} g = {:.3}× CRLB; initial state estimated (bank of {BANK}) RMS {:.4} g = {:.3}× CRLB, {:.3}× its own bound",
        unknown_bound / bound,
        at_rest.rms_g,
        at_rest.rms_g / bound,
        unknown.rms_g,
        unknown.rms_g / bound,
        unknown.rms_g / unknown_bound
    );
    assert_eq!(at_rest.valid, runs);
    assert_eq!(unknown.valid, runs);
    // The goal (≤ 1.2× the CRLB at 100 ms), for the variant that knows the onset and that the pan was at rest.
    assert!(at_rest.rms_g / bound <= 1.2, "{:.3}", at_rest.rms_g / bound);
    // The variant that estimates the initial state solves a harder problem: its bound is
    // 1.16× host-sim's. It must meet its own bound within the Monte Carlo error (+3σ = 7%)
    // and the identification's share (the measured gap to the true model is < 1%): 1.08.
    assert!(
        unknown.rms_g / unknown_bound <= 1.08,
        "{:.3}",
        unknown.rms_g / unknown_bound
    );
}

#[test]
fn the_physical_bank_is_unbiased_from_0_3_to_3_times_the_calibration_mass() {
    let model = calibrate().model;
    let runs = 1000;
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        for factor in MASS_FACTORS {
            let mass_g = factor * REFERENCE_STEP_G;
            let clean = noise_free(&mut bank::<f64>(&model, initial_state, DECIMATION), mass_g)
                .expect("valid at 100 ms");
            let calibrated_only = noise_free(
                &mut single::<f64>(&model, initial_state, DECIMATION),
                mass_g,
            )
            .unwrap();
            let errors = monte_carlo(
                &|| bank::<f64>(&model, initial_state, DECIMATION),
                mass_g,
                runs,
                0,
            );
            let clean_relative = (clean - mass_g) / mass_g;
            let relative_bias = errors.bias_g / mass_g;
            println!(
                "{initial_state:?} ×{factor}: noise-free {clean_relative:+.2e}, calibrated model alone {:+.2e}; {runs} runs: bias {relative_bias:+.2e} (±{:.1e}), RMS {:.4} g, {} valid",
                (calibrated_only - mass_g) / mass_g,
                errors.rms_g / mass_g / (runs as f64).sqrt(),
                errors.rms_g,
                errors.valid
            );
            // The goal: 0.05%. The Monte Carlo bias carries a standard error of
            // RMS/√1000 ≤ 0.025 g/31.6 = 2e-5 of the smallest mass: far inside the goal.
            assert!(
                clean_relative.abs() <= 5e-4,
                "×{factor}: {clean_relative:e}"
            );
            assert!(relative_bias.abs() <= 5e-4, "×{factor}: {relative_bias:e}");
            // Every run inside the range gets a valid reading at 100 ms.
            assert_eq!(errors.valid, runs, "×{factor}");
        }
    }
}

#[test]
fn off_calibration_the_calibrated_model_alone_is_biased() {
    // Why the bank: the single calibrated model is more than 0.05% off at 0.5× and 2×.
    let model = true_model(REFERENCE_STEP_G);
    for factor in [0.5, 2.0] {
        let mass_g = factor * REFERENCE_STEP_G;
        let estimate = noise_free(
            &mut single::<f64>(&model, InitialState::Unknown, DECIMATION),
            mass_g,
        )
        .unwrap();
        assert!(
            ((estimate - mass_g) / mass_g).abs() > 5e-4,
            "×{factor}: {estimate}"
        );
    }
}

#[test]
fn outside_the_bank_is_flagged() {
    // 0.05× and 8× the calibration mass ring at frequency ratios 1.51 and 0.44: beyond the
    // bank. Noise-free, the best fit sits on the edge and the reading says so.
    let model = true_model(REFERENCE_STEP_G);
    for factor in [0.05, 8.0] {
        let mut estimator = bank::<f64>(&model, InitialState::Unknown, DECIMATION);
        let mut last = None;
        for y in record(factor * REFERENCE_STEP_G, 0.0, 0, READOUT + 1) {
            last = Some(estimator.push(y));
        }
        let last = last.unwrap();
        assert_eq!(
            last.state,
            State::Invalid(InvalidReason::OutsideModelRange),
            "×{factor}"
        );
        assert_eq!(last.estimate, None);
    }
}

#[test]
fn saturated_overshoot_is_flagged_not_estimated() {
    // At 3× the calibration mass the reference 16-bit ADC clips the first overshoot. With
    // the converter's range as the valid range (codes 1..=max−1, tare removed), the bank
    // says so instead of fitting clipped data.
    let chain = chain();
    let model = true_model(REFERENCE_STEP_G);
    let zero = chain.zero_code();
    let (low, high) = (1.0 - zero, f64::from(chain.adc.max_code() - 1) - zero);
    let configs = model
        .bank_configs::<f64, 5, BANK>(RATIO_MIN, RATIO_MAX, DECIMATION, InitialState::Unknown)
        .unwrap()
        .map(|c| c.with_valid_range(low, high));
    let mut estimator = ModelBank::new(configs).unwrap();
    let mut adc = adc(3.0 * REFERENCE_STEP_G, sigma_g(), 1, READOUT + 1);
    let mut last = None;
    for _ in 0..=READOUT {
        last = Some(estimator.push(f64::from(adc.read().unwrap()) - zero));
    }
    let last = last.unwrap();
    assert_eq!(last.state, State::Invalid(InvalidReason::OutOfRange));
    assert_eq!(last.estimate, None);
}

#[test]
fn an_onset_error_biases_the_at_rest_variant_only() {
    // Noise-free, one sample late or early: estimating the initial state absorbs it (the
    // shifted response is the same model from another initial state); assuming rest
    // turns it into a bias of about 0.2% per sample (the step response's rise over one
    // sample, averaged over the fit), ten times the 0.0145% of the bound.
    let model = true_model(REFERENCE_STEP_G);
    let clean = record(REFERENCE_STEP_G, 0.0, 0, READOUT + 2);
    for (name, data, pad) in [
        ("late", &clean[1..], 0usize),
        ("early", &clean[..READOUT], 1usize),
    ] {
        for (initial_state, must_be_small) in
            [(InitialState::Unknown, true), (InitialState::AtRest, false)]
        {
            let mut estimator = single::<f64>(&model, initial_state, DECIMATION);
            for _ in 0..pad {
                estimator.push(0.0);
            }
            let mut last = None;
            for &y in data {
                last = estimator.push(y).estimate;
            }
            let relative = (last.unwrap() - REFERENCE_STEP_G) / REFERENCE_STEP_G;
            println!("one sample {name}, {initial_state:?}: {relative:+.2e}");
            if must_be_small {
                // Quantisation of the noise-free codes alone: well below 1e-5.
                assert!(relative.abs() < 2e-5, "{name}: {relative:e}");
            } else {
                assert!(relative.abs() > 1e-3, "{name}: {relative:e}");
            }
        }
    }
}

#[test]
fn f32_matches_f64_on_the_same_data() {
    // The same 300 runs in both precisions, the f32 estimator fed the f64 samples rounded.
    // Claim (the goal): the f32 RMS is within 10% of the f64 RMS. We also ask that the
    // RMS of the f32 − f64 difference stays below a tenth of the statistical RMS error
    // (adds < 0.5% to the error budget); the measured difference is about 0.2% of it.
    let model = calibrate().model;
    let runs = 300;
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        let (mut sq64, mut sq32, mut sq_diff) = (0.0, 0.0, 0.0);
        for run in 0..runs {
            let data = record(
                REFERENCE_STEP_G,
                sigma_g(),
                run_seed(SEED, run),
                READOUT + 1,
            );
            let mut e64 = bank::<f64>(&model, initial_state, DECIMATION);
            let mut e32 = bank::<f32>(&model, initial_state, DECIMATION);
            let (mut last64, mut last32) = (None, None);
            for &y in &data {
                last64 = e64.push(y).estimate;
                last32 = e32.push(y as f32).estimate;
            }
            let (m64, m32) = (last64.unwrap(), f64::from(last32.unwrap()));
            sq64 += (m64 - REFERENCE_STEP_G).powi(2);
            sq32 += (m32 - REFERENCE_STEP_G).powi(2);
            sq_diff += (m32 - m64).powi(2);
        }
        let n = runs as f64;
        let (rms64, rms32, diff) = ((sq64 / n).sqrt(), (sq32 / n).sqrt(), (sq_diff / n).sqrt());
        println!(
            "{initial_state:?}: RMS f64 {rms64:.5} g, f32 {rms32:.5} g, difference {diff:.2e} g"
        );
        assert!((rms32 / rms64 - 1.0).abs() < 0.1);
        assert!(diff < 0.1 * rms64, "{diff:e} vs {rms64:e}");
    }
}

#[test]
fn identification_in_f32_agrees_with_f64() {
    // The firmware may identify in f32. On the same drops the parameters agree within the
    // f64 bound (one standard deviation), so f32 adds less than the noise does.
    let drops = calibration_drops();
    let drops32: Vec<Vec<f32>> = drops
        .iter()
        .map(|d| d.iter().map(|&v| v as f32).collect())
        .collect();
    let slices: Vec<&[f32]> = drops32.iter().map(|d| d.as_slice()).collect();
    let m32 = identify::<f32, 5>(&slices, &identify_config())
        .unwrap()
        .model;
    let m64 = calibrate().model;
    let [sd_f, sd_zeta, sd_gain] = identification_bound(CALIBRATION_DROPS as usize);
    println!(
        "f32 − f64 identification: f {:+.2e} Hz, ζ {:+.2e}, gain {:+.2e}",
        m32.natural_frequency_hz - m64.natural_frequency_hz,
        m32.damping_ratio - m64.damping_ratio,
        m32.counts_per_gram - m64.counts_per_gram
    );
    assert!((m32.natural_frequency_hz - m64.natural_frequency_hz).abs() < sd_f);
    assert!((m32.damping_ratio - m64.damping_ratio).abs() < sd_zeta);
    assert!((m32.counts_per_gram - m64.counts_per_gram).abs() < sd_gain);
}

// ---------------------------------------------------------------------------------------
// Figures: `cargo test --release -p host-sim --test model_based -- --ignored --nocapture`

thread_local! {
    static MULTIPLIES: Cell<u64> = const { Cell::new(0) };
    static DIVIDES: Cell<u64> = const { Cell::new(0) };
    static ADDS: Cell<u64> = const { Cell::new(0) };
}

/// An `f32` that counts its arithmetic (per thread): the operation count of an estimator
/// as the Cortex-M4F would execute it (comparisons and moves not counted).
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
struct Counted(f32);

fn tick(counter: &'static std::thread::LocalKey<Cell<u64>>) {
    counter.with(|c| c.set(c.get() + 1));
}

macro_rules! counted_op {
    ($trait:ident, $method:ident, $op:tt, $counter:ident, $assign:ident, $assign_method:ident) => {
        impl $trait for Counted {
            type Output = Counted;
            fn $method(self, other: Counted) -> Counted {
                tick(&$counter);
                Counted(self.0 $op other.0)
            }
        }
        impl $assign for Counted {
            fn $assign_method(&mut self, other: Counted) {
                *self = *self $op other;
            }
        }
    };
}
counted_op!(Add, add, +, ADDS, AddAssign, add_assign);
counted_op!(Sub, sub, -, ADDS, SubAssign, sub_assign);
counted_op!(Mul, mul, *, MULTIPLIES, MulAssign, mul_assign);

impl Div for Counted {
    type Output = Counted;
    fn div(self, other: Counted) -> Counted {
        tick(&DIVIDES);
        Counted(self.0 / other.0)
    }
}

impl Neg for Counted {
    type Output = Counted;
    fn neg(self) -> Counted {
        Counted(-self.0)
    }
}

impl Real for Counted {
    const ZERO: Self = Counted(0.0);
    const ONE: Self = Counted(1.0);
    const EPSILON: Self = Counted(f32::EPSILON);
    const NAME: &'static str = "counted f32";
    fn from_f64(value: f64) -> Self {
        Counted(value as f32)
    }
    fn to_f64(self) -> f64 {
        f64::from(self.0)
    }
    fn from_i32(value: i32) -> Self {
        Counted(value as f32)
    }
    fn from_u32(value: u32) -> Self {
        Counted(value as f32)
    }
    fn abs(self) -> Self {
        Counted(self.0.abs())
    }
    fn is_finite(self) -> bool {
        self.0.is_finite()
    }
    fn sqrt(self) -> Self {
        Counted(self.0.sqrt())
    }
}

/// Operations per raw sample (multiplies, divides, adds) over one 1.5 s drop.
fn operations_per_sample<E: Estimator<Counted>>(mut estimator: E) -> [f64; 3] {
    let data = record(REFERENCE_STEP_G, sigma_g(), 1, CALIBRATION_SAMPLES);
    let counters = [&MULTIPLIES, &DIVIDES, &ADDS];
    for c in counters {
        c.with(|c| c.set(0));
    }
    for &y in &data {
        estimator.push(Counted(y as f32));
    }
    counters.map(|c| c.with(|c| c.get()) as f64 / data.len() as f64)
}

#[test]
#[ignore = "figures: about 20 s in release; run with --ignored --nocapture"]
fn figures() {
    let runs = 1000;
    let start = std::time::Instant::now();
    let identified = calibrate();
    let calibration_time = start.elapsed();
    let truth = true_model(REFERENCE_STEP_G);
    let model = identified.model;
    let [sd_f, sd_zeta, sd_gain] = identification_bound(CALIBRATION_DROPS as usize);
    println!("## Identification ({CALIBRATION_DROPS} drops × 1.5 s of 138.32 g at 50 dB)");
    println!(
        "f_n {:.6} Hz (true {:.6}, error {:+.2e} = {:+.2} bound sd), ζ {:.6} (true {:.6}, {:+.2} sd), gain {:.5} (true {:.5}, {:+.2} sd); noise {:.2} counts/sample; {} fits, {:.0} ms on the host (f64)",
        model.natural_frequency_hz, truth.natural_frequency_hz,
        model.natural_frequency_hz - truth.natural_frequency_hz,
        (model.natural_frequency_hz - truth.natural_frequency_hz) / sd_f,
        model.damping_ratio, truth.damping_ratio,
        (model.damping_ratio - truth.damping_ratio) / sd_zeta,
        model.counts_per_gram, truth.counts_per_gram,
        (model.counts_per_gram - truth.counts_per_gram) / sd_gain,
        identified.noise_rms, identified.evaluations, calibration_time.as_secs_f64() * 1e3
    );
    // Spread of repeated calibrations against the bound.
    let calibrations = 20;
    let (mut sq_f, mut sq_z, mut sq_g) = (0.0, 0.0, 0.0);
    for c in 0..calibrations {
        let drops: Vec<Vec<f64>> = (0..CALIBRATION_DROPS)
            .map(|i| {
                record(
                    REFERENCE_STEP_G,
                    sigma_g(),
                    run_seed(2000 + c, i),
                    CALIBRATION_SAMPLES,
                )
            })
            .collect();
        let slices: Vec<&[f64]> = drops.iter().map(|d| d.as_slice()).collect();
        let m = identify::<f64, 5>(&slices, &identify_config())
            .unwrap()
            .model;
        sq_f += (m.natural_frequency_hz - truth.natural_frequency_hz).powi(2);
        sq_z += (m.damping_ratio - truth.damping_ratio).powi(2);
        sq_g += (m.counts_per_gram - truth.counts_per_gram).powi(2);
    }
    let n = calibrations as f64;
    println!(
        "{calibrations} calibrations: RMS error / bound: f_n {:.2}, ζ {:.2}, gain {:.2} (an RMS over 20 has ±16% standard error)",
        (sq_f / n).sqrt() / sd_f, (sq_z / n).sqrt() / sd_zeta, (sq_g / n).sqrt() / sd_gain
    );

    println!("\n## RMS at 100 ms, calibration mass, {runs} runs (identified model)");
    let bound = crlb_g(REFERENCE_STEP_G);
    let unknown_bound = unknown_state_crlb_g(REFERENCE_STEP_G);
    println!("host-sim CRLB (known model, onset, tare) {bound:.5} g; bound with the initial state unknown {unknown_bound:.5} g = {:.3}×", unknown_bound / bound);
    println!("initial state, D, single model: bias g, RMS g, ×CRLB | bank of {BANK}: bias g, RMS g, ×CRLB");
    for initial_state in [InitialState::AtRest, InitialState::Unknown] {
        for decimation in [1u16, 4, 8, 16] {
            let one =
                at_calibration_mass(&|| single::<f64>(&model, initial_state, decimation), runs);
            let many =
                at_calibration_mass(&|| bank::<f64>(&model, initial_state, decimation), runs);
            println!(
                "{initial_state:?}, D = {decimation}: {:+.5} {:.5} {:.3} | {:+.5} {:.5} {:.3}",
                one.bias_g,
                one.rms_g,
                one.rms_g / bound,
                many.bias_g,
                many.rms_g,
                many.rms_g / bound
            );
        }
    }
    let with_truth = at_calibration_mass(
        &|| single::<f64>(&truth, InitialState::Unknown, DECIMATION),
        runs,
    );
    let with_truth_at_rest = at_calibration_mass(
        &|| single::<f64>(&truth, InitialState::AtRest, DECIMATION),
        runs,
    );
    println!(
        "true model, D = {DECIMATION}: AtRest RMS {:.5} g ({:.3}×), Unknown RMS {:.5} g ({:.3}×)",
        with_truth_at_rest.rms_g,
        with_truth_at_rest.rms_g / bound,
        with_truth.rms_g,
        with_truth.rms_g / bound
    );

    println!("\n## Where the load falls between the bank's candidates (calibration mass, {runs} runs; the grid shifted by a fraction of its 2% step)");
    let step = (RATIO_MAX / RATIO_MIN).powf(1.0 / (BANK - 1) as f64);
    for initial_state in [InitialState::AtRest, InitialState::Unknown] {
        let mut line = format!("{initial_state:?}:");
        for fraction in [0.0, 0.25, 0.5, 0.75] {
            let shift = step.powf(fraction);
            let configs = model
                .bank_configs::<f64, 5, BANK>(
                    RATIO_MIN * shift,
                    RATIO_MAX * shift,
                    DECIMATION,
                    initial_state,
                )
                .unwrap();
            let e = at_calibration_mass(&|| ModelBank::new(configs).unwrap(), runs);
            line += &format!(
                " shifted {fraction} step: bias {:+.5} RMS {:.5} ({:.3}×);",
                e.bias_g,
                e.rms_g,
                e.rms_g / bound
            );
        }
        println!("{line}");
    }

    println!(
        "\n## Onset error (single identified model, D = {DECIMATION}, 300 runs): bias g, RMS g"
    );
    for initial_state in [InitialState::AtRest, InitialState::Unknown] {
        for late in [-4i64, -2, -1, 0, 1, 2, 4] {
            let e = monte_carlo(
                &|| single::<f64>(&model, initial_state, DECIMATION),
                REFERENCE_STEP_G,
                300,
                late,
            );
            println!("{initial_state:?}, onset {late:+} samples (+: estimator starts late): {:+.4} {:.4}", e.bias_g, e.rms_g);
        }
    }

    println!("\n## Bank of {BANK} (ratios {RATIO_MIN}–{RATIO_MAX}), D = {DECIMATION}, across masses, {runs} runs; σ = {:.3} g at every mass", sigma_g());
    println!("initial state, ×mass: noise-free relative error | bias relative, RMS g, ×CRLB(mass), valid runs");
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        for factor in MASS_FACTORS {
            let mass_g = factor * REFERENCE_STEP_G;
            let clean = noise_free(&mut bank::<f64>(&model, initial_state, DECIMATION), mass_g)
                .unwrap_or(f64::NAN);
            let e = monte_carlo(
                &|| bank::<f64>(&model, initial_state, DECIMATION),
                mass_g,
                runs,
                0,
            );
            println!(
                "{initial_state:?} ×{factor}: {:+.2e} | {:+.2e} {:.5} {:.3} {}/{}",
                (clean - mass_g) / mass_g,
                e.bias_g / mass_g,
                e.rms_g,
                e.rms_g / crlb_g(mass_g),
                e.valid,
                e.runs
            );
        }
    }

    println!("\n## f32 against f64, {runs} runs, calibration mass, bank, D = {DECIMATION}");
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        let e64 = at_calibration_mass(&|| bank::<f64>(&model, initial_state, DECIMATION), runs);
        let e32 = at_calibration_mass(&|| bank::<f32>(&model, initial_state, DECIMATION), runs);
        println!(
            "{initial_state:?}: RMS f64 {:.5} g, f32 {:.5} g ({:+.2}%)",
            e64.rms_g,
            e32.rms_g,
            (e32.rms_g / e64.rms_g - 1.0) * 100.0
        );
    }

    println!("\n## Memory and operations (f32, S = 5)");
    println!(
        "size_of: ModelEstimator {} B, ModelBank<{BANK}> {} B (the firmware has 128 KiB of RAM)",
        std::mem::size_of::<ModelEstimator<f32, 5>>(),
        std::mem::size_of::<ModelBank<f32, 5, BANK>>()
    );
    let counted = |initial_state| {
        let configs = model
            .bank_configs::<Counted, 5, BANK>(RATIO_MIN, RATIO_MAX, DECIMATION, initial_state)
            .unwrap();
        ModelBank::new(configs).unwrap()
    };
    for initial_state in [InitialState::Unknown, InitialState::AtRest] {
        let [m, d, a] = operations_per_sample(counted(initial_state));
        println!(
            "bank of {BANK}, {initial_state:?}, D = {DECIMATION}: per raw sample {m:.0} multiplies, {d:.1} divides, {a:.0} adds/subtracts ({:.2e} multiplies/s at 4 kHz)",
            m * 4000.0
        );
        let [m, d, a] = operations_per_sample(
            ModelEstimator::new(
                ModelConfig::new(model.sensor_model::<Counted, 5>().unwrap())
                    .with_decimation(DECIMATION)
                    .with_initial_state(initial_state),
            )
            .unwrap(),
        );
        println!("single model, {initial_state:?}: {m:.1} multiplies, {d:.2} divides, {a:.1} adds per raw sample");
    }
    println!("\n(total {:.1} s)", start.elapsed().as_secs_f64());
}
