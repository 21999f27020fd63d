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
use crate::estimators::step_uncertainty::stated;
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
    /// The settled average's block means (Welford, as deviations from `settled_origin`):
    /// how many, their mean and their sum of squared deviations, from the `K` that made
    /// the reading stable on; the scatter its `u` rests on.
    settled_blocks: u32,
    settled_block_mean: T,
    settled_block_squares: T,
    /// The settled average's `u` and its degrees of freedom, as of the last whole block.
    settled_uncertainty: Option<(T, u32)>,
    /// The last raw sample (before the pre-filter), and Σ of squared sample-to-sample
    /// differences of the block in progress, of each of the `K` stored blocks, and of the
    /// settled average's samples with how many: the white noise, a floor for the block
    /// means' scatter that the stability decision does not select (see `mean_uncertainty`).
    previous: Option<T>,
    block_differences: T,
    differences: [T; K],
    settled_differences: T,
    settled_difference_count: u64,
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
                Some((
                    block_variance,
                    mismatch_threshold(degrees, reference.degrees_of_freedom()),
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
            settled_blocks: 0,
            settled_block_mean: T::ZERO,
            settled_block_squares: T::ZERO,
            settled_uncertainty: None,
            previous: None,
            block_differences: T::ZERO,
            differences: [T::ZERO; K],
            settled_differences: T::ZERO,
            settled_difference_count: 0,
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
        // The raw samples' differences, not the filtered ones: the pre-filter's DC gain is
        // one, so a long mean of its output has the raw white noise's variance over the
        // samples averaged, whatever the filter does to the differences (a shaper halves
        // their mean square, and its `u` covered 86 % at 400 ms on the reference drop at
        // 30 dB; a compensation filter multiplies it).
        let difference = self.previous.map_or(T::ZERO, |previous| sample - previous);
        self.previous = Some(sample);
        let difference_square = difference * difference;
        if self.settled_count > 0 && self.config.mode == BaselineMode::SettledAverage {
            self.settled_differences += difference_square;
            self.settled_difference_count = self.settled_difference_count.saturating_add(1);
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
            if let Some(block_mean) = self.block_mean.push(x) {
                self.push_settled_block(block_mean - self.settled_origin);
            }
            self.intake.state_uncertainty(self.settled_uncertainty);
            return;
        }
        self.block_differences += difference_square;
        let Some(block_mean) = self.block_mean.push(x) else {
            return;
        };
        self.differences[self.next_block] = self.block_differences;
        self.block_differences = T::ZERO;
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
            let squares = self.sample_variance(mean) * T::from_u32(K as u32 - 1);
            let mut window_differences = T::ZERO;
            for &sum in &self.differences {
                window_differences += sum;
            }
            let window_samples = K as u64 * u64::from(self.config.block);
            let uncertainty = self.mean_uncertainty(
                squares,
                K as u32,
                T::from_u32(K as u32),
                white_block_variance(window_differences, window_samples, self.config.block),
            );
            if self.config.mode == BaselineMode::SettledAverage {
                // Everything in the stable window counts towards the average.
                self.settled_differences = window_differences;
                self.settled_difference_count = window_samples;
                self.settled_origin = mean;
                self.settled_sum = T::ZERO;
                self.settled_count = window_samples;
                self.settled_blocks = K as u32;
                self.settled_block_mean = T::ZERO;
                self.settled_block_squares = squares;
                self.settled_uncertainty = uncertainty;
            }
            self.intake.state_uncertainty(uncertainty);
        } else {
            self.intake.warm_up();
        }
    }
}

impl<T: Real, const K: usize, F: Prefilter<T>> Baseline<T, K, F> {
    /// One whole block mean of the settled average (a deviation from its origin) into the
    /// scatter its `u` rests on (Welford's update), and that `u` for the samples averaged.
    fn push_settled_block(&mut self, deviation: T) {
        self.settled_blocks = self.settled_blocks.saturating_add(1);
        let delta = deviation - self.settled_block_mean;
        self.settled_block_mean += delta / T::from_u32(self.settled_blocks);
        self.settled_block_squares += delta * (deviation - self.settled_block_mean);
        let blocks_averaged = self.settled_weight() / T::from_u32(u32::from(self.config.block));
        let white = white_block_variance(
            self.settled_differences,
            self.settled_difference_count,
            self.config.block,
        );
        self.settled_uncertainty = self.mean_uncertainty(
            self.settled_block_squares,
            self.settled_blocks,
            blocks_averaged,
            white,
        );
    }

    /// The standard uncertainty of a mean of `averaged` block means whose scatter is
    /// `squares` (the sum of squared deviations of `blocks` of them): a Type A evaluation
    /// (GUM 4.2) with `blocks − 1` degrees of freedom, times `t_{0.975}(ν)/2` where that
    /// exceeds 1. The block means' variance is not taken below the white noise's share of
    /// one (`white`, from the samples' consecutive differences) nor below the metered noise
    /// where there is a reference: the reading is stable only once the block means' spread
    /// is within the band, and on a pan whose noise nearly fills the band that selects
    /// windows whose scatter is low by chance (at 0.63 band widths of block-mean noise, ±2u
    /// on the scatter alone covered 72 % of the first stable readings; test
    /// `the_baselines_u_covers_their_errors`). It takes the block means as independent,
    /// which noise correlated over more than a block (vibration below the block rate,
    /// drift) is not; residual ringing within the band counts as scatter, not as the bias
    /// it is.
    fn mean_uncertainty(&self, squares: T, blocks: u32, averaged: T, white: T) -> Option<(T, u32)> {
        let degrees = blocks.checked_sub(1)?;
        if degrees == 0 || !(averaged > T::ZERO) {
            return None;
        }
        let mut variance = squares / T::from_u32(degrees);
        // The degrees of freedom stay the block means' even where the white noise's
        // level, resting on thousands of differences, is the larger: on the rig's
        // coloured noise the first stable readings of the shaper and the compensation
        // filter were then covered 61-74 % of the time at 40-80 dB (t for the blocks'
        // few degrees keeps them at 94-99 %).
        if variance < white {
            variance = white;
        }
        if let Some((block_variance, _)) = self.noise {
            if variance < block_variance {
                variance = block_variance;
            }
        }
        stated(variance / averaged, degrees)
    }
}

/// The white noise's variance of one block mean of `block` samples, from `sum`, the sum of
/// `count` squared sample-to-sample differences (half their mean square per sample).
fn white_block_variance<T: Real>(sum: T, count: u64, block: u16) -> T {
    if count == 0 {
        return T::ZERO;
    }
    // Counts beyond u32 only make the mean more exact; cap them (f32 has 24 bits anyway).
    let count = T::from_u32(u32::try_from(count).unwrap_or(u32::MAX));
    sum / (T::from_f64(2.0) * count * T::from_u32(u32::from(block)))
}

/// The settled average's window: 2²² raw samples (17.5 minutes at 4 kHz), far longer than
/// any weighing, short enough that an `f32` sum of deviations keeps its precision.
const SETTLED_WINDOW: u32 = 1 << 22;

estimator_via_intake!(Baseline<T, const K, type F: Prefilter<T>>);

#[cfg(test)]
mod tests {
    extern crate std;
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

    /// The coverage of ±2u over `runs` noisy copies of the ringing scene (noise `sigma` raw
    /// units per sample), for readings `after` samples after the first stable one, in `T`;
    /// and the worst relative difference of each run's `u` from the f64 `u` on the same
    /// data.
    fn coverage<T: Real>(
        mode: BaselineMode,
        sigma: f64,
        after: usize,
        runs: u64,
    ) -> (f64, usize, f64) {
        let config = BaselineConfig {
            mode,
            gain: 2.0,
            block: 40,
            stable_band: 1.0,
            noise_reference: None,
        };
        let narrow = BaselineConfig {
            mode,
            gain: T::from_f64(2.0),
            block: 40,
            stable_band: T::ONE,
            noise_reference: None,
        };
        let mut covered = 0;
        let mut stated = 0;
        let mut worst = 0.0f64;
        for seed in 0..runs {
            let mut baseline = Baseline::<T, 10>::new(narrow).unwrap();
            let mut reference = Baseline::<f64, 10>::new(config).unwrap();
            let mut stable_at = None;
            for k in 0..40_000usize {
                let x = ringing(k) + sigma * crate::tuning::synthetic::gaussian(seed, k as u64);
                let reading = baseline.push(T::from_f64(x));
                let exact = reference.push(x);
                if reading.estimate.is_some() && stable_at.is_none() {
                    stable_at = Some(k);
                }
                if stable_at.is_some_and(|at| k == at + after) {
                    // The moving average may have lost its stability by then: no reading.
                    if let (Some(estimate), Some(u), Some(exact_u)) =
                        (reading.estimate, reading.uncertainty, exact.uncertainty)
                    {
                        let (estimate, u) = (estimate.to_f64(), u.to_f64());
                        stated += 1;
                        covered += usize::from((estimate - 100.0).abs() <= 2.0 * u);
                        worst = worst.max((u - exact_u).abs() / exact_u);
                    }
                    break;
                }
            }
        }
        (covered as f64 / stated.max(1) as f64, stated, worst)
    }

    /// Both baselines state a `u`, in f32 within 1 % of the f64 `u` on the same data,
    /// whose ±2u is never over-confident (at least 92 % of the errors, the low end of
    /// 95 ± 3 %: 400 runs observe a true 95 % within ±2.2 %) at the first stable reading
    /// and a second later, on a decaying ringing in white noise; where the noise fills
    /// half the stability band or more (block means scattering by 0.63 of it) it is
    /// calibrated (at most 98 %). On the block means' scatter alone, the first stable
    /// readings there were covered 72 % of the time: the stability decision selects
    /// windows whose scatter is low by chance. Where the noise is low the first stable
    /// window still holds some ringing, which its scatter counts: conservative (printed).
    #[test]
    fn the_baselines_u_covers_their_errors() {
        for mode in [BaselineMode::SettledAverage, BaselineMode::MovingAverage] {
            for (sigma, after) in [(2.0, 0), (2.0, 4000), (8.0, 0), (8.0, 4000)] {
                let (share, stated, worst) = coverage::<f32>(mode, sigma, after, 400);
                std::println!(
                    "{mode:?}, noise {sigma}, {after} samples after stable: {:.1} % of {stated} covered, f32 u within {:.2e} of f64",
                    100.0 * share,
                    worst
                );
                assert!(
                    worst < 0.01,
                    "{mode:?}, {sigma}, {after}: f32 u {worst:e} off"
                );
                // The moving average a second on is rarely still within the band at the
                // higher noise: too few readings to judge.
                if stated < 100 {
                    continue;
                }
                assert!(share >= 0.92, "{mode:?}, {sigma}, {after}: {share}");
                if sigma == 8.0 {
                    assert!(share <= 0.98, "{mode:?}, {sigma}, {after}: {share}");
                }
            }
        }
    }
}
