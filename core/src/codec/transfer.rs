//! The transfer response code: how the transfer basis `T_g` (crate docs, "Transfer basis") is quantized.
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

use super::ff::{f32_to_exact, pow2_f32, FfCodec, Frac};

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
