//! `trainer simulate`: a physics-based IFOG in a thermal chamber or in use
//! (equations, parameter values and their sources: docs/simulator.md).
//!
//! [`profile`] gives the air temperature history (chamber set points, in-use
//! histories, or a planned chamber run read by [`chamber_file`]), [`plant`]
//! integrates the thermal network (air → housing base/top → self-heated
//! electronics → fiber coil in radial layers on its hub → thermometers),
//! [`gyro`] turns the coil's temperature distribution into bias and adds
//! noise, [`unit`](mod@unit) draws a whole gyro (`--unit`, `--design`) from the
//! documented ranges.
//! [`ChamberRun::write_csv`] streams the recorded run, so hundreds of MB
//! never sit in memory.

pub mod axes;
pub mod chamber_file;
pub mod gyro;
pub mod params;
pub mod plant;
pub mod profile;
pub mod unit;

use std::io::Write;

use rand::SeedableRng;
use rand_pcg::Pcg64;

pub use params::{ParamsError, SimParams};
pub use profile::{Profile, Schedule};

/// Thermometer columns of multi-point runs; `temp_c` is the fiber-loop sensor,
/// so single-point models read the same files.
pub const MULTI_COLUMNS: [&str; 8] = [
    "temp_a", "temp_b", "temp_c", "temp_d", "temp_e", "temp_f", "temp_g", "temp_h",
];

/// What to simulate: a chamber run or a history in use.
#[derive(Clone, Debug)]
pub struct ChamberRun {
    /// Temperature profile.
    pub profile: Profile,
    /// Chamber ramp rate between set points, °C/min (ifog, cycle and designed profiles).
    pub ramp_c_per_min: f64,
    /// Hold at each set point, s (ifog and cycle profiles).
    pub hold_s: f64,
    /// Total duration, s; `None`: as long as the profile (random: 8 h and the
    /// hold it is in; in-use histories: [`Profile::default_duration_s`]).
    pub duration_s: Option<f64>,
    /// Gyro sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Write 8 thermometers `temp_a`…`temp_h` (and the gradient bias they reveal).
    pub multi: bool,
    /// Set-point range of random profiles, °C (min, max).
    pub random_range_c: (f64, f64),
    /// Ramp-rate range of random profiles, °C/min (slowest, fastest).
    pub ramp_range_c_per_min: (f64, f64),
    /// Chamber levels of [`Profile::Soak`] runs, in order, °C.
    pub soak_levels_c: Vec<f64>,
    /// Hold at each level of [`Profile::Soak`] runs, s.
    pub soak_hold_s: f64,
    /// The chamber profile of [`Profile::Planned`] runs.
    pub planned: Option<Schedule>,
    /// Where the planned profile was read from (metadata).
    pub planned_source: Option<String>,
    /// The gyro's thermal network and bias model.
    pub params: SimParams,
    /// The family and number the parameters were drawn for (`--unit N`,
    /// `--design N`; metadata).
    pub drawn: Option<(unit::Family, u64)>,
    /// Zero every thermal bias term: the run's noise alone, sample for sample
    /// the noise of the same run with its thermal bias (its noise ceiling).
    pub noise_only: bool,
    /// Random seed: the same seed gives the same file.
    pub seed: u64,
}

/// Ramp-rate range of random profiles unless told otherwise, °C/min.
pub const RANDOM_RAMP_RANGE_C_PER_MIN: (f64, f64) = (0.5, 5.0);

impl ChamberRun {
    /// The profile settings its schedule is drawn from.
    pub fn schedule_spec(&self) -> profile::ScheduleSpec<'_> {
        profile::ScheduleSpec {
            profile: self.profile,
            duration_s: self.duration_s,
            ramp_c_per_min: self.ramp_c_per_min,
            hold_s: self.hold_s,
            random_range_c: self.random_range_c,
            ramp_range_c_per_min: self.ramp_range_c_per_min,
            soak_levels_c: &self.soak_levels_c,
            soak_hold_s: self.soak_hold_s,
            planned: self.planned.as_ref(),
        }
    }

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
            ramp_range_c_per_min: RANDOM_RAMP_RANGE_C_PER_MIN,
            soak_levels_c: profile::SOAK_LEVELS_C.to_vec(),
            soak_hold_s: profile::SOAK_HOLD_S,
            planned: None,
            planned_source: None,
            params: SimParams::default(),
            drawn: None,
            noise_only: false,
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

    /// The designed multi-rate chamber run: cold start at −20 °C, ramps at
    /// 5 °C/min between levels across −40 … 60 °C, holds of 15 … 50 min.
    pub fn designed(seed: u64) -> Self {
        ChamberRun {
            profile: Profile::Designed,
            ramp_c_per_min: profile::DESIGNED_RAMP_C_PER_MIN,
            ..ChamberRun::ifog(1.0, seed)
        }
    }

    /// A run of `profile` with the defaults of [`ChamberRun::ifog`] (1 °C/min, 2-h holds, 1 Hz).
    pub fn with_profile(profile: Profile, seed: u64) -> Self {
        ChamberRun {
            profile,
            ..ChamberRun::ifog(1.0, seed)
        }
    }

    /// The chamber profile `schedule` (read from `source`, for the metadata).
    pub fn planned(schedule: Schedule, source: &str, seed: u64) -> Self {
        ChamberRun {
            profile: Profile::Planned,
            planned: Some(schedule),
            planned_source: Some(source.to_owned()),
            ..ChamberRun::ifog(1.0, seed)
        }
    }

    /// The run's length, s, and its number of samples (rows), as
    /// [`ChamberRun::write_csv`] will make them.
    pub fn extent(&self) -> (f64, u64) {
        let mut rng = Pcg64::seed_from_u64(self.seed);
        let (_, duration_s, _) = self.setup(&mut rng);
        (duration_s, (duration_s * self.sample_rate_hz).floor() as u64)
    }

    /// Streams the run as recorded-run CSV.
    pub fn write_csv(&self, out: &mut impl Write) -> std::io::Result<()> {
        let mut rng = Pcg64::seed_from_u64(self.seed);
        let (schedule, duration_s, params) = self.setup(&mut rng);
        let dt = 1.0 / self.sample_rate_hz;
        let start_c = schedule.air_c(0.0);
        let mut plant = plant::Plant::soaked(&params.plant, start_c);
        let mut gyro = gyro::Gyro::new(&params.gyro, self.sample_rate_hz, self.multi);
        let mut thermometers = plant::Thermometers::new(start_c);
        self.write_metadata(out, &params, start_c)?;
        if self.multi {
            writeln!(out, "time_s,rate_dph,ref_dph,{}", MULTI_COLUMNS.join(","))?;
        } else {
            writeln!(out, "time_s,rate_dph,temp_c,ref_dph")?;
        }
        let reference = gyro::earth_rate_projection_dph();
        let steps = (duration_s * self.sample_rate_hz).floor() as u64;
        let (substeps, h) = plant::substeps(dt);
        let mut line = String::with_capacity(160);
        for i in 0..steps {
            let t = i as f64 * dt;
            let mut rates = plant::NodeRates::default();
            for s in 0..substeps {
                rates = plant.step(&params.plant, schedule.air_c(t + s as f64 * h), h);
                thermometers.step(&params.plant, &plant, h);
            }
            let rate = reference + gyro.bias_dph(&plant, &rates, &mut rng) + gyro.noise_dph(&mut rng);
            let readings = thermometers.read(&params.plant, &mut rng);
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

    /// The air schedule, the run's length, s, and the simulated gyro's
    /// parameters (noise alone with `noise_only`), drawn from `rng` first.
    pub(crate) fn setup(&self, rng: &mut Pcg64) -> (Schedule, f64, SimParams) {
        let schedule = profile::schedule(&self.schedule_spec(), rng);
        // In-use histories end at their length; chamber runs with their last hold.
        let in_use_s = self.profile.default_duration_s().filter(|_| self.profile.in_use());
        let duration_s = self.duration_s.or(in_use_s).unwrap_or(schedule.duration_s());
        let params = match self.noise_only {
            true => SimParams {
                gyro: self.params.gyro.noise_only(),
                ..self.params.clone()
            },
            false => self.params.clone(),
        };
        (schedule, duration_s, params)
    }

    /// The `#` metadata lines of the run, for a gyro of `params` powered on at `start_c`, °C.
    pub(crate) fn write_metadata(&self, out: &mut impl Write, params: &SimParams, start_c: f64) -> std::io::Result<()> {
        let kind = if self.profile.in_use() {
            "in-use history"
        } else {
            "chamber run"
        };
        writeln!(
            out,
            "# source: trainer simulate (physics-based IFOG {kind}, docs/simulator.md)"
        )?;
        writeln!(out, "# profile: {}", self.profile.name())?;
        if let Some(source) = &self.planned_source {
            writeln!(out, "# chamber_profile: {source}")?;
        }
        writeln!(out, "# seed: {}", self.seed)?;
        writeln!(out, "# sample_rate_hz: {}", self.sample_rate_hz)?;
        match self.profile {
            Profile::Random => {
                writeln!(
                    out,
                    "# set_point_range_c: {} .. {}",
                    self.random_range_c.0, self.random_range_c.1
                )?;
                if self.ramp_range_c_per_min != RANDOM_RAMP_RANGE_C_PER_MIN {
                    let (slowest, fastest) = self.ramp_range_c_per_min;
                    writeln!(out, "# ramp_range_c_per_min: {slowest} .. {fastest}")?;
                }
            }
            Profile::Ifog | Profile::Cycle | Profile::Designed => {
                writeln!(out, "# ramp_c_per_min: {}", self.ramp_c_per_min)?;
            }
            Profile::Soak => {
                writeln!(out, "# ramp_c_per_min: {}", self.ramp_c_per_min)?;
                let levels: Vec<String> = self.soak_levels_c.iter().map(f64::to_string).collect();
                writeln!(out, "# soak_levels_c: {}", levels.join(", "))?;
                writeln!(out, "# soak_hold_h: {}", self.soak_hold_s / 3600.0)?;
            }
            _ => {}
        }
        if matches!(self.profile, Profile::Designed | Profile::Planned | Profile::Soak) || self.profile.in_use() {
            writeln!(out, "# power_on: at 0 s, soaked at {start_c:.2} °C")?;
        }
        writeln!(out, "# latitude_deg: {}", gyro::LATITUDE_DEG)?;
        writeln!(out, "# heading_deg: {}", gyro::HEADING_DEG)?;
        writeln!(out, "# arw_deg_per_sqrt_h: {}", params.gyro.arw_deg_per_sqrt_h)?;
        writeln!(out, "# bias_instability_dph: {}", params.gyro.bias_instability_dph)?;
        if let Some((family, n)) = self.drawn {
            writeln!(out, "# {}: {n}", family.name())?;
        }
        if self.noise_only {
            writeln!(
                out,
                "# noise_only: every thermal bias term zeroed (the run's noise ceiling)"
            )?;
        }
        if *params != SimParams::default() {
            let json = serde_json::to_string(&params).map_err(std::io::Error::other)?;
            writeln!(out, "# simulator_params: {json}")?;
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
        let documented = ChamberRun {
            duration_s: Some(4.0 * 3600.0),
            multi: true,
            ..ChamberRun::cycle(5.0, 7)
        };
        // A drawn unit (hub, stress and hub-expansion terms) in a field history.
        let unit = ChamberRun {
            params: unit::unit_params(3),
            multi: true,
            ..ChamberRun::with_profile(Profile::Field, 8)
        };
        // A drawn design: layers of large opposite-sign weights, the gain at each layer's temperature.
        let design = ChamberRun {
            params: unit::Family::Design.params(3),
            ..ChamberRun::with_profile(Profile::Swings, 9)
        };
        assert!(design.params.gyro.shupe_gain_of_layer_temp);
        for thermal in [documented, unit, design] {
            let quiet = ChamberRun {
                noise_only: true,
                ..thermal.clone()
            };
            let (with, without) = (rates_dph(&thermal), rates_dph(&quiet));
            assert_eq!(with.len(), without.len());
            let bias: Vec<f64> = with.iter().zip(&without).map(|(a, b)| a - b).collect();
            // The difference is the thermal bias alone: smooth from second to
            // second, where the white noise is not.
            let (bias_steps, noise_steps) = (step_std(&bias), step_std(&without));
            assert!(
                bias_steps < 0.01 * noise_steps,
                "bias steps {bias_steps} °/h, noise steps {noise_steps} °/h"
            );
            let span = bias.iter().fold(0.0f64, |m, b| m.max(b.abs()));
            assert!(span > 0.1, "the thermal bias is there: {span} °/h");
            // And nothing thermal is left: the 100-s cluster STD of the quiet
            // run is that of white noise plus the Gauss–Markov bias instability.
            let g = &thermal.params.gyro;
            let white_dph = 60.0 * g.arw_deg_per_sqrt_h / 100f64.sqrt();
            let gm_dph = 0.664 * g.bias_instability_dph / 0.62;
            let expected = white_dph.hypot(gm_dph);
            let reference = gyro::earth_rate_projection_dph();
            let deviation: Vec<f64> = without.iter().map(|r| r - reference).collect();
            let time_s: Vec<f64> = (0..deviation.len()).map(|i| i as f64).collect();
            let measured = crate::metrics::cluster_std(&time_s, &deviation, 1.0);
            assert!(
                measured < 1.3 * expected && measured > 0.5 * expected,
                "noise-only 100-s STD {measured} °/h, expected ≈ {expected} °/h"
            );
        }
    }

    #[test]
    fn the_same_unit_and_seed_give_the_same_file_and_record_the_gyro() {
        let run = |unit: u64, seed: u64| {
            ChamberRun {
                params: unit::unit_params(unit),
                drawn: Some((unit::Family::Unit, unit)),
                duration_s: Some(1800.0),
                ..ChamberRun::with_profile(Profile::ColdStart, seed)
            }
            .to_csv()
        };
        let first = run(4, 1);
        assert_eq!(first, run(4, 1));
        assert_ne!(first, run(5, 1), "another unit, another gyro");
        assert!(first.contains("# unit: 4\n"));
        let recorded = first
            .lines()
            .find_map(|l| l.strip_prefix("# simulator_params: "))
            .expect("parameters recorded");
        // The record is the gyro: read back as --params, it is unit 4.
        let params = SimParams::default().overridden(recorded).expect("a valid record");
        assert_eq!(params, unit::unit_params(4));
    }

    #[test]
    fn params_override_a_unit_field_by_field_and_are_checked_as_a_whole() {
        let unit = unit::unit_params(2);
        let over = unit
            .overridden(
                r#"{"plant": {"tau_top_s": 999, "hub": {"tau_coil_s": 77}}, "gyro": {"arw_deg_per_sqrt_h": 0.002}}"#,
            )
            .unwrap();
        assert_eq!(over.plant.tau_top_s.to_bits(), 999f64.to_bits());
        let (hub, unit_hub) = (over.plant.hub.unwrap(), unit.plant.hub.unwrap());
        assert_eq!(hub.tau_coil_s.to_bits(), 77f64.to_bits());
        assert_eq!(
            hub.tau_base_s.to_bits(),
            unit_hub.tau_base_s.to_bits(),
            "the unit's other hub fields stay"
        );
        assert_eq!(over.plant.tau_base_s.to_bits(), unit.plant.tau_base_s.to_bits());
        assert_eq!(
            over.gyro.static_coeffs.map(f64::to_bits),
            unit.gyro.static_coeffs.map(f64::to_bits)
        );
        // On the documented gyro a hub given in part takes the documented hub's other fields.
        let hubbed = SimParams::default()
            .overridden(r#"{"plant": {"hub": {"tau_base_s": 400}}}"#)
            .unwrap();
        assert_eq!(
            hubbed.plant.hub.unwrap().tau_coil_s.to_bits(),
            plant::Hub::default().tau_coil_s.to_bits()
        );
        // More layers need as many Shupe weights.
        let error = SimParams::default()
            .overridden(r#"{"plant": {"coil_layers": 6}}"#)
            .unwrap_err();
        assert!(error.to_string().contains("4 weights, the coil 6 layers"), "{error}");
        let error = SimParams::default()
            .overridden("{\"plant\": {\"hub\": {\"tau\": 1}}}")
            .unwrap_err();
        assert!(error.to_string().starts_with("1:24: unknown field `tau`"), "{error}");
    }
}
