//! Fixed-capacity Gaussian RBF network.
//!
//! ```text
//! z_i  = (x_i − offset_i) / scale_i                         (normalised inputs)
//! y    = c + Σ_i a_i z_i + Σ_j W_j exp(−‖z_[..m] − c_j‖² / 2σ_j²)
//! ```
//! The centres c_j and widths σ_j live in normalised units. The Gaussians see
//! the first m = `kernel_inputs` inputs (all of them in the IFOG paper's
//! network; only T in the partially linear default, whose ΔT terms enter
//! linearly as the Shupe effect does); the linear terms see all of them. Capacity is in the
//! type (`K` centres, `D` inputs); the cost of [`RbfNetwork::eval`] depends only
//! on the model's shape, never on the input values (no data-dependent loops).
//!
//! The network's types and their checked construction live here; what the
//! evaluation needs prepared (the table path's fixed-point exponents, the
//! linear terms over their boxes) and the output bound in `deployment`, the
//! evaluation paths in `evaluation`, the f64 reference in `reference`.

use crate::error::ModelError;

// The submodules' names keep the network's functions in the firmware images
// in the order they had in one file: the linker lays them out by symbol
// name, and another order pads the QEMU images differently
// (`cargo xtask bench-fw` shows their flash).
mod deployment;
mod evaluation;
mod reference;

/// Parameters of a network, as slices (host construction and blob decoding).
#[derive(Clone, Copy, Debug)]
pub struct RbfParams<'a> {
    /// Per-input offset subtracted before scaling (training mean), input units.
    pub offset: &'a [f32],
    /// Per-input scale divided by (training standard deviation), input units.
    pub scale: &'a [f32],
    /// How many leading inputs the Gaussians see (1 ..= inputs).
    pub kernel_inputs: usize,
    /// Centres in normalised units, row-major: `centers[j * kernel_inputs + i]`.
    pub centers: &'a [f32],
    /// Gaussian width σ_j of each centre, normalised units.
    pub widths: &'a [f32],
    /// Output weight W_j of each centre, °/h.
    pub weights: &'a [f32],
    /// Linear coefficient a_i per normalised input, °/h; empty for none.
    pub linear: &'a [f32],
    /// Constant term c, °/h.
    pub constant: f32,
}

/// A network's parameter arrays, for a decoder that fills them where the
/// network keeps them ([`RbfNetwork::init_in_place`]): no parameter is
/// staged anywhere else. Centres are rows of [`crate::MAX_KERNEL_INPUTS`]
/// values, of which the first `kernel_inputs` are used.
#[derive(Debug)]
pub struct RbfStorage<'a> {
    /// Per-input offsets, input units.
    pub offset: &'a mut [f32],
    /// Per-input scales, input units.
    pub scale: &'a mut [f32],
    /// Centres, normalised units, one row per centre.
    pub centers: &'a mut [[f32; KERNEL]],
    /// Gaussian widths, normalised units.
    pub widths: &'a mut [f32],
    /// Output weights, °/h.
    pub weights: &'a mut [f32],
    /// Linear coefficients, °/h.
    pub linear: &'a mut [f32],
}

/// How much of an [`RbfStorage`] a decoder filled, and the scalars: the
/// shape [`RbfParams`] gives by its slices' lengths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RbfShape {
    /// Offsets given (the input count).
    pub offsets: usize,
    /// Scales given.
    pub scales: usize,
    /// Leading inputs the Gaussians see.
    pub kernel_inputs: usize,
    /// Centre coordinates given (centres × kernel inputs).
    pub center_values: usize,
    /// Widths given (the centre count).
    pub widths: usize,
    /// Weights given.
    pub weights: usize,
    /// Linear coefficients given (0 or the input count).
    pub linear: usize,
    /// Constant term c, °/h.
    pub constant: f32,
}

/// A Gaussian RBF network holding at most `K` centres over at most `D` inputs.
///
/// `repr(C)` with what [`Self::eval`] reads first: the hot fields sit within
/// the immediate offsets of Cortex-M loads from the struct's address.
#[derive(Clone, Debug, PartialEq)]
#[repr(C)]
pub struct RbfNetwork<const K: usize, const D: usize> {
    kernel_inputs: usize,
    centers_used: usize,
    inputs_used: usize,
    /// Centres with positive weights at the front of `exponent`, and negative after them.
    positive: usize,
    negative: usize,
    /// [`Self::prepare_table`] proved the integer table path safe for the
    /// model's input box ([`Self::eval_table`]); otherwise [`Self::eval`].
    table: bool,
    /// Per kernel input, the box centre (input units) and the gain that maps
    /// the box's half-width onto 2^31: q_i = i32((x_i − mid_i)·gain_i).
    kernel_mid: [f32; TABLE_MAX_INPUTS],
    kernel_gain: [f32; TABLE_MAX_INPUTS],
    /// Per kernel input, H_i = S h_i² 2^18 (h_i the box's normalised
    /// half-width): Q·2^16 = Σ_i hi(q_i, hi(q_i, H_i)).
    shared_coeff: [i32; TABLE_MAX_INPUTS],
    /// Q is added to every exponent (T > 32: it would not fit the table
    /// as a separate factor) instead of multiplying the sum as 2^−Q.
    q_in_sum: bool,
    /// 2^(E+T), E = ⌈max log₂|W_j|⌉ (so every folded exponent is ≥ 0) and T
    /// the integer offset of the exponents (see `exponent`).
    weight_scale: f32,
    constant_raw: f32,
    /// Linear terms with the normalisation folded in: y_lin = c′ + Σ a′_i x_i,
    /// a′_i = a_i / scale_i, c′ = c − Σ a′_i offset_i.
    linear_raw: [f32; D],
    /// The linear terms over the saturating map of each input's linear box
    /// ([`Self::prepare_linear`]): y_lin = c″ + Σ b_i·f32(i32((x_i − mid_i)·gain_i)).
    linear_box_mid: [f32; D],
    linear_box_gain: [f32; D],
    linear_box_coeff: [f32; D],
    linear_box_constant: f32,
    offset: [f32; D],
    inv_scale: [f32; D],
    /// Per centre [A₁, A₂, A₃, B] in fixed point, packed two to a word
    /// (two LDRDs), centres with positive weights first, then negative ones
    /// (zero weights dropped): W_j·exp(−‖z − c_j‖²/2σ²) = ±2^(E+T) · 2^−Q ·
    /// 2^−v_j with v_j = B_j + Σ_i hi(A_ji, q_i), A_ji = 2S(m_i − c_ji)h_i·2^17
    /// and B_j = S‖m − c_j‖² + E + T − log₂|W_j| (Q[`U_FRAC`]; T = 0 when
    /// Q goes into every exponent instead, see `q_in_sum`); see
    /// [`Self::prepare_table`]. The square expanded, the weight folded in and
    /// the shared term Q taken out of the sum (T ≥ Q keeps v_j ≥ 0): per
    /// centre there is no subtraction, no multiplication by a weight and
    /// nothing but its four coefficients.
    exponent: [[u64; 2]; K],
    scale: [f32; D],
    centers: [[f32; KERNEL]; K],
    widths: [f32; K],
    neg_half_inv_var: [f32; K],
    weights: [f32; K],
    linear: [f32; D],
    has_linear: bool,
    constant: f32,
}

/// Input slots of a feature vector ([`crate::MAX_INPUTS`]).
const MAX_INPUTS_ALL: usize = crate::MAX_INPUTS;
/// Most inputs the Gaussians see ([`crate::MAX_KERNEL_INPUTS`]): centres hold that many coordinates.
const KERNEL: usize = crate::MAX_KERNEL_INPUTS;

/// Most kernel inputs the table path ([`crate::fastmath::exp2_neg_fixed`]) handles.
pub const TABLE_MAX_INPUTS: usize = 3;
/// Fraction bits of the fixed-point Gaussian exponent u (Q16).
const U_FRAC: u32 = 16;

/// The shape rules of a network of capacity `K` × `D`: counts within
/// capacity ([`ModelError::ShapeOverCapacity`]) and agreeing with each
/// other ([`ModelError::ShapeMismatch`]).
fn check_shape<const K: usize, const D: usize>(shape: &RbfShape) -> Result<(), ModelError> {
    let (d, k, m) = (shape.offsets, shape.widths, shape.kernel_inputs);
    if d == 0 || d > D || k > K || m > KERNEL {
        return Err(ModelError::ShapeOverCapacity);
    }
    let linear_ok = shape.linear == 0 || shape.linear == d;
    if !(1..=d).contains(&m) || shape.scales != d || shape.center_values != k * m || shape.weights != k || !linear_ok {
        return Err(ModelError::ShapeMismatch);
    }
    Ok(())
}

fn all_finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl<const K: usize, const D: usize> RbfNetwork<K, D> {
    /// A network with no centres, no inputs and every parameter 0 (all bits
    /// zero, so a `static` holding one costs no flash): what
    /// [`Self::init`] starts from.
    pub const EMPTY: Self = RbfNetwork {
        kernel_inputs: 0,
        centers_used: 0,
        inputs_used: 0,
        positive: 0,
        negative: 0,
        table: false,
        kernel_mid: [0.0; TABLE_MAX_INPUTS],
        kernel_gain: [0.0; TABLE_MAX_INPUTS],
        shared_coeff: [0; TABLE_MAX_INPUTS],
        q_in_sum: false,
        weight_scale: 0.0,
        constant_raw: 0.0,
        linear_raw: [0.0; D],
        linear_box_mid: [0.0; D],
        linear_box_gain: [0.0; D],
        linear_box_coeff: [0.0; D],
        linear_box_constant: 0.0,
        offset: [0.0; D],
        inv_scale: [0.0; D],
        exponent: [[0; 2]; K],
        scale: [0.0; D],
        centers: [[0.0; KERNEL]; K],
        widths: [0.0; K],
        neg_half_inv_var: [0.0; K],
        weights: [0.0; K],
        linear: [0.0; D],
        has_linear: false,
        constant: 0.0,
    };

    /// Builds a network, checking shapes against capacity and every parameter.
    pub fn new(p: &RbfParams<'_>) -> Result<Self, ModelError> {
        let mut net = Self::EMPTY;
        net.init(p)?;
        Ok(net)
    }

    /// [`Self::new`] in place: overwrites `self` with the network `p`
    /// describes (no network is moved by value). On error `self` is
    /// [`Self::EMPTY`].
    pub fn init(&mut self, p: &RbfParams<'_>) -> Result<(), ModelError> {
        *self = Self::EMPTY;
        let result = self.assign(p);
        if result.is_err() {
            *self = Self::EMPTY;
        }
        result
    }

    /// [`Self::init`] for a decoder that writes the parameters straight into
    /// the network's arrays: `fill` gets them (all zero) and returns how
    /// much it filled, or its own error. The same checks as [`Self::init`]
    /// follow. On any error `self` is [`Self::EMPTY`].
    pub fn init_in_place<E: From<ModelError>>(
        &mut self,
        fill: impl FnOnce(RbfStorage<'_>) -> Result<RbfShape, E>,
    ) -> Result<(), E> {
        *self = Self::EMPTY;
        let result = fill(RbfStorage {
            offset: &mut self.offset,
            scale: &mut self.scale,
            centers: &mut self.centers,
            widths: &mut self.widths,
            weights: &mut self.weights,
            linear: &mut self.linear,
        })
        .and_then(|shape| self.finish(&shape).map_err(E::from));
        if result.is_err() {
            *self = Self::EMPTY;
        }
        result
    }

    fn assign(&mut self, p: &RbfParams<'_>) -> Result<(), ModelError> {
        let shape = RbfShape {
            offsets: p.offset.len(),
            scales: p.scale.len(),
            kernel_inputs: p.kernel_inputs,
            center_values: p.centers.len(),
            widths: p.widths.len(),
            weights: p.weights.len(),
            linear: p.linear.len(),
            constant: p.constant,
        };
        check_shape::<K, D>(&shape)?;
        // Zipped iterators rather than indexing: the firmware validates blobs
        // on a path proven panic-free at link time (panic_free_check.rs).
        let copy = |dst: &mut [f32], src: &[f32]| dst.iter_mut().zip(src).for_each(|(d, s)| *d = *s);
        copy(&mut self.offset, p.offset);
        copy(&mut self.scale, p.scale);
        copy(&mut self.linear, p.linear);
        copy(&mut self.widths, p.widths);
        copy(&mut self.weights, p.weights);
        for (row, src) in self
            .centers
            .iter_mut()
            .zip(p.centers.chunks_exact(p.kernel_inputs.max(1)))
        {
            copy(row, src);
        }
        self.finish(&shape)
    }

    /// Checks the parameters in the arrays against `shape` and derives the
    /// evaluation's values from them.
    fn finish(&mut self, shape: &RbfShape) -> Result<(), ModelError> {
        check_shape::<K, D>(shape)?;
        let (d, k, m) = (shape.offsets, shape.widths, shape.kernel_inputs);
        let used = |a: &[f32], n: usize| -> bool { a.get(..n).is_some_and(all_finite) };
        let centers_finite = self
            .centers
            .get(..k)
            .is_some_and(|rows| rows.iter().all(|row| used(row, m)));
        let finite = used(&self.offset, d)
            && used(&self.scale, d)
            && centers_finite
            && used(&self.widths, k)
            && used(&self.weights, k)
            && used(&self.linear, shape.linear)
            && shape.constant.is_finite();
        if !finite {
            return Err(ModelError::NonFiniteParameter);
        }
        let positive = |a: &[f32], n: usize| a.iter().take(n).all(|&v| v > 0.0);
        if !(positive(&self.scale, d) && positive(&self.widths, k)) {
            return Err(ModelError::InvalidParameter);
        }
        let net = self;
        net.centers_used = k;
        net.inputs_used = d;
        net.kernel_inputs = m;
        net.has_linear = shape.linear > 0;
        net.constant = shape.constant;
        net.constant_raw = shape.constant;
        net.weight_scale = 1.0;
        for (inv, s) in net.inv_scale.iter_mut().zip(&net.scale).take(d) {
            *inv = 1.0 / s;
        }
        for (g, w) in net.neg_half_inv_var.iter_mut().zip(&net.widths).take(k) {
            *g = -0.5 / (w * w);
            if !g.is_finite() {
                return Err(ModelError::InvalidParameter);
            }
        }
        if !(all_finite(&net.inv_scale)) {
            return Err(ModelError::InvalidParameter);
        }
        net.fold_linear(d);
        Ok(())
    }

    /// True when [`Self::prepare_table`] enabled the table path.
    pub fn table_ready(&self) -> bool {
        self.table
    }

    /// Number of centres in use.
    pub fn centers_used(&self) -> usize {
        self.centers_used
    }

    /// Number of inputs in use.
    pub fn inputs_used(&self) -> usize {
        self.inputs_used
    }

    /// Number of leading inputs the Gaussians see.
    pub fn kernel_inputs(&self) -> usize {
        self.kernel_inputs
    }

    /// Input offsets (training means), input units.
    pub fn offset(&self) -> &[f32] {
        &self.offset[..self.inputs_used]
    }

    /// Input scales (training standard deviations), input units.
    pub fn scale(&self) -> &[f32] {
        &self.scale[..self.inputs_used]
    }

    /// Centre `j` in normalised units, over the kernel inputs (empty past the last centre).
    pub fn center(&self, j: usize) -> &[f32] {
        self.centers.get(j).map_or(&[], |c| &c[..self.kernel_inputs])
    }

    /// Gaussian widths σ_j, normalised units.
    pub fn widths(&self) -> &[f32] {
        &self.widths[..self.centers_used]
    }

    /// Output weights W_j, °/h.
    pub fn weights(&self) -> &[f32] {
        // `centers_used` ≤ K always; `get` keeps a panic path out of the board's update.
        self.weights.get(..self.centers_used).unwrap_or(&[])
    }

    /// Linear coefficients per normalised input, °/h (empty when the model has none).
    pub fn linear(&self) -> &[f32] {
        if self.has_linear {
            self.linear.get(..self.inputs_used).unwrap_or(&[])
        } else {
            &[]
        }
    }

    /// Constant term, °/h.
    pub fn constant(&self) -> f32 {
        self.constant
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A network of one centre over two kernel inputs, with linear terms.
    pub(super) fn one_center() -> RbfNetwork<4, 3> {
        RbfNetwork::new(&RbfParams {
            offset: &[20.0, 0.0],
            scale: &[10.0, 1.0],
            kernel_inputs: 2,
            centers: &[0.0, 0.0],
            widths: &[1.0],
            weights: &[2.0],
            linear: &[0.5, 0.0],
            constant: 1.0,
        })
        .unwrap()
    }

    #[test]
    fn refuses_shapes_over_capacity_or_inconsistent() {
        let ok = one_center();
        assert_eq!(ok.centers_used(), 1);
        let too_many_inputs = RbfParams {
            offset: &[0.0; 4],
            scale: &[1.0; 4],
            kernel_inputs: 4,
            centers: &[],
            widths: &[],
            weights: &[],
            linear: &[],
            constant: 0.0,
        };
        assert_eq!(
            RbfNetwork::<4, 3>::new(&too_many_inputs),
            Err(ModelError::ShapeOverCapacity)
        );
        let bad_centers = RbfParams {
            offset: &[0.0],
            scale: &[1.0],
            kernel_inputs: 1,
            centers: &[0.0, 1.0],
            widths: &[1.0],
            weights: &[1.0],
            linear: &[],
            constant: 0.0,
        };
        assert_eq!(RbfNetwork::<4, 3>::new(&bad_centers), Err(ModelError::ShapeMismatch));
    }

    #[test]
    fn refuses_non_finite_and_non_positive_parameters() {
        let mut widths = [1.0f32];
        let base = |w: &'_ [f32], c: f32| {
            RbfNetwork::<4, 3>::new(&RbfParams {
                offset: &[0.0],
                scale: &[1.0],
                kernel_inputs: 1,
                centers: &[0.0],
                widths: w,
                weights: &[1.0],
                linear: &[],
                constant: c,
            })
        };
        assert_eq!(base(&widths, f32::NAN), Err(ModelError::NonFiniteParameter));
        widths[0] = 0.0;
        assert_eq!(base(&widths, 0.0), Err(ModelError::InvalidParameter));
        widths[0] = 1e-30; // 1/(2σ²) overflows f32
        assert_eq!(base(&widths, 0.0), Err(ModelError::InvalidParameter));
    }
}
