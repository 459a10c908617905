//! Pictures: turning radiosity into things people look at.
//!
//! Layers, each usable on its own:
//! - [`camera`] and [`render`]: views through a pinhole camera (shaded, flat, by patch, by error), given a
//!   closest-hit function (the Embree module, or any other intersector).
//! - [`tonemap`]: linear radiosity (W/m^2) -> display values: an exposure, the extended Reinhard operator, and the
//!   sRGB transfer function (IEC 61966-2-1); 8-bit RGB images and PNG files ([`RgbImage`], [`write_png`]).
//! - [`hdr`]: linear (HDR) image files, Radiance `.hdr` (RGBE), PFM and OpenEXR, written and read back.
//! - [`shading`]: smooth shading: per-patch radiosity -> per-vertex values -> a value at any point of a patch.
//! - [`lightmap`]: per-face light-map atlases (linear `.exr` and `.hdr`, tone-mapped PNG, and a JSON placement map).
//! - [`glb`]: binary glTF 2.0 export of the patches with light-map UVs and the light map embedded.
//! - [`colormap`]: a perceptually ordered false-colour map for errors, and its legend strip.
//! - [`plot`]: report plots (error against work, error decomposition bars, patch-size histogram) as SVG and PNG.
//! - [`text`]: the font of plots and legends, and their tick labels (used by [`colormap`] and [`plot`]).
//!
//! Text in PNG plots and legends is drawn with the DejaVu Sans font from Debian's `fonts-dejavu-core` package
//! (installed by `scripts/deps.sh`), loaded at run time from [`text::DEFAULT_FONT_PATH`] or the path in the
//! `RADIOSITY_FONT` environment variable; a missing font is a clear [`PictureError::Font`].

pub mod camera;
pub mod colormap;
pub mod glb;
pub mod hdr;
pub mod lightmap;
pub mod plot;
pub mod render;
pub mod shading;
pub mod text;
pub mod tonemap;

use std::path::{Path, PathBuf};

pub use tonemap::{RgbImage, ToneMap};

/// Errors from the picture modules. Every variant names what was wrong and where.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PictureError {
    /// A value that must be finite was NaN or infinite.
    #[error("{what} {index} is not finite ({value})")]
    NonFinite {
        /// What the value is (e.g. "radiosity of patch").
        what: &'static str,
        /// Index of the offending element.
        index: usize,
        /// The value itself.
        value: f64,
    },
    /// An argument was out of its documented range or inconsistent with another.
    #[error("invalid {what}: {reason}")]
    Invalid {
        /// The argument or input concerned.
        what: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file could be read but its contents are not in the expected format.
    #[error("{path}: {reason}")]
    Format {
        /// The file (or `<memory>` for in-memory data).
        path: PathBuf,
        /// What is wrong, and where in the file.
        reason: String,
    },
    /// PNG encoding failed.
    #[error("PNG encoding of {path}: {reason}")]
    Png {
        /// The file being written.
        path: PathBuf,
        /// The encoder's message.
        reason: String,
    },
    /// The font for text in plots and legends could not be loaded.
    #[error("font {path}: {reason} (install Debian's fonts-dejavu-core, run scripts/deps.sh, or set RADIOSITY_FONT)")]
    Font {
        /// The font file tried.
        path: PathBuf,
        /// Why it failed.
        reason: String,
    },
    /// The plotting library reported an error.
    #[error("plot {what}: {reason}")]
    Plot {
        /// Which plot.
        what: String,
        /// The plotting library's message.
        reason: String,
    },
}

impl PictureError {
    pub(crate) fn invalid(what: &'static str, reason: impl Into<String>) -> Self {
        PictureError::Invalid { what, reason: reason.into() }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        PictureError::Io { path: path.to_path_buf(), source }
    }
}

/// Encodes an 8-bit RGB image as PNG bytes (colour type RGB, bit depth 8, sRGB chunk set: the pixel values are
/// sRGB-encoded as produced by [`tonemap::srgb_encode_u8`]).
///
/// # Errors
/// [`PictureError::Png`] if the encoder fails (it does not for a consistent image).
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>, PictureError> {
    let mut out = Vec::new();
    let png_err =
        |e: png::EncodingError| PictureError::Png { path: PathBuf::from("<memory>"), reason: e.to_string() };
    {
        let mut encoder = png::Encoder::new(&mut out, image.width, image.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(png_err)?;
        writer.write_image_data(&image.pixels).map_err(png_err)?;
        writer.finish().map_err(png_err)?;
    }
    Ok(out)
}

/// Writes an 8-bit RGB image as a PNG file (see [`encode_png`]).
///
/// # Errors
/// [`PictureError::Io`] if the file cannot be written, [`PictureError::Png`] if encoding fails.
pub fn write_png(path: &Path, image: &RgbImage) -> Result<(), PictureError> {
    let bytes = encode_png(image).map_err(|e| match e {
        PictureError::Png { reason, .. } => PictureError::Png { path: path.to_path_buf(), reason },
        other => other,
    })?;
    write_file(path, &bytes)
}

/// Writes bytes to a file atomically ([`crate::files::write_atomic`]), naming the path in the error.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), PictureError> {
    crate::files::write_atomic(path, bytes).map_err(|e| match e {
        crate::files::FileError::Io { source, .. } => PictureError::io(path, source),
        other => PictureError::io(path, std::io::Error::other(other.to_string())),
    })
}
