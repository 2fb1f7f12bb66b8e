//! The rate plot: a run's raw and compensated rate (10-s means) with the loop temperature.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::canvas::{DrawResult, Figure, plot_height_px, range};
use super::palette;
use crate::plotting::axes::{
    TICK_LABEL_PX, draw_legend, linear_mesh, linear_tick_labels, padded, tick_label, title_font_px, with_legend_room,
    y_label_area_px,
};

pub(super) struct RatePlot {
    pub(super) title: String,
    /// What the rates are taken from: `ref_dph`, or each trace's own mean.
    pub(super) y_desc: &'static str,
    pub(super) raw: Vec<(f64, f64)>,
    pub(super) comp: Vec<(f64, f64)>,
    /// The compensated 10-s means holding a sample clamped to the training range (flag 1).
    pub(super) clamped: Vec<(f64, f64)>,
    pub(super) temp: Vec<(f64, f64)>,
}

impl Figure for RatePlot {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_rate(root, self)
    }
}

pub(super) fn draw_rate<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &RatePlot) -> DrawResult
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
    linear_mesh(&mut chart).x_desc("time [h]").y_desc(p.y_desc).draw()?;
    chart
        .configure_secondary_axes()
        .y_label_formatter(&tick_label)
        .y_desc("loop temperature [°C]")
        .draw()?;
    let hours = |v: &Vec<(f64, f64)>| v.iter().map(|&(t, y)| (t / 3600.0, y)).collect::<Vec<_>>();
    chart
        .draw_series(LineSeries::new(hours(&p.raw), palette::BEFORE))?
        .label("raw")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], palette::BEFORE));
    chart
        .draw_series(LineSeries::new(hours(&p.comp), palette::AFTER))?
        .label("compensated")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], palette::AFTER));
    if !p.clamped.is_empty() {
        chart
            .draw_series(
                hours(&p.clamped)
                    .into_iter()
                    .map(|point| Cross::new(point, 3, palette::CLAMPED)),
            )?
            .label("compensated, inputs clamped to the training range (flag 1)")
            .legend(|(x, y)| Cross::new((x + 10, y), 3, palette::CLAMPED));
    }
    chart
        .draw_secondary_series(LineSeries::new(hours(&p.temp), palette::TEMPERATURE))?
        .label("loop temperature (right axis)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], palette::TEMPERATURE));
    draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
