//! `host-sim estimate`: run any of the core's estimators (a [`Method`]) over a recording
//! (one raw sample a row, read by [`crate::recording`]), so anyone's recorded data meets the
//! same core the firmware runs. It must never hold a second implementation: every number
//! comes from `estimator-core`; and a bad row must never be skipped: the recording refuses it
//! by its line (an empty cell is a lost sample, which the reading flags).

use std::io::Write;

use anyhow::Result;
use estimator_core::{InvalidReason, State};

use crate::method::{BoxedEstimator, BuildContext, Method};
use crate::recording::Recording;

/// How a reading's state is written in the CSV.
pub fn state_name(state: State) -> &'static str {
    match state {
        State::WarmingUp => "warming_up",
        State::Estimating => "estimating",
        State::Invalid(InvalidReason::NonFiniteInput) => "invalid_non_finite_input",
        State::Invalid(InvalidReason::OutOfRange) => "invalid_out_of_range",
        State::Invalid(InvalidReason::IllConditioned) => "invalid_ill_conditioned",
        State::Invalid(InvalidReason::NonFiniteUpdate) => "invalid_non_finite_update",
        State::Invalid(InvalidReason::MissingSample) => "invalid_missing_sample",
        State::Invalid(InvalidReason::OutsideModelRange) => "invalid_outside_model_range",
        State::Invalid(InvalidReason::LostDefiniteness) => "invalid_lost_definiteness",
        State::Invalid(InvalidReason::ModelMismatch) => "invalid_model_mismatch",
        State::Invalid(InvalidReason::Unconfigured) => "invalid_unconfigured",
    }
}

/// Run `method` over the samples of `recording`, write `k,estimate,u,state`. `zero` is
/// subtracted from every sample (in f64, before any conversion to f32). An empty cell is a
/// lost sample (the reading says so); a non-finite one is flagged by the estimator.
pub fn estimate_csv(
    recording: &Recording,
    method: &Method,
    context: &BuildContext,
    zero: f64,
    out: &mut impl Write,
) -> Result<()> {
    estimate_with(method.build(context)?, recording, zero, out)
}

/// [`estimate_csv`] with an estimator already built (e.g. a weighing configuration's).
pub fn estimate_with(
    mut estimator: BoxedEstimator,
    recording: &Recording,
    zero: f64,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(out, "k,estimate,u,state")?;
    for (k, row) in recording.rows.iter().enumerate() {
        let reading = match row.sample {
            Some(value) => estimator.push(value - zero),
            None => estimator.push_missing(),
        };
        let state = state_name(reading.state);
        match (reading.estimate, reading.uncertainty) {
            (Some(value), Some(u)) => writeln!(out, "{k},{value},{u},{state}")?,
            (Some(value), None) => writeln!(out, "{k},{value},,{state}")?,
            (None, _) => writeln!(out, "{k},,,{state}")?,
        }
    }
    Ok(())
}
