//! What a calibration may be on a given board: the front end's nominal gain and zero, and
//! how far a real chain can sit from them ([`CalibrationLimits`]). A new calibration and a
//! record loaded at boot are both checked here, against the nominal values and never
//! against the calibration in use, so a wrong calibration cannot become the reference
//! that lets the next one drift further.

use libm::roundf;

use super::record::{Calibration, CalibrationError};

/// The analogue chain of the hardware board: load cell → INA114 → ADC. Its nominal
/// calibration is the fallback when no valid record is stored, and the centre of the
/// window every calibration must fall in ([`FrontEnd::calibration_limits`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrontEnd {
    /// Bridge excitation in volts.
    pub excitation_v: f32,
    /// Rated output of the cell at capacity, in mV per volt of excitation.
    pub rated_output_mv_per_v: f32,
    /// Rated capacity of the cell in grams.
    pub capacity_g: f32,
    /// The INA114's gain resistor R_G in ohms (gain = 1 + 50 kΩ / R_G).
    pub gain_resistor_ohm: f32,
    /// Voltage on the INA114's REF pin: the output with a balanced bridge.
    pub reference_pin_v: f32,
    /// ADC reference (full scale) in volts.
    pub adc_reference_v: f32,
    /// ADC resolution in bits.
    pub adc_bits: u8,
}

impl FrontEnd {
    /// The STM32F411 board's INA114 front end as wired in `firmware/README.md`: a 600 g,
    /// 2 mV/V cell excited with 3.3 V, R_G = 130 Ω (gain 385.6), REF at 0.5 V, into the
    /// 12-bit ADC (3.3 V reference). The firmware's internal-ADC build, and the host's model
    /// of that chain, use this one constant.
    pub const STM32F411_INA114: Self = Self {
        excitation_v: 3.3,
        rated_output_mv_per_v: 2.0,
        capacity_g: 600.0,
        gain_resistor_ohm: 130.0,
        reference_pin_v: 0.5,
        adc_reference_v: 3.3,
        adc_bits: 12,
    };

    /// The same cell into the external ADS131M02's PGA at gain 128 with its 1.2 V internal
    /// reference, read as offset binary (code + 2^23). In the fields of the INA114 chain:
    /// the PGA's gain as the amplifier's (R_G = 50 kΩ / 127 makes 1 + 50 kΩ / R_G = 128),
    /// the converter's span ±1.2 V as a 2.4 V reference over 24 bits, and the zero at
    /// mid-scale (2^23 codes) as a 1.2 V REF. Nominal: 9,842.6 counts/g, the zero at
    /// 8,388,608; a full 600 g spans 5.9 M of the 8.4 M codes above it.
    pub const ADS131M02: Self = Self {
        excitation_v: 3.3,
        rated_output_mv_per_v: 2.0,
        capacity_g: 600.0,
        gain_resistor_ohm: 50_000.0 / 127.0,
        reference_pin_v: 1.2,
        adc_reference_v: 2.4,
        adc_bits: 24,
    };

    /// How far (relative) a working chain's gain can be from [`Self::nominal_calibration`],
    /// either way. The gain is excitation × rated output / capacity × INA114 gain × ADC
    /// counts per volt; its worst-case error is the sum of the parts' tolerances:
    /// - rated output: single-point cells are sold as 2.0 mV/V ± 10 % (± 0.2 mV/V; the
    ///   better ones ± 5 % or a calibration sheet): 10 %;
    /// - INA114 gain: the gain equation's error, internal 25 kΩ resistors included, is at
    ///   most ± 0.5 % at G = 100 and ± 1 % at G = 1000 (data sheet, "Gain error"), and a
    ///   1 % metal-film R_G adds 1 %: 2 %;
    /// - excitation against the ADC reference: 0 when both are the same 3.3 V rail
    ///   (ratiometric, as wired); ± 3 % when they come from separate regulators (a 1.5 %
    ///   regulator each): 3 %.
    ///
    /// 10 + 2 + 3 = 15 %. A wrong reference mass shows as its ratio to the right one
    /// (140 g, 250 g or 290 g put on for 200 g: −30 %, +25 %, +45 %) and is refused; one
    /// within 15 % of the right mass is not told from a cell at the end of its tolerance,
    /// which is why the mass comes from the board's constant, not from the operator.
    pub const GAIN_TOLERANCE: f32 = 0.15;

    /// How far the empty-pan zero can be from the nominal one, as a fraction of the counts
    /// the cell's capacity spans. What moves it: the platform's dead load (a single-point
    /// cell's pan and its fixings weigh up to about a quarter of its capacity: 25 %), the
    /// bridge's zero balance (± 0.1 mV/V on 2 mV/V cells, 5 %; cheap ones ± 10 %), the
    /// INA114's offset (± 125 µV input-referred against the 6.6 mV span, 2 %) and the REF
    /// divider (1 % resistors: well under 1 % of the span): 25 + 10 + 2 + 1 ≈ 40 %. Looser
    /// than the gain: it catches a pan loaded with a good part of the capacity, a broken
    /// bridge or amplifier (zero on a rail); a small offset is what the zero is for.
    pub const ZERO_TOLERANCE_OF_SPAN: f32 = 0.4;

    /// The INA114's gain, 1 + 50 kΩ / R_G (data sheet).
    pub fn ina114_gain(&self) -> f32 {
        1.0 + 50_000.0 / self.gain_resistor_ohm
    }

    /// ADC counts per volt at the ADC pin.
    pub fn counts_per_volt(&self) -> f32 {
        (1u32 << self.adc_bits) as f32 / self.adc_reference_v
    }

    /// The converter's largest code.
    pub fn max_code(&self) -> u32 {
        (1u32 << self.adc_bits) - 1
    }

    /// The nominal gain and zero of the chain.
    pub fn nominal_calibration(&self) -> Calibration {
        let volts_per_gram =
            self.excitation_v * self.rated_output_mv_per_v * 1e-3 / self.capacity_g;
        Calibration {
            counts_per_gram: volts_per_gram * self.ina114_gain() * self.counts_per_volt(),
            zero_counts: self.reference_pin_v * self.counts_per_volt(),
        }
    }

    /// ADC counts at the cell's capacity: must stay below full scale, or a full load
    /// saturates the converter (and reads invalid).
    pub fn counts_at_capacity(&self) -> f32 {
        let nominal = self.nominal_calibration();
        nominal.zero_counts + nominal.counts_per_gram * self.capacity_g
    }

    /// The window of plausible calibrations around the nominal one, with the tolerances
    /// argued at [`Self::GAIN_TOLERANCE`] and [`Self::ZERO_TOLERANCE_OF_SPAN`] (change a
    /// field of the result for another board).
    pub fn calibration_limits(&self) -> CalibrationLimits {
        let nominal = self.nominal_calibration();
        CalibrationLimits {
            nominal,
            gain_tolerance: Self::GAIN_TOLERANCE,
            zero_tolerance_counts: Self::ZERO_TOLERANCE_OF_SPAN
                * nominal.counts_per_gram
                * self.capacity_g,
            max_code: self.max_code(),
        }
    }
}

/// The calibrations a board accepts: a gain within `gain_tolerance` of the nominal gain
/// and a zero within `zero_tolerance_counts` of the nominal zero and inside the
/// converter's range. Anything else is refused with the reason, whether it comes from the
/// operator's calibration or from the store at boot.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalibrationLimits {
    /// The front end's nominal gain and zero: the centre of the window, and the fallback.
    pub nominal: Calibration,
    /// Relative distance of the gain from the nominal gain allowed either way (0.15: ±15 %).
    pub gain_tolerance: f32,
    /// Distance of the zero from the nominal zero allowed either way, in counts.
    pub zero_tolerance_counts: f32,
    /// The converter's largest code: a zero must lie strictly between the rails.
    pub max_code: u32,
}

impl CalibrationLimits {
    /// `calibration` if it is usable (finite, positive gain) and within the window, else
    /// why not: `OutOfDomain`, `GainOffNominal` or a zero error ([`Self::check_zero`]).
    pub fn check(&self, calibration: &Calibration) -> Result<Calibration, CalibrationError> {
        if !calibration.is_valid() {
            return Err(CalibrationError::OutOfDomain);
        }
        let off = calibration.counts_per_gram / self.nominal.counts_per_gram - 1.0;
        // Written so that a NaN (a nominal gain of zero) fails too.
        if !(off.abs() <= self.gain_tolerance) {
            return Err(CalibrationError::GainOffNominal {
                // `as` saturates: a gain a million times off still says so.
                percent: roundf(off * 100.0) as i16,
            });
        }
        self.check_zero(calibration.zero_counts)?;
        Ok(*calibration)
    }

    /// An empty-pan zero (in counts) is strictly between the converter's rails and within
    /// the tolerance of the nominal zero.
    pub fn check_zero(&self, zero_counts: f32) -> Result<(), CalibrationError> {
        if !(zero_counts > 0.0 && zero_counts < self.max_code as f32) {
            return Err(CalibrationError::ZeroOutsideConverter);
        }
        let off = zero_counts - self.nominal.zero_counts;
        if !(off.abs() <= self.zero_tolerance_counts) {
            return Err(CalibrationError::ZeroOffNominal { counts: off as i32 });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The STM32F411 board's front end (`firmware/src/stm32f411.rs`).
    const BOARD: FrontEnd = FrontEnd::STM32F411_INA114;

    #[test]
    fn front_end_gain_and_counts_follow_the_data_sheet_formulas() {
        let gain = BOARD.ina114_gain();
        assert!((gain - 385.615).abs() < 1e-2, "{gain}");
        let nominal = BOARD.nominal_calibration();
        // 6.6 mV at 600 g → 11 µV/g → ×385.6 → 4.242 mV/g → ×(4096/3.3) counts/V.
        let expected = 11e-6 * 385.615 * 4096.0 / 3.3;
        assert!((nominal.counts_per_gram as f64 - expected).abs() < 1e-3 * expected);
        assert!((nominal.zero_counts - 620.6).abs() < 0.1);
        assert!(BOARD.counts_at_capacity() < 4095.0);
        assert!(nominal.is_valid());
    }

    /// The hostile tester's case: 140, 250 and 290 g put on where 200 g was promised give
    /// gains 30 % low to 45 % high; all refused with how far off they are. The right mass
    /// on a cell at the ends of its tolerance is accepted.
    #[test]
    fn a_gain_from_the_wrong_mass_is_refused_with_how_far_off_it_is() {
        let limits = BOARD.calibration_limits();
        let nominal = limits.nominal;
        for (placed_g, percent) in [(140.0, -30), (250.0, 25), (290.0, 45), (100.0, -50)] {
            let measured = Calibration {
                counts_per_gram: nominal.counts_per_gram * placed_g / 200.0,
                ..nominal
            };
            assert_eq!(
                limits.check(&measured),
                Err(CalibrationError::GainOffNominal { percent }),
                "{placed_g} g"
            );
        }
        for factor in [0.86, 1.0, 1.14] {
            let measured = Calibration {
                counts_per_gram: nominal.counts_per_gram * factor,
                ..nominal
            };
            assert_eq!(limits.check(&measured), Ok(measured), "×{factor}");
        }
    }

    #[test]
    fn absurd_gains_and_zeros_are_refused() {
        let limits = BOARD.calibration_limits();
        let nominal = limits.nominal;
        let with_gain = |counts_per_gram| Calibration {
            counts_per_gram,
            ..nominal
        };
        assert_eq!(
            limits.check(&with_gain(1e-6)),
            Err(CalibrationError::GainOffNominal { percent: -100 })
        );
        assert_eq!(
            limits.check(&with_gain(1e30)),
            Err(CalibrationError::GainOffNominal { percent: i16::MAX })
        );
        for bad in [0.0, -5.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                limits.check(&with_gain(bad)),
                Err(CalibrationError::OutOfDomain)
            );
        }
        let with_zero = |zero_counts| Calibration {
            zero_counts,
            ..nominal
        };
        for rail in [0.0, -1.0, 4095.0, 1e9] {
            assert_eq!(
                limits.check(&with_zero(rail)),
                Err(CalibrationError::ZeroOutsideConverter),
                "{rail}"
            );
        }
        // Inside the converter, but 500 g of the 600 g cell's span above the nominal zero.
        let loaded = nominal.zero_counts + 500.0 * nominal.counts_per_gram;
        assert!(matches!(
            limits.check(&with_zero(loaded)),
            Err(CalibrationError::ZeroOffNominal { counts }) if counts > 2000
        ));
        // A 100 g dead load is what the zero is for.
        let dead_load = with_zero(nominal.zero_counts + 100.0 * nominal.counts_per_gram);
        assert_eq!(limits.check(&dead_load), Ok(dead_load));
    }
}
