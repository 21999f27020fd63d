//! The weighing firmware's board support: a thin shell that moves ADC samples to the
//! weighing core in `estimator-core` and its readings to the log.
//!
//! Two boards, chosen by exactly one feature: `qemu` (the `mps2-an386` Cortex-M4F under
//! QEMU, with the host-sim load-cell model as its ADC) and `stm32f411` (an STM32F411 with an
//! INA114 front end on ADC1). The RTIC applications are the binaries `firmware-qemu` and
//! `firmware-stm32f411`; everything numeric lives in `estimator-core`.
//!
//! What it must never do: compute in the sample hand-off, allocate, use `static mut`, loop
//! without a bound in a handler, lose a sample silently, or let a panic or fault look like
//! success (on QEMU both exit with a failing status; on hardware they halt the probe).
#![no_std]

#[cfg(all(feature = "qemu", feature = "stm32f411"))]
compile_error!("features `qemu` and `stm32f411` are mutually exclusive: pick one board");
#[cfg(not(any(feature = "qemu", feature = "stm32f411")))]
compile_error!("pick a board: feature `qemu` (default) or `stm32f411` (--no-default-features)");

pub mod console;
pub mod fault;
pub mod pipeline;

#[cfg(feature = "qemu")]
pub mod mps2_an386;
#[cfg(feature = "qemu")]
pub mod qemu;

#[cfg(feature = "stm32f411")]
pub mod stm32f411;

pub mod bench;

/// End the run after a fault or panic has been reported: a failing exit on QEMU.
#[cfg(feature = "qemu")]
pub fn board_fault_exit() -> ! {
    qemu::exit(false)
}

/// End the run after a fault or panic has been reported: a permanent undefined instruction,
/// so probe-rs sees the fault and exits with an error; without a probe the core locks up
/// and the independent watchdog resets it.
#[cfg(feature = "stm32f411")]
pub fn board_fault_exit() -> ! {
    cortex_m::asm::udf()
}
