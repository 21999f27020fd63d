//! The calibration record in NOR flash, power-fail safe: [`FlashStore`] keeps it under its
//! key of a `sequential-storage` map over two or more erase pages of any
//! `embedded-storage-async` [`NorFlash`], and the operator's settings record
//! (`crate::weighing::Settings`) under another.
//!
//! Why that crate rather than a hand-written A/B scheme: its map appends each new record
//! after the previous ones (header and data CRC-protected, its position in the page
//! sequence ordering it like a sequence number), so the previous record stays intact and is
//! what a read finds until the new one is complete; a page is erased only when the pages
//! fill up, after the newest record has been copied into the next page, and a state left by
//! a cut erase or write is repaired on the next operation. The record keeps its own magic,
//! version and CRC (`Calibration::decode`), so what comes back is checked twice.
//!
//! The crate's API is async; both boards' flashes are blocking (the STM32F4's stalls the
//! CPU anyway, the QEMU board's is RAM), so their futures are ready when first polled and
//! there is nothing an executor could interleave. Each operation is therefore polled once
//! ([`poll_once`]): no executor, no dependency (embassy-embedded-hal's adapter and
//! `block_on` would bring embassy-sync and two embedded-hal versions into the core), and no
//! unbounded loop in the task that stores. A flash that would wait gives `WouldWait`.
//!
//! What it must never do: erase or overwrite the newest complete record before a newer one
//! is complete, or block without bound.

use core::future::Future;
use core::ops::Range;
use core::pin::pin;
use core::task::{Context, Poll, Waker};

use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use super::record::RECORD_LEN;
use super::store::CalibrationStore;
use crate::weighing::settings::{SettingsStore, SETTINGS_LEN};

/// The map key of the calibration record (the map keeps the newest value of each key).
const RECORD_KEY: u8 = 0xCA;
/// The map key of the settings record.
const SETTINGS_KEY: u8 = 0x5E;
/// The map's working buffer: the key and the larger record, rounded up to a word of any
/// flash the crate supports (its largest, 32 bytes), aligned for flashes that need it.
const BUFFER_BYTES: usize = (1 + max(RECORD_LEN, SETTINGS_LEN)).div_ceil(32) * 32;

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

#[repr(align(4))]
struct Buffer([u8; BUFFER_BYTES]);

/// Why the flash store failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlashStoreError<E> {
    /// The flash refused an operation (its own error).
    Flash(E),
    /// The range is not whole erase pages, or fewer than two of them.
    BadRange,
    /// The flash holds a state the store could not repair.
    Corrupted,
    /// The record does not fit (never expected: one key, a 20-byte record).
    Full,
    /// The item under the record's key is not a record's length: not written by this code.
    ForeignItem,
    /// The flash did not complete an operation when polled (it is not a blocking flash).
    WouldWait,
    /// An error the crate reports as its own bug, or a buffer or serialisation error.
    Internal,
}

impl<E> From<sequential_storage::Error<E>> for FlashStoreError<E> {
    fn from(error: sequential_storage::Error<E>) -> Self {
        match error {
            sequential_storage::Error::Storage { value, .. } => Self::Flash(value),
            sequential_storage::Error::Corrupted { .. } => Self::Corrupted,
            sequential_storage::Error::FullStorage | sequential_storage::Error::ItemTooBig => {
                Self::Full
            }
            _ => Self::Internal,
        }
    }
}

type RecordMap<F> = MapStorage<u8, F, Cache<Uncached, Uncached, Uncached, u8>>;

/// The calibration record in `flash`, in the erase pages of `range`.
pub struct FlashStore<F: NorFlash> {
    map: RecordMap<F>,
}

impl<F: NorFlash> FlashStore<F> {
    /// The store over `range` of `flash` (offsets from the flash's start): whole erase
    /// pages, at least two. Nothing is read or written until the first operation.
    pub fn new(flash: F, range: Range<u32>) -> Result<Self, FlashStoreError<F::Error>> {
        let config = MapConfig::try_new(range).map_err(|_| FlashStoreError::BadRange)?;
        Ok(Self {
            // Uncached: every operation reads the state from the flash, so nothing in RAM can
            // disagree with it after a reset or a failed operation.
            map: MapStorage::new(flash, config, Cache::new_uncached()),
        })
    }

    /// The flash back (to reboot a store over it in the tests, or to reuse it).
    pub fn into_flash(self) -> F {
        self.map.destroy().0
    }
}

impl<F: NorFlash> FlashStore<F> {
    fn append(&mut self, key: u8, value: &[u8]) -> Result<(), FlashStoreError<F::Error>> {
        let mut buffer = Buffer([0; BUFFER_BYTES]);
        let stored = self.map.store_item(&mut buffer.0, &key, &value);
        poll_once(stored).ok_or(FlashStoreError::WouldWait)??;
        Ok(())
    }

    /// Append `value` under `key`. A map that is full or corrupted is erased and written
    /// again: the other key's record is lost with it (the boot log then says it is missing).
    fn write_item(&mut self, key: u8, value: &[u8]) -> Result<(), FlashStoreError<F::Error>> {
        match self.append(key, value) {
            Err(FlashStoreError::Full | FlashStoreError::Corrupted) => {
                poll_once(self.map.erase_all()).ok_or(FlashStoreError::WouldWait)??;
                self.append(key, value)
            }
            appended => appended,
        }
    }

    /// The newest value under `key`, if it is `N` bytes long.
    fn read_item<const N: usize>(
        &mut self,
        key: u8,
    ) -> Result<Option<[u8; N]>, FlashStoreError<F::Error>> {
        let mut buffer = Buffer([0; BUFFER_BYTES]);
        let fetched = self.map.fetch_item::<&[u8]>(&mut buffer.0, &key);
        let Some(bytes) = poll_once(fetched).ok_or(FlashStoreError::WouldWait)?? else {
            return Ok(None);
        };
        let record: [u8; N] = bytes.try_into().map_err(|_| FlashStoreError::ForeignItem)?;
        Ok(Some(record))
    }

    /// The flash under the store (a board that keeps an image of it elsewhere, as QEMU's in
    /// a host file, copies it from here after a write).
    pub fn flash(&mut self) -> &mut F {
        self.map.flash()
    }
}

impl<F: NorFlash> CalibrationStore for FlashStore<F> {
    type Error = FlashStoreError<F::Error>;

    /// Append `record` under the calibration's key (see [`FlashStore::write_item`] for a
    /// full or corrupted map).
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error> {
        self.write_item(RECORD_KEY, record)
    }

    fn read_record(&mut self) -> Result<Option<[u8; RECORD_LEN]>, Self::Error> {
        self.read_item(RECORD_KEY)
    }
}

impl<F: NorFlash> SettingsStore for FlashStore<F> {
    type Error = FlashStoreError<F::Error>;

    fn write_settings(&mut self, record: &[u8; SETTINGS_LEN]) -> Result<(), Self::Error> {
        self.write_item(SETTINGS_KEY, record)
    }

    fn read_settings(&mut self) -> Result<Option<[u8; SETTINGS_LEN]>, Self::Error> {
        self.read_item(SETTINGS_KEY)
    }
}

/// Poll `future` once: its output if it completed, `None` if it would wait.
fn poll_once<T>(future: impl Future<Output = T>) -> Option<T> {
    let mut future = pin!(future);
    match future
        .as_mut()
        .poll(&mut Context::from_waker(Waker::noop()))
    {
        Poll::Ready(output) => Some(output),
        Poll::Pending => None,
    }
}
