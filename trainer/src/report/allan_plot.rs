//! The Allan deviation plot: before and after compensation on log-log axes, with
//! shaded ±1-σ confidence bands.

use plotters::coord::Shift;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::prelude::*;

use super::canvas::{DrawResult, Figure, plot_height_px, range};
use crate::evaluation::evaluate::RunEvaluation;
use crate::plotting::axes::{
    TICK_LABEL_PX, draw_legend, log_tick_labels, log_ticks, padded_log, tick_label, title_font_px,
    with_legend_room_log, y_label_area_px,
};

pub(super) struct AllanPlot<'a> {
    pub(super) title: String,
    pub(super) evaluation: &'a RunEvaluation,
    /// Length of the run, s (the confidence bands' T).
    pub(super) duration_s: f64,
}

impl Figure for AllanPlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_allan(root, &self.title, self.evaluation, self.duration_s)
    }
}

/// The ±1-σ band (τ, lower, upper) of an Allan curve, per
/// [`crate::evaluation::allan::relative_error`]; the lower edge kept above zero for log axes.
pub(super) fn allan_band(points: &[(f64, f64)], duration_s: f64) -> Vec<(f64, f64, f64)> {
    points
        .iter()
        .map(|&(t, d)| {
            let e = crate::evaluation::allan::relative_error(t, duration_s).min(0.95);
            (t, d * (1.0 - e), d * (1.0 + e))
        })
        .collect()
}

/// A logarithmic axis over `lo` … `hi` with the ticks of [`log_ticks`].
pub(super) fn log_axis(lo: f64, hi: f64) -> WithKeyPoints<LogCoord<f64>> {
    let (labelled, grid) = log_ticks(lo, hi);
    LogCoord::from((lo..hi).log_scale())
        .with_key_points(labelled)
        .with_light_points(grid)
}

pub(super) fn draw_allan<DB: DrawingBackend>(
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
        (&before, &bands[0], "before", super::palette::BEFORE),
        (&after, &bands[1], "after", super::palette::AFTER),
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
    let guide = super::palette::GUIDE;
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
    // The line sits at the bias instability its label gives (σ/0.664), not at σ.
    let floor = a.bias_instability_dph;
    if floor.is_finite() && floor > 0.0 {
        let orange = super::palette::FLOOR;
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
                    "no floor above the white noise by τ {:.0} s (T/10): bias instability ≤ {:.2e} °/h",
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
    draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
