//! Shared-basis multi-axis models: one Gaussian basis, one output layer per axis.
//!
//! ```text
//! y_a = c_a + Σ_i a_ai z_i + Σ_j W_aj exp(−‖z_[..m] − c_j‖² / 2σ_j²)     (a = x, y, z)
//! ```
//! Everything but the output layer is shared by the axes: the features
//! (one thermometer set, hence one temperature history), the input
//! normalisation and ranges, the centres c_j and widths σ_j, and so the
//! kernel values. Per axis only the weights W_aj, the linear terms a_ai and
//! the constant c_a differ. One evaluation computes the features and the
//! kernel values once per sample and weights them three times
//! ([`SharedAxisModels::eval_axes`]), so a three-axis step costs about one
//! single-axis evaluation plus 3 × K multiply-adds rather than three
//! evaluations.
//!
//! The basis is held as a [`Model`] whose network has every weight 1 and no
//! linear terms: its table path then keeps every centre, in order, with
//! the unweighted exponents, and the same decoder and validation serve it.
//! Each axis's value is the weighted sum of the same kernel values: it does
//! not depend on which other axes are present (bit for bit), and it agrees
//! with a single-axis [`Model`] of the basis and that axis's layer
//! ([`SharedAxisModels::axis_model`]) within the table exponential's error,
//! not bit for bit, because the single-axis table path folds each weight
//! into its exponent.
//!
//! The axes read one thermometer set: a shared-basis model suits an IMU
//! whose axes share one loop thermometer (`temp_c` of a multi-axis run,
//! `trainer simulate --axes 3 --shared-thermometer`). Blob layout: format 3
//! with the shared-basis flag ([`crate::blob::shared_layout`]).

use crate::axis::{Axis, AxisSet, MAX_AXES};
use crate::blob::DecodeError;
use crate::features::{FeatureConfig, FeatureVector};
use crate::model::{MAX_ABS_BIAS_DPH, Model, ModelBody, ModelError};
use crate::rbf::{RbfShape, RbfStorage};
use crate::{MAX_CENTERS, MAX_INPUTS};

/// One axis's output layer, as slices (host construction and encoding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputLayer<'a> {
    /// Weight W_aj of each centre of the basis, °/h.
    pub weights: &'a [f32],
    /// Linear coefficient per normalised input, °/h; empty for none.
    pub linear: &'a [f32],
    /// Constant term, °/h.
    pub constant: f32,
}

/// An axis's linear terms and constant as given, and in the boxed form the
/// evaluation uses.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Layer {
    linear: [f32; MAX_INPUTS],
    has_linear: bool,
    constant: f32,
}

impl Layer {
    const EMPTY: Layer = Layer {
        linear: [0.0; MAX_INPUTS],
        has_linear: false,
        constant: 0.0,
    };
}

/// Result of evaluating every axis's layer on one feature vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxesEvaluation {
    /// Estimated bias per axis, °/h, x first (0 for an axis without a layer).
    pub bias_dph: [f32; MAX_AXES],
    /// At least one input was outside the training range and was clamped.
    pub clamped: bool,
}

/// A shared-basis model of up to three axes, with room for `K` centres.
///
/// `repr(C)` with what [`Self::eval_axes`] reads first.
#[derive(Clone, Debug, PartialEq)]
#[repr(C)]
pub struct SharedAxisModels<const K: usize = MAX_CENTERS> {
    /// Per axis, the linear terms in the boxed form (coefficients, constant).
    boxed: [([f32; MAX_INPUTS], f32); MAX_AXES],
    /// Per centre, the weights of x, y and z (0 for an absent axis).
    weights: [[f32; MAX_AXES]; K],
    basis: Model<K>,
    layers: [Layer; MAX_AXES],
    mask: AxisSet,
}

/// True when two models have the same basis: features, input ranges,
/// normalisation, kernel inputs, centres and widths, bit for bit.
fn same_basis<const K: usize>(a: &Model<K>, b: &Model<K>) -> bool {
    let bits = |x: &[f32], y: &[f32]| x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
    let (ModelBody::Rbf(n), ModelBody::Rbf(m)) = (a.body(), b.body()) else {
        return false;
    };
    let dims = a.features().dims();
    a.features() == b.features()
        && (0..dims).all(|i| {
            let (p, q) = (a.input_range(i), b.input_range(i));
            matches!((p, q), (Some(p), Some(q)) if p.0.to_bits() == q.0.to_bits() && p.1.to_bits() == q.1.to_bits())
        })
        && n.kernel_inputs() == m.kernel_inputs()
        && n.centers_used() == m.centers_used()
        && bits(n.offset(), m.offset())
        && bits(n.scale(), m.scale())
        && bits(n.widths(), m.widths())
        && (0..n.centers_used()).all(|j| bits(n.center(j), m.center(j)))
}

impl<const K: usize> SharedAxisModels<K> {
    /// No axis (all bits zero: a `static` holding it costs no flash).
    pub const EMPTY: Self = SharedAxisModels {
        boxed: [([0.0; MAX_INPUTS], 0.0); MAX_AXES],
        weights: [[0.0; MAX_AXES]; K],
        basis: Model::EMPTY,
        layers: [Layer::EMPTY; MAX_AXES],
        mask: AxisSet::EMPTY,
    };

    /// The shared-basis form of per-axis models that share one basis
    /// (features, ranges, normalisation, centres and widths bit for bit):
    /// each model's weights, linear terms and constant become its axis's
    /// layer, the first model's serial number the basis's.
    /// [`ModelError::ShapeMismatch`] when a model is not a network or the
    /// bases differ, or when `models` is empty.
    pub fn from_models(models: &[(Axis, &Model<K>)]) -> Result<Self, ModelError> {
        let Some((_, first)) = models.first() else {
            return Err(ModelError::ShapeMismatch);
        };
        if !models.iter().all(|(_, m)| same_basis(first, m)) {
            return Err(ModelError::ShapeMismatch);
        }
        let mut shared = Self::EMPTY;
        shared.assign_basis_of(first)?;
        for (axis, model) in models {
            let ModelBody::Rbf(net) = model.body() else {
                return Err(ModelError::ShapeMismatch);
            };
            shared.assign_layer(
                *axis,
                &OutputLayer {
                    weights: net.weights(),
                    linear: net.linear(),
                    constant: net.constant(),
                },
            )?;
        }
        Ok(shared)
    }

    /// Sets the basis from `model`'s (its network with every weight 1, no
    /// linear terms, constant 0) and removes every layer.
    fn assign_basis_of(&mut self, model: &Model<K>) -> Result<(), ModelError> {
        *self = Self::EMPTY;
        let result = copy_network(
            model,
            &mut self.basis,
            |w| w.iter_mut().for_each(|w| *w = 1.0),
            &[],
            0.0,
        )
        .unwrap_or(Err(ModelError::ShapeMismatch));
        if result.is_err() {
            *self = Self::EMPTY;
        }
        result
    }

    /// Checks that a decoded basis is one ([`Self::basis`]'s form: a
    /// network, every weight 1, no linear terms, constant 0) and removes
    /// every layer; [`DecodeError::Malformed`] otherwise.
    pub(crate) fn accept_basis(&mut self) -> Result<(), DecodeError> {
        self.mask = AxisSet::EMPTY;
        self.weights = [[0.0; MAX_AXES]; K];
        self.layers = [Layer::EMPTY; MAX_AXES];
        self.boxed = [([0.0; MAX_INPUTS], 0.0); MAX_AXES];
        let ModelBody::Rbf(net) = self.basis.body() else {
            return Err(DecodeError::Malformed);
        };
        let ones = net.weights().iter().all(|w| w.to_bits() == 1.0f32.to_bits());
        if !ones || !net.linear().is_empty() || net.constant().to_bits() != 0 {
            return Err(DecodeError::Malformed);
        }
        Ok(())
    }

    /// The basis model, to be filled in place by a decoder.
    pub(crate) fn basis_mut(&mut self) -> &mut Model<K> {
        &mut self.basis
    }

    /// Sets `axis`'s output layer: one weight per centre of the basis, no
    /// or one linear coefficient per input, finite, and the axis's output
    /// bounded ([`MAX_ABS_BIAS_DPH`]) over the basis's input box.
    pub fn assign_layer(&mut self, axis: Axis, layer: &OutputLayer<'_>) -> Result<(), ModelError> {
        let ModelBody::Rbf(net) = self.basis.body() else {
            return Err(ModelError::ShapeMismatch);
        };
        let dims = self.basis.features().dims();
        let k = net.centers_used();
        if layer.weights.len() != k || !(layer.linear.is_empty() || layer.linear.len() == dims) {
            return Err(ModelError::ShapeMismatch);
        }
        let finite = layer.weights.iter().chain(layer.linear).all(|v| v.is_finite()) && layer.constant.is_finite();
        if !finite {
            return Err(ModelError::NonFiniteParameter);
        }
        let (linear_lo, linear_hi) = self.basis.linear_box();
        let weight_sum: f64 = layer.weights.iter().map(|w| f64::from(*w).abs()).sum();
        let bound = net.layer_output_bound(layer.linear, layer.constant, weight_sum, linear_lo, linear_hi);
        if bound.is_nan() || bound > MAX_ABS_BIAS_DPH {
            return Err(ModelError::OutputUnbounded);
        }
        let a = axis.index() % MAX_AXES;
        for (row, w) in self.weights.iter_mut().zip(layer.weights) {
            row[a] = *w;
        }
        let mut linear = [0.0f32; MAX_INPUTS];
        linear.iter_mut().zip(layer.linear).for_each(|(d, s)| *d = *s);
        self.layers[a] = Layer {
            linear,
            has_linear: !layer.linear.is_empty(),
            constant: layer.constant,
        };
        self.boxed[a] = net.linear_box_terms(layer.linear, layer.constant);
        self.mask.insert(axis);
        Ok(())
    }

    /// Evaluates every axis's bias at `features`, °/h: the kernels once,
    /// then one weighted sum and one linear sum per axis. The same clamping
    /// and flag as [`Model::eval`].
    #[inline(always)]
    pub fn eval_axes(&self, features: &FeatureVector) -> AxesEvaluation {
        let (bias_dph, clamped) = self.basis.eval_layers(features, &self.weights, &self.boxed);
        AxesEvaluation { bias_dph, clamped }
    }

    /// How the firmware must compute the (shared) inputs.
    pub fn features(&self) -> &FeatureConfig {
        self.basis.features()
    }

    /// The basis: features, ranges and a network whose every weight is 1
    /// and which has no linear terms.
    pub fn basis(&self) -> &Model<K> {
        &self.basis
    }

    /// True when `axis` has an output layer.
    pub fn has(&self, axis: Axis) -> bool {
        self.mask.contains(axis)
    }

    /// The axes with a layer, x first.
    pub fn axes(&self) -> impl Iterator<Item = Axis> + '_ {
        self.mask.iter()
    }

    /// Axes present as a bit mask (bit 0 = x).
    pub fn mask(&self) -> u8 {
        self.mask.bits()
    }

    /// Centres of the basis.
    pub fn centers_used(&self) -> usize {
        match self.basis.body() {
            ModelBody::Rbf(net) => net.centers_used(),
            ModelBody::Poly3(_) => 0,
        }
    }

    /// `axis`'s weights (one per centre), written into `out`; the count.
    pub fn weights_into(&self, axis: Axis, out: &mut [f32]) -> usize {
        let a = axis.index() % MAX_AXES;
        let k = self.centers_used();
        out.iter_mut()
            .zip(&self.weights)
            .take(k)
            .map(|(o, row)| *o = row[a])
            .count()
    }

    /// `axis`'s linear coefficients (empty for none) and constant, °/h.
    pub fn linear_and_constant(&self, axis: Axis) -> (&[f32], f32) {
        let layer = &self.layers[axis.index() % MAX_AXES];
        let dims = self.basis.features().dims().min(MAX_INPUTS);
        let linear = if layer.has_linear { &layer.linear[..dims] } else { &[] };
        (linear, layer.constant)
    }

    /// The single-axis model of the basis and `axis`'s layer (host tools:
    /// inspection, reports and the reference the shared evaluation is
    /// checked against); `None` when the axis has no layer.
    pub fn axis_model(&self, axis: Axis) -> Option<Result<Model<K>, ModelError>> {
        if !self.has(axis) {
            return None;
        }
        let (linear, constant) = self.linear_and_constant(axis);
        let mut model = Model::EMPTY;
        let result = copy_network(
            &self.basis,
            &mut model,
            |w| {
                self.weights_into(axis, w);
            },
            linear,
            constant,
        )?;
        Some(result.map(|()| model))
    }
}

/// Makes `target` the Gaussian network of `source` (features, input ranges,
/// information, centres, widths, normalisation) with the output layer
/// `weights` fills (one weight per centre in use), the linear terms `linear`
/// and the constant `constant`; `None` when `source` is no network.
fn copy_network<const K: usize>(
    source: &Model<K>,
    target: &mut Model<K>,
    weights: impl FnOnce(&mut [f32]),
    linear: &[f32],
    constant: f32,
) -> Option<Result<(), ModelError>> {
    let ModelBody::Rbf(net) = source.body() else {
        return None;
    };
    let dims = source.features().dims();
    let mut ranges = [(0.0f32, 0.0f32); MAX_INPUTS];
    for (i, r) in ranges.iter_mut().enumerate().take(dims) {
        *r = source.input_range(i).unwrap_or((0.0, 0.0));
    }
    Some(target.assign_rbf_in_place(
        source.features(),
        ranges.get(..dims).unwrap_or(&[]),
        source.info().clone(),
        |storage: RbfStorage<'_>| {
            let k = net.centers_used();
            let m = net.kernel_inputs();
            let copy = |dst: &mut [f32], src: &[f32]| dst.iter_mut().zip(src).for_each(|(d, s)| *d = *s);
            copy(storage.offset, net.offset());
            copy(storage.scale, net.scale());
            copy(storage.widths, net.widths());
            copy(storage.linear, linear);
            let n = k.min(storage.weights.len());
            weights(storage.weights.get_mut(..n).unwrap_or(&mut []));
            for (j, row) in storage.centers.iter_mut().enumerate().take(k) {
                copy(row, net.center(j));
            }
            Ok::<_, ModelError>(RbfShape {
                offsets: dims,
                scales: dims,
                kernel_inputs: m,
                center_values: k * m,
                widths: k,
                weights: k,
                linear: linear.len(),
                constant,
            })
        },
    ))
}
