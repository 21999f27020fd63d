//! The QEMU board: the simulated load cell behind a converter "data register", the scene
//! it plays (chosen on QEMU's command line; the scenes themselves are
//! `host_sim::qemu_scenes`, which the host tests replay), the calibration store (the core's
//! flash store over a NOR flash in RAM),
//! and the exits that tell CI how a run ended. A panic or fault must never exit with
//! status 0.

use core::mem::MaybeUninit;

use estimator_core::sensor::{AdcError, AdcSource};
use estimator_core::weighing::{self, FlashStore, RamFlash};
use estimator_core::weighing::{Calibration, CalibrationLimits, CalibrationSource};
use host_sim::qemu_scenes;

use crate::pipeline::{self, SampleMessage};

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

    /// Fill `chunk` with the next samples as the hand-off would queue them, each followed
    /// by its conversion, numbered from `sequence` on: the scene replayed without the timer
    /// (the benchmarks).
    pub fn fill(&mut self, chunk: &mut [SampleMessage], sequence: &mut u32) {
        for message in chunk.iter_mut() {
            let sample = pipeline::read_sample(self);
            self.convert();
            *message = SampleMessage {
                sequence: *sequence,
                sample,
            };
            *sequence += 1;
        }
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

    fn rail_guard_codes(&self) -> u32 {
        self.model.rail_guard_codes()
    }

    fn is_saturated(&self, code: u32) -> bool {
        self.model.is_saturated(code)
    }
}

/// The QEMU board's flash, which it does not have: two 1 KiB pages of NOR flash in RAM
/// (the core's `RamFlash`, byte-programmable like the STM32F4's).
pub type QemuFlash = RamFlash<2, 1024>;

/// The calibration store of the QEMU board: the core's power-fail-safe `FlashStore` over
/// [`QemuFlash`], the very code the STM32 board runs over its flash sectors. The record is
/// written at "the factory" (boot) and by the operator's calibration, and read back through
/// the same decoder.
pub type QemuCalibrationStore = FlashStore<QemuFlash>;

/// An empty store over an erased [`QemuFlash`].
pub fn calibration_store() -> QemuCalibrationStore {
    match FlashStore::new(QemuFlash::new(), 0..QemuFlash::CAPACITY) {
        Ok(store) => store,
        // Unreachable: two whole pages.
        Err(error) => {
            defmt::error!("calibration store refused its flash: {}", error);
            exit(false)
        }
    }
}

/// The calibration to use at boot: the stored one if valid and within `limits`, else the
/// nominal values + reason.
pub fn load_calibration(
    store: &mut QemuCalibrationStore,
    limits: &CalibrationLimits,
) -> (Calibration, CalibrationSource) {
    weighing::load_calibration(store, limits)
}

/// The semihosting command line names no scene this firmware knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub struct UnknownScene;

/// What the QEMU board plays, chosen by the first argument after the program on QEMU's
/// semihosting command line (`-semihosting-config …,arg=firmware,arg=commands`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum Scene {
    /// The demo (the default): drops and a removal, no commands needed.
    Demo,
    /// The command path's end-to-end scene: tare, refused tare, calibration, with the
    /// harness typing the commands on UART 0 (`tests::commands`).
    Commands,
    /// The demo after `qemu_scenes::CHECKED_DEMO_EMPTY_S` more of empty pan: the scale meters the
    /// empty pan's noise before the first drop, so every run after it is checked by the
    /// consistency check (`estimator_core::weighing`), which the demo's short empty periods
    /// never allow.
    CheckedDemo,
}

impl Scene {
    /// The scene QEMU was asked for; the demo when there is no argument (or semihosting
    /// cannot say). An unknown name is an error, so a typo in the harness fails the run
    /// instead of silently playing the demo.
    pub fn from_command_line() -> Result<Self, UnknownScene> {
        let mut buffer = [MaybeUninit::<u8>::uninit(); 96];
        let Ok(line) = semihosting::sys::arm_compat::sys_get_cmdline_uninit(&mut buffer) else {
            return Ok(Self::Demo);
        };
        // The first word is the program; the scene name follows.
        match line
            .split(|&byte| byte == b' ')
            .filter(|word| !word.is_empty())
            .nth(1)
        {
            None | Some(b"demo") => Ok(Self::Demo),
            Some(b"commands") => Ok(Self::Commands),
            Some(b"checked-demo") => Ok(Self::CheckedDemo),
            Some(_) => Err(UnknownScene),
        }
    }

    /// The simulated cell playing this scene.
    pub fn load_cell(self) -> qemu_scenes::LoadCell {
        match self {
            Self::Demo => qemu_scenes::demo_scene(),
            Self::Commands => qemu_scenes::command_scene(),
            Self::CheckedDemo => qemu_scenes::checked_demo_scene(),
        }
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
