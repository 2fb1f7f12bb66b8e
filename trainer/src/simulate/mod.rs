//! `trainer simulate`: a physics-based IFOG in a thermal chamber
//! (equations, parameter values and their sources: docs/simulator.md).
//!
//! [`profile`] gives the chamber set-point schedule, [`plant`] integrates the
//! thermal network (chamber air → housing base/top → electronics → fiber coil
//! in radial layers → thermometers), [`gyro`] turns the coil's temperature
//! distribution into bias and adds noise. [`ChamberRun::write_csv`] streams
//! the recorded run, so hundreds of MB never sit in memory.

pub mod gyro;
pub mod plant;
pub mod profile;

use std::io::Write;

use rand::SeedableRng;
use rand_pcg::Pcg64;

pub use profile::Profile;

/// Thermometer columns of multi-point runs; `temp_c` is the fiber-loop sensor,
/// so single-point models read the same files.
pub const MULTI_COLUMNS: [&str; 8] = [
    "temp_a", "temp_b", "temp_c", "temp_d", "temp_e", "temp_f", "temp_g", "temp_h",
];

/// The simulated gyro: its thermal network and its bias and noise. Read from
/// `trainer simulate --params FILE.json` (any field left out keeps its
/// documented default), e.g. `{"plant": {"tau_top_s": 2400}, "gyro":
/// {"axial_gradient_dph_per_c": 0.05}}`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimParams {
    /// Time constants and couplings of the thermal network.
    pub plant: plant::PlantParams,
    /// Bias and noise.
    pub gyro: gyro::GyroParams,
}

impl SimParams {
    /// Why these parameters cannot be simulated, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        self.plant.check().and_then(|()| self.gyro.check())
    }
}

/// What to simulate.
#[derive(Clone, Debug)]
pub struct ChamberRun {
    /// Temperature profile.
    pub profile: Profile,
    /// Chamber ramp rate between set points, °C/min (ifog and cycle profiles).
    pub ramp_c_per_min: f64,
    /// Hold at each set point, s (ifog and cycle profiles).
    pub hold_s: f64,
    /// Total duration, s; `None`: as long as the profile (random: 8 h).
    pub duration_s: Option<f64>,
    /// Gyro sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Write 8 thermometers `temp_a`…`temp_h` (and the gradient bias they reveal).
    pub multi: bool,
    /// Set-point range of random profiles, °C (min, max).
    pub random_range_c: (f64, f64),
    /// The gyro's thermal network and bias model.
    pub params: SimParams,
    /// Random seed: the same seed gives the same file.
    pub seed: u64,
}

impl ChamberRun {
    /// The IFOG paper's protocol: 25 °C, down to 10 °C, hold, up to 40 °C, hold, back to 25 °C; 1 Hz.
    pub fn ifog(ramp_c_per_min: f64, seed: u64) -> Self {
        ChamberRun {
            profile: Profile::Ifog,
            ramp_c_per_min,
            hold_s: 7200.0,
            duration_s: None,
            sample_rate_hz: 1.0,
            multi: false,
            random_range_c: (-40.0, 60.0),
            params: SimParams::default(),
            seed,
        }
    }

    /// The RLG paper's cycle: 20 → −40 → 60 → −40 → 60 → 20 °C with 2-h holds.
    pub fn cycle(ramp_c_per_min: f64, seed: u64) -> Self {
        ChamberRun {
            profile: Profile::Cycle,
            ..ChamberRun::ifog(ramp_c_per_min, seed)
        }
    }

    /// Random set points within `range_c`, ramp rates and holds over 8 h.
    pub fn random(seed: u64, range_c: (f64, f64)) -> Self {
        ChamberRun {
            profile: Profile::Random,
            random_range_c: range_c,
            ..ChamberRun::ifog(1.0, seed)
        }
    }

    /// Streams the run as recorded-run CSV.
    pub fn write_csv(&self, out: &mut impl Write) -> std::io::Result<()> {
        let mut rng = Pcg64::seed_from_u64(self.seed);
        let schedule = profile::schedule(self, &mut rng);
        let duration_s = self.duration_s.unwrap_or(schedule.duration_s());
        let dt = 1.0 / self.sample_rate_hz;
        let start_c = schedule.air_c(0.0);
        let mut plant = plant::Plant::soaked(start_c);
        let mut gyro = gyro::Gyro::new(&self.params.gyro, self.sample_rate_hz, self.multi);
        let mut thermometers = plant::Thermometers::new(start_c);

        writeln!(
            out,
            "# source: trainer simulate (physics-based IFOG chamber run, docs/simulator.md)"
        )?;
        writeln!(out, "# profile: {}", self.profile.name())?;
        writeln!(out, "# seed: {}", self.seed)?;
        writeln!(out, "# sample_rate_hz: {}", self.sample_rate_hz)?;
        if self.profile == Profile::Random {
            writeln!(
                out,
                "# set_point_range_c: {} .. {}",
                self.random_range_c.0, self.random_range_c.1
            )?;
        } else {
            writeln!(out, "# ramp_c_per_min: {}", self.ramp_c_per_min)?;
        }
        writeln!(out, "# latitude_deg: {}", gyro::LATITUDE_DEG)?;
        writeln!(out, "# heading_deg: {}", gyro::HEADING_DEG)?;
        writeln!(out, "# arw_deg_per_sqrt_h: {}", self.params.gyro.arw_deg_per_sqrt_h)?;
        writeln!(out, "# bias_instability_dph: {}", self.params.gyro.bias_instability_dph)?;
        if self.params != SimParams::default() {
            let json = serde_json::to_string(&self.params).map_err(std::io::Error::other)?;
            writeln!(out, "# simulator_params: {json}")?;
        }
        if self.multi {
            writeln!(out, "time_s,rate_dph,ref_dph,{}", MULTI_COLUMNS.join(","))?;
        } else {
            writeln!(out, "time_s,rate_dph,temp_c,ref_dph")?;
        }
        let reference = gyro::earth_rate_projection_dph();
        let steps = (duration_s * self.sample_rate_hz).floor() as u64;
        // Internal thermal step: at most 1 s (explicit Euler, every τ ≥ plant::MIN_TAU_S).
        let substeps = dt.ceil().max(1.0) as u32;
        let h = dt / substeps as f64;
        let mut line = String::with_capacity(160);
        for i in 0..steps {
            let t = i as f64 * dt;
            let mut rates = plant::NodeRates::default();
            for s in 0..substeps {
                rates = plant.step(&self.params.plant, schedule.air_c(t + s as f64 * h), h);
                thermometers.step(&self.params.plant, &plant, h);
            }
            let rate = reference + gyro.bias_dph(&plant, &rates, &mut rng) + gyro.noise_dph(&mut rng);
            let readings = thermometers.read(&mut rng);
            line.clear();
            use std::fmt::Write as _;
            if self.multi {
                let _ = write!(line, "{t:.4},{rate:.5},{reference:.5}");
                for r in readings {
                    let _ = write!(line, ",{r:.7}");
                }
            } else {
                let _ = write!(
                    line,
                    "{t:.4},{rate:.5},{:.7},{reference:.5}",
                    readings[plant::LOOP_SENSOR]
                );
            }
            line.push('\n');
            out.write_all(line.as_bytes())?;
        }
        Ok(())
    }

    /// The whole run as a string (small runs, tests).
    pub fn to_csv(&self) -> String {
        let mut buf = Vec::new();
        self.write_csv(&mut buf).expect("writing to memory cannot fail");
        String::from_utf8(buf).expect("the simulator writes ASCII")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rate column of a simulated run, °/h.
    fn rates_dph(run: &ChamberRun) -> Vec<f64> {
        run.to_csv()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .skip(1)
            .map(|l| l.split(',').nth(1).and_then(|v| v.parse().ok()).expect("rate column"))
            .collect()
    }

    /// Standard deviation of the sample-to-sample differences.
    fn step_std(x: &[f64]) -> f64 {
        let d: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    }

    #[test]
    fn zeroing_the_thermal_bias_leaves_the_same_noise_sample_for_sample() {
        // bench-accuracy's noise ceiling relies on it: the thermal terms may
        // not draw from the random stream the noise draws from.
        let thermal = ChamberRun {
            duration_s: Some(4.0 * 3600.0),
            multi: true,
            ..ChamberRun::cycle(5.0, 7)
        };
        let mut quiet = thermal.clone();
        let gyro = &mut quiet.params.gyro;
        gyro.static_coeffs = [0.0; 4];
        gyro.shupe_dph_per_c_per_min = 0.0;
        gyro.radial_gradient_dph_per_c = 0.0;
        gyro.axial_gradient_dph_per_c = 0.0;
        let (with, without) = (rates_dph(&thermal), rates_dph(&quiet));
        assert_eq!(with.len(), without.len());
        let bias: Vec<f64> = with.iter().zip(&without).map(|(a, b)| a - b).collect();
        // The difference is the thermal bias alone: smooth from second to
        // second (5 °C/min ramps), where the white noise is not.
        let (bias_steps, noise_steps) = (step_std(&bias), step_std(&without));
        assert!(
            bias_steps < 0.01 * noise_steps,
            "bias steps {bias_steps} °/h, noise steps {noise_steps} °/h"
        );
        let span = bias.iter().fold(0.0f64, |m, b| m.max(b.abs()));
        assert!(span > 0.1, "the thermal bias is there: {span} °/h");
    }
}
