//! A model decoded in place from a blob, whichever kind a reader runs
//! ([`StoredModel`]): the firmware's model store decodes every slot through
//! it, and the host checks a blob through it before sending it to a unit,
//! so both accept and refuse the same blobs for the same reasons.

use crate::Model;
use crate::blob::axes::{AxisModels, decode_any_into};
use crate::blob::shared_layout::decode_shared_into;
use crate::blob::{self, DecodeError};
use crate::shared_basis::SharedAxisModels;

/// What a slot's blob decodes into, in place: a single-axis [`Model`], the
/// [`AxisModels`] of a multi-axis IMU or its [`SharedAxisModels`], each
/// with its centre capacity `K`.
pub trait StoredModel {
    /// Decodes and validates the blob at the start of `bytes` into `self`;
    /// the bytes it occupies. On error `self` holds no usable model.
    fn decode_from(&mut self, bytes: &[u8]) -> Result<usize, DecodeError>;
    /// Leaves no model behind.
    fn clear(&mut self);
}

impl<const K: usize> StoredModel for Model<K> {
    fn decode_from(&mut self, bytes: &[u8]) -> Result<usize, DecodeError> {
        blob::decode_into_capacity(self, bytes)
    }
    fn clear(&mut self) {
        *self = Model::EMPTY;
    }
}

/// A multi-axis blob, or a single-axis one as axis x alone.
impl<const K: usize> StoredModel for AxisModels<K> {
    fn decode_from(&mut self, bytes: &[u8]) -> Result<usize, DecodeError> {
        decode_any_into(self, bytes)
    }
    fn clear(&mut self) {
        *self = AxisModels::EMPTY;
    }
}

/// A shared-basis blob (format 3 with the shared-basis flag) alone: a
/// model per axis or a single-axis blob is refused with its reason
/// ([`DecodeError::NotSharedBasis`]), as the per-axis reader refuses this
/// one ([`DecodeError::SharedBasis`]).
impl<const K: usize> StoredModel for SharedAxisModels<K> {
    fn decode_from(&mut self, bytes: &[u8]) -> Result<usize, DecodeError> {
        decode_shared_into(self, bytes)
    }
    fn clear(&mut self) {
        *self = SharedAxisModels::EMPTY;
    }
}
