//! The bias-against-temperature plot: the measured bias (10-s means) against the loop
//! temperature, coloured by ramp direction, with the model overlaid, and the residual.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::canvas::{DrawResult, Figure, SIZE, plot_height_px, range};
use crate::plotting::axes::{
    TICK_LABEL_PX, draw_legend, linear_mesh, linear_tick_labels, padded, title_font_px, with_legend_room,
    y_label_area_px,
};

/// Below this |dT/dt|, °C/min, the loop temperature counts as steady.
pub(super) const STEADY_C_PER_MIN: f64 = 0.05;

/// Which way the loop temperature is moving at a plotted point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Ramp {
    Heating,
    Cooling,
    Steady,
}

impl Ramp {
    /// The direction of `rate_c_per_min`.
    pub(super) fn of(rate_c_per_min: f64) -> Ramp {
        if rate_c_per_min > STEADY_C_PER_MIN {
            Ramp::Heating
        } else if rate_c_per_min < -STEADY_C_PER_MIN {
            Ramp::Cooling
        } else {
            Ramp::Steady
        }
    }

    pub(super) fn colour(self) -> RGBColor {
        match self {
            Ramp::Heating => super::palette::HEATING,
            Ramp::Cooling => super::palette::COOLING,
            Ramp::Steady => super::palette::STEADY,
        }
    }

    pub(super) fn label(self) -> &'static str {
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
pub(super) struct BiasPoint {
    pub(super) temp_c: f64,
    pub(super) measured_dph: f64,
    pub(super) model_dph: f64,
    pub(super) residual_dph: f64,
    pub(super) ramp: Ramp,
}

/// The points of the bias-against-temperature plot from aligned 10-s means
/// (`temp`, `raw`, `model`, `comp`: (time s, value)); the ramp direction from
/// the temperature's central difference.
pub(super) fn bias_points(
    temp: &[(f64, f64)],
    raw: &[(f64, f64)],
    model: &[(f64, f64)],
    comp: &[(f64, f64)],
) -> Vec<BiasPoint> {
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
pub(super) struct BiasTempPlot {
    pub(super) title: String,
    pub(super) points: Vec<BiasPoint>,
}

impl Figure for BiasTempPlot {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        draw_bias_temp(root, self)
    }
}

pub(super) fn draw_bias_temp<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &BiasTempPlot) -> DrawResult
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
    linear_mesh(&mut chart).y_desc("bias [°/h] (10-s means)").draw()?;
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
    draw_legend(&mut chart)?;
    let mut residual = ChartBuilder::on(&bottom)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(y_label_px)
        .build_cartesian_2d(t_lo..t_hi, r_lo..r_hi)?;
    linear_mesh(&mut residual)
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
