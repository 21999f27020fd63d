//! The one seam between the estimators and the converter behind the INA114.
//!
//! embedded-hal 1.0 has no ADC trait, so this small one is ours. The real board implements
//! it over its HAL (timer-triggered conversions into DMA blocks, read through
//! [`CodeBlock`]; an external converter's frames), the simulator and the QEMU board
//! with the sensor model, tests with scripted fakes. A signed converter (the 24-bit
//! ADS131M02) reports offset binary, `code + 2^(bits−1)`, so every board's rails are `0`
//! and [`AdcSource::max_code`].

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

/// A block of conversions a DMA stream already wrote, read through the seam one code at a
/// time: the STM32's ADC1 fills a buffer of codes, and the hand-off takes each through
/// [`crate::weighing::RawSample::read`] exactly as a converter read one by one, with the
/// same rails and guard band. Reading past the block's end is [`AdcError::NotReady`].
#[derive(Clone, Debug)]
pub struct CodeBlock<'a, C> {
    codes: &'a [C],
    next: usize,
    max_code: u32,
    rail_guard_codes: u32,
}

impl<'a, C: Copy + Into<u32>> CodeBlock<'a, C> {
    /// The `codes` of a converter whose largest code is `max_code`, its front end clipping
    /// `rail_guard_codes` short of each rail ([`AdcSource::rail_guard_codes`]).
    pub fn new(codes: &'a [C], max_code: u32, rail_guard_codes: u32) -> Self {
        Self {
            codes,
            next: 0,
            max_code,
            rail_guard_codes,
        }
    }
}

impl<C: Copy + Into<u32>> AdcSource for CodeBlock<'_, C> {
    fn max_code(&self) -> u32 {
        self.max_code
    }

    #[inline]
    fn read(&mut self) -> Result<u32, AdcError> {
        let code = self.codes.get(self.next).ok_or(AdcError::NotReady)?;
        self.next += 1;
        Ok((*code).into())
    }

    fn rail_guard_codes(&self) -> u32 {
        self.rail_guard_codes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A DMA block of 12-bit codes read through the seam: each code in order, the guard
    /// band saturated as for any converter (the hand-off checked only the rails before,
    /// `code == 0 || code >= 4095`), and nothing past the block's end.
    #[test]
    fn a_dma_block_reads_through_the_seam_with_its_guard_band() {
        use crate::weighing::RawSample;
        let codes: [u16; 6] = [620, 0, 39, 40, 4055, 3784];
        let mut block = CodeBlock::new(&codes, 4095, 40);
        let read: [RawSample; 7] = core::array::from_fn(|_| RawSample::read(&mut block));
        assert_eq!(
            read,
            [
                RawSample::Counts(620),
                RawSample::Saturated,
                RawSample::Saturated,
                RawSample::Saturated,
                RawSample::Saturated,
                RawSample::Counts(3784),
                RawSample::Lost,
            ]
        );
        let mut unguarded = CodeBlock::new(&codes[2..3], 4095, 0);
        assert_eq!(RawSample::read(&mut unguarded), RawSample::Counts(39));
    }

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
