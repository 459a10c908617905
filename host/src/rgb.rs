//! [`Rgb`]: the host's colour type, for every per-patch reflectance, emission, radiosity, intensity and residual.
//!
//! An [`Rgb`] is a [`glam::DVec3`] whose `x`, `y`, `z` are the red, green and blue channels, in that order
//! (channel indices 0, 1, 2 in errors and tables). Channel-wise arithmetic is glam's: `a * b` and `a + b` are
//! per channel, `s * a` scales every channel, `v[c]` reads channel `c`. Serialized (serde), an [`Rgb`] is the
//! array `[r, g, b]`. The device side (`radiosity-core`) takes `[f32; 3]` and `[S; 3]`; conversions happen at
//! that boundary ([`Rgb::as_vec3`], [`Rgb::to_array`], [`Rgb::from_array`]).

/// Linear RGB, one `f64` per channel: `x` = R, `y` = G, `z` = B.
pub type Rgb = glam::DVec3;

/// Rec. 709 luminance weights for (R, G, B) (ITU-R BT.709-6, item 3.2; also the sRGB primaries').
pub const REC709_LUMINANCE: Rgb = Rgb::new(0.2126, 0.7152, 0.0722);

/// Rec. 709 relative luminance `Y = 0.2126 R + 0.7152 G + 0.0722 B` of a linear RGB value.
#[must_use]
pub fn luminance(rgb: Rgb) -> f64 {
    REC709_LUMINANCE.dot(rgb)
}

/// The largest channel of `rgb`, at least 0: `max(0, r, g, b)` (NaN channels are ignored, as [`f64::max`]
/// does).
#[must_use]
pub fn max_channel(rgb: Rgb) -> f64 {
    0.0f64.max(rgb.x).max(rgb.y).max(rgb.z)
}

/// The channel-wise maximum of `a` and `b` by [`f64::max`] (a NaN channel gives the other argument's), where
/// [`glam::DVec3::max`] compares with `>` and so gives `b`'s channel whenever a comparison fails.
#[must_use]
pub fn channel_max(a: Rgb, b: Rgb) -> Rgb {
    Rgb::new(a.x.max(b.x), a.y.max(b.y), a.z.max(b.z))
}

/// The channel-wise minimum of `a` and `b` by [`f64::min`] (the counterpart of [`channel_max`]).
#[must_use]
pub fn channel_min(a: Rgb, b: Rgb) -> Rgb {
    Rgb::new(a.x.min(b.x), a.y.min(b.y), a.z.min(b.z))
}
