//! `host-sim study stability`: run the four slices and write every report. The figures must
//! never depend on the thread count or the order the slices finish in.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use estimator_core::State;

use super::conditions::{
    noise_conditions, off_calibration_conditions, order_conditions, OFF_CALIBRATION_SNRS_DB,
};
use super::csv::write_csv;
use super::heatmap::{long_chart, order_heat_map, probe_heat_map};
use super::long::{run_long_slice, LongResult, BINS_PER_DECADE, FIRST_DECADE, LONG_DECIMATIONS};
use super::markdown::write_markdown;
use super::probes::{default_probes, order_probes};
use super::run::{run_slice, SliceResult};
use super::verdict::{f32_goal, failure_counts_text, failure_summary, long_f32_goal};
use crate::estimate::state_name;
use crate::scene::Scene;
use crate::study::create;

/// `host-sim study stability`: run the four slices, write the CSVs, the markdown and the
/// charts into `out`, print the verdicts and the wall time.
pub fn stability_command(
    runs: usize,
    seed: u64,
    snrs_db: &[f64],
    orders: &[usize],
    long_samples: usize,
    out: &Path,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let start = Instant::now();
    let base = Scene::load("reference-step")?;
    let slices = run_monte_carlo_slices(&base, runs, seed, snrs_db, orders)?;
    let long = if long_samples > 0 {
        eprintln!("slice D: long runs");
        Some(run_long_slice(&base, long_samples, seed)?)
    } else {
        None
    };
    let wall_s = start.elapsed().as_secs_f64();
    let mut csv = create(&out.join("stability-map.csv"))?;
    write_csv(&slices, &mut csv)?;
    csv.flush()?;
    let text = |v: &[String]| v.join(",");
    let command = format!(
        "host-sim study stability --runs {runs} --seed {seed} --snr-db {} --orders {} --long-samples {long_samples}",
        text(&snrs_db.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
        text(&orders.iter().map(|s| s.to_string()).collect::<Vec<_>>())
    );
    let mut markdown = create(&out.join("stability-map.md"))?;
    write_markdown(&slices, long.as_ref(), &command, wall_s, &mut markdown)?;
    markdown.flush()?;
    write_heat_maps(&slices, out)?;
    if let Some(long) = &long {
        let mut csv = create(&out.join("stability-long-runs.csv"))?;
        write_long_csv(long, &mut csv)?;
        csv.flush()?;
        for decimation in LONG_DECIMATIONS {
            long_chart(long, decimation)
                .write(&out.join(format!("j-stability-long-runs-d{decimation}")))?;
        }
    }
    print_verdicts(runs, seed, &slices, long.as_ref());
    println!(
        "{wall_s:.1} s wall on {} threads; wrote {}/stability-map.{{csv,md}}, stability-long-runs.csv, g-/h-/i-/j-stability-*.{{svg,png}}",
        rayon::current_num_threads(),
        out.display()
    );
    Ok(())
}

/// Slices A, B and C, in that order.
fn run_monte_carlo_slices(
    base: &Scene,
    runs: usize,
    seed: u64,
    snrs_db: &[f64],
    orders: &[usize],
) -> Result<[SliceResult; 3]> {
    eprintln!("slice A: order × SNR");
    let a = run_slice(
        order_conditions(base, snrs_db),
        order_probes(orders),
        runs,
        seed,
    )?;
    eprintln!("slice B: noise type × SNR");
    let b = run_slice(
        noise_conditions(base, snrs_db),
        default_probes(),
        runs,
        seed,
    )?;
    eprintln!("slice C: off-calibration");
    // Its own two noise levels, or those of them the caller's SNRs keep (a quick look).
    let mut off_snrs: Vec<f64> = OFF_CALIBRATION_SNRS_DB
        .iter()
        .copied()
        .filter(|s| snrs_db.contains(s))
        .collect();
    if off_snrs.is_empty() {
        off_snrs = OFF_CALIBRATION_SNRS_DB.to_vec();
    }
    let c = run_slice(
        off_calibration_conditions(base, &off_snrs)?,
        default_probes(),
        runs,
        seed,
    )?;
    Ok([a, b, c])
}

/// The heat maps of slices A (one per readout), B and C.
fn write_heat_maps(slices: &[SliceResult; 3], out: &Path) -> Result<()> {
    for r in 0..2 {
        order_heat_map(&slices[0], r).write(&out.join(format!(
            "g-stability-order-snr-{}",
            if r == 0 { "100ms" } else { "1500ms" }
        )))?;
    }
    probe_heat_map(
        &slices[1],
        "Stability map B: noise type × SNR",
        |c| c.noise.name().to_string(),
        |c| format!("{}", c.snr_db),
        "SNR of the white part, dB",
    )
    .write(&out.join("h-stability-noise"))?;
    probe_heat_map(
        &slices[2],
        "Stability map C: the load's resonance off the 200 g calibration",
        |c| format!("white noise of {} dB on the reference drop", c.snr_db),
        |c| format!("{}", c.resonance_ratio),
        "resonance / resonance at 200 g",
    )
    .write(&out.join("i-stability-off-calibration"))
}

/// The long runs' CSV: one line per run and log-spaced bin.
fn write_long_csv(long: &LongResult, csv: &mut impl Write) -> Result<()> {
    writeln!(
        csv,
        "spec,bin_first_sample,bin_last_sample,readings,valid,flagged,rms_over_bound,max_error_g,valid_after_lost_definiteness,first_flag_sample,first_flag_reason,lost_definiteness_at"
    )?;
    let edge = |i: usize| {
        10f64
            .powf(f64::from(FIRST_DECADE) + i as f64 / BINS_PER_DECADE as f64)
            .round()
    };
    for run in &long.runs {
        for (i, bin) in run.bins.iter().enumerate() {
            writeln!(
                csv,
                "{},{},{},{},{},{},{:.4},{:.4e},{},{},{},{}",
                run.probe.method.to_string().replace(',', " "),
                edge(i),
                edge(i + 1) - 1.0,
                bin.readings,
                bin.valid,
                bin.flagged,
                bin.normalised_rms(),
                bin.max_error_g,
                bin.valid_after_loss,
                run.first_flag.map(|f| f.0.to_string()).unwrap_or_default(),
                run.first_flag
                    .map(|f| state_name(State::Invalid(f.1)).to_string())
                    .unwrap_or_default(),
                run.lost_definiteness_at
                    .map(|k| k.to_string())
                    .unwrap_or_default()
            )?;
        }
    }
    Ok(())
}

/// The verdicts on stdout: the failure modes per family and the f32 goal.
fn print_verdicts(runs: usize, seed: u64, slices: &[SliceResult], long: Option<&LongResult>) {
    println!("stability map: {runs} runs a Monte Carlo cell, seed {seed}");
    for (family, counts) in failure_summary(slices) {
        println!(
            "  {family}: {}",
            failure_counts_text(&counts, " SILENT", " flagged")
        );
    }
    for (family, checked, failures) in f32_goal(slices) {
        println!(
            "  f32 goal {}: {family} ({} of {checked} valid f64 cells fail)",
            if failures.is_empty() { "PASS" } else { "FAIL" },
            failures.len()
        );
    }
    if let Some(long) = long {
        let failures = long_f32_goal(long);
        println!(
            "  f32 goal {}: long runs{}",
            if failures.is_empty() { "PASS" } else { "FAIL" },
            if failures.is_empty() {
                String::new()
            } else {
                format!(" ({})", failures.join("; "))
            }
        );
    }
}
