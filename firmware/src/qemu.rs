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
    /// The demo with a broken sample clock: the timer stops after
    /// [`Scene::STALL_AFTER_SAMPLES`], and the watchdog must end the run.
    Stall,
    /// The demo with a runaway recursion in the readout task at
    /// [`Scene::OVERFLOW_AT_SAMPLE`]: the stack guard must end the run with a fault.
    StackOverflow,
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
            Some(b"stall") => Ok(Self::Stall),
            Some(b"stack-overflow") => Ok(Self::StackOverflow),
            Some(_) => Err(UnknownScene),
        }
    }

    /// The simulated cell playing this scene.
    pub fn load_cell(self) -> qemu_scenes::LoadCell {
        match self {
            Self::Demo | Self::Stall | Self::StackOverflow => qemu_scenes::demo_scene(),
            Self::Commands => qemu_scenes::command_scene(),
            Self::CheckedDemo => qemu_scenes::checked_demo_scene(),
        }
    }
}

impl Scene {
    /// The `stall` scene's sample timer stops after this many samples (1 s).
    pub const STALL_AFTER_SAMPLES: u32 = 4_000;
    /// The `stack-overflow` scene's readout task recurses from this sample on (0.5 s).
    pub const OVERFLOW_AT_SAMPLE: u32 = 2_000;

    /// After how many samples the sample timer stops, in a scene that breaks it.
    pub fn stalls_after(self) -> Option<u32> {
        (self == Self::Stall).then_some(Self::STALL_AFTER_SAMPLES)
    }

    /// From which sample on the readout task overflows the stack, in a scene that does.
    pub fn overflows_stack_at(self) -> Option<u32> {
        (self == Self::StackOverflow).then_some(Self::OVERFLOW_AT_SAMPLE)
    }
}

/// Recurse until the stack runs out (the `stack-overflow` scene): each level keeps a
/// 64-byte frame alive across the call, so it cannot become a loop.
#[inline(never)]
pub fn exhaust_stack(depth: u32) -> u32 {
    let frame = core::hint::black_box([depth; 16]);
    if depth == u32::MAX {
        return frame[0];
    }
    exhaust_stack(depth + 1).wrapping_add(core::hint::black_box(frame)[15])
}

/// How long the watchdog waits for a new sample before its NMI ends the run (its reset
/// follows as long again later): 20 readout periods, far above the longest legitimate
/// stall on this board (a calibration record written to the RAM flash, microseconds).
pub const WATCHDOG_TIMEOUT_MS: u32 = 1_000;

/// The watchdog's NMI: no new sample reached the readout task within the timeout.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    defmt::error!(
        "watchdog: no new sample for {=u32} ms after sample={=u32}: the sample clock or a task stalled",
        WATCHDOG_TIMEOUT_MS,
        pipeline::LAST_FED_SAMPLE.load(core::sync::atomic::Ordering::Relaxed)
    );
    exit(false)
}

/// End the QEMU session with a status CI reads: 0 on success, 1 on failure.
pub fn exit(success: bool) -> ! {
    semihosting::process::exit(if success { 0 } else { 1 })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    crate::fault::report_panic(info)
}
