//! Running the Monte Carlo slices: one record per (condition, run), every probe on the same
//! record, in parallel over (condition, run) and accumulated in order, so the figures never
//! depend on the thread count.

use anyhow::Result;
use estimator_core::{InvalidReason, State};
use rayon::prelude::*;

use super::classify::{Cell, DIVERGED_FACTOR};
use super::conditions::{readout_indices, Condition};
use super::oracle::Tracked;
use super::probes::Probe;
use crate::method::{BuildContext, Method};
use crate::montecarlo::{self, centred_record, tare_record, Precision};
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

impl SliceResult {
    /// The orders of the probes, ascending, each once.
    pub(super) fn orders(&self) -> Vec<usize> {
        let mut orders: Vec<usize> = self.probes.iter().filter_map(|p| p.order).collect();
        orders.sort_unstable();
        orders.dedup();
        orders
    }

    /// The probe of `family` at `order` in `precision`, if the slice has one.
    pub(super) fn probe_at(
        &self,
        family: &str,
        order: usize,
        precision: Precision,
    ) -> Option<usize> {
        self.probes.iter().position(|p| {
            p.family == family && p.order == Some(order) && p.method.precision() == precision
        })
    }
}

/// The items, each once, in the order they first appear.
pub(super) fn distinct<T: PartialEq>(items: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut seen = Vec::new();
    for item in items {
        if !seen.contains(&item) {
            seen.push(item);
        }
    }
    seen
}

/// Run a Monte Carlo slice: `runs` records per condition (seeded as `montecarlo` seeds them),
/// every probe on every record; parallel over (condition, run), accumulated in order.
pub fn run_slice(
    conditions: Vec<Condition>,
    probes: Vec<Probe>,
    runs: usize,
    seed: u64,
) -> Result<SliceResult> {
    let contexts = build_contexts(&conditions);
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
            let result = run_record(&conditions[c], &contexts[c], &probes, seed, run);
            progress.inc(1);
            result
        })
        .collect();
    progress.finish_and_clear();
    let mut cells = empty_cells(&conditions, &probes);
    for (&(c, _), outcome) in items.iter().zip(outcomes) {
        accumulate(&mut cells[c], &probes, &outcome?, conditions[c].truth_g);
    }
    Ok(SliceResult {
        conditions,
        probes,
        cells,
        runs,
    })
}

/// Each condition's build context: the scene's chain, gain and ADC rails, the consistency
/// check on.
fn build_contexts(conditions: &[Condition]) -> Vec<BuildContext> {
    conditions
        .iter()
        .map(|c| BuildContext {
            noise_check: true,
            ..BuildContext::new(c.scene.chain, c.scene.chain.counts_per_gram())
                .with_adc_rails(c.scene.chain.zero_code())
        })
        .collect()
}

/// One run of one condition: its record (and tare), every probe on it.
fn run_record(
    condition: &Condition,
    context: &BuildContext,
    probes: &[Probe],
    seed: u64,
    run: usize,
) -> Result<Vec<RunOutcome>> {
    // Every method with residuals checks them against its own tare (the consistency check,
    // `estimator_core`'s `InvalidReason::ModelMismatch`), metered at its own D.
    let needs_tare = probes
        .iter()
        .any(|p| p.method.reference_decimation().is_some());
    let scene = &condition.scene;
    let readouts = readout_indices(scene);
    let mut adc = scene.adc(run_seed(seed, run as u64));
    let record = centred_record(&mut adc, scene.chain.zero_code(), readouts[1] + 1);
    let tare = needs_tare.then(|| tare_record(scene, seed, run as u64));
    probes
        .iter()
        .map(|probe| {
            let context = match (probe.method.reference_decimation(), &tare) {
                (Some(decimation), Some(tare)) => context.with_tare(tare, decimation),
                _ => *context,
            };
            run_probe(
                &probe.method,
                &context,
                &record,
                condition.truth_g,
                readouts,
            )
        })
        .collect()
}

/// Empty cells, each knowing its CRLB: `[condition][probe][readout]`.
fn empty_cells(conditions: &[Condition], probes: &[Probe]) -> Vec<Vec<[Cell; 2]>> {
    conditions
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
        .collect()
}

/// Add one run's outcomes to its condition's cells; an f32 probe also pairs its error with
/// its f64 twin's where both are valid and finite.
fn accumulate(cells: &mut [[Cell; 2]], probes: &[Probe], outcome: &[RunOutcome], truth_g: f64) {
    for (p, probe) in probes.iter().enumerate() {
        for r in 0..2 {
            cells[p][r].add(&outcome[p], r, truth_g);
            if let Some(twin) = probe.twin {
                if let (Outcome::Valid(mine), Outcome::Valid(theirs)) =
                    (outcome[p].at[r], outcome[twin].at[r])
                {
                    if mine.is_finite() && theirs.is_finite() {
                        let cell = &mut cells[p][r];
                        cell.paired += 1;
                        cell.paired_g2.0 += mine * mine;
                        cell.paired_g2.1 += theirs * theirs;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::scene::Scene;
    use crate::stability::conditions::{Noise, Slice};
    use crate::stability::probes::order_probes;

    /// A slice of one white-noise condition at 50 dB and the probes of slice A at order 7,
    /// every cell holding one valid run `error_g` off, judged against a CRLB of 0.1 g.
    pub(in crate::stability) fn known_slice(error_g: f64) -> SliceResult {
        let scene = Scene::load("reference-step").unwrap();
        let condition = Condition {
            slice: Slice::OrderSnr,
            noise: Noise::White,
            snr_db: 50.0,
            resonance_ratio: 1.25,
            truth_g: 138.32,
            scene,
            crlb_g: [0.1, 0.1],
        };
        let probes = order_probes(&[7]);
        let outcome = RunOutcome {
            at: [Outcome::Valid(error_g); 2],
            lost_definiteness_by: [false; 2],
            diverged_by: [false; 2],
            non_finite_by: [false; 2],
        };
        let mut cells = empty_cells(std::slice::from_ref(&condition), &probes);
        accumulate(&mut cells[0], &probes, &vec![outcome; probes.len()], 138.32);
        SliceResult {
            conditions: vec![condition],
            probes,
            cells,
            runs: 1,
        }
    }

    #[test]
    fn an_f32_probe_is_paired_with_its_f64_twin() {
        let slice = known_slice(0.2);
        assert_eq!(slice.cells[0].len(), 10);
        let f32_cell = &slice.cells[0][1][0];
        assert_eq!(f32_cell.paired, 1);
        assert_eq!(f32_cell.f32_over_f64(), Some(1.0));
        assert_eq!(slice.cells[0][0][0].paired, 0);
        assert_eq!(slice.orders(), vec![7]);
        assert_eq!(slice.probe_at("iv D=16", 7, Precision::F32), Some(7));
        assert_eq!(slice.probe_at("iv D=16", 3, Precision::F32), None);
    }

    #[test]
    fn distinct_keeps_the_first_appearance_order() {
        assert_eq!(distinct([3, 1, 3, 2, 1]), vec![3, 1, 2]);
    }
}
