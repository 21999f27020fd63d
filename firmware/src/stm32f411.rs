//! The STM32F411 board: its analogue front end, the KEY button's timing, the reference mass
//! of a calibration, the calibration store in flash sectors 6–7 (the core's power-fail-safe
//! `FlashStore` over the HAL's flash), the serial console's USB port, and what a panic or
//! fault does (halt, so probe-rs reports it and exits non-zero).
//!
//! None of this has run on hardware yet: CI builds it and checks its size, nothing more.

use core::ops::Range;

use embedded_storage::nor_flash::NorFlash as BlockingNorFlash;
use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use estimator_core::weighing::{self, Calibration, CalibrationSource, FlashStore, FrontEnd};
use stm32f4xx_hal::flash::{self, FlashExt, UnlockedFlash};
use stm32f4xx_hal::otg_fs::UsbBusType;
use stm32f4xx_hal::pac::FLASH;

/// The USB serial port (CDC ACM) the console runs on, with its buffers.
pub type UsbSerial =
    usbd_serial::SerialPort<'static, UsbBusType, &'static mut [u8], &'static mut [u8]>;

/// Bytes the USB console buffers on their way to the host: `config show`, the longest
/// answer (about 750 bytes), fits whole.
pub const USB_TX_BUFFER: usize = 1024;
/// Bytes the USB console buffers from the host (more than a line).
pub const USB_RX_BUFFER: usize = 128;

/// The console's serial port on USB: the CDC ACM class, written without waiting.
pub struct UsbConsolePort {
    serial: UsbSerial,
}

impl UsbConsolePort {
    /// The port on `serial`.
    pub fn new(serial: UsbSerial) -> Self {
        Self { serial }
    }

    /// The CDC ACM class, for the USB device's poll.
    pub fn class(&mut self) -> &mut UsbSerial {
        &mut self.serial
    }

    /// Bytes received from the host into `buffer` (0 when none are waiting).
    pub fn read(&mut self, buffer: &mut [u8]) -> usize {
        self.serial.read(buffer).unwrap_or(0)
    }
}

impl crate::console::SerialPort for UsbConsolePort {
    /// Buffered for the host; while no terminal has the port open (DTR low) the bytes are
    /// dropped on purpose (and not counted lost), so opening it later shows fresh lines
    /// rather than a buffer of old ones.
    fn write_bytes(&mut self, bytes: &[u8]) -> usize {
        if !self.serial.dtr() {
            return bytes.len();
        }
        self.serial.write(bytes).unwrap_or(0)
    }
}

#[cfg(feature = "ads131m02")]
pub mod ads131m02;

/// The ADS131M02's hand-off (DRDY → one frame → the queue). In the internal-ADC build a type
/// without values: RTIC declares every resource's type in both builds, cfg or not.
#[cfg(feature = "ads131m02")]
pub use ads131m02::DrdyHandoff;
/// See the `ads131m02` build's `DrdyHandoff`.
#[cfg(not(feature = "ads131m02"))]
pub type DrdyHandoff = core::convert::Infallible;

/// The INA114 front end as wired in `firmware/README.md` (`FrontEnd::STM32F411_INA114`).
#[cfg(not(feature = "ads131m02"))]
pub const FRONT_END: FrontEnd = FrontEnd::STM32F411_INA114;

/// The ADS131M02 chain (`ads131m02` build, `FrontEnd::ADS131M02`): the same cell into the
/// converter's PGA at gain 128, read as offset binary.
#[cfg(feature = "ads131m02")]
pub const FRONT_END: FrontEnd = FrontEnd::ADS131M02;

/// The reference mass a long press calibrates with: a 200 g class M1 weight (±10 mg, far
/// inside the 0.1 % the scale is judged by). Edit it for another weight.
pub const REFERENCE_MASS_G: f32 = 200.0;

/// The KEY button is polled at this rate while it is active (after its EXTI0 edge).
pub const KEY_POLL_HZ: u32 = 100;
/// The button's level must hold this long to count (contact bounce is a few ms).
pub const KEY_DEBOUNCE_MS: u32 = 30;
/// A press held this long or longer is a long press (calibrate); shorter is a tare.
pub const KEY_LONG_PRESS_MS: u32 = 2_000;

/// Core clock: `init` freezes the clocks at this (the DWT cycle counter counts it).
pub const SYSCLK_HZ: u32 = 84_000_000;

/// The flash reserved for the calibration store (see `memory.x`): sectors 6 and 7, two
/// 128 KiB erase pages, as offsets from the start of flash (`0x0804_0000..0x0808_0000`).
pub const CALIBRATION_FLASH: Range<u32> = 0x4_0000..0x8_0000;

/// Codes at each rail of ADC1 its front end cannot reach (`AdcSource::rail_guard_codes`):
/// a code within 40 codes (32 mV) of 0 or 4095 reads saturated. The INA114 does not swing
/// to its supply rails; with REF at 0.5 V and 600 g spanning 2.55 V its output for every
/// load up to Max lies at codes 620–3784, far inside the band, so the band only catches
/// an output clipped at a rail (or short of it by up to 32 mV). A placeholder until the
/// board's own clip levels are measured: a larger measured margin goes here.
pub const ADC_RAIL_GUARD_CODES: u32 = 40;

/// Samples per DMA buffer: the DMA fills one buffer while the hand-off drains the other.
pub const DMA_BLOCK: usize = 8;

/// Why the flash refused an operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// The chip's flash (its size register) does not reach the store's sectors: not an
    /// STM32F411CE.
    NoRecordSectors,
    /// The flash controller's error flags, as the HAL reports them.
    ProgrammingSequence,
    /// See [`FlashError::ProgrammingSequence`].
    ProgrammingParallelism,
    /// See [`FlashError::ProgrammingSequence`].
    ProgrammingAlignment,
    /// The sector is write protected (option bytes).
    WriteProtection,
    /// See [`FlashError::ProgrammingSequence`].
    Operation,
}

impl From<flash::Error> for FlashError {
    fn from(error: flash::Error) -> Self {
        match error {
            flash::Error::ProgrammingSequence => Self::ProgrammingSequence,
            flash::Error::ProgrammingParallelism => Self::ProgrammingParallelism,
            flash::Error::ProgrammingAlignment => Self::ProgrammingAlignment,
            flash::Error::WriteProtection => Self::WriteProtection,
            flash::Error::Operation => Self::Operation,
        }
    }
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::NoRecordSectors => NorFlashErrorKind::OutOfBounds,
            Self::ProgrammingAlignment => NorFlashErrorKind::NotAligned,
            _ => NorFlashErrorKind::Other,
        }
    }
}

// The store's range is whole erase pages, at least two (what `FlashStore::new` checks at
// run time), so `calibration_store` cannot fail.
const _: () = {
    let page = <Stm32Flash as NorFlash>::ERASE_SIZE as u32;
    assert!(
        CALIBRATION_FLASH.start.is_multiple_of(page)
            && CALIBRATION_FLASH.end.is_multiple_of(page)
            && CALIBRATION_FLASH.end - CALIBRATION_FLASH.start >= 2 * page,
        "CALIBRATION_FLASH must be two or more whole 128 KiB sectors"
    );
};

/// The calibration store of the board: the record in sectors 6–7, power-fail safe.
pub type CalibrationFlashStore = FlashStore<Stm32Flash>;

/// The calibration store over the flash controller (the only user of `FLASH` after the
/// clocks are set up).
pub fn calibration_store(flash: FLASH) -> CalibrationFlashStore {
    match FlashStore::new(Stm32Flash { flash }, CALIBRATION_FLASH) {
        Ok(store) => store,
        // Unreachable: the range is checked at compile time above.
        Err(error) => defmt::panic!("calibration flash range refused: {}", error),
    }
}

/// The calibration to use at boot: the flash record if valid and within the front end's
/// limits, else the front end's nominal values with the reason (erased flash reads
/// `Missing`).
pub fn load_calibration(store: &mut CalibrationFlashStore) -> (Calibration, CalibrationSource) {
    weighing::load_calibration(store, &FRONT_END.calibration_limits())
}

/// The STM32F411's flash as the store's `NorFlash`, through the HAL's (`UnlockedFlash`,
/// whose `ERASE_SIZE` is the 128 KiB of sectors 5–7): unlocked for each erase or write
/// only, error flags of an earlier operation cleared first, the ART data cache flushed
/// after. Blocking (the CPU stalls on flash fetches while the controller is busy), so each
/// future is ready when polled, as `FlashStore` requires.
///
/// A calibration programs about 30 bytes (a few hundred µs); a sector is erased only when
/// the two sectors fill up, once in about 4,500 calibrations (the core's power-cut tests
/// measure it on this geometry). That erase takes 2–4 s at the HAL's 8-bit parallelism,
/// and the samples the converter takes meanwhile are counted as dropped.
pub struct Stm32Flash {
    flash: FLASH,
}

impl Stm32Flash {
    /// Offsets must lie inside the chip's flash (an STM32F411CC has only 256 KiB).
    fn check(&self, end: u32) -> Result<(), FlashError> {
        if end as usize <= self.flash.len() {
            Ok(())
        } else {
            Err(FlashError::NoRecordSectors)
        }
    }

    /// Run one erase or program with the flash unlocked, its stale error flags (W1C)
    /// cleared before and the data cache flushed after.
    fn unlocked<T>(
        &mut self,
        operation: impl FnOnce(&mut UnlockedFlash<'_>) -> Result<T, flash::Error>,
    ) -> Result<T, FlashError> {
        self.flash.sr().write(|w| {
            w.operr().clear();
            w.wrperr().clear();
            w.pgaerr().clear();
            w.pgperr().clear();
            w.pgserr().clear()
        });
        let result = {
            // Locked again when dropped at the end of this block.
            let mut unlocked = self.flash.unlocked();
            operation(&mut unlocked)
        };
        self.reset_data_cache();
        result.map_err(FlashError::from)
    }

    /// Flush the ART data cache, which may still hold a sector as it was before an erase
    /// or a write (RM0383, "Flash memory": reset it with the cache disabled).
    fn reset_data_cache(&mut self) {
        let acr = self.flash.acr();
        let enabled = acr.read().dcen().bit_is_set();
        acr.modify(|_, w| w.dcen().clear_bit());
        acr.modify(|_, w| w.dcrst().set_bit());
        acr.modify(|_, w| w.dcrst().clear_bit());
        if enabled {
            acr.modify(|_, w| w.dcen().set_bit());
        }
    }
}

impl ErrorType for Stm32Flash {
    type Error = FlashError;
}

impl ReadNorFlash for Stm32Flash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let end = offset.saturating_add(bytes.len() as u32);
        self.check(end)?;
        let stored = self
            .flash
            .read()
            .get(offset as usize..end as usize)
            .ok_or(FlashError::NoRecordSectors)?;
        bytes.copy_from_slice(stored);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.flash.len()
    }
}

impl NorFlash for Stm32Flash {
    const WRITE_SIZE: usize = <UnlockedFlash<'static> as BlockingNorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <UnlockedFlash<'static> as BlockingNorFlash>::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        self.check(to)?;
        self.unlocked(|flash| BlockingNorFlash::erase(flash, from, to))
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.check(offset.saturating_add(bytes.len() as u32))?;
        self.unlocked(|flash| BlockingNorFlash::write(flash, offset, bytes))
    }
}

/// The independent watchdog's timeout, nominal (the HAL assumes a 32 kHz LSI; the
/// STM32F411's LSI runs at 17 to 47 kHz, so the real timeout is 6.8 to 18.8 s): above the
/// longest legitimate stall, a calibration store's sector erase (128 KiB: up to 4 s at
/// 8-bit parallelism, the CPU stalled on flash meanwhile).
pub const WATCHDOG_TIMEOUT_MS: u32 = 10_000;

impl crate::pipeline::Watchdog for stm32f4xx_hal::watchdog::IndependentWatchdog {
    fn feed(&mut self) {
        stm32f4xx_hal::watchdog::IndependentWatchdog::feed(self)
    }
}

/// Say at boot when the last reset was the watchdog's (a stall or a fault without a probe
/// attached), then clear the reset flags so the next boot tells its own cause.
pub fn log_reset_cause() {
    // Safety: RCC_CSR's reset flags are read and cleared once, in `init`, before the HAL
    // takes the RCC; no other code touches this register.
    let rcc = unsafe { &*stm32f4xx_hal::pac::RCC::ptr() };
    if rcc.csr().read().wdgrstf().bit_is_set() {
        defmt::error!(
            "reset by the independent watchdog: samples had stopped, or a fault locked the core up"
        );
    }
    rcc.csr().modify(|_, w| w.rmvf().set_bit());
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    crate::fault::report_panic(info)
}
