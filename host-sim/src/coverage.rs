//! `host-sim study coverage`: does the stated standard uncertainty hold? For each SNR and
//! readout time, the fraction of Monte Carlo runs whose error lies within ±2u, over the
//! runs that state an estimate with its `u` at that time (a run with no `u` yet, or a
//! flagged reading, is counted apart: it claims nothing).
//!
//! The scene is the reference drop (onset known, tare known) at each SNR; the method is
//! whatever the caller gives (by default the firmware's, in f32). A cell's Monte Carlo
//! band: with `m` readings and a true coverage of 95 %, the observed fraction lies within
//! `±1.96·sqrt(0.95·0.05/m)` of it 95 % of the time (±1.4 % at 1,000 runs).
//!
//! The noise runs before the landing ([`PRE_ROLL_S`] of empty pan): a scene's vibration
//! started with the load made its first 100 ms unlike any real pan's (the shipped `u` then
//! looked over-cautious where, with the vibration already running, it was over-confident).
//! A step method's `u` (and a whitening model bank's fit) rests on the empty pan's noise
//! colour, metered over [`METERING_S`]
//! of the same scene's empty pan (another seed), as the scale meters its pan whenever it
//! is empty and at rest (`estimator_core::AutocovarianceMeter`).

mod chart;
pub mod final_time;
pub mod scale;

use std::io::Write;

use anyhow::{anyhow, Result};
use estimator_core::sensor::AdcSource;
use estimator_core::{Autocovariance, AutocovarianceMeter};
use rayon::prelude::*;

use crate::method::{BuildContext, Method};
use crate::scene::Scene;
use crate::simulated::run_seed;

pub use chart::write as write_chart;

/// Seconds of empty pan, its noise running, before the studied load lands.
pub const PRE_ROLL_S: f64 = 2.0;
/// Seconds of the empty pan a step method's noise colour is metered over.
pub const METERING_S: f64 = 60.0;

/// Readout times of the table, milliseconds after the onset.
pub const TIMES_MS: [u32; 7] = [25, 50, 75, 100, 150, 200, 400];
/// SNRs of the table, dB.
pub const SNRS_DB: [f64; 6] = [30.0, 40.0, 50.0, 60.0, 70.0, 80.0];

/// One SNR and readout time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cell {
    /// Runs that gave an estimate with its `u` at this time.
    pub stated: u32,
    /// Of those, runs whose error is within ±2u.
    pub covered: u32,
    /// Runs with an estimate but no `u`.
    pub without_u: u32,
    /// Sum of (error/u)² over the stated runs (an RMS z of 1 is a calibrated `u`).
    pub z_square_sum: f64,
    /// Sum of error² over the stated runs (the estimate's unit², grams for the scale).
    pub error_square_sum: f64,
    /// Sum of u² over the stated runs.
    pub u_square_sum: f64,
    /// Stated runs whose error lies beyond ±4u: the tail a coverage near 95 % can hide.
    pub beyond_4u: u32,
    /// Of those, beyond ±5u.
    pub beyond_5u: u32,
}

impl Cell {
    /// Count a reading of `estimate` with its `u` against the truth `mass`.
    pub fn record(&mut self, estimate: f64, u: f64, mass: f64) {
        let error = estimate - mass;
        let z = error / u;
        self.stated += 1;
        self.covered += u32::from(z.abs() <= 2.0);
        self.z_square_sum += z * z;
        self.error_square_sum += error * error;
        self.u_square_sum += u * u;
        self.beyond_4u += u32::from(z.abs() > 4.0);
        self.beyond_5u += u32::from(z.abs() > 5.0);
    }

    /// The covered fraction, `None` without stated runs.
    pub fn coverage(&self) -> Option<f64> {
        (self.stated > 0).then(|| f64::from(self.covered) / f64::from(self.stated))
    }

    /// The RMS of error/u over the stated runs (1 for a calibrated `u`), `None` without
    /// stated runs.
    pub fn rms_z(&self) -> Option<f64> {
        (self.stated > 0).then(|| (self.z_square_sum / f64::from(self.stated)).sqrt())
    }

    /// The RMS error and the RMS `u` over the stated runs, `None` without stated runs.
    pub fn rms_error_and_u(&self) -> Option<(f64, f64)> {
        let runs = f64::from(self.stated);
        (self.stated > 0).then(|| {
            (
                (self.error_square_sum / runs).sqrt(),
                (self.u_square_sum / runs).sqrt(),
            )
        })
    }

    /// The half-width of the 95 % Monte Carlo band around a true 95 % coverage.
    pub fn band(&self) -> Option<f64> {
        (self.stated > 0).then(|| 1.96 * (0.95 * 0.05 / f64::from(self.stated)).sqrt())
    }

    /// Pool `other`'s runs into this cell (runs of one cell merged in run order, or cells
    /// of several SNRs pooled).
    pub fn merge(&mut self, other: &Cell) {
        self.stated += other.stated;
        self.covered += other.covered;
        self.without_u += other.without_u;
        self.z_square_sum += other.z_square_sum;
        self.error_square_sum += other.error_square_sum;
        self.u_square_sum += other.u_square_sum;
        self.beyond_4u += other.beyond_4u;
        self.beyond_5u += other.beyond_5u;
    }
}

/// The scenes `study coverage` runs by default: the reference drop in white noise, and the
/// same drop with noise coloured as on the thesis's rig (`rig-noise`: vibration near the
/// resonance, its Fig. 5.9) and with floor vibration and 50 Hz mains (`vibration`); and a
/// load off calibration (`off-calibration`: 340 g, 2.5 times the identified mass).
pub const SCENES: [&str; 4] = [
    "reference-step",
    "rig-noise",
    "vibration",
    "off-calibration",
];

/// The cells of one SNR, in [`TIMES_MS`] order.
#[derive(Clone, Debug, PartialEq)]
pub struct SnrRow {
    /// Signal-to-noise ratio of the scene, dB.
    pub snr_db: f64,
    /// One per readout time.
    pub cells: Vec<Cell>,
}

/// Run `runs` drops of the `scene` at each SNR through `method`; the result does not depend
/// on the thread count (each run's seed is `run_seed(seed, run)`, sums are exact counts and
/// f64 sums merged in run order).
pub fn study(
    scene: &str,
    method: &Method,
    runs: u64,
    seed: u64,
    snrs_db: &[f64],
) -> Result<Vec<SnrRow>> {
    study_with(scene, method, runs, seed, snrs_db, Colour::Metered)
}

/// Whether a step method's `u` rests on the empty pan's metered noise colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Colour {
    /// Metered over [`METERING_S`] of the scene's empty pan (what the scale does).
    Metered,
    /// Not metered: the `u` from the residuals alone (a scale before its first
    /// [`estimator_core::MIN_METERED_BLOCKS`] block means of empty pan).
    Unknown,
}

/// [`study`] with or without the metered noise colour.
pub fn study_with(
    scene: &str,
    method: &Method,
    runs: u64,
    seed: u64,
    snrs_db: &[f64],
    colour: Colour,
) -> Result<Vec<SnrRow>> {
    let base = Scene::load(scene)?;
    let (_, mass_g, _) = base.studied_step();
    snrs_db
        .iter()
        .map(|&snr_db| {
            let (scene, context) = prepared(&base, snr_db, method, seed, colour)?;
            method.build(&context)?;
            let per_run: Vec<Result<Vec<Cell>>> = (0..runs)
                .into_par_iter()
                .map(|run| one_run(&scene, method, &context, run_seed(seed, run), mass_g))
                .collect();
            let mut cells = vec![Cell::default(); TIMES_MS.len()];
            for run in per_run {
                for (cell, one) in cells.iter_mut().zip(run?) {
                    cell.merge(&one);
                }
            }
            Ok(SnrRow { snr_db, cells })
        })
        .collect()
}

fn one_run(
    scene: &Scene,
    method: &Method,
    context: &BuildContext,
    seed: u64,
    mass_g: f64,
) -> Result<Vec<Cell>> {
    let mut estimator = method.build(context)?;
    let mut adc = scene.adc(seed);
    // The estimate starts at the onset, as a scale that found the landing starts it.
    let (onset, _, _) = scene.studied_step();
    for _ in 0..onset {
        let _ = adc.read();
    }
    let zero = scene.chain.zero_code();
    let rate_hz = 1.0 / scene.chain.conversion_period_s();
    let last = samples_at(*TIMES_MS.last().unwrap(), rate_hz);
    let mut cells = vec![Cell::default(); TIMES_MS.len()];
    for k in 1..=last {
        let reading = match adc.read() {
            Ok(code) => estimator.push(f64::from(code) - zero),
            Err(_) => estimator.push_missing(),
        };
        if let Some(i) = TIMES_MS.iter().position(|&t| samples_at(t, rate_hz) == k) {
            let cell = &mut cells[i];
            match (reading.estimate, reading.uncertainty) {
                (Some(estimate), Some(u)) => cell.record(estimate, u, mass_g),
                (Some(_), None) => cell.without_u += 1,
                (None, _) => {}
            }
        }
    }
    Ok(cells)
}

/// `base` at `snr_db`, delayed by [`PRE_ROLL_S`], and the build context of its runs: with
/// [`Colour::Metered`] a step method's with the empty pan's colour
/// ([`metered_autocovariance`]; not metered at all otherwise).
pub fn prepared(
    base: &Scene,
    snr_db: f64,
    method: &Method,
    seed: u64,
    colour: Colour,
) -> Result<(Scene, BuildContext)> {
    let scene = base
        .with_snr_db(snr_db)
        .delayed(PRE_ROLL_S)
        .ok_or_else(|| anyhow!("the scene cannot be delayed by {PRE_ROLL_S} s"))?;
    let metered = match (method, colour) {
        (Method::Step(setup), Colour::Metered) => {
            metered_autocovariance(&scene, setup.decimation, seed)
        }
        (Method::Model(spec), Colour::Metered) if spec.whitening > 0 => {
            metered_autocovariance(&scene, spec.decimation, seed)
        }
        _ => None,
    };
    let context = BuildContext::new(scene.chain, scene.chain.counts_per_gram())
        .with_noise_autocovariance(metered);
    Ok((scene, context))
}

/// The block means' autocovariance of `scene`'s empty pan at block length `decimation`,
/// metered over [`METERING_S`] after a second of settling (seed apart from the runs').
pub fn metered_autocovariance(
    scene: &Scene,
    decimation: u16,
    seed: u64,
) -> Option<Autocovariance<f64>> {
    let empty = scene.empty_pan(METERING_S + 1.0);
    let mut adc = empty.adc(run_seed(seed, u64::MAX));
    let mut meter = AutocovarianceMeter::<f64>::new(decimation).ok()?;
    let zero = scene.chain.zero_code();
    let rate_hz = 1.0 / scene.chain.conversion_period_s();
    let settle = rate_hz.round() as usize;
    for k in 0..empty.samples() {
        match adc.read() {
            Ok(code) if k >= settle => {
                let _ = meter.push(f64::from(code) - zero);
            }
            Ok(_) => {}
            Err(_) => meter.push_missing(),
        }
    }
    meter.sums().autocovariance()
}

/// The sample index (1-based) of a readout `ms` after the onset.
fn samples_at(ms: u32, rate_hz: f64) -> u64 {
    (f64::from(ms) * 1e-3 * rate_hz).round() as u64
}

/// The diagnostic table (`study coverage --diagnose`): per SNR and time, the RMS error and
/// the RMS `u` (in the estimate's unit) over the runs that stated `u`, and how many of
/// those lay beyond ±4u and ±5u.
pub fn write_diagnostics(
    rows: &[SnrRow],
    unit: &str,
    out: &mut (impl Write + ?Sized),
) -> Result<()> {
    writeln!(out)?;
    write_columns(out)?;
    for row in rows {
        write!(out, "| {} dB |", row.snr_db)?;
        for cell in &row.cells {
            match cell.rms_error_and_u() {
                Some((error, u)) => write!(
                    out,
                    " error {error:.2e}, u {u:.2e}; >4u {}, >5u {} |",
                    cell.beyond_4u, cell.beyond_5u
                )?,
                None => write!(out, " |")?,
            }
        }
        writeln!(out)?;
    }
    writeln!(out)?;
    writeln!(
        out,
        "Each cell: the RMS error and the RMS `u` ({unit}) over the runs that stated `u`, and how many of them lay beyond ±4u and ±5u."
    )?;
    Ok(())
}

/// A table's header: the SNR, then one column per readout time.
fn write_columns(out: &mut (impl Write + ?Sized)) -> Result<()> {
    write!(out, "| SNR |")?;
    for t in TIMES_MS {
        write!(out, " {t} ms |")?;
    }
    writeln!(out)?;
    write!(out, "|---|")?;
    for _ in TIMES_MS {
        write!(out, "---|")?;
    }
    writeln!(out)?;
    Ok(())
}

/// The table: coverage in % with the stated runs, RMS z, per SNR and time.
pub fn write_markdown(rows: &[SnrRow], header: &str, out: &mut impl Write) -> Result<()> {
    writeln!(out, "{header}")?;
    writeln!(out)?;
    write_columns(out)?;
    for row in rows {
        write!(out, "| {} dB |", row.snr_db)?;
        for cell in &row.cells {
            match (cell.coverage(), cell.rms_z()) {
                (Some(coverage), Some(rms_z)) => write!(
                    out,
                    " {:.1} % (rms z {rms_z:.2}, {}) |",
                    100.0 * coverage,
                    cell.stated
                )?,
                _ if cell.without_u > 0 => write!(out, " no u ({}) |", cell.without_u)?,
                _ => write!(out, " no estimate |")?,
            }
        }
        writeln!(out)?;
    }
    // The band of the cells that stated u in at least half as many runs as the most: a
    // cell of a few runs (the scale's first readings) says little and is not the table's.
    let most = rows
        .iter()
        .flat_map(|row| row.cells.iter())
        .map(|cell| cell.stated)
        .max()
        .unwrap_or(0);
    let fewest = rows
        .iter()
        .flat_map(|row| row.cells.iter())
        .map(|cell| cell.stated)
        .filter(|&stated| stated > 0 && 2 * stated >= most)
        .min()
        .unwrap_or(0);
    let band = Cell {
        stated: fewest,
        ..Cell::default()
    }
    .band()
    .unwrap_or(0.0);
    writeln!(out)?;
    writeln!(
        out,
        "Each cell: the share of runs whose error is within ±2u (goal 95 %; a true 95 % is observed within ±{:.1} % with {} or more runs, 95 % of the time; wider in a cell of fewer), the RMS of error/u (1 for a calibrated u) and the runs that stated u. No estimate: the method is still warming up.",
        100.0 * band,
        fewest
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Cell;

    /// A cell counts what `study coverage --diagnose` prints: the RMS error and `u`, and
    /// the readings beyond ±4u and ±5u.
    #[test]
    fn a_cell_counts_the_tail_and_the_rms() {
        let mut cell = Cell::default();
        for (estimate, u) in [(1.015, 0.01), (0.965, 0.01), (1.045, 0.01), (1.06, 0.01)] {
            cell.record(estimate, u, 1.0);
        }
        assert_eq!((cell.stated, cell.covered), (4, 1));
        assert_eq!((cell.beyond_4u, cell.beyond_5u), (2, 1));
        let (error, u) = cell.rms_error_and_u().unwrap();
        let squares = [0.015f64, 0.035, 0.045, 0.06].map(|e| e * e);
        let expected = (squares.iter().sum::<f64>() / 4.0).sqrt();
        assert!(
            (error - expected).abs() < 1e-12,
            "{error} against {expected}"
        );
        assert!((u - 0.01).abs() < 1e-12, "{u}");
        assert_eq!(Cell::default().rms_error_and_u(), None);
    }
}
