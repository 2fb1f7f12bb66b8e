//! Gyro output model (docs/simulator.md, "Bias").

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::plant::{NodeRates, Plant};

/// Earth rotation rate, °/h.
pub const EARTH_RATE_DPH: f64 = 15.041_067;
/// Latitude of the test site, degrees.
pub const LATITUDE_DEG: f64 = 39.9;
/// Heading of the horizontal sensitive axis from north, degrees.
pub const HEADING_DEG: f64 = 30.0;
/// Reference temperature of the static bias polynomial, °C.
pub const STATIC_REF_C: f64 = 25.0;
/// Allan-deviation floor of a first-order Gauss–Markov process relative to its σ.
const GM_ALLAN_PEAK: f64 = 0.62;
/// Allan floor = 0.664 × bias instability (IEEE Std 952 flicker convention).
const FLICKER_FLOOR: f64 = 0.664;

/// The Earth-rate projection on a horizontal axis at [`LATITUDE_DEG`], [`HEADING_DEG`], °/h.
pub fn earth_rate_projection_dph() -> f64 {
    EARTH_RATE_DPH * LATITUDE_DEG.to_radians().cos() * HEADING_DEG.to_radians().cos()
}

/// Bias and noise parameters (docs/simulator.md, "Bias"). The defaults are
/// the documented gyro; `trainer simulate --params FILE.json` overrides any.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GyroParams {
    /// Angle random walk, °/√h.
    pub arw_deg_per_sqrt_h: f64,
    /// Bias instability, °/h (Allan floor / 0.664).
    pub bias_instability_dph: f64,
    /// Correlation time of the bias-instability process, s.
    pub bias_correlation_s: f64,
    /// Static bias c0 … c3 about 25 °C of the mean coil temperature, °/h/°Cⁿ.
    pub static_coeffs: [f64; 4],
    /// Shupe gain, °/h per °C/min of the weighted coil temperature rate.
    pub shupe_dph_per_c_per_min: f64,
    /// Relative change of the Shupe gain per °C (IFOG paper Eq. 13: the T×ΔT term).
    pub shupe_temp_coeff_per_c: f64,
    /// Weights of the layers' temperature rates in the Shupe term, outer to
    /// inner, one per coil layer.
    pub shupe_layer_weights: Vec<f64>,
    /// Whether the Shupe gain's temperature term follows each layer's own
    /// temperature, K_S Σ w_i (1 + α (T_i − 25 °C)) dT_i/dt, instead of the
    /// mean coil temperature's (false, the documented gyro). It matters where
    /// layers of large weights of opposite sign sit at different temperatures
    /// (`--design`). Left out of the JSON when false, so the records of the
    /// gyros before it stay as they were.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub shupe_gain_of_layer_temp: bool,
    /// Bias per °C of housing − coil (radial gradient), °/h/°C.
    pub radial_gradient_dph_per_c: f64,
    /// Thermal stress: bias per °C of innermost − outer coil layer, °/h/°C.
    pub stress_gradient_dph_per_c: f64,
    /// Relative change of the stress gain per °C of the mean coil temperature
    /// (the fiber coating stiffens in the cold), 1/°C.
    pub stress_temp_coeff_per_c: f64,
    /// Differential expansion of the hub against the coil: bias per °C of
    /// hub − mean coil temperature (coils with a hub), °/h/°C.
    pub hub_expansion_dph_per_c: f64,
    /// Bias per °C of base − top (axial gradient across the housing; multi-point runs), °/h/°C.
    pub axial_gradient_dph_per_c: f64,
}

impl Default for GyroParams {
    fn default() -> Self {
        GyroParams {
            arw_deg_per_sqrt_h: 0.001,
            bias_instability_dph: 0.001,
            bias_correlation_s: 600.0,
            static_coeffs: [0.08, 0.02, 2e-4, -2e-6],
            shupe_dph_per_c_per_min: 0.3,
            shupe_temp_coeff_per_c: 0.01,
            shupe_layer_weights: vec![0.55, 0.30, 0.10, 0.05],
            shupe_gain_of_layer_temp: false,
            radial_gradient_dph_per_c: 0.004,
            stress_gradient_dph_per_c: 0.0,
            stress_temp_coeff_per_c: 0.0,
            hub_expansion_dph_per_c: 0.0,
            axial_gradient_dph_per_c: 0.03,
        }
    }
}

impl GyroParams {
    /// Why these parameters cannot be simulated, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        let scalars = [
            self.shupe_dph_per_c_per_min,
            self.shupe_temp_coeff_per_c,
            self.radial_gradient_dph_per_c,
            self.stress_gradient_dph_per_c,
            self.stress_temp_coeff_per_c,
            self.hub_expansion_dph_per_c,
            self.axial_gradient_dph_per_c,
        ];
        let mut coefficients = self
            .static_coeffs
            .iter()
            .chain(&self.shupe_layer_weights)
            .chain(&scalars);
        if coefficients.any(|c| !c.is_finite()) {
            return Err("every bias coefficient must be a finite number".into());
        }
        if !(self.arw_deg_per_sqrt_h.is_finite() && self.arw_deg_per_sqrt_h >= 0.0) {
            return Err("arw_deg_per_sqrt_h must be ≥ 0".into());
        }
        if !(self.bias_instability_dph.is_finite() && self.bias_instability_dph >= 0.0) {
            return Err("bias_instability_dph must be ≥ 0".into());
        }
        if !(self.bias_correlation_s.is_finite() && self.bias_correlation_s > 0.0) {
            return Err("bias_correlation_s must be > 0".into());
        }
        Ok(())
    }

    /// These parameters with every thermal bias term zeroed (static curve,
    /// Shupe, radial gradient, stress, hub expansion, axial gradient): the
    /// same noise, sample for sample, and nothing else. Simulated with the
    /// same seed, a run's noise ceiling.
    pub fn noise_only(&self) -> GyroParams {
        GyroParams {
            static_coeffs: [0.0; 4],
            shupe_dph_per_c_per_min: 0.0,
            radial_gradient_dph_per_c: 0.0,
            stress_gradient_dph_per_c: 0.0,
            hub_expansion_dph_per_c: 0.0,
            axial_gradient_dph_per_c: 0.0,
            ..self.clone()
        }
    }
}

/// Running state of the output model.
#[derive(Clone, Debug)]
pub struct Gyro {
    params: GyroParams,
    multi: bool,
    white_dph: f64,
    gm_dph: f64,
    gm_phi: f64,
    gm_drive_dph: f64,
}

impl Gyro {
    /// A gyro sampled at `sample_rate_hz`; `multi` adds the axial-gradient term.
    pub fn new(params: &GyroParams, sample_rate_hz: f64, multi: bool) -> Self {
        let dt = 1.0 / sample_rate_hz;
        let gm_sigma = FLICKER_FLOOR * params.bias_instability_dph / GM_ALLAN_PEAK;
        let gm_phi = (-dt / params.bias_correlation_s).exp();
        Gyro {
            params: params.clone(),
            multi,
            // ARW N [°/√h] is white rate noise of PSD N² [(°/h)²/Hz]·3600²/3600: σ = 60 N √fs °/h.
            white_dph: 60.0 * params.arw_deg_per_sqrt_h * sample_rate_hz.sqrt(),
            gm_dph: 0.0,
            gm_phi,
            gm_drive_dph: gm_sigma * (1.0 - gm_phi * gm_phi).sqrt(),
        }
    }

    /// Thermal bias plus the bias-instability process, °/h.
    pub fn bias_dph(&mut self, plant: &Plant, rates: &NodeRates, rng: &mut impl Rng) -> f64 {
        let p = &self.params;
        let u = plant.coil_mean_c() - STATIC_REF_C;
        let [c0, c1, c2, c3] = p.static_coeffs;
        let static_dph = c0 + u * (c1 + u * (c2 + u * c3));
        let weighted_rates = p.shupe_layer_weights.iter().zip(&rates.coil_c_per_s);
        let shupe_dph = if p.shupe_gain_of_layer_temp {
            let gained_rate_c_per_min: f64 = weighted_rates
                .zip(plant.layers_c())
                .map(|((w, r), t)| w * (1.0 + p.shupe_temp_coeff_per_c * (t - STATIC_REF_C)) * r * 60.0)
                .sum();
            p.shupe_dph_per_c_per_min * gained_rate_c_per_min
        } else {
            let weighted_rate_c_per_min: f64 = weighted_rates.map(|(w, r)| w * r * 60.0).sum();
            p.shupe_dph_per_c_per_min * (1.0 + p.shupe_temp_coeff_per_c * u) * weighted_rate_c_per_min
        };
        let radial_dph = p.radial_gradient_dph_per_c * (plant.housing_c() - plant.coil_mean_c());
        let stress_dph =
            p.stress_gradient_dph_per_c * (1.0 + p.stress_temp_coeff_per_c * u) * (plant.inner_c() - plant.outer_c())
                + plant
                    .hub_c
                    .map_or(0.0, |hub_c| p.hub_expansion_dph_per_c * (hub_c - plant.coil_mean_c()));
        let axial_dph = if self.multi {
            p.axial_gradient_dph_per_c * (plant.base_c - plant.top_c)
        } else {
            0.0
        };
        let drive: f64 = StandardNormal.sample(rng);
        self.gm_dph = self.gm_phi * self.gm_dph + self.gm_drive_dph * drive;
        // Zero terms add ±0 exactly: the documented gyro's runs stay bit for bit.
        static_dph + shupe_dph + radial_dph + axial_dph + stress_dph + self.gm_dph
    }

    /// White rate noise of one sample (angle random walk), °/h.
    pub fn noise_dph(&mut self, rng: &mut impl Rng) -> f64 {
        let n: f64 = StandardNormal.sample(rng);
        self.white_dph * n
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_pcg::Pcg64;

    use super::*;
    use crate::simulate::plant::{Plant, PlantParams};

    /// The Shupe term alone, °/h: every other term zeroed, no noise.
    fn shupe_dph(params: &GyroParams, plant: &Plant, rates: &NodeRates) -> f64 {
        let p = GyroParams {
            static_coeffs: [0.0; 4],
            radial_gradient_dph_per_c: 0.0,
            bias_instability_dph: 0.0,
            ..params.clone()
        };
        Gyro::new(&p, 1.0, false).bias_dph(plant, rates, &mut Pcg64::seed_from_u64(1))
    }

    #[test]
    fn the_shupe_gain_follows_each_layers_own_temperature_when_asked() {
        let weights = vec![2.0, -3.0, 1.5, 0.5];
        let mean_gain = GyroParams {
            shupe_dph_per_c_per_min: 0.4,
            shupe_temp_coeff_per_c: 0.02,
            shupe_layer_weights: weights.clone(),
            ..GyroParams::default()
        };
        let layer_gain = GyroParams {
            shupe_gain_of_layer_temp: true,
            ..mean_gain.clone()
        };
        let mut plant = Plant::soaked(&PlantParams::default(), 0.0);
        let rates_c_per_min = [1.0, 0.6, 0.3, 0.1];
        let mut rates = NodeRates::default();
        for (r, per_min) in rates.coil_c_per_s.iter_mut().zip(rates_c_per_min) {
            *r = per_min / 60.0;
        }
        // Soaked at one temperature, both forms are the same law.
        let (a, b) = (
            shupe_dph(&mean_gain, &plant, &rates),
            shupe_dph(&layer_gain, &plant, &rates),
        );
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        // Layers 20, 10, 0, −10 °C (mean 5 °C): each layer's gain at its own temperature.
        plant.coil_c[..4].copy_from_slice(&[20.0, 10.0, 0.0, -10.0]);
        let expected = |temps: [f64; 4]| -> f64 {
            (0..4)
                .map(|i| 0.4 * weights[i] * (1.0 + 0.02 * (temps[i] - 25.0)) * rates_c_per_min[i])
                .sum()
        };
        let got = shupe_dph(&layer_gain, &plant, &rates);
        assert!((got - expected([20.0, 10.0, 0.0, -10.0])).abs() < 1e-12, "{got}");
        let got = shupe_dph(&mean_gain, &plant, &rates);
        assert!((got - expected([5.0; 4])).abs() < 1e-12, "{got}");
        // With weights of opposite sign the two differ by much more than rounding.
        assert!((got - expected([20.0, 10.0, 0.0, -10.0])).abs() > 0.01);
    }

    #[test]
    fn the_layer_gain_flag_is_recorded_only_when_set() {
        let json = serde_json::to_string(&GyroParams::default()).unwrap();
        assert!(!json.contains("shupe_gain_of_layer_temp"), "{json}");
        let set = GyroParams {
            shupe_gain_of_layer_temp: true,
            ..GyroParams::default()
        };
        let json = serde_json::to_string(&set).unwrap();
        assert!(json.contains("\"shupe_gain_of_layer_temp\":true"), "{json}");
        assert_eq!(serde_json::from_str::<GyroParams>(&json).unwrap(), set);
    }
}
