//! Thermal network of the gyro in the chamber (docs/simulator.md, "Thermal plant").
//!
//! Nodes: housing base (bolted to the chamber's mounting plate) and top cover,
//! each a first-order lag of the chamber air; the electronics board, heated by
//! its own dissipation; the fiber coil in radial layers, the outer one coupled
//! to the housing (warmed by the electronics), the others by conduction to
//! their neighbours. Explicit Euler with steps ≤ 1 s (smallest τ is 5 s).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rbf_core::sensor::tmp117_quantise;

/// Radial layers of the fiber coil, outer (0) to inner.
pub const COIL_LAYERS: usize = 4;

/// Time constants and couplings of the thermal network (docs/simulator.md,
/// "Thermal plant"). The defaults are the documented gyro; `trainer simulate
/// --params FILE.json` overrides any of them to simulate another one.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantParams {
    /// Housing base (bolted to the chamber's mounting plate) ↔ chamber air, s.
    pub tau_base_s: f64,
    /// Housing top cover ↔ chamber air, s.
    pub tau_top_s: f64,
    /// Electronics board ↔ housing, s.
    pub tau_electronics_s: f64,
    /// Steady-state rise of the electronics above the housing from its dissipation, °C.
    pub self_heating_c: f64,
    /// Share of the electronics' rise seen by the space around the coil.
    pub electronics_to_coil: f64,
    /// Outer coil layer ↔ its surroundings, s.
    pub tau_coil_outer_s: f64,
    /// Conduction between neighbouring coil layers, s.
    pub tau_coil_layer_s: f64,
    /// Each thermometer's own lag, s, in [`THERMOMETERS`] order.
    pub thermometer_lags_s: [f64; 8],
}

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            tau_base_s: 900.0,
            tau_top_s: 1500.0,
            tau_electronics_s: 600.0,
            self_heating_c: 4.0,
            electronics_to_coil: 0.2,
            tau_coil_outer_s: 500.0,
            tau_coil_layer_s: 700.0,
            thermometer_lags_s: THERMOMETERS.map(|(_, lag_s)| lag_s),
        }
    }
}

impl PlantParams {
    /// Shortest time constant, s: the explicit Euler step must stay well below it.
    pub fn shortest_tau_s(&self) -> f64 {
        [
            self.tau_base_s,
            self.tau_top_s,
            self.tau_electronics_s,
            self.tau_coil_outer_s,
            self.tau_coil_layer_s,
        ]
        .into_iter()
        .chain(self.thermometer_lags_s)
        .fold(f64::INFINITY, f64::min)
    }

    /// Why these parameters cannot be simulated, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        let shortest_s = self.shortest_tau_s();
        if !(shortest_s >= MIN_TAU_S && shortest_s.is_finite()) {
            return Err(format!("every time constant must be at least {MIN_TAU_S} s"));
        }
        if !(self.self_heating_c.is_finite() && self.self_heating_c.abs() <= 50.0) {
            return Err("self_heating_c must lie within −50 … 50 °C".into());
        }
        if !(0.0..=1.0).contains(&self.electronics_to_coil) {
            return Err("electronics_to_coil must lie within 0 … 1".into());
        }
        Ok(())
    }
}

/// Shortest time constant the integrator accepts, s (its step is ≤ 1 s).
pub const MIN_TAU_S: f64 = 5.0;

/// Temperatures of the plant's nodes, °C.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    /// Housing base plate.
    pub base_c: f64,
    /// Housing top cover.
    pub top_c: f64,
    /// Electronics board.
    pub electronics_c: f64,
    /// Coil layers, outer to inner.
    pub coil_c: [f64; COIL_LAYERS],
    /// Chamber air at the last step.
    pub air_c: f64,
}

/// Time derivatives of the coil layers at the last step, °C/s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NodeRates {
    /// d/dt of each coil layer, °C/s.
    pub coil_c_per_s: [f64; COIL_LAYERS],
}

impl Plant {
    /// Everything soaked at `temp_c`, electronics just switched on.
    pub fn soaked(temp_c: f64) -> Self {
        Plant {
            base_c: temp_c,
            top_c: temp_c,
            electronics_c: temp_c,
            coil_c: [temp_c; COIL_LAYERS],
            air_c: temp_c,
        }
    }

    /// Mean housing temperature, °C.
    pub fn housing_c(&self) -> f64 {
        0.5 * (self.base_c + self.top_c)
    }

    /// Mean coil temperature, °C.
    pub fn coil_mean_c(&self) -> f64 {
        self.coil_c.iter().sum::<f64>() / COIL_LAYERS as f64
    }

    /// Advances by `h` seconds with the chamber air at `air_c`; returns the coil rates.
    pub fn step(&mut self, p: &PlantParams, air_c: f64, h: f64) -> NodeRates {
        self.air_c = air_c;
        let housing = self.housing_c();
        let d_base = (air_c - self.base_c) / p.tau_base_s;
        let d_top = (air_c - self.top_c) / p.tau_top_s;
        let d_elec = (housing + p.self_heating_c - self.electronics_c) / p.tau_electronics_s;
        let surround = housing + p.electronics_to_coil * (self.electronics_c - housing);
        let c = self.coil_c;
        let mut d_coil = [0.0; COIL_LAYERS];
        for (i, d) in d_coil.iter_mut().enumerate() {
            let outer = if i == 0 {
                (surround - c[0]) / p.tau_coil_outer_s
            } else {
                (c[i - 1] - c[i]) / p.tau_coil_layer_s
            };
            let inner = if i + 1 < COIL_LAYERS {
                (c[i + 1] - c[i]) / p.tau_coil_layer_s
            } else {
                0.0
            };
            *d = outer + inner;
        }
        self.base_c += h * d_base;
        self.top_c += h * d_top;
        self.electronics_c += h * d_elec;
        for (t, d) in self.coil_c.iter_mut().zip(&d_coil) {
            *t += h * d;
        }
        NodeRates { coil_c_per_s: d_coil }
    }
}

/// Index of the fiber-loop sensor (written as `temp_c`).
pub const LOOP_SENSOR: usize = 2;
/// Thermometer noise, °C (1σ, before TMP117 quantisation).
pub const THERMOMETER_NOISE_C: f64 = 0.002;
/// Where each of the eight thermometers sits and its default lag, s
/// ([`PlantParams::thermometer_lags_s`]).
pub const THERMOMETERS: [(&str, f64); 8] = [
    ("housing base", 5.0),
    ("housing top cover", 5.0),
    ("fiber coil, outer surface (the loop sensor)", 8.0),
    ("fiber coil, inner layer (embedded)", 20.0),
    ("electronics board", 5.0),
    ("coil flange", 15.0),
    ("mounting plate", 300.0),
    ("chamber air", 30.0),
];

/// The eight thermometers: lagged views of the plant, read with noise and TMP117 resolution.
#[derive(Clone, Debug)]
pub struct Thermometers {
    lagged_c: [f64; 8],
}

impl Thermometers {
    /// All thermometers settled at `temp_c`.
    pub fn new(temp_c: f64) -> Self {
        Thermometers { lagged_c: [temp_c; 8] }
    }

    fn sensed_node_c(plant: &Plant, i: usize) -> f64 {
        match i {
            0 => plant.base_c,
            1 => plant.top_c,
            2 => plant.coil_c[0],
            3 => plant.coil_c[COIL_LAYERS - 1],
            4 => plant.electronics_c,
            5 => 0.5 * (plant.coil_c[1] + plant.housing_c()),
            6 | 7 => plant.air_c,
            _ => plant.coil_mean_c(),
        }
    }

    /// Advances each sensor's lag by `h` seconds.
    pub fn step(&mut self, p: &PlantParams, plant: &Plant, h: f64) {
        for (i, t) in self.lagged_c.iter_mut().enumerate() {
            *t += h / p.thermometer_lags_s[i] * (Self::sensed_node_c(plant, i) - *t);
        }
    }

    /// One reading of each thermometer, °C.
    pub fn read(&self, rng: &mut impl Rng) -> [f64; 8] {
        self.lagged_c.map(|t| {
            let noise: f64 = StandardNormal.sample(rng);
            tmp117_quantise(t + THERMOMETER_NOISE_C * noise) as f64
        })
    }
}
