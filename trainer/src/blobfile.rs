//! Model blob files: encode + atomic write, read + decode with reasons.

use std::path::Path;

use anyhow::Context;
use rbf_core::Model;
use rbf_core::blob::{self, MAX_BLOB_LEN};

use crate::output::{Existing, write_bytes_with};

/// Encodes `model` and writes it to `path` atomically; returns the blob bytes.
/// An existing file is replaced only with [`Existing::Replace`] (`--force`).
///
/// The bytes are decoded again before writing, so a blob that reaches the disk
/// is one the firmware accepts and that evaluates to the same model.
pub fn write_model(path: &Path, model: &Model, existing: Existing) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = blob::encode(model, &mut buf).context("encoding the model blob")?;
    buf.truncate(len);
    let back = blob::decode(&buf).context("the encoded blob does not decode")?;
    anyhow::ensure!(back.model == *model, "the encoded blob does not reproduce the model");
    write_bytes_with(path, existing, &buf)?;
    Ok(buf)
}

/// Reads and validates a model blob, refusing a corrupt one with the reason.
pub fn read_model(path: &Path) -> anyhow::Result<(Model, Vec<u8>)> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read model", path.display()))?;
    let decoded = blob::decode(&bytes).map_err(|e| anyhow::anyhow!("{}: model refused: {e}", path.display()))?;
    Ok((decoded.model, bytes))
}
