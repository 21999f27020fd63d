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

/// A scripted stand-in for the host-sim sensor model: a 25 Hz, ζ = 0.03 second-order cell
/// with pseudo-random noise, playing the demo scene. Used until `host-sim` provides its
/// `no_std` model.
pub mod scripted {
    use estimator_core::{AdcError, AdcSource};

    /// ADC counts per gram of the scripted chain.
    pub const COUNTS_PER_GRAM: f32 = 50.0;
    /// ADC counts of the empty pan.
    pub const ZERO_COUNTS: f32 = 20_000.0;
    const MAX_CODE: u32 = 65_535;

    /// The demo scene: (start second, load in grams).
    const SCENE: [(f32, f32); 4] = [(0.0, 0.0), (0.3, 138.32), (2.0, 0.0), (2.5, 250.0)];

    /// The scripted load cell.
    pub struct ScriptedCell {
        sample: u32,
        position_g: f32,
        velocity: f32,
        noise_state: u32,
        noise_g: f32,
    }

    impl ScriptedCell {
        /// The demo scene at 50 dB SNR relative to the 138.32 g step.
        pub fn demo_scene() -> Self {
            Self {
                sample: 0,
                position_g: 0.0,
                velocity: 0.0,
                noise_state: 0x1234_5678,
                noise_g: 138.32 / 316.23,
            }
        }

        fn load_g(&self) -> f32 {
            let t = self.sample as f32 / 4000.0;
            let mut load = 0.0;
            for (start, mass) in SCENE {
                if t >= start {
                    load = mass;
                }
            }
            load
        }

        fn uniform(&mut self) -> f32 {
            self.noise_state ^= self.noise_state << 13;
            self.noise_state ^= self.noise_state >> 17;
            self.noise_state ^= self.noise_state << 5;
            (self.noise_state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        }
    }

    impl AdcSource for ScriptedCell {
        fn max_code(&self) -> u32 {
            MAX_CODE
        }

        fn read(&mut self) -> Result<u32, AdcError> {
            let omega = 2.0 * core::f32::consts::PI * 25.0;
            let dt = 1.0 / 4000.0 / 4.0;
            let load = self.load_g();
            for _ in 0..4 {
                let accel =
                    omega * omega * (load - self.position_g) - 2.0 * 0.03 * omega * self.velocity;
                self.velocity += accel * dt;
                self.position_g += self.velocity * dt;
            }
            let noise = (self.uniform() + self.uniform() + self.uniform() + self.uniform())
                * 1.732_050_8
                * self.noise_g;
            self.sample += 1;
            let counts = ZERO_COUNTS + (self.position_g + noise) * COUNTS_PER_GRAM + 0.5;
            Ok(if counts <= 0.0 {
                0
            } else if counts >= MAX_CODE as f32 {
                MAX_CODE
            } else {
                counts as u32
            })
        }
    }
}
