//! `host-sim estimate`: run any of the core's estimators (a [`Method`]) over a recorded CSV
//! (one raw sample a row in a column `y`), so anyone's recorded data meets the same core the
//! firmware runs. It must never hold a second implementation: every number comes from
//! `estimator-core`; and a bad row must never be skipped: it is an error naming its line (an
//! empty `y` is a lost sample, which the reading flags).

use std::io::{BufRead, Write};

use anyhow::{bail, Context, Result};
use estimator_core::{InvalidReason, State};

use crate::method::{BoxedEstimator, BuildContext, Method};

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
    }
}

/// Read `input` (named `name` in errors), write `k,estimate,u,state`. `zero` is subtracted
/// from every sample (in f64, before any conversion to f32). An empty `y` is a lost sample
/// (the reading says so); a `y` that is not a number is an error naming the line.
pub fn estimate_csv(
    input: impl BufRead,
    name: &str,
    method: &Method,
    context: &BuildContext,
    zero: f64,
    out: &mut impl Write,
) -> Result<()> {
    estimate_with(method.build(context)?, input, name, zero, out)
}

/// [`estimate_csv`] with an estimator already built (e.g. a weighing configuration's).
pub fn estimate_with(
    mut estimator: BoxedEstimator,
    input: impl BufRead,
    name: &str,
    zero: f64,
    out: &mut impl Write,
) -> Result<()> {
    let rows = y_fields(input, name, |header| {
        format!("{name}: line 1: expected a column `y` in the header `{header}`")
    })?;
    writeln!(out, "k,estimate,u,state")?;
    for (k, row) in rows.enumerate() {
        let (line_number, field) = row?;
        let reading = if field.is_empty() {
            estimator.push_missing()
        } else {
            let value: f64 = field.parse().with_context(|| {
                format!(
                    "{name}: line {line_number}: column `y`: expected a number, found `{field}`"
                )
            })?;
            estimator.push(value - zero)
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

/// The `y` field of each row of a recording (a CSV whose header names a column `y`, as
/// `simulate` writes it), with its line number; blank rows are passed over, a row without
/// the column gives an empty field. An unreadable or empty file is an error naming `name`, a
/// header without `y` the error `no_column` words from the header.
pub(crate) fn y_fields<'a>(
    input: impl BufRead + 'a,
    name: &'a str,
    no_column: impl FnOnce(&str) -> String,
) -> Result<impl Iterator<Item = Result<(usize, String)>> + 'a> {
    let mut lines = input.lines();
    let header = match lines.next() {
        Some(line) => line.with_context(|| format!("{name}: cannot read the header"))?,
        None => bail!("{name}: empty file, expected a header with a column `y`"),
    };
    let column = header
        .split(',')
        .position(|field| field.trim() == "y")
        .with_context(|| no_column(&header))?;
    Ok(lines.enumerate().filter_map(move |(index, line)| {
        let line_number = index + 2;
        let line = match line.with_context(|| format!("{name}: line {line_number}: cannot read")) {
            Ok(line) => line,
            Err(e) => return Some(Err(e)),
        };
        if line.trim().is_empty() {
            return None;
        }
        let field = line.split(',').nth(column).map(str::trim).unwrap_or("");
        Some(Ok((line_number, field.to_string())))
    }))
}
