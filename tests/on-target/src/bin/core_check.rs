//! Runs `StepEstimator<f32, 12>` on the stored step response for every configuration in
//! `cases.rs` and prints every reading, with floats as IEEE-754 bit patterns, so that the
//! host test `tests/tests/on_target_core_check.rs` can compare them with the host `f32` run.
//!
//! Output lines (parsed by `tests::core_check`):
//! - `begin <cases> <samples>`
//! - `r <case> <sample> <state> <estimate|-> <residual|->` for every reading, where state is
//!   `W` (warming up), `E` (estimating) or `I<reason>`, and floats are `%08x` bit patterns;
//! - `end`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use estimator_core::{Estimator, Reading, State, StepConfig, StepEstimator};
use on_target::cases::{CAPACITY, CASES, GAIN_PER_G};
use on_target::{exit, println};

/// The stored response, `f32` little-endian (see `cases::RESPONSE_FILE`).
static RESPONSE: &[u8] = include_bytes!("../../data/step_response.f32le");

fn state_code(state: State) -> (char, u8) {
    match state {
        State::WarmingUp => ('W', 0),
        State::Estimating => ('E', 0),
        State::Invalid(reason) => ('I', reason as u8),
    }
}

fn report(case: usize, sample: usize, reading: &Reading<f32>) {
    let (state, reason) = state_code(reading.state);
    let mut line = on_target::Line::new();
    let _ = core::fmt::Write::write_fmt(
        &mut line,
        format_args!("r {case} {sample} {state}{reason} "),
    );
    let _ = match reading.estimate {
        Some(value) => {
            core::fmt::Write::write_fmt(&mut line, format_args!("{:08x} ", value.to_bits()))
        }
        None => core::fmt::Write::write_str(&mut line, "- "),
    };
    let _ = match reading.residual {
        Some(value) => {
            core::fmt::Write::write_fmt(&mut line, format_args!("{:08x}", value.to_bits()))
        }
        None => core::fmt::Write::write_str(&mut line, "-"),
    };
    line.send();
}

#[entry]
fn main() -> ! {
    let samples = RESPONSE.len() / 4;
    println!("begin {} {}", CASES.len(), samples);
    for (index, case) in CASES.iter().enumerate() {
        let config = StepConfig::new(case.order, GAIN_PER_G)
            .with_decimation(case.decimation)
            .with_forgetting(case.forgetting);
        let mut estimator = match StepEstimator::<f32, CAPACITY>::new(config) {
            Ok(estimator) => estimator,
            Err(error) => {
                println!("config {index} refused: {error}");
                exit(false)
            }
        };
        for (sample, bytes) in RESPONSE.chunks_exact(4).enumerate() {
            let raw = f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
            let reading = estimator.push(raw);
            report(index, sample, &reading);
        }
    }
    println!("end");
    exit(true)
}
