//! How the landing of a load is found in a record: the two-sided CUSUM's settings and the
//! converter's rails.

/// How a calibration drop is read.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OnsetConfig {
    /// The recording must start with at least this many samples of the empty pan (the
    /// reference stretch of the detection, and the least empty stretch accepted).
    pub min_empty_samples: usize,
    /// CUSUM drift ν, in noise standard deviations.
    pub drift_sigma: f64,
    /// CUSUM threshold h, in noise standard deviations.
    pub threshold_sigma: f64,
    /// Samples just before the onset left out of the zero and the noise.
    pub guard_samples: usize,
    /// The step must exceed this many noise standard deviations.
    pub min_step_sigma: f64,
    /// Floor on the detection's noise level, raw units (noise-free or heavily quantised
    /// data would otherwise give σ₀ = 0): half a code.
    pub min_noise_rms: f64,
    /// The converter's lowest code: a sample at or below it is saturated.
    pub rail_low: f64,
    /// The converter's highest code: a sample at or above it is saturated.
    pub rail_high: f64,
}

impl OnsetConfig {
    /// 0.1 s of empty pan at least, ν = 1σ, h = 12σ (see the module docs), a 2 ms guard,
    /// a step of at least 10σ (20 dB, as [`crate::sensor::identify()`] asks), no rails.
    pub fn new(sample_rate_hz: f64) -> Self {
        let samples = |seconds: f64| {
            let n = seconds * sample_rate_hz;
            if n.is_finite() && n > 0.0 {
                n as usize
            } else {
                0
            }
        };
        Self {
            min_empty_samples: samples(0.1).max(MIN_REFERENCE_SAMPLES),
            drift_sigma: 1.0,
            threshold_sigma: 12.0,
            guard_samples: samples(0.002),
            min_step_sigma: 10.0,
            min_noise_rms: 0.5,
            rail_low: f64::NEG_INFINITY,
            rail_high: f64::INFINITY,
        }
    }

    /// Set the converter's rails (codes at or beyond them are saturated).
    pub fn with_rails(mut self, low: f64, high: f64) -> Self {
        self.rail_low = low;
        self.rail_high = high;
        self
    }

    /// Refuse settings that cannot work.
    pub(crate) fn is_valid(&self) -> bool {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        self.min_empty_samples >= MIN_REFERENCE_SAMPLES
            && positive(self.drift_sigma)
            && positive(self.threshold_sigma)
            && self.min_step_sigma.is_finite()
            && self.min_step_sigma >= 0.0
            && positive(self.min_noise_rms)
            && !self.rail_low.is_nan()
            && !self.rail_high.is_nan()
            && self.rail_low < self.rail_high
    }
}

/// The shortest reference stretch: the noise meter's relative standard error is then
/// `√(3/15) = 45%`, about the worst a detection threshold tolerates.
pub const MIN_REFERENCE_SAMPLES: usize = 16;
