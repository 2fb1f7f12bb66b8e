//! Power-safe model storage in two flash slots (MODEL_A, MODEL_B in memory.x).
//!
//! Each slot holds a model blob at its start and, in its last
//! [`COMMIT_LEN`] bytes, a commit record:
//!
//! ```text
//! offset  size  field
//!      0     4  magic b"MCOM"
//!      4     4  sequence number, u32 LE (wrapping; larger = newer)
//!      8     4  blob length, u32 LE
//!     12     4  CRC-32/ISO-HDLC of bytes 0..12 followed by the blob
//! ```
//!
//! At boot ([`ModelStore::open`]) the slot to run is the one whose blob
//! decodes and whose commit record matches it, with the newest sequence; a
//! slot with a valid blob but no record (a blob flashed by a programmer, or by
//! QEMU's loader) counts below any committed slot, slot A before slot B. A
//! probe writes a slot by erasing its whole sector, commit record included,
//! so the documented probe procedure writes the model into both slots: no
//! earlier UART install is left to outrank it (docs/firmware.md, "Flashing
//! and debugging"; `tests/tests/host/probe_flash.rs` holds the documents to
//! this rule).
//!
//! [`ModelStore::install`] never touches the running slot: it checks the new
//! blob (CRC, shape, model), erases the other slot, writes the blob, reads it
//! back, then writes the commit record (the one step that switches, 16 bytes
//! whose CRC makes a torn write invalid), reads that back, and only then
//! switches. A reset at any point leaves either the old model or the new one
//! selected at the next boot, never neither (`tests/model_update.rs`, and the
//! QEMU fault campaign which cuts power after every flash operation).
//!
//! Blobs are read where they lie ([`MappedFlash`]: the STM32's flash is
//! memory-mapped) and decoded in place into a model the caller owns
//! ([`ModelStore::open_with`], [`ModelStore::load_into`],
//! [`ModelStore::install_into`]): the board keeps its one model in a
//! `static`, and neither a blob buffer nor a model (each kilobytes) lands
//! on its stack. [`ModelStore::open`], [`ModelStore::load`] and
//! [`ModelStore::install`] return models by value for host tools and tests.
//!
//! A slot holds either blob format: a single-axis model (format 2) or an
//! IMU's axis models (format 3). The `_into` methods decode into whichever
//! the firmware runs ([`StoredModel`]): a single-axis firmware's [`Model`]
//! refuses a format-3 blob with its reason; a multi-axis firmware's
//! [`AxisModels`](rbf_core::blob::axes::AxisModels) takes both (a format-2 blob as axis x alone); a
//! shared-basis firmware's [`SharedAxisModels`](rbf_core::shared_basis::SharedAxisModels) takes a shared-basis blob
//! alone.

use embedded_storage::nor_flash::NorFlash;
use rbf_core::Model;
use rbf_core::blob::axes::blob_len;
use rbf_core::blob::{self, DecodeError, HEADER_LEN, MAX_BLOB_LEN};

/// What a slot's blob decodes into, in place (rbf-core's, which the host's
/// blob checks use too).
pub use rbf_core::stored_model::StoredModel;

/// A NOR flash whose contents can also be read in place, as the STM32's
/// memory-mapped flash can: blobs are checked and decoded where they lie.
pub trait MappedFlash: NorFlash {
    /// The `len` bytes at `offset` from the start of the device; `None` out
    /// of bounds (or while the device cannot be read).
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]>;
}

impl<T: MappedFlash> MappedFlash for &mut T {
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
        T::mapped(self, offset, len)
    }
}

/// Bytes of the commit record at the end of a slot.
pub const COMMIT_LEN: usize = 16;
/// First bytes of a commit record.
pub const COMMIT_MAGIC: [u8; 4] = *b"MCOM";

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Where the two slots lie in the flash device, bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotLayout {
    /// Offsets of slot A and slot B from the start of the device.
    pub offsets: [u32; 2],
    /// Length of each slot: a multiple of the device's erase size, more than
    /// [`MAX_BLOB_LEN`] + [`COMMIT_LEN`].
    pub len: u32,
}

impl SlotLayout {
    /// Whether the 4-byte word at `offset` lies wholly inside one of the slots.
    pub fn holds_word(&self, offset: u32) -> bool {
        self.offsets.iter().any(|&start| {
            offset >= start
                && offset
                    .checked_add(4)
                    .is_some_and(|end| end <= start.saturating_add(self.len))
        })
    }

    fn commit_offset(&self, slot: usize) -> u32 {
        self.offsets[slot & 1] + self.len - COMMIT_LEN as u32
    }
}

/// What a slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    /// No decodable blob (erased, torn or corrupt); the reason.
    Invalid(DecodeError),
    /// A valid blob without a matching commit record.
    Uncommitted,
    /// A valid blob committed with this sequence number.
    Committed(u32),
}

impl SlotState {
    /// Boot preference: committed beats uncommitted, newer (wrapping) beats older.
    fn outranks(self, other: SlotState) -> bool {
        match (self, other) {
            (SlotState::Committed(a), SlotState::Committed(b)) => (a.wrapping_sub(b) as i32) > 0,
            (SlotState::Committed(_), _) => true,
            (SlotState::Uncommitted, SlotState::Invalid(_)) => true,
            _ => false,
        }
    }
}

/// Why an update was not installed. The running model is unchanged in every case.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InstallError<E> {
    /// The blob was refused (CRC, shape, parameters): the reason.
    Refused(DecodeError),
    /// A flash operation failed.
    Flash(E),
    /// The flash read back differs from what was written.
    Verify,
}

/// The two-slot model store over a NOR flash device.
#[derive(Debug)]
pub struct ModelStore<F> {
    flash: F,
    layout: SlotLayout,
    states: [SlotState; 2],
    active: Option<usize>,
    /// The last [`ModelStore::load_into`] left a usable model behind.
    loaded: bool,
}

impl<F: MappedFlash> ModelStore<F> {
    /// Scans both slots and selects the one to run (see the module docs);
    /// host tools and tests (the scan decodes into a model on the stack).
    pub fn open(flash: F, layout: SlotLayout) -> Self {
        let mut scratch: Model = Model::EMPTY;
        Self::open_with(flash, layout, &mut scratch)
    }

    /// [`Self::open`] decoding each slot into `scratch` (left holding no
    /// particular model: [`Self::load_into`] it).
    pub fn open_with<M: StoredModel>(flash: F, layout: SlotLayout, scratch: &mut M) -> Self {
        let mut store = ModelStore {
            flash,
            layout,
            states: [SlotState::Invalid(DecodeError::BadMagic); 2],
            active: None,
            loaded: false,
        };
        store.rescan(scratch);
        store
    }

    fn rescan<M: StoredModel>(&mut self, scratch: &mut M) {
        for slot in 0..2 {
            self.states[slot] = self.scan(slot, scratch);
        }
        self.active = match self.states {
            [SlotState::Invalid(_), SlotState::Invalid(_)] => None,
            [a, b] => Some(if b.outranks(a) { 1 } else { 0 }),
        };
    }

    /// Slot `slot`'s blob where it lies (its length from its header).
    fn blob(&self, slot: usize) -> Result<&[u8], DecodeError> {
        let start = self.layout.offsets[slot & 1];
        let header = self.flash.mapped(start, HEADER_LEN).ok_or(DecodeError::Malformed)?;
        let len = blob_len(header)?;
        let room = (self.layout.len as usize).saturating_sub(COMMIT_LEN);
        if len > MAX_BLOB_LEN || len > room {
            return Err(DecodeError::Truncated {
                needed: len,
                available: room.min(MAX_BLOB_LEN),
            });
        }
        self.flash.mapped(start, len).ok_or(DecodeError::Malformed)
    }

    fn scan<M: StoredModel>(&mut self, slot: usize, scratch: &mut M) -> SlotState {
        let blob_bytes = match self.blob(slot) {
            Ok(bytes) => bytes,
            Err(e) => return SlotState::Invalid(e),
        };
        if let Err(e) = scratch.decode_from(blob_bytes) {
            return SlotState::Invalid(e);
        }
        let record = self
            .flash
            .mapped(self.layout.commit_offset(slot), COMMIT_LEN)
            .and_then(|r| <&[u8; COMMIT_LEN]>::try_from(r).ok());
        match record.and_then(|r| parse_commit(r, blob_bytes)) {
            Some(sequence) => SlotState::Committed(sequence),
            None => SlotState::Uncommitted,
        }
    }

    /// The slot selected to run (0 = A, 1 = B), if any holds a valid blob.
    pub fn active_slot(&self) -> Option<usize> {
        self.active
    }

    /// What each slot holds.
    pub fn slot_states(&self) -> [SlotState; 2] {
        self.states
    }

    /// Decodes the selected slot's model; the reason if there is none.
    pub fn load(&mut self) -> Result<Model, DecodeError> {
        let mut model: Model = Model::EMPTY;
        self.load_into(&mut model).map(|()| model)
    }

    /// [`Self::load`] in place: `model` holds the selected slot's model, or
    /// none ([`StoredModel::clear`]) and the reason.
    pub fn load_into<M: StoredModel>(&mut self, model: &mut M) -> Result<(), DecodeError> {
        let Some(slot) = self.active else {
            model.clear();
            self.loaded = false;
            return Err(self.states[0].invalid_reason());
        };
        let bytes = self.blob(slot);
        let result = bytes.and_then(|b| model.decode_from(b));
        if result.is_err() {
            model.clear();
        }
        self.loaded = result.is_ok();
        result.map(|_| ())
    }

    /// Whether the model the last [`Self::load_into`] (or
    /// [`Self::install_into`]) decoded is usable: the selected slot's.
    pub fn model_loaded(&self) -> bool {
        self.loaded
    }

    /// Installs `blob` in the slot not running and switches to it; returns
    /// the new model. On any error the running slot is untouched and still
    /// selected.
    pub fn install(&mut self, blob_bytes: &[u8]) -> Result<Model, InstallError<F::Error>> {
        let mut model: Model = Model::EMPTY;
        self.install_into(blob_bytes, &mut model).map(|()| model)
    }

    /// [`Self::install`] in place: on success `model` holds the new model;
    /// on any error the running slot is untouched and still selected, and
    /// `model` holds its model again (decoded afresh from its slot: none if
    /// there is none). A blob of the other format than `M` is refused.
    pub fn install_into<M: StoredModel>(
        &mut self,
        blob_bytes: &[u8],
        model: &mut M,
    ) -> Result<(), InstallError<F::Error>> {
        let result = self.write_and_switch(blob_bytes, model);
        // The running model is rebuilt from its slot: the old one after an
        // error, the new one (now selected) after success.
        let loaded = self.load_into(model);
        match result {
            Ok(()) if loaded.is_err() => Err(InstallError::Verify),
            other => other,
        }
    }

    /// Checks `blob_bytes` (decoding it into `scratch`), writes it to the
    /// slot not running, verifies it and commits it.
    fn write_and_switch<M: StoredModel>(
        &mut self,
        blob_bytes: &[u8],
        scratch: &mut M,
    ) -> Result<(), InstallError<F::Error>> {
        let len = scratch.decode_from(blob_bytes).map_err(InstallError::Refused)?;
        let blob_bytes = blob_bytes.get(..len).ok_or(InstallError::Verify)?;
        let target = self.active.map_or(0, |a| 1 - (a & 1));
        let sequence = match self.active.map(|a| self.states[a & 1]) {
            Some(SlotState::Committed(s)) => s.wrapping_add(1),
            _ => 1,
        };
        let start = self.layout.offsets[target];
        self.flash
            .erase(start, start + self.layout.len)
            .map_err(InstallError::Flash)?;
        self.write_padded(start, blob_bytes)?;
        if self.blob(target).ok() != Some(blob_bytes) {
            return Err(InstallError::Verify);
        }
        // The switch: one small record, valid only if written whole.
        let record = commit_record(sequence, blob_bytes);
        self.write_padded(self.layout.commit_offset(target), &record)?;
        self.rescan(scratch);
        if self.active != Some(target) || self.states[target] != SlotState::Committed(sequence) {
            return Err(InstallError::Verify);
        }
        Ok(())
    }

    /// Writes `bytes` at `offset`, the last write unit padded with 0xFF (erased state).
    fn write_padded(&mut self, offset: u32, bytes: &[u8]) -> Result<(), InstallError<F::Error>> {
        let unit = F::WRITE_SIZE.max(1);
        let whole = bytes.len() / unit * unit;
        let (head, tail) = bytes.split_at(whole);
        if !head.is_empty() {
            self.flash.write(offset, head).map_err(InstallError::Flash)?;
        }
        if !tail.is_empty() {
            let mut last = [0xFFu8; 32];
            let last = last.get_mut(..unit).ok_or(InstallError::Verify)?;
            last.iter_mut().zip(tail).for_each(|(d, s)| *d = *s);
            self.flash
                .write(offset + whole as u32, last)
                .map_err(InstallError::Flash)?;
        }
        Ok(())
    }

    /// The running model's identity: its blob's CRC-32 (the blob's trailer) and its commit
    /// sequence number (0 for a blob without a record); zeros when none runs.
    pub fn identity(&self) -> gyro_wire::health::ModelIdentity {
        let Some(slot) = self.active.filter(|_| self.loaded) else {
            return gyro_wire::health::ModelIdentity::default();
        };
        // The blob's own trailer: the CRC-32 over its header and payload,
        // checked when it was loaded.
        let bytes = self.blob(slot).ok();
        let trailer = bytes.and_then(|b| b.last_chunk::<4>().copied());
        let mut identity = gyro_wire::health::ModelIdentity {
            blob_crc32: trailer.map_or(0, u32::from_le_bytes),
            sequence: match self.states[slot & 1] {
                SlotState::Committed(sequence) => sequence,
                _ => 0,
            },
            ..gyro_wire::health::ModelIdentity::default()
        };
        // The provenance section (formats 4 and 5): its id and serial, read where they lie.
        if let Some(Ok(Some(provenance))) = bytes.map(blob::provenance) {
            identity.model_id = provenance.model_id;
            identity.set_serial(provenance.serial);
        }
        identity
    }

    /// The flash device (its error counters, for the health report).
    pub fn flash(&self) -> &F {
        &self.flash
    }

    /// Gives the flash device back.
    pub fn into_flash(self) -> F {
        self.flash
    }
}

impl SlotState {
    fn invalid_reason(self) -> DecodeError {
        match self {
            SlotState::Invalid(e) => e,
            _ => DecodeError::Malformed,
        }
    }
}

fn commit_crc(head: &[u8], blob_bytes: &[u8]) -> u32 {
    let mut digest = CRC32.digest();
    digest.update(head);
    digest.update(blob_bytes);
    digest.finalize()
}

/// The commit record for `blob_bytes` at `sequence`.
pub fn commit_record(sequence: u32, blob_bytes: &[u8]) -> [u8; COMMIT_LEN] {
    let mut record = [0u8; COMMIT_LEN];
    let (head, crc) = record.split_at_mut(12);
    head[..4].copy_from_slice(&COMMIT_MAGIC);
    head[4..8].copy_from_slice(&sequence.to_le_bytes());
    head[8..12].copy_from_slice(&(blob_bytes.len() as u32).to_le_bytes());
    crc.copy_from_slice(&commit_crc(head, blob_bytes).to_le_bytes());
    record
}

/// The sequence number of `record` if it commits exactly `blob_bytes`.
pub fn parse_commit(record: &[u8; COMMIT_LEN], blob_bytes: &[u8]) -> Option<u32> {
    let word = |i: usize| {
        record
            .get(i..i + 4)
            .and_then(|b| <[u8; 4]>::try_from(b).ok())
            .map(u32::from_le_bytes)
    };
    let head = record.get(..12)?;
    let matches = record.get(..4)? == COMMIT_MAGIC
        && word(8)? as usize == blob_bytes.len()
        && word(12)? == commit_crc(head, blob_bytes);
    if matches { word(4) } else { None }
}
