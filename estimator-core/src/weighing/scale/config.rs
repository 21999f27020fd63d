//! The thresholds and times of the weighing decisions ([`ScaleConfig`]), and the defaults
//! per method.
//!
//! The defaults are set from measurements on host-sim's reference demo (`tests::e2e`
//! `residual_study` and `consistency_study`; the figures and the commands that re-run them
//! are in `firmware/README.md`), not derived from the raw noise alone: the residual test
//! sees the noise of block means through the fitted coefficients. A threshold must never be
//! lowered below what a settled run without a change reaches, or the scale announces load
//! changes that did not happen.

use crate::reading::ConfigError;
use crate::weighing::method::WeighingMethod;

/// Tuning of the weighing decisions. All masses in grams, all durations in raw samples.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScaleConfig {
    /// Raw sample rate of the ADC.
    pub sample_rate_hz: f32,
    /// A gross mass within ±this reads as an empty pan.
    pub empty_band_g: f32,
    /// The estimate is stable when it stays within ±(this + `stable_band_relative`·|mass|).
    pub stable_band_g: f32,
    /// Relative part of the stability band.
    pub stable_band_relative: f32,
    /// Samples the estimate must stay in the band to be called stable.
    pub stable_hold_samples: u32,
    /// CUSUM drift ν on the estimator residuals: residuals below it never accumulate.
    pub residual_drift_g: f32,
    /// CUSUM alarm threshold h on the residuals (gram·updates).
    pub residual_threshold_g: f32,
    /// Raw samples after a reset before the residual test is armed.
    pub residual_arm_samples: u32,
    /// CUSUM drift ν on the raw samples.
    pub raw_drift_g: f32,
    /// CUSUM alarm threshold h on the raw samples (gram·samples).
    pub raw_threshold_g: f32,
    /// Raw samples per block of the block-mean test: the mean of `B` samples has the raw
    /// noise over √B, so a change of one scale interval stands out of it.
    pub block_samples: u32,
    /// CUSUM drift ν on the block means against the displayed gross mass.
    pub block_drift_g: f32,
    /// CUSUM alarm threshold h on the block means (gram·blocks).
    pub block_threshold_g: f32,
    /// The lowest frequency the cell rings at with any load up to Max, Hz (0: not known).
    /// A ringing of amplitude A and frequency f adds at most A/(π f) seconds' worth of A to
    /// the sum of any stretch of samples (half a period's area), so the block test allows
    /// a fraction 1/(π f T) of the ringing on a block of T seconds, not all of it
    /// ([`Self::ringing_min_hz_for`]).
    pub ringing_min_hz: f32,
    /// Samples the reading must be stable or empty before the raw test is armed (the
    /// cell's settling time: the raw signal rings until then).
    pub raw_arm_samples: u32,
    /// On a restless pan — `RESTLESS_SHORT_RUNS` runs in a row ended by a load
    /// change before `raw_arm_samples` — a run's fit vouches for its reading (stable,
    /// empty, final) only once it is this many samples old.
    pub restless_fit_samples: u32,
    /// Consecutive samples the estimator may flag its readings (without latching) after a
    /// valid one in the same run before the scale takes it as a load change and restarts
    /// it.
    pub flag_restart_samples: u32,
    /// Capacity Max of the scale (OIML R 76).
    pub capacity_g: f32,
    /// Scale interval e (verification scale interval, OIML R 76): the displayed resolution
    /// and the unit of the maximum permissible errors.
    pub scale_interval_g: f32,
    /// A reading is final once twice its standard uncertainty (a 95 % interval), with the
    /// noise level at its upper 95 % confidence bound (`Reading::uncertainty_bound`), is at
    /// or below this, and the scale could show it stable by its `u` (four of them within
    /// the permissible error): the instrument vouches for it
    /// ([`super::ScaleReading::is_final`]).
    /// `+∞`: every reading with a `u` is final; the default is 0.5 e, OIML R 76's maximum
    /// permissible error on the smallest loads at verification (class III, up to 500 e).
    pub final_target_g: f32,
    /// The accuracy the instrument is configured for, relative to the load (`[target]
    /// target_relative` of the weighing configuration; `+∞`: none): where it is tighter
    /// than the MPE it is the permissible error ([`Self::permissible_error_g`]).
    pub accuracy_target_relative: f32,
    /// The load below which the relative target is taken at this mass (the calibration
    /// mass it was set at), g.
    pub accuracy_target_mass_g: f32,
    /// Zero tracking runs only while empty, stable, and within ±this of zero.
    pub zero_tracking_band_g: f32,
    /// The largest rate the zero may move at while tracking (OIML R 76: at most 0.5 e per
    /// second).
    pub zero_tracking_rate_g_per_s: f32,
    /// Zero tracking never moves the zero further than ±this from the power-up zero (the
    /// calibrated zero the scale started or was recalibrated with). OIML R 76 allows up to
    /// 4 % of Max for zero setting and tracking together; see
    /// [`Self::weighing_default`] for why the default is far tighter.
    pub zero_tracking_range_g: f32,
    /// The fastest the zero may drift while nothing tracks it (a load on the pan), g/s:
    /// every reading's `u` carries that drift since the zero was last seen (tracked on
    /// the empty pan, set, or taken over by a tare), as a rectangular distribution of
    /// half-width this rate times that time. 0: the cell's zero does not drift.
    pub zero_drift_g_per_s: f32,
    /// Check every run after the first metered empty period against the noise metered on
    /// the empty pan (`crate::estimators::consistency`; see the `Scale` module docs, "The consistency check").
    pub consistency_check: bool,
    /// Raw samples of one noise metering: the empty pan's noise, at rest, is metered over
    /// this many samples at a time (block means of the estimator's `D`).
    pub noise_window_samples: u32,
    /// Raw samples the pan must stay empty and at rest after a metering before it is taken
    /// as the reference: a load arriving in its last samples is detected by then.
    pub noise_guard_samples: u32,
}

impl ScaleConfig {
    /// Capacity Max of the reference cell.
    pub const CAPACITY_G: f32 = 600.0;

    /// Scale interval e of the reference cell: 0.1 g, so n = Max/e = 6000 ≤ 10 000, an OIML
    /// R 76 class III instrument with MPE 0.5 e = 0.05 g up to 500 e (50 g), 1 e up to
    /// 2000 e (200 g), 1.5 e above. Finer is not honest: the step estimator's target
    /// standard deviation on this cell is 0.069 g (`firmware/weighing.toml`), and a reading
    /// must be good to a fraction of e; 0.1 g is the 1-2-5 interval just above it.
    pub const SCALE_INTERVAL_G: f32 = 0.1;
    /// The fastest zero drift an approved instrument may have, in scale intervals per
    /// second: OIML R 76-1 lets the no-load indication of a class III instrument move 1 e
    /// per 5 °C (3.9.2.3), and a room swinging 10 °C in 10 minutes moves it 2 e in 600 s.
    /// What zero tracking must follow, what every reading's `u` allows for since the zero
    /// was last seen, and what `host-sim torture` drifts by at most.
    pub const FASTEST_ZERO_DRIFT_E_PER_S: f32 = 2.0 / 600.0;
    /// The reference cell's resonance with [`Self::REFERENCE_RING_LOAD_G`] on, Hz
    /// (host-sim's reference cell; `firmware/weighing.toml` identifies 25.0 Hz).
    pub const REFERENCE_RING_HZ: f32 = 25.0;
    /// The load the reference cell rings at [`Self::REFERENCE_RING_HZ`] with: its
    /// calibration mass, g.
    pub const REFERENCE_RING_LOAD_G: f32 = 138.32;

    /// The lowest frequency a cell ringing at `ring_hz` with `load_g` on can ring at with
    /// any load up to `capacity_g`: by the physical law (stiffness fixed, frequency ∝
    /// 1/√(moving mass)) the heaviest load rings slowest, and with the platform's own
    /// moving mass unknown the bound takes it as none, √(`load_g`/`capacity_g`) times
    /// `ring_hz` (12.0 Hz for the reference cell: 25 Hz at 138.32 g, Max 600 g). 0 (not
    /// known) when an argument is not finite and positive.
    pub fn ringing_min_hz_for(ring_hz: f32, load_g: f32, capacity_g: f32) -> f32 {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !(positive(ring_hz) && positive(load_g) && positive(capacity_g)) {
            return 0.0;
        }
        if load_g >= capacity_g {
            ring_hz
        } else {
            ring_hz * crate::numerics::real::Real::sqrt(load_g / capacity_g)
        }
    }

    /// The method the defaults' residual thresholds were measured with, and the firmware's
    /// choice before calibration wrote one: the step estimator, n = 7, D = 16, λ = 1
    /// (`tests::e2e` study, see `firmware/README.md`): block-averaging cuts the
    /// errors-in-variables bias of the full-rate form.
    pub const DEFAULT_METHOD: WeighingMethod = WeighingMethod::Step {
        order: 7,
        decimation: 16,
        forgetting: 1.0,
    };

    /// Defaults for a 4 kHz, 600 g class scale with about 0.5 g RMS raw noise, running the
    /// step estimator ([`Self::DEFAULT_METHOD`]).
    ///
    /// Why these numbers:
    /// - empty band 0.25 g: well above the error of a settled empty reading, well below any
    ///   item the scale is for;
    /// - stability: ±(0.02 g + 0.02 %) for 50 ms;
    /// - raw CUSUM: ν = 0.5 g (about one raw σ), h = 25 g·samples: an unchanged settled
    ///   signal essentially never alarms, a change of a few grams alarms within a few ms;
    /// - a flag persisting 25 ms after a valid reading is a load change: the residual
    ///   test's own arming time, and within the 50 ms the demo allows for detecting a drop
    ///   (instrumental variables can go ill-conditioned on a fresh drop before its
    ///   residuals alarm); their ill-conditioned flicker on a steady load is shorter;
    /// - the consistency check on, metering 0.3 s windows of the settled empty pan, each
    ///   accepted 50 ms later (the `Scale` module docs, "The consistency check");
    /// - residual CUSUM: ν = 1 g, h = 10 g·updates, from the residuals measured on
    ///   host-sim's reference demo at n = 7, D = 16: neither a settled empty fit nor a
    ///   fresh loaded fit accumulates, and a drop alarms within a few updates. Smaller ν
    ///   and h alarm sooner but falsely on some noise seeds;
    /// - block-mean CUSUM (armed with the raw test): 0.1 s blocks, ν = 0.2 e, h = 1.5 e
    ///   (gram·blocks). The raw tests cannot see an item of one scale interval e (their ν
    ///   is a raw σ); the mean of 400 samples of 0.43 g noise has σ = 0.022 g, so ν is
    ///   about 1σ and h 7σ of a block mean: an unchanged settled load essentially never
    ///   alarms (zero false changes over long settled runs at several seeds, tested), a
    ///   1 e item within a few blocks. ν at 0.5 e, the smallest MPE, let a trickle run the
    ///   display 0.1-0.3 g behind the load before it alarmed (`host-sim torture`); while
    ///   the sums are past a quarter of h the load is in motion, shown neither stable nor
    ///   final. At a raw noise much above 0.5 g, raise both;
    /// - zero tracking (OIML R 76 4.5.7 sets the outer limits: only at zero and stable, at
    ///   most 0.5 e/s, zero setting and tracking together within 4 % of Max): within
    ///   ±0.5 e of zero, at twice [`Self::FASTEST_ZERO_DRIFT_E_PER_S`] (0.0067 e/s), and at
    ///   most ±2 e from the power-up zero in total (the drift of that 10 °C swing). A
    ///   tracker cannot tell a drifting zero from a load trickling on slower than it tracks
    ///   (sand, a leaking cup), so its rate is what the drift needs and no more: a trickle
    ///   faster than that leaves the ±0.5 e band having lost at most what the tracker moved
    ///   meanwhile (0.008 g for 0.005 g/s), and only a trickle slower than a drift an
    ///   approved instrument may have is tracked away, up to the range. At 0.1 e/s (the
    ///   rate before) trickles of 0.005-0.05 g/s were tracked away by up to 0.5 e and
    ///   `host-sim torture --runs 300` counted 2,785 silent wrong readings with drifting
    ///   zeros, 472 at 0.02 e/s. Nothing is tracked until the pan has been settled for
    ///   `raw_arm_samples` after a start (the first readings of a noisy pan moved the zero
    ///   for the whole run);
    /// - a restless pan's fit vouches from 1 s of age: ten periods of the slowest floor
    ///   vibration `host-sim torture` shakes the pan with (10 Hz), long enough for a fit to
    ///   have seen the vibration go on where a transient would have died down. A fit of a
    ///   few tenths of a second takes a vibration for the cell's own transient and states
    ///   a `u` of hundredths of a gram on a pan that scatters by tenths, and on a vibrating
    ///   floor the change tests alarm every few tenths of a second, so every fit is that
    ///   young: run 7156 of `host-sim torture --runs 10000 --seed 1` showed 467.49 g final
    ///   and stable with u = 0.013 g, 0.28 g below the load, from a fit 0.1 s old, the 85th
    ///   run in 12 s. Three ages measured on those 10,000 runs (silent wrong readings, lines
    ///   shown settled): none 35 / 2,638,594; 0.5 s 25 / 2,594,840; 0.75 s 23 / 2,554,830;
    ///   1 s 20 / 2,507,650, none left on a load steady for 2 s or more (9, 2, 1 and 0),
    ///   at 5 % fewer lines shown settled than without the rule (run 3581: a fit 0.5 s old
    ///   on a vibrating floor, shown 0.054 g off with u = 0.010 g);
    /// - the zero's drift in every reading's `u`: at [`Self::FASTEST_ZERO_DRIFT_E_PER_S`]
    ///   since the zero was last seen (tracked, set, or taken into a tare), rectangular.
    ///   A load on the pan hides the zero, and nothing tracks it: after a minute at 0.5 e
    ///   permissible (loads up to 500 e) a reading is no longer certain enough to show
    ///   stable, after three at 1.5 e. Without it `host-sim torture --runs 10000` counted
    ///   73 silent wrong readings, 37 with it. A cell whose
    ///   zero is known to hold better sets a smaller rate (0 for none).
    pub fn weighing_default(sample_rate_hz: f32) -> Self {
        Self {
            sample_rate_hz,
            empty_band_g: 0.25,
            stable_band_g: 0.02,
            stable_band_relative: 2e-4,
            stable_hold_samples: (0.05 * sample_rate_hz) as u32,
            residual_drift_g: 1.0,
            residual_threshold_g: 10.0,
            residual_arm_samples: (0.025 * sample_rate_hz) as u32,
            raw_drift_g: 0.5,
            raw_threshold_g: 25.0,
            raw_arm_samples: (1.5 * sample_rate_hz) as u32,
            restless_fit_samples: (1.0 * sample_rate_hz) as u32,
            block_samples: (0.1 * sample_rate_hz) as u32,
            block_drift_g: 0.2 * Self::SCALE_INTERVAL_G,
            block_threshold_g: 1.5 * Self::SCALE_INTERVAL_G,
            ringing_min_hz: Self::ringing_min_hz_for(
                Self::REFERENCE_RING_HZ,
                Self::REFERENCE_RING_LOAD_G,
                Self::CAPACITY_G,
            ),
            flag_restart_samples: (0.025 * sample_rate_hz) as u32,
            capacity_g: Self::CAPACITY_G,
            scale_interval_g: Self::SCALE_INTERVAL_G,
            final_target_g: 0.5 * Self::SCALE_INTERVAL_G,
            accuracy_target_relative: f32::INFINITY,
            accuracy_target_mass_g: 0.0,
            zero_tracking_band_g: 0.5 * Self::SCALE_INTERVAL_G,
            zero_tracking_rate_g_per_s: 2.0
                * Self::FASTEST_ZERO_DRIFT_E_PER_S
                * Self::SCALE_INTERVAL_G,
            zero_tracking_range_g: 2.0 * Self::SCALE_INTERVAL_G,
            zero_drift_g_per_s: Self::FASTEST_ZERO_DRIFT_E_PER_S * Self::SCALE_INTERVAL_G,
            consistency_check: true,
            noise_window_samples: (0.3 * sample_rate_hz) as u32,
            noise_guard_samples: (0.05 * sample_rate_hz) as u32,
        }
    }

    /// The error a reading of the net load `load_g` may have: the maximum permissible error
    /// (OIML R 76-1, class III, at initial verification, in the scale interval e: 0.5 e up
    /// to 500 e, 1 e up to 2,000 e, 1.5 e above), or the configured accuracy target where
    /// that is tighter (`accuracy_target_relative` of the load, or of
    /// `accuracy_target_mass_g` below it). A reading is shown stable, empty or final only
    /// while [`super::VOUCHING_COVERAGE_FACTOR`] times its standard uncertainty is within it.
    pub fn permissible_error_g(&self, load_g: f32) -> f32 {
        let e = self.scale_interval_g;
        let intervals = load_g.abs() / e;
        let mpe = if intervals <= 500.0 {
            0.5 * e
        } else if intervals <= 2000.0 {
            e
        } else {
            1.5 * e
        };
        let at = if load_g.abs() > self.accuracy_target_mass_g {
            load_g.abs()
        } else {
            self.accuracy_target_mass_g
        };
        let target = self.accuracy_target_relative * at;
        if target < mpe {
            target
        } else {
            mpe
        }
    }

    /// Check every field: `Err(ConfigError::ScaleField(name))` names the first one out of
    /// its domain. Rates, bands, drifts and zero tracking must be finite and not negative
    /// (the sample rate positive); the CUSUM thresholds positive and not NaN (`+∞` switches
    /// a test off); the noise window at least one sample. [`super::Scale::new`] refuses an
    /// invalid configuration with this error instead of panicking on it later.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let finite_non_negative = |value: f32| value.is_finite() && value >= 0.0;
        let threshold = |value: f32| value > 0.0; // false for NaN; +∞ allowed
        let checks = [
            (
                "sample_rate_hz",
                self.sample_rate_hz.is_finite() && self.sample_rate_hz > 0.0,
            ),
            (
                "capacity_g",
                self.capacity_g.is_finite() && self.capacity_g > 0.0,
            ),
            (
                "scale_interval_g",
                self.scale_interval_g.is_finite() && self.scale_interval_g > 0.0,
            ),
            ("final_target_g", threshold(self.final_target_g)),
            (
                "accuracy_target_relative",
                threshold(self.accuracy_target_relative),
            ),
            (
                "accuracy_target_mass_g",
                finite_non_negative(self.accuracy_target_mass_g),
            ),
            ("empty_band_g", finite_non_negative(self.empty_band_g)),
            ("stable_band_g", finite_non_negative(self.stable_band_g)),
            (
                "stable_band_relative",
                finite_non_negative(self.stable_band_relative),
            ),
            (
                "residual_drift_g",
                finite_non_negative(self.residual_drift_g),
            ),
            ("residual_threshold_g", threshold(self.residual_threshold_g)),
            ("raw_drift_g", finite_non_negative(self.raw_drift_g)),
            ("raw_threshold_g", threshold(self.raw_threshold_g)),
            ("block_samples", self.block_samples > 0),
            ("block_drift_g", finite_non_negative(self.block_drift_g)),
            ("block_threshold_g", threshold(self.block_threshold_g)),
            ("ringing_min_hz", finite_non_negative(self.ringing_min_hz)),
            (
                "zero_tracking_band_g",
                finite_non_negative(self.zero_tracking_band_g),
            ),
            (
                "zero_tracking_rate_g_per_s",
                finite_non_negative(self.zero_tracking_rate_g_per_s),
            ),
            (
                "zero_tracking_range_g",
                finite_non_negative(self.zero_tracking_range_g),
            ),
            (
                "zero_drift_g_per_s",
                finite_non_negative(self.zero_drift_g_per_s),
            ),
            ("noise_window_samples", self.noise_window_samples > 0),
        ];
        match checks.iter().find(|(_, ok)| !ok) {
            Some((field, _)) => Err(ConfigError::ScaleField(field)),
            None => Ok(()),
        }
    }

    /// These decisions for a scale of capacity `capacity_g` and scale interval
    /// `scale_interval_g`: the fields set in scale intervals follow e (zero tracking band,
    /// rate and range; the block test's ν and h), in the proportions of
    /// [`Self::weighing_default`].
    pub fn with_scale(self, capacity_g: f32, scale_interval_g: f32) -> Self {
        let per_e = scale_interval_g / Self::SCALE_INTERVAL_G;
        Self {
            capacity_g,
            scale_interval_g,
            final_target_g: self.final_target_g * per_e,
            zero_tracking_band_g: self.zero_tracking_band_g * per_e,
            zero_tracking_rate_g_per_s: self.zero_tracking_rate_g_per_s * per_e,
            zero_tracking_range_g: self.zero_tracking_range_g * per_e,
            zero_drift_g_per_s: self.zero_drift_g_per_s * per_e,
            block_drift_g: self.block_drift_g * per_e,
            block_threshold_g: self.block_threshold_g * per_e,
            ..self
        }
    }

    /// These decisions with the permissible error no wider than `relative` of the load (of
    /// `at_mass_g` below it): the weighing configuration's accuracy target.
    pub fn with_accuracy_target(self, relative: f32, at_mass_g: f32) -> Self {
        Self {
            accuracy_target_relative: relative,
            accuracy_target_mass_g: at_mass_g,
            ..self
        }
    }

    /// These decisions for a cell that rings at `ring_hz` with `load_g` on (the weighing
    /// configuration's identified model at its calibration mass), up to the capacity set
    /// ([`Self::ringing_min_hz_for`]).
    pub fn with_ringing(self, ring_hz: f32, load_g: f32) -> Self {
        Self {
            ringing_min_hz: Self::ringing_min_hz_for(ring_hz, load_g, self.capacity_g),
            ..self
        }
    }

    /// These decisions with readings final once `2u ≤ final_target_g`.
    pub fn with_final_target(self, final_target_g: f32) -> Self {
        Self {
            final_target_g,
            ..self
        }
    }

    /// [`Self::weighing_default`] with the residual test's thresholds for `method`, set from
    /// the residuals measured on host-sim's reference demo, each method run alone from a
    /// restart at each change and 100 samples after it (where the scale restarts), and
    /// across each change from a settled run (`tests::e2e` `residual_study`, figures in
    /// `firmware/README.md`). The threshold `h` must stay above the largest CUSUM sum a run
    /// without a change reaches from the arming time on, with a margin.
    ///
    /// - The data-driven methods (step at any n, D; bias-compensated; instrumental
    ///   variables) keep the step estimator's ν = 1 g, h = 10 g.
    /// - The model bank: ν = 2 g, h = 10 g. Its residual (the interpolated model's, see
    ///   [`crate::ModelBank`]) carries a model error that a data-driven fit absorbs, for
    ///   hundreds of milliseconds on a heavy load: at ν = 1 g it raised false load changes.
    pub fn for_method(method: &WeighingMethod, sample_rate_hz: f32) -> Self {
        let defaults = Self::weighing_default(sample_rate_hz);
        match method {
            WeighingMethod::Step { .. }
            | WeighingMethod::BiasCompensated { .. }
            | WeighingMethod::InstrumentalVariable { .. } => defaults,
            WeighingMethod::ModelBank { .. } => Self {
                residual_drift_g: 2.0,
                ..defaults
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_scene::{calibration, FS};
    use super::super::StepScale;
    use super::*;

    /// Every bad value of every checked field is refused by `Scale::new` as a typed error
    /// naming the field, never a panic (a NaN or negative zero-tracking rate panicked in
    /// `f32::clamp` on the first empty reading).
    #[test]
    fn a_bad_field_is_refused_by_name_not_a_panic() {
        let good = ScaleConfig::weighing_default(FS);
        assert_eq!(good.validate(), Ok(()));
        type Set = fn(&mut ScaleConfig, f32);
        let fields: [(&str, Set); 19] = [
            ("accuracy_target_relative", |c, v| {
                c.accuracy_target_relative = v
            }),
            ("accuracy_target_mass_g", |c, v| {
                c.accuracy_target_mass_g = v
            }),
            ("block_drift_g", |c, v| c.block_drift_g = v),
            ("block_threshold_g", |c, v| c.block_threshold_g = v),
            ("ringing_min_hz", |c, v| c.ringing_min_hz = v),
            ("sample_rate_hz", |c, v| c.sample_rate_hz = v),
            ("capacity_g", |c, v| c.capacity_g = v),
            ("scale_interval_g", |c, v| c.scale_interval_g = v),
            ("zero_tracking_range_g", |c, v| c.zero_tracking_range_g = v),
            ("empty_band_g", |c, v| c.empty_band_g = v),
            ("stable_band_g", |c, v| c.stable_band_g = v),
            ("stable_band_relative", |c, v| c.stable_band_relative = v),
            ("residual_drift_g", |c, v| c.residual_drift_g = v),
            ("residual_threshold_g", |c, v| c.residual_threshold_g = v),
            ("raw_drift_g", |c, v| c.raw_drift_g = v),
            ("raw_threshold_g", |c, v| c.raw_threshold_g = v),
            ("zero_tracking_band_g", |c, v| c.zero_tracking_band_g = v),
            ("zero_tracking_rate_g_per_s", |c, v| {
                c.zero_tracking_rate_g_per_s = v
            }),
            ("zero_drift_g_per_s", |c, v| c.zero_drift_g_per_s = v),
        ];
        for (name, set) in fields {
            for bad in [f32::NAN, -1.0, f32::NEG_INFINITY] {
                let mut config = good;
                set(&mut config, bad);
                let estimator = StepScale::<8>::step_estimator(7, 16, 1.0).unwrap();
                let built = super::super::Scale::new(config, estimator, calibration());
                assert_eq!(
                    built.err(),
                    Some(ConfigError::ScaleField(name)),
                    "{name} = {bad}"
                );
            }
        }
        let config = ScaleConfig {
            noise_window_samples: 0,
            ..good
        };
        assert_eq!(
            config.validate(),
            Err(ConfigError::ScaleField("noise_window_samples"))
        );
    }

    /// The slowest ringing up to Max: the reference cell's 12.0 Hz; the cell's own
    /// frequency when it was identified at or above Max; not known (0, no attenuation)
    /// from a bad argument.
    #[test]
    fn the_slowest_ringing_follows_the_heaviest_load() {
        let reference = ScaleConfig::weighing_default(FS).ringing_min_hz;
        assert!((reference - 12.0).abs() < 0.01, "{reference}");
        assert_eq!(ScaleConfig::ringing_min_hz_for(25.0, 600.0, 600.0), 25.0);
        let quarter = ScaleConfig::ringing_min_hz_for(20.0, 150.0, 600.0);
        assert!((quarter - 10.0).abs() < 1e-5, "{quarter}");
        for bad in [f32::NAN, 0.0, -1.0, f32::INFINITY] {
            assert_eq!(ScaleConfig::ringing_min_hz_for(bad, 150.0, 600.0), 0.0);
            assert_eq!(ScaleConfig::ringing_min_hz_for(25.0, bad, 600.0), 0.0);
            assert_eq!(ScaleConfig::ringing_min_hz_for(25.0, 150.0, bad), 0.0);
        }
        let heavier = ScaleConfig::weighing_default(FS)
            .with_scale(3000.0, 0.5)
            .with_ringing(25.0, 138.32);
        assert!((heavier.ringing_min_hz - 25.0 * (138.32f32 / 3000.0).sqrt()).abs() < 1e-4);
    }
}
