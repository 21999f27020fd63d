//! A minimal hand-written device module for QEMU's `mps2-an386` (ARM MPS2 with the AN386
//! Cortex-M4F image), in the shape RTIC expects: an `Interrupt` enum, `NVIC_PRIO_BITS`,
//! and the interrupt vector table. Only what the firmware uses is here: the CMSDK timers
//! the receive side of CMSDK UART 0 (the operator's command console) and the watchdog.
//!
//! Interrupt numbers and addresses follow QEMU's `hw/arm/mps2.c` (and ARM's AN385/AN386
//! application notes): CMSDK APB timer 0 at `0x4000_0000` on IRQ 8, timer 1 at
//! `0x4000_1000` on IRQ 9, UART 0 at `0x4000_4000` with its receive interrupt on IRQ 0
//! (QEMU connects it to the first `-serial` device); the system clock is 25 MHz.
#![allow(unsafe_code)]

/// The system (and APB timer) clock of the board in QEMU.
pub const SYSTEM_CLOCK_HZ: u32 = 25_000_000;

/// Priority bits RTIC may use. QEMU's NVIC implements at least 3, like the FPGA board.
pub const NVIC_PRIO_BITS: u8 = 3;

/// External interrupts 0..=23 of the AN386 image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
#[allow(missing_docs)]
pub enum Interrupt {
    Uart0Rx = 0,
    Uart0Tx = 1,
    Uart1Rx = 2,
    Uart1Tx = 3,
    Uart2Rx = 4,
    Uart2Tx = 5,
    Gpio0Combined = 6,
    Gpio1Combined = 7,
    Timer0 = 8,
    Timer1 = 9,
    DualTimer = 10,
    Spi01 = 11,
    Uart012Overflow = 12,
    Ethernet = 13,
    AudioI2S = 14,
    TouchScreen = 15,
    Gpio2Combined = 16,
    Gpio3Combined = 17,
    Uart3Rx = 18,
    Uart3Tx = 19,
    Uart4Rx = 20,
    Uart4Tx = 21,
    Spi2 = 22,
    Spi34 = 23,
}

/// RTIC looks the enum up under this name too.
pub use Interrupt as interrupt;

// Safety: every variant is a distinct external interrupt number the AN386 NVIC implements.
unsafe impl cortex_m::interrupt::InterruptNumber for Interrupt {
    #[inline]
    fn number(self) -> u16 {
        self as u16
    }
}

extern "C" {
    fn Uart0Rx();
    fn Uart0Tx();
    fn Uart1Rx();
    fn Uart1Tx();
    fn Uart2Rx();
    fn Uart2Tx();
    fn Gpio0Combined();
    fn Gpio1Combined();
    fn Timer0();
    fn Timer1();
    fn DualTimer();
    fn Spi01();
    fn Uart012Overflow();
    fn Ethernet();
    fn AudioI2S();
    fn TouchScreen();
    fn Gpio2Combined();
    fn Gpio3Combined();
    fn Uart3Rx();
    fn Uart3Tx();
    fn Uart4Rx();
    fn Uart4Tx();
    fn Spi2();
    fn Spi34();
}

/// One entry of the vector table.
#[doc(hidden)]
#[derive(Clone, Copy)]
pub struct Vector {
    _handler: unsafe extern "C" fn(),
}

/// The external interrupt vectors, placed after cortex-m-rt's exception vectors. Handlers
/// the firmware does not define fall back to `DefaultHandler` through `device.x`.
#[doc(hidden)]
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
#[used]
pub static __INTERRUPTS: [Vector; 24] = [
    Vector { _handler: Uart0Rx },
    Vector { _handler: Uart0Tx },
    Vector { _handler: Uart1Rx },
    Vector { _handler: Uart1Tx },
    Vector { _handler: Uart2Rx },
    Vector { _handler: Uart2Tx },
    Vector {
        _handler: Gpio0Combined,
    },
    Vector {
        _handler: Gpio1Combined,
    },
    Vector { _handler: Timer0 },
    Vector { _handler: Timer1 },
    Vector {
        _handler: DualTimer,
    },
    Vector { _handler: Spi01 },
    Vector {
        _handler: Uart012Overflow,
    },
    Vector { _handler: Ethernet },
    Vector { _handler: AudioI2S },
    Vector {
        _handler: TouchScreen,
    },
    Vector {
        _handler: Gpio2Combined,
    },
    Vector {
        _handler: Gpio3Combined,
    },
    Vector { _handler: Uart3Rx },
    Vector { _handler: Uart3Tx },
    Vector { _handler: Uart4Rx },
    Vector { _handler: Uart4Tx },
    Vector { _handler: Spi2 },
    Vector { _handler: Spi34 },
];

/// Base address of CMSDK APB timer 0.
pub const TIMER0_BASE: usize = 0x4000_0000;
/// Base address of CMSDK APB timer 1.
pub const TIMER1_BASE: usize = 0x4000_1000;

/// The 32-bit registers of one CMSDK APB peripheral, owned by the driver that holds this
/// value: the one place their volatile accesses are written.
struct Registers {
    base: usize,
}

impl Registers {
    #[inline(always)]
    fn read(&self, offset: usize) -> u32 {
        // Safety: `base + offset` is a register of the peripheral this value's driver owns
        // (one driver per peripheral, see the constructors' contracts); device memory, so
        // the access is volatile and aligned.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    #[inline(always)]
    fn write(&mut self, offset: usize, value: u32) {
        // Safety: as in `read`; the driver holding this value is the peripheral's only owner.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, value) }
    }
}

/// A CMSDK APB timer: a 32-bit down-counter that reloads and raises its interrupt at zero.
pub struct CmsdkTimer {
    registers: Registers,
}

impl CmsdkTimer {
    const CTRL: usize = 0x00;
    const RELOAD: usize = 0x08;
    const INTCLEAR: usize = 0x0C;
    const CTRL_ENABLE: u32 = 1 << 0;
    const CTRL_INTERRUPT_ENABLE: u32 = 1 << 3;

    /// Take timer 0. Only one owner may exist: RTIC's `init` creates it once and moves it
    /// into the hand-off task.
    ///
    /// # Safety
    /// The caller must create at most one `CmsdkTimer` per timer.
    pub unsafe fn timer0() -> Self {
        Self::at(TIMER0_BASE)
    }

    /// Take timer 1 (same contract as [`CmsdkTimer::timer0`]).
    ///
    /// # Safety
    /// The caller must create at most one `CmsdkTimer` per timer.
    pub unsafe fn timer1() -> Self {
        Self::at(TIMER1_BASE)
    }

    fn at(base: usize) -> Self {
        Self {
            registers: Registers { base },
        }
    }

    fn write(&mut self, offset: usize, value: u32) {
        self.registers.write(offset, value)
    }

    /// Interrupt every `period_ticks` timer clocks, periodically.
    pub fn start_periodic(&mut self, period_ticks: u32) {
        self.write(Self::CTRL, 0);
        self.write(Self::RELOAD, period_ticks.saturating_sub(1));
        // VALUE is loaded from RELOAD when the counter is written; writing it directly
        // makes the first period exact too.
        self.write(0x04, period_ticks.saturating_sub(1));
        self.write(Self::INTCLEAR, 1);
        self.write(Self::CTRL, Self::CTRL_ENABLE | Self::CTRL_INTERRUPT_ENABLE);
    }

    /// Acknowledge the interrupt.
    #[inline(always)]
    pub fn clear_interrupt(&mut self) {
        self.write(Self::INTCLEAR, 1);
    }

    /// Stop counting: no more interrupts (the `stall` scene's broken sample clock).
    pub fn stop(&mut self) {
        self.write(Self::CTRL, 0);
    }
}

/// Base address of the CMSDK APB watchdog (QEMU's `hw/arm/mps2.c`: its interrupt is the
/// NMI).
pub const WATCHDOG_BASE: usize = 0x4000_8000;

/// The CMSDK APB watchdog (ARM DDI 0479, "APB watchdog"): a 32-bit down-counter on the
/// system clock. At zero it raises its interrupt (the NMI on this board) and reloads; at
/// zero again with the interrupt still raised it resets the system. Feeding it clears the
/// interrupt and reloads the counter. Its registers are locked against stray writes except
/// while this driver changes them.
pub struct CmsdkWatchdog {
    registers: Registers,
}

impl CmsdkWatchdog {
    const LOAD: usize = 0x000;
    const CONTROL: usize = 0x008;
    const INTCLR: usize = 0x00C;
    const LOCK: usize = 0xC00;
    const UNLOCK_KEY: u32 = 0x1ACC_E551;
    const CONTROL_INTERRUPT_ENABLE: u32 = 1 << 0;
    const CONTROL_RESET_ENABLE: u32 = 1 << 1;

    /// Take the watchdog. Only one owner may exist: RTIC's `init` creates it once and
    /// moves it into the task that feeds it.
    ///
    /// # Safety
    /// The caller must create at most one `CmsdkWatchdog`.
    pub unsafe fn take() -> Self {
        Self {
            registers: Registers {
                base: WATCHDOG_BASE,
            },
        }
    }

    fn unlocked(&mut self, work: impl FnOnce(&mut Registers)) {
        self.registers.write(Self::LOCK, Self::UNLOCK_KEY);
        work(&mut self.registers);
        // Any other value locks the registers again.
        self.registers.write(Self::LOCK, 0);
    }

    /// Start: the NMI after `timeout_ticks` system clocks without a feed, the reset after
    /// twice that.
    pub fn start(&mut self, timeout_ticks: u32) {
        self.unlocked(|registers| {
            registers.write(Self::LOAD, timeout_ticks.max(1));
            registers.write(Self::INTCLR, 1);
            registers.write(
                Self::CONTROL,
                Self::CONTROL_INTERRUPT_ENABLE | Self::CONTROL_RESET_ENABLE,
            );
        });
    }
}

impl crate::pipeline::Watchdog for CmsdkWatchdog {
    /// The counter starts over from the timeout.
    fn feed(&mut self) {
        self.unlocked(|registers| registers.write(Self::INTCLR, 1));
    }
}

/// Base address of CMSDK APB UART 0.
pub const UART0_BASE: usize = 0x4000_4000;

/// What went wrong on a UART's receive side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum UartError {
    /// A byte arrived before the previous one was read: at least one byte was lost.
    Overrun,
}

/// A CMSDK APB UART (ARM DDI 0479, "APB UART"): a one-byte receive buffer with a full
/// flag, an overrun flag and a receive interrupt; a one-byte transmit buffer with a full
/// flag, written by polling.
pub struct CmsdkUart {
    registers: Registers,
    /// A byte was given up and none has gone out since: the reader is gone or stuck, so
    /// the next bytes are tried only briefly (a terminal that stopped reading must not
    /// hold the readout task, which feeds the watchdog).
    stalled: bool,
}

impl CmsdkUart {
    const DATA: usize = 0x00;
    const STATE: usize = 0x04;
    const CTRL: usize = 0x08;
    /// INTSTATUS on read, INTCLEAR (write 1 to clear) on write.
    const INTCLEAR: usize = 0x0C;
    const BAUDDIV: usize = 0x10;
    const STATE_TX_FULL: u32 = 1 << 0;
    const STATE_RX_FULL: u32 = 1 << 1;
    const STATE_RX_OVERRUN: u32 = 1 << 3;
    const CTRL_TX_ENABLE: u32 = 1 << 0;
    const CTRL_RX_ENABLE: u32 = 1 << 1;
    const CTRL_RX_INTERRUPT_ENABLE: u32 = 1 << 3;
    const INT_RX: u32 = 1 << 1;
    const INT_RX_OVERRUN: u32 = 1 << 3;
    /// The smallest divisor the UART accepts (16 clocks per bit).
    const MIN_BAUDDIV: u32 = 16;

    /// Take UART 0. Only one owner may exist: RTIC's `init` creates it once and moves it
    /// into the command task.
    ///
    /// # Safety
    /// The caller must create at most one `CmsdkUart` per UART.
    pub unsafe fn uart0() -> Self {
        Self {
            registers: Registers { base: UART0_BASE },
            stalled: false,
        }
    }

    fn read(&self, offset: usize) -> u32 {
        self.registers.read(offset)
    }

    fn write(&mut self, offset: usize, value: u32) {
        self.registers.write(offset, value)
    }

    /// Polls of a full transmit buffer before a byte is given up: at 115,200 baud a byte
    /// leaves in 87 µs, 2,200 clocks at 25 MHz. QEMU holds the buffer full while the host
    /// end of the console's socket is full (one skb a byte: a few hundred bytes when the
    /// harness's reader is not scheduled for a while), so this waits for the reader: about
    /// 1.6 M instructions, 60 ms at QEMU's 25 MHz, within the watchdog's second. 10,000
    /// polls lost bytes of a recording's dump on a loaded host.
    const TX_POLLS: u32 = 200_000;
    /// Polls while [`Self::stalled`]: enough for a reader that came back.
    const TX_POLLS_STALLED: u32 = 1_000;

    /// Enable the receiver with its interrupt and the transmitter at `baud`.
    pub fn start(&mut self, baud: u32) {
        self.write(Self::CTRL, 0);
        let divisor = SYSTEM_CLOCK_HZ / baud.max(1);
        self.write(Self::BAUDDIV, divisor.max(Self::MIN_BAUDDIV));
        self.write(Self::STATE, Self::STATE_RX_OVERRUN);
        self.write(Self::INTCLEAR, Self::INT_RX | Self::INT_RX_OVERRUN);
        self.write(
            Self::CTRL,
            Self::CTRL_TX_ENABLE | Self::CTRL_RX_ENABLE | Self::CTRL_RX_INTERRUPT_ENABLE,
        );
    }

    /// Send `bytes`, each once the transmit buffer has room; returns how many went out (a
    /// byte still blocked after [`Self::TX_POLLS`] polls, or [`Self::TX_POLLS_STALLED`]
    /// after one was given up, is given up with the rest).
    pub fn write_bytes(&mut self, bytes: &[u8]) -> usize {
        for (sent, &byte) in bytes.iter().enumerate() {
            let limit = if self.stalled {
                Self::TX_POLLS_STALLED
            } else {
                Self::TX_POLLS
            };
            let mut polls = 0;
            while self.read(Self::STATE) & Self::STATE_TX_FULL != 0 {
                polls += 1;
                if polls >= limit {
                    self.stalled = true;
                    return sent;
                }
            }
            self.write(Self::DATA, u32::from(byte));
            self.stalled = false;
        }
        bytes.len()
    }

    /// The received byte, if there is one. The interrupt is acknowledged before the buffer
    /// is read, so a byte that arrives meanwhile raises it again instead of sitting in the
    /// buffer unannounced (which would also stop QEMU from delivering any further byte).
    /// An overrun is reported once and cleared; the byte then in the buffer is dropped with
    /// the lost one, as a command stream that lost a byte cannot be trusted.
    pub fn take_byte(&mut self) -> Result<Option<u8>, UartError> {
        self.write(Self::INTCLEAR, Self::INT_RX);
        let state = self.read(Self::STATE);
        if state & Self::STATE_RX_OVERRUN != 0 {
            self.write(Self::STATE, Self::STATE_RX_OVERRUN);
            let _ = self.read(Self::DATA);
            return Err(UartError::Overrun);
        }
        if state & Self::STATE_RX_FULL == 0 {
            return Ok(None);
        }
        Ok(Some(self.read(Self::DATA) as u8))
    }
}

impl crate::console::SerialPort for CmsdkUart {
    fn write_bytes(&mut self, bytes: &[u8]) -> usize {
        CmsdkUart::write_bytes(self, bytes)
    }
}
