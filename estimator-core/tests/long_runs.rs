//! Long runs with forgetting: the factored `f32` estimator stays finite and within the
//! error budget of the `f64` reference over 10^6 samples (250 s at 4 kHz), and is compared
//! with the textbook covariance form on the same data.
//!
//! Budget: the scale's accuracy target is 0.1% of the load; single precision may use a
//! tenth of it (0.01%).

mod support;

use estimator_core::{
    CovarianceStepEstimator, Estimator, InvalidReason, State, StepConfig, StepEstimator,
};
use support::*;

const MASS_G: f64 = 138.32;
const COUNTS_PER_GRAM: f64 = 145.0;

#[test]
fn factored_f32_tracks_f64_over_a_million_samples_with_forgetting() {
    let sensor = load_cell();
    let g = sensor.static_gain();
    let transient: Vec<f64> = sensor
        .step_response(MASS_G, 8000)
        .iter()
        .map(|v| v / g * COUNTS_PER_GRAM)
        .collect();
    let steady = MASS_G * COUNTS_PER_GRAM;
    let sigma = steady / 10f64.powf(50.0 / 20.0);
    let budget_g = 1e-4 * MASS_G;
    for (order, decimation, forgetting) in [(7usize, 1u16, 0.99f64), (7, 16, 0.99), (5, 1, 0.999)] {
        let cfg64 = StepConfig::new(order, COUNTS_PER_GRAM)
            .with_decimation(decimation)
            .with_forgetting(forgetting);
        let cfg32 = StepConfig::new(order, COUNTS_PER_GRAM as f32)
            .with_decimation(decimation)
            .with_forgetting(forgetting as f32);
        let mut f64_ref = StepEstimator::<f64, 12>::new(cfg64).unwrap();
        let mut f32_fac = StepEstimator::<f32, 12>::new(cfg32).unwrap();
        let mut f32_cov = CovarianceStepEstimator::<f32, 12, 13>::new(cfg32, 1e-6).unwrap();
        let mut noise = Gaussian::new(order as u64 * 100 + decimation as u64);
        let (mut worst_factored, mut worst_covariance) = (0.0f64, 0.0f64);
        let mut covariance_invalid = 0u32;
        for k in 0..1_000_000usize {
            let clean = transient.get(k).copied().unwrap_or(steady);
            let sample = clean + sigma * noise.sample();
            let reference = f64_ref.push(sample);
            let factored = f32_fac.push(sample as f32);
            let covariance = f32_cov.push(sample as f32);
            // Flagged only as barely determined in the transient (`MIN_IDENTIFIABILITY`).
            assert!(
                !factored.is_invalid()
                    || (k < 4000
                        && factored.state == State::Invalid(InvalidReason::IllConditioned)),
                "n={order} D={decimation} k={k}: {:?}",
                factored.state
            );
            if let (Some(r), Some(f)) = (reference.estimate, factored.estimate) {
                worst_factored = worst_factored.max((f as f64 - r).abs());
            }
            match (reference.estimate, covariance.estimate) {
                (Some(r), Some(c)) => worst_covariance = worst_covariance.max((c as f64 - r).abs()),
                (Some(_), None) if k > 4000 => covariance_invalid += 1,
                _ => {}
            }
        }
        println!(
            "n={order} D={decimation} λ={forgetting}: max |f32−f64| factored {worst_factored:.2e} g, covariance form {worst_covariance:.2e} g ({covariance_invalid} invalid), budget {budget_g:.2e} g"
        );
        assert!(
            worst_factored <= budget_g,
            "{worst_factored:.3e} g > {budget_g:.3e} g"
        );
    }
}
