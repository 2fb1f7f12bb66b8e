//! Multi-axis IMU runs: up to three fiber coils (x, y, z) in one housing,
//! each with its own bias law and coil thermal constants, written as a
//! multi-axis recorded run (`docs/recorded-run-format.md`, "Multi-axis
//! runs"). Each coil is the single-axis simulator's plant and gyro with
//! parameters of its own ([`axis_params`]); the housing, the electronics
//! and the air are the same for all.

use std::fmt::Write as _;
use std::io::Write;

use rand::SeedableRng;
use rand_pcg::Pcg64;
use rbf_core::axis::Axis;

use super::{ChamberRun, SimParams, gyro, plant};

/// Per axis y and z: factors on the first axis's static coefficients c0 … c3.
const STATIC_FACTORS: [[f64; 4]; 2] = [[-0.7, 1.35, 0.6, 1.4], [1.25, -0.8, 1.5, 0.7]];
/// Per axis y and z: factors on the Shupe gain and its temperature coefficient.
const SHUPE_FACTORS: [[f64; 2]; 2] = [[1.4, 0.5], [0.7, 1.6]];
/// Per axis y and z: factors on the radial-gradient gain.
const RADIAL_FACTORS: [f64; 2] = [-0.8, 1.5];
/// Per axis y and z: factors on the coil's outer and layer time constants.
const COIL_TAU_FACTORS: [[f64; 2]; 2] = [[1.3, 0.8], [0.75, 1.25]];

/// The parameters of `axis`'s coil: x has `base`; y and z have their own
/// static and Shupe coefficients, radial-gradient gain and coil time
/// constants (fixed factors on `base`'s), the same housing, electronics,
/// thermometer lags and noise.
pub fn axis_params(base: &SimParams, axis: Axis) -> SimParams {
    let Some(k) = axis.index().checked_sub(1) else {
        return base.clone();
    };
    let mut p = base.clone();
    for (c, f) in p.gyro.static_coeffs.iter_mut().zip(STATIC_FACTORS[k]) {
        *c *= f;
    }
    p.gyro.shupe_dph_per_c_per_min *= SHUPE_FACTORS[k][0];
    p.gyro.shupe_temp_coeff_per_c *= SHUPE_FACTORS[k][1];
    p.gyro.radial_gradient_dph_per_c *= RADIAL_FACTORS[k];
    p.plant.tau_coil_outer_s *= COIL_TAU_FACTORS[k][0];
    p.plant.tau_coil_layer_s = (p.plant.tau_coil_layer_s * COIL_TAU_FACTORS[k][1]).max(plant::MIN_TAU_S);
    p
}

/// The Earth-rate projection on `axis`, °/h: x horizontal at
/// [`gyro::HEADING_DEG`], y horizontal 90° to its right, z up.
pub fn earth_rate_projection_dph(axis: Axis) -> f64 {
    let lat = gyro::LATITUDE_DEG.to_radians();
    match axis {
        Axis::X => gyro::earth_rate_projection_dph(),
        Axis::Y => gyro::EARTH_RATE_DPH * lat.cos() * (gyro::HEADING_DEG + 90.0).to_radians().cos(),
        Axis::Z => gyro::EARTH_RATE_DPH * lat.sin(),
    }
}

/// One coil of the IMU as it runs.
struct Coil {
    params: SimParams,
    plant: plant::Plant,
    gyro: gyro::Gyro,
    thermometers: plant::Thermometers,
    reference_dph: f64,
}

/// Streams `run` as a multi-axis recorded run of the first `axes` axes
/// (1 … 3): per axis `rate_<axis>_dph`, `temp_<axis>_c` (each coil's loop
/// sensor; with `shared_thermometer` one `temp_c`, the x coil's, serves
/// all) and `ref_<axis>_dph`. The chamber air, seed and metadata are those
/// of the single-axis run; `run.multi` is not used.
pub fn write_axes_csv(
    run: &ChamberRun,
    axes: usize,
    shared_thermometer: bool,
    out: &mut impl Write,
) -> std::io::Result<()> {
    let axes = &Axis::ALL[..axes.clamp(1, Axis::ALL.len())];
    let mut rng = Pcg64::seed_from_u64(run.seed);
    let (schedule, duration_s, params) = run.setup(&mut rng);
    let dt = 1.0 / run.sample_rate_hz;
    let start_c = schedule.air_c(0.0);
    let mut coils: Vec<Coil> = axes
        .iter()
        .map(|&axis| {
            let params = axis_params(&params, axis);
            Coil {
                plant: plant::Plant::soaked(&params.plant, start_c),
                gyro: gyro::Gyro::new(&params.gyro, run.sample_rate_hz, false),
                thermometers: plant::Thermometers::new(start_c),
                reference_dph: earth_rate_projection_dph(axis),
                params,
            }
        })
        .collect();
    run.write_metadata(out, &params, start_c)?;
    let names: Vec<&str> = axes.iter().map(|a| a.name()).collect();
    writeln!(out, "# axes: {}", names.join(", "))?;
    for coil in coils.iter().zip(axes).skip(1) {
        let json = serde_json::to_string(&coil.0.params).map_err(std::io::Error::other)?;
        writeln!(out, "# axis_{}_params: {json}", coil.1.name())?;
    }
    let mut header = String::from("time_s");
    if shared_thermometer {
        header.push_str(",temp_c");
    }
    for a in &names {
        let _ = write!(header, ",rate_{a}_dph");
        if !shared_thermometer {
            let _ = write!(header, ",temp_{a}_c");
        }
        let _ = write!(header, ",ref_{a}_dph");
    }
    writeln!(out, "{header}")?;
    let steps = (duration_s * run.sample_rate_hz).floor() as u64;
    let (substeps, h) = plant::substeps(dt);
    let mut line = String::with_capacity(200);
    for i in 0..steps {
        let t = i as f64 * dt;
        line.clear();
        let _ = write!(line, "{t:.4}");
        for (k, coil) in coils.iter_mut().enumerate() {
            let mut rates = plant::NodeRates::default();
            for s in 0..substeps {
                rates = coil.plant.step(&coil.params.plant, schedule.air_c(t + s as f64 * h), h);
                coil.thermometers.step(&coil.params.plant, &coil.plant, h);
            }
            let rate =
                coil.reference_dph + coil.gyro.bias_dph(&coil.plant, &rates, &mut rng) + coil.gyro.noise_dph(&mut rng);
            let loop_c = coil.thermometers.read(&coil.params.plant, &mut rng)[plant::LOOP_SENSOR];
            match (shared_thermometer, k) {
                (true, 0) => {
                    let _ = write!(line, ",{loop_c:.7},{rate:.5}");
                }
                (true, _) => {
                    let _ = write!(line, ",{rate:.5}");
                }
                (false, _) => {
                    let _ = write!(line, ",{rate:.5},{loop_c:.7}");
                }
            }
            let _ = write!(line, ",{:.5}", coil.reference_dph);
        }
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::Profile;
    use rbf_core::record::Columns;

    fn run_text(axes: usize, shared: bool) -> String {
        let mut run = ChamberRun::with_profile(Profile::Cycle, 4);
        run.duration_s = Some(600.0);
        let mut out = Vec::new();
        write_axes_csv(&run, axes, shared, &mut out).unwrap();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn three_coils_have_their_own_columns_laws_and_references() {
        let text = run_text(3, false);
        let header = text.lines().find(|l| !l.starts_with('#')).unwrap();
        assert_eq!(
            header,
            "time_s,rate_x_dph,temp_x_c,ref_x_dph,rate_y_dph,temp_y_c,ref_y_dph,rate_z_dph,temp_z_c,ref_z_dph"
        );
        let columns = Columns::from_header(header).unwrap();
        assert_eq!(columns.axes_present().count(), 3);
        assert!(text.contains("# axes: x, y, z\n") && text.contains("# axis_z_params: {"));
        let rows: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .skip(1)
            .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 600);
        let last = rows.last().unwrap();
        let refs = [last[3], last[6], last[9]];
        for (a, r) in Axis::ALL.into_iter().zip(refs) {
            assert!((r - earth_rate_projection_dph(a)).abs() < 1e-5, "{a:?}");
        }
        // Own bias laws: the axes' biases differ, more than their noise.
        let bias = |k: usize| last[1 + 3 * k] - refs[k];
        assert!((bias(0) - bias(1)).abs() > 0.01 && (bias(1) - bias(2)).abs() > 0.01);
        // The same seed, the same file; the x coil is the single-axis gyro's.
        assert_eq!(text, run_text(3, false));
        assert_eq!(axis_params(&SimParams::default(), Axis::X), SimParams::default());
        assert!(axis_params(&SimParams::default(), Axis::Y).check().is_ok());
    }

    #[test]
    fn one_thermometer_can_serve_every_axis() {
        let text = run_text(2, true);
        let header = text.lines().find(|l| !l.starts_with('#')).unwrap();
        assert_eq!(header, "time_s,temp_c,rate_x_dph,ref_x_dph,rate_y_dph,ref_y_dph");
        let columns = Columns::from_header(header).unwrap();
        let y = columns.for_axis(Axis::Y).unwrap();
        assert_eq!(
            y.temp_c(),
            Some(1),
            "temp_c serves the axis without its own thermometer"
        );
    }
}
