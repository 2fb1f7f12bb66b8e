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
//! QEMU's loader) counts below any committed slot, slot A before slot B.
//!
//! [`ModelStore::install`] never touches the running slot: it checks the new
//! blob (CRC, shape, model), erases the other slot, writes the blob, reads it
//! back, then writes the commit record (the one step that switches, 16 bytes
//! whose CRC makes a torn write invalid), reads that back, and only then
//! switches. A reset at any point leaves either the old model or the new one
//! selected at the next boot, never neither (`tests/model_update.rs`, and the
//! QEMU fault campaign which cuts power after every flash operation).

use embedded_storage::nor_flash::NorFlash;
use rbf_core::Model;
use rbf_core::blob::{self, DecodeError, HEADER_LEN, Header, MAX_BLOB_LEN};

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
}

impl<F: NorFlash> ModelStore<F> {
    /// Scans both slots and selects the one to run (see the module docs).
    pub fn open(flash: F, layout: SlotLayout) -> Self {
        let mut store = ModelStore {
            flash,
            layout,
            states: [SlotState::Invalid(DecodeError::BadMagic); 2],
            active: None,
        };
        store.rescan();
        store
    }

    fn rescan(&mut self) {
        let mut buf = [0u8; MAX_BLOB_LEN];
        for slot in 0..2 {
            self.states[slot] = self.scan(slot, &mut buf);
        }
        self.active = match self.states {
            [SlotState::Invalid(_), SlotState::Invalid(_)] => None,
            [a, b] => Some(if b.outranks(a) { 1 } else { 0 }),
        };
    }

    /// Reads slot `slot`'s blob into `buf`; its length.
    fn read_blob(&mut self, slot: usize, buf: &mut [u8; MAX_BLOB_LEN]) -> Result<usize, DecodeError> {
        let start = self.layout.offsets[slot & 1];
        let header_bytes = buf.get_mut(..HEADER_LEN).ok_or(DecodeError::Malformed)?;
        self.flash
            .read(start, header_bytes)
            .map_err(|_| DecodeError::Malformed)?;
        let len = Header::parse(header_bytes)?.blob_len();
        let room = (self.layout.len as usize).saturating_sub(COMMIT_LEN);
        if len > MAX_BLOB_LEN || len > room {
            return Err(DecodeError::Truncated {
                needed: len,
                available: room.min(MAX_BLOB_LEN),
            });
        }
        let bytes = buf.get_mut(..len).ok_or(DecodeError::Malformed)?;
        self.flash.read(start, bytes).map_err(|_| DecodeError::Malformed)?;
        Ok(len)
    }

    fn scan(&mut self, slot: usize, buf: &mut [u8; MAX_BLOB_LEN]) -> SlotState {
        let len = match self.read_blob(slot, buf) {
            Ok(len) => len,
            Err(e) => return SlotState::Invalid(e),
        };
        let blob_bytes = buf.get(..len).unwrap_or(&[]);
        if let Err(e) = blob::decode(blob_bytes) {
            return SlotState::Invalid(e);
        }
        let mut record = [0u8; COMMIT_LEN];
        if self.flash.read(self.layout.commit_offset(slot), &mut record).is_err() {
            return SlotState::Uncommitted;
        }
        match parse_commit(&record, blob_bytes) {
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
        let slot = self.active.ok_or(self.states[0].invalid_reason())?;
        let mut buf = [0u8; MAX_BLOB_LEN];
        let len = self.read_blob(slot, &mut buf)?;
        blob::decode(buf.get(..len).unwrap_or(&[])).map(|d| d.model)
    }

    /// Installs `blob` in the slot not running and switches to it; returns
    /// the new model. On any error the running slot is untouched and still
    /// selected.
    pub fn install(&mut self, blob_bytes: &[u8]) -> Result<Model, InstallError<F::Error>> {
        let decoded = blob::decode(blob_bytes).map_err(InstallError::Refused)?;
        let blob_bytes = blob_bytes.get(..decoded.len).ok_or(InstallError::Verify)?;
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
        let mut buf = [0u8; MAX_BLOB_LEN];
        let read_back = self.read_blob(target, &mut buf).map_err(|_| InstallError::Verify)?;
        if buf.get(..read_back) != Some(blob_bytes) {
            return Err(InstallError::Verify);
        }
        // The switch: one small record, valid only if written whole.
        let record = commit_record(sequence, blob_bytes);
        self.write_padded(self.layout.commit_offset(target), &record)?;
        self.rescan();
        if self.active != Some(target) || self.states[target] != SlotState::Committed(sequence) {
            return Err(InstallError::Verify);
        }
        Ok(decoded.model)
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
