//! Bare-metal support for the on-target checks of `estimator-core` under QEMU
//! (`qemu-system-arm -cpu cortex-m4 -machine mps2-an386`): semihosting output and exit,
//! fault handling, and SysTick timing; and the configurations the checks run ([`cases`]),
//! which the host side (`tests::core_check`) takes from this crate, so the two sides
//! cannot drift apart. On the host only [`cases`] is compiled.
//!
//! It exists so that the very same estimator code the firmware runs is checked on the
//! Cortex-M4F's FPU (bit-exactness against the host, instruction counts). It must never
//! report success after a panic or a fault: both end QEMU with a failing exit status.
#![no_std]

pub mod cases;

#[cfg(target_os = "none")]
mod bare_metal;
#[cfg(target_os = "none")]
pub use bare_metal::*;
