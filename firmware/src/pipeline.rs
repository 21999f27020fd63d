//! What both boards share: the sample message, the estimator-side bookkeeping (sequence
//! numbers, dropped samples, readout cadence), the operator's commands on the scale, and
//! the readout and command line formats.

use estimator_core::command::{self, CalibrationStore, StoreFailure};
use estimator_core::{
    AdcSource, Calibration, CalibrationFailure, Command, CommandConfig, CommandOutcome,
    CommandRefusal, Commands, ConfigError, RawSample, Scale, ScaleConfig, ScaleReading,
};

/// Raw ADC sample rate of both boards.
pub const SAMPLE_RATE_HZ: u32 = 4_000;
/// Readout lines per second.
pub const READOUT_HZ: u32 = 20;
/// Raw samples between two readout lines.
pub const SAMPLES_PER_READOUT: u32 = SAMPLE_RATE_HZ / READOUT_HZ;
/// Depth of the hand-off queue: 16 ms of samples, far more than the estimator task ever
/// lags (it runs every sample); a full queue is counted, not hidden.
pub const QUEUE_CAPACITY: usize = 64;
/// Capacity (largest order) of the estimator in the firmware.
pub const ESTIMATOR_CAPACITY: usize = 8;

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
    let sample = match adc.read() {
        Ok(code) if adc.is_saturated(code) => RawSample::Saturated,
        Ok(code) => RawSample::Counts(code as i32),
        Err(_) => RawSample::Lost,
    };
    let _ = producer.enqueue(SampleMessage {
        sequence: *sequence,
        sample,
    });
    *sequence = sequence.wrapping_add(1);
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
}

/// The estimator task's state: the scale, the operator's commands on it, and the
/// bookkeeping around them.
pub struct Pipeline {
    scale: Scale<ESTIMATOR_CAPACITY>,
    commands: Commands,
    next_sequence: u32,
    dropped: u32,
}

impl Pipeline {
    /// A pipeline around a configured scale.
    pub fn new(scale: Scale<ESTIMATOR_CAPACITY>) -> Self {
        Self {
            scale,
            commands: Commands::new(CommandConfig::weighing_default(SAMPLE_RATE_HZ as f32)),
            next_sequence: 0,
            dropped: 0,
        }
    }

    /// Samples lost since boot.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Samples accepted so far: the time of a command, in samples.
    pub fn samples(&self) -> u32 {
        self.next_sequence
    }

    /// Decide an operator command against the current reading.
    pub fn command(&mut self, command: Command) -> Result<CommandOutcome, CommandRefusal> {
        self.commands
            .handle(command, &mut self.scale, self.next_sequence)
    }

    /// True while a calibration waits for its known mass.
    pub fn is_calibrating(&self) -> bool {
        self.commands.is_calibrating()
    }

    /// Refine a fresh tare and advance a calibration in progress (call it once per
    /// readout); `Some` when a calibration ends.
    pub fn poll_commands(&mut self) -> Option<Result<Calibration, CalibrationFailure>> {
        self.commands.poll(&mut self.scale, self.next_sequence)
    }

    /// Convert with `calibration` from now on (the estimate restarts, the tare clears).
    pub fn apply_calibration(&mut self, calibration: &Calibration) -> Result<(), ConfigError> {
        self.scale.recalibrate(calibration.counts_scale())
    }

    /// `samples` were lost without a gap in the sequence numbers (the CPU stalled while the
    /// converter ran on): count them and restart the estimate, as for a counted gap.
    pub fn samples_lost(&mut self, samples: u32) {
        if samples > 0 {
            self.dropped = self.dropped.saturating_add(samples);
            self.scale.push(RawSample::Lost);
        }
    }

    /// Process one queued sample; returns a readout every `SAMPLES_PER_READOUT` samples.
    /// A gap in the sequence numbers (a full queue) counts every missing sample as dropped
    /// and tells the scale once, which restarts its estimate after the gap.
    pub fn accept(&mut self, message: SampleMessage) -> Option<Readout> {
        let gap = message.sequence.wrapping_sub(self.next_sequence);
        if gap != 0 && gap < u32::MAX / 2 {
            self.dropped = self.dropped.saturating_add(gap);
            self.scale.push(RawSample::Lost);
        }
        self.next_sequence = message.sequence.wrapping_add(1);
        if message.sample == RawSample::Lost {
            self.dropped = self.dropped.saturating_add(1);
        }
        let reading = self.scale.push(message.sample);
        let samples_done = message.sequence.wrapping_add(1);
        if samples_done % SAMPLES_PER_READOUT == 0 {
            Some(Readout {
                sample: samples_done,
                reading,
                dropped: self.dropped,
            })
        } else {
            None
        }
    }
}

/// The scale configuration both boards run (see `firmware/README.md` for how it was chosen).
pub fn scale_config() -> ScaleConfig {
    ScaleConfig::weighing_default(SAMPLE_RATE_HZ as f32)
}

/// Emit one readout line. The host-side checker (`tests::e2e`) parses exactly this format.
pub fn log_readout(readout: &Readout) {
    let reading = &readout.reading;
    match reading.mass_g {
        Some(mass_g) => defmt::println!(
            "readout sample={=u32} mass_g={=f32} state={} since={=u32} dropped={=u32} changes={=u32}",
            readout.sample,
            mass_g,
            reading.state,
            reading.samples_since_change,
            readout.dropped,
            reading.load_changes
        ),
        None => defmt::println!(
            "readout sample={=u32} mass_g=none state={} since={=u32} dropped={=u32} changes={=u32}",
            readout.sample,
            reading.state,
            reading.samples_since_change,
            readout.dropped,
            reading.load_changes
        ),
    }
}

/// Log one command's outcome as `command sample=… <action>=<outcome> …`; the host-side
/// checker (`tests::commands`) parses exactly this format.
pub fn log_command(sample: u32, command: Command, result: &Result<CommandOutcome, CommandRefusal>) {
    let action = match command {
        Command::Tare => "tare",
        Command::ClearTare => "untare",
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
) where
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
            return;
        }
    };
    let stored = match command::store_calibration(store, &measured) {
        Ok(stored) => stored,
        Err(failure) => {
            log_store_failure(sample, &failure);
            return;
        }
    };
    let mut applied = Ok(());
    lock(&mut |pipeline| {
        sample = pipeline.samples();
        applied = pipeline.apply_calibration(&stored);
    });
    match applied {
        Ok(()) => defmt::println!(
            "command sample={=u32} calibrate=done counts_per_gram={=f32} zero_counts={=f32} (stored, read back, applied)",
            sample,
            stored.counts_per_gram,
            stored.zero_counts
        ),
        Err(error) => defmt::println!(
            "command sample={=u32} calibrate=failed (stored but refused by the scale: {})",
            sample,
            error
        ),
    }
}

fn log_store_failure<E: defmt::Format>(sample: u32, failure: &StoreFailure<E>) {
    defmt::println!(
        "command sample={=u32} calibrate=failed (Store({}))",
        sample,
        failure
    );
}
