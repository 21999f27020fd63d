//! Property tests of what the board loads at boot: arbitrary bytes, well-formed records
//! holding arbitrary numbers, and (with `flash-store`) arbitrary flash contents all give a
//! calibration within the board's limits or the nominal values with a typed reason; never
//! a panic, never an absurd gain or zero in use.

extern crate std;

use proptest::prelude::*;

use super::{load_or_default, Calibration, CalibrationLimits, CalibrationSource, RECORD_LEN};

/// The STM32F411 board's window (`FrontEnd::calibration_limits` of its front end).
fn limits() -> CalibrationLimits {
    super::FrontEnd::STM32F411_INA114.calibration_limits()
}

/// What must hold for whatever the store gave back: the stored calibration only if the
/// bytes decode to it and it is inside the window, the nominal values otherwise.
fn assert_loaded_safely(bytes: &[u8]) -> Result<(), TestCaseError> {
    let limits = limits();
    let (calibration, source) = load_or_default(Some(bytes), &limits);
    match source {
        CalibrationSource::Stored => {
            prop_assert_eq!(Calibration::decode(bytes), Ok(calibration));
            let gain_ratio = calibration.counts_per_gram / limits.nominal.counts_per_gram;
            prop_assert!((gain_ratio - 1.0).abs() <= limits.gain_tolerance);
            prop_assert!(calibration.zero_counts > 0.0);
            prop_assert!(calibration.zero_counts < limits.max_code as f32);
            prop_assert!(
                (calibration.zero_counts - limits.nominal.zero_counts).abs()
                    <= limits.zero_tolerance_counts
            );
        }
        CalibrationSource::Defaults(_) => prop_assert_eq!(calibration, limits.nominal),
    }
    Ok(())
}

/// A record of the current format around arbitrary bit patterns for the gain and the zero
/// (magic, version, length and CRC right): the case where only the limits stand between
/// the bytes and the scale.
fn well_formed(gain_bits: u32, zero_bits: u32) -> [u8; RECORD_LEN] {
    Calibration {
        counts_per_gram: f32::from_bits(gain_bits),
        zero_counts: f32::from_bits(zero_bits),
    }
    .encode()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100_000))]

    #[test]
    fn arbitrary_bytes_never_load_an_absurd_calibration(
        bytes in proptest::collection::vec(any::<u8>(), 0..64)
    ) {
        assert_loaded_safely(&bytes)?;
    }

    #[test]
    fn well_formed_records_with_arbitrary_numbers_load_only_within_the_limits(
        gain_bits in any::<u32>(),
        zero_bits in any::<u32>(),
    ) {
        assert_loaded_safely(&well_formed(gain_bits, zero_bits))?;
    }

    /// Numbers near the window's edges, where rounding could let one through.
    #[test]
    fn records_around_the_window_load_only_inside_it(
        gain_factor in 0.7f32..1.3,
        zero_off_g in -400.0f32..400.0,
    ) {
        let nominal = limits().nominal;
        let record = Calibration {
            counts_per_gram: nominal.counts_per_gram * gain_factor,
            zero_counts: nominal.zero_counts + zero_off_g * nominal.counts_per_gram,
        };
        assert_loaded_safely(&record.encode())?;
    }

    #[test]
    fn a_good_record_with_bytes_changed_is_refused_or_unchanged(
        changes in proptest::collection::vec((0..RECORD_LEN, 1..=255u8), 1..6)
    ) {
        let good = limits().nominal.encode();
        let mut bytes = good;
        for (at, flip) in changes {
            bytes[at] ^= flip;
        }
        assert_loaded_safely(&bytes)?;
        if bytes != good {
            // The CRC catches up to 32 changed bits in 20 bytes (every burst of ≤ 32 bits,
            // and these changes are within 5 bytes of bits: far below its 2^-32 escape).
            prop_assert!(Calibration::decode(&bytes).is_err());
        }
    }
}

/// Arbitrary flash contents under the flash store (what a board with foreign data in its
/// sectors, or a cut the store has not seen, boots on).
#[cfg(feature = "flash-store")]
mod flash_contents {
    use super::*;
    use crate::weighing::calibration::{load_calibration, FlashStore, RamFlash};

    type Flash = RamFlash<2, 128>;

    /// A flash holding `bytes` (the rest erased), written through the NOR interface.
    fn flash_holding(bytes: &[u8]) -> Flash {
        use core::future::Future;
        use embedded_storage_async::nor_flash::NorFlash;
        let mut flash = Flash::new();
        {
            let mut write = core::pin::pin!(flash.write(0, bytes));
            let ready = write.as_mut().poll(&mut core::task::Context::from_waker(
                core::task::Waker::noop(),
            ));
            assert!(matches!(ready, core::task::Poll::Ready(Ok(()))));
        }
        flash
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn arbitrary_flash_contents_never_load_an_absurd_calibration(
            bytes in proptest::collection::vec(any::<u8>(), 0..=256)
        ) {
            let mut store = FlashStore::new(flash_holding(&bytes), 0..Flash::CAPACITY)
                .expect("two pages");
            let limits = limits();
            let (calibration, source) = load_calibration(&mut store, &limits);
            if source == CalibrationSource::Stored {
                let stored = store.read_record();
                let record = stored.ok().flatten().expect("a record was read");
                assert_loaded_safely(&record)?;
            } else {
                prop_assert_eq!(calibration, limits.nominal);
            }
            // Whatever it held, the store takes a new record and gives it back.
            let good = limits.nominal.encode();
            use crate::weighing::calibration::CalibrationStore;
            prop_assert_eq!(store.write_record(&good), Ok(()));
            prop_assert_eq!(store.read_record(), Ok(Some(good)));
        }
    }
}
