//! Tone mapping: linear radiosity -> display pixels.
//!
//! The pipeline for one pixel with linear RGB radiosity `c` (W/m^2):
//! 1. **Exposure**: `c' = scale * c`. The scale is given, or chosen by [`ToneMap::from_percentile`] so that a
//!    high percentile of the visible luminances (95th by default: a bright surface, not the few pixels of a light)
//!    lands on exposed luminance 1, which displays as `(1 + 1 / L_white^2) / 2` (0.53 linear, sRGB 194 with the
//!    default `L_white = 4`). Luminances from `L_white` times that percentile up (the lights) burn out to white;
//!    everything below keeps its contrast.
//! 2. **Operator**: the extended Reinhard operator on luminance (Reinhard, Stark, Shirley, Ferwerda, "Photographic
//!    Tone Reproduction for Digital Images", SIGGRAPH 2002, eq. 4): `L_d = L (1 + L / L_white^2) / (1 + L)`, with
//!    `L = Y(c')` the Rec. 709 luminance `0.2126 R + 0.7152 G + 0.0722 B` ([`luminance`]; ITU-R BT.709, the sRGB
//!    primaries).
//!    The colour is scaled by `L_d / L`, which keeps its hue and saturation; channels above 1 are then clipped.
//!    `L_white` is the exposed luminance that maps to exactly 1.
//! 3. **Encoding**: the sRGB opto-electronic transfer function (IEC 61966-2-1:1999):
//!    `V = 12.92 v` for `v <= 0.0031308`, else `V = 1.055 v^(1/2.4) - 0.055`, then `round(255 V)`.
//!
//! Negative inputs (a device answer slightly below zero) are treated as zero: they display as black. NaN and
//! infinities are refused with an error naming the pixel.

use super::PictureError;
use crate::rgb::{luminance, Rgb};

/// The sRGB transfer function (IEC 61966-2-1), linear `[0, 1]` -> encoded `[0, 1]`. Inputs are clamped to `[0, 1]`
/// (NaN maps to 0).
#[must_use]
pub fn srgb_encode(linear: f64) -> f64 {
    let v = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse sRGB transfer function, encoded `[0, 1]` -> linear `[0, 1]` (inputs clamped to `[0, 1]`).
#[must_use]
pub fn srgb_decode(encoded: f64) -> f64 {
    let v = if encoded.is_nan() { 0.0 } else { encoded.clamp(0.0, 1.0) };
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// [`srgb_encode`] quantized to 8 bits: `round(255 V)`.
#[must_use]
pub fn srgb_encode_u8(linear: f64) -> u8 {
    // srgb_encode returns a value in [0, 1], so the product is in [0, 255] and the cast cannot truncate.
    (srgb_encode(linear) * 255.0).round() as u8
}

/// An 8-bit sRGB image, rows top to bottom, 3 bytes (R, G, B) per pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `3 * width * height` bytes, row-major from the top-left pixel.
    pub pixels: Vec<u8>,
}

impl RgbImage {
    /// A black image.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        RgbImage { width, height, pixels: vec![0; 3 * width as usize * height as usize] }
    }

    /// Sets pixel `(x, y)` (from the top-left).
    ///
    /// # Panics
    /// If `(x, y)` is outside the image.
    pub fn put(&mut self, x: u32, y: u32, rgb: [u8; 3]) {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}x{}", self.width, self.height);
        let i = 3 * (y as usize * self.width as usize + x as usize);
        self.pixels[i..i + 3].copy_from_slice(&rgb);
    }

    /// Pixel `(x, y)` (from the top-left).
    ///
    /// # Panics
    /// If `(x, y)` is outside the image.
    #[must_use]
    pub fn get(&self, x: u32, y: u32) -> [u8; 3] {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}x{}", self.width, self.height);
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.pixels[i], self.pixels[i + 1], self.pixels[i + 2]]
    }
}

/// A tone-mapping operator: exposure scale and extended-Reinhard white point (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToneMap {
    /// Exposure: linear radiosity is multiplied by this before the operator (units: 1 / (W/m^2)).
    pub scale: f64,
    /// Exposed luminance that maps to display white (`L_white` in Reinhard et al. 2002, eq. 4); at least 1.
    pub white: f64,
}

impl ToneMap {
    /// Default percentile used by [`ToneMap::from_percentile`] callers that have no preference.
    pub const DEFAULT_PERCENTILE: f64 = 0.95;
    /// Default white point: luminances up to 4x the exposure percentile keep some contrast.
    pub const DEFAULT_WHITE: f64 = 4.0;

    /// A tone map with a given exposure scale and white point.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] if `scale` is not finite and positive, or `white` is not finite and at least 1.
    pub fn new(scale: f64, white: f64) -> Result<Self, PictureError> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(PictureError::invalid(
                "tone map exposure scale",
                format!("{scale} is not finite and > 0"),
            ));
        }
        if !(white.is_finite() && white >= 1.0) {
            return Err(PictureError::invalid(
                "tone map white point",
                format!("{white} is not finite and >= 1"),
            ));
        }
        Ok(ToneMap { scale, white })
    }

    /// Chooses the exposure so that the `percentile` (in `(0, 1]`) of `luminances` maps to exposed luminance 1;
    /// `white` (at least 1) is the white point in multiples of that percentile.
    ///
    /// Pass the luminances of what is visible (pixels of a view, texels of a light map, or patch values) so that
    /// hidden bright surfaces do not darken the picture. If the percentile luminance is zero (an unlit scene), the
    /// largest luminance is used; if all are zero, the scale is 1.
    ///
    /// # Errors
    /// [`PictureError::NonFinite`] if a luminance is NaN or infinite (naming its index), [`PictureError::Invalid`]
    /// if `luminances` is empty or `percentile` / `white` are out of range.
    pub fn from_percentile(luminances: &[f64], percentile: f64, white: f64) -> Result<Self, PictureError> {
        if luminances.is_empty() {
            return Err(PictureError::invalid("tone map luminances", "no values to choose an exposure from"));
        }
        if !(percentile > 0.0 && percentile <= 1.0) {
            return Err(PictureError::invalid(
                "tone map percentile",
                format!("{percentile} is not in (0, 1]"),
            ));
        }
        let mut sorted = Vec::with_capacity(luminances.len());
        for (index, &l) in luminances.iter().enumerate() {
            if !l.is_finite() {
                return Err(PictureError::NonFinite { what: "luminance", index, value: l });
            }
            sorted.push(l.max(0.0));
        }
        sorted.sort_by(f64::total_cmp);
        // Nearest-rank percentile: the smallest value with at least `percentile` of the values at or below it.
        let rank = ((percentile * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
        let mut reference = sorted[rank - 1];
        if reference <= 0.0 {
            reference = sorted[sorted.len() - 1];
        }
        let scale = if reference > 0.0 { 1.0 / reference } else { 1.0 };
        ToneMap::new(scale, white)
    }

    /// Tone maps one linear RGB value to display-linear RGB in `[0, 1]` (before sRGB encoding).
    ///
    /// # Errors
    /// [`PictureError::NonFinite`] if a channel is NaN or infinite (`index` is the channel).
    pub fn map_linear(&self, rgb: Rgb) -> Result<Rgb, PictureError> {
        for (index, v) in rgb.to_array().into_iter().enumerate() {
            if !v.is_finite() {
                return Err(PictureError::NonFinite { what: "tone map input channel", index, value: v });
            }
        }
        let c = rgb.map(|v| v.max(0.0) * self.scale);
        let l = luminance(c);
        if l <= 0.0 {
            // Only possible for black (all channels zero after clamping).
            return Ok(Rgb::ZERO);
        }
        let ld = l * (1.0 + l / (self.white * self.white)) / (1.0 + l);
        let k = ld / l;
        Ok(c.map(|v| (v * k).min(1.0)))
    }

    /// Tone maps and sRGB-encodes one linear RGB value to 8-bit sRGB.
    ///
    /// # Errors
    /// As [`ToneMap::map_linear`].
    pub fn map_srgb8(&self, rgb: Rgb) -> Result<[u8; 3], PictureError> {
        Ok(self.map_linear(rgb)?.to_array().map(srgb_encode_u8))
    }

    /// Tone maps a linear image (`width * height` RGB values, rows from the top) to an 8-bit sRGB image.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] if the length is not `width * height`; [`PictureError::NonFinite`] naming the
    /// first pixel with a NaN or infinite channel.
    pub fn map_image(&self, linear: &[Rgb], width: u32, height: u32) -> Result<RgbImage, PictureError> {
        let n = width as usize * height as usize;
        if linear.len() != n {
            return Err(PictureError::invalid(
                "linear image",
                format!("{} pixels for a {width}x{height} image ({n} expected)", linear.len()),
            ));
        }
        let mut image = RgbImage::new(width, height);
        for (index, &rgb) in linear.iter().enumerate() {
            let mapped = self.map_srgb8(rgb).map_err(|e| match e {
                PictureError::NonFinite { value, .. } => {
                    PictureError::NonFinite { what: "pixel", index, value }
                }
                other => other,
            })?;
            image.pixels[3 * index..3 * index + 3].copy_from_slice(&mapped);
        }
        Ok(image)
    }
}
