//! A perceptually ordered false-colour map for errors, and its legend.
//!
//! The ramp is this project's own design, in the spirit of viridis (van der Walt and Smith, 2015) but not taken
//! from its tables: five control points in CIELAB (CIE 15:2004, D65 white) with lightness `L*` rising evenly from
//! 22 to 92 while the hue turns from violet through blue, teal and green to yellow. Between control points the
//! ramp interpolates linearly in CIELAB, so lightness is strictly increasing along the whole ramp (a reader can order
//! colours by brightness alone, also in greyscale print and for red-green colour-blind readers). CIELAB is converted
//! to XYZ and then to linear sRGB with the IEC 61966-2-1 matrix, and encoded with the sRGB transfer function. All
//! control points and the segments between them are inside the sRGB gamut (a test checks that no channel clips).
//!
//! [`ErrorScale`] maps error values (linear or log) onto the ramp; [`ErrorScale::legend`] draws a legend strip
//! (colour bar, tick marks and tick labels in DejaVu Sans, see [`super::text`]) and
//! [`ErrorScale::legend_json`] gives the same ticks as data.

use plotters::prelude::*;

use super::text::{ensure_font, format_tick, FONT_FAMILY};
use super::tonemap::srgb_encode_u8;
use super::{PictureError, RgbImage};
use crate::rgb::Rgb;

/// Control points `(L*, a*, b*)` at `t = 0, 0.25, 0.5, 0.75, 1`.
const CONTROL_LAB: [[f64; 3]; 5] =
    [[22.0, 30.0, -38.0], [39.5, 8.0, -42.0], [57.0, -30.0, -8.0], [74.5, -48.0, 38.0], [92.0, -12.0, 72.0]];

/// The ramp at `t` in `[0, 1]` (clamped; NaN gives 0) as CIELAB `(L*, a*, b*)`.
#[must_use]
pub fn ramp_lab(t: f64) -> [f64; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let s = t * (CONTROL_LAB.len() - 1) as f64;
    let i = (s.floor() as usize).min(CONTROL_LAB.len() - 2);
    let f = s - i as f64;
    let (a, b) = (CONTROL_LAB[i], CONTROL_LAB[i + 1]);
    [0, 1, 2].map(|k| a[k] + f * (b[k] - a[k]))
}

/// CIELAB (D65) -> linear sRGB, not clipped (CIE 15:2004 inverse; IEC 61966-2-1 XYZ -> RGB matrix).
#[must_use]
pub fn lab_to_linear_srgb(lab: [f64; 3]) -> Rgb {
    const WHITE: [f64; 3] = [0.950_47, 1.0, 1.088_83];
    let delta: f64 = 6.0 / 29.0;
    let finv = |t: f64| if t > delta { t * t * t } else { 3.0 * delta * delta * (t - 4.0 / 29.0) };
    let fy = (lab[0] + 16.0) / 116.0;
    let x = WHITE[0] * finv(fy + lab[1] / 500.0);
    let y = WHITE[1] * finv(fy);
    let z = WHITE[2] * finv(fy - lab[2] / 200.0);
    Rgb::new(
        3.2406 * x - 1.5372 * y - 0.4986 * z,
        -0.9689 * x + 1.8758 * y + 0.0415 * z,
        0.0557 * x - 0.2040 * y + 1.0570 * z,
    )
}

/// The ramp at `t` in `[0, 1]` as linear sRGB (clipped to `[0, 1]`).
#[must_use]
pub fn ramp(t: f64) -> Rgb {
    lab_to_linear_srgb(ramp_lab(t)).map(|v| v.clamp(0.0, 1.0))
}

/// The ramp at `t` in `[0, 1]` as 8-bit sRGB.
#[must_use]
pub fn ramp_srgb8(t: f64) -> [u8; 3] {
    ramp(t).to_array().map(srgb_encode_u8)
}

/// Maps error values onto the ramp: `min` -> 0 (dark violet), `max` -> 1 (yellow), linearly or in `log10`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorScale {
    /// Value at the dark end.
    pub min: f64,
    /// Value at the bright end.
    pub max: f64,
    /// Logarithmic scale (then `min > 0`).
    pub log: bool,
}

impl ErrorScale {
    /// A scale from `min` to `max`.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] unless both are finite, `min < max`, and `min > 0` for a log scale.
    pub fn new(min: f64, max: f64, log: bool) -> Result<Self, PictureError> {
        if !(min.is_finite() && max.is_finite() && min < max) {
            return Err(PictureError::invalid(
                "error scale",
                format!("[{min}, {max}] is not a finite, nonempty range"),
            ));
        }
        if log && min <= 0.0 {
            return Err(PictureError::invalid("error scale", format!("log scale needs min > 0, got {min}")));
        }
        Ok(ErrorScale { min, max, log })
    }

    /// Position of `value` along the ramp, clamped to `[0, 1]` (NaN maps to 0).
    #[must_use]
    pub fn position(&self, value: f64) -> f64 {
        let t = if self.log {
            (value.max(self.min).log10() - self.min.log10()) / (self.max.log10() - self.min.log10())
        } else {
            (value - self.min) / (self.max - self.min)
        };
        if t.is_nan() {
            0.0
        } else {
            t.clamp(0.0, 1.0)
        }
    }

    /// The 8-bit sRGB colour of `value`.
    #[must_use]
    pub fn colour(&self, value: f64) -> [u8; 3] {
        ramp_srgb8(self.position(value))
    }

    /// Tick values: decades (1, 2, 5 per decade when there are few) for a log scale, 1-2-5 steps for a linear one.
    #[must_use]
    pub fn ticks(&self) -> Vec<f64> {
        let inside = |v: f64| v >= self.min * (1.0 - 1e-12) && v <= self.max * (1.0 + 1e-12);
        if self.log {
            let (a, b) = (self.min.log10().floor() as i32, self.max.log10().ceil() as i32);
            let mantissas: &[f64] = if b - a <= 2 { &[1.0, 2.0, 5.0] } else { &[1.0] };
            let step = ((b - a) / 8).max(1);
            let mut ticks: Vec<f64> = (a..=b)
                .step_by(step as usize)
                .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
                .filter(|&v| inside(v))
                .collect();
            if ticks.len() < 2 {
                ticks = vec![self.min, self.max];
            }
            ticks
        } else {
            let raw = (self.max - self.min) / 5.0;
            let p = 10f64.powf(raw.log10().floor());
            let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|&s| s >= raw).unwrap_or(10.0 * p);
            let first = (self.min / step).ceil() as i64;
            let last = (self.max / step).floor() as i64;
            (first..=last).map(|k| k as f64 * step).collect()
        }
    }

    /// The legend as data: scale, colour map name, and ticks with their positions along the bar.
    #[must_use]
    pub fn legend_json(&self, label: &str) -> serde_json::Value {
        serde_json::json!({
            "label": label,
            "colormap": "radiosity-lab-ramp (CIELAB, L* 22..92)",
            "min": self.min,
            "max": self.max,
            "log": self.log,
            "ticks": self.ticks().iter().map(|&v| serde_json::json!({"value": v, "position": self.position(v)}))
                .collect::<Vec<_>>(),
        })
    }

    /// Draws a horizontal legend strip: the label, the colour bar, tick marks and tick labels.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] if the image is too small (below 64 x 48), [`PictureError::Font`] if the font
    /// is missing, [`PictureError::Plot`] if drawing fails.
    pub fn legend(&self, label: &str, width: u32, height: u32) -> Result<RgbImage, PictureError> {
        if width < 64 || height < 48 {
            return Err(PictureError::invalid("legend size", format!("{width}x{height} is below 64x48")));
        }
        ensure_font()?;
        let e = |err: DrawingAreaErrorKind<_>| PictureError::Plot {
            what: "legend".into(),
            reason: format!("{err:?}"),
        };
        let mut image = RgbImage::new(width, height);
        {
            let root = BitMapBackend::with_buffer(&mut image.pixels, (width, height)).into_drawing_area();
            root.fill(&WHITE).map_err(e)?;
            let (w, h) = (width as i32, height as i32);
            let font_px = (h / 6).clamp(10, 18);
            // Room for half a tick label beyond each end of the bar.
            let margin = 3 * font_px;
            let (x0, x1) = (margin, w - margin);
            let (y0, y1) = (font_px + 8, h - font_px - 14);
            let text = TextStyle::from((FONT_FAMILY, font_px)).color(&BLACK);
            root.draw(&Text::new(label.to_string(), (x0, 2), text.clone())).map_err(e)?;
            for x in x0..x1 {
                let t = f64::from(x - x0) / f64::from((x1 - x0 - 1).max(1));
                let [r, g, b] = ramp_srgb8(t);
                root.draw(&PathElement::new(vec![(x, y0), (x, y1)], RGBColor(r, g, b))).map_err(e)?;
            }
            root.draw(&Rectangle::new([(x0, y0), (x1, y1)], BLACK.stroke_width(1))).map_err(e)?;
            let centred = text.pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Center,
                plotters::style::text_anchor::VPos::Top,
            ));
            for v in self.ticks() {
                let x = x0 + (self.position(v) * f64::from(x1 - x0 - 1)).round() as i32;
                root.draw(&PathElement::new(vec![(x, y1), (x, y1 + 5)], BLACK)).map_err(e)?;
                root.draw(&Text::new(format_tick(v), (x, y1 + 7), centred.clone())).map_err(e)?;
            }
            root.present().map_err(e)?;
        }
        Ok(image)
    }
}

/// A distinct 8-bit sRGB colour per patch index, for pictures that show the mesh ("colour by patch").
///
/// Hues step by the golden angle (so neighbouring indices differ strongly and colours repeat only after many
/// patches) at CIELAB lightness cycling through 55, 65, 75 and chroma 30, which stays inside the sRGB gamut for
/// every hue at those lightness levels (the largest in-gamut chroma over all hues is about 31 at L* 55).
#[must_use]
pub fn patch_colour(index: usize) -> [u8; 3] {
    const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653; // pi * (3 - sqrt(5)) radians
    let hue = (index as f64 * GOLDEN_ANGLE) % std::f64::consts::TAU;
    let l = [55.0, 65.0, 75.0][index % 3];
    let lab = [l, 30.0 * hue.cos(), 30.0 * hue.sin()];
    lab_to_linear_srgb(lab).to_array().map(|v| srgb_encode_u8(v.clamp(0.0, 1.0)))
}
