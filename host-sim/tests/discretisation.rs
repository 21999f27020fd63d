//! The exact ZOH discretisation against closed-form step responses, and the reference
//! cell's settling time measured from the simulated response.

use host_sim::sensor::{SensorChain, STATES};
use host_sim::StepResponse;

#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }
    fn exp_times(self, t: f64) -> Self {
        let m = (self.re * t).exp();
        Self::new(m * (self.im * t).cos(), m * (self.im * t).sin())
    }
}

/// Step response of K/Π(s − p_j) with K = Π(−p_j) (unit static gain), distinct poles:
/// y(t) = 1 + Σ_i e^{p_i t} / (p_i Π_{j≠i} (p_i − p_j)) · K.
fn analytic_step(poles: &[Complex], t: f64) -> f64 {
    let mut gain = Complex::new(1.0, 0.0);
    for p in poles {
        gain = gain.mul(Complex::new(-p.re, -p.im));
    }
    let mut y = Complex::new(1.0, 0.0);
    for (i, p) in poles.iter().enumerate() {
        let mut denominator = *p;
        for (j, q) in poles.iter().enumerate() {
            if i != j {
                denominator = denominator.mul(p.sub(*q));
            }
        }
        let residue = gain.div(denominator);
        let term = residue.mul(p.exp_times(t));
        y = Complex::new(y.re + term.re, y.im + term.im);
    }
    y.re
}

fn mechanical_poles(chain: &SensorChain, load_g: f64) -> [Complex; 2] {
    let omega = chain.cell.natural_frequency_rad_s(load_g);
    let zeta = chain.cell.damping_ratio(load_g);
    let damped = omega * (1.0 - zeta * zeta).sqrt();
    [
        Complex::new(-zeta * omega, damped),
        Complex::new(-zeta * omega, -damped),
    ]
}

fn filter_poles(chain: &SensorChain) -> [Complex; 3] {
    let wc = 2.0 * std::f64::consts::PI * chain.filter_cutoff_hz;
    let half = 0.5 * wc;
    let imag = wc * 3f64.sqrt() / 2.0;
    [
        Complex::new(-wc, 0.0),
        Complex::new(-half, imag),
        Complex::new(-half, -imag),
    ]
}

#[test]
fn full_chain_matches_the_analytic_5th_order_step_response() {
    let chain = SensorChain::reference();
    for load_g in [20.0, 138.32, 250.0, 600.0] {
        let mut poles = mechanical_poles(&chain, load_g).to_vec();
        poles.extend_from_slice(&filter_poles(&chain));
        let period = 1.0 / chain.sample_rate_hz;
        let mut worst = 0.0_f64;
        for (k, y) in StepResponse::new(&chain, load_g).take(8000).enumerate() {
            let exact = analytic_step(&poles, k as f64 * period);
            worst = worst.max((y / load_g - exact).abs());
        }
        assert!(
            worst <= 1e-9,
            "load {load_g} g: worst relative error {worst:e}"
        );
    }
}

#[test]
fn mechanics_alone_match_the_damped_oscillator() {
    let chain = SensorChain::reference();
    let load_g = 138.32;
    let model = chain.discretise_over(load_g, 1.0 / chain.sample_rate_hz);
    let omega = chain.cell.natural_frequency_rad_s(load_g);
    let zeta = chain.cell.damping_ratio(load_g);
    let damped = omega * (1.0 - zeta * zeta).sqrt();
    let mut state = [0.0; STATES];
    let mut worst = 0.0_f64;
    for k in 0..8000 {
        let t = k as f64 / chain.sample_rate_hz;
        let exact = 1.0
            - (-zeta * omega * t).exp()
                * ((damped * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (damped * t).sin());
        worst = worst.max((state[0] / load_g - exact).abs());
        model.step(&mut state, [load_g, 0.0, 0.0]);
    }
    assert!(worst <= 1e-9, "worst relative error {worst:e}");
}

/// The last time the response is outside ±tolerance of its final value, s.
fn settling_time_s(chain: &SensorChain, load_g: f64, tolerance: f64) -> f64 {
    let mut last_outside = 0;
    for (k, y) in StepResponse::new(chain, load_g).take(20_000).enumerate() {
        if ((y - load_g) / load_g).abs() > tolerance {
            last_outside = k;
        }
    }
    (last_outside + 1) as f64 / chain.sample_rate_hz
}

#[test]
fn reference_cell_settles_to_0_2_percent_in_1_2_to_1_5_s() {
    let chain = SensorChain::reference();
    let settle = settling_time_s(&chain, 138.32, 0.002);
    assert!((1.2..=1.5).contains(&settle), "settling time {settle} s");
    // And it rings near 25 Hz: count the zero crossings of y − final over the first second.
    let response: Vec<f64> = StepResponse::new(&chain, 138.32).take(4000).collect();
    let crossings = response
        .windows(2)
        .filter(|w| (w[0] - 138.32).signum() != (w[1] - 138.32).signum())
        .count();
    let ring_hz = crossings as f64 / 2.0;
    assert!((ring_hz - 25.0).abs() <= 1.0, "rings at {ring_hz} Hz");
}
