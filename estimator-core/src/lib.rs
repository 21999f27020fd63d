//! Step-input estimators for fast weighing, in fixed-size, allocation-free `no_std` Rust.
//!
//! A load cell rings and creeps for a second or more after a mass lands. The estimators
//! here read the mass from that transient instead of waiting for it to settle. This crate
//! is the one implementation of every estimator and of the weighing decisions: the firmware
//! and the host simulator call the very same code, in `f32` on the Cortex-M4F and in `f32`
//! or `f64` on the host.
//!
//! What it must never do: allocate, panic on data, use `unsafe`, or report a number that is
//! not finite as a valid reading. Bad input becomes a [`Reading`] whose [`State`] says why.
//!
//! ## Layers
//! Each layer uses only those above it in this list:
//! - [`numerics`]: the scalar trait [`Real`], the Givens factor, small solves, the matrix
//!   exponential;
//! - the estimators (re-exported here): [`StepEstimator`], the data-driven estimator of
//!   Markovsky (2015) as analysed by Quintana-Carapia (2020), solved recursively in
//!   square-root information form; its errors-in-variables alternatives, the model-based
//!   [`ModelEstimator`] / [`ModelBank`], the [`RampEstimator`] and the [`Baseline`]s;
//! - [`sensor`]: the converter seam, the physical load-cell model and its identification;
//! - [`weighing`]: the scale, the operator's commands, the calibration record (gain and
//!   zero) and the configured method — what the firmware runs;
//! - [`tuning`]: the method search that turns a few recorded drops into the smallest
//!   configuration that meets an accuracy target. Only the host runs it.
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]
#![allow(clippy::needless_range_loop)]
// index loops mirror the matrix algebra
// `!(a < b)` is how a comparison that must also fail on NaN is written.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod estimators;
pub mod numerics;
mod reading;
pub mod sensor;
pub mod tuning;
pub mod weighing;

pub use estimators::baseline::{
    Baseline, BaselineConfig, BaselineMode, CellMode, Compensator, CompensatorConfig, Prefilter,
    Shaper, ShaperConfig, ShaperKind, Unfiltered,
};
pub use estimators::bias_compensated::{BiasCompensatedConfig, BiasCompensatedStepEstimator};
pub use estimators::consistency::{NoiseReference, MISMATCH_ALLOWANCE, MISMATCH_FALSE_ALARM};
pub use estimators::covariance::CovarianceStepEstimator;
pub use estimators::iv::{
    max_instrument_delay, IvConfig, IvStepEstimator, DEFAULT_MIN_IDENTIFIABILITY,
};
pub use estimators::metered_noise::MIN_METERED_BLOCKS;
pub use estimators::model::{
    InitialState, Interpolation, ModelBank, ModelConfig, ModelEstimator, SensorModel,
    WHITENING_ORDER,
};
pub use estimators::noise_meter::{
    Autocovariance, AutocovarianceMeter, AutocovarianceSums, NoiseMeter, AUTOCOVARIANCE_LAGS,
};
pub use estimators::ramp::{RampConfig, RampEstimator};
pub use estimators::step::{StepConfig, StepEstimator, MAX_DECIMATION, MIN_IDENTIFIABILITY};
pub use numerics::real::Real;
pub use reading::{ConfigError, Estimator, InvalidReason, Reading, State};
