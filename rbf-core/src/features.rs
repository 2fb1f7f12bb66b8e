//! Streaming fiber-loop temperature features.
//!
//! Per gyro sample the extractor turns (time step, loop temperature) into the
//! model inputs: T in °C, ΔT in °C/min and their product T×ΔT in °C²/min.
//!
//! ## What ΔT means
//! A per-sample difference is quantisation noise at kilohertz rates (a TMP117
//! LSB is 0.0078 °C), so ΔT is the rate of change in °C/min through a
//! first-order derivative filter with time constant τ = `rate_window_s`:
//!
//! ```text
//! ΔT_i = (T_i − S_{i−1}) / (τ + dt_i)          [°C/s, reported ×60 as °C/min]
//! S_i  = S_{i−1} + dt_i · ΔT_i                 (S: the smoothed temperature)
//! ```
//!
//! On a steady ramp of r °C/min this reads exactly r at any sample rate and
//! with jitter; noise is averaged over about τ. With τ = 0, S_i = T_i and
//! ΔT_i = (T_i − T_{i−1}) / dt_i: the IFOG paper's Eq. 22 (ΔT_i = T_i − T_{i−1},
//! 0 for i = 1) expressed per minute. τ is stored in the model blob, so the
//! firmware computes exactly what the trainer fitted on.
//!
//! After a start or a gap the filter restarts with S = T (ΔT = 0) and the
//! samples of the next 3τ are flagged as warming up (the filter's step
//! response has then settled to 95 %).
//!
//! ## Several time scales
//! The Shupe bias follows the time derivative of the coil's whole temperature
//! distribution, whose inner layers lag the outer ones: the loop sensor's rate
//! seen through derivative filters of three time constants (fast, slow,
//! slower) spans that history. The bias also follows a nonlinear static term
//! of the *mean* coil temperature T̄, which lags the sensor by an amount L·ΔT
//! proportional to the rate: f(T − L·ΔT) = f(T) − f′(T)·L·ΔT + ½f″(T)·L²·ΔT² − …
//! The first-order correction is the static term's derivative (quadratic in T
//! for a cubic) times the rate, the second-order one the rate squared.
//! [`FeatureSet::MultiScale`] gives T, the three ΔT, their products with T and
//! T²×ΔT₂: first-order terms only. [`FeatureSet::MultiScaleSecondOrder`] has
//! ΔT₃² (the slowest scale carries the coil's lag) in place of T×ΔT₁.
//! [`FeatureSet::MultiScaleLagged`] takes the whole lag into the nonlinear
//! part instead of its Taylor terms: the Gaussians see T̄ = T − L·ΔT₃, the
//! mean coil temperature estimated with a coil lag L (minutes) that the
//! trainer chooses by validation. The trainer's default fits these sets and
//! keeps a second-order one only where it validates clearly better. Warm-up
//! there counts 3 × the fastest τ; the slower filters start from the steady
//! state (ΔT = 0) like the fast one.
//!
//! ## Several thermometers
//! The RLG paper's method reads up to [`THERMOMETERS`] thermometers
//! (`temp_a` … `temp_h`; `temp_c` is the fiber-loop sensor the single-point
//! sets use) and feeds a selection of their temperatures and pairwise
//! gradients T_i − T_j to the model: [`FeatureSet::MultiPoint`] with its
//! [`Probes`]. These inputs need no filter state (no warm-up beyond the first
//! sample of a segment).

use serde::{Deserialize, Serialize};

use crate::MAX_INPUTS;
use crate::filter::DerivativeFilter;
pub use crate::lag_bank::{BANK_FILTERS, BankInput, GainOf, LagBank};
use crate::response_bank::{BANK_SIGNALS, WEIGHT_ROWS};
pub use crate::response_bank::{BankChannels, BankFilters, RESPONSE_FILTERS, ResponseBank, ResponseInput};
pub use crate::thermometer::{LOOP_THERMOMETER, THERMOMETERS, ThermometerSet, thermometer_letter};

/// Derivative filters of the loop temperature the extractor runs for every
/// set but the response bank (which runs its own, [`BankFilters`]): a lag
/// bank's ([`BANK_FILTERS`]), more than the multi-scale sets' [`WINDOWS`].
const FILTERS: usize = BANK_FILTERS;
const _: () = assert!(WINDOWS <= FILTERS);
/// Most inputs of a multi-point model (the RLG method's thermometer selection);
/// its blob encoding holds exactly this many probe slots.
pub const MAX_PROBES: usize = 8;

/// Warm-up lasts this many filter time constants (95 % settled).
const WARMUP_TIME_CONSTANTS: f32 = 3.0;
/// Longest derivative time constant accepted, s (one day).
const MAX_RATE_WINDOW_S: f32 = 86_400.0;

/// One multi-point model input, from thermometers by index (0 = `temp_a` … 7 = `temp_h`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Probe {
    /// The temperature of thermometer i, °C.
    Temp(u8),
    /// The gradient T_i − T_j between thermometers i and j, °C.
    Gradient(u8, u8),
}

impl Probe {
    /// The thermometers this input reads.
    pub const fn thermometers(self) -> ThermometerSet {
        ThermometerSet::from_bits(self.thermometer_bits())
    }

    /// [`Probe::thermometers`] as bits, what [`Probes::thermometers`] folds:
    /// over bare bits LLVM compiles the board's step smaller than over sets
    /// (`cargo xtask bench-fw` shows the flash).
    const fn thermometer_bits(self) -> u8 {
        match self {
            Probe::Temp(i) => bit(i),
            Probe::Gradient(i, j) => bit(i) | bit(j),
        }
    }

    /// True when the indices name thermometers and a gradient joins two different ones.
    pub const fn is_valid(self) -> bool {
        let n = THERMOMETERS as u8;
        match self {
            Probe::Temp(i) => i < n,
            Probe::Gradient(i, j) => i < n && j < n && i != j,
        }
    }

    /// The input's value from the thermometer readings, °C.
    #[inline]
    pub fn value(self, temps_c: &[f32; THERMOMETERS]) -> f32 {
        let at = |i: u8| temps_c.get(i as usize).copied().unwrap_or(0.0);
        match self {
            Probe::Temp(i) => at(i),
            Probe::Gradient(i, j) => at(i) - at(j),
        }
    }
}

/// Thermometer readings with the fiber loop at `temp_c` and the others at
/// 0 °C: what single-point feature sets read.
pub const fn loop_reading(temp_c: f32) -> [f32; THERMOMETERS] {
    let mut temps = [0.0; THERMOMETERS];
    temps[LOOP_THERMOMETER] = temp_c;
    temps
}

/// Bit `i` of a thermometer set (0 past the eighth thermometer).
const fn bit(i: u8) -> u8 {
    ThermometerSet::of(i).bits()
}

impl core::fmt::Display for Probe {
    /// `temp_a [°C]` or `temp_c − temp_e [°C]`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Probe::Temp(i) => write!(f, "temp_{} [°C]", thermometer_letter(i)),
            Probe::Gradient(i, j) => write!(
                f,
                "temp_{} − temp_{} [°C]",
                thermometer_letter(i),
                thermometer_letter(j)
            ),
        }
    }
}

/// The inputs of a multi-point model, in order (at most [`MAX_PROBES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Probes {
    list: [Probe; MAX_PROBES],
    len: u8,
}

impl Probes {
    /// The selection `probes`; `None` when empty, over [`MAX_PROBES`] or naming
    /// a thermometer that does not exist.
    pub fn new(probes: &[Probe]) -> Option<Self> {
        let mut list = [Probe::Temp(0); MAX_PROBES];
        list.get_mut(..probes.len())?.copy_from_slice(probes);
        let set = Probes {
            list,
            len: probes.len() as u8,
        };
        set.is_valid().then_some(set)
    }

    /// The inputs in order.
    pub fn as_slice(&self) -> &[Probe] {
        self.list.get(..self.len as usize).unwrap_or(&[])
    }

    /// Number of inputs (≤ [`MAX_PROBES`] for a valid set).
    pub const fn len(&self) -> usize {
        let n = self.len as usize;
        if n < MAX_PROBES { n } else { MAX_PROBES }
    }

    /// True when the selection holds no input (never for a valid set).
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// At least one input, at most [`MAX_PROBES`], each valid.
    pub fn is_valid(&self) -> bool {
        let n = self.len as usize;
        n > 0 && n <= MAX_PROBES && self.as_slice().iter().all(|p| p.is_valid())
    }

    /// The thermometers the inputs read.
    pub fn thermometers(&self) -> ThermometerSet {
        ThermometerSet::from_bits(self.as_slice().iter().fold(0, |m, p| m | p.thermometer_bits()))
    }
}

/// Which inputs a model takes, in this order.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
// An explicit tag: without it the compiler keeps the variant in a spare
// value of the lag bank's `gain_of` (a niche), so every match on the set
// decodes it, and an empty model is no longer all zero bytes: the board's
// `static` model then needs an initialiser constant in flash, and every
// sample pays for the decoding (docs/decisions.md).
#[repr(u8)]
#[allow(
    clippy::large_enum_variant,
    reason = "no_std without alloc: nothing to box into; the set lives in the model, which lives in RAM"
)]
pub enum FeatureSet {
    /// (T): the loop temperature alone, for the cubic-in-T baseline.
    Temp,
    /// (T, ΔT): the IFOG paper's model before its modification (`--method rbf2`).
    TempRate,
    /// (T, ΔT, T×ΔT): the IFOG paper's modified model (`--method rbf --features paper`).
    TempRateProduct,
    /// (T, ΔT₁, ΔT₂, ΔT₃, T×ΔT₁, T×ΔT₂, T×ΔT₃, T²×ΔT₂) over three filter windows
    /// (one of the two sets the trainer's default chooses between).
    MultiScale,
    /// Temperatures and gradients of several thermometers (the RLG paper's
    /// multi-point inputs, `--method svr-pso` on runs with `temp_a` … `temp_h`).
    MultiPoint(Probes),
    /// (T, ΔT₁, ΔT₂, ΔT₃, T×ΔT₂, T×ΔT₃, T²×ΔT₂, ΔT₃²) over three filter
    /// windows: the multi-scale set with the second-order lag term ΔT₃² in
    /// place of T×ΔT₁ (see the module docs). Declared last so
    /// that the blob encoding of the other sets is unchanged.
    MultiScaleSecondOrder,
    /// The second-order multi-scale set with its first input, the one the
    /// Gaussians see, the lag-corrected temperature T̄ = T − L·ΔT₃: an estimate
    /// of the mean coil temperature, which lags the loop sensor in proportion
    /// to the slow rate (see the module docs). The other inputs are those of
    /// [`FeatureSet::MultiScaleSecondOrder`]. Declared after it for the same
    /// reason.
    MultiScaleLagged {
        /// The coil lag L, minutes (T̄ = T − L·ΔT₃ with ΔT₃ in °C/min).
        coil_lag_min: u16,
    },
    /// The thermal lag bank ([`crate::lag_bank`]): the mean coil temperature
    /// T̂ (and its powers) and the Shupe-gained rates of up to
    /// [`BANK_FILTERS`] derivative filters whose time constants and weights
    /// the trainer identifies. Declared last for the same reason.
    LagBank(LagBank),
    /// The thermal response bank ([`crate::response_bank`]): powers of the
    /// mean coil temperature about T₀ and three free mixtures of the rates of
    /// [`RESPONSE_FILTERS`] derivative filters, two with gains of T̂.
    /// Declared last for the same reason.
    ResponseBank(ResponseBank),
}

impl FeatureSet {
    /// Number of model inputs this set produces.
    pub const fn dims(&self) -> usize {
        match self {
            FeatureSet::Temp => 1,
            FeatureSet::TempRate => 2,
            FeatureSet::TempRateProduct => 3,
            FeatureSet::MultiScale | FeatureSet::MultiScaleSecondOrder | FeatureSet::MultiScaleLagged { .. } => 8,
            FeatureSet::MultiPoint(probes) => probes.len(),
            FeatureSet::LagBank(bank) => bank.dims(),
            FeatureSet::ResponseBank(bank) => bank.dims(),
        }
    }

    /// Number of ΔT derivative filters the set uses.
    pub const fn windows(&self) -> usize {
        match self {
            FeatureSet::Temp | FeatureSet::MultiPoint(_) => 0,
            FeatureSet::TempRate | FeatureSet::TempRateProduct => 1,
            FeatureSet::MultiScale | FeatureSet::MultiScaleSecondOrder | FeatureSet::MultiScaleLagged { .. } => WINDOWS,
            FeatureSet::LagBank(bank) => bank.filter_count(),
            FeatureSet::ResponseBank(bank) => bank.filter_count(),
        }
    }

    /// True for the sets over three ΔT time scales.
    pub const fn is_multiscale(&self) -> bool {
        matches!(
            self,
            FeatureSet::MultiScale | FeatureSet::MultiScaleSecondOrder | FeatureSet::MultiScaleLagged { .. }
        )
    }

    /// The thermometers the inputs read: the loop thermometer alone for the
    /// single-point sets.
    pub fn thermometers(&self) -> ThermometerSet {
        match self {
            FeatureSet::MultiPoint(probes) => probes.thermometers(),
            _ => ThermometerSet::LOOP,
        }
    }

    /// The thermometer whose reading a compensated sample reports as its
    /// temperature: the loop thermometer, or for a multi-point set the first
    /// thermometer its first input reads.
    pub fn reference_thermometer(&self) -> usize {
        match self {
            FeatureSet::MultiPoint(probes) => match probes.as_slice().first() {
                Some(Probe::Temp(i) | Probe::Gradient(i, _)) => *i as usize,
                None => LOOP_THERMOMETER,
            },
            _ => LOOP_THERMOMETER,
        }
    }

    /// The name of input `i` with its unit, for reports (`None` past the last input).
    pub fn name(&self, i: usize) -> Option<InputName> {
        match self {
            FeatureSet::MultiPoint(probes) => probes.as_slice().get(i).copied().map(InputName::Probe),
            FeatureSet::LagBank(bank) => bank.input(i).map(InputName::Bank),
            FeatureSet::ResponseBank(bank) => bank.input(i).map(InputName::Response),
            _ => self.fixed_names().get(i).copied().map(InputName::Fixed),
        }
    }

    /// The names of all inputs with their units, in order.
    pub fn names(self) -> impl Iterator<Item = InputName> {
        (0..self.dims()).filter_map(move |i| self.name(i))
    }

    /// Names of the single-point inputs with units.
    const fn fixed_names(&self) -> &'static [&'static str] {
        match self {
            FeatureSet::Temp => &["T [°C]"],
            FeatureSet::TempRate => &["T [°C]", "ΔT [°C/min]"],
            FeatureSet::TempRateProduct => &["T [°C]", "ΔT [°C/min]", "T×ΔT [°C²/min]"],
            FeatureSet::MultiScale => &[
                "T [°C]",
                "ΔT₁ [°C/min]",
                "ΔT₂ [°C/min]",
                "ΔT₃ [°C/min]",
                "T×ΔT₁ [°C²/min]",
                "T×ΔT₂ [°C²/min]",
                "T×ΔT₃ [°C²/min]",
                "T²×ΔT₂ [°C³/min]",
            ],
            FeatureSet::MultiScaleSecondOrder => &SECOND_ORDER_NAMES,
            FeatureSet::MultiScaleLagged { .. } => &LAGGED_NAMES,
            FeatureSet::MultiPoint(_) | FeatureSet::LagBank(_) | FeatureSet::ResponseBank(_) => &[],
        }
    }
}

/// Input names of [`FeatureSet::MultiScaleSecondOrder`].
static SECOND_ORDER_NAMES: [&str; 8] = [
    "T [°C]",
    "ΔT₁ [°C/min]",
    "ΔT₂ [°C/min]",
    "ΔT₃ [°C/min]",
    "T×ΔT₂ [°C²/min]",
    "T×ΔT₃ [°C²/min]",
    "T²×ΔT₂ [°C³/min]",
    "ΔT₃² [°C²/min²]",
];

/// Input names of [`FeatureSet::MultiScaleLagged`]: the second-order set's
/// with the lag-corrected temperature first.
static LAGGED_NAMES: [&str; 8] = {
    let mut names = SECOND_ORDER_NAMES;
    names[0] = "T̄ = T − L·ΔT₃ [°C]";
    names
};

/// The name and unit of one model input ([`FeatureSet::name`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InputName {
    /// A single-point input, e.g. `ΔT [°C/min]`.
    Fixed(&'static str),
    /// A multi-point input, e.g. `temp_c − temp_e [°C]`.
    Probe(Probe),
    /// A lag-bank input, e.g. `g·ΔT(τ 240 s) [°C/min]`.
    Bank(BankInput),
    /// A response-bank input, e.g. `û_c·R₁ [°/h]`.
    Response(ResponseInput),
}

impl core::fmt::Display for InputName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            InputName::Fixed(name) => f.write_str(name),
            InputName::Probe(probe) => probe.fmt(f),
            InputName::Bank(input) => input.fmt(f),
            InputName::Response(input) => input.fmt(f),
        }
    }
}

/// Most ΔT filter windows a feature set uses.
pub const WINDOWS: usize = 3;

/// How features are computed; stored in the model blob.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureConfig {
    /// The inputs the model takes.
    pub set: FeatureSet,
    /// Time constant τ of the (fastest) ΔT derivative filter, s. 0 = one-sample difference (Eq. 22).
    pub rate_window_s: f32,
    /// Time constants of the slower filters, s (multi-scale sets only; else 0).
    pub slow_windows_s: [f32; WINDOWS - 1],
}

impl FeatureConfig {
    /// A set with one ΔT window (or none, for [`FeatureSet::Temp`]).
    pub const fn single(set: FeatureSet, rate_window_s: f32) -> Self {
        FeatureConfig {
            set,
            rate_window_s,
            slow_windows_s: [0.0; WINDOWS - 1],
        }
    }

    /// The multi-scale `set` ([`FeatureSet::is_multiscale`]) over windows `[τ₁, τ₂, τ₃]`, s.
    pub const fn multiscale(set: FeatureSet, windows_s: [f32; WINDOWS]) -> Self {
        FeatureConfig {
            set,
            rate_window_s: windows_s[0],
            slow_windows_s: [windows_s[1], windows_s[2]],
        }
    }

    /// The window time constants in use, s (fastest first).
    pub fn windows_s(&self) -> [f32; WINDOWS] {
        [self.rate_window_s, self.slow_windows_s[0], self.slow_windows_s[1]]
    }

    /// A lag bank's configuration: its filters, with the fastest as
    /// `rate_window_s` (which sets the warm-up).
    pub fn lag_bank(bank: LagBank) -> Self {
        FeatureConfig {
            set: FeatureSet::LagBank(bank),
            rate_window_s: bank.taus_s[0],
            slow_windows_s: [0.0; WINDOWS - 1],
        }
    }

    /// A response bank's configuration: its filters, with the fastest as
    /// `rate_window_s` (which sets the warm-up).
    pub fn response_bank(bank: ResponseBank) -> Self {
        FeatureConfig {
            set: FeatureSet::ResponseBank(bank),
            rate_window_s: bank.taus_s[0],
            slow_windows_s: [0.0; WINDOWS - 1],
        }
    }

    /// The time constants of every derivative filter the set runs, s,
    /// fastest first: a bank's filters, else the ΔT windows in use.
    pub fn filter_taus_s(&self) -> heapless::Vec<f32, RESPONSE_FILTERS> {
        let windows_s = self.windows_s();
        let taus: &[f32] = match &self.set {
            FeatureSet::LagBank(bank) => bank.taus(),
            FeatureSet::ResponseBank(bank) => bank.taus(),
            set => windows_s.get(..set.windows()).unwrap_or(&[]),
        };
        taus.iter().copied().collect()
    }

    /// Number of model inputs.
    pub const fn dims(&self) -> usize {
        self.set.dims()
    }

    /// How long after a (re)start samples are flagged as warming up, s.
    pub fn warmup_s(&self) -> f32 {
        WARMUP_TIME_CONSTANTS * self.rate_window_s
    }

    /// True when the configuration is usable (finite windows within 0 ..= 1 day;
    /// multi-point inputs that name existing thermometers; a valid lag or
    /// response bank whose fastest filter is `rate_window_s`).
    pub fn is_valid(&self) -> bool {
        let set_ok = match self.set {
            FeatureSet::MultiPoint(probes) => probes.is_valid(),
            FeatureSet::LagBank(bank) => bank.is_valid() && bank.taus_s[0].to_bits() == self.rate_window_s.to_bits(),
            FeatureSet::ResponseBank(bank) => {
                bank.is_valid() && bank.taus_s[0].to_bits() == self.rate_window_s.to_bits()
            }
            _ => true,
        };
        set_ok
            && self
                .windows_s()
                .iter()
                .all(|w| w.is_finite() && *w >= 0.0 && *w <= MAX_RATE_WINDOW_S)
    }

    /// A multi-point configuration over `probes` (no derivative filters).
    pub const fn multipoint(probes: Probes) -> Self {
        FeatureConfig::single(FeatureSet::MultiPoint(probes), 0.0)
    }
}

/// The model inputs of one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeatureVector {
    values: [f32; MAX_INPUTS],
    reference_temp_c: f32,
    len: u8,
    /// The derivative filter has not settled yet (see module docs).
    pub warming_up: bool,
}

impl FeatureVector {
    /// A feature vector from given values (analysis and plots on the host; the
    /// loop always builds them with [`FeatureExtractor::update`]). Values past
    /// [`MAX_INPUTS`] are ignored.
    pub fn from_values(values: &[f32]) -> Self {
        let mut v = [0.0; MAX_INPUTS];
        let n = values.len().min(MAX_INPUTS);
        v[..n].copy_from_slice(&values[..n]);
        FeatureVector {
            values: v,
            reference_temp_c: v[0],
            len: n as u8,
            warming_up: false,
        }
    }

    /// The inputs in [`FeatureSet`] order.
    pub fn as_slice(&self) -> &[f32] {
        self.values.get(..self.len as usize).unwrap_or(&[])
    }

    /// All value slots (those past the feature count are 0).
    pub(crate) fn values(&self) -> &[f32; MAX_INPUTS] {
        &self.values
    }

    /// The temperature the features were computed from, °C: the fiber-loop
    /// sensor's, or for multi-point inputs the reference thermometer's
    /// ([`FeatureSet::reference_thermometer`]).
    pub fn temp_c(&self) -> f32 {
        self.reference_temp_c
    }

    /// The inputs of the single-point set `set` at loop temperature `temp_c`
    /// once every ΔT filter reads a steady ramp of `rate_c_per_min` (the bias
    /// surface of a model, for plots); `None` for multi-point sets.
    pub fn settled(set: FeatureSet, temp_c: f32, rate_c_per_min: f32) -> Option<FeatureVector> {
        if matches!(set, FeatureSet::MultiPoint(_)) {
            return None;
        }
        let values = match &set {
            FeatureSet::ResponseBank(bank) => {
                let mut values = [0.0; MAX_INPUTS];
                bank.settled_inputs(temp_c, rate_c_per_min, &mut values);
                values
            }
            _ => assemble(&set, &[rate_c_per_min; FILTERS], &loop_reading(temp_c)),
        };
        Some(FeatureVector {
            values,
            reference_temp_c: temp_c,
            len: set.dims() as u8,
            warming_up: false,
        })
    }

    /// The same sample's inputs for the multi-scale set `to`, from this vector
    /// of the multi-scale set `from` with the same windows: both sets are built
    /// from the loop temperature and the three ΔT rates (inputs 1 ..= 3), so the
    /// trainer fits both from one filter pass, bit for bit what
    /// [`FeatureExtractor::update`] gives for `to`. `None` unless both sets are
    /// multi-scale and this vector has `from`'s length.
    pub fn to_multiscale_set(&self, from: FeatureSet, to: FeatureSet) -> Option<FeatureVector> {
        if !(from.is_multiscale() && to.is_multiscale()) || self.len as usize != from.dims() {
            return None;
        }
        // The loop temperature from the reference reading: the lagged set's
        // first input is not T.
        let [_, fast, slow, slowest, ..] = self.values;
        let mut rates = [0.0; FILTERS];
        rates[..WINDOWS].copy_from_slice(&[fast, slow, slowest]);
        Some(FeatureVector {
            values: assemble(&to, &rates, &loop_reading(self.reference_temp_c)),
            len: to.dims() as u8,
            ..*self
        })
    }
}

/// Running state of the feature computation (one `f32` of filter state).
///
/// The configuration is passed on every call rather than stored so that the
/// model stays the single owner of it (principle: model is data, state is separate).
#[derive(Clone, Copy, Debug, Default)]
pub struct FeatureExtractor {
    filters: [DerivativeFilter; FILTERS],
    /// A response bank's filters (its own: three signals, twelve filters).
    bank: BankFilters,
    since_restart_s: f32,
    started: bool,
}

impl FeatureExtractor {
    /// A fresh extractor; the first sample starts a segment.
    pub const fn new() -> Self {
        FeatureExtractor {
            filters: [DerivativeFilter::settled_at(0.0); FILTERS],
            bank: BankFilters {
                filters: [[DerivativeFilter::settled_at(0.0); RESPONSE_FILTERS]; BANK_SIGNALS],
            },
            since_restart_s: 0.0,
            started: false,
        }
    }

    /// Forgets the history: the next sample starts a new segment (after a gap).
    pub fn restart(&mut self) {
        self.started = false;
    }

    /// Consumes one sample and returns its features.
    ///
    /// `dt_s` is the time since the previous sample in seconds; it is ignored on
    /// the first sample of a segment. A non-finite or non-positive `dt_s`
    /// restarts the segment. `temps_c` holds the thermometer readings, °C
    /// (index [`LOOP_THERMOMETER`] is the fiber loop); those the set reads
    /// ([`FeatureSet::thermometers`]) must be finite (the compensator
    /// guarantees it by holding the last good values), the others are ignored.
    #[inline(always)]
    pub fn update(&mut self, config: &FeatureConfig, dt_s: f32, temps_c: &[f32; THERMOMETERS]) -> FeatureVector {
        self.step(config, dt_s, temps_c, None)
    }

    /// [`Self::update`], with a response bank's filter outputs the inputs
    /// were mixed from (zero for the other sets): what the trainer
    /// identifies a response bank's weights from, computed by the very
    /// arithmetic the firmware runs.
    pub fn update_with_channels(
        &mut self,
        config: &FeatureConfig,
        dt_s: f32,
        temps_c: &[f32; THERMOMETERS],
    ) -> (FeatureVector, BankChannels) {
        let mut channels = BankChannels::default();
        let features = self.step(config, dt_s, temps_c, Some(&mut channels));
        (features, channels)
    }

    /// [`Self::update`], writing a response bank's filter outputs to
    /// `channels` when given (the firmware passes none: no stores).
    #[inline(always)]
    fn step(
        &mut self,
        config: &FeatureConfig,
        dt_s: f32,
        temps_c: &[f32; THERMOMETERS],
        channels: Option<&mut BankChannels>,
    ) -> FeatureVector {
        let temp_c = temps_c[LOOP_THERMOMETER];
        let restart = !(self.started && dt_s.is_finite() && dt_s > 0.0);
        if restart {
            self.started = true;
            self.since_restart_s = 0.0;
        } else {
            self.since_restart_s += dt_s;
        }
        let values = match &config.set {
            // The response bank runs its own filters, read and mixed in one pass.
            FeatureSet::ResponseBank(bank) => {
                let mut values = [0.0; MAX_INPUTS];
                if restart {
                    self.bank = bank.start(temp_c);
                    let (powers, uc) = bank.powers(temp_c);
                    bank.inputs(powers, uc, [0.0; WEIGHT_ROWS], &mut values);
                } else {
                    bank.step(temp_c, dt_s, &mut self.bank, channels, &mut values);
                }
                values
            }
            set => {
                // A lag bank's time constants are read where the model keeps
                // them (no copy of the set per sample); the ΔT windows are three values.
                let windows_s;
                let taus: &[f32] = match set {
                    FeatureSet::LagBank(bank) => bank.taus(),
                    _ => {
                        windows_s = config.windows_s();
                        windows_s.get(..set.windows()).unwrap_or(&[])
                    }
                };
                let mut rate_c_per_min = [0.0f32; FILTERS];
                if restart {
                    self.filters = [DerivativeFilter::settled_at(temp_c); FILTERS];
                } else {
                    for ((filter, out), &tau_s) in self.filters.iter_mut().zip(rate_c_per_min.iter_mut()).zip(taus) {
                        *out = filter.update(temp_c, tau_s, dt_s);
                    }
                }
                assemble(set, &rate_c_per_min, temps_c)
            }
        };
        let warming_up = self.since_restart_s == 0.0 || self.since_restart_s < config.warmup_s();
        let reference_temp_c = temps_c
            .get(config.set.reference_thermometer())
            .copied()
            .unwrap_or(f32::NAN);
        FeatureVector {
            values,
            reference_temp_c,
            len: config.dims() as u8,
            warming_up,
        }
    }
}

/// The eight inputs of a multi-scale set, the remaining slots 0.
#[inline(always)]
fn padded(v: [f32; 8]) -> [f32; MAX_INPUTS] {
    let [a, b, c, d, e, f, g, h] = v;
    [a, b, c, d, e, f, g, h, 0.0, 0.0, 0.0, 0.0]
}

/// The inputs of `set` from the ΔT filters' rates, °C/min (the first three
/// for the multi-scale sets), and the thermometer readings, °C: the one place
/// each set's inputs are defined.
#[inline(always)]
fn assemble(set: &FeatureSet, rate_c_per_min: &[f32; FILTERS], temps_c: &[f32; THERMOMETERS]) -> [f32; MAX_INPUTS] {
    let temp_c = temps_c[LOOP_THERMOMETER];
    let mut values = [0.0; MAX_INPUTS];
    values[0] = temp_c;
    match set {
        FeatureSet::Temp => {}
        FeatureSet::TempRate => values[1] = rate_c_per_min[0],
        FeatureSet::TempRateProduct => {
            values[1] = rate_c_per_min[0];
            values[2] = temp_c * rate_c_per_min[0];
        }
        FeatureSet::MultiScale => {
            // Built whole (not slot by slot): no partial stores read back as a vector.
            let [fast, slow, slowest, ..] = *rate_c_per_min;
            values = padded([
                temp_c,
                fast,
                slow,
                slowest,
                temp_c * fast,
                temp_c * slow,
                temp_c * slowest,
                temp_c * temp_c * slow,
            ]);
        }
        FeatureSet::MultiScaleSecondOrder | FeatureSet::MultiScaleLagged { .. } => {
            // Written out apart from the first-order arm on purpose: one arm for
            // both sets with a shared prefix made the firmware's whole step
            // longer (`cargo xtask bench-fw`).
            let [fast, slow, slowest, ..] = *rate_c_per_min;
            // The lagged set's first input: T̄ = T − L·ΔT₃, the mean coil temperature.
            let first = match *set {
                FeatureSet::MultiScaleLagged { coil_lag_min } => temp_c - f32::from(coil_lag_min) * slowest,
                _ => temp_c,
            };
            values = padded([
                first,
                fast,
                slow,
                slowest,
                temp_c * slow,
                temp_c * slowest,
                temp_c * temp_c * slow,
                slowest * slowest,
            ]);
        }
        FeatureSet::MultiPoint(probes) => {
            for (v, p) in values.iter_mut().zip(probes.as_slice()) {
                *v = p.value(temps_c);
            }
        }
        FeatureSet::LagBank(bank) => bank.inputs(temp_c, rate_c_per_min, &mut values),
        // A response bank runs its own filters ([`ResponseBank::step`]);
        // from the loop temperature's rates alone: its inputs at rest.
        FeatureSet::ResponseBank(bank) => {
            let (powers, uc) = bank.powers(temp_c);
            bank.inputs(powers, uc, [0.0; WEIGHT_ROWS], &mut values);
        }
    }
    values
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    fn paper(rate_window_s: f32) -> FeatureConfig {
        FeatureConfig::single(FeatureSet::TempRateProduct, rate_window_s)
    }

    #[test]
    fn eq22_one_sample_difference_is_the_zero_window_case() {
        // IFOG Eq. 22: ΔT_i = T_i − T_{i−1}, 0 for i = 1; here per minute at dt = 1 s.
        let temps = [20.0f32, 20.5, 20.25, 21.0, 21.0];
        let mut fx = FeatureExtractor::new();
        let cfg = paper(0.0);
        let mut prev: Option<f32> = None;
        for &t in &temps {
            let f = fx.update(&cfg, 1.0, &loop_reading(t));
            let expected_per_sample = prev.map_or(0.0, |p| t - p);
            // Exact: differences of these binary fractions are exact in f32.
            assert_eq!(f.as_slice()[1], expected_per_sample * 60.0);
            assert_eq!(f.as_slice()[2], t * expected_per_sample * 60.0);
            prev = Some(t);
        }
    }

    #[test]
    fn steady_ramp_reads_its_rate_in_degrees_per_minute_at_any_sample_rate() {
        for &rate_hz in &[1.0f32, 10.0, 1000.0] {
            let dt = 1.0 / rate_hz;
            let cfg = paper(30.0);
            let mut fx = FeatureExtractor::new();
            let ramp_c_per_min = 2.0f32;
            let n = (600.0 * rate_hz) as usize; // 10 min = 20 τ: settled
            let mut last = None;
            for i in 0..n {
                let t_s = i as f64 * dt as f64;
                let temp = 10.0 + (ramp_c_per_min as f64 / 60.0 * t_s) as f32;
                last = Some(fx.update(&cfg, dt, &loop_reading(temp)));
            }
            let f = last.unwrap();
            let dtemp = f.as_slice()[1];
            assert!(
                (dtemp - ramp_c_per_min).abs() < 0.01,
                "{rate_hz} Hz: ΔT = {dtemp} °C/min"
            );
            assert!(!f.warming_up);
        }
    }

    #[test]
    fn warm_up_lasts_three_time_constants_and_restart_begins_again() {
        let cfg = paper(10.0);
        let mut fx = FeatureExtractor::new();
        let first = fx.update(&cfg, 1.0, &loop_reading(25.0));
        assert!(first.warming_up);
        assert_eq!(first.as_slice()[1], 0.0);
        let mut settled_at = None;
        for i in 1..100 {
            if !fx.update(&cfg, 1.0, &loop_reading(25.0)).warming_up {
                settled_at = Some(i);
                break;
            }
        }
        assert_eq!(settled_at, Some(30));
        fx.restart();
        let after_gap = fx.update(&cfg, 1.0, &loop_reading(40.0));
        assert!(after_gap.warming_up);
        assert_eq!(
            after_gap.as_slice()[1],
            0.0,
            "a gap must not read as a temperature step"
        );
    }

    #[test]
    fn every_multiscale_window_reads_a_steady_ramp_and_its_product_with_t() {
        let cfg = FeatureConfig::multiscale(FeatureSet::MultiScale, [10.0, 80.0, 640.0]);
        let mut fx = FeatureExtractor::new();
        let mut f = fx.update(&cfg, 1.0, &loop_reading(0.0));
        for i in 1..=20_000 {
            f = fx.update(&cfg, 1.0, &loop_reading(1.5 * i as f32 / 60.0)); // 1.5 °C/min
        }
        let v = f.as_slice();
        for w in 0..WINDOWS {
            assert!((v[1 + w] - 1.5).abs() < 2e-3, "window {w}: {}", v[1 + w]);
            assert_eq!(v[4 + w], v[0] * v[1 + w]);
        }
        assert_eq!(v[7], v[0] * v[0] * v[2]);
        assert!(!f.warming_up);
        let cfg_bad = FeatureConfig::multiscale(FeatureSet::MultiScale, [10.0, f32::NAN, 640.0]);
        assert!(!cfg_bad.is_valid());
    }

    #[test]
    fn the_second_order_set_adds_the_slowest_rate_squared_in_place_of_t_times_the_fastest() {
        let windows = [10.0, 80.0, 640.0];
        let first = FeatureConfig::multiscale(FeatureSet::MultiScale, windows);
        let second = FeatureConfig::multiscale(FeatureSet::MultiScaleSecondOrder, windows);
        let (mut fx1, mut fx2) = (FeatureExtractor::new(), FeatureExtractor::new());
        for i in 0..=5_000 {
            // A ramp at 2 °C/min from 15 °C: T = 15 + i/30.
            let temps = loop_reading(15.0 + 2.0 * i as f32 / 60.0);
            let (a, b) = (fx1.update(&first, 1.0, &temps), fx2.update(&second, 1.0, &temps));
            let (a, b) = (a.as_slice(), b.as_slice());
            // T, the three rates, T×ΔT₂, T×ΔT₃ and T²×ΔT₂: the same filters, the same values.
            assert_eq!(&b[..4], &a[..4], "sample {i}");
            assert_eq!(&b[4..7], &[a[5], a[6], a[7]], "sample {i}");
            assert_eq!(b[7], b[3] * b[3], "sample {i}");
        }
        assert_eq!(second.set.name(7), Some(InputName::Fixed("ΔT₃² [°C²/min²]")));
    }

    #[test]
    fn the_lagged_set_is_the_second_order_set_with_t_moved_back_by_the_coil_lag() {
        let windows = [10.0, 80.0, 640.0];
        let second = FeatureConfig::multiscale(FeatureSet::MultiScaleSecondOrder, windows);
        let lagged = FeatureConfig::multiscale(FeatureSet::MultiScaleLagged { coil_lag_min: 40 }, windows);
        let (mut fx1, mut fx2) = (FeatureExtractor::new(), FeatureExtractor::new());
        let mut last = None;
        for i in 0..=20_000 {
            // A ramp at 1.5 °C/min from −30 °C.
            let temps = loop_reading(-30.0 + 1.5 * i as f32 / 60.0);
            let (a, b) = (fx1.update(&second, 1.0, &temps), fx2.update(&lagged, 1.0, &temps));
            assert_eq!(&b.as_slice()[1..], &a.as_slice()[1..], "sample {i}");
            assert_eq!(b.as_slice()[0], a.as_slice()[0] - 40.0 * a.as_slice()[3], "sample {i}");
            assert_eq!(b.temp_c(), a.temp_c(), "the reported temperature stays the sensor's");
            last = Some(b);
        }
        // Settled on the ramp: T̄ is the sensor's reading 40 min × 1.5 °C/min back.
        let v = last.unwrap();
        assert!((v.temp_c() - v.as_slice()[0] - 60.0).abs() < 0.2, "{:?}", v.as_slice());
        assert_eq!(lagged.set.name(0), Some(InputName::Fixed("T̄ = T − L·ΔT₃ [°C]")));
        assert_eq!(lagged.dims(), 8);
        assert!(lagged.set.is_multiscale() && lagged.is_valid());
    }

    #[test]
    fn settled_inputs_are_what_the_filters_read_at_the_end_of_a_long_steady_ramp() {
        let sets = [
            FeatureSet::Temp,
            FeatureSet::TempRate,
            FeatureSet::TempRateProduct,
            FeatureSet::MultiScale,
            FeatureSet::MultiScaleSecondOrder,
            FeatureSet::MultiScaleLagged { coil_lag_min: 20 },
        ];
        for set in sets {
            let config = FeatureConfig::multiscale(set, [2.0, 32.0, 512.0]);
            let mut fx = FeatureExtractor::new();
            let mut last = fx.update(&config, 1.0, &loop_reading(10.0));
            for i in 1..=8_000 {
                last = fx.update(&config, 1.0, &loop_reading(10.0 + 1.5 * i as f32 / 60.0));
            }
            let settled = FeatureVector::settled(set, last.temp_c(), 1.5).unwrap();
            assert_eq!(settled.as_slice().len(), set.dims(), "{set:?}");
            for (a, b) in settled.as_slice().iter().zip(last.as_slice()) {
                assert!((a - b).abs() <= 2e-3 * b.abs().max(1.0), "{set:?}: {a} against {b}");
            }
        }
        let probes = Probes::new(&[Probe::Temp(0)]).unwrap();
        assert_eq!(FeatureVector::settled(FeatureSet::MultiPoint(probes), 20.0, 1.0), None);
    }

    #[test]
    fn a_multiscale_vector_converts_to_the_other_set_bit_for_bit() {
        let windows = [15.0, 240.0, 3840.0];
        let sets = [
            FeatureSet::MultiScale,
            FeatureSet::MultiScaleSecondOrder,
            FeatureSet::MultiScaleLagged { coil_lag_min: 10 },
        ];
        let configs = sets.map(|set| FeatureConfig::multiscale(set, windows));
        let mut extractors = [FeatureExtractor::new(); 3];
        // Irregular steps, a gap (dt = NaN restarts) and a non-monotone temperature.
        for i in 0..20_000u32 {
            let dt = if i == 7_000 {
                f32::NAN
            } else {
                0.01 + (i % 7) as f32 * 0.003
            };
            let temps = loop_reading(-20.0 + 0.004 * i as f32 + (i as f32 * 0.01).sin());
            let direct = [0, 1, 2].map(|k| extractors[k].update(&configs[k], dt, &temps));
            for (from, to) in [(0, 1), (1, 0), (0, 0), (0, 2), (2, 0), (2, 1)] {
                let converted = direct[from].to_multiscale_set(sets[from], sets[to]);
                assert_eq!(
                    converted,
                    Some(direct[to]),
                    "sample {i}: {:?} -> {:?}",
                    sets[from],
                    sets[to]
                );
            }
            // Inputs of the same name are the same computation (the trainer sums them once).
            for (a, name_a) in sets[0].names().enumerate() {
                for (b, name_b) in sets[1].names().enumerate() {
                    if name_a == name_b {
                        assert_eq!(direct[0].as_slice()[a], direct[1].as_slice()[b], "sample {i}: {name_a}");
                    }
                }
            }
        }
        let paper_vector = FeatureExtractor::new().update(&paper(15.0), 1.0, &loop_reading(20.0));
        assert_eq!(
            paper_vector.to_multiscale_set(FeatureSet::TempRateProduct, sets[0]),
            None
        );
        let v = FeatureExtractor::new().update(&configs[0], 1.0, &loop_reading(20.0));
        assert_eq!(v.to_multiscale_set(sets[0], FeatureSet::Temp), None);
    }

    #[test]
    fn a_response_bank_runs_all_its_filters_and_warms_up_over_three_of_its_fastest() {
        let taus: Vec<f32> = (1..=RESPONSE_FILTERS).map(|k| 4.0 * k as f32).collect();
        let mut bank = ResponseBank::new(&taus, 10.0, 0.0, 100.0, 1).unwrap();
        bank.weights[0] = [1.0 / RESPONSE_FILTERS as f32; RESPONSE_FILTERS];
        bank.weights[1][RESPONSE_FILTERS - 1] = 1.0;
        bank.weights[3][RESPONSE_FILTERS - 1] = 1.0;
        let cfg = FeatureConfig::response_bank(bank);
        assert!(cfg.is_valid());
        assert_eq!(cfg.warmup_s(), 12.0);
        let mut fx = FeatureExtractor::new();
        let mut settled_at = None;
        let mut last = fx.update(&cfg, 1.0, &loop_reading(10.0));
        for i in 1..=3_000 {
            last = fx.update(&cfg, 1.0, &loop_reading(10.0 + 1.5 * i as f32 / 60.0));
            if !last.warming_up && settled_at.is_none() {
                settled_at = Some(i);
            }
        }
        assert_eq!(settled_at, Some(12));
        // Every filter reads the ramp: R₀ is their mean, R₁ the slowest's times u.
        let [u, r0, r1] = [0, 1, 2].map(|i| last.as_slice()[i]);
        assert_eq!(last.as_slice().len(), 6);
        assert!((r0 - 1.5).abs() < 1e-3, "R₀ = {r0}");
        assert!((r1 - 1.5 * u).abs() < 1e-3 * u, "u_c·R₁ = {r1}, u = {u}");
        assert!((u - 75.0).abs() < 1e-3, "u = {u}");
        // H₂: the square's rate, d(u²)/dt = 2u·1.5 °C/min, less its lag (the slowest τ at 1.5 °C/min).
        let h2 = last.as_slice()[4];
        let slowest_s = 4.0 * RESPONSE_FILTERS as f32;
        assert!(
            (h2 - 2.0 * (u - 1.5 * slowest_s / 60.0) * 1.5).abs() < 0.05,
            "H₂ = {h2}"
        );
        assert_eq!(last.as_slice()[5], 0.0, "row 4 is zero");
        assert_eq!(cfg.set.names().count(), 6);
        let mut wrong = cfg;
        wrong.rate_window_s = 5.0;
        assert!(!wrong.is_valid(), "the fastest filter must be the warm-up window");
    }

    #[test]
    fn bad_time_steps_restart_instead_of_producing_nonsense() {
        let cfg = paper(0.0);
        let mut fx = FeatureExtractor::new();
        fx.update(&cfg, 1.0, &loop_reading(20.0));
        for dt in [0.0f32, -1.0, f32::NAN, f32::INFINITY] {
            let f = fx.update(&cfg, dt, &loop_reading(30.0));
            assert_eq!(f.as_slice()[1], 0.0, "dt = {dt}");
            assert!(f.as_slice().iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn feature_sets_have_their_documented_dimensions() {
        let mut fx = FeatureExtractor::new();
        for set in [
            FeatureSet::Temp,
            FeatureSet::TempRate,
            FeatureSet::TempRateProduct,
            FeatureSet::MultiScale,
            FeatureSet::MultiScaleSecondOrder,
            FeatureSet::MultiScaleLagged { coil_lag_min: 80 },
        ] {
            let cfg = if set.is_multiscale() {
                FeatureConfig::multiscale(set, [5.0, 40.0, 320.0])
            } else {
                FeatureConfig::single(set, 5.0)
            };
            assert_eq!(fx.update(&cfg, 1.0, &loop_reading(20.0)).as_slice().len(), set.dims());
            assert_eq!(set.names().count(), set.dims());
            assert_eq!(set.name(set.dims()), None);
        }
    }

    #[test]
    fn multipoint_inputs_are_the_selected_temperatures_and_gradients() {
        let probes = Probes::new(&[Probe::Temp(0), Probe::Gradient(2, 4), Probe::Gradient(7, 1)]).unwrap();
        let cfg = FeatureConfig::multipoint(probes);
        assert!(cfg.is_valid());
        assert_eq!(cfg.set.thermometers().bits(), 0b1001_0111);
        assert_eq!(cfg.set.reference_thermometer(), 0);
        let temps = [20.0, 21.0, 22.5, 0.0, 25.0, 0.0, 0.0, 30.0];
        let mut fx = FeatureExtractor::new();
        let first = fx.update(&cfg, 1.0, &temps);
        assert_eq!(first.as_slice(), &[20.0, -2.5, 9.0]);
        assert_eq!(first.temp_c(), 20.0, "reports the reference thermometer");
        assert!(first.warming_up, "the first sample of a segment");
        assert!(!fx.update(&cfg, 1.0, &temps).warming_up, "no filter to settle");
        assert_eq!(cfg.set.name(1).unwrap().to_string(), "temp_c − temp_e [°C]");
        assert_eq!(cfg.set.name(3), None);
        // Selections naming missing thermometers, a gradient of a thermometer
        // with itself, nothing or too much are refused.
        assert_eq!(Probes::new(&[Probe::Temp(8)]), None);
        assert_eq!(Probes::new(&[Probe::Gradient(3, 3)]), None);
        assert_eq!(Probes::new(&[]), None);
        assert_eq!(Probes::new(&[Probe::Temp(1); MAX_INPUTS + 1]), None);
    }
}
