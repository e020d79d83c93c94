//! PNG charts drawn in Rust: the setup every esgm chart shares (esgm-bench's
//! `--plots`, `esgm plot`).
//!
//! ## Design decisions
//! - **A bundled font.** Text is rasterised by `ab_glyph` (a `plotters` feature) from
//!   DejaVu Sans in `assets/` (Bitstream Vera licence beside it), registered under
//!   [`FAMILY`] by [`register_font`]. No system font library (fontconfig, freetype) is
//!   needed to build or to draw, so charts come out the same on every machine.
//! - **The bitmap backend only**: PNG files, no SVG or GUI backends to build.
//! - **One palette** ([`color`]), so a series looks the same in every esgm chart.
#![deny(missing_docs)]

pub mod graph;

pub use plotters;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font as register};

/// The font family every chart's text uses; [`register_font`] makes it available.
pub const FAMILY: &str = "sans-serif";

/// DejaVu Sans, the bundled font.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// The picture size of a chart, in pixels.
pub const SIZE: (u32, u32) = (1000, 650);

/// Why a chart could not be drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ChartError {
    /// The bundled font could not be read: the build is broken (report it).
    #[error("the bundled font could not be read")]
    Font,
    /// Drawing or writing the picture failed (most often: the file cannot be written
    /// where asked; check the path).
    #[error("drawing the chart failed: {reason}")]
    Draw {
        /// What plotters reported.
        reason: String,
    },
}

impl ChartError {
    /// A plotters drawing error as a [`ChartError::Draw`].
    pub fn draw(e: impl std::fmt::Display) -> Self {
        ChartError::Draw { reason: e.to_string() }
    }
}

/// Registers the bundled font as [`FAMILY`]; call before drawing text (again is
/// harmless).
pub fn register_font() -> Result<(), ChartError> {
    register(FAMILY, FontStyle::Normal, FONT).map_err(|_| ChartError::Font)
}

/// The `i`-th colour of the palette (matplotlib's ten), repeating.
pub fn color(i: usize) -> RGBColor {
    const COLORS: [RGBColor; 10] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(23, 190, 207),
        RGBColor(127, 127, 127),
        RGBColor(188, 189, 34),
    ];
    COLORS[i % COLORS.len()]
}

/// `0.5`, `2`, `150`: an axis label without trailing zeros.
pub fn number_label(v: f64) -> String {
    if v == 0.0 {
        "0".to_owned()
    } else if v.abs() >= 10.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}").trim_end_matches(".0").to_owned()
    } else {
        format!("{v:.2}")
    }
}

/// The axis range of `values` with a little room, never empty: a flat or empty series
/// still gets an axis (`esgm plot`, `esgm soak`).
pub fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = if hi > lo { (hi - lo) * 0.05 } else { lo.abs().max(1.0) * 0.5 };
    (lo - pad, hi + pad)
}

/// Draws the legend at `position` and writes the picture: how every chart ends.
pub fn finish<'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
    root: &DrawingArea<BitMapBackend<'a>, Shift>,
    position: SeriesLabelPosition,
) -> Result<(), ChartError> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FAMILY, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(ChartError::draw)?;
    root.present().map_err(ChartError::draw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_and_palette() {
        assert_eq!(number_label(0.5), "0.50");
        assert_eq!(number_label(0.0), "0");
        assert_eq!(number_label(2.0), "2");
        assert_eq!(number_label(-150.0), "-150");
        assert_eq!(color(0), color(10));
    }

    #[test]
    fn axes_are_never_empty() {
        assert_eq!(bounds(std::iter::empty()), (0.0, 1.0));
        assert_eq!(bounds([2.0].into_iter()), (1.0, 3.0));
        let (lo, hi) = bounds([0.0, 10.0].into_iter());
        assert!(lo < 0.0 && hi > 10.0);
    }

    #[test]
    fn the_bundled_font_draws_text_into_a_png() -> Result<(), Box<dyn std::error::Error>> {
        register_font()?;
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("t.png");
        {
            let root = BitMapBackend::new(&path, (200, 100)).into_drawing_area();
            root.fill(&WHITE).map_err(ChartError::draw)?;
            root.draw_text("esgm", &(FAMILY, 20).into_text_style(&root), (10, 10))
                .map_err(ChartError::draw)?;
            root.present().map_err(ChartError::draw)?;
        }
        assert!(std::fs::read(&path)?.starts_with(b"\x89PNG"));
        Ok(())
    }
}
