//! The unit's UART as messages: `COBS(payload) 0x00` in both directions.
//!
//! In: output frames (single- or three-axis, either format, gyro-wire's decoders via
//! [`crate::reading::frames::Frame`]), command replies (2 bytes), the boot report of
//! a fault or watchdog reset (11 bytes, tag 0xFB), the bench report (17
//! bytes, tag 0x02) and the health report (116 bytes, tag 0xFC;
//! [`HealthReport::from_bytes`]), each read with the wire protocol's code
//! the firmware encodes with ([`gyro_wire`]). Anything else is damage:
//! counted, and reading goes on at the next 0x00. Out: a command payload,
//! COBS-framed by the same crate's encoder. Every wait ends at a deadline.

use std::io::{Read, Write};
use std::time::Instant;

use gyro_wire::bench::{BENCH_REPORT_LEN, CMD_BENCH};
use gyro_wire::boot::{BOOT_REPORT_LEN, BOOT_REPORT_TAG};
use gyro_wire::cobs::{cobs_decode_in_place, cobs_encode, max_encoded_len};
use gyro_wire::command::{MAX_COMMAND_FRAME_LEN, REPLY_LEN};
use gyro_wire::frame::FrameFormat;
use gyro_wire::health::{HEALTH_FRAME_LEN, HEALTH_REPORT_LEN, HEALTH_REPORT_TAG, HealthReport};

use crate::reading::frames::Frame;

/// Longest message the unit sends on the wire, COBS bytes without the 0x00
/// (the health report's frame, one byte spare); anything longer is damage.
pub const MAX_MESSAGE_LEN: usize = HEALTH_FRAME_LEN;

/// One message from the unit.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// An output frame: one sample, and the format it came in.
    Output(Frame, FrameFormat),
    /// The health report (after every reset, and in answer to the health command).
    Health(HealthReport),
    /// The reply to a command: the command byte and its status.
    Reply {
        /// The command answered (0 for a frame that was no command).
        command: u8,
        /// Its status (`gyro_wire::command::UpdateStatus` for an install).
        status: u8,
    },
    /// The boot report of a fault or watchdog reset (the unit just restarted).
    BootReport,
    /// The bench command's report.
    BenchReport,
}

/// What the link has seen so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkCounters {
    /// Messages decoded.
    pub messages: u64,
    /// Stretches of bytes between delimiters that were no message (noise, a
    /// frame cut by a lost byte, a capture that started mid-frame).
    pub damaged: u64,
    /// Bytes received.
    pub bytes: u64,
}

/// Tells a COBS chunk (without its 0x00) apart; `None` for damage.
pub fn classify(chunk: &[u8]) -> Option<Message> {
    let mut payload = chunk.to_vec();
    let n = cobs_decode_in_place(&mut payload)?;
    let payload = payload.get(..n)?;
    let message = match (n, payload.first().copied()) {
        (REPLY_LEN, Some(command)) => Message::Reply {
            command,
            status: payload[1],
        },
        (HEALTH_REPORT_LEN, Some(HEALTH_REPORT_TAG)) => Message::Health(HealthReport::from_bytes(payload)?),
        (BOOT_REPORT_LEN, Some(BOOT_REPORT_TAG)) => Message::BootReport,
        (BENCH_REPORT_LEN, Some(CMD_BENCH)) => Message::BenchReport,
        _ => {
            let (frame, format) = Frame::decode(&mut chunk.to_vec())?;
            Message::Output(frame, format)
        }
    };
    Some(message)
}

/// The unit's UART: a port that reads with a short timeout (see
/// [`super::port::open`]) and the name messages give it.
pub struct Link<P> {
    port: P,
    name: String,
    read_buf: Vec<u8>,
    read_pos: usize,
    chunk: Vec<u8>,
    /// The chunk outgrew [`MAX_MESSAGE_LEN`]: damage up to the next 0x00.
    overlong: bool,
    counters: LinkCounters,
}

impl<P: Read + Write> Link<P> {
    /// A link over `port`, called `name` in messages.
    pub fn new(port: P, name: &str) -> Self {
        Link {
            port,
            name: crate::text::terminal_safe(name).into_owned(),
            read_buf: Vec::with_capacity(4096),
            read_pos: 0,
            chunk: Vec::with_capacity(MAX_MESSAGE_LEN),
            overlong: false,
            counters: LinkCounters::default(),
        }
    }

    /// The port as messages name it.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// What the link has seen so far.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// Sends `payload` as one COBS frame.
    pub fn send(&mut self, payload: &[u8]) -> anyhow::Result<()> {
        let mut frame = vec![0u8; MAX_COMMAND_FRAME_LEN.max(max_encoded_len(payload.len()))];
        let n = cobs_encode(payload, &mut frame)
            .ok_or_else(|| anyhow::anyhow!("{}: command too long to frame", self.name))?;
        self.send_encoded(&frame[..n])
    }

    /// Sends bytes already framed.
    pub fn send_encoded(&mut self, frame: &[u8]) -> anyhow::Result<()> {
        let name = &self.name;
        self.port
            .write_all(frame)
            .and_then(|()| self.port.flush())
            .map_err(|e| anyhow::anyhow!("{name}: write failed: {e}"))
    }

    /// Drops what was received and not yet read (stale frames from before a command).
    pub fn discard_pending(&mut self) {
        self.read_buf.clear();
        self.read_pos = 0;
        self.chunk.clear();
        self.overlong = false;
    }

    /// The next message, or `None` once `deadline` has passed without one.
    pub fn next(&mut self, deadline: Instant) -> anyhow::Result<Option<Message>> {
        loop {
            while let Some(&byte) = self.read_buf.get(self.read_pos) {
                self.read_pos += 1;
                if let Some(message) = self.take(byte) {
                    return Ok(Some(message));
                }
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            self.fill()?;
        }
    }

    /// One byte into the current chunk; at a delimiter, its message (damage counted).
    fn take(&mut self, byte: u8) -> Option<Message> {
        if byte != 0 {
            if self.chunk.len() < MAX_MESSAGE_LEN {
                self.chunk.push(byte);
            } else {
                self.overlong = true;
            }
            return None;
        }
        let message = if self.overlong || self.chunk.is_empty() {
            None
        } else {
            classify(&self.chunk)
        };
        let damaged = self.overlong || (!self.chunk.is_empty() && message.is_none());
        self.chunk.clear();
        self.overlong = false;
        if damaged {
            self.counters.damaged += 1;
        }
        if message.is_some() {
            self.counters.messages += 1;
        }
        message
    }

    /// Reads what the port has (waits at most its read timeout).
    fn fill(&mut self) -> anyhow::Result<()> {
        self.read_buf.resize(4096, 0);
        self.read_pos = 0;
        let result = self.port.read(&mut self.read_buf);
        let n = match result {
            Ok(0) => {
                self.read_buf.clear();
                anyhow::bail!("{}: the port closed (the unit or its adapter went away)", self.name)
            }
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted
                ) =>
            {
                0
            }
            Err(e) => {
                self.read_buf.clear();
                anyhow::bail!("{}: read failed: {e} (the unit or its adapter went away?)", self.name)
            }
        };
        self.read_buf.truncate(n);
        self.counters.bytes += n as u64;
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::io::Cursor;
    use std::time::Duration;

    use super::*;
    use gyro_wire::frame::{self, OutputFrame};

    /// A port that hands out `input` in reads of at most `slice` bytes and
    /// then times out; keeps what is written.
    pub(crate) struct FakePort {
        pub input: Cursor<Vec<u8>>,
        pub written: Vec<u8>,
        pub slice: usize,
    }

    impl FakePort {
        /// A port that answers with `input`, whatever is sent.
        pub(crate) fn answering(input: Vec<u8>) -> FakePort {
            FakePort {
                input: Cursor::new(input),
                written: Vec::new(),
                slice: 64,
            }
        }
    }

    impl Read for FakePort {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = buf.len().min(self.slice);
            match self.input.read(&mut buf[..n])? {
                0 => Err(std::io::ErrorKind::TimedOut.into()),
                n => Ok(n),
            }
        }
    }

    impl Write for FakePort {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.written.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// Output frame `seq`, COBS-framed with its 0x00.
    pub(crate) fn output_frame(seq: u32) -> Vec<u8> {
        let f = OutputFrame {
            seq,
            rate_dph: 1.5,
            bias_dph: 0.5,
            rate_comp_dph: 1.0,
            temp_c: 25.0,
            flags: 0,
        };
        let mut buf = [0u8; 64];
        let n = frame::encode(&f, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn garbage_is_counted_and_reading_resumes_at_the_next_delimiter() {
        let mut input = output_frame(1);
        input.extend_from_slice(&[0x55; 300]); // noise longer than any message
        input.push(0);
        input.extend_from_slice(&[0x03, 0x99, 0x00]); // a short stretch that is no message
        input.extend_from_slice(&output_frame(2));
        let mut reply = [0u8; 8];
        let n = gyro_wire::command::encode_reply(1, gyro_wire::command::UpdateStatus::Refused, &mut reply).unwrap();
        input.extend_from_slice(&reply[..n]);
        let port = FakePort {
            input: Cursor::new(input),
            written: Vec::new(),
            slice: 7,
        };
        let mut link = Link::new(port, "/dev/fake");
        let deadline = Instant::now() + Duration::from_millis(200);
        let mut seqs = Vec::new();
        let mut replies = Vec::new();
        while let Some(m) = link.next(deadline).unwrap() {
            match m {
                Message::Output(Frame::Single(f), _) => seqs.push(f.seq),
                Message::Reply { command, status } => replies.push((command, status)),
                other => panic!("unexpected {other:?}"),
            }
        }
        assert_eq!(seqs, [1, 2]);
        assert_eq!(replies, [(1, 4)]);
        assert_eq!(link.counters().damaged, 2);
    }

    #[test]
    fn a_health_report_is_read_with_the_firmware_s_layout() {
        let report = HealthReport {
            reset_cause: gyro_wire::health::ResetCause::Watchdog,
            reset_flags: 0x24,
            fault_pc: 0,
            fault_lr: 0,
            counters: Default::default(),
            model: gyro_wire::health::ModelIdentity {
                blob_crc32: 0xDEAD_BEEF,
                sequence: 2,
                model_id: 0x0102_0304,
                serial: [b'S'; 32],
            },
            board_flags: 0,
            firmware_version: gyro_wire::health::FirmwareVersion::CURRENT,
            stack_peak_bytes: 0,
        };
        let mut buf = [0u8; HEALTH_FRAME_LEN];
        let n = report.encode(&mut buf).unwrap();
        assert_eq!(classify(&buf[..n - 1]), Some(Message::Health(report)));
        assert_eq!(classify(&[0x02, 0xFB]), None, "one byte is no message");
    }
}
