//! Published cases: the thesis's second-order scene (eq. 4.38, N = 200) and Markovsky's
//! examples (mass-spring-damper m = 1, k = 1, d = 1 with M = 1, 10, 100 at ts = 1; the
//! first-order thermometer a = 0.35). The core's estimate must equal an independent batch
//! least-squares solve (nalgebra SVD, f64) of the same Hankel problem, and on the thesis
//! scene its empirical bias and variance must both scale like σ² (thesis ch. 4).

use estimator_core::{Estimator, StepConfig, StepEstimator};
use host_sim::expm;
use host_sim::Gaussian;
use nalgebra::{DMatrix, DVector};

/// Exact ZOH discretisation of a 2-state system with one input, by the augmented exponential.
fn zoh2(a: [[f64; 2]; 2], b: [f64; 2], ts: f64) -> ([[f64; 2]; 2], [f64; 2]) {
    let m = [
        [a[0][0] * ts, a[0][1] * ts, b[0] * ts],
        [a[1][0] * ts, a[1][1] * ts, b[1] * ts],
        [0.0, 0.0, 0.0],
    ];
    let e = expm::exp(&m);
    ([[e[0][0], e[0][1]], [e[1][0], e[1][1]]], [e[0][2], e[1][2]])
}

/// Step response `y(k) = c·x(k)` from rest for input `u`, `samples` long.
fn response(phi: [[f64; 2]; 2], gamma: [f64; 2], c: [f64; 2], u: f64, samples: usize) -> Vec<f64> {
    let mut x = [0.0, 0.0];
    (0..samples)
        .map(|_| {
            let y = c[0] * x[0] + c[1] * x[1];
            x = [
                phi[0][0] * x[0] + phi[0][1] * x[1] + gamma[0] * u,
                phi[1][0] * x[0] + phi[1][1] * x[1] + gamma[1] * u,
            ];
            y
        })
        .collect()
}

/// The batch LS estimate of u from y(0..len): rows k = n..len−1 of
/// y(k)/G = u + Σ ℓ_i Δy(k−n+i−1)/G (thesis eq. 3.15), solved by SVD.
fn batch_ls(y: &[f64], order: usize, gain: f64) -> f64 {
    let rows = y.len() - order;
    let mut a = DMatrix::<f64>::zeros(rows, order + 1);
    let mut b = DVector::<f64>::zeros(rows);
    for (row, k) in (order..y.len()).enumerate() {
        for i in 0..order {
            let j = k - order + i;
            a[(row, i)] = (y[j + 1] - y[j]) / gain;
        }
        a[(row, order)] = 1.0;
        b[row] = y[k] / gain;
    }
    let solution = a.svd(true, true).solve(&b, 0.0).expect("SVD solve");
    solution[order]
}

/// The core's estimate after every sample (None while warming up or invalid).
fn core_estimates(y: &[f64], order: usize, gain: f64) -> Vec<Option<f64>> {
    let mut estimator = StepEstimator::<f64, 8>::new(StepConfig::new(order, gain)).unwrap();
    y.iter()
        .map(|&sample| estimator.push(sample).estimate)
        .collect()
}

fn add_noise(y: &[f64], sigma: f64, noise: &mut Gaussian) -> Vec<f64> {
    y.iter().map(|v| v + sigma * noise.standard()).collect()
}

fn rms(y: &[f64]) -> f64 {
    (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt()
}

/// Compare the core with batch LS at several prefix lengths; returns the worst relative
/// difference.
fn worst_difference(y: &[f64], order: usize, gain: f64, u: f64) -> f64 {
    let estimates = core_estimates(y, order, gain);
    let mut worst = 0.0_f64;
    let first = 2 * order + 1;
    for len in (first..=y.len()).step_by(7).chain([y.len()]) {
        let core = estimates[len - 1].expect("estimating after warm-up");
        let batch = batch_ls(&y[..len], order, gain);
        worst = worst.max(((core - batch) / u).abs());
    }
    worst
}

/// Thesis eq. 4.38: m = 0.015 kg, k_s = 500, k_d = 0.5, M = 0.1 kg, g = 9.81, y = −x. The
/// thesis does not state the sample time; we take ts = 0.01 s, where the 200 samples still
/// show the transient (the envelope is ~1.3% at 2 s, inside the thesis's Figure 4.1 2% band
/// only near the end).
fn thesis_scene() -> (Vec<f64>, f64, f64) {
    let (m, ks, kd, big_m, g) = (0.015, 500.0, 0.5, 0.1, 9.81);
    let total = m + big_m;
    let a = [[0.0, 1.0], [-ks / total, -kd / total]];
    let b = [0.0, -g / total];
    let (phi, gamma) = zoh2(a, b, 0.01);
    let y = response(phi, gamma, [-1.0, 0.0], big_m, 200);
    (y, g / ks, big_m)
}

#[test]
fn thesis_second_order_scene_core_equals_batch_ls() {
    let (y, gain, u) = thesis_scene();
    let mut noise = Gaussian::new(11);
    let sigma = rms(&y) / 10f64.powf(50.0 / 20.0);
    let noisy = add_noise(&y, sigma, &mut noise);
    let worst = worst_difference(&noisy, 2, gain, u);
    // Both are backward-stable QR/SVD solutions in f64 of a problem whose condition number
    // here is ~1e3: agreement to 1e-10 relative leaves a margin of ~1e3 over rounding.
    assert!(worst < 1e-10, "worst relative difference {worst:e}");
}

#[test]
fn markovsky_mass_spring_damper_core_equals_batch_ls() {
    // m = 1, k = 1, d = 1, M = 1, 10, 100, ts = 1; input M, output the deflection x, whose
    // static gain is g/k.
    let (m, k, d, g) = (1.0, 1.0, 1.0, 9.81);
    for big_m in [1.0, 10.0, 100.0] {
        let total = m + big_m;
        let (phi, gamma) = zoh2(
            [[0.0, 1.0], [-k / total, -d / total]],
            [0.0, g / total],
            1.0,
        );
        let y = response(phi, gamma, [1.0, 0.0], big_m, 100);
        let mut noise = Gaussian::new(big_m as u64);
        let sigma = rms(&y) / 10f64.powf(40.0 / 20.0);
        let noisy = add_noise(&y, sigma, &mut noise);
        let worst = worst_difference(&noisy, 2, g / k, big_m);
        assert!(
            worst < 1e-9,
            "M = {big_m}: worst relative difference {worst:e}"
        );
    }
}

#[test]
fn markovsky_thermometer_core_equals_batch_ls() {
    // ẏ = a(u − y), a = 0.35 /s, ts = 1 s, from 23 °C towards u = 67 °C. The core removes
    // the known start (the "tare") first, as a caller does: it estimates u − 23.
    let a: f64 = 0.35;
    let pole = (-a).exp();
    let (start, u) = (23.0, 67.0);
    let mut temperature = start;
    let y: Vec<f64> = (0..60)
        .map(|_| {
            let now = temperature;
            temperature = pole * temperature + (1.0 - pole) * u;
            now - start
        })
        .collect();
    let mut noise = Gaussian::new(3);
    let noisy = add_noise(&y, rms(&y) / 10f64.powf(40.0 / 20.0), &mut noise);
    let worst = worst_difference(&noisy, 1, 1.0, u - start);
    assert!(worst < 1e-11, "worst relative difference {worst:e}");
    // And on noise-free data the estimate is exact from the first determined solve.
    let exact = core_estimates(&y, 1, 1.0)[2].unwrap();
    assert!((exact - (u - start)).abs() < 1e-9, "{exact}");
}

/// Bias and variance of the core's estimate at N = 200 on the thesis scene.
fn bias_and_variance(snr_db: f64, runs: usize, seed: u64) -> (f64, f64, f64) {
    let (y, gain, u) = thesis_scene();
    let sigma = rms(&y) / 10f64.powf(snr_db / 20.0);
    let mut noise = Gaussian::new(seed);
    let mut sum = 0.0;
    let mut sum_squares = 0.0;
    for _ in 0..runs {
        let noisy = add_noise(&y, sigma, &mut noise);
        let mut estimator = StepEstimator::<f64, 4>::new(StepConfig::new(2, gain)).unwrap();
        let mut last = f64::NAN;
        for &sample in &noisy {
            last = estimator.push(sample).estimate.unwrap_or(f64::NAN);
        }
        let error = last - u;
        sum += error;
        sum_squares += error * error;
    }
    let n = runs as f64;
    let bias = sum / n;
    let variance = (sum_squares - n * bias * bias) / (n - 1.0);
    (bias, variance, sigma)
}

#[test]
fn thesis_scene_bias_and_variance_scale_like_sigma_squared() {
    // 100,000 runs at 40, 45 and 50 dB (σ² steps by √10), the range where the thesis's
    // second-order analysis holds (below ~35 dB its Taylor expansion fails, ‖M‖ ≥ 1; we
    // measured b/σ² 35% lower at 30 dB than at 40–50 dB, so the law is not tested there).
    // Variance: relative standard error √(2/100000) = 0.45% per point, so a ratio is within
    // ~0.6% (1σ); we allow 5% (> 8σ), which the σ⁴ terms must also fit in. Bias: its
    // standard error is √(var/100000) (6% of the bias at 50 dB, 2% at 40 dB); the test
    // requires each bias to be resolved at > 10 standard errors and the ratio between
    // adjacent SNRs to be √10 within 25% (> 3.5 standard errors of the ratio).
    let runs = 100_000;
    let results: Vec<(f64, f64, f64)> = [40.0, 45.0, 50.0]
        .iter()
        .map(|&snr| bias_and_variance(snr, runs, 5))
        .collect();
    for pair in results.windows(2) {
        let (b_low, v_low, s_low) = pair[0];
        let (b_high, v_high, s_high) = pair[1];
        let sigma_ratio = (s_low / s_high).powi(2);
        let variance_ratio = v_low / v_high;
        assert!(
            (variance_ratio / sigma_ratio - 1.0).abs() < 0.05,
            "variance ratio {variance_ratio} vs σ² ratio {sigma_ratio}"
        );
        for (bias, variance) in [(b_low, v_low), (b_high, v_high)] {
            let standard_error = (variance / runs as f64).sqrt();
            assert!(
                bias.abs() > 10.0 * standard_error,
                "bias {bias:e} not resolved (se {standard_error:e})"
            );
        }
        let bias_ratio = b_low / b_high;
        assert!(
            (bias_ratio / sigma_ratio - 1.0).abs() < 0.25,
            "bias ratio {bias_ratio} vs σ² ratio {sigma_ratio}"
        );
    }
}
