//! Load-change detection: two two-sided CUSUM tests (Page 1954), one on the estimator's
//! a-priori residuals, one on the raw samples against the displayed gross mass (see the
//! `Scale` module docs for why two, and when each is armed).
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
        let new_update = self.samples_since_change % u64::from(self.samples_per_update) == 0;
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

    /// The raw test against the displayed gross mass, once the signal has settled: true
    /// when it alarms.
    pub(super) fn raw_alarm(&mut self, counts: i32) -> bool {
        let Some(gross) = self.gross_g else {
            return false;
        };
        if self.settled_samples < self.config.raw_arm_samples {
            return false;
        }
        let sample_g = (counts as f32 - self.zero_counts) * self.grams_per_count;
        self.raw_cusum.step(
            sample_g - gross,
            self.config.raw_drift_g,
            self.config.raw_threshold_g,
        )
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
    use super::super::test_scene::{run, scene};
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
}
