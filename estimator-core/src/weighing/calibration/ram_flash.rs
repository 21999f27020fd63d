//! A NOR flash in RAM, with the semantics the calibration store relies on and a power cut
//! that can be placed at any byte: the QEMU board's store (it has no flash) and the test
//! bench of the power-fail safety, so both run the very code the hardware runs.
//!
//! NOR semantics, as the STM32F4's flash (byte writes, `WRITE_SIZE` = 1): an erase sets a
//! whole page to 0xFF; a write can only clear bits (the stored byte becomes `old & new`);
//! reads and writes outside the flash or an erase not on page boundaries are errors.
//!
//! A power cut ([`RamFlash::cut_power_after`]) stops the flash after that many more bytes
//! of erasing or programming. The byte in progress is left half done (an erase sets only
//! its upper four bits, a write clears only its upper four bits' zeros), as an interrupted
//! cell may read; every operation then fails until [`RamFlash::restore_power`], the reboot.

use embedded_storage_async::nor_flash::{
    ErrorType, MultiwriteNorFlash, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Why a RAM flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RamFlashError {
    /// Outside the flash.
    OutOfBounds,
    /// An erase not on page boundaries.
    NotAligned,
    /// The power was cut (during this operation or before it).
    PowerCut,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            Self::NotAligned => NorFlashErrorKind::NotAligned,
            Self::PowerCut => NorFlashErrorKind::Other,
        }
    }
}

/// `PAGES` pages of `PAGE_BYTES` bytes of NOR flash in RAM, erased at creation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RamFlash<const PAGES: usize, const PAGE_BYTES: usize> {
    pages: [[u8; PAGE_BYTES]; PAGES],
    /// Bytes of erasing or programming left before the power goes; `None`: no cut planned.
    bytes_until_cut: Option<u32>,
    powered: bool,
    bytes_changed: u32,
    pages_erased: u32,
}

impl<const PAGES: usize, const PAGE_BYTES: usize> Default for RamFlash<PAGES, PAGE_BYTES> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const PAGES: usize, const PAGE_BYTES: usize> RamFlash<PAGES, PAGE_BYTES> {
    /// Capacity in bytes.
    pub const CAPACITY: u32 = (PAGES * PAGE_BYTES) as u32;

    /// An erased flash with power.
    pub const fn new() -> Self {
        Self {
            pages: [[0xFF; PAGE_BYTES]; PAGES],
            bytes_until_cut: None,
            powered: true,
            bytes_changed: 0,
            pages_erased: 0,
        }
    }

    /// Cut the power once `bytes` more bytes have been erased or programmed.
    pub fn cut_power_after(&mut self, bytes: u32) {
        self.bytes_until_cut = Some(bytes);
    }

    /// Power back on (a reboot): the contents stay as the cut left them, no cut is planned.
    pub fn restore_power(&mut self) {
        self.powered = true;
        self.bytes_until_cut = None;
    }

    /// Whether a power cut happened and the power is not restored yet.
    pub fn is_cut(&self) -> bool {
        !self.powered
    }

    /// Bytes erased or programmed since creation: how many cut points an operation has.
    pub fn bytes_changed(&self) -> u32 {
        self.bytes_changed
    }

    /// Pages erased (completely) since creation: on the hardware, each is a stall of the
    /// CPU for as long as a sector erase takes.
    pub fn pages_erased(&self) -> u32 {
        self.pages_erased
    }

    /// The whole contents, page after page.
    pub fn bytes(&self) -> impl Iterator<Item = u8> + '_ {
        self.pages.iter().flatten().copied()
    }

    /// A flash holding `image` (page after page, as [`Self::bytes`] gives it; bytes past
    /// its end stay erased, bytes past the capacity are ignored): a board's flash kept
    /// elsewhere between runs, as QEMU's in a host file.
    pub fn from_image(image: &[u8]) -> Self {
        let mut flash = Self::new();
        for (slot, &byte) in flash.pages.iter_mut().flatten().zip(image) {
            *slot = byte;
        }
        flash
    }

    fn byte_mut(&mut self, address: u32) -> &mut u8 {
        let address = address as usize;
        &mut self.pages[address / PAGE_BYTES][address % PAGE_BYTES]
    }

    /// Change the byte at `address` to `done`, unless the power goes first: then it is
    /// left as `half` and the power is off.
    fn change(&mut self, address: u32, done: u8, half: u8) -> Result<(), RamFlashError> {
        if !self.powered {
            return Err(RamFlashError::PowerCut);
        }
        if let Some(left) = self.bytes_until_cut {
            if left == 0 {
                *self.byte_mut(address) = half;
                self.powered = false;
                return Err(RamFlashError::PowerCut);
            }
            self.bytes_until_cut = Some(left - 1);
        }
        *self.byte_mut(address) = done;
        self.bytes_changed = self.bytes_changed.saturating_add(1);
        Ok(())
    }

    fn check_range(offset: u32, length: usize) -> Result<(), RamFlashError> {
        match (offset as u64).checked_add(length as u64) {
            Some(end) if end <= Self::CAPACITY as u64 => Ok(()),
            _ => Err(RamFlashError::OutOfBounds),
        }
    }
}

impl<const PAGES: usize, const PAGE_BYTES: usize> ErrorType for RamFlash<PAGES, PAGE_BYTES> {
    type Error = RamFlashError;
}

impl<const PAGES: usize, const PAGE_BYTES: usize> ReadNorFlash for RamFlash<PAGES, PAGE_BYTES> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamFlashError> {
        if !self.powered {
            return Err(RamFlashError::PowerCut);
        }
        Self::check_range(offset, bytes.len())?;
        for (address, byte) in (offset..).zip(bytes.iter_mut()) {
            *byte = *self.byte_mut(address);
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        Self::CAPACITY as usize
    }
}

impl<const PAGES: usize, const PAGE_BYTES: usize> NorFlash for RamFlash<PAGES, PAGE_BYTES> {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = PAGE_BYTES;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), RamFlashError> {
        if from > to
            || !(from as usize).is_multiple_of(PAGE_BYTES)
            || !(to as usize).is_multiple_of(PAGE_BYTES)
        {
            return Err(RamFlashError::NotAligned);
        }
        Self::check_range(from, (to - from) as usize)?;
        for address in from..to {
            let old = *self.byte_mut(address);
            self.change(address, 0xFF, old | 0xF0)?;
            if (address as usize + 1).is_multiple_of(PAGE_BYTES) {
                self.pages_erased = self.pages_erased.saturating_add(1);
            }
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamFlashError> {
        Self::check_range(offset, bytes.len())?;
        for (address, &new) in (offset..).zip(bytes) {
            let old = *self.byte_mut(address);
            self.change(address, old & new, old & (new | 0x0F))?;
        }
        Ok(())
    }
}

/// NOR flash allows programming a byte again (only clearing more bits), as the STM32F4's.
impl<const PAGES: usize, const PAGE_BYTES: usize> MultiwriteNorFlash
    for RamFlash<PAGES, PAGE_BYTES>
{
}
