//! Staging the model blob `trainer fit` writes.

use std::io::Write;

use anyhow::Context;
use trainer::output::{Output, Transaction};
use trainer::text;

/// Writes `blob` into `model_out` (if any), staged in `transaction`.
pub(super) fn write_blob(model_out: Option<Output>, blob: &[u8], transaction: &mut Transaction) -> anyhow::Result<()> {
    if let Some(mut output) = model_out {
        output
            .write_all(blob)
            .with_context(|| format!("{}: write failed", text::path(output.path())))?;
        transaction.add(output);
    }
    Ok(())
}
