//! The STM32 board's own 12-bit chain, as the firmware's internal-ADC build reads it: the
//! reference cell excited with 3.3 V, the INA114 at R_G = 130 Ω (gain 385.6) with REF at
//! 0.5 V, the 3rd-order 100 Hz Butterworth, ADC1 at 12 bits with a 3.3 V reference, 4 kHz
//! (the firmware's `stm32f411::FRONT_END`: 5.27 counts/g).
//!
//! How it is modelled, and how far that goes:
//! - the cell, the amplifier with its input noise and the filter are [`SensorChain`]'s
//!   (the INA114's 11 nV/√Hz, data sheet, G ≥ 100: 0.045 g per sample before the filter, a
//!   quarter of a code after it);
//! - the converter's own noise is white, added before quantisation, [`ADC_NOISE_LSB_RMS`]:
//!   an assumption, not a measurement (see there);
//! - codes clip at 0 and 4095. The output cannot leave 0..3.3 V anyway: the Butterworth's
//!   op-amps are rail-to-rail on 3.3 V, and the INA114 on ±5 V swings to about ±3.5 V (data
//!   sheet: (V+) − 1.5 V at worst), so the converter's rails are the chain's limit.
//!
//! Its range: the reference platform's 120 g dead load puts the empty pan at 1.02 V
//! (1,264 codes), so the rail (less the firmware's 40-code guard band) comes at about 530 g
//! of load, short of the cell's 600 g capacity (the `FRONT_END`'s nominal zero, 0.5 V, is a
//! pan without dead load).

use estimator_core::sensor::{AdcError, AdcSource};

use crate::sensor::{Adc, Ina114, LoadCell, SensorChain, SAMPLE_RATE_HZ};
use crate::simulated::{Disturbances, Gaussian, Script, SimulatedAdc};

/// The converter's own noise, LSB RMS, before quantisation. Assumed: the STM32F4's ADC is
/// rated at about 10.5–11 effective bits on a good layout (0.6–0.8 LSB RMS with the
/// quantisation's 0.29), and application notes (ST AN2834) report 1–2 LSB on ordinary
/// boards; 1.0 LSB (1.04 with quantisation, about 10.1 effective bits) is the quiet end of
/// the latter. Not measured on a board.
pub const ADC_NOISE_LSB_RMS: f64 = 1.0;

/// Codes at each rail the firmware reads as saturated (`stm32f411::ADC_RAIL_GUARD_CODES`).
pub const RAIL_GUARD_CODES: u32 = 40;

/// The board's chain with the converter's noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stm32BoardChain {
    /// Cell, INA114, Butterworth and the converter's resolution and reference.
    pub chain: SensorChain,
    /// The converter's own noise, LSB RMS (0: quantisation only).
    pub adc_noise_lsb_rms: f64,
}

impl Stm32BoardChain {
    /// The board as wired (firmware/README.md): the reference cell at 3.3 V excitation,
    /// the reference INA114 (25 µV offset, 11 nV/√Hz) with R_G = 130 Ω and REF at 0.5 V,
    /// the 100 Hz Butterworth, 12 bits on 3.3 V at 4 kHz, [`ADC_NOISE_LSB_RMS`].
    pub fn reference() -> Self {
        Self {
            chain: SensorChain {
                cell: LoadCell {
                    excitation_v: 3.3,
                    ..LoadCell::reference()
                },
                amplifier: Ina114 {
                    gain_resistor_ohm: 130.0,
                    output_reference_v: 0.5,
                    ..Ina114::reference()
                },
                filter_cutoff_hz: 100.0,
                adc: Adc {
                    bits: 12,
                    reference_v: 3.3,
                    oversampling: 1,
                },
                sample_rate_hz: SAMPLE_RATE_HZ,
            },
            adc_noise_lsb_rms: ADC_NOISE_LSB_RMS,
        }
    }

    /// Counts per gram.
    pub fn counts_per_gram(&self) -> f64 {
        self.chain.counts_per_gram()
    }

    /// Code of the empty platform, noise-free.
    pub fn zero_code(&self) -> f64 {
        self.chain.zero_code()
    }

    /// The converter's noise with its quantisation, as a load, g RMS per sample.
    pub fn adc_noise_g(&self) -> f64 {
        let lsb = libm::sqrt(self.adc_noise_lsb_rms * self.adc_noise_lsb_rms + 1.0 / 12.0);
        lsb / self.counts_per_gram()
    }
}

/// The board's chain as a converter: a scene's load script through the cell, the INA114
/// with its noise, the Butterworth, the converter's noise and its 12-bit quantiser.
#[derive(Clone, Debug)]
pub struct Stm32BoardAdc<const E: usize> {
    board: Stm32BoardChain,
    input: SimulatedAdc<E>,
    noise: Gaussian,
}

impl<const E: usize> Stm32BoardAdc<E> {
    /// The chain at rest with an empty platform at t = 0, playing `script` with the scene's
    /// `disturbances` (the INA114's noise is switched on whatever they say).
    pub fn new(
        board: Stm32BoardChain,
        script: Script<E>,
        mut disturbances: Disturbances,
        seed: u64,
    ) -> Self {
        disturbances.amplifier_noise = true;
        Self {
            board,
            input: SimulatedAdc::new(board.chain, script, disturbances, seed),
            // Its own stream, apart from the scene's noises.
            noise: Gaussian::new(seed ^ 0x5732_F411),
        }
    }

    /// The chain being simulated.
    pub fn board(&self) -> &Stm32BoardChain {
        &self.board
    }

    /// The true load on the platform over the last conversion, g.
    pub fn load_g(&self) -> f64 {
        self.input.load_g()
    }
}

impl<const E: usize> AdcSource for Stm32BoardAdc<E> {
    fn max_code(&self) -> u32 {
        self.board.chain.adc.max_code()
    }

    fn read(&mut self) -> Result<u32, AdcError> {
        let noise = self.board.adc_noise_lsb_rms * self.noise.standard();
        let code = libm::round(self.input.read_analog() + noise);
        let top = f64::from(self.max_code());
        // NaN lands on the lower rail, where it is flagged as saturated.
        Ok(if code > 0.0 { code.min(top) as u32 } else { 0 })
    }

    fn rail_guard_codes(&self) -> u32 {
        RAIL_GUARD_CODES
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::simulated::LoadEvent;
    use estimator_core::weighing::{FrontEnd, RawSample};

    /// The firmware's `stm32f411::FRONT_END` (the internal-ADC build).
    const FRONT_END: FrontEnd = FrontEnd::STM32F411_INA114;

    /// The chain's gain is the firmware's nominal one (5.265 counts/g, within 0.5 %); a
    /// static load reads it above the zero once the cell has rung down; the empty pan sits
    /// at 1,264 codes (REF 0.5 V plus the 120 g platform and the 25 µV offset times 385.6);
    /// 500 g reads within 0.05 g, while 550 g and 600 g reach the guard band at the upper
    /// rail and read `Saturated` (the range ends near 530 g, see the module's doc).
    #[test]
    fn counts_per_gram_zero_and_range() {
        let board = Stm32BoardChain::reference();
        let nominal = FRONT_END.nominal_calibration().counts_per_gram as f64;
        assert!((board.counts_per_gram() / nominal - 1.0).abs() < 0.005);
        assert!((board.counts_per_gram() - 5.265).abs() < 0.001);
        assert!(
            (board.zero_code() - 1_264.0).abs() < 1.0,
            "{}",
            board.zero_code()
        );

        for (load_g, saturated) in [(200.0, false), (500.0, false), (550.0, true), (600.0, true)] {
            let mut script = Script::<2>::new(10.0);
            script.push(LoadEvent::step(0.05, load_g)).unwrap();
            let mut adc = Stm32BoardAdc::new(board, script, Disturbances::none(), 1);
            let mut sum = 0.0;
            let mut last = RawSample::Lost;
            let mut saturations = 0;
            for sample in 0..40_000 {
                last = RawSample::read(&mut adc);
                if sample >= 32_000 {
                    match last {
                        RawSample::Counts(code) => sum += f64::from(code),
                        _ => saturations += 1,
                    }
                }
            }
            if saturated {
                assert_eq!(last, RawSample::Saturated, "{load_g} g");
            } else {
                assert_eq!(saturations, 0, "{load_g} g");
                let read_g = (sum / 8_000.0 - board.zero_code()) / board.counts_per_gram();
                assert!((read_g - load_g).abs() < 0.05, "{load_g} g read {read_g} g");
            }
        }
    }

    /// The converter's noise is what was asked for: the empty pan's codes spread by
    /// √(1² + 1/12 + the filtered INA114's) LSB, 1.04–1.10.
    #[test]
    fn empty_pan_noise_is_about_one_lsb() {
        let board = Stm32BoardChain::reference();
        let mut adc = Stm32BoardAdc::new(board, Script::<1>::new(3.0), Disturbances::none(), 3);
        let codes: std::vec::Vec<f64> =
            (0..8_000).map(|_| f64::from(adc.read().unwrap())).collect();
        let mean = codes.iter().sum::<f64>() / codes.len() as f64;
        let variance =
            codes.iter().map(|c| (c - mean) * (c - mean)).sum::<f64>() / codes.len() as f64;
        let rms = libm::sqrt(variance);
        assert!((1.02..1.12).contains(&rms), "{rms} LSB");
    }
}
