//! Axis ranges and tick labels the plots share (report and plan): room
//! above the data for the legend, so that it never covers a trace, margins
//! so that no trace touches the frame, and tick labels as an engineer
//! writes numbers (`0`, `10000`, `0.25`; never `-0.0` or `10000.0`).

/// Height of one legend row, px (plotters' default legend font and spacing).
const LEGEND_ROW_PX: f64 = 20.0;
/// The legend box's frame and its distance from the plot's top edge, px.
const LEGEND_FRAME_PX: f64 = 24.0;
/// Margin below the lowest value, as a share of the data's span.
const MARGIN: f64 = 0.04;

/// The share of a plot `plot_px` high that a legend of `rows` entries
/// takes at its top (at most 0.6).
pub fn legend_share(rows: usize, plot_px: u32) -> f64 {
    ((rows as f64 * LEGEND_ROW_PX + LEGEND_FRAME_PX) / f64::from(plot_px.max(1))).min(0.6)
}

/// A linear axis range for data `lo` … `hi` with a legend of `rows` entries
/// in the top of a plot `plot_px` high: the data lie below the legend's
/// share of the height, with a margin below.
pub fn with_legend_room(lo: f64, hi: f64, rows: usize, plot_px: u32) -> (f64, f64) {
    let span = if hi > lo { hi - lo } else { 1.0 };
    let lo = lo - MARGIN * span;
    let share = legend_share(rows, plot_px);
    (lo, lo + (hi - lo) / (1.0 - share))
}

/// [`with_legend_room`] on a logarithmic axis (`lo` > 0).
pub fn with_legend_room_log(lo: f64, hi: f64, rows: usize, plot_px: u32) -> (f64, f64) {
    let (l, h) = with_legend_room(lo.ln(), hi.ln(), rows, plot_px);
    (l.exp(), h.exp())
}

/// A tick label: at most 4 significant digits, no trailing zeros, `0` for
/// zero of either sign.
pub fn tick_label(v: &f64) -> String {
    if v.abs() < 1e-12 {
        return "0".to_owned();
    }
    crate::summary::sig(*v, 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_legend_lies_above_every_data_point() {
        for (lo, hi, rows, px) in [(-0.6, 4.7, 4, 300), (12.0, 38.0, 3, 480), (0.0, 0.0, 7, 480)] {
            let (bottom, top) = with_legend_room(lo, hi, rows, px);
            // The legend's lowest pixel, in data units.
            let legend_bottom = top - legend_share(rows, px) * (top - bottom);
            let rounding = 1e-9 * (top - bottom);
            assert!(
                legend_bottom >= hi - rounding && bottom < lo.min(hi),
                "{lo} … {hi}: {bottom} … {top}"
            );
        }
        let (bottom, top) = with_legend_room_log(1e-3, 6e-2, 7, 480);
        let legend_bottom = (top.ln() - legend_share(7, 480) * (top.ln() - bottom.ln())).exp();
        assert!(
            legend_bottom >= 6e-2 * (1.0 - 1e-12) && bottom < 1e-3,
            "{bottom} … {top}"
        );
    }

    #[test]
    fn tick_labels_read_as_numbers_are_written() {
        assert_eq!(tick_label(&-0.0), "0");
        assert_eq!(tick_label(&10000.0), "10000");
        assert_eq!(tick_label(&0.25), "0.25");
        assert_eq!(tick_label(&-1e-17), "0");
    }
}
