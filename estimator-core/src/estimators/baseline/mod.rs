//! The baselines a scale maker uses today, behind the same reading interface, so every
//! comparison of speed against accuracy has them as the reference.
//!
//! Both cut the raw stream into blocks of `block` samples and keep the last `K` block means.
//! The reading is stable when the spread (max − min) of those `K` means is within
//! `stable_band` (in the estimate's unit). Then:
//! - [`BaselineMode::SettledAverage`]: wait until stable, then average every sample from
//!   that moment on (the classic "wait, then average" scale);
//! - [`BaselineMode::MovingAverage`]: report the mean of the last `K` blocks (a boxcar
//!   low-pass of length `K·block`) while it is stable.
//!
//! ## The band and the noise (found by the stability map)
//! A fixed band is loose when the noise is low: it is then many block-mean standard
//! deviations wide, so the pan is called stable while it still rings, and the settled
//! average keeps that ringing. Given the
//! noise metered at tare ([`BaselineConfig::noise_reference`], at `D = block`), the `K` block
//! means must also be consistent with a constant load: their sample variance over the block
//! means' noise variance must stay below the threshold of `crate::estimators::consistency` (the F
//! quantile at `K − 1` and the reference's degrees of freedom, times its allowance).
//! Within the band but beyond the noise, the reading is `Invalid(ModelMismatch)` (not
//! latched) instead of a number.
//!
//! ## Pre-filters tuned to the cell
//! What a weighing terminal or a multihead weigher ships instead of waiting for the ring to
//! decay: a filter tuned to the cell's oscillatory mode ahead of the same averaging and
//! stability test ([`Baseline::with_prefilter`]): [`Compensator`] (pole-zero compensation,
//! with the notch as its special case) and [`Shaper`] (the input-shaper FIR of Richiedei and
//! Trevisani). Both are designed once, in `f64`, from the [`CellMode`] calibration identified;
//! both take the pan as at rest at the first sample after a reset (true at a landing, and on
//! a settled load).

mod compensation;
mod mode;
mod shaper;

pub use compensation::{Compensator, CompensatorConfig};
pub use mode::CellMode;
pub use shaper::{Shaper, ShaperConfig, ShaperKind};

use crate::estimators::consistency::{mismatch_threshold, NoiseReference};
use crate::estimators::input::Decimator;
use crate::estimators::intake::{estimator_via_intake, Intake};
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// Which baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BaselineMode {
    /// Wait until stable, then average everything from then on.
    SettledAverage,
    /// Boxcar mean of the last `K` blocks, reported while stable.
    MovingAverage,
}

/// Configuration of a [`Baseline`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BaselineConfig<T> {
    /// Which baseline.
    pub mode: BaselineMode,
    /// Static gain: raw units per unit of the estimate.
    pub gain: T,
    /// Raw samples per block.
    pub block: u16,
    /// Largest spread of the last `K` block means (estimate's unit) that counts as stable.
    pub stable_band: T,
    /// The noise measured at tare at `D = block` (`None`: the band alone decides): the block
    /// means must also be consistent with it to count as stable (see the module docs).
    pub noise_reference: Option<NoiseReference<T>>,
}

/// A filter ahead of a baseline's averaging, on samples in the estimate's unit.
pub trait Prefilter<T>: Clone {
    /// The filtered value of the next sample.
    fn filter(&mut self, x: T) -> T;
    /// Forget the history: the next sample is taken as the level the pan rested at before.
    fn restart(&mut self);
}

/// No pre-filter: the classic baselines.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unfiltered;

impl<T> Prefilter<T> for Unfiltered {
    #[inline]
    fn filter(&mut self, x: T) -> T {
        x
    }

    fn restart(&mut self) {}
}

/// A stability-detecting baseline estimator keeping `K` block means of the samples, or of
/// their pre-filtered values (`F`, see the module docs).
#[derive(Clone, Debug)]
pub struct Baseline<T: Real, const K: usize, F = Unfiltered> {
    config: BaselineConfig<T>,
    prefilter: F,
    /// No range limit: only samples that are not finite are refused.
    intake: Intake<T>,
    /// The block means as `sum / block`.
    block_mean: Decimator<T>,
    blocks: [T; K],
    blocks_filled: usize,
    next_block: usize,
    /// Σ (x − `settled_origin`) since the reading became stable: deviations, not the load,
    /// so that a long `f32` sum keeps the precision of the deviations (summing loads, the
    /// stability map found the `f32` settled average measurably worse than `f64`).
    settled_sum: T,
    settled_origin: T,
    /// Samples in the settled average since it became stable: `u64`, so it never wraps
    /// (a `u32` wrapped after 12.4 days at 4 kHz and divided by zero); past
    /// [`SETTLED_WINDOW`] the average forgets with that window instead of growing.
    settled_count: u64,
    /// The noise variance of one block mean (estimate's unit²) and the largest ratio of the
    /// block means' sample variance to it that is consistent with a constant load.
    noise: Option<(T, T)>,
}

impl<T: Real, const K: usize> Baseline<T, K> {
    /// A new baseline without a pre-filter, or why the configuration is impossible.
    pub fn new(config: BaselineConfig<T>) -> Result<Self, ConfigError> {
        Self::with_prefilter(config, Unfiltered)
    }
}

impl<T: Real, const K: usize, F: Prefilter<T>> Baseline<T, K, F> {
    /// A new baseline averaging what `prefilter` makes of the samples (restarted here), or
    /// why the configuration is impossible.
    pub fn with_prefilter(
        config: BaselineConfig<T>,
        mut prefilter: F,
    ) -> Result<Self, ConfigError> {
        prefilter.restart();
        if !config.gain.is_finite() || config.gain == T::ZERO {
            return Err(ConfigError::Gain);
        }
        if config.block == 0 || K < 2 {
            return Err(ConfigError::Decimation);
        }
        if !(config.stable_band > T::ZERO) || !config.stable_band.is_finite() {
            return Err(ConfigError::Model);
        }
        let noise = match &config.noise_reference {
            Some(reference) => {
                reference.validate()?;
                let inv_gain = T::ONE / config.gain;
                let block_variance =
                    reference.variance * inv_gain * inv_gain / T::from_u32(u32::from(config.block));
                let degrees = T::from_u32(K as u32 - 1);
                let reference_degrees = T::from_f64(2.0 / 3.0) * T::from_u32(reference.differences);
                Some((
                    block_variance,
                    mismatch_threshold(degrees, reference_degrees),
                ))
            }
            None => None,
        };
        Ok(Self {
            config,
            prefilter,
            intake: Intake::new(
                T::ONE / config.gain,
                T::from_f64(f64::NEG_INFINITY),
                T::from_f64(f64::INFINITY),
                Decimator::new(1),
            ),
            block_mean: Decimator::dividing(config.block),
            blocks: [T::ZERO; K],
            blocks_filled: 0,
            next_block: 0,
            settled_sum: T::ZERO,
            settled_origin: T::ZERO,
            settled_count: 0,
            noise,
        })
    }

    /// The sample variance of the stored block means over their noise variance from the
    /// reference (≈ 1 for a constant load); `None` without a reference or before `K` blocks.
    pub fn spread_ratio(&self) -> Option<T> {
        let (block_variance, _) = self.noise?;
        if self.blocks_filled < K {
            return None;
        }
        let (_, mean) = self.spread_and_mean();
        Some(self.sample_variance(mean) / block_variance)
    }

    /// `Σ (b − mean)² / (K − 1)` over the stored block means.
    fn sample_variance(&self, mean: T) -> T {
        let mut sum = T::ZERO;
        for &b in &self.blocks {
            let d = b - mean;
            sum += d * d;
        }
        sum / T::from_u32(K as u32 - 1)
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        Self::with_prefilter(self.config, self.prefilter.clone())
    }

    /// Spread and mean of the stored block means.
    fn spread_and_mean(&self) -> (T, T) {
        let mut min = self.blocks[0];
        let mut max = self.blocks[0];
        let mut sum = T::ZERO;
        for &b in &self.blocks {
            if b < min {
                min = b;
            }
            if b > max {
                max = b;
            }
            sum += b;
        }
        (max - min, sum / T::from_u32(K as u32))
    }

    /// The number of samples the settled sum stands for: the count, up to the window.
    fn settled_weight(&self) -> T {
        let weight = u32::try_from(self.settled_count.min(u64::from(SETTLED_WINDOW)));
        T::from_u32(weight.unwrap_or(SETTLED_WINDOW))
    }

    /// Count `samples` more settled samples equal to the current average without pushing
    /// them (tests of runs longer than a test can feed).
    #[cfg(test)]
    pub(crate) fn skip_settled_samples_for_test(&mut self, samples: u64) {
        let mean = self.settled_sum / self.settled_weight();
        self.settled_count = self.settled_count.saturating_add(samples);
        self.settled_sum = mean * self.settled_weight();
    }

    /// One sample in the estimate's unit.
    fn update(&mut self, sample: T) {
        let x = self.prefilter.filter(sample);
        if !x.is_finite() {
            // Only an overflow inside the filter gets here (the intake refused NaN input).
            self.intake.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if self.settled_count > 0 && self.config.mode == BaselineMode::SettledAverage {
            let deviation = x - self.settled_origin;
            self.settled_count = self.settled_count.saturating_add(1);
            if self.settled_count <= u64::from(SETTLED_WINDOW) {
                self.settled_sum += deviation;
            } else {
                // Exponential forgetting over the window: the sum stays `window · mean`.
                self.settled_sum += deviation - self.settled_sum / T::from_u32(SETTLED_WINDOW);
            }
            let average = self.settled_origin + self.settled_sum / self.settled_weight();
            self.intake.estimating(average, None);
            return;
        }
        let Some(block_mean) = self.block_mean.push(x) else {
            return;
        };
        self.blocks[self.next_block] = block_mean;
        self.next_block = (self.next_block + 1) % K;
        self.blocks_filled = (self.blocks_filled + 1).min(K);
        if self.blocks_filled < K {
            return;
        }
        let (spread, mean) = self.spread_and_mean();
        let consistent = match self.noise {
            Some((block_variance, threshold)) => {
                !(self.sample_variance(mean) > threshold * block_variance)
            }
            None => true,
        };
        if spread <= self.config.stable_band && !consistent {
            // Within the band, but the means still move beyond the noise: not a number yet.
            self.intake.invalidate(InvalidReason::ModelMismatch);
        } else if spread <= self.config.stable_band {
            self.intake.estimating(mean, None);
            if self.config.mode == BaselineMode::SettledAverage {
                // Everything in the stable window counts towards the average.
                let count = K as u64 * u64::from(self.config.block);
                self.settled_origin = mean;
                self.settled_sum = T::ZERO;
                self.settled_count = count;
            }
        } else {
            self.intake.warm_up();
        }
    }
}

/// The settled average's window: 2²² raw samples (17.5 minutes at 4 kHz), far longer than
/// any weighing, short enough that an `f32` sum of deviations keeps its precision.
const SETTLED_WINDOW: u32 = 1 << 22;

estimator_via_intake!(Baseline<T, const K, type F: Prefilter<T>>);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reading::{Estimator, State};

    fn ringing(k: usize) -> f64 {
        // 25 Hz at 4 kHz, decaying with a 0.2 s time constant, around 100 units (gain 2).
        let t = k as f64 / 4000.0;
        2.0 * (100.0 + 10.0 * (-t / 0.2).exp() * (2.0 * core::f64::consts::PI * 25.0 * t).cos())
    }

    fn ringing_config(mode: BaselineMode) -> BaselineConfig<f64> {
        BaselineConfig {
            mode,
            gain: 2.0,
            block: 40,
            stable_band: 0.1,
            noise_reference: None,
        }
    }

    fn first_stable(mode: BaselineMode) -> (usize, f64) {
        first_stable_of(&mut Baseline::<f64, 10>::new(ringing_config(mode)).unwrap())
    }

    fn first_stable_of(baseline: &mut impl Estimator<f64>) -> (usize, f64) {
        for k in 0..20_000 {
            if let Some(e) = baseline.push(ringing(k)).estimate {
                return (k, e);
            }
        }
        panic!("never stable");
    }

    #[test]
    fn waits_until_the_ringing_is_inside_the_band() {
        for mode in [BaselineMode::SettledAverage, BaselineMode::MovingAverage] {
            let (k, estimate) = first_stable(mode);
            // Envelope 10·e^(−t/0.2) ≤ 0.05 (half the band) needs t ≥ 0.2·ln(200) ≈ 1.06 s;
            // the 100 ms boxcar averages the ringing down sooner, but not before 0.5 s.
            assert!((2000..4400).contains(&k), "{mode:?}: first stable at {k}");
            assert!((estimate - 100.0).abs() < 0.1, "{mode:?}: {estimate}");
        }
    }

    /// `ringing`'s mode: 25 Hz, ζ = 1/(0.2 s · ω).
    fn ringing_mode() -> CellMode {
        CellMode {
            natural_frequency_hz: 25.0,
            damping_ratio: 1.0 / (0.2 * 2.0 * core::f64::consts::PI * 25.0),
            sample_rate_hz: 4000.0,
        }
    }

    fn compensator<T: Real>() -> Compensator<T> {
        Compensator::new(CompensatorConfig {
            cell: ringing_mode(),
            placed_frequency_hz: 50.0,
            placed_damping_ratio: 1.0,
        })
        .unwrap()
    }

    fn shaper<T: Real>() -> Shaper<T, 256> {
        Shaper::new(ShaperConfig {
            cell: ringing_mode(),
            kind: ShaperKind::Zvd,
        })
        .unwrap()
    }

    /// Tuned to the ring, either pre-filter takes it out, so the same band holds once the
    /// window of 400 samples has filled, not after the second the ring takes to decay.
    #[test]
    fn a_prefilter_tuned_to_the_ring_is_stable_sooner() {
        for mode in [BaselineMode::SettledAverage, BaselineMode::MovingAverage] {
            let config = ringing_config(mode);
            let mut compensated = Baseline::<f64, 10, _>::with_prefilter(config, compensator());
            let mut shaped = Baseline::<f64, 10, _>::with_prefilter(config, shaper());
            for (k, estimate) in [
                first_stable_of(compensated.as_mut().unwrap()),
                first_stable_of(shaped.as_mut().unwrap()),
            ] {
                assert!((399..600).contains(&k), "{mode:?}: first stable at {k}");
                assert!((estimate - 100.0).abs() < 0.05, "{mode:?}: {estimate}");
            }
        }
    }

    /// The whole estimator in `f32` against `f64` behind each pre-filter: the same first
    /// stable sample, and readings within 1e-5 of the load.
    #[test]
    fn f32_follows_f64_behind_each_prefilter() {
        fn compare<P32: Prefilter<f32>, P64: Prefilter<f64>>(narrow: P32, wide: P64) {
            let config = ringing_config(BaselineMode::SettledAverage);
            let narrow_config = BaselineConfig {
                gain: 2.0f32,
                stable_band: 0.1f32,
                mode: config.mode,
                block: config.block,
                noise_reference: None,
            };
            let mut narrow = Baseline::<f32, 10, _>::with_prefilter(narrow_config, narrow).unwrap();
            let mut wide = Baseline::<f64, 10, _>::with_prefilter(config, wide).unwrap();
            for k in 0..8000 {
                let x = ringing(k);
                let (n, w) = (narrow.push(x as f32).estimate, wide.push(x).estimate);
                assert_eq!(n.is_some(), w.is_some(), "{k}");
                if let (Some(n), Some(w)) = (n, w) {
                    assert!((f64::from(n) - w).abs() < 1e-5 * 100.0, "{k}: {n} {w}");
                }
            }
        }
        compare(compensator::<f32>(), compensator::<f64>());
        compare(shaper::<f32>(), shaper::<f64>());
    }

    /// NaN input latches behind a pre-filter as without one, and a reset starts it afresh.
    #[test]
    fn nan_is_flagged_behind_a_prefilter() {
        let config = ringing_config(BaselineMode::MovingAverage);
        let mut baseline = Baseline::<f64, 10, _>::with_prefilter(config, compensator()).unwrap();
        for k in 0..100 {
            baseline.push(ringing(k));
        }
        assert_eq!(
            baseline.push(f64::NAN).state,
            State::Invalid(InvalidReason::NonFiniteInput)
        );
        assert!(baseline.push(200.0).is_invalid());
        baseline.reset();
        let (k, estimate) = first_stable_of(&mut baseline);
        assert!(
            k < 600 && (estimate - 100.0).abs() < 0.05,
            "{k}: {estimate}"
        );
    }

    /// A settled average past 2³² samples (12.4 days at 4 kHz) still reads the load: its
    /// count must not wrap (a `u32` count wrapped to zero and read `NaN`).
    #[test]
    fn the_settled_average_survives_two_to_the_32_samples() {
        let config = BaselineConfig {
            mode: BaselineMode::SettledAverage,
            gain: 1.0,
            block: 4,
            stable_band: 1.0,
            noise_reference: None,
        };
        let mut baseline = Baseline::<f32, 4>::new(config).unwrap();
        for k in 0..100 {
            baseline.push(50.0 + if k % 2 == 0 { 0.1 } else { -0.1 });
        }
        assert!(baseline.push(50.0).estimate.is_some());
        baseline.skip_settled_samples_for_test((1 << 32) - 10);
        for k in 0..100 {
            let reading = baseline.push(50.0);
            let estimate = reading.estimate.unwrap_or(f32::NAN);
            assert!((estimate - 50.0).abs() < 0.01, "{k}: {reading:?}");
        }
        // Past the window the average still follows the data (forgetting, not frozen): half a
        // window of a 1 unit step moves it by 1 − e^(−1/2) = 0.3935.
        for _ in 0..(SETTLED_WINDOW / 2) {
            baseline.push(51.0);
        }
        let estimate = baseline.push(51.0).estimate.unwrap();
        assert!((estimate - 50.3935).abs() < 0.01, "{estimate}");
    }

    #[test]
    fn bad_input_latches_and_impossible_config_is_refused() {
        let config = BaselineConfig {
            mode: BaselineMode::MovingAverage,
            gain: 1.0,
            block: 4,
            stable_band: 1.0,
            noise_reference: None,
        };
        let mut baseline = Baseline::<f32, 4>::new(config).unwrap();
        assert_eq!(
            baseline.push(f32::NAN).state,
            State::Invalid(InvalidReason::NonFiniteInput)
        );
        assert!(baseline.push(1.0).is_invalid());
        baseline.reset();
        assert!(!baseline.push(1.0).is_invalid());
        let bad = BaselineConfig { block: 0, ..config };
        assert_eq!(
            Baseline::<f32, 4>::new(bad).err(),
            Some(ConfigError::Decimation)
        );
        let bad = BaselineConfig {
            gain: 0.0,
            ..config
        };
        assert_eq!(Baseline::<f32, 4>::new(bad).err(), Some(ConfigError::Gain));
    }
}
