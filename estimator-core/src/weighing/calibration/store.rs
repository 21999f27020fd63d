//! Where a board keeps its calibration record ([`CalibrationStore`]), and the two ways in
//! and out of it: [`load_calibration`] at boot (the stored record if it is intact and
//! plausible, else the nominal values and why) and [`store_calibration`] after a
//! calibration (write, read back through the CRC decoder, and return only what the store
//! really holds).

use super::limits::CalibrationLimits;
use super::record::{Calibration, CalibrationError, RECORD_LEN};

/// Where the calibration in use came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationSource {
    /// A valid, plausible record from the store (or the operator's calibration since boot).
    Stored,
    /// The board's nominal values, because the stored record was unusable.
    Defaults(CalibrationError),
}

impl CalibrationSource {
    /// The word the readout line carries: `stored`, or `nominal` for the fallback values.
    pub fn label(&self) -> &'static str {
        match self {
            Self::Stored => "stored",
            Self::Defaults(_) => "nominal",
        }
    }
}

/// Where a board keeps its calibration record. A write must leave the previous record
/// readable until the new one is complete, so a power cut in the middle of it loses at
/// most the new record (the flash store, `FlashStore`, is built that way).
pub trait CalibrationStore {
    /// Why a read or a write failed.
    type Error;
    /// Store `record` as the newest.
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error>;
    /// The newest complete record; `Ok(None)` when the store holds none.
    fn read_record(&mut self) -> Result<Option<[u8; RECORD_LEN]>, Self::Error>;
}

/// Why a calibration was not stored. The calibration in use stays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreFailure<E> {
    /// The store refused the write.
    Write(E),
    /// The store could not be read back.
    Read(E),
    /// What the store gave back is not a valid record.
    ReadBack(CalibrationError),
    /// The store gave back a valid record, but not the one written.
    Mismatch,
}

/// The stored record if it is intact and within `limits`, else the nominal values
/// (`limits.nominal`) and the reason (never garbage, never an absurd gain or zero).
/// `stored` is `None` when the store has no record.
pub fn load_or_default(
    stored: Option<&[u8]>,
    limits: &CalibrationLimits,
) -> (Calibration, CalibrationSource) {
    let checked = match stored {
        Some(bytes) => Calibration::decode(bytes).and_then(|record| limits.check(&record)),
        None => Err(CalibrationError::Missing),
    };
    match checked {
        Ok(calibration) => (calibration, CalibrationSource::Stored),
        Err(error) => (limits.nominal, CalibrationSource::Defaults(error)),
    }
}

/// The calibration to use at boot: the stored record if intact and within `limits`, else
/// the nominal values and why (a store that cannot be read: `Unreadable`).
pub fn load_calibration<S: CalibrationStore>(
    store: &mut S,
    limits: &CalibrationLimits,
) -> (Calibration, CalibrationSource) {
    match store.read_record() {
        Ok(stored) => load_or_default(stored.as_ref().map(|record| &record[..]), limits),
        Err(_) => (
            limits.nominal,
            CalibrationSource::Defaults(CalibrationError::Unreadable),
        ),
    }
}

/// Write `calibration` as a record, read it back through the CRC decoder, and return what
/// the store really holds; only that may be applied. The caller has checked it against the
/// board's limits (`Commands::poll` does).
pub fn store_calibration<S: CalibrationStore>(
    store: &mut S,
    calibration: &Calibration,
) -> Result<Calibration, StoreFailure<S::Error>> {
    store
        .write_record(&calibration.encode())
        .map_err(StoreFailure::Write)?;
    let stored = store
        .read_record()
        .map_err(StoreFailure::Read)?
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

/// A RAM store, with switchable faults, for the tests of the store and of the commands.
#[cfg(test)]
pub(crate) mod test_store {
    use super::{Calibration, CalibrationStore, RECORD_LEN};

    /// A RAM store, with switchable faults.
    #[derive(Default)]
    pub(crate) struct RamStore {
        pub(crate) record: Option<[u8; RECORD_LEN]>,
        pub(crate) refuse_writes: bool,
        pub(crate) refuse_reads: bool,
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
        fn read_record(&mut self) -> Result<Option<[u8; RECORD_LEN]>, Self::Error> {
            if self.refuse_reads {
                return Err("read error");
            }
            Ok(self.record)
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
    const LIMITS: CalibrationLimits = CalibrationLimits {
        nominal: Calibration {
            counts_per_gram: 50.0,
            zero_counts: 32_768.0,
        },
        gain_tolerance: 0.15,
        zero_tolerance_counts: 12_000.0,
        max_code: 65_535,
    };

    #[test]
    fn a_record_round_trips() {
        assert_eq!(
            load_or_default(Some(&GOOD.encode()), &LIMITS),
            (GOOD, CalibrationSource::Stored)
        );
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        let record = GOOD.encode();
        for bit in 0..RECORD_LEN * 8 {
            let mut corrupted = record;
            corrupted[bit / 8] ^= 1 << (bit % 8);
            let (calibration, source) = load_or_default(Some(&corrupted), &LIMITS);
            assert_eq!(calibration, LIMITS.nominal, "bit {bit}");
            assert!(
                matches!(source, CalibrationSource::Defaults(_)),
                "bit {bit}"
            );
        }
    }

    /// The hostile tester's record: a valid CRC around 1e-6 counts per gram used to be
    /// applied (every mass then reads millions of grams); now it is refused at boot.
    #[test]
    fn a_well_formed_record_with_an_absurd_gain_or_zero_is_not_used() {
        for (absurd, reason) in [
            (
                Calibration {
                    counts_per_gram: 1e-6,
                    zero_counts: 32_000.0,
                },
                CalibrationError::GainOffNominal { percent: -100 },
            ),
            (
                Calibration {
                    counts_per_gram: 50.0 * 1.45,
                    zero_counts: 32_000.0,
                },
                CalibrationError::GainOffNominal { percent: 45 },
            ),
            (
                Calibration {
                    counts_per_gram: 50.0,
                    zero_counts: 70_000.0,
                },
                CalibrationError::ZeroOutsideConverter,
            ),
        ] {
            assert_eq!(
                load_or_default(Some(&absurd.encode()), &LIMITS),
                (LIMITS.nominal, CalibrationSource::Defaults(reason)),
                "{absurd:?}"
            );
        }
    }

    #[test]
    fn missing_unreadable_and_foreign_records_give_defaults_with_the_reason() {
        assert_eq!(
            load_or_default(None, &LIMITS).1,
            CalibrationSource::Defaults(CalibrationError::Missing)
        );
        assert_eq!(
            load_calibration(&mut RamStore::default(), &LIMITS),
            (
                LIMITS.nominal,
                CalibrationSource::Defaults(CalibrationError::Missing)
            )
        );
        let mut unreadable = RamStore {
            record: Some(GOOD.encode()),
            refuse_reads: true,
            ..RamStore::default()
        };
        assert_eq!(
            load_calibration(&mut unreadable, &LIMITS).1,
            CalibrationSource::Defaults(CalibrationError::Unreadable)
        );
        assert_eq!(
            load_or_default(Some(&[0u8; RECORD_LEN]), &LIMITS).1,
            CalibrationSource::Defaults(CalibrationError::BadMagic)
        );
        assert_eq!(CalibrationSource::Stored.label(), "stored");
        assert_eq!(
            CalibrationSource::Defaults(CalibrationError::Missing).label(),
            "nominal"
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
        let mut unreadable = RamStore {
            refuse_reads: true,
            ..RamStore::default()
        };
        assert_eq!(
            store_calibration(&mut unreadable, &measured),
            Err(StoreFailure::Read("read error"))
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
        let mut good = RamStore::default();
        assert_eq!(store_calibration(&mut good, &measured), Ok(measured));
        assert_eq!(
            load_calibration(&mut good, &LIMITS),
            (measured, CalibrationSource::Stored)
        );
    }
}
