//! The model-based estimator: with the right model it is unbiased and its RMS error meets
//! the Cramér–Rao bound of the problem it solves (unknown initial state and step); with a
//! bank of candidate models it stays unbiased when the resonance moves with the load.

mod support;

use estimator_core::{Estimator, ModelBank, ModelConfig, ModelEstimator, SensorModel};
use nalgebra::{DMatrix, DVector};
use support::*;

const MASS_G: f64 = 138.32;

fn model_of(sensor: &Sensor) -> SensorModel<f64, 5> {
    let (ad, bd) = sensor.discretise();
    let mut a = [[0.0; 5]; 5];
    let (mut b, mut c) = ([0.0; 5], [0.0; 5]);
    for i in 0..5 {
        for j in 0..5 {
            a[i][j] = ad[(i, j)];
        }
        b[i] = bd[i];
        c[i] = sensor.c[i];
    }
    SensorModel { a, b, c }
}

fn config(model: SensorModel<f64, 5>) -> ModelConfig<f64, 5> {
    config_decimated(model, 1)
}

fn config_decimated(model: SensorModel<f64, 5>, decimation: u16) -> ModelConfig<f64, 5> {
    ModelConfig::new(model).with_decimation(decimation)
}

/// CRLB of u when x₀ and u are unknown: σ²·[(ΦᵀΦ)⁻¹]_uu with rows [C·A^k, s(k)].
fn crlb_rms(model: &SensorModel<f64, 5>, samples: usize, sigma: f64) -> f64 {
    let a = DMatrix::from_fn(5, 5, |i, j| model.a[i][j]);
    let b = DVector::from_row_slice(&model.b);
    let mut row = DVector::from_row_slice(&model.c).transpose();
    let mut step = 0.0;
    let mut phi = DMatrix::<f64>::zeros(samples, 6);
    for k in 0..samples {
        for j in 0..5 {
            phi[(k, j)] = row[j];
        }
        phi[(k, 5)] = step;
        step += (&row * &b)[0];
        row = &row * &a;
    }
    let info = phi.transpose() * &phi;
    sigma * info.try_inverse().expect("identifiable")[(5, 5)].sqrt()
}

#[test]
fn right_model_meets_the_cramer_rao_bound_at_100_ms() {
    right_model_against_the_bound(1);
}

#[test]
fn block_means_lose_little_against_the_full_rate_bound() {
    right_model_against_the_bound(8);
}

fn right_model_against_the_bound(decimation: u16) {
    let sensor = load_cell();
    let model = model_of(&sensor);
    let g = sensor.static_gain();
    // Restart 5 ms after the drop: the state at restart is unknown to the estimator.
    let skip = 20;
    let samples = 400;
    let full = sensor.step_response(MASS_G, skip + samples);
    let clean = &full[skip..];
    let sigma = g * MASS_G / 10f64.powf(50.0 / 20.0);
    let bound = crlb_rms(&model, samples, sigma);
    let runs = 1000;
    let (mut sum, mut sum_sq) = (0.0, 0.0);
    for run in 0..runs {
        let mut noise = Gaussian::new(run);
        let mut estimator = ModelEstimator::new(config_decimated(model, decimation)).unwrap();
        let mut last = None;
        for &y in clean {
            last = estimator.push(y + sigma * noise.sample()).estimate;
        }
        let err = last.unwrap() - MASS_G;
        sum += err;
        sum_sq += err * err;
    }
    let bias = sum / runs as f64;
    let rms = (sum_sq / runs as f64).sqrt();
    println!("model-based, right model, D = {decimation}, 50 dB, 100 ms: bias {bias:+.2e} g, RMS {rms:.4e} g, full-rate CRLB {bound:.4e} g, ratio {:.3}", rms / bound);
    // 1000 runs: the RMS estimate has a relative standard deviation of 1/√(2·1000) ≈ 2.2%,
    // so 0.9–1.1 is ±4.5σ at full rate. Block means discard a little of the fast transient:
    // allow 5% more there (the goal for the model-based estimator is 1.2×).
    let ceiling = if decimation == 1 { 1.1 } else { 1.15 };
    assert!(
        rms / bound < ceiling && rms / bound > 0.9,
        "{:.3}",
        rms / bound
    );
    assert!(
        bias.abs() < 4.0 * bound / (runs as f64).sqrt(),
        "bias {bias:e}"
    );
}

/// The load cell with its resonance scaled by `frequency_ratio` (damping ratio kept).
fn shifted_load_cell(frequency_ratio: f64) -> Sensor {
    let mut sensor = load_cell();
    let wn_ratio2 = frequency_ratio * frequency_ratio;
    // Row 1 of A is [−ωn², −2ζωn, …]; B[1] = ωn²·gain keeps the static gain.
    sensor.a[(1, 0)] *= wn_ratio2;
    sensor.a[(1, 1)] *= frequency_ratio;
    sensor.b[1] *= wn_ratio2;
    sensor
}

/// Candidates 0.68×–1.32× the calibrated resonance, 2.1% apart, fitted on block means of 8.
fn bank_over_the_resonance() -> ([f64; 33], [ModelConfig<f64, 5>; 33]) {
    let ratios: [f64; 33] = core::array::from_fn(|i| 0.68 * (1.32f64 / 0.68).powf(i as f64 / 32.0));
    let configs = ratios.map(|r| config_decimated(model_of(&shifted_load_cell(r)), 8));
    (ratios, configs)
}

#[test]
fn a_bank_over_the_resonance_stays_unbiased_off_calibration() {
    // The resonance moves up to ±30% off calibration (the range of the stability map);
    // candidates cover 0.68×–1.32×, 2.1% apart, fitted on block means of 8 samples so that
    // the whole bank costs about what 4 full-rate models would.
    let (ratios, configs) = bank_over_the_resonance();
    for true_ratio in [0.7, 0.77, 0.85, 0.93, 1.0, 1.06, 1.15, 1.3] {
        let sensor = shifted_load_cell(true_ratio);
        let clean = sensor.step_response(MASS_G, 420);
        let mut bank = ModelBank::new(configs).unwrap();
        let mut single = ModelEstimator::new(config(model_of(&load_cell()))).unwrap();
        let (mut banked, mut calibrated) = (None, None);
        for &y in &clean[20..] {
            banked = bank.push(y).estimate;
            calibrated = single.push(y).estimate;
        }
        let bias_bank = (banked.unwrap() - MASS_G) / MASS_G;
        let bias_single = (calibrated.unwrap() - MASS_G) / MASS_G;
        println!(
            "resonance ×{true_ratio}: noise-free relative error, bank {bias_bank:+.2e} (best candidate ×{:.3}), calibrated model only {bias_single:+.2e}",
            ratios[bank.best()]
        );
        assert!(
            bias_bank.abs() <= 5e-4,
            "bank bias {bias_bank:e} at ×{true_ratio}"
        );
    }
}

/// The bank's residual is that of its interpolated model (the sample minus the interpolated
/// prediction), as its estimate is: a truth between two candidates leaves the best one's
/// own prediction drifting out of phase with the ringing, while the interpolation follows
/// it. The scale's load-change test runs on this residual (`estimator_core::weighing`), where
/// the best candidate's own one alarmed on a steady 250 g.
#[test]
fn the_bank_residual_is_the_interpolated_models() {
    let (ratios, configs) = bank_over_the_resonance();
    let step = ratios[1] / ratios[0];
    for between in [0.25, 0.5] {
        // A truth a fraction of a grid step above candidate 16.
        let true_ratio = ratios[16] * step.powf(between);
        let clean = load_cell_like(true_ratio);
        let mut bank = ModelBank::new(configs).unwrap();
        let mut bank_residuals = Vec::new();
        for &y in &clean {
            if let Some(r) = bank.push(y).residual {
                bank_residuals.push(r);
            }
        }
        let mut best = ModelEstimator::new(configs[bank.best()]).unwrap();
        let mut best_residuals = Vec::new();
        for &y in &clean {
            if let Some(r) = best.push(y).residual {
                best_residuals.push(r);
            }
        }
        let late_rms = |r: &[f64]| {
            let late = &r[r.len() / 2..];
            (late.iter().map(|v| v * v).sum::<f64>() / late.len() as f64).sqrt()
        };
        let (bank_rms, best_rms) = (late_rms(&bank_residuals), late_rms(&best_residuals));
        println!(
            "truth {between} of a grid step above candidate 16: late residual RMS, bank {bank_rms:.3e}, its best candidate alone {best_rms:.3e}"
        );
        assert!(bank_rms < 0.5 * best_rms, "{bank_rms} vs {best_rms}");
    }
}

/// 0.5 s of the noise-free response of the load cell with its resonance at `ratio`.
fn load_cell_like(ratio: f64) -> Vec<f64> {
    shifted_load_cell(ratio).step_response(MASS_G, 2000)
}
