//! Unit → host: the bench report, the answer to [`CMD_BENCH`].
//!
//! `COBS([CMD_BENCH, steps u32, min u32, mean u32, max u32]) 0x00`,
//! [`BENCH_REPORT_LEN`] payload bytes, little-endian: the CPU cycles of the
//! sample steps the board timed (firmware's `bench` module times them).

use crate::cobs::cobs_encode;
pub use crate::command::CMD_BENCH;

/// Payload bytes of the bench report: command byte and four u32.
pub const BENCH_REPORT_LEN: usize = 1 + 4 * 4;

/// What the bench report carries: cycle counts at the core clock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BenchReport {
    /// Steps timed.
    pub steps: u32,
    /// Fewest cycles of a step.
    pub min: u32,
    /// Mean cycles per step, rounded down.
    pub mean: u32,
    /// Most cycles of a step.
    pub max: u32,
}

impl BenchReport {
    /// The payload bytes (module docs).
    pub fn to_bytes(&self) -> [u8; BENCH_REPORT_LEN] {
        let mut payload = [0u8; BENCH_REPORT_LEN];
        if let Some((command, fields)) = payload.split_first_mut() {
            *command = CMD_BENCH;
            for (chunk, value) in fields
                .chunks_exact_mut(4)
                .zip([self.steps, self.min, self.mean, self.max])
            {
                chunk.copy_from_slice(&value.to_le_bytes());
            }
        }
        payload
    }

    /// The report in a decoded `payload`; `None` for anything else.
    pub fn from_bytes(payload: &[u8]) -> Option<BenchReport> {
        let p: &[u8; BENCH_REPORT_LEN] = payload.try_into().ok()?;
        let (&CMD_BENCH, fields) = p.split_first()? else {
            return None;
        };
        let mut words = [0u32; 4];
        for (w, chunk) in words.iter_mut().zip(fields.chunks_exact(4)) {
            *w = u32::from_le_bytes(chunk.try_into().ok()?);
        }
        let [steps, min, mean, max] = words;
        Some(BenchReport { steps, min, mean, max })
    }

    /// The COBS-framed report into `out`; the bytes used.
    pub fn encode(&self, out: &mut [u8]) -> Option<usize> {
        cobs_encode(&self.to_bytes(), out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bench_report_is_the_command_byte_then_four_little_endian_words() {
        let report = BenchReport {
            steps: 1000,
            min: 0x0102_0304,
            mean: 2,
            max: u32::MAX,
        };
        let p = report.to_bytes();
        assert_eq!(&p[..9], &[CMD_BENCH, 0xE8, 0x03, 0, 0, 4, 3, 2, 1]);
        assert_eq!(&p[13..], &[0xFF; 4]);
        assert_eq!(BenchReport::from_bytes(&p), Some(report));
        assert_eq!(BenchReport::from_bytes(&p[..16]), None, "one byte short");
        let mut other = p;
        other[0] = 0x01;
        assert_eq!(BenchReport::from_bytes(&other), None, "another command's byte");
    }
}
