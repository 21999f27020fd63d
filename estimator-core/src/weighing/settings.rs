//! The operator's settings kept across a reset: the weighing decisions' configuration as
//! changed with the console's `config set`, and the console's rate and unit. One record,
//! versioned and CRC-checked like the calibration record, stored beside it
//! ([`SettingsStore`]; the flash store keeps both under their own keys).
//!
//! Layout (little-endian): magic `WSET`, version (u16), length (u16), every
//! [`ScaleConfig::FIELDS`] value as an `f32` in that order, the console's rate (u16) and
//! unit (u8), one zero byte, and a CRC-32 of everything before it. A record that fails any
//! check is refused with its reason and nothing of it is used: the board then runs on the
//! compiled-in configuration and says so.

use super::calibration::{check_frame, crc32, CalibrationError};
use super::console::Unit;
use super::scale::ScaleConfig;

/// Bytes of a settings record.
pub const SETTINGS_LEN: usize = 8 + 4 * ScaleConfig::FIELDS.len() + 4 + 4;
/// The layout this firmware writes and reads.
pub const SETTINGS_VERSION: u16 = 1;
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
        let crc = crc32(&bytes[..SETTINGS_LEN - 4]);
        bytes[SETTINGS_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    /// The settings in `bytes`, each field set on `base` and checked as `config set` checks
    /// it, or why the record is refused: `Missing` (erased or short), `BadMagic`,
    /// `UnsupportedVersion`, `BadCrc` (or a wrong length), `OutOfDomain` (a field, the rate
    /// or the unit outside its domain).
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
        Ok(Self {
            config,
            console_rate_hz,
            unit,
        })
    }
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
    }
}
