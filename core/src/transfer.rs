//! The precomputed transfer basis: relighting as `B = B_static + sum_g I_g T_g`, a peer of shooting.
//!
//! The radiosity equation is linear in the emission, so with reflectances fixed the radiosity for any light
//! group intensities `I_g` (RGB) is `B = B_static + sum_g I_g T_g` (per channel), `T_g` the response of every
//! patch to light group `g` at unit intensity. The host solves `T_g` in f64 and stores it, quantized, as the
//! table's optional transfer section; [`relight_transfer`] then relights the whole scene in one pass over
//! the section: exact up to quantization and arithmetic, no iteration, cost `patches x (groups + 1)` work
//! units. Shooting ([`crate::Solver`]) stays the path when reflectances change at run time (a transfer basis
//! is only valid for the table's reflectances) and when groups are many (the section grows as
//! `patches x groups`, the form-factor rows do not).
//!
//! # Quantization
//! Core's 16-bit small float ([`FfCodec::FLOAT16`](crate::FfCodec::FLOAT16): 4 exponent and 12 mantissa bits,
//! see [`crate::codec`]) under a power-of-two scale per light group and channel: `T_igc ~ f(q_igc) 2^K_gc`,
//! `f` the FLOAT16 decode with row exponent 0 (values in `[0, 2)`), `K_gc` an `i8`. The writer picks
//! `K_gc = floor(log2 max_i T_igc)` (one more if the largest would round past the top code), clamped to
//! [`TRANSFER_MIN_EXPONENT`]`..=`[`TRANSFER_MAX_EXPONENT`], and rounds each response to the nearest code.
//! So every stored response is within half a code step of the host's value:
//! `|error| <= max(2^-13 T, 2^(K_gc - 27))`, relative `2^-13` (1.2e-4) for responses down to `2^-14` of
//! the group's brightest and absolute `2^(K_gc - 27)` below (the code's subnormal step is `2^-26`). A uniform
//! 16-bit scale would be 8 times finer at the brightest patch but lose the dim ones (a patch at `1e-3` of
//! the brightest would get 1.5% error); the small float keeps the per-patch relative error bounded, as the
//! form-factor rows do. The decode `f(q) 2^K` is a dyadic number, exact in `f32` and in
//! [`Fixed`](crate::Fixed) (down to its resolution `2^-32`).
//!
//! # Error bound of a relight
//! Against `B_static + sum_g I_g T_g` with the host's `T_g` and `B_static`, per patch and channel:
//! `sum_g |I_gc| max(2^-13 T_igc, 2^(K_gc - 27))` (response quantization) `+ 2^-11 E_s + (2^-11 + 2^-17) G_s`
//! (the static base's emission and irradiance codes and the reflectance code, see the crate docs, "Error
//! bounds") plus the arithmetic: in `f32` one rounding per term (relative `2^-24` of the running sum,
//! `groups + 2` terms), in fixed point at most `2^-32` per decode and per product (`2 (groups + 1)` units of
//! `2^-32`).
//!
//! # Cost
//! One work unit per patch for the static base (decode `E_s`, `G_s`, `rho`: three multiply-adds) plus one per
//! patch and light group (decode an RGB code triple, three multiply-adds): [`transfer_cost`] `= patches x
//! (groups + 1)`, the same kind of unit as a form-factor entry applied by a shot (crate docs, "Cost model").
//! The pass runs outside any step budget and is not resumable: its cost is known from the counts up front.

use core::fmt;

use crate::codec::{decode_emission, decode_reflectance, f32_to_exact, pow2_f32, FfCodec, Frac};
use crate::scalar::Scalar;
use crate::table::Table;

/// The code of the transfer responses (under the per-group scale `2^K`): core's 16-bit small float.
pub const TRANSFER_CODEC: FfCodec = FfCodec::FLOAT16;

/// Smallest transfer scale exponent `K` (responses below `2^(TRANSFER_MIN_EXPONENT - 27)` W/m^2 round to 0).
pub const TRANSFER_MIN_EXPONENT: i8 = -96;
/// Largest transfer scale exponent `K` (responses up to [`TRANSFER_MAX`], about `8.6e9` W/m^2).
pub const TRANSFER_MAX_EXPONENT: i8 = 32;

/// Largest response the writer accepts: `(2 - 2^-13) 2^TRANSFER_MAX_EXPONENT`, the top code plus half a step.
pub const TRANSFER_MAX: f32 = 8_589_410_304.0; // 2^33 - 2^19

/// Largest scaled response that rounds to the top code rather than past it: `2 - 2^-13`.
const TOP_ROUNDING: f32 = 2.0 - 1.0 / 8192.0;

/// Decodes a transfer response code under scale exponent `k` to `(mantissa, exponent)`, value
/// `mantissa * 2^exponent` (exact; what both arithmetic paths start from).
#[must_use]
pub fn decode_transfer_dyadic(code: u16, k: i8) -> (u32, i32) {
    let Frac { mantissa, shift } = TRANSFER_CODEC.decode(code, 0);
    // shift <= 26 for row exponent 0, so the exponent stays within i32 and above -126 for valid k.
    (mantissa, i32::from(k) - shift as i32)
}

/// Decodes a transfer response code under scale exponent `k` to f32 (exact for valid `k`).
#[must_use]
pub fn decode_transfer(code: u16, k: i8) -> f32 {
    let (m, e) = decode_transfer_dyadic(code, k);
    m as f32 * pow2_f32(e)
}

/// The scale exponent for responses whose largest value is `max` (finite, `0 <= max <= TRANSFER_MAX`):
/// `floor(log2 max)`, plus one if `max` would round past the top code, clamped to the valid range.
pub(crate) fn transfer_exponent_for(max: f32) -> i8 {
    if max.is_nan() || max <= 0.0 {
        return TRANSFER_MIN_EXPONENT;
    }
    // Biased exponent field minus the bias: floor(log2 max) for normal numbers (subnormals clamp below).
    let mut k = ((max.to_bits() >> 23) & 0xff) as i32 - 127;
    if k >= i32::from(TRANSFER_MIN_EXPONENT) && max * pow2_f32(-k) > TOP_ROUNDING {
        k += 1;
    }
    k.clamp(i32::from(TRANSFER_MIN_EXPONENT), i32::from(TRANSFER_MAX_EXPONENT)) as i8
}

/// The code of response `v` (finite, `0 <= v <= TRANSFER_MAX`) under scale exponent `k`: the nearest code.
pub(crate) fn encode_transfer(v: f32, k: i8) -> u16 {
    // v * 2^-k is exact (power-of-two scaling within the normal range for valid k and v), so the only
    // rounding is to the nearest code.
    let exact = f32_to_exact(v * pow2_f32(-i32::from(k)));
    let lo = TRANSFER_CODEC.round_down(exact, 0);
    if lo >= TRANSFER_CODEC.max_code() {
        return lo;
    }
    let below = TRANSFER_CODEC.decode(lo, 0).to_exact();
    let above = TRANSFER_CODEC.decode(lo + 1, 0).to_exact();
    if above.saturating_sub(exact) < exact.saturating_sub(below) {
        lo + 1
    } else {
        lo
    }
}

/// Why a transfer relight cannot run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TransferError {
    /// The table has no transfer section (bake it with the transfer basis).
    NoTransferSection,
    /// The intensity slice has fewer entries than the table has light groups.
    IntensityTooShort {
        /// Light groups in the table.
        needed: u32,
        /// Entries given.
        got: usize,
    },
    /// The output slice has fewer entries than the table has patches.
    OutputTooSmall {
        /// Patches in the table.
        needed: u32,
        /// Entries given.
        got: usize,
    },
    /// An intensity is not usable (not finite in f32, saturated in fixed point).
    BadIntensity {
        /// The light group.
        group: u32,
        /// The channel (0 = red, 1 = green, 2 = blue).
        channel: u8,
    },
}

impl fmt::Display for TransferError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TransferError::NoTransferSection => write!(f, "the table has no transfer basis section"),
            TransferError::IntensityTooShort { needed, got } => {
                write!(f, "transfer relight: {got} intensities for {needed} light groups")
            }
            TransferError::OutputTooSmall { needed, got } => {
                write!(f, "transfer relight: output holds {got} patches, the table has {needed}")
            }
            TransferError::BadIntensity { group, channel } => {
                write!(f, "transfer relight: intensity of light group {group} channel {channel} not finite")
            }
        }
    }
}

impl core::error::Error for TransferError {}

/// Work units of one [`relight_transfer`] of `table`: `patches x (groups + 1)` (saturating).
#[must_use]
pub fn transfer_cost(table: &Table<'_>) -> u32 {
    table.patch_count().saturating_mul(table.group_count().saturating_add(1))
}

/// The static radiosity `B_static_i = E_s_i + rho_i G_s_i` (W/m^2, RGB) of `patch` from the table's static
/// base and reflectances (crate docs, "Static base"; the static solution when the base is solved), or `None`
/// out of range.
#[must_use]
pub fn static_radiosity<S: Scalar>(table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
    let e = table.base_emission(patch)?;
    let g = table.base_irradiance(patch)?;
    let rho = table.reflectance(table.material(patch)?)?;
    Some([0, 1, 2].map(|c| emission::<S>(e[c]).add(emission::<S>(g[c]).mul_frac(decode_reflectance(rho[c])))))
}

fn emission<S: Scalar>(code: u16) -> S {
    let (m, e) = decode_emission(code);
    S::from_dyadic(m, e)
}

/// Relights the whole table from its transfer basis: `out[i] = B_static_i + sum_g intensity[g] T_g,i`
/// (W/m^2, RGB, per channel), for every patch `i`. Returns the work units spent, [`transfer_cost`].
///
/// `intensity[g]` is light group `g`'s RGB intensity (the same multiplier as [`crate::Solver::set_light`]);
/// extra entries of `intensity` and `out` are ignored. The answer is for the table's reflectances: after
/// [`crate::Solver::set_reflectance`] use shooting. Never allocates; bounded work; see the module docs for
/// the error bound.
///
/// # Errors
/// [`TransferError::NoTransferSection`], [`TransferError::IntensityTooShort`],
/// [`TransferError::OutputTooSmall`], [`TransferError::BadIntensity`]; `out` is untouched on error.
pub fn relight_transfer<S: Scalar>(
    table: &Table<'_>,
    intensity: &[[S; 3]],
    out: &mut [[S; 3]],
) -> Result<u32, TransferError> {
    if !table.has_transfer() {
        return Err(TransferError::NoTransferSection);
    }
    let (n, groups) = (table.patch_count(), table.group_count());
    if intensity.len() < groups as usize {
        return Err(TransferError::IntensityTooShort { needed: groups, got: intensity.len() });
    }
    if out.len() < n as usize {
        return Err(TransferError::OutputTooSmall { needed: n, got: out.len() });
    }
    for (g, rgb) in intensity.iter().take(groups as usize).enumerate() {
        for (c, v) in rgb.iter().enumerate() {
            if !v.is_usable() {
                return Err(TransferError::BadIntensity { group: g as u32, channel: c as u8 });
            }
        }
    }
    for (i, o) in (0..n).zip(out.iter_mut()) {
        let mut b = static_radiosity::<S>(table, i).unwrap_or([S::ZERO; 3]);
        for (g, rgb) in (0..groups).zip(intensity) {
            let (Some(code), Some(k)) = (table.transfer_code(i, g), table.transfer_exponent(g)) else {
                continue;
            };
            for c in 0..3 {
                let (m, e) = decode_transfer_dyadic(code[c], k[c]);
                b[c] = b[c].add(rgb[c].mul(S::from_dyadic(m, e)));
            }
        }
        *o = b;
    }
    Ok(transfer_cost(table))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponent_puts_the_largest_response_in_the_top_binade() {
        assert_eq!(transfer_exponent_for(0.0), TRANSFER_MIN_EXPONENT);
        assert_eq!(transfer_exponent_for(1.0), 0);
        assert_eq!(transfer_exponent_for(1.99), 0);
        assert_eq!(transfer_exponent_for(2.0), 1);
        assert_eq!(transfer_exponent_for(0.3), -2);
        // Above the top code plus half a step: one binade up.
        assert_eq!(transfer_exponent_for(1.99995), 1);
        assert_eq!(transfer_exponent_for(TRANSFER_MAX), TRANSFER_MAX_EXPONENT);
        assert_eq!(transfer_exponent_for(1e-35), TRANSFER_MIN_EXPONENT);
    }

    #[test]
    fn codes_round_to_nearest_within_the_bound() {
        for &max in &[1.0f32, 7.3, 1e-6, 3e8] {
            let k = transfer_exponent_for(max);
            for &f in &[1.0f32, 0.999, 0.5001, 0.3, 1e-2, 1e-4, 7e-5, 1e-6, 0.0] {
                let v = max * f;
                let d = decode_transfer(encode_transfer(v, k), k);
                // max(2^-13 v, 2^(K - 27)), plus the f32 rounding of this check's bound.
                let bound = (v * pow2_f32(-13)).max(pow2_f32(i32::from(k) - 27));
                assert!((d - v).abs() <= bound * (1.0 + 1e-6), "max {max} v {v} decoded {d} k {k}");
            }
        }
        assert_eq!(encode_transfer(f32::NAN, 0), 0);
    }
}
