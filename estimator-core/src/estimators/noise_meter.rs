//! Measures the white-noise variance of the raw samples on an empty pan (at tare), for the
//! bias-compensated estimator ([`crate::BiasCompensatedStepEstimator`]).
//!
//! It works on first differences of block means, with their mean removed: a constant offset
//! cancels in the differences, and a slow linear drift only shifts their mean, so neither
//! inflates the variance. For block means `x̄(m)` of white noise with variance `v` the
//! differences `δ(m) = x̄(m+1) − x̄(m)` have variance `2v` and adjacent ones correlate by
//! `−v`; with `M` differences, `E[Σ(δ − δ̄)²] = 2v·M − 2v/M` (because `δ̄ = (x̄(M) − x̄(0))/M`),
//! so `v̂ = Σ(δ − δ̄)²·M / (2(M² − 1))` is unbiased. Its relative standard error is
//! `√(3/M)` (the differences are MA(1): `var Σδ² ≈ 2M(γ₀² + 2γ₁²) = 12M·v²`): 1,200 raw
//! samples (0.3 s at 4 kHz) at `D = 1` give 5%.
//!
//! The meter reports `D·v̂` in raw units², the raw-rate variance the estimator's
//! configuration takes (it divides by `D` again). Measuring at the estimator's own block
//! length `D` makes that value right for the block means even when the raw noise is not
//! white (e.g. amplifier noise coloured by the anti-alias filter), which is what the
//! compensation needs. It must never be fed samples with a load on the pan: a load step
//! is not a slow drift.
//!
//! ## The block means' autocovariance
//! The same block means also give their autocovariance at lags `0..=`[`AUTOCOVARIANCE_LAGS`]
//! ([`AutocovarianceSums`], [`Autocovariance`]): the colour of the noise (vibration near
//! the resonance, the amplifier's noise through the anti-alias filter), which the step
//! estimator's `u` needs where the noise is not white (`crate::estimators::step_uncertainty`).
//! Each lag is centred on its own pairs (`Σxy/p − (Σx/p)(Σy/p)`), so an offset cancels;
//! sums from several meterings of the same empty pan add ([`AutocovarianceSums::merge`]):
//! a narrow-band noise needs thousands of block means before its lags are known (a few
//! seconds are not enough: `host-sim study coverage`, see the README).

use crate::estimators::input::{check_sample, Decimator};
use crate::estimators::step::MAX_DECIMATION;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// The largest lag of the block means' autocovariance the meter keeps: the configured step
/// method's colour lags (`crate::weighing::COLOUR_LAGS`, 24) and its largest order's (8)
/// beyond them, which the equation error's autocovariance reaches.
pub const AUTOCOVARIANCE_LAGS: usize = 32;

/// The block means' autocovariance at lags `0..=`[`AUTOCOVARIANCE_LAGS`] (raw units², block
/// means of the meter's `D` raw samples), and the block means behind lag 0.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Autocovariance<T> {
    /// `γ(l)`, lag `l` at index `l`.
    pub lags: [T; AUTOCOVARIANCE_LAGS + 1],
    /// The block means lag 0 was measured over.
    pub blocks: u32,
}

impl<T: Real> Autocovariance<T> {
    /// `ConfigError::NoiseReference` unless every lag is finite, lag 0 is positive and no
    /// lag exceeds it in size (what an autocovariance cannot do).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let zero = self.lags[0];
        // Written so that NaN fails too.
        let ok = zero > T::ZERO
            && zero.is_finite()
            && self
                .lags
                .iter()
                .all(|&lag| lag.is_finite() && lag.abs() <= zero);
        if ok {
            Ok(())
        } else {
            Err(ConfigError::NoiseReference)
        }
    }

    /// The prediction-error filter of order `order` (Levinson–Durbin on lags `0..=order`):
    /// `φ` with `y_m − Σ_i φ_i·y_{m−i}` (`φ_i` at `i − 1`, zero beyond the order) white for
    /// an autoregressive noise of that order. `None` where a reflection coefficient is not
    /// within (−1, 1) (lags no stationary noise has, or an arithmetic that lost them) or the
    /// order exceeds the lags kept.
    pub fn prediction_filter(&self, order: usize) -> Option<[T; AUTOCOVARIANCE_LAGS]> {
        self.prediction(order).map(|(phi, _)| phi)
    }

    /// [`Self::prediction_filter`] and the one-step prediction's error variance at that
    /// order.
    pub(crate) fn prediction(&self, order: usize) -> Option<([T; AUTOCOVARIANCE_LAGS], T)> {
        if order > AUTOCOVARIANCE_LAGS {
            return None;
        }
        let mut phi = [T::ZERO; AUTOCOVARIANCE_LAGS];
        let mut error = self.lags[0];
        for k in 1..=order {
            if !levinson_step(&self.lags, &mut phi, &mut error, k) {
                return None;
            }
        }
        (error > T::ZERO).then_some((phi, error))
    }
}

/// One step of the Levinson–Durbin recursion: the prediction-error filter `φ` of order
/// `k − 1` (`φ_i` at `i − 1`) and its error variance become those of order `k`, from the
/// autocovariance `gamma` (lags `0..=k`). `false` (and both left as they were) where the
/// reflection coefficient is not within (−1, 1).
pub(crate) fn levinson_step<T: Real>(gamma: &[T], phi: &mut [T], error: &mut T, k: usize) -> bool {
    let mut acc = gamma[k];
    for i in 1..k {
        acc -= phi[i - 1] * gamma[k - i];
    }
    let reflection = acc / *error;
    if !(reflection.abs() < T::ONE) {
        return false;
    }
    for i in 1..=k / 2 {
        let (low, high) = (phi[i - 1], phi[k - i - 1]);
        phi[i - 1] = low - reflection * high;
        if k - i != i {
            phi[k - i - 1] = high - reflection * low;
        }
    }
    phi[k - 1] = reflection;
    *error *= T::ONE - reflection * reflection;
    true
}

/// The sums behind an [`Autocovariance`]: per lag, `Σ x_k·x_{k−l}`, `Σ x_k`, `Σ x_{k−l}` and
/// the pairs, over runs of consecutive block means (a lost sample ends a run), about an
/// origin (the first block mean) so that f32 keeps the noise, not the offset.
#[derive(Clone, Debug, PartialEq)]
pub struct AutocovarianceSums<T> {
    origin: Option<T>,
    products: [T; AUTOCOVARIANCE_LAGS + 1],
    later: [T; AUTOCOVARIANCE_LAGS + 1],
    earlier: [T; AUTOCOVARIANCE_LAGS + 1],
    pairs: [u32; AUTOCOVARIANCE_LAGS + 1],
    /// The run's last block means, the newest at `latest`, `held` of them.
    history: [T; AUTOCOVARIANCE_LAGS],
    latest: usize,
    held: usize,
}

impl<T: Real> Default for AutocovarianceSums<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> AutocovarianceSums<T> {
    /// Nothing summed.
    pub fn new() -> Self {
        Self {
            origin: None,
            products: [T::ZERO; AUTOCOVARIANCE_LAGS + 1],
            later: [T::ZERO; AUTOCOVARIANCE_LAGS + 1],
            earlier: [T::ZERO; AUTOCOVARIANCE_LAGS + 1],
            pairs: [0; AUTOCOVARIANCE_LAGS + 1],
            history: [T::ZERO; AUTOCOVARIANCE_LAGS],
            latest: 0,
            held: 0,
        }
    }

    /// One block mean, following the last one pushed (unless [`Self::end_run`] came between).
    pub fn push(&mut self, mean: T) {
        let origin = *self.origin.get_or_insert(mean);
        let x = mean - origin;
        self.fold(0, x, x);
        // The ring backwards from the newest, without a division per lag.
        let mut index = self.latest;
        for lag in 1..=self.held {
            let before = self.history[index];
            self.fold(lag, x, before);
            index = if index == 0 {
                AUTOCOVARIANCE_LAGS - 1
            } else {
                index - 1
            };
        }
        self.latest = if self.latest + 1 == AUTOCOVARIANCE_LAGS {
            0
        } else {
            self.latest + 1
        };
        self.history[self.latest] = x;
        if self.held < AUTOCOVARIANCE_LAGS {
            self.held += 1;
        }
    }

    #[inline]
    fn fold(&mut self, lag: usize, x: T, before: T) {
        self.products[lag] += x * before;
        self.later[lag] += x;
        self.earlier[lag] += before;
        self.pairs[lag] = self.pairs[lag].saturating_add(1);
    }

    /// The next block mean does not follow the last one (a sample was lost).
    pub fn end_run(&mut self) {
        self.held = 0;
    }

    /// Add another metering's sums (of the same noise): its runs stay apart from this one's.
    pub fn merge(&mut self, other: &Self) {
        let Some(theirs) = other.origin else {
            return;
        };
        let ours = *self.origin.get_or_insert(theirs);
        // Their block means about our origin: x + d.
        let d = theirs - ours;
        for lag in 0..=AUTOCOVARIANCE_LAGS {
            let pairs = T::from_u32(other.pairs[lag]);
            self.products[lag] +=
                other.products[lag] + d * (other.later[lag] + other.earlier[lag]) + pairs * d * d;
            self.later[lag] += other.later[lag] + pairs * d;
            self.earlier[lag] += other.earlier[lag] + pairs * d;
            self.pairs[lag] = self.pairs[lag].saturating_add(other.pairs[lag]);
        }
        self.held = 0;
    }

    /// Halve every sum and count: the older meterings weigh half as much from now on.
    pub fn halve(&mut self) {
        let half = T::from_f64(0.5);
        for lag in 0..=AUTOCOVARIANCE_LAGS {
            self.products[lag] *= half;
            self.later[lag] *= half;
            self.earlier[lag] *= half;
            self.pairs[lag] /= 2;
        }
    }

    /// The block means lag 0 is measured over.
    pub fn blocks(&self) -> u32 {
        self.pairs[0]
    }

    /// The autocovariance, once every lag has two pairs; `None` before, or when it is not
    /// one ([`Autocovariance::validate`]).
    pub fn autocovariance(&self) -> Option<Autocovariance<T>> {
        let mut lags = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        for (lag, value) in lags.iter_mut().enumerate() {
            if self.pairs[lag] < 2 {
                return None;
            }
            let pairs = T::from_u32(self.pairs[lag]);
            *value = self.products[lag] / pairs
                - (self.later[lag] / pairs) * (self.earlier[lag] / pairs);
        }
        let autocovariance = Autocovariance {
            lags,
            blocks: self.pairs[0],
        };
        autocovariance.validate().ok().map(|()| autocovariance)
    }
}

/// The block means' autocovariance of the empty pan, sample by sample: [`AutocovarianceSums`]
/// behind a decimator of `D` raw samples (the estimator's). Like [`NoiseMeter`], it must
/// only be fed the empty pan.
#[derive(Clone, Debug)]
pub struct AutocovarianceMeter<T> {
    decimation: u16,
    decimator: Decimator<T>,
    sums: AutocovarianceSums<T>,
}

impl<T: Real> AutocovarianceMeter<T> {
    /// A meter over block means of `decimation` raw samples.
    pub fn new(decimation: u16) -> Result<Self, ConfigError> {
        Ok(Self {
            decimation,
            decimator: block_decimator(decimation)?,
            sums: AutocovarianceSums::new(),
        })
    }

    /// One raw empty-pan sample; a NaN or infinite one is refused and breaks the run of
    /// block means, as a lost sample does.
    pub fn push(&mut self, sample: T) -> Result<(), InvalidReason> {
        let inf = T::from_f64(f64::INFINITY);
        match check_sample(sample, -inf, inf) {
            Ok(sample) => {
                if let Some(mean) = self.decimator.push(sample) {
                    self.sums.push(mean);
                }
                Ok(())
            }
            Err(reason) => {
                self.push_missing();
                Err(reason)
            }
        }
    }

    /// A sample was lost: its block is broken and the next block mean starts a new run.
    pub fn push_missing(&mut self) {
        self.decimator = Decimator::new(self.decimation);
        self.sums.end_run();
    }

    /// The sums so far.
    pub fn sums(&self) -> &AutocovarianceSums<T> {
        &self.sums
    }

    /// Hand over the sums so far (a window of the record) and go on metering the same
    /// record: the next block means' products with the last ones before them go into the
    /// next window's sums, so windows handed over one after another and merged
    /// ([`AutocovarianceSums::merge`]) are one metering of the whole record. A window that
    /// is [`Self::reset`] instead ends the record; the next starts a new one.
    ///
    /// Why: the scale meters the empty pan in windows of 0.3 s (50 block means at D = 24),
    /// and taken as separate records they lost every pair that spans two windows, most of
    /// the far lags' (lag 24: 26 pairs of 49 per window). Its step method filters the
    /// colour through the fit's moving average, and under a floor vibration the fit
    /// cancels: the equation error's power is the small difference of large lags, and from
    /// the windows apart it came out at or below zero in about a third of the runs at 70 dB
    /// and half at 80 dB, 100 ms after the landing (their `u` then fell back on the
    /// residuals: ±2u covered 99.3–99.8 % at 70 dB, `host-sim study coverage --runs 1000
    /// --seed 1`, the scale's vibration table); from the windows as one record, in none.
    pub fn take_window(&mut self) -> AutocovarianceSums<T> {
        let fresh = AutocovarianceSums {
            origin: self.sums.origin,
            history: self.sums.history,
            latest: self.sums.latest,
            held: self.sums.held,
            ..AutocovarianceSums::new()
        };
        core::mem::replace(&mut self.sums, fresh)
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        self.decimator = Decimator::new(self.decimation);
        self.sums = AutocovarianceSums::new();
    }
}

/// The decimator of a meter over block means of `decimation` raw samples (1 to
/// [`MAX_DECIMATION`], the estimators' range).
fn block_decimator<T: Real>(decimation: u16) -> Result<Decimator<T>, ConfigError> {
    if decimation == 0 || decimation > MAX_DECIMATION {
        return Err(ConfigError::Decimation);
    }
    Ok(Decimator::new(decimation))
}

/// A running, allocation-free noise-variance meter. See the module docs.
#[derive(Clone, Debug)]
pub struct NoiseMeter<T> {
    decimation: u16,
    decimator: Decimator<T>,
    previous: Option<T>,
    differences: u32,
    /// Running mean and sum of squared deviations of the differences (Welford).
    mean: T,
    sum_squares: T,
    fault: Option<InvalidReason>,
}

impl<T: Real> NoiseMeter<T> {
    /// A meter over block means of `decimation` raw samples (use the estimator's `D`).
    pub fn new(decimation: u16) -> Result<Self, ConfigError> {
        Ok(Self {
            decimation,
            decimator: block_decimator(decimation)?,
            previous: None,
            differences: 0,
            mean: T::ZERO,
            sum_squares: T::ZERO,
            fault: None,
        })
    }

    /// Feed one raw empty-pan sample (offset removed or not). A NaN or infinite sample is
    /// refused, and latched: the meter reports no variance until `reset()`.
    pub fn push(&mut self, sample: T) -> Result<(), InvalidReason> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        let inf = T::from_f64(f64::INFINITY);
        let sample = match check_sample(sample, -inf, inf) {
            Ok(sample) => sample,
            Err(reason) => {
                self.fault = Some(reason);
                return Err(reason);
            }
        };
        let Some(mean) = self.decimator.push(sample) else {
            return Ok(());
        };
        if let Some(previous) = self.previous {
            let difference = mean - previous;
            self.differences = self.differences.saturating_add(1);
            let delta = difference - self.mean;
            self.mean += delta / T::from_u32(self.differences);
            self.sum_squares += delta * (difference - self.mean);
            if !(self.sum_squares.is_finite() && self.mean.is_finite()) {
                self.fault = Some(InvalidReason::NonFiniteUpdate);
                return Err(InvalidReason::NonFiniteUpdate);
            }
        }
        self.previous = Some(mean);
        Ok(())
    }

    /// Tell the meter a sample was lost: the block it falls in is broken, so start the
    /// differences afresh (what was measured so far is kept).
    pub fn push_missing(&mut self) {
        self.decimator = Decimator::new(self.decimation);
        self.previous = None;
    }

    /// The raw-sample noise variance `D·v̂` in raw units², once at least two differences were
    /// seen and no fault latched.
    pub fn noise_variance(&self) -> Option<T> {
        if self.fault.is_some() || self.differences < 2 {
            return None;
        }
        let m = T::from_u32(self.differences);
        let v = self.sum_squares * m / (T::from_f64(2.0) * (m * m - T::ONE));
        Some(v * T::from_u32(self.decimation as u32))
    }

    /// Relative standard error of [`Self::noise_variance`] for white noise, `√(3/M)`.
    pub fn relative_standard_error(&self) -> Option<T> {
        if self.differences < 2 {
            return None;
        }
        Some((T::from_f64(3.0) / T::from_u32(self.differences)).sqrt())
    }

    /// Differences of block means seen so far.
    pub fn differences(&self) -> u32 {
        self.differences
    }

    /// The block length `D`.
    pub fn decimation(&self) -> u16 {
        self.decimation
    }

    /// Forget everything (e.g. before a new tare).
    pub fn reset(&mut self) {
        *self = Self {
            decimation: self.decimation,
            decimator: Decimator::new(self.decimation),
            previous: None,
            differences: 0,
            mean: T::ZERO,
            sum_squares: T::ZERO,
            fault: None,
        };
    }
}

#[cfg(test)]
mod tests {
    /// Levinson–Durbin on an AR(1)'s lags (γ(l) = ρ^l) finds the AR(1): φ = [ρ, 0, …] at
    /// every order; lags no stationary noise has (a reflection of 1) give no filter.
    #[test]
    fn the_prediction_filter_of_an_ar1_is_its_coefficient() {
        let ar1 = Autocovariance {
            lags: core::array::from_fn(|l| 4.0 * libm::pow(0.7, l as f64)),
            blocks: 1,
        };
        for order in [1, 2, 8, AUTOCOVARIANCE_LAGS] {
            let phi = ar1.prediction_filter(order).unwrap();
            assert!((phi[0] - 0.7).abs() < 1e-12, "order {order}: {phi:?}");
            assert!(
                phi[1..].iter().all(|v| v.abs() < 1e-12),
                "order {order}: {phi:?}"
            );
        }
        let constant = Autocovariance {
            lags: [4.0; AUTOCOVARIANCE_LAGS + 1],
            blocks: 1,
        };
        assert_eq!(constant.prediction_filter(2), None);
        assert_eq!(ar1.prediction_filter(AUTOCOVARIANCE_LAGS + 1), None);
    }

    use super::*;
    use crate::weighing::test_scene::unit_noise;

    /// An AR(1) process `x_k = φ·x_{k−1} + w_k` has `γ(l) = σ_w²·φ^l/(1 − φ²)`: the meter
    /// finds it on an offset of 10⁴ (block means of one sample) within 4 standard errors.
    #[test]
    fn the_autocovariance_of_an_ar1_process_is_found_on_any_offset() {
        let mut state = 0xA5A5_5A5A_1234_4321u64;
        let phi = 0.8;
        let samples = 400_000;
        let mut meter = AutocovarianceMeter::<f64>::new(1).unwrap();
        let mut x = 0.0;
        for _ in 0..samples {
            x = phi * x + unit_noise(&mut state);
            meter.push(1e4 + x).unwrap();
        }
        let found = meter.sums().autocovariance().unwrap();
        assert_eq!(found.blocks, samples);
        let gamma0 = 1.0 / (1.0 - phi * phi);
        // The standard error of a lag of an AR(1) with 400,000 samples: about
        // γ(0)·√((1 + φ²)/(1 − φ²)/N) = 0.0064·γ(0).
        let tolerance =
            4.0 * gamma0 * ((1.0 + phi * phi) / (1.0 - phi * phi) / samples as f64).sqrt();
        for (lag, &value) in found.lags.iter().enumerate() {
            let truth = gamma0 * phi.powi(lag as i32);
            assert!(
                (value - truth).abs() < tolerance,
                "lag {lag}: {value} against {truth} (± {tolerance})"
            );
        }
    }

    /// Sums merged from two meterings (each about its own origin) are the sums of one
    /// metering of both records with a break between them; halving leaves the
    /// autocovariance. (The lags are centred on the pooled pairs: meterings at different
    /// levels would count the difference as noise, so the scale meters counts centred on
    /// its tracked zero.)
    #[test]
    fn merged_meterings_are_one_metering_with_a_break() {
        let mut state = 0x0F0F_F0F0_AAAA_5555u64;
        let first: [f64; 300] = core::array::from_fn(|_| 50.0 + unit_noise(&mut state));
        let second: [f64; 200] = core::array::from_fn(|_| 50.0 + unit_noise(&mut state));
        let (mut a, mut b, mut both) = (
            AutocovarianceSums::<f64>::new(),
            AutocovarianceSums::new(),
            AutocovarianceSums::new(),
        );
        first.iter().for_each(|&x| a.push(x));
        second.iter().for_each(|&x| b.push(x));
        first.iter().for_each(|&x| both.push(x));
        both.end_run();
        second.iter().for_each(|&x| both.push(x));
        a.merge(&b);
        let (merged, single) = (a.autocovariance().unwrap(), both.autocovariance().unwrap());
        assert_eq!(merged.blocks, 500);
        for (m, s) in merged.lags.iter().zip(&single.lags) {
            assert!((m - s).abs() < 1e-9 * s.abs().max(1.0), "{m} against {s}");
        }
        // White noise: lag 1 about 0 (its standard error is 0.045·γ(0) with 499 pairs).
        assert!(merged.lags[1].abs() < 0.2 * merged.lags[0]);
        let mut halved = a.clone();
        halved.halve();
        let halved = halved.autocovariance().unwrap();
        assert_eq!(halved.blocks, 250);
        assert!((halved.lags[0] / merged.lags[0] - 1.0).abs() < 0.01);
    }

    /// Windows handed over one after another ([`AutocovarianceMeter::take_window`]) and
    /// merged are one metering of the whole record, to rounding: the pairs that span two
    /// windows are in them (separate meterings of the windows miss them, and their lags
    /// differ by the pairs' share); a window reset instead breaks the record.
    #[test]
    fn windows_handed_over_in_turn_are_one_metering_of_the_record() {
        let mut state = 0x1357_9BDF_2468_ACE0u64;
        // A narrow-band vibration (period 7.3 block means) in white noise, on an offset.
        let record: [f64; 600] = core::array::from_fn(|k| {
            30.0 + 5.0 * libm::sin(k as f64 * 0.86) + unit_noise(&mut state)
        });
        let mut whole = AutocovarianceMeter::<f64>::new(1).unwrap();
        record.iter().for_each(|&x| whole.push(x).unwrap());
        let whole = whole.sums().autocovariance().unwrap();
        let (mut windowed, mut apart) = (AutocovarianceSums::new(), AutocovarianceSums::new());
        let (mut meter, mut separate) = (
            AutocovarianceMeter::<f64>::new(1).unwrap(),
            AutocovarianceMeter::<f64>::new(1).unwrap(),
        );
        for window in record.chunks(50) {
            window.iter().for_each(|&x| meter.push(x).unwrap());
            windowed.merge(&meter.take_window());
            window.iter().for_each(|&x| separate.push(x).unwrap());
            apart.merge(separate.sums());
            separate.reset();
        }
        let (windowed, apart) = (
            windowed.autocovariance().unwrap(),
            apart.autocovariance().unwrap(),
        );
        assert_eq!(windowed.blocks, 600);
        for (lag, (w, s)) in windowed.lags.iter().zip(&whole.lags).enumerate() {
            assert!(
                (w - s).abs() < 1e-9 * whole.lags[0],
                "lag {lag}: {w} against {s}"
            );
        }
        let far = AUTOCOVARIANCE_LAGS;
        assert!(
            (apart.lags[far] - whole.lags[far]).abs() > 1e-3 * whole.lags[0],
            "windows apart: lag {far} {} against {}",
            apart.lags[far],
            whole.lags[far]
        );
    }

    /// Bad input: a NaN sample is refused and breaks the run (no pair spans it), a lag above
    /// lag 0 is no autocovariance, and nothing is stated before two pairs of every lag.
    #[test]
    fn bad_samples_break_the_run_and_no_autocovariance_is_invented() {
        let mut meter = AutocovarianceMeter::<f32>::new(2).unwrap();
        assert!(meter.sums().autocovariance().is_none());
        let mut state = 0x7777_1111_2222_3333u64;
        for _ in 0..100 {
            meter.push(unit_noise(&mut state) as f32).unwrap();
        }
        assert_eq!(meter.push(f32::NAN), Err(InvalidReason::NonFiniteInput));
        for _ in 0..100 {
            meter.push(unit_noise(&mut state) as f32).unwrap();
        }
        let found = meter.sums().autocovariance().unwrap();
        // 50 block means on either side of the break: no pair of the last lag spans it,
        // 50 − lag on either side, not 100 − lag.
        assert_eq!(found.blocks, 100);
        let side = 50 - AUTOCOVARIANCE_LAGS as u32;
        assert_eq!(meter.sums().pairs[AUTOCOVARIANCE_LAGS], side + side);
        let mut bad = found;
        bad.lags[3] = 2.0 * bad.lags[0];
        assert_eq!(bad.validate(), Err(ConfigError::NoiseReference));
        bad.lags[3] = f32::NAN;
        assert_eq!(bad.validate(), Err(ConfigError::NoiseReference));
        assert_eq!(
            AutocovarianceMeter::<f32>::new(0).err(),
            Some(ConfigError::Decimation)
        );
    }
}
