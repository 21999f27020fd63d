//! Instructions per estimator update on the Cortex-M4F, for orders n = 2..12 in `f32`.
//!
//! Run under `qemu-system-arm -icount shift=0` (see `cargo xtask bench`): virtual time then
//! advances one nanosecond per guest instruction, and SysTick, clocked from virtual time,
//! counts instructions. The ticks-to-instructions factor is not assumed but calibrated
//! against [`on_target::known_loop`], whose instruction count is known exactly; the
//! difference of two loop lengths cancels the call overhead.
//!
//! Output lines (parsed by the xtask):
//! - `calibration <extra_instructions> <ticks_short> <ticks_long>`
//! - `update <n> <updates> <ticks_updates> <ticks_baseline> <size_of_bytes>`
//! - `end`
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use estimator_core::{Estimator, StepConfig, StepEstimator};
use on_target::cases::GAIN_PER_G;
use on_target::{exit, println, Ticks};

static RESPONSE: &[u8] = include_bytes!("../../data/step_response.f32le");

/// Samples pushed before timing starts, so that every timed push is a full update.
const UNTIMED_SAMPLES: usize = 200;

fn sample(index: usize) -> f32 {
    let at = 4 * index;
    f32::from_le_bytes([
        RESPONSE[at],
        RESPONSE[at + 1],
        RESPONSE[at + 2],
        RESPONSE[at + 3],
    ])
}

/// The loop around `push` without the estimator: the overhead subtracted from the timing.
#[inline(never)]
fn baseline(range: core::ops::Range<usize>) -> f32 {
    let mut sink = 0.0;
    for index in range {
        sink = black_box(sample(index));
    }
    sink
}

#[inline(never)]
fn timed_pushes<const N: usize>(
    estimator: &mut StepEstimator<f32, N>,
    range: core::ops::Range<usize>,
) -> f32 {
    let mut sink = 0.0;
    for index in range {
        let reading = estimator.push(sample(index));
        sink = black_box(reading.estimate.unwrap_or(0.0));
    }
    sink
}

fn bench_order<const N: usize>(ticks: &Ticks) {
    let config = StepConfig::new(N, GAIN_PER_G);
    let mut estimator = match StepEstimator::<f32, N>::new(config) {
        Ok(estimator) => estimator,
        Err(error) => {
            println!("order {N} refused: {error}");
            exit(false)
        }
    };
    for index in 0..UNTIMED_SAMPLES {
        black_box(estimator.push(sample(index)));
    }
    let timed = UNTIMED_SAMPLES..RESPONSE.len() / 4;
    let updates = timed.len();
    let (ticks_updates, last) = ticks.measure(|| timed_pushes(&mut estimator, timed.clone()));
    let (ticks_baseline, _) = ticks.measure(|| baseline(timed.clone()));
    // Every timed push must have been a real, valid update, or the count means nothing.
    if last == 0.0 || estimator.push(sample(0)).estimate.is_none() {
        println!("order {N}: the timed pushes did not all estimate");
        exit(false)
    }
    println!(
        "update {N} {updates} {ticks_updates} {ticks_baseline} {}",
        core::mem::size_of::<StepEstimator<f32, N>>()
    );
}

/// Calibration loop lengths: the long loop runs `2 · CALIBRATION_ITERATIONS` more
/// instructions than the short one.
const CALIBRATION_ITERATIONS: u32 = 500_000;

#[entry]
fn main() -> ! {
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        println!("peripherals already taken");
        exit(false)
    };
    let ticks = Ticks::start(peripherals.SYST);

    let (short, ()) = ticks.measure(|| on_target::known_loop(CALIBRATION_ITERATIONS));
    let (long, ()) = ticks.measure(|| on_target::known_loop(2 * CALIBRATION_ITERATIONS));
    println!("calibration {} {short} {long}", 2 * CALIBRATION_ITERATIONS);

    bench_order::<2>(&ticks);
    bench_order::<3>(&ticks);
    bench_order::<4>(&ticks);
    bench_order::<5>(&ticks);
    bench_order::<6>(&ticks);
    bench_order::<7>(&ticks);
    bench_order::<8>(&ticks);
    bench_order::<9>(&ticks);
    bench_order::<10>(&ticks);
    bench_order::<11>(&ticks);
    bench_order::<12>(&ticks);
    println!("end");
    exit(true)
}
