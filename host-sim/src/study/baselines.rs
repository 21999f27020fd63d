//! The baselines at their best tuning, found by search, not picked by hand: for each
//! family (settle-then-average, moving average, compensation filter, shaper FIR) a grid of
//! its parameters, every candidate run on the reference scene at the goal SNR, the best
//! kept for `study speed`.
//!
//! The score is the study's own measure of speed at an accuracy: the 95th percentile of the
//! time to reach and stay within 0.1 %, then its median. Among equal scores the grid's order
//! decides: the tightest stability band first (a looser band only shows a reading sooner that
//! is not yet right), then the shortest window. The filters are tuned to the cell's mode as
//! calibration identified it (`firmware/weighing.toml`'s `[model]`), as a terminal would be.
//!
//! The search runs on runs of its own (the study's seed with [`SEARCH_SALT`]), so the study's
//! figures for the chosen tuning are not the ones it was chosen on.
//!
//! What it must never do: score candidates on different runs (one [`Study`] holds a batch,
//! every batch the same seeded runs), or hand out a tuning it did not score.

use std::io::Write;

use anyhow::{Context, Result};
use estimator_core::{BaselineMode, ShaperKind};

use super::{time_text, GOAL_SNR_DB, TOLERANCE_INDEX};
use crate::method::{BaselineSpec, FilteredSpec, Method, Prefiltering};
use crate::montecarlo::{self, Precision, SetupStats, Study};
use crate::scene::Scene;

/// Runs a candidate is scored on (at most the study's own).
pub const SEARCH_RUNS: usize = 200;
/// Added to the study's seed for the search's runs.
pub const SEARCH_SALT: u64 = 0xba5e_11ae;
/// Candidates run together in one Monte Carlo (memory: 120 KB a candidate per chunk of runs).
const BATCH: usize = 48;

/// Raw samples per block (5, 10, 20 ms at 4 kHz).
const BLOCKS: [u16; 3] = [20, 40, 80];
/// Block means kept.
const WINDOWS: [usize; 7] = [2, 3, 4, 6, 8, 12, 16];
/// Stability bands, g, tightest first (0.1 % of the reference load is 0.14 g).
const BANDS_G: [f64; 5] = [0.1, 0.2, 0.5, 1.0, 2.0];
/// The compensation's placed pair: frequency over the cell's, and damping.
const PLACED: [(f64, f64); 8] = [
    (1.0, 0.7),
    (1.0, 1.0),
    (1.5, 0.7),
    (1.5, 1.0),
    (2.0, 0.7),
    (2.0, 1.0),
    (3.0, 0.7),
    (3.0, 1.0),
];
const SHAPERS: [ShaperKind; 3] = [ShaperKind::Zv, ShaperKind::Zvd, ShaperKind::Zvdd];
const AVERAGES: [BaselineMode; 2] = [BaselineMode::MovingAverage, BaselineMode::SettledAverage];

/// The families, in the study's table order, with the names its rows take.
pub const FAMILY_NAMES: [&str; 4] = [
    "settled average (baseline, searched)",
    "moving average (baseline, searched)",
    "compensation filter tuned to the cell (baseline, searched)",
    "shaper FIR tuned to the cell (baseline, searched)",
];

/// A candidate's figures.
#[derive(Clone, Debug)]
pub struct Scored {
    /// The candidate.
    pub method: Method,
    /// 95th percentile of the time to reach and stay within 0.1 %, s (infinite: never).
    pub p95_s: f64,
    /// Its median, s.
    pub median_s: f64,
}

impl Scored {
    fn of(stats: &SetupStats) -> Self {
        Self {
            method: stats.setup,
            p95_s: stats.settle_quantile(TOLERANCE_INDEX, 0.95),
            median_s: stats.settle_quantile(TOLERANCE_INDEX, 0.5),
        }
    }

    /// The order of the score: an earlier 95th percentile first, then an earlier median.
    fn compare(&self, other: &Scored) -> std::cmp::Ordering {
        (self.p95_s.total_cmp(&other.p95_s)).then(self.median_s.total_cmp(&other.median_s))
    }
}

/// One family's search.
#[derive(Clone, Debug)]
pub struct Tuned {
    /// The row name of the study's table.
    pub name: &'static str,
    /// Candidates scored.
    pub candidates: usize,
    /// The best five, best first.
    pub best: Vec<Scored>,
}

/// The averaging grid, tightest band first, then the shortest window.
fn averagings() -> Vec<BaselineSpec> {
    let mut grid = Vec::new();
    for band_g in BANDS_G {
        for blocks in WINDOWS {
            for block in BLOCKS {
                grid.push(BaselineSpec {
                    block,
                    blocks,
                    band_g,
                    precision: Precision::F64,
                });
            }
        }
    }
    grid
}

/// Every family's candidates, in [`FAMILY_NAMES`]' order; the filters tuned to `fn_hz`, `zeta`.
pub fn families(natural_frequency_hz: f64, damping_ratio: f64) -> [Vec<Method>; 4] {
    let averagings = averagings();
    let filtered = |filters: &[Prefiltering]| -> Vec<Method> {
        let mut methods = Vec::new();
        for &filter in filters {
            for average in AVERAGES {
                methods.extend(averagings.iter().map(|&baseline| {
                    Method::Filtered(FilteredSpec {
                        natural_frequency_hz,
                        damping_ratio,
                        filter,
                        average,
                        baseline,
                    })
                }));
            }
        }
        methods
    };
    let placed: Vec<Prefiltering> = PLACED
        .iter()
        .map(|&(ratio, placed_zeta)| Prefiltering::Compensation { ratio, placed_zeta })
        .collect();
    let shapers: Vec<Prefiltering> = SHAPERS.map(Prefiltering::Shaper).to_vec();
    [
        averagings
            .iter()
            .map(|&spec| Method::Settled(spec))
            .collect(),
        averagings
            .iter()
            .map(|&spec| Method::Moving(spec))
            .collect(),
        filtered(&placed),
        filtered(&shapers),
    ]
}

/// Score every family's candidates on `runs` runs of the reference scene at the goal SNR
/// (seed `seed`), the best of each first.
pub fn search(
    natural_frequency_hz: f64,
    damping_ratio: f64,
    runs: usize,
    seed: u64,
) -> Result<Vec<Tuned>> {
    let scene = Scene::load("reference-step")?.with_snr_db(GOAL_SNR_DB);
    let mut tuned = Vec::new();
    for (name, candidates) in FAMILY_NAMES
        .iter()
        .zip(families(natural_frequency_hz, damping_ratio))
    {
        let mut scored: Vec<Scored> = Vec::with_capacity(candidates.len());
        for batch in candidates.chunks(BATCH) {
            let study = Study {
                scene: scene.clone(),
                setups: batch.to_vec(),
                runs,
                seed,
                samples: usize::MAX,
                final_target_g: None,
            };
            let result = montecarlo::run_studies(&study, &[])?;
            let result = result.first().context("no result")?;
            scored.extend(result.setups.iter().map(Scored::of));
        }
        // A stable sort keeps the grid's order among equals.
        scored.sort_by(Scored::compare);
        scored.truncate(5);
        tuned.push(Tuned {
            name,
            candidates: candidates.len(),
            best: scored,
        });
    }
    Ok(tuned)
}

/// The search's report: each family's grid size and its best five.
pub fn write_markdown(tuned: &[Tuned], command: &str, out: &mut impl Write) -> Result<()> {
    writeln!(out, "The baselines' tuning searched on `reference-step` at {GOAL_SNR_DB} dB (`{command}`): each family's grid, every candidate scored by the 95th percentile, then the median, of the time to reach and stay within 0.1%; among equals the tightest band, then the shortest window. Blocks {BLOCKS:?} samples, K {WINDOWS:?}, bands {BANDS_G:?} g; the compensation's placed pair (frequency ratio, damping) {PLACED:?}; shapers ZV, ZVD, ZVDD; the filters before a moving or a settled average.\n")?;
    writeln!(
        out,
        "| family | candidates | rank | spec | time to 0.1%: median / 95th pct |"
    )?;
    writeln!(out, "|---|---|---|---|---|")?;
    for family in tuned {
        for (rank, scored) in family.best.iter().enumerate() {
            writeln!(
                out,
                "| {} | {} | {} | `{}` | {} / {} |",
                family.name,
                family.candidates,
                rank + 1,
                scored.method,
                time_text(scored.median_s),
                time_text(scored.p95_s)
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid is what the docs say: every combination once, each spec parsing back to the
    /// same method, and every candidate buildable at the reference rate.
    #[test]
    fn the_grid_holds_every_combination_once_and_builds() {
        let families = families(25.0, 0.03);
        let averagings = BANDS_G.len() * WINDOWS.len() * BLOCKS.len();
        let sizes = families.each_ref().map(Vec::len);
        assert_eq!(
            sizes,
            [
                averagings,
                averagings,
                averagings * PLACED.len() * AVERAGES.len(),
                averagings * SHAPERS.len() * AVERAGES.len()
            ]
        );
        let context =
            crate::method::BuildContext::new(crate::sensor::SensorChain::reference(), 73.25);
        let mut seen = std::collections::HashSet::new();
        for method in families.iter().flatten() {
            let spec = method.to_string();
            assert_eq!(spec.parse::<Method>().unwrap(), *method);
            assert!(seen.insert(spec.clone()), "{spec} twice");
            assert!(method.build(&context).is_ok(), "{spec}");
        }
    }
}
