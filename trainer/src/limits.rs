//! Limits on every input, so that memory stays bounded whatever a file holds
//! (docs/reliability.md): a file past one of them is refused with a message
//! naming the limit, never read until memory runs out.

/// Longest line of a recorded run, bytes (metadata, comment, header or data
/// row; recorders write a few dozen to a few hundred).
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// Most columns a run's header may name.
pub const MAX_COLUMNS: usize = 1024;

/// Most bytes of metadata, comment and blank lines before the header (they
/// are kept: `compensate` passes them through).
pub const MAX_PREAMBLE_BYTES: usize = 1 << 20;

/// Lowest `# sample_rate_hz` a run may state, Hz (one sample in 1000 s).
pub const MIN_SAMPLE_RATE_HZ: f64 = 1e-3;

/// Highest `# sample_rate_hz` a run may state, Hz (past any gyro's output rate).
pub const MAX_SAMPLE_RATE_HZ: f64 = 1e6;

/// Largest `trainer simulate --params` file, bytes.
pub const MAX_PARAMS_BYTES: u64 = 1 << 20;

/// Bytes of a frame capture read without one valid frame before `decode`
/// gives up on it as not a capture.
pub const MAX_FRAME_SEARCH_BYTES: u64 = 1 << 20;

/// Most contiguous folds per training run (`trainer fit --folds`).
pub const MAX_FOLDS: u64 = 20;

/// Most rows averaged per block (`trainer correlate --block-samples`).
pub const MAX_BLOCK_SAMPLES: u64 = 1 << 24;

/// Human-readable size, for messages naming a limit.
pub fn bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 20 && n % (1 << 20) == 0 => format!("{} MiB", n >> 20),
        n if n >= 1 << 10 && n % (1 << 10) == 0 => format!("{} KiB", n >> 10),
        n => format!("{n} bytes"),
    }
}
