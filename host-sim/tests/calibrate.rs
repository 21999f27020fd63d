//! Calibration as one command (issue 5, item 6): from three simulated drops of the reference
//! mass, the core's `tuning::calibrate` chooses the smallest method that meets the target,
//! and that choice holds on FRESH drops of host-sim's own simulator (not the identified
//! model the choice was scored on).
//!
//! Every drop is the shipped `calibration-drop` scene (0.3 s of empty pan, then 138.32 g),
//! converted by the simulated 16-bit ADC. The fresh drops go through the same onset
//! detection and tare as calibration, and are read 100 ms after the true landing.
//! Figures: `cargo test --release -p host-sim --test calibrate -- --nocapture`.

use std::path::{Path, PathBuf};
use std::process::Command;

use estimator_core::tuning::{
    summarise_drop, CalibrationError, CandidateGrid, OnsetConfig, WeighingConfig,
    WeighingEstimator, WeighingMethod,
};
use estimator_core::{Estimator, LoadCellModel};
use host_sim::calibrate::{self, Options, Outcome};
use host_sim::montecarlo::Precision;
use host_sim::run_seed;
use host_sim::scene::Scene;

const MASS_G: f64 = 138.32;
/// The calibration drops' seeds; the fresh drops use `run_seed(FRESH_SEED, run)`.
const CALIBRATION_SEEDS: [u64; 3] = [1, 2, 3];
const FRESH_SEED: u64 = 20_240_601;

fn scene(snr_db: f64) -> Scene {
    Scene::load("calibration-drop").unwrap().with_snr_db(snr_db)
}

/// The codes of one drop of the scene, as `simulate` writes them.
fn record(scene: &Scene, seed: u64, samples: usize) -> Vec<f64> {
    use estimator_core::AdcSource;
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

fn options(readout_s: f64, target_relative: f64) -> Options {
    Options {
        readout_s,
        target_relative,
        ..Options::new(Vec::new(), MASS_G)
    }
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
    runs: usize,
    outside: usize,
    rms_g: f64,
    p95_g: f64,
}

fn fresh(config: &WeighingConfig, precision: Precision, snr_db: f64, runs: usize) -> Fresh {
    let scene = scene(snr_db);
    let (landing, _, _) = scene.studied_step();
    let readout = config.readout_samples();
    let target_g = config.target_relative * MASS_G;
    let mut errors = Vec::with_capacity(runs);
    for run in 0..runs as u64 {
        let codes = record(&scene, run_seed(FRESH_SEED, run), landing + readout + 1);
        // The config's own onset detection, as the firmware would run it; then the method
        // from the detected onset and from the landing (the two ends the config claims),
        // the larger |error| counting, as in the prediction.
        let error = match summarise_drop(&codes, &config.onset) {
            Ok(summary) => {
                let mut worst = 0.0f64;
                for start in [summary.onset, landing] {
                    let mut estimator =
                        calibrate::configured_estimator(config, precision, summary.zero).unwrap();
                    let mut last = None;
                    for &code in &codes[start.min(codes.len())..] {
                        last = estimator.push(code - summary.zero).estimate;
                    }
                    let error = last.map_or(f64::INFINITY, |estimate| estimate - MASS_G);
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
        runs,
        outside,
        rms_g,
        p95_g,
    }
}

fn check_on_fresh_drops(outcome: &Outcome, snr_db: f64, runs: usize) {
    let config = &outcome.calibrated.config;
    let result = fresh(config, outcome.precision, snr_db, runs);
    let target_g = config.target_relative * MASS_G;
    let p = &config.prediction;
    // The claim: P(|error| > target) ≤ 5%. Then the count outside is at most Bin(runs, 0.05)
    // in distribution; the test fails if it exceeds that law's 99.9th percentile (a 0.1%
    // false alarm for a selection that is exactly at its limit; a real one is below it).
    let allowed = binomial_upper(runs, 0.05, 0.001);
    println!(
        "{snr_db} dB, {} at {} ms: predicted RMS {:.4} g, p95 {:.4} g (bound {:.4}); fresh ({} runs) RMS {:.4} g, p95 {:.4} g, {} outside the target {:.4} g (allowed {allowed})",
        config.method,
        config.readout_s * 1e3,
        p.rms_g,
        p.p95_g,
        p.p95_upper_g,
        result.runs,
        result.rms_g,
        result.p95_g,
        result.outside,
        target_g
    );
    assert!(
        result.outside <= allowed,
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
fn the_chosen_configuration_meets_the_target_on_fresh_drops() {
    let options = options(0.1, 0.001);
    let outcome = calibrated(50.0, &options).unwrap();
    let c = &outcome.calibrated;
    println!(
        "50 dB, 0.1% at 100 ms: chose {} after {} candidates in {:.2} s",
        c.config.method, c.evaluated, outcome.elapsed_s
    );
    // Everything scored before the choice failed, and the choice is the first that passed:
    // candidates come in size order.
    for pair in outcome.scores.windows(2) {
        assert!(pair[0].method.size_key() < pair[1].method.size_key());
    }
    let (last, before) = outcome.scores.split_last().unwrap();
    assert!(last.meets && before.iter().all(|s| !s.meets));
    assert_eq!(last.method, c.config.method);
    // The gain the drops showed: the simulator's is 73.2547 counts/g; the identified one is
    // a fit over three 1.5 s drops whose standard deviation host-sim's model_based test
    // bounds at 1.8e-3 counts/g (2.4e-5 relative); allow 5 of them.
    let truth = scene(50.0).chain.counts_per_gram();
    assert!(
        (c.config.counts_per_gram / truth - 1.0).abs() < 1.2e-4,
        "{} vs {truth}",
        c.config.counts_per_gram
    );
    check_on_fresh_drops(&outcome, 50.0, 400);

    // The TOML written for it reads back to the same configuration.
    let names: Vec<String> = CALIBRATION_SEEDS
        .iter()
        .map(|s| format!("d{s}.csv"))
        .collect();
    let text = calibrate::to_toml(&outcome, &names, "host-sim calibrate ...");
    let (read, precision) = calibrate::parse_config(Path::new("w.toml"), &text).unwrap();
    assert_eq!(read, c.config);
    assert_eq!(precision, outcome.precision);
}

#[test]
fn a_quieter_scale_needs_no_larger_model() {
    // A target both SNRs can meet: 0.2% at 60 ms. At 40 dB (σ = 1.4 g) the noise decides;
    // at 70 dB (0.044 g) only the model error does.
    let options = options(0.06, 0.002);
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
    let grid = CandidateGrid::standard(0.02);
    assert_eq!(scores.len(), grid.len(), "every candidate was scored");
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
    let mut runs = vec![estimator_core::tuning::RunSlot::EMPTY; 60];
    let grid = CandidateGrid {
        max_order: 2,
        decimations: &[16],
        forgetting_memory_s: None,
        bias_compensated: false,
        instrumental_variable: false,
        bank: None,
    };
    match estimator_core::tuning::calibrate::<f64, 8, 5, 33>(
        &mut slices,
        &settings,
        &grid,
        &mut runs,
        |_| {},
    ) {
        Err(CalibrationError::NoneMeetsTarget {
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
        format!("{error:#}").contains("20 Monte Carlo runs: at least 59"),
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
    let options32 = options(0.1, 0.001);
    let options64 = Options {
        precision: Precision::F64,
        ..options32.clone()
    };
    let a = calibrated(50.0, &options32).unwrap();
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
        prediction: estimator_core::tuning::Prediction {
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
    }
}

#[test]
fn the_toml_round_trips_and_refuses_what_it_cannot_use() {
    let methods = [
        WeighingMethod::Step {
            order: 2,
            decimation: 32,
            forgetting: 1.0,
        },
        WeighingMethod::Step {
            order: 2,
            decimation: 32,
            forgetting: (-32.0f64 / 200.0).exp(),
        },
        WeighingMethod::BiasCompensated {
            order: 3,
            decimation: 16,
        },
        WeighingMethod::InstrumentalVariable {
            order: 2,
            decimation: 24,
        },
        WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 33,
            ratio_min: 0.68,
            ratio_max: 1.3,
        },
    ];
    for method in methods {
        for precision in [Precision::F32, Precision::F64] {
            let config = config_with(method);
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
    let message = refused(&text.replace("order = 2", "order = 2\nspeed = 3"));
    assert!(message.contains("speed"), "{message}");
    let message = refused(&text.replace(
        "spec = \"step:n=2,D=32,precision=f32\"",
        "spec = \"step:n=3,D=32\"",
    ));
    assert!(message.contains("`method.spec`"), "{message}");
    // `spec` is optional; without it an impossible order is caught by building the method.
    let without_spec: String = text
        .lines()
        .filter(|line| !line.starts_with("spec = "))
        .map(|line| format!("{line}\n"))
        .collect();
    assert!(calibrate::parse_config(Path::new("w.toml"), &without_spec).is_ok());
    let message = refused(&without_spec.replace("order = 2", "order = 0"));
    assert!(message.contains("order 0 is not in"), "{message}");
    let message = refused(&text.replace("format = 1", "format = 7"));
    assert!(message.contains("`format`"), "{message}");
    // A bank whose size the host's bank type does not hold.
    let bank = calibrate::config_toml(
        &config_with(WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 17,
            ratio_min: 0.68,
            ratio_max: 1.3,
        }),
        Precision::F32,
    );
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
        source.contains("pub const ORDER_CAPACITY: usize = 5;"),
        "{source}"
    );
    assert!(
        source.contains("pub const MODEL_STATES: usize = 5;"),
        "{source}"
    );
    assert!(
        source.contains("pub const BANK_CANDIDATES: usize = 1;"),
        "{source}"
    );
    let bank = WeighingMethod::ModelBank {
        decimation: 8,
        candidates: calibrate::BANK_CANDIDATES,
        ratio_min: 0.68,
        ratio_max: 1.3,
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

fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

/// This test process's own scratch directory (removed at the end of the test that uses it).
fn temp_dir() -> PathBuf {
    std::env::temp_dir().join(format!("host-sim-calibrate-{}", std::process::id()))
}

fn temp(name: &str) -> PathBuf {
    let dir = temp_dir();
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn run_ok(command: &mut Command) -> String {
    let output = command.output().unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
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
        .args(["calibrate", "--mass-g", "138.32", "--out"])
        .arg(&out);
    for drop in &drops {
        command.arg("--drop").arg(drop);
    }
    let stdout = run_ok(&mut command);
    assert!(stdout.contains("chosen: "), "{stdout}");
    let (config, precision) = calibrate::load_config(&out).unwrap();
    assert_eq!(precision, Precision::F32);

    // `estimate --config` on a fresh drop: exactly the core's configured estimator, built
    // as the firmware builds it, fed the same samples with the config's zero.
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
    let mut core = WeighingEstimator::<f32, 40, 5, 33>::new(&config, config.zero_counts).unwrap();
    let mut expected = vec!["k,estimate,state".to_string()];
    for (k, sample) in samples.iter().enumerate() {
        let reading = core.push((sample - config.zero_counts) as f32);
        let state = host_sim::estimate::state_name(reading.state);
        expected.push(match reading.estimate {
            Some(value) => format!("{k},{:e},{state}", f64::from(value)),
            None => format!("{k},,{state}"),
        });
    }
    let got: Vec<&str> = stdout.lines().collect();
    assert_eq!(got.len(), expected.len());
    for (line, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(g, e, "line {line}");
    }
    // The spec the TOML records gives the same numbers through the method layer.
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
                "--input",
            ])
            .arg(&input),
    );
    assert_eq!(by_spec, stdout, "{spec}");
    let _ = std::fs::remove_dir_all(temp_dir());
}
