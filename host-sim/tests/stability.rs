//! The stability map (`host-sim study stability`): the failure modes that need the simulator
//! (a heavy drop's overshoot clipping the ADC; the consistency check against a tare metered
//! in coloured noise, where it must not fire, and the modes it leaves silent), its
//! classification of cells, and its reproducibility. The core's own regression tests are in
//! estimator-core/tests/stability.rs.

use estimator_core::{
    Estimator, InvalidReason, NoiseReference, Reading, Real, State, StepConfig, StepEstimator,
};

use estimator_core::sensor::AdcSource;
use host_sim::method::{measured_tare_reference, BuildContext, Method};
use host_sim::montecarlo::tare_record;
use host_sim::scene::Scene;
use host_sim::simulated::{run_seed, LoadEvent, Script};
use host_sim::stability::{
    mass_for_ratio, noisy_scene, readout_indices, vibration_gain, Cell, Class, Noise,
};

mod support;

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
        let output = support::host_sim()
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

// ---------------------------------------------------------------------------------------
// The consistency check (estimator-core `consistency`, `InvalidReason::ModelMismatch`).

/// The reference scene at `snr_db` with `noise` as slice B of the map adds it.
fn slice_b_scene(snr_db: f64, noise: Noise, gain: f64) -> Scene {
    noisy_scene(&Scene::load("reference-step").unwrap(), snr_db, noise, gain)
}

/// Run `run`'s 1.5 s record (tare removed) and its 0.3 s tare on the own noise stream, as
/// the stability map seeds them.
fn record_and_tare(scene: &Scene, run: u64) -> (Vec<f64>, Vec<f64>) {
    let zero = scene.chain.zero_code();
    let mut adc = scene.adc(run_seed(1, run));
    let samples = readout_indices(scene)[1] + 1;
    let record = (0..samples)
        .map(|_| f64::from(adc.read().unwrap()) - zero)
        .collect();
    (record, tare_record(scene, 1, run))
}

/// The step estimator of `order`, `decimation` with the tare metered at its own D as its
/// noise reference (what `BuildContext::noise_check` gives the methods).
fn checked_step<T: Real>(
    order: usize,
    decimation: u16,
    gain: f64,
    tare: &[f64],
) -> StepEstimator<T, 8> {
    let (variance, differences) = measured_tare_reference(tare, decimation).unwrap();
    StepEstimator::new(
        StepConfig::new(order, T::from_f64(gain))
            .with_decimation(decimation)
            .with_noise_reference(NoiseReference::new(T::from_f64(variance), differences)),
    )
    .unwrap()
}

fn mismatch<T>(reading: &Reading<T>) -> bool {
    reading.state == State::Invalid(InvalidReason::ModelMismatch)
}

#[test]
fn the_consistency_check_does_not_fire_in_the_valid_region() {
    // The firmware default (`step:n=5,D=24` in f32) and `step:n=7,D=16` on the reference
    // scene, 30–80 dB, with white noise, with vibration near the loaded resonance and with
    // 50 Hz mains (each at the white noise's RMS, as slice B of the map adds them), the tare
    // metered per run at the method's D over 0.3 s of empty pan with the same noises.
    // 216 runs per configuration and noise (36 at each of the 6 SNRs), the whole 1.5 s.
    //
    // Designed: a correctly modelled record with white noise flags a reading with
    // probability below MISMATCH_FALSE_ALARM = 1e-5 before the allowance of 2; readings of
    // one run share rows, so by the union bound a run of R readings flags with probability
    // below R·1e-5. Over the 432 white-noise runs here (R = 239 at D = 24, 360 at D = 16)
    // that is at most 1.3 flagged runs expected; a Poisson count of mean 1.3 exceeds 5 with
    // probability 0.2%: allow 5. The coloured noises are outside the design (a tare cannot
    // show the loaded pan's vibration): measured beforehand, 2 of 2,100 runs of n = 7
    // flagged under vibration (at 20–30 dB, where a 0.3 s tare caught a quiet stretch of a
    // 1 Hz wide vibration) and none under mains (which the fit absorbs); allow 1% of runs.
    // And the f32 path against f64 on the same data: the flags agree at every reading, and
    // at the end of the window the residual ratios are within 1% of themselves (or of 1,
    // what noise alone gives, where they are smaller): single-precision rounding of 138 g is
    // 8e-6 g, 0.3% of the block means' noise at 80 dB, D = 24, and the ratio sums squares,
    // about twice that. (In the few rows right after warm-up, where the fit is barely
    // determined, the rounding is amplified: up to 3% was seen there at 80 dB, which the
    // growing window then dilutes.)
    let snrs = [30.0, 40.0, 50.0, 60.0, 70.0, 80.0];
    let runs_per_snr = 36u64;
    let gain_v = vibration_gain(&Scene::load("reference-step").unwrap());
    let mut worst_ratio_difference = 0.0f64;
    for noise in [Noise::White, Noise::Vibration, Noise::Mains] {
        for (order, decimation) in [(5usize, 24u16), (7, 16)] {
            let (mut flagged_runs, mut flagged_readings, mut readings) = (0u32, 0u64, 0u64);
            let mut largest_ratio = 0.0f64;
            for &snr_db in &snrs {
                let scene = slice_b_scene(snr_db, noise, gain_v);
                let gain = scene.chain.counts_per_gram();
                for run in 0..runs_per_snr {
                    let (record, tare) = record_and_tare(&scene, run);
                    let mut single = checked_step::<f32>(order, decimation, gain, &tare);
                    let mut double = checked_step::<f64>(order, decimation, gain, &tare);
                    let mut flagged = false;
                    for (k, &sample) in record.iter().enumerate() {
                        let reading = single.push(sample as f32);
                        let reference = double.push(sample);
                        if (k + 1) % usize::from(decimation) != 0 {
                            continue;
                        }
                        if let (Some(a), Some(b)) =
                            (single.residual_ratio(), double.residual_ratio())
                        {
                            readings += 1;
                            largest_ratio = largest_ratio.max(b);
                            // Relative to the ratio, or to 1 (what the noise alone gives)
                            // where the ratio is smaller: a first row's quotient can be tiny.
                            if k + 1 == record.len() {
                                let difference = (f64::from(a) - b).abs() / b.max(1.0);
                                worst_ratio_difference = worst_ratio_difference.max(difference);
                            }
                        }
                        if mismatch(&reading) {
                            flagged_readings += 1;
                            flagged = true;
                        }
                        assert_eq!(
                            mismatch(&reading),
                            mismatch(&reference),
                            "{noise:?} {snr_db} dB n={order} D={decimation} run {run} k={k}: f32 and f64 disagree"
                        );
                    }
                    flagged_runs += u32::from(flagged);
                }
            }
            let runs = runs_per_snr as u32 * snrs.len() as u32;
            println!(
                "{noise:?} n={order} D={decimation}: {flagged_runs}/{runs} runs and {flagged_readings}/{readings} readings flagged ModelMismatch (designed for white noise: < 1e-5 a reading); largest residual ratio {largest_ratio:.2}"
            );
            match noise {
                Noise::White => assert!(flagged_runs <= 5, "{flagged_runs}"),
                _ => assert!(flagged_runs * 100 <= runs, "{flagged_runs}"),
            }
        }
    }
    println!("f32 against f64: residual ratios within {worst_ratio_difference:.2e}");
    assert!(worst_ratio_difference < 0.01, "{worst_ratio_difference}");
}

/// The first `samples` readings of `spec` on `run`'s record of `scene`, its tare metered at
/// its own D and checked (as `BuildContext::noise_check` and the map run it).
fn checked_readings(spec: &str, scene: &Scene, run: u64, samples: usize) -> Vec<Reading<f64>> {
    let method: Method = spec.parse().unwrap();
    let (record, tare) = record_and_tare(scene, run);
    let context = BuildContext {
        noise_check: true,
        ..BuildContext::new(scene.chain, scene.chain.counts_per_gram())
            .with_adc_rails(scene.chain.zero_code())
    }
    .with_tare(&tare, method.reference_decimation().unwrap());
    let mut estimator = method.build(&context).unwrap();
    record
        .iter()
        .take(samples)
        .map(|&s| estimator.push(s))
        .collect()
}

#[test]
fn the_modes_the_check_cannot_see_stay_silent_and_are_refused_or_mitigated_by_configuration() {
    // What the residuals cannot show, pinned so that a change that starts to flag them (or
    // makes them worse) is seen. 12 runs each; CRLB from the map's bound (known model,
    // onset, tare), here at 100 ms: 0.0201 g at 50 dB, 0.00201 g at 70 dB (host-sim README).
    let runs = 12u64;
    let at_100_ms = 400;
    let rms =
        |errors: &[f64]| (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();

    // 1. The ramp estimator on a step with 50 Hz mains (50 dB): it fits a slope to the
    //    sinusoid, and the fit leaves no more than the tare's noise, which holds the mains:
    //    no flag, the reading 10× the bound (the map: 10.4–11.3× at 40–60 dB).
    let gain_v = vibration_gain(&Scene::load("reference-step").unwrap());
    let mains = slice_b_scene(50.0, Noise::Mains, gain_v);
    let mut errors = Vec::new();
    for run in 0..runs {
        let readings = checked_readings("ramp:n=5,D=16", &mains, run, at_100_ms + 1);
        assert!(
            !readings.iter().any(mismatch),
            "ramp with mains flagged: run {run}"
        );
        errors.push(readings[at_100_ms].estimate.unwrap() - 138.32);
    }
    // The CRLB with the mains' power counted as white (as the map judges slice B): √2 ×.
    let bound = 0.0201 * std::f64::consts::SQRT_2;
    println!(
        "ramp on a step with mains, 50 dB: {:.1}x the bound at 100 ms, no flag",
        rms(&errors) / bound
    );
    assert!(rms(&errors) > 5.0 * bound, "{}", rms(&errors) / bound);

    // 2. A model bank's 2% grid at 70 dB, the load at 0.9× the calibrated resonance: the
    //    interpolated estimate is biased (the map: 19× the bound at 100 ms); a grid does not
    //    check its residuals (ModelBank docs) and flags nothing. The mitigation is a denser
    //    bank, 65 candidates: within 10× here.
    let base = Scene::load("reference-step").unwrap();
    let mut off = base.with_snr_db(70.0);
    let mass_g = mass_for_ratio(&base, 0.9);
    let mut script = Script::new(1.5);
    script.push(LoadEvent::step(0.0, mass_g)).unwrap();
    off.script = script;
    let mut ratios = Vec::new();
    for spec in ["model", "model:K=65"] {
        let mut errors = Vec::new();
        for run in 0..runs {
            let readings = checked_readings(spec, &off, run, at_100_ms + 1);
            assert!(!readings.iter().any(mismatch), "{spec}: a grid flagged");
            errors.push(readings[at_100_ms].estimate.unwrap() - mass_g);
        }
        let crlb_g = host_sim::montecarlo::crlb_g2(&off, mass_g, at_100_ms + 1)[at_100_ms].sqrt();
        ratios.push(rms(&errors) / crlb_g);
    }
    println!(
        "bank at 0.9x, 70 dB, 100 ms: K=33 {:.1}x the bound, K=65 {:.1}x, no flag",
        ratios[0], ratios[1]
    );
    assert!(ratios[0] > 10.0 && ratios[1] < 10.0, "{ratios:?}");

    // 3. The full-rate regression (D = 1) at 60 dB: the check flags it while the transient
    //    is in the fit (at 100 ms) but not at 1.5 s, where the errors-in-variables bias is
    //    still over 10× the bound; configuration refuses D = 1 instead (estimator-core's
    //    `a_full_rate_regression_is_refused_by_configuration`).
    let quiet = base.with_snr_db(60.0);
    let last = readout_indices(&quiet)[1];
    let crlb_end = host_sim::montecarlo::crlb_g2(&quiet, 138.32, last + 1)[last].sqrt();
    let (mut flagged_at_100, mut errors_at_end) = (0, Vec::new());
    for run in 0..runs {
        let readings = checked_readings("step:n=7,D=1", &quiet, run, last + 1);
        flagged_at_100 += u32::from(mismatch(&readings[at_100_ms]));
        if let Some(estimate) = readings[last].estimate {
            errors_at_end.push(estimate - 138.32);
        }
    }
    println!(
        "step n=7 D=1, 60 dB: {flagged_at_100}/{runs} flagged at 100 ms; at 1.5 s {} valid, {:.0}x the bound",
        errors_at_end.len(),
        rms(&errors_at_end) / crlb_end
    );
    assert!(flagged_at_100 as u64 * 2 > runs);
    assert!(errors_at_end.len() as u64 * 2 > runs && rms(&errors_at_end) > 10.0 * crlb_end);
}

#[test]
fn a_single_model_off_its_load_is_flagged_a_grid_never_is() {
    // One model at the 200 g calibration (`model:K=1`) on the reference drop (138.32 g, its
    // resonance 1.11× the calibrated one) at 50 dB: the map found it 13–10⁴× the bound,
    // silent. With the tare as its reference every run is flagged by 100 ms. The same model
    // at its own load is not flagged; nor is the firmware's identified bank anywhere from
    // 0.3× to 3× the calibration mass (a grid does not check; ModelBank docs). 24 runs each.
    let base = Scene::load("reference-step").unwrap();
    let runs = 24u64;
    let at_100_ms = 400;
    let reference = base.with_snr_db(50.0);
    let mut at_calibration = reference.clone();
    let mut script = Script::new(1.5);
    script.push(LoadEvent::step(0.0, 200.0)).unwrap();
    at_calibration.script = script;
    let single = "model:K=1,span=0.999-1.001,cal_g=200";
    let (mut off_flagged, mut on_flagged) = (0, 0);
    for run in 0..runs {
        off_flagged += u32::from(mismatch(
            &checked_readings(single, &reference, run, at_100_ms + 1)[at_100_ms],
        ));
        on_flagged += u32::from(
            checked_readings(single, &at_calibration, run, 6000)
                .iter()
                .any(mismatch),
        );
    }
    println!("one model: flagged at 100 ms in {off_flagged}/{runs} runs off its load; in {on_flagged}/{runs} runs at its load (whole 1.5 s)");
    assert_eq!(off_flagged as u64, runs);
    // At its own load the check's design holds (white block means): 24 runs × 750 readings
    // × 1e-5 = 0.2 expected flagged runs; allow 2.
    assert!(on_flagged <= 2, "{on_flagged}");

    let bank = "model:D=8,K=33,span=0.68-1.3,fn_hz=25.000156487736767,zeta=0.0300060250982748";
    for factor in [0.3, 0.5, 1.0, 2.0] {
        let mut scene = reference.clone();
        let mut script = Script::new(1.5);
        script.push(LoadEvent::step(0.0, factor * 138.32)).unwrap();
        scene.script = script;
        for run in 0..4 {
            let readings = checked_readings(bank, &scene, run, 6000);
            assert!(!readings.iter().any(mismatch), "bank at {factor}x: flagged");
            assert!(readings[at_100_ms].estimate.is_some(), "bank at {factor}x");
        }
    }
}
