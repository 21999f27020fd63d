//! The bare-metal half: semihosting output and exit, the panic and HardFault handlers, and
//! SysTick timing. Compiled for the target only.

use core::fmt::{self, Write};
use core::panic::PanicInfo;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::{exception, ExceptionFrame};
use cortex_m_semihosting::debug;

/// Write a string to the host's stdout through semihosting, in one host call.
pub fn print_str(text: &str) {
    // `hprint!` keeps the host stream open; a single `{}` of a `str` is one write call.
    cortex_m_semihosting::hprint!("{}", text);
}

/// A line formatted on the stack so that it reaches the host in a single semihosting call.
pub struct Line {
    buffer: [u8; 160],
    len: usize,
}

impl Line {
    /// An empty line.
    pub const fn new() -> Self {
        Self {
            buffer: [0; 160],
            len: 0,
        }
    }

    /// Append the newline and send the line to the host.
    pub fn send(mut self) {
        let _ = self.write_str("\n");
        // Only whole `&str`s are ever copied in, so the bytes are valid UTF-8.
        if let Ok(text) = core::str::from_utf8(&self.buffer[..self.len]) {
            print_str(text);
        }
    }
}

impl Default for Line {
    fn default() -> Self {
        Self::new()
    }
}

impl Write for Line {
    fn write_str(&mut self, text: &str) -> fmt::Result {
        let bytes = text.as_bytes();
        let end = self.len + bytes.len();
        if end > self.buffer.len() {
            return Err(fmt::Error);
        }
        self.buffer[self.len..end].copy_from_slice(bytes);
        self.len = end;
        Ok(())
    }
}

/// Format and send one line to the host.
#[macro_export]
macro_rules! println {
    ($($arg:tt)*) => {{
        let mut line = $crate::Line::new();
        let _ = ::core::fmt::Write::write_fmt(&mut line, format_args!($($arg)*));
        line.send();
    }};
}

/// End the QEMU session: exit status 0 on success, 1 on failure.
pub fn exit(success: bool) -> ! {
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Only reached when no debugger/QEMU listens to semihosting.
    loop {
        cortex_m::asm::bkpt();
    }
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    println!("PANIC: {}", info);
    exit(false)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    println!("HARDFAULT at pc={:#010x}", frame.pc());
    exit(false)
}

/// SysTick reload: the full 24-bit range, so one measurement may last up to 2^24 ticks.
const SYSTICK_RELOAD: u32 = 0x00ff_ffff;

/// Free-running SysTick on the processor clock, counting down from [`SYSTICK_RELOAD`].
pub struct Ticks {
    syst: SYST,
}

impl Ticks {
    /// Start SysTick free-running without interrupts.
    pub fn start(mut syst: SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(SYSTICK_RELOAD);
        syst.clear_current();
        syst.enable_counter();
        Self { syst }
    }

    /// The current counter value (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        // Reading through `SYST` (owned by `self`) keeps the counter's configuration ours.
        let _ = &self.syst;
        SYST::get_current()
    }

    /// Ticks elapsed from `start` to `end`, for an interval shorter than one wrap.
    #[inline(always)]
    pub fn elapsed(start: u32, end: u32) -> u32 {
        start.wrapping_sub(end) & SYSTICK_RELOAD
    }

    /// Ticks spent in `work`, which must take fewer than 2^24 ticks.
    #[inline(never)]
    pub fn measure<R>(&self, work: impl FnOnce() -> R) -> (u32, R) {
        let start = self.now();
        let result = work();
        let end = self.now();
        (Self::elapsed(start, end), result)
    }
}

/// Execute exactly `2 · iterations` instructions (`subs` + `bne` per iteration; the final
/// not-taken `bne` counts like the others): the calibration loop of known length.
#[inline(never)]
pub fn known_loop(iterations: u32) {
    if iterations == 0 {
        return;
    }
    // Safety: a register-only countdown loop; it touches no memory and no flags outside
    // the asm block (flags are declared clobbered by default).
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
