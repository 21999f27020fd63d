//! The calibration record: counts per gram and the empty-pan zero, versioned and
//! CRC-protected, and every way its bytes can be wrong as a typed [`CalibrationError`].
//!
//! Layout (little-endian, 20 bytes):
//! `magic "WCAL" | version u16 | length u16 | counts_per_gram f32 | zero_counts f32 | crc32`
//! where the CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`) covers the first 16 bytes.
//! [`Calibration::decode`] checks the form (and that the values are numbers a scale can
//! use); whether they are plausible for the board is [`super::CalibrationLimits`]'s call.

use crate::weighing::scale::CountsScale;

/// Bytes of an encoded record.
pub const RECORD_LEN: usize = 20;
/// The record format this code writes and reads.
pub const RECORD_VERSION: u16 = 1;
const MAGIC: [u8; 4] = *b"WCAL";

/// Why a stored record was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationError {
    /// No record: erased flash, or too few bytes.
    Missing,
    /// The bytes are not a calibration record.
    BadMagic,
    /// A record of a version this firmware does not read.
    UnsupportedVersion(u16),
    /// The CRC does not match: the record is corrupted.
    BadCrc,
    /// The values are impossible (non-finite, zero or negative gain).
    OutOfDomain,
    /// A calibration run gave no usable gain (known mass ≤ 0, or no change in counts).
    NoSpan,
    /// The gain is this many per cent (rounded) off the front end's nominal gain, beyond
    /// the tolerance: the wrong reference mass, or a fault in the analogue chain.
    GainOffNominal {
        /// (gain / nominal − 1) × 100, rounded.
        percent: i16,
    },
    /// The empty-pan zero is this many ADC counts off the nominal zero, beyond the
    /// tolerance: a loaded pan, or a fault in the analogue chain.
    ZeroOffNominal {
        /// zero − nominal zero, in counts.
        counts: i32,
    },
    /// The empty-pan zero is on or outside the converter's rails.
    ZeroOutsideConverter,
    /// The store could not be read at all (a flash error, or a state it could not repair).
    Unreadable,
}

/// Counts per gram and zero of one scale.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibration {
    /// ADC counts per gram (gain of the whole chain).
    pub counts_per_gram: f32,
    /// ADC counts with the pan empty.
    pub zero_counts: f32,
}

impl Calibration {
    /// Calibrate from the mean counts of the empty pan and of the pan with a known mass.
    pub fn from_known_mass(
        empty_counts: f32,
        loaded_counts: f32,
        known_mass_g: f32,
    ) -> Result<Self, CalibrationError> {
        if !(known_mass_g > 0.0) || !empty_counts.is_finite() || !loaded_counts.is_finite() {
            return Err(CalibrationError::NoSpan);
        }
        let counts_per_gram = (loaded_counts - empty_counts) / known_mass_g;
        let calibration = Self {
            counts_per_gram,
            zero_counts: empty_counts,
        };
        if calibration.is_valid() {
            Ok(calibration)
        } else {
            Err(CalibrationError::NoSpan)
        }
    }

    /// Finite, positive gain and finite zero.
    pub fn is_valid(&self) -> bool {
        self.counts_per_gram.is_finite()
            && self.counts_per_gram > 0.0
            && self.zero_counts.is_finite()
    }

    /// The record bytes for storage.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut bytes = [0u8; RECORD_LEN];
        bytes[0..4].copy_from_slice(&MAGIC);
        bytes[4..6].copy_from_slice(&RECORD_VERSION.to_le_bytes());
        bytes[6..8].copy_from_slice(&(RECORD_LEN as u16).to_le_bytes());
        bytes[8..12].copy_from_slice(&self.counts_per_gram.to_le_bytes());
        bytes[12..16].copy_from_slice(&self.zero_counts.to_le_bytes());
        let crc = crc32(&bytes[..16]);
        bytes[16..20].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    /// Read a stored record; every way it can be wrong is a typed error.
    pub fn decode(bytes: &[u8]) -> Result<Self, CalibrationError> {
        check_frame(bytes, MAGIC, RECORD_VERSION, RECORD_LEN)?;
        let calibration = Self {
            counts_per_gram: f32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]),
            zero_counts: f32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]),
        };
        if calibration.is_valid() {
            Ok(calibration)
        } else {
            Err(CalibrationError::OutOfDomain)
        }
    }

    /// As the scale uses it.
    pub fn counts_scale(&self) -> CountsScale {
        CountsScale {
            counts_per_gram: self.counts_per_gram,
            zero_counts: self.zero_counts,
        }
    }
}

/// The checks every stored record passes before its fields are read: present (not erased,
/// not short), its magic, its version, its length and the CRC-32 in its last four bytes.
pub(crate) fn check_frame(
    bytes: &[u8],
    magic: [u8; 4],
    version: u16,
    len: usize,
) -> Result<(), CalibrationError> {
    if bytes.len() < len || bytes[..len].iter().all(|&b| b == 0xFF) {
        return Err(CalibrationError::Missing);
    }
    if bytes[0..4] != magic {
        return Err(CalibrationError::BadMagic);
    }
    let stored_version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if stored_version != version {
        return Err(CalibrationError::UnsupportedVersion(stored_version));
    }
    let length = u16::from_le_bytes([bytes[6], bytes[7]]);
    let crc = [
        bytes[len - 4],
        bytes[len - 3],
        bytes[len - 2],
        bytes[len - 1],
    ];
    if length as usize != len || crc32(&bytes[..len - 4]) != u32::from_le_bytes(crc) {
        return Err(CalibrationError::BadCrc);
    }
    Ok(())
}

/// CRC-32/ISO-HDLC, bitwise: 20 bytes at boot do not justify a 1 KiB table in flash.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in bytes {
        crc ^= byte as u32;
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: Calibration = Calibration {
        counts_per_gram: 52.5,
        zero_counts: 31_234.5,
    };

    #[test]
    fn crc_matches_the_standard_check_value() {
        // The catalogue check value of CRC-32/ISO-HDLC for "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn a_record_round_trips_and_every_single_bit_flip_is_caught() {
        let record = GOOD.encode();
        assert_eq!(Calibration::decode(&record), Ok(GOOD));
        for bit in 0..RECORD_LEN * 8 {
            let mut corrupted = record;
            corrupted[bit / 8] ^= 1 << (bit % 8);
            assert!(Calibration::decode(&corrupted).is_err(), "bit {bit}");
        }
    }

    #[test]
    fn missing_and_foreign_records_are_typed_errors() {
        assert_eq!(
            Calibration::decode(&[0xFF; RECORD_LEN]),
            Err(CalibrationError::Missing)
        );
        assert_eq!(
            Calibration::decode(&[0u8; 8]),
            Err(CalibrationError::Missing)
        );
        assert_eq!(
            Calibration::decode(&[0u8; RECORD_LEN]),
            Err(CalibrationError::BadMagic)
        );
        let mut future = GOOD.encode();
        future[4] = 2;
        let crc = crc32(&future[..16]);
        future[16..20].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            Calibration::decode(&future),
            Err(CalibrationError::UnsupportedVersion(2))
        );
    }

    #[test]
    fn a_well_formed_record_with_impossible_values_is_refused() {
        for counts_per_gram in [0.0, -3.0, f32::NAN, f32::INFINITY] {
            let bad = Calibration {
                counts_per_gram,
                zero_counts: 100.0,
            };
            assert_eq!(
                Calibration::decode(&bad.encode()),
                Err(CalibrationError::OutOfDomain)
            );
        }
    }

    #[test]
    fn calibration_from_a_known_mass() {
        let calibration = Calibration::from_known_mass(30_000.0, 40_000.0, 200.0).unwrap();
        assert_eq!(calibration.counts_per_gram, 50.0);
        assert_eq!(calibration.zero_counts, 30_000.0);
        assert_eq!(
            Calibration::from_known_mass(30_000.0, 30_000.0, 200.0),
            Err(CalibrationError::NoSpan)
        );
        assert_eq!(
            Calibration::from_known_mass(30_000.0, 40_000.0, 0.0),
            Err(CalibrationError::NoSpan)
        );
        assert_eq!(
            Calibration::from_known_mass(f32::NAN, 40_000.0, 200.0),
            Err(CalibrationError::NoSpan)
        );
    }
}
