//! `trainer report`: plots (SVG and PNG) and a written summary of a model on runs.
//!
//! Per run: raw and compensated rate − reference (10-s means) with the loop
//! temperature, and the Allan deviation before/after on log-log axes. For the
//! model: its bias over T and a steady ramp rate ΔT (every ΔT window reads the
//! same rate on a steady ramp). Plus report.json and report.md.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::coord::Shift;
use plotters::prelude::*;
use rbf_core::{FeatureSet, FeatureVector, Model};

use crate::evaluate::{RunEvaluation, compensate_run, evaluate_output};
use crate::output::write_bytes;
use crate::run::Run;

/// Plot size, pixels.
const SIZE: (u32, u32) = (1000, 560);
/// Averaging of the plotted rate, s (keeps days of 100 Hz data drawable).
const PLOT_MEAN_S: f64 = 10.0;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// A plot that can be drawn on any plotters backend.
trait Figure {
    /// Draws the plot onto `root`.
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// Draws `figure` to `stem.svg` and `stem.png`.
fn both(stem: &Path, figure: &impl Figure) -> anyhow::Result<Vec<PathBuf>> {
    let svg = stem.with_extension("svg");
    let png = stem.with_extension("png");
    figure
        .draw(SVGBackend::new(&svg, SIZE).into_drawing_area())
        .map_err(|e| anyhow::anyhow!("{}: {e}", svg.display()))?;
    figure
        .draw(BitMapBackend::new(&png, SIZE).into_drawing_area())
        .map_err(|e| anyhow::anyhow!("{}: {e}", png.display()))?;
    Ok(vec![svg, png])
}

fn block_means(time_s: &[f64], values: &[f64], block_s: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let (mut t0, mut sum_t, mut sum_v, mut n) = (time_s.first().copied().unwrap_or(0.0), 0.0, 0.0, 0.0);
    for (&t, &v) in time_s.iter().zip(values) {
        if t - t0 >= block_s && n > 0.0 {
            out.push((sum_t / n, sum_v / n));
            (t0, sum_t, sum_v, n) = (t, 0.0, 0.0, 0.0);
        }
        sum_t += t;
        sum_v += v;
        n += 1.0;
    }
    if n > 0.0 {
        out.push((sum_t / n, sum_v / n));
    }
    out
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if lo.is_finite() && hi > lo {
        (lo, hi)
    } else {
        (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0)
    }
}

struct RatePlot {
    title: String,
    raw: Vec<(f64, f64)>,
    comp: Vec<(f64, f64)>,
    temp: Vec<(f64, f64)>,
}

impl Figure for RatePlot {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_rate(root, self)
    }
}

struct AllanPlot<'a> {
    title: String,
    evaluation: &'a RunEvaluation,
}

impl Figure for AllanPlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_allan(root, &self.title, self.evaluation)
    }
}

struct SurfacePlot<'a> {
    model: &'a Model,
    /// (T, ΔT₁, bias) along the reported runs, for multi-scale models.
    trajectory: Vec<(f32, f32, f32)>,
}

impl Figure for SurfacePlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        if self.model.features().set.is_multiscale() {
            draw_trajectory(root, &self.trajectory)
        } else {
            draw_surface(root, self.model)
        }
    }
}

/// Blue → green → red for `x` in 0 … 1.
fn colour(x: f64) -> RGBColor {
    let x = x.clamp(0.0, 1.0);
    RGBColor(
        (40.0 + 215.0 * x) as u8,
        (90.0 + 80.0 * (1.0 - (2.0 * x - 1.0).abs())) as u8,
        (230.0 - 200.0 * x) as u8,
    )
}

/// Multi-scale models: a steady ramp (all ΔT windows equal) never occurs in a
/// chamber run, so a (T, ΔT) surface would show extrapolation; plot the bias
/// along the runs' own (T, ΔT₁) trajectory instead.
fn draw_trajectory<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, points: &[(f32, f32, f32)]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (t_lo, t_hi) = range(points.iter().map(|p| p.0 as f64));
    let (r_lo, r_hi) = range(points.iter().map(|p| p.1 as f64));
    let (b_lo, b_hi) = range(points.iter().map(|p| p.2 as f64));
    let caption = format!("model bias along the runs' (T, ΔT₁) path: blue {b_lo:.3} … red {b_hi:.3} °/h");
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t_lo..t_hi, r_lo..r_hi)?;
    chart
        .configure_mesh()
        .x_desc("loop temperature T [°C]")
        .y_desc("ΔT₁ [°C/min]")
        .draw()?;
    chart.draw_series(points.iter().map(|&(t, r, b)| {
        Circle::new(
            (t as f64, r as f64),
            2,
            colour((b as f64 - b_lo) / (b_hi - b_lo)).filled(),
        )
    }))?;
    root.present()?;
    Ok(())
}

fn draw_rate<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &RatePlot) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (t_lo, t_hi) = range(p.raw.iter().map(|v| v.0 / 3600.0));
    let (y_lo, y_hi) = range(p.raw.iter().chain(&p.comp).map(|v| v.1));
    let (c_lo, c_hi) = range(p.temp.iter().map(|v| v.1));
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .right_y_label_area_size(60)
        .build_cartesian_2d(t_lo..t_hi, y_lo..y_hi)?
        .set_secondary_coord(t_lo..t_hi, c_lo..c_hi);
    chart
        .configure_mesh()
        .x_desc("time [h]")
        .y_desc("rate − reference [°/h] (10-s means)")
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_desc("loop temperature [°C]")
        .draw()?;
    let hours = |v: &Vec<(f64, f64)>| v.iter().map(|&(t, y)| (t / 3600.0, y)).collect::<Vec<_>>();
    chart
        .draw_series(LineSeries::new(hours(&p.raw), RGBColor(200, 60, 40)))?
        .label("raw")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(200, 60, 40)));
    chart
        .draw_series(LineSeries::new(hours(&p.comp), RGBColor(30, 90, 200)))?
        .label("compensated")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(30, 90, 200)));
    chart
        .draw_secondary_series(LineSeries::new(hours(&p.temp), RGBColor(120, 120, 120)))?
        .label("loop temperature (right axis)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(120, 120, 120)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn draw_allan<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, title: &str, e: &RunEvaluation) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let pts = |a: &crate::allan::AllanDeviation| {
        a.tau_s
            .iter()
            .zip(&a.adev_dph)
            .filter(|(_, d)| d.is_finite() && **d > 0.0)
            .map(|(&t, &d)| (t, d))
            .collect::<Vec<_>>()
    };
    let (before, after) = (pts(&e.allan_before), pts(&e.allan_after));
    let (t_lo, t_hi) = range(before.iter().map(|p| p.0));
    let (d_lo, d_hi) = range(before.iter().chain(&after).map(|p| p.1));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d((t_lo..t_hi).log_scale(), (d_lo * 0.8..d_hi * 1.25).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("cluster time τ [s]")
        .y_desc("Allan deviation [°/h]")
        .draw()?;
    for (series, label, color) in [
        (&before, "before", RGBColor(200, 60, 40)),
        (&after, "after", RGBColor(30, 90, 200)),
    ] {
        chart
            .draw_series(LineSeries::new(series.iter().copied(), color))?
            .label(format!("{label} compensation"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        chart.draw_series(series.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Bias of `model` at loop temperature `t_c` on a steady ramp of `rate` °C/min.
fn steady_bias(model: &Model, t_c: f32, rate: f32) -> f32 {
    let set = model.features().set;
    let features = FeatureVector::settled(set, t_c, rate).unwrap_or_else(|| {
        // Multi-point: the first two inputs on the axes, the others at the
        // middle of their training range.
        let values: Vec<f32> = (0..set.dims())
            .map(|i| match i {
                0 => t_c,
                1 => rate,
                _ => model.input_range(i).map_or(0.0, |(lo, hi)| 0.5 * (lo + hi)),
            })
            .collect();
        FeatureVector::from_values(&values)
    });
    model.eval(&features).bias_dph
}

fn draw_surface<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, model: &Model) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (t_lo, t_hi) = model.input_range(0).unwrap_or((0.0, 1.0));
    let set = model.features().set;
    let (r_lo, r_hi) = if set.dims() < 2 {
        (-1.0, 1.0)
    } else {
        model.input_range(1).unwrap_or((-1.0, 1.0))
    };
    let multi_point = matches!(set, FeatureSet::MultiPoint(_));
    let axis = |i: usize| set.name(i).map_or_else(String::new, |n| n.to_string());
    let (x_desc, y_desc) = if multi_point {
        (axis(0), axis(1))
    } else {
        ("loop temperature T [°C]".to_owned(), "ΔT [°C/min]".to_owned())
    };
    const N: usize = 60;
    let grid: Vec<(f32, f32, f32)> = (0..N * N)
        .map(|k| {
            let t = t_lo + (t_hi - t_lo) * (k % N) as f32 / (N - 1) as f32;
            let r = r_lo + (r_hi - r_lo) * (k / N) as f32 / (N - 1) as f32;
            (t, r, steady_bias(model, t, r))
        })
        .collect();
    let (b_lo, b_hi) = range(grid.iter().map(|g| g.2 as f64));
    let over = if multi_point {
        "its first two inputs (others mid-range)"
    } else {
        "T and a steady-ramp ΔT"
    };
    let caption = format!("fitted bias over {over}: blue {b_lo:.3} … red {b_hi:.3} °/h");
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t_lo as f64..t_hi as f64, r_lo as f64..r_hi as f64)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .disable_mesh()
        .draw()?;
    let (dt, dr) = (
        (t_hi - t_lo) as f64 / (N - 1) as f64,
        (r_hi - r_lo) as f64 / (N - 1) as f64,
    );
    chart.draw_series(grid.iter().map(|&(t, r, b)| {
        let (t, r) = (t as f64, r as f64);
        let fill = colour((b as f64 - b_lo) / (b_hi - b_lo)).filled();
        Rectangle::new([(t - dt / 2.0, r - dr / 2.0), (t + dt / 2.0, r + dr / 2.0)], fill)
    }))?;
    root.present()?;
    Ok(())
}

/// Writes the report for `model` on `runs` into `dir`; returns the files written.
pub fn write_report(model: &Model, model_path: &Path, runs: &[Run], dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut files = Vec::new();
    let mut evaluations = Vec::new();
    let mut trajectory = Vec::new();
    let mut md = String::from("# Compensation report\n\n");
    md.push_str(&format!("Model: `{}`\n\n", model_path.display()));
    md.push_str("| run | 100-s STD before [°/h] | after [°/h] | improvement | MSD improvement | ARW after [°/√h] | BI before → after [°/h] |\n|---|---|---|---|---|---|---|\n");
    for run in runs {
        let stem = run
            .path
            .file_stem()
            .map_or("run".into(), |s| s.to_string_lossy().into_owned());
        let out = compensate_run(Some(model), run);
        let e = evaluate_output(run, &out);
        let config = run.compensator_config();
        let mut compensator = rbf_core::Compensator::new();
        let stride = (run.len() / 3000).max(1);
        for (i, sample) in run.samples().enumerate() {
            let frame = compensator.features(model.features(), &config, &sample);
            if let Some(f) = frame.features.filter(|_| i % stride == 0) {
                let v = f.as_slice();
                trajectory.push((v[0], v.get(1).copied().unwrap_or(0.0), out[i].bias_dph));
            }
        }
        let reference = run.reference_dph();
        let raw: Vec<f64> = (0..run.len()).map(|i| run.rate_dph[i] - reference.at(i)).collect();
        let comp: Vec<f64> = (0..run.len())
            .map(|i| out[i].rate_comp_dph as f64 - reference.at(i))
            .collect();
        let temp: Vec<f64> = run.temp_c.iter().map(|t| t.unwrap_or(f64::NAN)).collect();
        let plot = RatePlot {
            title: format!("{stem}: rate before and after compensation"),
            raw: block_means(&run.time_s, &raw, PLOT_MEAN_S),
            comp: block_means(&run.time_s, &comp, PLOT_MEAN_S),
            temp: block_means(&run.time_s, &temp, PLOT_MEAN_S),
        };
        files.extend(both(&dir.join(format!("{stem}_rate")), &plot)?);
        let allan = AllanPlot {
            title: format!("{stem}: overlapping Allan deviation"),
            evaluation: &e,
        };
        files.extend(both(&dir.join(format!("{stem}_allan")), &allan)?);
        md.push_str(&format!(
            "| {stem} | {:.4} | {:.4} | {:.1} % | {:.1} % | {:.2e} | {:.2e} → {:.2e} |\n",
            e.cluster_std_before_dph,
            e.cluster_std_after_dph,
            e.cluster_std_improvement_pct,
            e.msd_improvement_pct,
            e.allan_after.arw_deg_per_sqrt_h,
            e.allan_before.bias_instability_dph,
            e.allan_after.bias_instability_dph
        ));
        evaluations.push(e);
    }
    files.extend(both(&dir.join("bias_surface"), &SurfacePlot { model, trajectory })?);
    md.push_str("\n## Plots\n\n![bias surface](bias_surface.svg)\n\n");
    for run in runs {
        let stem = run
            .path
            .file_stem()
            .map_or("run".into(), |s| s.to_string_lossy().into_owned());
        md.push_str(&format!(
            "### {stem}\n\n![rate]({stem}_rate.svg)\n\n![Allan deviation]({stem}_allan.svg)\n\n"
        ));
    }
    let json = dir.join("report.json");
    write_bytes(
        &json,
        serde_json::to_string_pretty(
            &serde_json::json!({"model": model_path.display().to_string(), "runs": evaluations}),
        )?
        .as_bytes(),
    )?;
    let md_path = dir.join("report.md");
    let mut f = std::fs::File::create(&md_path).with_context(|| format!("{}: cannot create", md_path.display()))?;
    f.write_all(md.as_bytes())?;
    files.push(json);
    files.push(md_path);
    Ok(files)
}
