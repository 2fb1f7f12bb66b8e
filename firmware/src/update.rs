//! Model update over the UART: a COBS-framed command in, a COBS-framed reply out.
//!
//! Host → gyro: `COBS([CMD_INSTALL_MODEL] ++ blob) 0x00`. The firmware
//! collects bytes between output frames ([`CommandReceiver`]), checks the
//! blob's CRC and shape, installs it with [`ModelStore::install`] (inactive
//! slot, then an atomic switch) and switches the running loop to it.
//!
//! Gyro → host: `COBS([command, status]) 0x00` ([`UpdateStatus`]) on the same
//! UART as the output frames; a reply is told from an output frame by its
//! length (2 payload bytes, an output frame has at least 18). The command
//! and reply formats are the wire protocol's ([`gyro_wire::command`]).

use gyro_wire::cobs::cobs_decode_in_place;
/// A command's outcome, the reply's second byte (the wire protocol's).
pub use gyro_wire::command::UpdateStatus;
use gyro_wire::command::{MAX_COMMAND_FRAME_LEN, decode_install_command};
use rbf_core::Model;

use crate::compensation::InPlaceModel;
use crate::model_store::{InstallError, MappedFlash, ModelStore, StoredModel};

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
    match decode_install_command(payload) {
        Some(blob) => match store.install_into(blob, model) {
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
