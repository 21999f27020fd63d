//! Calibration: counts per gram and the empty-pan zero.
//!
//! - [`record`]: the versioned, CRC-protected record and every way its bytes can be wrong;
//! - [`limits`]: the front end's nominal values and the window a calibration must fall in,
//!   for a new calibration and for a record loaded at boot alike;
//! - [`store`]: the store both boards implement ([`CalibrationStore`]), loading at boot and
//!   storing with read-back: only what the store gives back intact is ever applied;
//! - `flash` (feature `flash-store`): that store in NOR flash, power-fail safe
//!   (`FlashStore`, over `sequential-storage`), and `ram_flash`, a NOR flash in RAM with
//!   power-cut injection (`RamFlash`: the QEMU board's flash and the power-cut tests').
//!
//! A record that is missing (erased flash), corrupted, of an unknown version, holding an
//! impossible value or one far from the board's nominal values is never used:
//! [`load_calibration`] then returns the nominal calibration with a flag saying why, which
//! every readout line carries (`cal=nominal`), instead of a number computed from garbage.

#[cfg(feature = "flash-store")]
mod flash;
mod limits;
#[cfg(feature = "flash-store")]
mod ram_flash;
mod record;
mod store;

#[cfg(test)]
mod fuzz_tests;
#[cfg(all(test, feature = "flash-store"))]
mod power_cut_tests;

pub use limits::{CalibrationLimits, FrontEnd};
pub(crate) use record::{check_frame, crc32};
pub use record::{Calibration, CalibrationError, RECORD_LEN, RECORD_VERSION};
pub use store::{
    load_calibration, load_or_default, store_calibration, CalibrationSource, CalibrationStore,
    StoreFailure,
};

#[cfg(feature = "flash-store")]
pub use flash::{FlashStore, FlashStoreError};
#[cfg(feature = "flash-store")]
pub use ram_flash::{RamFlash, RamFlashError};

#[cfg(test)]
pub(crate) use store::test_store;
