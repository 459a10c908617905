//! Radiometric codes: reflectance (`u16`, `q / 65536`) and emission or irradiance (a 16-bit float, 6
//! exponent and 10 mantissa bits); see the module docs of [`crate::codec`].

use super::ff::{pow2_f32, Frac};

/// Decodes a reflectance code: `q / 65536`.
#[must_use]
pub fn decode_reflectance(code: u16) -> Frac {
    Frac { mantissa: u32::from(code), shift: 16 }
}

/// Encodes a reflectance (round to nearest, clamped to `[0, 65535/65536]`; NaN gives 0).
#[must_use]
pub fn encode_reflectance(rho: f32) -> u16 {
    if rho.is_nan() || rho <= 0.0 {
        return 0;
    }
    let q = rho * 65536.0 + 0.5;
    if q >= 65535.0 {
        65535
    } else {
        q as u16
    }
}

/// Decodes an emission code to `(mantissa, exponent)` with value `mantissa * 2^exponent`.
#[must_use]
pub fn decode_emission(code: u16) -> (u32, i32) {
    let x = i32::from(code >> 10);
    let m = u32::from(code & 0x3ff);
    if x == 0 {
        (m, -40)
    } else {
        (1024 + m, x - 41)
    }
}

/// Decodes an emission code to f32 (exact).
#[must_use]
pub fn decode_emission_f32(code: u16) -> f32 {
    let (m, e) = decode_emission(code);
    m as f32 * pow2_f32(e)
}

/// Largest value the emission code represents: `(2 - 2^-10) * 2^32`.
pub const EMISSION_MAX: f32 = 2047.0 * 4_194_304.0; // 2047 * 2^22

/// Encodes a non-negative radiometric value (emission, irradiance) to the nearest emission code.
///
/// Returns `None` for negative, non-finite or too large (`> EMISSION_MAX`) values.
#[must_use]
pub fn encode_emission(v: f32) -> Option<u16> {
    if !(0.0..=EMISSION_MAX).contains(&v) {
        return None;
    }
    // Largest code with decode <= v (decode is monotone in the code and exact in f32).
    let (mut lo, mut hi) = (0u32, 0xffffu32);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if decode_emission_f32(mid as u16) <= v {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    if lo == 0xffff {
        return Some(0xffff);
    }
    let below = decode_emission_f32(lo as u16);
    let above = decode_emission_f32(lo as u16 + 1);
    // Both differences are exact: the two neighbours are within a factor 2 of v (Sterbenz).
    Some(if above - v <= v - below { lo as u16 + 1 } else { lo as u16 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::pow2_f32;
    use proptest::prelude::*;

    #[test]
    fn emission_code_extremes() {
        assert_eq!(encode_emission(0.0), Some(0));
        assert_eq!(decode_emission_f32(encode_emission(EMISSION_MAX).unwrap()), EMISSION_MAX);
        assert_eq!(encode_emission(EMISSION_MAX * 1.001), None);
        assert_eq!(encode_emission(-1.0), None);
        assert_eq!(encode_emission(f32::NAN), None);
        assert_eq!(decode_emission_f32(encode_emission(1.0).unwrap()), 1.0);
    }

    proptest! {
        #[test]
        fn emission_relative_error_bound(v in 1e-9f32..8e9) {
            let d = decode_emission_f32(encode_emission(v).unwrap());
            let bound = if v >= pow2_f32(-30) { v * pow2_f32(-11) } else { pow2_f32(-41) };
            prop_assert!((d - v).abs() <= bound * (1.0 + 1e-6), "v={} d={}", v, d);
        }

        #[test]
        fn reflectance_abs_error_bound(rho in 0.0f32..0.99998) {
            let d = decode_reflectance(encode_reflectance(rho)).to_f32();
            // 2^-17 from rounding plus the f32 rounding of rho * 65536 (an ulp of values < 65536, 2^-8 / 65536).
            prop_assert!((d - rho).abs() <= pow2_f32(-17) + pow2_f32(-24), "rho={} d={}", rho, d);
        }
    }
}
