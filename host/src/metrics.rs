//! Error metrics: how far a device answer is from the f64 reference.
//!
//! A device answer `b` and the reference `r` are per-patch RGB radiosities; `A_i` are the patch areas. `|x|` is
//! the Euclidean norm over the three channels and `d_i = b_i - r_i`. The metrics (all in [`ErrorReport`]):
//!
//! - **relative L2**, area-weighted: `sqrt(sum_i A_i |d_i|^2) / sqrt(sum_i A_i |r_i|^2)`;
//! - **absolute RMS**, area-weighted: `sqrt(sum_i A_i |d_i|^2 / sum_i A_i)` (W/m^2), meaningful even for a dark
//!   reference;
//! - **max per-patch relative error** with a floor for dark patches: `max_i |d_i| / max(|r_i|, floor)`, where
//!   `floor = FLOOR_FRACTION * (sum_i A_i |r_i|) / (sum_i A_i)` = `1e-3` times the area-weighted mean radiosity.
//!   A patch a thousand times darker than the scene average is judged against the average's thousandth, so an
//!   error that is invisible next to the rest of the scene does not dominate the maximum; patches brighter than
//!   the floor are judged against themselves;
//! - **luminance**, Rec. 709 ([`luminance`], ITU-R BT.709-6, item 3.2): `Y = 0.2126 R + 0.7152 G + 0.0722 B`; its area-weighted
//!   relative L2 and its max per-patch relative error with the same rule (`floor_Y = 1e-3` times the
//!   area-weighted mean of `|Y_r|`).
//!
//! A relative error with a zero denominator (an all-dark reference) is 0 when the answers agree exactly and
//! infinite otherwise; JSON (serde_json) writes an infinite value as `null`. The absolute RMS stays finite.

use std::fmt;

use serde::Serialize;
use thiserror::Error;

use crate::input::{check_finite, check_len, InputError};
use crate::rgb::{luminance, Rgb};

/// The dark-patch floor as a fraction of the area-weighted mean radiosity (or luminance).
pub const FLOOR_FRACTION: f64 = 1e-3;

/// Invalid input to [`compare`].
#[derive(Clone, Debug, PartialEq, Error)]
#[non_exhaustive]
pub enum MetricsError {
    /// An input slice has the wrong length or a radiosity is NaN or infinite.
    #[error(transparent)]
    Input(#[from] InputError),
    /// An area is not a positive finite number.
    #[error("area of patch {patch} is {value}, not a positive finite number")]
    BadArea {
        /// Patch index.
        patch: usize,
        /// The offending value.
        value: f64,
    },
}

/// Error of one device answer against the reference; see the module docs for the definitions.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ErrorReport {
    /// Number of patches compared.
    pub patches: usize,
    /// Area-weighted relative L2 error of `B` over patches and channels.
    pub rel_l2: f64,
    /// Area-weighted RMS of `|b_i - r_i|` (W/m^2).
    pub abs_rms: f64,
    /// Max per-patch relative error `|d_i| / max(|r_i|, floor)`.
    pub max_rel: f64,
    /// Patch where `max_rel` is reached (0 when there are no patches).
    pub max_rel_patch: usize,
    /// The dark-patch floor used for `max_rel` (W/m^2).
    pub floor: f64,
    /// Area-weighted relative L2 error of the Rec. 709 luminance.
    pub luminance_rel_l2: f64,
    /// Max per-patch relative luminance error `|Y_b - Y_r| / max(|Y_r|, floor_Y)`.
    pub luminance_max_rel: f64,
    /// Patch where `luminance_max_rel` is reached.
    pub luminance_max_rel_patch: usize,
    /// The dark-patch floor used for `luminance_max_rel` (W/m^2).
    pub luminance_floor: f64,
}

impl fmt::Display for ErrorReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "patches           {}", self.patches)?;
        writeln!(f, "relative L2       {:.3e}", self.rel_l2)?;
        writeln!(f, "absolute RMS      {:.3e}", self.abs_rms)?;
        writeln!(
            f,
            "max relative      {:.3e} (patch {}, floor {:.3e})",
            self.max_rel, self.max_rel_patch, self.floor
        )?;
        writeln!(f, "luminance rel L2  {:.3e}", self.luminance_rel_l2)?;
        write!(
            f,
            "luminance max rel {:.3e} (patch {}, floor {:.3e})",
            self.luminance_max_rel, self.luminance_max_rel_patch, self.luminance_floor
        )
    }
}

/// `num / den` with `0 / 0 = 0` and `x / 0 = inf` for `x > 0`.
pub(crate) fn relative(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        num / den
    } else if num == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

/// [`relative`] per channel.
pub(crate) fn relative_channels(num: Rgb, den: Rgb) -> Rgb {
    Rgb::new(relative(num.x, den.x), relative(num.y, den.y), relative(num.z, den.z))
}

/// Area-weighted relative L2 and floored max relative error of per-patch magnitudes.
///
/// `diff[i]` and `reference[i]` are the norms `|d_i|` and `|r_i|` (or their luminance counterparts).
/// Returns `(rel_l2, max_rel, max_rel_patch, floor)`.
fn scalar_errors(diff: &[f64], reference: &[f64], area: &[f64]) -> (f64, f64, usize, f64) {
    let total_area: f64 = area.iter().sum();
    let (mut diff2, mut ref2, mut ref1) = (0.0, 0.0, 0.0);
    for ((&d, &r), &a) in diff.iter().zip(reference).zip(area) {
        diff2 += a * d * d;
        ref2 += a * r * r;
        ref1 += a * r;
    }
    let floor = if total_area > 0.0 { FLOOR_FRACTION * ref1 / total_area } else { 0.0 };
    let (mut max_rel, mut max_patch) = (0.0, 0);
    for (i, (&d, &r)) in diff.iter().zip(reference).enumerate() {
        let e = relative(d, r.max(floor));
        if e > max_rel {
            max_rel = e;
            max_patch = i;
        }
    }
    (relative(diff2.sqrt(), ref2.sqrt()), max_rel, max_patch, floor)
}

/// Compares a device answer `b` with the reference `reference` on patches of area `area`.
///
/// # Errors
/// If `b` or `area` does not have one entry per reference patch, a radiosity is not finite, or an area is not a
/// positive finite number.
pub fn compare(b: &[Rgb], reference: &[Rgb], area: &[f64]) -> Result<ErrorReport, MetricsError> {
    let n = reference.len();
    check_len("device answer", b, n)?;
    check_len("area", area, n)?;
    check_finite("device answer", b)?;
    check_finite("reference", reference)?;
    if let Some((patch, &value)) = area.iter().enumerate().find(|(_, a)| !(a.is_finite() && **a > 0.0)) {
        return Err(MetricsError::BadArea { patch, value });
    }
    let diff: Vec<f64> = b.iter().zip(reference).map(|(&b, &r)| (b - r).length()).collect();
    let magnitude: Vec<f64> = reference.iter().map(|r| r.length()).collect();
    let (rel_l2, max_rel, max_rel_patch, floor) = scalar_errors(&diff, &magnitude, area);

    let y_diff: Vec<f64> =
        b.iter().zip(reference).map(|(&b, &r)| (luminance(b) - luminance(r)).abs()).collect();
    let y_ref: Vec<f64> = reference.iter().map(|&r| luminance(r).abs()).collect();
    let (luminance_rel_l2, luminance_max_rel, luminance_max_rel_patch, luminance_floor) =
        scalar_errors(&y_diff, &y_ref, area);

    let total_area: f64 = area.iter().sum();
    let diff2: f64 = diff.iter().zip(area).map(|(d, a)| a * d * d).sum();
    let abs_rms = if n == 0 { 0.0 } else { (diff2 / total_area).sqrt() };
    Ok(ErrorReport {
        patches: n,
        rel_l2,
        abs_rms,
        max_rel,
        max_rel_patch,
        floor,
        luminance_rel_l2,
        luminance_max_rel,
        luminance_max_rel_patch,
        luminance_floor,
    })
}
