//! Thermal network of the gyro (docs/simulator.md, "Thermal plant").
//!
//! Nodes: housing base (bolted to the mounting plate) and top cover, each a
//! first-order lag of the surrounding air; the electronics board, heated by
//! its own dissipation from power-on; the fiber coil in 2 … 8 radial layers,
//! the outer one coupled to the air inside the housing (warmed by the
//! electronics), the others by conduction to their neighbours; and, where the
//! coil is wound on one, the hub (spool) bolted to the base, which the
//! innermost layer exchanges heat with, so that heat reaches the coil from
//! both sides. Explicit Euler with steps ≤ 1 s (every τ ≥ [`MIN_TAU_S`]).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rbf_core::sensor::tmp117_quantise;

/// Most radial layers a coil may be simulated with.
pub const MAX_COIL_LAYERS: usize = 8;
/// Fewest radial layers a coil may be simulated with.
pub const MIN_COIL_LAYERS: usize = 2;

/// The hub (spool) the coil is wound on: bolted to the housing base, in
/// contact with the innermost layer. A field left out of `--params` keeps
/// the value the gyro had, or the default below if it had no hub.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Hub {
    /// Hub ↔ housing base, s (seen from the hub).
    pub tau_base_s: f64,
    /// Innermost coil layer ↔ hub, s (seen from the layer).
    pub tau_coil_s: f64,
    /// Heat capacity of the hub over one coil layer's: the hub's side of the
    /// exchange with the coil is this much slower.
    pub heat_capacity_ratio: f64,
}

impl Default for Hub {
    fn default() -> Self {
        Hub {
            tau_base_s: 1500.0,
            tau_coil_s: 800.0,
            heat_capacity_ratio: 1.5,
        }
    }
}

/// Where the fiber-loop sensor (`temp_c`) sits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LoopSensor {
    /// Glued on the outer surface of the coil (outer layer).
    #[default]
    OuterSurface,
    /// On the coil flange: half the coil's layer 1, half its mount (the hub, or the housing).
    Flange,
    /// On the hub (spool) inside the coil.
    Hub,
    /// Embedded in radial layer k (0 = outer), JSON `{"layer": k}`.
    Layer(usize),
    /// On the housing wall: the mean of base and top cover.
    HousingWall,
}

/// Time constants and couplings of the thermal network (docs/simulator.md,
/// "Thermal plant"). The defaults are the documented gyro; `trainer simulate
/// --params FILE.json` overrides any of them, `--unit N` draws them all.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantParams {
    /// Housing base (bolted to the mounting plate) ↔ surrounding air, s.
    pub tau_base_s: f64,
    /// Housing top cover ↔ surrounding air, s.
    pub tau_top_s: f64,
    /// Electronics board ↔ housing, s.
    pub tau_electronics_s: f64,
    /// Steady-state rise of the electronics above the housing from its dissipation, °C.
    pub self_heating_c: f64,
    /// Share of the electronics' rise seen by the air around the coil.
    pub electronics_to_coil: f64,
    /// Share of the electronics' rise the housing base settles above the surrounding air.
    pub electronics_to_base: f64,
    /// Share of the electronics' rise the hub settles above the housing base.
    pub electronics_to_hub: f64,
    /// Radial layers of the coil, 2 … 8.
    pub coil_layers: usize,
    /// Outer coil layer ↔ its surroundings, s.
    pub tau_coil_outer_s: f64,
    /// Conduction between neighbouring coil layers, s.
    pub tau_coil_layer_s: f64,
    /// The hub the coil is wound on; `null`: the innermost layer is insulated.
    pub hub: Option<Hub>,
    /// Where the loop sensor (`temp_c`) sits; its lag is `thermometer_lags_s[2]`.
    pub loop_sensor: LoopSensor,
    /// Each thermometer's own lag, s, in [`THERMOMETERS`] order.
    pub thermometer_lags_s: [f64; 8],
    /// Thermometer noise, °C (1σ, before TMP117 quantisation).
    pub thermometer_noise_c: f64,
}

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            tau_base_s: 900.0,
            tau_top_s: 1500.0,
            tau_electronics_s: 600.0,
            self_heating_c: 4.0,
            electronics_to_coil: 0.2,
            electronics_to_base: 0.0,
            electronics_to_hub: 0.0,
            coil_layers: 4,
            tau_coil_outer_s: 500.0,
            tau_coil_layer_s: 700.0,
            hub: None,
            loop_sensor: LoopSensor::OuterSurface,
            thermometer_lags_s: THERMOMETERS.map(|(_, lag_s)| lag_s),
            thermometer_noise_c: 0.002,
        }
    }
}

impl PlantParams {
    /// Shortest time constant, s: the explicit Euler step must stay well below it.
    pub fn shortest_tau_s(&self) -> f64 {
        let hub = self.hub.map_or([f64::INFINITY; 2], |h| {
            [h.tau_base_s, h.tau_coil_s * h.heat_capacity_ratio.min(1.0)]
        });
        [
            self.tau_base_s,
            self.tau_top_s,
            self.tau_electronics_s,
            self.tau_coil_outer_s,
            self.tau_coil_layer_s,
        ]
        .into_iter()
        .chain(hub)
        .chain(self.thermometer_lags_s)
        .fold(f64::INFINITY, f64::min)
    }

    /// Why these parameters cannot be simulated, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        if !(MIN_COIL_LAYERS..=MAX_COIL_LAYERS).contains(&self.coil_layers) {
            return Err(format!("coil_layers must be {MIN_COIL_LAYERS} … {MAX_COIL_LAYERS}"));
        }
        let shortest_s = self.shortest_tau_s();
        if !(shortest_s >= MIN_TAU_S && shortest_s.is_finite()) {
            return Err(format!("every time constant must be at least {MIN_TAU_S} s"));
        }
        if let Some(hub) = self.hub
            && !(hub.heat_capacity_ratio.is_finite() && hub.heat_capacity_ratio > 0.0)
        {
            return Err("hub.heat_capacity_ratio must be > 0".into());
        }
        if !(self.self_heating_c.is_finite() && self.self_heating_c.abs() <= 50.0) {
            return Err("self_heating_c must lie within −50 … 50 °C".into());
        }
        for (name, share) in [
            ("electronics_to_coil", self.electronics_to_coil),
            ("electronics_to_base", self.electronics_to_base),
            ("electronics_to_hub", self.electronics_to_hub),
        ] {
            if !(0.0..=1.0).contains(&share) {
                return Err(format!("{name} must lie within 0 … 1"));
            }
        }
        if !(self.thermometer_noise_c.is_finite() && (0.0..=1.0).contains(&self.thermometer_noise_c)) {
            return Err("thermometer_noise_c must lie within 0 … 1 °C".into());
        }
        match self.loop_sensor {
            LoopSensor::Hub if self.hub.is_none() => Err("loop_sensor \"hub\" needs a hub".into()),
            LoopSensor::Layer(k) if k >= self.coil_layers => Err(format!(
                "loop_sensor layer {k} does not exist: the coil has layers 0 … {}",
                self.coil_layers - 1
            )),
            _ => Ok(()),
        }
    }
}

/// Shortest time constant the integrator accepts, s (its step is ≤ 1 s).
pub const MIN_TAU_S: f64 = 5.0;

/// The integrator's internal thermal step for samples `dt` s apart: the
/// substeps per sample and their length, s (at most 1 s: explicit Euler,
/// every τ ≥ [`MIN_TAU_S`]).
pub fn substeps(dt: f64) -> (u32, f64) {
    let substeps = dt.ceil().max(1.0) as u32;
    (substeps, dt / substeps as f64)
}

/// Temperatures of the plant's nodes, °C.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    /// Housing base plate.
    pub base_c: f64,
    /// Housing top cover.
    pub top_c: f64,
    /// Electronics board.
    pub electronics_c: f64,
    /// Coil layers, outer to inner; the first [`Plant::layers`] are the coil's.
    pub coil_c: [f64; MAX_COIL_LAYERS],
    /// Radial layers of the coil.
    pub layers: usize,
    /// Hub (spool), if the coil has one.
    pub hub_c: Option<f64>,
    /// Surrounding air at the last step.
    pub air_c: f64,
}

/// Time derivatives of the coil layers at the last step, °C/s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NodeRates {
    /// d/dt of each coil layer, outer to inner, °C/s.
    pub coil_c_per_s: [f64; MAX_COIL_LAYERS],
}

impl Plant {
    /// Everything soaked at `temp_c`, electronics just switched on.
    pub fn soaked(p: &PlantParams, temp_c: f64) -> Self {
        Plant {
            base_c: temp_c,
            top_c: temp_c,
            electronics_c: temp_c,
            coil_c: [temp_c; MAX_COIL_LAYERS],
            layers: p.coil_layers.clamp(MIN_COIL_LAYERS, MAX_COIL_LAYERS),
            hub_c: p.hub.map(|_| temp_c),
            air_c: temp_c,
        }
    }

    /// Mean housing temperature, °C.
    pub fn housing_c(&self) -> f64 {
        0.5 * (self.base_c + self.top_c)
    }

    /// The coil's layers, outer to inner, °C.
    pub fn layers_c(&self) -> &[f64] {
        &self.coil_c[..self.layers]
    }

    /// Mean coil temperature, °C.
    pub fn coil_mean_c(&self) -> f64 {
        self.layers_c().iter().sum::<f64>() / self.layers as f64
    }

    /// Outer coil layer, °C.
    pub fn outer_c(&self) -> f64 {
        self.coil_c[0]
    }

    /// Innermost coil layer, °C.
    pub fn inner_c(&self) -> f64 {
        self.coil_c[self.layers - 1]
    }

    /// Coil flange: half layer 1, half the coil's mount (the hub, or the housing without one), °C.
    pub fn flange_c(&self) -> f64 {
        0.5 * (self.coil_c[1] + self.hub_c.unwrap_or_else(|| self.housing_c()))
    }

    /// Advances by `h` seconds with the surrounding air at `air_c`; returns the coil rates.
    pub fn step(&mut self, p: &PlantParams, air_c: f64, h: f64) -> NodeRates {
        self.air_c = air_c;
        let housing = self.housing_c();
        // The electronics' rise above the housing: the heat its dissipation spreads.
        let heat_c = self.electronics_c - housing;
        let d_base = (air_c + p.electronics_to_base * heat_c - self.base_c) / p.tau_base_s;
        let d_top = (air_c - self.top_c) / p.tau_top_s;
        let d_elec = (housing + p.self_heating_c - self.electronics_c) / p.tau_electronics_s;
        let surround = housing + p.electronics_to_coil * heat_c;
        let n = self.layers;
        let c = self.coil_c;
        let mut d_coil = [0.0; MAX_COIL_LAYERS];
        for (i, d) in d_coil[..n].iter_mut().enumerate() {
            let outer = if i == 0 {
                (surround - c[0]) / p.tau_coil_outer_s
            } else {
                (c[i - 1] - c[i]) / p.tau_coil_layer_s
            };
            let inner = match (i + 1 < n, self.hub_c, p.hub) {
                (true, _, _) => (c[i + 1] - c[i]) / p.tau_coil_layer_s,
                (false, Some(hub_c), Some(hub)) => (hub_c - c[i]) / hub.tau_coil_s,
                (false, _, _) => 0.0,
            };
            *d = outer + inner;
        }
        if let (Some(hub_c), Some(hub)) = (self.hub_c.as_mut(), p.hub) {
            let mount = self.base_c + p.electronics_to_hub * heat_c;
            let d_hub =
                (mount - *hub_c) / hub.tau_base_s + (c[n - 1] - *hub_c) / (hub.tau_coil_s * hub.heat_capacity_ratio);
            *hub_c += h * d_hub;
        }
        self.base_c += h * d_base;
        self.top_c += h * d_top;
        self.electronics_c += h * d_elec;
        for (t, d) in self.coil_c[..n].iter_mut().zip(&d_coil) {
            *t += h * d;
        }
        NodeRates { coil_c_per_s: d_coil }
    }
}

impl LoopSensor {
    /// The node temperature this placement senses, °C.
    pub fn node_c(self, plant: &Plant) -> f64 {
        match self {
            LoopSensor::OuterSurface => plant.outer_c(),
            LoopSensor::Flange => plant.flange_c(),
            // `PlantParams::check` refuses a hub sensor without a hub.
            LoopSensor::Hub => plant.hub_c.unwrap_or_else(|| plant.inner_c()),
            LoopSensor::Layer(k) => plant.coil_c[k.min(plant.layers - 1)],
            LoopSensor::HousingWall => plant.housing_c(),
        }
    }

    /// Name as the docs and the run's metadata write it.
    pub fn describe(self) -> String {
        match self {
            LoopSensor::OuterSurface => "outer coil surface".into(),
            LoopSensor::Flange => "coil flange".into(),
            LoopSensor::Hub => "hub".into(),
            LoopSensor::Layer(k) => format!("embedded in coil layer {k}"),
            LoopSensor::HousingWall => "housing wall".into(),
        }
    }
}

/// Index of the fiber-loop sensor (written as `temp_c`).
pub const LOOP_SENSOR: usize = 2;
/// Where each of the eight thermometers sits and its default lag, s
/// ([`PlantParams::thermometer_lags_s`]); the loop sensor's place is
/// [`PlantParams::loop_sensor`].
pub const THERMOMETERS: [(&str, f64); 8] = [
    ("housing base", 5.0),
    ("housing top cover", 5.0),
    ("fiber-loop sensor (default: outer coil surface)", 8.0),
    ("fiber coil, innermost layer (embedded)", 20.0),
    ("electronics board", 5.0),
    ("coil flange", 15.0),
    ("mounting plate", 300.0),
    ("surrounding air", 30.0),
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

    fn sensed_node_c(p: &PlantParams, plant: &Plant, i: usize) -> f64 {
        match i {
            0 => plant.base_c,
            1 => plant.top_c,
            LOOP_SENSOR => p.loop_sensor.node_c(plant),
            3 => plant.inner_c(),
            4 => plant.electronics_c,
            5 => plant.flange_c(),
            6 | 7 => plant.air_c,
            _ => plant.coil_mean_c(),
        }
    }

    /// Advances each sensor's lag by `h` seconds.
    pub fn step(&mut self, p: &PlantParams, plant: &Plant, h: f64) {
        for (i, t) in self.lagged_c.iter_mut().enumerate() {
            *t += h / p.thermometer_lags_s[i] * (Self::sensed_node_c(p, plant, i) - *t);
        }
    }

    /// One reading of each thermometer, °C.
    pub fn read(&self, p: &PlantParams, rng: &mut impl Rng) -> [f64; 8] {
        self.lagged_c.map(|t| {
            let noise: f64 = StandardNormal.sample(rng);
            tmp117_quantise(t + p.thermometer_noise_c * noise) as f64
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plant with a hub, self-heating into air, base and hub, six layers.
    fn hub_plant() -> PlantParams {
        PlantParams {
            electronics_to_base: 0.2,
            electronics_to_hub: 0.3,
            coil_layers: 6,
            tau_coil_layer_s: 300.0,
            hub: Some(Hub::default()),
            ..PlantParams::default()
        }
    }

    /// Runs `plant` for `seconds` at 1-s steps with the air at `air_c(t)`; the last rates.
    fn run(p: &PlantParams, plant: &mut Plant, seconds: u32, air_c: impl Fn(f64) -> f64) -> NodeRates {
        let mut rates = NodeRates::default();
        for s in 0..seconds {
            rates = plant.step(p, air_c(s as f64), 1.0);
        }
        rates
    }

    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "every exchange is a difference of equal temperatures: exactly zero, so nothing may move"
    )]
    fn a_soaked_plant_without_self_heating_stays_put() {
        for p in [PlantParams::default(), hub_plant()] {
            let p = PlantParams {
                self_heating_c: 0.0,
                ..p
            };
            let mut plant = Plant::soaked(&p, 13.7);
            let before = plant.clone();
            let rates = run(&p, &mut plant, 20_000, |_| 13.7);
            assert_eq!(plant, before, "{p:?}");
            assert_eq!(rates, NodeRates::default());
        }
    }

    #[test]
    fn self_heating_settles_where_its_shares_put_it() {
        let p = hub_plant();
        let mut plant = Plant::soaked(&p, -20.0);
        let rates = run(&p, &mut plant, 100 * 3600, |_| -20.0);
        assert!(rates.coil_c_per_s.iter().all(|r| r.abs() < 1e-12), "{rates:?}");
        let close = |a: f64, b: f64, what: &str| assert!((a - b).abs() < 1e-6, "{what}: {a} vs {b}");
        close(
            plant.electronics_c - plant.housing_c(),
            p.self_heating_c,
            "electronics rise",
        );
        close(
            plant.base_c + 20.0,
            p.electronics_to_base * p.self_heating_c,
            "base rise",
        );
        close(plant.top_c, -20.0, "top cover");
        let hub_c = plant.hub_c.expect("a hub");
        // The hub settles between its mount (base + its share) and the coil it exchanges with.
        let mount = plant.base_c + p.electronics_to_hub * p.self_heating_c;
        assert!(
            hub_c > plant.base_c && hub_c <= mount.max(plant.inner_c()) + 1e-9,
            "hub {hub_c}"
        );
        // Steady heat flows through the winding, so the layers keep a steady radial gradient.
        assert!(plant.layers_c().windows(2).all(|w| (w[0] - w[1]).abs() < 1.0));
    }

    #[test]
    fn on_a_steady_ramp_the_layers_lag_in_order_outer_to_inner() {
        let p = PlantParams {
            self_heating_c: 0.0,
            coil_layers: 6,
            tau_coil_layer_s: 300.0,
            ..PlantParams::default()
        };
        let mut plant = Plant::soaked(&p, 0.0);
        let rates = run(&p, &mut plant, 12 * 3600, |t| t / 60.0);
        let layers = plant.layers_c();
        assert!(
            layers.windows(2).all(|w| w[0] > w[1] + 0.01),
            "warming from outside: outer ahead of inner, {layers:?}"
        );
        assert!(plant.housing_c() > layers[0], "the housing leads the coil");
        // Settled ramp: every layer warms at the air's 1 °C/min.
        for r in &rates.coil_c_per_s[..6] {
            assert!((r * 60.0 - 1.0).abs() < 0.02, "{:?}", rates.coil_c_per_s);
        }
    }

    #[test]
    fn a_hub_feeds_the_inner_layers_from_inside() {
        let no_hub = PlantParams {
            self_heating_c: 0.0,
            coil_layers: 6,
            tau_coil_layer_s: 300.0,
            ..PlantParams::default()
        };
        let with_hub = PlantParams {
            hub: Some(Hub {
                tau_base_s: 300.0,
                tau_coil_s: 200.0,
                heat_capacity_ratio: 1.0,
            }),
            ..no_hub.clone()
        };
        let ramp = |t: f64| t / 60.0;
        let mut plain = Plant::soaked(&no_hub, 0.0);
        run(&no_hub, &mut plain, 3 * 3600, ramp);
        let mut hubbed = Plant::soaked(&with_hub, 0.0);
        run(&with_hub, &mut hubbed, 3 * 3600, ramp);
        let air_c = 3.0 * 60.0;
        let (plain_lag, hub_lag) = (air_c - plain.inner_c(), air_c - hubbed.inner_c());
        assert!(
            hub_lag < 0.5 * plain_lag,
            "inner layer lag: {hub_lag} °C with the hub, {plain_lag} °C without"
        );
        // Heat now comes from both sides: the coldest layer lies inside the winding.
        let layers = hubbed.layers_c();
        let coldest = (0..layers.len())
            .min_by(|&a, &b| layers[a].total_cmp(&layers[b]))
            .unwrap();
        assert!(0 < coldest && coldest < layers.len() - 1, "{layers:?}");
        // The outer layer hardly notices the hub.
        assert!((hubbed.outer_c() - plain.outer_c()).abs() < 0.3 * (air_c - plain.outer_c()));
    }

    #[test]
    fn the_loop_sensor_reads_the_node_it_is_placed_on() {
        let p = hub_plant();
        let mut plant = Plant::soaked(&p, 0.0);
        run(&p, &mut plant, 3600, |t| t / 60.0);
        let hub_c = plant.hub_c.unwrap();
        for (sensor, expected) in [
            (LoopSensor::OuterSurface, plant.coil_c[0]),
            (LoopSensor::Layer(4), plant.coil_c[4]),
            (LoopSensor::Hub, hub_c),
            (LoopSensor::Flange, 0.5 * (plant.coil_c[1] + hub_c)),
            (LoopSensor::HousingWall, plant.housing_c()),
        ] {
            assert_eq!(sensor.node_c(&plant).to_bits(), expected.to_bits(), "{sensor:?}");
        }
        // A place that does not exist is refused before any run.
        let bad = |loop_sensor| {
            PlantParams {
                loop_sensor,
                ..PlantParams::default()
            }
            .check()
        };
        assert!(bad(LoopSensor::Hub).unwrap_err().contains("needs a hub"));
        assert!(bad(LoopSensor::Layer(4)).unwrap_err().contains("layers 0 … 3"));
        assert!(bad(LoopSensor::Layer(3)).is_ok());
    }
}
