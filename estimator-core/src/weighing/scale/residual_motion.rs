//! The residual motion test: the estimator's a-priori residuals, averaged over stretches
//! of a block, against their own block means' scatter.
//!
//! Why a fourth look at the same data: the raw tests compare samples with the shown mass,
//! so they must allow for the ringing of the load that started the run. A heavy load
//! dropped on the reference cell (400 g rings near 13 Hz with ζ = 0.03) still rings by
//! grams two seconds later, and an item of a few grams put on by hand then hid inside that
//! allowance while it arrived: the old mass stayed `Stable` up to 0.7 g off
//! (`host-sim torture --runs 10000 --seed 1`: the 20 worst of its 171 silent wrong
//! readings, every one within 0.7–2.3 s of a placement of 200–480 g). The residuals are
//! what the fitted model cannot explain: the ringing is explained, a new load is not (the
//! a-priori residual steps by the load added). The residual test proper
//! (`change::residual_alarm`) judges single residuals with a drift of grams, for a fresh
//! fit's sake; this one waits until the run's residual block means have a scatter
//! ([`MIN_PAIRS`] differences), then judges the mean residual from each part boundary of
//! the block in progress to now, as `change::judge_parts` does with the raw samples: it is
//! motion when it lies [`Z`] standard errors out and beyond the same floor (a part of the
//! permissible error). Motion is not a change: the reading is only kept from being shown
//! stable or final; the change tests restart the run when the load has settled.
//!
//! Cost: once per regression update (every `D` samples), up to [`PARTS`] comparisons.

/// How many standard errors the mean residual of a stretch must lie out to be motion.
const Z: f32 = 5.0;

/// Differences of consecutive block means of residuals the run must have first (the first
/// residuals of a fit are large, and a scatter of fewer is itself too uncertain).
const MIN_PAIRS: u32 = 4;

/// The last differences of consecutive block means the scatter is taken from.
const SCATTER_BLOCKS: usize = 16;

/// The parts of a block (a part is where a stretch may start).
pub(super) const PARTS: usize = 4;

/// The whole parts a stretch may reach back over: two blocks, so a stretch goes on across
/// a block boundary instead of starting over there (an item arriving late in a block was
/// motion for one update, then not at the next block's start).
const REACH: usize = 2 * PARTS;

/// The residual motion test's sums for one run (cleared at every restart).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ResidualMotion {
    /// Σ residual of the part in progress, g, and the updates in it.
    part_sum_g: f32,
    part_filled: u32,
    /// The sums of the last whole parts, g (newest at `parts % REACH`), and how many.
    part_sums_g: [f32; REACH],
    parts: u32,
    /// Σ residual of the block in progress, g, its updates, and whether it held motion.
    block_sum_g: f32,
    block_filled: u32,
    block_moving: bool,
    /// The last squared differences of consecutive still block means (g²), how many in
    /// the run, and the last still block's mean (`None` after a block with motion: its
    /// difference would be the motion, not the scatter).
    squares_g2: [f32; SCATTER_BLOCKS],
    pairs: u32,
    last_mean_g: Option<f32>,
    /// Set at each block's start, for the updates of the block: the least mean residual
    /// that is motion (g), and `Z²` times one update's share of the block means'
    /// variance (g², +∞ while the scatter is not known).
    floor_g: f32,
    z2_variance_g2: f32,
    /// The last judgement.
    pub(super) moving: bool,
}

impl Default for ResidualMotion {
    fn default() -> Self {
        Self {
            part_sum_g: 0.0,
            part_filled: 0,
            part_sums_g: [0.0; REACH],
            parts: 0,
            block_sum_g: 0.0,
            block_filled: 0,
            block_moving: false,
            squares_g2: [0.0; SCATTER_BLOCKS],
            pairs: 0,
            last_mean_g: None,
            floor_g: f32::INFINITY,
            z2_variance_g2: f32::INFINITY,
            moving: false,
        }
    }
}

impl ResidualMotion {
    /// Start over for a new run. Only what marks the arrays' filling is cleared: a restart
    /// is on the firmware's budget, and entries past `parts` or `pairs` are never read.
    pub(super) fn clear(&mut self) {
        self.start_stretches_over();
        self.pairs = 0;
        self.z2_variance_g2 = f32::INFINITY;
    }

    /// The stretches and the block in progress start over; the scatter stays.
    fn start_stretches_over(&mut self) {
        self.part_sum_g = 0.0;
        self.part_filled = 0;
        self.parts = 0;
        self.block_sum_g = 0.0;
        self.block_filled = 0;
        self.block_moving = false;
        self.last_mean_g = None;
        self.moving = false;
    }

    /// A block is about to start: the caller hands over its floor (`at_block_start` says
    /// when, so the permissible error is worked out once per block, not per update).
    pub(super) fn at_block_start(&self) -> bool {
        self.block_filled == 0
    }

    /// The least mean residual that is motion for the block about to start, g.
    pub(super) fn set_floor(&mut self, floor_g: f32) {
        self.floor_g = floor_g;
    }

    /// One a-priori residual `residual_g` (grams) of a run whose blocks hold
    /// `updates_per_block` updates. Returns the judgement (also kept in `moving`).
    pub(super) fn push(&mut self, residual_g: f32, updates_per_block: u32) -> bool {
        if !residual_g.is_finite() {
            // Nothing to judge on.
            self.start_stretches_over();
            return false;
        }
        let block = updates_per_block.max(1);
        let part = (block / PARTS as u32).max(1);
        self.part_sum_g += residual_g;
        self.part_filled += 1;
        self.block_sum_g += residual_g;
        self.block_filled += 1;
        self.moving = self.judge(part);
        self.block_moving |= self.moving;
        if self.part_filled >= part {
            self.part_sums_g[self.parts as usize % REACH] = self.part_sum_g;
            self.parts = self.parts.saturating_add(1);
            self.part_sum_g = 0.0;
            self.part_filled = 0;
        }
        if self.block_filled >= block {
            self.end_block(block);
        }
        self.moving
    }

    /// Whether a stretch from the part in progress's start, or from one of the last
    /// [`REACH`] part boundaries, to now lies out (see the module docs): its sum beyond
    /// `floor · n` and its square beyond `Z² · variance · block · n` (no divisions).
    fn judge(&self, part: u32) -> bool {
        if self.z2_variance_g2 == f32::INFINITY {
            return false;
        }
        let reach = (self.parts as usize).min(REACH);
        let mut sum_g = self.part_sum_g;
        let mut updates = self.part_filled;
        for back in 0..=reach {
            if back > 0 {
                sum_g += self.part_sums_g[(self.parts as usize - back) % REACH];
                updates += part;
            }
            let n = updates as f32;
            let excess_g = sum_g.abs();
            if updates > 0
                && excess_g > self.floor_g * n
                && excess_g * excess_g > self.z2_variance_g2 * n
            {
                return true;
            }
        }
        false
    }

    /// A whole block of `block` updates: its mean's difference from the last still
    /// block's into the scatter, unless it held motion; the threshold for the next.
    fn end_block(&mut self, block: u32) {
        let mean_g = self.block_sum_g / self.block_filled as f32;
        if self.block_moving {
            self.last_mean_g = None;
        } else {
            if let Some(last_g) = self.last_mean_g {
                let difference = mean_g - last_g;
                let slot = self.pairs as usize % SCATTER_BLOCKS;
                self.squares_g2[slot] = difference * difference;
                self.pairs = self.pairs.saturating_add(1);
            }
            self.last_mean_g = Some(mean_g);
        }
        if self.pairs >= MIN_PAIRS {
            let pairs = (self.pairs as usize).min(SCATTER_BLOCKS);
            let squares: f32 = self.squares_g2[..pairs].iter().sum();
            // One block mean's variance is half the mean squared difference; a stretch of
            // n updates has variance `block / n` times that.
            self.z2_variance_g2 = Z * Z * 0.5 * squares / pairs as f32 * block as f32;
        }
        self.block_sum_g = 0.0;
        self.block_filled = 0;
        self.block_moving = false;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// A deterministic zero-mean "noise" of about `amplitude` (a fixed pseudo-random walk).
    fn noise(index: u32, amplitude: f32) -> f32 {
        let x = index.wrapping_mul(2_654_435_761) >> 8;
        amplitude * ((x % 2001) as f32 / 1000.0 - 1.0)
    }

    /// Push as the scale does: blocks of 16 updates, `floor_g` handed over at each start.
    fn push(test: &mut ResidualMotion, residual_g: f32, floor_g: f32) -> bool {
        if test.at_block_start() {
            test.set_floor(floor_g);
        }
        test.push(residual_g, 16)
    }

    #[test]
    fn still_residuals_are_not_motion_and_an_offset_is() {
        let mut test = ResidualMotion::default();
        for index in 0..16 * 20 {
            assert!(
                !push(&mut test, noise(index, 0.3), 0.0125),
                "update {index}"
            );
        }
        // A 0.5 g item: within a part of a block (4 updates) it is motion, and it stays
        // motion across the next block boundary.
        let seen: std::vec::Vec<bool> = (0..24)
            .map(|index| push(&mut test, 0.5 + noise(1000 + index, 0.3), 0.0125))
            .collect();
        let first = seen.iter().position(|&moving| moving);
        assert!(first.is_some_and(|at| at < 6), "{seen:?}");
        assert!(
            seen[first.unwrap()..].iter().all(|&moving| moving),
            "{seen:?}"
        );
    }

    #[test]
    fn nothing_is_judged_before_the_scatter_is_known_and_nan_is_no_motion() {
        let mut test = ResidualMotion::default();
        // Three whole blocks give two differences: too few.
        for _ in 0..16 * 3 {
            assert!(!push(&mut test, 5.0, 0.0));
        }
        assert!(!push(&mut test, f32::NAN, 0.0));
        assert!(!test.moving);
    }

    #[test]
    fn the_floor_keeps_a_tiny_offset_on_a_quiet_fit_from_being_motion() {
        let mut test = ResidualMotion::default();
        for index in 0..16 * 20 {
            push(&mut test, noise(index, 0.001), 0.0125);
        }
        // 0.01 g: far out in the scatter's terms, but below the floor.
        assert!(!(0..32).any(|index| push(&mut test, 0.01 + noise(index, 0.001), 0.0125)));
        // 0.02 g is above it.
        assert!((0..32).any(|index| push(&mut test, 0.02 + noise(index, 0.001), 0.0125)));
    }

    #[test]
    fn a_cleared_test_judges_nothing_until_it_has_a_scatter_again() {
        let mut test = ResidualMotion::default();
        for index in 0..16 * 20 {
            push(&mut test, noise(index, 0.3), 0.0125);
        }
        test.clear();
        assert!(!(0..16 * 4).any(|index| push(&mut test, 1.0 + noise(index, 0.3), 0.0125)));
    }
}
