//! The trend test: a straight line through the last [`TREND_WINDOW_BLOCKS`] block means of
//! the raw signal, and a t test on its slope (Student 1908; the residuals' own variance, so
//! the test needs no metered noise and holds on any pan).
//!
//! Why a third change test: a trickle (sand, a leaking cup) is a ramp, and the estimator
//! averages its run, so its reading lags the load by about the rate times half the run.
//! The CUSUM tests compare samples with that reading; on a noisy pan (40 dB: one block mean
//! of 0.1 s scatters by 0.05 g, the permissible error of a small load) their drift
//! allowance hides a lag of a few hundredths of a gram for seconds, and a reading 0.07 g
//! behind a 0.04 g/s trickle was shown stable (`host-sim torture --runs 1000 --seed 1`:
//! 85 of the 100 silent wrong readings were trickles; 15 of 29 with this test, and the
//! trickles' shown lines fell from 65,515 to 28,481: a trickle is mostly not shown
//! settled now). A slope is seen by its accumulated effect instead: over the 10 s window
//! of 0.1 s blocks its standard error is 0.035 σ_block per second.
//!
//! Not seen: a trickle that begins within about 3.5 s of a load put on or taken off, of
//! power-up or of a fault (the window must hold 2 s of the new load's settled blocks), on
//! a pan noisy enough that the reading's lag reaches the permissible error before then
//! (test `a_trickle_on_a_noisy_pan_is_seen_by_its_slope` says where; each trickle the
//! 1,000-run torture still shows settled wrong began 1.2–3.7 s after a hand placement or
//! removal).
//!
//! The window spans load changes: a trickle goes on across the restarts it causes (and
//! the false alarms a noisy pan gives the CUSUM tests), and the evidence for it should too.
//! A change the CUSUM tests saw may be a real step, though, and a step in the window would
//! look like a slope until it left. So at such an alarm the window marks the moment, skips
//! the blocks while a fresh load may ring (`raw_arm_samples` after a fast change, or
//! until a whole block rings no more than 1.5 times the pan's own ringing on settled runs
//! or moves a block mean by a tenth of the permissible error: `Scale::ringing_over`; none
//! after a slow one), and once [`STEP_DECISION_BLOCKS`] blocks follow, asks whether they
//! lie where the line through the blocks before predicts: if not (by four standard
//! errors), it was a step, and the blocks before it are dropped. The trend test's own
//! alarms are judged the same way (without skipping): a trickle that has stopped leaves
//! the line, and the ramp before it goes. The split is known, not searched: the best split
//! of a window that was flat and then rose looks like a step, and cutting there left too
//! little of a trickle to see it. Blocks carry their time, so the
//! skipped ones leave a gap, not a kink. A fault (lost or saturated samples) or a new
//! calibration starts the window over. Block means are taken against the calibrated zero,
//! so zero tracking and zero setting do not look like a trend.
//!
//! A slope alarms only when it matters: significant (|t| above [`TREND_T`] with at least
//! [`TREND_MIN_BLOCKS`] in the window) *and* lagging the reading by more than
//! [`TREND_LAG_OF_PERMISSIBLE`] of the permissible error (the rate times half the run, or
//! times [`TREND_LAG_S`] if that is longer).
//! A creeping cell on a quiet pan (0.005 g/s after a placement) is significant within
//! seconds but lags only after a long run, and is then restarted rather than shown behind.
//! A run the trend test restarted is not final before the raw tests are armed again
//! (1.5 s; `Scale::reading`), as it is not stable: a fresh fit of a ramp's few hundred
//! samples was final 0.09 g off with u = 0.004 g.
//!
//! The window also vouches for a settled reading (`distance_bound_g`, asked at each block
//! by `Scale::push_trend`): the tests above alarm only once a slope is *seen*, and on a
//! noisy pan a trickle begun within a few seconds of a change is not seen before the
//! reading lags it by the permissible error (`host-sim torture --runs 10000 --seed 1`: 91
//! of 138 silent wrong readings were such trickles). So a reading is shown stable, empty or
//! final only while the load, by the lines through the window's last 100, 32 and 16 blocks
//! (their values at the end of the next block: the newest block's mean is the load half a
//! block before it ended, and the bound vouches until the next block ends), lies within the
//! permissible error of it, each line's value's standard error included [`PROOF_T`] times
//! (Student's t for the line's own degrees of freedom at z = 2.5): its absence of motion
//! shown, not merely not refuted. The short lines see a ramp begun in a long flat window,
//! which the window's own line barely follows. With fewer than [`TREND_PROOF_MIN_BLOCKS`]
//! blocks, or while a step is judged (up to the first 1.8 s after a fast change), the
//! window says nothing and the other tests decide alone: a trickle can have built only a
//! small lag in a run that young. The price is paid on noisy pans: where the 16 newest
//! blocks' line is uncertain by about the permissible error (a block of 0.1 s scattering by
//! 0.04 g against 0.05 g permissible), small loads are not shown stable at all. The
//! 10,000-run torture went from 138 to 92 silent wrong readings (trickles 91 to 47) and
//! showed 6.1 % fewer readout lines settled, with two standard errors; with the 8 newest
//! blocks' line too, 79 and 10.7 % fewer. Two standard errors are a one-sided 3.3 % per
//! look on the line of 16 blocks (14 degrees of freedom), and a trickle is looked at once a
//! block: Student's t at z = 2.5, from 10 blocks, took it to 73 (trickles 29) and 4.0 %
//! fewer lines settled again; from 5 blocks to 68 and 6.2 % fewer; a flat three to 65 and
//! 6.6 % fewer.
//!
//! Cost: 100 means and their times (800 B); four passes over the window per 0.1 s block
//! (the slope, and the three lines that vouch).

use crate::numerics::student::t_quantile;

/// Block means in the window: 10 s of the default 0.1 s blocks.
pub(super) const TREND_WINDOW_BLOCKS: usize = 100;

/// Blocks the test needs before it judges (2 s of 0.1 s blocks; 18 degrees of freedom).
pub(super) const TREND_MIN_BLOCKS: usize = 20;

/// The |t| of a slope that is a trend. Four: at 18 degrees of freedom a still load passes
/// it once in about 1,300 looks, and the looks of a sliding window are far from
/// independent.
pub(super) const TREND_T: f32 = 4.0;

/// The lag (rate times half the run) a significant slope must have reached, as a part of
/// the permissible error of the load shown, before it restarts the run.
pub(super) const TREND_LAG_OF_PERMISSIBLE: f32 = 0.25;

/// The least lag a significant slope is charged with, s: a run restarted moments ago
/// lags little yet, but will, and the slope of a window that began before the trickle
/// (flat, then rising) understates the rate (a 0.05 g/s trickle fitted 0.017 g/s after 4 s).
pub(super) const TREND_LAG_S: f32 = 1.0;

/// Blocks the bound on the load now needs (`Trend::distance_bound_g`): 10 (1 s of 0.1 s
/// blocks, 8 degrees of freedom). A younger line's last value is too uncertain to vouch
/// with: on 5 blocks Student's t (5.3 at 3 degrees of freedom) times its standard error is
/// four block scatters: a settled empty pan with 0.4 g of raw noise was no longer shown
/// empty when its noise is metered (the `noise` tests, and the QEMU demo's check). At 5
/// with a flat two standard errors, the young window vouched at 1.5 block scatters.
pub(super) const TREND_PROOF_MIN_BLOCKS: usize = 10;

/// How far past the newest block's mean `Trend::distance_bound_g` takes each line: the
/// newest block's mean is the load half a block ago, and the bound vouches for the readings
/// until the next block ends, one block more.
const PROOF_AHEAD_BLOCKS: f32 = 1.5;

/// The spans, newest blocks, whose lines `Trend::distance_bound_g` asks.
const PROOF_SPANS: [usize; 3] = [TREND_WINDOW_BLOCKS, 32, 16];

/// The standard normal quantile whose Student counterpart, for the degrees of freedom of
/// each line's own variance, is the number of standard errors of a line's last value added
/// to its distance from the reading ([`PROOF_T`]): 2.5, a one-sided 0.6 % per look. At a
/// flat 2 (stop 32) a line of 16 blocks (14 degrees of freedom: 2 is a one-sided 3.3 %
/// there) vouched for readings a trickle had left behind in 47 of the 92 silent wrong
/// readings of `host-sim torture --runs 10000 --seed 1`.
const TREND_PROOF_Z: f64 = 2.5;

/// Student's t at [`TREND_PROOF_Z`] for a line of `blocks` blocks (`blocks − 2` degrees of
/// freedom; 2.87 at 16 blocks, 2.66 at 32, 2.55 at 100), for 3 blocks and more.
const PROOF_T: [f32; TREND_WINDOW_BLOCKS + 1] = proof_t();

const fn proof_t() -> [f32; TREND_WINDOW_BLOCKS + 1] {
    let mut table = [f32::INFINITY; TREND_WINDOW_BLOCKS + 1];
    let mut blocks = 3;
    while blocks <= TREND_WINDOW_BLOCKS {
        table[blocks] = t_quantile(TREND_PROOF_Z, (blocks - 2) as f64) as f32;
        blocks += 1;
    }
    table
}

/// The part of the permissible error that distance and its standard errors may reach on
/// a settled reading.
pub(super) const TREND_PROOF_OF_PERMISSIBLE: f32 = 1.0;

/// Blocks after a CUSUM alarm (and its settling) on which the step is judged.
pub(super) const STEP_DECISION_BLOCKS: usize = 3;

/// How many standard errors off the line before it the blocks after an alarm must lie to
/// make it a step.
const STEP_T: f32 = 4.0;

/// A fitted slope and its t statistic, and the line through the whole window it is the
/// slope of (`Trend::distance_bound_g` asks it again).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Slope {
    /// Grams per block.
    pub(super) per_block_g: f32,
    /// The slope over its standard error (infinite for a noise-free ramp, 0 for a
    /// noise-free constant).
    pub(super) t: f32,
    whole: Line,
}

impl Slope {
    /// Blocks in the window.
    pub(super) fn blocks(&self) -> usize {
        self.whole.blocks
    }
}

/// A line fitted to some blocks of the window: its value at the blocks' mean time, its
/// slope per block, and the residual variance (`None` below three blocks).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Line {
    time: f32,
    level: f32,
    per_block: f32,
    sxx: f32,
    blocks: usize,
    variance: Option<f32>,
}

/// The window of timed block means and the block in progress.
#[derive(Clone, Debug)]
pub(super) struct Trend {
    means_g: [f32; TREND_WINDOW_BLOCKS],
    /// Each mean's block number (the clock below when it ended).
    times: [u32; TREND_WINDOW_BLOCKS],
    /// Where the next block goes, and how many the window holds.
    next: usize,
    filled: usize,
    /// Blocks ended since the window started, taken or skipped.
    clock: u32,
    /// Σ grams and samples of the block in progress.
    sum_g: f32,
    samples: u32,
    /// Blocks still to skip (a fresh load rings).
    skip_blocks: u32,
    /// After a CUSUM alarm: the blocks before it, until the step is judged.
    split: Option<usize>,
}

impl Trend {
    /// An empty window that skips its first `skip_blocks` blocks.
    pub(super) fn new(skip_blocks: u32) -> Self {
        Self {
            means_g: [0.0; TREND_WINDOW_BLOCKS],
            times: [0; TREND_WINDOW_BLOCKS],
            next: 0,
            filled: 0,
            clock: 0,
            sum_g: 0.0,
            samples: 0,
            skip_blocks,
            split: None,
        }
    }

    /// Blocks ended since the window started.
    pub(super) fn clock(&self) -> u32 {
        self.clock
    }

    /// Start over (a fault, a new calibration): nothing before it counts.
    pub(super) fn clear(&mut self, skip_blocks: u32) {
        *self = Self::new(skip_blocks);
    }

    /// Blocks are being skipped while a fresh load may ring.
    pub(super) fn skipping(&self) -> bool {
        self.skip_blocks > 0
    }

    /// The ringing is measured to be over: take the blocks from the next on.
    pub(super) fn end_skip(&mut self) {
        self.skip_blocks = 0;
    }

    /// A CUSUM test alarmed: mark the moment, skip `skip_blocks` (a fresh load rings),
    /// and judge the step once [`STEP_DECISION_BLOCKS`] blocks follow. The block in
    /// progress is dropped (it straddles the change).
    pub(super) fn changed(&mut self, skip_blocks: u32) {
        self.split = Some(self.filled);
        self.skip_blocks = skip_blocks;
        self.sum_g = 0.0;
        self.samples = 0;
    }

    /// One good sample, grams above the calibrated zero; the fitted slope when it completed
    /// a block of `block_samples`, the window holds enough blocks and no step is being
    /// judged. A sample that is not finite starts the window over.
    pub(super) fn push(&mut self, gross_g: f32, block_samples: u32) -> Option<Slope> {
        if !gross_g.is_finite() {
            self.clear(0);
            return None;
        }
        self.sum_g += gross_g;
        self.samples += 1;
        if self.samples < block_samples.max(1) {
            return None;
        }
        let mean = self.sum_g / self.samples as f32;
        self.sum_g = 0.0;
        self.samples = 0;
        self.clock = self.clock.wrapping_add(1);
        if self.skip_blocks > 0 {
            self.skip_blocks -= 1;
            return None;
        }
        if self.filled == TREND_WINDOW_BLOCKS {
            // The oldest block leaves; so does a split's share of it.
            self.split = self.split.map(|before| before.saturating_sub(1));
        }
        self.means_g[self.next] = mean;
        self.times[self.next] = self.clock;
        self.next = (self.next + 1) % TREND_WINDOW_BLOCKS;
        self.filled = (self.filled + 1).min(TREND_WINDOW_BLOCKS);
        if let Some(before) = self.split {
            if self.filled - before < STEP_DECISION_BLOCKS {
                return None;
            }
            self.judge_step(before);
        }
        if self.filled < TREND_PROOF_MIN_BLOCKS {
            return None;
        }
        let line = self.line(0, self.filled);
        let variance = line.variance?;
        let standard_error = crate::numerics::real::Real::sqrt(variance / line.sxx);
        let t = if line.per_block == 0.0 {
            0.0
        } else if standard_error > 0.0 {
            line.per_block / standard_error
        } else {
            f32::INFINITY.copysign(line.per_block)
        };
        Some(Slope {
            per_block_g: line.per_block,
            t,
            whole: line,
        })
    }

    /// How far `value_g` may be from the load now, by the lines through the window's
    /// last [`PROOF_SPANS`] blocks (each of at least [`TREND_PROOF_MIN_BLOCKS`]): the
    /// largest distance from a line's value at the last block plus [`PROOF_T`] of its
    /// standard errors. Asked with the `slope` the block just gave (`push`: none with
    /// too few blocks or while a step is judged), whose line through the whole window is
    /// the longest span's.
    pub(super) fn distance_bound_g(&self, slope: &Slope, value_g: f32) -> f32 {
        let last = self.at(self.filled - 1).0.wrapping_sub(self.at(0).0) as f32;
        let mut widest = 0.0_f32;
        // The spans longer than the window are all the window: one line for them.
        let mut longest = usize::MAX;
        for span in PROOF_SPANS {
            let blocks = span.min(self.filled);
            if blocks < TREND_PROOF_MIN_BLOCKS {
                break;
            }
            if blocks == longest {
                continue;
            }
            longest = blocks;
            let line = if blocks == self.filled {
                slope.whole
            } else {
                self.line(self.filled - blocks, self.filled)
            };
            // Every span has at least three blocks; a line without a variance vouches
            // for nothing.
            let Some(variance) = line.variance else {
                return f32::INFINITY;
            };
            let ahead = last - line.time + PROOF_AHEAD_BLOCKS;
            let end = line.level + line.per_block * ahead;
            let se = crate::numerics::real::Real::sqrt(
                variance * (1.0 / blocks as f32 + ahead * ahead / line.sxx.max(f32::MIN_POSITIVE)),
            );
            let t = PROOF_T.get(blocks).copied().unwrap_or(f32::INFINITY);
            widest = widest.max((end - value_g).abs() + t * se);
        }
        widest
    }

    /// The blocks after the alarm against the line through those before: a step when
    /// their mean is more than [`STEP_T`] standard errors off it, and then the blocks
    /// before go. Fewer than three before: they go too (no line to judge by).
    fn judge_step(&mut self, before: usize) {
        self.split = None;
        let pre = self.line(0, before);
        let post = self.line(before, self.filled);
        let step = match pre.variance {
            None => true,
            Some(variance) => {
                let predicted = pre.level + pre.per_block * (post.time - pre.time);
                let offset = pre.time - post.time;
                let standard_error = crate::numerics::real::Real::sqrt(
                    variance
                        * (1.0 / post.blocks as f32
                            + 1.0 / pre.blocks as f32
                            + offset * offset / pre.sxx),
                );
                let off = (post.level - predicted).abs();
                off > STEP_T * standard_error || (standard_error == 0.0 && off > 0.0)
            }
        };
        if step {
            self.filled -= before;
        }
    }

    /// The `i`-th block of the window, oldest first: its time and mean.
    fn at(&self, i: usize) -> (u32, f32) {
        let j = self.slot(i);
        (self.times[j], self.means_g[j])
    }

    /// Where the `i`-th block of the window, oldest first, is kept.
    fn slot(&self, i: usize) -> usize {
        let j = self.next + TREND_WINDOW_BLOCKS - self.filled + i;
        if j >= TREND_WINDOW_BLOCKS {
            j - TREND_WINDOW_BLOCKS
        } else {
            j
        }
    }

    /// Least squares through blocks `from..to` of the window, in one pass (once per block
    /// on the target: the scale's budget is per sample). Times count from the window's
    /// oldest block, the same origin for every part of it; means from the first of the
    /// blocks, so that `f32` keeps a few hundred grams to a tenth of a microgram.
    fn line(&self, from: usize, to: usize) -> Line {
        let blocks = to.saturating_sub(from);
        let n = blocks.max(1) as f32;
        let (origin, shift) = (self.at(0).0, self.at(from).1);
        let (mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0_f32, 0.0, 0.0, 0.0, 0.0);
        let mut j = self.slot(from);
        for _ in from..to {
            let x = self.times[j].wrapping_sub(origin) as f32;
            let y = self.means_g[j] - shift;
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
            syy += y * y;
            j += 1;
            if j == TREND_WINDOW_BLOCKS {
                j = 0;
            }
        }
        let (time, mean) = (sx / n, sy / n);
        let sxx = (sxx - sx * time).max(0.0);
        let sxy = sxy - sx * mean;
        let syy = (syy - sy * mean).max(0.0);
        let per_block = if sxx > 0.0 { sxy / sxx } else { 0.0 };
        let variance = (blocks >= 3).then(|| (syy - per_block * sxy).max(0.0) / (n - 2.0));
        Line {
            time,
            level: mean + shift,
            per_block,
            sxx,
            blocks,
            variance,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fill(
        trend: &mut Trend,
        blocks: usize,
        block: u32,
        mut value: impl FnMut(usize) -> f32,
    ) -> Option<Slope> {
        let mut last = None;
        for b in 0..blocks {
            for s in 0..block as usize {
                last = trend.push(value(b * block as usize + s), block).or(last);
            }
        }
        last
    }

    fn wobble(k: usize) -> f32 {
        if k % 20 < 10 {
            0.01
        } else {
            -0.01
        }
    }

    #[test]
    fn a_ramp_is_significant_and_its_slope_is_measured() {
        let mut trend = Trend::new(0);
        // 0.004 g per block of 10 samples, with an alternating ±0.01 g wobble.
        let slope = fill(&mut trend, 30, 10, |k| 0.0004 * k as f32 + wobble(k)).unwrap();
        assert!((slope.per_block_g - 0.004).abs() < 2e-4, "{slope:?}");
        assert!(slope.t > TREND_T, "{slope:?}");
    }

    #[test]
    fn a_constant_with_noise_is_not_a_trend_and_needs_enough_blocks() {
        let mut trend = Trend::new(0);
        let mut state = 12345_u32;
        let mut noise = move || {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
            (state >> 8) as f32 / (1 << 24) as f32 - 0.5
        };
        assert!(fill(&mut trend, TREND_PROOF_MIN_BLOCKS - 1, 10, |_| 100.0
            + noise())
        .is_none());
        let mut largest = 0.0_f32;
        for _ in 0..300 {
            if let Some(slope) = fill(&mut trend, 1, 10, |_| 100.0 + noise()) {
                largest = largest.max(slope.t.abs());
            }
        }
        assert!(largest < TREND_T, "largest |t| {largest}");
    }

    #[test]
    fn skipped_blocks_and_a_non_finite_sample() {
        let mut trend = Trend::new(3);
        // The first 3 blocks are skipped, so 5 blocks need 8.
        assert!(fill(&mut trend, TREND_PROOF_MIN_BLOCKS + 2, 10, |k| k as f32).is_none());
        assert!(fill(&mut trend, 1, 10, |k| k as f32).is_some());
        assert!(trend.push(f32::NAN, 10).is_none());
        assert!(fill(&mut trend, TREND_PROOF_MIN_BLOCKS - 1, 10, |k| k as f32).is_none());
    }

    /// The bound on the load now: a reading on a flat window is vouched for to a few of
    /// its blocks' standard errors; a reading left behind by a ramp that began 1.2 s ago in
    /// a 6 s flat window is not (the line through the whole window barely rises; the
    /// newest blocks' does); none while a step is judged or with too few blocks (no slope
    /// to ask it with).
    #[test]
    fn the_bound_on_the_load_now_sees_a_ramp_begun_in_a_flat_window() {
        let mut trend = Trend::new(0);
        assert_eq!(
            fill(&mut trend, TREND_PROOF_MIN_BLOCKS - 1, 10, wobble),
            None
        );
        let slope = fill(&mut trend, 60 - TREND_PROOF_MIN_BLOCKS + 1, 10, wobble).unwrap();
        let flat = trend.distance_bound_g(&slope, 0.0);
        assert!(flat < 0.02, "flat: {flat}");
        // 0.005 g per block (0.05 g/s) for 12 blocks: 0.06 g on the pan now.
        let slope = fill(&mut trend, 12, 10, |k| 0.0005 * k as f32 + wobble(k)).unwrap();
        let behind = trend.distance_bound_g(&slope, 0.0);
        assert!(behind > 0.05, "behind the ramp: {behind}");
        let whole = trend.line(0, trend.filled);
        let whole_end = whole.level + whole.per_block * (71.0 - whole.time);
        assert!(
            whole_end < 0.05,
            "the whole window's line ends at {whole_end}"
        );
        trend.changed(0);
        assert_eq!(fill(&mut trend, 1, 10, wobble), None);
    }

    /// The bound vouches for the readings until the next block ends, so it takes each line
    /// that far: on a ramp of 0.01 g per block, a reading at the newest block's mean (the
    /// load half a block before that block ended) is 1.5 blocks of the ramp behind by then.
    /// Taken at the newest block, the lines found it right to their standard errors, and
    /// `host-sim torture` showed trickles 0.05-0.06 g behind as stable (runs 8655 and 8359
    /// of 10,000).
    #[test]
    fn the_bound_looks_as_far_ahead_as_it_vouches() {
        let mut trend = Trend::new(0);
        let ramp = |k: usize| 0.001 * k as f32 + 0.01 * wobble(k);
        let slope = fill(&mut trend, 30, 10, ramp).unwrap();
        // The newest block holds samples 290..300: its mean is the ramp at 294.5.
        let newest_mean = 0.001 * 294.5;
        let bound = trend.distance_bound_g(&slope, newest_mean);
        assert!((bound - 0.015).abs() < 0.001, "bound {bound}");
    }

    #[test]
    fn a_step_at_an_alarm_is_cut_and_a_ramp_across_one_is_kept() {
        // 30 blocks at 100 g, an alarm, 2 blocks skipped, then 100.5 g: the blocks before go.
        let mut trend = Trend::new(0);
        fill(&mut trend, 30, 10, |k| 100.0 + wobble(k));
        trend.changed(2);
        fill(&mut trend, 2 + STEP_DECISION_BLOCKS, 10, |k| {
            100.5 + wobble(k)
        });
        assert_eq!(trend.filled, STEP_DECISION_BLOCKS);
        // A ramp with an alarm (and a gap) in it: nothing goes, and the slope is the ramp's,
        // the gap's time counted.
        let mut trend = Trend::new(0);
        let ramp = |k: usize| 100.0 + 0.0004 * k as f32 + wobble(k);
        fill(&mut trend, 30, 10, ramp);
        trend.changed(5);
        let slope = fill(&mut trend, 5 + STEP_DECISION_BLOCKS, 10, |k| ramp(k + 300)).unwrap();
        assert_eq!(trend.filled, 30 + STEP_DECISION_BLOCKS);
        assert!((slope.per_block_g - 0.004).abs() < 2e-4, "{slope:?}");
    }

    #[test]
    fn a_noise_free_constant_has_no_trend_and_a_noise_free_ramp_an_infinite_t() {
        let mut trend = Trend::new(0);
        let flat = fill(&mut trend, TREND_MIN_BLOCKS, 4, |_| 250.0).unwrap();
        assert_eq!(flat.t, 0.0);
        let mut trend = Trend::new(0);
        let ramp = fill(&mut trend, TREND_MIN_BLOCKS, 4, |k| k as f32 / 64.0).unwrap();
        assert!(ramp.t.is_infinite() || ramp.t > 1e4, "{ramp:?}");
    }
}
