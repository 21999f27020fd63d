//! `host-sim replay` against the QEMU board: its rows for the QEMU demo scene must be the
//! readout lines the QEMU firmware printed, line for line: the same sample, the same mass to
//! the bit (both run the core's `Scale` in `f32`), the same state.

use estimator_core::weighing::{RawSample, ScaleState, WeighingConfig};
use host_sim::qemu_scenes;
use host_sim::replay::{self, ConfiguredScale, ReplayRow};

use crate::e2e::{firmware_weighing_config, RunLog};

/// `host-sim replay --scene qemu-demo`'s rows, computed by the library it calls.
pub fn qemu_demo_rows() -> anyhow::Result<Vec<ReplayRow>> {
    qemu_demo_rows_with(&firmware_weighing_config()?)
}

/// The same rows with `weighing` as the board's configuration.
pub fn qemu_demo_rows_with(weighing: &WeighingConfig) -> anyhow::Result<Vec<ReplayRow>> {
    let mut cell = qemu_scenes::demo_scene();
    let count = (cell.script().end_s() * host_sim::SAMPLE_RATE_HZ).round() as usize;
    let samples: Vec<RawSample> = replay::converter_samples(&mut cell, count);
    let factory = qemu_scenes::factory_calibration()
        .map_err(|e| anyhow::anyhow!("factory calibration: {e:?}"))?;
    let mut scale = Box::new(
        ConfiguredScale::configured(weighing, factory.counts_scale())
            .map_err(|e| anyhow::anyhow!("weighing configuration refused: {e}"))?,
    );
    Ok(replay::replay(samples, &mut scale))
}

/// Every difference between the replay's rows and the run's readout lines (empty: they
/// agree line for line).
pub fn differences(rows: &[ReplayRow], run: &RunLog) -> Vec<String> {
    let readouts = run.readouts();
    let mut failures = Vec::new();
    if readouts.len() != rows.len() {
        failures.push(format!(
            "replay has {} rows, the firmware printed {} readout lines",
            rows.len(),
            readouts.len()
        ));
    }
    for (row, line) in rows.iter().zip(&readouts) {
        let mass = row.reading.mass_g.map(f64::from);
        let same_mass = match (mass, line.mass_g) {
            (Some(a), Some(b)) => a as f32 == b as f32,
            (None, None) => true,
            _ => false,
        };
        let u = row.reading.uncertainty_g.map(f64::from);
        let same_u = match (u, line.u_g) {
            (Some(a), Some(b)) => a as f32 == b as f32,
            (None, None) => true,
            _ => false,
        };
        let state = format!("{:?}", row.reading.state);
        if row.sample != line.sample
            || !same_mass
            || !same_u
            || state != line.state
            || row.reading.is_final != line.is_final
        {
            failures.push(format!(
                "sample {}: replay mass {:?} u {u:?} state {state} final {}; firmware sample {} mass {:?} u {:?} state {} final {}",
                row.sample,
                mass,
                row.reading.is_final,
                line.sample,
                line.mass_g,
                line.u_g,
                line.state,
                line.is_final
            ));
        }
    }
    failures.truncate(10);
    failures
}

/// What a scale showed on the QEMU demo scene: readout lines, those with a mass, those
/// shown stable or empty, those final. Says whether a method's cost was measured on a scale
/// that weighs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Shown {
    pub lines: usize,
    pub with_mass: usize,
    pub stable: usize,
    pub is_final: usize,
}

impl Shown {
    /// Tally `rows`.
    pub fn of(rows: &[ReplayRow]) -> Self {
        let mut shown = Self {
            lines: rows.len(),
            ..Self::default()
        };
        for row in rows {
            let reading = &row.reading;
            shown.with_mass += usize::from(reading.mass_g.is_some());
            shown.stable += usize::from(matches!(
                reading.state,
                ScaleState::Stable | ScaleState::Empty
            ));
            shown.is_final += usize::from(reading.is_final);
        }
        shown
    }
}
