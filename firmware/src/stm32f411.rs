//! The STM32F411 board: its analogue front end, the KEY button's timing, the reference mass
//! of a calibration, the calibration record in flash sector 7, and what a panic or fault
//! does (halt, so probe-rs reports it and exits non-zero).
//!
//! None of this has run on hardware yet: CI builds it and checks its size, nothing more.

use estimator_core::weighing::{self, CalibrationStore};
use estimator_core::weighing::{Calibration, CalibrationSource, FrontEnd, RECORD_LEN};
use stm32f4xx_hal::flash::{self, FlashExt};
use stm32f4xx_hal::pac::FLASH;

/// The INA114 front end as wired in `firmware/README.md`: a 600 g, 2 mV/V cell excited
/// with 3.3 V, R_G = 130 Ω (gain 385.6), REF at 0.5 V, into the 12-bit ADC (3.3 V ref).
pub const FRONT_END: FrontEnd = FrontEnd {
    excitation_v: 3.3,
    rated_output_mv_per_v: 2.0,
    capacity_g: 600.0,
    gain_resistor_ohm: 130.0,
    reference_pin_v: 0.5,
    adc_reference_v: 3.3,
    adc_bits: 12,
};

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

/// Start of the flash sector reserved for the calibration record (see `memory.x`).
pub const CALIBRATION_RECORD_ADDRESS: usize = 0x0806_0000;
/// The sector's number and size in the STM32F411's map (sectors 5–7 are 128 KiB).
const CALIBRATION_SECTOR: u8 = 7;
const CALIBRATION_SECTOR_BYTES: usize = 128 * 1024;

/// Samples per DMA buffer: the DMA fills one buffer while the hand-off drains the other.
pub const DMA_BLOCK: usize = 8;

/// Why the calibration record could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// The chip's flash (its size register) has no sector 7: not an STM32F411CE.
    NoRecordSector,
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

/// The calibration record in flash sector 7, through the HAL's flash API: a write erases
/// the sector and programs the 20 bytes; a read is the memory-mapped bytes.
///
/// Erasing a 128 KiB sector takes 2–4 s at the HAL's 8-bit parallelism (data sheet), and
/// the CPU stalls on every flash fetch meanwhile, interrupts included: the sampling runs on
/// (timer, ADC, DMA) but its hand-off does not, so those samples are lost. The board counts
/// them ([`crate::pipeline::Pipeline::samples_lost`]); this happens only when the operator
/// calibrates.
pub struct FlashCalibrationStore {
    flash: FLASH,
}

impl FlashCalibrationStore {
    /// The store over the flash controller (the only user of `FLASH` after the clocks are
    /// set up).
    pub fn new(flash: FLASH) -> Self {
        Self { flash }
    }

    /// Offset of the record from the start of flash.
    fn offset() -> usize {
        CALIBRATION_RECORD_ADDRESS - 0x0800_0000
    }

    fn has_record_sector(&self) -> bool {
        self.flash.len() >= Self::offset() + CALIBRATION_SECTOR_BYTES
    }

    /// The calibration to use at boot: the flash record if valid, else the front end's
    /// nominal values with the reason (erased flash reads `Missing`).
    pub fn load(&mut self) -> (Calibration, CalibrationSource) {
        weighing::load_calibration(self, &FRONT_END.calibration_limits())
    }

    /// Flush the ART data cache, which may still hold the sector as it was before the
    /// write (RM0383, "Flash memory": reset it with the cache disabled).
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

impl CalibrationStore for FlashCalibrationStore {
    type Error = FlashError;

    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), FlashError> {
        if !self.has_record_sector() {
            return Err(FlashError::NoRecordSector);
        }
        // Error flags left by an earlier operation would fail this one: clear them (W1C).
        self.flash.sr().write(|w| {
            w.operr().clear();
            w.wrperr().clear();
            w.pgaerr().clear();
            w.pgperr().clear();
            w.pgserr().clear()
        });
        let result = {
            // Unlocked until dropped at the end of this block.
            let mut unlocked = self.flash.unlocked();
            unlocked
                .erase(CALIBRATION_SECTOR)
                .and_then(|()| unlocked.program(Self::offset(), record.iter()))
        };
        self.reset_data_cache();
        result.map_err(FlashError::from)
    }

    fn read_record(&mut self) -> Result<Option<[u8; RECORD_LEN]>, FlashError> {
        if !self.has_record_sector() {
            return Err(FlashError::NoRecordSector);
        }
        let offset = Self::offset();
        let Some(bytes) = self.flash.read().get(offset..offset + RECORD_LEN) else {
            return Ok(None);
        };
        let mut record = [0u8; RECORD_LEN];
        record.copy_from_slice(bytes);
        Ok(Some(record))
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    // A permanent undefined instruction: probe-rs sees the fault and exits with an error.
    cortex_m::asm::udf()
}

#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc={=u32:#010x}", frame.pc());
    cortex_m::asm::udf()
}
