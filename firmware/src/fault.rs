//! Faults on both boards: a stack guard, and one handler for every fault that works even
//! when the stack is gone.
//!
//! flip-link puts the stack at the bottom of RAM, so an overflow runs off the RAM's start
//! instead of into `.data`/`.bss`. What it hits there differs by board (reserved addresses
//! on the STM32F411, nothing on QEMU's AN386), so [`guard_stack`] also makes the lowest
//! [`STACK_GUARD_BYTES`] of the stack inaccessible with the MPU: the first push into them is
//! a MemManage fault on either board.
//!
//! The fault handlers are the hard part: the processor stacks its exception frame below the
//! faulting stack pointer, which after an overflow is inside the guard, so that stacking
//! fails too. With MemManage, BusFault and UsageFault enabled (they are off after reset,
//! and a fault with its handler off escalates to HardFault, where a failed stacking locks
//! the core up), the failed stacking escalates to HardFault, which is entered with the stack
//! pointer still in the guard. Every handler is therefore the same few instructions of
//! assembly ([`fault_entry`]): note the faulting stack pointer, move the stack pointer back
//! to the top of the stack (nothing that ran is ever returned to), and only then call Rust,
//! which says what happened and ends the run ([`crate::board_fault_exit`]): a failing exit
//! on QEMU, a halt on the STM32 (probe-rs reports it; without a probe the watchdog resets
//! the chip).
//!
//! What it cannot catch: a fault while faults are masked (`init`, a `critical_section`)
//! escalates straight to HardFault, and a failed stacking there locks the core up (QEMU
//! aborts with a failing status, the STM32's watchdog resets it).
#![allow(unsafe_code)]

use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m::peripheral::scb::Exception;
use cortex_m::peripheral::{MPU, SCB};

/// Bytes at the bottom of the stack no code may touch (an MPU region: a power of two of at
/// least 32, aligned to its size). Larger than the deepest exception frame (104 bytes with
/// the FPU's context), so the push that enters it faults before the frame below it can
/// land anywhere else.
pub const STACK_GUARD_BYTES: u32 = 256;

extern "C" {
    // From the linker script (cortex-m-rt's `link.x`, moved by flip-link): the stack grows
    // down from `_stack_start` to `_stack_end`.
    static _stack_start: u32;
    static _stack_end: u32;
}

/// The stack's bounds, as addresses: (lowest, highest). The guard is the lowest
/// [`STACK_GUARD_BYTES`] from the first aligned address on.
pub fn stack_bounds() -> (u32, u32) {
    // Only the addresses of the linker's symbols are taken (safe since Rust 1.82), nothing
    // is read.
    (
        core::ptr::addr_of!(_stack_end) as u32,
        core::ptr::addr_of!(_stack_start) as u32,
    )
}

/// The guard's address range (start inclusive, end exclusive).
pub fn guard_range() -> (u32, u32) {
    let (lowest, _) = stack_bounds();
    let start = lowest.next_multiple_of(STACK_GUARD_BYTES);
    (start, start + STACK_GUARD_BYTES)
}

/// Enable the configurable fault handlers and make the stack's guard inaccessible (MPU
/// region 0, no access, never executed; the default memory map everywhere else). Call it
/// first thing in `init`.
pub fn guard_stack(mpu: &mut MPU, scb: &mut SCB) {
    const RASR_ENABLE: u32 = 1;
    const RASR_NO_ACCESS_NEVER_EXECUTE: u32 = 1 << 28;
    const CTRL_ENABLE: u32 = 1;
    const CTRL_PRIVILEGED_DEFAULT_MAP: u32 = 1 << 2;
    // RASR.SIZE: the region is 2^(SIZE + 1) bytes.
    let size_field = STACK_GUARD_BYTES.trailing_zeros() - 1;
    let (start, _) = guard_range();
    // Safety: region 0 covers only the guard, which no frame uses (it lies below the
    // deepest stack the firmware is built for, see `cargo xtask bench`); PRIVDEFENA keeps
    // the default map for every other address, so nothing else changes. The barriers make
    // the new map apply to the next instruction.
    unsafe {
        mpu.ctrl.write(0);
        mpu.rnr.write(0);
        mpu.rbar.write(start);
        mpu.rasr
            .write(RASR_NO_ACCESS_NEVER_EXECUTE | (size_field << 1) | RASR_ENABLE);
        mpu.ctrl.write(CTRL_PRIVILEGED_DEFAULT_MAP | CTRL_ENABLE);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
    scb.enable(Exception::MemoryManagement);
    scb.enable(Exception::BusFault);
    scb.enable(Exception::UsageFault);
}

// Every fault vector: r0 = the stack pointer the fault left (the exception frame, when it
// could be stacked), the stack pointer back at the top of the stack, then Rust. A plain
// branch, so nothing is pushed before the stack pointer is good again.
core::arch::global_asm!(
    ".section .text.fault_entry,\"ax\",%progbits",
    ".global HardFault",
    ".global MemoryManagement",
    ".global BusFault",
    ".global UsageFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "mrs r0, msp",
    "ldr r1, =_stack_start",
    "mov sp, r1",
    "b {report}",
    ".ltorg",
    ".size HardFault, . - HardFault",
    ".thumb_set MemoryManagement, HardFault",
    ".thumb_set BusFault, HardFault",
    ".thumb_set UsageFault, HardFault",
    report = sym fault_entry,
);

/// Set once a fault is being reported: a fault while reporting one ends the run at once.
static REPORTING: AtomicBool = AtomicBool::new(false);

/// Configurable Fault Status Register bits.
const CFSR_MSTKERR: u32 = 1 << 4;
const CFSR_MMARVALID: u32 = 1 << 7;
const CFSR_STKERR: u32 = 1 << 12;
const CFSR_BFARVALID: u32 = 1 << 15;

/// What the fault vectors call, on a fresh stack: say what happened, then end the run.
/// `faulting_sp` is the stack pointer the fault left.
///
/// # Safety
/// Only the fault vectors above call it, with the stack pointer reset.
unsafe extern "C" fn fault_entry(faulting_sp: u32) -> ! {
    if REPORTING.swap(true, Ordering::Relaxed) {
        crate::board_fault_exit()
    }
    // Safety: read-only accesses to the System Control Block's fault registers.
    let scb = unsafe { &*SCB::PTR };
    let cfsr = scb.cfsr.read();
    let hfsr = scb.hfsr.read();
    let exception = cortex_m::peripheral::SCB::vect_active();
    let (_, guard_end) = guard_range();
    let (_, top) = stack_bounds();
    if faulting_sp < guard_end || cfsr & (CFSR_MSTKERR | CFSR_STKERR) != 0 {
        defmt::error!(
            "fault: stack overflow (sp={=u32:#010x}, the stack's guard ends at {=u32:#010x}, {=u32} bytes of stack) in {}",
            faulting_sp,
            guard_end,
            top - guard_end,
            defmt::Debug2Format(&exception)
        );
    } else {
        // The frame was stacked: its stacked pc is the faulting instruction (unless the
        // stack pointer itself was wild, then there is no frame to read).
        let pc = if faulting_sp <= top - 32 {
            // Safety: `faulting_sp` is above the guard and within the stack, where the
            // processor has just written the 8-word exception frame.
            unsafe { core::ptr::read_volatile((faulting_sp + 24) as *const u32) }
        } else {
            0
        };
        let address = if cfsr & CFSR_MMARVALID != 0 {
            scb.mmfar.read()
        } else if cfsr & CFSR_BFARVALID != 0 {
            scb.bfar.read()
        } else {
            0
        };
        defmt::error!(
            "fault: {} at pc={=u32:#010x} cfsr={=u32:#010x} hfsr={=u32:#010x} address={=u32:#010x}",
            defmt::Debug2Format(&exception),
            pc,
            cfsr,
            hfsr,
            address
        );
    }
    crate::board_fault_exit()
}

/// The panic handler's work on both boards: say what panicked, then end the run. A panic
/// while a fault or panic is being reported (the logger itself failing, say) ends the run
/// at once instead of recursing.
pub fn report_panic(info: &core::panic::PanicInfo) -> ! {
    if !REPORTING.swap(true, Ordering::Relaxed) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    crate::board_fault_exit()
}
