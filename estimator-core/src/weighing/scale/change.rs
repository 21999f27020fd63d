//! Load-change detection: two-sided CUSUM tests (Page 1954), one on the estimator's
//! a-priori residuals, one on the raw samples against the displayed gross mass (see the
//! `Scale` module docs for why two, and when each is armed), and one on block means of the
//! raw samples against it, armed with the raw test, which sees an item of one scale
//! interval; the block in progress is judged at each eighth of a block on the block
//! means' own scatter (`judge_parts`), so an item of 1 e on a quiet pan is seen within
//! 25 ms.
//!
//! A NaN deviation must never poison the sums: it resets them.

use super::trend::{
    TREND_LAG_OF_PERMISSIBLE, TREND_LAG_S, TREND_MIN_BLOCKS, TREND_PROOF_OF_PERMISSIBLE, TREND_T,
};
use super::{Scale, ScaleEstimator, ScaleReading, ScaleState};
use crate::numerics::real::Real;

/// The ringing's amplitude over the step that set it off, at most: a load dropped from a
/// height lands with its momentum, overshooting its step (the torture's drops reach about
/// twice; a margin over that).
const RINGING_OVER_STEP: f32 = 4.0;

/// The ringing measured in a block, over the amplitude its spread gives: √2 times the
/// standard deviation about the block mean of what is not white noise (the spread less
/// half the mean square of sample-to-sample differences, which a ringing far below the
/// sample rate hardly has; noise filtered before the converter shows less there, which
/// only makes the amplitude larger). The spread of 400 samples of a ringing of 1.2 periods
/// or more is within a few percent of a whole number of periods'; half as much again
/// covers that and the estimates' own scatter.
const RINGING_MEASURED_MARGIN: f32 = 1.5;

/// How many of its own standard errors on a pan with no ringing the spread a block's
/// ringing is measured from must exceed before the block in progress's test allows it
/// (`block_ringing_g`, `judge_parts`). On white noise alone the spread (the variance less
/// the white part from the differences) is about the mean of the products of consecutive
/// samples, whose standard error is the white noise's variance over the square root of
/// the samples. A pan with 0.17 g of noise per sample measured a ringing of 0.05-0.1 g in
/// a third of its blocks, and the test allowed it: a 0.43 g load lifted off at 2 g/s was
/// shown `Stable` 0.06 g above the truth (`host-sim torture --runs 10000 --seed 1`, run
/// 4278; the ideal test's z was 8.8). That test scales with the block means' own scatter,
/// so the noise counted twice there. The block and per-sample tests keep the whole
/// measure: their drift is fixed in grams, and taking the noise out of theirs as well
/// showed 2.0 % fewer lines settled at 1,000 runs and no fewer wrong at 10,000 (a noisy
/// pan's false motion).
const RINGING_NOISE_Z: f32 = 3.0;

/// The trend window stops skipping the blocks after a fast change once the ringing
/// measured in a whole block moves a block mean by less than this part of the permissible
/// error of the load shown, or is within [`PAN_RINGING_MARGIN`] of the pan's own
/// (`Scale::ringing_over`).
const RINGING_IN_TREND_OF_PERMISSIBLE: f32 = 0.1;

/// How far above the pan's own ringing (its average) a block may ring and still be the
/// pan's: one block's measure scatters about the average (by about a third on a floor
/// vibrating by 0.2–0.4 g at 20 Hz), so at the average itself the skip's end was a coin
/// toss per block.
const PAN_RINGING_MARGIN: f32 = 1.5;

/// The weight of each new settled block in the pan's own ringing (`Scale::pan_ringing_g`):
/// an average over about the last ten.
const PAN_RINGING_WEIGHT: f32 = 0.1;

/// The block test's sums past this part of its threshold are motion: no reading is shown
/// stable or final. A quarter: a trickle of 0.4 e/s was still shown stable 0.5 e behind
/// the load at a half.
const MOTION_OVER_THRESHOLD: f32 = 0.25;

/// How many standard errors the block in progress must lie beyond the block test's
/// allowance to be motion (`Scale::judge_parts`).
const PARTIAL_Z: f32 = 4.0;

/// Differences of consecutive whole block means the run must have before the block in
/// progress is judged on their scatter.
const PARTIAL_MIN_PAIRS: u32 = 4;

/// The last differences of consecutive block means the scatter is taken from.
pub(super) const PARTIAL_SCATTER_BLOCKS: usize = 8;

/// The parts of a block at whose boundaries the block in progress is judged (eighths:
/// every 12.5 ms of the default 0.1 s blocks).
pub(super) const PARTIAL_PARTS: usize = 8;

/// The least mean excess of the block in progress that is motion, a part of the permissible
/// error of the load shown.
const PARTIAL_LAG_OF_PERMISSIBLE: f32 = 0.25;

/// A two-sided CUSUM test with drift `drift` and threshold `threshold`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct TwoSidedCusum {
    high: f32,
    low: f32,
}

impl TwoSidedCusum {
    /// Add one deviation; true on an alarm (both sums restart then).
    pub(super) fn step(&mut self, deviation: f32, drift: f32, threshold: f32) -> bool {
        let high = self.high + deviation - drift;
        let low = self.low - deviation - drift;
        // `max` by comparison so a NaN deviation resets the sums instead of poisoning them.
        self.high = if high > 0.0 { high } else { 0.0 };
        self.low = if low > 0.0 { low } else { 0.0 };
        if self.high > threshold || self.low > threshold {
            *self = Self::default();
            true
        } else {
            false
        }
    }

    /// Either sum above `level`: a deviation is building up (not yet an alarm).
    pub(super) fn above(&self, level: f32) -> bool {
        self.high > level || self.low > level
    }
}

/// The ringing measured in a whole block of `filled` samples whose mean deviation is
/// `mean_g`, mean square `square_g2` and sum of squared consecutive differences
/// `difference_g2`: the amplitude its spread gives ([`RINGING_MEASURED_MARGIN`]), and the
/// same less the spread's own scatter on a pan with no ringing ([`RINGING_NOISE_Z`]), g.
/// `max` keeps a NaN out of both.
fn block_ringing_g(mean_g: f32, square_g2: f32, difference_g2: f32, filled: f32) -> (f32, f32) {
    let white_g2 = 0.5 * difference_g2 / (filled - 1.0).max(1.0);
    let spread_g2 = square_g2 - mean_g * mean_g - white_g2;
    let net_g2 = spread_g2 - RINGING_NOISE_Z * white_g2 / Real::sqrt(filled);
    (
        RINGING_MEASURED_MARGIN * Real::sqrt(2.0 * spread_g2.max(0.0)),
        RINGING_MEASURED_MARGIN * Real::sqrt(2.0 * net_g2.max(0.0)),
    )
}

impl<E: ScaleEstimator> Scale<E> {
    /// The residual test, once per decimated update and once the fit is determined enough:
    /// true when it alarms.
    pub(super) fn residual_alarm(&mut self, residual_counts: Option<f32>) -> bool {
        let new_update = self.update_phase == 0;
        let armed = self.samples_since_change >= u64::from(self.config.residual_arm_samples);
        if !(new_update && armed) {
            return false;
        }
        let Some(residual_counts) = residual_counts else {
            return false;
        };
        self.residual_cusum.step(
            residual_counts * self.grams_per_count,
            self.config.residual_drift_g,
            self.config.residual_threshold_g,
        )
    }

    /// A new residual into the residual motion test (`residual_motion`), its floor the same
    /// part of the permissible error of the load shown as the block in progress's.
    pub(super) fn judge_residual_motion(&mut self, residual_counts: Option<f32>) {
        let Some(residual_counts) = residual_counts.filter(|_| self.update_phase == 0) else {
            return;
        };
        if self.residual_motion.at_block_start() {
            let shown_g = self.last_shown_gross_g - self.tare_g;
            let permissible_g = self.config.permissible_error_g(shown_g);
            self.residual_motion
                .set_floor(PARTIAL_LAG_OF_PERMISSIBLE * permissible_g);
        }
        let updates_per_block = self.config.block_samples / self.samples_per_update;
        self.residual_motion.push(
            residual_counts * self.grams_per_count.abs(),
            updates_per_block,
        );
    }

    /// The raw tests against the displayed gross mass: true when either alarms. One on
    /// each sample (a large change alarms within ms), one on block means of
    /// `block_samples` (a change of one scale interval alarms: the raw noise would hide it
    /// from the first).
    ///
    /// The per-sample test starts as soon as the run's reading has held its band once, not
    /// only once the cell has stopped ringing: a load taken off by hand a second after it
    /// was put on went unseen for 100 ms while the old mass stayed on show, `Stable` (the
    /// estimator's residuals absorb a slow ramp). Until the ringing is over its drift
    /// carries the ringing's envelope: [`RINGING_OVER_STEP`] times the step that started
    /// the run, decaying to e⁻⁵ of it over `raw_arm_samples` (the settling the default
    /// arming is set for). The block test runs from the same moment with the same
    /// allowance in its drift: with no allowance (at boot, after a small change) it sees a
    /// change of 1 e long before the 1.5 s arming, which it used to wait for
    /// (`host-sim torture --runs 300 --seed 1`: silent wrong readings 232 → 122 of about
    /// 130,000 shown).
    ///
    /// That envelope is a bound for the worst landing (a drop) on the slowest-decaying
    /// load; the ringing as it is, measured in each whole block (its spread about the
    /// block mean, [`RINGING_MEASURED_MARGIN`]), caps it for the blocks after. The block
    /// test allows only what a ringing of at least `ringing_min_hz` can add to a sum of
    /// samples (half a period's area: a block mean of 100 ms takes 27 % of a 12 Hz
    /// ringing's amplitude). With the envelope alone and in full, an item placed by hand
    /// within two seconds of a load went unseen while it arrived, the old mass `Stable`
    /// (`host-sim torture --runs 1000 --seed 1`: 7 of 29 silent wrong readings).
    pub(super) fn raw_alarm(&mut self, counts: i32) -> bool {
        self.block_alarmed = false;
        self.ringing_envelope *= self.ringing_decay;
        self.ringing_g *= self.ringing_decay;
        let Some(gross) = self.gross_g else {
            self.block_sum_g = 0.0;
            self.block_filled = 0;
            self.part_left = 0;
            self.partial_moving = false;
            return false;
        };
        if !(self.raw_armed || self.held_in_run) {
            return false;
        }
        let deviation_g = (counts as f32 - self.zero_counts) * self.grams_per_count - gross;
        // The step that started this run rings on, and so does whatever rang before it (a
        // run restarted by the impact of its own load).
        let step_g = (gross - self.previous_gross_g).abs();
        self.ringing_g = self
            .ringing_g
            .max(RINGING_OVER_STEP * step_g * self.ringing_envelope);
        // The envelope's bound, or what the last block measured where that is less (by
        // comparison: `f32::min`'s NaN rule costs instructions on every sample).
        let ringing_g = if self.ringing_measured_g < self.ringing_g {
            self.ringing_measured_g
        } else {
            self.ringing_g
        };
        self.ringing_allowed_g = ringing_g;
        let raw = self.raw_cusum.step(
            deviation_g,
            self.config.raw_drift_g + ringing_g,
            self.config.raw_threshold_g,
        );
        if self.block_filled == 0 {
            self.previous_deviation_g = deviation_g;
        }
        let difference_g = deviation_g - self.previous_deviation_g;
        self.previous_deviation_g = deviation_g;
        self.block_sum_g += deviation_g;
        self.block_square_g2 += deviation_g * deviation_g;
        self.block_difference_g2 += difference_g * difference_g;
        self.block_filled += 1;
        self.judge_parts();
        if self.block_filled < self.config.block_samples {
            return raw;
        }
        let filled = self.block_filled as f32;
        let block_mean_g = self.block_sum_g / filled;
        let drift_g = self.block_allowance_g(self.block_filled, ringing_g) / filled;
        // The ringing of this block caps the allowance for the next.
        (self.ringing_measured_g, self.ringing_net_g) = block_ringing_g(
            block_mean_g,
            self.block_square_g2 / filled,
            self.block_difference_g2,
            filled,
        );
        if self.raw_armed && self.ringing_measured_g < f32::INFINITY {
            self.pan_ringing_g = if self.pan_ringing_g < f32::INFINITY {
                self.pan_ringing_g
                    + PAN_RINGING_WEIGHT * (self.ringing_measured_g - self.pan_ringing_g)
            } else {
                self.ringing_measured_g
            };
        }
        if self.trend.skipping() && self.ringing_over() {
            self.trend.end_skip();
        }
        self.block_sum_g = 0.0;
        self.block_square_g2 = 0.0;
        self.block_difference_g2 = 0.0;
        self.block_filled = 0;
        self.part_left = 0;
        self.end_block_scatter(block_mean_g, gross);
        // The pan shows empty and zero tracking may pull the zero: it is seen, once a
        // block (`zero`).
        if self.state == ScaleState::Empty && self.zero_trackable(gross) {
            self.zero_seen();
        }
        // The zero's drift into the net `u`, once a block.
        self.refresh_reference_u();
        let block = self
            .block_cusum
            .step(block_mean_g, drift_g, self.config.block_threshold_g);
        self.block_alarmed = block && !raw;
        raw || block
    }

    /// What the block test allows the sum of `filled` deviations (g·samples): its drift on
    /// each, and a ringing of `ringing_g` for at most `ringing_sum_samples` of them.
    fn block_allowance_g(&self, filled: u32, ringing_g: f32) -> f32 {
        let filled = filled as f32;
        let ringing_samples = if filled < self.ringing_sum_samples {
            filled
        } else {
            self.ringing_sum_samples
        };
        filled * self.config.block_drift_g + ringing_samples * ringing_g
    }

    /// The load may be moving, though no test has alarmed: the residual motion test sees
    /// motion, the trend window cannot vouch for the reading (`trend`), or the block
    /// test's sums are past [`MOTION_OVER_THRESHOLD`] of its threshold (a trickle, a
    /// creep). No reading is shown stable or final then.
    pub(super) fn in_motion(&self) -> bool {
        if self.residual_motion.moving || self.trend_unproven {
            return true;
        }
        if !(self.raw_armed || self.held_in_run) {
            return false;
        }
        let level = MOTION_OVER_THRESHOLD * self.config.block_threshold_g;
        // The block in progress counts for what it holds so far: the sums as they would
        // stand if the block ended now with its remaining samples at the shown mass. An
        // item put on just after a block boundary otherwise stayed `Stable` at the old
        // mass for up to a block (100 ms; `host-sim torture`, small additions).
        let per_block = 1.0 / self.config.block_samples as f32;
        let drifted = self.block_allowance_g(self.block_filled, self.ringing_allowed_g);
        let running = TwoSidedCusum {
            high: self.block_cusum.high + (self.block_sum_g - drifted) * per_block,
            low: self.block_cusum.low + (-self.block_sum_g - drifted) * per_block,
        };
        self.partial_moving || self.block_cusum.above(level) || running.above(level)
    }

    /// A whole block's mean deviation from the shown gross mass `gross_g`: its difference
    /// from the last one into the run's block-mean scatter, and the floor of the motion the
    /// block in progress may show ([`PARTIAL_LAG_OF_PERMISSIBLE`] of the permissible error).
    fn end_block_scatter(&mut self, block_mean_g: f32, gross_g: f32) {
        if let Some(last_g) = self.last_block_mean_g {
            let difference = block_mean_g - last_g;
            // A NaN mean never poisons the sum (the comparison fails).
            let square = difference * difference;
            if square < f32::INFINITY {
                // The last `PARTIAL_SCATTER_BLOCKS` only: the ringing of the run's first
                // blocks (grams after a placement) is forgotten.
                let slot = self.block_mean_pairs as usize % PARTIAL_SCATTER_BLOCKS;
                self.block_mean_squares_g2[slot] = square;
                self.block_mean_pairs = self.block_mean_pairs.saturating_add(1);
            }
        }
        self.last_block_mean_g = Some(block_mean_g);
        self.partial_floor_g =
            PARTIAL_LAG_OF_PERMISSIBLE * self.config.permissible_error_g(gross_g - self.tare_g);
    }

    /// At each boundary of a [`PARTIAL_PARTS`]th of the block in progress: its sum so far
    /// kept, and whether the block so far already says the load is moving
    /// (`partial_moving`, which holds until the next boundary). Every stretch from a part
    /// boundary to now is judged: its mean deviation beyond the block test's allowance
    /// (drift and ringing, for as many samples) is [`PARTIAL_Z`] standard errors out (the
    /// last block means' scatter, from their consecutive differences, scaled to the
    /// samples in it) and more than the floor `end_block_scatter` set. The block test's own
    /// level is fixed in grams (a quarter of its threshold, 0.0375 g by default): on a quiet
    /// pan an item of 1 e took up to 55 ms to reach it, and a tared item lifted off by hand
    /// at 0.9 g/s about 120 ms, while the old mass stayed `Stable` (the test below;
    /// `host-sim torture --runs 1000 --seed 1`, run 421). From part boundaries, not only the block's start: an item
    /// arriving mid-block is diluted by the samples before it.
    fn judge_parts(&mut self) {
        // A countdown, not `block_filled % part`: a division on every sample. Zero at the
        // start of a block.
        let part = (self.config.block_samples / PARTIAL_PARTS as u32).max(1);
        if self.part_left == 0 {
            self.part_left = part;
        }
        self.part_left -= 1;
        if self.part_left > 0 {
            return;
        }
        let parts = ((self.block_filled / part) as usize).clamp(1, PARTIAL_PARTS);
        self.part_sums_g[parts - 1] = self.block_sum_g;
        if self.block_mean_pairs < PARTIAL_MIN_PAIRS {
            self.partial_moving = false;
            return;
        }
        // One block mean's variance: half the mean squared difference of the last ones.
        let pairs = (self.block_mean_pairs as usize).min(PARTIAL_SCATTER_BLOCKS);
        let squares_g2: f32 = self.block_mean_squares_g2[..pairs].iter().sum();
        let block_variance_g2 = 0.5 * squares_g2 / pairs as f32;
        let ringing_g = if self.ringing_net_g < self.ringing_allowed_g {
            self.ringing_net_g
        } else {
            self.ringing_allowed_g
        };
        self.partial_moving =
            (0..parts).any(|start| self.stretch_moving(start, part, block_variance_g2, ringing_g));
    }

    /// Whether the samples of the block in progress from part `start` on (`part` samples
    /// each) are motion, one block mean's variance being `block_variance_g2` (see
    /// `judge_parts`). Without divisions: the mean excess `excess / n` against the floor
    /// and against `PARTIAL_Z` standard errors, `block_variance · block / n`.
    fn stretch_moving(
        &self,
        start: usize,
        part: u32,
        block_variance_g2: f32,
        ringing_g: f32,
    ) -> bool {
        let before_g = if start == 0 {
            0.0
        } else {
            self.part_sums_g[start - 1]
        };
        let samples = self.block_filled - start as u32 * part;
        let excess_g =
            (self.block_sum_g - before_g).abs() - self.block_allowance_g(samples, ringing_g);
        let n = samples as f32;
        excess_g > self.partial_floor_g * n
            && excess_g * excess_g
                > PARTIAL_Z * PARTIAL_Z * block_variance_g2 * self.config.block_samples as f32 * n
    }

    /// A load changed: a new run.
    pub(super) fn load_changed(&mut self) -> ScaleReading {
        self.restart_as_load_change();
        self.state = ScaleState::Estimating;
        self.reading()
    }

    /// The trend test's blocks while a fresh load may ring (`raw_arm_samples`, rounded up
    /// to whole blocks): skipped after power-up and after a fast change.
    pub(super) fn ringing_blocks(&self) -> u32 {
        self.config
            .raw_arm_samples
            .div_ceil(self.config.block_samples.max(1))
    }

    /// Whether the fresh load's ringing is over for the trend window (asked at the end of
    /// each whole block the raw tests measured): the ringing of that block moves a block
    /// mean (by half a period's area of it at most, `ringing_sum_samples`) by less than
    /// [`RINGING_IN_TREND_OF_PERMISSIBLE`] of the permissible error of the load shown, or
    /// is within [`PAN_RINGING_MARGIN`] of the pan's own ringing on settled runs (a
    /// vibrating floor's, which never dies down and which the window's lines carry in their
    /// scatter anyway). Always waiting the whole `raw_arm_samples`, the window said nothing
    /// for 1.5 s after every fast change, and trickles begun within a second of a removal
    /// on vibrating floors were shown settled behind (the 10,000-run torture of seed 1:
    /// 13 → 10 silent wrong readings, trickles 6 → 2, at 3.1 % fewer lines shown settled:
    /// the young window's lines doubt small loads on noisy pans sooner after each change).
    fn ringing_over(&self) -> bool {
        let block = self.config.block_samples.max(1) as f32;
        let in_block = self.ringing_sum_samples.min(block) / block;
        let permissible = self
            .config
            .permissible_error_g(self.last_shown_gross_g - self.tare_g);
        let small_g = RINGING_IN_TREND_OF_PERMISSIBLE * permissible / in_block;
        // Not yet measured on a settled run: only the permissible error's part counts.
        let pan_g = if self.pan_ringing_g < f32::INFINITY {
            PAN_RINGING_MARGIN * self.pan_ringing_g
        } else {
            0.0
        };
        self.ringing_measured_g <= if small_g > pan_g { small_g } else { pan_g }
    }

    /// One good sample into the trend test (`trend`): at the end of each block, a slope
    /// that is significant and lags the reading by more than its part of the permissible
    /// error is an alarm, taken at the next valid reading; and whether the window vouches
    /// for the reading shown (gross, against the calibrated zero like its blocks).
    pub(super) fn push_trend(&mut self, counts: i32) {
        let gross_g = (counts as f32 - self.calibrated_zero_counts) * self.grams_per_count;
        let Some(slope) = self.trend.push(gross_g, self.config.block_samples) else {
            return;
        };
        let blocks_per_s = self.config.sample_rate_hz / self.config.block_samples.max(1) as f32;
        let run_s = self.samples_since_change as f32 / self.config.sample_rate_hz;
        let lag_g = (slope.per_block_g * blocks_per_s).abs() * (0.5 * run_s).max(TREND_LAG_S);
        let permissible = self
            .config
            .permissible_error_g(self.last_shown_gross_g - self.tare_g);
        let shown_g = self.last_shown_gross_g
            + (self.zero_counts - self.calibrated_zero_counts) * self.grams_per_count;
        let bound_g = self.trend.distance_bound_g(&slope, shown_g);
        self.trend_unproven = !(bound_g <= TREND_PROOF_OF_PERMISSIBLE * permissible);
        if slope.blocks() >= TREND_MIN_BLOCKS
            && slope.t.abs() > TREND_T
            && lag_g > TREND_LAG_OF_PERMISSIBLE * permissible
        {
            // The blocks to come are judged against the line: a trickle goes on along it;
            // one that stopped (or a ramp the CUSUM tests cut short) leaves it, and what
            // came before is dropped instead of alarming until it leaves the window.
            self.trend.changed(0);
            self.trend_alarmed = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_scene::{run, scene, Cell};
    use super::super::ScaleConfig;
    use super::*;

    /// Samples from a load of `load_g` taken off a pan on a floor vibrating by `rms_g`
    /// (20 Hz; the cell seeded by `seed`) until the trend window takes blocks again, and
    /// the samples it skips at most (`ringing_blocks`).
    fn skip_after_a_removal(seed: u64, load_g: f64, rms_g: f64) -> (u32, u32) {
        let (mut scale, _) = scene(0.14);
        let mut cell = Cell::seeded(0.14, seed);
        cell.vibration = (rms_g, 20.0, 2.0);
        run(&mut scale, &mut cell, 8000);
        cell.load_g = load_g;
        run(&mut scale, &mut cell, 16_000);
        let changes = scale.reading().load_changes;
        cell.load_g = 0.0;
        let mut after = 0;
        // From the alarm the removal raised (within a few samples of it).
        while scale.reading().load_changes == changes || scale.trend.skipping() {
            if scale.reading().load_changes == changes {
                after = 0;
            }
            scale.push(cell.sample());
            after += 1;
            assert!(after < 40_000, "never took blocks again");
        }
        let most = scale.ringing_blocks() * scale.config.block_samples;
        (after, most)
    }

    /// The trend window skips the blocks after a fast change while the fresh load may ring,
    /// and, since it says nothing then, a trickle begun soon after (on a noisy or vibrating
    /// pan) could be shown settled a permissible error behind it (`host-sim torture --runs
    /// 10000 --seed 1`, runs 1490 and 1718: 3 of its 13 silent wrong readings). The skip
    /// now ends once a whole block rings no more than 1.5 times the pan's own vibration
    /// (`PAN_RINGING_MARGIN`): before the whole 1.5 s after 20 g taken off this cell (25
    /// Hz, ζ = 0.03; about 1.3 s on a still floor, whose pan rings by a few hundredths of a
    /// gram in the measure, 0.9-1 s on a floor vibrating by 0.2 g), yet not at once, while
    /// it rings. A pan that never settled on its load (a floor vibrating by 0.4 g under
    /// this cell) has no measure of its own ringing, and waits the whole 1.5 s as before.
    #[test]
    fn the_trend_window_takes_blocks_once_the_ringing_is_over() {
        for (seed, rms_g) in [(1, 0.0), (2, 0.0), (3, 0.2), (4, 0.2)] {
            let (after, most) = skip_after_a_removal(seed, 20.0, rms_g);
            assert!(after < most, "seed {seed}, {rms_g} g: {after} of {most}");
            assert!(after > 2000, "seed {seed}, {rms_g} g: {after} samples");
        }
        let (after, most) = skip_after_a_removal(5, 20.0, 0.4);
        assert_eq!(after, most + 1);
    }

    /// The pan's own ringing is measured in counts and kept in grams: a recalibration that
    /// raises the counts per gram by 10 % leaves the same vibration 10 % fewer grams (it
    /// used to keep the old gain's grams until the average had forgotten them).
    #[test]
    fn a_recalibration_rescales_the_pans_own_ringing() {
        let (mut scale, _) = scene(0.14);
        let mut cell = Cell::seeded(0.14, 3);
        cell.vibration = (0.2, 20.0, 2.0);
        cell.load_g = 100.0;
        run(&mut scale, &mut cell, 24_000);
        let before_g = scale.pan_ringing_g;
        assert!(before_g > 0.05 && before_g < 1.0, "{before_g} g");
        let mut calibration = super::super::test_scene::calibration();
        calibration.counts_per_gram *= 1.1;
        scale.recalibrate(calibration);
        let after_g = scale.pan_ringing_g;
        assert!(
            (after_g * 1.1 / before_g - 1.0).abs() < 1e-5,
            "{before_g} -> {after_g} g"
        );
    }

    /// Blocks of 400 samples with `noise_g` of white noise per sample and a ringing of
    /// `ringing_g` at 25 Hz: how many of `blocks` measure a ringing above `above_g`, and how
    /// many net of the noise (`block_ringing_g`).
    fn measured_ringings(noise_g: f64, ringing_g: f64, above_g: f32, blocks: u32) -> (u32, u32) {
        let mut state = 7;
        let (mut measured, mut net) = (0, 0);
        for block in 0..blocks {
            let (mut sum, mut square, mut difference, mut last) = (0.0f32, 0.0f32, 0.0f32, None);
            for k in 0..400 {
                let t = f64::from(block * 400 + k) / 4000.0;
                let x = (ringing_g * (2.0 * core::f64::consts::PI * 25.0 * t).sin()
                    + noise_g * super::super::test_scene::unit_noise(&mut state))
                    as f32;
                if let Some(last) = last {
                    difference += (x - last) * (x - last);
                }
                last = Some(x);
                sum += x;
                square += x * x;
            }
            let (all_g, net_g) = block_ringing_g(sum / 400.0, square / 400.0, difference, 400.0);
            measured += u32::from(all_g > above_g);
            net += u32::from(net_g > above_g);
        }
        (measured, net)
    }

    /// On 0.17 g of white noise per sample and nothing else, a third of the blocks measured
    /// a ringing of 0.05-0.1 g and the block in progress's test allowed it, hiding a 0.43 g
    /// load lifted off at 2 g/s (`host-sim torture --runs 10000 --seed 1`, run 4278): net of
    /// the noise's own scatter, next to none. A real ringing of 0.3 g in the same noise is
    /// still measured, within the margin of its amplitude.
    #[test]
    fn noise_alone_is_not_measured_as_ringing_net() {
        let (measured, net) = measured_ringings(0.17, 0.0, 0.05, 400);
        assert!(measured > 80, "{measured} of 400 blocks");
        assert!(net <= 2, "{net} of 400 blocks");
        let (measured, net) = measured_ringings(0.17, 0.3, 0.3, 100);
        assert_eq!((measured, net), (100, 100));
        let (measured, net) = measured_ringings(0.17, 0.3, 0.5, 100);
        assert_eq!((measured, net), (0, 0));
    }

    #[test]
    fn a_slow_creep_is_caught_by_the_raw_test() {
        let (mut scale, mut cell) = scene(0.2);
        run(&mut scale, &mut cell, 1000);
        cell.load_g = 100.0;
        run(&mut scale, &mut cell, 12_000);
        let before = scale.reading().load_changes;
        // 3 g added over 1 s: slow enough for the residual test to miss.
        for _ in 0..4000 {
            cell.load_g += 3.0 / 4000.0;
            scale.push(cell.sample());
        }
        // The raw test re-arms only after the reading settled again (1.5 s), so a creep
        // caught mid-ramp is caught again after it ended.
        run(&mut scale, &mut cell, 16_000);
        let after = scale.reading();
        assert!(after.load_changes > before, "{after:?}");
        assert!((after.mass_g.unwrap() - 103.0).abs() < 0.2, "{after:?}");
    }

    #[test]
    fn cusum_is_two_sided_and_ignores_small_deviations() {
        let mut cusum = TwoSidedCusum::default();
        assert!(!(0..1000).any(|_| cusum.step(0.4, 0.5, 5.0)));
        assert!((0..100).any(|_| cusum.step(-1.0, 0.5, 5.0)));
        assert!((0..100).any(|_| cusum.step(1.0, 0.5, 5.0)));
        assert!(!cusum.step(f32::NAN, 0.5, 5.0));
    }

    /// A scale settled for 3 s (plus `offset` samples) on `load_g` with `noise_g` of noise
    /// (`seed`), then `change_g` put on at once: from `skip` samples after it on, no
    /// reading is shown `Stable` further than `tolerance_g` from the load.
    fn item_on_a_settled_load(
        noise_g: f64,
        seed: u64,
        load_g: f64,
        offset: usize,
        change_g: f64,
        skip: usize,
        tolerance_g: f64,
    ) {
        let (mut scale, _) = scene(noise_g);
        let mut cell = Cell::seeded(noise_g, seed);
        cell.load_g = load_g;
        run(&mut scale, &mut cell, 3 * 4000 + offset);
        assert_eq!(scale.reading().state, ScaleState::Stable, "seed {seed}");
        cell.load_g += change_g;
        let after = run(&mut scale, &mut cell, 800);
        for (index, reading) in after.iter().enumerate().skip(skip) {
            if let (ScaleState::Stable, Some(mass)) = (reading.state, reading.mass_g) {
                assert!(
                    (f64::from(mass) - cell.load_g).abs() <= tolerance_g,
                    "seed {seed}, offset {offset}: {} ms after {change_g} g, {reading:?}",
                    index / 4
                );
            }
        }
    }

    /// An item of 5 e put on a settled load, wherever it lands in the block test's 100 ms
    /// blocks: 50 ms later (one readout period) the old mass is no longer shown stable. The
    /// block test judged only whole blocks, so an item landing just after a boundary left
    /// the old mass `Stable` for up to 165 ms (`host-sim torture`, small additions: shown
    /// 1.75 g stable, 2.23 g on the pan).
    #[test]
    fn an_item_stops_the_old_mass_being_shown_stable_within_a_readout_period() {
        let e = ScaleConfig::SCALE_INTERVAL_G as f64;
        for (seed, offset) in [
            (1u64, 0usize),
            (2, 37),
            (3, 101),
            (4, 203),
            (5, 307),
            (6, 389),
        ] {
            item_on_a_settled_load(0.43, seed, 200.0, offset, 5.0 * e, 200, e);
        }
    }

    /// On a quiet pan, an item of 1 e lifted off a settled load (or put on), wherever the
    /// 0.1 s blocks fall: from 25 ms after it the old mass is not shown stable. The block
    /// test's level for the block in progress is fixed (0.0375 g by default), and the
    /// item's 0.1 g less its 0.02 g drift took about 50 ms to reach it, the old mass
    /// `Stable` 0.1 g off where 0.05 g is permissible; on the block means' own scatter
    /// (0.005 g here) it is seen within 13-25 ms.
    #[test]
    fn on_a_quiet_pan_an_item_of_one_e_stops_the_old_mass_being_stable_within_25_ms() {
        let e = ScaleConfig::SCALE_INTERVAL_G as f64;
        let config = ScaleConfig::weighing_default(4000.0);
        for (seed, offset, change) in [
            (1u64, 0usize, -e),
            (2, 61, -e),
            (3, 149, e),
            (4, 233, -e),
            (5, 311, e),
            (6, 397, -e),
        ] {
            let permissible = f64::from(config.permissible_error_g((100.0 + change) as f32));
            item_on_a_settled_load(0.1, seed, 100.0, offset, change, 100, permissible);
        }
    }

    /// A small item (1 to 5 scale intervals) put on a load that has sat for a minute is
    /// detected and read: the raw tests could not see it (their ν is a raw σ), and the
    /// settled estimate averaging the whole run stayed up to 0.5 g off, `Stable`.
    #[test]
    fn a_small_item_on_a_settled_load_is_seen() {
        let e = ScaleConfig::SCALE_INTERVAL_G as f64;
        for (seed, item_g) in [(1, e), (2, 2.0 * e), (3, 5.0 * e), (4, e)] {
            let (mut scale, _) = scene(0.43);
            let mut cell = Cell::seeded(0.43, seed);
            cell.load_g = 200.0;
            run(&mut scale, &mut cell, 60 * 4000);
            assert_eq!(scale.reading().load_changes, 0);
            cell.load_g += item_g;
            let last = *run(&mut scale, &mut cell, 5 * 4000).last().unwrap();
            assert_eq!(last.state, ScaleState::Stable, "{item_g} g: {last:?}");
            let error = last.mass_g.unwrap() as f64 - cell.load_g;
            // Within the MPE at 200 g (2000 e: 1 e), with room to spare: 0.5 e.
            assert!(
                error.abs() < 0.5 * e,
                "{item_g} g: error {error} ({last:?})"
            );
        }
    }

    /// No false load change on a settled load: a minute each at several loads and seeds.
    #[test]
    fn a_settled_load_raises_no_change() {
        for seed in 1..5 {
            for load_g in [0.0, 50.0, 200.0, 600.0] {
                let (mut scale, _) = scene(0.43);
                let mut cell = Cell::seeded(0.43, seed);
                cell.load_g = load_g;
                let readings = run(&mut scale, &mut cell, 60 * 4000);
                let last = readings.last().unwrap();
                assert_eq!(last.load_changes, 0, "seed {seed}, {load_g} g: {last:?}");
            }
        }
    }
}

/// What the torture run found shown settled while wrong, each as a scene on the test cell:
/// every reading shown stable, empty or final must lie within the permissible error of the
/// truth of the last 50 ms (a display may lag one readout period), with twice its `u` within it.
#[cfg(test)]
mod shown_settled {
    extern crate std;
    use std::collections::VecDeque;

    use super::super::test_scene::{run, scene, Cell, CPG};
    use super::super::ScaleConfig;
    use super::super::{Scale, ScaleEstimator, ScaleState};

    const PERIOD: usize = 200;

    /// Push `samples`, the load at each from `load`, and check every settled reading
    /// against the truth of the last readout period (`recent`, kept across calls);
    /// returns the readings.
    fn checked<E: ScaleEstimator>(
        (scale, cell, recent): (&mut Scale<E>, &mut Cell, &mut VecDeque<f64>),
        samples: usize,
        load: impl Fn(usize) -> f64,
        what: &str,
    ) -> std::vec::Vec<super::super::ScaleReading> {
        let mut readings = std::vec::Vec::new();
        for k in 0..samples {
            cell.load_g = load(k);
            recent.push_back(cell.load_g);
            if recent.len() > PERIOD {
                recent.pop_front();
            }
            let reading = scale.push(cell.sample());
            let settled =
                matches!(reading.state, ScaleState::Stable | ScaleState::Empty) || reading.is_final;
            if let (true, Some(mass)) = (settled, reading.mass_g) {
                let low = recent.iter().cloned().fold(f64::INFINITY, f64::min);
                let high = recent.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let mass = mass as f64;
                let error = (low - mass).max(mass - high).max(0.0);
                let permissible = scale.config().permissible_error_g(mass as f32) as f64;
                assert!(
                    error <= permissible,
                    "{what}, sample {k}: shown {mass} ({reading:?}), truth {low}..{high}"
                );
                if let Some(u) = reading.uncertainty_g {
                    assert!(
                        2.0 * u as f64 <= permissible,
                        "{what}, sample {k}: {reading:?}"
                    );
                }
            }
            readings.push(reading);
        }
        readings
    }

    /// An item taken off by hand (over 150 ms) a second after it was put on: the raw test
    /// was not yet armed (it waited 1.5 s for the ringing to end), the residuals absorbed
    /// the ramp, and the old mass stayed on show, `Stable`, 1.7 g off.
    #[test]
    #[ignore = "known limit: nothing is shown settled wrong any more (it was: 0.058 g shown empty with u = 0.017 g), but 2 s after the 5 g removal a late restart leaves the pan estimating (u = 0.0128 g: four u just above the 0.05 g permissible error)"]
    fn an_item_removed_by_hand_soon_after_it_was_put_on() {
        for (seed, item_g) in [(1, 5.0), (2, 20.0), (3, 150.0)] {
            let (mut scale, _) = scene(0.43);
            let mut cell = Cell::seeded(0.43, seed);
            let mut recent = VecDeque::new();
            checked((&mut scale, &mut cell, &mut recent), 4000, |_| 0.0, "empty");
            checked(
                (&mut scale, &mut cell, &mut recent),
                4400,
                |_| item_g,
                "put on",
            );
            let ramp = |k: usize| (item_g * (1.0 - k as f64 / 600.0)).max(0.0);
            let readings = checked(
                (&mut scale, &mut cell, &mut recent),
                8000,
                ramp,
                "taken off",
            );
            let last = readings.last().unwrap();
            assert_eq!(last.state, ScaleState::Empty, "{item_g} g: {last:?}");
        }
    }

    /// An item of a few grams put on by hand (over 100 ms) 1.5-2.2 s after a heavy load was
    /// set down: the load still rang by grams, the raw tests allowed for it, and the old
    /// mass stayed `Stable` while the item arrived (`host-sim torture --runs 10000 --seed 1`:
    /// 0.72 g off at 480 g, run 4700). The residual motion test sees it through the ringing.
    #[test]
    fn an_item_put_on_a_ringing_heavy_load_stops_the_old_mass_being_stable() {
        for (seed, item_g, sit) in [
            (1, 1.0, 6000),
            (2, 3.0, 7000),
            (3, 4.0, 8000),
            (4, 2.0, 8800),
        ] {
            let (mut scale, _) = scene(0.6);
            let mut cell = Cell::heavy(0.6, seed);
            let mut recent = VecDeque::new();
            let scene = (&mut scale, &mut cell, &mut recent);
            checked(scene, 4000, |_| 0.0, "empty");
            let scene = (&mut scale, &mut cell, &mut recent);
            checked(scene, sit, |_| 400.0, "set down");
            let ramp = |k: usize| 400.0 + item_g * (k as f64 / 400.0).min(1.0);
            let scene = (&mut scale, &mut cell, &mut recent);
            checked(
                scene,
                4000,
                ramp,
                &std::format!("{item_g} g put on, seed {seed}"),
            );
        }
    }

    /// Items of 0.3-2 g arriving by hand (over 50-300 ms) on 150 g still ringing: a reading
    /// is final only while its estimate has held its band for the hold time. Final asked
    /// only for the bound and no motion, and the estimate of an arriving item could jump out
    /// of its band (the state `estimating`) and still be final, 0.55 g away from where it
    /// was 50 ms before (12 of these 64 scenes; `host-sim torture --runs 10000 --seed 1`,
    /// run 9291: final 0.21 g off, permissible 0.08 g).
    #[test]
    fn a_reading_whose_estimate_left_its_band_is_not_final() {
        for seed in 25..41u64 {
            for (item_g, arrive) in [(0.3, 200usize), (1.0, 400), (2.0, 800), (0.5, 1200)] {
                let (mut scale, _) = scene(0.3);
                let mut cell = Cell::heavy(0.3, seed);
                run(&mut scale, &mut cell, 4000);
                cell.load_g = 150.0;
                run(&mut scale, &mut cell, 8000 + (seed as usize * 37) % 400);
                let band = 2.0
                    * (scale.config().stable_band_g + 150.0 * scale.config().stable_band_relative);
                let mut recent = VecDeque::new();
                for k in 0..3000 {
                    cell.load_g = 150.0 + item_g * (k as f64 / arrive as f64).min(1.0);
                    let reading = scale.push(cell.sample());
                    match reading.mass_g {
                        Some(mass) => recent.push_back(mass),
                        None => recent.clear(),
                    }
                    if recent.len() > PERIOD {
                        recent.pop_front();
                    }
                    if reading.is_final {
                        let low = recent.iter().cloned().fold(f32::INFINITY, f32::min);
                        let high = recent.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                        assert!(
                            high - low <= band,
                            "seed {seed}, {item_g} g, sample {k}: final over {} g ({reading:?})",
                            high - low
                        );
                    }
                }
            }
        }
    }

    /// An item placed by hand on an empty pan (rising over 200 ms): a run restarted
    /// mid-rise read about zero with a `u` of grams, and showed `Empty`. (`checked` holds
    /// every settled reading to the truth; the item must also be shown `Stable` within the
    /// 2 s. Until stop 41 it was `Stable` at the end of them: since the trend window takes
    /// blocks once the ringing is measured over, its young lines doubt 8 g on this pan of
    /// 0.43 g of raw noise by then, and the reading is `Stable` 31 % of its second second.)
    #[test]
    fn an_item_placed_by_hand_is_not_shown_empty_on_its_way() {
        for (seed, item_g) in [(4, 5.0), (5, 8.0), (6, 60.0)] {
            let (mut scale, _) = scene(0.43);
            let mut cell = Cell::seeded(0.43, seed);
            let mut recent = VecDeque::new();
            checked((&mut scale, &mut cell, &mut recent), 8000, |_| 0.0, "empty");
            let rise = |k: usize| item_g * (k as f64 / 800.0).min(1.0);
            let readings = checked((&mut scale, &mut cell, &mut recent), 8000, rise, "placed");
            let stable = readings
                .iter()
                .filter(|r| r.state == ScaleState::Stable)
                .count();
            assert!(stable > 0, "{item_g} g: {:?}", readings.last());
        }
    }

    /// A load trickling on (0.02 and 0.04 g/s, sand or a leaking cup) onto a settled
    /// load: a reading creeping out of its stability band reset the raw test's arming,
    /// so the block test never ran, and the display lagged 0.3 g behind, `Stable`; later a
    /// run restarted mid-trickle read the step model's extrapolation of the ramp, 0.051 g
    /// behind at 0.04 g/s with u = 0.022 g, `Stable` before the raw tests armed (the block
    /// test now runs from the first held reading and counts its block in progress).
    #[test]
    fn a_trickle_is_never_shown_stable_behind_the_load() {
        for (seed, rate_g_per_s) in [(7, 0.02), (8, 0.04)] {
            let (mut scale, _) = scene(0.43);
            let mut cell = Cell::seeded(0.43, seed);
            let mut recent = VecDeque::new();
            checked((&mut scale, &mut cell, &mut recent), 2000, |_| 0.0, "empty");
            checked(
                (&mut scale, &mut cell, &mut recent),
                12_000,
                |_| 20.0,
                "settling",
            );
            let trickle = |k: usize| 20.0 + rate_g_per_s * k as f64 / 4000.0;
            let readings = checked(
                (&mut scale, &mut cell, &mut recent),
                80_000,
                trickle,
                "trickle",
            );
            assert!(
                readings.last().unwrap().load_changes > 1,
                "{rate_g_per_s} g/s: the trickle went unseen"
            );
        }
    }

    /// Sand trickling onto the pan for 25 s (0.02–0.05 g/s) on a noisy pan (0.85 g of raw
    /// noise: a block mean of 0.1 s scatters by 0.04 g, nearly the 0.05 g permissible): the
    /// CUSUM tests' allowances hid a lag of 0.05–0.07 g for up to a second, and the reading
    /// was shown stable or empty that far behind (`host-sim torture --runs 1000 --seed 1`:
    /// 85 of 100 silent wrong readings were trickles, this scene its run 447). The trend
    /// test sees the slope over the last 10 s instead.
    ///
    /// Not covered, and not claimed: a trickle that begins within about 3.5 s of power-up
    /// (the window fills only once the ringing is over, 1.5 s, and judges from 2 s of
    /// blocks). On this pan a 0.03 g/s trickle begun 1.5 s after power-up was shown
    /// `Empty` 0.05 g behind after another 1.5 s: no test can see that slope yet (its t is
    /// about 1), and the reading averages the 3 s run.
    #[test]
    fn a_trickle_on_a_noisy_pan_is_seen_by_its_slope() {
        for (seed, rate_g_per_s) in [(11, 0.02), (12, 0.03), (13, 0.04), (14, 0.05)] {
            let (mut scale, _) = scene(0.85);
            let mut cell = Cell::seeded(0.85, seed);
            let mut recent = VecDeque::new();
            let what = std::format!("{rate_g_per_s} g/s");
            checked((&mut scale, &mut cell, &mut recent), 32_000, |_| 0.0, &what);
            let trickle = |k: usize| rate_g_per_s * k as f64 / 4000.0;
            checked(
                (&mut scale, &mut cell, &mut recent),
                100_000,
                trickle,
                &what,
            );
        }
    }

    /// A trickle begun soon after a change on a noisy pan (0.85 g of raw noise, cell seeded
    /// by `seed`): 2 s of empty pan, `load_g` set down (none: the empty pan goes on), and
    /// `after_s` later sand trickling on at `rate_g_per_s` for 6 s, every settled reading
    /// checked against the truth.
    fn trickle_after_a_change(seed: u64, load_g: f64, after_s: f64, rate_g_per_s: f64) {
        let (mut scale, _) = scene(0.85);
        let mut cell = Cell::seeded(0.85, seed);
        let mut recent = VecDeque::new();
        let what = std::format!("{rate_g_per_s} g/s onto {load_g} g after {after_s} s");
        checked((&mut scale, &mut cell, &mut recent), 8000, |_| 0.0, &what);
        let before = (after_s * 4000.0) as usize;
        checked(
            (&mut scale, &mut cell, &mut recent),
            before,
            |_| load_g,
            &what,
        );
        let trickle = |k: usize| load_g + rate_g_per_s * k as f64 / 4000.0;
        checked((&mut scale, &mut cell, &mut recent), 24_000, trickle, &what);
    }

    /// The kinds of scene of [`trickle_after_a_change`] the tests below draw on: load,
    /// delay and rate.
    const TRICKLES_AFTER_A_CHANGE: [(f64, f64, f64); 4] = [
        (20.0, 1.7, 0.04),
        (5.0, 2.0, 0.03),
        (0.0, 2.0, 0.04),
        (0.0, 1.5, 0.03),
    ];

    /// No test can see the slope of these trickles before the reading lags by the
    /// permissible error (see the test above), and each was shown `Stable` or `Empty`
    /// 0.05-0.07 g behind (`host-sim torture --runs 10000 --seed 1`: 91 of 138 silent wrong
    /// readings were trickles, 44 of them shown `Empty`, each begun within a few seconds of
    /// a load change). The trend window vouches for a settled reading: the load now, by
    /// the lines through its last blocks, within the permissible error of it. The first
    /// five scenes were wrong before it did; the last three (seeds 101 and 123) while each
    /// line's last value was taken within two standard errors, not Student's t at
    /// z = 2.5 for its degrees of freedom (`trend::PROOF_T`).
    #[test]
    fn a_trickle_begun_soon_after_a_change_is_not_shown_settled_behind() {
        for (seed, load_g, after_s, rate_g_per_s) in [
            (105u64, 20.0, 1.7, 0.04),
            (105, 5.0, 2.0, 0.03),
            (106, 0.0, 2.0, 0.04),
            (120, 0.0, 1.5, 0.03),
            (121, 0.0, 1.5, 0.03),
            (101, 0.0, 2.0, 0.04),
            (101, 0.0, 1.5, 0.03),
            (123, 5.0, 2.0, 0.03),
        ] {
            trickle_after_a_change(seed, load_g, after_s, rate_g_per_s);
        }
    }

    /// The same four kinds of scene on 100 seeds none of the settings was chosen on
    /// (130-229): at most one scene in 50 may be shown settled wrong. Figures:
    /// `cargo test -p estimator-core --lib trickles_begun_soon_after_a_change_on_fresh_seeds -- --nocapture`:
    /// 3 of 400 with Student's t at z = 2.5; 22 of 400 with two standard errors; seeds
    /// 100-129 (where the test above found its scenes): 0 and 3 of 120.
    #[test]
    fn trickles_begun_soon_after_a_change_on_fresh_seeds() {
        let mut wrong = std::vec::Vec::new();
        let mut scenes = 0;
        for seed in 130..230u64 {
            for (load_g, after_s, rate_g_per_s) in TRICKLES_AFTER_A_CHANGE {
                scenes += 1;
                let outcome = std::panic::catch_unwind(|| {
                    trickle_after_a_change(seed, load_g, after_s, rate_g_per_s);
                });
                if outcome.is_err() {
                    wrong.push((seed, load_g, after_s, rate_g_per_s));
                }
            }
        }
        std::eprintln!(
            "{} of {scenes} scenes shown settled wrong: {wrong:?}",
            wrong.len()
        );
        assert!(wrong.len() * 50 <= scenes, "{wrong:?}");
    }

    /// A load left on the pan while the zero drifts at the fastest rate the configuration
    /// allows (2 e in 10 minutes, OIML R 76's 1 e per 5 °C in a room swinging 10 °C): no
    /// tracking can follow it under a load, and the reading moves with it while the truth
    /// stays. On a quiet pan (0.1 g of raw noise) 20 g, whose permissible error is 0.5 e,
    /// was shown stable and final 0.05 g off, its `u` 0.001 g
    /// (`host-sim torture --runs 10000 --seed 1`: 73 silent wrong readings before the drift
    /// was in `u`, 37 with it). The zero's drift since it was last seen is
    /// now in every reading's `u`, and a reading whose `u` grew past a quarter of the
    /// permissible error is not shown stable; with the pan emptied the zero is seen again.
    #[test]
    fn a_load_left_on_a_drifting_zero_is_not_shown_settled_off() {
        let (mut scale, mut cell) = scene(0.1);
        let mut recent = VecDeque::new();
        let drift_counts_per_block = f64::from(
            ScaleConfig::FASTEST_ZERO_DRIFT_E_PER_S * ScaleConfig::SCALE_INTERVAL_G * CPG * 0.1,
        );
        let mut stable_at = std::vec::Vec::new();
        let mut last = None;
        for block in 0..(200 * 10) {
            let load_g = if (20..1820).contains(&block) {
                20.0
            } else {
                0.0
            };
            let readings = checked(
                (&mut scale, &mut cell, &mut recent),
                400,
                |_| load_g,
                "20 g on a drifting zero",
            );
            cell.offset_counts += drift_counts_per_block;
            last = readings.last().copied();
            if last.is_some_and(|r| r.state == ScaleState::Stable) {
                stable_at.push(block);
            }
        }
        // Shown stable soon after it was set down, and not after 90 s on (the drift's `u`
        // reaches a quarter of 0.05 g at about 65 s).
        assert!(stable_at.first().is_some_and(|&b| b < 60), "{stable_at:?}");
        assert!(
            !stable_at.iter().any(|&b| (920..1820).contains(&b)),
            "{stable_at:?}"
        );
        // Emptied, the pan reads the zero's drift, 0.06 g: beyond the band zero tracking
        // may pull from, so not shown empty. Zero setting takes it back, though the
        // reading is not stable (its `u` carries 3 minutes of drift).
        let emptied = last.unwrap();
        assert_eq!(emptied.state, ScaleState::Estimating, "{emptied:?}");
        assert_eq!(scale.set_zero(), Ok(()));
        let readings = checked(
            (&mut scale, &mut cell, &mut recent),
            4000,
            |_| 0.0,
            "zero set",
        );
        let end = readings.last().unwrap();
        assert_eq!(end.state, ScaleState::Empty, "{end:?}");
        assert!(end.uncertainty_g.is_some_and(|u| u < 0.01), "{end:?}");
    }

    /// On a pan with 0.43 g of raw noise (cell seeded by `seed`): 1 s empty, `load_g` set
    /// down for `after_s`, then `item_g` placed by hand (rising over 130 ms) and 2 s more,
    /// every settled reading checked against the truth.
    fn item_placed_after_a_load(seed: u64, load_g: f64, after_s: f64, item_g: f64) {
        let (mut scale, _) = scene(0.43);
        let mut cell = Cell::seeded(0.43, seed);
        let mut recent = VecDeque::new();
        let what = std::format!("{item_g} g onto {load_g} g after {after_s} s");
        checked((&mut scale, &mut cell, &mut recent), 4000, |_| 0.0, &what);
        let set = (after_s * 4000.0) as usize;
        checked((&mut scale, &mut cell, &mut recent), set, |_| load_g, &what);
        let rise = |k: usize| load_g + item_g * (k as f64 / 520.0).min(1.0);
        checked((&mut scale, &mut cell, &mut recent), 8000, rise, &what);
    }

    /// An item of 0.6-2 g placed by hand (rising over 130 ms) on a load set down 1.5-1.9 s
    /// before: the ringing allowance of the raw and block tests (four times the step,
    /// decaying to e⁻⁵ over 1.5 s) was grams to tens of grams then, where the cell rang by
    /// a few hundredths, and the old mass stayed on show, `Stable`, while the item arrived
    /// (`host-sim torture --runs 1000 --seed 1`: 7 of 29 silent wrong readings, run 720
    /// shown 215.71 g with 216.0-217.2 g on the pan). The ringing measured caps it now.
    #[test]
    fn an_item_placed_soon_after_a_load_is_not_shown_stable_without_it() {
        for (seed, load_g, after_s, item_g) in [
            (22, 215.0, 1.9, 1.5),
            (23, 438.0, 1.85, 2.0),
            (24, 300.0, 1.6, 0.6),
            (21u64, 166.0, 1.5, 1.07),
        ] {
            item_placed_after_a_load(seed, load_g, after_s, item_g);
        }
    }

    /// The limit of the test above: an item smaller than the ringing still on the pan.
    /// 1.1 s after 166 g was set down on this cell (ζ = 0.03) it rings by about 0.9 g, and
    /// 64 ms into the arrival of a 1.07 g item (half of it on) the old mass is still shown
    /// `Stable`, 0.1 g below the truth of the last readout period; it leaves `Stable` at the
    /// next (`host-sim torture --runs 1000 --seed 1`, run 381). Seeing it sooner needs the
    /// ringing predicted, not allowed for.
    #[test]
    #[ignore = "known limit: an item smaller than the ringing still on the pan is seen a readout period late"]
    fn an_item_smaller_than_the_ringing_is_seen_within_a_readout_period() {
        for (seed, load_g, after_s, item_g) in [(21u64, 166.0, 1.1, 1.07), (25, 152.0, 0.9, 0.5)] {
            item_placed_after_a_load(seed, load_g, after_s, item_g);
        }
    }

    /// Small loads (10 g: the permissible error is 0.5 e) dropped on a noisy pan, forty
    /// times: no reading is shown stable, empty or final outside the permissible error.
    /// With twice `u` within it (a 95 % interval) the first settled readings of some drops
    /// lay 2–3 u off, beyond it (`host-sim torture`: 186 of 675 silent wrong readings).
    #[test]
    fn small_loads_on_a_noisy_pan_are_never_shown_settled_outside_the_permissible_error() {
        for seed in 0..40u64 {
            let (mut scale, _) = scene(1.0);
            let mut cell = Cell::seeded(1.0, 100 + seed);
            let mut recent = VecDeque::new();
            let what = std::format!("seed {seed}");
            checked((&mut scale, &mut cell, &mut recent), 4000, |_| 0.0, &what);
            checked((&mut scale, &mut cell, &mut recent), 8000, |_| 10.0, &what);
        }
    }

    /// A trickle (0.04 g/s) onto a small load on a noisy pan (1 g of raw noise), from the
    /// moment it is put on, for 4 s: never shown settled behind the load. The scene of
    /// `host-sim torture --runs 1000 --seed 1` run 72 (which `host-sim`'s torture tests
    /// replay themselves), where the first certain reading of the fit was shown stable
    /// 0.09 g behind the load before the block test had judged a block.
    #[test]
    fn a_trickle_onto_a_fresh_load_is_not_shown_stable_behind_it() {
        for seed in 0..6u64 {
            let (mut scale, _) = scene(1.0);
            let mut cell = Cell::seeded(1.0, 200 + seed);
            let mut recent = VecDeque::new();
            // Long enough for the empty pan's noise to be metered.
            checked(
                (&mut scale, &mut cell, &mut recent),
                10_000,
                |_| 0.0,
                "empty",
            );
            let trickle = |k: usize| 0.3 + 0.04 * k as f64 / 4000.0;
            checked(
                (&mut scale, &mut cell, &mut recent),
                16_000,
                trickle,
                "trickle",
            );
        }
    }
}
