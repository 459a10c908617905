//! Linear (high dynamic range) image files: Radiance `.hdr` (RGBE), PFM and OpenEXR.
//!
//! **Radiance RGBE** (Greg Ward, "Real Pixels", Graphics Gems II, 1991; the Radiance file format as documented in
//! the Radiance reference manual): a text header starting `#?RADIANCE`, a `FORMAT=32-bit_rle_rgbe` line, an empty
//! line, the resolution line `-Y height +X width` (rows top to bottom, columns left to right), then one 4-byte pixel
//! per column: three 8-bit mantissas sharing one exponent byte. A value `v = max(r, g, b)` is written as
//! `v = m * 2^e` with `m` in `[0.5, 1)`; each channel `c` becomes `floor(c * 256 / 2^e)` and the exponent byte is
//! `e + 128`. Reading gives `(byte + 0.5) * 2^(e - 136)`, so the error of each channel is at most `2^e / 512`, i.e.
//! at most `max(r, g, b) / 256`. This writer emits flat (uncompressed) scanlines, which the format allows
//! (normalized mantissas make a flat pixel never look like a run-length marker); the reader also accepts the
//! run-length-encoded scanlines that other tools write. Negative values are written as zero.
//!
//! **PFM** (portable float map, colour variant): the text header `PF\n<width> <height>\n<scale>\n`, then 32-bit
//! IEEE floats, three per pixel, rows from the **bottom** up; a negative scale means little-endian. This writer uses
//! scale `-1.0` (little-endian), and values round-trip exactly at f32 precision.
//!
//! **OpenEXR** (through the `exr` crate): one layer with channels `R`, `G`, `B` of 32-bit floats (not half: the
//! scenes' radiosities span 1e-6..1e6, beyond half's range of 6e-5..65504), the crate's default lossless
//! compression, rows top to bottom; values round-trip exactly at f32 precision. This is the format game engines
//! and compositing tools read for linear light maps.

use std::path::{Path, PathBuf};

use super::{write_file, PictureError};

/// A linear RGB image with f32 channels, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` RGB values, row-major from the top-left pixel.
    pub pixels: Vec<[f32; 3]>,
}

impl LinearImage {
    /// A black image.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        LinearImage { width, height, pixels: vec![[0.0; 3]; width as usize * height as usize] }
    }

    fn check(&self) -> Result<(), PictureError> {
        let n = self.width as usize * self.height as usize;
        if self.pixels.len() != n {
            return Err(PictureError::invalid(
                "linear image",
                format!("{} pixels for {}x{} ({n} expected)", self.pixels.len(), self.width, self.height),
            ));
        }
        for (index, p) in self.pixels.iter().enumerate() {
            if let Some(&v) = p.iter().find(|v| !v.is_finite()) {
                return Err(PictureError::NonFinite {
                    what: "linear image pixel",
                    index,
                    value: f64::from(v),
                });
            }
        }
        Ok(())
    }
}

/// Encodes one RGB value as RGBE (see the module docs).
#[must_use]
pub fn rgbe_encode(rgb: [f32; 3]) -> [u8; 4] {
    let c = rgb.map(|v| f64::from(v.max(0.0)));
    let v = c[0].max(c[1]).max(c[2]);
    // Below 2^-128 the exponent byte cannot represent the value (and NaN lands here too): black.
    if v.is_nan() || v < 2f64.powi(-127) {
        return [0; 4];
    }
    // v = m * 2^e with m in [0.5, 1).
    let mut e = v.log2().floor() as i32 + 1;
    if v / 2f64.powi(e) >= 1.0 {
        e += 1;
    }
    if v / 2f64.powi(e) < 0.5 {
        e -= 1;
    }
    let e = e.clamp(-127, 127);
    let scale = 256.0 / 2f64.powi(e);
    let m = c.map(|x| (x * scale).floor().clamp(0.0, 255.0) as u8);
    [m[0], m[1], m[2], (e + 128) as u8]
}

/// Decodes one RGBE pixel (see the module docs).
#[must_use]
pub fn rgbe_decode(rgbe: [u8; 4]) -> [f32; 3] {
    if rgbe[3] == 0 {
        return [0.0; 3];
    }
    let f = 2f64.powi(i32::from(rgbe[3]) - 136);
    [0, 1, 2].map(|i| ((f64::from(rgbe[i]) + 0.5) * f) as f32)
}

/// Encodes an image as a Radiance `.hdr` file (flat scanlines).
///
/// # Errors
/// [`PictureError::Invalid`] / [`PictureError::NonFinite`] if the image is inconsistent or has NaN / infinite
/// values.
pub fn encode_hdr(image: &LinearImage) -> Result<Vec<u8>, PictureError> {
    image.check()?;
    let mut out = format!(
        "#?RADIANCE\n# radiosity light map (linear radiosity, W/m^2)\nFORMAT=32-bit_rle_rgbe\n\n-Y {} +X {}\n",
        image.height, image.width
    )
    .into_bytes();
    out.reserve(4 * image.pixels.len());
    for &p in &image.pixels {
        out.extend_from_slice(&rgbe_encode(p));
    }
    Ok(out)
}

/// Writes an image as a Radiance `.hdr` file (see [`encode_hdr`]).
///
/// # Errors
/// As [`encode_hdr`], and [`PictureError::Io`] if the file cannot be written.
pub fn write_hdr(path: &Path, image: &LinearImage) -> Result<(), PictureError> {
    write_file(path, &encode_hdr(image)?)
}

fn format_err(path: &Path, reason: impl Into<String>) -> PictureError {
    PictureError::Format { path: path.to_path_buf(), reason: reason.into() }
}

/// Decodes a Radiance `.hdr` file (flat or run-length-encoded scanlines, orientation `-Y H +X W` only).
/// `path` only names the data in errors.
///
/// # Errors
/// [`PictureError::Format`] naming what is wrong (header, resolution line, or the scanline that is truncated).
pub fn decode_hdr(bytes: &[u8], path: &Path) -> Result<LinearImage, PictureError> {
    let mut pos = 0;
    let next_line = |pos: &mut usize| -> Option<String> {
        let rest = bytes.get(*pos..)?;
        let end = rest.iter().position(|&b| b == b'\n')?;
        *pos += end + 1;
        Some(String::from_utf8_lossy(&rest[..end]).into_owned())
    };
    let first = next_line(&mut pos).ok_or_else(|| format_err(path, "no header line"))?;
    if first != "#?RADIANCE" && first != "#?RGBE" {
        return Err(format_err(path, format!("first line {first:?} is not #?RADIANCE")));
    }
    loop {
        let line =
            next_line(&mut pos).ok_or_else(|| format_err(path, "header does not end with an empty line"))?;
        if line.is_empty() {
            break;
        }
        if let Some(format) = line.strip_prefix("FORMAT=") {
            if format != "32-bit_rle_rgbe" {
                return Err(format_err(path, format!("pixel format {format:?} is not 32-bit_rle_rgbe")));
            }
        }
    }
    let res = next_line(&mut pos).ok_or_else(|| format_err(path, "no resolution line"))?;
    let parts: Vec<&str> = res.split_whitespace().collect();
    let (height, width) = match parts.as_slice() {
        ["-Y", h, "+X", w] => match (h.parse::<u32>(), w.parse::<u32>()) {
            (Ok(h), Ok(w)) => (h, w),
            _ => return Err(format_err(path, format!("resolution line {res:?} has no valid sizes"))),
        },
        _ => {
            return Err(format_err(
                path,
                format!("resolution line {res:?} is not \"-Y <height> +X <width>\""),
            ))
        }
    };
    let mut image = LinearImage::new(width, height);
    let w = width as usize;
    let mut row = vec![[0u8; 4]; w];
    for y in 0..height as usize {
        let truncated = || format_err(path, format!("scanline {y} is truncated"));
        let head = bytes.get(pos..pos + 4).ok_or_else(truncated)?;
        let rle = (8..=0x7fff).contains(&w) && head[0] == 2 && head[1] == 2 && head[2] & 0x80 == 0;
        if rle {
            let len = (usize::from(head[2]) << 8) | usize::from(head[3]);
            if len != w {
                return Err(format_err(path, format!("scanline {y} says width {len}, image width is {w}")));
            }
            pos += 4;
            for channel in 0..4 {
                let mut x = 0;
                while x < w {
                    let count = *bytes.get(pos).ok_or_else(truncated)? as usize;
                    pos += 1;
                    if count > 128 {
                        let run = count - 128;
                        let value = *bytes.get(pos).ok_or_else(truncated)?;
                        pos += 1;
                        if x + run > w {
                            return Err(format_err(
                                path,
                                format!("scanline {y}: run past the end of the line"),
                            ));
                        }
                        for px in &mut row[x..x + run] {
                            px[channel] = value;
                        }
                        x += run;
                    } else {
                        if count == 0 || x + count > w {
                            return Err(format_err(path, format!("scanline {y}: bad literal count {count}")));
                        }
                        let data = bytes.get(pos..pos + count).ok_or_else(truncated)?;
                        for (px, &value) in row[x..x + count].iter_mut().zip(data) {
                            px[channel] = value;
                        }
                        pos += count;
                        x += count;
                    }
                }
            }
        } else {
            let data = bytes.get(pos..pos + 4 * w).ok_or_else(truncated)?;
            for (px, chunk) in row.iter_mut().zip(data.chunks_exact(4)) {
                px.copy_from_slice(chunk);
            }
            pos += 4 * w;
        }
        for (x, &px) in row.iter().enumerate() {
            image.pixels[y * w + x] = rgbe_decode(px);
        }
    }
    Ok(image)
}

/// Reads a Radiance `.hdr` file (see [`decode_hdr`]).
///
/// # Errors
/// [`PictureError::Io`] if the file cannot be read, else as [`decode_hdr`].
pub fn read_hdr(path: &Path) -> Result<LinearImage, PictureError> {
    let bytes = std::fs::read(path).map_err(|e| PictureError::io(path, e))?;
    decode_hdr(&bytes, path)
}

/// Encodes an image as a little-endian colour PFM (rows stored bottom-up, as the format requires).
///
/// # Errors
/// [`PictureError::Invalid`] / [`PictureError::NonFinite`] if the image is inconsistent or has NaN / infinite
/// values.
pub fn encode_pfm(image: &LinearImage) -> Result<Vec<u8>, PictureError> {
    image.check()?;
    let mut out = format!("PF\n{} {}\n-1.0\n", image.width, image.height).into_bytes();
    let w = image.width as usize;
    for y in (0..image.height as usize).rev() {
        for p in &image.pixels[y * w..(y + 1) * w] {
            for v in p {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    Ok(out)
}

/// Writes an image as a PFM file (see [`encode_pfm`]).
///
/// # Errors
/// As [`encode_pfm`], and [`PictureError::Io`] if the file cannot be written.
pub fn write_pfm(path: &Path, image: &LinearImage) -> Result<(), PictureError> {
    write_file(path, &encode_pfm(image)?)
}

/// Decodes a colour PFM (either byte order). `path` only names the data in errors.
///
/// # Errors
/// [`PictureError::Format`] naming the bad header field or the truncated data.
pub fn decode_pfm(bytes: &[u8], path: &Path) -> Result<LinearImage, PictureError> {
    // Header: three whitespace-separated tokens after "PF", the last one followed by exactly one whitespace byte.
    let mut pos = 0;
    let mut tokens = Vec::new();
    while tokens.len() < 4 {
        while bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
            pos += 1;
        }
        let start = pos;
        while bytes.get(pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            pos += 1;
        }
        if start == pos {
            return Err(format_err(path, "PFM header is truncated"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..pos]).into_owned());
    }
    pos += 1;
    if tokens[0] != "PF" {
        return Err(format_err(path, format!("magic {:?} is not PF (colour PFM)", tokens[0])));
    }
    let width: u32 = tokens[1].parse().map_err(|_| format_err(path, format!("width {:?}", tokens[1])))?;
    let height: u32 = tokens[2].parse().map_err(|_| format_err(path, format!("height {:?}", tokens[2])))?;
    let scale: f64 = tokens[3].parse().map_err(|_| format_err(path, format!("scale {:?}", tokens[3])))?;
    if scale == 0.0 || !scale.is_finite() {
        return Err(format_err(path, format!("scale {scale} must be finite and nonzero")));
    }
    let little = scale < 0.0;
    let w = width as usize;
    let need = 12 * w * height as usize;
    let data = bytes.get(pos..pos + need).ok_or_else(|| {
        format_err(path, format!("{} data bytes, {need} expected", bytes.len().saturating_sub(pos)))
    })?;
    let mut image = LinearImage::new(width, height);
    for (i, chunk) in data.chunks_exact(12).enumerate() {
        let (file_row, x) = (i / w, i % w);
        let y = height as usize - 1 - file_row;
        let f = |k: usize| {
            let b = [chunk[4 * k], chunk[4 * k + 1], chunk[4 * k + 2], chunk[4 * k + 3]];
            if little {
                f32::from_le_bytes(b)
            } else {
                f32::from_be_bytes(b)
            }
        };
        image.pixels[y * w + x] = [f(0), f(1), f(2)];
    }
    Ok(image)
}

/// Reads a PFM file (see [`decode_pfm`]).
///
/// # Errors
/// [`PictureError::Io`] if the file cannot be read, else as [`decode_pfm`].
pub fn read_pfm(path: &Path) -> Result<LinearImage, PictureError> {
    let bytes = std::fs::read(path).map_err(|e| PictureError::io(path, e))?;
    decode_pfm(&bytes, path)
}

/// Encodes an image as OpenEXR: RGB, 32-bit float channels, lossless (see the module docs).
///
/// # Errors
/// [`PictureError::Invalid`] / [`PictureError::NonFinite`] if the image is inconsistent or has NaN / infinite
/// values; [`PictureError::Format`] if the encoder fails.
pub fn encode_exr(image: &LinearImage) -> Result<Vec<u8>, PictureError> {
    use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
    image.check()?;
    let width = image.width as usize;
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let [r, g, b] = image.pixels[y * width + x];
        (r, g, b)
    });
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_channels((width, image.height as usize), channels)
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| PictureError::Format {
            path: memory_path(),
            reason: format!("OpenEXR encoding: {e}"),
        })?;
    Ok(out.into_inner())
}

/// Writes an image as an OpenEXR file (see [`encode_exr`]).
///
/// # Errors
/// As [`encode_exr`], and [`PictureError::Io`] if the file cannot be written.
pub fn write_exr(path: &Path, image: &LinearImage) -> Result<(), PictureError> {
    write_file(path, &encode_exr(image)?)
}

/// Decodes the first RGB(A) layer of an OpenEXR file (any channel type, converted to f32; alpha is ignored).
///
/// # Errors
/// [`PictureError::Format`] naming `path` if the bytes are not an OpenEXR image with R, G and B channels, or the
/// image is larger than [`crate::limits::MAX_IMAGE_PIXELS`].
pub fn decode_exr(bytes: &[u8], path: &Path) -> Result<LinearImage, PictureError> {
    use exr::prelude::{read, ReadChannels, ReadLayers};
    let format = |reason: String| PictureError::Format { path: path.to_path_buf(), reason };
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |size, _| {
                let (w, h) = (size.width().min(u32::MAX as usize), size.height().min(u32::MAX as usize));
                // Nothing is allocated for an image over the size limit; the check below reports it.
                let fits = crate::limits::check_image_size("OpenEXR image", w as u32, h as u32).is_ok();
                let pixels = if fits { vec![[0.0; 3]; w * h] } else { Vec::new() };
                LinearImage { width: w as u32, height: h as u32, pixels }
            },
            |image: &mut LinearImage, at, (r, g, b, _a): (f32, f32, f32, f32)| {
                let index = at.y() * image.width as usize + at.x();
                if let Some(p) = image.pixels.get_mut(index) {
                    *p = [r, g, b];
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| format(format!("not a readable OpenEXR RGB image: {e}")))?;
    let pixels = image.layer_data.channel_data.pixels;
    crate::limits::check_image_size("OpenEXR image", pixels.width, pixels.height)
        .map_err(|e| format(e.to_string()))?;
    Ok(pixels)
}

/// Reads an OpenEXR file (see [`decode_exr`]).
///
/// # Errors
/// [`PictureError::Io`] if the file cannot be read, else as [`decode_exr`].
pub fn read_exr(path: &Path) -> Result<LinearImage, PictureError> {
    let bytes = std::fs::read(path).map_err(|e| PictureError::io(path, e))?;
    decode_exr(&bytes, path)
}

/// The path used in errors for in-memory data.
#[must_use]
pub fn memory_path() -> PathBuf {
    PathBuf::from("<memory>")
}
