//! The scales the firmware and the tests build: around the step estimator, or around the
//! configured method (what tuning chose), owned or in storage of its own.

use core::fmt;

use super::noise::NoiseMetering;
use super::{CountsScale, Scale, ScaleConfig, ScaleEstimator};
use crate::estimators::step::{StepConfig, StepEstimator};
use crate::reading::ConfigError;
use crate::weighing::method::{RegionError, WeighingConfig, WeighingEstimator, WeighingMethod};

impl<const N: usize, const C: usize> Scale<StepEstimator<f32, N, N, C>> {
    /// The step estimator of `order`, `decimation` and `forgetting` in counts (gain 1, no
    /// range limit: the ADC's rails arrive as [`super::RawSample::Saturated`]).
    pub fn step_estimator(
        order: usize,
        decimation: u16,
        forgetting: f32,
    ) -> Result<StepEstimator<f32, N, N, C>, ConfigError> {
        StepEstimator::new(
            StepConfig::new(order, 1.0)
                .with_decimation(decimation)
                .with_forgetting(forgetting),
        )
    }

    /// [`ScaleConfig::weighing_default`] around the step estimator of
    /// [`ScaleConfig::DEFAULT_METHOD`] (n = 7, D = 16, λ = 1).
    pub fn step_default(
        sample_rate_hz: f32,
        calibration: CountsScale,
    ) -> Result<Self, ConfigError> {
        Self::new(
            ScaleConfig::weighing_default(sample_rate_hz),
            Self::step_estimator(7, 16, 1.0)?,
            calibration,
        )
    }
}

impl<const N: usize, const S: usize, const K: usize> Scale<WeighingEstimator<f32, N, S, K>> {
    /// The scale running the configured method of `weighing` (what calibration chose), with
    /// the decisions' thresholds for that method ([`ScaleConfig::for_method`]) at the
    /// method's sample rate, converting counts with `calibration` (the board's record, not
    /// the gain in `weighing`: that is the calibrating chain's).
    pub fn configured(
        weighing: &WeighingConfig,
        calibration: CountsScale,
    ) -> Result<Self, ConfigError> {
        Self::new(
            decisions_for(weighing)?,
            WeighingEstimator::in_counts(weighing)?,
            calibration,
        )
    }
}

impl<'a, const N: usize, const S: usize, const K: usize>
    Scale<&'a mut WeighingEstimator<f32, N, S, K>>
{
    /// [`Scale::configured`] with the estimator configured where it lives, in `storage`
    /// (on a microcontroller a `static` that starts as [`WeighingEstimator::UNCONFIGURED`],
    /// built at link time), and the scale holding a reference to it. A model bank is
    /// 20 KB: configured in place ([`WeighingEstimator::configure_in_counts`]), it is never
    /// copied through a stack of about 100 KB, nor moved again with the scale (into a
    /// pipeline, into the RTIC resources).
    pub fn configured_in(
        weighing: &WeighingConfig,
        storage: &'a mut WeighingEstimator<f32, N, S, K>,
        calibration: CountsScale,
    ) -> Result<Self, ConfigError> {
        let config = decisions_for(weighing)?;
        storage.configure_in_counts(weighing)?;
        Self::new(config, storage, calibration)
    }
}

/// An estimator that can become another configured method where it stands (the console's
/// `method`): what [`WeighingEstimator::in_counts`] builds, written over the old one.
pub trait ConfiguredEstimator: ScaleEstimator {
    /// Become the method of `weighing` in counts, or refuse (this type cannot hold it) and
    /// stay as it was.
    fn rebuild(&mut self, weighing: &WeighingConfig) -> Result<(), ConfigError>;

    /// Whether `method` may be built while the board runs: not a model bank, and nothing
    /// on an image built with a bank. A bank is chosen with its image (`K` is the image's,
    /// `firmware/weighing.toml`), at calibration; it is configured in place at boot. An
    /// image built for a data-driven method has no room for a bank (`K = 0`), so none of
    /// the bank's code is linked into it.
    fn rebuilds(method: &WeighingMethod) -> bool
    where
        Self: Sized;
}

impl<const N: usize, const S: usize, const K: usize> ConfiguredEstimator
    for WeighingEstimator<f32, N, S, K>
{
    fn rebuild(&mut self, weighing: &WeighingConfig) -> Result<(), ConfigError> {
        // A bank image's method is fixed (`rebuilds`).
        if K > 0 {
            return Err(ConfigError::Model);
        }
        self.configure_in_counts(weighing)
    }

    fn rebuilds(method: &WeighingMethod) -> bool {
        K == 0 && !matches!(method, WeighingMethod::ModelBank { .. })
    }
}

impl<E: ConfiguredEstimator> ConfiguredEstimator for &mut E {
    fn rebuild(&mut self, weighing: &WeighingConfig) -> Result<(), ConfigError> {
        (**self).rebuild(weighing)
    }

    fn rebuilds(method: &WeighingMethod) -> bool {
        E::rebuilds(method)
    }
}

/// Why a scale refused a method; it runs the one it had.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MethodRefusal {
    /// Outside the valid region of the configured model ([`WeighingConfig::check_region`]).
    Region(RegionError),
    /// The estimator this board was built with cannot hold it (an order above its
    /// capacity, a model bank of another size).
    Estimator(ConfigError),
    /// A model bank, or any method on an image built with one: a bank is built only at
    /// boot, from the compiled-in configuration.
    Fixed,
    /// A method that states no `u` on a board (forgetting; bias compensation and
    /// instrumental variables, built without their lag sums:
    /// [`WeighingMethod::states_uncertainty_on_board`]): the scale could never show its
    /// readings stable, empty or final.
    NoUncertainty,
}

impl fmt::Display for MethodRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MethodRefusal::Region(error) => write!(f, "outside the valid region: {error}"),
            MethodRefusal::Estimator(ConfigError::Order { capacity, .. }) => {
                write!(f, "this board's estimator holds orders 1 to {capacity}")
            }
            MethodRefusal::Estimator(ConfigError::Model) => {
                f.write_str("this board's estimator holds no model bank of that size")
            }
            MethodRefusal::Estimator(error) => write!(f, "{error}"),
            MethodRefusal::Fixed => f.write_str(
                "a model bank is built only at boot, from the compiled-in configuration, and an image built with one runs only it",
            ),
            MethodRefusal::NoUncertainty => f.write_str(
                "it states no uncertainty on this board, so no reading of it could be shown stable",
            ),
        }
    }
}

impl<E: ConfiguredEstimator> Scale<E> {
    /// Run the method of `weighing` from now on (its other fields as the board was built
    /// with), or refuse it and keep the one in use. The run restarts as after a load
    /// change; the calibration, the zero and the tare stay; the noise metered on the empty
    /// pan is forgotten (it was metered at the old method's `D`) until the pan is metered
    /// again; the decisions' residual drift becomes the new method's
    /// ([`ScaleConfig::for_method`]), every other decision field stays.
    pub fn set_method(&mut self, weighing: &WeighingConfig) -> Result<(), MethodRefusal> {
        if !E::rebuilds(&weighing.method) {
            return Err(MethodRefusal::Fixed);
        }
        weighing.check_region().map_err(MethodRefusal::Region)?;
        // An order beyond what states a `u` is beyond what a board's estimator holds too
        // (`UPLOAD_ORDER_CAPACITY`): that refusal, from the rebuild, says more.
        let held = weighing
            .method
            .order()
            .is_none_or(|order| order <= crate::weighing::UNCERTAINTY_ORDERS);
        if held && !weighing.method.states_uncertainty_on_board() {
            return Err(MethodRefusal::NoUncertainty);
        }
        self.estimator
            .rebuild(weighing)
            .map_err(MethodRefusal::Estimator)?;
        self.samples_per_update = self.estimator.samples_per_update().max(1);
        self.config.residual_drift_g =
            ScaleConfig::for_method(&weighing.method, self.config.sample_rate_hz).residual_drift_g;
        self.noise = NoiseMetering::new(self.samples_per_update, self.config.noise_window_samples);
        self.restart_as_load_change();
        Ok(())
    }
}

/// The decisions' thresholds for the method of `weighing`, at the method's sample rate.
fn decisions_for(weighing: &WeighingConfig) -> Result<ScaleConfig, ConfigError> {
    let sample_rate_hz = weighing.sample_rate_hz() as f32;
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        return Err(ConfigError::Model);
    }
    Ok(ScaleConfig::for_method(&weighing.method, sample_rate_hz)
        .with_scale(weighing.capacity_g as f32, weighing.scale_interval_g as f32)
        .with_ringing(
            weighing.model.natural_frequency_hz as f32,
            weighing.calibration_mass_g as f32,
        )
        .with_final_target(weighing.final_target_g as f32)
        .with_accuracy_target(
            weighing.target_relative as f32,
            weighing.calibration_mass_g as f32,
        ))
}

#[cfg(test)]
mod tests {
    use super::super::test_scene::{calibration, run, Cell, CPG, FS, ZERO};
    use super::super::ScaleState;
    use super::*;
    use crate::weighing::method::WeighingMethod;

    /// A weighing configuration of `method` for the test cell (gain and noise in counts).
    fn weighing(method: WeighingMethod) -> WeighingConfig {
        use crate::sensor::LoadCellModel;
        use crate::weighing::{LoadCoverage, OnsetConfig, Prediction};
        let prediction = Prediction::default();
        WeighingConfig {
            method,
            counts_per_gram: CPG as f64,
            zero_counts: ZERO as f64,
            noise_variance_counts2: (0.4 * CPG as f64).powi(2),
            raw_noise_variance_counts2: (0.4 * CPG as f64).powi(2),
            onset: OnsetConfig::new(FS as f64).with_rails(0.0, 65_535.0),
            detection_lag_samples: 10.0,
            model: LoadCellModel {
                counts_per_gram: CPG as f64,
                sample_rate_hz: FS as f64,
                ..crate::sensor::reference_cell()
            },
            identified_counts_per_gram: CPG as f64,
            calibration_mass_g: 138.32,
            readout_s: 0.1,
            target_relative: 0.001,
            prediction,
            recorded_drops: 0,
            recorded_worst_error_g: 0.0,
            capacity_g: crate::weighing::WeighingConfig::REFERENCE_CAPACITY_G,
            scale_interval_g: crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
            final_target_g: crate::weighing::WeighingConfig::FINAL_TARGET_E
                * crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
            loads: LoadCoverage::calibration_mass_only(138.32, prediction),
        }
    }

    /// The configured methods run behind the same decisions: the step estimator (as the
    /// default) and instrumental variables at the cell's own order, each from
    /// `Scale::configured`: the empty pan reads empty, a drop is one load change and the mass
    /// follows within the tolerance of `a_drop_is_detected_and_the_mass_follows`. The
    /// scale's gain is the board's calibration, not the config's: a config with another gain
    /// reads the same.
    #[test]
    fn configured_methods_run_behind_the_same_decisions() {
        for method in [
            ScaleConfig::DEFAULT_METHOD,
            WeighingMethod::InstrumentalVariable {
                order: 2,
                decimation: 32,
            },
        ] {
            for config_gain in [CPG as f64, 2.0 * CPG as f64] {
                let mut config = WeighingConfig {
                    counts_per_gram: config_gain,
                    ..weighing(method)
                };
                if method != ScaleConfig::DEFAULT_METHOD {
                    // The test cell as it is, a mechanical mode without a filter: its valid
                    // region (`WeighingConfig::check_region`) takes n = 2 at D ≥ 32.
                    config.model.filter_order = 0;
                }
                let mut scale =
                    Scale::<WeighingEstimator<f32, 8, 5, 0>>::configured(&config, calibration())
                        .unwrap();
                let mut cell = Cell::new(0.4);
                let empty = *run(&mut scale, &mut cell, 4000).last().unwrap();
                // Instrumental variables state no `u` here (weak instruments, see
                // `estimators::iv_uncertainty`): a reading nobody vouches for is shown, never
                // as empty or stable.
                let vouched = if empty.uncertainty_g.is_some() {
                    ScaleState::Empty
                } else {
                    ScaleState::Estimating
                };
                assert_eq!(empty.state, vouched, "{method}: {empty:?}");
                assert!(empty.mass_g.unwrap().abs() < 0.05, "{method}: {empty:?}");
                cell.load_g = 138.32;
                let last = *run(&mut scale, &mut cell, 4000).last().unwrap();
                // Stable needs the estimate to hold ±0.05 g for 50 ms and a `u`: the step
                // estimator does by 1 s; instrumental variables trade variance for no bias
                // and state no `u` on this cell, so for it the reading must only be valid.
                if method == ScaleConfig::DEFAULT_METHOD {
                    assert_eq!(last.state, ScaleState::Stable, "{method}: {last:?}");
                } else {
                    assert!(!matches!(last.state, ScaleState::Invalid(_)), "{last:?}");
                }
                assert!(
                    (last.mass_g.unwrap() - 138.32).abs() < 0.14,
                    "{method}: {last:?}"
                );
                assert_eq!(last.load_changes, 1, "{method}: {last:?}");
            }
        }
        // With the estimator in storage of its own (the firmware's static), the same readings.
        let config = weighing(ScaleConfig::DEFAULT_METHOD);
        let mut owned =
            Scale::<WeighingEstimator<f32, 8, 5, 0>>::configured(&config, calibration()).unwrap();
        let mut storage = WeighingEstimator::<f32, 8, 5, 0>::UNCONFIGURED;
        let mut borrowing = Scale::configured_in(&config, &mut storage, calibration()).unwrap();
        let mut cell = Cell::new(0.4);
        for k in 0..6000 {
            if k == 2000 {
                cell.load_g = 50.0;
            }
            let sample = cell.sample();
            assert_eq!(owned.push(sample), borrowing.push(sample), "sample {k}");
        }
        // A method the estimator type cannot hold is refused, not truncated.
        let too_big = weighing(WeighingMethod::Step {
            order: 9,
            decimation: 16,
            forgetting: 1.0,
        });
        assert!(
            Scale::<WeighingEstimator<f32, 8, 5, 0>>::configured(&too_big, calibration()).is_err()
        );
    }

    /// A scale changes method where it stands (the console's `method`): after the change
    /// it reads exactly as a scale built with the new method from the start would, over
    /// the same samples after a load change; a method it cannot run is refused with the
    /// reason and changes nothing (the readings stay those of a scale never asked).
    #[test]
    fn a_scale_changes_method_in_place_or_refuses_and_keeps_its_own() {
        type Built = Scale<WeighingEstimator<f32, 8, 5, 0>>;
        let first = weighing(ScaleConfig::DEFAULT_METHOD);
        let second = weighing(WeighingMethod::Step {
            order: 5,
            decimation: 24,
            forgetting: 1.0,
        });
        let mut all = [&first, &first, &first, &second]
            .map(|config| Built::configured(config, calibration()).unwrap());
        // What the empty pan's first second leaves behind depends on the method that ran
        // it (the zero tracked while it read empty, the noise metered at its `D`): without
        // either, the scales' futures may be compared sample by sample.
        let decisions = ScaleConfig {
            zero_tracking_rate_g_per_s: 0.0,
            consistency_check: false,
            ..*all[0].config()
        };
        for scale in all.iter_mut() {
            scale.reconfigure(decisions).unwrap();
        }
        let mut cell = Cell::new(0.4);
        let feed = |scales: &mut [Built; 4], cell: &mut Cell, samples: usize| {
            for _ in 0..samples {
                let sample = cell.sample();
                for scale in scales.iter_mut() {
                    scale.push(sample);
                }
            }
        };
        feed(&mut all, &mut cell, 4000);
        let [mut changed, mut asked_wrong, untouched, built_new] = all;
        changed.set_method(&second).unwrap();
        assert_eq!(changed.estimator().samples_per_update(), 24);
        let too_big = weighing(WeighingMethod::Step {
            order: 9,
            decimation: 16,
            forgetting: 1.0,
        });
        assert_eq!(
            asked_wrong.set_method(&too_big),
            Err(MethodRefusal::Estimator(ConfigError::Order {
                requested: 9,
                capacity: 8
            }))
        );
        let biased = weighing(WeighingMethod::Step {
            order: 7,
            decimation: 1,
            forgetting: 1.0,
        });
        assert!(matches!(
            asked_wrong.set_method(&biased),
            Err(MethodRefusal::Region(RegionError::Decimation { .. }))
        ));
        let bank = weighing(WeighingMethod::ModelBank {
            decimation: 8,
            candidates: 1,
            ratio_min: 0.9,
            ratio_max: 1.1,
            interpolation: crate::Interpolation::ThreePoint,
            whitening: 0,
        });
        assert_eq!(asked_wrong.set_method(&bank), Err(MethodRefusal::Fixed));
        // Methods it runs but could never show stable (no `u` on a board) are refused too.
        for unvouched in [
            WeighingMethod::Step {
                order: 7,
                decimation: 24,
                forgetting: 0.99,
            },
            WeighingMethod::BiasCompensated {
                order: 7,
                decimation: 24,
            },
            WeighingMethod::InstrumentalVariable {
                order: 7,
                decimation: 24,
            },
        ] {
            assert_eq!(
                asked_wrong.set_method(&weighing(unvouched)),
                Err(MethodRefusal::NoUncertainty),
                "{unvouched}"
            );
        }
        assert_eq!(asked_wrong.estimator().samples_per_update(), 16);
        // The change restarted `changed`'s run: its raw tests re-arm once the pan has
        // settled again (1.5 s), as `built_new`'s did at boot.
        let mut all = [changed, asked_wrong, untouched, built_new];
        feed(&mut all, &mut cell, 8000);
        let [mut changed, mut asked_wrong, mut untouched, mut built_new] = all;
        // A load change restarts the run of the scale built with the new method too.
        cell.load_g = 138.32;
        let mut last = None;
        for k in 0..8000 {
            let sample = cell.sample();
            let reading = changed.push(sample);
            let reference = built_new.push(sample);
            assert_eq!(
                asked_wrong.push(sample),
                untouched.push(sample),
                "sample {k}"
            );
            // From the new run on (the drop is seen within 100 ms; before it, each scale's
            // empty-pan run started at its own sample).
            if k > 400 {
                assert_eq!(reading.mass_g, reference.mass_g, "sample {k}");
                assert_eq!(reading.state, reference.state, "sample {k}");
            }
            last = Some(reading);
        }
        let last = last.unwrap();
        assert_eq!(last.state, ScaleState::Stable, "{last:?}");
        assert!((last.mass_g.unwrap() - 138.32).abs() < 0.14, "{last:?}");
    }

    /// Max and e of the weighing configuration reach the scale: a 300 g scale with
    /// e = 0.05 g shows overload above 300.45 g, and its e-set fields follow e.
    #[test]
    fn capacity_and_scale_interval_come_from_the_weighing_configuration() {
        let config = WeighingConfig {
            capacity_g: 300.0,
            scale_interval_g: 0.05,
            final_target_g: 0.04,
            ..weighing(ScaleConfig::DEFAULT_METHOD)
        };
        let mut scale =
            Scale::<WeighingEstimator<f32, 8, 5, 0>>::configured(&config, calibration()).unwrap();
        let decisions = *scale.config();
        assert_eq!(decisions.capacity_g, 300.0);
        assert_eq!(decisions.scale_interval_g, 0.05);
        assert_eq!(decisions.final_target_g, 0.04);
        let default = ScaleConfig::weighing_default(FS);
        assert_eq!(
            decisions.zero_tracking_range_g,
            default.zero_tracking_range_g / 2.0
        );
        let mut cell = Cell::new(0.4);
        cell.load_g = 320.0;
        let last = *run(&mut scale, &mut cell, 12_000).last().unwrap();
        assert_eq!(
            last.state,
            ScaleState::Invalid(super::super::ScaleFault::Overload)
        );
    }
}
