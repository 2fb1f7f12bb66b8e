//! Unit-to-unit variation: `trainer simulate --unit N` draws every constant
//! of the thermal plant and of the bias model from the ranges below
//! (docs/simulator.md, "Unit-to-unit variation", says why each range), so
//! that what is developed on the simulator is not developed on one plant.
//! The draw depends on N alone: unit 7 is the same gyro in every run.

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::SimParams;
use super::gyro::GyroParams;
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

/// Housing base ↔ air, s: bolted to a massive plate … on isolators.
pub const TAU_BASE_S: Range = Range::LogUniform(300.0, 2400.0);
/// Housing top cover ↔ air, s.
pub const TAU_TOP_S: Range = Range::LogUniform(600.0, 3600.0);
/// Electronics board ↔ housing, s.
pub const TAU_ELECTRONICS_S: Range = Range::LogUniform(200.0, 1800.0);
/// The electronics' steady rise above the housing, °C (1 … 5 W in a 1 … 2 kg housing).
pub const SELF_HEATING_C: Range = Range::Uniform(1.0, 10.0);
/// Share of the electronics' rise in the air around the coil.
pub const ELECTRONICS_TO_COIL: Range = Range::Uniform(0.05, 0.5);
/// Share of the electronics' rise the base settles above the air.
pub const ELECTRONICS_TO_BASE: Range = Range::Uniform(0.0, 0.3);
/// Share of the electronics' rise the hub settles above the base.
pub const ELECTRONICS_TO_HUB: Range = Range::Uniform(0.0, 0.3);
/// Outer coil layer ↔ the air around it, s.
pub const TAU_COIL_OUTER_S: Range = Range::LogUniform(150.0, 1500.0);
/// Radial diffusion time of the whole winding, s: `tau_coil_layer_s` = this / layers².
pub const COIL_DIFFUSION_S: Range = Range::LogUniform(4000.0, 30000.0);
/// Hub ↔ housing base, s.
pub const HUB_TAU_BASE_S: Range = Range::LogUniform(300.0, 3000.0);
/// Innermost layer ↔ hub, s.
pub const HUB_TAU_COIL_S: Range = Range::LogUniform(200.0, 2000.0);
/// Hub heat capacity over one layer's.
pub const HUB_HEAT_CAPACITY_RATIO: Range = Range::LogUniform(0.5, 4.0);
/// The loop sensor's own lag, s (thermal paste on the coil … a sensor behind a board).
pub const LOOP_SENSOR_LAG_S: Range = Range::LogUniform(MIN_TAU_S, 60.0);
/// The other thermometers' lags, as a factor of their documented default
/// (at least [`MIN_TAU_S`]).
pub const OTHER_LAG_FACTOR: Range = Range::LogUniform(0.5, 2.0);
/// Thermometer noise, °C.
pub const THERMOMETER_NOISE_C: Range = Range::Uniform(0.001, 0.004);
/// Static bias c0, °/h.
pub const STATIC_C0: Range = Range::Uniform(-0.1, 0.1);
/// Static bias c1, °/h/°C.
pub const STATIC_C1: Range = Range::EitherSign(0.005, 0.04);
/// Static bias c2, °/h/°C².
pub const STATIC_C2: Range = Range::Uniform(-4e-4, 4e-4);
/// Static bias c3, °/h/°C³.
pub const STATIC_C3: Range = Range::Uniform(-3e-6, 3e-6);
/// Shupe gain, °/h per °C/min.
pub const SHUPE_DPH_PER_C_PER_MIN: Range = Range::Uniform(0.1, 0.6);
/// Shupe gain's relative change per °C.
pub const SHUPE_TEMP_COEFF_PER_C: Range = Range::Uniform(-0.01, 0.02);
/// Decay length of the Shupe weights from the outer layer inwards, as a
/// fraction of the winding's depth.
pub const SHUPE_WEIGHT_DECAY: Range = Range::LogUniform(0.2, 2.0);
/// Per-layer scatter of the Shupe weights before normalising (winding errors), 1σ.
pub const SHUPE_WEIGHT_SCATTER: f64 = 0.1;
/// Radial gradient gain, °/h/°C.
pub const RADIAL_GRADIENT_DPH_PER_C: Range = Range::Uniform(-0.01, 0.01);
/// Stress gain, °/h per °C of innermost − outer layer.
pub const STRESS_GRADIENT_DPH_PER_C: Range = Range::EitherSign(0.005, 0.03);
/// Stress gain's relative change per °C: ≤ 0, the coating stiffens in the cold.
pub const STRESS_TEMP_COEFF_PER_C: Range = Range::Uniform(-0.015, 0.0);
/// Hub expansion gain, °/h per °C of hub − mean coil.
pub const HUB_EXPANSION_DPH_PER_C: Range = Range::Uniform(-0.02, 0.02);
/// Axial gradient gain (multi-point runs), °/h/°C.
pub const AXIAL_GRADIENT_DPH_PER_C: Range = Range::EitherSign(0.01, 0.05);
/// Angle random walk, °/√h.
pub const ARW_DEG_PER_SQRT_H: Range = Range::Uniform(0.0007, 0.0015);
/// Bias instability, °/h.
pub const BIAS_INSTABILITY_DPH: Range = Range::Uniform(0.0005, 0.0015);
/// Correlation time of the bias instability, s.
pub const BIAS_CORRELATION_S: Range = Range::LogUniform(300.0, 1200.0);

/// Keeps the unit stream apart from the run seeds (ASCII "unit").
const UNIT_STREAM: u64 = 0x756e_6974;

/// The simulator parameters of unit `unit`: every constant drawn from the
/// ranges of this module.
pub fn unit_params(unit: u64) -> SimParams {
    let mut rng = Pcg64::seed_from_u64(UNIT_STREAM ^ unit);
    let rng = &mut rng;
    let layers = rng.random_range(MIN_COIL_LAYERS..=MAX_COIL_LAYERS);
    let mut lags = THERMOMETERS.map(|(_, lag_s)| (lag_s * OTHER_LAG_FACTOR.draw(rng)).max(MIN_TAU_S));
    lags[super::plant::LOOP_SENSOR] = LOOP_SENSOR_LAG_S.draw(rng);
    let plant = PlantParams {
        tau_base_s: TAU_BASE_S.draw(rng),
        tau_top_s: TAU_TOP_S.draw(rng),
        tau_electronics_s: TAU_ELECTRONICS_S.draw(rng),
        self_heating_c: SELF_HEATING_C.draw(rng),
        electronics_to_coil: ELECTRONICS_TO_COIL.draw(rng),
        electronics_to_base: ELECTRONICS_TO_BASE.draw(rng),
        electronics_to_hub: ELECTRONICS_TO_HUB.draw(rng),
        coil_layers: layers,
        tau_coil_outer_s: TAU_COIL_OUTER_S.draw(rng),
        tau_coil_layer_s: (COIL_DIFFUSION_S.draw(rng) / (layers * layers) as f64).max(MIN_TAU_S),
        hub: Some(Hub {
            tau_base_s: HUB_TAU_BASE_S.draw(rng),
            tau_coil_s: HUB_TAU_COIL_S.draw(rng),
            heat_capacity_ratio: HUB_HEAT_CAPACITY_RATIO.draw(rng),
        }),
        loop_sensor: loop_sensor(rng, layers),
        thermometer_lags_s: lags,
        thermometer_noise_c: THERMOMETER_NOISE_C.draw(rng),
    };
    let gyro = GyroParams {
        arw_deg_per_sqrt_h: ARW_DEG_PER_SQRT_H.draw(rng),
        bias_instability_dph: BIAS_INSTABILITY_DPH.draw(rng),
        bias_correlation_s: BIAS_CORRELATION_S.draw(rng),
        static_coeffs: [STATIC_C0, STATIC_C1, STATIC_C2, STATIC_C3].map(|r| r.draw(rng)),
        shupe_dph_per_c_per_min: SHUPE_DPH_PER_C_PER_MIN.draw(rng),
        shupe_temp_coeff_per_c: SHUPE_TEMP_COEFF_PER_C.draw(rng),
        shupe_layer_weights: shupe_weights(rng, layers),
        radial_gradient_dph_per_c: RADIAL_GRADIENT_DPH_PER_C.draw(rng),
        stress_gradient_dph_per_c: STRESS_GRADIENT_DPH_PER_C.draw(rng),
        stress_temp_coeff_per_c: STRESS_TEMP_COEFF_PER_C.draw(rng),
        hub_expansion_dph_per_c: HUB_EXPANSION_DPH_PER_C.draw(rng),
        axial_gradient_dph_per_c: AXIAL_GRADIENT_DPH_PER_C.draw(rng),
    };
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
fn shupe_weights(rng: &mut impl Rng, layers: usize) -> Vec<f64> {
    let decay = SHUPE_WEIGHT_DECAY.draw(rng);
    loop {
        let raw: Vec<f64> = (0..layers)
            .map(|i| {
                let depth = i as f64 / (layers - 1) as f64;
                let scatter: f64 = StandardNormal.sample(rng);
                (-depth / decay).exp() + SHUPE_WEIGHT_SCATTER * scatter
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

    #[test]
    fn a_unit_is_the_same_gyro_every_time_and_units_differ() {
        assert_eq!(unit_params(7), unit_params(7));
        let units: Vec<SimParams> = (0..200).map(unit_params).collect();
        for (i, a) in units.iter().enumerate() {
            a.check().unwrap_or_else(|e| panic!("unit {i}: {e}"));
            for b in &units[i + 1..] {
                assert_ne!(a.plant.tau_base_s.to_bits(), b.plant.tau_base_s.to_bits());
                assert_ne!(
                    a.gyro.static_coeffs.map(f64::to_bits),
                    b.gyro.static_coeffs.map(f64::to_bits)
                );
            }
        }
        // The discrete choices cover their whole range.
        for layers in MIN_COIL_LAYERS..=MAX_COIL_LAYERS {
            assert!(units.iter().any(|u| u.plant.coil_layers == layers), "{layers} layers");
        }
        let placed = |want: fn(LoopSensor) -> bool| units.iter().any(|u| want(u.plant.loop_sensor));
        assert!(placed(|s| s == LoopSensor::OuterSurface));
        assert!(placed(|s| s == LoopSensor::Flange));
        assert!(placed(|s| s == LoopSensor::Hub));
        assert!(placed(|s| s == LoopSensor::HousingWall));
        assert!(placed(|s| matches!(s, LoopSensor::Layer(k) if k > 0)));
    }

    #[test]
    fn every_drawn_constant_lies_in_its_documented_range() {
        for unit in 0..200 {
            let SimParams { plant: p, gyro: g } = unit_params(unit);
            let hub = p.hub.expect("every drawn unit has a hub");
            let layers = p.coil_layers as f64;
            for (name, range, value) in [
                ("tau_base_s", TAU_BASE_S, p.tau_base_s),
                ("tau_top_s", TAU_TOP_S, p.tau_top_s),
                ("tau_electronics_s", TAU_ELECTRONICS_S, p.tau_electronics_s),
                ("self_heating_c", SELF_HEATING_C, p.self_heating_c),
                ("electronics_to_coil", ELECTRONICS_TO_COIL, p.electronics_to_coil),
                ("electronics_to_base", ELECTRONICS_TO_BASE, p.electronics_to_base),
                ("electronics_to_hub", ELECTRONICS_TO_HUB, p.electronics_to_hub),
                ("tau_coil_outer_s", TAU_COIL_OUTER_S, p.tau_coil_outer_s),
                ("coil diffusion", COIL_DIFFUSION_S, p.tau_coil_layer_s * layers * layers),
                ("hub.tau_base_s", HUB_TAU_BASE_S, hub.tau_base_s),
                ("hub.tau_coil_s", HUB_TAU_COIL_S, hub.tau_coil_s),
                (
                    "hub.heat_capacity_ratio",
                    HUB_HEAT_CAPACITY_RATIO,
                    hub.heat_capacity_ratio,
                ),
                ("loop sensor lag", LOOP_SENSOR_LAG_S, p.thermometer_lags_s[2]),
                ("thermometer_noise_c", THERMOMETER_NOISE_C, p.thermometer_noise_c),
                ("c0", STATIC_C0, g.static_coeffs[0]),
                ("c1", STATIC_C1, g.static_coeffs[1]),
                ("c2", STATIC_C2, g.static_coeffs[2]),
                ("c3", STATIC_C3, g.static_coeffs[3]),
                ("shupe", SHUPE_DPH_PER_C_PER_MIN, g.shupe_dph_per_c_per_min),
                ("shupe temp coeff", SHUPE_TEMP_COEFF_PER_C, g.shupe_temp_coeff_per_c),
                ("radial", RADIAL_GRADIENT_DPH_PER_C, g.radial_gradient_dph_per_c),
                ("stress", STRESS_GRADIENT_DPH_PER_C, g.stress_gradient_dph_per_c),
                ("stress temp coeff", STRESS_TEMP_COEFF_PER_C, g.stress_temp_coeff_per_c),
                ("hub expansion", HUB_EXPANSION_DPH_PER_C, g.hub_expansion_dph_per_c),
                ("axial", AXIAL_GRADIENT_DPH_PER_C, g.axial_gradient_dph_per_c),
                ("arw", ARW_DEG_PER_SQRT_H, g.arw_deg_per_sqrt_h),
                ("bias instability", BIAS_INSTABILITY_DPH, g.bias_instability_dph),
                ("correlation", BIAS_CORRELATION_S, g.bias_correlation_s),
            ] {
                assert!(range.contains(value), "unit {unit}: {name} = {value} outside {range:?}");
            }
            let sum: f64 = g.shupe_layer_weights.iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "unit {unit}: Shupe weights sum to {sum}");
            assert!(g.shupe_layer_weights[0] > 0.0, "unit {unit}: the outer turns weigh in");
        }
    }
}
