//! Tare, noise and onset of one recorded calibration drop: an empty-pan stretch, then the
//! reference mass lands.
//!
//! 1. **Checks.** A sample that is NaN or infinite, or at or beyond a rail of the converter,
//!    is a typed error naming it (a clipped overshoot is not a step response).
//! 2. **Reference stretch.** The first `min_empty_samples` must be empty: their mean is a
//!    first zero `z₀`, and [`NoiseMeter`] gives a first noise level `σ₀` (first differences,
//!    so an offset does not count as noise).
//! 3. **Change detection.** A two-sided CUSUM (Page 1954) on `(y − z₀)/σ₀` with drift `ν`
//!    and threshold `h` (both in units of `σ₀`): `S⁺ ← max(0, S⁺ + z − ν)`, the same for
//!    `−z`. White noise alone crosses `h = 12` with drift `ν = 1` about once in 10¹¹ samples
//!    (Siegmund's approximation of the average run length, `(e^{2ν(h+1.166)} − 2ν(h+1.166) −
//!    1)/(2ν²)`), while a step of the calibration mass crosses it within milliseconds of
//!    landing.
//! 4. **Onset.** Backed off from the alarm to the first sample of the excursion that raised
//!    it: the sample after the last one at which the alarming sum was zero, i.e. the last
//!    point still consistent with "no change" (the CUSUM change-point estimate). On the
//!    reference cell, whose response starts like `t⁵` behind the 3rd-order filter, that is
//!    within a few samples of the true landing. The estimators that start there estimate
//!    their initial state (or, data-driven, absorb it), so a few samples either way cost
//!    nothing; the Monte Carlo of [`super`] applies this very detection to its synthetic
//!    drops, so whatever lateness it has is in the scores.
//! 5. **Tare and noise.** The zero is the mean of the empty stretch up to `guard_samples`
//!    before the onset (the response may already be rising, below the noise, just before
//!    it); the noise variance is [`NoiseMeter`]'s over the same stretch.
//! 6. **A step at all.** The mean of the second half of the response must differ from the
//!    zero by more than `min_step_sigma` noise standard deviations.
//!
//! Fixed memory: the drop is read as often as needed (three passes) from a source the caller
//! can restart: a slice, or the seeded synthetic drops of the Monte Carlo.

use crate::estimators::noise_meter::NoiseMeter;
use crate::numerics::real::Real;
use crate::weighing::OnsetConfig;

/// What one drop showed.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DropSummary {
    /// Samples in the drop.
    pub samples: usize,
    /// Index of the first sample of the response (see the module docs).
    pub onset: usize,
    /// Index at which the detection raised its alarm.
    pub alarm: usize,
    /// Samples of the empty stretch the zero and noise come from: `onset − guard`.
    pub empty_samples: usize,
    /// Mean of the empty stretch, raw units.
    pub zero: f64,
    /// White-noise variance of one raw sample over the empty stretch, raw units².
    pub noise_variance: f64,
    /// Mean of the second half of the response minus the zero, raw units.
    pub level: f64,
}

/// Why a drop cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DropError {
    /// Fewer samples than the reference stretch and the readout need.
    TooShort {
        /// Samples in the drop.
        samples: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A sample is NaN or infinite.
    NonFinite {
        /// Its index.
        sample: usize,
    },
    /// A sample is at or beyond a rail of the converter.
    Saturated {
        /// Its index.
        sample: usize,
    },
    /// The recording does not start with the empty pan: the change begins within the first
    /// `min_empty_samples` (or the stretch before the onset is shorter than that).
    NoEmptyStretch {
        /// Samples of empty pan found before the onset (minus the guard).
        empty_samples: usize,
        /// Samples needed.
        needed: usize,
    },
    /// No change from the empty pan was detected, or the level after it is within
    /// `min_step_sigma` noise standard deviations of the zero.
    NoStep,
}

/// Read a drop held in a slice of raw samples (not tared). Whether the drop also holds the
/// readout after its onset is the caller's to check, with the result.
pub fn summarise_drop<T: Real>(drop: &[T], config: &OnsetConfig) -> Result<DropSummary, DropError> {
    summarise(|| drop.iter().map(|v| v.to_f64()), config)
}

/// [`summarise_drop`] over any source that can be read again from its start (each call of
/// `source` restarts it and must give the same samples).
pub fn summarise<I: Iterator<Item = f64>>(
    source: impl Fn() -> I,
    config: &OnsetConfig,
) -> Result<DropSummary, DropError> {
    let reference = config.min_empty_samples;
    // Pass 1: checks over every sample; the reference stretch's zero and noise.
    let mut samples = 0usize;
    let mut sum = 0.0;
    let mut meter = NoiseMeter::<f64>::new(1).map_err(|_| DropError::NoStep)?;
    for (index, y) in source().enumerate() {
        if !y.is_finite() {
            return Err(DropError::NonFinite { sample: index });
        }
        if !(y > config.rail_low && y < config.rail_high) {
            return Err(DropError::Saturated { sample: index });
        }
        if index < reference {
            sum += y;
            // Finite by the check above: cannot fail.
            let _ = meter.push(y);
        }
        samples += 1;
    }
    let needed = reference + 2 * config.guard_samples + 2;
    if samples < needed {
        return Err(DropError::TooShort { samples, needed });
    }
    let zero_reference = sum / reference as f64;
    let sigma = libm::sqrt(meter.noise_variance().unwrap_or(0.0)).max(config.min_noise_rms);

    // Pass 2: the CUSUM from the first sample, the onset backed off from its alarm.
    let (drift, threshold) = (config.drift_sigma, config.threshold_sigma);
    let (mut up, mut down) = (0.0f64, 0.0f64);
    let (mut up_start, mut down_start) = (0usize, 0usize);
    let mut detected = None;
    for (index, y) in source().enumerate() {
        let z = (y - zero_reference) / sigma;
        up = (up + z - drift).max(0.0);
        down = (down - z - drift).max(0.0);
        if up == 0.0 {
            up_start = index + 1;
        }
        if down == 0.0 {
            down_start = index + 1;
        }
        if up > threshold {
            detected = Some((up_start, index));
            break;
        }
        if down > threshold {
            detected = Some((down_start, index));
            break;
        }
    }
    let Some((onset, alarm)) = detected else {
        return Err(DropError::NoStep);
    };
    let empty_samples = onset.saturating_sub(config.guard_samples);
    if empty_samples < reference {
        return Err(DropError::NoEmptyStretch {
            empty_samples,
            needed: reference,
        });
    }

    // Pass 3: zero and noise over the empty stretch; the level of the response's second half.
    let half = onset + (samples - onset) / 2;
    let (mut empty_sum, mut level_sum, mut level_count) = (0.0, 0.0, 0usize);
    meter.reset();
    for (index, y) in source().enumerate() {
        if index < empty_samples {
            empty_sum += y;
            let _ = meter.push(y);
        } else if index >= half {
            level_sum += y;
            level_count += 1;
        }
    }
    let zero = empty_sum / empty_samples as f64;
    let noise_variance = meter.noise_variance().unwrap_or(0.0);
    let level = level_sum / level_count.max(1) as f64 - zero;
    let noise_rms = libm::sqrt(noise_variance).max(config.min_noise_rms);
    if !(libm::fabs(level) > config.min_step_sigma * noise_rms) {
        return Err(DropError::NoStep);
    }
    Ok(DropSummary {
        samples,
        onset,
        alarm,
        empty_samples,
        zero,
        noise_variance,
        level,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tuning::synthetic::gaussian;

    /// 0.2 s of empty pan at `zero`, then a first-order rise to `step` (τ = 5 ms), white
    /// noise `sigma`, at 4 kHz.
    fn recording(zero: f64, step: f64, sigma: f64, empty: usize, samples: usize) -> [f64; 4000] {
        let mut out = [0.0; 4000];
        for k in 0..samples.min(4000) {
            let response = if k < empty {
                0.0
            } else {
                step * (1.0 - libm::exp(-((k - empty) as f64) / 20.0))
            };
            out[k] = zero + response + sigma * gaussian(99, k as u64);
        }
        out
    }

    #[test]
    fn finds_the_onset_zero_and_noise_of_a_clean_drop() {
        let data = recording(16_764.0, 10_000.0, 30.0, 800, 4000);
        let summary = summarise_drop(&data, &OnsetConfig::new(4000.0)).unwrap();
        // The response rises 10,000·k/20 counts per sample at first: it leaves the noise
        // (30 counts) within a sample or two, and the back-off lands on the first sample of
        // the excursion; the CUSUM may also start one sample early on a noise sample above
        // the drift.
        assert!(
            (799..=802).contains(&summary.onset),
            "onset {}",
            summary.onset
        );
        // Zero: mean of ~790 samples of σ = 30, standard error 1.1 counts; 5 of them.
        assert!((summary.zero - 16_764.0).abs() < 5.5, "{}", summary.zero);
        // Noise: relative standard error √(3/790) = 6%; 4 of them.
        assert!(
            (summary.noise_variance / 900.0 - 1.0).abs() < 0.25,
            "{}",
            summary.noise_variance
        );
        assert!((summary.level - 10_000.0).abs() < 10.0, "{}", summary.level);
    }

    #[test]
    fn a_negative_step_is_found_too() {
        let data = recording(30_000.0, -8_000.0, 10.0, 1000, 4000);
        let summary = summarise_drop(&data, &OnsetConfig::new(4000.0)).unwrap();
        assert!((999..=1002).contains(&summary.onset), "{}", summary.onset);
    }

    #[test]
    fn malformed_drops_are_typed_errors() {
        let config = OnsetConfig::new(4000.0).with_rails(0.0, 65_535.0);
        // No step at all: noise only.
        let flat = recording(16_764.0, 0.0, 30.0, 800, 4000);
        assert_eq!(summarise_drop(&flat, &config), Err(DropError::NoStep));
        // A step smaller than 10σ after its onset is not a calibration drop either (the
        // CUSUM finds a 4σ step, the level check refuses it).
        let small = recording(16_764.0, 120.0, 30.0, 800, 4000);
        assert_eq!(summarise_drop(&small, &config), Err(DropError::NoStep));
        // The mass lands within the first 0.1 s: no empty stretch.
        let early = recording(16_764.0, 10_000.0, 30.0, 200, 4000);
        assert!(matches!(
            summarise_drop(&early, &config),
            Err(DropError::NoEmptyStretch { needed: 400, .. })
        ));
        // Already loaded when the recording starts: the reference stretch is the loaded
        // level, nothing changes after it.
        let loaded = recording(26_764.0, 0.0, 30.0, 0, 4000);
        assert_eq!(summarise_drop(&loaded, &config), Err(DropError::NoStep));
        // NaN, infinity and a rail.
        let mut bad = recording(16_764.0, 10_000.0, 30.0, 800, 4000);
        bad[1234] = f64::NAN;
        assert_eq!(
            summarise_drop(&bad, &config),
            Err(DropError::NonFinite { sample: 1234 })
        );
        bad[1234] = f64::INFINITY;
        assert_eq!(
            summarise_drop(&bad, &config),
            Err(DropError::NonFinite { sample: 1234 })
        );
        bad[1234] = 65_535.0;
        assert_eq!(
            summarise_drop(&bad, &config),
            Err(DropError::Saturated { sample: 1234 })
        );
        // Too short for the reference stretch.
        assert!(matches!(
            summarise_drop(&bad[..300], &config),
            Err(DropError::TooShort { samples: 300, .. })
        ));
        assert!(matches!(
            summarise_drop::<f64>(&[], &config),
            Err(DropError::TooShort { samples: 0, .. })
        ));
    }

    #[test]
    fn noise_free_data_uses_the_floor() {
        // Exactly constant zero, then a step: σ₀ = 0 would divide by zero; the floor (half a
        // code) keeps the CUSUM finite and finds the first sample that moved.
        let data = recording(100.0, 1000.0, 0.0, 500, 2000);
        let summary = summarise_drop(&data[..2000], &OnsetConfig::new(4000.0)).unwrap();
        assert_eq!(summary.onset, 501, "the first sample above the zero");
        assert_eq!(summary.zero, 100.0);
        assert_eq!(summary.noise_variance, 0.0);
    }

    #[test]
    fn f32_data_gives_the_f64_summary() {
        // Codes are whole numbers below 2^24: exact in f32, so the summary is identical.
        let data = recording(16_764.0, 10_000.0, 30.0, 800, 4000).map(libm::round);
        let data32 = data.map(|v| v as f32);
        let config = OnsetConfig::new(4000.0);
        assert_eq!(
            summarise_drop(&data, &config),
            summarise_drop(&data32, &config)
        );
    }
}
