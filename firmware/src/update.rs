//! Model update over the UART: a COBS-framed command in, a COBS-framed reply out.
//!
//! Host → gyro: `COBS([CMD_INSTALL_MODEL] ++ blob) 0x00`. The firmware
//! collects bytes between output frames ([`CommandReceiver`]), checks the
//! blob's CRC and shape, installs it with [`ModelStore::install`] (inactive
//! slot, then an atomic switch) and switches the running loop to it.
//!
//! Gyro → host: `COBS([command, status]) 0x00` ([`UpdateStatus`]) on the same
//! UART as the output frames; a reply is told from an output frame by its
//! length (2 payload bytes, an output frame has at least 18).

use rbf_core::Model;
use rbf_core::blob::MAX_BLOB_LEN;
use rbf_core::frame::cobs_encode;

use crate::compensation::InPlaceModel;
use crate::model_store::{InstallError, MappedFlash, ModelStore, StoredModel};

/// Command: install the model blob that follows.
pub const CMD_INSTALL_MODEL: u8 = 0x01;
/// Longest command payload (command byte + largest blob), bytes.
pub const MAX_COMMAND_LEN: usize = 1 + MAX_BLOB_LEN;
/// Longest COBS-framed command on the wire, bytes.
pub const MAX_COMMAND_FRAME_LEN: usize = MAX_COMMAND_LEN + MAX_COMMAND_LEN / 254 + 2;
/// Payload bytes of a reply frame.
pub const REPLY_LEN: usize = 2;

/// Outcome of a command, sent back as the reply's second byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum UpdateStatus {
    /// The model is installed and running.
    Installed = 0,
    /// The command byte is not known.
    UnknownCommand = 1,
    /// The frame is not valid COBS or is empty.
    Malformed = 2,
    /// The frame is longer than [`MAX_COMMAND_FRAME_LEN`].
    TooLong = 3,
    /// The blob was refused (CRC, shape or parameters); the old model runs on.
    Refused = 4,
    /// Writing or verifying the flash failed; the old model runs on.
    FlashFailed = 5,
}

/// Collects UART bytes into command frames.
#[derive(Debug)]
pub struct CommandReceiver {
    buf: [u8; MAX_COMMAND_FRAME_LEN],
    len: usize,
    overflow: bool,
}

impl Default for CommandReceiver {
    fn default() -> Self {
        Self::new()
    }
}

/// A complete frame from [`CommandReceiver::push`].
#[derive(Debug, PartialEq, Eq)]
pub enum Received<'a> {
    /// A decoded command payload (command byte first).
    Command(&'a [u8]),
    /// A frame that cannot be a command; the reply to send.
    Rejected(UpdateStatus),
}

impl CommandReceiver {
    /// An empty receiver.
    pub const fn new() -> Self {
        CommandReceiver {
            buf: [0; MAX_COMMAND_FRAME_LEN],
            len: 0,
            overflow: false,
        }
    }

    /// Takes one received byte; at a frame's 0x00 returns what it was.
    pub fn push(&mut self, byte: u8) -> Option<Received<'_>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflow = true,
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if overflow {
            return Some(Received::Rejected(UpdateStatus::TooLong));
        }
        let frame = self.buf.get_mut(..len)?;
        match cobs_decode_in_place(frame) {
            Some(n) if n > 0 => frame.get(..n).map(Received::Command),
            _ => Some(Received::Rejected(UpdateStatus::Malformed)),
        }
    }
}

/// COBS decoding in place, rbf-core's: one decoder for commands and
/// output frames, every access checked (it links in the panic-free image).
pub use rbf_core::frame::cobs_decode_in_place;

/// Carries out one command payload on `store`; the status and, when a model
/// was installed, the model to switch the loop to (host tools and tests).
pub fn execute<F: MappedFlash>(store: &mut ModelStore<F>, payload: &[u8]) -> (UpdateStatus, Option<Model>) {
    let mut model: Model = Model::EMPTY;
    let status = execute_into(store, payload, &mut model);
    (status, (status == UpdateStatus::Installed).then_some(model))
}

/// [`execute`] in place on the running model (the board's `static`): after
/// an install command `model` holds the model of the slot selected now,
/// the new one ([`UpdateStatus::Installed`]) or the old one decoded afresh
/// from its untouched slot; after any other command it is untouched. The
/// running model may be a single-axis [`Model`] (a multi-axis blob is
/// refused) or an IMU's [`rbf_core::blob::axes::AxisModels`] (either format).
pub fn execute_into<F: MappedFlash, M: StoredModel>(
    store: &mut ModelStore<F>,
    payload: &[u8],
    model: &mut M,
) -> UpdateStatus {
    match payload.split_first() {
        Some((&CMD_INSTALL_MODEL, blob)) => match store.install_into(blob, model) {
            Ok(()) => UpdateStatus::Installed,
            Err(InstallError::Refused(_)) => UpdateStatus::Refused,
            Err(InstallError::Flash(_) | InstallError::Verify) => UpdateStatus::FlashFailed,
        },
        _ => UpdateStatus::UnknownCommand,
    }
}

/// The board's command step on the running model held in place: runs
/// `payload` on `store` and rebuilds `model` from the slot selected after
/// it; the status. Pass it to the loop's `update_model_if` as
/// `|m| run_in_place(store, payload, m) == UpdateStatus::Installed`, so
/// that the filters restart only for a model actually installed.
pub fn run_in_place<F: MappedFlash, M: StoredModel>(
    store: &mut ModelStore<F>,
    payload: &[u8],
    model: &mut InPlaceModel<'_, M>,
) -> UpdateStatus {
    let mut status = UpdateStatus::UnknownCommand;
    model.rebuild(|m| {
        status = execute_into(store, payload, m);
        store.model_loaded()
    });
    status
}

/// Encodes the reply to `command` into `out`; the bytes used.
pub fn encode_reply(command: u8, status: UpdateStatus, out: &mut [u8]) -> Option<usize> {
    cobs_encode(&[command, status as u8], out)
}

/// Encodes an install command for `blob` into `out` (host side and tests); the bytes used.
pub fn encode_install_command(blob: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut payload = [0u8; MAX_COMMAND_LEN];
    let (command, rest) = payload.split_first_mut()?;
    *command = CMD_INSTALL_MODEL;
    let body = rest.get_mut(..blob.len())?;
    body.copy_from_slice(blob);
    cobs_encode(payload.get(..1 + blob.len())?, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cobs_decoding_inverts_the_encoder_and_refuses_what_is_not_cobs() {
        // Payloads with zeros in every position and runs past 254 bytes.
        let mut state = 0x1234_5678u32;
        for len in (0..600).step_by(7) {
            let payload: std::vec::Vec<u8> = (0..len)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    if state.is_multiple_of(5) { 0 } else { state as u8 }
                })
                .collect();
            let mut out = std::vec![0u8; len + len / 254 + 2];
            let n = cobs_encode(&payload, &mut out).unwrap();
            let frame = &mut out[..n - 1];
            let decoded = cobs_decode_in_place(frame).unwrap();
            assert_eq!(&frame[..decoded], &payload[..], "length {len}");
        }
        assert_eq!(cobs_decode_in_place(&mut [3, 1, 0, 2]), None, "a zero inside");
        assert_eq!(cobs_decode_in_place(&mut [5, 1, 2]), None, "a block past the end");
        assert_eq!(cobs_decode_in_place(&mut []), Some(0));
    }
}
