//! Running the Monte Carlo slices: one record per (condition, run), every probe on the same
//! record, in parallel over (condition, run) and accumulated in order, so the figures never
//! depend on the thread count.

use anyhow::Result;
use estimator_core::{AdcSource, InvalidReason, State};
use rayon::prelude::*;

use super::classify::{Cell, DIVERGED_FACTOR};
use super::conditions::{readout_indices, Condition};
use super::oracle::Tracked;
use super::probes::Probe;
use crate::method::{BuildContext, Method};
use crate::montecarlo::{self, tare_record};
use crate::simulated::run_seed;

/// What a run's reading was at a readout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Not yet determined.
    WarmingUp,
    /// Flagged.
    Flagged(InvalidReason),
    /// Valid, with this error, g.
    Valid(f64),
}

/// One run of one method, seen at the readouts.
#[derive(Clone, Copy, Debug)]
pub struct RunOutcome {
    /// The reading at each readout.
    pub at: [Outcome; 2],
    /// The oracle saw the state lose positive definiteness by each readout.
    pub lost_definiteness_by: [bool; 2],
    /// A valid reading further than [`DIVERGED_FACTOR`] loads from the truth, from the first
    /// readout up to each readout.
    pub diverged_by: [bool; 2],
    /// A valid reading that was not finite, up to each readout.
    pub non_finite_by: [bool; 2],
}

/// The sample period the oracle is consulted at: every decimated update of a step or
/// covariance estimator.
fn oracle_period(method: &Method) -> usize {
    match method {
        Method::Step(setup) | Method::Covariance { setup, .. } => usize::from(setup.decimation),
        _ => usize::MAX,
    }
}

fn run_probe(
    method: &Method,
    context: &BuildContext,
    record: &[f64],
    truth_g: f64,
    readouts: [usize; 2],
) -> Result<RunOutcome> {
    let mut estimator = Tracked::new(method, context)?;
    let period = oracle_period(method);
    let mut outcome = RunOutcome {
        at: [Outcome::WarmingUp; 2],
        lost_definiteness_by: [false; 2],
        diverged_by: [false; 2],
        non_finite_by: [false; 2],
    };
    let (mut lost, mut diverged, mut non_finite, mut determined) = (false, false, false, false);
    for (k, &sample) in record.iter().enumerate().take(readouts[1] + 1) {
        let reading = estimator.push(sample);
        if let Some(estimate) = reading.estimate {
            determined = true;
            if !estimate.is_finite() {
                non_finite = true;
            } else if k >= readouts[0] && (estimate - truth_g).abs() > DIVERGED_FACTOR * truth_g {
                diverged = true;
            }
        }
        if period != usize::MAX && (k + 1) % period == 0 && !lost {
            lost = !estimator.definite(determined);
        }
        for (r, &index) in readouts.iter().enumerate() {
            if k == index {
                outcome.at[r] = match (reading.state, reading.estimate) {
                    (State::Invalid(reason), _) => Outcome::Flagged(reason),
                    (_, Some(estimate)) => Outcome::Valid(estimate - truth_g),
                    (_, None) => Outcome::WarmingUp,
                };
                outcome.lost_definiteness_by[r] = lost;
                outcome.diverged_by[r] = diverged;
                outcome.non_finite_by[r] = non_finite;
            }
        }
    }
    Ok(outcome)
}

/// A Monte Carlo slice's results: `cells[condition][probe][readout]`.
pub struct SliceResult {
    /// The conditions.
    pub conditions: Vec<Condition>,
    /// The probes.
    pub probes: Vec<Probe>,
    /// The cells.
    pub cells: Vec<Vec<[Cell; 2]>>,
    /// Runs per cell.
    pub runs: usize,
}

/// Run a Monte Carlo slice: `runs` records per condition (seeded as `montecarlo` seeds them),
/// every probe on every record; parallel over (condition, run), accumulated in order.
pub fn run_slice(
    conditions: Vec<Condition>,
    probes: Vec<Probe>,
    runs: usize,
    seed: u64,
) -> Result<SliceResult> {
    // Every method with residuals checks them against its own tare (the consistency check,
    // `estimator_core`'s `InvalidReason::ModelMismatch`), metered at its own D.
    let needs_tare = probes
        .iter()
        .any(|p| p.method.reference_decimation().is_some());
    let contexts: Vec<BuildContext> = conditions
        .iter()
        .map(|c| BuildContext {
            noise_check: true,
            ..BuildContext::new(c.scene.chain, c.scene.chain.counts_per_gram())
                .with_adc_rails(c.scene.chain.zero_code())
        })
        .collect();
    // Refuse impossible methods before spending time (validated with a variance of 1).
    for probe in &probes {
        let context = BuildContext {
            tare_noise_variance: Some(1.0),
            ..contexts[0]
        };
        Tracked::new(&probe.method, &context)?;
    }
    let items: Vec<(usize, usize)> = (0..conditions.len())
        .flat_map(|c| (0..runs).map(move |run| (c, run)))
        .collect();
    let progress = montecarlo::progress_bar(items.len() as u64);
    let outcomes: Vec<Result<Vec<RunOutcome>>> = items
        .par_iter()
        .map(|&(c, run)| {
            let condition = &conditions[c];
            let scene = &condition.scene;
            let readouts = readout_indices(scene);
            let zero = scene.chain.zero_code();
            let mut adc = scene.adc(run_seed(seed, run as u64));
            let record: Vec<f64> = (0..=readouts[1])
                .map(|_| {
                    adc.read()
                        .map(|code| f64::from(code) - zero)
                        .unwrap_or(f64::NAN)
                })
                .collect();
            let tare = needs_tare.then(|| tare_record(scene, seed, run as u64));
            let result = probes
                .iter()
                .map(|probe| {
                    let context = match (probe.method.reference_decimation(), &tare) {
                        (Some(decimation), Some(tare)) => contexts[c].with_tare(tare, decimation),
                        _ => contexts[c],
                    };
                    run_probe(
                        &probe.method,
                        &context,
                        &record,
                        condition.truth_g,
                        readouts,
                    )
                })
                .collect();
            progress.inc(1);
            result
        })
        .collect();
    progress.finish_and_clear();
    let mut cells: Vec<Vec<[Cell; 2]>> = conditions
        .iter()
        .map(|c| {
            probes
                .iter()
                .map(|_| {
                    c.crlb_g.map(|crlb_g| Cell {
                        crlb_g,
                        ..Cell::default()
                    })
                })
                .collect()
        })
        .collect();
    for (&(c, _), outcome) in items.iter().zip(outcomes) {
        let outcome = outcome?;
        let truth_g = conditions[c].truth_g;
        for (p, probe) in probes.iter().enumerate() {
            for r in 0..2 {
                cells[c][p][r].add(&outcome[p], r, truth_g);
                if let Some(twin) = probe.twin {
                    if let (Outcome::Valid(mine), Outcome::Valid(theirs)) =
                        (outcome[p].at[r], outcome[twin].at[r])
                    {
                        if mine.is_finite() && theirs.is_finite() {
                            let cell = &mut cells[c][p][r];
                            cell.paired += 1;
                            cell.paired_g2.0 += mine * mine;
                            cell.paired_g2.1 += theirs * theirs;
                        }
                    }
                }
            }
        }
    }
    Ok(SliceResult {
        conditions,
        probes,
        cells,
        runs,
    })
}
