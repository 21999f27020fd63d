//! Conveyor weighing (thesis ch. 6): a 100 g item slides onto a 2nd-order scale whose
//! dynamics change with the load (eq. 6.1–6.2), u(t) = 10 g + 1000 g/s · t over 0.1 s,
//! sampled every 0.1 ms. Goal: slope error below 1% at the end of the ramp at 40 dB (the
//! thesis reports < 2%).
//!
//! The readings' standard uncertainty: ±2u covers 95 % on an LTI sensor (where the model
//! holds), the conveyor's model error is flagged rather than given a `u`, f32 states the
//! f64 `u`, and no `u` comes without a valid estimate. The wider study:
//! `cargo test --release -p estimator-core --test ramp -- --ignored --nocapture
//! ramp_uncertainty_study`.

mod support;

use estimator_core::{Estimator, NoiseReference, RampConfig, RampEstimator, StepConfig};
use support::{stated_u_around_a_bad_sample, u_f32_against_f64, Gaussian};

const PLATFORM_KG: f64 = 0.015;
const DAMPING_NS_PER_M: f64 = 5.5;
const STIFFNESS_N_PER_M: f64 = 10250.0;
const GRAVITY: f64 = 9.81;
const SAMPLE_PERIOD_S: f64 = 1e-4;
const SLOPE_G_PER_S: f64 = 1000.0;
const INTERCEPT_G: f64 = 10.0;

/// Eq. 6.2 integrated with RK4 at 1/20 of the sample period; output in metres.
fn ramp_response(samples: usize) -> Vec<f64> {
    let mass_kg = |t: f64| (INTERCEPT_G + SLOPE_G_PER_S * t) * 1e-3;
    let slope_kg_per_s = SLOPE_G_PER_S * 1e-3;
    let deriv = |t: f64, x: [f64; 2]| {
        let total = mass_kg(t) + PLATFORM_KG;
        [
            x[1],
            (-STIFFNESS_N_PER_M * x[0] - (DAMPING_NS_PER_M + slope_kg_per_s) * x[1]) / total
                + GRAVITY * mass_kg(t) / total,
        ]
    };
    let steps = 20;
    let h = SAMPLE_PERIOD_S / steps as f64;
    let mut x = [0.0, 0.0];
    let mut y = Vec::with_capacity(samples);
    for k in 0..samples {
        y.push(x[0]);
        for s in 0..steps {
            let t = k as f64 * SAMPLE_PERIOD_S + s as f64 * h;
            let k1 = deriv(t, x);
            let k2 = deriv(
                t + h / 2.0,
                [x[0] + h / 2.0 * k1[0], x[1] + h / 2.0 * k1[1]],
            );
            let k3 = deriv(
                t + h / 2.0,
                [x[0] + h / 2.0 * k2[0], x[1] + h / 2.0 * k2[1]],
            );
            let k4 = deriv(t + h, [x[0] + h * k3[0], x[1] + h * k3[1]]);
            for i in 0..2 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    y
}

fn slope_error(
    order: usize,
    forgetting: f64,
    decimation: u16,
    snr_db: f64,
    runs: u64,
) -> (f64, f64) {
    let samples = 1000;
    let clean = ramp_response(samples);
    let gain_m_per_g = GRAVITY * 1e-3 / STIFFNESS_N_PER_M;
    let rms = (clean.iter().map(|v| v * v).sum::<f64>() / samples as f64).sqrt();
    let sigma = rms / 10f64.powf(snr_db / 20.0);
    let (mut sum_sq, mut sum) = (0.0, 0.0);
    for run in 0..runs {
        let mut noise = Gaussian::new(run);
        let regression = StepConfig::new(order, gain_m_per_g as f32)
            .with_forgetting(forgetting as f32)
            .with_decimation(decimation);
        let config = RampConfig {
            regression,
            sample_period_s: SAMPLE_PERIOD_S as f32,
            lag_s: 0.0,
        };
        let mut estimator = RampEstimator::<f32, 8>::new(config).unwrap();
        for &y in &clean {
            let reading = estimator.push((y + sigma * noise.sample()) as f32);
            assert_eq!(
                reading.estimate.is_some(),
                reading.state == estimator_core::State::Estimating
            );
            assert!(reading.estimate.is_none_or(f32::is_finite));
        }
        let (slope, _) = estimator.line().expect("line determined");
        let err = (slope as f64 - SLOPE_G_PER_S) / SLOPE_G_PER_S;
        sum_sq += err * err;
        sum += err;
    }
    ((sum / runs as f64), (sum_sq / runs as f64).sqrt())
}

#[test]
fn slope_of_a_conveyor_ramp_within_one_percent_at_40_db() {
    // The sensor's true order, growing window, full rate: no more model than the scene needs.
    let (bias, rms) = slope_error(2, 1.0, 1, 40.0, 200);
    println!(
        "conveyor ramp, n = 2, λ = 1, D = 1, 40 dB, 200 runs: slope bias {bias:+.4}, RMS {rms:.4}"
    );
    assert!(rms < 0.01, "RMS slope error {rms:.4}");
}

#[test]
fn noise_free_ramp_on_an_lti_sensor_gives_the_exact_line() {
    // 2nd-order LTI sensor (fixed mass), exact ZOH response to u(k) = a·k·ts + b computed by
    // superposition of the discretised step response (a ramp is piecewise linear, so use a
    // fine inner step and compare to the tolerance that rounding allows).
    let sensor = support::mass_spring_damper();
    let (ad, bd) = sensor.discretise();
    let ts = sensor.sample_time_s;
    let (a, b) = (0.3, 2.0);
    // Ramp input held constant over each sample: u(k) = a·k·ts + b (ZOH), so the sampled
    // response is exactly that of an LTI system driven by a sampled ramp.
    let mut x = nalgebra::DVector::<f64>::zeros(2);
    let mut y = Vec::new();
    for k in 0..80 {
        y.push(sensor.c.dot(&x));
        x = &ad * &x + &bd * (a * k as f64 * ts + b);
    }
    let g = sensor.static_gain();
    let config = RampConfig {
        regression: StepConfig::new(2, g),
        sample_period_s: ts,
        lag_s: 0.0,
    };
    let mut estimator = RampEstimator::<f64, 4>::new(config).unwrap();
    for &sample in &y {
        estimator.push(sample);
    }
    let (slope, _) = estimator.line().unwrap();
    let err = (slope - a).abs() / a;
    println!("noise-free LTI ramp: slope relative error {err:.2e}");
    assert!(err < 1e-9, "{err:.3e}");
}

// ---------------------------------------------------------------------------------------
// The readings' standard uncertainty
// ---------------------------------------------------------------------------------------

/// Ramp estimator with lag sums for orders up to 7.
type Ramp<T> = RampEstimator<T, 8, 8>;

/// `(runs with a u, runs with |error| ≤ 2u, Σ (error/u)²)` at one readout.
#[derive(Clone, Copy, Debug, Default)]
struct Coverage {
    stated: u32,
    covered: u32,
    z_square_sum: f64,
    z_sum: f64,
}

impl Coverage {
    fn fraction(&self) -> f64 {
        f64::from(self.covered) / f64::from(self.stated)
    }
}

/// Monte Carlo coverage of the line's readings at `readouts` (samples pushed) against
/// `truth(t)` (t in seconds from the first sample), σ `sigma` on the clean response.
fn ramp_coverage(
    clean: &[f64],
    config: RampConfig<f64>,
    sigma: f64,
    truth: impl Fn(f64) -> f64,
    readouts: &[usize],
    runs: u64,
) -> Vec<Coverage> {
    let mut cells = vec![Coverage::default(); readouts.len()];
    for run in 0..runs {
        let mut noise = Gaussian::new(5000 + run);
        let mut estimator = Ramp::<f64>::new(config).unwrap();
        for (k, &y) in clean.iter().enumerate() {
            let reading = estimator.push(y + sigma * noise.sample());
            assert!(reading.uncertainty.is_none() || reading.estimate.is_some());
            let Some(index) = readouts.iter().position(|&r| r == k + 1) else {
                continue;
            };
            if let (Some(estimate), Some(u)) = (reading.estimate, reading.uncertainty) {
                let error = estimate - truth(k as f64 * config.sample_period_s);
                let cell = &mut cells[index];
                cell.stated += 1;
                cell.covered += u32::from(error.abs() <= 2.0 * u);
                cell.z_square_sum += (error / u).powi(2);
                cell.z_sum += error / u;
            }
        }
    }
    cells
}

/// The sensor's ramp lag τ as the estimator sees it on noise-free data: `b − c₀` over the
/// slope at the end of `clean` (what a calibration with a reference mass measures).
fn calibrated_lag(clean: &[f64], config: RampConfig<f64>, intercept: f64) -> f64 {
    let mut estimator = Ramp::<f64>::new(RampConfig {
        lag_s: 0.0,
        ..config
    })
    .unwrap();
    for &y in clean {
        estimator.push(y);
    }
    let (slope, c0) = estimator.line().unwrap();
    (intercept - c0) / slope
}

/// The conveyor scene with the lag calibrated on its noise-free response, and the noise
/// measured at tare as the consistency check's reference when `checked`.
fn conveyor(snr_db: f64, checked: bool, readouts: &[usize], runs: u64) -> Vec<Coverage> {
    let clean = ramp_response(1000);
    let gain_m_per_g = GRAVITY * 1e-3 / STIFFNESS_N_PER_M;
    let rms = (clean.iter().map(|v| v * v).sum::<f64>() / clean.len() as f64).sqrt();
    let sigma = rms / 10f64.powf(snr_db / 20.0);
    let mut regression = StepConfig::new(2, gain_m_per_g);
    let config = RampConfig {
        regression,
        sample_period_s: SAMPLE_PERIOD_S,
        lag_s: 0.0,
    };
    let lag_s = calibrated_lag(&clean, config, INTERCEPT_G);
    if checked {
        regression = regression.with_noise_reference(NoiseReference::exact(sigma * sigma));
    }
    let config = RampConfig {
        regression,
        lag_s,
        ..config
    };
    ramp_coverage(
        &clean,
        config,
        sigma,
        |t| INTERCEPT_G + SLOPE_G_PER_S * t,
        readouts,
        runs,
    )
}

/// The ZOH response of the LTI mass–spring–damper of `support` to `u(k) = a·k·ts + b`.
fn lti_ramp(samples: usize, slope: f64, intercept: f64) -> (Vec<f64>, f64, f64) {
    let sensor = support::mass_spring_damper();
    let (ad, bd) = sensor.discretise();
    let ts = sensor.sample_time_s;
    let mut x = nalgebra::DVector::<f64>::zeros(2);
    let mut y = Vec::with_capacity(samples);
    for k in 0..samples {
        y.push(sensor.c.dot(&x));
        x = &ad * &x + &bd * (slope * k as f64 * ts + intercept);
    }
    (y, sensor.static_gain(), ts)
}

const LTI_SLOPE: f64 = 0.3;
const LTI_INTERCEPT: f64 = 2.0;

/// The LTI scene at `snr_db` (σ against the steady level `G·b`): response, configuration
/// with the calibrated lag, and σ.
fn lti_scene(snr_db: f64, decimation: u16, samples: usize) -> (Vec<f64>, RampConfig<f64>, f64) {
    let (clean, gain, ts) = lti_ramp(samples, LTI_SLOPE, LTI_INTERCEPT);
    let sigma = gain * LTI_INTERCEPT / 10f64.powf(snr_db / 20.0);
    let config = RampConfig {
        regression: StepConfig::new(2, gain).with_decimation(decimation),
        sample_period_s: ts,
        lag_s: 0.0,
    };
    let lag_s = calibrated_lag(&clean, config, LTI_INTERCEPT);
    (clean, RampConfig { lag_s, ..config }, sigma)
}

fn lti(snr_db: f64, decimation: u16, readouts: &[usize], runs: u64) -> Vec<Coverage> {
    let (clean, config, sigma) = lti_scene(snr_db, decimation, *readouts.last().unwrap());
    ramp_coverage(
        &clean,
        config,
        sigma,
        |t| LTI_INTERCEPT + LTI_SLOPE * t,
        readouts,
        runs,
    )
}

fn print(scene: &str, readouts: &[usize], cells: &[Coverage], runs: u64) {
    for (readout, cell) in readouts.iter().zip(cells) {
        println!(
            "{scene:24} at {readout:5}: stated {:4}/{runs}, coverage {:5.1} %, mean error/u {:+.2}, rms error/u {:.2}",
            cell.stated,
            100.0 * cell.fraction(),
            cell.z_sum / f64::from(cell.stated),
            (cell.z_square_sum / f64::from(cell.stated)).sqrt()
        );
    }
}

/// On an LTI sensor (the model holds) at 20 dB, ±2u covers 95 % of the line's errors at
/// full rate and decimated; at 40 dB it is not over-confident (the first-order
/// errors-in-variables bias is half the measured one there; the residuals' own
/// autocovariance, the step estimator's guard, makes up for it, 97–100 % in the study).
#[test]
fn ramp_two_u_covers_95_percent_on_an_lti_sensor() {
    let runs = 400;
    let readouts = [40, 80, 160, 320];
    for (snr_db, decimation, band) in [
        (20.0, 1, 0.91..=0.99),
        (20.0, 2, 0.91..=0.99),
        (40.0, 1, 0.91..=1.0),
    ] {
        let cells = lti(snr_db, decimation, &readouts, runs);
        print(
            &format!("LTI {snr_db} dB D={decimation}"),
            &readouts,
            &cells,
            runs,
        );
        for (readout, cell) in readouts.iter().zip(&cells) {
            assert_eq!(
                cell.stated, runs as u32,
                "{snr_db} dB D={decimation} at {readout}"
            );
            assert!(
                band.contains(&cell.fraction()),
                "{snr_db} dB D={decimation} at {readout}: {cell:?}"
            );
        }
    }
}

/// On the conveyor the load changes the sensor's dynamics while it slides on (thesis
/// eq. 6.1), a model error no `u` of the LTI regression contains: with the noise at tare as
/// the consistency check's reference, the readings are flagged (`ModelMismatch`) at 40 dB,
/// so none states a `u`. (Unchecked, the `u` covered 0.6–83 % at 10 ms at 30–50 dB, and
/// 100 % from 25 ms on: the model error is larger than the noise early, and inflates the
/// residuals later.)
#[test]
fn ramp_on_the_conveyor_is_flagged_not_given_a_u() {
    let readouts = [100, 250, 500, 1000];
    let cells = conveyor(40.0, true, &readouts, 100);
    for (readout, cell) in readouts.iter().zip(&cells) {
        assert_eq!(cell.stated, 0, "at {readout}: {cell:?}");
    }
}

/// f32 states the f64 `u` of the same data within 10 % wherever both state one.
#[test]
fn ramp_f32_states_the_f64_uncertainty() {
    for snr_db in [20.0, 40.0, 60.0] {
        let (clean, config, sigma) = lti_scene(snr_db, 1, 320);
        let config32 = RampConfig {
            regression: StepConfig::new(2, config.regression.gain as f32),
            sample_period_s: config.sample_period_s as f32,
            lag_s: config.lag_s as f32,
        };
        let (mut worst, mut compared) = (0.0f64, 0);
        for run in 0..40 {
            let mut noise = Gaussian::new(7000 + run);
            let mut e64 = Ramp::<f64>::new(config).unwrap();
            let mut e32 = Ramp::<f32>::new(config32).unwrap();
            let samples = clean.iter().map(|y| (y + sigma * noise.sample()) as f32);
            let (run_worst, run_compared) = u_f32_against_f64(&mut e32, &mut e64, samples);
            worst = worst.max(run_worst);
            compared += run_compared;
        }
        println!("ramp LTI {snr_db} dB: f32 u against f64, worst {worst:.2e} over {compared}");
        assert!(compared > 40 * 250, "{snr_db} dB: {compared}");
        assert!(worst < 0.1, "{snr_db} dB: {worst}");
    }
}

/// No `u` without an estimate, after a bad sample, with forgetting, or without lag sums for
/// the order (`L ≤ n`, the default `L = 0` among them).
#[test]
fn ramp_states_no_u_where_it_has_no_valid_estimate() {
    let (clean, config, sigma) = lti_scene(40.0, 1, 200);
    let mut noise = Gaussian::new(9);
    let data: Vec<f64> = clean.iter().map(|v| v + sigma * noise.sample()).collect();
    let mut plain = Ramp::<f64>::new(config).unwrap();
    let mut bare = RampEstimator::<f64, 8>::new(config).unwrap();
    let mut narrow = RampEstimator::<f64, 8, 2>::new(config).unwrap();
    let forgetting_config = RampConfig {
        regression: config.regression.with_forgetting(0.99),
        ..config
    };
    let mut forgetting = Ramp::<f64>::new(forgetting_config).unwrap();
    let mut others: [&mut dyn Estimator<f64>; 3] = [&mut bare, &mut narrow, &mut forgetting];
    let stated = stated_u_around_a_bad_sample(&mut plain, &mut others, &data, f64::INFINITY);
    assert!(stated > 100, "{stated}");
    assert!(bare.line().is_some());
}

#[test]
#[ignore = "study: coverage of the ramp's u, 1,000 runs per cell (~3 s in release)"]
fn ramp_uncertainty_study() {
    let runs = 1000;
    let readouts = [40, 80, 160, 320, 640, 1280];
    for decimation in [1u16, 2] {
        for snr_db in [20.0, 40.0, 60.0] {
            let cells = lti(snr_db, decimation, &readouts, runs);
            print(
                &format!("LTI {snr_db} dB D={decimation}"),
                &readouts,
                &cells,
                runs,
            );
        }
    }
    let readouts = [100, 250, 500, 1000];
    for checked in [false, true] {
        for snr_db in [30.0, 40.0, 50.0, 60.0] {
            let cells = conveyor(snr_db, checked, &readouts, runs);
            let scene = format!("conveyor {snr_db} dB checked {checked}");
            print(&scene, &readouts, &cells, runs);
        }
    }
}
