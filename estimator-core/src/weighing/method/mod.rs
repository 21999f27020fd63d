//! What calibration writes and the scale runs: [`WeighingConfig`] (the chosen method, the
//! scale's constants, the identified model and what calibration measured) and
//! [`WeighingEstimator`] (the configured method as one [`Estimator`]).
//!
//! The config is a plain `no_std` struct of numbers and enums, so a build script can turn
//! host-sim's TOML into a `const WeighingConfig` and the firmware build
//! `WeighingEstimator::<f32, N, 5, K>::new(&CONFIG, zero)` from it: no parsing on target.
//!
//! ## The valid region ([`WeighingConfig::check_region`])
//! Some failures of the stability map (host-sim `study stability`) leave nothing to see in
//! the data at run time, so a configuration that invites them is refused before it runs
//! ([`RegionError`]): by [`WeighingEstimator::new`] and [`WeighingEstimator::in_counts`]
//! (what the firmware and `estimate --config` build), and calibration never chooses one.
//! Each rule is the map's measured boundary on the reference cell (the figures are in
//! host-sim's README, beside `study stability`):
//! - **Decimation**: a data-driven method needs its decimated Nyquist frequency
//!   `f_s/(2D)` at most [`MAX_NYQUIST_OVER_BANDWIDTH`] times the model's bandwidth (the
//!   higher of the filter's cut-off and the resonance). At full rate the one-sample
//!   differences drown in noise and least squares is biased by errors in variables, while
//!   its residuals stay near the noise after the first 0.1 s, so the run-time check cannot
//!   see it then; the error falls towards the Cramér–Rao bound as `D` grows to this limit.
//! - **Order**: a data-driven order of at least [`MIN_DATA_DRIVEN_ORDER`] for a sensor with
//!   a mechanical mode and a filter (a lower order is far off the bound at any noise), 2
//!   for a mechanical mode alone (whose bandwidth is then its resonance). The run-time
//!   check flags too low an order as well, but only at low noise.
//! - **Bank span**: a model bank's candidates must cover the resonances of the configured
//!   load range with one candidate to spare at each end (a best fit on the edge is flagged
//!   `OutsideModelRange`), and a single model (`K = 1`) serves only its calibration mass
//!   (away from its resonance it is far off the bound).

use crate::sensor::LoadCellModel;
use core::fmt;

mod coverage;
mod estimator;
mod kind;
mod onset;
mod spec;

pub use coverage::{LoadCoverage, LoadScene, LoadScore, MAX_LOADS, MAX_SCENES};
pub use estimator::{WeighingEstimator, COLOUR_LAGS, UNCERTAINTY_ORDERS, UPLOAD_ORDER_CAPACITY};
pub use kind::{BankCandidate, WeighingMethod};
pub use onset::{OnsetConfig, MIN_REFERENCE_SAMPLES};
pub use spec::{Spec, SpecError};

/// What the Monte Carlo of calibration predicts for a method at the readout time.
/// `Default`: no runs and every figure zero (a configuration calibration did not score).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Prediction {
    /// Synthetic drops run (fewer than planned when the method was stopped early).
    pub runs: u32,
    /// Synthetic drops planned.
    pub planned_runs: u32,
    /// Runs with a valid reading at the readout.
    pub valid_runs: u32,
    /// Runs whose reading was valid and within the target.
    pub within_target_runs: u32,
    /// Runs in which the onset detection failed (counted as outside the target).
    pub detection_failures: u32,
    /// Mean error over the valid runs, g.
    pub bias_g: f64,
    /// RMS error over the valid runs, g.
    pub rms_g: f64,
    /// The 95th percentile of |error| over the runs (an invalid reading counts as an
    /// infinite error), g.
    pub p95_g: f64,
    /// A distribution-free upper 95% confidence bound on that percentile (an order
    /// statistic; see [`crate::tuning::upper_order_statistic`]); infinite when the
    /// method was stopped early.
    pub p95_upper_g: f64,
}

/// The weighing configuration calibration writes and the scale reads.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WeighingConfig {
    /// The method the scale runs.
    pub method: WeighingMethod,
    /// Static gain used by the method, counts per gram (given, or the identified one).
    pub counts_per_gram: f64,
    /// Empty-pan code at calibration (mean over the drops' empty stretches), counts. The
    /// scale re-tares; this is the value to start from.
    pub zero_counts: f64,
    /// White noise of one raw sample measured on the empty stretches with block means of the
    /// method's `D` ([`crate::NoiseMeter`]: the raw-rate variance the block means see),
    /// counts². The bias-compensated method uses it.
    pub noise_variance_counts2: f64,
    /// The same at `D = 1`, counts² (what the Monte Carlo's white noise is set from).
    pub raw_noise_variance_counts2: f64,
    /// How the scale must find the landing of a load: the scores hold for the method started
    /// anywhere from the landing itself to the onset this detection finds (both ends were
    /// scored). Its rails are the converter's: a code at or beyond either is saturated.
    pub onset: OnsetConfig,
    /// Mean lag of that detected onset behind the landing in the synthetic drops, samples.
    pub detection_lag_samples: f64,
    /// The load-cell model identified from the drops, with `counts_per_gram` set to the gain
    /// above (the model bank runs on it).
    pub model: LoadCellModel,
    /// The static gain the drops themselves showed (the identified model's fitted step over
    /// the known mass), counts per gram.
    pub identified_counts_per_gram: f64,
    /// The known mass of the calibration drops, g.
    pub calibration_mass_g: f64,
    /// Readout time after the landing of the mass, s.
    pub readout_s: f64,
    /// Accuracy target at the readout, relative (0.001 = 0.1%).
    pub target_relative: f64,
    /// The Monte Carlo's prediction for the method at the readout.
    pub prediction: Prediction,
    /// Recorded drops the method was confirmed on.
    pub recorded_drops: u32,
    /// The largest |error| at the readout over the recorded drops, g.
    pub recorded_worst_error_g: f64,
    /// The loads the method was scored at (`prediction` is the one at the calibration
    /// mass) and what it did at each: the range the target holds over.
    pub loads: LoadCoverage,
    /// Capacity Max of the scale, g (OIML R 76; the scale shows overload above Max + 9 e).
    pub capacity_g: f64,
    /// Scale interval e, g (OIML R 76: the display's resolution, the MPE's unit; see
    /// [`crate::weighing::ScaleConfig::SCALE_INTERVAL_G`] for the reference cell's).
    pub scale_interval_g: f64,
    /// A reading is final once 2u is at or below this, g
    /// ([`crate::weighing::ScaleConfig::final_target_g`]; files without it read 0.5 e).
    pub final_target_g: f64,
}

impl WeighingConfig {
    /// The reference cell's capacity Max, g ([`crate::weighing::ScaleConfig::CAPACITY_G`]);
    /// what a file written before Max was a key loads.
    pub const REFERENCE_CAPACITY_G: f64 = 600.0;
    /// The reference cell's scale interval e, g
    /// ([`crate::weighing::ScaleConfig::SCALE_INTERVAL_G`], argued there).
    pub const REFERENCE_SCALE_INTERVAL_G: f64 = 0.1;
    /// The final target a file without one reads: 0.5 e (OIML R 76's smallest maximum
    /// permissible error at verification, class III).
    pub const FINAL_TARGET_E: f64 = 0.5;
}

/// A data-driven method's decimated Nyquist frequency may be at most this many times the
/// model's bandwidth (see the module docs: D ≥ 8 on the reference chain at 4 kHz).
pub const MAX_NYQUIST_OVER_BANDWIDTH: f64 = 2.5;
/// The lowest data-driven order for a sensor with a mechanical mode and a filter (module
/// docs); a mechanical mode alone (`filter_order = 0`) takes 2.
pub const MIN_DATA_DRIVEN_ORDER: usize = 3;

/// Why a weighing configuration lies outside the region the stability map measured as valid
/// (see the module docs): a failure there would not be flagged at run time.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RegionError {
    /// The block length is below what the model's bandwidth needs (errors-in-variables bias).
    Decimation {
        /// The configured `D`.
        decimation: u16,
        /// The smallest `D` with `f_s/(2D)` ≤ [`MAX_NYQUIST_OVER_BANDWIDTH`] × the bandwidth.
        minimum: u16,
    },
    /// The order is below what the sensor needs.
    Order {
        /// The configured order.
        order: usize,
        /// The smallest order accepted.
        minimum: usize,
    },
    /// The bank's candidates do not cover the resonances of the configured loads with one
    /// candidate to spare at each end (or a single model serves more than its calibration
    /// mass).
    BankSpan {
        /// The lowest and highest frequency ratio the loads need.
        needed: (f64, f64),
        /// The lowest and highest ratio covered with a candidate to spare.
        covered: (f64, f64),
    },
    /// A number the rules need is not finite and positive (sample rate, bandwidth, masses).
    Model,
}

impl fmt::Display for RegionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RegionError::Decimation {
                decimation,
                minimum,
            } => write!(
                f,
                "decimation D = {decimation} is below {minimum}: the decimated Nyquist frequency must be at most {MAX_NYQUIST_OVER_BANDWIDTH}x the model's bandwidth, or least squares is biased by errors in variables (not detectable at run time)"
            ),
            RegionError::Order { order, minimum } => write!(
                f,
                "order n = {order} is below {minimum}, the lowest that describes a load cell with its filter"
            ),
            RegionError::BankSpan { needed, covered } => write!(
                f,
                "the bank covers resonance ratios {:.4}-{:.4} with a candidate to spare, the loads need {:.4}-{:.4}",
                covered.0, covered.1, needed.0, needed.1
            ),
            RegionError::Model => {
                f.write_str("sample rate, bandwidth or load range not finite and positive")
            }
        }
    }
}

impl WeighingConfig {
    /// Refuse a configuration outside the stability map's valid region (see the module
    /// docs): a data-driven method with too small a `D` or too low an order, a bank that
    /// does not cover the load range.
    pub fn check_region(&self) -> Result<(), RegionError> {
        match self.method {
            WeighingMethod::Step {
                order, decimation, ..
            }
            | WeighingMethod::BiasCompensated { order, decimation }
            | WeighingMethod::InstrumentalVariable { order, decimation } => {
                let filtered = self.model.filter_order > 0;
                let bandwidth_hz = if filtered {
                    self.model
                        .filter_cutoff_hz
                        .max(self.model.natural_frequency_hz)
                } else {
                    self.model.natural_frequency_hz
                };
                let rate_hz = self.model.sample_rate_hz;
                if !(bandwidth_hz > 0.0 && rate_hz > 0.0 && rate_hz.is_finite()) {
                    return Err(RegionError::Model);
                }
                // f_s/(2D) ≤ k·bandwidth ⇔ D ≥ f_s/(2k·bandwidth).
                let minimum =
                    libm::ceil(rate_hz / (2.0 * MAX_NYQUIST_OVER_BANDWIDTH * bandwidth_hz));
                let minimum = minimum.clamp(1.0, f64::from(u16::MAX)) as u16;
                if decimation < minimum {
                    return Err(RegionError::Decimation {
                        decimation,
                        minimum,
                    });
                }
                // A mechanical mode alone (no filter) is of order 2.
                let minimum = if filtered { MIN_DATA_DRIVEN_ORDER } else { 2 };
                if order < minimum {
                    return Err(RegionError::Order { order, minimum });
                }
                Ok(())
            }
            WeighingMethod::ModelBank {
                candidates,
                ratio_min,
                ratio_max,
                ..
            } => {
                let needed = self.needed_ratios().ok_or(RegionError::Model)?;
                // One candidate to spare at each end: the covered span is one grid step in.
                let covered = if candidates >= 2 && ratio_max > ratio_min && ratio_min > 0.0 {
                    let step = libm::pow(ratio_max / ratio_min, 1.0 / (candidates - 1) as f64);
                    (ratio_min * step, ratio_max / step)
                } else {
                    // A single model: its own ratio only (the geometric centre).
                    let centre = libm::sqrt(ratio_min * ratio_max);
                    (centre, centre)
                };
                // A relative tolerance for the rounding of ratios computed from masses.
                let slack = 1e-9;
                if needed.0 < covered.0 * (1.0 - slack) || needed.1 > covered.1 * (1.0 + slack) {
                    return Err(RegionError::BankSpan { needed, covered });
                }
                Ok(())
            }
        }
    }

    /// The model bank `bank` widened as calibration widens its bank candidates, to cover
    /// this configuration's load range with a candidate to spare at each end (what
    /// [`Self::check_region`] requires); `None` when the load range gives no ratios.
    pub fn bank_covering_loads(&self, bank: BankCandidate) -> Option<WeighingMethod> {
        let (low, high) = self.needed_ratios()?;
        let (mut ratio_min, mut ratio_max) = (bank.ratio_min, bank.ratio_max);
        cover_ratios(bank.candidates, &mut ratio_min, &mut ratio_max, low, high);
        Some(
            BankCandidate {
                ratio_min,
                ratio_max,
                ..bank
            }
            .method(),
        )
    }

    /// The lowest and highest resonance ratio (relative to the calibration mass's) of the
    /// configured load range: with the platform mass unknown, the widest it can be (a
    /// platform of no mass, the end calibration also scores).
    fn needed_ratios(&self) -> Option<(f64, f64)> {
        let loads = &self.loads;
        let calibration = self.calibration_mass_g;
        let platform = loads.platform_mass_g.unwrap_or(0.0);
        let ratio = |mass_g: f64| {
            crate::sensor::LoadCellModel::frequency_ratio_for_mass(calibration, platform, mass_g)
        };
        let (a, b) = (ratio(loads.max_g), ratio(loads.min_g));
        let (low, high) = (a.min(b).min(1.0), a.max(b).max(1.0));
        (low > 0.0 && high.is_finite()).then_some((low, high))
    }

    /// The sample rate of the method, Hz (that of the identified model).
    pub fn sample_rate_hz(&self) -> f64 {
        self.model.sample_rate_hz
    }

    /// The readout as a sample index after the onset: `round(readout_s · f_s)`.
    pub fn readout_samples(&self) -> usize {
        readout_samples(self.readout_s, self.model.sample_rate_hz)
    }
}

/// `round(readout_s · f_s)`, zero when not finite or negative.
pub(crate) fn readout_samples(readout_s: f64, sample_rate_hz: f64) -> usize {
    let samples = libm::round(readout_s * sample_rate_hz);
    if samples.is_finite() && samples > 0.0 {
        samples as usize
    } else {
        0
    }
}

/// Widen a bank of `candidates` models over `[ratio_min, ratio_max]` so that it spans the
/// scored resonances `[low, high]` with one candidate beyond each end (the bank flags a best
/// fit on its edge as out of range): unchanged when it already does, else
/// `[low/s, high·s]` with the spacing `s = (high/low)^(1/(K − 3))`.
pub(crate) fn cover_ratios(
    candidates: usize,
    ratio_min: &mut f64,
    ratio_max: &mut f64,
    low: f64,
    high: f64,
) {
    if candidates < 4 || !(*ratio_max > *ratio_min) {
        return;
    }
    let given_step = libm::pow(*ratio_max / *ratio_min, 1.0 / (candidates - 1) as f64);
    if *ratio_min * given_step <= low && *ratio_max / given_step >= high {
        return;
    }
    let step = libm::pow(high / low, 1.0 / (candidates - 3) as f64);
    *ratio_min = low / step;
    *ratio_max = high * step;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::bias_compensated::{
        BiasCompensatedConfig, BiasCompensatedStepEstimator,
    };
    use crate::estimators::iv::{IvConfig, IvStepEstimator};
    use crate::estimators::model::{InitialState, ModelBank};
    use crate::estimators::step::{StepConfig, StepEstimator};
    use crate::reading::{ConfigError, Estimator, InvalidReason, State};

    fn config(method: WeighingMethod) -> WeighingConfig {
        WeighingConfig {
            method,
            counts_per_gram: 73.25,
            zero_counts: 16_764.0,
            noise_variance_counts2: 1_060.0,
            raw_noise_variance_counts2: 1_050.0,
            onset: OnsetConfig::new(4000.0).with_rails(0.0, 65_535.0),
            detection_lag_samples: 10.0,
            model: crate::sensor::reference_cell(),
            identified_counts_per_gram: 73.25,
            calibration_mass_g: 138.32,
            readout_s: 0.1,
            target_relative: 0.001,
            prediction: Prediction::default(),
            recorded_drops: 0,
            recorded_worst_error_g: 0.0,
            capacity_g: crate::weighing::WeighingConfig::REFERENCE_CAPACITY_G,
            scale_interval_g: crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
            final_target_g: crate::weighing::WeighingConfig::FINAL_TARGET_E
                * crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
            loads: LoadCoverage::calibration_mass_only(138.32, Prediction::default()),
        }
    }

    /// Counts (zero removed) of a noisy drop of the reference cell.
    fn samples() -> [f64; 600] {
        let model = config(WeighingMethod::Step {
            order: 1,
            decimation: 1,
            forgetting: 1.0,
        })
        .model
        .sensor_model::<f64, 5>()
        .unwrap();
        // Test data only: the tuning layer's seeded synthetic drop of the model.
        let synthetic = crate::tuning::synthetic::Synthetic {
            model,
            mass_g: 138.32,
            sigma: 32.6,
            empty: 0,
            length: 600,
        };
        let mut out = [0.0; 600];
        for (slot, y) in out.iter_mut().zip(synthetic.samples(5, 0)) {
            *slot = y;
        }
        out
    }

    fn same<A: Estimator<f32>, B: Estimator<f32>>(mut a: A, mut b: B) {
        for &y in samples().iter() {
            assert_eq!(a.push(y as f32), b.push(y as f32));
        }
    }

    #[test]
    fn each_method_is_the_core_type_with_the_configured_settings() {
        let zero = 16_764.0;
        let (low, high) = (0.5 - zero, 65_534.5 - zero);
        let step = |order, decimation, forgetting: f32| {
            StepConfig::new(order, 73.25f32)
                .with_decimation(decimation)
                .with_forgetting(forgetting)
                .with_valid_range(low as f32, high as f32)
        };
        let method = WeighingMethod::Step {
            order: 3,
            decimation: 32,
            forgetting: 0.9,
        };
        same(
            WeighingEstimator::<f32, 8, 5, 3>::new(&config(method), zero).unwrap(),
            StepEstimator::<f32, 8>::new(step(3, 32, 0.9)).unwrap(),
        );
        let method = WeighingMethod::BiasCompensated {
            order: 3,
            decimation: 16,
        };
        same(
            WeighingEstimator::<f32, 8, 5, 3>::new(&config(method), zero).unwrap(),
            BiasCompensatedStepEstimator::<f32, 8>::new(BiasCompensatedConfig::new(
                step(3, 16, 1.0),
                1_060.0,
            ))
            .unwrap(),
        );
        let method = WeighingMethod::InstrumentalVariable {
            order: 3,
            decimation: 24,
        };
        same(
            WeighingEstimator::<f32, 8, 5, 3>::new(&config(method), zero).unwrap(),
            IvStepEstimator::<f32, 8>::new(IvConfig::new(step(3, 24, 1.0))).unwrap(),
        );
        // Three candidates 11% apart: the middle one (at 1, with one to spare at each end)
        // covers the calibration mass, the only load of this config.
        let method = WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 3,
            ratio_min: 0.9,
            ratio_max: 1.0 / 0.9,
            interpolation: crate::Interpolation::ThreePoint,
            whitening: 0,
        };
        let configs = config(method)
            .model
            .bank_configs::<f32, 5, 3>(0.9, 1.0 / 0.9, 8, InitialState::Unknown)
            .unwrap()
            .map(|c| c.with_valid_range(low as f32, high as f32));
        same(
            WeighingEstimator::<f32, 8, 5, 3>::new(&config(method), zero).unwrap(),
            ModelBank::new(configs).unwrap(),
        );
        // A type with room for more candidates holds the same bank (a host's one type for
        // every size) and reads the same; a bank larger than the type's room is refused,
        // not truncated.
        same(
            WeighingEstimator::<f32, 8, 5, 5>::new(&config(method), zero).unwrap(),
            ModelBank::new(configs).unwrap(),
        );
        assert_eq!(
            WeighingEstimator::<f32, 8, 5, 2>::new(&config(method), zero).err(),
            Some(ConfigError::Model)
        );
        // A type with no room for a bank (`K = 0`: the firmware's data-driven images, which
        // then hold no bank code) refuses one, in place too, and is left as it was; it holds
        // the data-driven methods as the others do, from its unconfigured start, which
        // flags every sample and survives a reset.
        let mut roomless = WeighingEstimator::<f32, 8, 5, 0>::UNCONFIGURED;
        roomless.reset();
        let flagged = roomless.push(1.0);
        assert_eq!(
            (flagged.estimate, flagged.state),
            (None, State::Invalid(InvalidReason::Unconfigured))
        );
        assert_eq!(
            WeighingEstimator::<f32, 8, 5, 0>::new(&config(method), zero).err(),
            Some(ConfigError::Model)
        );
        let step_method = WeighingMethod::Step {
            order: 3,
            decimation: 32,
            forgetting: 0.9,
        };
        roomless.configure_in_counts(&config(step_method)).unwrap();
        assert_eq!(
            roomless.configure_in_counts(&config(method)),
            Err(ConfigError::Model)
        );
        same(
            roomless,
            WeighingEstimator::<f32, 8, 5, 3>::in_counts(&config(step_method)).unwrap(),
        );
        assert_eq!(
            WeighingEstimator::<f32, 8, 5, 3>::new(&config(method), f64::NAN).err(),
            Some(ConfigError::Range)
        );
    }

    #[test]
    fn a_code_at_a_rail_is_flagged() {
        let method = WeighingMethod::Step {
            order: 3,
            decimation: 8,
            forgetting: 1.0,
        };
        let zero = 16_764.0;
        let mut estimator = WeighingEstimator::<f64, 8, 5, 1>::new(&config(method), zero).unwrap();
        for _ in 0..7 {
            assert_eq!(estimator.push(65_534.0 - zero).state, State::WarmingUp);
        }
        assert_eq!(
            estimator.push(65_535.0 - zero).state,
            State::Invalid(InvalidReason::OutOfRange)
        );
        estimator.reset();
        assert_eq!(
            estimator.push(0.0 - zero).state,
            State::Invalid(InvalidReason::OutOfRange)
        );
    }

    #[test]
    fn a_configuration_outside_the_valid_region_is_refused() {
        let step = |order, decimation| WeighingMethod::Step {
            order,
            decimation,
            forgetting: 1.0,
        };
        // 4 kHz and a 100 Hz filter: D ≥ 4000/(2·2.5·100) = 8.
        assert_eq!(config(step(5, 8)).check_region(), Ok(()));
        assert_eq!(
            config(step(7, 4)).check_region(),
            Err(RegionError::Decimation {
                decimation: 4,
                minimum: 8
            })
        );
        assert_eq!(
            config(WeighingMethod::InstrumentalVariable {
                order: 7,
                decimation: 1
            })
            .check_region(),
            Err(RegionError::Decimation {
                decimation: 1,
                minimum: 8
            })
        );
        assert_eq!(
            config(step(2, 16)).check_region(),
            Err(RegionError::Order {
                order: 2,
                minimum: 3
            })
        );
        // A slower filter needs more decimation: 50 Hz → D ≥ 16.
        let mut slow = config(step(5, 8));
        slow.model.filter_cutoff_hz = 50.0;
        assert_eq!(
            slow.check_region(),
            Err(RegionError::Decimation {
                decimation: 8,
                minimum: 16
            })
        );
        // What the constructors say.
        assert_eq!(
            WeighingEstimator::<f64, 8, 5, 1>::new(&config(step(2, 16)), 0.0).err(),
            Some(ConfigError::OutsideValidRegion)
        );
        assert_eq!(
            WeighingEstimator::<f32, 8, 5, 1>::in_counts(&config(step(7, 1))).err(),
            Some(ConfigError::OutsideValidRegion)
        );
        assert!(
            WeighingEstimator::<f64, 8, 5, 1>::with_method(&config(step(7, 1)), &step(7, 1), 0.0)
                .is_ok(),
            "calibration may still try it"
        );

        // The bank: the loads 100–300 g on a platform of 120 g with the calibration at
        // 138.32 g need ratios √(258.32/420) = 0.7843 … √(258.32/220) = 1.0836.
        let bank = |candidates, ratio_min, ratio_max| WeighingMethod::ModelBank {
            decimation: 8,
            candidates,
            ratio_min,
            ratio_max,
            interpolation: crate::Interpolation::ThreePoint,
            whitening: 0,
        };
        let ranged = |method| {
            let mut c = config(method);
            c.loads.min_g = 100.0;
            c.loads.max_g = 300.0;
            c.loads.platform_mass_g = Some(120.0);
            c
        };
        assert_eq!(ranged(bank(33, 0.68, 1.3)).check_region(), Ok(()));
        match ranged(bank(33, 0.8, 1.3)).check_region() {
            Err(RegionError::BankSpan { needed, covered }) => {
                assert!((needed.0 - 0.7843).abs() < 1e-4 && (needed.1 - 1.0836).abs() < 1e-4);
                assert!(covered.0 > 0.8 && covered.0 < 0.82, "{covered:?}");
            }
            other => panic!("{other:?}"),
        }
        // One model serves its calibration mass only.
        assert!(ranged(bank(1, 1.0, 1.0)).check_region().is_err());
        assert_eq!(config(bank(1, 1.0, 1.0)).check_region(), Ok(()));
        // The platform mass unknown: the widest ratios (no platform), √(138.32/300) = 0.679.
        let mut unknown = ranged(bank(33, 0.68, 1.3));
        unknown.loads.platform_mass_g = None;
        assert!(matches!(
            unknown.check_region(),
            Err(RegionError::BankSpan { .. })
        ));
    }
}
