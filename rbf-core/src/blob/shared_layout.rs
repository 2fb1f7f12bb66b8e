//! The shared-basis multi-axis blob: format 3 with the shared-basis flag.
//!
//! ```text
//! offset  size  field
//!      0     4  magic  b"IFOG"
//!      4     2  format version, u16 LE (3: multi-axis; 5: with provenance, see [`super`])
//!      6     1  axis mask: bit 0 = x, bit 1 = y, bit 2 = z (at least one)
//!      7     1  1: shared basis (0: one model per axis, see [`super::axes`])
//!      8     4  reserved, 0
//!     12     4  payload length N, u32 LE
//!     16     N  payload: an 8-byte section header (kind u8 = 1, inputs D
//!               u8, centres K u16 LE, section length L u32 LE) and L bytes:
//!               the basis as a version-2 payload (every weight 1.0, no
//!               linear terms, constant 0); then per axis in the mask, x
//!               first, postcard(weights: K × f32, linear: 0 or D × f32,
//!               constant: f32)
//!   16+N     4  CRC-32/ISO-HDLC of bytes 0 .. 16+N, u32 LE
//! ```
//! The basis goes through the single-axis decoder and validation; each
//! layer is checked against it ([`SharedAxisModels::assign_layer`]). The
//! whole blob stays within [`MAX_BLOB_LEN`](super::MAX_BLOB_LEN). A reader of one model per
//! axis refuses this blob with [`DecodeError::SharedBasis`], this reader
//! refuses the others with [`DecodeError::NotSharedBasis`].

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::axes::{AxesHeader, SHARED_BASIS_FLAG};
use super::{
    DecodeError, EncodeError, Layout, Provenance, RawHeader, checked_payload, decode_section, split_section,
    write_blob, write_section,
};
use crate::axis::{Axis, MAX_AXES};
use crate::shared_basis::{OutputLayer, SharedAxisModels};
use crate::{MAX_CENTERS, MAX_INPUTS};

/// One axis's output layer on the wire.
#[derive(Serialize, Deserialize)]
struct LayerWire {
    weights: Vec<f32, MAX_CENTERS>,
    linear: Vec<f32, MAX_INPUTS>,
    constant: f32,
}

/// Encodes `models` into `out` as one shared-basis blob (format 3, no provenance);
/// returns the number of bytes written. [`EncodeError::NoModel`] when no axis has a
/// layer, [`EncodeError::BufferTooSmall`] when the blob would pass `out` or
/// [`super::MAX_BLOB_LEN`].
pub fn encode_shared<const K: usize>(models: &SharedAxisModels<K>, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_shared_with(models, None, out)
}

/// [`encode_shared`] with `provenance` (format 5) or without (format 3); the models'
/// bytes are the same either way.
pub fn encode_shared_with<const K: usize>(
    models: &SharedAxisModels<K>,
    provenance: Option<&Provenance<'_>>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    if models.mask() == 0 {
        return Err(EncodeError::NoModel);
    }
    write_blob(out, Layout::Axes, provenance, |area| {
        let mut at = write_section(models.basis(), area)?;
        for axis in models.axes() {
            let mut weights = [0.0f32; MAX_CENTERS];
            let k = models.weights_into(axis, &mut weights);
            let (linear, constant) = models.linear_and_constant(axis);
            let wire = LayerWire {
                weights: Vec::from_slice(weights.get(..k).unwrap_or(&[])).map_err(|_| EncodeError::BufferTooSmall)?,
                linear: Vec::from_slice(linear).map_err(|_| EncodeError::BufferTooSmall)?,
                constant,
            };
            let layer_area = area.get_mut(at..).ok_or(EncodeError::BufferTooSmall)?;
            at += postcard::to_slice(&wire, layer_area)
                .map_err(|_| EncodeError::BufferTooSmall)?
                .len();
        }
        Ok(([models.mask(), SHARED_BASIS_FLAG, 0, 0, 0, 0], at))
    })
}

/// Decodes and validates a shared-basis blob from untrusted bytes into
/// `models`, in place; returns the bytes the blob occupied (trailing bytes
/// are ignored). On error `models` is [`SharedAxisModels::EMPTY`] and the
/// reason is returned; it never panics.
pub fn decode_shared_into<const K: usize>(
    models: &mut SharedAxisModels<K>,
    bytes: &[u8],
) -> Result<usize, DecodeError> {
    let result = decode_shared_payload(models, bytes);
    if result.is_err() {
        *models = SharedAxisModels::EMPTY;
    }
    result
}

fn decode_shared_payload<const K: usize>(models: &mut SharedAxisModels<K>, bytes: &[u8]) -> Result<usize, DecodeError> {
    let header = AxesHeader::parse(bytes)?;
    if !header.shared_basis {
        return Err(DecodeError::NotSharedBasis);
    }
    let (_, payload) = checked_payload(bytes, &RawHeader::read(bytes)?)?;
    let (shape, section, mut rest) = split_section(payload)?;
    decode_section(models.basis_mut(), shape, section)?;
    models.accept_basis()?;
    for axis in Axis::ALL.into_iter().take(MAX_AXES) {
        if header.axis_mask & (1 << axis.index()) == 0 {
            continue;
        }
        let (wire, tail): (LayerWire, _) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Malformed)?;
        models.assign_layer(
            axis,
            &OutputLayer {
                weights: &wire.weights,
                linear: &wire.linear,
                constant: wire.constant,
            },
        )?;
        rest = tail;
    }
    if !rest.is_empty() {
        return Err(DecodeError::Malformed);
    }
    Ok(header.blob_len())
}

#[cfg(test)]
#[allow(clippy::float_cmp, reason = "the evaluation's bits are what these tests guard")]
mod tests {
    use super::*;
    use crate::blob::axes::{AxisModels, decode_any_into, decode_axes_into, encode_axes};
    use crate::blob::damage::{assert_every_bit_flip_refused, garbage_never_panics, reseal};
    use crate::blob::{self, decode};
    use crate::blob::{HEADER_LEN, MAX_BLOB_LEN};
    use crate::features::{FeatureConfig, FeatureSet, FeatureVector};
    use crate::model::ModelBody;
    use crate::model::{BodyParams, Model, ModelError, ModelInfo};
    use crate::rbf::RbfParams;

    /// Pseudo-random values in [−1, 1).
    fn noise(seed: u32, n: usize) -> std::vec::Vec<f32> {
        let mut state = seed;
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state >> 8) as f32 / (1 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// A model over (T, ΔT, T×ΔT) of `k` centres (one basis for every
    /// `seed`) with `seed`'s output layer; `width` the shared width (the
    /// table path) or `None` for widths per centre (the polynomial path).
    fn axis_model<const K: usize>(k: usize, seed: u32, width: Option<f32>) -> Model<K> {
        let centers = noise(7, k * 3);
        let widths: std::vec::Vec<f32> = (0..k).map(|j| width.unwrap_or(0.8 + 0.02 * j as f32)).collect();
        let weights: std::vec::Vec<f32> = noise(seed, k).iter().map(|w| 0.05 * w).collect();
        let lin = noise(seed ^ 0x55, 4);
        let params = RbfParams {
            offset: &[25.0, 0.0, 0.0],
            scale: &[10.0, 0.5, 12.0],
            kernel_inputs: 3,
            centers: &centers,
            widths: &widths,
            weights: &weights,
            linear: &[0.01 * lin[0], 0.02 * lin[1], 0.01 * lin[2]],
            constant: 0.1 * lin[3],
        };
        let mut model = Model::<K>::EMPTY;
        let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
        let ranges = [(0.0, 50.0), (-3.0, 3.0), (-150.0, 150.0)];
        model
            .assign(&features, &ranges, BodyParams::Rbf(&params), ModelInfo::default())
            .unwrap();
        model
    }

    fn shared(width: Option<f32>) -> (SharedAxisModels, [Model; 3]) {
        let models = [0x2545_f491, 0x9E37_79B9, 0x1234_5678].map(|seed| axis_model(32, seed, width));
        let pairs: std::vec::Vec<(Axis, &Model)> = Axis::ALL.into_iter().zip(&models).collect();
        (SharedAxisModels::from_models(&pairs).unwrap(), models)
    }

    fn encoded<const K: usize>(models: &SharedAxisModels<K>) -> std::vec::Vec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode_shared(models, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    /// Inputs sweeping the training box and beyond it.
    fn inputs() -> impl Iterator<Item = FeatureVector> {
        (0..400).map(|i| {
            let t = i as f32;
            FeatureVector::from_values(&[-5.0 + 0.15 * t, 3.5 * (t * 0.07).sin(), 160.0 * (t * 0.031).cos()])
        })
    }

    #[test]
    fn each_axis_is_its_single_axis_model_within_the_table_error_and_independent_of_the_others() {
        for width in [Some(1.5), Some(0.5), None] {
            let (models, singles) = shared(width);
            assert_eq!(models.mask(), 0b111);
            let ModelBody::Rbf(basis) = models.basis().body() else {
                panic!("an RBF basis")
            };
            assert_eq!(basis.table_ready(), width.is_some(), "width {width:?}");
            // Each axis alone (its layer only) evaluates to the same bits as within three.
            let alone: std::vec::Vec<SharedAxisModels> = Axis::ALL
                .into_iter()
                .zip(&singles)
                .map(|(axis, m)| SharedAxisModels::from_models(&[(axis, m)]).unwrap())
                .collect();
            for f in inputs() {
                let all = models.eval_axes(&f);
                for (a, single) in singles.iter().enumerate() {
                    let own = alone[a].eval_axes(&f);
                    assert_eq!(
                        all.bias_dph[a].to_bits(),
                        own.bias_dph[a].to_bits(),
                        "axis {a} at {f:?}"
                    );
                    assert_eq!(all.clamped, own.clamped);
                    let reference = single.eval(&f);
                    assert_eq!(all.clamped, reference.clamped, "the same clamping flag");
                    // Σ|W| ≤ 32 × 0.05 = 1.6 °/h; each kernel within the
                    // table's bound twice (its term and the shared factor).
                    let tol = 1.6 * 2.0 * crate::fastmath::EXP2_FIXED_REL_ERROR + 1e-5;
                    let diff = (all.bias_dph[a] - reference.bias_dph).abs();
                    assert!(f64::from(diff) <= tol, "axis {a} width {width:?}: {diff} > {tol}");
                }
                for (a, axis) in Axis::ALL.into_iter().enumerate() {
                    if a > 0 {
                        assert_eq!(alone[0].eval_axes(&f).bias_dph[a], 0.0, "{axis:?}: no layer, no bias");
                    }
                }
            }
            // The single-axis model of the basis and a layer is that axis's model.
            for (axis, single) in Axis::ALL.into_iter().zip(&singles) {
                assert_eq!(&models.axis_model(axis).unwrap().unwrap(), single);
            }
        }
    }

    #[test]
    fn the_compensator_steps_every_axis_from_one_feature_computation() {
        use crate::compensator::{Compensator, CompensatorConfig};
        let (models, _) = shared(Some(1.5));
        let config = CompensatorConfig::for_sample_rate(10.0);
        let (mut joint, mut reference) = (Compensator::new(), Compensator::new());
        let mut temps = [None; crate::features::THERMOMETERS];
        for i in 0..500 {
            let t = 20.0 + 0.01 * i as f32;
            temps[crate::features::LOOP_THERMOMETER] = (i % 97 != 5).then_some(t);
            let rates = [1.0, f32::NAN, -3.0];
            let out = joint.process_shared(Some(&models), &config, 0.1, &temps, &rates);
            let frame = reference.features(
                models.features(),
                &config,
                &crate::GyroSample {
                    dt_s: 0.1,
                    rate_dph: 0.0,
                    temps_c: temps,
                },
            );
            let eval = frame.features.map(|f| models.eval_axes(&f));
            for a in 0..3 {
                let bias = eval.map_or(0.0, |e| e.bias_dph[a]);
                assert_eq!(out[a].bias_dph.to_bits(), bias.to_bits());
                assert_eq!(out[a].rate_comp_dph.to_bits(), (rates[a] - bias).to_bits());
                assert_eq!(out[a].flags.contains(crate::Flags::RATE_INVALID), a == 1);
                assert_eq!(
                    out[a].flags.contains(crate::Flags::TEMP_SENSOR_FAULT),
                    frame.flags.contains(crate::Flags::TEMP_SENSOR_FAULT)
                );
            }
        }
        let none = Compensator::new().process_shared::<64>(None, &config, 0.1, &temps, &[1.0; 3]);
        assert!(
            none.iter()
                .all(|o| o.flags.contains(crate::Flags::NO_VALID_MODEL) && o.rate_comp_dph == 1.0)
        );
    }

    #[test]
    fn shared_blobs_round_trip_bit_for_bit_within_4_kib() {
        for width in [Some(1.5), None] {
            let (models, _) = shared(width);
            let blob = encoded(&models);
            assert!(blob.len() <= MAX_BLOB_LEN, "{} B", blob.len());
            assert_eq!(crate::blob::blob_kind(&blob), Ok(crate::blob::BlobKind::SharedBasis));
            let mut back = SharedAxisModels::<64>::EMPTY;
            assert_eq!(decode_shared_into(&mut back, &blob), Ok(blob.len()));
            assert_eq!(back, models);
            for f in inputs() {
                assert_eq!(back.eval_axes(&f), models.eval_axes(&f));
            }
        }
        // Two axes; a smaller capacity.
        let singles = [axis_model::<32>(20, 1, Some(1.0)), axis_model::<32>(20, 2, Some(1.0))];
        let two = SharedAxisModels::from_models(&[(Axis::X, &singles[0]), (Axis::Z, &singles[1])]).unwrap();
        let blob = encoded(&two);
        let mut back = SharedAxisModels::<32>::EMPTY;
        assert_eq!(decode_shared_into(&mut back, &blob), Ok(blob.len()));
        assert_eq!((back.mask(), &back), (0b101, &two));
        let mut small = SharedAxisModels::<16>::EMPTY;
        assert_eq!(
            decode_shared_into(&mut small, &blob),
            Err(DecodeError::ShapeOverCapacity { centers: 20, inputs: 3 })
        );
        assert_eq!(small, SharedAxisModels::EMPTY);
    }

    #[test]
    fn a_shared_blob_with_provenance_decodes_to_the_same_models() {
        let (models, _) = shared(Some(1.5));
        let provenance = blob::Provenance {
            model_id: 0xfeed,
            serial: "",
            record: b"",
        };
        let mut buf = [0u8; MAX_BLOB_LEN];
        let n = encode_shared_with(&models, Some(&provenance), &mut buf).unwrap();
        let with = &buf[..n];
        let plain = encoded(&models);
        assert_eq!(with[HEADER_LEN + 7..n - 4], plain[HEADER_LEN..plain.len() - 4]);
        assert_eq!(blob::blob_kind(with), Ok(blob::BlobKind::SharedBasis));
        let mut back = SharedAxisModels::<64>::EMPTY;
        assert_eq!(decode_shared_into(&mut back, with), Ok(n));
        assert_eq!(back, models);
        assert_eq!(blob::provenance(with), Ok(Some(provenance)));
    }

    #[test]
    fn models_of_different_bases_or_kinds_make_no_shared_model() {
        let a = axis_model::<64>(8, 1, Some(1.0));
        let b = axis_model::<64>(8, 2, Some(1.1));
        assert_eq!(
            SharedAxisModels::from_models(&[(Axis::X, &a), (Axis::Y, &b)]),
            Err(ModelError::ShapeMismatch)
        );
        assert_eq!(SharedAxisModels::<64>::from_models(&[]), Err(ModelError::ShapeMismatch));
        let mut shared = SharedAxisModels::from_models(&[(Axis::X, &a)]).unwrap();
        let layer = |weights: &'static [f32], constant: f32| OutputLayer {
            weights,
            linear: &[],
            constant,
        };
        assert_eq!(
            shared.assign_layer(Axis::Y, &layer(&[0.0; 7], 0.0)),
            Err(ModelError::ShapeMismatch)
        );
        assert_eq!(
            shared.assign_layer(Axis::Y, &layer(&[0.0; 8], f32::NAN)),
            Err(ModelError::NonFiniteParameter)
        );
        assert_eq!(
            shared.assign_layer(Axis::Y, &layer(&[1e30; 8], 0.0)),
            Err(ModelError::OutputUnbounded)
        );
        assert_eq!(shared.mask(), 0b001, "a refused layer adds no axis");
    }

    #[test]
    fn every_reader_refuses_the_other_layouts_with_a_reason_and_old_blobs_still_load() {
        let (models, singles) = shared(Some(1.5));
        let blob = encoded(&models);
        let mut per_axis = AxisModels::<64>::EMPTY;
        assert_eq!(decode_axes_into(&mut per_axis, &blob), Err(DecodeError::SharedBasis));
        assert_eq!(decode_any_into(&mut per_axis, &blob), Err(DecodeError::SharedBasis));
        assert!(decode(&blob).is_err(), "a single-axis reader refuses it");
        // Format 2 and format 3 (one model per axis) load as before, and the
        // shared reader refuses them.
        let mut v2 = [0u8; MAX_BLOB_LEN];
        let n2 = blob::encode(&singles[0], &mut v2).unwrap();
        assert_eq!(decode(&v2[..n2]).unwrap().model, singles[0]);
        let mut axes = AxisModels::<64>::EMPTY;
        for (axis, m) in Axis::ALL.into_iter().zip(&singles) {
            axes.insert(axis, m.clone());
        }
        let mut v3 = [0u8; MAX_BLOB_LEN];
        let n3 = encode_axes(&axes, &mut v3).unwrap();
        assert_eq!(decode_axes_into(&mut per_axis, &v3[..n3]), Ok(n3));
        assert_eq!(per_axis, axes);
        assert_eq!(
            (crate::blob::blob_kind(&v3[..n3]), crate::blob::blob_kind(&v2[..n2])),
            (
                Ok(crate::blob::BlobKind::PerAxis),
                Ok(crate::blob::BlobKind::SingleAxis)
            )
        );
        let mut back = SharedAxisModels::<64>::EMPTY;
        assert_eq!(
            decode_shared_into(&mut back, &v3[..n3]),
            Err(DecodeError::NotSharedBasis)
        );
        assert_eq!(
            decode_shared_into(&mut back, &v2[..n2]),
            Err(DecodeError::UnsupportedVersion(2))
        );
        assert!(
            blob.len() < n3,
            "one basis is smaller than three models: {} vs {n3} B",
            blob.len()
        );
    }

    #[test]
    fn every_defect_is_refused_with_a_reason_and_none_panics() {
        let (models, _) = shared(Some(1.5));
        let good = encoded(&models);
        let mut back = SharedAxisModels::<64>::EMPTY;
        let mut decode = |bytes: &[u8]| decode_shared_into(&mut back, bytes).map(|_| ());
        assert!(matches!(decode(&good[..10]), Err(DecodeError::Truncated { .. })));
        assert!(matches!(
            decode(&good[..good.len() - 1]),
            Err(DecodeError::Truncated { .. })
        ));
        assert_eq!(decode(&[0xFF; 64]), Err(DecodeError::BadMagic));
        // An unknown flag value.
        let mut v = good.clone();
        v[7] = 2;
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        // The mask names two axes, the payload holds three layers.
        let mut v = good.clone();
        v[6] = 0b011;
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        // The mask names an axis beyond z.
        let mut v = good.clone();
        v[6] = 0b1111;
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::BadAxisMask(0b1111)));
        // A basis section longer than the payload.
        let mut v = good.clone();
        v[HEADER_LEN + 4..HEADER_LEN + 8].copy_from_slice(&u32::MAX.to_le_bytes());
        reseal(&mut v);
        assert_eq!(decode(&v), Err(DecodeError::Malformed));
        // A basis whose weights are not 1: the weight 1.0f32 is 0x3F800000 LE.
        let one = 1.0f32.to_le_bytes();
        let at = good.windows(4).position(|w| w == one).unwrap();
        let mut v = good.clone();
        v[at..at + 4].copy_from_slice(&2.0f32.to_le_bytes());
        reseal(&mut v);
        assert!(decode(&v).is_err(), "a basis weight of 2 is refused");
        assert_every_bit_flip_refused(&good, &mut decode);
        garbage_never_panics(&good, 0x2545_f491, 5_000, 3, &mut decode);
    }
}
