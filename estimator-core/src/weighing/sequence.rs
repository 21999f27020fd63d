//! The bookkeeping between a board's sample hand-off and its estimator task: sequence
//! numbers in, lost samples counted, nothing lost silently.
//!
//! The hand-off numbers every sample it takes (wrapping at 2³²) and skips the numbers of
//! samples it could not queue (a full queue, a DMA overrun); the estimator task checks
//! each number it receives against the one it expects. A stall that stops both (the CPU
//! held on a flash erase while the converter runs on) leaves no gap in the numbers: the
//! board measures the stall's length and asks [`SampleSequence::stall_loss`] how many
//! samples it cost. Written here, not in the firmware, so it is tested on the host.

/// The sequence check and the count of samples lost since boot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleSequence {
    next: u32,
    dropped: u32,
}

impl SampleSequence {
    /// Expecting sample 0, nothing lost.
    pub const fn new() -> Self {
        Self {
            next: 0,
            dropped: 0,
        }
    }

    /// Sample `sequence` arrived: how many were missing before it (counted as dropped).
    ///
    /// A number behind the one expected (less than half the number space ahead of it,
    /// modulo 2³²) is not a gap of billions: the hand-off started counting again (a
    /// restart of the pipeline while the hand-off ran on). The check follows it and
    /// counts nothing.
    pub fn accept(&mut self, sequence: u32) -> u32 {
        let gap = sequence.wrapping_sub(self.next);
        let missing = if gap < u32::MAX / 2 { gap } else { 0 };
        self.dropped = self.dropped.saturating_add(missing);
        self.next = sequence.wrapping_add(1);
        missing
    }

    /// Count `samples` lost without a gap in the numbers (see [`Self::stall_loss`]).
    pub fn count_lost(&mut self, samples: u32) {
        self.dropped = self.dropped.saturating_add(samples);
    }

    /// The number expected next: the samples accepted so far, modulo 2³².
    pub fn next(&self) -> u32 {
        self.next
    }

    /// Samples lost since boot (saturating at `u32::MAX`: 12 days of samples at 4 kHz).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The samples a stall lost: `converted` samples the converter took during it (its
    /// length times the sample rate), of which `accepted` reached the estimator meanwhile
    /// and up to `queued` may still sit in the hand-off queue (the queue's capacity), to
    /// arrive with their numbers. Never negative, never more than were converted.
    pub fn stall_loss(converted: u32, accepted: u32, queued: u32) -> u32 {
        converted.saturating_sub(accepted.saturating_add(queued))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_gap_is_counted_and_the_next_number_follows_the_sample() {
        let mut sequence = SampleSequence::new();
        assert_eq!(sequence.accept(0), 0);
        assert_eq!(sequence.accept(1), 0);
        assert_eq!(sequence.accept(5), 3);
        assert_eq!(sequence.next(), 6);
        assert_eq!(sequence.dropped(), 3);
    }

    #[test]
    fn the_numbers_wrap_at_two_to_the_32_without_a_phantom_loss() {
        let mut sequence = SampleSequence {
            next: u32::MAX - 1,
            dropped: 0,
        };
        for number in [u32::MAX - 1, u32::MAX, 0, 1] {
            assert_eq!(sequence.accept(number), 0, "at {number}");
        }
        // A gap across the wrap: u32::MAX lost with 0 and 1.
        let mut sequence = SampleSequence {
            next: u32::MAX,
            dropped: 0,
        };
        assert_eq!(sequence.accept(2), 3);
        assert_eq!(sequence.dropped(), 3);
    }

    #[test]
    fn a_hand_off_counting_again_is_not_billions_lost() {
        let mut sequence = SampleSequence::new();
        sequence.accept(100_000);
        let dropped = sequence.dropped();
        assert_eq!(sequence.accept(0), 0);
        assert_eq!(sequence.dropped(), dropped);
        assert_eq!(sequence.next(), 1);
    }

    #[test]
    fn the_lost_count_saturates_instead_of_wrapping() {
        let mut sequence = SampleSequence::new();
        sequence.count_lost(u32::MAX - 2);
        sequence.accept(10);
        sequence.count_lost(7);
        assert_eq!(sequence.dropped(), u32::MAX);
    }

    #[test]
    fn a_stall_costs_what_was_converted_less_what_arrived_or_may_still_arrive() {
        // 3 s of a flash erase at 4 kHz: 12,000 converted, 40 accepted, 64 queued.
        assert_eq!(SampleSequence::stall_loss(12_000, 40, 64), 11_896);
        assert_eq!(SampleSequence::stall_loss(50, 40, 64), 0);
        assert_eq!(SampleSequence::stall_loss(u32::MAX, u32::MAX, u32::MAX), 0);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2048))]

        /// Any start (near the wrap too) and any gaps: the count is the sum of the gaps,
        /// each gap is reported with the sample after it, and `next` follows.
        #[test]
        fn every_missing_number_is_counted_once(
            start in prop_oneof![Just(u32::MAX - 300), any::<u32>()],
            gaps in proptest::collection::vec(0u32..200, 1..200),
        ) {
            let mut sequence = SampleSequence { next: start, dropped: 0 };
            let mut number = start;
            let mut total = 0u64;
            for gap in gaps {
                number = number.wrapping_add(gap);
                prop_assert_eq!(sequence.accept(number), gap);
                total += u64::from(gap);
                number = number.wrapping_add(1);
                prop_assert_eq!(sequence.next(), number);
            }
            prop_assert_eq!(u64::from(sequence.dropped()), total);
        }
    }
}
