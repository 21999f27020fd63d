//! `host-sim torture`: the firmware's scale over random sequences of weighings, counting
//! the readings it shows as settled while they are wrong.
//!
//! Each run draws a [`plan::Plan`] from its own seed (`run_seed(seed, run)`: the same runs
//! on any number of threads), plays it on the reference chain and runs the scale the
//! firmware builds from the weighing configuration (`Scale::configured`, with the command
//! state machine for tare and calibration) on it. Every 20 Hz readout line is judged
//! ([`judge`]): a line shown stable or empty with a mass further from the truth than the
//! maximum permissible error (OIML R 76 class III at the scale interval e, or the
//! configured target where tighter), or any mass shown settled above Max + 9 e, is a silent
//! wrong reading. The display may lag one readout period: the truth is the range of the
//! true net load over the period before the line.
//!
//! What it must never do: judge a reading by anything but the truth of the scene, or count
//! a flagged reading (estimating, invalid) as silent.

pub mod judge;
pub mod plan;
pub mod run;

use std::fmt::Write as _;

use estimator_core::weighing::WeighingConfig;

use crate::sensor::SensorChain;
use crate::simulated::run_seed;
use judge::{Limits, Tallies};
use plan::{ActKind, Plan};

/// What a torture run is asked to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TortureSettings {
    /// Runs (random sequences of weighings).
    pub runs: u64,
    /// Seed of the runs.
    pub seed: u64,
    /// Worker threads.
    pub threads: usize,
    /// The limits the readings are judged against.
    pub limits: Limits,
}

/// Run the torture: every run of `settings` on the scale of `weighing`.
pub fn torture(
    settings: &TortureSettings,
    weighing: &WeighingConfig,
) -> Result<Tallies, estimator_core::ConfigError> {
    let chain = SensorChain::reference();
    let threads = settings.threads.max(1) as u64;
    let results: Vec<Result<Tallies, estimator_core::ConfigError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|worker| {
                let chain = &chain;
                std::thread::Builder::new()
                    .stack_size(16 << 20)
                    .spawn_scoped(scope, move || {
                        let mut tallies = Tallies::default();
                        let mut run = worker;
                        while run < settings.runs {
                            one_run(run, settings, chain, weighing, &mut tallies, None)?;
                            run += threads;
                        }
                        Ok(tallies)
                    })
            })
            .collect();
        handles
            .into_iter()
            .map(|handle| match handle {
                Ok(handle) => handle
                    .join()
                    .unwrap_or(Err(estimator_core::ConfigError::Model)),
                Err(_) => Err(estimator_core::ConfigError::Model),
            })
            .collect()
    });
    let mut all = Tallies::default();
    for result in results {
        all.merge(result?);
    }
    Ok(all)
}

/// Draw and run run `run`.
pub fn one_run(
    run: u64,
    settings: &TortureSettings,
    chain: &SensorChain,
    weighing: &WeighingConfig,
    tallies: &mut Tallies,
    trace: Option<&mut dyn std::io::Write>,
) -> Result<(), estimator_core::ConfigError> {
    let seed = run_seed(settings.seed, run);
    let plan = Plan::draw(seed, chain, run::instrument(&settings.limits));
    run::run_plan(run, &plan, settings, chain, weighing, tallies, trace)
}

/// The report: a table per act, the worst silent wrong readings, and the last line
/// `silent wrong readings: W of M shown in N runs`.
pub fn report(settings: &TortureSettings, tallies: &Tallies) -> String {
    let mut out = String::new();
    let l = &settings.limits;
    let _ = writeln!(
        out,
        "torture: {} runs, seed {}; Max {} g, e {} g, MPE OIML R 76 class III (or the target {:.3} % where tighter)",
        tallies.runs,
        settings.seed,
        l.capacity_g,
        l.scale_interval_g,
        l.target_relative * 100.0
    );
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "| act in progress | readout lines | shown settled | silent wrong | flagged wrong | no mass | worst error / permissible |"
    );
    let _ = writeln!(out, "|---|---:|---:|---:|---:|---:|---:|");
    for kind in ActKind::ALL {
        let Some(t) = tallies.by_act.get(&kind) else {
            continue;
        };
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {:.2} |",
            kind.name(),
            t.readings,
            t.shown,
            t.silent_wrong,
            t.flagged_wrong,
            t.no_mass,
            t.worst_ratio
        );
    }
    let total = tallies.total();
    let _ = writeln!(
        out,
        "| all | {} | {} | {} | {} | {} | {:.2} |",
        total.readings,
        total.shown,
        total.silent_wrong,
        total.flagged_wrong,
        total.no_mass,
        total.worst_ratio
    );
    let why = &tallies.no_mass_by_why;
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "lines with no mass by why: no estimate yet: {}, model mismatch (the consistency check): {}, other estimator flags: {}, faults (overload, saturated or lost samples): {}",
        why[0], why[1], why[2], why[3]
    );
    let _ = writeln!(
        out,
        "lines shown settled by how finely one readout line resolves their permissible error on that pan (the error over the scatter of one line's mean, from the pan's still lines so far; what a test could at best see of a change of that size a line after it began): {}",
        z_buckets(&tallies.shown_by_resolution, &["not yet known"], Some(total.shown))
    );
    if total.silent_wrong > 0 {
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "silent wrong readings by error / u shown: {}",
            z_buckets(&tallies.silent_by_z, &["no u"], None)
        );
        let steady = &tallies.silent_by_steady;
        let _ = writeln!(
            out,
            "silent wrong readings by how long the load had stayed within the permissible error: below 0.1 s: {}, 0.1-0.5 s: {}, 0.5-2 s: {}, 2 s and more: {}",
            steady[0], steady[1], steady[2], steady[3]
        );
        let _ = writeln!(
            out,
            "silent wrong readings by the evidence against them in the data by their line (z of the true load's mean over the best stretch ending there, white noise alone): {}",
            z_buckets(&tallies.silent_by_evidence, &[], None)
        );
        let _ = writeln!(
            out,
            "silent wrong readings by how finely one readout line resolved their permissible error (as above): {}",
            z_buckets(&tallies.silent_by_resolution, &["not yet known"], None)
        );
    }
    if !tallies.worst.is_empty() {
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "worst silent wrong readings (run: rerun with --only-run):"
        );
        for w in &tallies.worst {
            // An infinite error is the judge's mark for a mass shown above Max + 9 e.
            let error = if w.error_g.is_finite() {
                format!("error {:.3} g", w.error_g)
            } else {
                "the load is above Max + 9 e: it should read overload, not a mass".to_string()
            };
            let _ = writeln!(
                out,
                "  run {} at {:.2} s ({}): shown {:.3} g {}, truth {:.3}..{:.3} g, {error}, permissible ±{:.3} g, load steady {:.2} s, evidence z {:.1}, one line resolves {}",
                w.run,
                w.time_s,
                w.act.name(),
                w.shown_g,
                w.state,
                w.truth_g.0,
                w.truth_g.1,
                w.permissible_g,
                w.steady_s,
                w.evidence_z,
                w.resolution
                    .map_or("not yet known".to_string(), |r| format!("{r:.1}"))
            );
        }
    }
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "silent wrong readings: {} of {} shown in {} runs",
        total.silent_wrong, total.shown, tallies.runs
    );
    out
}

/// Counts in the buckets of a z (`judge`'s: below 2, 2-3, 3-5, 5 and above), then in those
/// `extra` names, as `label: count` joined by commas; with `share_of`, each count's share
/// of it as well.
fn z_buckets(counts: &[u64], extra: &[&str], share_of: Option<u64>) -> String {
    const Z: [&str; 4] = ["below 2", "2-3", "3-5", "5 and above"];
    Z.iter()
        .chain(extra)
        .zip(counts)
        .map(|(label, &count)| match share_of {
            Some(total) => format!(
                "{label}: {count} ({:.1} %)",
                100.0 * count as f64 / total.max(1) as f64
            ),
            None => format!("{label}: {count}"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}
