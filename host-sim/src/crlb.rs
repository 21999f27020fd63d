//! The Cramér–Rao lower bound on the step level, the floor drawn on every accuracy chart.
//!
//! Model: `y(k) = b + G·u·s(k) + e(k)`, `k = 0..N`, with `s` the unit-step response of the
//! discretised sensor (known model and onset), `G` the static gain and `e` zero-mean
//! Gaussian noise. The Fisher information for `u` gives (thesis §4.1.3):
//! - white noise, known tare `b`: `var(û) ≥ σ² / (G² Σ s(k)²)`;
//! - white noise, unknown tare: the tare's column is profiled out, `Σ s²` becomes the
//!   centred sum `Σ (s(k) − s̄)²`;
//! - coloured noise with covariance `C`: `var(û) ≥ 1 / (G² sᵀC⁻¹s)`. For stationary noise
//!   `sᵀC⁻¹s` is accumulated sample by sample with the Levinson–Durbin recursion (the
//!   innovations form of `C⁻¹`), O(N²) time and O(N) memory, so every prefix length gets its
//!   bound in one pass.
//!
//! The amplifier's noise is coloured by the anti-alias filter:
//! [`amplifier_autocovariance_g2`] gives its autocovariance for the coloured form.
//!
//! With the sensor's initial state unknown (an estimator that fits `[x₀; u]`, as the model
//! bank does, or one that assumes nothing of the state, as the data-driven `ℓ` does) the
//! free responses of the chain's states are profiled out ([`coloured_unknown_state`]). An
//! unknown onset then adds nothing for a window that starts after it: moving the onset
//! moves the output along the impulse response, itself a free response (a test builds
//! the onset's column independently and finds 1e-11 of it outside their span).
//!
//! Every function returns the bound for each prefix length `k + 1`, in the unit of `u`
//! squared (`f64::INFINITY` where the prefix does not identify `u`).
//!
//! What it must never do: go through transfer-function polynomials (the bound uses the exact
//! discretised step response), or report a finite bound for a prefix that cannot identify `u`.

use crate::sensor::SensorChain;
use crate::simulated::StepResponse;

/// The unit-step response `s(k)` of `chain` for a step of `step_g` (s → 1), `samples` long.
pub fn unit_step_response(chain: &SensorChain, step_g: f64, samples: usize) -> Vec<f64> {
    StepResponse::new(chain, step_g)
        .take(samples)
        .map(|value| value / step_g)
        .collect()
}

/// Known model, onset and tare, white noise of variance `noise_variance` (raw units²).
pub fn white_known_tare(unit_step: &[f64], gain: f64, noise_variance: f64) -> Vec<f64> {
    let mut energy = 0.0;
    unit_step
        .iter()
        .map(|s| {
            energy += s * s;
            bound(noise_variance, gain * gain * energy)
        })
        .collect()
}

/// Known model and onset, unknown tare, white noise: the centred form.
pub fn white_unknown_tare(unit_step: &[f64], gain: f64, noise_variance: f64) -> Vec<f64> {
    // Welford's running centred sum of squares.
    let mut mean = 0.0;
    let mut centred = 0.0;
    unit_step
        .iter()
        .enumerate()
        .map(|(index, &s)| {
            let count = (index + 1) as f64;
            let delta = s - mean;
            mean += delta / count;
            centred += delta * (s - mean);
            bound(noise_variance, gain * gain * centred)
        })
        .collect()
}

/// Known model, onset and tare, stationary coloured noise with autocovariance
/// `autocovariance[lag]` (raw units², at least as long as `unit_step`).
pub fn coloured_known_tare(unit_step: &[f64], gain: f64, autocovariance: &[f64]) -> Vec<f64> {
    let n = unit_step.len().min(autocovariance.len());
    let mut bounds = Vec::with_capacity(n);
    let mut whitener = Innovations::new(autocovariance, n);
    let mut information = 0.0;
    for k in 0..n {
        whitener.advance(k);
        let innovation = whitener.innovation(unit_step, k);
        information += innovation * innovation / whitener.error;
        bounds.push(bound(1.0, gain * gain * information));
    }
    bounds
}

/// The innovations form of stationary noise's inverse covariance, one sample at a time:
/// the Levinson–Durbin predictor of order `k` and its prediction-error variance.
struct Innovations<'a> {
    autocovariance: &'a [f64],
    /// `predictor[i]` predicts y(k) from y(k−1−i).
    predictor: Vec<f64>,
    /// The innovation variance at the current order.
    error: f64,
}

impl<'a> Innovations<'a> {
    fn new(autocovariance: &'a [f64], capacity: usize) -> Self {
        Self {
            autocovariance,
            predictor: Vec::with_capacity(capacity),
            error: autocovariance.first().copied().unwrap_or(0.0),
        }
    }

    /// Raise the predictor to order `k` (a Levinson–Durbin step from order k−1; nothing at
    /// k = 0).
    fn advance(&mut self, k: usize) {
        if k == 0 {
            return;
        }
        let r = self.autocovariance;
        let mut acc = r[k];
        for (i, a) in self.predictor.iter().enumerate() {
            acc -= a * r[k - 1 - i];
        }
        let reflection = acc / self.error;
        let previous = self.predictor.clone();
        for i in 0..previous.len() {
            self.predictor[i] = previous[i] - reflection * previous[previous.len() - 1 - i];
        }
        self.predictor.push(reflection);
        self.error *= 1.0 - reflection * reflection;
    }

    /// The whitened value of `column` at sample `k` (its innovation).
    fn innovation(&self, column: &[f64], k: usize) -> f64 {
        let mut innovation = column[k];
        for (i, a) in self.predictor.iter().enumerate() {
            innovation -= a * column[k - 1 - i];
        }
        innovation
    }
}

/// The output (g) of the sensor `chain` carrying `load_g` released from each unit initial
/// state (1 in one state, 0 in the others, no input), `samples` long: the columns an
/// unknown initial state adds to the step's regression (see [`coloured_unknown_state`]).
pub fn free_responses(
    chain: &SensorChain,
    load_g: f64,
    samples: usize,
) -> [Vec<f64>; crate::sensor::STATES] {
    // The same discretisation as `unit_step_response`: one output per sample.
    let model = chain.discretise_over(load_g, 1.0 / chain.sample_rate_hz);
    core::array::from_fn(|state| {
        let mut x = [0.0; crate::sensor::STATES];
        x[state] = 1.0;
        (0..samples)
            .map(|_| model.step(&mut x, [0.0; crate::sensor::INPUTS]))
            .collect()
    })
}

/// Known model, onset and tare, the sensor's initial state unknown (what a model-based
/// estimator that fits `[x₀; u]` does not assume): the bound on `u` with the columns of
/// `nuisance` (the free responses, [`free_responses`]) profiled out, for stationary noise
/// with autocovariance `autocovariance[lag]` (raw units²; `[σ², 0, …]` for white noise).
/// Each column is whitened by the same Levinson–Durbin innovations as in
/// [`coloured_known_tare`] (`Innovations`); the information matrix of `[u; x₀]` is accumulated and its
/// inverse's first element taken per prefix. Never below the known-state bound.
pub fn coloured_unknown_state(
    unit_step: &[f64],
    nuisance: &[Vec<f64>],
    gain: f64,
    autocovariance: &[f64],
) -> Vec<f64> {
    let columns: Vec<&[f64]> = std::iter::once(unit_step)
        .chain(nuisance.iter().map(Vec::as_slice))
        .collect();
    let p = columns.len();
    let n = columns
        .iter()
        .map(|c| c.len())
        .min()
        .unwrap_or(0)
        .min(autocovariance.len());
    let mut bounds = Vec::with_capacity(n);
    let mut whitener = Innovations::new(autocovariance, n);
    let mut information = vec![vec![0.0; p]; p];
    let mut innovation = vec![0.0; p];
    for k in 0..n {
        whitener.advance(k);
        for (w, column) in innovation.iter_mut().zip(&columns) {
            *w = whitener.innovation(column, k);
        }
        for (row, &wr) in information.iter_mut().zip(&innovation) {
            for (cell, &wc) in row.iter_mut().zip(&innovation) {
                *cell += gain * gain * wr * wc / whitener.error;
            }
        }
        bounds.push(first_of_inverse(&information));
    }
    bounds
}

/// `(J⁻¹)₀₀` of a symmetric information matrix, by nalgebra's Cholesky factor of its
/// unit-diagonal scaling (infinite when `J` is not positive definite to 1e-12 relative:
/// the prefix does not identify every parameter, or the columns are not yet independent).
fn first_of_inverse(information: &[Vec<f64>]) -> f64 {
    let p = information.len();
    let scale: Vec<f64> = (0..p).map(|i| information[i][i].sqrt()).collect();
    if scale.iter().any(|s| !(*s > 0.0)) {
        return f64::INFINITY;
    }
    // (D⁻¹ J D⁻¹)⁻¹₀₀ / J₀₀ = (J⁻¹)₀₀.
    let scaled = nalgebra::DMatrix::from_fn(p, p, |i, j| information[i][j] / (scale[i] * scale[j]));
    let Some(factor) = scaled.cholesky() else {
        return f64::INFINITY;
    };
    if factor.l_dirty().diagonal().iter().any(|d| !(d * d > 1e-12)) {
        return f64::INFINITY;
    }
    let mut unit = nalgebra::DVector::zeros(p);
    unit[0] = 1.0;
    factor.solve(&unit)[0] / (scale[0] * scale[0])
}

/// The autocovariance (g², lags `0..lags`) at the filter output of the INA114's input noise,
/// white over one conversion period with the variance of
/// [`SensorChain::amplifier_noise_g`], coloured by the anti-alias filter:
/// `r(l) = σ² Σ_j h(j)·h(j+l)` with `h` the discretised impulse response.
pub fn amplifier_autocovariance_g2(chain: &SensorChain, lags: usize) -> Vec<f64> {
    // The noise enters the filter only, so the load does not matter; 0.25 s of impulse
    // response is ~150 time constants of the 100 Hz filter.
    let model = chain.discretise(0.0);
    let length = (0.25 / chain.conversion_period_s()) as usize + lags;
    let mut state = [0.0; crate::sensor::STATES];
    let mut impulse = Vec::with_capacity(length);
    for k in 0..length {
        let input = if k == 0 { 1.0 } else { 0.0 };
        impulse.push(model.step(&mut state, [0.0, 0.0, input]));
    }
    let variance = chain.amplifier_noise_g().powi(2);
    (0..lags)
        .map(|lag| {
            variance
                * impulse
                    .iter()
                    .zip(impulse.iter().skip(lag))
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
        })
        .collect()
}

fn bound(numerator: f64, information: f64) -> f64 {
    if information > 0.0 {
        numerator / information
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coloured_with_white_covariance_equals_white() {
        let s: Vec<f64> = (0..50).map(|k| 1.0 - (-(k as f64) / 7.0).exp()).collect();
        let mut r = vec![0.0; 50];
        r[0] = 2.5;
        let white = white_known_tare(&s, 3.0, 2.5);
        let coloured = coloured_known_tare(&s, 3.0, &r);
        for (a, b) in white.iter().zip(&coloured).skip(1) {
            assert!((a - b).abs() <= 1e-12 * a, "{a} {b}");
        }
    }

    #[test]
    fn coloured_matches_a_dense_inverse_for_ar1() {
        // AR(1) noise, φ = 0.8: C⁻¹ is known in closed form (tridiagonal); compare sᵀC⁻¹s.
        let phi: f64 = 0.8;
        let innovation_variance = 1.0;
        let n = 40;
        let r: Vec<f64> = (0..n)
            .map(|lag| innovation_variance / (1.0 - phi * phi) * phi.powi(lag as i32))
            .collect();
        let s: Vec<f64> = (0..n).map(|k| (k as f64 * 0.3).sin() + 1.0).collect();
        let mut quadratic = s[0] * s[0] * (1.0 - phi * phi);
        for k in 1..n {
            let w = s[k] - phi * s[k - 1];
            quadratic += w * w;
        }
        let expected = 1.0 / quadratic;
        let got = *coloured_known_tare(&s, 1.0, &r).last().unwrap();
        assert!(
            (got - expected).abs() <= 1e-10 * expected,
            "{got} {expected}"
        );
    }

    #[test]
    fn an_unknown_state_is_profiled_out_exactly_and_never_lowers_the_bound() {
        // Without nuisance columns the unknown-state bound is the known one.
        let s: Vec<f64> = (0..60).map(|k| 1.0 - (-(k as f64) / 9.0).exp()).collect();
        let mut r = vec![0.0; 60];
        r[0] = 1.7;
        let known = coloured_known_tare(&s, 2.0, &r);
        let alone = coloured_unknown_state(&s, &[], 2.0, &r);
        for (a, b) in known.iter().zip(&alone) {
            assert!(a == b || (a - b).abs() <= 1e-12 * a, "{a} {b}");
        }
        // One nuisance column, white noise: the closed form of the 2 × 2 Schur complement,
        // σ² / (G² (Σs² − (Σsf)²/Σf²)), and never below the known bound.
        let f: Vec<f64> = (0..60).map(|k| (-(k as f64) / 5.0).exp()).collect();
        let with = coloured_unknown_state(&s, std::slice::from_ref(&f), 2.0, &r);
        let (mut ss, mut sf, mut ff) = (0.0, 0.0, 0.0);
        for k in 0..60 {
            ss += s[k] * s[k];
            sf += s[k] * f[k];
            ff += f[k] * f[k];
            let expected = 1.7 / (4.0 * (ss - sf * sf / ff));
            if k >= 2 {
                assert!(
                    (with[k] - expected).abs() <= 1e-9 * expected,
                    "{k}: {} {expected}",
                    with[k]
                );
                assert!(with[k] >= known[k]);
            }
        }
        // A nuisance column equal to the step's leaves u unidentified.
        let same = coloured_unknown_state(&s, std::slice::from_ref(&s), 2.0, &r);
        assert!(same.iter().all(|b| b.is_infinite()));
    }

    #[test]
    fn the_free_responses_and_the_step_response_span_every_start_of_the_sensor() {
        // Superposition: the reference chain started in an arbitrary state and stepped by
        // 138.32 g outputs exactly u·s(k) + Σ x₀ⱼ·fⱼ(k), so profiling the fⱼ out is the
        // bound of an estimator that fits the state with the step.
        let chain = crate::scene::Scene::load("reference-step").unwrap().chain;
        let (load, samples) = (138.32, 400);
        let s = unit_step_response(&chain, load, samples);
        let free = free_responses(&chain, load, samples);
        let start = [3.0, -0.7, 12.5, -4.0, 0.9];
        let model = chain.discretise_over(load, 1.0 / chain.sample_rate_hz);
        let mut x = start;
        for k in 0..samples {
            let y = model.step(&mut x, [load, 0.0, 0.0]);
            let sum = load * s[k] + (0..start.len()).map(|j| start[j] * free[j][k]).sum::<f64>();
            assert!((y - sum).abs() <= 1e-9 * load, "{k}: {y} {sum}");
        }
    }

    /// The part of `column` no combination of `basis` explains, relative to its norm
    /// (modified Gram–Schmidt in f64).
    fn unexplained(column: &[f64], basis: &[Vec<f64>]) -> f64 {
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut orthonormal: Vec<Vec<f64>> = Vec::new();
        for vector in basis {
            let mut v = vector.clone();
            for q in &orthonormal {
                let c = dot(&v, q);
                v.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
            }
            let norm = dot(&v, &v).sqrt();
            if norm > 0.0 {
                orthonormal.push(v.iter().map(|x| x / norm).collect());
            }
        }
        let mut r = column.to_vec();
        for q in &orthonormal {
            let c = dot(&r, q);
            r.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
        }
        (dot(&r, &r) / dot(column, column)).sqrt()
    }

    /// With the initial state unknown, an unknown onset (within the first sample period)
    /// adds nothing: shifting the onset moves the output along the chain's impulse
    /// response, which is a free response of the state the load's input sets. So the bound
    /// with the initial state unknown is also the bound with the onset and the initial
    /// state unknown, for a window that starts after the landing. The onset's column here
    /// is the central difference of step responses whose onset is moved by ±δ inside the
    /// first sample period, built from the chain's exact discretisation over fractions of
    /// a period, not from the free responses; the step itself is not in their span.
    #[test]
    fn an_unknown_onset_adds_nothing_once_the_initial_state_is_unknown() {
        let chain = crate::scene::Scene::load("reference-step").unwrap().chain;
        let (load, samples) = (138.32, 400);
        let period = 1.0 / chain.sample_rate_hz;
        let delta = 1e-3 * period;
        let model = chain.discretise_over(load, period);
        // A step at +δ after sample 0: the first period holds the load for T − δ only.
        let late = {
            let part = chain.discretise_over(load, period - delta);
            let mut x = [0.0; crate::sensor::STATES];
            let mut out = vec![0.0];
            for (row, value) in x.iter_mut().enumerate() {
                *value = part.input[row][0] * load;
            }
            for _ in 1..samples {
                out.push(model.step(&mut x, [load, 0.0, 0.0]));
            }
            out
        };
        // A step at −δ: the state at sample 0 already holds δ of it.
        let early = {
            let part = chain.discretise_over(load, delta);
            let mut x = [0.0; crate::sensor::STATES];
            for (row, value) in x.iter_mut().enumerate() {
                *value = part.input[row][0] * load;
            }
            (0..samples)
                .map(|_| model.step(&mut x, [load, 0.0, 0.0]))
                .collect::<Vec<f64>>()
        };
        let onset: Vec<f64> = late
            .iter()
            .zip(&early)
            .map(|(a, b)| (a - b) / (2.0 * delta))
            .collect();
        let free = free_responses(&chain, load, samples);
        let onset_left = unexplained(&onset, &free);
        assert!(
            onset_left < 1e-5,
            "the onset's column: {onset_left:e} unexplained"
        );
        let step = unit_step_response(&chain, load, samples);
        let step_left = unexplained(&step, &free);
        assert!(
            step_left > 0.1,
            "the step's column: {step_left:e} unexplained"
        );
    }

    #[test]
    fn unknown_tare_is_never_below_known_tare() {
        let s: Vec<f64> = (0..100).map(|k| 1.0 - (-(k as f64) / 20.0).exp()).collect();
        let known = white_known_tare(&s, 1.0, 1.0);
        let unknown = white_unknown_tare(&s, 1.0, 1.0);
        assert!(unknown[0].is_infinite());
        for (a, b) in known.iter().zip(&unknown).skip(1) {
            assert!(b >= a);
        }
    }
}
