//! Drawn gyros. `trainer simulate --unit N` draws every constant of the
//! thermal plant and of the bias model from the ranges of [`UNIT`]
//! (unit-to-unit variation of one design), `--design N` from the wider ones
//! of [`DESIGN`] (gyros of other mechanical designs); docs/simulator.md says
//! why each range. So what is developed on the simulator is not developed on
//! one plant. The draw depends on the family and N alone: design 7 is the
//! same gyro in every run.

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::gyro::GyroParams;
use super::params::SimParams;
use super::plant::{Hub, LoopSensor, MAX_COIL_LAYERS, MIN_COIL_LAYERS, MIN_TAU_S, PlantParams, THERMOMETERS};

/// A range a constant is drawn from: uniform, or uniform in its logarithm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Range {
    /// Uniform in `lo … hi`.
    Uniform(f64, f64),
    /// Uniform in `ln lo … ln hi` (time constants: a factor matters, not a difference).
    LogUniform(f64, f64),
    /// Magnitude uniform in `lo … hi`, either sign.
    EitherSign(f64, f64),
}

impl Range {
    /// One draw.
    pub fn draw(self, rng: &mut impl Rng) -> f64 {
        match self {
            Range::Uniform(lo, hi) => rng.random_range(lo..=hi),
            Range::LogUniform(lo, hi) => rng.random_range(lo.ln()..=hi.ln()).exp(),
            Range::EitherSign(lo, hi) => {
                let magnitude = rng.random_range(lo..=hi);
                if rng.random_bool(0.5) { magnitude } else { -magnitude }
            }
        }
    }

    /// Whether `x` can come out of [`Range::draw`] (bounds with a relative rounding guard).
    pub fn contains(self, x: f64) -> bool {
        let within = |lo: f64, hi: f64, x: f64| x >= lo * (1.0 - 1e-12) && x <= hi * (1.0 + 1e-12);
        match self {
            Range::Uniform(lo, hi) => x >= lo - 1e-12 * lo.abs() && x <= hi + 1e-12 * hi.abs(),
            Range::LogUniform(lo, hi) => within(lo, hi, x),
            Range::EitherSign(lo, hi) => within(lo, hi, x.abs()),
        }
    }
}

/// The ranges one family of gyros is drawn from: every constant of the plant
/// and of the bias model (docs/simulator.md says why each range).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ranges {
    /// Radial coil layers (uniform integer, inclusive).
    pub coil_layers: (usize, usize),
    /// Housing base ↔ air, s.
    pub tau_base_s: Range,
    /// Housing top cover ↔ air, s.
    pub tau_top_s: Range,
    /// Electronics board ↔ housing, s.
    pub tau_electronics_s: Range,
    /// The electronics' steady rise above the housing, °C.
    pub self_heating_c: Range,
    /// Share of the electronics' rise in the air around the coil.
    pub electronics_to_coil: Range,
    /// Share of the electronics' rise the base settles above the air.
    pub electronics_to_base: Range,
    /// Share of the electronics' rise the hub settles above the base.
    pub electronics_to_hub: Range,
    /// Outer coil layer ↔ the air around it, s.
    pub tau_coil_outer_s: Range,
    /// Radial diffusion time of the whole winding, s: `tau_coil_layer_s` = this / layers².
    pub coil_diffusion_s: Range,
    /// Hub ↔ housing base, s.
    pub hub_tau_base_s: Range,
    /// Innermost layer ↔ hub, s.
    pub hub_tau_coil_s: Range,
    /// Hub heat capacity over one layer's.
    pub hub_heat_capacity_ratio: Range,
    /// The loop sensor's own lag, s.
    pub loop_sensor_lag_s: Range,
    /// The other thermometers' lags, as a factor of their documented default
    /// (at least [`MIN_TAU_S`]).
    pub other_lag_factor: Range,
    /// Thermometer noise, °C.
    pub thermometer_noise_c: Range,
    /// Static bias c0 … c3, °/h/°Cⁿ.
    pub static_coeffs: [Range; 4],
    /// Net Shupe gain, °/h per °C/min (a coil warming uniformly sees this).
    pub shupe_dph_per_c_per_min: Range,
    /// Shupe gain's relative change per °C.
    pub shupe_temp_coeff_per_c: Range,
    /// Decay length of the Shupe weights from the outer layer inwards, as a
    /// fraction of the winding's depth.
    pub shupe_weight_decay: Range,
    /// Per-layer scatter of the Shupe weights before normalising (winding errors), 1σ.
    pub shupe_weight_scatter: f64,
    /// Each layer's own Shupe residual, in units of the net gain: its scale
    /// ρ (the residuals are ρ·(z_i − z̄), z_i standard normal, so they sum to
    /// zero and the net gain stays the net); `None`: no residuals (units).
    pub shupe_layer_residual: Option<Range>,
    /// Radial gradient gain, °/h/°C.
    pub radial_gradient_dph_per_c: Range,
    /// Stress gain, °/h per °C of innermost − outer layer.
    pub stress_gradient_dph_per_c: Range,
    /// Stress gain's relative change per °C: ≤ 0, the coating stiffens in the cold.
    pub stress_temp_coeff_per_c: Range,
    /// Hub expansion gain, °/h per °C of hub − mean coil.
    pub hub_expansion_dph_per_c: Range,
    /// Axial gradient gain (multi-point runs), °/h/°C.
    pub axial_gradient_dph_per_c: Range,
    /// Angle random walk, °/√h.
    pub arw_deg_per_sqrt_h: Range,
    /// Bias instability, °/h.
    pub bias_instability_dph: Range,
    /// Correlation time of the bias instability, s.
    pub bias_correlation_s: Range,
}

/// Unit-to-unit variation of one design (`trainer simulate --unit N`).
pub const UNIT: Ranges = Ranges {
    coil_layers: (MIN_COIL_LAYERS, MAX_COIL_LAYERS),
    tau_base_s: Range::LogUniform(300.0, 2400.0),
    tau_top_s: Range::LogUniform(600.0, 3600.0),
    tau_electronics_s: Range::LogUniform(200.0, 1800.0),
    self_heating_c: Range::Uniform(1.0, 10.0),
    electronics_to_coil: Range::Uniform(0.05, 0.5),
    electronics_to_base: Range::Uniform(0.0, 0.3),
    electronics_to_hub: Range::Uniform(0.0, 0.3),
    tau_coil_outer_s: Range::LogUniform(150.0, 1500.0),
    coil_diffusion_s: Range::LogUniform(4000.0, 30000.0),
    hub_tau_base_s: Range::LogUniform(300.0, 3000.0),
    hub_tau_coil_s: Range::LogUniform(200.0, 2000.0),
    hub_heat_capacity_ratio: Range::LogUniform(0.5, 4.0),
    loop_sensor_lag_s: Range::LogUniform(MIN_TAU_S, 60.0),
    other_lag_factor: Range::LogUniform(0.5, 2.0),
    thermometer_noise_c: Range::Uniform(0.001, 0.004),
    static_coeffs: [
        Range::Uniform(-0.1, 0.1),
        Range::EitherSign(0.005, 0.04),
        Range::Uniform(-4e-4, 4e-4),
        Range::Uniform(-3e-6, 3e-6),
    ],
    shupe_dph_per_c_per_min: Range::Uniform(0.1, 0.6),
    shupe_temp_coeff_per_c: Range::Uniform(-0.01, 0.02),
    shupe_weight_decay: Range::LogUniform(0.2, 2.0),
    shupe_weight_scatter: 0.1,
    shupe_layer_residual: None,
    radial_gradient_dph_per_c: Range::Uniform(-0.01, 0.01),
    stress_gradient_dph_per_c: Range::EitherSign(0.005, 0.03),
    stress_temp_coeff_per_c: Range::Uniform(-0.015, 0.0),
    hub_expansion_dph_per_c: Range::Uniform(-0.02, 0.02),
    axial_gradient_dph_per_c: Range::EitherSign(0.01, 0.05),
    arw_deg_per_sqrt_h: Range::Uniform(0.0007, 0.0015),
    bias_instability_dph: Range::Uniform(0.0005, 0.0015),
    bias_correlation_s: Range::LogUniform(300.0, 1200.0),
};

/// Gyros of other mechanical designs (`trainer simulate --design N`): every
/// range at least as wide as [`UNIT`]'s, most wider, each layer with its own
/// Shupe residual of either sign and up to several times the net gain, and
/// the Shupe gain drifting with each layer's own temperature.
pub const DESIGN: Ranges = Ranges {
    tau_base_s: Range::LogUniform(200.0, 6000.0),
    tau_top_s: Range::LogUniform(400.0, 7200.0),
    tau_electronics_s: Range::LogUniform(150.0, 3600.0),
    self_heating_c: Range::Uniform(1.0, 15.0),
    electronics_to_coil: Range::Uniform(0.05, 0.8),
    electronics_to_base: Range::Uniform(0.0, 0.5),
    electronics_to_hub: Range::Uniform(0.0, 0.6),
    tau_coil_outer_s: Range::LogUniform(100.0, 3600.0),
    coil_diffusion_s: Range::LogUniform(2000.0, 60000.0),
    hub_tau_base_s: Range::LogUniform(200.0, 6000.0),
    hub_tau_coil_s: Range::LogUniform(150.0, 4000.0),
    hub_heat_capacity_ratio: Range::LogUniform(0.3, 6.0),
    loop_sensor_lag_s: Range::LogUniform(MIN_TAU_S, 150.0),
    other_lag_factor: Range::LogUniform(0.5, 3.0),
    thermometer_noise_c: Range::Uniform(0.001, 0.005),
    static_coeffs: [
        Range::Uniform(-0.2, 0.2),
        Range::EitherSign(0.002, 0.06),
        Range::Uniform(-6e-4, 6e-4),
        Range::Uniform(-8e-6, 8e-6),
    ],
    shupe_dph_per_c_per_min: Range::Uniform(0.05, 0.8),
    shupe_temp_coeff_per_c: Range::Uniform(-0.02, 0.03),
    shupe_layer_residual: Some(Range::LogUniform(0.3, 4.0)),
    radial_gradient_dph_per_c: Range::Uniform(-0.02, 0.02),
    stress_gradient_dph_per_c: Range::EitherSign(0.005, 0.06),
    stress_temp_coeff_per_c: Range::Uniform(-0.02, 0.0),
    hub_expansion_dph_per_c: Range::Uniform(-0.05, 0.05),
    arw_deg_per_sqrt_h: Range::Uniform(0.0005, 0.002),
    bias_instability_dph: Range::Uniform(0.0003, 0.002),
    bias_correlation_s: Range::LogUniform(200.0, 2000.0),
    // The layer count, the outer-to-inner fall of the weights and their
    // scatter, and the axial gradient: as a unit's.
    ..UNIT
};

/// A family of drawn gyros: `--unit N` or `--design N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Unit-to-unit variation of one design ([`UNIT`]).
    Unit,
    /// Other mechanical designs ([`DESIGN`]).
    Design,
}

impl Family {
    /// The family's name, as the run's metadata writes it (`# unit: 7`).
    pub fn name(self) -> &'static str {
        match self {
            Family::Unit => "unit",
            Family::Design => "design",
        }
    }

    /// The ranges its gyros are drawn from.
    pub fn ranges(self) -> &'static Ranges {
        match self {
            Family::Unit => &UNIT,
            Family::Design => &DESIGN,
        }
    }

    /// Keeps each family's stream apart from the run seeds and from the
    /// other family's (ASCII "unit", "dsgn").
    fn stream(self) -> u64 {
        match self {
            Family::Unit => 0x756e_6974,
            Family::Design => 0x6473_676e,
        }
    }

    /// Gyro `n` of this family: the same gyro for the same `n`, every time.
    pub fn params(self, n: u64) -> SimParams {
        draw(self.ranges(), &mut Pcg64::seed_from_u64(self.stream() ^ n))
    }
}

/// The simulator parameters of unit `unit`: every constant drawn from [`UNIT`].
pub fn unit_params(unit: u64) -> SimParams {
    Family::Unit.params(unit)
}

/// Every constant drawn from `r`. The order of the draws is that of the
/// first family (units); what later families add is drawn last, so a unit
/// stays the gyro it always was.
fn draw(r: &Ranges, rng: &mut Pcg64) -> SimParams {
    let layers = rng.random_range(r.coil_layers.0..=r.coil_layers.1);
    let mut lags = THERMOMETERS.map(|(_, lag_s)| (lag_s * r.other_lag_factor.draw(rng)).max(MIN_TAU_S));
    lags[super::plant::LOOP_SENSOR] = r.loop_sensor_lag_s.draw(rng);
    let plant = PlantParams {
        tau_base_s: r.tau_base_s.draw(rng),
        tau_top_s: r.tau_top_s.draw(rng),
        tau_electronics_s: r.tau_electronics_s.draw(rng),
        self_heating_c: r.self_heating_c.draw(rng),
        electronics_to_coil: r.electronics_to_coil.draw(rng),
        electronics_to_base: r.electronics_to_base.draw(rng),
        electronics_to_hub: r.electronics_to_hub.draw(rng),
        coil_layers: layers,
        tau_coil_outer_s: r.tau_coil_outer_s.draw(rng),
        tau_coil_layer_s: (r.coil_diffusion_s.draw(rng) / (layers * layers) as f64).max(MIN_TAU_S),
        hub: Some(Hub {
            tau_base_s: r.hub_tau_base_s.draw(rng),
            tau_coil_s: r.hub_tau_coil_s.draw(rng),
            heat_capacity_ratio: r.hub_heat_capacity_ratio.draw(rng),
        }),
        loop_sensor: loop_sensor(rng, layers),
        thermometer_lags_s: lags,
        thermometer_noise_c: r.thermometer_noise_c.draw(rng),
    };
    let mut gyro = GyroParams {
        arw_deg_per_sqrt_h: r.arw_deg_per_sqrt_h.draw(rng),
        bias_instability_dph: r.bias_instability_dph.draw(rng),
        bias_correlation_s: r.bias_correlation_s.draw(rng),
        static_coeffs: r.static_coeffs.map(|c| c.draw(rng)),
        shupe_dph_per_c_per_min: r.shupe_dph_per_c_per_min.draw(rng),
        shupe_temp_coeff_per_c: r.shupe_temp_coeff_per_c.draw(rng),
        shupe_layer_weights: shupe_weights(rng, r, layers),
        shupe_gain_of_layer_temp: false,
        radial_gradient_dph_per_c: r.radial_gradient_dph_per_c.draw(rng),
        stress_gradient_dph_per_c: r.stress_gradient_dph_per_c.draw(rng),
        stress_temp_coeff_per_c: r.stress_temp_coeff_per_c.draw(rng),
        hub_expansion_dph_per_c: r.hub_expansion_dph_per_c.draw(rng),
        axial_gradient_dph_per_c: r.axial_gradient_dph_per_c.draw(rng),
    };
    if let Some(residual) = r.shupe_layer_residual {
        let scale = residual.draw(rng);
        let z: Vec<f64> = (0..layers).map(|_| StandardNormal.sample(rng)).collect();
        let mean = z.iter().sum::<f64>() / layers as f64;
        for (w, z) in gyro.shupe_layer_weights.iter_mut().zip(&z) {
            *w += scale * (z - mean);
        }
        // Residuals of several times the net gain in layers at different
        // temperatures: the gain must follow each layer's own.
        gyro.shupe_gain_of_layer_temp = true;
    }
    SimParams { plant, gyro }
}

/// The loop sensor's place, in eighths: outer coil surface 3, flange 2,
/// embedded in a layer (uniform over the layers) 1, hub 1, housing wall 1.
fn loop_sensor(rng: &mut impl Rng, layers: usize) -> LoopSensor {
    match rng.random_range(0..8u32) {
        0..=2 => LoopSensor::OuterSurface,
        3 | 4 => LoopSensor::Flange,
        5 => LoopSensor::Layer(rng.random_range(0..layers)),
        6 => LoopSensor::Hub,
        _ => LoopSensor::HousingWall,
    }
}

/// Shupe weights falling from the outer layer inwards, exp(−x/λ) at depth x
/// = i/(layers − 1) plus winding scatter, normalised to sum 1 (so a coil
/// warming uniformly at 1 °C/min sees the whole Shupe gain).
fn shupe_weights(rng: &mut impl Rng, r: &Ranges, layers: usize) -> Vec<f64> {
    let decay = r.shupe_weight_decay.draw(rng);
    loop {
        let raw: Vec<f64> = (0..layers)
            .map(|i| {
                let depth = i as f64 / (layers - 1) as f64;
                let scatter: f64 = StandardNormal.sample(rng);
                (-depth / decay).exp() + r.shupe_weight_scatter * scatter
            })
            .collect();
        let sum: f64 = raw.iter().sum();
        // A sum near zero would blow the weights up: draw the scatter again.
        if sum > 0.5 {
            return raw.iter().map(|w| w / sum).collect();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FAMILIES: [Family; 2] = [Family::Unit, Family::Design];

    /// Unit 3 as `trainer simulate --unit 3` recorded it before designs
    /// existed (`# simulator_params`, at 98612e5): the bench's figures and
    /// the examples rest on the units staying the gyros they were.
    const UNIT_3_RECORD: &str = r#"{"plant":{"tau_base_s":628.590453549777,"tau_top_s":2409.163080080855,"tau_electronics_s":383.6216671293433,"self_heating_c":3.3139515435717937,"electronics_to_coil":0.13946173435698317,"electronics_to_base":0.047043473430779414,"electronics_to_hub":0.06872301866676864,"coil_layers":6,"tau_coil_outer_s":185.29383113738947,"tau_coil_layer_s":386.6464308074043,"hub":{"tau_base_s":499.5002611576989,"tau_coil_s":275.1131472403708,"heat_capacity_ratio":1.1081489383361027},"loop_sensor":"flange","thermometer_lags_s":[7.7311474042905175,8.123154175171864,12.60832363307555,37.50151055888671,5.453268033085599,8.743914231330496,232.42246170031314,27.745849176473747],"thermometer_noise_c":0.0019440262710769965},"gyro":{"arw_deg_per_sqrt_h":0.0014343524405594813,"bias_instability_dph":0.0006579802730041262,"bias_correlation_s":755.8102063634676,"static_coeffs":[0.019518469801654878,-0.0182662614721213,-0.00004193622200328041,2.8392787490623424e-6],"shupe_dph_per_c_per_min":0.3211977029321529,"shupe_temp_coeff_per_c":-0.001199034156542319,"shupe_layer_weights":[0.23632446879272984,0.19735711616696505,0.17496255273315184,0.17508955676550525,0.1119874300315924,0.10427887551005563],"radial_gradient_dph_per_c":-0.0009383341411096733,"stress_gradient_dph_per_c":-0.02145457193924073,"stress_temp_coeff_per_c":-0.0006448604829854803,"hub_expansion_dph_per_c":-0.01660354856435177,"axial_gradient_dph_per_c":-0.03963346523792859}}"#;

    #[test]
    fn units_stay_the_gyros_they_were() {
        let recorded: serde_json::Value = serde_json::from_str(UNIT_3_RECORD).unwrap();
        assert_eq!(serde_json::to_value(unit_params(3)).unwrap(), recorded);
        let back = SimParams::default().overridden(UNIT_3_RECORD).unwrap();
        assert_eq!(back, unit_params(3));
    }

    #[test]
    fn a_drawn_gyro_is_the_same_every_time_and_draws_differ() {
        for family in FAMILIES {
            assert_eq!(family.params(7), family.params(7), "{family:?}");
            let drawn: Vec<SimParams> = (0..200).map(|n| family.params(n)).collect();
            for (i, a) in drawn.iter().enumerate() {
                a.check().unwrap_or_else(|e| panic!("{family:?} {i}: {e}"));
                for b in &drawn[i + 1..] {
                    assert_ne!(a.plant.tau_base_s.to_bits(), b.plant.tau_base_s.to_bits());
                    assert_ne!(
                        a.gyro.static_coeffs.map(f64::to_bits),
                        b.gyro.static_coeffs.map(f64::to_bits)
                    );
                }
            }
            // The discrete choices cover their whole range.
            let (fewest, most) = family.ranges().coil_layers;
            for layers in fewest..=most {
                assert!(
                    drawn.iter().any(|u| u.plant.coil_layers == layers),
                    "{family:?}: {layers} layers"
                );
            }
            let placed = |want: fn(LoopSensor) -> bool| drawn.iter().any(|u| want(u.plant.loop_sensor));
            assert!(placed(|s| s == LoopSensor::OuterSurface));
            assert!(placed(|s| s == LoopSensor::Flange));
            assert!(placed(|s| s == LoopSensor::Hub));
            assert!(placed(|s| s == LoopSensor::HousingWall));
            assert!(placed(|s| matches!(s, LoopSensor::Layer(k) if k > 0)));
        }
        // Design n is not unit n: the families draw from streams of their own.
        assert_ne!(
            Family::Design.params(3).plant.tau_base_s.to_bits(),
            unit_params(3).plant.tau_base_s.to_bits()
        );
    }

    /// Every drawn scalar constant of `p` beside its range in `r`, by name.
    fn constants(r: &Ranges, p: &SimParams) -> Vec<(&'static str, Range, f64)> {
        let SimParams { plant: p, gyro: g } = p;
        let hub = p.hub.expect("every drawn gyro has a hub");
        let layers = p.coil_layers as f64;
        vec![
            ("tau_base_s", r.tau_base_s, p.tau_base_s),
            ("tau_top_s", r.tau_top_s, p.tau_top_s),
            ("tau_electronics_s", r.tau_electronics_s, p.tau_electronics_s),
            ("self_heating_c", r.self_heating_c, p.self_heating_c),
            ("electronics_to_coil", r.electronics_to_coil, p.electronics_to_coil),
            ("electronics_to_base", r.electronics_to_base, p.electronics_to_base),
            ("electronics_to_hub", r.electronics_to_hub, p.electronics_to_hub),
            ("tau_coil_outer_s", r.tau_coil_outer_s, p.tau_coil_outer_s),
            (
                "coil diffusion",
                r.coil_diffusion_s,
                p.tau_coil_layer_s * layers * layers,
            ),
            ("hub.tau_base_s", r.hub_tau_base_s, hub.tau_base_s),
            ("hub.tau_coil_s", r.hub_tau_coil_s, hub.tau_coil_s),
            (
                "hub.heat_capacity_ratio",
                r.hub_heat_capacity_ratio,
                hub.heat_capacity_ratio,
            ),
            ("loop sensor lag", r.loop_sensor_lag_s, p.thermometer_lags_s[2]),
            ("thermometer_noise_c", r.thermometer_noise_c, p.thermometer_noise_c),
            ("c0", r.static_coeffs[0], g.static_coeffs[0]),
            ("c1", r.static_coeffs[1], g.static_coeffs[1]),
            ("c2", r.static_coeffs[2], g.static_coeffs[2]),
            ("c3", r.static_coeffs[3], g.static_coeffs[3]),
            ("shupe", r.shupe_dph_per_c_per_min, g.shupe_dph_per_c_per_min),
            ("shupe temp coeff", r.shupe_temp_coeff_per_c, g.shupe_temp_coeff_per_c),
            ("radial", r.radial_gradient_dph_per_c, g.radial_gradient_dph_per_c),
            ("stress", r.stress_gradient_dph_per_c, g.stress_gradient_dph_per_c),
            (
                "stress temp coeff",
                r.stress_temp_coeff_per_c,
                g.stress_temp_coeff_per_c,
            ),
            ("hub expansion", r.hub_expansion_dph_per_c, g.hub_expansion_dph_per_c),
            ("axial", r.axial_gradient_dph_per_c, g.axial_gradient_dph_per_c),
            ("arw", r.arw_deg_per_sqrt_h, g.arw_deg_per_sqrt_h),
            ("bias instability", r.bias_instability_dph, g.bias_instability_dph),
            ("correlation", r.bias_correlation_s, g.bias_correlation_s),
        ]
    }

    #[test]
    fn every_design_range_is_at_least_as_wide_as_the_units() {
        let any = unit_params(0);
        let bounds = |r: Range| match r {
            Range::Uniform(lo, hi) | Range::LogUniform(lo, hi) | Range::EitherSign(lo, hi) => (lo, hi),
        };
        let both = constants(&UNIT, &any).into_iter().zip(constants(&DESIGN, &any));
        for ((name, unit, _), (_, design, _)) in both {
            let ((u_lo, u_hi), (d_lo, d_hi)) = (bounds(unit), bounds(design));
            assert_eq!(std::mem::discriminant(&unit), std::mem::discriminant(&design), "{name}");
            assert!(d_lo <= u_lo && d_hi >= u_hi, "{name}: design {design:?}, unit {unit:?}");
        }
        assert!(DESIGN.coil_layers.0 <= UNIT.coil_layers.0 && DESIGN.coil_layers.1 >= UNIT.coil_layers.1);
    }

    #[test]
    fn every_drawn_constant_lies_in_its_documented_range() {
        for family in FAMILIES {
            let r = family.ranges();
            for n in 0..200 {
                let drawn = family.params(n);
                for (name, range, value) in constants(r, &drawn) {
                    assert!(
                        range.contains(value),
                        "{family:?} {n}: {name} = {value} outside {range:?}"
                    );
                }
                let SimParams { plant: p, gyro: g } = drawn;
                assert!((r.coil_layers.0..=r.coil_layers.1).contains(&p.coil_layers));
                for (i, lag_s) in p.thermometer_lags_s.iter().enumerate() {
                    let documented_s = THERMOMETERS[i].1;
                    let (lo, hi) = match r.other_lag_factor {
                        Range::LogUniform(lo, hi) => (lo, hi),
                        other => panic!("lag factor {other:?}"),
                    };
                    if i != crate::simulate::plant::LOOP_SENSOR {
                        assert!(
                            *lag_s >= MIN_TAU_S
                                && *lag_s <= (documented_s * hi).max(MIN_TAU_S) * (1.0 + 1e-12)
                                && *lag_s >= documented_s * lo * (1.0 - 1e-12),
                            "{family:?} {n}: thermometer {i} lag {lag_s} s"
                        );
                    }
                }
                // The weights sum to 1 (residuals sum to zero): a coil warming
                // uniformly sees the net gain.
                let sum: f64 = g.shupe_layer_weights.iter().sum();
                assert!((sum - 1.0).abs() < 1e-12, "{family:?} {n}: Shupe weights sum to {sum}");
                assert_eq!(g.shupe_layer_weights.len(), p.coil_layers);
                assert_eq!(g.shupe_gain_of_layer_temp, r.shupe_layer_residual.is_some());
                if r.shupe_layer_residual.is_none() {
                    assert!(g.shupe_layer_weights[0] > 0.0, "unit {n}: the outer turns weigh in");
                }
            }
        }
    }

    #[test]
    fn design_layers_carry_residuals_of_either_sign_several_times_the_net_gain() {
        // Σ of the negative weights' magnitudes: the part of the Shupe
        // response of the opposite sign to the net (which sums to 1).
        let opposite = |p: &SimParams| -> f64 {
            p.gyro
                .shupe_layer_weights
                .iter()
                .filter(|w| **w < 0.0)
                .map(|w| -w)
                .sum()
        };
        let designs: Vec<f64> = (0..200).map(|n| opposite(&Family::Design.params(n))).collect();
        let units: Vec<f64> = (0..200).map(|n| opposite(&unit_params(n))).collect();
        let share = |x: &[f64], above: f64| x.iter().filter(|o| **o > above).count() as f64 / x.len() as f64;
        // Nearly every design has layers of opposite sign; in most they add
        // up to more than the net gain, in some to several times it.
        assert!(share(&designs, 0.0) > 0.9, "{designs:?}");
        assert!(share(&designs, 1.0) > 0.4, "{designs:?}");
        assert!(share(&designs, 3.0) > 0.05, "{designs:?}");
        // A unit's winding scatter is small beside its net gain.
        assert!(share(&units, 0.5) == 0.0, "{units:?}");
    }
}
