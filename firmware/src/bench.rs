//! Instruction counting for `cargo xtask bench`: SysTick free-running on the core clock.
//! Under `qemu-system-arm -icount shift=0` one guest instruction is one nanosecond of
//! virtual time, so SysTick counts instructions (in ticks of a fixed ratio); the ratio is
//! calibrated at boot against a loop of exactly known length, not assumed.

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

const RELOAD: u32 = 0x00ff_ffff;

/// Start SysTick free-running, without its interrupt.
pub fn start(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_counter();
}

/// The counter now (it counts down).
#[inline(always)]
pub fn now() -> u32 {
    SYST::get_current()
}

/// Ticks from `start` to now, for intervals shorter than one wrap (2^24 ticks).
#[inline(always)]
pub fn since(start: u32) -> u32 {
    start.wrapping_sub(now()) & RELOAD
}

/// Accumulated ticks over a number of events.
#[derive(Clone, Copy, Debug, Default)]
pub struct Totals {
    /// Sum of ticks.
    pub ticks: u64,
    /// Events summed.
    pub events: u32,
}

impl Totals {
    /// Add one event of `ticks`.
    #[inline(always)]
    pub fn add(&mut self, ticks: u32) {
        self.ticks += ticks as u64;
        self.events += 1;
    }
}

/// Execute exactly `2 · iterations` instructions (`subs` + `bne` per iteration).
#[inline(never)]
pub fn known_loop(iterations: u32) {
    if iterations == 0 {
        return;
    }
    // Safety: a register-only countdown loop; it touches no memory.
    unsafe {
        core::arch::asm!(
            "1:",
            "subs {0}, {0}, #1",
            "bne 1b",
            inout(reg) iterations => _,
            options(nomem, nostack),
        );
    }
}

/// Ticks of two loops of known length: their difference is `2 · iterations` instructions.
pub fn calibrate(iterations: u32) -> (u32, u32) {
    let start = now();
    known_loop(iterations);
    let short = since(start);
    let start = now();
    known_loop(2 * iterations);
    let long = since(start);
    (short, long)
}
