//! The instrumental-variable (IV) and bias-compensated (BCLS) variants of the data-driven
//! step estimator against least squares (LS):
//!
//! - exact on noise-free data of the right order once determined;
//! - equal, at every sample, to independent batch solves (nalgebra) of the same systems;
//! - Monte Carlo on the thesis's second-order scene (eq. 4.38, N = 200), where the theory's
//!   promise holds: IV and BCLS remove the LS bias at the same variance (thesis §4.2.4);
//! - Monte Carlo on the 4 kHz load cell at D = 1 and D = 12, where it mostly does not, and
//!   the tests pin down how the variants lose and that the loss is flagged or bounded;
//! - the `f32` path against `f64` on the same data.
//!
//! The bigger table of the module docs: `cargo test --release -p estimator-core --test eiv
//! -- --ignored --nocapture study_table` (2,000 runs per configuration, ~20 s).

mod support;

use estimator_core::{
    BiasCompensatedConfig, BiasCompensatedStepEstimator, Estimator, IvConfig, IvStepEstimator,
    NoiseMeter, Reading, State, StepConfig, StepEstimator,
};
use nalgebra::{DMatrix, DVector};
use support::*;

/// The reference scene of host-sim: 138.32 g at 73.2547 counts/g, σ = 0.445 g (50 dB by
/// thesis eq. 4.39), read out 100 ms (400 samples at 4 kHz) after the drop.
const COUNTS_PER_GRAM: f64 = 73.2547;
const MASS_G: f64 = 138.32;
const SIGMA_G: f64 = 0.445;
const READOUT_SAMPLES: usize = 400;

/// Up to order 8 in these tests.
type Ls = StepEstimator<f64, 8>;
type Iv = IvStepEstimator<f64, 8>;
type Bc = BiasCompensatedStepEstimator<f64, 8>;

/// The thesis scene: response, static gain, true input, and σ for an SNR by eq. 4.39.
fn thesis_scene() -> (Vec<f64>, f64, f64, impl Fn(f64) -> f64) {
    let sensor = thesis_second_order();
    let u = 0.1;
    let y = sensor.step_response(u, 200);
    let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
    (y, sensor.static_gain(), u, move |snr_db: f64| {
        rms / 10f64.powf(snr_db / 20.0)
    })
}

fn with_noise(clean: &[f64], sigma: f64, noise: &mut Gaussian) -> Vec<f64> {
    clean.iter().map(|v| v + sigma * noise.sample()).collect()
}

fn last_reading<E: Estimator<f64>>(estimator: &mut E, data: &[f64]) -> Reading<f64> {
    let mut last = None;
    for &sample in data {
        last = Some(estimator.push(sample));
    }
    last.expect("data")
}

// ---------------------------------------------------------------------------------------
// Exactness and batch equivalence
// ---------------------------------------------------------------------------------------

#[test]
fn noise_free_data_of_the_right_order_give_the_exact_step_once_determined() {
    let scenes = [
        (thermometer(), 60),
        (mass_spring_damper(), 60),
        (thesis_second_order(), 200),
        (load_cell(), 400),
    ];
    for (sensor, samples) in scenes {
        let order = sensor.order;
        let g = sensor.static_gain();
        let u = 1.3832;
        let y = sensor.step_response(u, samples);
        let step = StepConfig::new(order, g);
        for delay in [order + 1, 2 * order + 1] {
            // The weak-instrument floor is a statistical guard; exactness is about the algebra.
            let config = IvConfig::new(step)
                .with_instrument_delay(delay)
                .with_min_identifiability(0.0);
            let mut iv = Iv::new(config).unwrap();
            let warm_up = iv.warm_up_samples() as usize;
            let (mut worst, mut checked) = (0.0_f64, 0);
            for (k, &sample) in y.iter().enumerate() {
                let reading = iv.push(sample);
                if k + 1 < warm_up {
                    assert_eq!(reading.state, State::WarmingUp, "{} k={k}", sensor.name);
                    continue;
                }
                // From 10n rows after warm-up on (as in batch_equivalence.rs, where the
                // 4 kHz Hankel data are too ill-conditioned for 1e-9 in the first rows).
                if let Some(estimate) = reading.estimate {
                    if k + 1 >= warm_up + 10 * order {
                        worst = worst.max((estimate - u).abs() / u);
                        checked += 1;
                    }
                }
            }
            println!(
                "{:40} IV d={delay:2}: max relative error {worst:.2e} over {checked} readings",
                sensor.name
            );
            assert!(checked > 0, "{}: never estimating", sensor.name);
            assert!(worst <= 1e-9, "{} d={delay}: {worst:.3e}", sensor.name);
        }
        // BCLS with σ² = 0 is least squares: the same estimate, bit for bit, at every sample
        // (and the LS estimate is exact, batch_equivalence.rs). With σ² > 0 on noise-free
        // data it compensates noise that is not there, so it is not exact then.
        let mut bc = Bc::new(BiasCompensatedConfig::new(step, 0.0)).unwrap();
        let mut ls = Ls::new(step).unwrap();
        for &sample in &y {
            let (a, b) = (bc.push(sample), ls.push(sample));
            assert_eq!(a.estimate, b.estimate, "{}", sensor.name);
            assert_eq!(a.state, b.state, "{}", sensor.name);
        }
    }
}

/// Weighted rows of the IV problem for the decimated sequence `x`: regressors `K`, targets,
/// and instruments `Z` (the regressor `delay` rows earlier), rows k = n+d .. len−1.
fn iv_system(
    x: &[f64],
    order: usize,
    delay: usize,
    forgetting: f64,
) -> (DMatrix<f64>, DVector<f64>, DMatrix<f64>) {
    let first = order + delay;
    let rows = x.len() - first;
    let mut k_mat = DMatrix::zeros(rows, order + 1);
    let mut z_mat = DMatrix::zeros(rows, order + 1);
    let mut rhs = DVector::zeros(rows);
    for (r, k) in (first..x.len()).enumerate() {
        let w = forgetting.powi((x.len() - 1 - k) as i32).sqrt();
        for i in 0..order {
            let j = k - order + i;
            k_mat[(r, i)] = w * (x[j + 1] - x[j]);
            let j = j - delay;
            z_mat[(r, i)] = w * (x[j + 1] - x[j]);
        }
        k_mat[(r, order)] = w;
        z_mat[(r, order)] = w;
        rhs[r] = w * x[k];
    }
    (k_mat, rhs, z_mat)
}

/// Columns scaled to unit norm: the condition number that matters for a solver whose
/// backward error is small column by column (Givens/Householder QR, equilibrated LU).
fn column_scaled_cond(m: &DMatrix<f64>) -> (f64, DVector<f64>) {
    let scale = DVector::from_iterator(m.ncols(), m.column_iter().map(|c| 1.0 / c.norm()));
    let scaled = m * DMatrix::from_diagonal(&scale);
    let sv = scaled.singular_values();
    (sv.max() / sv.min(), scale)
}

/// Block means of `D` raw samples divided by the gain, as the estimators form them.
fn decimated(y: &[f64], gain: f64, decimation: usize) -> Vec<f64> {
    y.chunks_exact(decimation)
        .map(|block| block.iter().map(|v| v / gain).sum::<f64>() / decimation as f64)
        .collect()
}

/// Independent batch IV: QR of Z (nalgebra Householder), then `(QᵀK) θ = Qᵀx` by LU with
/// full pivoting (nalgebra's SVD solve was seen to miss by 1e-6 on one of these matrices).
/// Returns u and the relative tolerance on it. Both solutions are backward stable, column by
/// column: the computed θ is the exact IV solution for `Z + δZ`, `K + δK`, `x + δx` with
/// `‖δ·_j‖ ≤ c·ε·‖·_j‖`. With unknowns scaled by K's column norms (θ̃ = θ·‖k_j‖), first-order
/// perturbation of `θ = (ZᵀK)⁻¹Zᵀx` gives
/// `‖δθ̃‖ ≤ c·ε·κ̃_M·‖θ̃‖·(1 + κ̃_Z·ρ)`, with κ̃ the condition numbers of the column-scaled
/// `M = QᵀK` and `Z`, and ρ = ‖x − Kθ‖/(‖K̃‖·‖θ̃‖) the IV residual (the δZ term acts through
/// it, as the κ²·ρ term of least squares). Relative to u: divide by |θ̃_u|. Two stages (ours
/// and the reference): 2c, c = 10·(n+1) as in `ls_tolerance`.
fn batch_iv(x: &[f64], order: usize, delay: usize, forgetting: f64) -> (f64, f64) {
    let (k_mat, rhs, z_mat) = iv_system(x, order, delay, forgetting);
    let q = z_mat.clone().qr().q();
    let m = q.transpose() * &k_mat;
    let b = q.transpose() * &rhs;
    let theta = m.clone().full_piv_lu().solve(&b).unwrap();
    let column_norms = DVector::from_iterator(k_mat.ncols(), k_mat.column_iter().map(|c| c.norm()));
    let unscale = DMatrix::from_diagonal(&column_norms.map(|v| 1.0 / v));
    let cond = |a: &DMatrix<f64>| {
        let sv = a.singular_values();
        sv.max() / sv.min()
    };
    let cond_m = cond(&(&m * &unscale));
    let (cond_z, _) = column_scaled_cond(&z_mat);
    let scaled_k_norm = (&k_mat * &unscale).singular_values().max();
    let scaled_theta = theta.component_mul(&column_norms);
    let rho = (&rhs - &k_mat * &theta).norm() / (scaled_k_norm * scaled_theta.norm());
    let c = 10.0 * (order + 1) as f64;
    let tol = 2.0 * c * f64::EPSILON * cond_m * (1.0 + cond_z * rho) * scaled_theta.norm()
        / scaled_theta[order].abs();
    (theta[order], tol)
}

#[test]
fn recursive_iv_equals_batch_iv_at_every_sample() {
    let scenes = [
        (thermometer(), 1usize, 60usize, 1u16),
        (mass_spring_damper(), 2, 60, 1),
        (thesis_second_order(), 2, 200, 1),
        (thesis_second_order(), 4, 200, 1),
        (load_cell(), 5, 400, 1),
        (load_cell(), 7, 1200, 12),
    ];
    for (sensor, order, samples, decimation) in scenes {
        let g = sensor.static_gain();
        let clean = sensor.step_response(1.3832, samples);
        for forgetting in [1.0, 0.97] {
            for delay in [order + 1, 2 * order + 1] {
                let y = add_noise(&clean, g * 1.3832, 40.0, 5 + order as u64).0;
                let x = decimated(&y, g, decimation as usize);
                let step = StepConfig::new(order, g)
                    .with_forgetting(forgetting)
                    .with_decimation(decimation);
                let config = IvConfig::new(step)
                    .with_instrument_delay(delay)
                    .with_min_identifiability(0.0);
                let mut iv = Iv::new(config).unwrap();
                let (mut worst_ratio, mut worst, mut checked) = (0.0_f64, 0.0_f64, 0);
                for (k, &sample) in y.iter().enumerate() {
                    let reading = iv.push(sample);
                    let blocks = (k + 1) / decimation as usize;
                    if (k + 1) % decimation as usize != 0 || blocks < 2 * order + delay + 1 {
                        continue;
                    }
                    let (reference, tol) = batch_iv(&x[..blocks], order, delay, forgetting);
                    let Some(estimate) = reading.estimate else {
                        // Only the rounding-level floor is on: a flag means the batch system
                        // is singular to working precision too.
                        assert!(
                            tol > 1e-3,
                            "{} k={k}: flagged but tol {tol:.1e}",
                            sensor.name
                        );
                        continue;
                    };
                    let err = (estimate - reference).abs() / reference.abs();
                    assert!(
                        err <= tol,
                        "{} n={order} d={delay} λ={forgetting} k={k}: {err:.3e} > {tol:.3e}",
                        sensor.name
                    );
                    worst = worst.max(err);
                    worst_ratio = worst_ratio.max(err / tol);
                    checked += 1;
                }
                println!(
                    "{:40} n={order} D={decimation:2} d={delay:2} λ={forgetting}: max rel diff {worst:.1e}, max diff/bound {worst_ratio:.1e}, {checked} readings",
                    sensor.name
                );
                assert!(checked > 0);
            }
        }
    }
}

/// Independent batch BCLS from the QR of K (nalgebra): with R θ = w, the compensated
/// equations `(RᵀR − S) θ = Rᵀc − r` become `B w = c − R⁻ᵀ r`, `B = I − X Xᵀ`, `X = R⁻ᵀ H`
/// (`S = H Hᵀ`): a different algorithm from the recursive hyperbolic downdate. Returns u,
/// the tolerance on it, the smallest LDLᵀ pivot of `B` (no pivoting; these pivots are the
/// shares of each direction's energy the compensation leaves, which the estimator tests),
/// and the effective row count.
///
/// Tolerance: the LS part contributes `ls_tolerance` (κ of K); the square solve, backward
/// stable, adds `c·ε·κ(B)·‖w‖/|w_u|` relative to u (u = w_u / R_uu).
fn batch_bcls(x: &[f64], order: usize, forgetting: f64, variance: f64) -> (f64, f64, f64, f64) {
    let (k_mat, rhs) = hankel_system(x, order, forgetting, x.len());
    let rows = k_mat.nrows();
    let effective_rows: f64 = (0..rows).map(|r| forgetting.powi(r as i32)).sum();
    let qr = k_mat.clone().qr();
    let r_mat = qr.r();
    let c_vec = qr.q().transpose() * &rhs;
    let p = order + 1;
    let scale = (effective_rows * variance).sqrt();
    let mut h = DMatrix::<f64>::zeros(p, p);
    for j in 0..=order {
        if j >= 1 {
            h[(j - 1, j)] = scale;
        }
        if j < order {
            h[(j, j)] = -scale;
        }
    }
    let mut r_vec = DVector::<f64>::zeros(p);
    r_vec[order - 1] = effective_rows * variance;
    let rt = r_mat.transpose();
    let x_mat = rt.solve_lower_triangular(&h).unwrap();
    let t = rt.solve_lower_triangular(&r_vec).unwrap();
    let b_mat = DMatrix::<f64>::identity(p, p) - &x_mat * x_mat.transpose();
    // LDLᵀ without pivoting: d_k = B_kk − Σ_{j<k} L_kj² d_j.
    let mut l = DMatrix::<f64>::identity(p, p);
    let mut pivots = DVector::<f64>::zeros(p);
    for k in 0..p {
        pivots[k] = b_mat[(k, k)] - (0..k).map(|j| l[(k, j)].powi(2) * pivots[j]).sum::<f64>();
        for i in (k + 1)..p {
            l[(i, k)] = (b_mat[(i, k)]
                - (0..k)
                    .map(|j| l[(i, j)] * l[(k, j)] * pivots[j])
                    .sum::<f64>())
                / pivots[k];
        }
    }
    let w = b_mat.clone().full_piv_lu().solve(&(c_vec - t)).unwrap();
    let u = w[order] / r_mat[(order, order)];
    let eig = b_mat.symmetric_eigen().eigenvalues;
    let cond_b = eig.abs().max() / eig.abs().min();
    let c = 10.0 * p as f64;
    let tol = ls_tolerance(&batch_solve(&k_mat, &rhs))
        + c * f64::EPSILON * cond_b * w.norm() / w[order].abs();
    (u, tol, pivots.min(), effective_rows)
}

#[test]
fn recursive_bcls_equals_batch_bcls_and_is_refused_exactly_where_a_share_is_unresolved() {
    let scenes = [
        (thermometer(), 1usize, 60usize, 1u16, 40.0),
        (mass_spring_damper(), 2, 60, 1, 40.0),
        (thesis_second_order(), 2, 200, 1, 40.0),
        (thesis_second_order(), 3, 200, 1, 50.0),
        (load_cell(), 5, 1200, 12, 50.0),
    ];
    for (sensor, order, samples, decimation, snr_db) in scenes {
        let g = sensor.static_gain();
        let clean = sensor.step_response(1.3832, samples);
        for forgetting in [1.0, 0.97] {
            let (y, sigma) = add_noise(&clean, g * 1.3832, snr_db, 17 + order as u64);
            let x = decimated(&y, g, decimation as usize);
            let step = StepConfig::new(order, g)
                .with_forgetting(forgetting)
                .with_decimation(decimation);
            let mut bc = Bc::new(BiasCompensatedConfig::new(step, sigma * sigma)).unwrap();
            let variance = sigma * sigma / (g * g * decimation as f64);
            let (mut worst_ratio, mut checked, mut refused, mut borderline) = (0.0_f64, 0, 0, 0);
            for (k, &sample) in y.iter().enumerate() {
                let reading = bc.push(sample);
                let blocks = (k + 1) / decimation as usize;
                if (k + 1) % decimation as usize != 0 || blocks < 2 * order + 1 {
                    continue;
                }
                let (reference, tol, min_share, effective_rows) =
                    batch_bcls(&x[..blocks], order, forgetting, variance);
                // The documented floor. The shares computed two ways agree to far better
                // than 1e-6 on these scenes, so only shares within 1e-6 of it are undecided.
                let floor = (2.0 / effective_rows).sqrt();
                if (min_share - floor).abs() < 1e-6 {
                    borderline += 1;
                    continue;
                }
                match reading.estimate {
                    Some(estimate) => {
                        assert!(
                            min_share > floor,
                            "{} k={k}: kept, share {min_share:.3e}",
                            sensor.name
                        );
                        let err = (estimate - reference).abs() / reference.abs();
                        assert!(
                            err <= tol,
                            "{} n={order} λ={forgetting} k={k}: {err:.3e} > {tol:.3e}",
                            sensor.name
                        );
                        worst_ratio = worst_ratio.max(err / tol);
                        checked += 1;
                    }
                    None => {
                        assert_eq!(
                            reading.state,
                            State::Invalid(estimator_core::InvalidReason::IllConditioned)
                        );
                        assert!(
                            min_share < floor,
                            "{} k={k}: refused, share {min_share:.3e}",
                            sensor.name
                        );
                        refused += 1;
                    }
                }
            }
            println!(
                "{:40} n={order} D={decimation:2} λ={forgetting}: {checked} readings equal batch (max diff/bound {worst_ratio:.1e}), {refused} refused, {borderline} at the floor",
                sensor.name
            );
            assert!(checked > 0);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Monte Carlo: bias and RMS of LS, IV and BCLS
// ---------------------------------------------------------------------------------------

/// Errors of one method over the runs (None: the reading was flagged).
#[derive(Default)]
struct Errors(Vec<Option<f64>>);

#[derive(Debug)]
struct Summary {
    bias: f64,
    /// Standard error of the bias.
    bias_se: f64,
    sd: f64,
    rms: f64,
    median_abs: f64,
    valid: usize,
    runs: usize,
}

impl Errors {
    fn summary(&self) -> Summary {
        let valid: Vec<f64> = self.0.iter().flatten().copied().collect();
        let n = valid.len() as f64;
        let bias = valid.iter().sum::<f64>() / n;
        let sd = (valid.iter().map(|e| (e - bias).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let rms = (valid.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let mut abs: Vec<f64> = valid.iter().map(|e| e.abs()).collect();
        abs.sort_by(f64::total_cmp);
        Summary {
            bias,
            bias_se: sd / n.sqrt(),
            sd,
            rms,
            median_abs: abs.get(abs.len() / 2).copied().unwrap_or(f64::NAN),
            valid: valid.len(),
            runs: self.0.len(),
        }
    }
}

fn print_row(scene: &str, method: &str, s: &Summary) {
    println!(
        "{scene:22} {method:14} bias {:+10.3e} ± {:8.1e}  sd {:9.3e}  RMS {:9.3e}  median|e| {:9.3e}  valid {:4}/{}",
        s.bias, s.bias_se, s.sd, s.rms, s.median_abs, s.valid, s.runs
    );
}

struct ThesisStudy {
    ls: Summary,
    iv: Summary,
    bc: Summary,
    bc_metered: Summary,
}

fn thesis_study(snr_db: f64, runs: usize, seed: u64) -> ThesisStudy {
    let (y, g, u, sigma_for) = thesis_scene();
    let sigma = sigma_for(snr_db);
    let order = 2;
    let step = StepConfig::new(order, g);
    let mut noise = Gaussian::new(seed);
    let (mut ls, mut iv, mut bc, mut bc_metered) = (
        Errors::default(),
        Errors::default(),
        Errors::default(),
        Errors::default(),
    );
    for _ in 0..runs {
        // 200 empty-pan samples at tare first, for the metered variance.
        let mut meter = NoiseMeter::<f64>::new(1).unwrap();
        for _ in 0..200 {
            meter.push(sigma * noise.sample()).unwrap();
        }
        let metered = meter.noise_variance().unwrap();
        let data = with_noise(&y, sigma, &mut noise);
        let mut estimators: (Ls, Iv, Bc, Bc) = (
            Ls::new(step).unwrap(),
            Iv::new(IvConfig::new(step)).unwrap(),
            Bc::new(BiasCompensatedConfig::new(step, sigma * sigma)).unwrap(),
            Bc::new(BiasCompensatedConfig::new(step, metered)).unwrap(),
        );
        let error = |reading: Reading<f64>| reading.estimate.map(|v| v - u);
        ls.0.push(error(last_reading(&mut estimators.0, &data)));
        iv.0.push(error(last_reading(&mut estimators.1, &data)));
        bc.0.push(error(last_reading(&mut estimators.2, &data)));
        bc_metered
            .0
            .push(error(last_reading(&mut estimators.3, &data)));
    }
    ThesisStudy {
        ls: ls.summary(),
        iv: iv.summary(),
        bc: bc.summary(),
        bc_metered: bc_metered.summary(),
    }
}

#[test]
fn on_the_thesis_scene_iv_and_bcls_remove_the_ls_bias_at_the_same_variance() {
    // 4,000 runs: the bias's standard error is sd/63; at 30 and 40 dB the LS bias is
    // 20 and 10 standard errors (measured), so "resolved" and "removed" are both decidable.
    let runs = 4000;
    for snr_db in [30.0, 40.0] {
        let study = thesis_study(snr_db, runs, 7);
        let scene = format!("thesis N=200 {snr_db:.0} dB");
        print_row(&scene, "LS", &study.ls);
        print_row(&scene, "IV d=n+1", &study.iv);
        print_row(&scene, "BCLS (true σ²)", &study.bc);
        print_row(&scene, "BCLS (metered)", &study.bc_metered);
        let ls = &study.ls;
        assert!(
            ls.bias.abs() > 5.0 * ls.bias_se,
            "the LS bias must be resolved to test its removal: {ls:?}"
        );
        for (name, s) in [
            ("IV", &study.iv),
            ("BCLS", &study.bc),
            ("BCLS metered", &study.bc_metered),
        ] {
            // Consistent estimators: what is left is within 4 standard errors of zero
            // (a 6e-5 chance of failing if truly unbiased) and far below the LS bias.
            assert!(s.bias.abs() < 4.0 * s.bias_se, "{name} {snr_db} dB: {s:?}");
            assert!(
                s.bias.abs() < ls.bias.abs() / 4.0,
                "{name} {snr_db} dB: {s:?}"
            );
            // Thesis §4.2.4: "the empirical variances of the two solutions are very close".
            // Same noise in every run, so the ratio is far more precise than each sd; the
            // metered σ² (12% relative error per run) may add a little.
            let ratio = s.sd / ls.sd;
            assert!(
                (0.9..1.1).contains(&ratio),
                "{name} {snr_db} dB: sd ratio {ratio:.3}"
            );
            // No reading flagged on this well-excited, right-order scene (allow 1%).
            assert!(s.valid * 100 >= s.runs * 99, "{name} {snr_db} dB: {s:?}");
        }
    }
}

struct CellStudy {
    ls: Summary,
    iv: Summary,
    bc: Summary,
}

fn load_cell_study(
    order: usize,
    decimation: u16,
    delay: usize,
    runs: usize,
    seed: u64,
) -> CellStudy {
    let clean = load_cell_counts(MASS_G, COUNTS_PER_GRAM, READOUT_SAMPLES);
    let sigma = SIGMA_G * COUNTS_PER_GRAM;
    let step = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
    let mut noise = Gaussian::new(seed);
    let (mut ls, mut iv, mut bc) = (Errors::default(), Errors::default(), Errors::default());
    for _ in 0..runs {
        let data = with_noise(&clean, sigma, &mut noise);
        let mut a = Ls::new(step).unwrap();
        let mut b = Iv::new(IvConfig::new(step).with_instrument_delay(delay)).unwrap();
        let mut c = Bc::new(BiasCompensatedConfig::new(step, sigma * sigma)).unwrap();
        ls.0.push(last_reading(&mut a, &data).estimate.map(|v| v - MASS_G));
        iv.0.push(last_reading(&mut b, &data).estimate.map(|v| v - MASS_G));
        bc.0.push(last_reading(&mut c, &data).estimate.map(|v| v - MASS_G));
    }
    CellStudy {
        ls: ls.summary(),
        iv: iv.summary(),
        bc: bc.summary(),
    }
}

#[test]
fn on_the_load_cell_the_variants_lose_to_decimated_least_squares_and_say_so() {
    // 300 runs per configuration, 50 dB, readout at 100 ms. CRLB there ≈ 0.020 g.
    let runs = 300;
    let mut full_rate_iv_rms = f64::INFINITY;
    let mut decimated_ls_rms: f64 = 0.0;
    for order in [7, 5] {
        let full = load_cell_study(order, 1, order + 1, runs, 99);
        let decimated = load_cell_study(order, 12, order + 1, runs, 99);
        for (label, s) in [("D=1", &full), ("D=12", &decimated)] {
            let scene = format!("load cell n={order} {label}");
            print_row(&scene, "LS", &s.ls);
            print_row(&scene, "IV d=n+1", &s.iv);
            print_row(&scene, "BCLS", &s.bc);
        }
        // D = 1: the errors-in-variables bias of LS dominates (thesis ch. 4; host-sim's
        // 4.29 g RMS at n = 7): resolved, and grams.
        let ls = &full.ls;
        assert!(
            ls.bias.abs() > 10.0 * ls.bias_se && ls.bias.abs() > 1.0,
            "{ls:?}"
        );
        // IV removes most of it: its typical error is a fraction of the LS bias...
        let iv = &full.iv;
        assert!(iv.median_abs < ls.bias.abs() / 2.0, "{iv:?}");
        // ...and its weak-instrument outliers (tens to hundreds of grams without the floor)
        // are flagged: the readings kept beat LS in RMS, and few are flagged.
        assert!(iv.rms < ls.rms, "IV {iv:?} vs LS {ls:?}");
        assert!(iv.valid * 10 >= iv.runs * 9, "{iv:?}");
        full_rate_iv_rms = full_rate_iv_rms.min(iv.rms);
        // BCLS: with noise-only directions in the regressor space (fast filter modes, order
        // above the data's), some direction's signal share is unresolved in most runs and the
        // compensation is refused; the readings kept carry less bias than LS's.
        let bc = &full.bc;
        assert!(bc.valid * 2 < bc.runs, "expected mostly refused: {bc:?}");
        assert!(bc.valid == 0 || bc.rms < ls.rms, "{bc:?}");

        // D = 12: LS is at ~1.2× the CRLB with a bias of a few mg at most: nothing to
        // remove. IV only adds variance; BCLS is refused in most runs. The loss of what is
        // kept is bounded: the floors keep readings whose noise gain is within √10 of LS's
        // (IV) or whose every direction is resolved (BCLS), so ≤ 3× the LS RMS (2,000-run
        // study: IV 1.3–1.6×, BCLS 1.0–1.2×).
        let ls = &decimated.ls;
        decimated_ls_rms = decimated_ls_rms.max(ls.rms);
        assert!(ls.bias.abs() < 0.01, "{ls:?}");
        let iv = &decimated.iv;
        assert!(
            iv.rms > ls.rms && iv.rms < 3.0 * ls.rms,
            "IV {iv:?} vs LS {ls:?}"
        );
        let bc = &decimated.bc;
        assert!(bc.valid * 2 < bc.runs, "expected mostly refused: {bc:?}");
        assert!(
            bc.valid == 0 || bc.rms < 3.0 * ls.rms,
            "BCLS {bc:?} vs LS {ls:?}"
        );
    }
    // The verdict: the best full-rate variant is still two orders of magnitude behind
    // decimated least squares.
    println!(
        "best full-rate IV RMS {full_rate_iv_rms:.3} g vs decimated LS {decimated_ls_rms:.4} g"
    );
    assert!(full_rate_iv_rms > 10.0 * decimated_ls_rms);
}

#[test]
#[ignore = "study for the module docs' table (~20 s in release)"]
fn study_table() {
    let runs = 2000;
    println!(
        "load cell, 138.32 g, σ = {SIGMA_G} g (50 dB), readout 100 ms, {runs} runs, seed 2024"
    );
    for order in [7, 5] {
        for decimation in [1, 12] {
            for delay in [order + 1, 2 * order + 1] {
                // Warm-up (2n + d + 1)·D must fit in the 400 samples.
                if (2 * order + delay + 1) * decimation as usize > READOUT_SAMPLES {
                    continue;
                }
                let s = load_cell_study(order, decimation, delay, runs, 2024);
                let scene = format!("n={order} D={decimation}");
                if delay == order + 1 {
                    print_row(&scene, "LS", &s.ls);
                    print_row(&scene, "BCLS", &s.bc);
                }
                print_row(&scene, &format!("IV d={delay}"), &s.iv);
            }
        }
    }
    for snr_db in [30.0, 40.0, 50.0] {
        let s = thesis_study(snr_db, 20_000, 7);
        let scene = format!("thesis {snr_db:.0} dB");
        print_row(&scene, "LS", &s.ls);
        print_row(&scene, "IV d=n+1", &s.iv);
        print_row(&scene, "BCLS", &s.bc);
        print_row(&scene, "BCLS metered", &s.bc_metered);
    }
}

// ---------------------------------------------------------------------------------------
// f32 against f64 on the same data
// ---------------------------------------------------------------------------------------

/// RMS over runs of |f32 − f64| (where both are valid), RMS error of f64, and the number of
/// runs where the two disagree on validity.
fn f32_against_f64<E32, E64>(
    clean: &[f64],
    sigma: f64,
    truth: f64,
    runs: u64,
    mut make: impl FnMut() -> (E32, E64),
) -> (f64, f64, usize, usize)
where
    E32: Estimator<f32>,
    E64: Estimator<f64>,
{
    let (mut diff2, mut err2, mut both, mut disagree) = (0.0, 0.0, 0, 0);
    for run in 0..runs {
        let mut noise = Gaussian::new(1000 + run);
        let data: Vec<f32> = clean
            .iter()
            .map(|v| (v + sigma * noise.sample()) as f32)
            .collect();
        let (mut e32, mut e64) = make();
        let (mut r32, mut r64) = (None, None);
        for &s in &data {
            r32 = e32.push(s).estimate;
            r64 = e64.push(s as f64).estimate;
        }
        match (r32, r64) {
            (Some(a), Some(b)) => {
                diff2 += (a as f64 - b).powi(2);
                err2 += (b - truth).powi(2);
                both += 1;
            }
            (None, None) => {}
            _ => disagree += 1,
        }
    }
    let n = both.max(1) as f64;
    ((diff2 / n).sqrt(), (err2 / n).sqrt(), both, disagree)
}

#[test]
fn f32_adds_less_than_a_tenth_of_the_statistical_error_where_the_variants_are_valid() {
    // Claim as in f32_against_f64.rs: RMS |f32 − f64| < 0.1 × RMS error of f64, i.e. single
    // precision adds < 0.5% to the error budget. Checked where each variant is valid: the
    // thesis scene (both) and the decimated load cell (IV; BCLS is mostly flagged there).
    let (y, g, u, sigma_for) = thesis_scene();
    let runs = 100;
    println!("scene                         method   RMS err f64    RMS |f32−f64|   ratio  both  disagree");
    let mut failures = Vec::new();
    for snr_db in [30.0, 50.0, 70.0] {
        let sigma = sigma_for(snr_db);
        let step64 = StepConfig::new(2, g);
        let step32 = StepConfig::new(2, g as f32);
        let iv = f32_against_f64(&y, sigma, u, runs, || {
            (
                IvStepEstimator::<f32, 8>::new(IvConfig::new(step32)).unwrap(),
                Iv::new(IvConfig::new(step64)).unwrap(),
            )
        });
        let variance = sigma * sigma;
        let bc = f32_against_f64(&y, sigma, u, runs, || {
            (
                BiasCompensatedStepEstimator::<f32, 8>::new(BiasCompensatedConfig::new(
                    step32,
                    variance as f32,
                ))
                .unwrap(),
                Bc::new(BiasCompensatedConfig::new(step64, variance)).unwrap(),
            )
        });
        for (name, (diff, err, both, disagree)) in [("IV", iv), ("BCLS", bc)] {
            let ratio = diff / err;
            println!(
                "thesis {snr_db:2.0} dB                 {name:6} {err:12.3e} {diff:15.3e} {ratio:8.4} {both:5} {disagree:5}"
            );
            if ratio.is_nan() || ratio >= 0.1 || disagree > 0 {
                failures.push((format!("thesis {snr_db} dB {name}"), ratio, disagree));
            }
        }
    }
    let clean = load_cell_counts(MASS_G, COUNTS_PER_GRAM, READOUT_SAMPLES);
    let sigma = SIGMA_G * COUNTS_PER_GRAM;
    for order in [5, 7] {
        let step64 = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(12);
        let step32 = StepConfig::new(order, COUNTS_PER_GRAM as f32).with_decimation(12);
        let (diff, err, both, disagree) = f32_against_f64(&clean, sigma, MASS_G, 40, || {
            (
                IvStepEstimator::<f32, 8>::new(IvConfig::new(step32)).unwrap(),
                Iv::new(IvConfig::new(step64)).unwrap(),
            )
        });
        let ratio = diff / err;
        println!(
            "load cell n={order} D=12           IV     {err:12.3e} {diff:15.3e} {ratio:8.4} {both:5} {disagree:5}"
        );
        // A reading whose identifiability sits at the floor may be flagged in one precision
        // only; allow one such run in 40.
        if ratio.is_nan() || ratio >= 0.1 || disagree > 1 {
            failures.push((format!("load cell n={order} IV"), ratio, disagree));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
