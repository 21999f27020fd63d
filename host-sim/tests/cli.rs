//! The `host-sim` command: `simulate` writes the scene, `estimate` on that CSV equals the
//! core called directly (same numbers, same states), bad input becomes an error naming it.

use std::path::PathBuf;
use std::process::Command;

use estimator_core::{Estimator, StepConfig, StepEstimator};
use host_sim::estimate::state_name;
use host_sim::scene::Scene;

fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("host-sim-cli-{}", std::process::id()));
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
        let mut expected = vec!["k,estimate,state".to_string()];
        let config64 = StepConfig::new(order, gain).with_decimation(decimation as u16);
        let mut core64 = StepEstimator::<f64, 40>::new(config64).unwrap();
        let config32 = StepConfig::new(order, gain as f32).with_decimation(decimation as u16);
        let mut core32 = StepEstimator::<f32, 40>::new(config32).unwrap();
        for (k, sample) in samples.iter().enumerate() {
            let (estimate, state) = if precision == "f64" {
                let r = core64.push(sample - zero);
                (r.estimate, r.state)
            } else {
                let r = core32.push((sample - zero) as f32);
                (r.estimate.map(f64::from), r.state)
            };
            expected.push(match estimate {
                Some(value) => format!("{k},{value:e},{}", state_name(state)),
                None => format!("{k},,{}", state_name(state)),
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
    let output = host_sim()
        .args(["estimate", "--order", "1", "--gain", "1", "--input"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("line 3") && stderr.contains("abc"),
        "{stderr}"
    );
    std::fs::write(&csv, "t,x\n0,1\n").unwrap();
    let output = host_sim()
        .args(["estimate", "--order", "1", "--gain", "1", "--input"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("column `y`"));
}

#[test]
fn malformed_scene_file_error_names_file_and_key() {
    let scene = temp("broken.toml");
    std::fs::write(&scene, "[[events]]\ntime_s = 0.0\nmass_g = \"heavy\"\n").unwrap();
    let output = host_sim()
        .args(["simulate", "--out", "/dev/null"])
        .arg(&scene)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
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
    assert_eq!(outputs[0].lines().count(), 1 + 2 * 600);
}
