//! Calibration as one command: from three simulated drops of the reference
//! mass, the core's `tuning::tune` chooses the smallest method that meets the target
//! at every load of the scale's range, and that choice holds on FRESH drops of host-sim's
//! own simulator (not the identified model the choice was scored on) at loads across the
//! range, with the simulator's true platform mass (120 g), which calibration did not know.
//!
//! Every calibration drop is the shipped `calibration-drop` scene (0.3 s of empty pan, then
//! 138.32 g), converted by the simulated 16-bit ADC; a fresh drop is the same scene with
//! another load and the same noise (σ set by the SNR of the 138.32 g step). The fresh drops
//! go through the same onset detection and tare as calibration, and are read 100 ms after
//! the true landing.
//! Figures: `cargo test --release -p host-sim --test calibrate -- --nocapture`.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use estimator_core::tuning::{summarise_drop, CandidateGrid, TuningError, STANDARD_DECIMATIONS};

use estimator_core::sensor::LoadCellModel;
use estimator_core::weighing::{
    LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, RegionError, WeighingConfig,
    WeighingEstimator, WeighingMethod, MAX_SCENES,
};
use estimator_core::Estimator;
use host_sim::calibrate::{self, Options, Outcome};
use host_sim::montecarlo::Precision;
use host_sim::run_seed;
use host_sim::scene::Scene;

mod support;
use support::{host_sim, run_ok};

const MASS_G: f64 = 138.32;
/// The calibration drops' seeds; the fresh drops use `run_seed(FRESH_SEED, run)`.
const CALIBRATION_SEEDS: [u64; 3] = [1, 2, 3];
const FRESH_SEED: u64 = 20_240_601;

/// The lightest load at which 0.1% at 100 ms is asked at 50 dB. The noise floor there
/// (Cramér–Rao bound with the tare, 0.026 g) puts even an estimator at the floor at a 95th
/// percentile of 1.96 × 0.026 = 0.051 g, i.e. 0.1% of 51 g. The range starts at the lightest
/// load for which calibration finds a method with the platform mass unknown (host-sim's
/// README, calibration table). Its top is the
/// default: the heaviest load whose overshoot the 16-bit converter takes (~342 g).
const MIN_LOAD_G: f64 = 80.0;
/// Loads the fresh drops check: the range's ends (340 g: just inside the top), the
/// calibration mass and one between.
const FRESH_LOADS_G: [f64; 4] = [MIN_LOAD_G, MASS_G, 250.0, 340.0];

fn scene(snr_db: f64) -> Scene {
    Scene::load("calibration-drop").unwrap().with_snr_db(snr_db)
}

/// The calibration-drop scene with another load, the noise set by the same 138.32 g step.
fn scene_with_load(snr_db: f64, mass_g: f64) -> Scene {
    Scene::parse(
        Path::new("fresh.toml"),
        &format!(
            "duration_s = 1.8\n[[events]]\ntime_s = 0.3\nmass_g = {mass_g}\n[noise]\nsnr_step_g = {MASS_G}\n"
        ),
    )
    .unwrap()
    .with_snr_db(snr_db)
}

/// The codes of one drop of the scene, as `simulate` writes them.
fn record(scene: &Scene, seed: u64, samples: usize) -> Vec<f64> {
    use estimator_core::sensor::AdcSource;
    let mut adc = scene.adc(seed);
    (0..samples)
        .map(|_| f64::from(adc.read().unwrap()))
        .collect()
}

fn calibration_drops(scene: &Scene) -> (Vec<Vec<f64>>, Vec<String>) {
    let drops = CALIBRATION_SEEDS
        .iter()
        .map(|&seed| record(scene, seed, scene.samples()))
        .collect();
    let names = CALIBRATION_SEEDS
        .iter()
        .map(|seed| format!("seed {seed}"))
        .collect();
    (drops, names)
}

/// With least squares with forgetting scored too (`--forgetting`), as the README's
/// calibration table and the choices these tests pin down were made.
fn options(readout_s: f64, target_relative: f64) -> Options {
    Options {
        readout_s,
        target_relative,
        forgetting: true,
        ..Options::new(Vec::new(), MASS_G)
    }
}

/// The scoring before load ranges: the calibration mass only.
fn at_calibration_mass_only(options: Options) -> Options {
    Options {
        min_load_g: Some(MASS_G),
        max_load_g: Some(MASS_G),
        ..options
    }
}

/// 50 dB, 0.1% at 100 ms from 80 g to the converter's limit, platform mass unknown, f32:
/// calibrated once for the tests that need it.
fn range_50db() -> &'static Outcome {
    static OUTCOME: OnceLock<Outcome> = OnceLock::new();
    OUTCOME.get_or_init(|| {
        let options = Options {
            min_load_g: Some(MIN_LOAD_G),
            ..options(0.1, 0.001)
        };
        calibrated(50.0, &options).unwrap()
    })
}

fn calibrated(snr_db: f64, options: &Options) -> Result<Outcome, String> {
    let (drops, names) = calibration_drops(&scene(snr_db));
    calibrate::calibrate_samples(&drops, &names, options, |_| {}).map_err(|e| format!("{e:#}"))
}

/// The smallest `k` with `P(Bin(n, p) > k) ≤ alpha`.
fn binomial_upper(n: usize, p: f64, alpha: f64) -> usize {
    let mut log_pmf = n as f64 * (1.0 - p).ln();
    let mut cdf = log_pmf.exp();
    let mut k = 0;
    while 1.0 - cdf > alpha && k < n {
        log_pmf += ((n - k) as f64 / (k + 1) as f64).ln() + (p / (1.0 - p)).ln();
        cdf += log_pmf.exp();
        k += 1;
    }
    k
}

/// Errors at the readout on fresh drops, through the same detection and tare.
struct Fresh {
    mass_g: f64,
    runs: usize,
    outside: usize,
    rms_g: f64,
    p95_g: f64,
}

/// `runs` fresh drops of `mass_g` (seeds `run_seed(FRESH_SEED, run)`), each through the
/// config's own onset detection and tare, as the firmware would run them; then the method
/// from the detected onset and from the landing (the two ends the config claims), the larger
/// |error| counting, as in the prediction.
/// The configured method as `calibrate::configured_estimator` builds it, but without the
/// valid-region check (`WeighingConfig::check_region`), so that a method outside the region
/// can be shown failing.
fn unchecked_estimator(
    config: &WeighingConfig,
    precision: Precision,
    zero_counts: f64,
) -> Box<dyn Estimator<f64>> {
    use estimator_core::weighing::WeighingEstimator;
    match precision {
        Precision::F64 => Box::new(
            WeighingEstimator::<f64, 40, 5, 33>::with_method(config, &config.method, zero_counts)
                .unwrap(),
        ),
        Precision::F32 => {
            let estimator = WeighingEstimator::<f32, 40, 5, 33>::with_method(
                config,
                &config.method,
                zero_counts,
            )
            .unwrap();
            Box::new(Widened(estimator))
        }
    }
}

/// An `f32` estimator behind the `f64` interface (the sample rounded, the reading widened).
struct Widened<E>(E);

impl<E: Estimator<f32>> Estimator<f64> for Widened<E> {
    fn push(&mut self, sample: f64) -> estimator_core::Reading<f64> {
        let r = self.0.push(sample as f32);
        estimator_core::Reading {
            estimate: r.estimate.map(f64::from),
            samples: r.samples,
            state: r.state,
            residual: r.residual.map(f64::from),
            uncertainty: r.uncertainty.map(f64::from),
            degrees_of_freedom: r.degrees_of_freedom,
        }
    }
    fn push_missing(&mut self) -> estimator_core::Reading<f64> {
        let r = self.0.push_missing();
        estimator_core::Reading {
            estimate: r.estimate.map(f64::from),
            samples: r.samples,
            state: r.state,
            residual: r.residual.map(f64::from),
            uncertainty: r.uncertainty.map(f64::from),
            degrees_of_freedom: r.degrees_of_freedom,
        }
    }
    fn reset(&mut self) {
        self.0.reset()
    }
}

fn fresh_at(
    config: &WeighingConfig,
    precision: Precision,
    snr_db: f64,
    mass_g: f64,
    runs: usize,
) -> Fresh {
    let scene = scene_with_load(snr_db, mass_g);
    let (landing, _, _) = scene.studied_step();
    let readout = config.readout_samples();
    let target_g = config.target_relative * mass_g;
    let mut errors = Vec::with_capacity(runs);
    for run in 0..runs as u64 {
        let codes = record(&scene, run_seed(FRESH_SEED, run), landing + readout + 1);
        let error = match summarise_drop(&codes, &config.onset) {
            Ok(summary) => {
                let mut worst = 0.0f64;
                for start in [summary.onset, landing] {
                    let mut estimator = unchecked_estimator(config, precision, summary.zero);
                    let mut last = None;
                    for &code in &codes[start.min(codes.len())..] {
                        last = estimator.push(code - summary.zero).estimate;
                    }
                    let error = last.map_or(f64::INFINITY, |estimate| estimate - mass_g);
                    // Never NaN: a missing reading is an infinite error.
                    if error.abs() > worst.abs() {
                        worst = error;
                    }
                }
                worst
            }
            Err(_) => f64::INFINITY,
        };
        errors.push(error);
    }
    // An infinite error (no valid reading) is outside.
    let outside = errors.iter().filter(|e| e.abs() > target_g).count();
    let finite: Vec<f64> = errors.iter().copied().filter(|e| e.is_finite()).collect();
    let rms_g = (finite.iter().map(|e| e * e).sum::<f64>() / finite.len().max(1) as f64).sqrt();
    let mut magnitudes: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
    magnitudes.sort_by(f64::total_cmp);
    let p95_g = magnitudes[((0.95 * runs as f64).ceil() as usize).max(1) - 1];
    Fresh {
        mass_g,
        runs,
        outside,
        rms_g,
        p95_g,
    }
}

fn fresh(config: &WeighingConfig, precision: Precision, snr_db: f64, runs: usize) -> Fresh {
    fresh_at(config, precision, snr_db, MASS_G, runs)
}

/// The claim at one load: P(|error| > target) ≤ 5%. Then the count outside is at most
/// Bin(runs, 0.05) in distribution; the check fails if it exceeds that law's 99.9th
/// percentile (a 0.1% false alarm for a selection exactly at its limit at that load; with
/// four loads checked, at most 0.4% for the test).
fn holds(result: &Fresh) -> bool {
    result.outside <= binomial_upper(result.runs, 0.05, 0.001)
}

fn describe(result: &Fresh, target_relative: f64) -> String {
    format!(
        "{:.2} g: {} fresh drops, RMS {:.4} g ({:.4}%), p95 {:.4} g ({:.4}%), {} outside {:.4} g (allowed {})",
        result.mass_g,
        result.runs,
        result.rms_g,
        result.rms_g / result.mass_g * 100.0,
        result.p95_g,
        result.p95_g / result.mass_g * 100.0,
        result.outside,
        target_relative * result.mass_g,
        binomial_upper(result.runs, 0.05, 0.001)
    )
}

fn check_on_fresh_drops(outcome: &Outcome, snr_db: f64, runs: usize) {
    let config = &outcome.calibrated.config;
    let result = fresh(config, outcome.precision, snr_db, runs);
    let p = &config.prediction;
    println!(
        "{snr_db} dB, {} at {} ms: predicted RMS {:.4} g, p95 {:.4} g (bound {:.4}); {}",
        config.method,
        config.readout_s * 1e3,
        p.rms_g,
        p.p95_g,
        p.p95_upper_g,
        describe(&result, config.target_relative)
    );
    assert!(
        holds(&result),
        "{} of {runs} fresh drops outside the target",
        result.outside
    );
    // The prediction must not be optimistic either. Its RMS is over 400 runs, the fresh one
    // over `runs`; each RMS has a relative standard error 1/√(2N) (3.5% and 3.5–5%), so the
    // ratio's is at most 6%; 4 of those is 24%. The Monte Carlo's noise is the measured
    // variance's upper confidence value (3% above it in σ), which only makes it cautious.
    assert!(
        result.rms_g <= 1.24 * p.rms_g,
        "fresh RMS {} against predicted {}",
        result.rms_g,
        p.rms_g
    );
}

#[test]
fn the_chosen_configuration_meets_the_target_on_fresh_drops_across_the_load_range() {
    let outcome = range_50db();
    let c = &outcome.calibrated;
    let config = &c.config;
    println!(
        "50 dB, 0.1% at 100 ms over {:.1}-{:.1} g: chose {} after {} candidates in {:.2} s",
        config.loads.min_g, config.loads.max_g, config.method, c.evaluated, outcome.elapsed_s
    );
    // Everything scored before the choice failed, and the choice is the first that passed:
    // candidates come in size order.
    for pair in outcome.scores.windows(2) {
        assert!(pair[0].method.size_key() < pair[1].method.size_key());
    }
    let (last, before) = outcome.scores.split_last().unwrap();
    assert!(last.meets && before.iter().all(|s| !s.meets));
    assert_eq!(last.method, config.method);
    // The gain the drops showed: the simulator's is 73.2547 counts/g; the identified one is
    // a fit over three 1.5 s drops whose standard deviation host-sim's model_based test
    // bounds at 1.8e-3 counts/g (2.4e-5 relative); allow 5 of them.
    let truth = scene(50.0).chain.counts_per_gram();
    assert!(
        (config.counts_per_gram / truth - 1.0).abs() < 1.2e-4,
        "{} vs {truth}",
        config.counts_per_gram
    );
    // The range asked for, its top the converter's limit (the fresh loads lie inside it),
    // and the platform mass unknown: the calibration mass, then each of 4 loads at two
    // resonances; every scene within the target relative to its load.
    let loads = &config.loads;
    assert_eq!(loads.min_g, MIN_LOAD_G);
    assert!(loads.max_g >= FRESH_LOADS_G[3], "{}", loads.max_g);
    assert_eq!(loads.platform_mass_g, None);
    let scored: Vec<&LoadScore> = loads.scores.iter().flatten().collect();
    assert_eq!(scored.len(), 9);
    for score in &scored {
        println!(
            "  scored {:.2} g at {:.3}x f_n: p95 {:.4}% (bound {:.4}%), floor {:.4} g",
            score.scene.mass_g,
            score.scene.frequency_ratio,
            score.p95_over_target(1.0) * 100.0,
            score.bound_over_target(1.0) * 100.0,
            score.noise_floor_g
        );
        assert!(score.bound_over_target(config.target_relative) <= 1.0);
    }

    // Fresh drops of the simulator (platform mass 120 g: each load at its true resonance,
    // between the two ends scored): 400 at the calibration mass (also checked against the
    // prediction), 300 at each other load.
    check_on_fresh_drops(outcome, 50.0, 400);
    for mass_g in FRESH_LOADS_G {
        if mass_g == MASS_G {
            continue;
        }
        let result = fresh_at(config, outcome.precision, 50.0, mass_g, 300);
        println!("  {}", describe(&result, config.target_relative));
        assert!(
            holds(&result),
            "{}",
            describe(&result, config.target_relative)
        );
    }

    // The TOML written for it reads back to the same configuration.
    let names: Vec<String> = CALIBRATION_SEEDS
        .iter()
        .map(|s| format!("d{s}.csv"))
        .collect();
    let text = calibrate::to_toml(outcome, &names, "host-sim calibrate ...");
    let (read, precision) = calibrate::parse_config(Path::new("w.toml"), &text).unwrap();
    assert_eq!(read, *config);
    assert_eq!(precision, outcome.precision);
}

#[test]
fn a_choice_good_only_at_the_calibration_mass_is_rejected_and_a_range_the_noise_rules_out_is_refused(
) {
    // Scored at the calibration mass only (the scoring before load ranges), calibration chose
    // `step:n=2,D=32,lambda=0.852`, within 0.1% at 138.32 g but not at light loads. An order
    // of 2 now lies outside the stability map's valid region (`WeighingConfig::check_region`),
    // so it still meets the target there but is no longer chosen.
    let old = calibrated(50.0, &at_calibration_mass_only(options(0.1, 0.001))).unwrap();
    let old_score = old
        .scores
        .iter()
        .find(|s| {
            matches!(
                s.method,
                WeighingMethod::Step {
                    order: 2,
                    decimation: 32,
                    forgetting,
                } if forgetting < 1.0
            ) && s.recorded.is_some_and(|c| c.failing == 0)
        })
        .expect("the old choice is scored and meets the target at the calibration mass");
    let old_method = old_score.method;
    assert!(!old_score.meets);
    assert_eq!(
        old_score.outside_region,
        Some(RegionError::Order {
            order: 2,
            minimum: 3
        })
    );
    assert!(old.calibrated.config.method.size_key() > old_method.size_key());
    assert_eq!(old.calibrated.config.loads.scores[1], None);
    // The README's old failure, on fresh simulator drops: at 50 g it misses 0.1% in far more
    // runs than a 95% claim allows.
    let old_config = WeighingConfig {
        method: old_method,
        ..old.calibrated.config
    };
    let at_50 = fresh_at(&old_config, old.precision, 50.0, 50.0, 400);
    println!("old choice {old_method}: {}", describe(&at_50, 0.001));
    assert!(!holds(&at_50), "{}", describe(&at_50, 0.001));

    // Over 80 g to the converter's limit it is scored again and stopped at a load lighter
    // than the calibration mass; the choice is a larger model (which holds on fresh drops
    // across the range: the test above).
    let new = range_50db();
    let new_method = new.calibrated.config.method;
    let again = new
        .scores
        .iter()
        .find(|s| s.method == old_method)
        .expect("the old choice is scored over the range too");
    let failed = again.failed_load.expect("it fails at some load");
    println!(
        "over {MIN_LOAD_G} g and up it fails at {:.2} g at {:.3}x f_n; the range chose {new_method}",
        failed.scene.mass_g, failed.scene.frequency_ratio
    );
    assert!(!again.meets && failed.scene.mass_g < MASS_G);
    assert!(new_method.size_key() > old_method.size_key());

    // And a range that holds 50 g (the default, 0.3× = 41.5 g) is refused, not given a
    // configuration that misses there: no candidate meets it, and where the best one failed
    // even a method at the noise floor would not (its 95th percentile, 1.96 × the floor, is
    // above 0.1% of the load).
    let options = options(0.1, 0.001);
    let settings = options.settings();
    let (drops, _) = calibration_drops(&scene(50.0));
    let mut data: Vec<Vec<f32>> = drops
        .iter()
        .map(|d| d.iter().map(|&v| v as f32).collect())
        .collect();
    let mut slices: Vec<&mut [f32]> = data.iter_mut().map(|d| d.as_mut_slice()).collect();
    let mut runs = vec![estimator_core::tuning::RunSlot::EMPTY; 400 * settings.max_scenes()];
    let grid = CandidateGrid::standard(0.1);
    match estimator_core::tuning::tune::<f32, 40, 5, 33>(
        &mut slices,
        &settings,
        &grid,
        &mut runs,
        |_| {},
    ) {
        Err(TuningError::NoneMeetsTarget {
            best,
            failed_load: Some(load),
            evaluated,
            ..
        }) => {
            println!(
                "0.3x-3x: refused after {evaluated}; best {best} failed at {:.2} g, noise floor {:.4} g",
                load.scene.mass_g, load.noise_floor_g
            );
            assert_eq!(evaluated, grid.len());
            assert!((load.scene.mass_g / (0.3 * MASS_G) - 1.0).abs() < 1e-12);
            assert!(1.96 * load.noise_floor_g > 0.001 * load.scene.mass_g);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn at_70_db_the_default_range_holds_at_both_ends() {
    // At 70 dB (σ = 0.044 g) the noise floor is 0.003 g at every load: what decides is the
    // model's own error. The default range, 0.3× the mass to the converter's limit.
    let outcome = calibrated(70.0, &options(0.1, 0.001)).unwrap();
    let config = &outcome.calibrated.config;
    let loads = &config.loads;
    println!(
        "70 dB, 0.1% at 100 ms over {:.2}-{:.2} g: {}",
        loads.min_g, loads.max_g, config.method
    );
    assert!((loads.min_g / (0.3 * MASS_G) - 1.0).abs() < 1e-12);
    // Scored at the calibration mass only it would be `step:n=2,D=32` (0.09% off at 138 g,
    // nearly all bias); over the range that one is stopped at a light load.
    let small = WeighingMethod::Step {
        order: 2,
        decimation: 32,
        forgetting: 1.0,
    };
    let scored = outcome.scores.iter().find(|s| s.method == small).unwrap();
    assert!(scored.prediction.p95_upper_g <= 0.001 * MASS_G && !scored.meets);
    assert!(config.method.size_key() > small.size_key());
    for mass_g in [loads.min_g, 340.0] {
        let result = fresh_at(config, outcome.precision, 70.0, mass_g, 300);
        println!("  {}", describe(&result, 0.001));
        assert!(holds(&result), "{}", describe(&result, 0.001));
    }
}

#[test]
fn the_platform_mass_from_a_second_mass_is_the_simulators() {
    // Two drops of 250 g besides the three of 138.32 g: the two identified resonances and the
    // physical law give the platform's moving mass, 120 g in the simulator.
    let (first, first_names) = calibration_drops(&scene(50.0));
    let heavy = scene_with_load(50.0, 250.0);
    let second: Vec<Vec<f64>> = [11u64, 12]
        .iter()
        .map(|&seed| record(&heavy, seed, heavy.samples()))
        .collect();
    let second_names = vec!["s11.csv".to_string(), "s12.csv".to_string()];
    let options = options(0.1, 0.001);
    let fit = calibrate::platform_mass_from_drops(
        &first,
        &first_names,
        &second,
        &second_names,
        250.0,
        &options,
    )
    .unwrap();
    println!(
        "platform mass {:.3} g from {:.5} Hz at 138.32 g and {:.5} Hz at 250 g; damping law misfit {:+.2e}",
        fit.platform_mass_g,
        fit.first.1,
        fit.second.1,
        fit.damping_law_misfit()
    );
    // host-sim's model_based test bounds the identified f_n of three 50 dB drops at 1.9e-4
    // Hz (7.7e-6 relative; two 250 g drops: ~1.1e-5) and ζ at 2.6e-4 relative (two drops:
    // ~4e-4). m_p = (M_a − ρM_b)/(ρ − 1) with ρ = (f_b/f_a)² = 0.698 moves by
    // (M_b − M_a)/(ρ − 1)² = 1,224 g per unit of ρ, and ρ by 2ρ·1.3e-5 = 1.9e-5 (1σ): 0.023 g.
    // Allow 5σ: 0.12 g. The damping law's misfit has σ ≈ 4.8e-4; 5σ: 2.4e-3.
    assert!(
        (fit.platform_mass_g - 120.0).abs() < 0.12,
        "{}",
        fit.platform_mass_g
    );
    assert!(fit.damping_law_misfit().abs() < 2.4e-3);
    // Drops of 250 g said to be of 100 g: the "lighter" mass rings slower, which no platform
    // explains.
    let message = format!(
        "{:#}",
        calibrate::platform_mass_from_drops(
            &first,
            &first_names,
            &second,
            &second_names,
            100.0,
            &options
        )
        .unwrap_err()
    );
    assert!(message.contains("no platform mass"), "{message}");
}

#[test]
fn a_quieter_scale_needs_no_larger_model() {
    // A target both SNRs can meet: 0.2% at 60 ms. At 40 dB (σ = 1.4 g) the noise decides;
    // at 70 dB (0.044 g) only the model error does.
    // From the calibration mass to the converter's limit, with the platform mass known
    // (120 g, as a second mass gives it: `platform_mass_from_drops`): at 40 dB the noise
    // floor alone (0.099 g at 60 ms) rules out 0.2% of lighter loads, and with the platform
    // unknown the slowest resonance allowed at 342 g (0.64×) leaves no method within 0.2%
    // 60 ms after the landing.
    let options = Options {
        min_load_g: Some(MASS_G),
        platform_mass_g: Some(120.0),
        ..options(0.06, 0.002)
    };
    let noisy = calibrated(40.0, &options).unwrap();
    let quiet = calibrated(70.0, &options).unwrap();
    let (noisy_method, quiet_method) = (
        noisy.calibrated.config.method,
        quiet.calibrated.config.method,
    );
    println!(
        "0.2% at 60 ms: 40 dB chose {noisy_method} ({} scored), 70 dB chose {quiet_method} ({} scored)",
        noisy.calibrated.evaluated, quiet.calibrated.evaluated
    );
    assert!(quiet_method.size_key() <= noisy_method.size_key());
    // The noisy choice sits close to its limit: it must hold on fresh drops too.
    check_on_fresh_drops(&noisy, 40.0, 300);
}

#[test]
fn an_impossible_target_names_the_best_candidate() {
    // 0.001% (1.4 mg) at 20 ms: the bound alone (known model, onset and tare) is ~0.1 g
    // there, so nothing meets it.
    let options = options(0.02, 0.00001);
    let (drops, names) = calibration_drops(&scene(50.0));
    let mut scores = Vec::new();
    let error = calibrate::calibrate_samples(&drops, &names, &options, |s| scores.push(*s))
        .expect_err("nothing meets 0.001% at 20 ms");
    let message = format!("{error:#}");
    assert_eq!(
        scores.len(),
        calibrate::grid(&options).len(),
        "every candidate was scored"
    );
    // Without `--forgetting`, no method whose readings state no uncertainty is scored.
    let plain = Options {
        forgetting: false,
        ..options.clone()
    };
    assert_eq!(
        calibrate::grid(&plain).len(),
        calibrate::grid(&options).len() - 8 * STANDARD_DECIMATIONS.len()
    );
    for index in 0..calibrate::grid(&plain).len() {
        let method = calibrate::grid(&plain).get(index, 4000.0).unwrap();
        assert!(
            !matches!(method, WeighingMethod::Step { forgetting, .. } if forgetting < 1.0),
            "{method}"
        );
    }
    let best = scores
        .iter()
        .min_by(|a, b| a.prediction.p95_g.total_cmp(&b.prediction.p95_g))
        .unwrap();
    println!("{message}");
    assert!(
        message.contains("no candidate meets the target of 0.0010% at 20 ms")
            && message.contains(&format!("best is {}", best.method)),
        "{message}"
    );
    assert!(scores.iter().all(|s| !s.meets));
    // The core's typed error, directly.
    let settings = options.settings();
    let mut data: Vec<Vec<f64>> = drops.clone();
    let mut slices: Vec<&mut [f64]> = data.iter_mut().map(|d| d.as_mut_slice()).collect();
    let mut runs = vec![estimator_core::tuning::RunSlot::EMPTY; 60 * settings.max_scenes()];
    let grid = CandidateGrid {
        max_order: 2,
        decimations: &[16],
        forgetting_memory_s: None,
        bias_compensated: false,
        instrumental_variable: false,
        bank: None,
    };
    match estimator_core::tuning::tune::<f64, 8, 5, 33>(
        &mut slices,
        &settings,
        &grid,
        &mut runs,
        |_| {},
    ) {
        Err(TuningError::NoneMeetsTarget {
            best,
            prediction,
            evaluated,
            ..
        }) => {
            assert_eq!(evaluated, 2);
            assert!(matches!(best, WeighingMethod::Step { .. }));
            assert!(prediction.p95_g > 0.00001 * MASS_G);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn malformed_drops_are_refused_by_name() {
    let good = record(&scene(50.0), 1, scene(50.0).samples());
    let options = options(0.1, 0.001);
    let refuse = |drops: Vec<Vec<f64>>| -> String {
        let names: Vec<String> = (0..drops.len()).map(|i| format!("d{i}.csv")).collect();
        match calibrate::calibrate_samples(&drops, &names, &options, |_| {}) {
            Ok(outcome) => panic!("accepted: {:?}", outcome.calibrated.config.method),
            Err(e) => format!("{e:#}"),
        }
    };
    // A NaN in the second drop.
    let mut broken = good.clone();
    broken[2000] = f64::NAN;
    let message = refuse(vec![good.clone(), broken]);
    assert!(
        message.contains("drop d1.csv: sample 2000 is not a finite number"),
        "{message}"
    );
    // A heavy mass: the 16-bit converter clips its overshoot.
    let heavy = Scene::parse(
        Path::new("heavy.toml"),
        "duration_s = 1.8\n[[events]]\ntime_s = 0.3\nmass_g = 450.0\n",
    )
    .unwrap();
    let message = refuse(vec![record(&heavy, 1, heavy.samples())]);
    assert!(
        message.contains("drop d0.csv: sample") && message.contains("saturated"),
        "{message}"
    );
    // The mass is on the pan from the first sample: no empty stretch.
    let reference = Scene::load("reference-step").unwrap();
    let message = refuse(vec![record(&reference, 1, reference.samples())]);
    assert!(message.contains("no empty-pan stretch"), "{message}");
    // Nothing lands.
    let empty = Scene::parse(
        Path::new("empty.toml"),
        "duration_s = 1.8\n[[events]]\ntime_s = 0.3\nmass_g = 0.0\n[noise]\nsnr_step_g = 138.32\n",
    )
    .unwrap();
    let message = refuse(vec![record(&empty, 1, empty.samples())]);
    assert!(message.contains("drop d0.csv: no step"), "{message}");
    // Too short to hold the readout after the onset.
    let message = refuse(vec![good[..1500].to_vec()]);
    assert!(message.contains("drop d0.csv: too short"), "{message}");
    // Too few Monte Carlo runs for the 95%/95% bound.
    let few = Options {
        runs: 20,
        ..options.clone()
    };
    let error = calibrate::calibrate_samples(
        std::slice::from_ref(&good),
        &["d0.csv".into()],
        &few,
        |_| {},
    )
    .err()
    .unwrap();
    assert!(
        format!("{error:#}").contains("20 Monte Carlo runs per scene (9 scenes): at least 59"),
        "{error:#}"
    );
}

#[test]
fn f32_and_f64_calibrations_agree() {
    // The same drops, candidates scored in f32 (the firmware's arithmetic) and in f64. The
    // synthetic drops are the same (generated in f64 from the identified model); only the
    // identification and the estimators' arithmetic differ. The identified model agrees to
    // ~1e-6 relative (host-sim's model_based test), far below its own error (~1e-5), and the
    // estimators' f32 rounding moves each error by ~1e-4 g against a 95th percentile of
    // ~0.08 g: the same method must be chosen and its percentile agree within 2%.
    let options64 = Options {
        precision: Precision::F64,
        min_load_g: Some(MIN_LOAD_G),
        ..options(0.1, 0.001)
    };
    let a = range_50db();
    let b = calibrated(50.0, &options64).unwrap();
    let (c32, c64) = (&a.calibrated.config, &b.calibrated.config);
    println!(
        "f32: {} p95 {:.5} g, f_n {:.6} Hz; f64: {} p95 {:.5} g, f_n {:.6} Hz",
        c32.method,
        c32.prediction.p95_g,
        c32.model.natural_frequency_hz,
        c64.method,
        c64.prediction.p95_g,
        c64.model.natural_frequency_hz
    );
    assert_eq!(c32.method, c64.method);
    assert!((c32.prediction.p95_g / c64.prediction.p95_g - 1.0).abs() < 0.02);
    assert!((c32.model.natural_frequency_hz / c64.model.natural_frequency_hz - 1.0).abs() < 1e-5);
    assert!((c32.counts_per_gram / c64.counts_per_gram - 1.0).abs() < 1e-5);
}

fn config_with(method: WeighingMethod) -> WeighingConfig {
    WeighingConfig {
        method,
        counts_per_gram: 73.25593,
        zero_counts: 16_764.605_2,
        noise_variance_counts2: 1_049.3,
        raw_noise_variance_counts2: 1_048.125,
        onset: OnsetConfig::new(4000.0).with_rails(0.0, 65_535.0),
        detection_lag_samples: 10.25,
        model: LoadCellModel {
            natural_frequency_hz: 25.000_21,
            damping_ratio: 0.030_012_5,
            filter_order: 3,
            filter_cutoff_hz: 100.0,
            counts_per_gram: 73.25593,
            sample_rate_hz: 4000.0,
        },
        identified_counts_per_gram: 73.255_93,
        calibration_mass_g: MASS_G,
        readout_s: 0.1,
        target_relative: 0.001,
        prediction: estimator_core::weighing::Prediction {
            runs: 400,
            planned_runs: 400,
            valid_runs: 400,
            within_target_runs: 399,
            detection_failures: 0,
            bias_g: -0.001_25,
            rms_g: 0.048_2,
            p95_g: 0.082_8,
            p95_upper_g: 0.089_1,
        },
        recorded_drops: 3,
        recorded_worst_error_g: 0.085_5,
        capacity_g: estimator_core::weighing::WeighingConfig::REFERENCE_CAPACITY_G,
        scale_interval_g: estimator_core::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        final_target_g: estimator_core::weighing::WeighingConfig::FINAL_TARGET_E
            * estimator_core::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        loads: coverage(None),
    }
}

/// Three scenes: a light load at two resonances and the calibration mass.
fn coverage(platform_mass_g: Option<f64>) -> LoadCoverage {
    let prediction = |rms_g: f64| Prediction {
        runs: 400,
        planned_runs: 400,
        valid_runs: 400,
        within_target_runs: 398,
        detection_failures: 0,
        bias_g: 0.002_5,
        rms_g,
        p95_g: 2.0 * rms_g,
        p95_upper_g: 2.2 * rms_g,
    };
    let score = |mass_g: f64, frequency_ratio: f64, rms_g: f64| {
        Some(LoadScore {
            scene: LoadScene {
                mass_g,
                frequency_ratio,
            },
            noise_floor_g: 0.026_1,
            prediction: prediction(rms_g),
        })
    };
    let mut scores = [None; MAX_SCENES];
    scores[0] = score(80.0, 1.0, 0.036_4);
    scores[1] = score(80.0, (MASS_G / 80.0f64).sqrt(), 0.036_8);
    scores[2] = score(MASS_G, 1.0, 0.048_2);
    LoadCoverage {
        min_g: 80.0,
        max_g: 341.720_7,
        loads: 4,
        platform_mass_g,
        scores,
    }
}

#[test]
fn the_toml_round_trips_and_refuses_what_it_cannot_use() {
    let methods = [
        WeighingMethod::Step {
            order: 3,
            decimation: 32,
            forgetting: 1.0,
        },
        WeighingMethod::Step {
            order: 3,
            decimation: 32,
            forgetting: (-32.0f64 / 200.0).exp(),
        },
        WeighingMethod::BiasCompensated {
            order: 3,
            decimation: 16,
        },
        WeighingMethod::InstrumentalVariable {
            order: 3,
            decimation: 24,
        },
        // Covering the loads' resonances with a candidate to spare at each end with the
        // platform mass unknown (0.636–1.315: no platform, the widest).
        WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 33,
            ratio_min: 0.6,
            ratio_max: 1.4,
            interpolation: estimator_core::Interpolation::ThreePoint,
            whitening: 0,
        },
        // The bank whose `u` holds in coloured noise: five-point, whitened.
        WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 65,
            ratio_min: 0.6,
            ratio_max: 1.4,
            interpolation: estimator_core::Interpolation::FivePoint,
            whitening: 32,
        },
    ];
    for method in methods {
        for precision in [Precision::F32, Precision::F64] {
            let mut config = config_with(method);
            // The platform mass known and unknown in turn.
            if precision == Precision::F64 {
                config.loads = coverage(Some(119.99));
            }
            let text = calibrate::config_toml(&config, precision);
            let (read, read_precision) = calibrate::parse_config(Path::new("w.toml"), &text)
                .unwrap_or_else(|e| panic!("{method}: {e:#}\n{text}"));
            assert_eq!(read, config, "{text}");
            assert_eq!(read_precision, precision);
            // The printed Rust constant names every field (a build script's output).
            let constant = calibrate::rust_const(&config);
            assert!(constant.starts_with("pub const WEIGHING: WeighingConfig"));
        }
    }
    let text = calibrate::config_toml(&config_with(methods[0]), Precision::F32);
    let refused = |text: &str| match calibrate::parse_config(Path::new("w.toml"), text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => format!("{e:#}"),
    };
    let message = refused(&text.replace("kind = \"step\"", "kind = \"kalman\""));
    assert!(
        message.contains("`method.kind`") && message.contains("kalman"),
        "{message}"
    );
    let message = refused(&text.replace("\norder = 3", "\norder = 3\nspeed = 3"));
    assert!(message.contains("speed"), "{message}");
    let message = refused(&text.replace(
        "spec = \"step:n=3,D=32,precision=f32\"",
        "spec = \"step:n=4,D=32\"",
    ));
    assert!(message.contains("`method.spec`"), "{message}");
    // `spec` is optional; without it an impossible order is caught by the region check.
    let without_spec: String = text
        .lines()
        .filter(|line| !line.starts_with("spec = "))
        .map(|line| format!("{line}\n"))
        .collect();
    assert!(calibrate::parse_config(Path::new("w.toml"), &without_spec).is_ok());
    let message = refused(&without_spec.replace("\norder = 3", "\norder = 0"));
    assert!(
        message.contains("`method.order`") && message.contains("n = 0"),
        "{message}"
    );
    // Outside the stability map's valid region, by key: an order below the sensor's, a
    // decimation below the model's bandwidth, a bank short of the loads.
    let message = refused(&without_spec.replace("\norder = 3", "\norder = 2"));
    assert!(
        message.contains("`method.order`") && message.contains("valid region"),
        "{message}"
    );
    let message = refused(&without_spec.replace("\ndecimation = 32", "\ndecimation = 4"));
    assert!(
        message.contains("`method.decimation`") && message.contains("below 8"),
        "{message}"
    );
    let bank_toml = |candidates, ratio_min, ratio_max| {
        calibrate::config_toml(
            &config_with(WeighingMethod::ModelBank {
                decimation: 8,
                candidates,
                ratio_min,
                ratio_max,
                interpolation: estimator_core::Interpolation::ThreePoint,
                whitening: 0,
            }),
            Precision::F32,
        )
    };
    // A bank's options, by key: the combination and the whitening order.
    let bank = calibrate::config_toml(&config_with(methods[5]), Precision::F32);
    let without_spec = |text: &str| -> String {
        text.lines()
            .filter(|line| !line.starts_with("spec = "))
            .map(|line| format!("{line}\n"))
            .collect()
    };
    let bank = without_spec(&bank);
    assert!(
        bank.contains("\ninterpolation = \"five_point\"\nwhitening = 32\n"),
        "{bank}"
    );
    let message = refused(&bank.replace("\nwhitening = 32", "\nwhitening = 33"));
    assert!(message.contains("`method.whitening`"), "{message}");
    let message = refused(&bank.replace("\"five_point\"", "\"seven_point\""));
    assert!(message.contains("`method.interpolation`"), "{message}");
    // A file written before the keys: the three-point bank, not whitened.
    let before = bank
        .replace("\ninterpolation = \"five_point\"", "")
        .replace("\nwhitening = 32", "");
    let (read, _) = calibrate::parse_config(Path::new("w.toml"), &before).unwrap();
    assert!(matches!(
        read.method,
        WeighingMethod::ModelBank {
            interpolation: estimator_core::Interpolation::ThreePoint,
            whitening: 0,
            ..
        }
    ));
    let short_bank = bank_toml(33, 0.68, 1.3);
    let message = refused(&short_bank);
    assert!(message.contains("`method.ratio_min`"), "{message}");
    let message = refused(&text.replace("format = 2", "format = 7"));
    assert!(message.contains("`format`"), "{message}");
    // Format 1 (before load ranges) still reads, as scored at the calibration mass only; a
    // format-1 file with a range, or a format-2 file without one, is refused.
    let ranged_from = text.find("\n[range]").unwrap();
    let format_1 = text[..ranged_from].replace("format = 2", "format = 1");
    let (read, _) = calibrate::parse_config(Path::new("w.toml"), &format_1).unwrap();
    let config = config_with(methods[0]);
    assert_eq!(
        read.loads,
        LoadCoverage::calibration_mass_only(MASS_G, config.prediction)
    );
    let message = refused(&text.replace("format = 2", "format = 1"));
    assert!(message.contains("`format`"), "{message}");
    let message = refused(&text[..ranged_from]);
    assert!(message.contains("`range`"), "{message}");
    // A file written before Max and e were keys reads the reference cell's; given, they
    // are read.
    assert!(text.contains("capacity_g = ") && text.contains("scale_interval_g = "));
    let without_scale: String = text
        .lines()
        .filter(|line| !line.starts_with("capacity_g") && !line.starts_with("scale_interval_g"))
        .map(|line| format!("{line}\n"))
        .collect();
    let (read, _) = calibrate::parse_config(Path::new("w.toml"), &without_scale).unwrap();
    assert_eq!(read.capacity_g, 600.0);
    assert_eq!(read.scale_interval_g, 0.1);
    let smaller = text
        .replace("capacity_g = 600.0", "capacity_g = 300.0")
        .replace("scale_interval_g = 0.1", "scale_interval_g = 0.05");
    let (read, _) = calibrate::parse_config(Path::new("w.toml"), &smaller).unwrap();
    assert_eq!((read.capacity_g, read.scale_interval_g), (300.0, 0.05));
    // A bank larger than the host's bank type holds; any size up to it reads (17 here).
    let bank = bank_toml(17, 0.6, 1.4);
    assert!(calibrate::parse_config(Path::new("w.toml"), &bank).is_ok());
    let bank = bank_toml(calibrate::BANK_CANDIDATES + 1, 0.6, 1.4);
    let message = refused(&bank);
    assert!(message.contains("model bank"), "{message}");
}

/// What the firmware's build script generates: the constant and the sizes of the configured
/// method; and every refusal names the file, the key and what was expected (the build fails
/// with exactly these messages).
#[test]
fn the_firmware_constants_size_the_method_and_refuse_by_key() {
    let path = Path::new("firmware/weighing.toml");
    let step = WeighingMethod::Step {
        order: 5,
        decimation: 24,
        forgetting: 1.0,
    };
    let text = calibrate::config_toml(&config_with(step), Precision::F32);
    let source = calibrate::firmware_constants(path, &text).unwrap();
    assert!(source.contains("pub const WEIGHING: WeighingConfig = WeighingConfig {"));
    assert!(source
        .contains("method: WeighingMethod::Step { order: 5, decimation: 24, forgetting: 1.0 }"));
    assert!(
        source.contains("pub const ORDER_CAPACITY: usize = 8;"),
        "{source}"
    );
    assert!(
        source.contains("pub const MODEL_STATES: usize = 5;"),
        "{source}"
    );
    assert!(
        source.contains("pub const BANK_CANDIDATES: usize = 0;"),
        "{source}"
    );
    let bank = WeighingMethod::ModelBank {
        decimation: 8,
        candidates: calibrate::BANK_CANDIDATES,
        ratio_min: 0.6,
        ratio_max: 1.4,
        interpolation: estimator_core::Interpolation::ThreePoint,
        whitening: 0,
    };
    let bank_text = calibrate::config_toml(&config_with(bank), Precision::F32);
    let source = calibrate::firmware_constants(path, &bank_text).unwrap();
    assert!(
        source.contains("pub const ORDER_CAPACITY: usize = 1;"),
        "{source}"
    );
    assert!(
        source.contains(&format!(
            "pub const BANK_CANDIDATES: usize = {};",
            calibrate::BANK_CANDIDATES
        )),
        "{source}"
    );

    let refused = |text: &str| match calibrate::firmware_constants(path, text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => format!("{e:#}"),
    };
    let names = |message: &str, key: &str, expected: &str| {
        assert!(message.contains("firmware/weighing.toml"), "{message}");
        assert!(message.contains(key), "{message}");
        assert!(message.contains(expected), "{message}");
    };
    // A key left out (every one is required).
    let without: String = text
        .lines()
        .filter(|line| !line.starts_with("counts_per_gram = "))
        .map(|line| format!("{line}\n"))
        .collect();
    names(
        &refused(&without),
        "`scale.counts_per_gram`",
        "missing field",
    );
    // A value of the wrong type.
    names(
        &refused(&text.replace("decimation = 24", "decimation = \"24\"")),
        "`method.decimation`",
        "expected u16",
    );
    // Scored in f64: the firmware runs f32.
    let f64_text = calibrate::config_toml(&config_with(step), Precision::F64);
    names(
        &refused(&f64_text),
        "`method.precision`",
        "expected \"f32\"",
    );
    // Not a method the core has.
    names(
        &refused(&text.replace("kind = \"step\"", "kind = \"kalman\"")),
        "`method.kind`",
        "one of step",
    );
    // Not TOML at all.
    assert!(refused("format = [").contains("firmware/weighing.toml"));
}

/// This test process's own scratch directory (removed at the end of the test that uses it).
fn temp_dir() -> PathBuf {
    support::scratch_dir("calibrate")
}

fn temp(name: &str) -> PathBuf {
    support::scratch("calibrate", name)
}

#[test]
fn the_command_end_to_end_and_estimate_config_equals_the_core() {
    let drops: Vec<PathBuf> = CALIBRATION_SEEDS
        .iter()
        .map(|seed| {
            let path = temp(&format!("d{seed}.csv"));
            run_ok(
                host_sim()
                    .args([
                        "simulate",
                        "calibration-drop",
                        "--seed",
                        &seed.to_string(),
                        "--out",
                    ])
                    .arg(&path),
            );
            path
        })
        .collect();
    let out = temp("weighing.toml");
    let mut command = host_sim();
    command
        .args([
            "calibrate",
            "--mass-g",
            "138.32",
            "--min-load-g",
            "80",
            "--out",
        ])
        .arg(&out);
    for drop in &drops {
        command.arg("--drop").arg(drop);
    }
    let stdout = run_ok(&mut command);
    assert!(stdout.contains("chosen: "), "{stdout}");
    let (config, precision) = calibrate::load_config(&out).unwrap();
    assert_eq!(precision, Precision::F32);

    // `estimate --config` on a fresh drop: exactly the core's configured estimator, built
    // as the firmware builds it, its fit checked against the config's noise, fed the same
    // samples with the config's zero.
    let input = temp("fresh.csv");
    run_ok(
        host_sim()
            .args(["simulate", "calibration-drop", "--seed", "77", "--out"])
            .arg(&input),
    );
    let text = std::fs::read_to_string(&input).unwrap();
    let samples: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let stdout = run_ok(
        host_sim()
            .args(["estimate", "--config"])
            .arg(&out)
            .arg("--input")
            .arg(&input),
    );
    // Checked against the config's noise, as `estimate --config` runs it by default.
    let mut core = WeighingEstimator::<f32, 40, 5, 33>::new(&config, config.zero_counts).unwrap();
    core.set_noise_reference(Some(estimator_core::NoiseReference::new(
        config.noise_variance_counts2 as f32,
        0,
    )))
    .unwrap();
    estimator_core::Estimator::reset(&mut core);
    let mut expected = vec!["k,estimate,u,state".to_string()];
    for (k, sample) in samples.iter().enumerate() {
        let reading = core.push((sample - config.zero_counts) as f32);
        let state = host_sim::estimate::state_name(reading.state);
        let u = reading
            .uncertainty
            .map_or(String::new(), |u| format!("{}", f64::from(u)));
        expected.push(match reading.estimate {
            Some(value) => format!("{k},{},{u},{state}", f64::from(value)),
            None => format!("{k},,,{state}"),
        });
    }
    let got: Vec<&str> = stdout.lines().collect();
    assert_eq!(got.len(), expected.len());
    for (line, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(g, e, "line {line}");
    }
    // The spec the TOML records gives the same numbers through the method layer (with the
    // same check, given as the tare's variance).
    let spec = calibrate::method_spec(&config, precision).to_string();
    let by_spec = run_ok(
        host_sim()
            .args([
                "estimate",
                "--method",
                &spec,
                "--gain",
                &config.counts_per_gram.to_string(),
                "--zero",
                &config.zero_counts.to_string(),
                "--tare-variance",
                &config.noise_variance_counts2.to_string(),
                "--check-residuals",
                "--input",
            ])
            .arg(&input),
    );
    assert_eq!(by_spec, stdout, "{spec}");
    let _ = std::fs::remove_dir_all(temp_dir());
}

/// The README's calibration table, checked on fresh drops across each range (400 per load):
/// `cargo test --release -p host-sim --test calibrate readme_table -- --ignored --nocapture`
/// (behind `--ignored` for CI time).
#[test]
#[ignore]
fn readme_table_on_fresh_drops_across_the_loads() {
    // (SNR, target, lightest load, platform mass): the platform mass the second-mass drops
    // identify (README: 119.99 g; the test above) lets 0.1% hold from 70 g at 50 dB.
    let rows: [(f64, f64, Option<f64>, Option<f64>); 6] = [
        (50.0, 0.001, Some(MIN_LOAD_G), None),
        (50.0, 0.001, Some(70.0), Some(119.99)),
        (50.0, 0.0005, Some(MASS_G), None),
        (70.0, 0.001, None, None),
        (70.0, 0.0005, None, None),
        (40.0, 0.002, Some(MASS_G), None),
    ];
    for (snr_db, target, min_load_g, platform_mass_g) in rows {
        let options = Options {
            min_load_g,
            platform_mass_g,
            ..options(0.1, target)
        };
        let outcome = match calibrated(snr_db, &options) {
            Ok(outcome) => outcome,
            Err(e) => {
                println!("{snr_db} dB, {}%: {e}", target * 100.0);
                continue;
            }
        };
        let config = &outcome.calibrated.config;
        let loads = &config.loads;
        println!(
            "{snr_db} dB, {}% at 100 ms over {:.2}-{:.2} g: {} ({} scored, {:.2} s)",
            target * 100.0,
            loads.min_g,
            loads.max_g,
            config.method,
            outcome.calibrated.evaluated,
            outcome.elapsed_s
        );
        let worst = loads.worst(target).unwrap();
        println!(
            "  worst scene {:.2} g at {:.3}x: p95 {:.4}% (bound {:.4}%)",
            worst.scene.mass_g,
            worst.scene.frequency_ratio,
            worst.p95_over_target(1.0) * 100.0,
            worst.bound_over_target(1.0) * 100.0
        );
        let mut masses = vec![loads.min_g];
        for mass_g in [80.0, MASS_G, 250.0, 340.0] {
            if mass_g > loads.min_g && mass_g <= loads.max_g && !masses.contains(&mass_g) {
                masses.push(mass_g);
            }
        }
        for mass_g in masses {
            let result = fresh_at(config, outcome.precision, snr_db, mass_g, 400);
            println!("  {}", describe(&result, target));
            assert!(holds(&result), "{}", describe(&result, target));
        }
    }
}
