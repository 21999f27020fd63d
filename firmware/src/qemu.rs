//! The QEMU board: the simulated load cell behind a converter "data register", the
//! RAM-backed calibration store, and the exits that tell CI how a run ended.

use estimator_core::calibration::{self, Calibration, CalibrationSource, RECORD_LEN};
use estimator_core::{AdcError, AdcSource};

/// The simulated converter as the hand-off sees it: a data register holding the latest
/// conversion, read once per timer tick. Stepping the sensor model (`convert`) is the
/// simulated analogue hardware; on the real board that is silicon, so it runs after the
/// hand-off and is not part of its instruction count.
pub struct SimulatedConverter<M: AdcSource> {
    model: M,
    data_register: Option<Result<u32, AdcError>>,
}

impl<M: AdcSource> SimulatedConverter<M> {
    /// A converter with the first conversion already done, like a free-running ADC.
    pub fn new(mut model: M) -> Self {
        let first = model.read();
        Self {
            model,
            data_register: Some(first),
        }
    }

    /// Run the next conversion. A conversion nobody read is an overrun, as on the STM32.
    pub fn convert(&mut self) {
        let next = self.model.read();
        self.data_register = Some(match self.data_register {
            Some(_) => Err(AdcError::Overrun),
            None => next,
        });
    }
}

impl<M: AdcSource> AdcSource for SimulatedConverter<M> {
    fn max_code(&self) -> u32 {
        self.model.max_code()
    }

    #[inline(always)]
    fn read(&mut self) -> Result<u32, AdcError> {
        self.data_register.take().unwrap_or(Err(AdcError::NotReady))
    }

    fn is_saturated(&self, code: u32) -> bool {
        self.model.is_saturated(code)
    }
}

/// The calibration store of the QEMU board: a record in RAM, written at "the factory"
/// (boot) and read back through the same decoder as flash on the hardware.
pub struct RamCalibrationStore {
    record: [u8; RECORD_LEN],
}

impl RamCalibrationStore {
    /// A store holding `record` (possibly corrupted, to exercise the fallback).
    pub fn with_record(record: [u8; RECORD_LEN]) -> Self {
        Self { record }
    }

    /// The calibration to use at boot: the stored one if valid, else `defaults` + reason.
    pub fn load(&self, defaults: Calibration) -> (Calibration, CalibrationSource) {
        calibration::load_or_default(Some(&self.record), defaults)
    }
}

/// End the QEMU session with a status CI reads: 0 on success, 1 on failure.
pub fn exit(success: bool) -> ! {
    semihosting::process::exit(if success { 0 } else { 1 })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    exit(false)
}

#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc={=u32:#010x}", frame.pc());
    exit(false)
}

/// The simulated load cell: host-sim's `no_std` model of the reference chain (load cell,
/// INA114, 3rd-order Butterworth, 16-bit ADC), the same code the host studies run.
pub mod load_cell {
    use estimator_core::{AdcSource, Calibration, CalibrationError};
    use host_sim::{
        white_noise_for_snr, Disturbances, LoadEvent, Script, SensorChain, SimulatedAdc,
    };

    /// The simulated cell with room for eight scripted load changes.
    pub type LoadCell = SimulatedAdc<8>;

    /// Noise seed of the demo scene (fixed, so a run is reproducible; not chosen by result).
    pub const DEMO_SEED: u64 = 1;
    /// Noise seed of the factory calibration run (a different cell session).
    pub const CALIBRATION_SEED: u64 = 0x00ca_1b7a;
    /// The known mass of the factory calibration.
    pub const CALIBRATION_MASS_G: f64 = 200.0;

    /// Issue 4's demo scene: empty 0.3 s, 138.32 g, removed at 2.0 s, 250 g at 2.5 s, end
    /// at 4.0 s, 50 dB SNR.
    pub fn demo_scene() -> LoadCell {
        SimulatedAdc::reference_demo(DEMO_SEED)
    }

    /// The chain's nominal gain and zero: the fallback if the stored record is unusable.
    pub fn nominal_calibration() -> Calibration {
        let chain = SensorChain::reference();
        Calibration {
            counts_per_gram: chain.counts_per_gram() as f32,
            zero_counts: chain.zero_code() as f32,
        }
    }

    /// The factory procedure on a simulated cell with the demo's noise: the mean code of
    /// the empty pan over 0.5–2.0 s, then the mean with the known mass over 4.0–6.0 s (the
    /// cell has settled far below the noise by then), and `Calibration::from_known_mass`.
    pub fn factory_calibration() -> Result<Calibration, CalibrationError> {
        const RATE: u32 = 4000;
        let chain = SensorChain::reference();
        let mut script = Script::<8>::new(6.0);
        script
            .push(LoadEvent::step(2.0, CALIBRATION_MASS_G))
            .map_err(|_| CalibrationError::NoSpan)?;
        let mut disturbances = Disturbances::white(white_noise_for_snr(
            &chain,
            host_sim::simulated::REFERENCE_STEP_G,
            host_sim::simulated::REFERENCE_SNR_DB,
            host_sim::simulated::SNR_WINDOW_SAMPLES,
        ));
        disturbances.amplifier_noise = true;
        let mut cell = SimulatedAdc::new(chain, script, disturbances, CALIBRATION_SEED);
        let (mut empty_sum, mut empty_count) = (0u64, 0u32);
        let (mut loaded_sum, mut loaded_count) = (0u64, 0u32);
        for sample in 0..6 * RATE {
            let code = match cell.read() {
                Ok(code) if !cell.is_saturated(code) => code as u64,
                _ => return Err(CalibrationError::NoSpan),
            };
            if (RATE / 2..2 * RATE).contains(&sample) {
                empty_sum += code;
                empty_count += 1;
            } else if sample >= 4 * RATE {
                loaded_sum += code;
                loaded_count += 1;
            }
        }
        let empty = empty_sum as f64 / empty_count as f64;
        let loaded = loaded_sum as f64 / loaded_count as f64;
        Calibration::from_known_mass(empty as f32, loaded as f32, CALIBRATION_MASS_G as f32)
    }
}
