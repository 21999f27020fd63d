//! The STM32F411 board: its analogue front end, where its calibration record lives, and
//! what a panic or fault does (halt, so probe-rs reports it and exits non-zero).

use estimator_core::calibration::{self, Calibration, CalibrationSource, FrontEnd, RECORD_LEN};

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

/// Start of the flash sector reserved for the calibration record (see `memory.x`).
pub const CALIBRATION_RECORD_ADDRESS: usize = 0x0806_0000;

/// Samples per DMA buffer: the DMA fills one buffer while the hand-off drains the other.
pub const DMA_BLOCK: usize = 8;

/// The calibration to use at boot: the flash record if valid, else the front end's
/// nominal values with the reason (erased flash reads `Missing`).
#[allow(unsafe_code)]
pub fn load_calibration() -> (Calibration, CalibrationSource) {
    // Safety: the sector is inside the STM32F411CE's 512 KiB flash, always mapped and
    // readable, and `memory.x` keeps the program out of it, so nothing aliases it mutably.
    let record =
        unsafe { core::slice::from_raw_parts(CALIBRATION_RECORD_ADDRESS as *const u8, RECORD_LEN) };
    calibration::load_or_default(Some(record), FRONT_END.nominal_calibration())
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
