//! The parametric load-cell model: a mechanical second-order mode `(f_n, ζ)` in series with
//! a known Butterworth low-pass, a static gain and a sample rate, discretised exactly.
//!
//! It is what calibration identifies ([`crate::sensor::identify`]) and what the model-based
//! estimators run on ([`crate::ModelEstimator`], [`crate::ModelBank`]). Its load
//! dependence is the physical one: with stiffness `k` and damping `c` fixed,
//! `ω² = k/(m_platform + M)` and `2ζω = c/(m_platform + M)`, so a cell that rings `r` times
//! faster carries a moving mass `1/r²` times as large and has `r` times the damping ratio
//! ([`LoadCellModel::with_frequency_ratio`]).
//!
//! What it must never do: discretise through transfer-function polynomials (the ZOH is a
//! matrix exponential, [`crate::numerics::expm::zoh`]), or hand out a model with a NaN in it.
//!
//! ## States (continuous time), all in grams of equivalent static load
//! So that every matrix entry is O(1) after discretisation and `f32` keeps its precision:
//! `p` (the deflection, as the load that would hold it statically), `q = ṗ/ω_n`, then the
//! Butterworth's sections in series, each with its output `f` in grams and, for a
//! second-order section, `g = ḟ/ω_c`:
//!
//! ```text
//! ṗ = ω_n q                  q̇ = ω_n (M − p) − 2ζω_n q
//! ḟ = ω_c (in − f)                                         (first-order section, odd order)
//! ḟ = ω_c g                  ġ = ω_c (in − f − 2cos φ_j g)  (second-order sections)
//! y = G · f_last             (raw units; G = counts per gram, the static gain)
//! ```
//!
//! with the Butterworth pole angles `φ_j = π(N + 1 − 2j)/(2N)`, `j = 1..=N/2`, measured from
//! the negative real axis. `S = 2 + N` states.

use crate::estimators::model::{InitialState, ModelConfig, SensorModel};
use crate::numerics::expm;
use crate::numerics::real::Real;
use crate::reading::ConfigError;

/// A load cell with its platform, amplifier low-pass and converter, as the estimators see it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadCellModel {
    /// Undamped natural frequency of the mechanical mode with the load on, Hz.
    pub natural_frequency_hz: f64,
    /// Damping ratio of the mechanical mode with the load on.
    pub damping_ratio: f64,
    /// Order N of the Butterworth low-pass (the model has `2 + N` states).
    pub filter_order: u8,
    /// Cut-off of the Butterworth low-pass, Hz.
    pub filter_cutoff_hz: f64,
    /// Static gain: raw units (ADC counts, tare removed) per gram.
    pub counts_per_gram: f64,
    /// Raw samples per second, Hz.
    pub sample_rate_hz: f64,
}

/// The largest damping ratio accepted: beyond it the mode is not a resonance worth a model.
pub const MAX_DAMPING_RATIO: f64 = 10.0;

impl LoadCellModel {
    /// Why the parameters are not a model with `states` states, if they are not.
    pub fn check(&self, states: usize) -> Result<(), ConfigError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let ok = positive(self.natural_frequency_hz)
            && positive(self.damping_ratio)
            && self.damping_ratio <= MAX_DAMPING_RATIO
            && positive(self.filter_cutoff_hz)
            && positive(self.sample_rate_hz)
            && self.counts_per_gram.is_finite()
            && self.counts_per_gram != 0.0
            && usize::from(self.filter_order) + 2 == states;
        if ok {
            Ok(())
        } else {
            Err(ConfigError::Model)
        }
    }

    /// The same cell carrying a load that makes it ring `ratio` times as fast, by the physical
    /// law (stiffness and damping fixed): frequency × `ratio`, damping ratio × `ratio`.
    pub fn with_frequency_ratio(&self, ratio: f64) -> Self {
        Self {
            natural_frequency_hz: self.natural_frequency_hz * ratio,
            damping_ratio: self.damping_ratio * ratio,
            ..*self
        }
    }

    /// The frequency ratio of a load of `mass_g` relative to `calibration_mass_g` on a platform
    /// whose moving mass is `platform_mass_g`: `√((m_p + M_cal)/(m_p + M))`. NaN when a moving
    /// mass is not positive.
    pub fn frequency_ratio_for_mass(
        calibration_mass_g: f64,
        platform_mass_g: f64,
        mass_g: f64,
    ) -> f64 {
        let (calibrated, loaded) = (
            platform_mass_g + calibration_mass_g,
            platform_mass_g + mass_g,
        );
        if calibrated > 0.0 && loaded > 0.0 {
            libm::sqrt(calibrated / loaded)
        } else {
            f64::NAN
        }
    }

    /// The continuous-time `(A, B)` (input in grams) and the output row.
    fn continuous<const S: usize>(&self) -> ([[f64; S]; S], [[f64; 1]; S], [f64; S]) {
        let omega_n = 2.0 * core::f64::consts::PI * self.natural_frequency_hz;
        let omega_c = 2.0 * core::f64::consts::PI * self.filter_cutoff_hz;
        let order = usize::from(self.filter_order);
        let mut a = [[0.0; S]; S];
        let mut b = [[0.0; 1]; S];
        let mut c = [0.0; S];
        a[0][1] = omega_n;
        a[1][0] = -omega_n;
        a[1][1] = -2.0 * self.damping_ratio * omega_n;
        b[1][0] = omega_n;
        // The state that feeds the next section: the deflection first.
        let mut feed = 0;
        let mut next = 2;
        if order % 2 == 1 {
            a[next][feed] = omega_c;
            a[next][next] = -omega_c;
            feed = next;
            next += 1;
        }
        for j in 1..=order / 2 {
            let angle = core::f64::consts::PI * (order + 1 - 2 * j) as f64 / (2.0 * order as f64);
            let (f, g) = (next, next + 1);
            a[f][g] = omega_c;
            a[g][feed] = omega_c;
            a[g][f] = -omega_c;
            a[g][g] = -2.0 * libm::cos(angle) * omega_c;
            feed = f;
            next += 2;
        }
        c[feed] = self.counts_per_gram;
        (a, b, c)
    }

    /// The exact ZOH discretisation at the sample rate, as a [`SensorModel`] with
    /// `S = 2 + filter_order` states, in `T` (computed in `f64`, rounded once).
    pub fn sensor_model<T: Real, const S: usize>(&self) -> Result<SensorModel<T, S>, ConfigError> {
        self.check(S)?;
        let (a, b, c) = self.continuous::<S>();
        let (phi, gamma) = expm::zoh(&a, &b, 1.0 / self.sample_rate_hz);
        let model = SensorModel {
            a: phi.map(|row| row.map(T::from_f64)),
            b: gamma.map(|row| T::from_f64(row[0])),
            c: c.map(T::from_f64),
        };
        let finite = model.a.iter().flatten().all(|v| v.is_finite())
            && model.b.iter().all(|v| v.is_finite())
            && model.c.iter().all(|v| v.is_finite());
        if finite {
            Ok(model)
        } else {
            Err(ConfigError::Model)
        }
    }

    /// The `K` frequency ratios of a bank over `[ratio_min, ratio_max]`, evenly spaced in
    /// log (equal relative steps), ascending.
    pub fn frequency_ratios<const K: usize>(
        ratio_min: f64,
        ratio_max: f64,
    ) -> Result<[f64; K], ConfigError> {
        Self::frequency_ratio(ratio_min, ratio_max, K, 0)?;
        Ok(core::array::from_fn(|i| {
            Self::frequency_ratio(ratio_min, ratio_max, K, i).unwrap_or(ratio_min)
        }))
    }

    /// The `index`-th of [`Self::frequency_ratios`] for `count` candidates, one at a time
    /// (a bank configured in place, `ModelBank::configure`).
    pub fn frequency_ratio(
        ratio_min: f64,
        ratio_max: f64,
        count: usize,
        index: usize,
    ) -> Result<f64, ConfigError> {
        let valid = ratio_min.is_finite()
            && ratio_max.is_finite()
            && ratio_min > 0.0
            && (ratio_max > ratio_min || (count == 1 && ratio_max == ratio_min));
        if count == 0 || index >= count || !valid {
            return Err(ConfigError::Model);
        }
        Ok(if count == 1 {
            libm::sqrt(ratio_min * ratio_max)
        } else {
            let span = libm::log(ratio_max / ratio_min);
            ratio_min * libm::exp(span * index as f64 / (count - 1) as f64)
        })
    }

    /// The configurations of a [`crate::ModelBank`] of `K` candidates built from this
    /// (calibrated) model by the physical law, over frequency ratios `[ratio_min, ratio_max]`
    /// (see [`Self::frequency_ratios`]; [`Self::frequency_ratio_for_mass`] turns a mass range
    /// into one). Each gets `decimation`, `initial_state` and no range limit; set one with
    /// `configs.map(|c| c.with_valid_range(lo, hi))`.
    pub fn bank_configs<T: Real, const S: usize, const K: usize>(
        &self,
        ratio_min: f64,
        ratio_max: f64,
        decimation: u16,
        initial_state: InitialState,
    ) -> Result<[ModelConfig<T, S>; K], ConfigError> {
        let ratios = Self::frequency_ratios::<K>(ratio_min, ratio_max)?;
        let mut error = None;
        let configs = ratios.map(|ratio| {
            self.bank_config(ratio, decimation, initial_state)
                .unwrap_or_else(|e| {
                    error.get_or_insert(e);
                    // A placeholder that is never returned.
                    ModelConfig::new(SensorModel {
                        a: [[T::ZERO; S]; S],
                        b: [T::ZERO; S],
                        c: [T::ZERO; S],
                    })
                })
        });
        match error {
            Some(e) => Err(e),
            None => Ok(configs),
        }
    }

    /// One candidate of [`Self::bank_configs`]: this model at frequency ratio `ratio`.
    pub fn bank_config<T: Real, const S: usize>(
        &self,
        ratio: f64,
        decimation: u16,
        initial_state: InitialState,
    ) -> Result<ModelConfig<T, S>, ConfigError> {
        Ok(
            ModelConfig::new(self.with_frequency_ratio(ratio).sensor_model::<T, S>()?)
                .with_decimation(decimation)
                .with_initial_state(initial_state),
        )
    }
}

/// The reference cell of the tests (25 Hz, ζ = 0.03, a third-order 100 Hz filter,
/// 73.25 counts/g at 4 kHz): one fixture for the tests of every layer.
#[cfg(test)]
pub(crate) fn reference_cell() -> LoadCellModel {
    LoadCellModel {
        natural_frequency_hz: 25.0,
        damping_ratio: 0.03,
        filter_order: 3,
        filter_cutoff_hz: 100.0,
        counts_per_gram: 73.25,
        sample_rate_hz: 4000.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference() -> LoadCellModel {
        reference_cell()
    }

    fn static_gain<const S: usize>(m: &SensorModel<f64, S>) -> f64 {
        // Run the step response to its end: C·Σ A^j·B.
        let mut x = [0.0; S];
        let mut y = 0.0;
        for _ in 0..200_000 {
            let mut next = [0.0; S];
            for r in 0..S {
                next[r] = m.b[r];
                for c in 0..S {
                    next[r] += m.a[r][c] * x[c];
                }
            }
            x = next;
            y = (0..S).map(|i| m.c[i] * x[i]).sum();
        }
        y
    }

    #[test]
    fn static_gain_is_counts_per_gram_for_every_filter_order() {
        let mut model = reference();
        model.damping_ratio = 0.3;
        model.sample_rate_hz = 400.0;
        for order in 0..=4u8 {
            model.filter_order = order;
            let gain = match order {
                0 => static_gain(&model.sensor_model::<f64, 2>().unwrap()),
                1 => static_gain(&model.sensor_model::<f64, 3>().unwrap()),
                2 => static_gain(&model.sensor_model::<f64, 4>().unwrap()),
                3 => static_gain(&model.sensor_model::<f64, 5>().unwrap()),
                _ => static_gain(&model.sensor_model::<f64, 6>().unwrap()),
            };
            assert!((gain - 73.25).abs() < 1e-9, "order {order}: {gain}");
        }
    }

    #[test]
    fn filter_order_must_match_the_states() {
        assert_eq!(
            reference().sensor_model::<f64, 4>(),
            Err(ConfigError::Model)
        );
        let mut bad = reference();
        bad.damping_ratio = f64::NAN;
        assert_eq!(bad.sensor_model::<f32, 5>(), Err(ConfigError::Model));
        bad = reference();
        bad.counts_per_gram = 0.0;
        assert_eq!(bad.sensor_model::<f32, 5>(), Err(ConfigError::Model));
    }

    #[test]
    fn physical_law_keeps_stiffness_and_damping() {
        // k ∝ ω²·m and c ∝ 2ζω·m with m ∝ 1/ω² (k fixed): c ∝ ζ/ω must not change.
        let model = reference();
        let heavier = model.with_frequency_ratio(0.7);
        let c_ratio = (heavier.damping_ratio / heavier.natural_frequency_hz)
            / (model.damping_ratio / model.natural_frequency_hz);
        assert!((c_ratio - 1.0).abs() < 1e-12);
        let r = LoadCellModel::frequency_ratio_for_mass(138.32, 120.0, 3.0 * 138.32);
        assert!((r - (258.32f64 / 534.96).sqrt()).abs() < 1e-12);
        assert!(LoadCellModel::frequency_ratio_for_mass(1.0, -5.0, 1.0).is_nan());
    }

    #[test]
    fn ratios_are_log_spaced_and_refuse_nonsense() {
        let r = LoadCellModel::frequency_ratios::<5>(0.5, 2.0).unwrap();
        assert!((r[0] - 0.5).abs() < 1e-15 && (r[4] - 2.0).abs() < 1e-12);
        assert!((r[2] - 1.0).abs() < 1e-12);
        assert!(LoadCellModel::frequency_ratios::<5>(2.0, 0.5).is_err());
        assert!(LoadCellModel::frequency_ratios::<5>(f64::NAN, 0.5).is_err());
        assert!(LoadCellModel::frequency_ratios::<0>(0.5, 2.0).is_err());
    }
}
