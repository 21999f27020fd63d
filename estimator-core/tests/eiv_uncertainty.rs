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

use estimator_core::{
    BiasCompensatedConfig, BiasCompensatedStepEstimator, Estimator, IvConfig, IvStepEstimator,
    NoiseMeter, StepConfig,
};
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

type Iv = IvStepEstimator<f64, 8, 8>;
type Bc = BiasCompensatedStepEstimator<f64, 8, 8>;

/// BCLS on the thesis scene with the noise variance metered at tare (200 empty-pan
/// samples per run, as in `tests/eiv.rs`) or, with `metered` false, the true one.
fn bc_thesis(snr_db: f64, metered: bool, readouts: &[usize], runs: u64, seed: u64) -> Vec<Cell> {
    let (y, g, u, sigma) = thesis_scene(snr_db);
    let step = StepConfig::new(2, g);
    let mut tare = Gaussian::new(seed + 1_000_000);
    coverage(&y, sigma, u, readouts, runs, seed, || {
        let variance = if metered {
            let mut meter = NoiseMeter::<f64>::new(1).unwrap();
            for _ in 0..200 {
                meter.push(sigma * tare.sample()).unwrap();
            }
            meter.noise_variance().unwrap()
        } else {
            sigma * sigma
        };
        Bc::new(BiasCompensatedConfig::new(step, variance)).unwrap()
    })
}

fn bc_load_cell(
    order: usize,
    decimation: u16,
    samples: usize,
    readouts: &[usize],
    runs: u64,
    seed: u64,
) -> Vec<Cell> {
    let clean = load_cell_counts(MASS_G, COUNTS_PER_GRAM, samples);
    let sigma = SIGMA_G * COUNTS_PER_GRAM;
    let step = StepConfig::new(order, COUNTS_PER_GRAM).with_decimation(decimation);
    coverage(&clean, sigma, MASS_G, readouts, runs, seed, || {
        Bc::new(BiasCompensatedConfig::new(step, sigma * sigma)).unwrap()
    })
}

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
    let clean = load_cell_counts(MASS_G, COUNTS_PER_GRAM, samples);
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

/// Over `runs` noisy copies of the thesis scene at `snr_db` (noise seed `seed`), each fed
/// to a fresh f32 and f64 pair from `build(gain, σ)`: the worst relative difference of the
/// f32 `u` from the f64 one, and how many readings both stated.
fn thesis_u_f32_against_f64<E32, E64>(
    snr_db: f64,
    runs: usize,
    seed: u64,
    build: impl Fn(f64, f64) -> (E32, E64),
) -> (f64, usize)
where
    E32: Estimator<f32>,
    E64: Estimator<f64>,
{
    let (y, g, _, sigma) = thesis_scene(snr_db);
    let mut noise = Gaussian::new(seed);
    let (mut worst, mut compared) = (0.0f64, 0);
    for _ in 0..runs {
        let (mut e32, mut e64) = build(g, sigma);
        let samples = y
            .iter()
            .map(|clean| (clean + sigma * noise.sample()) as f32);
        let (run_worst, run_compared) = u_f32_against_f64(&mut e32, &mut e64, samples);
        worst = worst.max(run_worst);
        compared += run_compared;
    }
    (worst, compared)
}

/// f32 states the f64 `u` of the same data within 10 % wherever both state one.
#[test]
fn iv_f32_states_the_f64_uncertainty() {
    let runs = 40;
    for snr_db in [30.0, 50.0, 70.0] {
        let (worst, compared) = thesis_u_f32_against_f64(snr_db, runs, 13, |g, _| {
            let e32 =
                IvStepEstimator::<f32, 8, 8>::new(IvConfig::new(StepConfig::new(2, g as f32)))
                    .unwrap();
            (e32, Iv::new(IvConfig::new(StepConfig::new(2, g))).unwrap())
        });
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
    let mut others: [&mut dyn Estimator<f64>; 3] = [&mut bare, &mut narrow, &mut forgetting];
    let stated = stated_u_around_a_bad_sample(&mut plain, &mut others, &data, f64::NAN);
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

/// On the thesis scene, with the noise variance true or metered at tare, ±2u covers 95 %
/// of the BCLS errors from 100 samples on (at 50 the shares are not yet resolved well
/// enough for the first-order `u`, and none is stated).
#[test]
fn bc_two_u_covers_95_percent_on_the_thesis_scene() {
    let runs = 400;
    let readouts = [50, 100, 200];
    for (snr_db, metered) in [(30.0, false), (50.0, false), (30.0, true)] {
        let cells = bc_thesis(snr_db, metered, &readouts, runs, 21);
        let scene = format!("BCLS thesis {snr_db} dB metered {metered}");
        print(&scene, &readouts, &cells, runs);
        assert_eq!(cells[0].stated, 0, "{scene} at 50: {:?}", cells[0]);
        for (readout, cell) in readouts.iter().zip(&cells).skip(1) {
            assert!(
                cell.stated * 100 >= runs as u32 * 95,
                "{scene} at {readout}: {cell:?}"
            );
            assert!(
                (0.91..=0.99).contains(&cell.coverage()),
                "{scene} at {readout}: {cell:?}"
            );
        }
    }
}

/// On the load cell the readings BCLS keeps have a share barely above its floor (1–3.5×,
/// against 6–7× on the thesis scene at 200 samples, 30 dB): no `u`. At the full rate the
/// first-order `u` of those readings covered 0–2 % (what is kept is selected and still
/// carries most of the LS bias); decimated, 94–100 % of the few kept.
#[test]
fn bc_states_no_u_on_the_load_cell() {
    let readouts = [400, 800];
    for (order, decimation) in [(5, 1), (5, 12)] {
        let cells = bc_load_cell(order, decimation, 800, &readouts, 150, 22);
        for (readout, cell) in readouts.iter().zip(&cells) {
            assert!(
                cell.estimated > 0,
                "n={order} D={decimation} at {readout}: {cell:?}"
            );
            assert_eq!(cell.stated, 0, "n={order} D={decimation} at {readout}");
        }
    }
}

/// f32 states the f64 `u` of the same data within 10 % wherever both state one.
#[test]
fn bc_f32_states_the_f64_uncertainty() {
    let runs = 40;
    for snr_db in [30.0, 50.0, 70.0] {
        let (worst, compared) = thesis_u_f32_against_f64(snr_db, runs, 23, |g, sigma| {
            let variance = sigma * sigma;
            let e32 = BiasCompensatedStepEstimator::<f32, 8, 8>::new(BiasCompensatedConfig::new(
                StepConfig::new(2, g as f32),
                variance as f32,
            ))
            .unwrap();
            let e64 = Bc::new(BiasCompensatedConfig::new(StepConfig::new(2, g), variance)).unwrap();
            (e32, e64)
        });
        println!("BCLS thesis {snr_db} dB: f32 u against f64, worst {worst:.2e} over {compared}");
        assert!(compared > runs * 100, "{snr_db} dB: {compared}");
        assert!(worst < 0.1, "{snr_db} dB: {worst}");
    }
}

/// No `u` without an estimate, after a bad sample, with forgetting, without a noise
/// variance (no compensation: least squares, whose `u` is the step estimator's), or for an
/// order above `L` (the default `L = 0` among them).
#[test]
fn bc_states_no_u_where_it_has_no_valid_estimate() {
    let (y, g, _, sigma) = thesis_scene(40.0);
    let mut noise = Gaussian::new(24);
    let data: Vec<f64> = y.iter().map(|v| v + sigma * noise.sample()).collect();
    let config = BiasCompensatedConfig::new(StepConfig::new(2, g), sigma * sigma);
    let mut plain = Bc::new(config).unwrap();
    let mut bare = BiasCompensatedStepEstimator::<f64, 8>::new(config).unwrap();
    let mut narrow = BiasCompensatedStepEstimator::<f64, 8, 1>::new(config).unwrap();
    let mut forgetting = Bc::new(BiasCompensatedConfig {
        step: config.step.with_forgetting(0.99),
        ..config
    })
    .unwrap();
    let mut uncompensated = Bc::new(BiasCompensatedConfig {
        noise_variance: 0.0,
        ..config
    })
    .unwrap();
    let mut others: [&mut dyn Estimator<f64>; 4] =
        [&mut bare, &mut narrow, &mut forgetting, &mut uncompensated];
    let stated = stated_u_around_a_bad_sample(&mut plain, &mut others, &data, f64::NAN);
    assert!(stated > 50, "{stated}");
}

#[test]
#[ignore = "study: BCLS coverage over 1,000 runs per SNR"]
fn bc_study() {
    let runs = 1000;
    let readouts = [50, 100, 200];
    for metered in [false, true] {
        for snr_db in [30.0, 40.0, 50.0, 70.0] {
            let cells = bc_thesis(snr_db, metered, &readouts, runs, 1);
            let scene = format!("BCLS thesis {snr_db} dB metered {metered}");
            print(&scene, &readouts, &cells, runs);
        }
    }
    let readouts = [400, 800, 1600];
    for (order, decimation) in [(5, 12), (7, 12), (5, 1), (7, 1)] {
        let cells = bc_load_cell(order, decimation, 1600, &readouts, runs, 2);
        let scene = format!("BCLS load cell n={order} D={decimation}");
        print(&scene, &readouts, &cells, runs);
    }
}
