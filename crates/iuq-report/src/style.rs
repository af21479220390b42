//! The figures' look: one colour per source, the font, and text sizes.
//!
//! The colour of a source depends only on its name, so the GP surrogate is blue and the cell
//! model orange in every figure; the measurements are black.

use std::sync::OnceLock;

use plotters::style::{FontStyle, RGBColor, register_font};

use crate::error::{ReportError, Result};

/// The font family every figure asks for; PNG text is drawn with the embedded DejaVu Sans
/// registered under this name, SVG text names it for the viewer.
pub(crate) const FONT: &str = "sans-serif";
/// Size of figure and panel titles, in pixels.
pub(crate) const TITLE_SIZE: u32 = 23;
/// Size of axis descriptions.
pub(crate) const AXIS_LABEL_SIZE: u32 = 19;
/// Size of tick labels.
pub(crate) const TICK_SIZE: u32 = 16;
/// Size of legend entries.
pub(crate) const LEGEND_SIZE: u32 = 17;

/// Colour of the measurements.
pub(crate) const DATA_COLOUR: RGBColor = RGBColor(0, 0, 0);
/// Colour of the Gaussian-process surrogate (matplotlib's "tab:blue").
pub(crate) const SURROGATE_COLOUR: RGBColor = RGBColor(31, 119, 180);
/// Colour of the cell model and of direct model runs ("tab:orange").
pub(crate) const MODEL_COLOUR: RGBColor = RGBColor(255, 127, 14);
/// Colours of further sources, in order ("tab:green", "tab:red", "tab:purple", "tab:brown").
const OTHER_COLOURS: [RGBColor; 4] = [
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
/// Colour of light grid lines.
pub(crate) const GRID_COLOUR: RGBColor = RGBColor(225, 225, 225);

/// The colour of a source, from its name: blue for a surrogate ("GP", "surrogate"), orange for
/// the model itself ("model", "runs"), otherwise a further colour picked by `index`.
pub(crate) fn source_colour(source: &str, index: usize) -> RGBColor {
    let name = source.to_lowercase();
    let is_word = |word: &str| {
        name.split(|c: char| !c.is_alphanumeric())
            .any(|w| w == word)
    };
    if is_word("gp") || name.contains("surrogate") || name.contains("emulator") {
        SURROGATE_COLOUR
    } else if name.contains("model") || name.contains("runs") || name.contains("simulat") {
        MODEL_COLOUR
    } else {
        OTHER_COLOURS[index % OTHER_COLOURS.len()]
    }
}

/// The embedded font (DejaVu Sans, see `assets/DejaVuSans.LICENSE.txt`).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Registers the embedded font with plotters once per process; plotters needs it to measure
/// text (both back-ends) and to draw PNG text.
pub(crate) fn ensure_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ]
        .into_iter()
        .all(|style| register_font(FONT, style, FONT_BYTES).is_ok())
    });
    if ok { Ok(()) } else { Err(ReportError::Font) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_keep_their_colour() {
        assert_eq!(source_colour("GP surrogate", 0), SURROGATE_COLOUR);
        assert_eq!(source_colour("surrogate", 3), SURROGATE_COLOUR);
        assert_eq!(source_colour("cell model", 0), MODEL_COLOUR);
        assert_eq!(source_colour("model runs", 1), MODEL_COLOUR);
        assert_ne!(source_colour("other", 0), source_colour("other", 1));
    }

    #[test]
    fn the_embedded_font_registers() {
        assert!(ensure_font().is_ok());
    }
}
