//! Test scenes for the core: exact ZOH step responses of known sensors, seeded noise, and an
//! independent batch least-squares reference of the same Hankel system.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};

/// A continuous-time SISO sensor `ẋ = A x + B u, y = C x`, sampled with a zero-order hold.
pub struct Sensor {
    pub name: &'static str,
    pub order: usize,
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DVector<f64>,
    pub sample_time_s: f64,
}

impl Sensor {
    /// Exact ZOH discretisation: expm([[A, B], [0, 0]]·ts).
    pub fn discretise(&self) -> (DMatrix<f64>, DVector<f64>) {
        let n = self.order;
        let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
        m.view_mut((0, 0), (n, n)).copy_from(&self.a);
        m.view_mut((0, n), (n, 1)).copy_from(&self.b);
        let e = (m * self.sample_time_s).exp();
        (
            e.view((0, 0), (n, n)).into_owned(),
            e.view((0, n), (n, 1)).column(0).into_owned(),
        )
    }

    /// Static gain `G = −C A⁻¹ B`.
    pub fn static_gain(&self) -> f64 {
        let x = self.a.clone().lu().solve(&self.b).expect("A is invertible");
        -(self.c.dot(&x))
    }

    /// Noise-free response to a step of size `u` applied at k = 0, from rest.
    pub fn step_response(&self, u: f64, samples: usize) -> Vec<f64> {
        let (ad, bd) = self.discretise();
        let mut x = DVector::<f64>::zeros(self.order);
        let mut y = Vec::with_capacity(samples);
        for _ in 0..samples {
            y.push(self.c.dot(&x));
            x = &ad * &x + &bd * u;
        }
        y
    }
}

/// 1st-order thermometer (Markovsky 2015): pole at −a, unit gain, ts = 1.
pub fn thermometer() -> Sensor {
    let a = 0.35;
    Sensor {
        name: "thermometer (1st order)",
        order: 1,
        a: DMatrix::from_row_slice(1, 1, &[-a]),
        b: DVector::from_row_slice(&[a]),
        c: DVector::from_row_slice(&[1.0]),
        sample_time_s: 1.0,
    }
}

/// 2nd-order mass–spring–damper (m = 1, k = 1, d = 1, load M = 1), ts = 1.
pub fn mass_spring_damper() -> Sensor {
    let (m, k, d, load) = (1.0, 1.0, 1.0, 1.0);
    let mt = m + load;
    Sensor {
        name: "mass-spring-damper (2nd order)",
        order: 2,
        a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -k / mt, -d / mt]),
        b: DVector::from_row_slice(&[0.0, 1.0 / mt]),
        c: DVector::from_row_slice(&[1.0, 0.0]),
        sample_time_s: 1.0,
    }
}

/// 5th-order load cell: 25 Hz, ζ = 0.03 mechanics in series with a 3rd-order 100 Hz
/// Butterworth low-pass, sampled at 4 kHz; output in volts per gram (gain 1e-3).
pub fn load_cell() -> Sensor {
    let wn = 2.0 * core::f64::consts::PI * 25.0;
    let zeta = 0.03;
    let wc = 2.0 * core::f64::consts::PI * 100.0;
    // States: [position, velocity, f1, f2, f3]; Butterworth as a controllable companion
    // form driven by the position: H(s) = wc³ / (s³ + 2wc s² + 2wc² s + wc³).
    let gain = 1e-3;
    #[rustfmt::skip]
    let a = DMatrix::from_row_slice(5, 5, &[
        0.0, 1.0, 0.0, 0.0, 0.0,
        -wn * wn, -2.0 * zeta * wn, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 1.0,
        wc * wc * wc, 0.0, -wc * wc * wc, -2.0 * wc * wc, -2.0 * wc,
    ]);
    Sensor {
        name: "load cell (5th order, 4 kHz)",
        order: 5,
        a,
        b: DVector::from_row_slice(&[0.0, wn * wn * gain, 0.0, 0.0, 0.0]),
        c: DVector::from_row_slice(&[0.0, 0.0, 1.0, 0.0, 0.0]),
        sample_time_s: 1.0 / 4000.0,
    }
}

/// SplitMix64 with Box–Muller: a seeded Gaussian source with no dependencies.
pub struct Gaussian(u64);

impl Gaussian {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn sample(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * core::f64::consts::PI * u2).cos()
    }
}

/// Add white noise at `snr_db`, defined as 20·log10(|G·u| / σ) (thesis eq. 4.39 uses the
/// steady-state level as the signal).
pub fn add_noise(y: &[f64], steady_state: f64, snr_db: f64, seed: u64) -> (Vec<f64>, f64) {
    let sigma = steady_state.abs() / 10f64.powf(snr_db / 20.0);
    let mut g = Gaussian::new(seed);
    (y.iter().map(|v| v + sigma * g.sample()).collect(), sigma)
}

/// The weighted Hankel system of eq. 3.15 (divided by G) for the first `rows_end` samples:
/// rows k = n..rows_end−1 of `[Δx(k−n) … Δx(k−1), 1] θ = x(k)`, each row weighted by
/// sqrt(λ^(last−k)).
pub fn hankel_system(
    x: &[f64],
    order: usize,
    forgetting: f64,
    rows_end: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    let rows = rows_end - order;
    let mut k_mat = DMatrix::<f64>::zeros(rows, order + 1);
    let mut rhs = DVector::<f64>::zeros(rows);
    for (r, k) in (order..rows_end).enumerate() {
        let w = forgetting.powi((rows_end - 1 - k) as i32).sqrt();
        for i in 0..order {
            let j = k - order + i;
            k_mat[(r, i)] = w * (x[j + 1] - x[j]);
        }
        k_mat[(r, order)] = w;
        rhs[r] = w * x[k];
    }
    (k_mat, rhs)
}

/// Batch least squares by Householder QR, with what its accuracy depends on.
pub struct BatchSolution {
    pub theta: DVector<f64>,
    /// 2-norm condition number of K over its numerical rank (∞ never: rank-deficient
    /// directions below ε·σ_max·size are left out, as they do not affect an identifiable u).
    pub cond: f64,
    /// Sensitivity of the last unknown u alone: σ_max · ‖e_uᵀ K⁺‖ (≤ cond).
    pub cond_u: f64,
    /// ‖r‖ / (‖K‖·‖θ‖).
    pub relative_residual: f64,
}

pub fn batch_solve(k_mat: &DMatrix<f64>, rhs: &DVector<f64>) -> BatchSolution {
    let qr = k_mat.clone().qr();
    let qt_b = qr.q().transpose() * rhs;
    let theta = qr
        .r()
        .solve_upper_triangular(&qt_b)
        .unwrap_or_else(|| DVector::from_element(k_mat.ncols(), f64::NAN));
    let svd = k_mat.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let cutoff = smax * f64::EPSILON * (k_mat.nrows().max(k_mat.ncols()) as f64);
    let smin = svd
        .singular_values
        .iter()
        .copied()
        .filter(|s| *s > cutoff)
        .fold(f64::INFINITY, f64::min);
    let pinv = svd.pseudo_inverse(cutoff).expect("U and V were computed");
    let last = pinv.nrows() - 1;
    let cond_u = smax * pinv.row(last).norm();
    let relative_residual = (rhs - k_mat * &theta).norm() / (smax * theta.norm());
    BatchSolution {
        theta,
        cond: smax / smin,
        cond_u,
        relative_residual,
    }
}

/// Relative forward error bound for u from a backward-stable LS solve. A backward error
/// ‖δK‖ ≤ c·ε·‖K‖ moves u by at most ‖e_uᵀK⁺‖·‖δK‖·‖θ‖·(1 + κ·ρ) (Golub & Van Loan
/// §5.3.8, taken for the one component u), so relative to |u|:
/// c·ε·κ_u·(‖θ‖/|u|)·(1 + κ·ρ). The factor ‖θ‖/|u| matters at 4 kHz, where the tiny
/// differences make ℓ large. c = 10·(unknowns) covers the growth constants of Givens and
/// Householder QR.
pub fn ls_tolerance(solution: &BatchSolution) -> f64 {
    let c = 10.0 * (solution.theta.len() as f64);
    let u = solution.theta[solution.theta.len() - 1];
    let scale = solution.theta.norm() / u.abs();
    c * f64::EPSILON * solution.cond_u * scale * (1.0 + solution.cond * solution.relative_residual)
}

/// The thesis's second-order weighing sensor (eq. 4.38): m = 0.015 kg, k_s = 500, k_d = 0.5,
/// M = 0.1 kg, g = 9.81, y = −x₁. The thesis does not state the sample time; like
/// host-sim's published-case test we take ts = 0.01 s, where N = 200 samples still show the
/// transient. The step input is u = M = 0.1 (kg); the static gain is g/k_s.
pub fn thesis_second_order() -> Sensor {
    let (m, ks, kd, big_m, g) = (0.015, 500.0, 0.5, 0.1, 9.81);
    let total = m + big_m;
    Sensor {
        name: "thesis eq. 4.38 (2nd order, N = 200)",
        order: 2,
        a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -ks / total, -kd / total]),
        b: DVector::from_row_slice(&[0.0, -g / total]),
        c: DVector::from_row_slice(&[-1.0, 0.0]),
        sample_time_s: 0.01,
    }
}

/// A random stable sensor: poles inside the unit circle as real poles and complex pairs,
/// realised as a cascade of 1st/2nd-order sections with unit static gain each.
pub fn stable_sensor_response(poles: &[(f64, f64)], gain: f64, u: f64, samples: usize) -> Vec<f64> {
    // Each (r, θ): θ = 0 → a real pole r; θ > 0 → a pair r·e^{±iθ}.
    let mut signal = vec![u; samples];
    for &(r, theta) in poles {
        let mut out = vec![0.0; samples];
        if theta == 0.0 {
            let mut y = 0.0;
            for k in 0..samples {
                out[k] = y;
                y = r * y + (1.0 - r) * signal[k];
            }
        } else {
            let (a1, a2) = (2.0 * r * theta.cos(), -r * r);
            let b = 1.0 - a1 - a2;
            let (mut y1, mut y2) = (0.0, 0.0);
            for k in 0..samples {
                let y = a1 * y1 + a2 * y2 + b * signal[k];
                out[k] = y1;
                y2 = y1;
                y1 = y;
            }
        }
        signal = out;
    }
    signal.iter().map(|v| v * gain).collect()
}

/// The reading contract: an estimate exactly while estimating, every number finite.
pub fn well_formed<T: estimator_core::Real>(reading: &estimator_core::Reading<T>) -> bool {
    reading.estimate.is_some() == (reading.state == estimator_core::State::Estimating)
        && reading.estimate.is_none_or(|v| v.is_finite())
        && reading.residual.is_none_or(|v| v.is_finite())
}

/// The load cell's noise-free response to `mass_g`, in ADC counts at `counts_per_gram`.
pub fn load_cell_counts(mass_g: f64, counts_per_gram: f64, samples: usize) -> Vec<f64> {
    let cell = load_cell();
    let volts_per_gram = cell.static_gain();
    cell.step_response(mass_g, samples)
        .iter()
        .map(|v| v / volts_per_gram * counts_per_gram)
        .collect()
}

/// Pushes the same `samples` into an `f32` and an `f64` estimator and returns the worst
/// relative difference of their `u` wherever both state one, and how many readings that was.
pub fn u_f32_against_f64(
    e32: &mut dyn estimator_core::Estimator<f32>,
    e64: &mut dyn estimator_core::Estimator<f64>,
    samples: impl IntoIterator<Item = f32>,
) -> (f64, usize) {
    let (mut worst, mut compared) = (0.0f64, 0);
    for sample in samples {
        let (a, b) = (e32.push(sample), e64.push(f64::from(sample)));
        if let (Some(u32_), Some(u64_)) = (a.uncertainty, b.uncertainty) {
            worst = worst.max((f64::from(u32_) / u64_ - 1.0).abs());
            compared += 1;
        }
    }
    (worst, compared)
}

/// Pushes `data` into `plain`, with `bad` in place of sample 150 (which latches it), and
/// into each of `others`, which must never state a `u`. Asserts that `plain` states no `u`
/// without an estimate nor from the bad sample on; returns how many readings state one.
pub fn stated_u_around_a_bad_sample(
    plain: &mut dyn estimator_core::Estimator<f64>,
    others: &mut [&mut dyn estimator_core::Estimator<f64>],
    data: &[f64],
    bad: f64,
) -> usize {
    let mut stated = 0;
    for (k, &sample) in data.iter().enumerate() {
        let reading = plain.push(if k == 150 { bad } else { sample });
        assert!(reading.uncertainty.is_none() || reading.estimate.is_some());
        if k >= 150 {
            assert!(reading.is_invalid() && reading.uncertainty.is_none());
        }
        stated += usize::from(reading.uncertainty.is_some());
        for other in others.iter_mut() {
            let reading = other.push(sample);
            assert_eq!(reading.uncertainty, None);
            assert_eq!(reading.degrees_of_freedom, 0);
        }
    }
    stated
}
