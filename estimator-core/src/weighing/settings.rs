//! The operator's settings kept across a reset: the weighing decisions' configuration as
//! changed with the console's `config set`, the console's rate and unit, and the weighing
//! method (the console's `method`, which an upload from `host-sim calibrate` types). One record,
//! versioned and CRC-checked like the calibration record, stored beside it
//! ([`SettingsStore`]; the flash store keeps both under their own keys).
//!
//! Layout (little-endian): magic `WSET`, version (u16), length (u16), every
//! [`ScaleConfig::FIELDS`] value as an `f32` in that order, the console's rate (u16) and
//! unit (u8), one zero byte, the method (family u8: 0 step, 1 bias-compensated, 2
//! instrumental variables, 3 model bank; order u8; D u16; λ f64; candidates u16; two zero
//! bytes; lowest and highest ratio f64: exact, as typed), and a CRC-32 of everything before
//! it. A record of an earlier version (1: no method; 2: no `ringing_min_hz`; 3: no
//! `restless_fit_samples`) is refused as an unsupported version. A record that fails any
//! check is refused with its reason and nothing of it is used: the board then runs on the
//! compiled-in configuration and says so.

use super::calibration::{check_frame, crc32, CalibrationError};
use super::console::Unit;
use super::method::WeighingMethod;
use super::scale::ScaleConfig;
use crate::estimators::model::{Interpolation, WHITENING_ORDER};

/// Bytes of a settings record.
pub const SETTINGS_LEN: usize = 8 + 4 * ScaleConfig::FIELDS.len() + 4 + METHOD_LEN + 4;
/// The layout this firmware writes and reads.
pub const SETTINGS_VERSION: u16 = 4;
/// Bytes of the method in a settings record.
const METHOD_LEN: usize = 32;
const MAGIC: [u8; 4] = *b"WSET";

/// What a board keeps of the operator's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// The weighing decisions' configuration.
    pub config: ScaleConfig,
    /// The console's reading lines per second.
    pub console_rate_hz: u16,
    /// The console's unit.
    pub unit: Unit,
    /// The weighing method (checked against the board's model and estimator when applied).
    pub method: WeighingMethod,
}

impl Settings {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; SETTINGS_LEN] {
        let mut bytes = [0u8; SETTINGS_LEN];
        bytes[0..4].copy_from_slice(&MAGIC);
        bytes[4..6].copy_from_slice(&SETTINGS_VERSION.to_le_bytes());
        bytes[6..8].copy_from_slice(&(SETTINGS_LEN as u16).to_le_bytes());
        for (slot, field) in bytes[8..].chunks_exact_mut(4).zip(ScaleConfig::FIELDS) {
            slot.copy_from_slice(&field.get(&self.config).to_le_bytes());
        }
        let tail = 8 + 4 * ScaleConfig::FIELDS.len();
        bytes[tail..tail + 2].copy_from_slice(&self.console_rate_hz.to_le_bytes());
        bytes[tail + 2] = unit_code(self.unit);
        encode_method(&self.method, &mut bytes[tail + 4..tail + 4 + METHOD_LEN]);
        let crc = crc32(&bytes[..SETTINGS_LEN - 4]);
        bytes[SETTINGS_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    /// The settings in `bytes`, each field set on `base` and checked as `config set` checks
    /// it, or why the record is refused: `Missing` (erased or short), `BadMagic`,
    /// `UnsupportedVersion`, `BadCrc` (or a wrong length), `OutOfDomain` (a field, the rate
    /// or the unit outside its domain, a method family unknown or a number of the method
    /// out of its domain: a spec [`WeighingMethod::parse_spec`] would refuse).
    pub fn decode(bytes: &[u8], base: &ScaleConfig) -> Result<Self, CalibrationError> {
        check_frame(bytes, MAGIC, SETTINGS_VERSION, SETTINGS_LEN)?;
        let mut config = *base;
        for (slot, field) in bytes[8..].chunks_exact(4).zip(ScaleConfig::FIELDS) {
            let value = f32::from_le_bytes([slot[0], slot[1], slot[2], slot[3]]);
            config = field
                .set(&config, value)
                .map_err(|_| CalibrationError::OutOfDomain)?;
        }
        let tail = 8 + 4 * ScaleConfig::FIELDS.len();
        let console_rate_hz = u16::from_le_bytes([bytes[tail], bytes[tail + 1]]);
        let unit = unit_from_code(bytes[tail + 2]).ok_or(CalibrationError::OutOfDomain)?;
        if !(1..=1000).contains(&console_rate_hz) {
            return Err(CalibrationError::OutOfDomain);
        }
        let method = decode_method(&bytes[tail + 4..tail + 4 + METHOD_LEN])
            .ok_or(CalibrationError::OutOfDomain)?;
        Ok(Self {
            config,
            console_rate_hz,
            unit,
            method,
        })
    }
}

fn encode_method(method: &WeighingMethod, bytes: &mut [u8]) {
    let (family, order, forgetting, candidates, span) = match *method {
        WeighingMethod::Step {
            order, forgetting, ..
        } => (0, order, forgetting, 0, (0.0, 0.0)),
        WeighingMethod::BiasCompensated { order, .. } => (1, order, 1.0, 0, (0.0, 0.0)),
        WeighingMethod::InstrumentalVariable { order, .. } => (2, order, 1.0, 0, (0.0, 0.0)),
        WeighingMethod::ModelBank {
            candidates,
            ratio_min,
            ratio_max,
            interpolation,
            whitening,
            ..
        } => {
            // Bytes 14 and 15, zero in a record written before the bank had them: the
            // three-point combination, not whitened (what those records meant).
            bytes[14] = u8::from(interpolation == Interpolation::FivePoint);
            bytes[15] = u8::try_from(whitening).unwrap_or(u8::MAX);
            (3, 0, 1.0, candidates, (ratio_min, ratio_max))
        }
    };
    bytes[0] = family;
    bytes[1] = u8::try_from(order).unwrap_or(u8::MAX);
    bytes[2..4].copy_from_slice(&method.decimation().to_le_bytes());
    bytes[4..12].copy_from_slice(&forgetting.to_le_bytes());
    let candidates = u16::try_from(candidates).unwrap_or(u16::MAX);
    bytes[12..14].copy_from_slice(&candidates.to_le_bytes());
    bytes[16..24].copy_from_slice(&span.0.to_le_bytes());
    bytes[24..32].copy_from_slice(&span.1.to_le_bytes());
}

/// The method in `bytes`, if it is well formed (what its spec would need).
fn decode_method(bytes: &[u8]) -> Option<WeighingMethod> {
    let f64_at = |at: usize| {
        let mut word = [0u8; 8];
        word.copy_from_slice(&bytes[at..at + 8]);
        f64::from_le_bytes(word)
    };
    let order = usize::from(bytes[1]);
    let decimation = u16::from_le_bytes([bytes[2], bytes[3]]);
    let forgetting = f64_at(4);
    let candidates = usize::from(u16::from_le_bytes([bytes[12], bytes[13]]));
    let (ratio_min, ratio_max) = (f64_at(16), f64_at(24));
    let interpolation = match bytes[14] {
        0 => Interpolation::ThreePoint,
        1 => Interpolation::FivePoint,
        _ => return None,
    };
    let whitening = usize::from(bytes[15]);
    let data_driven = order >= 1 && decimation >= 1;
    let method = match bytes[0] {
        0 if data_driven && forgetting > 0.0 && forgetting <= 1.0 => WeighingMethod::Step {
            order,
            decimation,
            forgetting,
        },
        1 if data_driven => WeighingMethod::BiasCompensated { order, decimation },
        2 if data_driven => WeighingMethod::InstrumentalVariable { order, decimation },
        3 if decimation >= 1
            && candidates >= 1
            && ratio_min > 0.0
            && ratio_min < ratio_max
            && ratio_max.is_finite()
            && whitening <= WHITENING_ORDER =>
        {
            WeighingMethod::ModelBank {
                decimation,
                candidates,
                ratio_min,
                ratio_max,
                interpolation,
                whitening,
            }
        }
        _ => return None,
    };
    Some(method)
}

fn unit_code(unit: Unit) -> u8 {
    match unit {
        Unit::G => 0,
        Unit::Kg => 1,
        Unit::Lb => 2,
        Unit::Oz => 3,
    }
}

fn unit_from_code(code: u8) -> Option<Unit> {
    Unit::ALL.into_iter().find(|&unit| unit_code(unit) == code)
}

/// Where a board keeps its settings record (beside the calibration record). As for the
/// calibration, a write must leave the previous record readable until the new one is
/// complete.
pub trait SettingsStore {
    /// Why a read or a write failed.
    type Error;
    /// Store `record` as the newest.
    fn write_settings(&mut self, record: &[u8; SETTINGS_LEN]) -> Result<(), Self::Error>;
    /// The newest complete record; `Ok(None)` when the store holds none.
    fn read_settings(&mut self) -> Result<Option<[u8; SETTINGS_LEN]>, Self::Error>;
}

/// The settings a board boots with: the stored record if it is intact and in range, else
/// `None` and why (`Missing` when none was ever stored; a store that cannot be read counts
/// as `Unreadable`).
pub fn load_settings<S: SettingsStore>(
    store: &mut S,
    base: &ScaleConfig,
) -> Result<Settings, CalibrationError> {
    match store.read_settings() {
        Ok(Some(bytes)) => Settings::decode(&bytes, base),
        Ok(None) => Err(CalibrationError::Missing),
        Err(_) => Err(CalibrationError::Unreadable),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weighing::BankCandidate;

    fn settings() -> Settings {
        let base = ScaleConfig::weighing_default(4000.0);
        Settings {
            config: ScaleConfig {
                capacity_g: 620.0,
                block_samples: 300,
                consistency_check: false,
                ..base
            },
            console_rate_hz: 50,
            unit: Unit::Kg,
            method: WeighingMethod::Step {
                order: 7,
                decimation: 16,
                forgetting: 0.999,
            },
        }
    }

    /// Every family of method reads back exactly as written.
    #[test]
    fn every_method_reads_back() {
        let base = ScaleConfig::weighing_default(4000.0);
        for method in [
            WeighingMethod::Step {
                order: 5,
                decimation: 24,
                forgetting: 1.0,
            },
            WeighingMethod::BiasCompensated {
                order: 6,
                decimation: 20,
            },
            WeighingMethod::InstrumentalVariable {
                order: 4,
                decimation: 32,
            },
            BankCandidate::REFERENCE.method(),
            BankCandidate::CALIBRATED_U.method(),
        ] {
            let written = Settings {
                method,
                ..settings()
            };
            assert_eq!(
                Settings::decode(&written.encode(), &base).map(|s| s.method),
                Ok(method)
            );
        }
    }

    #[test]
    fn a_record_reads_back_as_written() {
        let base = ScaleConfig::weighing_default(4000.0);
        let written = settings();
        assert_eq!(Settings::decode(&written.encode(), &base), Ok(written));
    }

    #[test]
    fn every_damaged_byte_is_refused() {
        let base = ScaleConfig::weighing_default(4000.0);
        let good = settings().encode();
        for index in 0..SETTINGS_LEN {
            let mut bytes = good;
            bytes[index] ^= 0x10;
            assert!(Settings::decode(&bytes, &base).is_err(), "byte {index}");
        }
        assert_eq!(
            Settings::decode(&[0xFF; SETTINGS_LEN], &base),
            Err(CalibrationError::Missing)
        );
        assert_eq!(
            Settings::decode(&good[..SETTINGS_LEN - 1], &base),
            Err(CalibrationError::Missing)
        );
    }

    #[test]
    fn a_well_formed_record_out_of_range_is_refused() {
        let base = ScaleConfig::weighing_default(4000.0);
        // A negative capacity, written with a valid CRC.
        let mut bad = settings();
        bad.config.capacity_g = -1.0;
        assert_eq!(
            Settings::decode(&bad.encode(), &base),
            Err(CalibrationError::OutOfDomain)
        );
        let mut bad = settings();
        bad.console_rate_hz = 0;
        assert_eq!(
            Settings::decode(&bad.encode(), &base),
            Err(CalibrationError::OutOfDomain)
        );
        for method in [
            WeighingMethod::Step {
                order: 5,
                decimation: 24,
                forgetting: 1.5,
            },
            WeighingMethod::InstrumentalVariable {
                order: 0,
                decimation: 24,
            },
            WeighingMethod::ModelBank {
                decimation: 8,
                candidates: 33,
                ratio_min: 1.3,
                ratio_max: 0.68,
                interpolation: Interpolation::ThreePoint,
                whitening: 0,
            },
            BankCandidate {
                whitening: WHITENING_ORDER + 1,
                ..BankCandidate::CALIBRATED_U
            }
            .method(),
        ] {
            let bad = Settings {
                method,
                ..settings()
            };
            assert_eq!(
                Settings::decode(&bad.encode(), &base),
                Err(CalibrationError::OutOfDomain),
                "{method}"
            );
        }
    }
}
