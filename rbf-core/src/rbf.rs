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

use crate::error::ModelError;

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
/// Bound every fixed-point partial sum must stay under (no i32 overflow).
const FIXED_LIMIT: f64 = (1u32 << 30) as f64;
/// Exponent range a Gaussian term needs: terms below 2^−32 of the largest
/// weight may be dropped. The offset T may use the rest of the table's range.
const GAUSS_EXP2_RANGE: u32 = 32;

/// [A₁, A₂, A₃, B] as two 64-bit words: loaded with two LDRDs.
fn pack_coefficients(c: [i32; 4]) -> [u64; 2] {
    let word = |lo: i32, hi: i32| u64::from(lo as u32) | (u64::from(hi as u32) << 32);
    [word(c[0], c[1]), word(c[2], c[3])]
}

/// Inverse of [`pack_coefficients`].
#[inline(always)]
fn unpack_coefficients(p: u64, q: u64) -> [i32; 4] {
    [
        p as u32 as i32,
        (p >> 32) as u32 as i32,
        q as u32 as i32,
        (q >> 32) as u32 as i32,
    ]
}

/// Σ_pos 2^−v_j − Σ_neg 2^−v_j with v_j = B_j [+ Q when `ADD_Q`] + Σ_i hi(A_ji, q_i)
/// over the first `M` kernel inputs: the per-centre loops of
/// [`RbfNetwork::eval_table`], one small function per (M, ADD_Q) so that
/// each loop is straight-line; everything around it is shared.
#[inline(always)]
fn exp2_sums<const M: usize, const ADD_Q: bool>(
    positive: &[[u64; 2]],
    negative: &[[u64; 2]],
    q: &[i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> f32 {
    let q = *q;
    exp2_sum::<M, ADD_Q>(positive, q, shared) - exp2_sum::<M, ADD_Q>(negative, q, shared)
}

/// Σ_j 2^−v_j over `centres`, in their order.
///
/// Over three kernel inputs, two centres per iteration: LLVM's own
/// unrolling would hold two centres' eight coefficient words, the three
/// q_i, the table, the pointer and the count at once, one register more
/// than a Cortex-M4 has free (r7 is the frame pointer), and rebuild the
/// table's address in every iteration. The empty `black_box` (no
/// instruction) keeps it from unrolling this loop further. With fewer
/// kernel inputs the registers suffice and LLVM's unrolling is left alone.
#[inline(always)]
fn exp2_sum<const M: usize, const ADD_Q: bool>(centres: &[[u64; 2]], q: [i32; TABLE_MAX_INPUTS], shared: i32) -> f32 {
    let table = &crate::fastmath::EXP2_OCTAVE_BITS;
    let mut sum = 0.0f32;
    if M < 3 {
        for centre in centres {
            sum += exp2_term::<M, ADD_Q>(table, centre, q, shared);
        }
        return sum;
    }
    let mut pairs = centres.chunks_exact(2);
    for pair in &mut pairs {
        if let [first, second] = pair {
            sum += exp2_term::<M, ADD_Q>(table, first, q, shared);
            core::hint::black_box(());
            sum += exp2_term::<M, ADD_Q>(table, second, q, shared);
        }
    }
    for centre in pairs.remainder() {
        sum += exp2_term::<M, ADD_Q>(table, centre, q, shared);
    }
    sum
}

/// Σ_j w_j[a]·2^−v_j for the three layers `a`, over `centres` in order
/// (the kernel of [`RbfNetwork::kernel_dots`]): one table exponential and
/// three multiply-adds per centre.
#[inline(always)]
fn exp2_dots<const M: usize, const ADD_Q: bool>(
    centres: &[[u64; 2]],
    weights: &[[f32; 3]],
    q: [i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> [f32; 3] {
    let table = &crate::fastmath::EXP2_OCTAVE_BITS;
    let (mut x, mut y, mut z) = (0.0f32, 0.0f32, 0.0f32);
    for (centre, &[wx, wy, wz]) in centres.iter().zip(weights) {
        let g = exp2_term::<M, ADD_Q>(table, centre, q, shared);
        x += wx * g;
        y += wy * g;
        z += wz * g;
    }
    [x, y, z]
}

/// 2^−v_j of one centre's packed coefficients.
#[inline(always)]
fn exp2_term<const M: usize, const ADD_Q: bool>(
    table: &[u32; crate::fastmath::EXP2_CELLS],
    &[p, r]: &[u64; 2],
    q: [i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> f32 {
    let [a1, a2, a3, b] = unpack_coefficients(p, r);
    let mut v = if ADD_Q { b.wrapping_add(shared) } else { b };
    if M >= 1 {
        v = v.wrapping_add(mul_hi(a1, q[0]));
    }
    if M >= 2 {
        v = v.wrapping_add(mul_hi(a2, q[1]));
    }
    if M >= 3 {
        v = v.wrapping_add(mul_hi(a3, q[2]));
    }
    crate::fastmath::exp2_neg_q16(table, v)
}

/// The largest ⌈log₂ |w|⌉ over the nonzero `weights`, exactly, from their
/// bits: the exponent, one more where the significand is not a power of
/// two. `None` when every weight is 0 or one is ±∞ or NaN. Integer work in
/// one out-of-line loop: exact by construction, where a rounded f64 log2
/// and `ceil` are exact only by care, and small in the board image.
#[inline(never)]
fn max_ceil_log2_abs(weights: &[f32]) -> Option<i32> {
    let mut max = None;
    for w in weights {
        let bits = w.to_bits() & 0x7FFF_FFFF;
        let (biased, significand) = ((bits >> 23) as i32, bits & 0x007F_FFFF);
        let e = match biased {
            _ if bits == 0 => continue,
            0xFF => return None,
            // Subnormal: |w| = significand · 2^−149.
            0 => 31 - significand.leading_zeros() as i32 - 149 + i32::from(!significand.is_power_of_two()),
            _ => biased - 127 + i32::from(significand != 0),
        };
        max = Some(max.map_or(e, |m: i32| m.max(e)));
    }
    max
}

/// 2^n for an integer-valued `n`, exactly `libm::exp2(n) as f32` (0 below
/// 2^−149, +∞ above 2^127) built in the exponent bits: libm's exp2 would
/// bring its lookup table into the firmware for a power of two.
fn exp2_integer(n: f64) -> f32 {
    if n > 127.0 {
        f32::INFINITY
    } else if n >= -126.0 {
        f32::from_bits(((n as i32 + 127) as u32) << 23)
    } else if n >= -149.0 {
        f32::from_bits(1 << (n as i32 + 149) as u32)
    } else {
        0.0
    }
}

/// High word of the 64-bit product: one SMMUL/SMMLA on a Cortex-M4.
#[inline(always)]
fn mul_hi(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b)) >> 32) as i32
}

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
        let centres_finite = self
            .centers
            .get(..k)
            .is_some_and(|rows| rows.iter().all(|row| used(row, m)));
        let finite = used(&self.offset, d)
            && used(&self.scale, d)
            && centres_finite
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

    /// Upper bound of |output| when the linear terms see inputs in
    /// [`linear_lo`, `linear_hi`] and the Gaussians inputs in [`kernel_lo`,
    /// `kernel_hi`] (per input, input units), °/h; +∞ when a normalised input
    /// could leave the finite f32 range (where 0 × ∞ would give NaN).
    ///
    /// Interval arithmetic in f64: |c| + Σ|a_i|·max|z_i| + Σ|W_j| (each Gaussian ≤ 1).
    pub fn output_bound(&self, linear_lo: &[f32], linear_hi: &[f32], kernel_lo: &[f32], kernel_hi: &[f32]) -> f64 {
        let d = self.inputs_used.min(D);
        let max_abs_z = |lo: &[f32], hi: &[f32], i: usize| {
            let z = |x: Option<&f32>| {
                ((f64::from(x.copied().unwrap_or(f32::NAN)) - f64::from(self.offset[i])) * f64::from(self.inv_scale[i]))
                    .abs()
            };
            let m = z(lo.get(i)).max(z(hi.get(i)));
            // Far inside f32: a normalised value, its square and its product stay finite.
            if m <= 1e15 { m } else { f64::INFINITY }
        };
        let mut bound = f64::from(self.constant).abs();
        for i in 0..d {
            let z_linear = max_abs_z(linear_lo, linear_hi, i);
            let z_kernel = max_abs_z(kernel_lo, kernel_hi, i);
            if z_kernel.is_infinite() {
                return f64::INFINITY;
            }
            bound += f64::from(self.linear[i]).abs() * z_linear;
            if z_linear.is_infinite() {
                return f64::INFINITY;
            }
        }
        bound
            + self.weights[..self.centers_used.min(K)]
                .iter()
                .map(|w| f64::from(*w).abs())
                .sum::<f64>()
    }

    /// Folds the input normalisation into the linear terms (f64, rounded once).
    fn fold_linear(&mut self, d: usize) {
        let mut constant = f64::from(self.constant);
        for i in 0..d.min(D) {
            let a = f64::from(self.linear[i]) * f64::from(self.inv_scale[i]);
            self.linear_raw[i] = a as f32;
            constant -= a * f64::from(self.offset[i]);
        }
        self.constant_raw = constant as f32;
    }

    /// Enables the integer table path for Gaussian inputs clamped to
    /// [`kernel_lo`, `kernel_hi`] (input units: the training box) when its
    /// conditions hold: one shared width, at most [`TABLE_MAX_INPUTS`] kernel
    /// inputs, each with a non-empty range, a nonzero weight, a shared-term
    /// offset T ≤ 32 (it must fit the table beside the 32 a term needs) and
    /// every fixed-point quantity of the evaluation provably inside i32.
    /// Otherwise the polynomial path stays. f64 arithmetic rounded once:
    /// deterministic, so host and target prepare the same bits.
    ///
    /// The table path clamps kernel inputs itself, by the saturating
    /// conversion q_i = i32(x_i − mid_i)·gain_i) that maps the box onto the
    /// whole i32 range: z_i = m_i + h_i·q_i/2^31 with m_i, h_i the box's
    /// normalised centre and half-width. Then
    /// S‖z − c_j‖² = S‖m − c_j‖² + Σ_i 2S(m_i − c_ji)h_i·q_i/2^31 + S Σ_i h_i²(q_i/2^31)²,
    /// whose last sum (call it Q, 0 ≤ Q ≤ T) is the same for every centre.
    pub fn prepare_table(&mut self, kernel_lo: &[f32], kernel_hi: &[f32]) {
        self.table = false;
        let (m, k) = (self.kernel_inputs, self.centers_used.min(K));
        let widths = self.widths.get(..k).unwrap_or(&[]);
        let weights = self.weights.get(..k).unwrap_or(&[]);
        let shared = widths
            .first()
            .is_some_and(|w0| widths.iter().all(|w| w.to_bits() == w0.to_bits()));
        let Some(e) = max_ceil_log2_abs(weights) else {
            return;
        };
        if !shared || m > TABLE_MAX_INPUTS {
            return;
        }
        let e = f64::from(e);
        let sigma = f64::from(widths.first().copied().unwrap_or(1.0));
        let s = core::f64::consts::LOG2_E / (2.0 * sigma * sigma);
        let (u_one, q_one) = (f64::from(1u32 << U_FRAC), f64::from(1u32 << 31));
        // The saturating map of each kernel input, and its box in normalised units.
        let (mut mid_z, mut half_z) = ([0.0f64; TABLE_MAX_INPUTS], [0.0f64; TABLE_MAX_INPUTS]);
        let mut t_real = 0.0;
        for i in 0..m {
            let (Some(lo), Some(hi)) = (kernel_lo.get(i), kernel_hi.get(i)) else {
                return;
            };
            let half = (f64::from(*hi) - f64::from(*lo)) / 2.0;
            let mid = ((f64::from(*lo) + f64::from(*hi)) / 2.0) as f32;
            let gain = (q_one / half) as f32;
            if !(half > 0.0 && gain.is_finite() && gain > 0.0) {
                return;
            }
            let scale = f64::from(self.scale[i]);
            mid_z[i] = (f64::from(mid) - f64::from(self.offset[i])) / scale;
            half_z[i] = q_one / f64::from(gain) / scale;
            self.kernel_mid[i] = mid;
            self.kernel_gain[i] = gain;
            t_real += s * half_z[i] * half_z[i];
        }
        // The offset T: an integer, so 2^T is exact. Q in fixed point may
        // exceed T by a unit of 2^−16 through rounding: a v_j of −2^−16 reads
        // as 0, an error far below the table's. Narrow Gaussians over
        // a wide box (T > 32) add Q to every exponent instead (one more
        // instruction per centre): then Q itself must fit.
        let t = libm::ceil(t_real);
        let q_max = t_real * u_one;
        if q_max.is_nan() || q_max >= FIXED_LIMIT {
            return;
        }
        let factored = t <= f64::from(crate::fastmath::EXP2_RANGE - GAUSS_EXP2_RANGE);
        let (offset, q_in_sum) = if factored { (t, 0.0) } else { (0.0, q_max) };
        // Q·2^16 = Σ_i hi(q_i, hi(q_i, H_i)) with H_i = S h_i² 2^18.
        for (h, hz) in self.shared_coeff.iter_mut().zip(&half_z).take(m) {
            let h_fixed = s * hz * hz * f64::from(1u32 << (U_FRAC + 2));
            if h_fixed.is_nan() || h_fixed >= FIXED_LIMIT * 2.0 {
                return;
            }
            *h = h_fixed as i32;
        }
        let mut slot = 0;
        for positive in [true, false] {
            for (c, &w) in self.centers.iter().zip(weights) {
                if w == 0.0 || (w > 0.0) != positive {
                    continue;
                }
                let Some(packed) = self.exponent.get_mut(slot) else {
                    return;
                };
                let mut coeffs = [0i32; 4];
                let (mut dist_sq, mut products_max) = (0.0f64, 0.0f64);
                for (((a, ci), mz), hz) in coeffs.iter_mut().zip(c).zip(&mid_z).zip(&half_z).take(m) {
                    // hi(A, q) = A·q/2^32 = 2S(m − c)h·(q/2^31)·2^16.
                    let diff = mz - f64::from(*ci);
                    let a_real = 2.0 * s * diff * hz;
                    let a_fixed = a_real * u_one * 2.0;
                    if a_fixed.abs() >= FIXED_LIMIT {
                        return;
                    }
                    *a = a_fixed as i32;
                    dist_sq += diff * diff;
                    products_max += a_real.abs() * u_one;
                }
                let b = (s * dist_sq + e + offset - libm::log2(f64::from(w).abs())) * u_one;
                if b + products_max + q_in_sum >= FIXED_LIMIT {
                    return;
                }
                coeffs[3] = b as i32;
                *packed = pack_coefficients(coeffs);
                slot += 1;
            }
            if positive {
                self.positive = slot;
            }
        }
        self.negative = slot - self.positive;
        let weight_scale = exp2_integer(e + offset);
        if weight_scale.is_finite() && weight_scale > 0.0 {
            self.weight_scale = weight_scale;
            self.q_in_sum = !factored;
            self.table = true;
        }
    }

    /// Prepares the linear terms of the table path for inputs clamped to
    /// [`linear_lo`, `linear_hi`] (input units) by the saturating conversion
    /// q_i = i32((x_i − mid_i)·gain_i), which maps the box onto the i32
    /// range: x_i = mid_i + q_i/gain_i, so a′_i x_i = a′_i mid_i + (a′_i/gain_i)·q_i,
    /// and the constants go into c″. An empty box maps every value to its
    /// one point. f64 arithmetic rounded once: host and target agree.
    pub fn prepare_linear(&mut self, linear_lo: &[f32], linear_hi: &[f32]) {
        let mut constant = f64::from(self.constant_raw);
        let q_one = f64::from(1u32 << 31);
        for i in 0..self.inputs_used.min(D) {
            let (lo, hi) = (
                f64::from(linear_lo.get(i).copied().unwrap_or(0.0)),
                f64::from(linear_hi.get(i).copied().unwrap_or(0.0)),
            );
            let mid = ((lo + hi) / 2.0) as f32;
            let half = (hi - lo) / 2.0;
            let gain = if half > 0.0 { (q_one / half) as f32 } else { 0.0 };
            let a = f64::from(self.linear_raw[i]);
            self.linear_box_mid[i] = mid;
            self.linear_box_gain[i] = gain;
            self.linear_box_coeff[i] = if gain > 0.0 { (a / f64::from(gain)) as f32 } else { 0.0 };
            constant += a * f64::from(mid);
        }
        self.linear_box_constant = constant as f32;
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

    /// Evaluates the network on its polynomial path, °/h: the Gaussians at
    /// `x_kernel` (input units, already clamped by the caller), the linear
    /// terms at `x_linear` (the model clamps them to a wider range); `N` is
    /// the model's input count.
    ///
    /// Cost: `K_used × kernel_inputs` multiply-adds, `K_used` f32
    /// exponentials ([`crate::fastmath::exp_neg`]) and `inputs_used` linear
    /// terms, independent of the values. [`Self::eval_table`] is the fast path.
    pub fn eval<const N: usize>(&self, x_kernel: &[f32; N], x_linear: &[f32; N]) -> f32 {
        self.linear_sum(x_linear) + self.polynomial_gaussians(x_kernel)
    }

    /// The Gaussian sum of [`Self::eval`], °/h.
    fn polynomial_gaussians(&self, x_kernel: &[f32]) -> f32 {
        let k = self.centers_used.min(K);
        if k == 0 {
            // A network of linear terms alone (a response bank's): nothing to normalise.
            return 0.0;
        }
        let m = self.kernel_inputs.min(D);
        let mut z = [0.0f32; D];
        for (((zi, x), o), s) in z
            .iter_mut()
            .zip(x_kernel)
            .zip(&self.offset)
            .zip(&self.inv_scale)
            .take(m)
        {
            *zi = (x - o) * s;
        }
        let z = z.get(..m).unwrap_or(&[]);
        let mut sum = 0.0f32;
        for ((c, w), g) in self
            .centers
            .iter()
            .zip(&self.weights)
            .zip(&self.neg_half_inv_var)
            .take(k)
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in z.iter().zip(c) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            sum += w * crate::fastmath::exp_neg(dist_sq * g);
        }
        sum
    }

    /// Evaluates the network on its table path (only meaningful when
    /// [`Self::table_ready`]), °/h: the Gaussians at the kernel inputs
    /// `x_kernel` as they come (the saturating conversion clamps them to the
    /// box given to [`Self::prepare_table`]; NaN reads as the box's centre),
    /// the linear terms at `x_linear`; `x_kernel` holds a feature vector's
    /// slots, the first `kernel_inputs` of which the Gaussians see.
    ///
    /// Σ_j W_j exp(−‖z − c_j‖²/2σ²) = 2^(E+T) · 2^−Q · (Σ_pos 2^−v_j − Σ_neg 2^−v_j)
    /// with the fixed-point exponents of [`Self::prepare_table`] and the
    /// table exponential. Per centre: one integer multiply-accumulate of
    /// high words (SMMLA) per kernel input onto B_j, one saturation, one
    /// table load, the exponent subtraction, one float add; no branch, no
    /// conversion, no weight multiplication. Integer arithmetic, so host and
    /// target agree bit for bit.
    ///
    /// `N` is the caller's linear input count (the linear sum is straight-line).
    #[inline(always)]
    pub fn eval_table<const N: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL], x_linear: &[f32; N]) -> f32 {
        self.linear_sum(x_linear) + self.table_gaussians(x_kernel)
    }

    /// The Gaussian sum of [`Self::eval_table`], °/h.
    #[inline(always)]
    pub(crate) fn table_gaussians(&self, x_kernel: &[f32; MAX_INPUTS_ALL]) -> f32 {
        match self.kernel_inputs {
            1 => self.table_gaussians_over::<1>(x_kernel),
            2 => self.table_gaussians_over::<2>(x_kernel),
            _ => self.table_gaussians_over::<3>(x_kernel),
        }
    }

    /// [`Self::table_gaussians`] over the first `M` kernel inputs: the
    /// inputs past them take no instruction.
    #[inline(always)]
    fn table_gaussians_over<const M: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL]) -> f32 {
        // `as` saturates (VCVT does the same): the clamp to the box. NaN
        // converts to 0, the box's centre.
        let q: [i32; TABLE_MAX_INPUTS] =
            core::array::from_fn(
                |i| match (i < M, x_kernel.get(i), self.kernel_mid.get(i), self.kernel_gain.get(i)) {
                    (true, Some(x), Some(mid), Some(gain)) => ((x - mid) * gain) as i32,
                    _ => 0,
                },
            );
        // Q·2^16 = Σ_i hi(q_i, hi(q_i, H_i)): SMMUL + SMMLA. (hi(hi(q, q), H)
        // would let the compiler see a non-negative factor and widen it.)
        let mut shared = 0i32;
        for (qi, h) in q.iter().zip(&self.shared_coeff).take(M) {
            shared = shared.wrapping_add(mul_hi(*qi, mul_hi(*qi, *h)));
        }
        let (positive, rest) = self.exponent.split_at(self.positive.min(K));
        let negative = rest.get(..self.negative).unwrap_or(&[]);
        if self.q_in_sum {
            exp2_sums::<M, true>(positive, negative, &q, shared) * self.weight_scale
        } else {
            let sums = exp2_sums::<M, false>(positive, negative, &q, 0);
            let factor = crate::fastmath::exp2_neg_q16(&crate::fastmath::EXP2_OCTAVE_BITS, shared) * self.weight_scale;
            sums * factor
        }
    }

    /// Σ_j w_j[a]·exp(−‖z − c_j‖²/2σ²) for each of the three output layers
    /// `a` of a shared basis ([`crate::shared_basis`]): the kernel values are
    /// computed once per centre and weighted three times. On the table path
    /// (only meaningful when [`Self::table_ready`] with every centre at
    /// weight 1, which puts every centre in `exponent` in order with
    /// E = 0) the kernels are 2^T · 2^−Q · 2^−v_j as in
    /// [`Self::eval_table`]; otherwise the polynomial path's exponentials at
    /// `x_kernel` clamped by the caller. Each layer's sum depends only on
    /// its own weights: a layer evaluates to the same bits whichever other
    /// layers are present.
    #[inline(always)]
    pub(crate) fn kernel_dots(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        if !self.table {
            return self.polynomial_kernel_dots(x_kernel, weights);
        }
        match self.kernel_inputs {
            1 => self.table_kernel_dots::<1>(x_kernel, weights),
            2 => self.table_kernel_dots::<2>(x_kernel, weights),
            _ => self.table_kernel_dots::<3>(x_kernel, weights),
        }
    }

    /// [`Self::kernel_dots`] on the table path over the first `M` kernel inputs.
    #[inline(always)]
    fn table_kernel_dots<const M: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        let q: [i32; TABLE_MAX_INPUTS] =
            core::array::from_fn(
                |i| match (i < M, x_kernel.get(i), self.kernel_mid.get(i), self.kernel_gain.get(i)) {
                    (true, Some(x), Some(mid), Some(gain)) => ((x - mid) * gain) as i32,
                    _ => 0,
                },
            );
        let mut shared = 0i32;
        for (qi, h) in q.iter().zip(&self.shared_coeff).take(M) {
            shared = shared.wrapping_add(mul_hi(*qi, mul_hi(*qi, *h)));
        }
        let centres = self.exponent.get(..self.positive.min(K)).unwrap_or(&[]);
        let (sums, factor) = if self.q_in_sum {
            (exp2_dots::<M, true>(centres, weights, q, shared), self.weight_scale)
        } else {
            let factor = crate::fastmath::exp2_neg_q16(&crate::fastmath::EXP2_OCTAVE_BITS, shared) * self.weight_scale;
            (exp2_dots::<M, false>(centres, weights, q, 0), factor)
        };
        sums.map(|s| s * factor)
    }

    /// [`Self::kernel_dots`] on the polynomial path. Its normalisation and
    /// kernel loop repeat [`Self::polynomial_gaussians`]' on purpose: one
    /// helper taking a closure for both cost the board image flash and every
    /// evaluation instructions (`cargo xtask bench-fw` shows both).
    fn polynomial_kernel_dots(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        let m = self.kernel_inputs.min(D);
        let mut z = [0.0f32; D];
        for (((zi, x), o), s) in z
            .iter_mut()
            .zip(x_kernel)
            .zip(&self.offset)
            .zip(&self.inv_scale)
            .take(m)
        {
            *zi = (x - o) * s;
        }
        let z = z.get(..m).unwrap_or(&[]);
        let mut sums = [0.0f32; 3];
        for ((c, w), g) in self
            .centers
            .iter()
            .zip(weights)
            .zip(&self.neg_half_inv_var)
            .take(self.centers_used.min(K))
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in z.iter().zip(c) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            let kernel = crate::fastmath::exp_neg(dist_sq * g);
            for (s, wa) in sums.iter_mut().zip(w) {
                *s += wa * kernel;
            }
        }
        sums
    }

    /// The linear terms of an output layer with coefficients `linear` (per
    /// normalised input, °/h; empty for none) and constant `constant`, °/h,
    /// in the form [`Self::linear_sum_with`] evaluates: (b_i, c″) as
    /// [`Self::fold_linear`] and [`Self::prepare_linear`] derive them for
    /// the network's own terms, in the same f64 steps rounded at the same
    /// places, over the linear boxes already prepared.
    pub(crate) fn linear_box_terms(&self, linear: &[f32], constant: f32) -> ([f32; D], f32) {
        let d = self.inputs_used.min(D);
        let mut raw = [0.0f32; D];
        let mut folded = f64::from(constant);
        for (i, (r, a)) in raw.iter_mut().zip(linear).take(d).enumerate() {
            let a = f64::from(*a) * f64::from(self.inv_scale[i]);
            *r = a as f32;
            folded -= a * f64::from(self.offset[i]);
        }
        let mut boxed = f64::from(folded as f32);
        let mut coeff = [0.0f32; D];
        for i in 0..d {
            let a = f64::from(raw[i]);
            let gain = self.linear_box_gain[i];
            coeff[i] = if gain > 0.0 { (a / f64::from(gain)) as f32 } else { 0.0 };
            boxed += a * f64::from(self.linear_box_mid[i]);
        }
        (coeff, boxed as f32)
    }

    /// [`Self::linear_sum_boxed`] with an output layer's own (b_i, c″)
    /// ([`Self::linear_box_terms`]).
    #[inline(always)]
    pub(crate) fn linear_sum_with<const N: usize>(
        &self,
        raw: &[f32; MAX_INPUTS_ALL],
        coeff: &[f32; D],
        constant: f32,
    ) -> f32 {
        let mut y = constant;
        for (((x, mid), gain), b) in raw
            .iter()
            .zip(&self.linear_box_mid)
            .zip(&self.linear_box_gain)
            .zip(coeff)
            .take(N)
        {
            y += b * (((x - mid) * gain) as i32) as f32;
        }
        y
    }

    /// [`Self::output_bound`] of an output layer over this network's basis:
    /// `linear` and `constant` in place of the network's, Σ|W_j| given.
    pub(crate) fn layer_output_bound(
        &self,
        linear: &[f32],
        constant: f32,
        weight_abs_sum: f64,
        linear_lo: &[f32],
        linear_hi: &[f32],
    ) -> f64 {
        let d = self.inputs_used.min(D);
        let mut bound = f64::from(constant).abs() + weight_abs_sum;
        for i in 0..d {
            let z = |x: Option<&f32>| {
                ((f64::from(x.copied().unwrap_or(f32::NAN)) - f64::from(self.offset[i])) * f64::from(self.inv_scale[i]))
                    .abs()
            };
            let m = z(linear_lo.get(i)).max(z(linear_hi.get(i)));
            let m = if m <= 1e15 { m } else { f64::INFINITY };
            let a = f64::from(linear.get(i).copied().unwrap_or(0.0)).abs();
            if m.is_infinite() {
                return f64::INFINITY;
            }
            bound += a * m;
        }
        bound
    }

    /// The linear terms at `raw` clamped to the box given to
    /// [`Self::prepare_linear`] by the saturating conversion (NaN reads as
    /// the box's centre): no compare, no branch.
    #[inline(always)]
    pub(crate) fn linear_sum_boxed<const N: usize>(&self, raw: &[f32; MAX_INPUTS_ALL]) -> f32 {
        let mut y = self.linear_box_constant;
        for (((x, mid), gain), b) in raw
            .iter()
            .zip(&self.linear_box_mid)
            .zip(&self.linear_box_gain)
            .zip(&self.linear_box_coeff)
            .take(N)
        {
            y += b * (((x - mid) * gain) as i32) as f32;
        }
        y
    }

    /// c′ + Σ a′_i x_i: the linear terms with the normalisation folded in.
    #[inline(always)]
    pub(crate) fn linear_sum<const N: usize>(&self, x_linear: &[f32; N]) -> f32 {
        let mut y = self.constant_raw;
        for (a, x) in self.linear_raw.iter().zip(x_linear) {
            y += a * x;
        }
        y
    }

    /// The network's value in f64 with exact exponentials (libm), from its
    /// stored parameters: the reference for the deployed evaluation's error.
    pub fn eval_reference(&self, x_kernel: &[f64], x_linear: &[f64]) -> f64 {
        let d = self.inputs_used.min(D);
        let z = |x: &[f64], i: usize| {
            (x.get(i).copied().unwrap_or(0.0) - f64::from(self.offset[i])) / f64::from(self.scale[i])
        };
        let mut y = f64::from(self.constant);
        for i in 0..d {
            y += f64::from(self.linear[i]) * z(x_linear, i);
        }
        for j in 0..self.centers_used.min(K) {
            let mut dist_sq = 0.0;
            for i in 0..self.kernel_inputs.min(d) {
                let diff = z(x_kernel, i) - f64::from(self.centers[j][i]);
                dist_sq += diff * diff;
            }
            let sigma = f64::from(self.widths[j]);
            y += f64::from(self.weights[j]) * libm::exp(-dist_sq / (2.0 * sigma * sigma));
        }
        y
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    /// Kernel inputs as a feature vector's slots (the rest 0).
    fn slots(x: &[f32]) -> [f32; MAX_INPUTS_ALL] {
        core::array::from_fn(|i| x.get(i).copied().unwrap_or(0.0))
    }

    fn one_centre() -> RbfNetwork<4, 3> {
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
    fn both_paths_evaluate_the_documented_formula() {
        let poly = one_centre();
        let mut table = one_centre();
        table.prepare_table(&[0.0, -5.0], &[40.0, 5.0]);
        assert!(table.table_ready() && !poly.table_ready());
        // The table path: each Gaussian within the table exponential's bound,
        // twice (its own term and the shared factor), W = 2; the polynomial
        // path is far closer.
        let tol = 2.0 * 2.0 * crate::fastmath::EXP2_FIXED_REL_ERROR + 1e-6;
        let both = |kernel: [f32; 2], linear: [f32; 2]| {
            let p = poly.eval(&[kernel[0], kernel[1], 0.0], &[linear[0], linear[1], 0.0]);
            (f64::from(p), f64::from(table.eval_table(&slots(&kernel), &linear)))
        };
        let cases = [
            // At the centre: c + 0 + W·exp(0) = 1 + 2 = 3.
            ([20.0, 0.0], [20.0, 0.0], 3.0),
            // One σ away along T (z = 1): 1 + 0.5 + 2·e^{−1/2}.
            ([30.0, 0.0], [30.0, 0.0], 1.0 + 0.5 + 2.0 * (-0.5f64).exp()),
            // The Gaussians and the linear terms take their own inputs.
            ([30.0, 0.0], [40.0, 0.0], 1.0 + 0.5 * 2.0 + 2.0 * (-0.5f64).exp()),
            // Off-axis: z = (−1, 2), ‖z‖² = 5.
            ([10.0, 2.0], [10.0, 2.0], 1.0 - 0.5 + 2.0 * (-2.5f64).exp()),
        ];
        for (kernel, linear, expected) in cases {
            let (p, t) = both(kernel, linear);
            assert!((p - expected).abs() < 1e-6, "{kernel:?}: polynomial {p} vs {expected}");
            assert!((t - expected).abs() < tol, "{kernel:?}: table {t} vs {expected}");
        }
    }

    #[test]
    fn the_table_path_clamps_kernel_inputs_to_its_box() {
        let mut table = one_centre();
        table.prepare_table(&[0.0, -5.0], &[40.0, 5.0]);
        let at = |t: f32, r: f32| table.eval_table(&slots(&[t, r]), &[20.0, 0.0]).to_bits();
        assert_eq!(at(55.0, 0.0), at(40.0, 0.0), "above the box: its edge");
        assert_eq!(at(-1e30, 0.0), at(0.0, 0.0), "far below: its edge");
        assert_eq!(at(20.0, f32::INFINITY), at(20.0, 5.0));
        assert_eq!(at(f32::NAN, 0.0), at(20.0, 0.0), "NaN reads as the box's centre");
    }

    #[test]
    fn table_path_matches_the_polynomial_path_within_its_bound() {
        // The same network with per-centre widths (polynomial exponential) and
        // with a shared width (table exponential), over a grid of inputs.
        let centers = [0.3, -0.2, 0.1, -1.0, 0.5, 0.8, 1.2, 0.0, -0.7];
        let build = |widths: &[f32]| {
            RbfNetwork::<4, 3>::new(&RbfParams {
                offset: &[25.0, 0.0, 0.0],
                scale: &[10.0, 1.0, 20.0],
                kernel_inputs: 3,
                centers: &centers,
                widths,
                weights: &[1.5, -2.0, 0.7],
                linear: &[],
                constant: 0.0,
            })
            .unwrap()
        };
        let (lo, hi) = ([5.0, -2.0, -40.0], [45.0, 2.0, 40.0]);
        // σ = 0.8: T = S Σh² = 13.5, the shared term is a factor; σ = 0.3:
        // T = 96, it is added to every exponent.
        for (sigma, q_in_sum) in [(0.8f32, false), (0.3, true)] {
            let mut table = build(&[sigma; 3]);
            table.prepare_table(&lo, &hi);
            let mut exact = build(&[sigma, sigma, sigma * (1.0 + f32::EPSILON)]);
            exact.prepare_table(&lo, &hi);
            assert!(table.table_ready() && !exact.table_ready());
            assert_eq!(table.q_in_sum, q_in_sum, "σ = {sigma}");
            // Each term's table error, and the shared factor's on the sum.
            let rel = (1.0 + crate::fastmath::EXP2_FIXED_REL_ERROR).powi(2) - 1.0;
            let bound = (1.5 + 2.0 + 0.7) * rel;
            for i in 0..40 {
                let x = [5.0 + i as f32, -2.0 + 0.1 * i as f32, 40.0 - 2.0 * i as f32];
                let (a, b) = (table.eval_table(&slots(&x), &x), exact.eval(&x, &x));
                assert!((a - b).abs() as f64 <= bound + 1e-5, "σ = {sigma}, {x:?}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn integer_powers_of_two_match_libm_bit_for_bit() {
        for n in -200..=200 {
            let n = f64::from(n);
            assert_eq!(exp2_integer(n).to_bits(), (libm::exp2(n) as f32).to_bits(), "2^{n}");
        }
    }

    #[test]
    fn refuses_shapes_over_capacity_or_inconsistent() {
        let ok = one_centre();
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
        let bad_centres = RbfParams {
            offset: &[0.0],
            scale: &[1.0],
            kernel_inputs: 1,
            centers: &[0.0, 1.0],
            widths: &[1.0],
            weights: &[1.0],
            linear: &[],
            constant: 0.0,
        };
        assert_eq!(RbfNetwork::<4, 3>::new(&bad_centres), Err(ModelError::ShapeMismatch));
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
