//! Axis ranges and tick labels the plots share (report and plan): room
//! above the data for the legend, so that it never covers a trace, margins
//! so that no trace touches the frame, and tick labels as an engineer
//! writes numbers (`0`, `10000`, `0.25`; never `-0.0` or `10000.0`).
//! Logarithmic axes get their ticks here too ([`log_ticks`]): plotters'
//! own put a light line on the next decade (a doubled label there) and
//! stack a hundred light lines per decade on a short axis.

use plotters::chart::{ChartContext, MeshStyle, SeriesLabelPosition};
use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::ranged1d::Ranged;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::drawing::DrawingAreaErrorKind;
use plotters::prelude::{BLACK, Color, DrawingArea, DrawingBackend, IntoTextStyle, WHITE};

/// A title's font size, px, unless it must shrink to fit.
pub const TITLE_PX: f64 = 22.0;
/// The smallest a title's font shrinks to, px.
pub const MIN_TITLE_PX: f64 = 11.0;
/// Room left on each side of a title, px.
const TITLE_SIDE_PX: u32 = 8;

/// The largest font size up to [`TITLE_PX`] at which `title` fits the width
/// of `area` (which plotters would otherwise clip on both sides), px; at
/// least [`MIN_TITLE_PX`].
pub fn title_font_px<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str) -> f64 {
    let room = area.dim_in_pixel().0.saturating_sub(2 * TITLE_SIDE_PX);
    let mut px = TITLE_PX;
    while px > MIN_TITLE_PX {
        match area.estimate_text_size(title, &("sans-serif", px).into_text_style(area)) {
            Ok((width, _)) if width > room => px -= 1.0,
            _ => break,
        }
    }
    px
}

/// Font size of tick labels, px (plotters' default).
pub const TICK_LABEL_PX: f64 = 12.0;
/// Room a y label area keeps beside its tick labels, px: the rotated axis
/// description, the tick marks and the gaps plotters leaves between them.
const Y_DESC_ROOM_PX: u32 = 38;

/// Width of the label area of a y axis whose tick labels are `labels`,
/// written at `font_px`, px: the widest of them beside the axis's
/// description, so that neither is clipped nor overlaps the other; at
/// least `min_px`.
pub fn y_label_area_px<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: impl IntoIterator<Item = String>,
    font_px: f64,
    min_px: u32,
) -> u32 {
    let style = ("sans-serif", font_px).into_text_style(area);
    let widest = labels
        .into_iter()
        .filter_map(|l| area.estimate_text_size(&l, &style).ok())
        .map(|(width, _)| width)
        .max()
        .unwrap_or(0);
    (widest + Y_DESC_ROOM_PX).max(min_px)
}

/// The tick labels plotters writes on a linear axis over `lo` … `hi`
/// ([`LINEAR_TICKS`] key points, as [`tick_label`] writes them).
pub fn linear_tick_labels(lo: f64, hi: f64) -> Vec<String> {
    RangedCoordf64::from(lo..hi)
        .key_points(LINEAR_TICKS)
        .iter()
        .map(tick_label)
        .collect()
}

/// Labelled ticks of a linear axis at most (plotters' default).
pub const LINEAR_TICKS: usize = 11;
/// Closest two light grid lines come, px: closer, they stack into a grey band.
pub const MIN_LIGHT_LINE_GAP_PX: u32 = 8;

/// How many light grid lines plotters may draw per labelled tick of a
/// linear axis `axis_px` long ([`MIN_LIGHT_LINE_GAP_PX`] apart at the least;
/// none on a short axis).
pub fn light_lines(axis_px: u32) -> usize {
    (axis_px / MIN_LIGHT_LINE_GAP_PX) as usize / LINEAR_TICKS
}

/// [`light_lines`] for the x and the y axis of a plot whose plotting area is `area`.
pub fn light_lines_of<DB: DrawingBackend, CT: CoordTranslate>(area: &DrawingArea<DB, CT>) -> (usize, usize) {
    let (width_px, height_px) = area.dim_in_pixel();
    (light_lines(width_px), light_lines(height_px))
}

/// The grid and tick labels of a plot whose two axes are linear: light
/// lines no closer than [`MIN_LIGHT_LINE_GAP_PX`], every label by
/// [`tick_label`]; the caller names the axes and draws it.
pub fn linear_mesh<'a, 'b, DB: DrawingBackend>(
    chart: &'b mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> MeshStyle<'a, 'b, RangedCoordf64, RangedCoordf64, DB> {
    let (x_light, y_light) = light_lines_of(chart.plotting_area());
    let mut mesh = chart.configure_mesh();
    mesh.x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label);
    mesh
}

/// The tick labels of a logarithmic axis over `lo` … `hi` ([`log_ticks`]).
pub fn log_tick_labels(lo: f64, hi: f64) -> Vec<String> {
    log_ticks(lo, hi).0.iter().map(tick_label).collect()
}

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

/// `lo` … `hi` widened by a margin on each side, so that no trace or marker
/// touches the frame.
pub fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let span = if hi > lo { hi - lo } else { 1.0 };
    (lo - MARGIN * span, hi + MARGIN * span)
}

/// [`padded`] on a logarithmic axis (`lo` > 0).
pub fn padded_log(lo: f64, hi: f64) -> (f64, f64) {
    let (l, h) = padded(lo.ln(), hi.ln());
    (l.exp(), h.exp())
}

/// Fewest labelled ticks a logarithmic axis shows.
const MIN_LOG_LABELS: usize = 3;

/// Ticks of a logarithmic axis over `lo` … `hi` (0 < `lo` < `hi`): the
/// labelled ones (decades when three fit; else 1-2-5; else every digit;
/// on an axis shorter than that, evenly spaced ones at a 1-2-5 step) and
/// the grid-only ones (the digits 2 … 9 of each decade not labelled). Each
/// value occurs once, so no label is written twice and no grid line drawn
/// over another.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let (k_lo, k_hi) = (lo.log10().floor() as i32 - 1, hi.log10().ceil() as i32 + 1);
    let within = |v: f64| {
        // A tick at an end that rounding put just outside still counts.
        (v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9)).then_some(v)
    };
    let over = |mantissas: &[u32]| -> Vec<f64> {
        (k_lo..=k_hi)
            .flat_map(|k| {
                mantissas
                    .iter()
                    .filter_map(move |&m| within(f64::from(m) * 10f64.powi(k)))
            })
            .collect()
    };
    let labelled = [&[1][..], &[1, 2, 5], &[1, 2, 3, 4, 5, 6, 7, 8, 9]]
        .into_iter()
        .find(|m| over(m).len() >= MIN_LOG_LABELS);
    let Some(labelled) = labelled else {
        return (evenly_spaced(lo, hi, MIN_LOG_LABELS), Vec::new());
    };
    let grid: Vec<u32> = (2..=9).filter(|m| !labelled.contains(m)).collect();
    (over(labelled), over(&grid))
}

/// At least `count` multiples of one step 1, 2 or 5 × 10ⁿ within `lo` … `hi`
/// (`lo` < `hi`): the largest such step that fits `count` of them.
fn evenly_spaced(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    let most = (hi - lo) / count as f64;
    let decade = 10f64.powf(most.log10().floor());
    let step = [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|&s| s <= most)
        .unwrap_or(decade);
    let first = (lo / step).ceil() as i64;
    (first..)
        .map(|k| k as f64 * step)
        .take_while(|&v| v <= hi * (1.0 + 1e-9))
        .collect()
}

/// Combining marks the plots name in words, with the words: the PNG's
/// font draws a combining mark not at all, so T̂ would read as T.
const COMBINING_WORDS: [(char, &str); 5] = [
    ('\u{302}', "-hat"),
    ('\u{304}', "-bar"),
    ('\u{303}', "-tilde"),
    ('\u{307}', "-dot"),
    ('\u{308}', "-ddot"),
];

/// Whether `c` is a combining mark (drawn on the character before it).
pub fn is_combining(c: char) -> bool {
    matches!(c, '\u{300}'..='\u{36F}' | '\u{1AB0}'..='\u{1AFF}' | '\u{1DC0}'..='\u{1DFF}' | '\u{20D0}'..='\u{20FF}' | '\u{FE20}'..='\u{FE2F}')
}

/// Text as the plots' fonts can draw it: a letter with a combining mark
/// written with the mark's word after it (T̂ as `T-hat`, T̄ as `T-bar`), the
/// same words on every plot; a mark without a word is left out.
pub fn drawable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if !is_combining(c) {
            out.push(c);
        } else if let Some((_, word)) = COMBINING_WORDS.iter().find(|(mark, _)| *mark == c) {
            out.push_str(word);
        }
    }
    out
}

/// A tick label: at most 4 significant digits, no trailing zeros, `0` for
/// zero of either sign.
pub fn tick_label(v: &f64) -> String {
    if v.abs() < 1e-12 {
        return "0".to_owned();
    }
    let label = crate::describe::summary::sig(*v, 4);
    // Exponent form keeps its digits (tables align them); a tick label drops them.
    match label.split_once('e') {
        Some((mantissa, exponent)) if mantissa.contains('.') => {
            format!("{}e{exponent}", mantissa.trim_end_matches('0').trim_end_matches('.'))
        }
        _ => label,
    }
}

/// Draws `chart`'s legend as every plot of the project places it: upper
/// right, on a translucent white box with a black border.
pub fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
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
    fn a_short_log_axis_is_labelled_below_its_first_decade_and_writes_each_tick_once() {
        // 0.003 … 0.3: only 0.01 and 0.1 are decades.
        let (labels, grid) = log_ticks(0.003, 0.3);
        let text: Vec<String> = labels.iter().map(tick_label).collect();
        assert_eq!(text, ["0.005", "0.01", "0.02", "0.05", "0.1", "0.2"]);
        assert!(grid.iter().all(|g| labels.iter().all(|l| (g / l - 1.0).abs() > 1e-6)));
        // Four decades: decades labelled, the digits between them grid only, one line each.
        let (labels, grid) = log_ticks(0.1, 20000.0);
        let text: Vec<String> = labels.iter().map(tick_label).collect();
        assert_eq!(text, ["0.1", "1", "10", "100", "1000", "10000"]);
        assert_eq!(grid.len(), 8 * 5 + 1, "{grid:?}");
        // Less than a decade: every digit.
        let (labels, _) = log_ticks(2.5, 9.5);
        assert_eq!(
            labels.iter().map(tick_label).collect::<Vec<_>>(),
            ["3", "4", "5", "6", "7", "8", "9"]
        );
    }

    #[test]
    fn margins_keep_the_data_off_the_frame() {
        let (lo, hi) = padded(0.0, 8.0);
        assert!(lo < 0.0 && hi > 8.0 && lo > -1.0 && hi < 9.0, "{lo} … {hi}");
        let (lo, hi) = padded_log(0.1, 10000.0);
        assert!(lo < 0.1 && hi > 10000.0 && lo > 0.05 && hi < 20000.0, "{lo} … {hi}");
    }

    #[test]
    fn every_log_axis_has_three_labels_each_once_however_short() {
        for (lo, hi) in [
            (3.1, 4.9),
            (0.0021, 0.0029),
            (0.0015, 0.08),
            (0.002, 0.099),
            (0.11, 0.19),
            (1.0, 1.05),
            (0.7, 20000.0),
        ] {
            let (labels, grid) = log_ticks(lo, hi);
            assert!(labels.len() >= MIN_LOG_LABELS, "{lo} … {hi}: {labels:?}");
            assert!(
                labels
                    .iter()
                    .chain(&grid)
                    .all(|v| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9)),
                "{lo} … {hi}: a tick outside"
            );
            let mut text: Vec<String> = labels.iter().chain(&grid).map(tick_label).collect();
            let all = text.len();
            text.sort();
            text.dedup();
            assert_eq!(text.len(), all, "{lo} … {hi}: a tick twice: {labels:?} {grid:?}");
        }
        let (labels, _) = log_ticks(3.1, 4.9);
        assert_eq!(labels.iter().map(tick_label).collect::<Vec<_>>(), ["3.5", "4", "4.5"]);
    }

    #[test]
    fn combining_marks_the_font_lacks_are_written_as_words() {
        assert_eq!(
            drawable("mean coil temperature T\u{302} [°C]"),
            "mean coil temperature T-hat [°C]"
        );
        assert_eq!(drawable("T\u{304} = T − L·ΔT₃ [°C]"), "T-bar = T − L·ΔT₃ [°C]");
        assert_eq!(drawable("ΔT [°C/min]"), "ΔT [°C/min]");
        assert!(!drawable("a\u{301}\u{20D7}").chars().any(is_combining));
    }

    #[test]
    fn tick_labels_read_as_numbers_are_written() {
        assert_eq!(tick_label(&-0.0), "0");
        assert_eq!(tick_label(&10000.0), "10000");
        assert_eq!(tick_label(&0.25), "0.25");
        assert_eq!(tick_label(&-1e-17), "0");
        assert_eq!(tick_label(&-2e-5), "-2e-5");
        assert_eq!(tick_label(&1.25e-5), "1.25e-5");
        assert_eq!(tick_label(&1.5e7), "1.5e7");
    }
}
