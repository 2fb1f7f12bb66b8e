//! The command path of the board's loop, run between samples: the bytes
//! the UART interrupt queued go into the [`CommandReceiver`]; a model
//! install runs through the model store into the running model (every
//! axis's feature filters restart only for a model actually installed),
//! with the watchdog fed around the flash work; `bench` and `health` are
//! answered by the board's own reports ([`Report`]); every other command,
//! and a frame refused as it arrived, gets its reply frame between the
//! output frames. `Board::run` runs it on the chip, the fault campaign
//! (`firmware-harness/tests/board_faults`) on the host.

use embedded_io::Write;
use gyro_wire::command::{CMD_BENCH, CMD_HEALTH, REPLY_FRAME_LEN, encode_reply};

use crate::compensation::{CompensationLoop, InPlaceModel, ModelHolder, write_frame};
use crate::model_store::{MappedFlash, ModelStore, StoredModel};
use crate::sensors::{AxisFrontEnds, AxisThermometers};
use crate::update::{self, CommandReceiver, Received, UpdateStatus};
use crate::watchdog::Watchdog;

/// A command the board answers with a report of its own, not a reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Report {
    /// `bench`: time the next steps, then send their statistics.
    Bench,
    /// `health`: send the health report now.
    Health,
}

/// Serves every command byte `next_byte` gives (the receive queue) into
/// `receiver`; installs through `store` into `compensation`'s model,
/// feeding `watchdog` before and after; `report` answers `bench` and
/// `health`; `replied` hears each reply's status with the store after it.
#[allow(clippy::too_many_arguments, reason = "the loop's parts, each borrowed for one pass")]
pub fn serve_commands<'m, T, R, W, M, F, D, const K: usize, const N: usize>(
    mut next_byte: impl FnMut() -> Option<u8>,
    receiver: &mut CommandReceiver,
    compensation: &mut CompensationLoop<T, R, W, InPlaceModel<'m, M>, K, N>,
    store: &mut ModelStore<F>,
    watchdog: &mut D,
    mut report: impl FnMut(Report, &mut CompensationLoop<T, R, W, InPlaceModel<'m, M>, K, N>, &ModelStore<F>),
    mut replied: impl FnMut(UpdateStatus, &ModelStore<F>),
) where
    T: AxisThermometers,
    R: AxisFrontEnds,
    W: Write,
    M: StoredModel,
    InPlaceModel<'m, M>: ModelHolder<K, N>,
    F: MappedFlash,
    D: Watchdog,
{
    while let Some(byte) = next_byte() {
        let (command, status) = match receiver.push(byte) {
            None => continue,
            Some(Received::Rejected(status)) => (0, status),
            Some(Received::Command(&[CMD_BENCH])) => {
                report(Report::Bench, compensation, store);
                continue;
            }
            Some(Received::Command(&[CMD_HEALTH])) => {
                report(Report::Health, compensation, store);
                continue;
            }
            Some(Received::Command(payload)) => {
                // The flash driver runs the watchdog at its install period around the erase.
                watchdog.feed();
                let mut status = UpdateStatus::UnknownCommand;
                compensation.update_model_if(|model| {
                    status = update::run_in_place(store, payload, model);
                    status == UpdateStatus::Installed
                });
                watchdog.feed();
                (payload.first().copied().unwrap_or(0), status)
            }
        };
        let mut reply = [0u8; REPLY_FRAME_LEN];
        if let Some(n) = encode_reply(command, status, &mut reply) {
            write_frame(compensation.output_mut(), reply.get(..n).unwrap_or(&[]));
        }
        replied(status, store);
    }
}
