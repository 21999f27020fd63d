//! The consistency check's hand-off: the scale meters the noise of the empty pan itself
//! and hands it to the estimator, which checks every later run against it
//! (`crate::estimators::consistency`): a fit that leaves more unexplained than that noise
//! can is flagged `Invalid(ModelMismatch)`. On with
//! [`ScaleConfig::consistency_check`](super::ScaleConfig::consistency_check).
//!
//! - **Metering.** A [`crate::NoiseMeter`] at the estimator's `D` is fed the centred raw
//!   counts of every sample on which the pan is empty and at rest (`decide::EmptyPan`:
//!   vouched for and held in its band, the residuals showing no motion; not asked to be
//!   shown stable) *and* the run has been settled for `raw_arm_samples` (the raw test's
//!   arming: the pan still rings before, and a window metered on a ringing empty pan reads
//!   far above the noise). It meters windows of `noise_window_samples` (the window on which
//!   the check's allowance was measured, `crate::estimators::consistency`). A complete
//!   window becomes the reference once the pan stayed empty and at rest for
//!   `noise_guard_samples` more (a load landing in the window's last samples is detected by
//!   then; one landing earlier already moves the reading out of its band or alarms, and so
//!   ends the window); anything else (a load change, a flag, a sample lost, leaving the
//!   empty band) drops the window in progress and one waiting out its guard.
//! - **When it is live.** The estimator takes the latest accepted metering at each restart
//!   (a load change, the run after a fault, a recalibration: the reference is in counts,
//!   which a new gain does not change): every run that starts after the first settled empty
//!   period is checked; before one, none is (as with the check off). The run in which the
//!   metering happens is not re-checked; a later metering replaces the reference for the
//!   runs after it.
//! - **Tare** plays no part: metering needs the gross reading empty, not a tare command, and
//!   a container tared on the pan is not empty, so it is not metered (its loaded resonance
//!   is not the empty pan's); the reference stays the last empty pan's.
//! - **What a flag does.** `ModelMismatch` is not latched; like any non-latched flag after a
//!   valid reading it hides the mass and, persisting `flag_restart_samples`, restarts the
//!   run as a load change. A flagged reading runs neither change test, so a check that sees
//!   a new load before the residual test delays the change to its first flag plus that
//!   hold (`tests::e2e` `consistency_study` measures how often, per method).
//!
//! - **The noise's colour.** The same windows meter the block means' autocovariance
//!   ([`crate::AutocovarianceMeter`]); every window that passes the guard adds its sums to
//!   those of the windows before (a narrow-band noise's lags need thousands of block
//!   means: [`crate::MIN_METERED_BLOCKS`]), windows that follow each other as one record
//!   (the pairs that span two of them count: [`crate::AutocovarianceMeter::take_window`]
//!   says what windows apart did to the `u` under floor vibration), and past
//!   [`COLOUR_BLOCKS`] the older windows are halved in weight, so the colour follows a pan
//!   whose vibration changes over minutes. It is handed to the estimator at each restart like the reference
//!   (`crate::estimators::metered_noise`: the step method's `u` rests on it once there are
//!   enough block means). A recalibration keeps it (in counts); `forget_noise_reference`
//!   and a new configuration drop it.
//!
//! What must never happen: a load in a metered window. It could only inflate the reference
//! (fewer flags, never more); the settling and the guard keep it out.

use super::{Scale, ScaleEstimator};
use crate::estimators::consistency::NoiseReference;
use crate::estimators::noise_meter::{
    Autocovariance, AutocovarianceMeter, AutocovarianceSums, NoiseMeter,
};

/// Block means of the empty pan's colour beyond which the older windows are halved in
/// weight (98 s of empty pan at D = 24).
pub(super) const COLOUR_BLOCKS: u32 = 16_384;

/// The noise of the empty, stable pan, metered window by window (see the module docs).
#[derive(Clone, Debug)]
pub(super) struct NoiseMetering {
    /// At the estimator's `D`; `None` if that `D` is out of the meter's range.
    pub(super) meter: Option<NoiseMeter<f32>>,
    /// Differences of block means that complete one window.
    pub(super) window_differences: u32,
    /// A complete window waiting out the guard, and the samples waited so far.
    pub(super) pending: Option<NoiseReference<f32>>,
    pub(super) pending_samples: u32,
    /// The latest window that passed the guard: what the next run is checked against.
    pub(super) reference: Option<NoiseReference<f32>>,
    /// Samples went into the meter since the last interruption.
    pub(super) active: bool,
    /// The window's block-mean autocovariance, beside `meter`.
    colour: Option<AutocovarianceMeter<f32>>,
    /// A complete window's, waiting out the guard with `pending`.
    pending_colour: Option<AutocovarianceSums<f32>>,
    /// Every accepted window's, added up (see the module docs).
    colour_sums: AutocovarianceSums<f32>,
}

impl NoiseMetering {
    pub(super) fn new(decimation: u32, window_samples: u32) -> Self {
        let meter = u16::try_from(decimation)
            .ok()
            .and_then(|d| NoiseMeter::new(d).ok());
        let colour = u16::try_from(decimation)
            .ok()
            .and_then(|d| AutocovarianceMeter::new(d).ok());
        Self {
            meter,
            colour,
            pending_colour: None,
            colour_sums: AutocovarianceSums::new(),
            // `window/D` block means give one difference fewer; at least two for a variance.
            window_differences: (window_samples / decimation.max(1))
                .saturating_sub(1)
                .max(2),
            pending: None,
            pending_samples: 0,
            reference: None,
            active: false,
        }
    }

    /// The pan was not empty and at rest on this sample (or the run restarted): the window
    /// in progress and one waiting out the guard are dropped; the reference is kept.
    pub(super) fn interrupt(&mut self) {
        if self.active {
            self.drop_windows();
        }
    }

    /// Drop the window in progress and one waiting out its guard (`interrupt`).
    #[inline(never)]
    fn drop_windows(&mut self) {
        if let Some(meter) = self.meter.as_mut() {
            meter.reset();
        }
        if let Some(colour) = self.colour.as_mut() {
            colour.reset();
        }
        self.active = false;
        self.pending = None;
        self.pending_colour = None;
        self.pending_samples = 0;
    }

    /// The empty pan's block-mean autocovariance over every accepted window, in counts²;
    /// `None` before one.
    #[inline(never)]
    pub(super) fn autocovariance(&self) -> Option<Autocovariance<f32>> {
        self.colour_sums.autocovariance()
    }

    /// Forget the colour metered so far.
    pub(super) fn forget_colour(&mut self) {
        self.colour_sums = AutocovarianceSums::new();
    }

    /// A window passed its guard: its reference and colour are the latest.
    #[inline(never)]
    fn accept(&mut self, reference: NoiseReference<f32>, colour: Option<AutocovarianceSums<f32>>) {
        self.reference = Some(reference);
        if let Some(colour) = colour {
            self.colour_sums.merge(&colour);
            if self.colour_sums.blocks() > COLOUR_BLOCKS {
                self.colour_sums.halve();
            }
        }
    }

    /// One centred sample of the empty pan at rest.
    #[inline(never)]
    pub(super) fn push(&mut self, centred_counts: f32, guard_samples: u32) {
        if self.meter.is_none() {
            return;
        }
        self.active = true;
        if let Some(pending) = self.pending {
            self.pending_samples = self.pending_samples.saturating_add(1);
            if self.pending_samples >= guard_samples {
                self.pending = None;
                let colour = self.pending_colour.take();
                self.accept(pending, colour);
            }
        }
        let Some(meter) = self.meter.as_mut() else {
            return;
        };
        let colour_refused = self
            .colour
            .as_mut()
            .is_some_and(|colour| colour.push(centred_counts).is_err());
        if meter.push(centred_counts).is_err() || colour_refused {
            meter.reset();
            if let Some(colour) = self.colour.as_mut() {
                colour.reset();
            }
            return;
        }
        if meter.differences() >= self.window_differences {
            let metered = meter
                .noise_variance()
                .map(|variance| NoiseReference::new(variance, meter.differences()))
                .filter(|reference| reference.validate().is_ok());
            meter.reset();
            // The next window goes on with the same record (its pairs with this one's last
            // block means count), unless a drop resets it.
            let colour = self.colour.as_mut().map(AutocovarianceMeter::take_window);
            if let Some(metered) = metered {
                if guard_samples == 0 {
                    self.accept(metered, colour);
                } else {
                    self.pending = Some(metered);
                    self.pending_colour = colour;
                    self.pending_samples = 0;
                }
            }
        }
    }
}

impl<E: ScaleEstimator> Scale<E> {
    /// The noise reference the runs are checked against from the next load change on:
    /// the latest complete metering of the empty pan; `None` before one, or with the check
    /// off.
    pub fn noise_reference(&self) -> Option<NoiseReference<f32>> {
        if self.config.consistency_check {
            self.noise.reference
        } else {
            None
        }
    }

    /// Forget the metered noise and any metering in progress, as at boot: no run is checked
    /// from the next restart on until the empty pan is metered again.
    pub fn forget_noise_reference(&mut self) {
        self.noise.interrupt();
        self.noise.reference = None;
        self.noise.forget_colour();
    }

    /// The empty pan's metered block-mean autocovariance (counts², at the estimator's `D`)
    /// the runs' `u` rests on from the next load change on (see the module docs); `None`
    /// before a metering, or with the check off.
    pub fn noise_autocovariance(&self) -> Option<Autocovariance<f32>> {
        if self.config.consistency_check {
            self.noise.autocovariance()
        } else {
            None
        }
    }

    /// Meter the empty pan's centred sample, at rest (`decide::EmptyPan`) and settled, in a
    /// run of its own: a load change restarts the run and drops the window in progress
    /// (`restart`).
    pub(super) fn meter_empty_pan(&mut self, centred_counts: i32) {
        if self.settled_samples >= self.config.raw_arm_samples && self.config.consistency_check {
            self.noise
                .push(centred_counts as f32, self.config.noise_guard_samples);
            self.noise_metered = true;
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::super::test_scene::{calibration, new_scale, run, Cell, CPG, FS, ZERO};
    use super::super::{CountsScale, ScaleConfig, ScaleFault, ScaleReading, ScaleState, StepScale};
    use super::*;
    use crate::reading::InvalidReason;

    /// Samples of the empty pan after which a metering has passed its guard: the settling
    /// (`raw_arm_samples`, counted from the first stable empty reading, well within the
    /// first 0.2 s), one window and the guard, plus a window's worth of margin.
    fn metered_after(config: &ScaleConfig) -> usize {
        (0.2 * FS) as usize
            + (config.raw_arm_samples
                + 2 * config.noise_window_samples
                + config.noise_guard_samples) as usize
    }

    fn is_mismatch(reading: &ScaleReading) -> bool {
        reading.state == ScaleState::Invalid(ScaleFault::Estimator(InvalidReason::ModelMismatch))
    }

    #[test]
    fn the_settled_empty_pan_is_metered_and_a_modelled_drop_passes_the_check() {
        let mut scale = new_scale();
        let config = *scale.config();
        assert!(config.consistency_check);
        let mut cell = Cell::new(0.4);
        // Before the pan settled (1.5 s): no reference yet.
        run(&mut scale, &mut cell, config.raw_arm_samples as usize);
        assert_eq!(scale.noise_reference(), None);
        run(
            &mut scale,
            &mut cell,
            metered_after(&config) - config.raw_arm_samples as usize,
        );
        let reference = scale.noise_reference().expect("metered");
        // The cell's white noise, 0.4 g at 50 counts/g, plus the rounding's 1/12 count²: the
        // meter's relative standard error is √(3/M); 4 of them is a 1-in-15,000 miss.
        let truth = (0.4f32 * CPG).powi(2) + 1.0 / 12.0;
        let window = config.noise_window_samples / 16 - 1;
        assert_eq!(reference.differences, window);
        let allowed = 4.0 * (3.0 / window as f32).sqrt();
        assert!(
            (reference.variance / truth - 1.0).abs() < allowed,
            "{reference:?} against {truth}"
        );
        // The run the drop starts is checked and passes: no flag, the ratio near 1.
        assert_eq!(
            scale.estimator().residual_ratio(),
            None,
            "not before a restart"
        );
        cell.load_g = 138.32;
        let readings = run(&mut scale, &mut cell, 6000);
        assert!(!readings.iter().any(is_mismatch));
        let ratio = scale.estimator().residual_ratio().expect("checked");
        assert!(ratio < 2.0, "residual ratio {ratio}");
        let last = readings.last().unwrap();
        assert_eq!((last.state, last.load_changes), (ScaleState::Stable, 1));
        assert!((last.mass_g.unwrap() - 138.32).abs() < 0.14, "{last:?}");
        // The reference is in counts: a new gain keeps it; forgetting it is as at boot.
        scale.recalibrate(CountsScale {
            counts_per_gram: 2.0 * CPG,
            zero_counts: ZERO,
        });
        assert_eq!(scale.noise_reference(), Some(reference));
        scale.forget_noise_reference();
        assert_eq!(scale.noise_reference(), None);
    }

    /// The colour adds up over every window that passes its guard, reaches the estimator
    /// at the next restart once it rests on enough block means, follows a recalibration
    /// (it is in counts) and is forgotten with the reference.
    #[test]
    fn the_empty_pans_colour_adds_up_over_its_windows_and_reaches_the_estimator() {
        use crate::MIN_METERED_BLOCKS;
        let mut scale = new_scale();
        let config = *scale.config();
        let mut cell = Cell::new(0.4);
        run(&mut scale, &mut cell, metered_after(&config));
        let first = scale.noise_autocovariance().expect("one window");
        let window_blocks = config.noise_window_samples / 16;
        assert!(first.blocks >= window_blocks && first.blocks < MIN_METERED_BLOCKS);
        // One window is not enough for the estimator: a load's run does not rest on it.
        cell.load_g = 100.0;
        run(&mut scale, &mut cell, 4000);
        assert!(!scale.estimator().rests_on_metered_colour());
        cell.load_g = 0.0;
        // 3,000 block means of 16 samples are 12 s of metered empty pan (and its settling).
        run(&mut scale, &mut cell, 64_000);
        let colour = scale.noise_autocovariance().expect("metered");
        assert!(colour.blocks >= MIN_METERED_BLOCKS, "{}", colour.blocks);
        // The cell's white noise (0.4 g at 50 counts/g and the rounding) over 16 samples:
        // lag 0 within 4 standard errors (√(2/M)), the lags after it near 0.
        let truth = ((0.4f32 * CPG).powi(2) + 1.0 / 12.0) / 16.0;
        let relative = 4.0 * (2.0 / colour.blocks as f32).sqrt();
        assert!(
            (colour.lags[0] / truth - 1.0).abs() < relative,
            "{colour:?}"
        );
        assert!(colour.lags[1..]
            .iter()
            .all(|lag| lag.abs() < relative * truth));
        cell.load_g = 100.0;
        run(&mut scale, &mut cell, 4000);
        assert!(scale.estimator().rests_on_metered_colour());
        scale.recalibrate(CountsScale {
            counts_per_gram: 2.0 * CPG,
            zero_counts: ZERO,
        });
        assert_eq!(scale.noise_autocovariance(), Some(colour));
        scale.forget_noise_reference();
        assert_eq!(scale.noise_autocovariance(), None);
    }

    #[test]
    fn the_ringing_after_a_removal_is_not_metered() {
        let mut scale = new_scale();
        let config = *scale.config();
        let mut cell = Cell::new(0.4);
        cell.load_g = 250.0;
        run(&mut scale, &mut cell, 8000);
        cell.load_g = 0.0;
        // The empty pan rings at 25 Hz, ζ = 0.03 (a 1/e time of 0.21 s) and reads empty and
        // stable long before it is still: nothing is metered until it has been so for the
        // raw test's arming time.
        let readings = run(&mut scale, &mut cell, config.raw_arm_samples as usize);
        assert!(readings.iter().any(|r| r.state == ScaleState::Empty));
        assert_eq!(scale.noise_reference(), None);
        run(&mut scale, &mut cell, metered_after(&config));
        let reference = scale.noise_reference().expect("metered once settled");
        // What is left of the ringing after 1.5 s (e^-7 of 250 g) adds less than the
        // meter's own error (see the first test).
        let truth = (0.4f32 * CPG).powi(2) + 1.0 / 12.0;
        let allowed = 4.0 * (3.0 / reference.differences as f32).sqrt();
        assert!(
            (reference.variance / truth - 1.0).abs() < allowed,
            "{reference:?} against {truth}"
        );
    }

    #[test]
    fn a_load_landing_at_the_end_of_a_window_is_kept_out_by_the_guard() {
        // Where the first window completes, and what it meters, on a twin of the scene.
        let (completes, clean) = {
            let mut scale = new_scale();
            let mut cell = Cell::new(0.4);
            let completes = (0..20_000)
                .position(|_| {
                    scale.push(cell.sample());
                    scale.noise.pending.is_some()
                })
                .expect("a window completes");
            (completes, scale.noise.pending.unwrap())
        };
        // 138.32 g lands 1 ms (4 samples) before that: the estimate leaves the stability band
        // only at its next update (a drop 2 ms or more before the end drops the window
        // then), so the window completes with the onset in its last block.
        let scene = |config: ScaleConfig| {
            let estimator = StepScale::<8>::step_estimator(7, 16, 1.0).unwrap();
            let mut scale = Scale::new(config, estimator, calibration()).unwrap();
            let mut cell = Cell::new(0.4);
            run(&mut scale, &mut cell, completes - 4);
            cell.load_g = 138.32;
            let readings = run(&mut scale, &mut cell, 4000);
            assert_eq!(readings.last().unwrap().load_changes, 1);
            scale.noise_reference()
        };
        let config = ScaleConfig::weighing_default(FS);
        assert_eq!(scene(config), None, "the guard dropped the window");
        // Without the guard the window is taken, the onset in it, above the clean one.
        let unguarded = scene(ScaleConfig {
            noise_guard_samples: 0,
            ..config
        })
        .expect("taken without a guard");
        assert_eq!(unguarded.differences, clean.differences);
        assert!(
            unguarded.variance > clean.variance,
            "{unguarded:?} vs {clean:?}"
        );
    }

    /// The scene of the mismatch tests: the empty pan for `empty` samples, 138.32 g dropped,
    /// and 0.5 s later (still ringing: the raw test is not armed) 20 g more, which the
    /// residual test is prevented from catching (its threshold out of reach). Returns the
    /// reference the drop's run started with and the readings from the second step on.
    fn second_step_in_a_run(
        config: ScaleConfig,
        empty: usize,
    ) -> (Option<NoiseReference<f32>>, Vec<ScaleReading>) {
        let config = ScaleConfig {
            residual_threshold_g: f32::MAX,
            ..config
        };
        let estimator = StepScale::<8>::step_estimator(7, 16, 1.0).unwrap();
        let mut scale = Scale::new(config, estimator, calibration()).unwrap();
        let mut cell = Cell::new(0.4);
        run(&mut scale, &mut cell, empty);
        cell.load_g = 138.32;
        let first = run(&mut scale, &mut cell, 2000);
        // The raw test caught the drop (the residual test cannot), and the run is valid.
        assert_eq!(first.last().unwrap().load_changes, 1, "{:?}", first.last());
        assert!(first.last().unwrap().mass_g.is_some(), "{:?}", first.last());
        let reference = scale.noise_reference();
        cell.load_g += 20.0;
        (reference, run(&mut scale, &mut cell, 4000))
    }

    #[test]
    fn a_second_load_inside_a_run_is_flagged_and_restarts_it() {
        let config = ScaleConfig::weighing_default(FS);
        let (reference, readings) = second_step_in_a_run(config, metered_after(&config));
        assert!(reference.is_some());
        let first_flag = readings
            .iter()
            .position(is_mismatch)
            .expect("the second load is flagged");
        // The check needs a few rows of the new load: within 50 ms.
        assert!(first_flag < 200, "flagged {first_flag} samples after it");
        // The flag persists and the flag rule restarts the run after its hold.
        let hold = config.flag_restart_samples as usize;
        let restart = readings
            .iter()
            .position(|r| r.load_changes == 2)
            .expect("restarted");
        assert!(readings[first_flag..restart].iter().all(is_mismatch));
        // The `hold`-th flagged sample is the one that restarts.
        assert_eq!(restart - first_flag, hold - 1);
        // The new run holds one load: it fits, and reads it.
        let last = readings.last().unwrap();
        assert_eq!((last.state, last.load_changes), (ScaleState::Stable, 2));
        assert!((last.mass_g.unwrap() - 158.32).abs() < 0.14, "{last:?}");
    }

    #[test]
    fn no_metering_no_check() {
        // The drop lands after the pan settled (the raw test catches it) but before a window
        // was metered: the run is not checked, so no flag. The second load is a change all
        // the same: the raw test runs (its drift widened by the ringing) from the first
        // reading that held its band, long before the ringing is over.
        let config = ScaleConfig::weighing_default(FS);
        let settled = (0.25 * FS) as usize + config.raw_arm_samples as usize;
        let (reference, early) = second_step_in_a_run(config, settled);
        assert_eq!(reference, None);
        assert!(!early.iter().any(is_mismatch));
        assert_eq!(early.last().unwrap().load_changes, 2);
        // The check off: metered or not, never a flag.
        let off = ScaleConfig {
            consistency_check: false,
            ..config
        };
        let (reference, unchecked) = second_step_in_a_run(off, metered_after(&config));
        assert_eq!(reference, None);
        assert!(!unchecked.iter().any(is_mismatch));
        assert_eq!(unchecked.last().unwrap().load_changes, 2);
    }
}
