//! Panics on purpose: the host test `on_target_core_check.rs` checks that a panic ends QEMU
//! with a failing status (and the message), so a failing on-target check can never pass.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
// The panic handler and HardFault handler under test.
use on_target as _;

#[entry]
fn main() -> ! {
    let order = core::hint::black_box(13usize);
    panic!("deliberate panic: order {order} exceeds the capacity");
}
