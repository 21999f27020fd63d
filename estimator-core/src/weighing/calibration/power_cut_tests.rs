//! The flash store under power cuts: a cut at every byte of a write, erase included, keeps
//! the previous record (or, once the new one is complete, the new one), never nothing and
//! never a third value; the store works again after the reboot. And the store's erase
//! budget: on the STM32F411's geometry a calibration erases nothing for thousands of
//! writes (the old store erased a 128 KiB sector, 2–4 s of stalled CPU, every time).

extern crate std;
use std::boxed::Box;
use std::vec::Vec;

use super::{Calibration, CalibrationStore, FlashStore, FlashStoreError, RamFlash, RamFlashError};

/// Small pages, so that a handful of writes fills one and the next write migrates the
/// record and erases a page: every kind of step a write can take is cut somewhere.
type SmallFlash = RamFlash<2, 256>;

fn record(index: u32) -> [u8; super::RECORD_LEN] {
    Calibration {
        counts_per_gram: 50.0 + index as f32 * 0.01,
        zero_counts: 30_000.0 + index as f32,
    }
    .encode()
}

fn store(flash: SmallFlash) -> FlashStore<SmallFlash> {
    FlashStore::new(flash, 0..SmallFlash::CAPACITY).expect("two whole pages")
}

/// Reboot: the power back, a new store over what the flash holds.
fn reboot(mut flash: SmallFlash) -> FlashStore<SmallFlash> {
    flash.restore_power();
    store(flash)
}

/// A flash holding records 0..written, the newest last.
fn flash_with(written: u32) -> SmallFlash {
    let mut store = store(SmallFlash::new());
    for index in 0..written {
        store.write_record(&record(index)).expect("a clean write");
    }
    store.into_flash()
}

#[test]
fn a_power_cut_at_every_byte_of_a_write_keeps_the_previous_record() {
    let mut cases = 0u32;
    let mut migrations_cut = 0u32;
    // Histories of 0 to 24 records put the write under test at every place in a page, at
    // the switch to the next page (migration of the record, erase of the old page) and
    // after a wrap-around to the first page again.
    for written in 0..=24u32 {
        let base = flash_with(written);
        let previous = written.checked_sub(1).map(record);
        let new = record(written);
        // The bytes this write erases or programs: each is a cut point.
        let mut clean = store(base.clone());
        clean.write_record(&new).expect("a clean write");
        let clean = clean.into_flash();
        let steps = clean.bytes_changed() - base.bytes_changed();
        if clean.pages_erased() > base.pages_erased() {
            migrations_cut += 1;
        }
        for cut in 0..steps {
            let mut flash = base.clone();
            flash.cut_power_after(cut);
            let mut cut_store = store(flash);
            assert_eq!(
                cut_store.write_record(&new),
                Err(FlashStoreError::Flash(RamFlashError::PowerCut)),
                "{written} records, cut after {cut} of {steps} bytes"
            );
            let mut rebooted = reboot(cut_store.into_flash());
            let found = rebooted.read_record().expect("readable after a cut");
            assert!(
                found == previous || found == Some(new),
                "{written} records, cut after {cut} of {steps} bytes: {found:?}"
            );
            // The store works again: the next record is written and read back.
            let next = record(1000 + written);
            rebooted
                .write_record(&next)
                .expect("a write after the reboot");
            assert_eq!(rebooted.read_record(), Ok(Some(next)));
            cases += 1;
        }
    }
    std::println!("{cases} cut points over 25 writes, {migrations_cut} of them page switches");
    assert!(
        migrations_cut >= 2,
        "only {migrations_cut} page switches cut"
    );
    assert!(cases > 1000, "only {cases} cut points");
}

/// A cut during the erase of an old page, with the previous record's copy already in the
/// next page, is the case the old store lost its record in (erase, then program): here the
/// record is still there, whichever byte of the erase the power stops at.
#[test]
fn a_power_cut_during_a_page_erase_keeps_the_record() {
    // The write that fills the first page and moves on erases the other one.
    let written = (0..40u32)
        .find(|&written| {
            let base = flash_with(written);
            let mut next = store(base.clone());
            next.write_record(&record(written)).expect("a clean write");
            next.into_flash().pages_erased() > base.pages_erased()
        })
        .expect("a page switch within 40 writes");
    let base = flash_with(written);
    let mut erase_cuts = 0;
    for cut in 0.. {
        let mut flash = base.clone();
        flash.cut_power_after(cut);
        let mut cut_store = store(flash);
        if cut_store.write_record(&record(written)).is_ok() {
            break;
        }
        let flash = cut_store.into_flash();
        // Cut inside the erase: it had begun (more bytes read 0xFF than before the write,
        // which only programmed a few dozen) and not finished.
        let erased = flash.bytes().filter(|&byte| byte == 0xFF).count();
        let erased_before = base.bytes().filter(|&byte| byte == 0xFF).count();
        if erased > erased_before && flash.pages_erased() == base.pages_erased() {
            erase_cuts += 1;
        }
        let found = reboot(flash).read_record().expect("readable");
        assert!(
            found == Some(record(written - 1)) || found == Some(record(written)),
            "cut after {cut}: {found:?}"
        );
    }
    std::println!("{erase_cuts} cuts inside the erase of write {written}");
    assert!(erase_cuts > 100, "only {erase_cuts} cuts inside the erase");
}

/// On the STM32F411's geometry (two 128 KiB sectors), calibrations erase nothing until a
/// sector is full: thousands of them, each a few dozen programmed bytes.
#[test]
fn on_the_boards_geometry_a_calibration_erases_nothing_for_thousands_of_writes() {
    type BoardFlash = RamFlash<2, { 128 * 1024 }>;
    let flash: Box<BoardFlash> = Box::default();
    let mut store = FlashStore::new(*flash, 0..BoardFlash::CAPACITY).expect("two sectors");
    let mut bytes_per_write = Vec::new();
    let mut writes_before_an_erase = None;
    for index in 0..5_000u32 {
        let flash = store.into_flash();
        let (before, erased) = (flash.bytes_changed(), flash.pages_erased());
        store = FlashStore::new(flash, 0..BoardFlash::CAPACITY).expect("two sectors");
        store.write_record(&record(index)).expect("a write");
        assert_eq!(store.read_record(), Ok(Some(record(index))));
        let flash = store.into_flash();
        if flash.pages_erased() > erased && writes_before_an_erase.is_none() {
            writes_before_an_erase = Some(index);
        }
        bytes_per_write.push(flash.bytes_changed() - before);
        store = FlashStore::new(flash, 0..BoardFlash::CAPACITY).expect("two sectors");
    }
    let writes_before_an_erase = writes_before_an_erase.expect("a sector filled");
    assert!(writes_before_an_erase > 4_000, "{writes_before_an_erase}");
    let typical = bytes_per_write[..100].iter().max().copied().unwrap_or(0);
    std::println!(
        "128 KiB pages: first erase at write {writes_before_an_erase}, {typical} bytes programmed per write"
    );
    assert!(typical < 64, "{typical} bytes programmed per calibration");
}

#[test]
fn a_range_that_is_not_two_whole_pages_is_refused() {
    for range in [0..256, 1..513, 0..300] {
        assert!(
            matches!(
                FlashStore::new(RamFlash::<4, 256>::new(), range.clone()),
                Err(FlashStoreError::BadRange)
            ),
            "{range:?}"
        );
    }
}

/// The store the boards had before (erase the record's page, then program the record at
/// its start), on the same flash and the same cuts: the harness above would have failed
/// it, as a cut during the erase leaves no record and the board boots on nominal values.
struct EraseThenProgram(SmallFlash);

impl CalibrationStore for EraseThenProgram {
    type Error = RamFlashError;
    fn write_record(&mut self, record: &[u8; super::RECORD_LEN]) -> Result<(), RamFlashError> {
        use embedded_storage_async::nor_flash::NorFlash;
        let erase = self.0.erase(0, 256);
        poll(erase)?;
        poll(self.0.write(0, record))
    }
    fn read_record(&mut self) -> Result<Option<[u8; super::RECORD_LEN]>, RamFlashError> {
        use embedded_storage_async::nor_flash::ReadNorFlash;
        let mut record = [0; super::RECORD_LEN];
        poll(self.0.read(0, &mut record))?;
        Ok(Some(record))
    }
}

fn poll<T>(future: impl core::future::Future<Output = T>) -> T {
    let mut future = core::pin::pin!(future);
    let mut context = core::task::Context::from_waker(core::task::Waker::noop());
    match future.as_mut().poll(&mut context) {
        core::task::Poll::Ready(output) => output,
        core::task::Poll::Pending => panic!("the RAM flash never waits"),
    }
}

#[test]
fn the_harness_catches_the_old_erase_then_program_store() {
    let mut old = EraseThenProgram(SmallFlash::new());
    old.write_record(&record(0)).expect("a clean write");
    let base = old.0.clone();
    let mut lost = 0;
    for cut in 0..256 + super::RECORD_LEN as u32 {
        let mut flash = base.clone();
        flash.cut_power_after(cut);
        let mut cut_store = EraseThenProgram(flash);
        assert!(cut_store.write_record(&record(1)).is_err());
        cut_store.0.restore_power();
        let found = cut_store.read_record().expect("readable");
        if found != Some(record(0)) && found != Some(record(1)) {
            lost += 1;
        }
    }
    // Every cut point loses the record: during the erase and during the programming.
    assert_eq!(lost, 256 + super::RECORD_LEN);
}

/// A board flashed over the earlier firmware holds that firmware's record (erase, then the
/// 20 bytes at the start of sector 7, the store's second page) in the store's range: the
/// store does not take it for its own, boots on the nominal values, and the next
/// calibration is stored and read back.
#[test]
fn the_earlier_firmwares_record_in_the_range_does_not_block_the_store() {
    let mut old = EraseThenProgram(SmallFlash::new());
    let old_record = record(7);
    let page = 256;
    {
        use embedded_storage_async::nor_flash::NorFlash;
        poll(old.0.write(page, &old_record)).expect("programmed");
    }
    let mut store = store(old.0);
    let found = store.read_record();
    assert!(found != Ok(Some(old_record)), "{found:?}");
    store
        .write_record(&record(8))
        .expect("a calibration is stored");
    assert_eq!(store.read_record(), Ok(Some(record(8))));
}

/// The QEMU board's geometry: two 1 KiB pages.
type BoardFlash = RamFlash<2, 1024>;

fn settings_record(index: u32) -> [u8; crate::weighing::SETTINGS_LEN] {
    let base = crate::weighing::ScaleConfig::weighing_default(4000.0);
    crate::weighing::Settings {
        config: crate::weighing::ScaleConfig {
            capacity_g: 600.0 + index as f32,
            ..base
        },
        console_rate_hz: 20,
        unit: crate::weighing::console::Unit::G,
        method: crate::weighing::ScaleConfig::DEFAULT_METHOD,
    }
    .encode()
}

/// The settings record beside the calibration record: a cut at every byte of a settings
/// write, over histories that fill the pages and switch them (each with and without a
/// calibration write first), keeps the calibration record as it was and the settings as
/// they were or as written, never neither.
#[test]
fn a_power_cut_during_a_settings_write_keeps_both_records() {
    use crate::weighing::SettingsStore;
    let board_store =
        |flash: BoardFlash| FlashStore::new(flash, 0..BoardFlash::CAPACITY).expect("two pages");
    let mut cases = 0u32;
    let mut page_switches = 0u32;
    // With or without one calibration write first: which write fills a page depends on
    // the two records' sizes (with a 164-byte settings record, stop 38, histories of pairs
    // alone switched pages only at calibration writes).
    let histories = (0..=1u32).flat_map(|lead| (0..=14u32).map(move |written| (lead, written)));
    for (lead, written) in histories {
        let mut history = board_store(BoardFlash::new());
        for index in 0..lead {
            history
                .write_record(&record(1000 + index))
                .expect("a clean write");
        }
        for index in 0..written {
            history.write_record(&record(index)).expect("a clean write");
            history
                .write_settings(&settings_record(index))
                .expect("a clean write");
        }
        history
            .write_record(&record(written))
            .expect("a clean write");
        let base = history.into_flash();
        let previous = written.checked_sub(1).map(settings_record);
        let new = settings_record(written);
        let mut clean = board_store(base.clone());
        clean.write_settings(&new).expect("a clean write");
        let clean = clean.into_flash();
        if clean.pages_erased() > base.pages_erased() {
            page_switches += 1;
        }
        for cut in 0..clean.bytes_changed() - base.bytes_changed() {
            let mut flash = base.clone();
            flash.cut_power_after(cut);
            let mut cut_store = board_store(flash);
            assert!(cut_store.write_settings(&new).is_err());
            let mut flash = cut_store.into_flash();
            flash.restore_power();
            let mut rebooted = board_store(flash);
            assert_eq!(
                rebooted.read_record(),
                Ok(Some(record(written))),
                "{written} pairs after {lead} calibration writes, cut after {cut} bytes: the calibration record"
            );
            let found = rebooted.read_settings().expect("readable after a cut");
            assert!(
                found == previous || found == Some(new),
                "{written} pairs after {lead} calibration writes, cut after {cut} bytes"
            );
            cases += 1;
        }
    }
    std::println!("{cases} cut points, {page_switches} writes that switched pages");
    assert!(page_switches >= 1, "no page switch was cut");
    assert!(cases > 1000, "only {cases} cut points");
}
