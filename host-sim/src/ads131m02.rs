//! The 24-bit chain: the load cell straight into a TI ADS131M02 (PGA at gain 128, 1.2 V
//! internal reference, sinc3 filter at OSR 1024: 4 kSPS from 8.192 MHz), as the firmware's
//! `ads131m02` build reads it (offset binary codes, 0..=2^24 − 1).
//!
//! How it is modelled, and how far that goes:
//! - the cell and the analogue filter in front of the converter are the reference chain's
//!   [`SensorChain`] (the same mechanics; the 100 Hz Butterworth kept by default, so the
//!   identified models and the shipped methods carry over; the ADS131M02 itself needs only
//!   an RC at its inputs), simulated at [`SUBSAMPLES`] times the data rate, each input
//!   sample quantised to 24 bits and clipped at ±1.2 V / gain as the modulator overloads;
//! - the sinc3 filter is a sinc3 over those input samples, decimated by [`SUBSAMPLES`]: the
//!   shape of the real one at OSR 1024 (it settles in 3 output samples, 750 µs at 4 kSPS;
//!   its group delay is 3(S − 1)/2 input samples, 1.41 output samples against the device's
//!   1.50 = 375 µs), not its modulator;
//! - the converter's own noise is added at its output, white, at the data sheet's
//!   input-referred RMS for gain 128 at OSR 1024 ([`NOISE_V_RMS`]);
//! - the output clips at the codes 0 and 2^24 − 1 (800000h and 7FFFFFh signed).
//!
//! A scene's disturbances enter at the converter's input, at the input sample rate: white
//! noise there is averaged by the sinc3, vibration and mains pass as they would.

use estimator_core::sensor::{AdcError, AdcSource};

use crate::sensor::{Adc, Ina114, LoadCell, SensorChain};
use crate::simulated::{Disturbances, Gaussian, Script, SimulatedAdc};

/// Input samples per output sample in the model of the sinc3 filter (the device's modulator
/// takes 1024; 16 keeps the filter's shape to within a few % up to the Nyquist rate).
pub const SUBSAMPLES: usize = 16;
/// Taps of the sinc3 over the input samples: (1 + z⁻¹ + … + z^−(S−1))³ has 3S − 2.
const TAPS: usize = 3 * SUBSAMPLES - 2;
/// Data rate at OSR 1024 from an 8.192 MHz CLKIN in high-resolution mode, Hz.
pub const DATA_RATE_HZ: f64 = 4000.0;
/// Input-referred noise at gain 128 and OSR 1024 (4 kSPS), V RMS: the ADS131M0x family's
/// noise table (ADS131M04-Q1 data sheet, table 7-1; gains 32–128 alike). The ADS131M02's
/// own table (SBAS853) was not at hand: check it before trusting the last digit.
pub const NOISE_V_RMS: f64 = 1.20e-6;

/// The 24-bit chain's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ads131m02Chain {
    /// The load cell (excited from the converter's 3.3 V supply).
    pub cell: LoadCell,
    /// The PGA's gain (1, 2, 4, … 128).
    pub pga_gain: f64,
    /// The reference, V: full scale is ±reference / gain.
    pub reference_v: f64,
    /// The analogue low-pass in front of the converter (3rd-order Butterworth), Hz.
    pub filter_cutoff_hz: f64,
    /// The converter's input-referred noise, V RMS (0: none).
    pub noise_v_rms: f64,
}

impl Ads131m02Chain {
    /// The reference cell at 3.3 V excitation (a 2 mV/V, 600 g cell spans 6.6 mV of the
    /// ±9.375 mV at gain 128), the 1.2 V internal reference, the reference chain's 100 Hz
    /// Butterworth, the data sheet's noise.
    pub fn reference() -> Self {
        Self {
            cell: LoadCell {
                excitation_v: 3.3,
                ..LoadCell::reference()
            },
            pga_gain: 128.0,
            reference_v: 1.2,
            filter_cutoff_hz: 100.0,
            noise_v_rms: NOISE_V_RMS,
        }
    }

    /// The chain in front of the sinc3, at [`SUBSAMPLES`] × the data rate: the PGA as the
    /// amplifier, the converter's span (2 × reference) over 24 bits, its zero input at
    /// mid-scale (offset binary), no amplifier noise (the converter's is added at its output).
    pub fn input_chain(&self) -> SensorChain {
        SensorChain {
            cell: self.cell,
            amplifier: Ina114 {
                gain_resistor_ohm: 50_000.0 / (self.pga_gain - 1.0),
                input_offset_v: 0.0,
                output_reference_v: self.reference_v,
                input_noise_v_per_rt_hz: 0.0,
            },
            filter_cutoff_hz: self.filter_cutoff_hz,
            adc: Adc {
                bits: 24,
                reference_v: 2.0 * self.reference_v,
                oversampling: 1,
            },
            sample_rate_hz: DATA_RATE_HZ * SUBSAMPLES as f64,
        }
    }

    /// Counts per gram of the output code.
    pub fn counts_per_gram(&self) -> f64 {
        self.input_chain().counts_per_gram()
    }

    /// Output code of the empty platform, noise-free (mid-scale plus the platform's preload).
    pub fn zero_code(&self) -> f64 {
        self.input_chain().zero_code()
    }

    /// The largest output code, 2^24 − 1.
    pub fn max_code(&self) -> u32 {
        (1 << 24) - 1
    }

    /// The converter's noise in output codes, RMS.
    pub fn noise_codes(&self) -> f64 {
        self.noise_v_rms * self.pga_gain / self.input_chain().adc.volts_per_code()
    }

    /// The converter's noise as a load, g RMS.
    pub fn noise_g(&self) -> f64 {
        self.noise_codes() / self.counts_per_gram()
    }

    /// The sinc3's group delay: 1.5 output samples, s.
    pub fn group_delay_s(&self) -> f64 {
        1.5 / DATA_RATE_HZ
    }

    /// The sinc3's settling time after a step: 3 output samples, s.
    pub fn settling_s(&self) -> f64 {
        3.0 / DATA_RATE_HZ
    }
}

/// A sinc3 filter over input samples, decimated by [`SUBSAMPLES`], unity gain at DC.
#[derive(Clone, Debug)]
pub struct Sinc3 {
    weights: [f64; TAPS],
    history: [f64; TAPS],
    newest: usize,
}

impl Sinc3 {
    /// A filter that has seen `initial` forever.
    pub fn new(initial: f64) -> Self {
        // The coefficients of (1 + z⁻¹ + … + z^−(S−1))³, by convolving the box three times.
        let mut weights = [0.0; TAPS];
        weights[0] = 1.0;
        let mut length = 1;
        for _ in 0..3 {
            let mut next = [0.0; TAPS];
            for (index, &weight) in weights[..length].iter().enumerate() {
                for slot in &mut next[index..index + SUBSAMPLES] {
                    *slot += weight;
                }
            }
            length += SUBSAMPLES - 1;
            weights = next;
        }
        let total = (SUBSAMPLES * SUBSAMPLES * SUBSAMPLES) as f64;
        for weight in &mut weights {
            *weight /= total;
        }
        Self {
            weights,
            history: [initial; TAPS],
            newest: 0,
        }
    }

    /// Take one input sample.
    pub fn push(&mut self, sample: f64) {
        self.newest = (self.newest + 1) % TAPS;
        self.history[self.newest] = sample;
    }

    /// The output over the last 3S − 2 input samples (call once per [`SUBSAMPLES`] pushes).
    pub fn output(&self) -> f64 {
        (0..TAPS)
            .map(|age| self.weights[age] * self.history[(self.newest + TAPS - age) % TAPS])
            .sum()
    }
}

/// The 24-bit chain as a converter: a scene's load script through the cell, the analogue
/// filter, the modulator's input range, the sinc3 and the converter's noise, one offset
/// binary code per 4 kHz sample.
#[derive(Clone, Debug)]
pub struct Ads131m02Adc<const E: usize> {
    chain: Ads131m02Chain,
    input: SimulatedAdc<E>,
    filter: Sinc3,
    noise: Gaussian,
}

impl<const E: usize> Ads131m02Adc<E> {
    /// The chain at rest with an empty platform at t = 0, playing `script`.
    pub fn new(
        chain: Ads131m02Chain,
        script: Script<E>,
        disturbances: Disturbances,
        seed: u64,
    ) -> Self {
        let mut input = SimulatedAdc::new(chain.input_chain(), script, disturbances, seed);
        let first = input.read().map_or(0.0, f64::from);
        Self {
            chain,
            input,
            filter: Sinc3::new(first),
            // Its own stream, apart from the scene's noises.
            noise: Gaussian::new(seed ^ 0xAD5_131),
        }
    }

    /// The chain being simulated.
    pub fn chain(&self) -> &Ads131m02Chain {
        &self.chain
    }

    /// The true load on the platform over the last input sample, g.
    pub fn load_g(&self) -> f64 {
        self.input.load_g()
    }
}

impl<const E: usize> AdcSource for Ads131m02Adc<E> {
    fn max_code(&self) -> u32 {
        self.chain.max_code()
    }

    fn read(&mut self) -> Result<u32, AdcError> {
        for _ in 0..SUBSAMPLES {
            let code = self.input.read()?;
            self.filter.push(f64::from(code));
        }
        let noise = self.chain.noise_codes() * self.noise.standard();
        let code = libm::round(self.filter.output() + noise);
        let top = f64::from(self.chain.max_code());
        // NaN lands on the lower rail, where it is flagged as saturated.
        Ok(if code > 0.0 { code.min(top) as u32 } else { 0 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulated::LoadEvent;
    use estimator_core::weighing::{FrontEnd, RawSample};

    /// The chain's gain is the firmware's nominal one for the same parts (estimator-core's
    /// `FrontEnd` with the PGA as the amplifier): 9,842.6 counts/g; a static load reads that
    /// gain above the zero once the cell has rung down (8 s: at 600 g it rings at 15 Hz with
    /// ζ = 0.018, and is still 4 g out at 3 s); beyond about 730 g (the platform's
    /// 120 g preload uses the rest of the ±9.375 mV) the code clips and reads `Saturated`.
    #[test]
    fn counts_per_gram_and_saturation() {
        let mut chain = Ads131m02Chain::reference();
        let firmware = FrontEnd::ADS131M02;
        let nominal = firmware.nominal_calibration().counts_per_gram as f64;
        assert!((chain.counts_per_gram() - 9_842.6).abs() < 0.1);
        assert!((chain.counts_per_gram() / nominal - 1.0).abs() < 1e-6);
        assert!(
            (chain.noise_g() - 0.109).abs() < 0.001,
            "{}",
            chain.noise_g()
        );

        chain.noise_v_rms = 0.0;
        for (load_g, saturated) in [(200.0, false), (600.0, false), (1_000.0, true)] {
            let mut script = Script::<2>::new(10.0);
            script.push(LoadEvent::step(0.05, load_g)).unwrap();
            let mut adc = Ads131m02Adc::new(chain, script, Disturbances::none(), 1);
            let mut sum = 0.0;
            let mut last = RawSample::Lost;
            for sample in 0..40_000 {
                last = RawSample::read(&mut adc);
                if sample >= 32_000 {
                    if let RawSample::Counts(code) = last {
                        sum += f64::from(code);
                    }
                }
            }
            if saturated {
                assert_eq!(last, RawSample::Saturated, "{load_g} g");
            } else {
                let read_g = (sum / 8_000.0 - chain.zero_code()) / chain.counts_per_gram();
                assert!(
                    (read_g - load_g).abs() < 0.005,
                    "{load_g} g read {read_g} g"
                );
            }
        }
    }

    /// Figures for each chain (README): the firmware's default method (`step:n=5,D=24`, f64
    /// here) on a 138.32 g drop, started at the drop with the zero known, with only each
    /// chain's own noise: the INA114's through the 100 Hz Butterworth into the 16-bit
    /// converter; the STM32 board's 12-bit chain (INA114 at gain 385.6, its converter's
    /// assumed 1 LSB RMS and quantisation, `stm32_board`); or the ADS131M02's. Prints the raw
    /// noise per sample, the RMS error 100 ms after the drop, and the time from which the
    /// reading stays within 0.1 % up to 1 s (median, 95th percentile, runs within by 100 ms).
    /// `cargo test --release -p host-sim --lib ads131m02::tests::chain_figures -- --ignored --nocapture`
    #[test]
    #[ignore = "prints figures (a few seconds)"]
    fn chain_figures() {
        use crate::sensor::SensorChain;
        use crate::stm32_board::{Stm32BoardAdc, Stm32BoardChain};
        use estimator_core::{Estimator, StepConfig, StepEstimator};
        extern crate std;
        use std::vec::Vec;
        const RUNS: u64 = 400;
        const DROP_G: f64 = 138.32;
        const READOUT: usize = 400;
        const WINDOW: usize = 4_000;
        /// One run: the error at the readout and the first sample from which the reading
        /// stays within 0.1 % of the drop up to the end of the window.
        fn run(adc: &mut impl AdcSource, counts_per_gram: f64, zero_code: f64) -> (f64, usize) {
            let config = StepConfig::new(5, counts_per_gram).with_decimation(24);
            let mut estimator = StepEstimator::<f64, 8>::new(config).unwrap();
            let mut at_readout = f64::NAN;
            let mut settled_from = 0;
            for sample in 0..WINDOW {
                let code = f64::from(adc.read().unwrap());
                let error = estimator
                    .push(code - zero_code)
                    .estimate
                    .map_or(f64::INFINITY, |reading| reading - DROP_G);
                if sample + 1 == READOUT {
                    at_readout = error;
                }
                if !(error.abs() <= 1e-3 * DROP_G) {
                    settled_from = sample + 1;
                }
            }
            (at_readout, settled_from)
        }
        fn summary(runs: &[(f64, usize)]) -> std::string::String {
            let rms = libm::sqrt(runs.iter().map(|(e, _)| e * e).sum::<f64>() / runs.len() as f64);
            let mut times: Vec<usize> = runs.iter().map(|&(_, t)| t).collect();
            times.sort_unstable();
            let ms = |sample: usize| sample as f64 * 1e3 / DATA_RATE_HZ;
            let by_readout = times.iter().filter(|&&t| t <= READOUT).count();
            std::format!(
                "RMS error at 100 ms {rms:.5} g; within 0.1 % from {:.1} ms (median), {:.1} ms (95th percentile), {} of {} runs by 100 ms",
                ms(times[times.len() / 2]),
                ms(times[times.len() * 95 / 100]),
                by_readout,
                runs.len()
            )
        }
        let script = || {
            let mut script = Script::<2>::new(1.0);
            script.push(LoadEvent::step(0.0, DROP_G)).unwrap();
            script
        };

        let reference = SensorChain::reference();
        let mut amplifier_only = Disturbances::none();
        amplifier_only.amplifier_noise = true;
        let runs: Vec<(f64, usize)> = (0..RUNS)
            .map(|seed| {
                let mut adc = SimulatedAdc::new(reference, script(), amplifier_only, seed);
                run(&mut adc, reference.counts_per_gram(), reference.zero_code())
            })
            .collect();
        std::println!(
            "16-bit chain (INA114, 100 Hz Butterworth, its noise only): {:.1} counts/g, raw noise {:.4} g before the filter, {}",
            reference.counts_per_gram(),
            reference.amplifier_noise_g(),
            summary(&runs)
        );

        for adc_noise_lsb_rms in [crate::stm32_board::ADC_NOISE_LSB_RMS, 2.0] {
            let board = Stm32BoardChain {
                adc_noise_lsb_rms,
                ..Stm32BoardChain::reference()
            };
            let runs: Vec<(f64, usize)> = (0..RUNS)
                .map(|seed| {
                    let mut adc = Stm32BoardAdc::new(board, script(), Disturbances::none(), seed);
                    run(&mut adc, board.counts_per_gram(), board.zero_code())
                })
                .collect();
            std::println!(
                "12-bit STM32 board chain (INA114 at gain 385.6, 100 Hz Butterworth, ADC1 with {:.1} LSB RMS of its own): {:.3} counts/g, converter noise {:.4} g per sample (INA114 {:.4} g before the filter), {}",
                adc_noise_lsb_rms,
                board.counts_per_gram(),
                board.adc_noise_g(),
                board.chain.amplifier_noise_g(),
                summary(&runs)
            );
        }

        let chain = Ads131m02Chain::reference();
        let runs: Vec<(f64, usize)> = (0..RUNS)
            .map(|seed| {
                let mut adc = Ads131m02Adc::new(chain, script(), Disturbances::none(), seed);
                run(&mut adc, chain.counts_per_gram(), chain.zero_code())
            })
            .collect();
        std::println!(
            "ADS131M02 chain (gain 128, OSR 1024, its noise only): {:.1} counts/g, raw noise {:.4} g per sample, {}",
            chain.counts_per_gram(),
            chain.noise_g(),
            summary(&runs)
        );
    }

    /// The sinc3 settles in 3 output samples: a step in its input at an output boundary
    /// gives a partial output twice, the new level exactly on the third.
    #[test]
    fn sinc3_settles_in_three_samples() {
        let mut filter = Sinc3::new(0.0);
        let mut outputs = [0.0; 4];
        for output in &mut outputs {
            for _ in 0..SUBSAMPLES {
                filter.push(1.0);
            }
            *output = filter.output();
        }
        assert!(outputs[0] > 0.0 && outputs[0] < outputs[1] && outputs[1] < 1.0);
        assert!((outputs[2] - 1.0).abs() < 1e-12 && (outputs[3] - 1.0).abs() < 1e-12);
    }
}
