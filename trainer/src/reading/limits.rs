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

/// Fewest data rows a recorded run may hold (the period needs a time step).
pub const MIN_RUN_ROWS: u64 = 2;

/// Longest run `trainer simulate` writes, hours (with `--hours` or a
/// `--chamber-profile` alike).
pub const MAX_SIM_HOURS: f64 = 1000.0;

/// Most bytes `trainer simulate` writes, as estimated before it starts
/// (rows × columns × [`SIM_BYTES_PER_FIELD`]): 4 GiB.
pub const MAX_SIM_OUTPUT_BYTES: u64 = 4 << 30;

/// Bytes a simulated field takes with its comma, at most (`-12.3456789,`).
pub const SIM_BYTES_PER_FIELD: u64 = 12;

/// Largest `trainer simulate --chamber-profile` file, bytes (a set point a
/// second for 1000 h fits).
pub const MAX_PROFILE_BYTES: u64 = 128 << 20;

/// Largest `trainer simulate --params` file, bytes.
pub const MAX_PARAMS_BYTES: u64 = 1 << 20;

/// Longest recording `trainer device record` takes (`--seconds`, `--hours`), hours.
pub const MAX_RECORD_HOURS: f64 = 1000.0;

/// Most seconds between `trainer device record`'s progress lines.
pub const MAX_PROGRESS_S: f64 = 3600.0;

/// Fewest seconds between `trainer device record`'s progress lines.
pub const MIN_PROGRESS_S: f64 = 0.01;

/// Bytes of a frame capture read without one valid frame before `decode`
/// gives up on it as not a capture.
pub const MAX_FRAME_SEARCH_BYTES: u64 = 1 << 20;

/// Most contiguous folds per training run (`trainer fit --folds`).
pub const MAX_FOLDS: u64 = 20;

/// Most rows averaged per block (`trainer correlate --block-samples`).
pub const MAX_BLOCK_SAMPLES: u64 = 1 << 24;

/// Shortest averaging block (`fit`, `blocks --block-s`), s.
pub const MIN_BLOCK_S: f64 = 1e-3;

/// Longest averaging block, s (a day).
pub const MAX_BLOCK_S: f64 = 86_400.0;

/// Most blocks `trainer blocks` writes per run (it holds them in memory,
/// about 100 bytes each).
pub const MAX_BLOCKS_WRITTEN: usize = 1 << 20;

/// Refuses a `--block-s` outside [`MIN_BLOCK_S`] … [`MAX_BLOCK_S`].
pub fn check_block_s(block_s: f64) -> anyhow::Result<()> {
    anyhow::ensure!(
        block_s.is_finite() && (MIN_BLOCK_S..=MAX_BLOCK_S).contains(&block_s),
        "--block-s {block_s}: must be {MIN_BLOCK_S} … {MAX_BLOCK_S} s"
    );
    Ok(())
}

/// Human-readable size, for messages naming a limit.
pub fn bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 30 && n % (1 << 30) == 0 => format!("{} GiB", n >> 30),
        n if n >= 1 << 20 && n % (1 << 20) == 0 => format!("{} MiB", n >> 20),
        n if n >= 1 << 10 && n % (1 << 10) == 0 => format!("{} KiB", n >> 10),
        n => format!("{n} bytes"),
    }
}
