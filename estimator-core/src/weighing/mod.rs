//! The weighing application on top of the estimators: the [`Scale`] that finds load
//! changes, tares, tracks the zero and runs the configured method; the operator's
//! [`Commands`] (tare, calibration with a known mass); the [`Calibration`] record (gain and
//! zero, CRC-protected) the board stores; and the configured method ([`WeighingConfig`],
//! what tuning chose and the firmware builds).
//!
//! This layer never imports the method search ([`crate::tuning`]): the firmware runs it
//! without the search.

mod calibration;
mod command;
mod method;
mod scale;

pub use calibration::{
    load_or_default, Calibration, CalibrationError, CalibrationSource, FrontEnd, RECORD_LEN,
    RECORD_VERSION,
};
pub use command::{
    load_calibration, store_calibration, CalibrationFailure, CalibrationStore, Command,
    CommandConfig, CommandOutcome, CommandRefusal, Commands, KeyDebouncer, KeyPress, StoreFailure,
};
pub(crate) use method::cover_ratios;
pub(crate) use method::readout_samples;
pub use method::{
    BankCandidate, LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, RegionError,
    WeighingConfig, WeighingEstimator, WeighingMethod, MAX_LOADS, MAX_NYQUIST_OVER_BANDWIDTH,
    MAX_SCENES, MIN_DATA_DRIVEN_ORDER, MIN_REFERENCE_SAMPLES,
};
pub use scale::{
    CountsScale, RawSample, Scale, ScaleConfig, ScaleEstimator, ScaleFault, ScaleReading,
    ScaleState, StepScale, TareError,
};
