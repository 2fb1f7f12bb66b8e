//! Model blob files: encode + write through [`crate::output`], read through
//! the blob size limit + decode with reasons.

use std::io::Read;
use std::path::Path;

use anyhow::Context;
use rbf_core::Model;
use rbf_core::axis::Axis;
use rbf_core::blob::axes::{self, AxisModels};
use rbf_core::blob::{self, BlobKind, MAX_BLOB_LEN, shared_layout};
use rbf_core::shared_basis::SharedAxisModels;

use crate::output::{Existing, write_bytes_with};
use crate::provenance::ProvenanceRecord;
use crate::reading::input;
use crate::text;

/// Encodes `model` into blob bytes, with `provenance` (format 4) or without (format 2),
/// decoded again and compared: a blob that reaches the disk is one the firmware
/// accepts and that evaluates to the same model.
pub fn encode_model(model: &Model, provenance: Option<&ProvenanceRecord>) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = match provenance {
        Some(p) => p.with_section(|section| blob::encode_with(model, Some(section), &mut buf)),
        None => blob::encode(model, &mut buf),
    }
    .context("encoding the model blob")?;
    buf.truncate(len);
    let back = blob::decode(&buf).context("the encoded blob does not decode")?;
    anyhow::ensure!(back.model == *model, "the encoded blob does not reproduce the model");
    Ok(buf)
}

/// Encodes `model` ([`encode_model`]) and writes it to `path`; returns the
/// blob bytes. An existing file is replaced only with [`Existing::Replace`] (`--force`).
pub fn write_model(path: &Path, model: &Model, existing: Existing) -> anyhow::Result<Vec<u8>> {
    let buf = encode_model(model, None)?;
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
    let len = match decode_file(bytes) {
        Ok((_, len)) => len,
        Err(e) => return Some(e.to_string()),
    };
    (bytes.len() > len).then(|| {
        format!(
            "{} bytes follow the blob's end (the blob is {} bytes, the file {})",
            bytes.len() - len,
            len,
            bytes.len()
        )
    })
}

/// What a model file holds: one model, or one per gyro axis.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelFile {
    /// A single-axis model (format 2), for runs with `rate_dph`.
    Single(Box<Model>),
    /// A multi-axis blob (format 3): a model per axis, for runs with `rate_x_dph` ….
    Axes(Box<AxisModels>),
    /// A shared-basis multi-axis blob (format 3, shared-basis flag): one
    /// basis, an output layer per axis, for runs whose axes read one
    /// thermometer.
    Shared(Box<SharedAxisModels>),
}

impl ModelFile {
    /// The axes with a model (empty for a single-axis model).
    pub fn axes(&self) -> Vec<Axis> {
        match self {
            ModelFile::Single(_) => Vec::new(),
            ModelFile::Axes(m) => m.axes().collect(),
            ModelFile::Shared(m) => m.axes().collect(),
        }
    }

    /// The model of `axis` (`None`: the single-axis model), if the file
    /// has one model for it (a shared-basis file has none: see
    /// [`SharedAxisModels::axis_model`]).
    pub fn model(&self, axis: Option<Axis>) -> Option<&Model> {
        match (self, axis) {
            (ModelFile::Single(m), None) => Some(m),
            (ModelFile::Axes(m), Some(axis)) => m.get(axis),
            _ => None,
        }
    }
}

/// Decodes a blob of either format; with the bytes it occupied.
fn decode_file(bytes: &[u8]) -> Result<(ModelFile, usize), blob::DecodeError> {
    match blob::blob_kind(bytes)? {
        BlobKind::SharedBasis => {
            let mut models = Box::new(SharedAxisModels::EMPTY);
            let len = shared_layout::decode_shared_into(&mut models, bytes)?;
            Ok((ModelFile::Shared(models), len))
        }
        BlobKind::PerAxis => {
            let mut models = Box::new(AxisModels::EMPTY);
            let len = axes::decode_axes_into(&mut models, bytes)?;
            Ok((ModelFile::Axes(models), len))
        }
        BlobKind::SingleAxis => {
            let decoded = blob::decode(bytes)?;
            Ok((ModelFile::Single(Box::new(decoded.model)), decoded.len))
        }
    }
}

/// A blob's CRC-32, its trailer (ISO-HDLC over header and payload): what a
/// unit's health report names as its running model (0 for a blob too short
/// to have one).
pub fn blob_crc32(blob: &[u8]) -> u32 {
    blob.last_chunk::<4>().map_or(0, |t| u32::from_le_bytes(*t))
}

/// The provenance a blob holds and its short model id: `None` for a blob written before
/// provenance existed (formats 2 and 3); an error for a damaged blob or record.
pub fn blob_provenance(bytes: &[u8]) -> anyhow::Result<Option<(ProvenanceRecord, u32)>> {
    match blob::provenance(bytes)? {
        Some(section) => Ok(Some((ProvenanceRecord::from_section(&section)?, section.model_id))),
        None => Ok(None),
    }
}

/// The metadata lines a compensated run carries about the model that
/// compensated it: `# model: FILE` (the file's name, or standard input)
/// and `# model_blob_crc32: 0x…` (as `trainer device status` and a
/// recording name the model a unit runs). `trainer compensate` and
/// `cargo xtask qemu-replay` write them first.
pub fn provenance_lines(model_path: &Path, blob: &[u8]) -> String {
    let name = if model_path == Path::new("-") {
        "standard input".to_owned()
    } else {
        model_path.file_name().map_or_else(
            || model_path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    };
    format!("# model: {name}\n# model_blob_crc32: {:#010x}\n", blob_crc32(blob))
}

/// Reads and validates a model file of either format, refusing a corrupt one with the reason.
pub fn read_model_file(path: &Path) -> anyhow::Result<(ModelFile, Vec<u8>)> {
    let bytes = read_blob(path)?;
    if let Some(reason) = file_problem(&bytes) {
        anyhow::bail!("{}: model refused: {reason}", text::path(path));
    }
    let (file, _) = decode_file(&bytes).map_err(|e| anyhow::anyhow!("{}: model refused: {e}", text::path(path)))?;
    Ok((file, bytes))
}

/// Encodes one model per axis into a multi-axis blob, decoded again and
/// compared (see [`encode_model`]); refused, naming the fix, when the
/// models together pass the [`MAX_BLOB_LEN`] a blob may take.
pub fn encode_axis_models(models: &[(Axis, &Model)], provenance: Option<&ProvenanceRecord>) -> anyhow::Result<Vec<u8>> {
    let mut set = Box::new(AxisModels::EMPTY);
    for (axis, model) in models {
        set.insert(*axis, (*model).clone());
    }
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let encoded = match provenance {
        Some(p) => p.with_section(|section| axes::encode_axes_with(&set, Some(section), &mut buf)),
        None => axes::encode_axes(&set, &mut buf),
    };
    let len = encoded.map_err(|e| {
        let singles: Vec<String> = models
            .iter()
            .map(|(axis, m)| {
                let mut one = vec![0u8; MAX_BLOB_LEN];
                let n = blob::encode(*m, &mut one).map_or("?".to_owned(), |n| n.to_string());
                format!("{} {n} bytes", axis.name())
            })
            .collect();
        anyhow::anyhow!(
            "the axis models do not fit one {MAX_BLOB_LEN}-byte blob ({e}; alone: {}); fit with fewer \
             --max-centers",
            singles.join(", ")
        )
    })?;
    buf.truncate(len);
    let mut back = Box::new(AxisModels::EMPTY);
    axes::decode_axes_into(&mut back, &buf).context("the encoded multi-axis blob does not decode")?;
    anyhow::ensure!(back == set, "the encoded blob does not reproduce the axis models");
    Ok(buf)
}

/// Encodes a shared-basis model into a blob, decoded again and compared
/// (see [`encode_model`]).
pub fn encode_shared_models(
    models: &SharedAxisModels,
    provenance: Option<&ProvenanceRecord>,
) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = match provenance {
        Some(p) => p.with_section(|section| shared_layout::encode_shared_with(models, Some(section), &mut buf)),
        None => shared_layout::encode_shared(models, &mut buf),
    }
    .map_err(|e| anyhow::anyhow!("the shared-basis model does not fit one {MAX_BLOB_LEN}-byte blob: {e}"))?;
    buf.truncate(len);
    let mut back = Box::new(SharedAxisModels::EMPTY);
    shared_layout::decode_shared_into(&mut back, &buf).context("the encoded shared-basis blob does not decode")?;
    anyhow::ensure!(
        *back == *models,
        "the encoded blob does not reproduce the shared-basis model"
    );
    Ok(buf)
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
