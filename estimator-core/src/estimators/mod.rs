//! The estimators: each turns raw samples of a step response into an estimate of the step
//! level, one [`crate::Reading`] per sample, behind the one [`crate::Estimator`] interface.
//!
//! - data-driven (no model of the sensor, only its static gain): [`step`] (square-root
//!   information RLS, the method of the thesis), [`covariance`] (the textbook covariance
//!   RLS, kept as the reference it is compared with), [`iv`] and [`bias_compensated`]
//!   (errors-in-variables alternatives), [`ramp`] (a load sliding on);
//! - model-based: [`model`] (Kalman/RLS on the initial state and the input, and a bank of
//!   models across the resonance);
//! - baselines a user would otherwise pick: [`baseline`] (settle-then-average, moving
//!   average, each also behind a compensation filter or an input-shaper FIR tuned to the
//!   cell);
//! - shared: [`intake`] (the sample count, fault latch, range check, gain, decimation and
//!   reading every estimator answers with), [`input`] (sample checks, block averaging, the
//!   difference window),
//!   [`consistency`] (residuals against the noise metered at tare), [`noise_meter`].
//!
//! The crate root re-exports the estimators and their configurations; the modules stay
//! private so that every item has one path.

pub(crate) mod baseline;
pub(crate) mod bc_uncertainty;
pub(crate) mod bias_compensated;
pub(crate) mod consistency;
pub(crate) mod covariance;
pub(crate) mod input;
pub(crate) mod intake;
pub(crate) mod iv;
pub(crate) mod iv_uncertainty;
pub(crate) mod metered_noise;
pub(crate) mod model;
pub(crate) mod noise_meter;
pub(crate) mod ramp;
pub(crate) mod ramp_uncertainty;
pub(crate) mod step;
pub(crate) mod step_uncertainty;
