//! A deployable model: feature configuration, training input ranges and the
//! regression body (Gaussian RBF network or cubic baseline).

pub use crate::error::{MAX_ABS_BIAS_DPH, ModelError};
use crate::fastmath::clamp;
use crate::features::{FeatureConfig, FeatureSet, FeatureVector};
use crate::poly::Poly3;
use crate::rbf::{RbfNetwork, RbfParams, RbfShape, RbfStorage};
use crate::{MAX_CENTERS, MAX_INPUTS};

/// Linear terms may follow an input up to this many training spans beyond
/// either end of its training range (the Gaussians stop at the range).
pub const LINEAR_EXTRAPOLATION_SPANS: f32 = 2.0;

/// Longest unit serial number a blob may carry, bytes of UTF-8.
pub const SERIAL_CAPACITY: usize = 32;

/// Which regression a model holds; the code is stored in the blob header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum ModelKind {
    /// Gaussian RBF network ([`RbfNetwork`]).
    Rbf = 1,
    /// Cubic polynomial in T ([`Poly3`]).
    Poly3 = 2,
}

impl ModelKind {
    /// The kind for a header code, if known.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(ModelKind::Rbf),
            2 => Some(ModelKind::Poly3),
            _ => None,
        }
    }

    /// Short name for reports.
    pub const fn name(self) -> &'static str {
        match self {
            ModelKind::Rbf => "gaussian-rbf",
            ModelKind::Poly3 => "poly3",
        }
    }
}

/// Descriptive data carried in the blob beside the parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelInfo {
    /// Serial number of the gyro the model was calibrated for, if given.
    pub serial: Option<heapless::String<SERIAL_CAPACITY>>,
}

/// The RBF network at the firmware's capacity.
pub type DeployedRbf = RbfNetwork<MAX_CENTERS, MAX_INPUTS>;

/// The regression part of a model.
#[derive(Clone, Debug, PartialEq)]
#[allow(
    clippy::large_enum_variant,
    reason = "no_std without alloc: nothing to box into; one model lives in RAM"
)]
pub enum ModelBody<const K: usize = MAX_CENTERS> {
    /// Gaussian RBF network.
    Rbf(RbfNetwork<K, MAX_INPUTS>),
    /// Cubic baseline in T.
    Poly3(Poly3),
}

/// The parameters of a model body, as [`Model::assign`] takes them.
#[derive(Clone, Copy, Debug)]
pub enum BodyParams<'a> {
    /// A Gaussian RBF network, built in place.
    Rbf(&'a RbfParams<'a>),
    /// A cubic baseline.
    Poly3(Poly3),
}

/// The network of `body`, made an RBF body first if it is not one (in
/// place: a network is never moved by value).
fn rbf_body<const K: usize>(body: &mut ModelBody<K>) -> Result<&mut RbfNetwork<K, MAX_INPUTS>, ModelError> {
    if !matches!(body, ModelBody::Rbf(_)) {
        *body = ModelBody::Rbf(RbfNetwork::EMPTY);
    }
    match body {
        ModelBody::Rbf(net) => Ok(net),
        ModelBody::Poly3(_) => Err(ModelError::ShapeMismatch),
    }
}

/// Result of evaluating a model on one feature vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evaluation {
    /// Estimated gyro bias, °/h.
    pub bias_dph: f32,
    /// At least one input was outside the training range and was clamped.
    pub clamped: bool,
}

/// A complete, validated model: what a blob decodes to and the firmware runs.
///
/// `repr(C)` with the clamping limits and the body first: what
/// [`Self::eval`] reads sits within the immediate offsets of Cortex-M loads.
#[derive(Clone, Debug, PartialEq)]
#[repr(C)]
pub struct Model<const K: usize = MAX_CENTERS> {
    input_min: [f32; MAX_INPUTS],
    input_max: [f32; MAX_INPUTS],
    linear_min: [f32; MAX_INPUTS],
    linear_max: [f32; MAX_INPUTS],
    body: ModelBody<K>,
    features: FeatureConfig,
    info: ModelInfo,
}

impl Model {
    /// Assembles a model, checking that features, ranges and body agree.
    ///
    /// `input_range` holds (min, max) per input in input units: the training range
    /// that inputs are clamped to.
    pub fn new(
        features: FeatureConfig,
        input_range: &[(f32, f32)],
        body: ModelBody,
        info: ModelInfo,
    ) -> Result<Self, ModelError> {
        let mut model = Model { body, ..Self::EMPTY };
        model.complete(&features, input_range, info)?;
        Ok(model)
    }
}

impl<const K: usize> Model<K> {
    /// The model of no gyro: no inputs' ranges, an empty network, every
    /// bit zero (a `static` holding one costs no flash). It evaluates to a
    /// bias of 0; [`crate::blob::decode_into`] fills it in place.
    pub const EMPTY: Self = Model {
        input_min: [0.0; MAX_INPUTS],
        input_max: [0.0; MAX_INPUTS],
        linear_min: [0.0; MAX_INPUTS],
        linear_max: [0.0; MAX_INPUTS],
        body: ModelBody::Rbf(RbfNetwork::EMPTY),
        features: FeatureConfig::single(FeatureSet::Temp, 0.0),
        info: ModelInfo { serial: None },
    };

    /// [`Self::new`] in place, for the firmware's `static` model (no model
    /// is moved by value): the network is built where it will run. On error
    /// `self` is [`Self::EMPTY`].
    pub fn assign(
        &mut self,
        features: &FeatureConfig,
        input_range: &[(f32, f32)],
        body: BodyParams<'_>,
        info: ModelInfo,
    ) -> Result<(), ModelError> {
        self.assign_with(features, input_range, info, |model_body| match body {
            BodyParams::Rbf(params) => rbf_body(model_body)?.init(params),
            BodyParams::Poly3(poly) => {
                *model_body = ModelBody::Poly3(poly);
                Ok(())
            }
        })
    }

    /// [`Self::assign`] for a Gaussian RBF network whose parameters a
    /// decoder writes straight into the network's arrays
    /// ([`RbfNetwork::init_in_place`]: the blob decoder stages nothing).
    pub fn assign_rbf_in_place<E: From<ModelError>>(
        &mut self,
        features: &FeatureConfig,
        input_range: &[(f32, f32)],
        info: ModelInfo,
        fill: impl FnOnce(RbfStorage<'_>) -> Result<RbfShape, E>,
    ) -> Result<(), E> {
        self.assign_with(features, input_range, info, |body| rbf_body(body)?.init_in_place(fill))
    }

    /// Builds the body with `build`, then completes the model; on error
    /// `self` is [`Self::EMPTY`].
    fn assign_with<E: From<ModelError>>(
        &mut self,
        features: &FeatureConfig,
        input_range: &[(f32, f32)],
        info: ModelInfo,
        build: impl FnOnce(&mut ModelBody<K>) -> Result<(), E>,
    ) -> Result<(), E> {
        let result = build(&mut self.body).and_then(|()| self.complete(features, input_range, info).map_err(E::from));
        if result.is_err() {
            *self = Self::EMPTY;
        }
        result
    }

    /// Checks that features, ranges and the body (already in place) agree,
    /// sets the ranges and prepares the network's table path.
    fn complete(
        &mut self,
        features: &FeatureConfig,
        input_range: &[(f32, f32)],
        info: ModelInfo,
    ) -> Result<(), ModelError> {
        let dims = features.dims();
        if dims > MAX_INPUTS {
            return Err(ModelError::ShapeOverCapacity);
        }
        let body_dims = match &self.body {
            ModelBody::Rbf(net) => net.inputs_used(),
            ModelBody::Poly3(_) => {
                if !matches!(features.set, FeatureSet::Temp) {
                    return Err(ModelError::ShapeMismatch);
                }
                1
            }
        };
        if body_dims != dims || input_range.len() != dims {
            return Err(ModelError::ShapeMismatch);
        }
        if !features.is_valid() {
            return Err(ModelError::InvalidParameter);
        }
        self.input_min = [0.0; MAX_INPUTS];
        self.input_max = [0.0; MAX_INPUTS];
        self.linear_min = [0.0; MAX_INPUTS];
        self.linear_max = [0.0; MAX_INPUTS];
        for (i, &(lo, hi)) in input_range.iter().enumerate().take(MAX_INPUTS) {
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(ModelError::NonFiniteParameter);
            }
            if lo > hi {
                return Err(ModelError::InvalidParameter);
            }
            let reach = LINEAR_EXTRAPOLATION_SPANS * (hi - lo);
            let (linear_lo, linear_hi) = (lo - reach, hi + reach);
            if !(linear_lo.is_finite() && linear_hi.is_finite()) {
                return Err(ModelError::InvalidParameter);
            }
            self.input_min[i] = lo;
            self.input_max[i] = hi;
            self.linear_min[i] = linear_lo;
            self.linear_max[i] = linear_hi;
        }
        let (input_min, input_max) = (&self.input_min, &self.input_max);
        if let ModelBody::Rbf(net) = &mut self.body {
            let m = net.kernel_inputs().min(MAX_INPUTS);
            net.prepare_table(&input_min[..m], &input_max[..m]);
            net.prepare_linear(&self.linear_min[..dims], &self.linear_max[..dims]);
        }
        let bound_dph = match &self.body {
            ModelBody::Rbf(net) => net.output_bound(
                &self.linear_min[..dims],
                &self.linear_max[..dims],
                &self.input_min[..dims],
                &self.input_max[..dims],
            ),
            ModelBody::Poly3(p) => p.output_bound(self.input_min[0], self.input_max[0]),
        };
        if bound_dph.is_nan() || bound_dph > MAX_ABS_BIAS_DPH {
            return Err(ModelError::OutputUnbounded);
        }
        self.features = *features;
        self.info = info;
        Ok(())
    }

    /// How the firmware must compute this model's inputs.
    pub fn features(&self) -> &FeatureConfig {
        &self.features
    }

    /// The regression body.
    pub fn body(&self) -> &ModelBody<K> {
        &self.body
    }

    /// Descriptive data (serial number).
    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// The model kind stored in the blob header.
    pub fn kind(&self) -> ModelKind {
        match self.body {
            ModelBody::Rbf(_) => ModelKind::Rbf,
            ModelBody::Poly3(_) => ModelKind::Poly3,
        }
    }

    /// Training range (min, max) of input `i`, input units.
    pub fn input_range(&self, i: usize) -> Option<(f32, f32)> {
        (i < self.features.dims()).then(|| (self.input_min[i], self.input_max[i]))
    }

    /// Evaluates the bias, °/h: nonlinear parts (Gaussians, the cubic) at the
    /// inputs clamped to the training range, linear terms at the inputs clamped
    /// to [`LINEAR_EXTRAPOLATION_SPANS`] spans beyond it (on the RBF table
    /// path by a saturating conversion, [`RbfNetwork::prepare_linear`]: no
    /// compares; a NaN input reads as its box's centre). `clamped` says that
    /// an input left its training range.
    pub fn eval(&self, features: &FeatureVector) -> Evaluation {
        // The input clamping is straight-line per input count (1, 2, 3, the
        // 8 of the multi-scale sets and of the default lag bank, or up to
        // MAX_INPUTS); the Gaussians of the table path, with the network's
        // per-centre loops, are one copy after it.
        let raw = features.values();
        let table_net = match &self.body {
            ModelBody::Rbf(net) if net.table_ready() => Some(net),
            _ => None,
        };
        let (value, clamped) = match self.features.dims() {
            1 => self.eval_inputs::<1>(raw, table_net),
            2 => self.eval_inputs::<2>(raw, table_net),
            3 => self.eval_inputs::<3>(raw, table_net),
            8 => self.eval_inputs::<8>(raw, table_net),
            _ => self.eval_inputs::<MAX_INPUTS>(raw, table_net),
        };
        let bias_dph = match table_net {
            // The table path clamps kernel inputs itself, to the same training box.
            Some(net) => value + net.table_gaussians(raw),
            None => value,
        };
        Evaluation { bias_dph, clamped }
    }

    /// The clamping of [`Self::eval`] for `N` inputs and the value of
    /// everything but the Gaussians of `table_net` (the network when its
    /// table path is ready: then its linear terms), with whether an input
    /// left its training range.
    #[inline(always)]
    fn eval_inputs<const N: usize>(
        &self,
        raw: &[f32; MAX_INPUTS],
        table_net: Option<&RbfNetwork<K, MAX_INPUTS>>,
    ) -> (f32, bool) {
        let mut outside = 0.0f32;
        for (v, (lo, hi)) in raw.iter().zip(self.input_min.iter().zip(&self.input_max)).take(N) {
            outside += outside_measure(*v, *lo, *hi);
        }
        let value = match (table_net, &self.body) {
            (Some(net), _) => net.linear_sum_boxed::<N>(raw),
            (None, body) => {
                let mut x_linear = [0.0f32; N];
                for ((li, v), (llo, lhi)) in x_linear
                    .iter_mut()
                    .zip(raw)
                    .zip(self.linear_min.iter().zip(&self.linear_max))
                {
                    *li = clamp(*v, *llo, *lhi);
                }
                let mut x = [0.0f32; N];
                for ((xi, v), (lo, hi)) in x.iter_mut().zip(raw).zip(self.input_min.iter().zip(&self.input_max)) {
                    *xi = clamp(*v, *lo, *hi);
                }
                match body {
                    ModelBody::Rbf(net) => net.eval(&x, &x_linear),
                    ModelBody::Poly3(p) => p.eval(x[0]),
                }
            }
        };
        (value, outside_flag(outside))
    }

    /// The linear box (min, max per input, input units): where linear terms
    /// stop following an input.
    pub(crate) fn linear_box(&self) -> (&[f32], &[f32]) {
        let d = self.features.dims().min(MAX_INPUTS);
        (&self.linear_min[..d], &self.linear_max[..d])
    }

    /// The evaluation of a shared basis ([`crate::shared_basis`]): this model's
    /// network is the basis (every weight 1, no linear terms), `weights`
    /// hold each centre's three output-layer weights and `linear` each
    /// layer's linear terms ([`RbfNetwork::linear_box_terms`]). The same
    /// clamping and flag as [`Self::eval`]; the kernels once, then one
    /// weighted sum and one linear sum per layer. A body that is not a
    /// network gives three zeros.
    #[inline(always)]
    pub(crate) fn eval_layers(
        &self,
        features: &FeatureVector,
        weights: &[[f32; 3]],
        linear: &[([f32; MAX_INPUTS], f32); 3],
    ) -> ([f32; 3], bool) {
        let raw = features.values();
        let ModelBody::Rbf(net) = &self.body else {
            return ([0.0; 3], false);
        };
        // Two shapes of their own (the contract's three inputs, the lag
        // bank's eight); fewer inputs go through the widest, whose inputs
        // past `dims` are 0 with range [0, 0] and no linear term: the same
        // sums and flag, less code in a board image.
        let (lin, clamped) = match self.features.dims() {
            3 => self.layer_linear::<3>(net, raw, linear),
            8 => self.layer_linear::<8>(net, raw, linear),
            _ => self.layer_linear::<MAX_INPUTS>(net, raw, linear),
        };
        let kernels = if net.table_ready() {
            net.kernel_dots(raw, weights)
        } else {
            let mut x = [0.0f32; MAX_INPUTS];
            for ((xi, v), (lo, hi)) in x.iter_mut().zip(raw).zip(self.input_min.iter().zip(&self.input_max)) {
                *xi = clamp(*v, *lo, *hi);
            }
            net.kernel_dots(&x, weights)
        };
        ([lin[0] + kernels[0], lin[1] + kernels[1], lin[2] + kernels[2]], clamped)
    }

    /// The range test of [`Self::eval`] and the linear sums of
    /// [`Self::eval_layers`] for `N` inputs.
    #[inline(always)]
    fn layer_linear<const N: usize>(
        &self,
        net: &RbfNetwork<K, MAX_INPUTS>,
        raw: &[f32; MAX_INPUTS],
        linear: &[([f32; MAX_INPUTS], f32); 3],
    ) -> ([f32; 3], bool) {
        let mut outside = 0.0f32;
        for (v, (lo, hi)) in raw.iter().zip(self.input_min.iter().zip(&self.input_max)).take(N) {
            outside += outside_measure(*v, *lo, *hi);
        }
        let sums = [
            net.linear_sum_with::<N>(raw, &linear[0].0, linear[0].1),
            net.linear_sum_with::<N>(raw, &linear[1].0, linear[1].1),
            net.linear_sum_with::<N>(raw, &linear[2].0, linear[2].1),
        ];
        (sums, outside_flag(outside))
    }

    /// The model's mathematical value at `features` in f64 with exact
    /// exponentials (same clamping as [`Self::eval`]): the reference the
    /// deployed evaluation is measured against (host tools and tests; the
    /// firmware never calls it).
    pub fn eval_reference(&self, features: &FeatureVector) -> f64 {
        let raw = features.values();
        let mut x = [0.0f64; MAX_INPUTS];
        let mut x_linear = [0.0f64; MAX_INPUTS];
        for (i, v) in raw.iter().enumerate().take(MAX_INPUTS) {
            x[i] = f64::from(clamp(*v, self.input_min[i], self.input_max[i]));
            x_linear[i] = f64::from(clamp(*v, self.linear_min[i], self.linear_max[i]));
        }
        match &self.body {
            ModelBody::Rbf(net) => net.eval_reference(&x, &x_linear),
            ModelBody::Poly3(p) => {
                let u = x[0] - f64::from(p.ref_temp_c);
                let [c0, c1, c2, c3] = p.coeffs.map(f64::from);
                c0 + u * (c1 + u * (c2 + u * c3))
            }
        }
    }
}

/// 0 when `v` lies in [lo, hi], positive when outside, NaN when `v` is NaN:
/// with d = (v − lo)(hi − v), whose sign says inside (≥ 0) or outside
/// (< 0) exactly, |d| − d. Summed over the inputs and tested once by
/// [`outside_flag`]: four f32 operations per input and no compare, where a
/// range test costs two compares and two flag transfers. Conservative for
/// ranges wider than about 1e19, where d may overflow to +∞ and ∞ − ∞
/// flags an input inside them.
#[inline(always)]
fn outside_measure(v: f32, lo: f32, hi: f32) -> f32 {
    let d = (v - lo) * (hi - v);
    d.abs() - d
}

/// Whether a sum of [`outside_measure`]s says that an input left its range.
#[inline(always)]
#[allow(
    clippy::neg_cmp_op_on_partial_ord,
    reason = "the negated comparison is what makes NaN count as outside"
)]
fn outside_flag(sum: f32) -> bool {
    !(sum <= 0.0)
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::features::{FeatureExtractor, loop_reading};

    fn poly_model() -> Model {
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let body = ModelBody::Poly3(Poly3::new(20.0, [0.0, 1.0, 0.0, 0.0]).unwrap());
        Model::new(cfg, &[(10.0, 30.0)], body, ModelInfo::default()).unwrap()
    }

    #[test]
    fn inputs_outside_the_training_range_are_clamped_and_flagged() {
        let model = poly_model();
        let mut fx = FeatureExtractor::new();
        let inside = model.eval(&fx.update(model.features(), 1.0, &loop_reading(25.0)));
        assert_eq!(
            inside,
            Evaluation {
                bias_dph: 5.0,
                clamped: false
            }
        );
        let hot = model.eval(&fx.update(model.features(), 1.0, &loop_reading(45.0)));
        assert_eq!(
            hot,
            Evaluation {
                bias_dph: 10.0,
                clamped: true
            }
        );
        let cold = model.eval(&fx.update(model.features(), 1.0, &loop_reading(-40.0)));
        assert_eq!(
            cold,
            Evaluation {
                bias_dph: -10.0,
                clamped: true
            }
        );
    }

    #[test]
    fn the_table_path_flags_exactly_the_inputs_outside_the_training_range() {
        use crate::rbf::{RbfNetwork, RbfParams};
        let net = RbfNetwork::new(&RbfParams {
            offset: &[25.0, 0.0, 0.0],
            scale: &[10.0, 1.0, 5.0],
            kernel_inputs: 3,
            centers: &[0.0, 0.0, 0.0, 1.0, -1.0, 0.5],
            widths: &[1.0, 1.0],
            weights: &[0.5, -0.25],
            linear: &[0.1, 0.2, 0.3],
            constant: 0.0,
        })
        .unwrap();
        let cfg = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
        let ranges = [(10.0, 40.0), (-2.0, 2.0), (-10.0, 10.0)];
        let model = Model::new(cfg, &ranges, ModelBody::Rbf(net), ModelInfo::default()).unwrap();
        assert!(matches!(model.body(), ModelBody::Rbf(net) if net.table_ready()));
        let flag = |x: [f32; 3]| model.eval(&FeatureVector::from_values(&x)).clamped;
        assert!(!flag([25.0, 0.0, 0.0]));
        assert!(!flag([10.0, -2.0, 10.0]), "the range's edges are inside");
        assert!(!flag([40.0, 2.0, -10.0]));
        let above_40 = f32::from_bits(40.0f32.to_bits() + 1);
        assert!(flag([above_40, 0.0, 0.0]), "one ulp beyond is outside");
        assert!(flag([25.0, -2.000_001, 0.0]));
        assert!(flag([25.0, 0.0, 1e30]));
        assert!(flag([25.0, f32::NAN, 0.0]));
        assert!(flag([f32::NEG_INFINITY, 0.0, 0.0]));
        // Kernel inputs are clamped to the edge: 5 °C beyond it, only the
        // linear term (0.1 per 10 °C) moves.
        let bias = |x: [f32; 3]| model.eval(&FeatureVector::from_values(&x)).bias_dph;
        let step = bias([45.0, 0.0, 0.0]) - bias([40.0, 0.0, 0.0]);
        assert!((step - 0.05).abs() < 1e-6, "{step}");
    }

    #[test]
    fn linear_terms_extrapolate_two_spans_beyond_the_training_range_gaussians_stop_at_it() {
        use crate::rbf::{RbfNetwork, RbfParams};
        // bias = 1·z_T (linear, scale 1) + 0 Gaussians; training range of T: 10 … 20.
        let net = RbfNetwork::new(&RbfParams {
            offset: &[0.0],
            scale: &[1.0],
            kernel_inputs: 1,
            centers: &[15.0],
            widths: &[1.0],
            weights: &[0.0],
            linear: &[1.0],
            constant: 0.0,
        })
        .unwrap();
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let model = Model::new(cfg, &[(10.0, 20.0)], ModelBody::Rbf(net), ModelInfo::default()).unwrap();
        let mut fx = FeatureExtractor::new();
        let e = model.eval(&fx.update(&cfg, 1.0, &loop_reading(35.0)));
        assert_eq!(
            e,
            Evaluation {
                bias_dph: 35.0,
                clamped: true
            },
            "linear part follows T past the range"
        );
        let e = model.eval(&fx.update(&cfg, 1.0, &loop_reading(100.0)));
        assert_eq!(e.bias_dph, 40.0, "…but no further than two spans (20 + 2·10)");
    }

    #[test]
    fn on_the_table_path_linear_terms_follow_the_input_to_two_spans_and_hold() {
        use crate::rbf::{RbfNetwork, RbfParams};
        // bias = 1·z_T + 0.5·Gaussian; training range of T: 10 … 20, so the
        // Gaussian holds its value at 20 beyond it and only the linear part moves.
        let net = RbfNetwork::new(&RbfParams {
            offset: &[0.0],
            scale: &[1.0],
            kernel_inputs: 1,
            centers: &[15.0],
            widths: &[3.0],
            weights: &[0.5],
            linear: &[1.0],
            constant: 0.0,
        })
        .unwrap();
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let model = Model::new(cfg, &[(10.0, 20.0)], ModelBody::Rbf(net), ModelInfo::default()).unwrap();
        assert!(
            matches!(&model.body, ModelBody::Rbf(n) if n.table_ready()),
            "the table path runs"
        );
        let bias = |t: f32| model.eval(&FeatureVector::from_values(&[t])).bias_dph;
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * b.abs().max(1.0);
        assert!(close(bias(35.0) - bias(25.0), 10.0), "{}", bias(35.0) - bias(25.0));
        assert!(
            close(bias(100.0), bias(40.0)),
            "held at 20 + 2·10: {} {}",
            bias(100.0),
            bias(40.0)
        );
        assert!(close(bias(-1e9), bias(-10.0)), "and at 10 − 2·10");
        assert!(
            bias(f32::NAN).is_finite(),
            "NaN reads as a point of the box, not as NaN"
        );
    }

    #[test]
    fn the_empty_model_evaluates_to_zero_bias_without_flagging() {
        let empty: Model = Model::EMPTY;
        let e = empty.eval(&FeatureVector::from_values(&[25.0]));
        assert_eq!(e.bias_dph.to_bits(), 0f32.to_bits());
        assert_eq!(empty.features().dims(), 1);
    }

    #[test]
    fn refuses_inconsistent_assemblies() {
        let cfg = FeatureConfig::single(FeatureSet::TempRate, 0.0);
        let body = ModelBody::Poly3(Poly3::new(20.0, [0.0; 4]).unwrap());
        let err = Model::new(cfg, &[(0.0, 1.0)], body.clone(), ModelInfo::default());
        assert_eq!(err, Err(ModelError::ShapeMismatch));
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let err = Model::new(cfg, &[(2.0, 1.0)], body.clone(), ModelInfo::default());
        assert_eq!(err, Err(ModelError::InvalidParameter));
        let bad_window = FeatureConfig::single(FeatureSet::Temp, -1.0);
        let err = Model::new(bad_window, &[(0.0, 1.0)], body, ModelInfo::default());
        assert_eq!(err, Err(ModelError::InvalidParameter));
    }
}
