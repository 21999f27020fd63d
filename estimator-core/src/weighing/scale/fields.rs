//! The weighing configuration by field name: what a console's `config show` lists and
//! `config set <key> <value>` changes, with the same checks as [`ScaleConfig::validate`].
//!
//! Every field is here, each as one number: whole-sample counts must be whole and fit a
//! `u32`, the consistency check is 0 or 1. A new value is checked with the whole
//! configuration before anything changes, so a refused `set` leaves the scale as it was.

use super::ScaleConfig;
use crate::reading::ConfigError;

/// How a field holds its number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Any `f32` (the configuration's checks decide).
    Real,
    /// A whole number of samples.
    Samples,
    /// 0 (off) or 1 (on).
    Switch,
}

/// One field of [`ScaleConfig`], named as the console and `weighing.toml` name it.
#[derive(Clone, Copy)]
pub struct ConfigField {
    /// The key.
    pub name: &'static str,
    kind: Kind,
    get: fn(&ScaleConfig) -> f32,
    set: fn(&mut ScaleConfig, f32),
}

impl core::fmt::Debug for ConfigField {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name)
    }
}

impl ConfigField {
    /// The field's value in `config`.
    pub fn get(&self, config: &ScaleConfig) -> f32 {
        (self.get)(config)
    }

    /// `config` with this field set to `value`, or why not (a sample count that is not a
    /// whole number in range, a switch that is not 0 or 1, or the configuration's own
    /// checks: [`ScaleConfig::validate`]).
    pub fn set(&self, config: &ScaleConfig, value: f32) -> Result<ScaleConfig, ConfigError> {
        let refused = Err(ConfigError::ScaleField(self.name));
        let representable = match self.kind {
            Kind::Real => true,
            // u32::MAX as f32 rounds up to 2^32, which does not fit: strictly below it.
            Kind::Samples => {
                (0.0..4_294_967_296.0).contains(&value) && value == (value as u32) as f32
            }
            Kind::Switch => value == 0.0 || value == 1.0,
        };
        if !representable {
            return refused;
        }
        let mut changed = *config;
        (self.set)(&mut changed, value);
        changed.validate()?;
        Ok(changed)
    }

    /// Whether the value is a whole number (a sample count or a switch): printed without
    /// decimals.
    pub fn is_whole(&self) -> bool {
        self.kind != Kind::Real
    }
}

macro_rules! real {
    ($name:ident) => {
        ConfigField {
            name: stringify!($name),
            kind: Kind::Real,
            get: |c| c.$name,
            set: |c, v| c.$name = v,
        }
    };
}

macro_rules! samples {
    ($name:ident) => {
        ConfigField {
            name: stringify!($name),
            kind: Kind::Samples,
            get: |c| c.$name as f32,
            set: |c, v| c.$name = v as u32,
        }
    };
}

impl ScaleConfig {
    /// Every field by name, in the order `config show` lists them: the instrument (Max, e,
    /// targets), stability and the empty pan, zero tracking, then the change tests.
    pub const FIELDS: [ConfigField; 29] = [
        real!(capacity_g),
        real!(scale_interval_g),
        real!(final_target_g),
        real!(accuracy_target_relative),
        real!(accuracy_target_mass_g),
        real!(sample_rate_hz),
        real!(empty_band_g),
        real!(stable_band_g),
        real!(stable_band_relative),
        samples!(stable_hold_samples),
        real!(zero_tracking_band_g),
        real!(zero_tracking_rate_g_per_s),
        real!(zero_tracking_range_g),
        real!(zero_drift_g_per_s),
        ConfigField {
            name: "consistency_check",
            kind: Kind::Switch,
            get: |c| f32::from(u8::from(c.consistency_check)),
            set: |c, v| c.consistency_check = v == 1.0,
        },
        samples!(noise_window_samples),
        samples!(noise_guard_samples),
        real!(residual_drift_g),
        real!(residual_threshold_g),
        samples!(residual_arm_samples),
        real!(raw_drift_g),
        real!(raw_threshold_g),
        samples!(raw_arm_samples),
        samples!(restless_fit_samples),
        samples!(block_samples),
        real!(block_drift_g),
        real!(block_threshold_g),
        real!(ringing_min_hz),
        samples!(flag_restart_samples),
    ];

    /// The field named `name` (ASCII case ignored), if there is one.
    pub fn field(name: &str) -> Option<ConfigField> {
        Self::FIELDS
            .iter()
            .find(|field| field.name.eq_ignore_ascii_case(name))
            .copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> ScaleConfig {
        ScaleConfig::weighing_default(4000.0)
    }

    #[test]
    fn every_field_reads_back_what_was_set() {
        let good = config();
        for field in ScaleConfig::FIELDS {
            let value = field.get(&good);
            let same = field.set(&good, value).unwrap();
            assert_eq!(same, good, "{}", field.name);
        }
        let set = ScaleConfig::field("Capacity_G")
            .unwrap()
            .set(&good, 3000.0)
            .unwrap();
        assert_eq!(set.capacity_g, 3000.0);
        assert!(
            !ScaleConfig::field("consistency_check")
                .unwrap()
                .set(&good, 0.0)
                .unwrap()
                .consistency_check
        );
        assert!(ScaleConfig::field("no_such_key").is_none());
    }

    #[test]
    fn a_value_outside_a_field_is_refused_by_name() {
        let good = config();
        let refused = |name: &'static str, value: f32| {
            assert_eq!(
                ScaleConfig::field(name).unwrap().set(&good, value),
                Err(ConfigError::ScaleField(name)),
                "{name} = {value}"
            );
        };
        refused("capacity_g", -1.0);
        refused("capacity_g", f32::NAN);
        refused("block_samples", 0.0);
        refused("block_samples", 2.5);
        refused("block_samples", -1.0);
        refused("block_samples", 5e9);
        refused("consistency_check", 0.5);
        refused("zero_tracking_rate_g_per_s", f32::INFINITY);
    }

    #[test]
    fn the_fields_are_listed_once_each() {
        for (i, a) in ScaleConfig::FIELDS.iter().enumerate() {
            for b in &ScaleConfig::FIELDS[i + 1..] {
                assert_ne!(a.name, b.name);
            }
        }
    }
}
