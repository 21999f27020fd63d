//! The external converter of the `ads131m02` build: a TI ADS131M02 on SPI1 (PA5 SCK, PA6
//! MISO, PA7 MOSI, PA4 CS), its DRDY on PA3 (EXTI3, falling edge), clocked by an 8.192 MHz
//! oscillator on its CLKIN; wiring in `firmware/README.md`.

use estimator_core::sensor::ads131m02::{Ads131m02, Config, Oversampling, CLKIN_HZ};
use stm32f4xx_hal::gpio::{Edge, Input, Output, PA3, PA4, PA5, PA6, PA7};
use stm32f4xx_hal::hal::delay::DelayNs;
use stm32f4xx_hal::hal::spi::MODE_1;
use stm32f4xx_hal::pac::{EXTI, SPI1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Rcc;
use stm32f4xx_hal::spi::Spi;
use stm32f4xx_hal::syscfg::SysCfg;

use crate::pipeline::{SampleMessage, SAMPLE_RATE_HZ};
use estimator_core::weighing::RawSample;
use heapless::spsc::Producer;

/// The converter's configuration: OSR 1024 (4 kSPS), the bridge on channel 0 at gain 128.
pub const ADC_CONFIG: Config = Config {
    oversampling: Oversampling::Osr1024,
    gains: [
        estimator_core::sensor::ads131m02::Gain::G128,
        estimator_core::sensor::ads131m02::Gain::G1,
    ],
    load_cell_channel: estimator_core::sensor::ads131m02::Channel::Ch0,
    rail_guard_codes: 0,
};

// The converter's data rate is the weighing core's sample rate.
const _: () = assert!(
    ADC_CONFIG.oversampling.data_rate_hz(CLKIN_HZ) == SAMPLE_RATE_HZ,
    "the ADS131M02's data rate must be the pipeline's sample rate"
);

/// SCLK: PCLK2 (84 MHz) / 8, a divider the HAL can set exactly; the device takes up to
/// 25 MHz. A 12-byte frame then takes about 9 µs of the 250 µs between conversions.
const SPI_HZ: u32 = 10_500_000;

/// SPI1 with its chip select, as one embedded-hal 1.0 `SpiDevice`.
pub type AdcSpi =
    embedded_hal_bus::spi::ExclusiveDevice<Spi<SPI1>, PA4<Output>, embedded_hal_bus::spi::NoDelay>;

/// The converter as the hand-off reads it.
pub type ExternalAdc = Ads131m02<AdcSpi>;

/// DRDY: low when a conversion is ready.
pub type Drdy = PA3<Input>;

/// The pins the converter uses.
pub struct AdcPins {
    /// SPI1 SCK.
    pub sck: PA5,
    /// SPI1 MISO (the device's DOUT).
    pub miso: PA6,
    /// SPI1 MOSI (the device's DIN).
    pub mosi: PA7,
    /// Chip select, active low.
    pub cs: PA4,
    /// DRDY, active low.
    pub drdy: PA3,
}

/// Busy-wait delays for the converter's bring-up (5 µs after its reset), on the core clock.
struct SpinDelay;

impl DelayNs for SpinDelay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles_per_us = super::SYSCLK_HZ / 1_000_000;
        cortex_m::asm::delay(ns.div_ceil(1_000).saturating_mul(cycles_per_us));
    }
}

/// Bring the converter up (reset, ID, registers written and read back) and arm DRDY's
/// falling edge on EXTI3. A converter that does not answer stops the boot: the scale would
/// have no samples.
pub fn external_adc(
    spi1: SPI1,
    pins: AdcPins,
    syscfg: &mut SysCfg,
    exti: &mut EXTI,
    rcc: &mut Rcc,
) -> (ExternalAdc, Drdy) {
    let spi = Spi::new(
        spi1,
        (Some(pins.sck), Some(pins.miso), Some(pins.mosi)),
        MODE_1,
        SPI_HZ.Hz(),
        rcc,
    );
    let device = match embedded_hal_bus::spi::ExclusiveDevice::new_no_delay(
        spi,
        pins.cs.into_push_pull_output(),
    ) {
        Ok(device) => device,
        Err(never) => match never {},
    };
    let mut adc = Ads131m02::new(device);
    if let Err(error) = adc.init(ADC_CONFIG, &mut SpinDelay) {
        defmt::panic!("ADS131M02 refused: {}", error.map_spi(|_| ()));
    }
    let mut drdy = pins.drdy.into_pull_up_input();
    drdy.make_interrupt_source(syscfg);
    drdy.trigger_on_edge(exti, Edge::Falling);
    drdy.enable_interrupt(exti);
    (adc, drdy)
}

/// The sample hand-off of this build, run at each DRDY edge: what it owns and its one step.
pub struct DrdyHandoff {
    adc: ExternalAdc,
    drdy: Drdy,
    producer: Producer<'static, SampleMessage>,
    sequence: u32,
}

impl DrdyHandoff {
    /// The hand-off of `adc` (ready, from [`external_adc`]) into the queue's `producer`.
    pub fn new(adc: ExternalAdc, drdy: Drdy, producer: Producer<'static, SampleMessage>) -> Self {
        Self {
            adc,
            drdy,
            producer,
            sequence: 0,
        }
    }

    /// Read one frame through the converter seam (a clip code becomes `Saturated`; a frame
    /// that fails its CRC or DRDY check, or a bus error, is `Lost` under its own sequence
    /// number, so the estimator task counts it) and queue it. A full queue drops the sample,
    /// and the estimator task counts the gap in the sequence numbers.
    pub fn hand_off(&mut self) {
        self.drdy.clear_interrupt_pending_bit();
        let sample = RawSample::read(&mut self.adc);
        let sequence = self.sequence;
        let _ = self.producer.enqueue(SampleMessage { sequence, sample });
        self.sequence = sequence.wrapping_add(1);
    }
}
