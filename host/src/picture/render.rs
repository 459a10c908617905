//! Views of a lit scene through a [`Camera`]: shaded, flat, coloured by patch, or coloured by error.
//!
//! Ray casting is not done here: the caller passes a closest-hit function (the Embree module in the tool, a brute
//! force intersector in tests), so this module only turns hits into pixels. Pixels whose ray hits nothing are
//! black.
//!
//! Error views colour each patch by its relative error against a reference solution (flat, so the mesh that carries
//! the error stays visible): `e_i = max_c |B_ic - R_ic| / max(max_c R_ic, floor)`, with
//! `floor = 1e-3 * max_j max_c R_jc` so nearly black patches do not dominate. The default scale is logarithmic over
//! three decades below the largest error (see [`ErrorScale`]); draw its legend with [`ErrorScale::legend`].

use glam::DVec3;
use rayon::prelude::*;

use super::camera::Camera;
use super::colormap::{patch_colour, ErrorScale};
use super::shading::SmoothShader;
use super::{PictureError, RgbImage, ToneMap};
use crate::rgb::{luminance, max_channel, Rgb};

/// A camera and an image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// The camera.
    pub camera: Camera,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// The closest hit of a primary ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index of the patch hit.
    pub patch: usize,
    /// The hit point (scene units).
    pub point: DVec3,
}

/// What a view shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Colouring<'a> {
    /// Smoothly shaded radiosity ([`SmoothShader::shade`]), tone mapped.
    Shaded,
    /// One radiosity value per patch, tone mapped (shows the mesh through the lighting).
    Flat,
    /// A distinct colour per patch ([`patch_colour`]), no lighting.
    ByPatch,
    /// Per-patch relative error against `reference`, false-coloured with `scale` (or the default scale).
    Error {
        /// The reference radiosity, one value per patch.
        reference: &'a [Rgb],
        /// The colour scale; `None` chooses the module's default.
        scale: Option<ErrorScale>,
    },
}

/// A rendered view.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The picture.
    pub image: RgbImage,
    /// Linear radiosity per pixel (zero where nothing is hit), rows from the top.
    pub linear: Vec<Rgb>,
    /// The patch seen at each pixel.
    pub patch: Vec<Option<u32>>,
    /// The tone map used (shaded and flat views).
    pub tone: Option<ToneMap>,
    /// The error scale used (error views), for the legend.
    pub error_scale: Option<ErrorScale>,
}

/// Per-patch relative error of `value` against `reference` (see the module docs).
///
/// # Errors
/// [`PictureError::Invalid`] if the lengths differ; [`PictureError::NonFinite`] naming a patch with a NaN or
/// infinite value in either.
pub fn patch_errors(value: &[Rgb], reference: &[Rgb]) -> Result<Vec<f64>, PictureError> {
    if value.len() != reference.len() {
        return Err(PictureError::invalid(
            "error view",
            format!("{} values against {} reference values", value.len(), reference.len()),
        ));
    }
    for (what, set) in [("radiosity of patch", value), ("reference radiosity of patch", reference)] {
        if let Some((index, v)) = set
            .iter()
            .enumerate()
            .find_map(|(i, b)| b.to_array().into_iter().find(|v| !v.is_finite()).map(|v| (i, v)))
        {
            return Err(PictureError::NonFinite { what, index, value: v });
        }
    }
    let peak = reference.iter().fold(0.0, |peak: f64, &r| peak.max(max_channel(r)));
    let floor = (1e-3 * peak).max(f64::MIN_POSITIVE);
    Ok(value
        .iter()
        .zip(reference)
        .map(|(&b, &r)| max_channel((b - r).abs()) / max_channel(r).max(floor))
        .collect())
}

/// The default error scale: log over three decades below the largest error (linear 0..1 if all errors are zero).
///
/// # Errors
/// [`PictureError::Invalid`] if `errors` is empty.
pub fn default_error_scale(errors: &[f64]) -> Result<ErrorScale, PictureError> {
    if errors.is_empty() {
        return Err(PictureError::invalid("error view", "no errors to scale"));
    }
    let max = errors.iter().copied().fold(0.0, f64::max);
    if max > 0.0 {
        ErrorScale::new(max * 1e-3, max, true)
    } else {
        ErrorScale::new(0.0, 1.0, false)
    }
}

/// The primary-ray hits of a view, cast once and reused for every colouring and every frame of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewHits {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The closest hit per pixel, rows from the top.
    pub hits: Vec<Option<Hit>>,
}

/// Casts the primary rays of `frame` with `trace(origin, direction)` (the closest hit), in parallel.
///
/// # Errors
/// [`PictureError::Invalid`] for a zero-sized image.
pub fn trace_view(
    frame: &Frame,
    trace: &(dyn Fn(DVec3, DVec3) -> Option<Hit> + Sync),
) -> Result<ViewHits, PictureError> {
    let Frame { camera, width, height } = *frame;
    // Checked before anything is allocated: a huge size is an error, not an aborted allocation.
    crate::limits::check_image_size("view size", width, height)
        .map_err(|e| PictureError::invalid("view size", e.to_string()))?;
    let w = width as usize;
    let hits = (0..w * height as usize)
        .into_par_iter()
        .map(|k| {
            let (origin, dir) = camera.ray((k % w) as u32, (k / w) as u32, width, height);
            trace(origin, dir)
        })
        .collect();
    Ok(ViewHits { width, height, hits })
}

/// Renders the view of `frame`: [`trace_view`] then [`colour_view`].
///
/// # Errors
/// As [`trace_view`] and [`colour_view`].
pub fn render(
    frame: &Frame,
    trace: &(dyn Fn(DVec3, DVec3) -> Option<Hit> + Sync),
    shader: &SmoothShader,
    radiosity: &[Rgb],
    colouring: Colouring<'_>,
    tone: Option<ToneMap>,
) -> Result<View, PictureError> {
    colour_view(&trace_view(frame, trace)?, shader, radiosity, colouring, tone)
}

/// Colours traced hits.
///
/// `shader` must be built from the patches the hits name and `radiosity` has one value per patch. For shaded and
/// flat views, `tone` gives the tone map, or when `None` it is chosen by [`ToneMap::from_percentile`] over the
/// visible pixels.
///
/// # Errors
/// [`PictureError::Invalid`] for mismatched lengths or a hit naming a patch that does not exist (with the pixel);
/// [`PictureError::NonFinite`] from shading or tone mapping (naming the patch or pixel).
pub fn colour_view(
    view: &ViewHits,
    shader: &SmoothShader,
    radiosity: &[Rgb],
    colouring: Colouring<'_>,
    tone: Option<ToneMap>,
) -> Result<View, PictureError> {
    let ViewHits { width, height, ref hits } = *view;
    let w = width as usize;
    if hits.len() != w * height as usize {
        return Err(PictureError::invalid("view hits", format!("{} hits for {width}x{height}", hits.len())));
    }
    if radiosity.len() != shader.patch_count() {
        return Err(PictureError::invalid(
            "radiosity",
            format!("{} values for {} patches", radiosity.len(), shader.patch_count()),
        ));
    }
    if let Some((k, h)) =
        hits.iter().enumerate().find_map(|(k, h)| h.filter(|h| h.patch >= radiosity.len()).map(|h| (k, h)))
    {
        return Err(PictureError::invalid(
            "hit",
            format!("pixel ({}, {}) hit patch {} of {}", k % w, k / w, h.patch, radiosity.len()),
        ));
    }
    let linear: Vec<Rgb> = hits
        .par_iter()
        .map(|h| match (h, colouring) {
            (None, _) => Ok(Rgb::ZERO),
            (Some(h), Colouring::Shaded) => shader.shade(radiosity, h.patch, h.point),
            (Some(h), _) => Ok(radiosity[h.patch]),
        })
        .collect::<Result<_, _>>()?;
    let patch: Vec<Option<u32>> = hits.iter().map(|h| h.map(|h| h.patch as u32)).collect();
    let mut image = RgbImage::new(width, height);
    let mut used_tone = None;
    let mut used_scale = None;
    match colouring {
        Colouring::Shaded | Colouring::Flat => {
            let tone = match tone {
                Some(t) => t,
                None => {
                    let visible: Vec<f64> = linear
                        .iter()
                        .zip(&patch)
                        .filter(|(_, p)| p.is_some())
                        .map(|(c, _)| luminance(*c))
                        .collect();
                    if visible.is_empty() {
                        ToneMap::new(1.0, ToneMap::DEFAULT_WHITE)?
                    } else {
                        ToneMap::from_percentile(
                            &visible,
                            ToneMap::DEFAULT_PERCENTILE,
                            ToneMap::DEFAULT_WHITE,
                        )?
                    }
                }
            };
            image = tone.map_image(&linear, width, height)?;
            used_tone = Some(tone);
        }
        Colouring::ByPatch => {
            for (k, p) in patch.iter().enumerate() {
                if let Some(p) = p {
                    image.pixels[3 * k..3 * k + 3].copy_from_slice(&patch_colour(*p as usize));
                }
            }
        }
        Colouring::Error { reference, scale } => {
            let errors = patch_errors(radiosity, reference)?;
            let scale = match scale {
                Some(s) => s,
                None => default_error_scale(&errors)?,
            };
            for (k, p) in patch.iter().enumerate() {
                if let Some(p) = p {
                    image.pixels[3 * k..3 * k + 3].copy_from_slice(&scale.colour(errors[*p as usize]));
                }
            }
            used_scale = Some(scale);
        }
    }
    Ok(View { image, linear, patch, tone: used_tone, error_scale: used_scale })
}

/// Writes one shaded PNG per frame of a sequence (e.g. a relight script's per-frame device output) as
/// `<dir>/<prefix>-0000.png`, `-0001.png`, ... and returns the paths and the tone map used.
///
/// Every frame uses the same tone map, `tone` or, when `None`, the one [`colour_view`] would choose for the
/// **last** frame (the converged answer), so brightness is comparable across frames and an unconverged frame
/// looks as dark as it is.
///
/// # Errors
/// [`PictureError::Invalid`] if there are no frames; otherwise as [`colour_view`] (naming the frame) and
/// [`PictureError::Io`] / [`PictureError::Png`] for files.
pub fn write_frame_sequence(
    view: &ViewHits,
    shader: &SmoothShader,
    frames: &[Vec<Rgb>],
    tone: Option<ToneMap>,
    dir: &std::path::Path,
    prefix: &str,
) -> Result<(Vec<std::path::PathBuf>, ToneMap), PictureError> {
    let last = frames.last().ok_or_else(|| PictureError::invalid("frame sequence", "no frames"))?;
    let tone = match tone {
        Some(t) => t,
        None => colour_view(view, shader, last, Colouring::Shaded, None)?
            .tone
            .ok_or_else(|| PictureError::invalid("frame sequence", "no tone map for the last frame"))?,
    };
    let mut paths = Vec::with_capacity(frames.len());
    for (k, radiosity) in frames.iter().enumerate() {
        let image = colour_view(view, shader, radiosity, Colouring::Shaded, Some(tone)).map_err(|e| {
            PictureError::Invalid { what: "frame sequence", reason: format!("frame {k}: {e}") }
        })?;
        let path = dir.join(format!("{prefix}-{k:04}.png"));
        super::write_png(&path, &image.image)?;
        paths.push(path);
    }
    Ok((paths, tone))
}
