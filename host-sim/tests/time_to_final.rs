//! `host-sim study speed`'s time to a final reading: the speed study records each
//! run's first final reading in its own Monte Carlo, and it must agree with the coverage
//! study's independent loop over the same records (`coverage::final_time`), and no method
//! whose `u` is honest may be final sooner than the Cramér–Rao bound allows, beyond the 5 %
//! of runs whose `u`, at its upper 95 % bound, still falls below the estimate's spread.

use host_sim::coverage::final_time;
use host_sim::montecarlo::Precision;
use host_sim::study::{self, firmware_default, identified_bank, Entry};

#[test]
fn the_speed_study_finds_the_final_readings_the_coverage_study_finds_and_none_before_the_bound() {
    let (firmware, config) = firmware_default().unwrap();
    let bank = identified_bank(&config, Precision::F32);
    let target_g = config.final_target_g;
    let (runs, seed, snrs) = (200, 11, [50.0, 60.0]);
    let entries = vec![
        Entry {
            name: "firmware".into(),
            method: firmware,
        },
        Entry {
            name: "bank".into(),
            method: bank,
        },
    ];
    let speed = study::run(entries, runs, seed, &snrs, target_g).unwrap();
    for (result, snr_db) in speed.results.iter().zip(snrs) {
        let crlb_s = host_sim::montecarlo::crlb_final_s(result, target_g);
        assert!(crlb_s.is_finite(), "{snr_db} dB");
        for stats in &result.setups {
            assert_eq!(stats.finals.len(), runs, "{snr_db} dB {}", stats.setup);
            assert_eq!(stats.runs_with_u, runs, "{snr_db} dB {}", stats.setup);
            let early = stats.finals.iter().filter(|(t, _)| *t < crlb_s).count();
            assert!(
                early * 20 <= runs,
                "{snr_db} dB {}: {early} of {runs} runs final before the CRLB allows ({:.1} ms)",
                stats.setup,
                crlb_s * 1e3
            );
            // Both methods are final within the window at 50 dB and above.
            assert!(stats.final_quantile(0.95).is_finite(), "{snr_db} dB");
        }
    }
    // The coverage study's loop (its own estimator, its own readout of `u`) on the same
    // seeds: the same first final readings, to the sample, within its 400 ms horizon.
    let rows = final_time::study(
        "reference-step",
        &firmware,
        runs as u64,
        seed,
        &snrs,
        target_g,
        host_sim::coverage::Colour::Unknown,
    )
    .unwrap();
    for (row, result) in rows.iter().zip(&speed.results) {
        let mut finals: Vec<(f64, f64)> = result.setups[0]
            .finals
            .iter()
            .copied()
            .filter(|(t, _)| *t * 1e3 <= final_time::HORIZON_MS)
            .map(|(t, e)| (t * 1e3, e))
            .collect();
        finals.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(finals.len(), row.finals.len(), "{} dB", row.snr_db);
        for (mine, theirs) in finals.iter().zip(&row.finals) {
            assert!(
                (mine.0 - theirs.0).abs() < 1e-9 && (mine.1 - theirs.1).abs() < 1e-12,
                "{} dB: {mine:?} against {theirs:?}",
                row.snr_db
            );
        }
    }
}

/// The firmware's own scale on an empty pan and then a drop (`study::scale_final`): at
/// 60 dB every run is final by the scene's end, none before the landing or before the
/// bound allows, and every first final reading lies within 0.1 % of the mass.
#[test]
fn the_firmware_scale_is_final_after_the_landing_within_0_1_percent() {
    let (truth_g, rows) = study::scale_final::study(20, 5, &[60.0]).unwrap();
    let row = &rows[0];
    assert_eq!(row.finals.len(), 20);
    for &(t, error) in &row.finals {
        // The bound's earliest final at 60 dB is 17 ms; the scale needs its hold too.
        assert!(t.is_finite() && t > 0.017, "{t} s");
        assert!(error.abs() <= 1e-3 * truth_g, "{error} g at {t} s");
    }
    assert_eq!(row.beyond(1e-3 * truth_g), 0.0);
}
