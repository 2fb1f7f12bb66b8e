//! The model's surface plot with its colour bar: a lag bank's or multi-scale model's
//! bias along the runs' path over its own inputs ([`Trajectory`]), any other model's
//! over the loop temperature and a steady ramp rate, greyed where no training sample lay.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use rbf_core::{FeatureSet, FeatureVector, Model};

use super::canvas::{DrawResult, Figure, range};
use crate::plotting::axes::{
    TICK_LABEL_PX, drawable, linear_mesh, linear_tick_labels, padded, tick_label, title_font_px, y_label_area_px,
};

pub(super) struct SurfacePlot<'a> {
    pub(super) model: &'a Model,
    /// Per sample, the plot's two coordinates and the model's bias
    /// ([`SurfaceCoordinates`]): of every reported run on a path plot, of
    /// the training runs on a box surface when they are known.
    pub(super) trajectory: Vec<(f32, f32, f32)>,
    /// Whether `trajectory` holds the training runs' samples alone.
    pub(super) training_only: bool,
}

impl<'a> SurfacePlot<'a> {
    /// The bias plot of `model` from the reported runs' `points` (sample
    /// index, point); those before `trained_end_index` are the training
    /// runs'.
    pub(super) fn new(
        model: &'a Model,
        points: Vec<(usize, (f32, f32, f32))>,
        trained_end_index: Option<usize>,
    ) -> Self {
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
pub(super) fn drawn_along_the_path(set: FeatureSet) -> bool {
    set.is_multiscale() || matches!(set, FeatureSet::LagBank(_))
}

/// The ΔT window of the bias surface of a model without a ΔT input of its
/// own (a cubic in T, the response bank), s.
pub(super) const SURFACE_RATE_WINDOW_S: f32 = 60.0;

/// What a bias plot's point is made of, per sample: input 0 and input
/// `rate_input` of `features`, computed by `extractor`. Those are the
/// model's own inputs on path plots and multi-point surfaces; on the other
/// surfaces (over T and a steady-ramp ΔT, whatever the model's inputs: a
/// response bank's are T − T₀ and its powers, a cubic in T has no rate) the
/// loop temperature and its rate.
pub(super) struct SurfaceCoordinates {
    pub(super) features: rbf_core::FeatureConfig,
    pub(super) rate_input: Option<usize>,
    pub(super) extractor: rbf_core::Compensator,
}

/// The ΔT window of `model`'s bias surface over T and ΔT, s: its own for a
/// model with a ΔT input, so that the plotted points are its inputs.
pub(super) fn surface_rate_window_s(model: &Model) -> f32 {
    let features = model.features();
    if surface_rate_input(features.set).is_some() && features.rate_window_s > 0.0 {
        features.rate_window_s
    } else {
        SURFACE_RATE_WINDOW_S
    }
}

impl SurfaceCoordinates {
    /// The coordinates of `model`'s bias plot.
    pub(super) fn of(model: &Model) -> Self {
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
    pub(super) fn point(
        &mut self,
        config: &rbf_core::CompensatorConfig,
        sample: &rbf_core::GyroSample,
    ) -> Option<(f32, f32)> {
        let inputs = self.extractor.features(&self.features, config, sample).features?;
        let v = inputs.as_slice();
        Some((v[0], self.rate_input.and_then(|i| v.get(i).copied()).unwrap_or(0.0)))
    }
}

/// Blue → green → red for `x` in 0 … 1.
pub(super) fn colour(x: f64) -> RGBColor {
    let x = x.clamp(0.0, 1.0);
    RGBColor(
        (40.0 + 215.0 * x) as u8,
        (90.0 + 80.0 * (1.0 - (2.0 * x - 1.0).abs())) as u8,
        (230.0 - 200.0 * x) as u8,
    )
}

/// Width of the colour bar beside a plot whose colour carries a value, pixels.
pub(super) const COLOUR_BAR_PX: u32 = 120;
/// Font size of the colour bar's tick labels, px.
pub(super) const BAR_LABEL_PX: f64 = 13.0;

/// The chart of a bias map on `plot` (the area beside its colour bar):
/// titled `caption`, over inputs `x` (horizontal) and `y`.
fn plane_chart<'a, DB: DrawingBackend>(
    plot: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    Ok(ChartBuilder::on(plot)
        .caption(caption, ("sans-serif", title_font_px(plot, caption)))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_area_px(
            plot,
            linear_tick_labels(y.start, y.end),
            TICK_LABEL_PX,
            70,
        ))
        .build_cartesian_2d(x, y)?)
}

/// Splits `root` into the plot's area and the colour bar's, draws the bar
/// (the [`colour`] scale from `lo` at the bottom to `hi` at the top, with an
/// axis labelled `label`) and returns the plot's area.
pub(super) fn with_colour_bar<DB: DrawingBackend>(
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
pub(super) fn draw_trajectory<DB: DrawingBackend>(
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
    let mut chart = plane_chart(&plot, &caption, t_lo..t_hi, r_lo..r_hi)?;
    linear_mesh(&mut chart)
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

/// Bias of `model` at loop temperature `t_c` on a steady ramp of `rate` °C/min.
pub(super) fn steady_bias(model: &Model, t_c: f32, rate: f32) -> f32 {
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
pub(super) fn surface_rate_input(set: FeatureSet) -> Option<usize> {
    let input = match set {
        FeatureSet::LagBank(bank) => bank.static_inputs(),
        FeatureSet::Temp | FeatureSet::ResponseBank(_) => return None,
        _ => 1,
    };
    (input < set.dims()).then_some(input)
}

/// The training range of [`surface_rate_input`], °C/min (multi-point:
/// input 1's units).
pub(super) fn surface_rate_range(model: &Model) -> Option<(f32, f32)> {
    model.input_range(surface_rate_input(model.features().set)?)
}

/// The loop temperature range a model was trained over, °C: its input 0,
/// or a response bank's covered range (its input 0 is T − T₀).
pub(super) fn loop_temperature_range(model: &Model) -> (f32, f32) {
    match model.features().set {
        FeatureSet::ResponseBank(bank) => (bank.range_min_c, bank.range_max_c),
        _ => model.input_range(0).unwrap_or((0.0, 1.0)),
    }
}

pub(super) use super::palette::{MASKED, OUTSIDE_TRAINING};

/// Which cells of an `n` × `n` grid over `t` × `r` some sample of `points`
/// (x, y) lies in or next to, row-major from (t.0, r.0).
pub(super) fn reached_cells(points: &[(f32, f32, f32)], t: (f32, f32), r: (f32, f32), n: usize) -> Vec<bool> {
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

pub(super) fn draw_surface<DB: DrawingBackend>(
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
    let mut chart = plane_chart(&plot, &caption, x_lo..x_hi, y_lo..y_hi)?;
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
pub(super) const TRAJECTORY_POINTS: usize = 3000;

/// Every `stride`-th sample's (T, ΔT₁, bias), the stride doubling whenever
/// twice [`TRAJECTORY_POINTS`] are held: bounded whatever the run's length.
#[derive(Debug)]
pub(super) struct Trajectory {
    pub(super) stride: usize,
    pub(super) points: Vec<(usize, (f32, f32, f32))>,
}

impl Trajectory {
    pub(super) fn new() -> Self {
        Trajectory {
            stride: 1,
            points: Vec::new(),
        }
    }

    /// Takes the point of sample `index` (counted over all runs).
    pub(super) fn push(&mut self, index: usize, point: (f32, f32, f32)) {
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
