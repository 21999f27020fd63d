//! `cargo xtask bench`: figures, not assertions.
//!
//! 1. host updates/s for n = 2..12 in `f32` and `f64` (the `host-bench` binary, release);
//! 2. on-target instructions per update for n = 2..12 in `f32`: `bench_core` under
//!    `qemu-system-arm -icount shift=0`, SysTick calibrated against a loop of known length;
//! 3. `size_of::<StepEstimator<f32, n>>()` on the target (and on the host, from `host-bench`);
//! 4. the simulator's Monte Carlo rate (`cargo run --release -p host-sim -- bench`);
//! 5. the firmware's figures (`firmware::bench()`).
//!
//! Parts 4 and 5 belong to other packages; when they fail the bench says so and goes on.

use std::time::Duration;

use ::tests::qemu;
use anyhow::{bail, Context, Result};

use crate::util::{build_on_target, cargo, run_checked};

/// The core's speed goal: instructions per update at n = 7 on the Cortex-M4F (a 4 kHz
/// update must leave the MCU most of its time).
const GOAL_INSTRUCTIONS_AT_N7: f64 = 1_500.0;
/// The core's size goal: bytes of a `StepEstimator<f32, 7>`.
const GOAL_BYTES_AT_N7: usize = 512;

/// One row of `bench_core`'s output.
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrderFigures {
    order: usize,
    updates: u64,
    ticks_updates: u64,
    ticks_baseline: u64,
    size_bytes: usize,
}

/// What `bench_core` printed.
#[derive(Debug, Clone, PartialEq)]
struct TargetFigures {
    /// Instructions added by the longer calibration loop, and the ticks of both loops.
    calibration_instructions: u64,
    ticks_short: u64,
    ticks_long: u64,
    orders: Vec<OrderFigures>,
}

impl TargetFigures {
    /// Instructions per SysTick tick, from the calibration loops.
    fn instructions_per_tick(&self) -> Result<f64> {
        let ticks = self.ticks_long.saturating_sub(self.ticks_short);
        if ticks == 0 {
            bail!(
                "calibration failed: the longer loop took no more ticks ({} vs {})",
                self.ticks_long,
                self.ticks_short
            );
        }
        Ok(self.calibration_instructions as f64 / ticks as f64)
    }
}

fn parse_target_figures(text: &str) -> Result<TargetFigures> {
    let mut calibration = None;
    let mut orders = Vec::new();
    let mut ended = false;
    for line in text.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let number = |field: &str| -> Result<u64> {
            field
                .parse()
                .with_context(|| format!("bad number {field:?} in {line:?}"))
        };
        match fields.as_slice() {
            ["calibration", instructions, short, long] => {
                calibration = Some((number(instructions)?, number(short)?, number(long)?));
            }
            ["update", order, updates, ticks, baseline, size] => orders.push(OrderFigures {
                order: number(order)? as usize,
                updates: number(updates)?,
                ticks_updates: number(ticks)?,
                ticks_baseline: number(baseline)?,
                size_bytes: number(size)? as usize,
            }),
            ["end"] => ended = true,
            _ => {}
        }
    }
    let Some((calibration_instructions, ticks_short, ticks_long)) = calibration else {
        bail!("bench_core printed no calibration line");
    };
    if !ended {
        bail!("bench_core output is incomplete (no `end` line)");
    }
    Ok(TargetFigures {
        calibration_instructions,
        ticks_short,
        ticks_long,
        orders,
    })
}

/// Run `bench_core` under `-icount shift=0` and print its figures.
fn on_target() -> Result<()> {
    let elf = build_on_target("bench_core")?.join("bench_core");
    let run = qemu::run(&elf, &qemu::ICOUNT_ARGS, Duration::from_secs(120))
        .context("start qemu-system-arm")?;
    if !run.success() {
        bail!(
            "bench_core {}; stderr: {}",
            run.describe_end(),
            String::from_utf8_lossy(&run.stderr)
        );
    }
    let figures = parse_target_figures(&run.stdout_text())?;
    let per_tick = figures.instructions_per_tick()?;
    println!("on-target: qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -icount shift=0");
    println!(
        "  calibration: a loop of {} more instructions took {} - {} = {} more SysTick ticks \
         => {:.3} instructions per tick (1 instruction = 1 ns virtual; SysTick at 25 MHz => 40 expected)",
        figures.calibration_instructions,
        figures.ticks_long,
        figures.ticks_short,
        figures.ticks_long.saturating_sub(figures.ticks_short),
        per_tick
    );
    println!("  StepEstimator<f32, n> at order n, D = 1, λ = 1, every timed push a full update;");
    println!(
        "  the loop overhead (read sample, keep result) is measured separately and subtracted."
    );
    println!("   n   updates   instr/update   loop overhead/update   size_of (target) bytes");
    for row in &figures.orders {
        let updates = row.updates.max(1) as f64;
        let per_update =
            (row.ticks_updates.saturating_sub(row.ticks_baseline)) as f64 * per_tick / updates;
        let overhead = row.ticks_baseline as f64 * per_tick / updates;
        println!(
            "  {:>2} {:>9} {:>14.1} {:>22.1} {:>24}",
            row.order, row.updates, per_update, overhead, row.size_bytes
        );
    }
    if let Some(row) = figures.orders.iter().find(|row| row.order == 7) {
        let per_update = (row.ticks_updates.saturating_sub(row.ticks_baseline)) as f64 * per_tick
            / row.updates.max(1) as f64;
        let verdict = |met: bool| if met { "met" } else { "MISSED" };
        println!(
            "  goal n = 7: {per_update:.0} instructions/update vs ≤ {GOAL_INSTRUCTIONS_AT_N7:.0}: {}",
            verdict(per_update <= GOAL_INSTRUCTIONS_AT_N7)
        );
        println!(
            "  goal n = 7: size_of::<StepEstimator<f32, 7>>() = {} B on the target vs ≤ {GOAL_BYTES_AT_N7} B: {}",
            row.size_bytes,
            verdict(row.size_bytes <= GOAL_BYTES_AT_N7)
        );
    } else {
        bail!("bench_core printed no figures for n = 7");
    }
    Ok(())
}

/// `cargo xtask bench`.
pub fn run() -> Result<()> {
    crate::install::ensure_tools()?;
    let mut failures = Vec::new();

    println!("\n==> host: updates/s (cargo run --release -p tests --bin host-bench)");
    if let Err(error) = run_checked(cargo().args([
        "run",
        "--quiet",
        "--release",
        "-p",
        "tests",
        "--bin",
        "host-bench",
    ])) {
        println!("host bench FAILED: {error:#}");
        failures.push("host bench");
    }

    println!("\n==> on-target: instructions per update (bench_core under QEMU)");
    if let Err(error) = on_target() {
        println!("on-target bench FAILED: {error:#}");
        failures.push("on-target bench");
    }

    println!("\n==> simulator: cargo run --release -p host-sim -- bench");
    if let Err(error) = run_checked(cargo().args([
        "run",
        "--quiet",
        "--release",
        "-p",
        "host-sim",
        "--",
        "bench",
    ])) {
        println!("NOTE: simulator bench skipped, it did not run: {error:#}");
    }

    println!("\n==> firmware: firmware::bench()");
    if let Err(error) = crate::firmware::bench() {
        println!("NOTE: firmware bench skipped, it did not run: {error:#}");
    }

    if failures.is_empty() {
        Ok(())
    } else {
        bail!("benches that did not run: {}", failures.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_bench_core_output_and_calibrates() {
        let text = "calibration 1000000 25000 50000\nupdate 7 1000 21225 175 392\nend\n";
        let figures = parse_target_figures(text).expect("complete output parses");
        assert_eq!(figures.orders.len(), 1);
        assert_eq!(figures.orders[0].size_bytes, 392);
        assert!((figures.instructions_per_tick().unwrap() - 40.0).abs() < 1e-12);
    }

    #[test]
    fn refuses_incomplete_output_and_a_failed_calibration() {
        assert!(parse_target_figures("calibration 1000000 25000 50000\n").is_err());
        let flat = parse_target_figures("calibration 1000000 25000 25000\nend\n").unwrap();
        assert!(flat.instructions_per_tick().is_err());
    }
}
