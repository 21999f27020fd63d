//! What both boards share: the sample message and its hand-off, the estimator task's body
//! and its bookkeeping (sequence numbers, dropped samples, readout cadence), the operator's
//! commands on the scale, and the readout and command line formats (the host checkers in
//! `tests` parse exactly these).
//!
//! Written once so both boards run the same weighing path. Nothing here may compute in the
//! hand-off, wait, or lose a sample without counting it.

use core::fmt::Write as _;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::interrupt::InterruptNumber;
use rtic::Mutex;

use estimator_core::sensor::AdcSource;
use estimator_core::weighing::console::Unit;
use estimator_core::weighing::{self, CalibrationStore, StoreFailure};
use estimator_core::weighing::{
    Calibration, CalibrationFailure, CalibrationLimits, CalibrationSource, Command, CommandConfig,
    CommandOutcome, CommandRefusal, Commands, CountsScale, RawSample, SampleSequence, Scale,
    ScaleReading,
};
use estimator_core::weighing::{
    CaptureInfo, MethodRefusal, RecordRefusal, Recorder, Settings, SettingsStore,
    WeighingEstimator, WeighingMethod,
};
use estimator_core::ConfigError;

/// The weighing configuration, generated at build time from `firmware/weighing.toml` (what
/// `host-sim calibrate` wrote) by `build.rs`: `WEIGHING` and the estimator's sizes.
pub mod config {
    #![allow(clippy::excessive_precision, clippy::unreadable_literal)]
    use estimator_core::sensor::LoadCellModel;
    use estimator_core::weighing::{
        LoadCoverage, LoadScene, LoadScore, OnsetConfig, Prediction, WeighingConfig, WeighingMethod,
    };
    #[allow(unused_imports)] // Only a bank's configuration names it.
    use estimator_core::Interpolation;
    include!(concat!(env!("OUT_DIR"), "/weighing.rs"));
}

/// Raw ADC sample rate of both boards.
pub const SAMPLE_RATE_HZ: u32 = 4_000;
/// Readout lines per second.
pub const READOUT_HZ: u32 = 20;
/// Raw samples between two readout lines.
pub const SAMPLES_PER_READOUT: u32 = SAMPLE_RATE_HZ / READOUT_HZ;
/// Depth of the hand-off queue: 16 ms of samples, far more than the estimator task ever
/// lags (it runs every sample); a full queue is counted, not hidden.
pub const QUEUE_CAPACITY: usize = 64;
/// The configured method's estimator, sized for it (`config::ORDER_CAPACITY` etc.).
pub type FirmwareEstimator = WeighingEstimator<
    f32,
    { config::ORDER_CAPACITY },
    { config::MODEL_STATES },
    { config::BANK_CANDIDATES },
>;

/// Where the configured estimator lives: a `static` (an RTIC `init` local) that starts as
/// [`FirmwareEstimator::UNCONFIGURED`], built at link time, and that [`scale`] configures in
/// place. The scale holds a reference, so the estimator (a model bank takes tens of KB) is
/// never copied through the stack nor moved with the scale and the pipeline.
pub type EstimatorStorage = FirmwareEstimator;

/// The scale both boards run: the weighing decisions around the configured method.
pub type FirmwareScale = Scale<&'static mut FirmwareEstimator>;

/// Raw samples a `record` keeps: 1.25 s at 4 kHz (0.25 s before the load change, 1 s
/// after), 20 KB, on every image: a model bank's image has the RAM for it since its bank is
/// configured in place (`cargo xtask bench bank`: the boot's stack 33.5 KB, 92 KB before,
/// when no image with a bank had room for the samples).
pub const RECORD_SAMPLES: usize = 5_000;
/// The recorder of `record`, in a `static` of its own (an RTIC `init` local), as the
/// estimator is.
pub type FirmwareRecorder = Recorder<RECORD_SAMPLES>;

// The configuration was identified and scored at a sample rate: it must be the boards'.
const _: () = assert!(
    config::WEIGHING.model.sample_rate_hz == SAMPLE_RATE_HZ as f64,
    "firmware/weighing.toml: key `model.sample_rate_hz`: expected 4000.0, the boards' ADC rate (pipeline::SAMPLE_RATE_HZ); recalibrate at that rate"
);

/// One sample as the hand-off queues it: its sequence number and what the ADC gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleMessage {
    /// Counts every sample period from boot, whether or not the sample reached the queue.
    pub sequence: u32,
    /// The conversion, a rail, or a lost conversion.
    pub sample: RawSample,
}

/// The hand-off queue (lock-free single producer, single consumer).
pub type SampleQueue = heapless::spsc::Queue<SampleMessage, QUEUE_CAPACITY>;

/// The hand-off proper: take one conversion and queue it, no arithmetic beyond the
/// sequence number. A full queue drops the message; the gap in sequence numbers is how the
/// estimator task counts it.
#[inline(always)]
pub fn hand_off<A: AdcSource>(
    adc: &mut A,
    producer: &mut heapless::spsc::Producer<'_, SampleMessage>,
    sequence: &mut u32,
) {
    let _ = producer.enqueue(SampleMessage {
        sequence: *sequence,
        sample: read_sample(adc),
    });
    *sequence = sequence.wrapping_add(1);
}

/// One conversion as the weighing core takes it: counts, a rail, or a lost conversion.
#[inline(always)]
pub fn read_sample<A: AdcSource>(adc: &mut A) -> RawSample {
    RawSample::read(adc)
}

/// The estimator task of both boards: drain the hand-off queue into the pipeline, at most
/// its capacity per run so the task is bounded; each readout goes to `latest` and pends
/// `readout_task`. Runs above the command and readout tasks, so its lock on the pipeline
/// costs nothing; it must never log or wait.
pub fn estimate<I: InterruptNumber>(
    pipeline: &mut impl Mutex<T = Pipeline>,
    latest: &mut impl Mutex<T = Lines>,
    consumer: &mut heapless::spsc::Consumer<'_, SampleMessage>,
    readout_task: I,
) {
    pipeline.lock(|pipeline| {
        for _ in 0..QUEUE_CAPACITY {
            let Some(message) = consumer.dequeue() else {
                break;
            };
            let lines = pipeline.accept(message);
            if !lines.is_empty() {
                latest.lock(|latest| latest.merge(lines));
                rtic::pend(readout_task);
            }
        }
    });
}

/// What the readout task has to print: the latest 20 Hz readout, and a final reading the
/// moment a run reached one (not at the next tick; kept until printed even if a readout
/// follows before the task runs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lines {
    /// The latest readout tick.
    pub readout: Option<Readout>,
    /// The latest tick of the serial console's reading lines (at its own `rate`).
    pub console: Option<Readout>,
    /// The run's first final reading, when it has just been reached.
    pub final_reading: Option<Readout>,
}

impl Lines {
    /// Nothing to print.
    pub fn is_empty(&self) -> bool {
        self.readout.is_none() && self.console.is_none() && self.final_reading.is_none()
    }

    /// Take in newer lines: a newer readout replaces an unprinted one (the display shows
    /// the latest); a final reading is kept until printed.
    pub fn merge(&mut self, newer: Lines) {
        if newer.readout.is_some() {
            self.readout = newer.readout;
        }
        if newer.console.is_some() {
            self.console = newer.console;
        }
        if newer.final_reading.is_some() {
            self.final_reading = newer.final_reading;
        }
    }

    /// Print them (the final reading first: it was reached at or before the tick) and
    /// return the readout, for the task's regular work after a tick.
    pub fn log(&self) -> Option<Readout> {
        if let Some(final_reading) = &self.final_reading {
            log_final(final_reading);
        }
        if let Some(readout) = &self.readout {
            log_readout(readout);
        }
        self.readout
    }
}

/// One readout line's content.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Readout {
    /// Sequence number of the sample the reading follows (time = sample / rate).
    pub sample: u32,
    /// The scale's answer.
    pub reading: ScaleReading,
    /// Samples lost since boot (ADC overruns, full queue).
    pub dropped: u32,
    /// Where the calibration converting the reading came from: the line says `cal=stored`,
    /// or `cal=nominal` while the board weighs on the front end's nominal values (no valid
    /// record), on every line, not only in the boot log.
    pub calibration: CalibrationSource,
}

/// The estimator task's state: the scale, the operator's commands on it, and the
/// bookkeeping around them.
pub struct Pipeline {
    scale: FirmwareScale,
    limits: CalibrationLimits,
    calibration_source: CalibrationSource,
    commands: Commands,
    sequence: SampleSequence,
    /// The run (its load-change count) whose final reading was printed.
    final_run: Option<u32>,
    /// Samples between two of the serial console's reading lines.
    console_interval: u32,
    /// The console's reading lines per second.
    console_rate_hz: u16,
    /// The weighing method the scale runs (the configured one until the console's
    /// `method` or a stored setting changes it).
    method: WeighingMethod,
    /// Raw samples around a load change, for the console's `record`.
    recorder: &'static mut FirmwareRecorder,
}

/// The reading-line rates the console offers (`rate <Hz>`): whole divisors of the sample
/// rate, so every line falls on a sample, up to 100 lines a second (a 70-byte line at
/// 100 Hz is 7 kB/s, within a 115,200 baud UART).
pub const CONSOLE_RATES_HZ: [u16; 11] = [1, 2, 4, 5, 8, 10, 20, 25, 40, 50, 100];
/// The rates as the console's refusal lists them.
pub const CONSOLE_RATES_TEXT: &str = "lines per second, one of 1 2 4 5 8 10 20 25 40 50 100";

/// How a calibration that ended came out (what the console reports).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CalibrationEnd {
    /// Stored, read back and applied: the values in use now.
    Applied(Calibration),
    /// The measurement failed; the calibration in use stays.
    Failed(CalibrationFailure),
    /// The store failed; the calibration in use stays.
    NotStored,
}

impl Pipeline {
    /// A pipeline around a configured scale, on a board whose calibrations must fall within
    /// `limits`, converting with the calibration that came from `calibration_source`.
    pub fn new(
        scale: FirmwareScale,
        limits: CalibrationLimits,
        calibration_source: CalibrationSource,
        recorder: &'static mut FirmwareRecorder,
    ) -> Self {
        Self {
            scale,
            limits,
            calibration_source,
            commands: Commands::new(command_config(limits)),
            sequence: SampleSequence::new(),
            final_run: None,
            console_interval: SAMPLES_PER_READOUT,
            console_rate_hz: READOUT_HZ as u16,
            method: config::WEIGHING.method,
            recorder,
        }
    }

    /// Record the raw samples around the next load change (`record`), or why not.
    pub fn arm_record(&mut self) -> Result<(), RecordRefusal> {
        let changes = self.scale.reading().load_changes;
        self.recorder.arm(changes)
    }

    /// The recording once it is complete (and until [`Self::release_record`]).
    pub fn record_capture(&self) -> Option<CaptureInfo> {
        self.recorder.capture()
    }

    /// Copy the recording's samples from `start` into `out`; how many there were.
    pub fn record_samples(&self, start: usize, out: &mut [RawSample]) -> usize {
        self.recorder.copy(start, out)
    }

    /// The recording was read out: give it up.
    pub fn release_record(&mut self) {
        self.recorder.release();
    }

    /// The weighing method in use.
    pub fn method(&self) -> WeighingMethod {
        self.method
    }

    /// Run `method` from now on, with the rest of the board's weighing configuration
    /// (its model decides the valid region), or refuse it and keep the one in use. The run
    /// restarts as after a load change (`Scale::set_method`).
    pub fn set_method(&mut self, method: WeighingMethod) -> Result<(), MethodRefusal> {
        let weighing = weighing::WeighingConfig {
            method,
            ..config::WEIGHING
        };
        self.scale.set_method(&weighing)?;
        self.method = method;
        Ok(())
    }

    /// The console's reading lines per second.
    pub fn console_rate_hz(&self) -> u16 {
        self.console_rate_hz
    }

    /// What a reset should keep: the configuration in use, the console's rate, and `unit`.
    pub fn settings(&self, unit: Unit) -> Settings {
        Settings {
            config: self.scale_config(),
            console_rate_hz: self.console_rate_hz,
            unit,
            method: self.method,
        }
    }

    /// Console reading lines at `hz` from now on, if it is one of [`CONSOLE_RATES_HZ`].
    pub fn set_console_rate(&mut self, hz: u16) -> bool {
        if !CONSOLE_RATES_HZ.contains(&hz) {
            return false;
        }
        self.console_interval = SAMPLE_RATE_HZ / u32::from(hz);
        self.console_rate_hz = hz;
        true
    }

    /// The weighing decisions' configuration in use.
    pub fn scale_config(&self) -> weighing::ScaleConfig {
        *self.scale.config()
    }

    /// Decide with `config` from now on (the run restarts), or refuse it unchanged.
    pub fn reconfigure(&mut self, config: weighing::ScaleConfig) -> Result<(), ConfigError> {
        self.scale.reconfigure(config)
    }

    /// Start over as at boot, with the same scale configuration and the calibration in use
    /// (the bench replays a scene through the application's pipeline first: a second one
    /// would need a second estimator's worth of stack for a model bank). The restart counts as a load
    /// change; the noise metered on the empty pan is forgotten, as at boot.
    pub fn restart(&mut self) {
        self.scale.forget_noise_reference();
        self.scale.recalibrate(self.scale.counts_scale());
        self.commands = Commands::new(command_config(self.limits));
        self.sequence = SampleSequence::new();
        self.final_run = None;
    }

    /// Whether the runs from the next load change on are checked against a metered noise
    /// reference (the consistency check, `estimator_core::weighing`).
    pub fn noise_checked(&self) -> bool {
        self.scale.noise_reference().is_some()
    }

    /// Whether the scale hands its runs the empty pan's noise colour with enough block means
    /// for the step method's `u` to rest on it (`estimator_core::MIN_METERED_BLOCKS`).
    pub fn noise_coloured(&self) -> bool {
        self.scale
            .noise_autocovariance()
            .is_some_and(|colour| colour.blocks >= estimator_core::MIN_METERED_BLOCKS)
    }

    /// Samples lost since boot.
    pub fn dropped(&self) -> u32 {
        self.sequence.dropped()
    }

    /// Samples accepted so far: the time of a command, in samples.
    pub fn samples(&self) -> u32 {
        self.sequence.next()
    }

    /// Decide an operator command against the current reading.
    pub fn command(&mut self, command: Command) -> Result<CommandOutcome, CommandRefusal> {
        self.commands
            .handle(command, &mut self.scale, self.sequence.next())
    }

    /// True while a calibration waits for its known mass.
    pub fn is_calibrating(&self) -> bool {
        self.commands.is_calibrating()
    }

    /// Refine a fresh tare and advance a calibration in progress (call it once per
    /// readout); `Some` when a calibration ends.
    pub fn poll_commands(&mut self) -> Option<Result<Calibration, CalibrationFailure>> {
        self.commands.poll(&mut self.scale, self.sequence.next())
    }

    /// Convert with `calibration`, which the store gave back, from now on (the estimate
    /// restarts, the tare clears; the readout says `cal=stored`).
    pub fn apply_calibration(&mut self, calibration: &Calibration) {
        self.scale.recalibrate(calibration.counts_scale());
        self.calibration_source = CalibrationSource::Stored;
    }

    /// `samples` were lost without a gap in the sequence numbers (the CPU stalled while the
    /// converter ran on): count them and restart the estimate, as for a counted gap.
    pub fn samples_lost(&mut self, samples: u32) {
        if samples > 0 {
            self.sequence.count_lost(samples);
            self.scale.push(RawSample::Lost);
        }
    }

    /// Process one queued sample; returns a readout every `SAMPLES_PER_READOUT` samples,
    /// and the run's final reading on the sample that first reached it (once per load
    /// change). A gap in the sequence numbers (a full queue) counts every missing sample as
    /// dropped and tells the scale once, which restarts its estimate after the gap.
    pub fn accept(&mut self, message: SampleMessage) -> Lines {
        if self.sequence.accept(message.sequence) != 0 {
            let reading = self.scale.push(RawSample::Lost);
            self.recorder.push(RawSample::Lost, reading.load_changes);
        }
        if message.sample == RawSample::Lost {
            self.sequence.count_lost(1);
        }
        let reading = self.scale.push(message.sample);
        self.recorder.push(message.sample, reading.load_changes);
        let samples_done = message.sequence.wrapping_add(1);
        let tick = samples_done.is_multiple_of(SAMPLES_PER_READOUT);
        let console_tick = samples_done.is_multiple_of(self.console_interval);
        let first_final = reading.is_final && self.final_run != Some(reading.load_changes);
        if !(tick || console_tick || first_final) {
            return Lines::default();
        }
        if first_final {
            self.final_run = Some(reading.load_changes);
        }
        let line = Readout {
            sample: samples_done,
            reading,
            dropped: self.sequence.dropped(),
            calibration: self.calibration_source,
        };
        Lines {
            readout: tick.then_some(line),
            console: console_tick.then_some(line),
            final_reading: first_final.then_some(line),
        }
    }
}

/// A hardware watchdog: reset (or on QEMU, the NMI) unless fed in time.
pub trait Watchdog {
    /// Start the countdown over.
    fn feed(&mut self);
}

/// The sample count at the watchdog's last feed, for the watchdog's own report (its NMI
/// on QEMU cannot borrow the pipeline).
pub static LAST_FED_SAMPLE: AtomicU32 = AtomicU32::new(0);

/// The watchdog, fed only while samples advance: by the lowest-priority task (the
/// readout, pended after each readout line), and only when the estimator has taken new
/// samples since the last feed. So a stopped sample clock, a stalled DMA stream, a hung
/// estimator or a readout task starved or stuck all end in the watchdog's reset instead
/// of a frozen display.
/// The count it was last fed at is [`LAST_FED_SAMPLE`] (one watchdog per board).
pub struct SampleWatchdog<W> {
    watchdog: W,
}

impl<W: Watchdog> SampleWatchdog<W> {
    /// Around a started watchdog, fed now.
    pub fn new(mut watchdog: W, samples: u32) -> Self {
        watchdog.feed();
        LAST_FED_SAMPLE.store(samples, Ordering::Relaxed);
        Self { watchdog }
    }

    /// Feed it if `samples` (the pipeline's count) moved since the last feed; whether it
    /// was fed.
    pub fn service(&mut self, samples: u32) -> bool {
        if LAST_FED_SAMPLE.swap(samples, Ordering::Relaxed) == samples {
            return false;
        }
        self.watchdog.feed();
        true
    }
}

/// The operator commands' configuration on a board with these calibration limits.
fn command_config(limits: CalibrationLimits) -> CommandConfig {
    CommandConfig::weighing_default(SAMPLE_RATE_HZ as f32, limits)
}

/// The scale both boards run: the configured method (`firmware/weighing.toml`) with the
/// decisions' thresholds for it, converting counts with the board's `calibration`.
///
/// The estimator is configured where it lives, in `storage` (a model bank candidate by
/// candidate). Not inlined: in a frame of its own, the stack its build takes is free again
/// once the scale is built.
#[inline(never)]
pub fn scale(
    calibration: CountsScale,
    storage: &'static mut EstimatorStorage,
) -> Result<FirmwareScale, ConfigError> {
    Scale::configured_in(&config::WEIGHING, storage, calibration)
}

/// Log the configured method and what calibration predicted for it, as one line:
/// `config method=step n=5 D=24 lambda=1 … sample_rate_hz=4000 target_pct=0.05 readout_ms=100
/// p95_g=…` (the bench and the README quote it).
pub fn log_config() {
    let weighing = &config::WEIGHING;
    let target_pct = (weighing.target_relative * 100.0) as f32;
    let readout_ms = (weighing.readout_s * 1e3) as f32;
    let p95_g = weighing.prediction.p95_g as f32;
    let p95_upper_g = weighing.prediction.p95_upper_g as f32;
    let calibration_mass_g = weighing.calibration_mass_g as f32;
    match weighing.method {
        WeighingMethod::Step {
            order,
            decimation,
            forgetting,
        } => defmt::println!(
            "config method=step n={=usize} D={=u16} lambda={=f32} sample_rate_hz={=u32} target_pct={=f32} readout_ms={=f32} mass_g={=f32} p95_g={=f32} p95_bound_g={=f32}",
            order, decimation, forgetting as f32, SAMPLE_RATE_HZ, target_pct, readout_ms, calibration_mass_g, p95_g, p95_upper_g
        ),
        WeighingMethod::BiasCompensated { order, decimation } => defmt::println!(
            "config method=bias_compensated n={=usize} D={=u16} noise_variance_counts2={=f32} sample_rate_hz={=u32} target_pct={=f32} readout_ms={=f32} mass_g={=f32} p95_g={=f32} p95_bound_g={=f32}",
            order, decimation, weighing.noise_variance_counts2 as f32, SAMPLE_RATE_HZ, target_pct, readout_ms, calibration_mass_g, p95_g, p95_upper_g
        ),
        WeighingMethod::InstrumentalVariable { order, decimation } => defmt::println!(
            "config method=instrumental_variable n={=usize} D={=u16} sample_rate_hz={=u32} target_pct={=f32} readout_ms={=f32} mass_g={=f32} p95_g={=f32} p95_bound_g={=f32}",
            order, decimation, SAMPLE_RATE_HZ, target_pct, readout_ms, calibration_mass_g, p95_g, p95_upper_g
        ),
        WeighingMethod::ModelBank {
            decimation,
            candidates,
            ratio_min,
            ratio_max,
            interpolation,
            whitening,
        } => defmt::println!(
            "config method=model_bank D={=u16} K={=usize} ratios={=f32}-{=f32} interp={=u8} whiten={=usize} fn_hz={=f32} zeta={=f32} sample_rate_hz={=u32} target_pct={=f32} readout_ms={=f32} mass_g={=f32} p95_g={=f32} p95_bound_g={=f32}",
            decimation, candidates, ratio_min as f32, ratio_max as f32,
            interpolation.points(), whitening,
            weighing.model.natural_frequency_hz as f32, weighing.model.damping_ratio as f32,
            SAMPLE_RATE_HZ, target_pct, readout_ms, calibration_mass_g, p95_g, p95_upper_g
        ),
    }
}

/// Log the calibration the board booted with and where it came from (the stored record,
/// or the defaults and why): `calibration counts_per_gram=… zero_counts=… source=…`.
pub fn log_calibration(calibration: &Calibration, source: &CalibrationSource) {
    defmt::println!(
        "calibration counts_per_gram={=f32} zero_counts={=f32} source={}",
        calibration.counts_per_gram,
        calibration.zero_counts,
        source
    );
}

/// The settings a reset kept, applied at boot (the method, the configuration, the console's
/// rate; the caller gives the unit to its console), or the compiled-in ones and why: logged
/// either way as `settings stored capacity_g=… e_g=… rate_hz=… unit=… method=<spec>` or
/// `settings compiled-in (…)`. A stored method this image cannot run (another model or a
/// smaller estimator since) is logged `settings method refused (…)` and the configured
/// one stays; the rest of the record is used. Returns the unit to use.
pub fn load_settings<S: SettingsStore>(store: &mut S, pipeline: &mut Pipeline) -> Unit {
    let compiled_in = pipeline.scale_config();
    let loaded = weighing::load_settings(store, &compiled_in).and_then(|settings| {
        // A record written by another board's sample rate or rates is not this board's.
        let fits = settings.config.sample_rate_hz == compiled_in.sample_rate_hz
            && CONSOLE_RATES_HZ.contains(&settings.console_rate_hz);
        fits.then_some(settings)
            .ok_or(weighing::CalibrationError::OutOfDomain)
    });
    let settings = match loaded {
        Ok(settings) => settings,
        Err(reason) => {
            defmt::println!("settings compiled-in ({})", reason);
            return Unit::G;
        }
    };
    // The method first: changing it sets the decisions' residual drift for it, and the
    // stored configuration was saved with the method it was used with.
    if let Err(refusal) = pipeline.set_method(settings.method) {
        defmt::println!("settings method refused ({})", refusal);
    }
    match pipeline.reconfigure(settings.config) {
        Ok(()) => {
            pipeline.set_console_rate(settings.console_rate_hz);
            let mut spec = heapless::String::<64>::new();
            let _ = write!(spec, "{}", pipeline.method().spec());
            defmt::println!(
                "settings stored capacity_g={=f32} e_g={=f32} rate_hz={=u16} unit={=str} method={=str}",
                settings.config.capacity_g,
                settings.config.scale_interval_g,
                settings.console_rate_hz,
                settings.unit.name(),
                spec.as_str()
            );
            settings.unit
        }
        Err(error) => {
            defmt::println!("settings compiled-in (stored ones refused: {})", error);
            Unit::G
        }
    }
}

/// Log a method change asked for on the console: `method sample=… spec=… outcome=ok` or
/// `… outcome=refused (<reason>)` (an accepted change restarts the run).
pub fn log_method(sample: u32, method: &WeighingMethod, result: &Result<(), MethodRefusal>) {
    let mut spec = heapless::String::<64>::new();
    let _ = write!(spec, "{}", method.spec());
    match result {
        Ok(()) => defmt::println!(
            "method sample={=u32} spec={=str} outcome=ok",
            sample,
            spec.as_str()
        ),
        Err(refusal) => defmt::println!(
            "method sample={=u32} spec={=str} outcome=refused ({})",
            sample,
            spec.as_str(),
            refusal
        ),
    }
}

/// Store `settings` (a console change); false when the store failed (logged).
pub fn save_settings<S>(store: &mut S, settings: &Settings) -> bool
where
    S: SettingsStore,
    S::Error: defmt::Format,
{
    match store.write_settings(&settings.encode()) {
        Ok(()) => true,
        Err(error) => {
            defmt::println!("settings not stored: {}", error);
            false
        }
    }
}

/// Emit one readout line. The host-side checker (`tests::e2e`) parses exactly this format;
/// the host replays write it with these very format strings (`tests::firmware_log`, which
/// `cargo xtask test` checks against this image's defmt table).
pub fn log_readout(readout: &Readout) {
    let reading = &readout.reading;
    match (reading.mass_g, reading.uncertainty_g) {
        (Some(mass_g), Some(u_g)) => defmt::println!(
            "readout sample={=u32} mass_g={=f32} u_g={=f32} state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final={=u8}",
            readout.sample,
            mass_g,
            u_g,
            reading.state,
            reading.samples_since_change,
            readout.dropped,
            reading.load_changes,
            readout.calibration.label(),
            u8::from(reading.is_final)
        ),
        (Some(mass_g), None) => defmt::println!(
            "readout sample={=u32} mass_g={=f32} u_g=none state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final=0",
            readout.sample,
            mass_g,
            reading.state,
            reading.samples_since_change,
            readout.dropped,
            reading.load_changes,
            readout.calibration.label()
        ),
        (None, _) => defmt::println!(
            "readout sample={=u32} mass_g=none u_g=none state={} since={=u32} dropped={=u32} changes={=u32} cal={=str} final=0",
            readout.sample,
            reading.state,
            reading.samples_since_change,
            readout.dropped,
            reading.load_changes,
            readout.calibration.label()
        ),
    }
}

/// Emit a run's final reading as its own line, the moment it is reached (`final sample=…
/// mass_g=… u_g=… …`; `tests::e2e` parses exactly this format).
pub fn log_final(line: &Readout) {
    let reading = &line.reading;
    if let (Some(mass_g), Some(u_g)) = (reading.mass_g, reading.uncertainty_g) {
        defmt::println!(
            "final sample={=u32} mass_g={=f32} u_g={=f32} state={} since={=u32} changes={=u32} cal={=str}",
            line.sample,
            mass_g,
            u_g,
            reading.state,
            reading.samples_since_change,
            reading.load_changes,
            line.calibration.label()
        );
    }
}

/// Log one command's outcome as `command sample=… <action>=<outcome> …`; the host-side
/// checker (`tests::commands`) parses exactly this format, and the host replay writes it
/// with these format strings (`tests::firmware_log`, checked against this image).
pub fn log_command(sample: u32, command: Command, result: &Result<CommandOutcome, CommandRefusal>) {
    let action = match command {
        Command::Tare => "tare",
        Command::ClearTare => "untare",
        Command::Zero => "zero",
        Command::Calibrate { .. } => "calibrate",
        Command::CancelCalibration => "cancel",
    };
    match result {
        Ok(CommandOutcome::Tared { tare_g }) => {
            defmt::println!("command sample={=u32} tare=ok tare_g={=f32}", sample, tare_g)
        }
        Ok(CommandOutcome::TareCleared) => {
            defmt::println!("command sample={=u32} untare=ok", sample)
        }
        Ok(CommandOutcome::Zeroed) => defmt::println!("command sample={=u32} zero=ok", sample),
        Ok(CommandOutcome::CalibrationStarted {
            zero_counts,
            known_mass_g,
        }) => defmt::println!(
            "command sample={=u32} calibrate=zero_taken zero_counts={=f32} known_mass_g={=f32} (put the mass on)",
            sample,
            zero_counts,
            known_mass_g
        ),
        Ok(CommandOutcome::CalibrationCancelled) => {
            defmt::println!("command sample={=u32} cancel=ok", sample)
        }
        Err(refusal) => defmt::println!(
            "command sample={=u32} {=str}=refused ({})",
            sample,
            action,
            refusal
        ),
    }
}

/// Finish a calibration that ended: store the measured one through `store` (write, read
/// back through the CRC decoder) and apply only what the store gave back; log the outcome
/// as `command sample=… calibrate=done|failed …`. `lock` gives the pipeline for a moment;
/// the store is written outside it, so a slow flash write never holds up the estimator
/// task's lock.
pub fn finish_calibration<S>(
    result: Result<Calibration, CalibrationFailure>,
    store: &mut S,
    mut lock: impl FnMut(&mut dyn FnMut(&mut Pipeline)),
) -> CalibrationEnd
where
    S: CalibrationStore,
    S::Error: defmt::Format,
{
    let mut sample = 0;
    lock(&mut |pipeline| sample = pipeline.samples());
    let measured = match result {
        Ok(measured) => measured,
        Err(failure) => {
            defmt::println!(
                "command sample={=u32} calibrate=failed ({})",
                sample,
                failure
            );
            return CalibrationEnd::Failed(failure);
        }
    };
    let stored = match weighing::store_calibration(store, &measured) {
        Ok(stored) => stored,
        Err(failure) => {
            log_store_failure(sample, &failure);
            return CalibrationEnd::NotStored;
        }
    };
    lock(&mut |pipeline| {
        sample = pipeline.samples();
        pipeline.apply_calibration(&stored);
    });
    defmt::println!(
        "command sample={=u32} calibrate=done counts_per_gram={=f32} zero_counts={=f32} (stored, read back, applied)",
        sample,
        stored.counts_per_gram,
        stored.zero_counts
    );
    CalibrationEnd::Applied(stored)
}

fn log_store_failure<E: defmt::Format>(sample: u32, failure: &StoreFailure<E>) {
    defmt::println!(
        "command sample={=u32} calibrate=failed (Store({}))",
        sample,
        failure
    );
}
