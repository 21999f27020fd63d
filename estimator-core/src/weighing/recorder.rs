//! Raw samples around a load change, kept for the host (the console's `record`): what
//! `host-sim calibrate` needs from a board to choose and check a method on its own cell.
//!
//! Armed, the recorder keeps the newest `N` raw samples in a ring; at the first load
//! change the scale reports after arming it goes on for the samples after the change and
//! then freezes, holding [`Recorder::BEFORE`] samples before the change (fewer if it was
//! armed later than that before it) and the rest from the change on. The frozen capture is
//! read out in time order ([`Recorder::copy`]) and released; nothing is recorded until it
//! is armed again. Pushing costs a store and a compare per sample while armed, nothing
//! otherwise.
//!
//! What it must never do: record over a capture that was not released, or hand out a
//! sample it did not record (lost and saturated samples stay what they were).

use super::scale::RawSample;

/// The ring's word for a lost sample (no code ever takes it: codes are at least 0).
const LOST: i32 = i32::MIN;
/// The ring's word for a saturated sample (on a rail; its code is not kept).
const SATURATED: i32 = i32::MIN + 1;

/// Why `record` was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordRefusal {
    /// This board has no room for a recording (its build gave the RAM to the model bank).
    NotBuilt,
    /// A capture is under way or not yet read out.
    Busy,
}

/// Where a recorder is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Idle,
    /// Waiting for a load change after `changes` of them.
    Armed {
        changes: u32,
    },
    /// After the change: this many samples still to record.
    Capturing {
        remaining: u32,
    },
    /// Frozen: `len` samples, the change at `change_index` of them.
    Done {
        len: u32,
        change_index: u32,
    },
}

/// A frozen capture's shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CaptureInfo {
    /// Samples held.
    pub len: u32,
    /// Index of the sample at which the load change was detected (samples before it are
    /// the pan as it was).
    pub change_index: u32,
}

/// A recorder of `N` raw samples.
#[derive(Clone, Debug)]
pub struct Recorder<const N: usize> {
    ring: [i32; N],
    written: u32,
    state: State,
}

impl<const N: usize> Default for Recorder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Recorder<N> {
    /// Samples kept from before the load change: a fifth of the capture.
    pub const BEFORE: usize = N / 5;

    /// An idle recorder (`const`: a board keeps it in a `static`).
    pub const fn new() -> Self {
        Self {
            ring: [0; N],
            written: 0,
            state: State::Idle,
        }
    }

    /// Record around the next load change after the `load_changes` the scale has counted
    /// so far; a capture under way or not yet read out is not given up.
    pub fn arm(&mut self, load_changes: u32) -> Result<(), RecordRefusal> {
        if N == 0 {
            return Err(RecordRefusal::NotBuilt);
        }
        match self.state {
            State::Idle | State::Armed { .. } => {
                self.written = 0;
                self.state = State::Armed {
                    changes: load_changes,
                };
                Ok(())
            }
            State::Capturing { .. } | State::Done { .. } => Err(RecordRefusal::Busy),
        }
    }

    /// Take one sample and the scale's load-change count after it; true when this sample
    /// completed the capture.
    #[inline]
    pub fn push(&mut self, sample: RawSample, load_changes: u32) -> bool {
        match self.state {
            State::Idle | State::Done { .. } => return false,
            State::Armed { changes } if changes != load_changes => {
                self.store(sample);
                self.state = State::Capturing {
                    remaining: (N - Self::BEFORE) as u32 - 1,
                };
            }
            State::Armed { .. } => self.store(sample),
            State::Capturing { remaining } => {
                self.store(sample);
                self.state = State::Capturing {
                    remaining: remaining - 1,
                };
            }
        }
        if let State::Capturing { remaining: 0 } = self.state {
            let len = self.written.min(N as u32);
            self.state = State::Done {
                len,
                change_index: len - (N - Self::BEFORE) as u32,
            };
            return true;
        }
        false
    }

    fn store(&mut self, sample: RawSample) {
        let word = match sample {
            RawSample::Counts(code) => code.max(0),
            RawSample::Saturated => SATURATED,
            RawSample::Lost => LOST,
        };
        self.ring[self.written as usize % N] = word;
        self.written = self.written.saturating_add(1);
    }

    /// Whether it is waiting for a load change or recording after one.
    pub fn is_recording(&self) -> bool {
        matches!(self.state, State::Armed { .. } | State::Capturing { .. })
    }

    /// The frozen capture's shape, once there is one.
    pub fn capture(&self) -> Option<CaptureInfo> {
        match self.state {
            State::Done { len, change_index } => Some(CaptureInfo { len, change_index }),
            _ => None,
        }
    }

    /// Sample `index` of the frozen capture, in time order.
    pub fn sample(&self, index: usize) -> Option<RawSample> {
        let State::Done { len, .. } = self.state else {
            return None;
        };
        if index >= len as usize {
            return None;
        }
        // The oldest sample held: the ring's next slot once it has wrapped.
        let oldest = if self.written as usize > N {
            self.written as usize % N
        } else {
            0
        };
        Some(match self.ring[(oldest + index) % N] {
            LOST => RawSample::Lost,
            SATURATED => RawSample::Saturated,
            code => RawSample::Counts(code),
        })
    }

    /// Copy the capture's samples from `start` into `out`; how many were copied (0 past
    /// the end or without a capture).
    pub fn copy(&self, start: usize, out: &mut [RawSample]) -> usize {
        let mut copied = 0;
        for (offset, slot) in out.iter_mut().enumerate() {
            match self.sample(start + offset) {
                Some(sample) => {
                    *slot = sample;
                    copied += 1;
                }
                None => break,
            }
        }
        copied
    }

    /// Give the capture up (it was read out): idle until armed again.
    pub fn release(&mut self) {
        self.state = State::Idle;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(recorder: &Recorder<10>) -> [i32; 10] {
        let mut out = [0; 10];
        for (index, slot) in out.iter_mut().enumerate() {
            *slot = match recorder.sample(index) {
                Some(RawSample::Counts(code)) => code,
                Some(RawSample::Lost) => -1,
                Some(RawSample::Saturated) => -2,
                None => -3,
            };
        }
        out
    }

    /// Armed long before the change: the two samples before it (a fifth of ten) and eight
    /// from it on, in order, then frozen: later samples and changes do not touch it.
    #[test]
    fn a_capture_holds_the_samples_around_the_change() {
        let mut recorder = Recorder::<10>::new();
        assert!(
            !recorder.push(RawSample::Counts(1), 0),
            "idle records nothing"
        );
        recorder.arm(3).unwrap();
        let mut done_at = None;
        for k in 0..40 {
            let changes = if k >= 20 { 4 } else { 3 };
            if recorder.push(RawSample::Counts(k), changes) {
                done_at = Some(k);
            }
        }
        assert_eq!(done_at, Some(27));
        assert_eq!(counts(&recorder), [18, 19, 20, 21, 22, 23, 24, 25, 26, 27]);
        let info = recorder.capture().unwrap();
        assert_eq!((info.len, info.change_index), (10, 2));
        assert_eq!(recorder.arm(4), Err(RecordRefusal::Busy));
        recorder.release();
        assert_eq!(recorder.capture(), None);
        assert!(recorder.arm(4).is_ok());
    }

    /// Armed just before the change: fewer samples before it, none invented; lost and
    /// saturated samples are kept as such.
    #[test]
    fn a_late_arm_keeps_what_it_saw_and_marks_bad_samples() {
        let mut recorder = Recorder::<10>::new();
        recorder.arm(0).unwrap();
        recorder.push(RawSample::Lost, 0);
        let mut done = false;
        for k in 0..8 {
            let sample = if k == 3 {
                RawSample::Saturated
            } else {
                RawSample::Counts(100 + k)
            };
            done = recorder.push(sample, 1);
        }
        assert!(done);
        let info = recorder.capture().unwrap();
        assert_eq!(
            info,
            CaptureInfo {
                len: 9,
                change_index: 1,
            }
        );
        assert_eq!(
            counts(&recorder),
            [-1, 100, 101, 102, -2, 104, 105, 106, 107, -3]
        );
        let mut out = [RawSample::Lost; 4];
        assert_eq!(recorder.copy(7, &mut out), 2);
        assert_eq!(out[..2], [RawSample::Counts(106), RawSample::Counts(107)]);
    }

    #[test]
    fn a_board_without_room_refuses() {
        let mut recorder = Recorder::<0>::new();
        assert_eq!(recorder.arm(0), Err(RecordRefusal::NotBuilt));
        assert!(!recorder.push(RawSample::Counts(1), 1));
    }
}
