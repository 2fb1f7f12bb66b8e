//! A synthetic IFOG thermal-chamber run (`trainer simulate`).
//!
//! A compact plant, independent of the fitting code's assumptions (the full
//! physics simulator with radial coil distribution and multi-point
//! thermometers is a planned extension):
//! - chamber air follows set points joined by ramps of `ramp_c_per_min`;
//! - housing and fiber coil follow as first-order lags (τ 900 s and 400 s);
//! - the loop-temperature sensor reads the coil through a 20-s lag with
//!   0.003 °C noise and TMP117 quantisation (0.0078125 °C);
//! - bias = static polynomial in coil temperature + a Shupe term proportional
//!   to the coil's rate of change with a T-dependent gain (IFOG paper Eq. 13,
//!   so T×ΔT matters) + a term in the housing–coil gradient + Gauss–Markov bias
//!   instability + white noise (angle random walk);
//! - `ref_dph` is the Earth-rate projection on a vertical axis at 45° N.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

/// Earth rotation rate, °/h.
const EARTH_RATE_DPH: f64 = 15.041_07;
/// TMP117 resolution, °C.
const TMP117_LSB_C: f64 = 0.007_812_5;

/// What to simulate.
#[derive(Clone, Debug)]
pub struct ChamberRun {
    /// Set points in order, °C; the run starts settled at the first.
    pub set_points_c: Vec<f64>,
    /// Hold at each set point after reaching it, s.
    pub hold_s: f64,
    /// Chamber ramp rate between set points, °C/min.
    pub ramp_c_per_min: f64,
    /// Gyro sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Angle random walk, °/√h.
    pub arw_deg_per_sqrt_h: f64,
    /// Random seed (same seed, same run).
    pub seed: u64,
}

impl ChamberRun {
    /// The IFOG paper's protocol: 25 → 10 → 40 → 25 °C with holds, 1 Hz.
    pub fn ifog(ramp_c_per_min: f64, seed: u64) -> Self {
        ChamberRun {
            set_points_c: vec![25.0, 10.0, 40.0, 25.0],
            hold_s: 3600.0,
            ramp_c_per_min,
            sample_rate_hz: 1.0,
            arw_deg_per_sqrt_h: 0.002,
            seed,
        }
    }

    /// Knots (time s, chamber air °C) of the piecewise-linear chamber profile.
    fn schedule(&self) -> Vec<(f64, f64)> {
        // (time, temperature) knots of a piecewise-linear profile.
        let mut knots = vec![(0.0, self.set_points_c[0])];
        let mut t = self.hold_s;
        knots.push((t, self.set_points_c[0]));
        for w in self.set_points_c.windows(2) {
            t += (w[1] - w[0]).abs() / self.ramp_c_per_min * 60.0;
            knots.push((t, w[1]));
            t += self.hold_s;
            knots.push((t, w[1]));
        }
        knots
    }

    /// Generates the run as recorded-run CSV text.
    pub fn to_csv(&self) -> String {
        let knots = self.schedule();
        let duration = knots.last().map_or(0.0, |k| k.0);
        let dt = 1.0 / self.sample_rate_hz;
        let mut rng = Pcg64::seed_from_u64(self.seed);
        let unit = Normal::new(0.0, 1.0).expect("unit normal");
        let white_dph = self.arw_deg_per_sqrt_h * 60.0 * self.sample_rate_hz.sqrt();
        let (tau_housing, tau_coil, tau_sensor) = (900.0, 400.0, 20.0);
        let (gm_sigma, gm_tau) = (0.002, 1800.0);
        let earth = EARTH_RATE_DPH * 45f64.to_radians().sin();
        let start = knots[0].1;
        let (mut housing, mut coil, mut sensor, mut gm) = (start, start, start, 0.0);
        let mut out = String::with_capacity((duration * self.sample_rate_hz) as usize * 48);
        out.push_str("# source: trainer simulate (synthetic IFOG chamber run)\n");
        out.push_str(&format!("# sample_rate_hz: {}\n", self.sample_rate_hz));
        out.push_str(&format!(
            "# ramp_c_per_min: {}\n# seed: {}\n",
            self.ramp_c_per_min, self.seed
        ));
        out.push_str("time_s,rate_dph,temp_c,ref_dph\n");
        let n = (duration * self.sample_rate_hz) as usize;
        for i in 0..n {
            let t = i as f64 * dt;
            let air = interpolate(&knots, t);
            housing += dt / tau_housing * (air - housing);
            let coil_rate_c_per_s = (housing - coil) / tau_coil;
            coil += dt * coil_rate_c_per_s;
            sensor += dt / tau_sensor * (coil - sensor);
            gm = gm * (-dt / gm_tau).exp()
                + gm_sigma * (1.0 - (-2.0 * dt / gm_tau).exp()).sqrt() * unit.sample(&mut rng);
            let u = coil - 25.0;
            let static_dph = 0.05 + 0.02 * u + 4e-4 * u * u - 1e-5 * u * u * u;
            let shupe_dph = 0.35 * (1.0 + 0.012 * u) * coil_rate_c_per_s * 60.0;
            let gradient_dph = 0.01 * (housing - coil);
            let rate = earth + static_dph + shupe_dph + gradient_dph + gm + white_dph * unit.sample(&mut rng);
            let reading = sensor + 0.003 * unit.sample(&mut rng);
            let quantised = (reading / TMP117_LSB_C).round() * TMP117_LSB_C;
            out.push_str(&format!("{t:.3},{rate:.5},{quantised:.7},{earth:.5}\n"));
        }
        out
    }
}

fn interpolate(knots: &[(f64, f64)], t: f64) -> f64 {
    for w in knots.windows(2) {
        if t <= w[1].0 {
            let span = w[1].0 - w[0].0;
            return if span <= 0.0 {
                w[1].1
            } else {
                w[0].1 + (w[1].1 - w[0].1) * (t - w[0].0) / span
            };
        }
    }
    knots.last().map_or(0.0, |k| k.1)
}
