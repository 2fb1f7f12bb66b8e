//! `trainer report`: plots (SVG and PNG) and a written summary of a model on runs.
//!
//! Per run: raw and compensated rate − reference (10-s means) with the loop
//! temperature; the measured bias (10-s means) against the loop temperature,
//! coloured by ramp direction, with the model overlaid, and the residual
//! against temperature; the Allan deviation before/after on log-log axes with
//! shaded ±1-σ confidence bands. For the model, with a colour bar: a lag bank's
//! or multi-scale model's bias along the runs' path over its own inputs; any
//! other model's over the loop temperature T and a steady ramp rate ΔT (every
//! ΔT window reads the same rate on a steady ramp), greyed where no training
//! sample lay (no sample of the reported runs, when the training runs are not
//! known). Plus report.json and report.md (the model, and per run its figures
//! and how many samples were clamped).

use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::coord::Shift;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::prelude::*;
use rbf_core::{FeatureSet, FeatureVector, Model};

use crate::evaluation::diagnose::RunDiagnosis;
use crate::evaluation::evaluate::{Evaluator, RunEvaluation, figure, require_compensated, require_evaluable};
use crate::output::{self, DirTarget, Existing, StagedDir};
use crate::plotting::axes::{
    TICK_LABEL_PX, drawable, light_lines_of, linear_tick_labels, log_tick_labels, log_ticks, padded, padded_log,
    tick_label, title_font_px, with_legend_room, with_legend_room_log, y_label_area_px,
};
use crate::reading::run::{RunReader, StreamedRun};
use crate::{describe::summary, reading::input, text};
use rbf_core::axis::Axis;

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

/// `figure` drawn as SVG text and as PNG bytes.
fn render(figure: &impl Figure) -> anyhow::Result<(String, Vec<u8>)> {
    let mut svg = String::new();
    figure
        .draw(SVGBackend::with_string(&mut svg, SIZE).into_drawing_area())
        .map_err(|e| anyhow::anyhow!("drawing the SVG: {e}"))?;
    let mut rgb = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
    figure
        .draw(BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area())
        .map_err(|e| anyhow::anyhow!("drawing the PNG: {e}"))?;
    Ok((svg, crate::plotting::png::encode_png(&rgb, SIZE)?))
}

/// Running means over consecutive blocks of `block_s` seconds (a block
/// starts with the first sample at least `block_s` after the previous
/// block's first): (mean time, mean value) per block.
#[derive(Clone, Debug, Default)]
struct BlockMeans {
    block_s: f64,
    t0: Option<f64>,
    sum_t: f64,
    sum_v: f64,
    n: f64,
    out: Vec<(f64, f64)>,
}

impl BlockMeans {
    fn new(block_s: f64) -> Self {
        BlockMeans {
            block_s,
            ..BlockMeans::default()
        }
    }

    fn push(&mut self, t: f64, v: f64) {
        let t0 = *self.t0.get_or_insert(t);
        if t - t0 >= self.block_s && self.n > 0.0 {
            self.out.push((self.sum_t / self.n, self.sum_v / self.n));
            (self.t0, self.sum_t, self.sum_v, self.n) = (Some(t), 0.0, 0.0, 0.0);
        }
        self.sum_t += t;
        self.sum_v += v;
        self.n += 1.0;
    }

    fn finish(mut self) -> Vec<(f64, f64)> {
        if self.n > 0.0 {
            self.out.push((self.sum_t / self.n, self.sum_v / self.n));
        }
        self.out
    }
}

/// The height of the plotting area of a chart on `area`, px: the area less
/// the label areas and captions below and above it (`reserved_px`) and the margins.
fn plot_height_px<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, reserved_px: u32) -> u32 {
    area.dim_in_pixel().1.saturating_sub(reserved_px + 24).max(1)
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
    /// What the rates are taken from: `ref_dph`, or each trace's own mean.
    y_desc: &'static str,
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

/// Below this |dT/dt|, °C/min, the loop temperature counts as steady.
const STEADY_C_PER_MIN: f64 = 0.05;

/// Which way the loop temperature is moving at a plotted point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ramp {
    Heating,
    Cooling,
    Steady,
}

impl Ramp {
    /// The direction of `rate_c_per_min`.
    fn of(rate_c_per_min: f64) -> Ramp {
        if rate_c_per_min > STEADY_C_PER_MIN {
            Ramp::Heating
        } else if rate_c_per_min < -STEADY_C_PER_MIN {
            Ramp::Cooling
        } else {
            Ramp::Steady
        }
    }

    fn colour(self) -> RGBColor {
        match self {
            Ramp::Heating => RGBColor(210, 60, 40),
            Ramp::Cooling => RGBColor(30, 90, 210),
            Ramp::Steady => RGBColor(150, 150, 150),
        }
    }

    fn label(self) -> &'static str {
        match self {
            Ramp::Heating => "measured, heating",
            Ramp::Cooling => "measured, cooling",
            Ramp::Steady => "measured, steady",
        }
    }
}

/// One 10-s mean of a run: loop temperature, measured bias (rate − reference),
/// the model's bias, the residual after compensation, and the ramp direction.
#[derive(Clone, Copy, Debug, PartialEq)]
struct BiasPoint {
    temp_c: f64,
    measured_dph: f64,
    model_dph: f64,
    residual_dph: f64,
    ramp: Ramp,
}

/// The points of the bias-against-temperature plot from aligned 10-s means
/// (`temp`, `raw`, `model`, `comp`: (time s, value)); the ramp direction from
/// the temperature's central difference.
fn bias_points(temp: &[(f64, f64)], raw: &[(f64, f64)], model: &[(f64, f64)], comp: &[(f64, f64)]) -> Vec<BiasPoint> {
    let n = temp.len().min(raw.len()).min(model.len()).min(comp.len());
    (0..n)
        .filter(|&i| temp[i].1.is_finite() && raw[i].1.is_finite())
        .map(|i| {
            let (a, b) = (temp[i.saturating_sub(1)], temp[(i + 1).min(n - 1)]);
            let rate_c_per_min = if b.0 > a.0 {
                (b.1 - a.1) / (b.0 - a.0) * 60.0
            } else {
                0.0
            };
            BiasPoint {
                temp_c: temp[i].1,
                measured_dph: raw[i].1,
                model_dph: model[i].1,
                residual_dph: comp[i].1,
                ramp: Ramp::of(rate_c_per_min),
            }
        })
        .collect()
}

/// Measured bias against loop temperature, coloured by ramp direction, with
/// the model overlaid (top), and the residual after compensation (bottom).
struct BiasTempPlot {
    title: String,
    points: Vec<BiasPoint>,
}

impl Figure for BiasTempPlot {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_bias_temp(root, self)
    }
}

fn draw_bias_temp<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &BiasTempPlot) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let root = root.titled(&p.title, ("sans-serif", title_font_px(&root, &p.title)))?;
    let (top, bottom) = root.split_vertically((SIZE.1 as f64 * 0.58) as u32);
    let (t_lo, t_hi) = range(p.points.iter().map(|q| q.temp_c));
    let (t_lo, t_hi) = padded(t_lo, t_hi);
    let (y_lo, y_hi) = range(p.points.iter().flat_map(|q| [q.measured_dph, q.model_dph]));
    let (y_lo, y_hi) = with_legend_room(y_lo, y_hi, 4, plot_height_px(&top, 30));
    let (r_lo, r_hi) = range(p.points.iter().map(|q| q.residual_dph));
    let (r_lo, r_hi) = padded(r_lo, r_hi);
    // One width for both panels, so that their temperature axes line up.
    let labels = linear_tick_labels(y_lo, y_hi)
        .into_iter()
        .chain(linear_tick_labels(r_lo, r_hi));
    let y_label_px = y_label_area_px(&root, labels, TICK_LABEL_PX, 80);
    let mut chart = ChartBuilder::on(&top)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(y_label_px)
        .build_cartesian_2d(t_lo..t_hi, y_lo..y_hi)?;
    let (x_light, y_light) = light_lines_of(chart.plotting_area());
    chart
        .configure_mesh()
        .x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .y_desc("bias [°/h] (10-s means)")
        .draw()?;
    for ramp in [Ramp::Steady, Ramp::Cooling, Ramp::Heating] {
        let colour = ramp.colour();
        chart
            .draw_series(
                p.points
                    .iter()
                    .filter(|q| q.ramp == ramp)
                    .map(|q| Circle::new((q.temp_c, q.measured_dph), 2, colour.filled())),
            )?
            .label(ramp.label())
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, colour.filled()));
    }
    chart
        .draw_series(
            p.points
                .iter()
                .map(|q| Circle::new((q.temp_c, q.model_dph), 1, BLACK.filled())),
        )?
        .label("model")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    let mut residual = ChartBuilder::on(&bottom)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(y_label_px)
        .build_cartesian_2d(t_lo..t_hi, r_lo..r_hi)?;
    let (x_light, y_light) = light_lines_of(residual.plotting_area());
    residual
        .configure_mesh()
        .x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc("loop temperature T [°C]")
        .y_desc("residual [°/h]")
        .draw()?;
    for ramp in [Ramp::Steady, Ramp::Cooling, Ramp::Heating] {
        let colour = ramp.colour();
        residual.draw_series(
            p.points
                .iter()
                .filter(|q| q.ramp == ramp)
                .map(|q| Circle::new((q.temp_c, q.residual_dph), 2, colour.filled())),
        )?;
    }
    root.present()?;
    Ok(())
}

struct AllanPlot<'a> {
    title: String,
    evaluation: &'a RunEvaluation,
    /// Length of the run, s (the confidence bands' T).
    duration_s: f64,
}

impl Figure for AllanPlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_allan(root, &self.title, self.evaluation, self.duration_s)
    }
}

struct SurfacePlot<'a> {
    model: &'a Model,
    /// Per sample, the plot's two coordinates and the model's bias
    /// ([`SurfaceCoordinates`]): of every reported run on a path plot, of
    /// the training runs on a box surface when they are known.
    trajectory: Vec<(f32, f32, f32)>,
    /// Whether `trajectory` holds the training runs' samples alone.
    training_only: bool,
}

impl<'a> SurfacePlot<'a> {
    /// The bias plot of `model` from the reported runs' `points` (sample
    /// index, point); those before `trained_end_index` are the training
    /// runs'.
    fn new(model: &'a Model, points: Vec<(usize, (f32, f32, f32))>, trained_end_index: Option<usize>) -> Self {
        let training_only = trained_end_index
            .is_some_and(|end| !drawn_along_the_path(model.features().set) && points.iter().any(|(i, _)| *i < end));
        let end = trained_end_index.filter(|_| training_only).unwrap_or(usize::MAX);
        SurfacePlot {
            model,
            trajectory: points.into_iter().filter(|(i, _)| *i < end).map(|(_, p)| p).collect(),
            training_only,
        }
    }
}

impl Figure for SurfacePlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let set = self.model.features().set;
        // Where the runs went, not a box whose corners (fast rates at the
        // extremes of temperature) no run reached: there the model only extrapolates.
        if drawn_along_the_path(set) {
            let axis = |i: usize| set.name(i).map_or_else(String::new, |n| n.to_string());
            let x_desc = match set {
                FeatureSet::LagBank(_) => format!("mean coil temperature {}", axis(0)),
                _ => axis(0),
            };
            let rate_input = surface_rate_input(set).unwrap_or(1);
            let (t, r) = (
                self.model.input_range(0).unwrap_or((0.0, 0.0)),
                surface_rate_range(self.model).unwrap_or((-1.0, 1.0)),
            );
            let training = ((f64::from(t.0), f64::from(t.1)), (f64::from(r.0), f64::from(r.1)));
            draw_trajectory(root, &self.trajectory, training, &x_desc, &axis(rate_input))
        } else {
            draw_surface(root, self.model, &self.trajectory, self.training_only)
        }
    }
}

/// Whether the bias plot of a model of `set` follows the runs' path over
/// its own inputs (multi-scale models and lag banks: a steady ramp, all
/// filters equal, never occurs in a run) rather than filling a box.
fn drawn_along_the_path(set: FeatureSet) -> bool {
    set.is_multiscale() || matches!(set, FeatureSet::LagBank(_))
}

/// The ΔT window of the bias surface of a model without a ΔT input of its
/// own (a cubic in T, the response bank), s.
const SURFACE_RATE_WINDOW_S: f32 = 60.0;

/// What a bias plot's point is made of, per sample: input 0 and input
/// `rate_input` of `features`, computed by `extractor`. Those are the
/// model's own inputs on path plots and multi-point surfaces; on the other
/// surfaces (over T and a steady-ramp ΔT, whatever the model's inputs: a
/// response bank's are T − T₀ and its powers, a cubic in T has no rate) the
/// loop temperature and its rate.
struct SurfaceCoordinates {
    features: rbf_core::FeatureConfig,
    rate_input: Option<usize>,
    extractor: rbf_core::Compensator,
}

/// The ΔT window of `model`'s bias surface over T and ΔT, s: its own for a
/// model with a ΔT input, so that the plotted points are its inputs.
fn surface_rate_window_s(model: &Model) -> f32 {
    let features = model.features();
    if surface_rate_input(features.set).is_some() && features.rate_window_s > 0.0 {
        features.rate_window_s
    } else {
        SURFACE_RATE_WINDOW_S
    }
}

impl SurfaceCoordinates {
    /// The coordinates of `model`'s bias plot.
    fn of(model: &Model) -> Self {
        let set = model.features().set;
        let (features, rate_input) = if drawn_along_the_path(set) || matches!(set, FeatureSet::MultiPoint(_)) {
            (*model.features(), surface_rate_input(set))
        } else {
            let rate = rbf_core::FeatureConfig::single(FeatureSet::TempRate, surface_rate_window_s(model));
            (rate, Some(1))
        };
        SurfaceCoordinates {
            features,
            rate_input,
            extractor: rbf_core::Compensator::new(),
        }
    }

    /// The point of `sample` (`config`: the run's); `None` while the
    /// filters warm up.
    fn point(&mut self, config: &rbf_core::CompensatorConfig, sample: &rbf_core::GyroSample) -> Option<(f32, f32)> {
        let inputs = self.extractor.features(&self.features, config, sample).features?;
        let v = inputs.as_slice();
        Some((v[0], self.rate_input.and_then(|i| v.get(i).copied()).unwrap_or(0.0)))
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

/// Width of the colour bar beside a plot whose colour carries a value, pixels.
const COLOUR_BAR_PX: u32 = 120;
/// Font size of the colour bar's tick labels, px.
const BAR_LABEL_PX: f64 = 13.0;

/// Splits `root` into the plot's area and the colour bar's, draws the bar
/// (the [`colour`] scale from `lo` at the bottom to `hi` at the top, with an
/// axis labelled `label`) and returns the plot's area.
fn with_colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    lo: f64,
    hi: f64,
    label: &str,
) -> Result<DrawingArea<DB, Shift>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let width = root.dim_in_pixel().0;
    let (plot, bar) = root.split_horizontally(width.saturating_sub(COLOUR_BAR_PX));
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo - 0.5, lo + 0.5) };
    let mut chart = ChartBuilder::on(&bar)
        .margin_top(46)
        .margin_bottom(52)
        .margin_right(8)
        .y_label_area_size(y_label_area_px(&bar, linear_tick_labels(lo, hi), BAR_LABEL_PX, 70))
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_x_axis()
        .disable_mesh()
        .y_desc(label)
        .label_style(("sans-serif", BAR_LABEL_PX))
        .axis_desc_style(("sans-serif", 14))
        .y_label_formatter(&tick_label)
        .draw()?;
    const STEPS: usize = 100;
    let step = (hi - lo) / STEPS as f64;
    chart.draw_series((0..STEPS).map(|k| {
        let from = lo + step * k as f64;
        Rectangle::new(
            [(0.0, from), (1.0, from + step)],
            colour((k as f64 + 0.5) / STEPS as f64).filled(),
        )
    }))?;
    Ok(plot)
}

/// Multi-scale models and lag banks: a steady ramp (all ΔT windows equal)
/// never occurs in a chamber run, and the corners of the inputs' box are
/// never reached, so a surface would show extrapolation; plot the bias along
/// the runs' own trajectory (`x_desc`, `y_desc`: its inputs) instead.
fn draw_trajectory<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    points: &[(f32, f32, f32)],
    training: ((f64, f64), (f64, f64)),
    x_desc: &str,
    y_desc: &str,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (t_lo, t_hi) = range(points.iter().map(|p| p.0 as f64));
    let (t_lo, t_hi) = padded(t_lo, t_hi);
    let (r_lo, r_hi) = range(points.iter().map(|p| p.1 as f64));
    let (r_lo, r_hi) = padded(r_lo, r_hi);
    let ((tt_lo, tt_hi), (tr_lo, tr_hi)) = training;
    // Within the training range by a rounding's width (f32 inputs, f32 range).
    let trained = |t: f64, r: f64| {
        let slack = |lo: f64, hi: f64| 1e-4 * (hi - lo).abs().max(1e-3);
        t >= tt_lo - slack(tt_lo, tt_hi)
            && t <= tt_hi + slack(tt_lo, tt_hi)
            && r >= tr_lo - slack(tr_lo, tr_hi)
            && r <= tr_hi + slack(tr_lo, tr_hi)
    };
    let inside = |p: &&(f32, f32, f32)| trained(p.0 as f64, p.1 as f64);
    // The colours span the bias where the model was trained, not where it is held at an edge.
    let (b_lo, b_hi) = if points.iter().any(|p| inside(&p)) {
        range(points.iter().filter(inside).map(|p| p.2 as f64))
    } else {
        range(points.iter().map(|p| p.2 as f64))
    };
    let (t_lo, t_hi) = (t_lo.min(tt_lo), t_hi.max(tt_hi));
    let (r_lo, r_hi) = (r_lo.min(tr_lo), r_hi.max(tr_hi));
    let caption = "model bias where the runs went; dashed: training range, grey: outside it".to_owned();
    let plot = with_colour_bar(&root, b_lo, b_hi, "model bias [°/h]")?;
    let mut chart = ChartBuilder::on(&plot)
        .caption(&caption, ("sans-serif", title_font_px(&plot, &caption)))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_area_px(
            &plot,
            linear_tick_labels(r_lo, r_hi),
            TICK_LABEL_PX,
            70,
        ))
        .build_cartesian_2d(t_lo..t_hi, r_lo..r_hi)?;
    let (x_light, y_light) = light_lines_of(chart.plotting_area());
    chart
        .configure_mesh()
        .x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc(drawable(x_desc))
        .y_desc(drawable(y_desc))
        .draw()?;
    chart.draw_series(points.iter().map(|&(t, r, b)| {
        let (t, r) = (t as f64, r as f64);
        let style = if trained(t, r) {
            colour((b as f64 - b_lo) / (b_hi - b_lo)).filled()
        } else {
            OUTSIDE_TRAINING.filled()
        };
        Circle::new((t, r), 2, style)
    }))?;
    chart.draw_series(DashedLineSeries::new(
        [
            (tt_lo, tr_lo),
            (tt_hi, tr_lo),
            (tt_hi, tr_hi),
            (tt_lo, tr_hi),
            (tt_lo, tr_lo),
        ],
        6,
        4,
        BLACK.stroke_width(1),
    ))?;
    root.present()?;
    Ok(())
}

fn draw_rate<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &RatePlot) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (t_lo, t_hi) = range(p.raw.iter().map(|v| v.0 / 3600.0));
    let (t_lo, t_hi) = padded(t_lo, t_hi);
    let plot_px = plot_height_px(&root, 40 + 30);
    let (y_lo, y_hi) = range(p.raw.iter().chain(&p.comp).map(|v| v.1));
    let (y_lo, y_hi) = with_legend_room(y_lo, y_hi, 3, plot_px);
    let (c_lo, c_hi) = range(p.temp.iter().map(|v| v.1));
    let (c_lo, c_hi) = with_legend_room(c_lo, c_hi, 3, plot_px);
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", title_font_px(&root, &p.title)))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_area_px(
            &root,
            linear_tick_labels(y_lo, y_hi),
            TICK_LABEL_PX,
            70,
        ))
        .right_y_label_area_size(y_label_area_px(
            &root,
            linear_tick_labels(c_lo, c_hi),
            TICK_LABEL_PX,
            60,
        ))
        .build_cartesian_2d(t_lo..t_hi, y_lo..y_hi)?
        .set_secondary_coord(t_lo..t_hi, c_lo..c_hi);
    let (x_light, y_light) = light_lines_of(chart.plotting_area());
    chart
        .configure_mesh()
        .x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc("time [h]")
        .y_desc(p.y_desc)
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_label_formatter(&tick_label)
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
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The ±1-σ band (τ, lower, upper) of an Allan curve, per
/// [`crate::evaluation::allan::relative_error`]; the lower edge kept above zero for log axes.
fn allan_band(points: &[(f64, f64)], duration_s: f64) -> Vec<(f64, f64, f64)> {
    points
        .iter()
        .map(|&(t, d)| {
            let e = crate::evaluation::allan::relative_error(t, duration_s).min(0.95);
            (t, d * (1.0 - e), d * (1.0 + e))
        })
        .collect()
}

/// A logarithmic axis over `lo` … `hi` with the ticks of [`log_ticks`].
fn log_axis(lo: f64, hi: f64) -> WithKeyPoints<LogCoord<f64>> {
    let (labelled, grid) = log_ticks(lo, hi);
    LogCoord::from((lo..hi).log_scale())
        .with_key_points(labelled)
        .with_light_points(grid)
}

fn draw_allan<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    e: &RunEvaluation,
    duration_s: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let pts = |a: &crate::evaluation::allan::AllanDeviation| {
        a.tau_s
            .iter()
            .zip(&a.adev_dph)
            .filter(|(_, d)| d.is_finite() && **d > 0.0)
            .map(|(&t, &d)| (t, d))
            .collect::<Vec<_>>()
    };
    let (before, after) = (pts(&e.allan_before), pts(&e.allan_after));
    let bands = [allan_band(&before, duration_s), allan_band(&after, duration_s)];
    let (t_lo, t_hi) = range(before.iter().map(|p| p.0));
    let (t_lo, t_hi) = padded_log(t_lo, t_hi);
    let (d_lo, d_hi) = range(before.iter().chain(&after).map(|p| p.1));
    let (d_lo, d_hi) = (
        bands.iter().flatten().map(|b| b.1).fold(d_lo, f64::min),
        bands.iter().flatten().map(|b| b.2).fold(d_hi, f64::max),
    );
    // Two curves with their bands, and up to three read-off lines.
    let (d_lo, d_hi) = with_legend_room_log(d_lo, d_hi, 7, plot_height_px(&root, 40 + 34));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", title_font_px(&root, title)))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_area_px(&root, log_tick_labels(d_lo, d_hi), TICK_LABEL_PX, 80))
        .build_cartesian_2d(log_axis(t_lo, t_hi), log_axis(d_lo, d_hi))?;
    chart
        .configure_mesh()
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc("cluster time τ [s]")
        .y_desc("Allan deviation [°/h]")
        .draw()?;
    for (series, band, label, color) in [
        (&before, &bands[0], "before", RGBColor(200, 60, 40)),
        (&after, &bands[1], "after", RGBColor(30, 90, 200)),
    ] {
        // The ±1-σ confidence band as a shaded area: the upper edge left to
        // right, the lower edge back.
        let outline: Vec<(f64, f64)> = band
            .iter()
            .map(|b| (b.0, b.2))
            .chain(band.iter().rev().map(|b| (b.0, b.1)))
            .collect();
        if outline.len() >= 4 {
            chart
                .draw_series(std::iter::once(Polygon::new(outline, color.mix(0.18).filled())))?
                .label(format!("{label}: ±1σ band, 1/√(2(T/τ−1)) (IEEE 952)"))
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], color.mix(0.18).filled()));
        }
        chart
            .draw_series(LineSeries::new(series.iter().copied(), color))?
            .label(format!("{label} compensation"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        chart.draw_series(series.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
    }
    // Read-offs of the compensated curve: the τ^−½ line of its angle random
    // walk, the floor that gives its bias instability, a τ^+½ guide through
    // its last point (rate random walk or a residual ramp rises that way).
    let a = &e.allan_after;
    let guide = RGBColor(90, 90, 90);
    let in_box = |d: f64| d.is_finite() && d >= d_lo && d <= d_hi;
    let taus = |from: f64, to: f64| (0..=40).map(move |k| from * (to / from).powf(f64::from(k) / 40.0));
    if a.arw_deg_per_sqrt_h.is_finite() && a.arw_deg_per_sqrt_h > 0.0 {
        let arw = a.arw_deg_per_sqrt_h;
        let line: Vec<(f64, f64)> = taus(t_lo, t_hi)
            .map(|t| (t, arw / (t / 3600.0).sqrt()))
            .filter(|p| in_box(p.1))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(line, 6, 4, guide.into()))?
            .label(format!("τ^−½: ARW {arw:.2e} °/√h"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], guide));
    }
    let floor = a.bias_instability_dph * crate::evaluation::allan::FLICKER_FLOOR;
    if floor.is_finite() && floor > 0.0 {
        let orange = RGBColor(230, 140, 20);
        chart
            .draw_series(DashedLineSeries::new(
                [(t_lo, floor), (t_hi, floor)],
                3,
                3,
                orange.into(),
            ))?
            .label(if a.floor_reached {
                format!(
                    "floor at τ {:.0} s (≤ T/10): bias instability {:.2e} °/h ±{:.0} %",
                    a.floor_tau_s, a.bias_instability_dph, a.floor_uncertainty_pct
                )
            } else {
                format!(
                    "no floor by τ {:.0} s (T/10): bias instability ≤ {:.2e} °/h",
                    a.confident_tau_max_s, a.bias_instability_dph
                )
            })
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], orange));
    }
    if let Some(&(t_last, d_last)) = after.last() {
        let line: Vec<(f64, f64)> = taus(t_last / 16.0, t_last)
            .map(|t| (t, d_last * (t / t_last).sqrt()))
            .filter(|p| in_box(p.1))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(line, 2, 4, guide.into()))?
            .label("τ^+½ guide")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], guide));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
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

/// The model input on the bias plot's second axis, a rate: the fastest
/// (input 1 of the paper and multi-scale sets; the first after the static
/// powers of T̂ in the lag bank); a multi-point set's input 1. `None` for a
/// model with no rate among its inputs (a cubic in T; the response bank,
/// whose inputs are T − T₀, its powers and mixtures of filtered rates).
fn surface_rate_input(set: FeatureSet) -> Option<usize> {
    let input = match set {
        FeatureSet::LagBank(bank) => bank.static_inputs(),
        FeatureSet::Temp | FeatureSet::ResponseBank(_) => return None,
        _ => 1,
    };
    (input < set.dims()).then_some(input)
}

/// The training range of [`surface_rate_input`], °C/min (multi-point:
/// input 1's units).
fn surface_rate_range(model: &Model) -> Option<(f32, f32)> {
    model.input_range(surface_rate_input(model.features().set)?)
}

/// The loop temperature range a model was trained over, °C: its input 0,
/// or a response bank's covered range (its input 0 is T − T₀).
fn loop_temperature_range(model: &Model) -> (f32, f32) {
    match model.features().set {
        FeatureSet::ResponseBank(bank) => (bank.range_min_c, bank.range_max_c),
        _ => model.input_range(0).unwrap_or((0.0, 1.0)),
    }
}

/// Grey of what lies outside the training data on the bias plots.
const OUTSIDE_TRAINING: RGBColor = RGBColor(170, 170, 170);
/// Fill of the bias surface's cells that no sample reached (hatched in
/// [`OUTSIDE_TRAINING`] over it): no colour, so none reads as a bias.
const MASKED: RGBColor = RGBColor(232, 232, 232);

/// Which cells of an `n` × `n` grid over `t` × `r` some sample of `points`
/// (x, y) lies in or next to, row-major from (t.0, r.0).
fn reached_cells(points: &[(f32, f32, f32)], t: (f32, f32), r: (f32, f32), n: usize) -> Vec<bool> {
    let cell = |v: f32, (lo, hi): (f32, f32)| {
        let x = ((v - lo) / (hi - lo) * (n - 1) as f32).round();
        (x >= -1.0 && x <= n as f32).then_some(x as i64)
    };
    let mut hit = vec![false; n * n];
    for p in points {
        let (Some(i), Some(j)) = (cell(p.0, t), cell(p.1, r)) else {
            continue;
        };
        for jj in j - 1..=j + 1 {
            for ii in i - 1..=i + 1 {
                if (0..n as i64).contains(&ii) && (0..n as i64).contains(&jj) {
                    hit[jj as usize * n + ii as usize] = true;
                }
            }
        }
    }
    hit
}

fn draw_surface<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    model: &Model,
    trajectory: &[(f32, f32, f32)],
    training_only: bool,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let set = model.features().set;
    let multi_point = matches!(set, FeatureSet::MultiPoint(_));
    let (t_lo, t_hi) = if multi_point {
        model.input_range(0).unwrap_or((0.0, 1.0))
    } else {
        loop_temperature_range(model)
    };
    // A model without a rate input: the rates the runs went through.
    let (r_lo, r_hi) = surface_rate_range(model).unwrap_or_else(|| {
        let (lo, hi) = range(trajectory.iter().map(|p| f64::from(p.1)));
        (lo as f32, hi as f32)
    });
    let axis = |i: usize| set.name(i).map_or_else(String::new, |n| n.to_string());
    let no_rate_input = surface_rate_input(set).is_none() && !matches!(set, FeatureSet::ResponseBank(_));
    let (x_desc, y_desc) = if multi_point {
        (axis(0), axis(1))
    } else {
        let rate = format!("ΔT (τ {} s) [°C/min]", surface_rate_window_s(model));
        (
            "loop temperature T [°C]".to_owned(),
            if no_rate_input {
                format!("{rate}, not a model input")
            } else {
                rate
            },
        )
    };
    const N: usize = 60;
    let grid: Vec<(f32, f32, f32)> = (0..N * N)
        .map(|k| {
            let t = t_lo + (t_hi - t_lo) * (k % N) as f32 / (N - 1) as f32;
            let r = r_lo + (r_hi - r_lo) * (k / N) as f32 / (N - 1) as f32;
            (t, r, steady_bias(model, t, r))
        })
        .collect();
    let reached = reached_cells(trajectory, (t_lo, t_hi), (r_lo, r_hi), N);
    // The colours span the bias where the runs went; elsewhere in the box the
    // model extrapolates between edges that no sample joined.
    let (b_lo, b_hi) = if reached.contains(&true) {
        range(grid.iter().zip(&reached).filter(|g| *g.1).map(|g| g.0.2 as f64))
    } else {
        range(grid.iter().map(|g| g.2 as f64))
    };
    let over = if multi_point {
        "its first two inputs (others mid-range)"
    } else if no_rate_input {
        "T"
    } else {
        "T and a steady-ramp ΔT"
    };
    let unsampled = if training_only {
        "no training sample"
    } else {
        "no sample of these runs"
    };
    let caption = format!("fitted bias over {over}; grey, hatched: {unsampled}");
    let plot = with_colour_bar(&root, b_lo, b_hi, "fitted bias [°/h]")?;
    // The cells reach half a cell past the box; the margins keep them off the frame.
    let (x_lo, x_hi) = padded(t_lo as f64, t_hi as f64);
    let (y_lo, y_hi) = padded(r_lo as f64, r_hi as f64);
    let mut chart = ChartBuilder::on(&plot)
        .caption(&caption, ("sans-serif", title_font_px(&plot, &caption)))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_area_px(
            &plot,
            linear_tick_labels(y_lo, y_hi),
            TICK_LABEL_PX,
            70,
        ))
        .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
    chart
        .configure_mesh()
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc(drawable(&x_desc))
        .y_desc(drawable(&y_desc))
        .disable_mesh()
        .draw()?;
    let (dt, dr) = (
        (t_hi - t_lo) as f64 / (N - 1) as f64,
        (r_hi - r_lo) as f64 / (N - 1) as f64,
    );
    chart.draw_series(grid.iter().zip(&reached).map(|(&(t, r, b), &reached)| {
        let (t, r) = (t as f64, r as f64);
        let fill = if reached {
            colour((b as f64 - b_lo) / (b_hi - b_lo)).filled()
        } else {
            MASKED.filled()
        };
        Rectangle::new([(t - dt / 2.0, r - dr / 2.0), (t + dt / 2.0, r + dr / 2.0)], fill)
    }))?;
    // Hatching over the cells no sample reached: one diagonal per cell.
    chart.draw_series(grid.iter().zip(&reached).filter(|g| !*g.1).map(|(&(t, r, _), _)| {
        let (t, r) = (t as f64, r as f64);
        PathElement::new(
            [(t - dt / 2.0, r - dr / 2.0), (t + dt / 2.0, r + dr / 2.0)],
            OUTSIDE_TRAINING.stroke_width(1),
        )
    }))?;
    root.present()?;
    Ok(())
}

/// Points of the bias trajectory kept per report (between this and twice it).
const TRAJECTORY_POINTS: usize = 3000;

/// Every `stride`-th sample's (T, ΔT₁, bias), the stride doubling whenever
/// twice [`TRAJECTORY_POINTS`] are held: bounded whatever the run's length.
#[derive(Debug)]
struct Trajectory {
    stride: usize,
    points: Vec<(usize, (f32, f32, f32))>,
}

impl Trajectory {
    fn new() -> Self {
        Trajectory {
            stride: 1,
            points: Vec::new(),
        }
    }

    /// Takes the point of sample `index` (counted over all runs).
    fn push(&mut self, index: usize, point: (f32, f32, f32)) {
        if !index.is_multiple_of(self.stride) {
            return;
        }
        self.points.push((index, point));
        if self.points.len() >= 2 * TRAJECTORY_POINTS {
            self.stride *= 2;
            let stride = self.stride;
            self.points.retain(|(i, _)| i.is_multiple_of(stride));
        }
    }
}

/// What one run contributes to the report, gathered in one streaming pass.
struct RunPlots {
    stem: String,
    /// Rows × nominal sample period, s.
    duration_s: f64,
    evaluation: RunEvaluation,
    rate: RatePlot,
    bias_temp: BiasTempPlot,
}

/// One pass over the run of `reader`: evaluation, 10-s means for the rate
/// plot, trajectory points (sample indices from `first_index` on).
fn read_run(
    model: &Model,
    reader: RunReader,
    stem: &str,
    title: &str,
    trajectory: &mut Trajectory,
    first_index: &mut usize,
    accept: crate::evaluation::axes::Acceptance,
) -> anyhow::Result<RunPlots> {
    let path = reader.path().to_owned();
    let mask = model.features().set.thermometer_mask();
    let mut surface = SurfaceCoordinates::of(model);
    let named = RunDiagnosis::new(&path, 1.0).named_by(reader.header_line(), reader.columns());
    let run = StreamedRun::from_reader(reader, mask)?;
    let (period_s, has_ref) = (run.nominal_period_s, run.has_ref);
    let config = rbf_core::CompensatorConfig::for_nominal_period_s(period_s);
    let mut compensator = rbf_core::Compensator::new();
    let mut evaluator = Evaluator::new(&path, period_s, has_ref);
    let mut diagnosis = RunDiagnosis::new(&path, period_s).named_like(&named);
    let (mut raw, mut comp, mut temp, mut bias) = (
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
    );
    let (mut rows, mut compensated, mut rate_sum, mut comp_sum) = (0usize, 0usize, 0.0f64, 0.0f64);
    run.for_each_line(|line, row, sample| {
        let out = compensator.process(Some(model), &config, sample);
        let r = row.ref_dph.unwrap_or(0.0);
        evaluator.push(row.time_s, row.rate_dph - r, out.rate_comp_dph as f64 - r, out.flags);
        diagnosis.push(line, row);
        compensated += usize::from(!out.flags.contains(rbf_core::Flags::NO_VALID_MODEL));
        rate_sum += row.rate_dph;
        comp_sum += f64::from(out.rate_comp_dph);
        raw.push(row.time_s, row.rate_dph - r);
        comp.push(row.time_s, out.rate_comp_dph as f64 - r);
        bias.push(row.time_s, out.bias_dph as f64);
        temp.push(
            row.time_s,
            row.readings_c()[rbf_core::features::LOOP_THERMOMETER].unwrap_or(f64::NAN),
        );
        if let Some((x, y)) = surface.point(&config, sample) {
            trajectory.push(*first_index + rows, (x, y, out.bias_dph));
        }
        rows += 1;
    })?;
    *first_index += rows;
    require_evaluable(&path, rows, &diagnosis)?;
    require_compensated(&path, rows, compensated, &diagnosis, mask, accept.uncompensated)?;
    crate::reading::plausible::require_plausible(&diagnosis.implausible(), accept.implausible)?;
    // Without ref_dph each trace is taken about its own mean (as the
    // evaluation's figures are), known only now: a block mean of (v − m) is
    // the block mean of v, less m.
    let mean = |sum: f64| if has_ref { 0.0 } else { sum / rows.max(1) as f64 };
    let less_mean = |blocks: BlockMeans, mean: f64| -> Vec<(f64, f64)> {
        blocks.finish().into_iter().map(|(t, v)| (t, v - mean)).collect()
    };
    let evaluation = evaluator.finish();
    let (raw, comp, temp) = (
        less_mean(raw, mean(rate_sum)),
        less_mean(comp, mean(comp_sum)),
        temp.finish(),
    );
    let points = bias_points(&temp, &raw, &bias.finish(), &comp);
    Ok(RunPlots {
        stem: stem.to_owned(),
        duration_s: rows as f64 * period_s,
        bias_temp: BiasTempPlot {
            title: format!(
                "{title}: bias against loop temperature; 100-s STD {:.3} → {:.3} °/h",
                evaluation.cluster_std_before_dph, evaluation.cluster_std_after_dph
            ),
            points,
        },
        rate: RatePlot {
            title: format!(
                "{title}: rate before and after compensation; 100-s STD {:.3} → {:.3} °/h",
                evaluation.cluster_std_before_dph, evaluation.cluster_std_after_dph
            ),
            y_desc: if has_ref {
                "rate − ref_dph [°/h] (10-s means)"
            } else {
                "rate − its run mean (no ref_dph) [°/h] (10-s means)"
            },
            raw,
            comp,
            temp,
        },
        evaluation,
    })
}

/// The name a run's plots take: its file stem (`stdin` for `-`).
fn run_stem(path: &Path) -> String {
    if input::is_stdin(path) {
        return "stdin".to_owned();
    }
    path.file_stem()
        .map_or("run".into(), |s| s.to_string_lossy().into_owned())
}

/// Whether `rel` (a path relative to a report directory) names a file a
/// report writes: a plot (`.svg`, `.png`), `report.json`, `report.md`,
/// `fit.txt`, at the top or in a multi-axis report's `axis-x`, `axis-y`,
/// `axis-z` (those directories themselves included). A directory holding
/// anything else is never replaced.
pub fn report_may_hold(rel: &Path) -> bool {
    let parts: Vec<&std::ffi::OsStr> = rel.iter().collect();
    let axis_dir = |p: &std::ffi::OsStr| ["axis-x", "axis-y", "axis-z"].iter().any(|a| p == *a);
    if let [only] = parts[..]
        && axis_dir(only)
    {
        return true;
    }
    let (dirs, name) = match parts.split_last() {
        Some((name, dirs)) => (dirs, name.to_string_lossy()),
        None => return false,
    };
    let in_place = match dirs {
        [] => true,
        [axis] => axis_dir(axis),
        _ => false,
    };
    in_place
        && (name.ends_with(".svg")
            || name.ends_with(".png")
            || ["report.json", "report.md", "fit.txt"].contains(&name.as_ref()))
}

/// Checks, before any work, that a report on `runs` can be written into
/// `dir` ([`output::check_dir_target`]: the directory is replaced as a
/// whole, so none of `inputs` or `outputs` may lie in it, and an existing
/// one that is not empty only with [`Existing::Replace`] and when it holds
/// nothing but a report's files) and that the runs' plot names differ.
/// Returns the runs' plot names and the checked directory.
pub fn check_report_targets(
    runs: &[PathBuf],
    dir: &Path,
    inputs: &[&Path],
    outputs: &[&Path],
    existing: Existing,
) -> anyhow::Result<(Vec<String>, DirTarget)> {
    let stems: Vec<String> = runs.iter().map(|p| run_stem(p)).collect();
    for (i, stem) in stems.iter().enumerate() {
        if stems[..i].contains(stem) {
            anyhow::bail!(
                "two runs are named {}: their plots would overwrite each other; rename one",
                text::escape_controls(stem)
            );
        }
    }
    let target = output::check_dir_target(dir, inputs, outputs, existing, &report_may_hold)?;
    Ok((stems, target))
}

/// The model section of report.md: its file, kind, form, centres and every
/// input with its training range.
fn model_markdown(model: &Model, model_path: &Path) -> String {
    let mut md = format!("## Model\n\n- file: `{}`\n", text::path(model_path));
    let description = crate::describe::describe(model);
    md.push_str(&format!("- kind: {}\n", description.kind));
    md.push_str(&format!("- form: {}\n", description.form));
    if let Some(t0) = description.ref_temp_c {
        md.push_str(&format!(
            "- reference temperature T₀: {} °C\n",
            summary::sig(f64::from(t0), 4)
        ));
    }
    md.push_str(&format!(
        "- centres: {}\n",
        summary::count(summary::centres(model) as u64, "centre", "centres")
    ));
    md.push_str("- inputs (training range):\n");
    for (name, lo, hi) in summary::training_ranges(model) {
        md.push_str(&format!(
            "  - {}: {} … {}\n",
            text::escape_controls(&name),
            summary::sig(f64::from(lo), 4),
            summary::sig(f64::from(hi), 4)
        ));
    }
    md.push('\n');
    md
}

/// `n` of `samples` as a table cell: the count and its percentage.
fn clamped_cell(n: usize, samples: usize) -> String {
    if samples == 0 {
        return n.to_string();
    }
    format!("{n} ({:.1} %)", 100.0 * n as f64 / samples as f64)
}

/// The runs a report is made of.
#[derive(Clone, Copy, Debug)]
pub struct ReportRuns<'a> {
    /// Every run, in the order reported.
    pub paths: &'a [PathBuf],
    /// How many of the first `paths` the model was trained on (`trainer
    /// fit`): their samples alone mark where a box model's bias surface is
    /// backed by data. `None` when that is not known (`trainer report`):
    /// every run's samples then.
    pub trained_on: Option<usize>,
}

/// Writes the report of `model` (read from `model_path`) on the runs at
/// `runs` (`-`: standard input) into the staged directory `out`, in its
/// subdirectory `sub` (empty: at the top); returns how many files it wrote
/// and the runs' evaluations.
/// `axis` picks that axis of multi-axis runs (`None`: single-axis runs).
///
/// Every run is read once, streaming (memory: 10-s means and a bounded
/// trajectory, whatever the run's length), before any file is written.
/// Nothing is visible until `out`'s [`output::Transaction`] commits. A run
/// where no row could be compensated, or that is implausible
/// ([`crate::reading::plausible`]), is refused unless `accept` says so.
pub fn write_report(
    model: &Model,
    model_path: &Path,
    runs: ReportRuns,
    out: &StagedDir,
    sub: &Path,
    accept: crate::evaluation::axes::Acceptance,
    axis: Option<Axis>,
) -> anyhow::Result<(usize, Vec<RunEvaluation>)> {
    let (trained_on, runs) = (runs.trained_on, runs.paths);
    input::check_stdin_once(runs.iter().map(|p| p.as_path()).chain([model_path]))?;
    let stems: Vec<String> = runs.iter().map(|p| run_stem(p)).collect();
    // A multi-axis report's titles name the axis.
    let titled = |stem: &str| match axis {
        Some(a) => format!("{stem}, axis {}", a.name()),
        None => stem.to_owned(),
    };
    let mut trajectory = Trajectory::new();
    let mut first_index = 0;
    // The first sample index past the training runs.
    let mut trained_end_index = None;
    let plots = runs
        .iter()
        .zip(&stems)
        .enumerate()
        .map(|(k, (path, stem))| {
            if Some(k) == trained_on {
                trained_end_index = Some(first_index);
            }
            let mut reader = RunReader::open(path)?;
            match axis {
                Some(axis) => reader.select_axis(axis)?,
                None => reader.require_single_axis()?,
            }
            read_run(
                model,
                reader,
                stem,
                &titled(stem),
                &mut trajectory,
                &mut first_index,
                accept,
            )
        })
        .collect::<anyhow::Result<Vec<_>>>()?;

    let written = std::cell::Cell::new(0);
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        out.write(&sub.join(name), bytes)?;
        written.set(written.get() + 1);
        Ok(())
    };
    let both = |stem: &str, drawn: anyhow::Result<(String, Vec<u8>)>| -> anyhow::Result<()> {
        let (svg, png) = drawn.with_context(|| format!("{}: plot {stem}", text::path(&out.target().join(sub))))?;
        write(&format!("{stem}.svg"), svg.as_bytes())?;
        write(&format!("{stem}.png"), &png)
    };
    let mut md = match axis {
        Some(a) => format!("# Compensation report, axis {}\n\n", a.name()),
        None => String::from("# Compensation report\n\n"),
    };
    md.push_str(&model_markdown(model, model_path));
    md.push_str("## Runs\n\n| run | 100-s STD before [°/h] | after [°/h] | improvement | MSD improvement | ARW after [°/√h] | BI before → after [°/h] | clamped samples |\n|---|---|---|---|---|---|---|---|\n");
    for p in &plots {
        let stem = &p.stem;
        both(&format!("{stem}_rate"), render(&p.rate))?;
        both(&format!("{stem}_bias_vs_temp"), render(&p.bias_temp))?;
        let allan = AllanPlot {
            title: format!(
                "{}: overlapping Allan deviation; bias instability {} → {} °/h",
                titled(stem),
                p.evaluation.allan_before.bias_instability_cell(),
                p.evaluation.allan_after.bias_instability_cell()
            ),
            evaluation: &p.evaluation,
            duration_s: p.duration_s,
        };
        both(&format!("{stem}_allan"), render(&allan))?;
        let e = &p.evaluation;
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} → {} | {} |\n",
            text::escape_controls(stem),
            figure(e.cluster_std_before_dph, |v| format!("{v:.4}")),
            figure(e.cluster_std_after_dph, |v| format!("{v:.4}")),
            figure(e.cluster_std_improvement_pct, |v| format!("{v:.1} %")),
            figure(e.msd_improvement_pct, |v| format!("{v:.1} %")),
            figure(e.allan_after.arw_deg_per_sqrt_h, |v| format!("{v:.2e}")),
            e.allan_before.bias_instability_cell(),
            e.allan_after.bias_instability_cell(),
            clamped_cell(e.flagged.input_clamped, e.samples)
        ));
    }
    md.push_str(
        "\nClamped samples: inputs outside the model's training range, held at its edge \
         (flag 1).\n",
    );
    md.push_str(&format!("{}.\n", crate::evaluation::allan::FLOOR_RULE));
    let trained_end_index = trained_end_index.or(trained_on.map(|_| first_index));
    let surface = SurfacePlot::new(model, trajectory.points, trained_end_index);
    both("bias_surface", render(&surface))?;
    md.push_str("\n## Plots\n\n![bias surface](bias_surface.svg)\n\n");
    for p in &plots {
        let stem = &p.stem;
        md.push_str(&format!(
            "### {}\n\n![rate]({stem}_rate.svg)\n\n![bias against temperature]({stem}_bias_vs_temp.svg)\n\n![Allan deviation]({stem}_allan.svg)\n\n",
            text::escape_controls(stem)
        ));
    }
    let evaluations: Vec<&RunEvaluation> = plots.iter().map(|p| &p.evaluation).collect();
    let json =
        serde_json::to_string_pretty(&serde_json::json!({"model": text::path(model_path), "runs": evaluations}))?;
    write("report.json", json.as_bytes())?;
    write("report.md", md.as_bytes())?;
    Ok((written.get(), plots.into_iter().map(|p| p.evaluation).collect()))
}

/// The summary page of a multi-axis report (its top report.md): every run
/// and axis side by side, with links to each axis's own report.
pub fn axes_summary_markdown(model_path: &Path, axes: &[(Axis, Vec<RunEvaluation>)]) -> String {
    let names: Vec<&str> = axes.iter().map(|(a, _)| a.name()).collect();
    let mut md = format!(
        "# Compensation report, axes {}\n\nModel: `{}`. Each axis in full: {}.\n\n",
        names.join(", "),
        text::path(model_path),
        names
            .iter()
            .map(|n| format!("[axis {n}](axis-{n}/report.md)"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    md.push_str(
        "| run | axis | 100-s STD before [°/h] | after [°/h] | improvement | BI after [°/h] | clamped |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let runs = axes.iter().map(|(_, e)| e.len()).max().unwrap_or(0);
    for run in 0..runs {
        for (axis, evaluations) in axes {
            let Some(e) = evaluations.get(run) else { continue };
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                text::escape_controls(&run_stem(Path::new(&e.run))),
                axis.name(),
                figure(e.cluster_std_before_dph, |v| format!("{v:.4}")),
                figure(e.cluster_std_after_dph, |v| format!("{v:.4}")),
                figure(e.cluster_std_improvement_pct, |v| format!("{v:.1} %")),
                e.allan_after.bias_instability_cell(),
                clamped_cell(e.flagged.input_clamped, e.samples)
            ));
        }
    }
    md.push_str(&format!("\n{}.\n", crate::evaluation::allan::FLOOR_RULE));
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_directory_may_hold_only_what_a_report_writes() {
        for ok in ["report.md", "fit.txt", "run_rate.svg", "axis-y", "axis-y/run_allan.png"] {
            assert!(report_may_hold(Path::new(ok)), "{ok}");
        }
        for not in ["notes.txt", "run.csv", "keep", "axis-y/sub/x.svg", "other/report.md"] {
            assert!(!report_may_hold(Path::new(not)), "{not}");
        }
    }

    #[test]
    fn the_default_models_surface_spans_its_fastest_rate_input_not_a_power_of_temperature() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::Run::load(&data).unwrap();
        let opts = crate::fit::FitOptions::default();
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &opts).unwrap().model;
        let FeatureSet::LagBank(bank) = model.features().set else {
            panic!("the default is the lag bank")
        };
        let fastest = model.input_range(bank.static_inputs()).unwrap();
        assert_eq!(surface_rate_range(&model), Some(fastest));
        // The 1 °C/min run's rates stay within ±1 °C/min; (T̂ − T₀)² reaches 100 °C².
        assert!(fastest.0 > -1.0 && fastest.1 < 1.0, "{fastest:?}");
    }

    #[test]
    fn bias_points_are_coloured_by_the_direction_the_temperature_moves() {
        // 10-s means: heating at 1 °C/min, a hold, cooling at 1 °C/min.
        let temps = [20.0, 20.1667, 20.3333, 20.3333, 20.3333, 20.1667, 20.0];
        let temp: Vec<(f64, f64)> = temps.iter().enumerate().map(|(i, &t)| (10.0 * i as f64, t)).collect();
        let value = |v: f64| temp.iter().map(|&(t, _)| (t, v)).collect::<Vec<_>>();
        let points = bias_points(&temp, &value(1.0), &value(0.75), &value(0.25));
        let ramps: Vec<Ramp> = points.iter().map(|p| p.ramp).collect();
        use Ramp::{Cooling, Heating, Steady};
        assert_eq!(ramps, [Heating, Heating, Heating, Steady, Cooling, Cooling, Cooling]);
        assert_eq!(
            (points[0].measured_dph, points[0].model_dph, points[0].residual_dph),
            (1.0, 0.75, 0.25)
        );
    }

    #[test]
    fn allan_bands_narrow_with_more_clusters() {
        // T/τ = 3: 1/√4; T/τ = 51: 1/√100.
        assert!((crate::evaluation::allan::relative_error(10.0, 30.0) - 0.5).abs() < 1e-12);
        assert!((crate::evaluation::allan::relative_error(1.0, 51.0) - 0.1).abs() < 1e-12);
        assert!(crate::evaluation::allan::relative_error(10.0, 10.0).is_infinite());
        let band = allan_band(&[(1.0, 2.0)], 51.0);
        assert!((band[0].1 - 1.8).abs() < 1e-12 && (band[0].2 - 2.2).abs() < 1e-12);
    }

    #[test]
    fn clamped_samples_are_a_count_and_a_percentage() {
        assert_eq!(clamped_cell(11, 100), "11 (11.0 %)");
        assert_eq!(clamped_cell(0, 0), "0");
    }

    /// The text labels and the circles' centres (x, y) of an SVG that plotters drew.
    fn svg_texts_and_circles(svg: &str) -> (Vec<String>, Vec<(f64, f64)>) {
        let texts = svg
            .split("<text")
            .skip(1)
            .filter_map(|t| Some(t.split_once('>')?.1.split_once("</text>")?.0.trim().to_owned()))
            .collect();
        let attr = |e: &str, name: &str| -> f64 {
            let v = e
                .split(&format!(" {name}=\""))
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap();
            v.parse().unwrap()
        };
        let circles = svg
            .split("<circle")
            .skip(1)
            .map(|c| (attr(c, "cx"), attr(c, "cy")))
            .collect();
        (texts, circles)
    }

    /// An evaluation whose Allan curves run from `hi` down to `lo`, °/h, over 1 … 1000 s.
    fn evaluation_with_allan(lo: f64, hi: f64) -> RunEvaluation {
        let tau_s: Vec<f64> = (0..11).map(|k| 2f64.powi(k)).collect();
        let curve = |top: f64| crate::evaluation::allan::AllanDeviation {
            adev_dph: tau_s.iter().map(|t| top * (lo / top).powf(t.log2() / 10.0)).collect(),
            tau_s: tau_s.clone(),
            arw_deg_per_sqrt_h: f64::NAN,
            bias_instability_dph: f64::NAN,
            floor_tau_s: f64::NAN,
            floor_reached: false,
            floor_uncertainty_pct: f64::NAN,
            confident_tau_max_s: 1000.0,
        };
        RunEvaluation {
            run: "r.csv".into(),
            axis: None,
            basis: "samples".into(),
            samples: 10_000,
            reference: "ref_dph",
            msd_before_dph2: 1.0,
            msd_after_dph2: 1.0,
            msd_improvement_pct: 0.0,
            cluster_std_before_dph: 1.0,
            cluster_std_after_dph: 1.0,
            cluster_std_improvement_pct: 0.0,
            flagged: Default::default(),
            allan_before: curve(hi),
            allan_after: curve(hi * 0.9),
        }
    }

    #[test]
    fn a_short_allan_axis_is_labelled_below_its_first_decade_once_per_value_and_off_the_frame() {
        // 0.003 … 0.05 °/h: the axis starts above 0.001.
        let e = evaluation_with_allan(0.003, 0.05);
        let plot = AllanPlot {
            title: "r".into(),
            evaluation: &e,
            duration_s: 20_000.0,
        };
        let (svg, _) = render(&plot).unwrap();
        assert_drawable(&svg);
        let (texts, circles) = svg_texts_and_circles(&svg);
        for label in ["0.005", "0.01", "0.02", "0.05"] {
            assert!(texts.iter().any(|t| t == label), "no tick label {label}: {texts:?}");
        }
        let numbers: Vec<&String> = texts.iter().filter(|t| t.parse::<f64>().is_ok()).collect();
        let mut unique = numbers.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(numbers.len(), unique.len(), "a tick label written twice: {numbers:?}");
        // The markers at τ = 1 s and 1024 s stay off the frame (the plot's
        // area starts after the 80-px label area and the 12-px margin).
        let (x_min, x_max) = circles
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), c| (a.min(c.0), b.max(c.0)));
        assert!(x_min > 12.0 + 80.0 + 10.0, "first marker on the frame: x {x_min}");
        assert!(
            x_max < f64::from(SIZE.0) - 12.0 - 10.0,
            "last marker on the frame: x {x_max}"
        );
    }

    /// The font size an SVG that plotters drew gives the text `content`.
    fn svg_font_size(svg: &str, content: &str) -> f64 {
        svg.split("<text")
            .skip(1)
            .find(|t| {
                t.split_once('>')
                    .is_some_and(|(_, rest)| rest.trim_start().starts_with(content))
            })
            .and_then(|t| t.split(" font-size=\"").nth(1)?.split('"').next()?.parse().ok())
            .unwrap_or_else(|| panic!("no text {content:?}"))
    }

    #[test]
    fn a_title_too_long_for_the_plot_shrinks_to_fit_rather_than_being_clipped() {
        let e = evaluation_with_allan(0.003, 0.05);
        let size_of = |title: String| {
            let plot = AllanPlot {
                title: title.clone(),
                evaluation: &e,
                duration_s: 20_000.0,
            };
            svg_font_size(&render(&plot).unwrap().0, &title)
        };
        let tail = ": overlapping Allan deviation; bias instability ≤9.75e-3 → ≤2.24e-3 °/h";
        let short = size_of(format!("run{tail}"));
        let long = size_of(format!("{}{tail}", "chamber_run_of_unit_0042_axis_z_".repeat(2)));
        assert!(long < 0.9 * short, "{long} against {short}");
    }

    #[test]
    fn long_y_tick_labels_widen_their_label_area_rather_than_run_into_the_axis_description() {
        // A rate about -1.2e-4 °/h that varies by 1e-6: labels such as -0.0001202.
        let wave = |k: usize| -1.2e-4 + 1e-6 * (k as f64 / 9.0).sin();
        let series = |f: &dyn Fn(usize) -> f64| (0..400).map(|k| (10.0 * k as f64, f(k))).collect::<Vec<_>>();
        let plot = RatePlot {
            title: "r".into(),
            y_desc: "rate − ref_dph [°/h] (10-s means)",
            raw: series(&wave),
            comp: series(&|k| wave(k) + 2e-7),
            temp: series(&|k| 20.0 + k as f64 / 40.0),
        };
        let (svg, _) = render(&plot).unwrap();
        let mut area_svg = String::new();
        let area = SVGBackend::with_string(&mut area_svg, SIZE).into_drawing_area();
        let style = ("sans-serif", TICK_LABEL_PX).into_text_style(&area);
        // The description's rotated line ends at its x plus its font's height.
        let desc_right_px = 12.0 + TICK_LABEL_PX;
        let left_labels: Vec<(f64, String)> = svg
            .split("<text")
            .skip(1)
            .filter_map(|t| {
                let (attrs, rest) = t.split_once('>')?;
                let text = rest.split_once("</text>")?.0.trim();
                text.parse::<f64>().ok()?;
                let x: f64 = attrs.split(" x=\"").nth(1)?.split('"').next()?.parse().ok()?;
                (x < 200.0 && attrs.contains("text-anchor=\"end\"")).then(|| (x, text.to_owned()))
            })
            .collect();
        assert!(left_labels.len() >= 3, "{left_labels:?}");
        assert!(left_labels.iter().any(|(_, t)| t.len() >= 10), "{left_labels:?}");
        for (right_px, text) in &left_labels {
            let (width, _) = area.estimate_text_size(text, &style).unwrap();
            assert!(
                right_px - f64::from(width) > desc_right_px,
                "{text} reaches the axis description: {right_px} − {width} px"
            );
        }
    }

    #[test]
    fn light_grid_lines_stay_apart_rather_than_stack_into_a_grey_band() {
        let points: Vec<BiasPoint> = (0..300)
            .map(|k| {
                let temp_c = 12.0 + k as f64 * 0.09;
                BiasPoint {
                    temp_c,
                    measured_dph: 0.02 * temp_c,
                    model_dph: 0.02 * temp_c,
                    residual_dph: 0.06 * (k as f64 / 5.0).sin(),
                    ramp: Ramp::Heating,
                }
            })
            .collect();
        let (svg, _) = render(&BiasTempPlot {
            title: "r".into(),
            points,
        })
        .unwrap();
        // plotters draws the light lines at a tenth of black's opacity.
        let attr = |l: &str, name: &str| -> i64 {
            l.split(&format!(" {name}=\""))
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let light: Vec<&str> = svg
            .split("<line")
            .skip(1)
            .filter(|l| l.contains("opacity=\"0.1\""))
            .collect();
        assert!(light.len() > 10, "no light grid lines drawn");
        for (from, to) in [("y1", "y2"), ("x1", "x2")] {
            let mut at: Vec<i64> = light
                .iter()
                .filter(|l| attr(l, from) == attr(l, to))
                .map(|l| attr(l, from))
                .collect();
            at.sort_unstable();
            at.dedup();
            let closest = at.windows(2).map(|w| w[1] - w[0]).min().unwrap_or(i64::MAX);
            assert!(closest >= 7, "light lines along {from} {closest} px apart: {at:?}");
        }
    }

    #[test]
    fn the_bias_surface_masks_what_no_run_reached_and_spends_its_colours_on_the_rest() {
        // Samples only in the lower-left quarter of the box.
        let path: Vec<(f32, f32, f32)> = (0..200)
            .map(|k| (-40.0 + k as f32 * 0.2, -1.0 + k as f32 * 0.004, 0.0))
            .collect();
        let reached = reached_cells(&path, (-40.0, 60.0), (-1.0, 1.0), 60);
        let share = reached.iter().filter(|r| **r).count() as f64 / reached.len() as f64;
        assert!(share > 0.01 && share < 0.2, "{share}");
        // The corner no sample reached is masked; where they went is not.
        assert!(!reached[60 * 60 - 1] && reached[0]);
    }

    /// The SVG of `model`'s bias plot over `trajectory` (the reported runs').
    fn surface_svg(model: &Model, trajectory: Vec<(f32, f32, f32)>) -> String {
        let surface = SurfacePlot {
            model,
            trajectory,
            training_only: false,
        };
        render(&surface).unwrap().0
    }

    /// A cubic in T trained over -40 … 60 °C.
    fn cubic_in_t() -> Model {
        use rbf_core::model::{ModelBody, ModelInfo};
        use rbf_core::poly::Poly3;
        Model::new(
            rbf_core::FeatureConfig::single(FeatureSet::Temp, 0.0),
            &[(-40.0, 60.0)],
            ModelBody::Poly3(Poly3::new(25.0, [0.5, -0.01, 1e-4, -2e-6]).unwrap()),
            ModelInfo::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_box_models_surface_hatches_what_no_run_reached_with_ticks_written_as_numbers() {
        let model = cubic_in_t();
        // The runs stayed below 0 °C and within ±0.2 °C/min.
        let trajectory: Vec<(f32, f32, f32)> = (0..100)
            .map(|k| (-40.0 + 0.4 * k as f32, 0.2 * (k as f32 / 7.0).sin(), 0.0))
            .collect();
        let svg = surface_svg(&model, trajectory);
        let hatch = format!(
            "stroke=\"#{:02X}{:02X}{:02X}\"",
            OUTSIDE_TRAINING.0, OUTSIDE_TRAINING.1, OUTSIDE_TRAINING.2
        );
        assert!(svg.matches(&hatch).count() > 60, "the warm half is hatched");
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t.contains("hatched")), "{texts:?}");
        assert!(texts.iter().any(|t| t.contains("not a model input")), "{texts:?}");
        for t in texts.iter().filter(|t| t.parse::<f64>().is_ok()) {
            assert!(!t.ends_with(".0") && t != "-0", "tick label {t}");
        }
        // The rate axis spans the runs' rates, not a made-up ±1 °C/min.
        let rates = y_ticks(&svg);
        assert!(rates.len() >= 3 && rates.iter().all(|r| r.abs() <= 0.25), "{rates:?}");
    }

    #[test]
    fn a_box_surface_from_a_fit_is_masked_by_the_training_runs_alone() {
        let model = cubic_in_t();
        // A training run below 0 °C (samples 0 … 99), a holdout above it.
        let points: Vec<(usize, (f32, f32, f32))> = (0..200).map(|k| (k, (-40.0 + 0.5 * k as f32, 0.0, 0.0))).collect();
        let surface = SurfacePlot::new(&model, points.clone(), Some(100));
        assert!(surface.training_only);
        assert!(surface.trajectory.len() == 100 && surface.trajectory.iter().all(|p| p.0 < 10.0));
        let (svg, _) = render(&surface).unwrap();
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t.contains("no training sample")), "{texts:?}");
        // Without knowing the training runs (trainer report): every run's samples.
        let surface = SurfacePlot::new(&model, points, None);
        assert!(!surface.training_only && surface.trajectory.len() == 200);
    }

    /// The numbers an SVG that plotters drew writes, with where: (x, y, value).
    fn svg_numbers(svg: &str) -> Vec<(f64, f64, f64)> {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let (attrs, rest) = t.split_once('>')?;
                let value = rest.split_once("</text>")?.0.trim().parse().ok()?;
                let attr = |name: &str| -> Option<f64> {
                    attrs
                        .split(&format!(" {name}=\""))
                        .nth(1)?
                        .split('"')
                        .next()?
                        .parse()
                        .ok()
                };
                Some((attr("x")?, attr("y")?, value))
            })
            .collect()
    }

    /// The tick labels of a surface plot's x axis (below the plot, left of
    /// the colour bar).
    fn x_ticks(svg: &str) -> Vec<f64> {
        svg_numbers(svg)
            .into_iter()
            .filter(|n| n.1 > f64::from(SIZE.1) - 60.0 && n.0 < f64::from(SIZE.0 - COLOUR_BAR_PX))
            .map(|n| n.2)
            .collect()
    }

    /// The tick labels of a plot's left y axis.
    fn y_ticks(svg: &str) -> Vec<f64> {
        svg_numbers(svg)
            .into_iter()
            .filter(|n| n.0 < 100.0 && n.1 < f64::from(SIZE.1) - 60.0)
            .map(|n| n.2)
            .collect()
    }

    /// No text of `svg` carries a combining mark, which the PNG's font does not draw.
    fn assert_drawable(svg: &str) {
        let (texts, _) = svg_texts_and_circles(svg);
        for t in texts {
            assert!(
                !t.chars().any(crate::plotting::axes::is_combining),
                "a combining mark the PNG font drops: {t:?}"
            );
        }
    }

    #[test]
    fn a_response_banks_surface_spans_the_loop_temperature_and_the_runs_rates() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::Run::load(&data).unwrap();
        let opts = crate::fit::FitOptions {
            features: crate::fit::RbfFeatures::ResponseBank,
            ..crate::fit::FitOptions::default()
        };
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &opts).unwrap().model;
        let FeatureSet::ResponseBank(bank) = model.features().set else {
            panic!("the response bank was asked for")
        };
        let (t_lo, t_hi) = (f64::from(bank.range_min_c), f64::from(bank.range_max_c));
        // Along the run: T across the covered range, ΔT within ±0.5 °C/min.
        let trajectory: Vec<(f32, f32, f32)> = (0..200)
            .map(|k| {
                let t = t_lo + (t_hi - t_lo) * f64::from(k) / 199.0;
                (t as f32, 0.5 * (k as f32 / 20.0).sin(), 0.0)
            })
            .collect();
        let svg = surface_svg(&model, trajectory);
        let temps = x_ticks(&svg);
        assert!(
            temps.len() >= 3 && temps.iter().all(|&t| t >= t_lo - 1.0 && t <= t_hi + 1.0),
            "the x axis spans the loop temperature {t_lo} … {t_hi}: {temps:?}"
        );
        let rates = y_ticks(&svg);
        assert!(rates.len() >= 3 && rates.iter().all(|r| r.abs() <= 0.6), "{rates:?}");
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t == "loop temperature T [°C]"), "{texts:?}");
        // The colours: the bias at the run's temperatures, below 1 °/h in size
        // (off the run's temperatures, the bank's tangents reach over 1 °/h).
        let bar: Vec<f64> = svg_numbers(&svg)
            .into_iter()
            .filter(|n| n.0 > f64::from(SIZE.0 - COLOUR_BAR_PX))
            .map(|n| n.2)
            .collect();
        assert!(!bar.is_empty() && bar.iter().all(|b| b.abs() <= 1.0), "{bar:?}");
        assert_drawable(&svg);
    }

    #[test]
    fn the_lag_banks_bias_plot_marks_its_training_range_and_writes_t_hat_in_words() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::Run::load(&data).unwrap();
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &crate::fit::FitOptions::default())
            .unwrap()
            .model;
        let (lo, hi) = model.input_range(0).unwrap();
        // One sample beyond the training range: drawn grey, outside the dashed box.
        let svg = surface_svg(&model, vec![(lo, 0.0, 0.1), (hi, 0.0, 0.2), (hi + 20.0, 0.0, 9.0)]);
        assert_drawable(&svg);
        assert!(svg.contains("mean coil temperature T-hat [°C]"), "T̂ written out");
        assert!(
            svg.contains("stroke-dasharray") || svg.matches("<polyline").count() > 10,
            "training range drawn"
        );
        let grey = format!(
            "fill=\"#{:02X}{:02X}{:02X}\"",
            OUTSIDE_TRAINING.0, OUTSIDE_TRAINING.1, OUTSIDE_TRAINING.2
        );
        assert_eq!(svg.matches("<circle").count(), 3);
        assert!(svg.contains(&grey), "the sample outside the training range is grey");
        // The colour bar spans 0.1 … 0.2, not the extrapolated 9.
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(
            !texts
                .iter()
                .any(|t| t.parse::<f64>().is_ok_and(|v| v > 1.0 && v < 10.0)),
            "{texts:?}"
        );
    }

    #[test]
    fn a_point_without_a_temperature_is_left_out() {
        let temp = [(0.0, 20.0), (10.0, f64::NAN), (20.0, 20.0)];
        let v = [(0.0, 1.0), (10.0, 1.0), (20.0, 1.0)];
        assert_eq!(bias_points(&temp, &v, &v, &v).len(), 2);
    }
}
