//! The settled-bias plot of a soak test: each plateau's settled bias
//! ([`crate::dataset::plateaus`]) against its loop temperature, before
//! compensation (top) and after (bottom), with error bars of ±2× the noise of
//! the mean, and the spread in the title. A plateau outside the model's
//! training range ([`crate::dataset::plateaus::SettledPlateau::outside_range`])
//! is drawn hollow after compensation: its settled bias there is the model's
//! extrapolation.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::canvas::{DrawResult, Figure, SIZE, range};
use crate::dataset::plateaus::SettledBias;
use crate::plotting::axes::{TICK_LABEL_PX, linear_mesh, linear_tick_labels, padded, title_font_px, y_label_area_px};

/// The error bars' half-height, in noises of the mean (about 95 %).
pub(super) const ERROR_BAR_NOISES: f64 = 2.0;

/// Settled bias against loop temperature, before and after compensation.
pub(super) struct SettledPlot<'a> {
    pub(super) title: String,
    pub(super) settled: &'a SettledBias,
}

/// The words a title or report.md gives the spread: `spread 1.234 → 0.0123 °/h`
/// or why there is none.
pub(super) fn spread_words(settled: &SettledBias) -> String {
    match (settled.settled_spread_before_dph, settled.settled_spread_dph) {
        (Some(before), Some(after)) => format!(
            "settled spread {before:.3} → {after:.4} °/h over {} plateaus{}",
            settled.plateaus.len(),
            crate::evaluation::table::in_range_words(settled)
        ),
        _ if settled.plateaus.len() == 1 => "one settled plateau, no spread".to_owned(),
        _ => crate::evaluation::table::NO_PLATEAU.to_owned(),
    }
}

impl Figure for SettledPlot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled(&self.title, ("sans-serif", title_font_px(&root, &self.title)))?;
        let (top, bottom) = root.split_vertically((SIZE.1 as f64 * 0.5) as u32);
        let plateaus = &self.settled.plateaus;
        let (t_lo, t_hi) = padded_range(plateaus.iter().map(|p| p.temp_c));
        let bars = |bias: fn(&crate::dataset::plateaus::SettledPlateau) -> (f64, f64)| {
            plateaus
                .iter()
                .map(|p| {
                    let (b, noise) = bias(p);
                    let half = ERROR_BAR_NOISES * if noise.is_finite() { noise } else { 0.0 };
                    (p.temp_c, b - half, b, b + half, p.outside_range())
                })
                .collect::<Vec<_>>()
        };
        let before = bars(|p| (p.bias_before_dph, p.noise_before_dph));
        let after = bars(|p| (p.bias_after_dph, p.noise_dph));
        let y_range = |bars: &[Bar]| padded_range(bars.iter().flat_map(|b| [b.1, b.3]));
        let (b_lo, b_hi) = y_range(&before);
        let (a_lo, a_hi) = y_range(&after);
        // One width for both panels, so that their temperature axes line up.
        let labels = linear_tick_labels(b_lo, b_hi)
            .into_iter()
            .chain(linear_tick_labels(a_lo, a_hi));
        let y_label_px = y_label_area_px(&root, labels, TICK_LABEL_PX, 80);
        let panels = [
            (
                &top,
                &before,
                (b_lo, b_hi),
                "before [°/h]",
                super::palette::BEFORE,
                30,
                false,
            ),
            (
                &bottom,
                &after,
                (a_lo, a_hi),
                "after [°/h]",
                super::palette::AFTER,
                40,
                true,
            ),
        ];
        for (area, bars, (lo, hi), y_desc, colour, x_label_px, hollow_outside) in panels {
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(x_label_px)
                .y_label_area_size(y_label_px)
                .build_cartesian_2d(t_lo..t_hi, lo..hi)?;
            let mut mesh = linear_mesh(&mut chart);
            let mesh = mesh.y_desc(format!("settled bias {y_desc}"));
            if x_label_px == 40 {
                mesh.x_desc(
                    "loop temperature T [°C] (settled window: last 30 min of a plateau; hollow: outside the model's \
                     training range)",
                )
                .draw()?;
            } else {
                mesh.draw()?;
            }
            // Error bars: a line from lo to hi with short caps (plotters' ErrorBar
            // sits behind a feature the workspace does not turn on).
            let cap_c = 0.006 * (t_hi - t_lo);
            chart.draw_series(bars.iter().flat_map(|&(t, lo, _, hi, _)| {
                [
                    PathElement::new(vec![(t, lo), (t, hi)], colour.stroke_width(2)),
                    PathElement::new(vec![(t - cap_c, lo), (t + cap_c, lo)], colour.stroke_width(2)),
                    PathElement::new(vec![(t - cap_c, hi), (t + cap_c, hi)], colour.stroke_width(2)),
                ]
            }))?;
            chart.draw_series(bars.iter().map(|&(t, _, mid, _, outside)| {
                let style = if outside && hollow_outside {
                    colour.stroke_width(1)
                } else {
                    colour.filled()
                };
                Circle::new((t, mid), 3, style)
            }))?;
        }
        root.present()?;
        Ok(())
    }
}

/// One plateau's error bar: its temperature, °C; the bar's low end, middle
/// and high end, °/h; whether it lies outside the model's training range.
type Bar = (f64, f64, f64, f64, bool);

/// The range of `values`, padded; a range about a single value or none widened.
fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let values: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    let (lo, hi) = range(values.iter().copied());
    if values.len() == 1 || (hi - lo) < 1e-12 {
        let half = (0.05 * lo.abs()).max(1e-3);
        return padded(lo - half, hi + half);
    }
    padded(lo, hi)
}
