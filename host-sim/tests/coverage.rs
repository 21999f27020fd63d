//! The stated uncertainty holds: ±2u covers about 95 % of the errors of the firmware's
//! method on the reference drop, and f32 states the same `u` as f64 on the same data.
//!
//! Before the sandwich form (`estimator_core::estimators::step_uncertainty`), the
//! white-noise least-squares `u` of the same method covered 60–74 % (RMS error/u 2.0–2.8)
//! at 30–70 dB: over-confident by a factor of two.

use estimator_core::sensor::AdcSource;
use estimator_core::{Autocovariance, Estimator, StepConfig, StepEstimator, MIN_METERED_BLOCKS};
use host_sim::coverage::{metered_autocovariance, study, study_with, Colour, TIMES_MS};
use host_sim::scene::Scene;
use host_sim::study::firmware_default;

#[test]
fn two_u_covers_95_percent_of_the_firmware_methods_errors() {
    let (method, _) = firmware_default().unwrap();
    let rows = study("reference-step", &method, 600, 7, &[30.0, 50.0, 70.0]).unwrap();
    for row in &rows {
        for (t, cell) in TIMES_MS.iter().zip(&row.cells) {
            if *t < 100 {
                // Warming up, or too few rows for u: nothing is stated, so nothing can be
                // over-confident.
                assert_eq!(cell.stated, 0, "{} dB {t} ms", row.snr_db);
                continue;
            }
            let coverage = cell.coverage().unwrap();
            let rms_z = cell.rms_z().unwrap();
            assert!(cell.stated >= 590, "{} dB {t} ms: {cell:?}", row.snr_db);
            // The goal is 95 % ± 3 %; `study coverage --runs 1000 --seed 1` measures
            // 92.1-95.6 % (RMS error/u 0.98-1.15: u is still slightly small). This test
            // is the floor against over-confidence, with the Monte Carlo band at 600 runs
            // (±1.7 %) below the goal's edge: the white-noise u it replaced covered 60-74 %.
            assert!(
                (0.90..=0.99).contains(&coverage) && rms_z < 1.25,
                "{} dB {t} ms: {:.1} % (rms z {rms_z:.2})",
                row.snr_db,
                100.0 * coverage
            );
        }
    }
}

/// f32 on the target states the f64 `u` of the same data within 10 % from the first
/// readout (100 ms) at 30 and 50 dB, with the `u` from the residuals and resting on the
/// empty pan's metered noise colour. At 70 dB the first readings after 100 ms differ by up
/// to 12 % (the f32 influence row `z` on a Hankel matrix that ill-conditioned) and 1 % from
/// 200 ms: checked from there. Floor vibration at 80 dB, from 200 ms, too: there the
/// residuals leave more than the metered colour explains in most runs late in a drop, and
/// the `u` rests on their own sandwich.
#[test]
fn f32_states_the_f64_uncertainty() {
    for (name, snr_db, from_sample) in [
        ("reference-step", 30.0, 400),
        ("reference-step", 50.0, 400),
        ("reference-step", 70.0, 800),
        ("vibration", 80.0, 800),
    ] {
        let scene = Scene::load(name).unwrap().with_snr_db(snr_db);
        let gain = scene.chain.counts_per_gram();
        let zero = scene.chain.zero_code();
        let metered = metered_autocovariance(&scene, 24, 5).unwrap();
        for colour in [None, Some(metered)] {
            let mut worst = 0.0f64;
            // Readings with the colour whose `u` rests on the residuals (their degrees of
            // freedom, not the metering's).
            let mut on_residuals = 0;
            for seed in 1..=40 {
                let mut adc = scene.adc(seed);
                let mut e64 = StepEstimator::<f64, 5, 5, 10>::new(
                    StepConfig::new(5, gain).with_decimation(24),
                )
                .unwrap();
                let mut e32 = StepEstimator::<f32, 5, 5, 10>::new(
                    StepConfig::new(5, gain as f32).with_decimation(24),
                )
                .unwrap();
                e64.set_noise_autocovariance(colour.as_ref()).unwrap();
                let colour32 = colour.map(|c| Autocovariance {
                    lags: c.lags.map(|lag| lag as f32),
                    blocks: c.blocks,
                });
                e32.set_noise_autocovariance(colour32.as_ref()).unwrap();
                for k in 1..=4000 {
                    let centred = f64::from(adc.read().unwrap()) - zero;
                    let (a, b) = (e64.push(centred), e32.push(centred as f32));
                    if k >= from_sample {
                        let (u64_, u32_) = (a.uncertainty.unwrap(), b.uncertainty.unwrap());
                        worst = worst.max((f64::from(u32_) / u64_ - 1.0).abs());
                        on_residuals += u32::from(a.degrees_of_freedom < MIN_METERED_BLOCKS);
                    }
                }
            }
            let label = if colour.is_some() {
                "metered"
            } else {
                "residuals"
            };
            assert!(
                worst < 0.1,
                "{name} {snr_db} dB, {label}: f32 u off by {worst}"
            );
            if name == "vibration" && colour.is_some() {
                assert!(on_residuals > 0, "the residuals' sandwich never checked");
            }
        }
    }
}

/// The identified-model bank's `u` in its first readings. Before the grid's model choice
/// entered `u` (the candidates' own `u`, interpolated, knew nothing of which model), ±2u at
/// 25 ms covered 68 % at 50 dB and at 50 ms 89 % on the reference drop; with the choice's
/// spread in quadrature (`ModelBank::combined`), 95 % and 92 %. In the rig's coloured noise
/// and with floor vibration it still covered 4–75 % at 25–50 ms (`study coverage --runs
/// 1000 --seed 1`): a fit over less than about one and a half periods of the mode tells the
/// step from the ringing by detail that anything but white noise moves. So the bank states
/// no `u` before its step response's second maximum (64 ms on the reference cell), and
/// from there ±2u must hold in both scenes. The floor here is the goal's edge less this
/// run count's Monte Carlo band.
#[test]
fn the_bank_states_no_u_before_the_cell_has_rung_and_a_u_that_holds_after() {
    let (_, config) = firmware_default().unwrap();
    let bank = host_sim::study::identified_bank(&config, host_sim::montecarlo::Precision::F32);
    for scene in ["reference-step", "rig-noise"] {
        let rows = study(scene, &bank, 400, 3, &[50.0]).unwrap();
        for (t, cell) in TIMES_MS.iter().zip(&rows[0].cells) {
            if *t <= 50 {
                assert_eq!(cell.stated, 0, "{scene} {t} ms");
            } else if *t <= 150 {
                let coverage = cell.coverage().unwrap();
                assert!(
                    coverage >= 0.90 && cell.stated >= 390,
                    "{scene} {t} ms: {:.1} % of {} stated",
                    100.0 * coverage,
                    cell.stated
                );
            }
        }
    }
}

/// The firmware's bank (K = 33, three-point, its block means fitted as they are) is cautious
/// in the rig's noise from 60 dB on: its residuals carry the grid's misfit. The identified
/// bank over twice the grid, combined by five points and whitening its block means with the
/// empty pan's metered colour (`interp=5,whiten=32`) holds the goal there 150–400 ms after
/// the landing (`host-sim study coverage --runs 1000 --seed 1 --method model:D=8,K=65,…`:
/// 94.7–96.9 % in the rig's noise at 60–80 dB), where the firmware's bank covered 99.5–100 %
/// (RMS error/u 0.41–0.65). 400 runs at 60 and 80 dB: ±2u within 92–98 %, RMS error/u
/// within 0.9–1.1.
#[test]
fn the_whitened_five_point_bank_holds_the_goal_in_the_rigs_noise() {
    let (_, config) = firmware_default().unwrap();
    let bank = host_sim::study::calibrated_bank(&config, host_sim::montecarlo::Precision::F32);
    let rows = study("rig-noise", &bank, 400, 1, &[60.0, 80.0]).unwrap();
    for row in &rows {
        for (t, cell) in TIMES_MS.iter().zip(&row.cells) {
            if *t < 150 {
                continue;
            }
            let (coverage, rms_z) = (cell.coverage().unwrap(), cell.rms_z().unwrap());
            assert!(
                (0.92..=0.98).contains(&coverage) && (0.9..=1.1).contains(&rms_z),
                "{} dB {t} ms: {:.1} % (rms z {rms_z:.2})",
                row.snr_db,
                100.0 * coverage
            );
        }
    }
}

/// The whitened bank's noise level: the interpolated model is chosen anew with each block
/// in its residual sums, so its residuals are partly fitted and their mean square falls
/// short of the whitened block means' variance; the `u` came out 4–8 % small: RMS error/u
/// 1.07–1.10 and ±2u 92.5–93.6 % 100 ms after the landing on the reference drop at 30–50 dB
/// (`host-sim study coverage --runs 1000 --seed 1 --scene reference-step --method
/// model:D=8,K=65,…,interp=5,whiten=32` before the floor). With the metered prediction error
/// as its floor: 0.99–1.01 and 94.6–94.9 %. The same 3,000 runs: at 100 ms the RMS error/u
/// over them within 0.95–1.04 (1.084 before the floor, 1.001 with it; a calibrated `u`'s
/// figure over 3,000 runs lies within ±0.013 of 1, one standard deviation).
#[test]
fn the_whitened_banks_u_rests_on_no_less_than_the_metered_noise() {
    let (_, config) = firmware_default().unwrap();
    let bank = host_sim::study::calibrated_bank(&config, host_sim::montecarlo::Precision::F32);
    let rows = study("reference-step", &bank, 1000, 1, &[30.0, 40.0, 50.0]).unwrap();
    let at_100_ms = TIMES_MS.iter().position(|&t| t == 100).unwrap();
    // The three SNRs' cells at 100 ms pooled into one.
    let mut pooled = host_sim::coverage::Cell::default();
    for row in &rows {
        pooled.merge(&row.cells[at_100_ms]);
    }
    let rms_z = pooled.rms_z().unwrap();
    assert!(
        pooled.stated >= 2900 && (0.95..=1.04).contains(&rms_z),
        "100 ms: RMS error/u {rms_z:.3} over {} runs",
        pooled.stated
    );
}

/// The first final reading of a run is a stopping rule on a fluctuating `u`: on `u` itself,
/// at 40 dB the few runs that became final were those whose residuals happened to be small,
/// and 6 of the 23 first finals of 1,000 runs lay beyond the permissible 0.069 g. With the
/// noise level at its upper 95 % bound (`Reading::uncertainty_bound`): 0 of 1 at 40 dB, 3 of
/// 500 at 45 dB (0.6 %, what a 95 % interval within 0.05 g allows beyond 0.069 g). The
/// check: at most 2 % of the first finals, plus one, lie beyond the permissible error.
#[test]
fn first_final_readings_are_not_picked_by_chance() {
    use host_sim::coverage::final_time;
    let (method, config) = firmware_default().unwrap();
    let limit_g = (config.target_relative * 138.32).min(config.scale_interval_g);
    let rows = final_time::study(
        "reference-step",
        &method,
        1000,
        1,
        &[40.0, 45.0],
        config.final_target_g,
        host_sim::coverage::Colour::Unknown,
    )
    .unwrap();
    for row in &rows {
        let wrong = row.finals.iter().filter(|(_, e)| e.abs() > limit_g).count();
        assert!(
            wrong as f64 <= 0.02 * row.finals.len() as f64 + 1.0,
            "{} dB: {wrong} of {} first finals wrong",
            row.snr_db,
            row.finals.len()
        );
    }
}

/// In noise coloured as on the thesis's rig (vibration at the resonance outweighing the
/// white noise at 80 dB) the residual-based `u` (the model's white noise or the residuals'
/// own 8 lags, the larger) looked safe, 95.7–97 % within ±2u, as long as the scene's
/// vibration started with the load. With the noise already running when the load lands (as
/// on any real pan; the study now runs 2 s of empty pan first) it is over-confident: 85.2 %
/// at 100 ms (400 runs), 91–93 % later. Resting on the empty pan's metered autocovariance
/// (`estimator_core::AutocovarianceMeter`, 60 s) every cell holds at least the goal's edge
/// less this run count's Monte Carlo band (92 − 2.1 %); at 100 ms it was cautious until
/// stop 55 (98.5 %: the errors-in-variables bias on the run's own fit, mostly noise there;
/// now less its own scatter, the test below).
#[test]
fn the_empty_pans_noise_colour_makes_the_firmware_u_hold_in_the_rigs_noise() {
    let (method, _) = firmware_default().unwrap();
    let coverage = |colour| {
        let rows = study_with("rig-noise", &method, 400, 1, &[80.0], colour).unwrap();
        let cells: Vec<f64> = TIMES_MS
            .iter()
            .zip(&rows[0].cells)
            .filter(|(t, _)| (100..=400).contains(*t))
            .map(|(_, cell)| cell.coverage().unwrap())
            .collect();
        cells
    };
    let unknown = coverage(Colour::Unknown);
    assert!(
        unknown.iter().any(|&c| c < 0.90),
        "without the colour: {unknown:?}"
    );
    let metered = coverage(Colour::Metered);
    assert!(
        metered.iter().all(|&c| c >= 0.90),
        "with the metered colour: {metered:?}"
    );
}

/// The errors-in-variables bias of the metered `u` is evaluated on the run's own `ℓ`, and
/// its square overstates the bias by its own scatter (`E[b̂²] = b² + var(b̂)`): until stop 55
/// it kept the rig's noise at 70 and 80 dB 100 ms after the landing cautious, ±2u covering
/// 98.8 % and 99.1 % (`host-sim study coverage --runs 1000 --seed 1`). With the scatter
/// taken off both cells are within the goal's 92–98 % over the same 1,000 runs (97.5 % and
/// 97.8 %) and the RMS of error/u is at least 0.8 (0.74 and 0.64 before).
#[test]
fn the_bias_less_its_scatter_keeps_the_rigs_noise_within_the_goal_at_100_ms() {
    let (method, _) = firmware_default().unwrap();
    let rows = study_with(
        "rig-noise",
        &method,
        1000,
        1,
        &[70.0, 80.0],
        Colour::Metered,
    )
    .unwrap();
    for row in &rows {
        let (_, cell) = TIMES_MS
            .iter()
            .zip(&row.cells)
            .find(|(t, _)| **t == 100)
            .unwrap();
        let (coverage, rms_z) = (cell.coverage().unwrap(), cell.rms_z().unwrap());
        assert!(
            (0.92..=0.98).contains(&coverage) && rms_z >= 0.8,
            "{} dB: {:.1} % (rms z {rms_z:.2})",
            row.snr_db,
            100.0 * coverage
        );
    }
}

/// The rig's vibration near the resonance stays correlated for longer than the first 16
/// block means (96 ms at D = 24): with the metered sandwich summed over 16 lags its `u` was
/// too small late in a drop at 60–70 dB (RMS error/u 1.10–1.11 at 400 ms over these 400
/// runs, ±2u 93.0 %; 1.06–1.11 and 92.6–93.9 % at 200–400 ms over 1,000). Over
/// `COLOUR_LAGS` = 24 lags it is calibrated there: ±2u within the goal's 95 ± 3 % and the
/// RMS of error/u at most 1.05 at 200 and 400 ms.
#[test]
fn the_colour_over_24_lags_holds_the_rigs_noise_late_in_a_drop() {
    let (method, _) = firmware_default().unwrap();
    let rows = study_with("rig-noise", &method, 400, 1, &[60.0, 70.0], Colour::Metered).unwrap();
    for row in &rows {
        for (t, cell) in TIMES_MS.iter().zip(&row.cells) {
            if *t < 200 {
                continue;
            }
            let coverage = cell.coverage().unwrap();
            let rms_z = cell.rms_z().unwrap();
            assert!(
                (0.92..=0.98).contains(&coverage) && rms_z <= 1.05,
                "{} dB {t} ms: {:.1} % (rms z {rms_z:.2})",
                row.snr_db,
                100.0 * coverage
            );
        }
    }
}

/// The firmware's own scale (`firmware/weighing.toml` as both boards build it) meters the
/// empty pan's colour itself, in the 0.3 s windows it meters the noise in, and its step
/// method's `u` rests on it once 3,000 block means are in (`estimator_core::
/// MIN_METERED_BLOCKS`): after 24 s of empty pan in the rig's noise at 80 dB every run rests
/// on it at the landing, and ±2u holds the scale's readings 100–400 ms after the landing
/// at least at the goal's edge less this run count's Monte Carlo band (92 − 2.5 %).
/// A scale just built has metered nothing of it: no run rests on it.
#[test]
fn the_firmware_scale_meters_the_colour_itself_and_its_u_holds_on_it() {
    use host_sim::coverage::scale::{study, Pan};
    let rows = study(&shipped(), "rig-noise", 300, 1, &[80.0], Pan::Metered).unwrap();
    let row = &rows[0];
    assert_eq!(row.coloured, row.runs, "runs resting on the colour");
    for (t, cell) in TIMES_MS.iter().zip(&row.row.cells) {
        if (100..=400).contains(t) {
            let coverage = cell.coverage().expect("a reading with its u");
            assert!(
                coverage >= 0.895 && cell.stated >= 290,
                "{t} ms: {coverage} of {} stated",
                cell.stated
            );
        }
    }
    let fresh = study(&shipped(), "rig-noise", 20, 1, &[80.0], Pan::Fresh).unwrap();
    assert_eq!(fresh[0].coloured, 0);
}

/// Under floor vibration the step fit models the vibration with the cell, and its moving
/// average cancels most of the metered colour: the equation error's power is the small
/// difference of the colour's large lags. The scale metered its 0.3 s windows as separate
/// records, which lose the pairs that span two windows, and in about a third of the runs
/// at 70 dB and half at 80 dB (100 ms after the landing) that power came out at or below
/// zero, and the `u` fell back on the residuals: ±2u covered 99.3–99.7 % at 70 dB, 100–200
/// ms after the landing. Metered as one record while the windows follow each other
/// (`AutocovarianceMeter::take_window`), no run falls back there, and the scale's `u` holds
/// the goal, 92–98 %, 100–200 ms after the landing at 70 and 80 dB (1,000 runs: a true
/// 95 % is within ±1.4 % of it 95 % of the time). 400 ms after the landing, where the
/// residuals leave more than the metered colour explains in most runs, the metered variance
/// scaled by that excess made it cautious (98.4 % and 99.2 %; the estimator with the
/// study's 60 s of colour 97.1 % and 98.3 %) until stop 50: the excess is narrow-band
/// vibration near the loaded resonance, which reaches the level far less than its power
/// says. The residuals' own sandwich there holds the goal too (95.1 %, 96.0 %).
#[test]
fn the_scales_colour_metered_as_one_record_holds_the_goal_under_floor_vibration() {
    use host_sim::coverage::scale::{study, Pan};
    for row in study(
        &shipped(),
        "vibration",
        1000,
        1,
        &[70.0, 80.0],
        Pan::Metered,
    )
    .unwrap()
    {
        assert_eq!(row.coloured, row.runs, "runs resting on the colour");
        for (t, cell) in TIMES_MS.iter().zip(&row.row.cells) {
            if (100..=400).contains(t) {
                let coverage = cell.coverage().expect("a reading with its u");
                assert!(
                    (0.92..=0.98).contains(&coverage) && cell.stated >= 990,
                    "{} dB, {t} ms: {coverage} of {} stated",
                    row.row.snr_db,
                    cell.stated
                );
            }
        }
    }
}

/// A run the scale has just restarted on the landing it found states its first `u` from
/// few rows, its noise level on the floor (the raw samples' white noise, metered over
/// 0.1 s blocks of 400 differences) where the residuals' level lies below it. Its
/// coverage factor was still that of the residuals' few degrees of freedom (1.29 at 5):
/// 100 ms after the landing at 40 dB ±2u covered 99.3 % on the reference drop and 99.5 %
/// under floor vibration (RMS error/u 0.69-0.72). With the floor's degrees of freedom it
/// holds the goal, 92-98 % (1,000 runs, of which about 850 state a `u` by then).
#[test]
fn a_u_on_the_noise_floor_takes_the_floors_degrees_of_freedom() {
    use host_sim::coverage::scale::{study, Pan};
    let at_100_ms = TIMES_MS.iter().position(|&t| t == 100).unwrap();
    for scene in ["reference-step", "vibration"] {
        let rows = study(&shipped(), scene, 1000, 1, &[40.0], Pan::Metered).unwrap();
        let cell = &rows[0].row.cells[at_100_ms];
        let coverage = cell.coverage().expect("a reading with its u");
        assert!(
            (0.92..=0.98).contains(&coverage) && cell.stated >= 800,
            "{scene}: {coverage} of {} stated",
            cell.stated
        );
    }
}

/// Under floor vibration at 80 dB the step fit models the vibration with the cell: its
/// moving average cancels most of the metered colour, and in some runs (with the colour
/// metered in windows apart, until stop 49) the metered equation error had no power left at
/// all. Those runs then fell back on the `u` with the
/// empty pan's whole noise level as its floor, a level the fit does not see: u = 0.14 g on
/// errors of 0.003 g (2 of 8 runs), a reading that could never be final. The fallback now
/// takes the residuals with the raw samples' white noise as the floor: no run's reading
/// 200 ms after the landing states a `u` beyond the 0.05 g final target while within
/// 0.01 g of the truth.
#[test]
fn a_fit_that_cancels_the_metered_colour_does_not_state_the_pans_whole_noise() {
    use estimator_core::weighing::RawSample;
    use host_sim::coverage::scale::{standing_scale, Pan};
    use host_sim::replay;
    use host_sim::simulated::run_seed;
    let scene = Scene::load("vibration")
        .unwrap()
        .with_snr_db(80.0)
        .delayed(host_sim::coverage::PRE_ROLL_S)
        .unwrap();
    let (weighing, _) = replay::shipped_config().unwrap();
    let metered = standing_scale(&weighing, &scene, 1, Pan::Metered).unwrap();
    let (onset, mass_g, _) = scene.studied_step();
    let at = onset + 800; // 200 ms after the landing
    let mut blocked = Vec::new();
    for run in 0..100 {
        let mut scale = metered.clone();
        let mut adc = scene.adc(run_seed(1, run));
        let mut last = None;
        for _ in 0..at {
            last = Some(scale.push(RawSample::read(&mut adc)));
        }
        let reading = last.unwrap();
        if let (Some(mass), Some(u)) = (reading.mass_g, reading.uncertainty_g) {
            if u > 0.05 && (f64::from(mass) - mass_g).abs() < 0.01 {
                blocked.push((run, u));
            }
        }
    }
    assert!(blocked.is_empty(), "{blocked:?}");
}

/// The shipped weighing configuration, the firmware's scale's.
fn shipped() -> estimator_core::weighing::WeighingConfig {
    host_sim::replay::shipped_config().unwrap().0
}
