//! Step-input estimators for fast weighing, in fixed-size, allocation-free `no_std` Rust.
//!
//! A load cell rings and creeps for a second or more after a mass lands. The estimators
//! here read the mass from that transient instead of waiting for it to settle. This crate
//! is the one implementation of every estimator: the firmware and the host simulator call
//! the very same code, in `f32` on the Cortex-M4F and in `f32` or `f64` on the host.
//!
//! What it must never do: allocate, panic on data, use `unsafe`, or report a number that is
//! not finite as a valid reading. Bad input becomes a [`Reading`] whose [`State`] says why.
//!
//! The core method is [`StepEstimator`], the data-driven estimator of Markovsky (2015) as
//! analysed by Quintana-Carapia (2020), solved recursively in square-root information form.
//! The model-based alternative is [`ModelEstimator`] / [`ModelBank`] on a [`LoadCellModel`]
//! identified at calibration by [`identify()`](crate::identify::identify). [`tuning`] turns a
//! few recorded drops of a reference mass into the smallest configuration that meets an
//! accuracy target ([`tuning::calibrate`], [`tuning::WeighingConfig`]).
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]
#![allow(clippy::needless_range_loop)]
// index loops mirror the matrix algebra
// `!(a < b)` is how a comparison that must also fail on NaN is written.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod adc;
mod baseline;
pub mod bias_compensated;
pub mod calibration;
pub mod command;
mod consistency;
mod covariance;
pub mod expm;
mod factor;
pub mod identify;
mod input;
pub mod iv;
mod loadcell;
mod model;
mod noise_meter;
mod ramp;
mod reading;
mod real;
pub mod scale;
mod square;
mod step;
pub mod tuning;

pub use adc::{AdcError, AdcSource};
pub use baseline::{Baseline, BaselineConfig, BaselineMode};
pub use bias_compensated::{BiasCompensatedConfig, BiasCompensatedStepEstimator};
pub use calibration::{Calibration, CalibrationError, CalibrationSource, FrontEnd};
pub use command::{
    CalibrationFailure, CalibrationStore, Command, CommandConfig, CommandOutcome, CommandRefusal,
    Commands, KeyDebouncer, KeyPress, StoreFailure,
};
pub use consistency::{NoiseReference, MISMATCH_ALLOWANCE, MISMATCH_FALSE_ALARM};
pub use covariance::CovarianceStepEstimator;
pub use identify::{identify, Identified, IdentifyConfig, IdentifyError};
pub use iv::{max_instrument_delay, IvConfig, IvStepEstimator, DEFAULT_MIN_IDENTIFIABILITY};
pub use loadcell::{LoadCellModel, MAX_DAMPING_RATIO};
pub use model::{InitialState, ModelBank, ModelConfig, ModelEstimator, SensorModel};
pub use noise_meter::NoiseMeter;
pub use ramp::{RampConfig, RampEstimator};
pub use reading::{ConfigError, Estimator, InvalidReason, Reading, State};
pub use real::Real;
pub use scale::{
    CountsScale, RawSample, Scale, ScaleConfig, ScaleEstimator, ScaleFault, ScaleReading,
    ScaleState, StepScale, TareError,
};
pub use step::{StepConfig, StepEstimator, MAX_DECIMATION, MIN_IDENTIFIABILITY};
