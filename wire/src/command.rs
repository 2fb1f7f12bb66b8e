//! Host → unit: commands, and the unit's replies.
//!
//! A command is `COBS([command] ++ argument) 0x00`: [`CMD_INSTALL_MODEL`]
//! with a model blob (at most [`MAX_COMMAND_FRAME_LEN`] bytes on the wire),
//! [`CMD_BENCH`] and [`CMD_HEALTH`] alone. The install command and the
//! commands the unit does not know are answered by a reply,
//! `COBS([command, status]) 0x00` ([`REPLY_LEN`] payload bytes,
//! [`UpdateStatus`]); `bench` and `health` by their reports
//! ([`crate::bench`], [`crate::health`]).

use rbf_core::blob::MAX_BLOB_LEN;

use crate::cobs::{cobs_encode, max_encoded_len};

/// Command: install the model blob that follows.
pub const CMD_INSTALL_MODEL: u8 = 0x01;
/// Command: time the next sample steps and send the bench report ([`crate::bench`]).
pub const CMD_BENCH: u8 = 0x02;
/// Command: send the health report ([`crate::health`]).
pub const CMD_HEALTH: u8 = 0x03;
/// Longest command payload (command byte + largest blob), bytes.
pub const MAX_COMMAND_LEN: usize = 1 + MAX_BLOB_LEN;
/// Longest COBS-framed command on the wire, its 0x00 included, bytes.
pub const MAX_COMMAND_FRAME_LEN: usize = max_encoded_len(MAX_COMMAND_LEN);
/// Payload bytes of a reply frame.
pub const REPLY_LEN: usize = 2;
/// Bytes of a COBS-framed reply with its 0x00.
pub const REPLY_FRAME_LEN: usize = max_encoded_len(REPLY_LEN);

byte_enum! {
    /// Outcome of a command, sent back as the reply's second byte.
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
}

/// Encodes the reply to `command` into `out` (at least [`REPLY_FRAME_LEN`]
/// bytes); the bytes used.
pub fn encode_reply(command: u8, status: UpdateStatus, out: &mut [u8]) -> Option<usize> {
    cobs_encode(&[command, status as u8], out)
}

/// Encodes an install command for `blob` into `out` (host side and tests); the
/// bytes used, `None` for a blob over [`MAX_BLOB_LEN`] or a short `out`.
pub fn encode_install_command(blob: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut payload = [0u8; MAX_COMMAND_LEN];
    let (command, rest) = payload.split_first_mut()?;
    *command = CMD_INSTALL_MODEL;
    let body = rest.get_mut(..blob.len())?;
    body.copy_from_slice(blob);
    cobs_encode(payload.get(..1 + blob.len())?, out)
}

/// The blob of an install command's decoded `payload`; `None` for any other command.
pub fn decode_install_command(payload: &[u8]) -> Option<&[u8]> {
    match payload.split_first() {
        Some((&CMD_INSTALL_MODEL, blob)) => Some(blob),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cobs::cobs_decode_in_place;

    #[test]
    fn an_install_command_carries_the_blob_whole_up_to_the_largest_blob() {
        let blob: std::vec::Vec<u8> = (0..MAX_BLOB_LEN).map(|i| (i % 7) as u8).collect();
        let mut wire = std::vec![0u8; MAX_COMMAND_FRAME_LEN];
        let n = encode_install_command(&blob, &mut wire).unwrap();
        assert!(n <= MAX_COMMAND_FRAME_LEN);
        assert_eq!(wire[n - 1], 0);
        let len = cobs_decode_in_place(&mut wire[..n - 1]).unwrap();
        assert_eq!(decode_install_command(&wire[..len]), Some(&blob[..]));
        let too_long = std::vec![1u8; MAX_BLOB_LEN + 1];
        assert_eq!(encode_install_command(&too_long, &mut wire), None);
        assert_eq!(decode_install_command(&[CMD_HEALTH]), None, "another command");
        assert_eq!(decode_install_command(&[]), None);
        assert_eq!(
            decode_install_command(&[CMD_INSTALL_MODEL]),
            Some(&[][..]),
            "an empty blob, for the unit to refuse"
        );
    }

    #[test]
    fn a_reply_is_the_command_and_its_status_in_two_bytes() {
        let mut out = [0u8; REPLY_FRAME_LEN];
        let n = encode_reply(CMD_INSTALL_MODEL, UpdateStatus::Refused, &mut out).unwrap();
        assert_eq!(&out[..n], &[3, 0x01, 0x04, 0]);
        let n = encode_reply(0, UpdateStatus::Malformed, &mut out).unwrap();
        assert_eq!(&out[..n], &[1, 2, 2, 0], "a frame that was no command: command 0");
        for value in 0..=255u8 {
            if let Some(status) = UpdateStatus::from_u8(value) {
                assert_eq!(status as u8, value);
            } else {
                assert!(value > 5, "{value}");
            }
        }
    }
}
