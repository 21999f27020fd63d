//! What both boards share: the sample message, the estimator-side bookkeeping (sequence
//! numbers, dropped samples, readout cadence) and the readout line format.

use estimator_core::{AdcSource, RawSample, Scale, ScaleConfig, ScaleReading};

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

/// The estimator task's state: the scale plus the bookkeeping around it.
pub struct Pipeline {
    scale: Scale<ESTIMATOR_CAPACITY>,
    next_sequence: u32,
    dropped: u32,
}

impl Pipeline {
    /// A pipeline around a configured scale.
    pub fn new(scale: Scale<ESTIMATOR_CAPACITY>) -> Self {
        Self {
            scale,
            next_sequence: 0,
            dropped: 0,
        }
    }

    /// Samples lost since boot.
    pub fn dropped(&self) -> u32 {
        self.dropped
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
