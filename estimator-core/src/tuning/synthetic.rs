//! The Monte Carlo of calibration: seeded synthetic drops of the identified model with the
//! measured noise, the score of a method on them, and the order statistic that makes "the
//! 95th percentile is within the target" a statement with a confidence.
//!
//! ## Noise that can be jumped into
//! Every synthetic sample's noise is a function of `(seed, run, sample index)` only: a
//! SplitMix64 finaliser (Steele, Lea & Flood 2014) of a counter gives two uniforms, Box–Muller
//! turns them into a normal deviate. So a run can be replayed from any sample (the estimator
//! starts at the detected onset) without storing it and without replaying the generator, and
//! every method sees exactly the same drops (common random numbers: differences between
//! methods are not Monte Carlo noise).
//!
//! ## The percentile with a confidence
//! With `R` runs and `X ~ Bin(R, 0.95)` the number of runs below the true 95th percentile
//! `q`, the `j`-th smallest |error| is at least `q` with probability `P(X < j)`. The smallest
//! `j` with `P(X ≥ j) ≤ 0.05` makes `e_(j)` an upper 95% confidence bound on `q` for any
//! error distribution ([`upper_order_statistic`]); at `R = 400`, `j = 388`. A method meets
//! the target when `e_(j) ≤ target`, i.e. when at most `R − j` runs (12 of 400) are outside
//! it. Once more runs than that are outside, the method cannot meet the target and its
//! remaining runs are skipped. `R` must be at least 59 (`0.95⁵⁹ < 0.05`).

use crate::estimators::model::SensorModel;
use crate::numerics::real::Real;
use crate::reading::Estimator;

use crate::weighing::Prediction;

const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 finaliser: a bijective mix of 64 bits.
pub fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The key of run `run` of a study seeded `seed`.
pub fn run_key(seed: u64, run: u64) -> u64 {
    mix(mix(seed) ^ mix(run.wrapping_mul(GOLDEN_GAMMA).wrapping_add(1)))
}

/// The standard normal deviate of sample `index` of the run with key `key`.
pub fn gaussian(key: u64, index: u64) -> f64 {
    let counter = index.wrapping_mul(2);
    let a = mix(key.wrapping_add(counter.wrapping_add(1).wrapping_mul(GOLDEN_GAMMA)));
    let b = mix(key.wrapping_add(counter.wrapping_add(2).wrapping_mul(GOLDEN_GAMMA)));
    const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
    // u1 in (0, 1): never 0, so the logarithm is finite.
    let u1 = ((a >> 11) as f64 + 0.5) * SCALE;
    let u2 = (b >> 11) as f64 * SCALE;
    libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
}

/// The smallest `j` (1-based) such that the `j`-th smallest of `runs` samples is an upper
/// bound on the `quantile` with confidence `confidence`: `P(Bin(runs, quantile) ≥ j) ≤
/// 1 − confidence`. `None` when even the largest sample is not (too few runs).
pub fn upper_order_statistic(runs: usize, quantile: f64, confidence: f64) -> Option<usize> {
    if runs == 0 || !(quantile > 0.0 && quantile < 1.0) || !(confidence > 0.0 && confidence < 1.0) {
        return None;
    }
    let alpha = 1.0 - confidence;
    let n = runs as f64;
    let log_ratio = libm::log((1.0 - quantile) / quantile);
    // Walk down from k = runs: ln pmf(k − 1) = ln pmf(k) + ln(k/(n − k + 1)) + ln((1−q)/q).
    let mut log_pmf = n * libm::log(quantile);
    let mut tail = libm::exp(log_pmf);
    if tail > alpha {
        return None;
    }
    let mut j = runs;
    while j > 1 {
        let k = j as f64;
        let next_log_pmf = log_pmf + libm::log(k / (n - k + 1.0)) + log_ratio;
        let next_tail = tail + libm::exp(next_log_pmf);
        if next_tail > alpha {
            break;
        }
        log_pmf = next_log_pmf;
        tail = next_tail;
        j -= 1;
    }
    Some(j)
}

/// The least number of runs for which [`upper_order_statistic`] exists at 95%/95%.
pub const MIN_RUNS: usize = 59;

/// One synthetic run: where its onset was detected, its zero, and the method's error.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunSlot {
    /// The run's index (its noise key is `run_key(seed, run)`).
    pub run: u32,
    /// The detected onset; `u32::MAX` when the detection failed.
    pub onset: u32,
    /// The zero the run's empty stretch gave, raw units.
    pub zero: f64,
    /// The error of the method being scored at the readout, g (infinite: no valid reading).
    pub error_g: f64,
}

impl RunSlot {
    /// A slot before the runs are prepared (for `[RunSlot::EMPTY; R]`).
    pub const EMPTY: Self = Self {
        run: 0,
        onset: u32::MAX,
        zero: 0.0,
        error_g: f64::INFINITY,
    };
}

impl Default for RunSlot {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// Synthetic drops of a model: `empty` samples of noise around zero, then the response to a
/// step of `mass_g` from rest, `length` samples in all.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Synthetic<const S: usize> {
    /// The model in raw units per gram (`C` carries the gain the drops showed).
    pub model: SensorModel<f64, S>,
    pub mass_g: f64,
    /// White noise standard deviation, raw units.
    pub sigma: f64,
    pub empty: usize,
    pub length: usize,
}

impl<const S: usize> Synthetic<S> {
    /// The run with key `key` from sample `from` on.
    pub fn samples(&self, key: u64, from: usize) -> Samples<'_, S> {
        // Before the drop the model is at rest, so a replay can start anywhere up to it.
        let start = from.min(self.empty);
        Samples {
            synthetic: self,
            key,
            index: start,
            from,
            state: [0.0; S],
        }
    }
}

pub(crate) struct Samples<'a, const S: usize> {
    synthetic: &'a Synthetic<S>,
    key: u64,
    index: usize,
    from: usize,
    state: [f64; S],
}

impl<const S: usize> Iterator for Samples<'_, S> {
    type Item = f64;

    fn next(&mut self) -> Option<f64> {
        let synthetic = self.synthetic;
        loop {
            let index = self.index;
            if index >= synthetic.length {
                return None;
            }
            self.index += 1;
            let clean = if index < synthetic.empty {
                0.0
            } else {
                let m = &synthetic.model;
                let mut y = 0.0;
                let mut next = [0.0; S];
                for r in 0..S {
                    y += m.c[r] * self.state[r];
                    next[r] = m.b[r] * synthetic.mass_g;
                    for c in 0..S {
                        next[r] += m.a[r][c] * self.state[c];
                    }
                }
                self.state = next;
                y
            };
            if index >= self.from {
                return Some(clean + synthetic.sigma * gaussian(self.key, index as u64));
            }
        }
    }
}

/// What scoring needs besides the method.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scoring {
    pub readout_samples: usize,
    pub target_g: f64,
    /// `j` of [`upper_order_statistic`] for the slots' count.
    pub upper_index: usize,
    /// Failing methods still run this many runs (so their percentile means something).
    pub min_runs: usize,
}

/// Run `estimator` (reset before each run) over the prepared runs and summarise its errors
/// at the readout. Each run is estimated twice, from the detected onset and from the landing
/// itself (the two ends of where a scale may start it), and keeps the larger |error|: a
/// model of too low an order can meet a target from one start and miss it by far from the
/// other (host-sim's README: `n = 2, D = 32` on the reference cell). The slots come back
/// sorted by run.
pub(crate) fn score<T: Real, E: Estimator<T>, const S: usize>(
    estimator: &mut E,
    synthetic: &Synthetic<S>,
    seed: u64,
    slots: &mut [RunSlot],
    scoring: &Scoring,
) -> Prediction {
    slots.sort_unstable_by_key(|slot| slot.run);
    let planned = slots.len();
    let allowed_outside = planned - scoring.upper_index;
    let readout_index = synthetic.empty + scoring.readout_samples;
    let (mut done, mut outside, mut valid, mut failures) = (0usize, 0usize, 0u32, 0u32);
    let (mut sum, mut sum_squares) = (0.0, 0.0);
    for slot in slots.iter_mut() {
        if outside > allowed_outside && done >= scoring.min_runs {
            break;
        }
        done += 1;
        slot.error_g = f64::INFINITY;
        if slot.onset == u32::MAX {
            failures += 1;
            outside += 1;
            continue;
        }
        let key = run_key(seed, u64::from(slot.run));
        let mut worst = Some(0.0f64);
        for start in [slot.onset as usize, synthetic.empty] {
            estimator.reset();
            let mut last = None;
            if start <= readout_index {
                let samples = synthetic
                    .samples(key, start)
                    .take(readout_index + 1 - start);
                for y in samples {
                    last = estimator.push(T::from_f64(y - slot.zero)).estimate;
                }
            }
            worst = match (worst, last) {
                (Some(error), Some(estimate)) if estimate.is_finite() => {
                    let this = estimate.to_f64() - synthetic.mass_g;
                    Some(if libm::fabs(this) > libm::fabs(error) {
                        this
                    } else {
                        error
                    })
                }
                _ => None,
            };
        }
        match worst {
            Some(error) => {
                slot.error_g = error;
                valid += 1;
                sum += error;
                sum_squares += error * error;
                if !(libm::fabs(error) <= scoring.target_g) {
                    outside += 1;
                }
            }
            None => outside += 1,
        }
    }
    let used = &mut slots[..done];
    used.sort_unstable_by(|a, b| libm::fabs(a.error_g).total_cmp(&libm::fabs(b.error_g)));
    let order_statistic = |j: usize| libm::fabs(used[j.clamp(1, done) - 1].error_g);
    let p95_index = libm::ceil(0.95 * done as f64) as usize;
    let n = f64::from(valid.max(1));
    Prediction {
        runs: done as u32,
        planned_runs: planned as u32,
        valid_runs: valid,
        within_target_runs: (done - outside) as u32,
        detection_failures: failures,
        bias_g: sum / n,
        rms_g: libm::sqrt(sum_squares / n),
        p95_g: order_statistic(p95_index),
        p95_upper_g: if done == planned {
            order_statistic(scoring.upper_index)
        } else {
            f64::INFINITY
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_deviates_have_the_right_moments_and_are_reproducible() {
        // 200,000 deviates: the mean's standard error is 0.0022, the variance's 0.0032, the
        // fourth moment's (var z⁴ = 96) 0.022; 5 of each.
        let n = 200_000u64;
        let (mut m1, mut m2, mut m4, mut beyond) = (0.0, 0.0, 0.0, 0u32);
        for k in 0..n {
            let z = gaussian(run_key(7, k / 1000), k % 1000);
            m1 += z;
            m2 += z * z;
            m4 += z * z * z * z;
            if z.abs() > 1.959_964 {
                beyond += 1;
            }
        }
        let nf = n as f64;
        assert!((m1 / nf).abs() < 0.011, "{}", m1 / nf);
        assert!((m2 / nf - 1.0).abs() < 0.016, "{}", m2 / nf);
        assert!((m4 / nf - 3.0).abs() < 0.11, "{}", m4 / nf);
        // 5% two-sided tail: 10,000 expected, binomial sd 97.
        assert!((f64::from(beyond) - 10_000.0).abs() < 500.0, "{beyond}");
        assert_eq!(gaussian(run_key(1, 2), 3), gaussian(run_key(1, 2), 3));
        assert_ne!(gaussian(run_key(1, 2), 3), gaussian(run_key(1, 3), 3));
        assert_ne!(gaussian(run_key(1, 2), 3), gaussian(run_key(2, 2), 3));
    }

    /// P(Bin(n, p) ≥ j) summed directly, for checking.
    fn tail(n: usize, p: f64, j: usize) -> f64 {
        let mut total = 0.0;
        for k in j..=n {
            let mut log_choose = 0.0;
            for i in 0..k {
                log_choose += libm::log((n - i) as f64) - libm::log((i + 1) as f64);
            }
            total += libm::exp(
                log_choose + k as f64 * libm::log(p) + (n - k) as f64 * libm::log(1.0 - p),
            );
        }
        total
    }

    #[test]
    fn the_upper_order_statistic_is_the_smallest_with_the_confidence() {
        assert_eq!(upper_order_statistic(58, 0.95, 0.95), None);
        assert_eq!(upper_order_statistic(MIN_RUNS, 0.95, 0.95), Some(59));
        for runs in [59usize, 100, 200, 400, 1000] {
            let j = upper_order_statistic(runs, 0.95, 0.95).unwrap();
            assert!(tail(runs, 0.95, j) <= 0.05, "{runs}: {j}");
            assert!(tail(runs, 0.95, j - 1) > 0.05, "{runs}: {j}");
        }
        assert_eq!(upper_order_statistic(400, 0.95, 0.95), Some(388));
        assert_eq!(upper_order_statistic(0, 0.95, 0.95), None);
        assert_eq!(upper_order_statistic(100, f64::NAN, 0.95), None);
    }

    #[test]
    fn a_replay_from_any_sample_gives_the_same_samples() {
        let model = SensorModel {
            a: [[0.9, 0.1], [-0.1, 0.9]],
            b: [0.1, 0.0],
            c: [10.0, 0.0],
        };
        let synthetic = Synthetic {
            model,
            mass_g: 5.0,
            sigma: 0.3,
            empty: 20,
            length: 60,
        };
        let key = run_key(3, 4);
        let mut whole = [0.0; 60];
        for (slot, y) in whole.iter_mut().zip(synthetic.samples(key, 0)) {
            *slot = y;
        }
        assert_eq!(synthetic.samples(key, 0).count(), 60);
        for from in [0usize, 7, 20, 21, 45, 59] {
            for (k, y) in synthetic.samples(key, from).enumerate() {
                assert_eq!(y, whole[from + k], "from {from}, k {k}");
            }
        }
        // The empty stretch is noise around zero; the first sample of the drop is 0 + noise
        // (the state is at rest when the mass lands).
        assert_eq!(whole[20], 0.3 * gaussian(key, 20));
        assert!(whole[21] != 0.3 * gaussian(key, 21));
    }
}
