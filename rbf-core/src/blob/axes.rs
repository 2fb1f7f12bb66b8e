//! The multi-axis model blob: one model per gyro axis (up to x, y, z of an
//! IMU), one header, one CRC.
//!
//! ```text
//! offset  size  field
//!      0     4  magic  b"IFOG"
//!      4     2  format version, u16 LE (3: multi-axis; 5: with provenance, see [`super`])
//!      6     1  axis mask: bit 0 = x, bit 1 = y, bit 2 = z (at least one)
//!      7     5  reserved, 0
//!     12     4  payload length N, u32 LE
//!     16     N  payload: per axis in the mask, x first, an 8-byte section
//!               header (kind u8, inputs D u8, centres K u16 LE, section
//!               length L u32 LE) and L bytes: postcard(common part) ++
//!               postcard(body), exactly a version-2 payload
//!   16+N     4  CRC-32/ISO-HDLC of bytes 0 .. 16+N, u32 LE
//! ```
//! The whole blob stays within [`MAX_BLOB_LEN`](super::MAX_BLOB_LEN). Each section is encoded
//! and decoded by the single-axis code ([`super::encode`], [`super::decode_into`]
//! share it), so an axis's model is bit for bit what a single-axis blob of
//! it would give.
//!
//! [`AxisModels`] holds the decoded models with a centre capacity `K` per
//! axis chosen by the user of the crate: RAM is `3 × size_of::<Model<K>>()`
//! (see `docs/blob-format.md` for the figures), so a firmware picks the
//! smallest `K` its blobs need. [`decode_axes_into`] builds them in place.

// The multi-axis header lives with the other headers in `blob`, so that
// `blob` does not import its child; re-exported here, where it was.
pub use super::{AXES_FORMAT_VERSION, AxesHeader, SECTION_HEADER_LEN, SHARED_BASIS_FLAG};
use super::{
    BlobKind, DecodeError, EncodeError, Layout, Provenance, RawHeader, checked_payload, decode_section, split_section,
    write_blob, write_section,
};
use crate::MAX_CENTERS;
use crate::axis::{Axis, AxisSet, MAX_AXES};
use crate::model::Model;

/// The models of a multi-axis IMU, one per axis present, each with room
/// for `K` Gaussian centres; a model is read through `&self` and never
/// changes while it runs.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisModels<const K: usize = MAX_CENTERS> {
    models: [Model<K>; MAX_AXES],
    mask: AxisSet,
}

impl<const K: usize> AxisModels<K> {
    /// No axis: every model [`Model::EMPTY`] (all bits zero: a `static`
    /// holding it costs no flash).
    pub const EMPTY: Self = AxisModels {
        models: [Model::EMPTY, Model::EMPTY, Model::EMPTY],
        mask: AxisSet::EMPTY,
    };

    /// The model of `axis`, if the blob had one.
    pub fn get(&self, axis: Axis) -> Option<&Model<K>> {
        self.models.get(axis.index()).filter(|_| self.has(axis))
    }

    /// True when `axis` has a model.
    pub fn has(&self, axis: Axis) -> bool {
        self.mask.contains(axis)
    }

    /// The axes with a model, x first.
    pub fn axes(&self) -> impl Iterator<Item = Axis> + '_ {
        self.mask.iter()
    }

    /// Axes present as a bit mask (bit 0 = x).
    pub fn mask(&self) -> u8 {
        self.mask.bits()
    }

    /// Sets the model of `axis` (host tools assembling a blob).
    pub fn insert(&mut self, axis: Axis, model: Model<K>) {
        if let Some(slot) = self.models.get_mut(axis.index()) {
            *slot = model;
            self.mask.insert(axis);
        }
    }
}

/// Encodes the models of `axes` into `out` as one multi-axis blob (format 3, no
/// provenance); returns the number of bytes written. [`EncodeError::NoModel`] when there
/// is no axis, [`EncodeError::BufferTooSmall`] when the blob would pass `out` or
/// [`super::MAX_BLOB_LEN`].
pub fn encode_axes<const K: usize>(axes: &AxisModels<K>, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_axes_with(axes, None, out)
}

/// [`encode_axes`] with `provenance` (format 5) or without (format 3); the models'
/// bytes are the same either way.
pub fn encode_axes_with<const K: usize>(
    axes: &AxisModels<K>,
    provenance: Option<&Provenance<'_>>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    if axes.mask.is_empty() {
        return Err(EncodeError::NoModel);
    }
    write_blob(out, Layout::Axes, provenance, |area| {
        let mut at = 0;
        for axis in axes.axes() {
            let section = area.get_mut(at..).ok_or(EncodeError::BufferTooSmall)?;
            at += write_section(&axes.models[axis.index()], section)?;
        }
        Ok(([axes.mask.bits(), 0, 0, 0, 0, 0], at))
    })
}

/// Decodes and validates a multi-axis blob from untrusted bytes into
/// `axes`, in place (the firmware's `static`: no model is moved by value);
/// returns the bytes the blob occupied (trailing bytes are ignored). On
/// error `axes` is [`AxisModels::EMPTY`] and the reason is returned; it
/// never panics.
pub fn decode_axes_into<const K: usize>(axes: &mut AxisModels<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    let result = decode_axes_payload(axes, bytes);
    if result.is_err() {
        *axes = AxisModels::EMPTY;
    }
    result
}

/// The length of the blob in `bytes` of any kind by its header (header, payload and CRC;
/// the CRC is not checked), for a store that copies or scans blobs.
pub fn blob_len(bytes: &[u8]) -> Result<usize, DecodeError> {
    match super::blob_kind(bytes)? {
        BlobKind::PerAxis | BlobKind::SharedBasis => AxesHeader::parse(bytes).map(|h| h.blob_len()),
        BlobKind::SingleAxis => super::Header::parse(bytes).map(|h| h.blob_len()),
    }
}

/// Decodes a blob of either per-axis kind into `axes`, in place: a multi-axis blob
/// as [`decode_axes_into`], a single-axis (format 2) blob into axis x alone,
/// so one `AxisModels<K>` (one capacity, one copy of the decoder and the
/// evaluation in flash) serves both. Returns the bytes the blob occupied;
/// on error `axes` is [`AxisModels::EMPTY`].
pub fn decode_any_into<const K: usize>(axes: &mut AxisModels<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    match super::blob_kind(bytes) {
        Ok(BlobKind::SingleAxis) => {}
        Ok(BlobKind::PerAxis | BlobKind::SharedBasis) => return decode_axes_into(axes, bytes),
        Err(e) => {
            *axes = AxisModels::EMPTY;
            return Err(e);
        }
    }
    let [x, y, z] = &mut axes.models;
    *y = Model::EMPTY;
    *z = Model::EMPTY;
    axes.mask = AxisSet::EMPTY;
    let len = super::decode_into_capacity(x, bytes)?;
    axes.mask.insert(Axis::X);
    Ok(len)
}

fn decode_axes_payload<const K: usize>(axes: &mut AxisModels<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    let header = AxesHeader::parse(bytes)?;
    if header.shared_basis {
        return Err(DecodeError::SharedBasis);
    }
    let (_, mut rest) = checked_payload(bytes, &RawHeader::read(bytes)?)?;
    axes.mask = AxisSet::EMPTY;
    for axis in Axis::ALL {
        let slot = &mut axes.models[axis.index()];
        if header.axis_mask & (1 << axis.index()) == 0 {
            *slot = Model::EMPTY;
            continue;
        }
        let (shape, section, tail) = split_section(rest)?;
        decode_section(slot, shape, section)?;
        rest = tail;
    }
    if !rest.is_empty() {
        return Err(DecodeError::Malformed);
    }
    axes.mask = AxisSet::from_bits(header.axis_mask);
    Ok(header.blob_len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blob::damage::{assert_every_bit_flip_refused, garbage_never_panics, reseal};
    use crate::blob::{self, decode};
    use crate::blob::{HEADER_LEN, MAX_BLOB_LEN};
    use crate::features::{FeatureConfig, FeatureSet};
    use crate::model::ModelInfo;
    use crate::poly::Poly3;
    use crate::rbf::RbfParams;

    /// An RBF model of `centers` centres over (T, ΔT, T×ΔT), its weights scaled by `gain`.
    fn rbf_model<const K: usize>(centers: usize, gain: f32) -> Model<K> {
        let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
        let c: std::vec::Vec<f32> = (0..centers * 3).map(|i| (i as f32 * 0.37).sin()).collect();
        let widths: std::vec::Vec<f32> = (0..centers).map(|j| 0.8 + 0.01 * j as f32).collect();
        let weights: std::vec::Vec<f32> = (0..centers).map(|j| gain * (0.02 - 0.001 * j as f32)).collect();
        let params = RbfParams {
            offset: &[25.0, 0.0, 0.0],
            scale: &[10.0, 0.5, 12.0],
            kernel_inputs: 3,
            centers: &c,
            widths: &widths,
            weights: &weights,
            linear: &[0.001, 0.003, -0.002],
            constant: 0.05,
        };
        let mut model = Model::<K>::EMPTY;
        let ranges = [(10.0, 40.0), (-1.5, 1.5), (-60.0, 60.0)];
        model
            .assign(
                &features,
                &ranges,
                crate::model::BodyParams::Rbf(&params),
                ModelInfo::default(),
            )
            .unwrap();
        model
    }

    fn poly_model<const K: usize>() -> Model<K> {
        let mut model = Model::<K>::EMPTY;
        let body = crate::model::BodyParams::Poly3(Poly3::new(25.0, [0.1, 0.2, -0.3, 0.004]).unwrap());
        let f = FeatureConfig::single(FeatureSet::Temp, 0.0);
        model.assign(&f, &[(10.0, 40.0)], body, ModelInfo::default()).unwrap();
        model
    }

    fn three_axes() -> AxisModels {
        let mut axes = AxisModels::EMPTY;
        axes.insert(Axis::X, rbf_model(32, 1.0));
        axes.insert(Axis::Y, poly_model());
        axes.insert(Axis::Z, rbf_model(20, -2.0));
        axes
    }

    fn encoded<const K: usize>(axes: &AxisModels<K>) -> std::vec::Vec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode_axes(axes, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn three_axes_round_trip_bit_for_bit_each_as_its_single_axis_blob_would() {
        let axes = three_axes();
        let blob = encoded(&axes);
        assert!(blob.len() <= MAX_BLOB_LEN);
        let mut back = AxisModels::EMPTY;
        assert_eq!(decode_axes_into(&mut back, &blob), Ok(blob.len()));
        assert_eq!(back, axes);
        assert_eq!(back.axes().collect::<std::vec::Vec<_>>(), Axis::ALL);
        // Each section is the single-axis payload: the model decoded from
        // its own version-2 blob is the same.
        for axis in Axis::ALL {
            let model = axes.get(axis).unwrap();
            let mut single = [0u8; MAX_BLOB_LEN];
            let n = blob::encode(model, &mut single).unwrap();
            assert_eq!(decode(&single[..n]).unwrap().model, *model, "axis {axis:?}");
        }
        // Two axes, and a smaller capacity per axis.
        let mut xz = AxisModels::<32>::EMPTY;
        xz.insert(Axis::X, rbf_model(32, 0.5));
        xz.insert(Axis::Z, poly_model());
        let blob = encoded(&xz);
        let mut back = AxisModels::<32>::EMPTY;
        assert_eq!(decode_axes_into(&mut back, &blob), Ok(blob.len()));
        assert_eq!(back, xz);
        assert!(back.get(Axis::Y).is_none() && back.get(Axis::Z).is_some());
    }

    #[test]
    fn a_multi_axis_blob_with_provenance_decodes_to_the_same_models() {
        let axes = three_axes();
        let provenance = blob::Provenance {
            model_id: 7,
            serial: "IMU-3",
            record: &[1, 2, 3],
        };
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode_axes_with(&axes, Some(&provenance), &mut buf).unwrap();
        let with = &buf[..n];
        assert_eq!(
            u16::from_le_bytes([with[4], with[5]]),
            blob::AXES_PROVENANCE_FORMAT_VERSION
        );
        let plain = encoded(&axes);
        assert_eq!(with[HEADER_LEN + 7 + 5 + 3..n - 4], plain[HEADER_LEN..plain.len() - 4]);
        let mut back = AxisModels::EMPTY;
        assert_eq!(decode_axes_into(&mut back, with), Ok(n));
        assert_eq!(back, axes);
        assert_eq!(blob_len(with), Ok(n));
        assert_eq!(blob::blob_kind(with), Ok(BlobKind::PerAxis));
        assert_eq!(blob::provenance(with), Ok(Some(provenance)));
        assert_eq!(decode(with), Err(DecodeError::MultiAxis));
    }

    #[test]
    fn single_and_multi_axis_readers_refuse_each_other_with_a_reason() {
        let blob = encoded(&three_axes());
        assert_eq!(decode(&blob), Err(DecodeError::MultiAxis));
        let mut single = [0u8; MAX_BLOB_LEN];
        let n = blob::encode(&rbf_model::<{ MAX_CENTERS }>(4, 1.0), &mut single).unwrap();
        let mut axes = three_axes();
        assert_eq!(
            decode_axes_into(&mut axes, &single[..n]),
            Err(DecodeError::UnsupportedVersion(2))
        );
        assert_eq!(axes, AxisModels::EMPTY, "a refused blob leaves no model behind");
    }

    #[test]
    fn every_defect_has_its_own_error_and_none_panics() {
        let good = encoded(&three_axes());
        let mut axes = AxisModels::<{ MAX_CENTERS }>::EMPTY;
        let mut decode = |bytes: &[u8]| decode_axes_into(&mut axes, bytes).map(|_| ());
        assert!(matches!(decode(&good[..10]), Err(DecodeError::Truncated { .. })));
        assert!(matches!(
            decode(&good[..good.len() - 1]),
            Err(DecodeError::Truncated { .. })
        ));
        assert_eq!(decode(&[0xFF; 64]), Err(DecodeError::BadMagic));
        for mask in [0u8, 0b1000, 0xFF] {
            let mut v = good.clone();
            v[6] = mask;
            reseal(&mut v);
            assert_eq!(decode(&v), Err(DecodeError::BadAxisMask(mask)));
        }
        // The mask names two axes, the payload holds three sections.
        let mut v = good.clone();
        v[6] = 0b011;
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        // A section longer than the payload.
        let mut v = good.clone();
        v[HEADER_LEN + 4..HEADER_LEN + 8].copy_from_slice(&u32::MAX.to_le_bytes());
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        // A payload length past the 4 KiB limit.
        let mut v = good.clone();
        v[12..16].copy_from_slice(&(MAX_BLOB_LEN as u32).to_le_bytes());
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        assert_every_bit_flip_refused(&good, &mut decode);
        garbage_never_panics(&good, 0x2545_f491, 5_000, 3, &mut decode);
    }

    #[test]
    fn either_format_decodes_into_one_axis_set_and_reports_its_length() {
        let multi = encoded(&three_axes());
        let mut single = [0u8; MAX_BLOB_LEN];
        let model = rbf_model::<32>(12, 1.0);
        let n = blob::encode(&model, &mut single).unwrap();
        let single = &single[..n];
        assert_eq!(
            (blob::blob_kind(&multi), blob::blob_kind(single)),
            (Ok(BlobKind::PerAxis), Ok(BlobKind::SingleAxis))
        );
        assert_eq!(blob::blob_kind(&[0xFF; 16]), Err(DecodeError::BadMagic));
        let mut future = single.to_vec();
        future[4] = 9;
        assert_eq!(blob::blob_kind(&future), Err(DecodeError::UnsupportedVersion(9)));
        assert_eq!((blob_len(&multi), blob_len(single)), (Ok(multi.len()), Ok(n)));
        let mut axes = AxisModels::<32>::EMPTY;
        assert_eq!(decode_any_into(&mut axes, single), Ok(n));
        assert_eq!((axes.mask(), axes.get(Axis::X)), (0b001, Some(&model)));
        let mut full = AxisModels::<{ MAX_CENTERS }>::EMPTY;
        assert_eq!(decode_any_into(&mut full, &multi), Ok(multi.len()));
        assert_eq!(full, three_axes());
        let mut damaged = single.to_vec();
        damaged[HEADER_LEN] ^= 1;
        assert!(decode_any_into(&mut axes, &damaged).is_err());
        assert_eq!(axes, AxisModels::EMPTY, "a refused blob leaves no model behind");
    }

    #[test]
    fn a_capacity_too_small_for_an_axis_or_a_blob_past_4_kib_is_refused() {
        let blob = encoded(&three_axes());
        let mut small = AxisModels::<16>::EMPTY;
        assert_eq!(
            decode_axes_into(&mut small, &blob),
            Err(DecodeError::ShapeOverCapacity { centers: 32, inputs: 3 })
        );
        let mut big = AxisModels::<{ MAX_CENTERS }>::EMPTY;
        for axis in Axis::ALL {
            big.insert(axis, rbf_model(64, 1.0));
        }
        let mut buf = [0u8; 2 * MAX_BLOB_LEN];
        assert_eq!(encode_axes(&big, &mut buf), Err(EncodeError::BufferTooSmall));
        assert_eq!(
            encode_axes(&AxisModels::<8>::EMPTY, &mut buf),
            Err(EncodeError::NoModel)
        );
    }
}
