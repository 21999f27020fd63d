//! What the scale takes in and answers: one raw sample, one reading per sample, the state
//! the display shows and why a mass is missing; the gain and zero it converts with.
//!
//! A reading never carries a mass the scale cannot vouch for: `mass_g` is `None` whenever
//! the state is invalid, and the state says why.

use crate::reading::InvalidReason;
use crate::sensor::AdcSource;

/// One raw sample as the firmware hands it over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RawSample {
    /// A conversion result in ADC counts (not on a rail).
    Counts(i32),
    /// The converter sat on a rail: the input is out of its range.
    Saturated,
    /// The sample was lost (ADC overrun, full queue, a gap in the sequence numbers).
    Lost,
}

impl RawSample {
    /// The next conversion of `adc` as the scale takes it: a code on a rail is
    /// [`Self::Saturated`], a failed conversion [`Self::Lost`].
    #[inline]
    pub fn read<A: AdcSource>(adc: &mut A) -> Self {
        match adc.read() {
            Ok(code) if adc.is_saturated(code) => Self::Saturated,
            Ok(code) => Self::Counts(code as i32),
            Err(_) => Self::Lost,
        }
    }
}

/// Why the scale cannot show a mass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ScaleFault {
    /// The ADC sat on a rail (overload, or a wiring fault).
    Saturated,
    /// A sample was lost; the estimator restarts on the samples after the gap.
    SampleLost,
    /// The estimator refused the data, with its reason.
    Estimator(InvalidReason),
    /// The calibration in use is not a valid record (non-finite or zero gain).
    Uncalibrated,
    /// The gross mass is above Max + 9 e (OIML R 76 4.4.3): beyond what the scale may
    /// show. A front end that clips a few codes short of the ADC's rail reads every
    /// heavier load as the clip level; this is what keeps that level off the display.
    Overload,
}

/// What the pan holds, as the display says it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ScaleState {
    /// Stable (below), the gross mass within `empty_band_g` of zero.
    Empty,
    /// A load changed recently, or nothing vouches for the reading yet: the mass (if any)
    /// is the estimator's current answer, with no claim that it is right.
    Estimating,
    /// The estimate has stayed within the stability band for `stable_hold_samples`, states
    /// a `u` whose upper bound, [`super::VOUCHING_COVERAGE_FACTOR`] times, is within the
    /// permissible error, and no motion is building up. A reading without a `u` is never
    /// stable (nor empty, nor final).
    Stable,
    /// No mass can be shown, and why.
    Invalid(ScaleFault),
}

/// One answer per raw sample.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScaleReading {
    /// Net mass in grams (gross minus tare); `None` while warming up or invalid.
    pub mass_g: Option<f32>,
    /// The standard uncertainty of `mass_g` in grams (GUM; ±2u is a 95 % interval): the
    /// estimator's, converted with the gain, the tare's when a tare is in use, and the
    /// zero's possible drift since it was last seen (`ScaleConfig::zero_drift_g_per_s`),
    /// in quadrature. `None` without a mass, or when the configured method states none.
    pub uncertainty_g: Option<f32>,
    /// The reading is final: a mass, estimating or stable, whose 95 % interval (±2u) is
    /// within the configured target ([`super::ScaleConfig::final_target_g`]) and four of
    /// whose `u` are within the permissible error ([`super::VOUCHING_COVERAGE_FACTOR`]),
    /// its estimate held within the stability band for the hold time and the load not in
    /// motion.
    pub is_final: bool,
    /// What the pan holds.
    pub state: ScaleState,
    /// Raw samples since the last detected load change (or restart), shown saturating at
    /// `u32::MAX` (12.4 days at 4 kHz, past every threshold that reads it); the scale's own
    /// count is `u64` and never saturates.
    pub samples_since_change: u32,
    /// Load changes detected since boot (saturating).
    pub load_changes: u32,
}

/// Why a tare command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TareError {
    /// Tare needs a stable (or empty) reading; the pan is still moving or invalid.
    NotStable,
    /// The reading is stable but not yet known well enough to tare with: the tare's
    /// error carries over into every net reading after it, so it must be within
    /// ±[`super::TARE_ACCURACY_E`] e (twice the upper bound of its `u`), as OIML R 76 asks
    /// of zero setting and tare.
    Uncertain,
}

/// Why a zero-setting command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ZeroError {
    /// Zero setting needs a stable (or empty) reading.
    NotStable,
    /// The reading is not yet known to within ±0.25 e (as for a tare).
    Uncertain,
    /// The pan holds more than the zero-setting range from the calibrated zero allows
    /// (±[`super::ZERO_SETTING_RANGE_OF_MAX`] of Max): a load, not a zero drift.
    OutOfRange,
    /// A tare is in use: clear it first (the zero is set on the gross reading).
    Tared,
}

/// Gain and zero the scale converts counts with (see `crate::weighing::calibration`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CountsScale {
    /// ADC counts per gram.
    pub counts_per_gram: f32,
    /// ADC counts of the empty pan.
    pub zero_counts: f32,
}
