//! Executes a permanently undefined instruction on purpose: the host test checks that the
//! resulting HardFault ends QEMU with a failing status.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
// The panic handler and HardFault handler under test.
use on_target as _;

#[entry]
fn main() -> ! {
    // UDF raises a UsageFault, which escalates to HardFault (UsageFault is not enabled).
    cortex_m::asm::udf()
}
