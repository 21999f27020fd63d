//! The raw samples' white noise, from their sample-to-sample differences, on every pan.
//!
//! A fit of a few rows can all but interpolate its data: a run restarted on a resting load
//! (a cascade of restarts on a vibrating pan, a trickle) has no transient for its
//! parameters to explain, so they explain the noise, and the residuals' level falls far
//! below the block means' noise. Its `u` then says milligrams on a pan that scatters by a
//! tenth of a gram (`host-sim torture --runs 1000 --seed 1`, run 976: a fit of 14 blocks
//! on a 0.37 g vibration stated u = 0.0037 g and was final 0.13 g off). The empty pan's
//! metered noise (`noise`) is a floor for that `u`, but a pan that never reads empty and
//! settled is never metered, and that is the vibrating one.
//!
//! The differences of consecutive raw samples see the white noise on any pan, loaded,
//! ringing or vibrating: a ringing of amplitude `A` at `f` adds only `(2πf/fs)²·A²/2` to
//! their mean square (0.15 % of `A²/2` at 25 Hz and 4 kHz), a load step one difference.
//! Half their mean square over a block of `block_samples` is one measurement of the
//! per-sample white variance; the floor handed to each new run is the smallest of the last
//! [`WHITE_BLOCKS`] (the first blocks of a heavy drop ring by grams, and their differences
//! with them: the minimum is from a quiet block). The run in progress when the meter's
//! first block ends (the power-up run, which began before there was any) gets it then:
//! handed only at restarts, that run's `u` went without a floor for as long as it lasted
//! (test `the_power_up_run_rests_its_u_on_the_white_noise_once_metered`). A floor a
//! little low is harmless (the residuals' own level is stated where it is higher); one
//! too high would only widen `u`, and the minimum keeps it low: the white noise of the
//! front end is all it can see.
//!
//! Cost per sample: one subtraction, a multiply-add and a count, in the sample's integer
//! counts (no gain, no zero: a recalibration leaves it as it is).

/// Blocks whose smallest white-noise measurement is the floor: 1.6 s of 0.1 s blocks,
/// longer than a heavy drop rings by more than its white noise.
pub(super) const WHITE_BLOCKS: usize = 16;

use crate::estimators::consistency::NoiseReference;

/// The white noise of the raw samples, block by block (see the module docs).
#[derive(Clone, Debug)]
pub(super) struct WhiteNoise {
    /// The last good sample, `None` after a fault (no difference spans a gap).
    previous: Option<i32>,
    /// Σ d² and the differences of the block in progress.
    sum_counts2: f32,
    differences: u32,
    /// The last blocks' variances (counts² per sample), newest at `next − 1`.
    blocks: [f32; WHITE_BLOCKS],
    next: usize,
    filled: usize,
}

impl WhiteNoise {
    pub(super) fn new() -> Self {
        Self {
            previous: None,
            sum_counts2: 0.0,
            differences: 0,
            blocks: [0.0; WHITE_BLOCKS],
            next: 0,
            filled: 0,
        }
    }

    /// One good sample; a block ends every `block_samples` differences. True when that
    /// block was the meter's first: from then on [`Self::variance`] has a value.
    pub(super) fn push(&mut self, counts: i32, block_samples: u32) -> bool {
        let mut first = false;
        if let Some(previous) = self.previous {
            let difference = counts.saturating_sub(previous) as f32;
            self.sum_counts2 += difference * difference;
            self.differences += 1;
            if self.differences >= block_samples {
                let before = self.filled;
                self.end_block();
                first = before == 0 && self.filled > 0;
            }
        }
        self.previous = Some(counts);
        first
    }

    /// A sample lost or saturated: the next difference would span the gap.
    pub(super) fn gap(&mut self) {
        self.previous = None;
    }

    fn end_block(&mut self) {
        let variance = 0.5 * self.sum_counts2 / self.differences as f32;
        self.sum_counts2 = 0.0;
        self.differences = 0;
        if !variance.is_finite() {
            return;
        }
        self.blocks[self.next] = variance;
        self.next = (self.next + 1) % WHITE_BLOCKS;
        self.filled = (self.filled + 1).min(WHITE_BLOCKS);
    }

    /// The per-sample white variance in counts², the smallest of the last blocks; `None`
    /// before the first whole block.
    pub(super) fn variance(&self) -> Option<f32> {
        self.blocks[..self.filled]
            .iter()
            .copied()
            .reduce(|a, b| if b < a { b } else { a })
    }

    /// [`Self::variance`] as the estimator takes it: the differences of one block
    /// (`block_samples`) are what it rests on.
    pub(super) fn reference(&self, block_samples: u32) -> Option<NoiseReference<f32>> {
        self.variance()
            .map(|variance| NoiseReference::new(variance, block_samples))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tuning::synthetic::gaussian;

    const BLOCK: u32 = 400;

    /// White noise of σ counts on a constant, plus `ring` counts of a 25 Hz ringing
    /// decaying over 0.5 s from sample `ring_from` on.
    fn feed(meter: &mut WhiteNoise, sigma: f64, samples: usize, ring: f64, seed: u64) {
        for k in 0..samples {
            let t = k as f64 / 4000.0;
            let ringing =
                ring * libm::exp(-t / 0.5) * libm::sin(2.0 * core::f64::consts::PI * 25.0 * t);
            let counts = 30_000.0 + ringing + sigma * gaussian(seed, k as u64);
            meter.push(libm::round(counts) as i32, BLOCK);
        }
    }

    #[test]
    fn the_floor_is_the_white_noise_and_not_above_it() {
        for sigma in [3.0, 14.0, 60.0] {
            let mut meter = WhiteNoise::new();
            assert_eq!(meter.variance(), None);
            feed(&mut meter, sigma, 20 * BLOCK as usize, 0.0, 1);
            let measured = meter.variance().unwrap() as f64;
            let truth = sigma * sigma + 1.0 / 12.0;
            // The minimum of 16 blocks of 400 differences (each within about 9 %) lies a
            // little below the variance, never above it by more than chance.
            assert!(
                measured < 1.02 * truth,
                "{sigma}: {measured} against {truth}"
            );
            assert!(
                measured > 0.7 * truth,
                "{sigma}: {measured} against {truth}"
            );
        }
    }

    /// A heavy drop rings by thousands of counts; its differences are far above the white
    /// noise while it rings, and the floor stays the noise's.
    #[test]
    fn a_ringing_drop_does_not_raise_the_floor() {
        let mut meter = WhiteNoise::new();
        feed(&mut meter, 14.0, 8 * BLOCK as usize, 0.0, 2);
        let before = meter.variance().unwrap();
        feed(&mut meter, 14.0, 8 * BLOCK as usize, 8_000.0, 3);
        let after = meter.variance().unwrap();
        assert!(after <= before * 1.05, "{before} -> {after}");
        // Even a window that rang throughout (1.6 s from 8,000 counts) ends below four
        // times the noise: the differences see 0.15 % of a 25 Hz ringing's power.
        let mut ringing = WhiteNoise::new();
        feed(
            &mut ringing,
            14.0,
            WHITE_BLOCKS * BLOCK as usize,
            8_000.0,
            4,
        );
        let floor = ringing.variance().unwrap() as f64;
        assert!(floor < 4.0 * 14.0 * 14.0, "{floor}");
    }

    /// A board switched on with a load on the pan never reads empty, so it never meters
    /// the empty pan's noise; a run restarted on that resting load (here by a lost sample)
    /// has no transient to fit. Its first `u` rests on the raw samples' white noise: ±2u
    /// covers the first errors as a 95 % interval should: 57 of 2,000 beyond it (2.9 %; 96,
    /// 4.8 %, with the errors-in-variables bias weighed by the rows' noise share, tried and
    /// reverted at stop 51; without the floor 26 of 200, 13 %, at 0.3–1 g of noise alike).
    /// The test allows the 95 % goal's Monte Carlo scatter, 5 % plus three binomial standard
    /// deviations of the count (until stop 51 it allowed 10 of 200, which a calibrated `u`
    /// exceeds four times in ten).
    #[test]
    fn a_run_restarted_on_a_resting_load_is_not_overconfident() {
        use super::super::test_scene::{run, scene};
        use super::super::RawSample;
        let (mut scale, mut cell) = scene(1.0);
        cell.load_g = 100.0;
        run(&mut scale, &mut cell, 12_000);
        let restarts: u32 = 2000;
        let (mut stated, mut outside) = (0, 0);
        for _ in 0..restarts {
            scale.push(RawSample::Lost);
            for _ in 0..4000 {
                let reading = scale.push(cell.sample());
                if let (Some(mass), Some(u)) = (reading.mass_g, reading.uncertainty_g) {
                    stated += 1;
                    outside += u32::from((mass - 100.0).abs() > 2.0 * u);
                    break;
                }
            }
        }
        assert_eq!(stated, restarts, "every run states a u");
        let expected = 0.05 * f64::from(restarts);
        let allowed = expected + 3.0 * (expected * 0.95).sqrt();
        assert!(
            f64::from(outside) <= allowed,
            "{outside} of {restarts} beyond 2u (at most {allowed:.0})"
        );
    }

    #[test]
    fn no_difference_spans_a_gap() {
        let mut meter = WhiteNoise::new();
        for k in 0..(3 * BLOCK) {
            // A constant on each side of a lost stretch 5,000 counts away.
            meter.push(if k < BLOCK { 1_000 } else { 6_000 }, BLOCK);
            if k + 1 == BLOCK {
                meter.gap();
            }
        }
        assert_eq!(meter.variance(), Some(0.0));
    }

    /// The power-up run: its fit of an empty pan has no transient to fit, and a fit of a few
    /// rows can all but interpolate its noise; the white-noise floor under its `u` is what
    /// keeps that `u` honest (`estimators::step_uncertainty`). The scale hands the floor to
    /// the estimator at each restart, and at power-up the meter has no block yet: before
    /// the meter's first value went to the running estimator, the power-up run went without
    /// it for as long as it lasted (`host-sim torture --runs 10000 --seed 1`, run 2501:
    /// shown empty 0.052 g off at 0.25 s with u = 0.009 g). Over 400 power-ups on an empty
    /// pan with 0.45 g of raw noise, the readout lines from 0.15 s to 0.5 s (3,200, none
    /// after a load change): 7.3 % beyond 2u without the floor, 4.2 % with it. A calibrated
    /// 95 % interval leaves 5 % out, within ±0.8 % over 3,200 independent lines (fewer
    /// here: 8 lines a power-up), so the test asks for at most 6 %.
    #[test]
    fn the_power_up_run_rests_its_u_on_the_white_noise_once_metered() {
        use super::super::test_scene::{new_scale, Cell};
        let seeds = 400_u64;
        let mut outside = 0_u64;
        let mut stated = 0_u64;
        for seed in 0..seeds {
            let mut scale = new_scale();
            let mut cell = Cell::seeded(0.45, seed);
            for k in 1..=2000 {
                let reading = scale.push(cell.sample());
                // Every readout line (20 Hz) from 0.15 s on: the meter's first block ends
                // at 0.1 s.
                if k < 600 || k % 200 != 0 {
                    continue;
                }
                assert_eq!(reading.load_changes, 0, "seed {seed}: {reading:?}");
                if let (Some(mass), Some(u)) = (reading.mass_g, reading.uncertainty_g) {
                    stated += 1;
                    outside += u64::from(mass.abs() > 2.0 * u);
                }
            }
        }
        assert!(
            stated >= seeds * 8 * 9 / 10,
            "{stated} of {} stated u",
            seeds * 8
        );
        assert!(
            outside * 100 <= 6 * stated,
            "{outside} of {stated} beyond 2u"
        );
    }
}
