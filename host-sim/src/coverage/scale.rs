//! The coverage of the firmware's own scale (`firmware/weighing.toml` as both boards build
//! it: onset detection, its own restarts, zero tracking, the metered noise): its readings at
//! the readout times after the landing against ±2u, where the estimator table above it
//! (`super::study`) gives the estimator the onset and the noise colour.
//!
//! The scale meters the empty pan's colour itself, window by window while the pan is empty
//! and at rest, and its step method's `u` rests on it once the windows hold
//! `estimator_core::MIN_METERED_BLOCKS` block means (18 s of windows at D = 24). Per scene
//! and SNR one scale stands [`METERED_EMPTY_S`] on the empty pan (a seed apart from the
//! runs'); every run then continues a copy of it ([`Pan::Metered`]), or starts a fresh
//! scale ([`Pan::Fresh`]: the colour not yet metered, its `u` from the residuals alone),
//! with the scene delayed by [`super::PRE_ROLL_S`]: the noise runs before the landing.
//! A reading before the scale saw the landing (its load-change count unchanged: it still
//! shows the empty pan) claims nothing about the load and is not counted.

use anyhow::{anyhow, Result};
use estimator_core::weighing::{RawSample, WeighingConfig};
use estimator_core::MIN_METERED_BLOCKS;
use rayon::prelude::*;

use super::{samples_at, Cell, SnrRow, PRE_ROLL_S, TIMES_MS};
use crate::replay::{self, ConfiguredScale};
use crate::scene::Scene;
use crate::simulated::run_seed;

/// Seconds the metered scale stands on the empty pan before the runs (the QEMU bench's
/// coloured demo waits as long: `crate::qemu_scenes::COLOURED_DEMO_EMPTY_S`).
pub const METERED_EMPTY_S: f64 = crate::qemu_scenes::COLOURED_DEMO_EMPTY_S;

/// How the scale stands before a run's pre-roll.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pan {
    /// [`METERED_EMPTY_S`] on the empty pan: its colour metered.
    Metered,
    /// Just built: the pre-roll is all it has seen.
    Fresh,
}

/// One SNR's cells and how many runs rested their `u` on the metered colour at the landing.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleRow {
    /// The cells, in [`TIMES_MS`] order.
    pub row: SnrRow,
    /// Runs whose scale held the colour with enough block means when the load landed.
    pub coloured: u32,
    /// Runs.
    pub runs: u32,
}

/// `runs` seeded drops of `scene` per SNR through the scale `weighing` builds (the shipped
/// one: [`replay::shipped_config`]; `study coverage --config` another, e.g. with a model
/// bank).
pub fn study(
    weighing: &WeighingConfig,
    scene: &str,
    runs: u64,
    seed: u64,
    snrs_db: &[f64],
    pan: Pan,
) -> Result<Vec<ScaleRow>> {
    let base = Scene::load(scene)?;
    snrs_db
        .iter()
        .map(|&snr_db| {
            let scene = base
                .with_snr_db(snr_db)
                .delayed(PRE_ROLL_S)
                .ok_or_else(|| anyhow!("the scene cannot be delayed by {PRE_ROLL_S} s"))?;
            let scale = standing_scale(weighing, &scene, seed, pan)?;
            let per_run: Vec<(Vec<Cell>, bool)> = (0..runs)
                .into_par_iter()
                .map(|run| one_run(&scene, scale.clone(), run_seed(seed, run)))
                .collect();
            let mut cells = vec![Cell::default(); TIMES_MS.len()];
            let mut coloured = 0;
            for (run, rested) in per_run {
                for (cell, one) in cells.iter_mut().zip(&run) {
                    cell.merge(one);
                }
                coloured += u32::from(rested);
            }
            Ok(ScaleRow {
                row: SnrRow { snr_db, cells },
                coloured,
                runs: runs as u32,
            })
        })
        .collect()
}

/// The shipped scale (`weighing` as both boards build it) for `scene`'s chain as it stands
/// before a run: just built, or after [`METERED_EMPTY_S`] on `scene`'s empty pan (its
/// colour metered; seed `run_seed(seed, u64::MAX)`, apart from the runs').
pub fn standing_scale(
    weighing: &WeighingConfig,
    scene: &Scene,
    seed: u64,
    pan: Pan,
) -> Result<Box<ConfiguredScale>> {
    let counts = replay::calibration(
        scene.chain.counts_per_gram(),
        scene.chain.zero_code(),
        None,
        None,
    );
    let mut scale = Box::new(
        ConfiguredScale::configured(weighing, counts)
            .map_err(|e| anyhow!("the shipped configuration is refused: {e}"))?,
    );
    if pan == Pan::Metered {
        let empty = scene.empty_pan(METERED_EMPTY_S);
        let mut adc = empty.adc(run_seed(seed, u64::MAX));
        for _ in 0..empty.samples() {
            scale.push(RawSample::read(&mut adc));
        }
    }
    Ok(scale)
}

/// One drop: the scale's readings at the readout times after the landing, and whether its
/// colour held enough block means at the landing.
fn one_run(scene: &Scene, mut scale: Box<ConfiguredScale>, seed: u64) -> (Vec<Cell>, bool) {
    let (onset, mass_g, _) = scene.studied_step();
    let rate_hz = scene.chain.sample_rate_hz;
    let last = onset + samples_at(*TIMES_MS.last().unwrap(), rate_hz) as usize;
    let mut adc = scene.adc(seed);
    let mut cells = vec![Cell::default(); TIMES_MS.len()];
    let mut coloured = false;
    let mut changes_before = u32::MAX;
    for k in 0..last {
        if k == onset {
            coloured = scale
                .noise_autocovariance()
                .is_some_and(|colour| colour.blocks >= MIN_METERED_BLOCKS);
            changes_before = scale.reading().load_changes;
        }
        let reading = scale.push(RawSample::read(&mut adc));
        // Sample k is the (k + 1 − onset)-th after the onset (1-based, as `super::one_run`).
        let Some(after) = (k + 1).checked_sub(onset) else {
            continue;
        };
        // Until the scale sees the landing it still shows the empty pan: no claim about
        // the load (the display's latency, not its `u`).
        if reading.load_changes == changes_before {
            continue;
        }
        if let Some(i) = TIMES_MS
            .iter()
            .position(|&t| samples_at(t, rate_hz) == after as u64)
        {
            let cell = &mut cells[i];
            match (reading.mass_g, reading.uncertainty_g) {
                (Some(mass), Some(u)) => cell.record(f64::from(mass), f64::from(u), mass_g),
                (Some(_), _) => cell.without_u += 1,
                (None, _) => {}
            }
        }
    }
    (cells, coloured)
}

/// The table ([`super::write_markdown`]) and, per SNR, the runs whose `u` rested on the
/// metered colour at the landing.
pub fn write_markdown(
    rows: &[ScaleRow],
    header: &str,
    out: &mut impl std::io::Write,
) -> Result<()> {
    let cells: Vec<SnrRow> = rows.iter().map(|row| row.row.clone()).collect();
    super::write_markdown(&cells, header, out)?;
    let rested: Vec<String> = rows
        .iter()
        .map(|row| format!("{} of {} at {} dB", row.coloured, row.runs, row.row.snr_db))
        .collect();
    writeln!(
        out,
        "Runs whose scale rested its `u` on the metered colour when the load landed: {}.",
        rested.join(", ")
    )?;
    Ok(())
}
