//! The calibration record: counts per gram and the empty-pan zero, versioned and
//! CRC-protected, as the firmware keeps it in flash (hardware) or a RAM store (QEMU), and
//! the store both boards implement ([`CalibrationStore`]): only what it gives back intact
//! is ever applied ([`store_calibration`]).
//!
//! A record that is missing (erased flash), corrupted, of an unknown version or holding an
//! impossible value is never used: [`load_or_default`] then returns the board's nominal
//! calibration with a flag saying why, so the display can say "uncalibrated" instead of
//! showing a number computed from garbage.
//!
//! Layout (little-endian, 20 bytes):
//! `magic "WCAL" | version u16 | length u16 | counts_per_gram f32 | zero_counts f32 | crc32`
//! where the CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`) covers the first 16 bytes.

use super::scale::CountsScale;

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
    /// The gain is further from the front end's nominal gain than its tolerance
    /// ([`GAIN_TOLERANCE`]): the wrong reference mass, or a fault in the analogue chain.
    Implausible,
}

/// How far a chain's gain may lie from its front end's nominal gain, as a fraction either
/// way. The parts that set it: the cell's rated output (a 1004-class cell: 2 mV/V ± 10 %),
/// the INA114's gain (R_G at 1 %, the amplifier's own ±0.5 %), the ADC's reference (a 3.3 V
/// rail at ±3 %): ±14 % at worst, so ±15 %. A calibration or a stored record outside it is
/// the wrong mass or a broken chain, never a gain to weigh with.
pub const GAIN_TOLERANCE: f32 = 0.15;

/// Where the calibration in use came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationSource {
    /// A valid stored record.
    Stored,
    /// The board's nominal values, because the stored record was unusable.
    Defaults(CalibrationError),
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

    /// A gain within `tolerance` (a fraction, either way) of `nominal`'s.
    pub fn is_plausible(&self, nominal: &Calibration, tolerance: f32) -> bool {
        let ratio = self.counts_per_gram / nominal.counts_per_gram;
        self.is_valid() && (ratio - 1.0).abs() <= tolerance
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
        if bytes.len() < RECORD_LEN || bytes[..RECORD_LEN].iter().all(|&b| b == 0xFF) {
            return Err(CalibrationError::Missing);
        }
        if bytes[0..4] != MAGIC {
            return Err(CalibrationError::BadMagic);
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        if version != RECORD_VERSION {
            return Err(CalibrationError::UnsupportedVersion(version));
        }
        let stored_crc = u32::from_le_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]);
        let length = u16::from_le_bytes([bytes[6], bytes[7]]);
        if length as usize != RECORD_LEN || crc32(&bytes[..16]) != stored_crc {
            return Err(CalibrationError::BadCrc);
        }
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

/// The analogue chain of the hardware board: load cell → INA114 → ADC. Its nominal
/// calibration is the fallback when no valid record is stored.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrontEnd {
    /// Bridge excitation in volts.
    pub excitation_v: f32,
    /// Rated output of the cell at capacity, in mV per volt of excitation.
    pub rated_output_mv_per_v: f32,
    /// Rated capacity of the cell in grams.
    pub capacity_g: f32,
    /// The INA114's gain resistor R_G in ohms (gain = 1 + 50 kΩ / R_G).
    pub gain_resistor_ohm: f32,
    /// Voltage on the INA114's REF pin: the output with a balanced bridge.
    pub reference_pin_v: f32,
    /// ADC reference (full scale) in volts.
    pub adc_reference_v: f32,
    /// ADC resolution in bits.
    pub adc_bits: u8,
}

impl FrontEnd {
    /// The INA114's gain, 1 + 50 kΩ / R_G (data sheet).
    pub fn ina114_gain(&self) -> f32 {
        1.0 + 50_000.0 / self.gain_resistor_ohm
    }

    /// ADC counts per volt at the ADC pin.
    pub fn counts_per_volt(&self) -> f32 {
        (1u32 << self.adc_bits) as f32 / self.adc_reference_v
    }

    /// The nominal gain and zero of the chain.
    pub fn nominal_calibration(&self) -> Calibration {
        let volts_per_gram =
            self.excitation_v * self.rated_output_mv_per_v * 1e-3 / self.capacity_g;
        Calibration {
            counts_per_gram: volts_per_gram * self.ina114_gain() * self.counts_per_volt(),
            zero_counts: self.reference_pin_v * self.counts_per_volt(),
        }
    }

    /// ADC counts at the cell's capacity: must stay below full scale, or a full load
    /// saturates the converter (and reads invalid).
    pub fn counts_at_capacity(&self) -> f32 {
        let nominal = self.nominal_calibration();
        nominal.zero_counts + nominal.counts_per_gram * self.capacity_g
    }
}

/// The stored record if it is good, else `defaults` and the reason (never garbage).
/// `stored` is `None` when the store has nothing at all. `defaults` are the front end's
/// nominal values: a record whose gain is not within [`GAIN_TOLERANCE`] of theirs is not
/// used ([`CalibrationError::Implausible`]; a CRC says the bytes are intact, not that they
/// describe this chain).
pub fn load_or_default(
    stored: Option<&[u8]>,
    defaults: Calibration,
) -> (Calibration, CalibrationSource) {
    match stored.map(Calibration::decode) {
        Some(Ok(calibration)) if !calibration.is_plausible(&defaults, GAIN_TOLERANCE) => (
            defaults,
            CalibrationSource::Defaults(CalibrationError::Implausible),
        ),
        Some(Ok(calibration)) => (calibration, CalibrationSource::Stored),
        Some(Err(error)) => (defaults, CalibrationSource::Defaults(error)),
        None => (
            defaults,
            CalibrationSource::Defaults(CalibrationError::Missing),
        ),
    }
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

/// Where a board keeps its calibration record: flash on hardware, RAM under QEMU.
pub trait CalibrationStore {
    /// Why a write failed.
    type Error;
    /// Replace the stored record.
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error>;
    /// The stored bytes, `None` when the store has no room for a record at all.
    fn read_record(&self) -> Option<[u8; RECORD_LEN]>;
}

/// Why a calibration was not stored. The calibration in use stays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreFailure<E> {
    /// The store refused the write.
    Write(E),
    /// What the store gave back is not a valid record.
    ReadBack(CalibrationError),
    /// The store gave back a valid record, but not the one written.
    Mismatch,
}

/// Write `calibration` as a record, read it back through the CRC decoder, and return what
/// the store really holds; only that may be applied.
pub fn store_calibration<S: CalibrationStore>(
    store: &mut S,
    calibration: &Calibration,
) -> Result<Calibration, StoreFailure<S::Error>> {
    store
        .write_record(&calibration.encode())
        .map_err(StoreFailure::Write)?;
    let stored = store
        .read_record()
        .ok_or(StoreFailure::ReadBack(CalibrationError::Missing))?;
    let read_back = Calibration::decode(&stored).map_err(StoreFailure::ReadBack)?;
    // Bit-exact: the record holds the very f32 values written.
    let same = read_back.counts_per_gram.to_bits() == calibration.counts_per_gram.to_bits()
        && read_back.zero_counts.to_bits() == calibration.zero_counts.to_bits();
    if same {
        Ok(read_back)
    } else {
        Err(StoreFailure::Mismatch)
    }
}

/// The calibration to use at boot: the stored record if valid, else `defaults` and why.
pub fn load_calibration<S: CalibrationStore>(
    store: &S,
    defaults: Calibration,
) -> (Calibration, CalibrationSource) {
    let stored = store.read_record();
    load_or_default(stored.as_ref().map(|record| &record[..]), defaults)
}

/// A RAM store, with switchable faults, for the tests of the store and of the commands.
#[cfg(test)]
pub(crate) mod test_store {
    use super::{Calibration, CalibrationStore, RECORD_LEN};

    /// A RAM store, with switchable faults.
    #[derive(Default)]
    pub(crate) struct RamStore {
        pub(crate) record: Option<[u8; RECORD_LEN]>,
        pub(crate) refuse_writes: bool,
        pub(crate) flip_bit: Option<usize>,
        pub(crate) replace_with: Option<Calibration>,
    }

    impl CalibrationStore for RamStore {
        type Error = &'static str;
        fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error> {
            if self.refuse_writes {
                return Err("write protected");
            }
            let mut stored = *record;
            if let Some(bit) = self.flip_bit {
                stored[bit / 8] ^= 1 << (bit % 8);
            }
            if let Some(other) = self.replace_with {
                stored = other.encode();
            }
            self.record = Some(stored);
            Ok(())
        }
        fn read_record(&self) -> Option<[u8; RECORD_LEN]> {
            self.record
        }
    }
}

#[cfg(test)]
mod tests {
    use super::test_store::RamStore;
    use super::*;

    const GOOD: Calibration = Calibration {
        counts_per_gram: 52.5,
        zero_counts: 31_234.5,
    };
    const DEFAULTS: Calibration = Calibration {
        counts_per_gram: 50.0,
        zero_counts: 32_768.0,
    };

    /// A record with a valid CRC and 1e-6 counts/g (or 30 % off nominal) was used at boot;
    /// it is not: the nominal values are, with the reason.
    #[test]
    fn a_stored_gain_far_from_nominal_is_not_used() {
        let nominal = Calibration {
            counts_per_gram: 73.25,
            zero_counts: 16_764.0,
        };
        for gain in [1e-6, 0.7 * 73.25, 1.2 * 73.25] {
            let record = Calibration {
                counts_per_gram: gain,
                zero_counts: 16_760.0,
            }
            .encode();
            assert_eq!(
                load_or_default(Some(&record), nominal),
                (
                    nominal,
                    CalibrationSource::Defaults(CalibrationError::Implausible)
                ),
                "{gain}"
            );
        }
        let within = Calibration {
            counts_per_gram: 1.1 * 73.25,
            zero_counts: 16_760.0,
        };
        assert_eq!(
            load_or_default(Some(&within.encode()), nominal),
            (within, CalibrationSource::Stored)
        );
    }

    #[test]
    fn crc_matches_the_standard_check_value() {
        // The catalogue check value of CRC-32/ISO-HDLC for "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn a_record_round_trips() {
        assert_eq!(Calibration::decode(&GOOD.encode()), Ok(GOOD));
        assert_eq!(
            load_or_default(Some(&GOOD.encode()), DEFAULTS),
            (GOOD, CalibrationSource::Stored)
        );
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        let record = GOOD.encode();
        for bit in 0..RECORD_LEN * 8 {
            let mut corrupted = record;
            corrupted[bit / 8] ^= 1 << (bit % 8);
            let (calibration, source) = load_or_default(Some(&corrupted), DEFAULTS);
            assert_eq!(calibration, DEFAULTS, "bit {bit}");
            assert!(
                matches!(source, CalibrationSource::Defaults(_)),
                "bit {bit}"
            );
        }
    }

    #[test]
    fn missing_and_foreign_records_give_defaults_with_the_reason() {
        assert_eq!(
            load_or_default(None, DEFAULTS).1,
            CalibrationSource::Defaults(CalibrationError::Missing)
        );
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
    fn front_end_gain_and_counts_follow_the_data_sheet_formulas() {
        let front_end = FrontEnd {
            excitation_v: 3.3,
            rated_output_mv_per_v: 2.0,
            capacity_g: 600.0,
            gain_resistor_ohm: 130.0,
            reference_pin_v: 0.5,
            adc_reference_v: 3.3,
            adc_bits: 12,
        };
        let gain = front_end.ina114_gain();
        assert!((gain - 385.615).abs() < 1e-2, "{gain}");
        let nominal = front_end.nominal_calibration();
        // 6.6 mV at 600 g → 11 µV/g → ×385.6 → 4.242 mV/g → ×(4096/3.3) counts/V.
        let expected = 11e-6 * 385.615 * 4096.0 / 3.3;
        assert!((nominal.counts_per_gram as f64 - expected).abs() < 1e-3 * expected);
        assert!((nominal.zero_counts - 620.6).abs() < 0.1);
        assert!(front_end.counts_at_capacity() < 4095.0);
        assert!(nominal.is_valid());
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

    #[test]
    fn only_what_the_store_gives_back_intact_is_returned() {
        let measured = Calibration {
            counts_per_gram: 51.234,
            zero_counts: 30_012.5,
        };
        let mut refusing = RamStore {
            refuse_writes: true,
            ..RamStore::default()
        };
        assert_eq!(
            store_calibration(&mut refusing, &measured),
            Err(StoreFailure::Write("write protected"))
        );
        for bit in [0, 77, 159] {
            let mut corrupting = RamStore {
                flip_bit: Some(bit),
                ..RamStore::default()
            };
            assert!(
                matches!(
                    store_calibration(&mut corrupting, &measured),
                    Err(StoreFailure::ReadBack(_))
                ),
                "bit {bit}"
            );
        }
        let mut foreign = RamStore {
            replace_with: Some(Calibration {
                counts_per_gram: 50.0,
                zero_counts: 30_000.0,
            }),
            ..RamStore::default()
        };
        assert_eq!(
            store_calibration(&mut foreign, &measured),
            Err(StoreFailure::Mismatch)
        );
        let defaults = Calibration {
            counts_per_gram: 50.0,
            zero_counts: 32_768.0,
        };
        assert_eq!(
            load_calibration(&RamStore::default(), defaults),
            (
                defaults,
                CalibrationSource::Defaults(CalibrationError::Missing)
            )
        );
    }
}
