//! The stability map (`host-sim study stability`): the failure mode it found that needs the
//! simulator (a heavy drop's overshoot clipping the ADC), its classification of cells, and
//! its reproducibility. The core's own regression tests are in
//! estimator-core/tests/stability.rs.

use std::process::Command;

use estimator_core::{AdcSource, InvalidReason, State};
use host_sim::method::{BuildContext, Method};
use host_sim::scene::Scene;
use host_sim::simulated::{LoadEvent, Script};
use host_sim::stability::{mass_for_ratio, Cell, Class};

/// The reference chain with `mass_g` dropped at t = 0, at the reference scene's noise.
fn drop_of(mass_g: f64) -> Scene {
    let mut scene = Scene::load("reference-step").unwrap();
    let mut script = Script::new(1.5);
    script.push(LoadEvent::step(0.0, mass_g)).unwrap();
    scene.script = script;
    scene
}

#[test]
fn a_drop_whose_overshoot_clips_the_adc_is_refused_by_every_method() {
    // The map (slice C): drops of 380–593 g (the resonance 0.8–0.67× the one at 200 g)
    // overshoot to ~1.9× the load, beyond the 16-bit ADC's 666 g full scale; the clipped
    // record was estimated silently by every method, thousands of CRLBs off. The method
    // layer now gives the estimators the ADC's rails (`BuildContext::with_adc_rails`), so
    // the core refuses a clipped sample as `OutOfRange` and latches. Here: 380 g (×0.8).
    let mass_g = mass_for_ratio(&Scene::load("reference-step").unwrap(), 0.8);
    assert!((mass_g - 380.0).abs() < 1.0, "{mass_g}");
    let scene = drop_of(mass_g);
    let chain = scene.chain;
    let (gain, zero) = (chain.counts_per_gram(), chain.zero_code());
    let mut adc = scene.adc(3);
    let codes: Vec<u32> = (0..6000).map(|_| adc.read().unwrap()).collect();
    let top = chain.adc.max_code();
    let first_clip = codes
        .iter()
        .position(|&c| c == top)
        .expect("the overshoot clips");
    let samples: Vec<f64> = codes.iter().map(|&c| f64::from(c) - zero).collect();
    let context = BuildContext {
        tare_noise_variance: Some(1063.0),
        ..BuildContext::new(chain, gain).with_adc_rails(zero)
    };
    for spec in [
        "step:n=7,D=16,precision=f32",
        "step:n=7,D=1",
        "covariance:n=7,D=16",
        "iv:n=7,D=16",
        "bc:n=7,D=16",
        "ramp:n=5,D=16",
        "model",
    ] {
        let method: Method = spec.parse().unwrap();
        let mut estimator = method.build(&context).unwrap();
        for (k, &sample) in samples.iter().enumerate() {
            let reading = estimator.push(sample);
            if k >= first_clip {
                assert_eq!(
                    (reading.state, reading.estimate),
                    (State::Invalid(InvalidReason::OutOfRange), None),
                    "{spec}: k={k}"
                );
            }
        }
    }
    // Without the rails the same record gives a silent wrong number: what the flag prevents.
    let unranged = BuildContext::new(chain, gain);
    let mut estimator = "step:n=7,D=16"
        .parse::<Method>()
        .unwrap()
        .build(&unranged)
        .unwrap();
    let at_100_ms = samples
        .iter()
        .take(401)
        .map(|&s| estimator.push(s))
        .last()
        .unwrap();
    let error = (at_100_ms.estimate.unwrap() - mass_g).abs();
    println!("unranged step estimator on the clipped drop: {error:.1} g off at 100 ms");
    // The CRLB at 100 ms is ~0.02 g; the map's cell was 433× it (20 runs).
    assert!(error > 1.0, "{error}");
}

#[test]
fn cells_are_classified_by_what_their_runs_did() {
    let crlb_g = 0.02;
    let base = Cell {
        runs: 100,
        crlb_g,
        ..Cell::default()
    };
    let valid = |rms_g: f64| Cell {
        valid: 100,
        sum_squared_g2: 100.0 * rms_g * rms_g,
        ..base.clone()
    };
    assert_eq!(valid(0.19).class(), (Class::Ok, false));
    assert_eq!(valid(0.21).class(), (Class::OverBound, true));
    let mut refused = valid(0.01);
    refused.valid = 40;
    refused.sum_squared_g2 = 40.0 * 0.01 * 0.01;
    refused.flagged[2] = 60;
    assert_eq!(refused.class(), (Class::Refused, false));
    refused.flagged[2] = 10;
    refused.warming = 50;
    assert_eq!(refused.class(), (Class::OkPartly, false));
    // A loss of definiteness is silent when a run that lost it still gave a reading.
    let mut lost = valid(0.01);
    lost.lost_definiteness = 3;
    assert_eq!(lost.class(), (Class::LostDefiniteness, false));
    lost.lost_definiteness_valid = 1;
    assert_eq!(lost.class(), (Class::LostDefiniteness, true));
    let mut diverged = valid(0.01);
    diverged.diverged = 1;
    assert_eq!(diverged.class(), (Class::Diverged, true));
    let not_yet = Cell {
        warming: 100,
        ..base.clone()
    };
    assert_eq!(not_yet.class(), (Class::NotYet, false));
}

#[test]
fn the_stability_study_is_reproducible_across_thread_counts() {
    // A tiny map (4 runs a cell, 50 dB, orders 3 and 7, long runs of 2·10⁴ samples): the
    // CSV and the markdown must be byte-identical on 1 and 2 threads (the wall time aside),
    // and every chart written.
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let dir = std::env::temp_dir().join(format!(
            "host-sim-stability-{}-{threads}",
            std::process::id()
        ));
        let output = Command::new(env!("CARGO_BIN_EXE_host-sim"))
            .env("RAYON_NUM_THREADS", threads)
            .args(["study", "stability", "--runs", "4", "--seed", "2"])
            .args([
                "--snr-db",
                "50",
                "--orders",
                "3,7",
                "--long-samples",
                "20000",
            ])
            .arg("--out")
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let stdout = String::from_utf8(output.stdout).unwrap();
        assert!(stdout.contains("f32 goal"), "{stdout}");
        for chart in [
            "g-stability-order-snr-100ms",
            "g-stability-order-snr-1500ms",
            "h-stability-noise",
            "i-stability-off-calibration",
            "j-stability-long-runs-d1",
            "j-stability-long-runs-d16",
        ] {
            for extension in ["svg", "png"] {
                assert!(dir.join(format!("{chart}.{extension}")).exists(), "{chart}");
            }
        }
        let csv = std::fs::read_to_string(dir.join("stability-map.csv")).unwrap();
        let long = std::fs::read_to_string(dir.join("stability-long-runs.csv")).unwrap();
        let markdown: String = std::fs::read_to_string(dir.join("stability-map.md"))
            .unwrap()
            .lines()
            .filter(|l| !l.contains(" s wall"))
            .collect();
        outputs.push((csv, long, markdown));
    }
    assert_eq!(outputs[0], outputs[1]);
    // Slice A: 5 families × 2 orders × 2 precisions; B: 3 noises; C: 10 resonances at the
    // one noise level kept (50 dB); the default probes 10 × 2 precisions; 2 readouts each.
    let cells = 2 * (20 + 20 * 3 + 20 * 10);
    assert_eq!(outputs[0].0.lines().count(), 1 + cells);
}
