//! Text in pictures: the font that plots and legends draw with, and the tick labels they share.
//!
//! Text layout needs a font: DejaVu Sans from Debian's `fonts-dejavu-core` ([`DEFAULT_FONT_PATH`], or the file
//! named by the `RADIOSITY_FONT` environment variable), loaded once per process. Plotters' own font feature
//! (`ttf`) would need fontconfig and freetype development libraries; `ab_glyph` reads the TrueType file directly.
//! Both [`super::plot`] and [`super::colormap`] (its legend) use this module.

use std::path::PathBuf;
use std::sync::OnceLock;

use plotters::style::FontStyle;

use super::PictureError;

/// Where Debian's `fonts-dejavu-core` installs DejaVu Sans.
pub const DEFAULT_FONT_PATH: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// The font family name plots use (registered by [`ensure_font`]).
pub const FONT_FAMILY: &str = "sans-serif";

/// Loads and registers the plot font once per process.
///
/// # Errors
/// [`PictureError::Font`] if the file cannot be read or is not a font.
pub fn ensure_font() -> Result<(), PictureError> {
    static LOADED: OnceLock<Result<(), (PathBuf, String)>> = OnceLock::new();
    let result = LOADED.get_or_init(|| {
        let path = std::env::var_os("RADIOSITY_FONT")
            .map_or_else(|| PathBuf::from(DEFAULT_FONT_PATH), PathBuf::from);
        let bytes = std::fs::read(&path).map_err(|e| (path.clone(), e.to_string()))?;
        // Registered fonts live for the whole process (plotters keeps a 'static reference); this runs once.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, bytes)
            .map_err(|_| (path.clone(), "not a TrueType/OpenType font".to_string()))
    });
    result.clone().map_err(|(path, reason)| PictureError::Font { path, reason })
}

/// A short tick label: plain for moderate magnitudes, scientific otherwise.
#[must_use]
pub fn format_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        // Four significant digits, trailing zeros after the decimal point dropped.
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.0e}")
    }
}
