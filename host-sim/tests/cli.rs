//! The `host-sim` command: `simulate` writes the scene, `estimate` on that CSV equals the
//! core called directly (same numbers, same states) for every method, bad input becomes an
//! error naming it, Monte Carlo and the speed study give the same output on 1 and 2 threads.

use std::path::PathBuf;

use estimator_core::weighing::UNCERTAINTY_ORDERS;
use estimator_core::{
    Baseline, BaselineConfig, BaselineMode, BiasCompensatedConfig, BiasCompensatedStepEstimator,
    CovarianceStepEstimator, Estimator, InvalidReason, IvConfig, IvStepEstimator, ModelBank,
    ModelConfig, RampConfig, RampEstimator, Reading, Real, State, StepConfig, StepEstimator,
};
use host_sim::estimate::state_name;
use host_sim::method::{self, Method};
use host_sim::scene::Scene;

mod support;
use support::{host_sim, run_ok, run_refused};

fn temp(name: &str) -> PathBuf {
    support::scratch("cli", name)
}

#[test]
fn estimate_on_a_simulated_csv_equals_the_core() {
    let csv = temp("reference.csv");
    run_ok(
        host_sim()
            .args(["simulate", "reference-step", "--seed", "4", "--out"])
            .arg(&csv),
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,y,truth"));
    let samples: Vec<f64> = lines
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let scene = Scene::load("reference-step").unwrap();
    assert_eq!(samples.len(), scene.samples());
    let (gain, zero) = (scene.chain.counts_per_gram(), scene.chain.zero_code());

    for (precision, order, decimation) in [("f64", 7, 1), ("f32", 5, 16)] {
        let stdout = run_ok(
            host_sim()
                .args([
                    "estimate",
                    "--order",
                    &order.to_string(),
                    "--decimation",
                    &decimation.to_string(),
                    "--gain",
                    &gain.to_string(),
                    "--zero",
                    &zero.to_string(),
                    "--precision",
                    precision,
                    "--input",
                ])
                .arg(&csv),
        );
        let mut expected = vec!["k,estimate,u,state".to_string()];
        let config64 = StepConfig::new(order, gain).with_decimation(decimation as u16);
        let mut core64 = StepEstimator::<f64, 40, 8>::new(config64).unwrap();
        let config32 = StepConfig::new(order, gain as f32).with_decimation(decimation as u16);
        let mut core32 = StepEstimator::<f32, 40, 8>::new(config32).unwrap();
        for (k, sample) in samples.iter().enumerate() {
            let (estimate, u, state) = if precision == "f64" {
                let r = core64.push(sample - zero);
                (r.estimate, r.uncertainty, r.state)
            } else {
                let r = core32.push((sample - zero) as f32);
                (
                    r.estimate.map(f64::from),
                    r.uncertainty.map(f64::from),
                    r.state,
                )
            };
            let u = u.map_or(String::new(), |u| format!("{u}"));
            expected.push(match estimate {
                Some(value) => format!("{k},{value},{u},{}", state_name(state)),
                None => format!("{k},,,{}", state_name(state)),
            });
        }
        let got: Vec<&str> = stdout.lines().collect();
        assert_eq!(got.len(), expected.len());
        for (g, e) in got.iter().zip(&expected) {
            assert_eq!(g, e, "{precision}");
        }
        // And it does estimate the drop: within 0.5% at the end of the 1.5 s scene.
        let last: f64 = got
            .last()
            .unwrap()
            .split(',')
            .nth(1)
            .unwrap()
            .parse()
            .unwrap();
        assert!((last / 138.32 - 1.0).abs() < 5e-3, "{precision}: {last}");
    }
}

#[test]
fn estimate_flags_missing_and_rejects_garbage() {
    let csv = temp("bad.csv");
    std::fs::write(&csv, "t,y\n0,1\n1,\n2,3\n").unwrap();
    let stdout = run_ok(
        host_sim()
            .args(["estimate", "--order", "1", "--gain", "1", "--input"])
            .arg(&csv),
    );
    assert!(
        stdout
            .lines()
            .nth(2)
            .unwrap()
            .ends_with(",,invalid_missing_sample"),
        "{stdout}"
    );
    std::fs::write(&csv, "t,y\n0,1\n1,abc\n").unwrap();
    let stderr = run_refused(
        host_sim()
            .args(["estimate", "--order", "1", "--gain", "1", "--input"])
            .arg(&csv),
    );
    assert!(
        stderr.contains("line 3") && stderr.contains("abc"),
        "{stderr}"
    );
    std::fs::write(&csv, "t,x\n0,1\n").unwrap();
    assert!(run_refused(
        host_sim()
            .args(["estimate", "--order", "1", "--gain", "1", "--input"])
            .arg(&csv)
    )
    .contains("column `y`"));
}

#[test]
fn malformed_scene_file_error_names_file_and_key() {
    let scene = temp("broken.toml");
    std::fs::write(&scene, "[[events]]\ntime_s = 0.0\nmass_g = \"heavy\"\n").unwrap();
    let stderr = run_refused(
        host_sim()
            .args(["simulate", "--out", "/dev/null"])
            .arg(&scene),
    );
    assert!(
        stderr.contains("broken.toml") && stderr.contains("mass_g") && stderr.contains("expected"),
        "{stderr}"
    );
}

#[test]
fn montecarlo_is_reproducible_across_thread_counts() {
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out = temp(&format!("mc-{threads}.csv"));
        run_ok(
            host_sim()
                .env("RAYON_NUM_THREADS", threads)
                .args([
                    "montecarlo",
                    "reference-step",
                    "--runs",
                    "40",
                    "--seed",
                    "9",
                    "--samples",
                    "600",
                    "--config",
                    "n=5,D=16",
                    "--config",
                    "n=3,D=1",
                    "--method",
                    "model:K=5",
                    "--method",
                    "settled",
                    "--out",
                ])
                .arg(&out),
        );
        outputs.push(std::fs::read_to_string(&out).unwrap());
    }
    assert_eq!(outputs[0], outputs[1]);
    assert!(outputs[0].starts_with(
        "snr_db,config,k,t_s,valid_runs,bias_g,std_g,rms_g,rms_rel,crlb_g,mse_over_crlb"
    ));
    assert_eq!(outputs[0].lines().count(), 1 + 4 * 600);
    // The `config` column names every method by its comma-free label.
    for label in ["n=5 D=16", "n=3 D=1", "model:D=8 K=5", "settled:block=80"] {
        assert!(outputs[0].contains(&format!(",{label}")), "{label}");
    }
}

/// The reference scene simulated to a CSV (seed 4), its samples, gain and zero.
fn simulated_reference(name: &str) -> (PathBuf, Vec<f64>, f64, f64) {
    let csv = temp(name);
    run_ok(
        host_sim()
            .args(["simulate", "reference-step", "--seed", "4", "--out"])
            .arg(&csv),
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let samples = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let scene = Scene::load("reference-step").unwrap();
    (
        csv,
        samples,
        scene.chain.counts_per_gram(),
        scene.chain.zero_code(),
    )
}

/// The CSV lines `estimate` must print for these readings.
fn expected_lines(readings: impl Iterator<Item = Reading<f64>>) -> Vec<String> {
    let mut lines = vec!["k,estimate,u,state".to_string()];
    for (k, r) in readings.enumerate() {
        let u = r.uncertainty.map_or(String::new(), |u| format!("{u}"));
        lines.push(match r.estimate {
            Some(value) => format!("{k},{value},{u},{}", state_name(r.state)),
            None => format!("{k},,,{}", state_name(r.state)),
        });
    }
    lines
}

fn widen(r: Reading<f32>) -> Reading<f64> {
    Reading {
        estimate: r.estimate.map(f64::from),
        samples: r.samples,
        state: r.state,
        residual: r.residual.map(f64::from),
        uncertainty: r.uncertainty.map(f64::from),
        degrees_of_freedom: r.degrees_of_freedom,
    }
}

/// A raw-sample noise variance for `bc`, counts²: the reference scene's white noise at 50 dB
/// (0.445 g × 73.25 counts/g ≈ 32.6 counts) and the quantisation.
const TARE_VARIANCE: f64 = 1063.0;

/// The covariance form as `covariance:n=..,D=..` builds it (prior information 10⁻⁶).
fn covariance<T: Real>(
    order: usize,
    decimation: u16,
    gain: T,
) -> CovarianceStepEstimator<T, 40, 41> {
    CovarianceStepEstimator::new(
        StepConfig::new(order, gain).with_decimation(decimation),
        T::from_f64(1e-6),
    )
    .unwrap()
}

/// The bias-compensated form as `bc:n=..,D=..` builds it with [`TARE_VARIANCE`].
fn bias_compensated<T: Real>(
    order: usize,
    decimation: u16,
    gain: T,
) -> BiasCompensatedStepEstimator<T, 40, UNCERTAINTY_ORDERS> {
    BiasCompensatedStepEstimator::new(BiasCompensatedConfig::new(
        StepConfig::new(order, gain).with_decimation(decimation),
        T::from_f64(TARE_VARIANCE),
    ))
    .unwrap()
}

/// A baseline as `settled` and `moving` build it by default (blocks of 80, a 0.5 g band).
fn baseline<T: Real>(mode: BaselineMode, gain: T) -> Baseline<T, 10> {
    Baseline::new(BaselineConfig {
        mode,
        gain,
        block: 80,
        stable_band: T::from_f64(0.5),
        noise_reference: None,
    })
    .unwrap()
}

/// Every method through `estimate --method` equals the core's own type fed directly, in the
/// precision the spec names (f32: the tare removed in f64, then rounded, as the CLI does).
#[test]
fn estimate_with_every_method_equals_the_core() {
    let (csv, samples, gain, zero) = simulated_reference("methods.csv");
    let centred: Vec<f64> = samples.iter().map(|s| s - zero).collect();
    let chain = Scene::load("reference-step").unwrap().chain;
    let all_f64 = |e: &mut dyn Estimator<f64>| -> Vec<Reading<f64>> {
        centred.iter().map(|&x| e.push(x)).collect()
    };
    let all_f32 = |e: &mut dyn Estimator<f32>| -> Vec<Reading<f64>> {
        centred.iter().map(|&x| widen(e.push(x as f32))).collect()
    };
    let g32 = gain as f32;
    let model_spec = |spec: &str| match spec.parse::<Method>().unwrap() {
        Method::Model(spec) => spec,
        other => panic!("{other}"),
    };
    let bank_configs = |spec: &str| -> Vec<ModelConfig<f64, 5>> {
        method::model_candidates(&chain, gain, &model_spec(spec))
            .unwrap()
            .into_iter()
            .map(|model| ModelConfig::new(model).with_decimation(model_spec(spec).decimation))
            .collect()
    };
    let cases: Vec<(&str, Vec<Reading<f64>>)> = vec![
        (
            "step:n=7,D=16,precision=f32",
            all_f32(
                &mut StepEstimator::<f32, 40, 8>::new(StepConfig::new(7, g32).with_decimation(16))
                    .unwrap(),
            ),
        ),
        (
            "step:n=5,D=8,lambda=0.999",
            all_f64(
                &mut StepEstimator::<f64, 40, 8>::new(
                    StepConfig::new(5, gain)
                        .with_decimation(8)
                        .with_forgetting(0.999),
                )
                .unwrap(),
            ),
        ),
        ("covariance:n=7,D=16", all_f64(&mut covariance(7, 16, gain))),
        (
            "covariance:n=7,D=16,precision=f32",
            all_f32(&mut covariance(7, 16, g32)),
        ),
        (
            "model",
            all_f64(
                &mut ModelBank::<f64, 5, 33>::new(bank_configs("model").try_into().unwrap())
                    .unwrap(),
            ),
        ),
        (
            "model:D=4,K=5,span=0.9-1.2,cal_g=150",
            all_f64(
                &mut ModelBank::<f64, 5, 5>::new(
                    bank_configs("model:D=4,K=5,span=0.9-1.2,cal_g=150")
                        .try_into()
                        .unwrap(),
                )
                .unwrap(),
            ),
        ),
        (
            "settled",
            all_f64(&mut baseline(BaselineMode::SettledAverage, gain)),
        ),
        (
            "moving:precision=f32",
            all_f32(&mut baseline(BaselineMode::MovingAverage, g32)),
        ),
        (
            "ramp:n=5,D=16,lag_s=0.01",
            all_f64(
                &mut RampEstimator::<f64, 40, UNCERTAINTY_ORDERS>::new(RampConfig {
                    regression: StepConfig::new(5, gain).with_decimation(16),
                    sample_period_s: 1.0 / chain.sample_rate_hz,
                    lag_s: 0.01,
                })
                .unwrap(),
            ),
        ),
        (
            "iv:n=7,D=16",
            all_f64(
                &mut IvStepEstimator::<f64, 40, UNCERTAINTY_ORDERS>::new(IvConfig::new(
                    StepConfig::new(7, gain).with_decimation(16),
                ))
                .unwrap(),
            ),
        ),
        (
            "iv:n=5,D=12,delay=11,precision=f32",
            all_f32(
                &mut IvStepEstimator::<f32, 40, UNCERTAINTY_ORDERS>::new(
                    IvConfig::new(StepConfig::new(5, g32).with_decimation(12))
                        .with_instrument_delay(11),
                )
                .unwrap(),
            ),
        ),
        ("bc:n=3,D=16", all_f64(&mut bias_compensated(3, 16, gain))),
        (
            "bc:n=3,D=16,precision=f32",
            all_f32(&mut bias_compensated(3, 16, g32)),
        ),
    ];
    for (spec, readings) in cases {
        // Each case must exercise a valid estimate (or, for the f32 covariance form, which
        // the stability map found to lose positive definiteness, its flag), or equality
        // would prove little.
        assert!(
            readings.iter().any(|r| r.estimate.is_some())
                || readings
                    .iter()
                    .any(|r| r.state == State::Invalid(InvalidReason::LostDefiniteness)),
            "{spec}: never valid"
        );
        let stdout = run_ok(
            host_sim()
                .args(["estimate", "--method", spec, "--gain", &gain.to_string()])
                .args(["--zero", &zero.to_string()])
                // Only `bc` reads it; the others must ignore it.
                .args(["--tare-variance", &TARE_VARIANCE.to_string(), "--input"])
                .arg(&csv),
        );
        let expected = expected_lines(readings.into_iter());
        let got: Vec<&str> = stdout.lines().collect();
        assert_eq!(got.len(), expected.len(), "{spec}");
        for (g, e) in got.iter().zip(&expected) {
            assert_eq!(g, e, "{spec}");
        }
    }
}

#[test]
fn bad_method_specs_are_errors_naming_spec_key_and_expectation() {
    let csv = temp("tiny.csv");
    std::fs::write(&csv, "y\n1\n2\n").unwrap();
    for (spec, needles) in [
        (
            "model:K=4",
            vec!["model:K=4", "`K`", "[1, 3, 5, 9, 17, 33, 65]"],
        ),
        (
            "step:n=7,D=2000",
            vec!["step:n=7,D=2000", "`D`", "1 to 1024"],
        ),
        (
            "kalman:n=3",
            vec!["kalman:n=3", "unknown method", "step, covariance"],
        ),
        (
            "settled:block=80,n=7",
            vec!["`n`", "expected block, K, band_g"],
        ),
    ] {
        let output = host_sim()
            .args(["estimate", "--gain", "1", "--method", spec, "--input"])
            .arg(&csv)
            .output()
            .unwrap();
        assert!(!output.status.success(), "{spec}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        for needle in needles {
            assert!(stderr.contains(needle), "{spec}: {stderr}");
        }
    }
    // The same parser behind montecarlo --method and --config.
    let stderr = run_refused(
        host_sim()
            .args(["montecarlo", "reference-step", "--runs", "1"])
            .args(["--method", "moving:band_g=0"]),
    );
    assert!(
        stderr.contains("moving:band_g=0") && stderr.contains("`band_g`"),
        "{stderr}"
    );
    assert!(run_refused(
        host_sim()
            .args(["montecarlo", "reference-step", "--runs", "1"])
            .args(["--config", "settled"])
    )
    .contains("--method"));
    // `bc` without the tare's noise variance is refused, naming what is missing.
    let stderr = run_refused(
        host_sim()
            .args(["estimate", "--gain", "1", "--method", "bc:n=3", "--input"])
            .arg(&csv),
    );
    assert!(
        stderr.contains("bc:n=3,D=1") && stderr.contains("--tare-variance"),
        "{stderr}"
    );
    // --method and the step shorthand exclude each other.
    run_refused(
        host_sim()
            .args(["estimate", "--gain", "1", "--method", "settled"])
            .args(["--order", "3", "--input"])
            .arg(&csv),
    );
}

#[test]
fn speed_study_is_reproducible_across_thread_counts() {
    // A tiny study (16 runs at 50 dB): the CSV and the markdown must be byte-identical on
    // 1 and 2 threads, hold one row per method, and the goals must be judged.
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let dir = temp(&format!("study-{threads}"));
        let stdout = run_ok(
            host_sim()
                .env("RAYON_NUM_THREADS", threads)
                .args(["study", "speed", "--runs", "16", "--seed", "3"])
                .args(["--snr-db", "50", "--out"])
                .arg(&dir),
        );
        // Three goals of the firmware default; the final reading by 50 ms, the model-free
        // 1.25x and the model bank within 5 % of the bound with the initial state unknown.
        assert_eq!(
            stdout.matches("PASS: ").count() + stdout.matches("GAP: ").count(),
            6,
            "{stdout}"
        );
        assert!(
            stdout.contains("the CRLB allows a final reading from"),
            "{stdout}"
        );
        let csv = std::fs::read_to_string(dir.join("speed-study.csv")).unwrap();
        let markdown = std::fs::read_to_string(dir.join("speed-study.md")).unwrap();
        for chart in [
            "e-rms-vs-readout-time",
            "f-time-to-0p1pct-vs-snr",
            "k-time-to-final-vs-snr",
        ] {
            for extension in ["svg", "png"] {
                assert!(dir.join(format!("{chart}.{extension}")).exists());
            }
        }
        outputs.push((csv, markdown));
    }
    assert_eq!(outputs[0], outputs[1]);
    let csv = &outputs[0].0;
    assert_eq!(
        csv.lines().count(),
        1 + host_sim::study::default_entries().unwrap().len()
            + host_sim::study::baselines::FAMILY_NAMES.len()
    );
    // The first row is the method firmware/weighing.toml configures, in f32.
    let (firmware, _) = host_sim::study::firmware_default().unwrap();
    let first = csv.lines().nth(1).unwrap();
    assert!(
        first.starts_with(&format!(
            "firmware default (firmware/weighing.toml),{},50,16,",
            firmware.to_string().replace(',', " ")
        )),
        "{first}"
    );
}

/// What a user types first: `--version`, a negative number as a value, and estimates in
/// plain decimals, not `1.38e2`.
#[test]
fn version_negative_values_and_plain_decimals() {
    let version = run_ok(host_sim().arg("--version"));
    assert_eq!(
        version.trim(),
        format!("host-sim {}", env!("CARGO_PKG_VERSION"))
    );

    let (csv, _, gain, zero) = simulated_reference("negative-gain.csv");
    let estimates = |gain: f64| -> Vec<(String, String)> {
        let out = run_ok(
            host_sim()
                .args(["estimate", "--method", "step:n=5,D=24", "--input"])
                .arg(&csv)
                .args(["--gain", &gain.to_string(), "--zero", &zero.to_string()]),
        );
        out.lines()
            .skip(1)
            .map(|line| {
                let fields: Vec<&str> = line.split(',').collect();
                (fields[1].to_string(), fields[2].to_string())
            })
            .collect()
    };
    let positive = estimates(gain);
    let negative = estimates(-gain);
    assert_eq!(positive.len(), negative.len());
    let mut valid = 0;
    for ((p, p_state), (n, n_state)) in positive.iter().zip(&negative) {
        assert_eq!(p_state, n_state);
        assert!(!p.contains(['e', 'E']), "not a plain decimal: {p}");
        if p.is_empty() {
            assert!(n.is_empty());
            continue;
        }
        valid += 1;
        let (p, n): (f64, f64) = (p.parse().unwrap(), n.parse().unwrap());
        assert!((p + n).abs() <= 1e-9 * p.abs().max(1.0), "{p} vs {n}");
    }
    assert!(valid > 1000, "only {valid} valid estimates");
}

/// A moved or installed binary finds the shipped scenes and the firmware's configuration
/// (they are in it, not read from the source tree it was built in): a copy of it in a
/// directory of its own, run from there, simulates a shipped scene and replays it with the
/// built-in configuration.
#[test]
fn a_moved_binary_needs_nothing_from_its_source_tree() {
    let dir = temp("moved-binary");
    std::fs::create_dir_all(&dir).unwrap();
    let moved = dir.join("host-sim");
    std::fs::copy(env!("CARGO_BIN_EXE_host-sim"), &moved).unwrap();
    let run = |args: &[&str]| {
        let mut command = std::process::Command::new(&moved);
        command
            .args(args)
            .current_dir(&dir)
            .env_remove("CARGO_MANIFEST_DIR");
        // A test thread that forks while the copy's file is still open for writing
        // keeps it open in its child until that child execs: the copy cannot be
        // executed for that moment ("Text file busy"). Wait it out; nothing else retries.
        let mut tries = 0;
        let output = loop {
            match command.output() {
                Err(e) if e.kind() == std::io::ErrorKind::ExecutableFileBusy && tries < 100 => {
                    tries += 1;
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                result => break result.unwrap(),
            }
        };
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        String::from_utf8(output.stdout).unwrap()
    };
    run(&[
        "simulate",
        "calibration-drop",
        "--seed",
        "5",
        "--out",
        "drop.csv",
    ]);
    let csv = std::fs::read_to_string(dir.join("drop.csv")).unwrap();
    assert!(csv.starts_with("t,y,truth\n") && csv.lines().count() > 1000);
    let replay = run(&["replay", "--input", "drop.csv"]);
    assert!(replay.starts_with("t_s,mass_g,u_g,state,final"), "{replay}");
    assert!(replay.lines().count() > 10, "{replay}");
}

/// `study coverage --scene FILE` names the charts by the file's stem: a scene given as a
/// path once made the chart's name a path into a directory that did not exist, and the
/// study failed after its runs with "drawing failed: No such file or directory".
#[test]
fn coverage_study_on_a_scene_file_names_its_charts_by_the_stem() {
    let out = temp("coverage-on-file");
    let _ = std::fs::remove_dir_all(&out);
    let scene = temp("my-drop.toml");
    std::fs::write(
        &scene,
        "duration_s = 0.5\n[[events]]\ntime_s = 0.0\nmass_g = 200.0\n",
    )
    .unwrap();
    run_ok(
        host_sim()
            .args([
                "study", "coverage", "--runs", "8", "--seed", "1", "--snr-db", "50",
            ])
            .args(["--method", "step:n=5,D=24", "--scene"])
            .arg(&scene)
            .arg("--out")
            .arg(&out),
    );
    assert!(out.join("coverage-my-drop-0.svg").exists());
    assert!(out.join("coverage.md").exists());
}
