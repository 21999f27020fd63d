//! The QEMU board: the simulated load cell behind a converter "data register", the scene
//! it plays (chosen on QEMU's command line; the scenes themselves are
//! `host_sim::qemu_scenes`, which the host tests replay), the calibration store (the core's
//! flash store over a NOR flash in RAM),
//! and the exits that tell CI how a run ended. A panic or fault must never exit with
//! status 0.

use core::mem::MaybeUninit;

use estimator_core::sensor::{AdcError, AdcSource};
use estimator_core::weighing::{self, CalibrationStore, FlashStore, FlashStoreError, RamFlash};
use estimator_core::weighing::{Calibration, CalibrationLimits, CalibrationSource};
use estimator_core::weighing::{RamFlashError, SettingsStore, RECORD_LEN, SETTINGS_LEN};
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

/// The QEMU board's store: the calibration and settings records in its RAM flash
/// (`FlashStore`, as on hardware). With an image file named on the semihosting command
/// line (the third word: `arg=firmware-qemu,arg=<scene>,arg=<file>`), the flash starts as
/// the file holds it and every write is copied back to the file, so a later run (a reset)
/// boots with what this one stored; without one it lives and dies with the run.
pub struct QemuCalibrationStore {
    store: FlashStore<QemuFlash>,
    image: Option<ImagePath>,
}

/// A host file's path, NUL-terminated for semihosting.
#[derive(Clone, Copy)]
pub struct ImagePath([u8; 96]);

impl ImagePath {
    fn c_str(&self) -> Option<&core::ffi::CStr> {
        core::ffi::CStr::from_bytes_until_nul(&self.0).ok()
    }
}

impl QemuCalibrationStore {
    /// After a successful write: the flash to the image file, if there is one. A failed
    /// copy is logged; the run goes on with the store in RAM.
    fn persist(&mut self) {
        let Some(path) = self.image else {
            return;
        };
        let mut bytes = [0u8; QemuFlash::CAPACITY as usize];
        for (slot, byte) in bytes.iter_mut().zip(self.store.flash().bytes()) {
            *slot = byte;
        }
        let written = path
            .c_str()
            .map(|path| semihosting::fs::write(path, bytes).is_ok());
        if written != Some(true) {
            defmt::error!(
                "flash image not written to its file: the next run will not see this write"
            );
        }
    }
}

impl CalibrationStore for QemuCalibrationStore {
    type Error = FlashStoreError<RamFlashError>;

    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error> {
        self.store.write_record(record)?;
        self.persist();
        Ok(())
    }

    fn read_record(&mut self) -> Result<Option<[u8; RECORD_LEN]>, Self::Error> {
        self.store.read_record()
    }
}

impl SettingsStore for QemuCalibrationStore {
    type Error = FlashStoreError<RamFlashError>;

    fn write_settings(&mut self, record: &[u8; SETTINGS_LEN]) -> Result<(), Self::Error> {
        self.store.write_settings(record)?;
        self.persist();
        Ok(())
    }

    fn read_settings(&mut self) -> Result<Option<[u8; SETTINGS_LEN]>, Self::Error> {
        self.store.read_settings()
    }
}

/// The board's store over its RAM flash, filled from the image file the semihosting
/// command line names (if any, and if it can be read: a missing file is an erased flash).
pub fn calibration_store() -> QemuCalibrationStore {
    let image = image_path();
    let mut bytes = [0xFFu8; QemuFlash::CAPACITY as usize];
    if let Some(path) = image.as_ref().and_then(ImagePath::c_str) {
        if let Ok(mut file) = semihosting::fs::File::open(path) {
            let mut filled = 0;
            while filled < bytes.len() {
                match semihosting::io::Read::read(&mut file, &mut bytes[filled..]) {
                    Ok(0) | Err(_) => break,
                    Ok(count) => filled += count,
                }
            }
            defmt::println!("flash image: {=usize} bytes read from its file", filled);
        } else {
            defmt::println!("flash image: no file yet (an erased flash)");
        }
    }
    match FlashStore::new(QemuFlash::from_image(&bytes), 0..QemuFlash::CAPACITY) {
        Ok(store) => QemuCalibrationStore { store, image },
        Err(error) => {
            defmt::error!("calibration store refused its flash: {}", error);
            exit(false)
        }
    }
}

/// The third word of the semihosting command line: the flash image's file.
fn image_path() -> Option<ImagePath> {
    let mut buffer = [MaybeUninit::<u8>::uninit(); 160];
    let line = semihosting::sys::arm_compat::sys_get_cmdline_uninit(&mut buffer).ok()?;
    let word = line
        .split(|&byte| byte == b' ')
        .filter(|word| !word.is_empty())
        .nth(2)?;
    let mut path = [0u8; 96];
    // Room for the terminating NUL; a longer path is not taken (no file rather than another).
    path.get_mut(..word.len())?.copy_from_slice(word);
    (word.len() < path.len()).then_some(ImagePath(path))
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
    /// Boot and weigh the empty pan of the demo for 0.5 s: what a reset keeps, shown in
    /// the boot log (with a flash image file from an earlier run).
    Boot,
    /// Three drops of one mass on the settled empty pan, the harness arming `record`
    /// before each (`qemu_scenes::record_scene`): the recordings `host-sim calibrate`
    /// chooses a method from.
    Record,
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
            Some(b"boot") => Ok(Self::Boot),
            Some(b"record") => Ok(Self::Record),
            Some(_) => Err(UnknownScene),
        }
    }

    /// The simulated cell playing this scene.
    pub fn load_cell(self) -> qemu_scenes::LoadCell {
        match self {
            Self::Demo | Self::Stall | Self::StackOverflow | Self::Boot => {
                qemu_scenes::demo_scene()
            }
            Self::Commands => qemu_scenes::command_scene(),
            Self::CheckedDemo => qemu_scenes::checked_demo_scene(),
            Self::Record => qemu_scenes::record_scene(),
        }
    }
}

impl Scene {
    /// Samples the scene plays before the board exits: the whole script, or 0.5 s of the
    /// `boot` scene.
    pub fn samples(self, load_cell: &qemu_scenes::LoadCell) -> u32 {
        let end_s = match self {
            Self::Boot => 0.5,
            _ => load_cell.script().end_s(),
        };
        (end_s * f64::from(pipeline::SAMPLE_RATE_HZ)) as u32
    }

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
