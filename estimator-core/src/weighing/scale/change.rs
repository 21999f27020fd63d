//! Load-change detection: two-sided CUSUM tests (Page 1954), one on the estimator's
//! a-priori residuals, one on the raw samples against the displayed gross mass (see the
//! `Scale` module docs for why two, and when each is armed), and one on block means of the
//! raw samples against it, armed with the raw test, which sees an item of one scale
//! interval.
//!
//! A NaN deviation must never poison the sums: it resets them.

use super::{Scale, ScaleEstimator, ScaleReading, ScaleState};

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
}

impl<E: ScaleEstimator> Scale<E> {
    /// The residual test, once per decimated update and once the fit is determined enough:
    /// true when it alarms.
    pub(super) fn residual_alarm(&mut self, residual_counts: Option<f32>) -> bool {
        let new_update = self
            .samples_since_change
            .is_multiple_of(u64::from(self.samples_per_update));
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

    /// The raw tests against the displayed gross mass, once the signal has settled: true
    /// when either alarms. One on each sample (a large change alarms within ms), one on
    /// block means of `block_samples` (a change of one scale interval alarms: the raw
    /// noise would hide it from the first).
    pub(super) fn raw_alarm(&mut self, counts: i32) -> bool {
        let Some(gross) = self.gross_g else {
            self.block_sum_g = 0.0;
            self.block_filled = 0;
            return false;
        };
        if self.settled_samples < self.config.raw_arm_samples {
            self.block_sum_g = 0.0;
            self.block_filled = 0;
            return false;
        }
        let deviation_g = (counts as f32 - self.zero_counts) * self.grams_per_count - gross;
        let raw = self.raw_cusum.step(
            deviation_g,
            self.config.raw_drift_g,
            self.config.raw_threshold_g,
        );
        self.block_sum_g += deviation_g;
        self.block_filled += 1;
        if self.block_filled < self.config.block_samples {
            return raw;
        }
        let block_mean_g = self.block_sum_g / self.block_filled as f32;
        self.block_sum_g = 0.0;
        self.block_filled = 0;
        let block = self.block_cusum.step(
            block_mean_g,
            self.config.block_drift_g,
            self.config.block_threshold_g,
        );
        raw || block
    }

    /// A load changed: a new run.
    pub(super) fn load_changed(&mut self) -> ScaleReading {
        self.restart_as_load_change();
        self.state = ScaleState::Estimating;
        self.reading()
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_scene::{run, scene, Cell};
    use super::super::ScaleConfig;
    use super::*;

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
