//! What every plot of the report shares: the [`Figure`] trait a plot implements, its
//! rendering as SVG text and PNG bytes ([`render`]), the plot size, and the running
//! block means and value ranges the plots are drawn from.

use plotters::coord::Shift;
use plotters::prelude::*;

/// Plot size, pixels.
pub(super) const SIZE: (u32, u32) = (1000, 560);
/// Averaging of the plotted rate, s (keeps days of 100 Hz data drawable).
pub(super) const PLOT_MEAN_S: f64 = 10.0;

pub(super) type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// A plot that can be drawn on any plotters backend.
pub(super) trait Figure {
    /// Draws the plot onto `root`.
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// `figure` drawn as SVG text and as PNG bytes.
pub(super) fn render(figure: &impl Figure) -> anyhow::Result<(String, Vec<u8>)> {
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
pub(super) struct BlockMeans {
    pub(super) block_s: f64,
    pub(super) t0: Option<f64>,
    pub(super) sum_t: f64,
    pub(super) sum_v: f64,
    pub(super) n: f64,
    pub(super) out: Vec<(f64, f64)>,
}

impl BlockMeans {
    pub(super) fn new(block_s: f64) -> Self {
        BlockMeans {
            block_s,
            ..BlockMeans::default()
        }
    }

    pub(super) fn push(&mut self, t: f64, v: f64) {
        let t0 = *self.t0.get_or_insert(t);
        if t - t0 >= self.block_s && self.n > 0.0 {
            self.out.push((self.sum_t / self.n, self.sum_v / self.n));
            (self.t0, self.sum_t, self.sum_v, self.n) = (Some(t), 0.0, 0.0, 0.0);
        }
        self.sum_t += t;
        self.sum_v += v;
        self.n += 1.0;
    }

    pub(super) fn finish(mut self) -> Vec<(f64, f64)> {
        if self.n > 0.0 {
            self.out.push((self.sum_t / self.n, self.sum_v / self.n));
        }
        self.out
    }
}

/// The height of the plotting area of a chart on `area`, px: the area less
/// the label areas and captions below and above it (`reserved_px`) and the margins.
pub(super) fn plot_height_px<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, reserved_px: u32) -> u32 {
    area.dim_in_pixel().1.saturating_sub(reserved_px + 24).max(1)
}

pub(super) fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if lo.is_finite() && hi > lo {
        (lo, hi)
    } else {
        (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0)
    }
}
