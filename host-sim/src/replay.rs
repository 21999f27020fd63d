//! `host-sim replay`: exactly what the firmware runs, on a recording or a scene — the scale
//! with the configured method (`Scale::configured`, as both boards build it), its onset
//! detection, zero tracking, flags and states — printed as the readout the board shows, one
//! CSV row per 20 Hz readout line: `t_s,mass_g,u_g,state,final`.
//!
//! `host-sim estimate` runs the bare estimator; this runs the instrument.
//!
//! What it must never do: run anything but the core's `Scale` (no second decision logic),
//! or print a mass the scale did not show.

use std::io::Write;

use anyhow::Result;
use estimator_core::sensor::AdcSource;
use estimator_core::weighing::console::StateWord;
use estimator_core::weighing::{
    CountsScale, RawSample, Scale, ScaleEstimator, ScaleReading, ScaleState,
};

/// The scale both boards build from a weighing configuration (`Scale::configured`), with
/// host-sim's sizes: any order up to its capacity, its bank size. The firmware sizes the
/// same type for its one configured method; the sizes hold the arrays, the arithmetic is
/// the same.
pub type ConfiguredScale = Scale<
    estimator_core::weighing::WeighingEstimator<
        f32,
        { crate::montecarlo::CAPACITY },
        { crate::sensor::STATES },
        { crate::calibrate::BANK_CANDIDATES },
    >,
>;

/// Raw samples per readout line at 4 kHz (the boards' 20 Hz readout).
pub const READOUT_SAMPLES: u32 = 200;

/// The header of the replay CSV.
pub const HEADER: &str = "t_s,mass_g,u_g,state,final";

/// One readout line.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayRow {
    /// Samples the scale had taken at this line (the firmware's `sample=`).
    pub sample: u32,
    /// The reading of that sample.
    pub reading: ScaleReading,
}

impl ReplayRow {
    /// The row as CSV (`t_s,mass_g,u_g,state,final`) at `sample_rate_hz`.
    pub fn csv(&self, sample_rate_hz: f64) -> String {
        let t_s = f64::from(self.sample) / sample_rate_hz;
        let mass = self
            .reading
            .mass_g
            .map_or(String::new(), |mass| format!("{mass}"));
        let u = self
            .reading
            .uncertainty_g
            .map_or(String::new(), |u| format!("{u}"));
        let final_flag = u8::from(self.reading.is_final);
        format!(
            "{t_s},{mass},{u},{},{final_flag}",
            state_word(&self.reading.state)
        )
    }
}

/// The state as the replay CSV names it: the console's word (`empty`, `estimating`,
/// `stable`, or `invalid:<reason>`: `saturated`, `sample_lost`, `uncalibrated`, or the
/// estimator's reason, `ill_conditioned`, `model_mismatch`, …).
pub fn state_word(state: &ScaleState) -> String {
    StateWord(*state).to_string()
}

/// Push `samples` through `scale` and keep the reading of every `READOUT_SAMPLES`-th
/// sample, as the boards print it.
pub fn replay<E: ScaleEstimator>(
    samples: impl IntoIterator<Item = RawSample>,
    scale: &mut Scale<E>,
) -> Vec<ReplayRow> {
    let mut rows = Vec::new();
    for (index, sample) in samples.into_iter().enumerate() {
        let reading = scale.push(sample);
        let taken = index as u64 + 1;
        if taken.is_multiple_of(u64::from(READOUT_SAMPLES)) {
            rows.push(ReplayRow {
                sample: u32::try_from(taken).unwrap_or(u32::MAX),
                reading,
            });
        }
    }
    rows
}

/// The raw samples of a recording of ADC codes, as the board's converter hands them over:
/// a code at or beyond a rail (`rail_low`, `rail_high`) is saturated, a missing value
/// (NaN) is a lost sample.
pub fn recorded_samples(codes: &[f64], rail_low: f64, rail_high: f64) -> Vec<RawSample> {
    codes
        .iter()
        .map(|&code| {
            if code.is_nan() {
                RawSample::Lost
            } else if code <= rail_low || code >= rail_high {
                RawSample::Saturated
            } else {
                RawSample::Counts(code.round() as i32)
            }
        })
        .collect()
}

/// `count` raw samples of a simulated converter, as the boards read it.
pub fn converter_samples(adc: &mut impl AdcSource, count: usize) -> Vec<RawSample> {
    (0..count).map(|_| RawSample::read(adc)).collect()
}

/// Write the CSV: the header, then one row per readout line.
pub fn write_csv(rows: &[ReplayRow], sample_rate_hz: f64, out: &mut impl Write) -> Result<()> {
    writeln!(out, "{HEADER}")?;
    for row in rows {
        writeln!(out, "{}", row.csv(sample_rate_hz))?;
    }
    Ok(())
}

/// The calibration a replay converts with: the configuration's gain and zero unless given.
pub fn calibration(
    counts_per_gram: f64,
    zero_counts: f64,
    override_gain: Option<f64>,
    override_zero: Option<f64>,
) -> CountsScale {
    CountsScale {
        counts_per_gram: override_gain.unwrap_or(counts_per_gram) as f32,
        zero_counts: override_zero.unwrap_or(zero_counts) as f32,
    }
}

/// The firmware's weighing configuration as shipped (`firmware/weighing.toml`, what its
/// images are built with), built into this binary so it needs no source tree.
pub const SHIPPED_CONFIG: &str = include_str!("../../firmware/weighing.toml");

/// [`SHIPPED_CONFIG`], parsed.
pub fn shipped_config() -> Result<(
    estimator_core::weighing::WeighingConfig,
    crate::montecarlo::Precision,
)> {
    crate::calibrate::parse_config(
        std::path::Path::new("firmware/weighing.toml (built in)"),
        SHIPPED_CONFIG,
    )
}
