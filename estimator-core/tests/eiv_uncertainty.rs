//! The standard uncertainty `u` of the errors-in-variables variants (instrumental variables,
//! bias compensation): ±2u covers 95 % of the errors where the method is valid, `f32`
//! states the `f64` `u`, and no `u` comes without an estimate.
//!
//! Coverage is the fraction of runs with |error| ≤ 2u among those that state a `u`, at a
//! few readout times, over seeded Monte Carlo runs: at 400 runs the 2σ band of a 95 %
//! proportion is ±2.2 %, so the asserted band 95 ± 4 % leaves the goal's ±3 % and the
//! band's own width, not more. The wider study:
//! `cargo test --release -p estimator-core --test eiv_uncertainty -- --ignored --nocapture`.

mod support;

use estimator_core::{Estimator, IvConfig, IvStepEstimator, StepConfig};
use support::*;

/// The load cell of `tests/eiv.rs`: 138.32 g at 73.2547 counts/g, σ = 0.445 g (50 dB).
const COUNTS_PER_GRAM: f64 = 73.2547;
const MASS_G: f64 = 138.32;
const SIGMA_G: f64 = 0.445;

/// Coverage at one readout time.
#[derive(Clone, Copy, Debug, Default)]
struct Cell {
    /// Runs whose reading there has an estimate.
    estimated: u32,
    /// Runs whose reading there states a `u`.
    stated: u32,
    /// Of those, runs with |error| ≤ 2u.
    covered: u32,
    /// Σ (error/u)².
    z_square_sum: f64,
}

impl Cell {
    fn coverage(&self) -> f64 {
        f64::from(self.covered) / f64::from(self.stated)
    }

    fn rms_z(&self) -> f64 {
        (self.z_square_sum / f64::from(self.stated)).sqrt()
    }
}

/// Runs `runs` noisy copies of `clean` (σ `sigma`, seeds from `seed`) through estimators
/// from `make`, and tallies the readings after `readouts` samples against `truth`.
fn coverage<E: Estimator<f64>>(
    clean: &[f64],
    sigma: f64,
    truth: f64,
    readouts: &[usize],
    runs: u64,
    seed: u64,
    mut make: impl FnMut() -> E,
) -> Vec<Cell> {
    let mut cells = vec![Cell::default(); readouts.len()];
    let mut noise = Gaussian::new(seed);
    for _ in 0..runs {
        let mut estimator = make();
        for (k, &value) in clean.iter().enumerate() {
            let reading = estimator.push(value + sigma * noise.sample());
            assert!(reading.uncertainty.is_none() || reading.estimate.is_some());
            let Some(index) = readouts.iter().position(|&r| r == k + 1) else {
                continue;
            };
            let cell = &mut cells[index];
            let Some(estimate) = reading.estimate else {
                continue;
            };
            cell.estimated += 1;
            let Some(u) = reading.uncertainty else {
                continue;
            };
            let error = estimate - truth;
            cell.stated += 1;
            cell.covered += u32::from(error.abs() <= 2.0 * u);
            cell.z_square_sum += (error / u).powi(2);
        }
    }
    cells
}

fn print(scene: &str, readouts: &[usize], cells: &[Cell], runs: u64) {
    for (readout, cell) in readouts.iter().zip(cells) {
        println!(
            "{scene:34} at {readout:5}: estimated {:4}/{runs}, stated {:4}, coverage {:5.1} %, rms error/u {:.2}",
            cell.estimated,
            cell.stated,
            100.0 * cell.coverage(),
            cell.rms_z()
        );
    }
}

/// The thesis scene: response, static gain, true input, and σ for an SNR by eq. 4.39.
fn thesis_scene(snr_db: f64) -> (Vec<f64>, f64, f64, f64) {
    let sensor = thesis_second_order();
    let u = 0.1;
    let y = sensor.step_response(u, 200);
    let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
    (y, sensor.static_gain(), u, rms / 10f64.powf(snr_db / 20.0))
}

fn load_cell_counts(samples: usize) -> Vec<f64> {
    let cell = load_cell();
    let volts_per_gram = cell.static_gain();
    cell.step_response(MASS_G, samples)
        .iter()
        .map(|v| v / volts_per_gram * COUNTS_PER_GRAM)
        .collect()
}

type Iv = IvStepEstimator<f64, 8, 8>;

fn iv_thesis(snr_db: f64, readouts: &[usize], runs: u64, seed: u64) -> Vec<Cell> {
    let (y, g, u, sigma) = thesis_scene(snr_db);
    let step = StepConfig::new(2, g);
    coverage(&y, sigma, u, readouts, runs, seed, || {
        Iv::new(IvConfig::new(step)).unwrap()
    })
}

fn iv_load_cell(
    order: usize,
    decimation: u16,
    samples: usize,
    readouts: &[usize],
    runs: u64,
    seed: u64,
) -> Vec<Cell> {
    let clean = load_cell_counts(samples);
    let step = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
    coverage(
        &clean,
        SIGMA_G * COUNTS_PER_GRAM,
        MASS_G,
        readouts,
        runs,
        seed,
        || Iv::new(IvConfig::new(step)).unwrap(),
    )
}

/// On the thesis scene (second order, strong instruments), ±2u covers 95 % of the IV
/// errors at every readout, at low and high SNR; every reading states a `u`.
#[test]
fn iv_two_u_covers_95_percent_on_the_thesis_scene() {
    let runs = 400;
    let readouts = [50, 100, 200];
    for snr_db in [30.0, 50.0] {
        let cells = iv_thesis(snr_db, &readouts, runs, 11);
        print(&format!("IV thesis {snr_db} dB"), &readouts, &cells, runs);
        for (readout, cell) in readouts.iter().zip(&cells) {
            assert_eq!(
                cell.stated, runs as u32,
                "{snr_db} dB at {readout}: {cell:?}"
            );
            assert!(
                (0.91..=0.99).contains(&cell.coverage()),
                "{snr_db} dB at {readout}: {cell:?}"
            );
        }
    }
}

/// On the load cell the delayed differences leave some direction of `ℓ` to the noise
/// (Cragg–Donald statistic ≈ 0–1.5, against 110–140 on the thesis scene): no `u`, at the
/// full rate (where the first-order `u` covered 46–76 %) and decimated (97–99 %, but
/// scattered over two orders of magnitude).
#[test]
fn iv_states_no_u_with_weak_instruments_on_the_load_cell() {
    let runs = 100;
    let readouts = [400, 800];
    for (order, decimation) in [(5, 1), (7, 1), (5, 12)] {
        let cells = iv_load_cell(order, decimation, 800, &readouts, runs, 12);
        for (readout, cell) in readouts.iter().zip(&cells) {
            assert!(
                cell.estimated > 80,
                "n={order} D={decimation} at {readout}: {cell:?}"
            );
            assert_eq!(cell.stated, 0, "n={order} D={decimation} at {readout}");
        }
    }
}

/// f32 states the f64 `u` of the same data within 10 % wherever both state one.
#[test]
fn iv_f32_states_the_f64_uncertainty() {
    let runs = 40;
    for snr_db in [30.0, 50.0, 70.0] {
        let (y, g, _, sigma) = thesis_scene(snr_db);
        let mut noise = Gaussian::new(13);
        let (mut worst, mut compared) = (0.0f64, 0);
        for _ in 0..runs {
            let mut e64 = Iv::new(IvConfig::new(StepConfig::new(2, g))).unwrap();
            let mut e32 =
                IvStepEstimator::<f32, 8, 8>::new(IvConfig::new(StepConfig::new(2, g as f32)))
                    .unwrap();
            for &clean in &y {
                let sample = (clean + sigma * noise.sample()) as f32;
                let (a, b) = (e32.push(sample), e64.push(f64::from(sample)));
                if let (Some(u32_), Some(u64_)) = (a.uncertainty, b.uncertainty) {
                    worst = worst.max((f64::from(u32_) / u64_ - 1.0).abs());
                    compared += 1;
                }
            }
        }
        println!("IV thesis {snr_db} dB: f32 u against f64, worst {worst:.2e} over {compared}");
        assert!(compared > runs * 150, "{snr_db} dB: {compared}");
        assert!(worst < 0.1, "{snr_db} dB: {worst}");
    }
}

/// No `u` without an estimate, after a bad sample (latched), with forgetting, or for an
/// order above the lag sums' `L` (the default `L = 0` among them).
#[test]
fn iv_states_no_u_where_it_has_no_valid_estimate() {
    let (y, g, _, sigma) = thesis_scene(40.0);
    let mut noise = Gaussian::new(14);
    let data: Vec<f64> = y.iter().map(|v| v + sigma * noise.sample()).collect();
    let step = StepConfig::new(2, g);
    let mut plain = Iv::new(IvConfig::new(step)).unwrap();
    let mut bare = IvStepEstimator::<f64, 8>::new(IvConfig::new(step)).unwrap();
    let mut narrow = IvStepEstimator::<f64, 8, 1>::new(IvConfig::new(step)).unwrap();
    let mut forgetting = Iv::new(IvConfig::new(step.with_forgetting(0.99))).unwrap();
    let mut stated = 0;
    for (k, &sample) in data.iter().enumerate() {
        let bad = if k == 150 { f64::NAN } else { sample };
        let reading = plain.push(bad);
        assert!(reading.uncertainty.is_none() || reading.estimate.is_some());
        if k >= 150 {
            assert!(reading.is_invalid() && reading.uncertainty.is_none());
        }
        stated += usize::from(reading.uncertainty.is_some());
        let others: [&mut dyn Estimator<f64>; 3] = [&mut bare, &mut narrow, &mut forgetting];
        for other in others {
            let reading = other.push(sample);
            assert_eq!(reading.uncertainty, None);
            assert_eq!(reading.degrees_of_freedom, 0);
        }
    }
    assert!(stated > 100, "{stated}");
    assert!(bare.push(data[0]).estimate.is_some());
}

#[test]
#[ignore = "study: IV coverage over 1,000 runs per SNR (~10 s in release)"]
fn iv_study() {
    let runs = 1000;
    let readouts = [50, 100, 200];
    for snr_db in [30.0, 40.0, 50.0, 70.0] {
        let cells = iv_thesis(snr_db, &readouts, runs, 1);
        print(&format!("IV thesis {snr_db} dB"), &readouts, &cells, runs);
    }
    let readouts = [400, 800, 1600];
    for (order, decimation) in [(5, 12), (7, 12), (5, 1), (7, 1)] {
        let cells = iv_load_cell(order, decimation, 1600, &readouts, runs, 2);
        print(
            &format!("IV load cell n={order} D={decimation}"),
            &readouts,
            &cells,
            runs,
        );
    }
}
