//! The one seam between the estimators and the converter behind the INA114.
//!
//! embedded-hal 1.0 has no ADC trait, so this small one is ours. The real board implements
//! it over its HAL (timer-triggered conversions, DMA); the simulator and the QEMU board
//! implement it with the sensor model; tests implement it with scripted fakes.

/// Why a conversion produced no usable code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdcError {
    /// A conversion was overwritten before it was read: a sample is lost.
    Overrun,
    /// No conversion was ready when one was expected.
    NotReady,
}

/// A source of raw ADC codes, one per sample period.
pub trait AdcSource {
    /// The largest code the converter returns (4095 for 12 bits, 65535 for 16 bits, more
    /// with oversampling). Codes `0` and `max_code()` mean the input is saturated.
    fn max_code(&self) -> u32;

    /// The next conversion.
    fn read(&mut self) -> Result<u32, AdcError>;

    /// True when `code` sits on a rail of the converter.
    fn is_saturated(&self, code: u32) -> bool {
        code == 0 || code >= self.max_code()
    }
}
