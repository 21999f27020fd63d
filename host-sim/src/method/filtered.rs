//! The baselines behind a pre-filter tuned to the cell: `compensated:` (the core's
//! [`Compensator`]) and `shaped:` (its [`Shaper`]), each ahead of the same averaging and
//! stability test as `settled` and `moving` (`average=` picks which).
//!
//! ```text
//! compensated:fn_hz=25,zeta=0.03[,ratio=2][,placed_zeta=1][,average=moving][,block=80][,K=10][,band_g=0.5][,precision=..]
//! shaped:fn_hz=25,zeta=0.03[,shaper=zvd][,average=moving][,block=80][,K=10][,band_g=0.5][,precision=..]
//! ```
//!
//! `fn_hz` and `zeta` are the cell's mode as calibration identified it (`firmware/weighing.toml`'s
//! `[model]`); `ratio` is the placed pair's frequency over `fn_hz`.

use std::fmt;

use anyhow::Result;
use estimator_core::{
    BaselineMode, CellMode, Compensator, CompensatorConfig, Estimator, NoiseReference, Real,
    Shaper, ShaperConfig, ShaperKind,
};

use super::{baseline, BaselineSpec};

/// Past values the shaper's delay line holds (a const generic in the core): three stages of
/// half a period down to 5.9 Hz at 4 kHz.
pub const SHAPER_CAPACITY: usize = 1024;

/// Which pre-filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Prefiltering {
    /// Pole-zero compensation: the placed pair at `ratio` times the cell's frequency, damping
    /// `placed_zeta`.
    Compensation {
        /// The placed pair's frequency over the cell's.
        ratio: f64,
        /// The placed pair's damping ratio.
        placed_zeta: f64,
    },
    /// The input-shaper FIR.
    Shaper(ShaperKind),
}

/// A baseline behind a pre-filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilteredSpec {
    /// The cell's natural frequency the filter is tuned to, Hz.
    pub natural_frequency_hz: f64,
    /// The cell's damping ratio the filter is tuned to.
    pub damping_ratio: f64,
    /// The pre-filter.
    pub filter: Prefiltering,
    /// The averaging after it.
    pub average: BaselineMode,
    /// Blocks, band and precision, as for `settled` and `moving`.
    pub baseline: BaselineSpec,
}

/// `average=` as written.
pub(super) fn average_name(mode: BaselineMode) -> &'static str {
    match mode {
        BaselineMode::SettledAverage => "settled",
        BaselineMode::MovingAverage => "moving",
    }
}

/// `shaper=` as written.
pub(super) fn shaper_name(kind: ShaperKind) -> &'static str {
    match kind {
        ShaperKind::Zv => "zv",
        ShaperKind::Zvd => "zvd",
        ShaperKind::Zvdd => "zvdd",
    }
}

impl FilteredSpec {
    /// The spec's family: `compensated` or `shaped`.
    pub fn family(&self) -> &'static str {
        match self.filter {
            Prefiltering::Compensation { .. } => "compensated",
            Prefiltering::Shaper(_) => "shaped",
        }
    }

    /// The estimator at the context's sample rate.
    pub(super) fn build<T: Real + Send + 'static>(
        &self,
        gain: T,
        sample_rate_hz: f64,
        reference: Option<NoiseReference<T>>,
    ) -> Result<Box<dyn Estimator<T> + Send>> {
        let cell = CellMode {
            natural_frequency_hz: self.natural_frequency_hz,
            damping_ratio: self.damping_ratio,
            sample_rate_hz,
        };
        let core = |e: estimator_core::ConfigError| anyhow::anyhow!("{e}");
        let spec = &self.baseline;
        match self.filter {
            Prefiltering::Compensation { ratio, placed_zeta } => {
                let filter = Compensator::<T>::new(CompensatorConfig {
                    cell,
                    placed_frequency_hz: ratio * self.natural_frequency_hz,
                    placed_damping_ratio: placed_zeta,
                })
                .map_err(core)?;
                baseline(spec, self.average, gain, reference, filter)
            }
            Prefiltering::Shaper(kind) => {
                let filter =
                    Shaper::<T, SHAPER_CAPACITY>::new(ShaperConfig { cell, kind }).map_err(core)?;
                baseline(spec, self.average, gain, reference, filter)
            }
        }
    }
}

impl fmt::Display for FilteredSpec {
    /// Every parameter written out (the defaults of the text form are only for typing).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:fn_hz={},zeta={}",
            self.family(),
            self.natural_frequency_hz,
            self.damping_ratio
        )?;
        match self.filter {
            Prefiltering::Compensation { ratio, placed_zeta } => {
                write!(f, ",ratio={ratio},placed_zeta={placed_zeta}")?
            }
            Prefiltering::Shaper(kind) => write!(f, ",shaper={}", shaper_name(kind))?,
        }
        write!(f, ",average={},", average_name(self.average))?;
        self.baseline.write_fields(f)
    }
}
