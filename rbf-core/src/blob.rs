//! The model blob: what `trainer fit` writes and the firmware reads from flash.
//!
//! ```text
//! offset  size  field
//!      0     4  magic  b"IFOG"
//!      4     2  format version, u16 LE (currently 2)
//!      6     1  model kind (1 = Gaussian RBF, 2 = cubic in T)
//!      7     1  inputs D
//!      8     2  centres K, u16 LE (0 for the cubic)
//!     10     2  reserved, 0
//!     12     4  payload length N, u32 LE
//!     16     N  payload: postcard(common part) ++ postcard(body)
//!   16+N     4  CRC-32/ISO-HDLC of bytes 0 .. 16+N, u32 LE
//! ```
//! The common part holds the feature configuration, units, training input
//! ranges and optional serial number; the body the kind's parameters. The
//! shape in the header is checked against the firmware capacity before the
//! payload is touched. Bytes after the CRC are ignored (erased flash).
//!
//! [`decode`] takes untrusted bytes: it returns a [`DecodeError`] for every
//! defect and never panics.
//!
//! **Provenance** (formats 4 and 5): format 4 is format 2, and format 5 format 3
//! ([`axes`], [`shared_layout`]), with a provenance section at the start of the
//! payload, before the model's bytes (which are exactly those of the older format):
//!
//! ```text
//! offset  size  field (from the payload's start)
//!      0     2  section length P (the bytes after these two), u16 LE
//!      2     4  model id, u32 LE: the short id a unit's health report names
//!      6     1  serial length S (at most SERIAL_CAPACITY), then S bytes UTF-8
//!    7+S   P-5-S  the provenance record (the trainer's: postcard; skipped here)
//! ```
//! A blob of format 2 or 3 still loads: it has no provenance ([`provenance`] is
//! `Ok(None)`). The 16-byte header is written by one function (`RawHeader::write`,
//! through `write_blob`) and read by one (`RawHeader::read`), whatever the layout.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::axis::MAX_AXES;
use crate::features::FeatureConfig;
use crate::model::{BodyParams, Model, ModelBody, ModelError, ModelInfo, ModelKind, SERIAL_CAPACITY};
use crate::poly::Poly3;
use crate::rbf::{RbfShape, RbfStorage};
use crate::{MAX_CENTERS, MAX_INPUTS, MAX_KERNEL_INPUTS};

/// First four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"IFOG";
/// Format version this crate writes and reads.
pub const FORMAT_VERSION: u16 = 2;
/// Header length, bytes.
pub const HEADER_LEN: usize = 16;
/// CRC trailer length, bytes.
pub const CRC_LEN: usize = 4;
/// Upper bound of an encoded blob at full capacity, bytes: size buffers with it.
pub const MAX_BLOB_LEN: usize = 4096;

pub mod axes;
#[cfg(test)]
mod damage;
pub mod shared_layout;

/// CRC-32 (ISO-HDLC) of blobs and of output frames (format 2, `gyro-wire`): one table in flash.
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Physical unit of the model output; stored so a reader can refuse surprises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RateUnit {
    /// Degrees per hour.
    DegPerHour,
}

/// Physical unit of temperature inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TempUnit {
    /// Degrees Celsius.
    Celsius,
}

#[derive(Serialize, Deserialize)]
struct CommonWire {
    features: FeatureConfig,
    rate_unit: RateUnit,
    temp_unit: TempUnit,
    input_min: Vec<f32, MAX_INPUTS>,
    input_max: Vec<f32, MAX_INPUTS>,
    serial: Option<heapless::String<SERIAL_CAPACITY>>,
}

/// The body of an RBF blob as the encoder writes it; the decoder reads the
/// same fields in place ([`read_rbf_in_place`]).
#[derive(Serialize)]
struct RbfWire {
    kernel_inputs: u8,
    offset: Vec<f32, MAX_INPUTS>,
    scale: Vec<f32, MAX_INPUTS>,
    centers: Vec<f32, { MAX_CENTERS * MAX_KERNEL_INPUTS }>,
    widths: Vec<f32, MAX_CENTERS>,
    weights: Vec<f32, MAX_CENTERS>,
    linear: Vec<f32, MAX_INPUTS>,
    constant: f32,
}

#[derive(Serialize, Deserialize)]
struct Poly3Wire {
    ref_temp_c: f32,
    coeffs: [f32; 4],
}

/// Format version of a single-axis blob with a provenance section (format 2 after it).
pub const PROVENANCE_FORMAT_VERSION: u16 = 4;
/// Format version of a multi-axis blob with a provenance section (format 3 after it).
pub const AXES_PROVENANCE_FORMAT_VERSION: u16 = 5;

/// The two payload layouts a header's bytes 6..12 describe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Layout {
    /// One model: kind, inputs, centres (formats 2 and 4).
    Single,
    /// Models per axis: axis mask, shared-basis flag (formats 3 and 5).
    Axes,
}

impl Layout {
    /// The layout a format version names and whether a provenance section leads the payload.
    fn of_version(version: u16) -> Option<(Layout, bool)> {
        match version {
            FORMAT_VERSION => Some((Layout::Single, false)),
            AXES_FORMAT_VERSION => Some((Layout::Axes, false)),
            PROVENANCE_FORMAT_VERSION => Some((Layout::Single, true)),
            AXES_PROVENANCE_FORMAT_VERSION => Some((Layout::Axes, true)),
            _ => None,
        }
    }

    /// The format version of this layout with or without provenance.
    fn version(self, provenance: bool) -> u16 {
        match (self, provenance) {
            (Layout::Single, false) => FORMAT_VERSION,
            (Layout::Axes, false) => AXES_FORMAT_VERSION,
            (Layout::Single, true) => PROVENANCE_FORMAT_VERSION,
            (Layout::Axes, true) => AXES_PROVENANCE_FORMAT_VERSION,
        }
    }
}

/// The 16 bytes in front of every blob, whatever its layout: the one reader and writer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct RawHeader {
    /// Format version.
    pub version: u16,
    /// Bytes 6..12: the layout's own fields.
    pub fields: [u8; 6],
    /// Payload length, bytes.
    pub payload_len: u32,
}

impl RawHeader {
    /// The header at the start of `bytes`: there, and starting with [`MAGIC`].
    pub(crate) fn read(bytes: &[u8]) -> Result<RawHeader, DecodeError> {
        let h: &[u8; HEADER_LEN] = bytes.first_chunk().ok_or(DecodeError::Truncated {
            needed: HEADER_LEN,
            available: bytes.len(),
        })?;
        if h[0..4] != MAGIC {
            return Err(DecodeError::BadMagic);
        }
        let mut fields = [0u8; 6];
        fields.copy_from_slice(&h[6..12]);
        Ok(RawHeader {
            version: u16::from_le_bytes([h[4], h[5]]),
            fields,
            payload_len: u32::from_le_bytes([h[12], h[13], h[14], h[15]]),
        })
    }

    /// Writes the header into the first [`HEADER_LEN`] bytes of `out`.
    fn write(&self, out: &mut [u8]) -> Result<(), EncodeError> {
        let h: &mut [u8; HEADER_LEN] = out.first_chunk_mut().ok_or(EncodeError::BufferTooSmall)?;
        h[0..4].copy_from_slice(&MAGIC);
        h[4..6].copy_from_slice(&self.version.to_le_bytes());
        h[6..12].copy_from_slice(&self.fields);
        h[12..16].copy_from_slice(&self.payload_len.to_le_bytes());
        Ok(())
    }

    /// Total blob length (header + payload + CRC), bytes.
    fn blob_len(&self) -> usize {
        HEADER_LEN + self.payload_len as usize + CRC_LEN
    }
}

/// Where a blob came from, as its provenance section holds it (formats 4 and 5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Provenance<'a> {
    /// The short id of this calibration (a unit's health report carries it).
    pub model_id: u32,
    /// The unit's serial number (empty when none was given).
    pub serial: &'a str,
    /// The rest of the provenance, as the trainer wrote it (postcard; this crate does not read it).
    pub record: &'a [u8],
}

/// Bytes of the provenance section before the serial: length, model id, serial length.
const PROVENANCE_FIXED_LEN: usize = 2 + 4 + 1;

impl<'a> Provenance<'a> {
    /// Writes the section at the start of `out`; its length.
    fn write(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let serial = self.serial.as_bytes();
        if serial.len() > SERIAL_CAPACITY {
            return Err(EncodeError::SerialTooLong);
        }
        let total = PROVENANCE_FIXED_LEN + serial.len() + self.record.len();
        let after_len = u16::try_from(total - 2).map_err(|_| EncodeError::BufferTooSmall)?;
        let section = out.get_mut(..total).ok_or(EncodeError::BufferTooSmall)?;
        section[0..2].copy_from_slice(&after_len.to_le_bytes());
        section[2..6].copy_from_slice(&self.model_id.to_le_bytes());
        section[6] = serial.len() as u8;
        let (serial_area, record_area) = section[PROVENANCE_FIXED_LEN..].split_at_mut(serial.len());
        serial_area.copy_from_slice(serial);
        record_area.copy_from_slice(self.record);
        Ok(total)
    }

    /// Splits the section off the start of `payload`: the provenance and the model's bytes after it.
    fn split(payload: &'a [u8]) -> Result<(Provenance<'a>, &'a [u8]), DecodeError> {
        let (len, rest) = payload.split_first_chunk::<2>().ok_or(DecodeError::Malformed)?;
        let (section, model) = rest
            .split_at_checked(usize::from(u16::from_le_bytes(*len)))
            .ok_or(DecodeError::Malformed)?;
        let (id, rest) = section.split_first_chunk::<4>().ok_or(DecodeError::Malformed)?;
        let (&serial_len, rest) = rest.split_first().ok_or(DecodeError::Malformed)?;
        let serial_len = usize::from(serial_len);
        if serial_len > SERIAL_CAPACITY {
            return Err(DecodeError::Malformed);
        }
        let (serial, record) = rest.split_at_checked(serial_len).ok_or(DecodeError::Malformed)?;
        let serial = core::str::from_utf8(serial).map_err(|_| DecodeError::Malformed)?;
        let provenance = Provenance {
            model_id: u32::from_le_bytes(*id),
            serial,
            record,
        };
        Ok((provenance, model))
    }
}

/// The checked payload of the blob `header` describes: CRC matched, the provenance
/// section (if the version has one) split off; the provenance and the model's bytes.
pub(crate) fn checked_payload<'a>(
    bytes: &'a [u8],
    header: &RawHeader,
) -> Result<(Option<Provenance<'a>>, &'a [u8]), DecodeError> {
    let (_, provenance) = Layout::of_version(header.version).ok_or(DecodeError::UnsupportedVersion(header.version))?;
    let end = HEADER_LEN + header.payload_len as usize;
    crc_status_at(bytes, end)?;
    let payload = bytes.get(HEADER_LEN..end).ok_or(DecodeError::Malformed)?;
    if provenance {
        let (provenance, model) = Provenance::split(payload)?;
        Ok((Some(provenance), model))
    } else {
        Ok((None, payload))
    }
}

/// The provenance of the blob in `bytes`, of any layout: `Ok(None)` for a blob
/// written before provenance existed (formats 2 and 3); the CRC is checked, the
/// models are not decoded.
pub fn provenance(bytes: &[u8]) -> Result<Option<Provenance<'_>>, DecodeError> {
    let header = RawHeader::read(bytes)?;
    if header.blob_len() > MAX_BLOB_LEN {
        return Err(DecodeError::Malformed);
    }
    checked_payload(bytes, &header).map(|(provenance, _)| provenance)
}

/// Writes a whole blob of `layout` into `out`: the header, the provenance section
/// when given, the model bytes `body` writes (it gets the area after the provenance and
/// returns the header's layout fields and its length), and the CRC; the blob's length.
/// Every encoder goes through here; a blob stays within [`MAX_BLOB_LEN`].
pub(crate) fn write_blob(
    out: &mut [u8],
    layout: Layout,
    provenance: Option<&Provenance<'_>>,
    body: impl FnOnce(&mut [u8]) -> Result<([u8; 6], usize), EncodeError>,
) -> Result<usize, EncodeError> {
    let limit = out.len().min(MAX_BLOB_LEN);
    let out = out.get_mut(..limit).ok_or(EncodeError::BufferTooSmall)?;
    let mut at = HEADER_LEN;
    if let Some(p) = provenance {
        at += p.write(out.get_mut(at..).ok_or(EncodeError::BufferTooSmall)?)?;
    }
    let (fields, len) = body(out.get_mut(at..).ok_or(EncodeError::BufferTooSmall)?)?;
    at += len;
    if at + CRC_LEN > out.len() {
        return Err(EncodeError::BufferTooSmall);
    }
    RawHeader {
        version: layout.version(provenance.is_some()),
        fields,
        payload_len: (at - HEADER_LEN) as u32,
    }
    .write(out)?;
    seal(out, at)
}

/// The fixed-size header of a blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Format version.
    pub version: u16,
    /// Model kind code (see [`ModelKind`]).
    pub kind_code: u8,
    /// Number of model inputs D.
    pub inputs: u8,
    /// Number of Gaussian centres K.
    pub centers: u16,
    /// Payload length, bytes (with the provenance section, if any).
    pub payload_len: u32,
    /// A provenance section leads the payload (format 4).
    pub provenance: bool,
}

impl Header {
    /// Total blob length described by this header (header + payload + CRC), bytes.
    pub fn blob_len(&self) -> usize {
        HEADER_LEN + self.payload_len as usize + CRC_LEN
    }

    /// Parses and checks the header: magic, version, kind and shape.
    pub fn parse(bytes: &[u8]) -> Result<Header, DecodeError> {
        let raw = RawHeader::read(bytes)?;
        let provenance = match Layout::of_version(raw.version) {
            Some((Layout::Single, provenance)) => provenance,
            Some((Layout::Axes, _)) => return Err(DecodeError::MultiAxis),
            None => return Err(DecodeError::UnsupportedVersion(raw.version)),
        };
        let f = raw.fields;
        let header = Header {
            version: raw.version,
            kind_code: f[0],
            inputs: f[1],
            centers: u16::from_le_bytes([f[2], f[3]]),
            payload_len: raw.payload_len,
            provenance,
        };
        if ModelKind::from_code(header.kind_code).is_none() {
            return Err(DecodeError::UnknownKind(header.kind_code));
        }
        if header.inputs as usize > MAX_INPUTS || header.centers as usize > MAX_CENTERS {
            return Err(DecodeError::ShapeOverCapacity {
                centers: header.centers,
                inputs: header.inputs,
            });
        }
        if header.blob_len() > MAX_BLOB_LEN {
            return Err(DecodeError::Malformed);
        }
        Ok(header)
    }
}

/// Format version of multi-axis blobs.
pub const AXES_FORMAT_VERSION: u16 = 3;

/// The header of a multi-axis blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AxesHeader {
    /// Axes present: bit 0 = x, bit 1 = y, bit 2 = z.
    pub axis_mask: u8,
    /// Payload length, bytes (with the provenance section, if any).
    pub payload_len: u32,
    /// The axes share one basis ([`shared_layout`]): header byte 7 is
    /// [`SHARED_BASIS_FLAG`] (else 0).
    pub shared_basis: bool,
    /// A provenance section leads the payload (format 5).
    pub provenance: bool,
}

/// Header byte 7 of a format-3 blob whose axes share one basis
/// ([`shared_layout`]); 0 for one model per axis.
pub const SHARED_BASIS_FLAG: u8 = 1;

impl AxesHeader {
    /// Total blob length (header + payload + CRC), bytes.
    pub fn blob_len(&self) -> usize {
        HEADER_LEN + self.payload_len as usize + CRC_LEN
    }

    /// Parses and checks a multi-axis header: magic, version, axis mask,
    /// reserved bytes and the length limit.
    pub fn parse(bytes: &[u8]) -> Result<AxesHeader, DecodeError> {
        let raw = RawHeader::read(bytes)?;
        let Some((Layout::Axes, provenance)) = Layout::of_version(raw.version) else {
            return Err(DecodeError::UnsupportedVersion(raw.version));
        };
        let f = raw.fields;
        let axis_mask = f[0];
        if axis_mask == 0 || axis_mask >> MAX_AXES != 0 {
            return Err(DecodeError::BadAxisMask(axis_mask));
        }
        if f[2..6].iter().any(|&b| b != 0) || !matches!(f[1], 0 | SHARED_BASIS_FLAG) {
            return Err(DecodeError::Malformed);
        }
        let header = AxesHeader {
            axis_mask,
            payload_len: raw.payload_len,
            shared_basis: f[1] == SHARED_BASIS_FLAG,
            provenance,
        };
        if header.blob_len() > MAX_BLOB_LEN {
            return Err(DecodeError::Malformed);
        }
        Ok(header)
    }
}

/// What a blob holds, by its header: the one place a reader recognises a blob's kind
/// (the firmware's model store, the trainer's model files and `trainer inspect` ask here,
/// then call that kind's decoder).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlobKind {
    /// Format 2: one model ([`decode`], [`decode_into`]).
    SingleAxis,
    /// Format 3: one model per axis in the mask ([`axes::decode_axes_into`]).
    PerAxis,
    /// Format 3 with the shared-basis flag: the axes share centres and widths
    /// ([`shared_layout::decode_shared_into`]).
    SharedBasis,
}

/// The kind of the blob in `bytes`, from its header alone (the CRC and the payload are the
/// decoder's to check); the header's defect otherwise: too short, no magic, an unknown
/// version, or a multi-axis header that does not parse.
pub fn blob_kind(bytes: &[u8]) -> Result<BlobKind, DecodeError> {
    let version = RawHeader::read(bytes)?.version;
    match Layout::of_version(version) {
        Some((Layout::Axes, _)) => Ok(if AxesHeader::parse(bytes)?.shared_basis {
            BlobKind::SharedBasis
        } else {
            BlobKind::PerAxis
        }),
        Some((Layout::Single, _)) => Ok(BlobKind::SingleAxis),
        None => Err(DecodeError::UnsupportedVersion(version)),
    }
}

/// Why bytes are not a usable model blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum DecodeError {
    /// Fewer bytes than the header or the stated payload needs.
    Truncated {
        /// Bytes the blob needs.
        needed: usize,
        /// Bytes there were.
        available: usize,
    },
    /// The first four bytes are not `IFOG`: not a model blob (or erased flash).
    BadMagic,
    /// A format version this build cannot read.
    UnsupportedVersion(u16),
    /// A model kind code this build does not know.
    UnknownKind(u8),
    /// The CRC-32 does not match: the blob is corrupt.
    CrcMismatch {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// The header announces more centres or inputs than the firmware can hold.
    ShapeOverCapacity {
        /// Centres announced.
        centers: u16,
        /// Inputs announced.
        inputs: u8,
    },
    /// The payload does not parse as the announced kind, or disagrees with the header.
    Malformed,
    /// The parameters parse but do not form a valid model.
    Model(ModelError),
    /// A multi-axis blob ([`AXES_FORMAT_VERSION`]) where one model was
    /// expected: decode it with [`axes::decode_axes_into`].
    MultiAxis,
    /// A multi-axis blob's axis mask is 0 or names an axis beyond z.
    BadAxisMask(u8),
    /// A shared-basis blob ([`shared_layout`]) where one model per axis is
    /// expected: decode it with [`shared_layout::decode_shared_into`].
    SharedBasis,
    /// A blob with one model per axis (or one model) where a shared-basis
    /// blob is expected.
    NotSharedBasis,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            DecodeError::Truncated { needed, available } => {
                write!(f, "truncated: needs {needed} bytes, has {available}")
            }
            DecodeError::BadMagic => f.write_str("bad magic: not an IFOG model blob"),
            DecodeError::UnsupportedVersion(v) => {
                write!(
                    f,
                    "unsupported format version {v} (this build reads {FORMAT_VERSION} to {AXES_PROVENANCE_FORMAT_VERSION})"
                )
            }
            DecodeError::UnknownKind(k) => write!(f, "unknown model kind code {k}"),
            DecodeError::CrcMismatch { stored, computed } => {
                write!(
                    f,
                    "CRC mismatch: stored {stored:#010x}, computed {computed:#010x} (corrupt blob)"
                )
            }
            DecodeError::ShapeOverCapacity { centers, inputs } => write!(
                f,
                "shape over capacity: {centers} centres × {inputs} inputs (firmware holds {MAX_CENTERS} × {MAX_INPUTS})"
            ),
            DecodeError::Malformed => f.write_str("malformed payload"),
            DecodeError::Model(e) => write!(f, "invalid model: {e}"),
            DecodeError::MultiAxis => {
                f.write_str("a multi-axis blob (one model per gyro axis) where a single-axis model is expected")
            }
            DecodeError::BadAxisMask(m) => write!(f, "axis mask {m:#04x} names no axis or one beyond z"),
            DecodeError::SharedBasis => f.write_str(
                "a shared-basis multi-axis blob (one basis, an output layer per axis) where one model per axis is \
                 expected",
            ),
            DecodeError::NotSharedBasis => f.write_str("not a shared-basis multi-axis blob"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

impl From<ModelError> for DecodeError {
    fn from(e: ModelError) -> Self {
        DecodeError::Model(e)
    }
}

/// Why a model could not be encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum EncodeError {
    /// The output buffer is too small; [`MAX_BLOB_LEN`] always suffices
    /// for one model (a multi-axis blob may not fit it at all).
    BufferTooSmall,
    /// A multi-axis blob without any axis's model.
    NoModel,
    /// The provenance's serial is longer than [`SERIAL_CAPACITY`] bytes.
    SerialTooLong,
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            EncodeError::BufferTooSmall => f.write_str("output buffer too small for the model blob"),
            EncodeError::NoModel => f.write_str("no axis has a model"),
            EncodeError::SerialTooLong => {
                write!(f, "serial number longer than the {SERIAL_CAPACITY} bytes a blob holds")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// A decoded blob: the model and how many bytes it occupied.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    /// The validated model.
    pub model: Model,
    /// Bytes the blob occupied (header + payload + CRC).
    pub len: usize,
}

/// True when the CRC over the blob described by `header` matches.
pub fn crc_status(bytes: &[u8], header: &Header) -> Result<(), DecodeError> {
    crc_status_at(bytes, HEADER_LEN + header.payload_len as usize)
}

/// True when the CRC after the first `body_len` bytes (header and payload) matches them.
pub(crate) fn crc_status_at(bytes: &[u8], body_len: usize) -> Result<(), DecodeError> {
    let need = body_len + CRC_LEN;
    let (Some(body), Some(crc)) = (bytes.get(..body_len), bytes.get(body_len..need)) else {
        return Err(DecodeError::Truncated {
            needed: need,
            available: bytes.len(),
        });
    };
    let Ok(crc) = <[u8; CRC_LEN]>::try_from(crc) else {
        return Err(DecodeError::Truncated {
            needed: need,
            available: bytes.len(),
        });
    };
    let stored = u32::from_le_bytes(crc);
    let computed = CRC32.checksum(body);
    if stored != computed {
        return Err(DecodeError::CrcMismatch { stored, computed });
    }
    Ok(())
}

fn copy_vec<const N: usize>(src: &[f32]) -> Result<Vec<f32, N>, EncodeError> {
    Vec::from_slice(src).map_err(|_| EncodeError::BufferTooSmall)
}

/// The shape of one encoded model (v2 header fields, a v3 section's header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SectionShape {
    /// Model kind code.
    pub kind_code: u8,
    /// Inputs D.
    pub inputs: u8,
    /// Centres K (0 for the cubic).
    pub centers: u16,
}

/// Writes `model`'s payload, postcard(common part) ++ postcard(body), at
/// the start of `out`; returns its shape and length.
pub(crate) fn encode_section<const K: usize>(
    model: &Model<K>,
    out: &mut [u8],
) -> Result<(SectionShape, usize), EncodeError> {
    let dims = model.features().dims();
    let mut input_min = Vec::<f32, MAX_INPUTS>::new();
    let mut input_max = Vec::<f32, MAX_INPUTS>::new();
    for i in 0..dims {
        let (lo, hi) = model.input_range(i).unwrap_or((0.0, 0.0));
        input_min.push(lo).map_err(|_| EncodeError::BufferTooSmall)?;
        input_max.push(hi).map_err(|_| EncodeError::BufferTooSmall)?;
    }
    let common = CommonWire {
        features: *model.features(),
        rate_unit: RateUnit::DegPerHour,
        temp_unit: TempUnit::Celsius,
        input_min,
        input_max,
        serial: model.info().serial.clone(),
    };
    let common_len = postcard::to_slice(&common, out)
        .map_err(|_| EncodeError::BufferTooSmall)?
        .len();
    let body_area = out.get_mut(common_len..).ok_or(EncodeError::BufferTooSmall)?;
    let (centers, body_len) = match model.body() {
        ModelBody::Rbf(net) => {
            let mut centers = Vec::<f32, { MAX_CENTERS * MAX_KERNEL_INPUTS }>::new();
            for j in 0..net.centers_used() {
                centers
                    .extend_from_slice(net.center(j))
                    .map_err(|_| EncodeError::BufferTooSmall)?;
            }
            let wire = RbfWire {
                kernel_inputs: net.kernel_inputs() as u8,
                offset: copy_vec(net.offset())?,
                scale: copy_vec(net.scale())?,
                centers,
                widths: copy_vec(net.widths())?,
                weights: copy_vec(net.weights())?,
                linear: copy_vec(net.linear())?,
                constant: net.constant(),
            };
            let len = postcard::to_slice(&wire, body_area)
                .map_err(|_| EncodeError::BufferTooSmall)?
                .len();
            (net.centers_used() as u16, len)
        }
        ModelBody::Poly3(p) => {
            let wire = Poly3Wire {
                ref_temp_c: p.ref_temp_c,
                coeffs: p.coeffs,
            };
            (
                0,
                postcard::to_slice(&wire, body_area)
                    .map_err(|_| EncodeError::BufferTooSmall)?
                    .len(),
            )
        }
    };
    let shape = SectionShape {
        kind_code: model.kind() as u8,
        inputs: dims as u8,
        centers,
    };
    Ok((shape, common_len + body_len))
}

/// Writes the CRC-32 of `out[..body_len]` after it; returns the blob's length.
pub(crate) fn seal(out: &mut [u8], body_len: usize) -> Result<usize, EncodeError> {
    let total = body_len + CRC_LEN;
    let crc = CRC32.checksum(out.get(..body_len).ok_or(EncodeError::BufferTooSmall)?);
    out.get_mut(body_len..total)
        .ok_or(EncodeError::BufferTooSmall)?
        .copy_from_slice(&crc.to_le_bytes());
    Ok(total)
}

/// Encodes `model` into `out` as a format-2 blob (no provenance); returns the number of
/// bytes written.
pub fn encode<const K: usize>(model: &Model<K>, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_with(model, None, out)
}

/// Encodes `model` into `out`, with `provenance` (format 4) or without (format 2);
/// returns the number of bytes written. The model's bytes are the same either way.
pub fn encode_with<const K: usize>(
    model: &Model<K>,
    provenance: Option<&Provenance<'_>>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    write_blob(out, Layout::Single, provenance, |area| {
        let (shape, len) = encode_section(model, area)?;
        let [c0, c1] = shape.centers.to_le_bytes();
        Ok(([shape.kind_code, shape.inputs, c0, c1, 0, 0], len))
    })
}

/// Length of the header in front of each section of a multi-axis blob, bytes.
pub const SECTION_HEADER_LEN: usize = 8;

/// Writes `model` as a section at the start of `out`: its 8-byte section header (kind
/// u8, inputs D u8, centres K u16 LE, section length L u32 LE) and L bytes, the
/// single-axis payload; the bytes written. The one section writer ([`split_section`] reads).
pub(crate) fn write_section<const K: usize>(model: &Model<K>, out: &mut [u8]) -> Result<usize, EncodeError> {
    let area = out.get_mut(SECTION_HEADER_LEN..).ok_or(EncodeError::BufferTooSmall)?;
    let (shape, len) = encode_section(model, area)?;
    let head: &mut [u8; SECTION_HEADER_LEN] = out.first_chunk_mut().ok_or(EncodeError::BufferTooSmall)?;
    head[0] = shape.kind_code;
    head[1] = shape.inputs;
    head[2..4].copy_from_slice(&shape.centers.to_le_bytes());
    head[4..8].copy_from_slice(&(len as u32).to_le_bytes());
    Ok(SECTION_HEADER_LEN + len)
}

/// Splits the next section off `rest`: the shape its 8-byte header states, its bytes, and
/// what follows it (the per-axis and the shared-basis layouts read sections alike).
pub(crate) fn split_section(rest: &[u8]) -> Result<(SectionShape, &[u8], &[u8]), DecodeError> {
    let (head, tail) = rest
        .split_first_chunk::<SECTION_HEADER_LEN>()
        .ok_or(DecodeError::Malformed)?;
    let shape = SectionShape {
        kind_code: head[0],
        inputs: head[1],
        centers: u16::from_le_bytes([head[2], head[3]]),
    };
    let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]) as usize;
    let (section, tail) = tail.split_at_checked(len).ok_or(DecodeError::Malformed)?;
    Ok((shape, section, tail))
}

/// Decodes and validates a blob from untrusted bytes (trailing bytes ignored).
pub fn decode(bytes: &[u8]) -> Result<Decoded, DecodeError> {
    let mut model = Model::EMPTY;
    let len = decode_into(&mut model, bytes)?;
    Ok(Decoded { model, len })
}

/// [`decode`] in place: validates the blob in `bytes` and builds its model
/// in `model` (the firmware's `static`, so that the model, the largest
/// object the board holds, is not moved by value); returns the bytes the blob occupied. On error `model` is
/// [`Model::EMPTY`] and the reason is returned.
pub fn decode_into(model: &mut Model, bytes: &[u8]) -> Result<usize, DecodeError> {
    // Non-generic: the firmware's decoder is instantiated here, at full
    // capacity, whatever other capacities the crate's users take.
    decode_into_capacity(model, bytes)
}

/// [`decode_into`] for a model of any centre capacity `K`; a blob with
/// more centres is refused ([`DecodeError::ShapeOverCapacity`]).
pub fn decode_into_capacity<const K: usize>(model: &mut Model<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    let result = decode_payload(model, bytes);
    if result.is_err() {
        *model = Model::EMPTY;
    }
    result
}

fn decode_payload<const K: usize>(model: &mut Model<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    let header = Header::parse(bytes)?;
    let (_, payload) = checked_payload(bytes, &RawHeader::read(bytes)?)?;
    let shape = SectionShape {
        kind_code: header.kind_code,
        inputs: header.inputs,
        centers: header.centers,
    };
    decode_section(model, shape, payload)?;
    Ok(header.blob_len())
}

/// Builds `model` from one model's payload (common part ++ body) of the
/// announced `shape`, in place; the CRC is already checked.
pub(crate) fn decode_section<const K: usize>(
    model: &mut Model<K>,
    shape: SectionShape,
    payload: &[u8],
) -> Result<(), DecodeError> {
    if usize::from(shape.centers) > K || usize::from(shape.inputs) > MAX_INPUTS {
        return Err(DecodeError::ShapeOverCapacity {
            centers: shape.centers,
            inputs: shape.inputs,
        });
    }
    let header = shape;
    let (common, rest): (CommonWire, _) = postcard::take_from_bytes(payload).map_err(|_| DecodeError::Malformed)?;
    let dims = common.features.dims();
    if dims != header.inputs as usize || common.input_min.len() != dims || common.input_max.len() != dims {
        return Err(DecodeError::Malformed);
    }
    let mut ranges = [(0.0f32, 0.0f32); MAX_INPUTS];
    for ((r, lo), hi) in ranges.iter_mut().zip(&common.input_min).zip(&common.input_max) {
        *r = (*lo, *hi);
    }
    let ranges = ranges.get(..dims).ok_or(DecodeError::Malformed)?;
    let info = ModelInfo { serial: common.serial };
    match ModelKind::from_code(header.kind_code) {
        Some(ModelKind::Rbf) => {
            let centers = usize::from(header.centers);
            model.assign_rbf_in_place(&common.features, ranges, info, |storage| {
                read_rbf_in_place(rest, centers, storage)
            })?;
        }
        Some(ModelKind::Poly3) => {
            let (w, rest): (Poly3Wire, _) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Malformed)?;
            if header.centers != 0 || !rest.is_empty() {
                return Err(DecodeError::Malformed);
            }
            let poly = Poly3::new(w.ref_temp_c, w.coeffs)?;
            model.assign(&common.features, ranges, BodyParams::Poly3(poly), info)?;
        }
        None => return Err(DecodeError::UnknownKind(header.kind_code)),
    }
    Ok(())
}

/// Reads an RBF body ([`RbfWire`], postcard) straight into a network's
/// arrays: the fields in their wire order, each sequence through
/// [`F32Seq`]; the body must fill `rest` exactly and announce `centers`
/// centres, as the header does. Sequences longer than the wire format
/// allows are refused as malformed, exactly as decoding into `RbfWire`
/// would.
fn read_rbf_in_place(rest: &[u8], centers: usize, storage: RbfStorage<'_>) -> Result<RbfShape, DecodeError> {
    use serde::de::DeserializeSeed;
    let malformed = |_| DecodeError::Malformed;
    let RbfStorage {
        offset,
        scale,
        centers: center_rows,
        widths,
        weights,
        linear,
    } = storage;
    let mut de = postcard::Deserializer::from_bytes(rest);
    let kernel_inputs = usize::from(u8::deserialize(&mut de).map_err(malformed)?);
    let offsets = F32Seq::into_slice(offset, MAX_INPUTS)
        .deserialize(&mut de)
        .map_err(malformed)?;
    let scales = F32Seq::into_slice(scale, MAX_INPUTS)
        .deserialize(&mut de)
        .map_err(malformed)?;
    // Rows of `kernel_inputs` values; a count the network cannot hold is
    // read and refused by the shape check after.
    let m = kernel_inputs.max(1);
    let center_values = F32Seq {
        capacity: MAX_CENTERS * MAX_KERNEL_INPUTS,
        put: |i: usize, v: f32| {
            if let Some(c) = center_rows.get_mut(i / m).and_then(|row| row.get_mut(i % m)) {
                *c = v;
            }
        },
    }
    .deserialize(&mut de)
    .map_err(malformed)?;
    let widths = F32Seq::into_slice(widths, MAX_CENTERS)
        .deserialize(&mut de)
        .map_err(malformed)?;
    let weights = F32Seq::into_slice(weights, MAX_CENTERS)
        .deserialize(&mut de)
        .map_err(malformed)?;
    let linear = F32Seq::into_slice(linear, MAX_INPUTS)
        .deserialize(&mut de)
        .map_err(malformed)?;
    let constant = f32::deserialize(&mut de).map_err(malformed)?;
    let left = de.finalize().map_err(malformed)?;
    if widths != centers || !left.is_empty() {
        return Err(DecodeError::Malformed);
    }
    Ok(RbfShape {
        offsets,
        scales,
        kernel_inputs,
        center_values,
        widths,
        weights,
        linear,
        constant,
    })
}

/// A postcard sequence of f32 handed to `put` (index, value) as it is
/// read, at most `capacity` long; its length.
struct F32Seq<P> {
    capacity: usize,
    put: P,
}

impl<'a> F32Seq<()> {
    /// A sequence written into `out` (at most `capacity` long; values past
    /// `out` are read and dropped).
    fn into_slice(out: &'a mut [f32], capacity: usize) -> F32Seq<impl FnMut(usize, f32) + 'a> {
        F32Seq {
            capacity,
            put: move |i: usize, v: f32| {
                if let Some(slot) = out.get_mut(i) {
                    *slot = v;
                }
            },
        }
    }
}

impl<'de, P: FnMut(usize, f32)> serde::de::DeserializeSeed<'de> for F32Seq<P> {
    type Value = usize;

    fn deserialize<D: serde::Deserializer<'de>>(self, deserializer: D) -> Result<usize, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de, P: FnMut(usize, f32)> serde::de::Visitor<'de> for F32Seq<P> {
    type Value = usize;

    fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "at most {} f32 values", self.capacity)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(mut self, mut seq: A) -> Result<usize, A::Error> {
        let mut n = 0;
        while let Some(v) = seq.next_element::<f32>()? {
            if n == self.capacity {
                return Err(serde::de::Error::invalid_length(n + 1, &self));
            }
            (self.put)(n, v);
            n += 1;
        }
        Ok(n)
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::damage::{assert_every_bit_flip_refused, garbage_never_panics, reseal};
    use super::*;
    use crate::features::FeatureSet;
    use crate::rbf::{RbfNetwork, RbfParams};

    fn rbf_model() -> Model {
        let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
        let net = RbfNetwork::new(&RbfParams {
            offset: &[25.0, 0.0, 0.0],
            scale: &[10.0, 0.5, 12.0],
            kernel_inputs: 3,
            centers: &[0.0, 0.0, 0.0, 1.0, -1.0, 0.5],
            widths: &[0.8, 1.3],
            weights: &[0.02, -0.01],
            linear: &[0.001, 0.003, -0.002],
            constant: 0.05,
        })
        .unwrap();
        let serial = heapless::String::try_from("FOG-0042").unwrap();
        let ranges = [(10.0, 40.0), (-1.5, 1.5), (-60.0, 60.0)];
        Model::new(
            features,
            &ranges,
            ModelBody::Rbf(net),
            ModelInfo { serial: Some(serial) },
        )
        .unwrap()
    }

    fn encoded(model: &Model) -> std::vec::Vec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode(model, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn round_trip_preserves_every_parameter_bit() {
        for model in [rbf_model(), {
            let f = FeatureConfig::single(FeatureSet::Temp, 0.0);
            let body = ModelBody::Poly3(Poly3::new(25.0, [0.1, 0.2, -0.3, 0.004]).unwrap());
            Model::new(f, &[(10.0, 40.0)], body, ModelInfo::default()).unwrap()
        }] {
            let blob = encoded(&model);
            let decoded = decode(&blob).unwrap();
            assert_eq!(decoded.model, model);
            assert_eq!(decoded.len, blob.len());
        }
    }

    #[test]
    fn decode_into_builds_the_model_in_place_and_empties_it_on_a_defect() {
        let rbf = encoded(&rbf_model());
        let poly_model = Model::new(
            FeatureConfig::single(FeatureSet::Temp, 0.0),
            &[(10.0, 30.0)],
            ModelBody::Poly3(Poly3::new(20.0, [0.1, 0.01, 0.0, 0.0]).unwrap()),
            ModelInfo::default(),
        )
        .unwrap();
        let poly = encoded(&poly_model);
        // Over a model of the other kind, then over one of the same kind.
        let mut model = poly_model.clone();
        assert_eq!(decode_into(&mut model, &rbf), Ok(rbf.len()));
        assert_eq!(model, rbf_model());
        assert_eq!(decode_into(&mut model, &poly), Ok(poly.len()));
        assert_eq!(model, poly_model);
        assert_eq!(decode_into(&mut model, &rbf), Ok(rbf.len()));
        assert_eq!(decode_into(&mut model, &rbf), Ok(rbf.len()));
        assert_eq!(model, rbf_model());
        let mut corrupt = rbf.clone();
        corrupt[HEADER_LEN + 3] ^= 0x10;
        assert!(matches!(
            decode_into(&mut model, &corrupt),
            Err(DecodeError::CrcMismatch { .. })
        ));
        assert_eq!(
            model,
            Model::EMPTY,
            "a refused blob leaves the empty model, not a half-built one"
        );
    }

    #[test]
    fn trailing_bytes_such_as_erased_flash_are_ignored() {
        let mut blob = encoded(&rbf_model());
        let n = blob.len();
        blob.extend_from_slice(&[0xFF; 256]);
        assert_eq!(decode(&blob).unwrap().len, n);
    }

    #[test]
    fn every_defect_has_its_own_error() {
        let good = encoded(&rbf_model());
        assert!(matches!(decode(&good[..10]), Err(DecodeError::Truncated { .. })));
        assert!(matches!(
            decode(&good[..good.len() - 1]),
            Err(DecodeError::Truncated { .. })
        ));
        assert_eq!(decode(&[0xFF; 64]), Err(DecodeError::BadMagic));

        let mut v = good.clone();
        v[4] = 9;
        assert_eq!(decode(&v), Err(DecodeError::UnsupportedVersion(9)));
        let mut v = good.clone();
        v[6] = 77;
        assert_eq!(decode(&v), Err(DecodeError::UnknownKind(77)));
        let mut v = good.clone();
        v[8] = 200;
        assert_eq!(
            decode(&v),
            Err(DecodeError::ShapeOverCapacity {
                centers: 200,
                inputs: 3
            })
        );
        let mut v = good.clone();
        v[HEADER_LEN + 3] ^= 0x10;
        assert!(matches!(decode(&v), Err(DecodeError::CrcMismatch { .. })));

        // Header says 1 centre, payload holds 2: refused even with a valid CRC.
        let mut v = good.clone();
        v[8] = 1;
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));

        // A NaN weight, resealed so only the parameter check can catch it.
        let model = rbf_model();
        let ModelBody::Rbf(net) = model.body() else {
            unreachable!()
        };
        let constant_at = good.len() - CRC_LEN - 4;
        assert_eq!(&good[constant_at..constant_at + 4], &net.constant().to_le_bytes());
        let mut v = good.clone();
        v[constant_at..constant_at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Model(ModelError::NonFiniteParameter)));
    }

    /// A response-bank model: 12 filters, a static quartic, no centres,
    /// the linear layer [c₁ … c₄, 1, 1, 1] (the trainer's form).
    fn response_bank_model() -> Model {
        let taus: std::vec::Vec<f32> = (0..12)
            .map(|k| 10.0 * 2.0f32.powi(k))
            .map(|t| t.min(86_400.0))
            .collect();
        let mut bank = crate::response_bank::ResponseBank::new(&taus[..11], 22.5, -5.0, 50.0, 4).unwrap();
        for (j, row) in bank.weights.iter_mut().enumerate() {
            for (k, w) in row.iter_mut().take(11).enumerate() {
                *w = (j as f32 + 1.0) * 0.125 - k as f32 * 0.015_625;
            }
        }
        let net = RbfNetwork::new(&RbfParams {
            offset: &[0.0; 9],
            scale: &[1.0; 9],
            kernel_inputs: 1,
            centers: &[],
            widths: &[],
            weights: &[],
            linear: &[0.25, -0.0625, 0.001, -0.000_01, 1.0, 1.0, 1.0, 1.0, 1.0],
            constant: -0.5,
        })
        .unwrap();
        let ranges = [
            (-27.5, 27.5),
            (0.0, 756.25),
            (-20_796.875, 20_796.875),
            (0.0, 571_914.06),
            (-3.0, 3.0),
            (-50.0, 50.0),
            (-900.0, 900.0),
            (-5.0, 5.0),
            (-7.0, 7.0),
        ];
        Model::new(
            FeatureConfig::response_bank(bank),
            &ranges,
            ModelBody::Rbf(net),
            ModelInfo::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_response_bank_model_round_trips_and_a_damaged_one_is_refused() {
        let model = response_bank_model();
        let blob = encoded(&model);
        let decoded = decode(&blob).unwrap();
        assert_eq!(decoded.model, model);
        assert_eq!(encoded(&decoded.model), blob, "re-encodes to the same bytes");
        assert_every_bit_flip_refused(&blob, decode);
        garbage_never_panics(&blob, 0x0bad_cafe, 5_000, 4, decode);
        // The set's tag (variant 8, after the lag bank's 7), then the filter
        // count, the static degree, T₀ and the range, the 12 time constants.
        assert_eq!(blob[HEADER_LEN], 8);
        let filters_at = HEADER_LEN + 1;
        assert_eq!(blob[filters_at..filters_at + 2], [11, 4]);
        assert_eq!(blob[filters_at + 2..filters_at + 6], 22.5f32.to_le_bytes());
        let taus_at = filters_at + 2 + 3 * 4;
        assert_eq!(blob[taus_at..taus_at + 4], 10.0f32.to_le_bytes());
        // An invalid bank with a good CRC: refused for its parameters (too
        // many filters, none, an unused time constant not 0).
        for (at, byte) in [(filters_at, 13), (filters_at, 0), (taus_at + 11 * 4 + 3, 0x3f)] {
            let mut v = blob.clone();
            v[at] = byte;
            reseal(&mut v);
            assert_eq!(
                decode(&v).map(|_| ()),
                Err(DecodeError::Model(ModelError::InvalidParameter)),
                "byte {at} = {byte:#x}"
            );
        }
    }

    /// A lag-bank model as the default fit writes them.
    fn lag_bank_model() -> Model {
        use crate::lag_bank::{GainOf, LagBank};
        let mut bank = LagBank::plain(&[30.0, 120.0, 480.0, 1920.0, 7680.0], 25.0).unwrap();
        bank.coil_lag_min[..5].copy_from_slice(&[-1.5, -6.0, 2.25, -30.0, 0.5]);
        bank.gain_per_c = 0.0125;
        bank.gain_per_c2 = -0.000_25;
        bank.static_degree = 3;
        bank.coil_min_c = -10.0;
        bank.coil_max_c = 60.0;
        bank.gain_of = GainOf::Coil;
        let net = RbfNetwork::new(&RbfParams {
            offset: &[25.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            scale: &[10.0, 100.0, 1000.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            kernel_inputs: 1,
            centers: &[0.5],
            widths: &[0.75],
            weights: &[0.0625],
            linear: &[0.01, 0.002, -0.0005, 0.125, -0.25, 0.5, 0.75, -1.0],
            constant: 0.375,
        })
        .unwrap();
        let ranges = [
            (-10.0, 60.0),
            (0.0, 1225.0),
            (-42875.0, 42875.0),
            (-2.0, 2.0),
            (-2.0, 2.0),
            (-1.5, 1.5),
            (-1.0, 1.0),
            (-0.5, 0.5),
        ];
        Model::new(
            FeatureConfig::lag_bank(bank),
            &ranges,
            ModelBody::Rbf(net),
            ModelInfo::default(),
        )
        .unwrap()
    }

    /// [`lag_bank_model`] as the encoder wrote it before the response bank
    /// existed (commit cc4a648).
    const LAG_BANK_BLOB_HEX: &str = "49464f4702000108010000001f010000070000f0410000f0420000f0430000f0440000f045000000000000000000000000050000c0bf0000c0c0000010400000f0c10000003f0000000000000000000000000000c841cdcc4c3c6f1283b983000020c1000070420000f0410000000000000000000008000020c100000000007b27c7000000c0000000c00000c0bf000080bf000000bf080000704200209944007b274700000040000000400000c03f0000803f0000003f0001080000c8410000000000000000000000000000000000000000000000000000000008000020410000c84200007a440000803f0000803f0000803f0000803f0000803f010000003f010000403f010000803d080ad7233c6f12033b6f1203ba0000003e000080be0000003f0000403f000080bf0000c03e5f6473ec";

    #[test]
    fn a_lag_bank_blob_written_before_the_response_bank_decodes_and_re_encodes_unchanged() {
        let hex = LAG_BANK_BLOB_HEX.as_bytes();
        let golden: std::vec::Vec<u8> = hex
            .chunks(2)
            .map(|c| u8::from_str_radix(core::str::from_utf8(c).unwrap(), 16).unwrap())
            .collect();
        let decoded = decode(&golden).unwrap();
        assert_eq!(decoded.model, lag_bank_model());
        assert_eq!(encoded(&decoded.model), golden);
    }

    fn provenance_of<'a>(serial: &'a str, record: &'a [u8]) -> Provenance<'a> {
        Provenance {
            model_id: 0x1a2b_3c4d,
            serial,
            record,
        }
    }

    /// Removes the provenance section of a format-4/5 blob and writes the older
    /// version and length back: what the blob would be without provenance.
    fn without_provenance(blob: &[u8]) -> std::vec::Vec<u8> {
        let section = 2 + usize::from(u16::from_le_bytes([blob[HEADER_LEN], blob[HEADER_LEN + 1]]));
        let mut v = blob[..HEADER_LEN].to_vec();
        v.extend_from_slice(&blob[HEADER_LEN + section..blob.len() - CRC_LEN]);
        let version = u16::from_le_bytes([v[4], v[5]]) - 2;
        v[4..6].copy_from_slice(&version.to_le_bytes());
        let payload = (v.len() - HEADER_LEN) as u32;
        v[12..16].copy_from_slice(&payload.to_le_bytes());
        v.extend_from_slice(&[0; CRC_LEN]);
        reseal(&mut v);
        v
    }

    #[test]
    fn a_blob_with_provenance_holds_the_same_model_bytes_and_gives_its_provenance_back() {
        let model = rbf_model();
        let record = b"fitted 2026-11-29T07:00:00Z";
        let given = provenance_of("FOG-0042", record);
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode_with(&model, Some(&given), &mut buf).unwrap();
        let blob = &buf[..n];
        assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), PROVENANCE_FORMAT_VERSION);
        assert_eq!(decode(blob).unwrap().model, model);
        assert_eq!(provenance(blob), Ok(Some(given)));
        assert_eq!(blob_kind(blob), Ok(BlobKind::SingleAxis));
        assert_eq!(
            without_provenance(blob),
            encoded(&model),
            "the model's bytes are those of the format-2 blob"
        );
        // A format-2 blob (every blob written before provenance) has none.
        assert_eq!(provenance(&encoded(&model)), Ok(None));
        assert_every_bit_flip_refused(blob, decode);
        assert_every_bit_flip_refused(blob, |b| provenance(b).map(|_| ()));
        garbage_never_panics(blob, 0x5eed_0004, 5_000, 3, |b| provenance(b).map(|_| ()));
        garbage_never_panics(blob, 0x5eed_0005, 5_000, 3, decode);
    }

    #[test]
    fn a_serial_longer_than_the_blob_holds_is_refused_and_a_lying_section_length_is_malformed() {
        let long = "S".repeat(SERIAL_CAPACITY + 1);
        let mut buf = [0u8; MAX_BLOB_LEN];
        assert_eq!(
            encode_with(&rbf_model(), Some(&provenance_of(&long, b"")), &mut buf),
            Err(EncodeError::SerialTooLong)
        );
        let n = encode_with(&rbf_model(), Some(&provenance_of("FOG-1", b"r")), &mut buf).unwrap();
        let mut v = buf[..n].to_vec();
        v[HEADER_LEN..HEADER_LEN + 2].copy_from_slice(&4000u16.to_le_bytes());
        reseal(&mut v);
        assert_eq!(provenance(&v), Err(DecodeError::Malformed));
        assert_eq!(decode(&v).map(|_| ()), Err(DecodeError::Malformed));
    }

    #[test]
    fn every_single_bit_flip_is_refused() {
        assert_every_bit_flip_refused(&encoded(&rbf_model()), decode);
    }

    #[test]
    fn arbitrary_garbage_never_panics() {
        garbage_never_panics(&encoded(&rbf_model()), 0x1234_5678, 20_000, 4, decode);
    }
}
