//! The plan drawn: set points and the predicted loop temperature, as SVG or PNG
//! ([`plot()`]).

use plotters::coord::Shift;
use plotters::prelude::*;

use super::Plan;
use super::criterion::*;
use crate::simulate::SimParams;

/// Image formats `--plot` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlotFormat {
    /// Scalable vector graphics.
    Svg,
    /// Portable network graphics.
    Png,
}

/// Plot size, pixels.
pub(super) const PLOT_SIZE: (u32, u32) = (1000, 480);

/// The plan drawn: chamber set points and the nominal loop temperature over hours.
pub fn plot(plan: &Plan, format: PlotFormat) -> anyhow::Result<Vec<u8>> {
    let temps = loop_temps(&plan.segments, &SimParams::default().plant);
    match format {
        PlotFormat::Svg => {
            let mut svg = String::new();
            draw_plan(
                SVGBackend::with_string(&mut svg, PLOT_SIZE).into_drawing_area(),
                plan,
                &temps,
            )
            .map_err(|e| anyhow::anyhow!("drawing the SVG: {e}"))?;
            Ok(svg.into_bytes())
        }
        PlotFormat::Png => {
            let mut rgb = vec![0u8; PLOT_SIZE.0 as usize * PLOT_SIZE.1 as usize * 3];
            draw_plan(
                BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area(),
                plan,
                &temps,
            )
            .map_err(|e| anyhow::anyhow!("drawing the PNG: {e}"))?;
            crate::plotting::png::encode_png(&rgb, PLOT_SIZE)
        }
    }
}

pub(super) fn draw_plan<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    plan: &Plan,
    temps: &[f64],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let l = &plan.limits;
    let hours = (plan.duration_s() / 3600.0).max(1e-3);
    let (x_lo, x_hi) = crate::plotting::axes::padded(0.0, hours);
    let (c_lo, c_hi) =
        crate::plotting::axes::with_legend_room(l.min_c, l.max_c, 2, root.dim_in_pixel().1.saturating_sub(100));
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "chamber plan {} … {} °C, ≤ {} °C/min, {:.2} h (D-criterion {:.3})",
                l.min_c, l.max_c, l.max_rate_c_per_min, hours, plan.criterion
            ),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(crate::plotting::axes::y_label_area_px(
            &root,
            crate::plotting::axes::linear_tick_labels(c_lo, c_hi),
            crate::plotting::axes::TICK_LABEL_PX,
            60,
        ))
        .build_cartesian_2d(x_lo..x_hi, c_lo..c_hi)?;
    crate::plotting::axes::linear_mesh(&mut chart)
        .x_desc("time [h]")
        .y_desc("temperature [°C]")
        .draw()?;
    let set_points: Vec<(f64, f64)> = plan.knots().iter().map(|&(t, c)| (t / 3600.0, c)).collect();
    chart
        .draw_series(LineSeries::new(set_points, RGBColor(200, 60, 40).stroke_width(2)))?
        .label("chamber set point")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(200, 60, 40)));
    let sensed: Vec<(f64, f64)> = temps
        .iter()
        .enumerate()
        .step_by(10)
        .map(|(i, &c)| (i as f64 / 3600.0, c))
        .collect();
    chart
        .draw_series(LineSeries::new(sensed, RGBColor(30, 90, 200)))?
        .label("loop sensor, nominal plant")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(30, 90, 200)));
    crate::plotting::axes::draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
