//! The `f32` path (what the Cortex-M4F runs) against the `f64` reference on the same data.
//!
//! Claim: across SNR 40–80 dB, the RMS difference between the `f32` and `f64` estimates is
//! below a tenth of the statistical RMS error of the `f64` estimate, so single precision
//! adds less than 0.5% to the error budget (√(1 + 0.1²) − 1). Where the claim does not
//! hold, the test says so in the table it prints and asserts the documented exception.

mod support;

use estimator_core::{Estimator, StepConfig, StepEstimator};
use support::*;

/// Counts per gram of the simulated front end (16-bit ADC, 138.32 g ≈ 20,000 counts).
const COUNTS_PER_GRAM: f64 = 145.0;
const MASS_G: f64 = 138.32;
const SAMPLE_RATE_HZ: f64 = 4000.0;

struct Row {
    order: usize,
    decimation: u16,
    snr_db: f64,
    readout_ms: f64,
    rms_error_f64: f64,
    rms_diff_f32: f64,
}

fn study(order: usize, decimation: u16, snr_db: f64, readout_ms: f64, runs: u64) -> Row {
    let sensor = load_cell();
    let g_volts = sensor.static_gain();
    let samples = (readout_ms * 1e-3 * SAMPLE_RATE_HZ) as usize;
    // Scale the sensor's volts to ADC counts; the estimator gain is counts per gram.
    let clean: Vec<f64> = sensor
        .step_response(MASS_G, samples)
        .iter()
        .map(|v| v / g_volts * COUNTS_PER_GRAM)
        .collect();
    let (mut sum_err2, mut sum_diff2) = (0.0, 0.0);
    for run in 0..runs {
        let (noisy, _) = add_noise(&clean, MASS_G * COUNTS_PER_GRAM, snr_db, 1000 + run);
        // The same data for both: what the f32 path can see.
        let data: Vec<f32> = noisy.iter().map(|&v| v as f32).collect();
        let cfg64 = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
        let cfg32 = StepConfig::new(order, COUNTS_PER_GRAM as f32).with_decimation(decimation);
        let mut e64 = StepEstimator::<f64, 12>::new(cfg64).unwrap();
        let mut e32 = StepEstimator::<f32, 12>::new(cfg32).unwrap();
        let (mut last64, mut last32) = (None, None);
        for &s in &data {
            last64 = e64.push(s as f64).estimate;
            last32 = e32.push(s).estimate;
        }
        let (m64, m32) = (
            last64.expect("f64 determined"),
            last32.expect("f32 determined"),
        );
        sum_err2 += (m64 - MASS_G).powi(2);
        sum_diff2 += (m32 as f64 - m64).powi(2);
    }
    Row {
        order,
        decimation,
        snr_db,
        readout_ms,
        rms_error_f64: (sum_err2 / runs as f64).sqrt(),
        rms_diff_f32: (sum_diff2 / runs as f64).sqrt(),
    }
}

#[test]
fn f32_difference_is_below_a_tenth_of_the_statistical_error() {
    let mut failures = Vec::new();
    println!("  n    D  SNR/dB  t/ms   RMS err f64 (g)   RMS |f32−f64| (g)   ratio");
    for (order, decimation) in [(5, 1), (7, 1), (5, 8), (7, 16)] {
        for snr_db in [40.0, 50.0, 60.0, 70.0, 80.0] {
            for readout_ms in [100.0, 250.0] {
                let row = study(order, decimation, snr_db, readout_ms, 40);
                let ratio = row.rms_diff_f32 / row.rms_error_f64;
                println!(
                    "{:3} {:4} {:7.0} {:5.0} {:17.3e} {:19.3e} {:8.4}",
                    row.order,
                    row.decimation,
                    row.snr_db,
                    row.readout_ms,
                    row.rms_error_f64,
                    row.rms_diff_f32,
                    ratio
                );
                if ratio.is_nan() || ratio >= 0.1 {
                    failures.push((order, decimation, snr_db, readout_ms, ratio));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "f32 adds more than a tenth of the statistical error: {failures:?}"
    );
}
