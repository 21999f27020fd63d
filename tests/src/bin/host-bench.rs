//! Host throughput of the step estimator: updates per second for n = 2..12 in `f32` and
//! `f64`, and `size_of` on the host. Run in release (`cargo xtask bench` does); it prints
//! figures and asserts nothing.
//!
//! Each figure times only full regression updates (D = 1, λ = 1): per load the estimator is
//! reset, the first samples of the stored step response are pushed untimed (warm-up), the
//! rest are timed; loads repeat until [`ROUND_TIME`] of timed pushing has accumulated. The
//! figure is the best of [`ROUNDS`] rounds: the machine is shared (2 cores, parallel builds),
//! and interference only ever makes a round slower.

use std::hint::black_box;
use std::time::{Duration, Instant};

use estimator_core::{Estimator, Real, StepConfig, StepEstimator};
use tests::core_check::{self, cases::GAIN_PER_G};

/// Samples pushed untimed after each reset (covers warm-up up to n = 12: 2n + 1 = 25).
const UNTIMED_SAMPLES: usize = 200;
/// Timed pushing per round.
const ROUND_TIME: Duration = Duration::from_millis(60);
/// Rounds per (type, order) figure; the fastest counts.
const ROUNDS: usize = 5;

fn updates_per_second<T: Real, const N: usize>(response: &[f32]) -> f64 {
    let samples: Vec<T> = response
        .iter()
        .map(|&s| T::from_f64(f64::from(s)))
        .collect();
    let config = StepConfig::new(N, T::from_f64(f64::from(GAIN_PER_G)));
    let mut estimator = match StepEstimator::<T, N>::new(config) {
        Ok(estimator) => estimator,
        Err(error) => panic!("order {N} refused: {error}"),
    };
    let mut best = 0.0f64;
    for _ in 0..ROUNDS {
        best = best.max(one_round(&mut estimator, &samples));
    }
    best
}

fn one_round<T: Real, const N: usize>(estimator: &mut StepEstimator<T, N>, samples: &[T]) -> f64 {
    let mut timed = Duration::ZERO;
    let mut updates = 0u64;
    while timed < ROUND_TIME {
        estimator.reset();
        for &sample in &samples[..UNTIMED_SAMPLES] {
            black_box(estimator.push(sample));
        }
        let started = Instant::now();
        for &sample in &samples[UNTIMED_SAMPLES..] {
            black_box(estimator.push(black_box(sample)));
        }
        timed += started.elapsed();
        updates += (samples.len() - UNTIMED_SAMPLES) as u64;
    }
    updates as f64 / timed.as_secs_f64()
}

fn row<const N: usize>(response: &[f32]) {
    let single = updates_per_second::<f32, N>(response);
    let double = updates_per_second::<f64, N>(response);
    println!(
        "  {:>2} {:>14.2} {:>14.2} {:>10.2} {:>14} {:>14}",
        N,
        single / 1e6,
        double / 1e6,
        single / double,
        std::mem::size_of::<StepEstimator<f32, N>>(),
        std::mem::size_of::<StepEstimator<f64, N>>(),
    );
}

fn main() {
    let stored = std::fs::read(core_check::response_path()).expect("read the stored response");
    let response = core_check::decode_response(&stored);
    println!(
        "host ({} {}): StepEstimator<T, n> at order n, D = 1, λ = 1, best of {ROUNDS} rounds of {} ms",
        std::env::consts::ARCH,
        std::env::consts::OS,
        ROUND_TIME.as_millis()
    );
    println!("   n  f32 Mupdates/s  f64 Mupdates/s  f32/f64  size_of f32 B  size_of f64 B  (host sizes; usize is 8 B here)");
    row::<2>(&response);
    row::<3>(&response);
    row::<4>(&response);
    row::<5>(&response);
    row::<6>(&response);
    row::<7>(&response);
    row::<8>(&response);
    row::<9>(&response);
    row::<10>(&response);
    row::<11>(&response);
    row::<12>(&response);
}
