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
    /// The conversion did not arrive intact: the bus failed, the frame's check failed, or
    /// the converter lost its configuration (an external converter on SPI).
    Transfer,
}

/// A source of raw ADC codes, one per sample period.
pub trait AdcSource {
    /// The largest code the converter returns (4095 for 12 bits, 65535 for 16 bits, more
    /// with oversampling). Codes `0` and `max_code()` mean the input is saturated.
    fn max_code(&self) -> u32;

    /// The next conversion.
    fn read(&mut self) -> Result<u32, AdcError>;

    /// Codes at each end of the converter's range the front end in front of it cannot
    /// reach: a rail-to-rail amplifier still stops a few codes short of the rails, and
    /// clips there. `0` (the default) trusts the front end to reach the rails; a board
    /// whose front end clips short sets its measured margin here.
    fn rail_guard_codes(&self) -> u32 {
        0
    }

    /// True when `code` sits on a rail of the converter or within
    /// [`Self::rail_guard_codes`] of one: the input is out of range.
    fn is_saturated(&self, code: u32) -> bool {
        let guard = self.rail_guard_codes();
        code <= guard || code >= self.max_code().saturating_sub(guard)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16-bit converter behind a front end that clips 40 codes short of each rail.
    struct ClippingFrontEnd;

    impl AdcSource for ClippingFrontEnd {
        fn max_code(&self) -> u32 {
            65_535
        }

        fn read(&mut self) -> Result<u32, AdcError> {
            Ok(65_495)
        }

        fn rail_guard_codes(&self) -> u32 {
            40
        }
    }

    /// A code within the guard band of either rail is saturated: a front end clipping 40
    /// codes below the rail read as an ordinary (stable) load before.
    #[test]
    fn the_guard_band_is_saturated() {
        let adc = ClippingFrontEnd;
        for code in [0, 1, 40, 65_495, 65_534, 65_535, u32::MAX] {
            assert!(adc.is_saturated(code), "{code}");
        }
        for code in [41, 30_000, 65_494] {
            assert!(!adc.is_saturated(code), "{code}");
        }
        let mut adc = ClippingFrontEnd;
        assert_eq!(
            crate::weighing::RawSample::read(&mut adc),
            crate::weighing::RawSample::Saturated
        );
    }
}
