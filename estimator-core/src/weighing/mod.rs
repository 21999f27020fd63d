//! The weighing application on top of the estimators: the [`Scale`] that finds load
//! changes, tares, tracks the zero and runs the configured method; the operator's
//! [`Commands`] (tare, calibration with a known mass) and the KEY button's
//! [`KeyDebouncer`]; the [`Calibration`] record (gain and zero, CRC-protected), the
//! [`CalibrationLimits`] it must fall in and the [`CalibrationStore`] the board keeps it
//! in; and the configured method ([`WeighingConfig`], what tuning chose and the firmware
//! builds).
//!
//! This layer never imports the method search ([`crate::tuning`]): the firmware runs it
//! without the search.

mod calibration;
mod command;
pub mod console;
mod key;
mod method;
mod recorder;
mod scale;
#[cfg(test)]
pub(crate) use scale::test_scene;
mod sequence;
mod settings;

pub use calibration::{
    load_calibration, load_or_default, store_calibration, Calibration, CalibrationError,
    CalibrationLimits, CalibrationSource, CalibrationStore, FrontEnd, StoreFailure, RECORD_LEN,
    RECORD_VERSION,
};
#[cfg(feature = "flash-store")]
pub use calibration::{FlashStore, FlashStoreError, RamFlash, RamFlashError};
pub use command::{
    CalibrationFailure, Command, CommandConfig, CommandOutcome, CommandRefusal, Commands,
};
pub use key::{KeyDebouncer, KeyPress};
pub(crate) use method::cover_ratios;
pub(crate) use method::readout_samples;
pub use method::{
    BankCandidate, LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, RegionError, Spec,
    SpecError, WeighingConfig, WeighingEstimator, WeighingMethod, COLOUR_LAGS, MAX_LOADS,
    MAX_NYQUIST_OVER_BANDWIDTH, MAX_SCENES, MIN_DATA_DRIVEN_ORDER, MIN_REFERENCE_SAMPLES,
    UNCERTAINTY_ORDERS, UPLOAD_ORDER_CAPACITY,
};
pub use recorder::{CaptureInfo, RecordRefusal, Recorder};
pub use scale::{
    ConfiguredEstimator, CountsScale, MethodRefusal, RawSample, Scale, ScaleConfig, ScaleEstimator,
    ScaleFault, ScaleReading, ScaleState, StepScale, TareError, ZeroError, TARE_ACCURACY_E,
    VOUCHING_COVERAGE_FACTOR, ZERO_SETTING_RANGE_OF_MAX,
};
pub use sequence::SampleSequence;
pub use settings::{load_settings, Settings, SettingsStore, SETTINGS_LEN, SETTINGS_VERSION};
