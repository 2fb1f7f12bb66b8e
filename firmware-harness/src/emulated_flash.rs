//! A RAM-backed NOR flash (embedded-storage) that can lose power mid-operation.
//!
//! QEMU's STM32F405 (netduinoplus2) maps flash as ROM and does not model the
//! flash controller, so the model-update tests run the real
//! [`firmware::model_store::ModelStore`] on this device instead, in QEMU and on
//! the host. It behaves as NOR flash does: erase sets whole pages to 0xFF,
//! programming can only clear bits. [`EmulatedFlash::cut_power_after`] makes
//! the n-th primitive operation (one page erase or one word program) tear (a
//! page left partly erased, a word with only some of its bits programmed)
//! and every later operation fail until [`EmulatedFlash::power_cycle`].

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash, check_erase, check_read, check_write,
};

/// Erase page, bytes.
pub const PAGE: usize = 1024;
/// Program unit, bytes.
pub const WORD: usize = 4;

/// Why an emulated flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Address or alignment out of bounds.
    Bounds(NorFlashErrorKind),
    /// Power was cut (during this operation or before it).
    PowerLost,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Bounds(kind) => *kind,
            FlashError::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

/// `N` bytes of emulated NOR flash.
#[derive(Clone, Debug)]
pub struct EmulatedFlash<const N: usize> {
    bytes: [u8; N],
    operations: u32,
    cut_after: Option<u32>,
    powered: bool,
    noise: u32,
}

impl<const N: usize> Default for EmulatedFlash<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> EmulatedFlash<N> {
    /// An erased device.
    pub const fn new() -> Self {
        EmulatedFlash {
            bytes: [0xFF; N],
            operations: 0,
            cut_after: None,
            powered: true,
            noise: 0x6D2B_79F5,
        }
    }

    /// Tears the operation after `n` more complete ones (`n = 0`: the next);
    /// everything after it fails until [`Self::power_cycle`].
    pub fn cut_power_after(&mut self, n: u32) {
        self.cut_after = Some(self.operations.wrapping_add(n));
    }

    /// Power comes back (a reset): operations work again; contents stay as torn.
    pub fn power_cycle(&mut self) {
        self.powered = true;
        self.cut_after = None;
    }

    /// Primitive operations (page erases, word programs) completed or torn so far.
    pub fn operations(&self) -> u32 {
        self.operations
    }

    /// The raw contents.
    pub fn contents(&self) -> &[u8; N] {
        &self.bytes
    }

    /// Mutable raw contents (to place a factory image or corrupt it).
    pub fn contents_mut(&mut self) -> &mut [u8; N] {
        &mut self.bytes
    }

    fn next_noise(&mut self) -> u32 {
        self.noise ^= self.noise << 13;
        self.noise ^= self.noise >> 17;
        self.noise ^= self.noise << 5;
        self.noise
    }

    /// Starts one primitive operation: `Ok(true)` runs whole, `Ok(false)` tears.
    fn begin(&mut self) -> Result<bool, FlashError> {
        if !self.powered {
            return Err(FlashError::PowerLost);
        }
        let torn = self.cut_after == Some(self.operations);
        self.operations = self.operations.wrapping_add(1);
        if torn {
            self.powered = false;
        }
        Ok(!torn)
    }
}

impl<const N: usize> ErrorType for EmulatedFlash<N> {
    type Error = FlashError;
}

impl<const N: usize> ReadNorFlash for EmulatedFlash<N> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len()).map_err(FlashError::Bounds)?;
        let start = offset as usize;
        let src = self
            .bytes
            .get(start..start + bytes.len())
            .ok_or(FlashError::Bounds(NorFlashErrorKind::OutOfBounds))?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        N
    }
}

impl<const N: usize> firmware::model_store::MappedFlash for EmulatedFlash<N> {
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
        let start = offset as usize;
        self.bytes.get(start..start.checked_add(len)?)
    }
}

impl<const N: usize> NorFlash for EmulatedFlash<N> {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to).map_err(FlashError::Bounds)?;
        for page in (from as usize..to as usize).step_by(PAGE) {
            let whole = self.begin()?;
            let noise = self.next_noise();
            let Some(bytes) = self.bytes.get_mut(page..page + PAGE) else {
                return Err(FlashError::Bounds(NorFlashErrorKind::OutOfBounds));
            };
            if whole {
                bytes.fill(0xFF);
            } else {
                // Torn erase: a leading part of the page is erased, the rest untouched.
                let erased = noise as usize % PAGE;
                bytes[..erased].fill(0xFF);
                return Err(FlashError::PowerLost);
            }
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, data.len()).map_err(FlashError::Bounds)?;
        for (i, word) in data.chunks(WORD).enumerate() {
            let whole = self.begin()?;
            let noise = self.next_noise().to_le_bytes();
            let at = offset as usize + i * WORD;
            let Some(cells) = self.bytes.get_mut(at..at + word.len()) else {
                return Err(FlashError::Bounds(NorFlashErrorKind::OutOfBounds));
            };
            for ((cell, &value), &n) in cells.iter_mut().zip(word).zip(&noise) {
                // Programming clears bits; a torn program clears only some of them.
                let clear = !value & if whole { 0xFF } else { n };
                *cell &= !clear;
            }
            if !whole {
                return Err(FlashError::PowerLost);
            }
        }
        Ok(())
    }
}
