//! Model blob files: encode + write through [`crate::output`], read through
//! the blob size limit + decode with reasons.

use std::io::Read;
use std::path::Path;

use anyhow::Context;
use rbf_core::Model;
use rbf_core::blob::{self, MAX_BLOB_LEN};

use crate::input;
use crate::output::{Existing, write_bytes_with};
use crate::text;

/// Encodes `model` into blob bytes, decoded again and compared: a blob that
/// reaches the disk is one the firmware accepts and that evaluates to the
/// same model.
pub fn encode_model(model: &Model) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = blob::encode(model, &mut buf).context("encoding the model blob")?;
    buf.truncate(len);
    let back = blob::decode(&buf).context("the encoded blob does not decode")?;
    anyhow::ensure!(back.model == *model, "the encoded blob does not reproduce the model");
    Ok(buf)
}

/// Encodes `model` ([`encode_model`]) and writes it to `path`; returns the
/// blob bytes. An existing file is replaced only with [`Existing::Replace`] (`--force`).
pub fn write_model(path: &Path, model: &Model, existing: Existing) -> anyhow::Result<Vec<u8>> {
    let buf = encode_model(model)?;
    write_bytes_with(path, &[], existing, &buf)?;
    Ok(buf)
}

/// The bytes of a model file (`-`: standard input), refused past
/// [`MAX_BLOB_LEN`] without reading further: a blob is never larger, and
/// an endless source (`/dev/zero`) is refused at once.
pub fn read_blob(path: &Path) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    input::open(path)
        .and_then(|source| source.take(MAX_BLOB_LEN as u64 + 1).read_to_end(&mut bytes))
        .map_err(|e| anyhow::anyhow!("{}: cannot read model: {e}", text::path(path)))?;
    if bytes.len() > MAX_BLOB_LEN {
        anyhow::bail!(
            "{}: model refused: more than {MAX_BLOB_LEN} bytes, the largest a model blob can be",
            text::path(path)
        );
    }
    Ok(bytes)
}

/// Why `bytes`, a whole model file, is not one valid blob: `None` when it is.
/// Bytes after the blob's end are refused (a file holds one blob; the
/// firmware's flash region may hold erased bytes after it, a file may not).
pub fn file_problem(bytes: &[u8]) -> Option<String> {
    let decoded = match blob::decode(bytes) {
        Ok(d) => d,
        Err(e) => return Some(e.to_string()),
    };
    (bytes.len() > decoded.len).then(|| {
        format!(
            "{} bytes follow the blob's end (the blob is {} bytes, the file {})",
            bytes.len() - decoded.len,
            decoded.len,
            bytes.len()
        )
    })
}

/// Reads and validates a model file, refusing a corrupt one with the reason.
pub fn read_model(path: &Path) -> anyhow::Result<(Model, Vec<u8>)> {
    let bytes = read_blob(path)?;
    if let Some(reason) = file_problem(&bytes) {
        anyhow::bail!("{}: model refused: {reason}", text::path(path));
    }
    let decoded = blob::decode(&bytes).map_err(|e| anyhow::anyhow!("{}: model refused: {e}", text::path(path)))?;
    Ok((decoded.model, bytes))
}
