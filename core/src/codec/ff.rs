//! Form-factor codes: [`FfCodec`] (a small float per entry under a per-row power-of-two scale), the
//! dyadic [`Frac`] every code decodes to, and the writer's row quantization (module docs of [`crate::codec`]).

/// Fixed-point exponent used for exact sums of decoded form factors: values are held as integers in units of
/// `2^-EXACT_SHIFT` in a `u128`.
pub(crate) const EXACT_SHIFT: u32 = 100;

/// Largest row exponent a table may hold.
pub const MAX_ROW_EXPONENT: u8 = 64;

/// A dyadic fraction `mantissa * 2^-shift`, the decoded form of every form-factor and reflectance code.
///
/// Decoding yields `mantissa < 2^17` and `shift <= 94` for form factors, `shift = 16` for reflectances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frac {
    /// Integer mantissa.
    pub mantissa: u32,
    /// Power-of-two divisor exponent.
    pub shift: u32,
}

impl Frac {
    /// Zero.
    pub const ZERO: Frac = Frac { mantissa: 0, shift: 0 };

    /// The value as f32 (exact for every code this crate decodes).
    #[must_use]
    #[inline]
    pub fn to_f32(self) -> f32 {
        self.mantissa as f32 * pow2_f32(-(self.shift as i32))
    }

    /// The value in units of `2^-EXACT_SHIFT` (truncated if `shift > EXACT_SHIFT`, which decoding never yields).
    #[must_use]
    pub(crate) fn to_exact(self) -> u128 {
        if self.shift <= EXACT_SHIFT {
            u128::from(self.mantissa) << (EXACT_SHIFT - self.shift)
        } else {
            u128::from(self.mantissa) >> (self.shift - EXACT_SHIFT).min(127)
        }
    }
}

/// `2^k` as f32 for `-126 <= k <= 127` (clamped outside), built from bits so it is exact and needs no FPU.
#[must_use]
pub(crate) fn pow2_f32(k: i32) -> f32 {
    let k = k.clamp(-126, 127);
    f32::from_bits(((k + 127) as u32) << 23)
}

/// [`FfCodec::decode`] for one row, its constants precomputed ([`FfCodec::row_decoder`]) so that a loop over a
/// row's entries does not recompute them per entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowDecoder {
    max_code: u32,
    m_bits: u32,
    base: i32,
}

impl RowDecoder {
    /// The least and the largest shift of the row's codes' values (as [`RowDecoder::decode`] gives them).
    #[must_use]
    pub fn shift_range(self) -> (u32, u32) {
        let largest_x = (self.max_code >> self.m_bits) as i32;
        let least = if largest_x == 0 { self.base } else { self.base + 1 - largest_x };
        (least.max(0) as u32, self.base.max(0) as u32)
    }

    /// Bits of the largest mantissa of the row's values (with a normal code's leading one).
    #[must_use]
    pub fn mantissa_bits(self) -> u32 {
        self.m_bits + u32::from(self.max_code >> self.m_bits != 0)
    }

    /// [`RowDecoder::decode`] without its clamps, for codes no larger than the largest (every code read at the
    /// codec's width) in rows whose shifts are all positive ([`RowDecoder::shift_range`]): then the same
    /// value. Any other use gives some value, never a panic.
    #[must_use]
    #[inline(always)]
    pub fn decode_unclamped(self, code: u32) -> Frac {
        let x = code.wrapping_shr(self.m_bits);
        let m = code & 1u32.wrapping_shl(self.m_bits).wrapping_sub(1);
        if x == 0 {
            Frac { mantissa: m, shift: self.base as u32 }
        } else {
            Frac {
                mantissa: 1u32.wrapping_shl(self.m_bits) | m,
                shift: self.base.wrapping_add(1).wrapping_sub(x as i32) as u32,
            }
        }
    }

    /// The code's value, as [`FfCodec::decode`] gives it (codes above the largest are clamped).
    #[must_use]
    #[inline]
    pub fn decode(self, code: u32) -> Frac {
        let code = code.min(self.max_code);
        let x = code >> self.m_bits;
        let m = code & ((1u32 << self.m_bits) - 1);
        if x == 0 {
            Frac { mantissa: m, shift: self.base.max(0) as u32 }
        } else {
            Frac { mantissa: (1u32 << self.m_bits) | m, shift: (self.base + 1 - x as i32).max(0) as u32 }
        }
    }
}

/// A [`RowDecoder`] that decodes straight to f32 (hierarchical shooting's per-link factor): a normal code's
/// exponent and mantissa fields are moved into an f32's fields by integer work, one shift, one add and one
/// or per code, instead of the dyadic [`Frac`] and its conversion; the value is the same, bit for bit
/// ([`Frac::to_f32`] of [`RowDecoder::decode`]).
///
/// Why it is exact: a normal code (exponent field `x >= 1`) decodes to `(2^M + m) 2^-s` with `s = base + 1 -
/// x`; when `0 <= s <= 126` for every `x` of the codec, that is the normal f32 with exponent field `127 + M -
/// s` and mantissa field `m 2^(23 - M)`, and `Frac::to_f32` computes exactly it (an integer below `2^24`
/// times an exact power of two). A code with `x = 0` decodes to `m 2^-base`: the same product with the power
/// of two kept. Rows whose exponent puts some `s` outside that range (none that a valid table's row exponents
/// `<= 64` give with a standard codec, but the check is cheap) take the `Frac` path for every code.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32RowDecoder {
    row: RowDecoder,
    /// `2^(126 + M - base)`: the f32 whose bits are a code shifted into the f32's exponent and mantissa
    /// fields, times this, is the code's value.
    scale: f32,
    /// `23 - M`: the shift that puts a code's mantissa at the top of the f32's mantissa field.
    shift: u32,
    /// Whether the bit path is exact for every code of the row.
    fast: bool,
}

impl F32RowDecoder {
    /// Prepares `row`'s codes for decoding to f32.
    #[must_use]
    pub fn new(row: RowDecoder) -> Self {
        let largest_x = (row.max_code >> row.m_bits) as i32;
        // Shifts of the normal codes run from `base + 1 - largest_x` (largest code) to `base` (x = 1), so
        // every value is an f32 without rounding; the scale `2^(126 + M - base)` must be one too.
        let k = 126 + row.m_bits as i32 - row.base;
        let fast = row.m_bits <= 23 && row.base + 1 - largest_x >= 0 && row.base <= 126 && k <= 127;
        let scale = if fast { pow2_f32(k) } else { 0.0 };
        F32RowDecoder { row, scale, shift: 23u32.saturating_sub(row.m_bits), fast }
    }

    /// The value of `code` (codes above the largest are clamped), bit for bit `row.decode(code).to_f32()`.
    #[must_use]
    #[inline(always)]
    pub fn decode(self, code: u32) -> f32 {
        if !self.fast {
            return self.row.decode(code).to_f32();
        }
        self.decode_fast(code.min(self.row.max_code))
    }

    /// Whether [`F32RowDecoder::decode_fast`] is exact for this row (the bit path above).
    #[must_use]
    pub fn is_fast(self) -> bool {
        self.fast
    }

    /// [`F32RowDecoder::decode`] without its checks, for rows where [`F32RowDecoder::is_fast`] holds and codes
    /// no larger than the codec's largest (every code read at the codec's own width): then the same bits. Any
    /// other use gives some value, never a panic.
    ///
    /// The code's exponent `x` and mantissa `m`, shifted into an f32's fields, make the f32 `(2^M + m)
    /// 2^(x - 127 - M)` for `x >= 1` and, as an f32 subnormal, `m 2^(-126 - M)` for `x = 0`: the code's values
    /// `(2^M + m) 2^(x - 1 - base)` and `m 2^-base` over one power of two, `2^(126 + M - base)` (the codes share
    /// IEEE 754's subnormal rule). So one shift and one exact multiply, without a branch for `x = 0`.
    #[must_use]
    #[inline(always)]
    pub fn decode_fast(self, code: u32) -> f32 {
        f32::from_bits(code.wrapping_shl(self.shift)) * self.scale
    }
}

/// A form-factor codec: code width and exponent bits (see the module docs for the decoding rule).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FfCodec {
    /// Code width in bits: 8 or 16.
    pub bits: u8,
    /// Exponent bits `E`, `0..=4`; 0 is the block-linear code.
    pub exponent_bits: u8,
}

/// Why an [`FfCodec`] is not usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecParamError {
    /// Code width other than 8 or 16 bits.
    Bits(u8),
    /// More than 4 exponent bits, or no mantissa bit left.
    ExponentBits(u8),
}

/// The codec's name: `FLOAT16`, `FLOAT8`, `LINEAR16`, `LINEAR8`, or `E{exponent bits}M{mantissa bits}`.
impl core::fmt::Display for FfCodec {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            FfCodec::FLOAT16 => f.write_str("FLOAT16"),
            FfCodec::FLOAT8 => f.write_str("FLOAT8"),
            FfCodec::LINEAR16 => f.write_str("LINEAR16"),
            FfCodec::LINEAR8 => f.write_str("LINEAR8"),
            c => write!(f, "E{}M{}", c.exponent_bits, c.bits.saturating_sub(c.exponent_bits)),
        }
    }
}

impl FfCodec {
    /// 16-bit small float, 4 exponent bits, 12 mantissa bits (relative error `< 2^-12`). The default.
    pub const FLOAT16: FfCodec = FfCodec { bits: 16, exponent_bits: 4 };
    /// 8-bit small float, 3 exponent bits, 5 mantissa bits (relative error `< 2^-5`).
    pub const FLOAT8: FfCodec = FfCodec { bits: 8, exponent_bits: 3 };
    /// 16-bit block-linear code (absolute error `< row_max * 2^-15`).
    pub const LINEAR16: FfCodec = FfCodec { bits: 16, exponent_bits: 0 };
    /// 8-bit block-linear code (absolute error `< row_max * 2^-7`).
    pub const LINEAR8: FfCodec = FfCodec { bits: 8, exponent_bits: 0 };

    /// Checks the parameters.
    ///
    /// # Errors
    /// [`CodecParamError`] naming the bad field.
    pub fn check(self) -> Result<(), CodecParamError> {
        if self.bits != 8 && self.bits != 16 {
            return Err(CodecParamError::Bits(self.bits));
        }
        if self.exponent_bits > 4 || self.exponent_bits >= self.bits {
            return Err(CodecParamError::ExponentBits(self.exponent_bits));
        }
        Ok(())
    }

    /// Bytes per code.
    #[must_use]
    pub fn code_bytes(self) -> usize {
        usize::from(self.bits / 8)
    }

    /// Largest code.
    #[must_use]
    pub fn max_code(self) -> u16 {
        if self.bits >= 16 {
            u16::MAX
        } else {
            (1u16 << self.bits) - 1
        }
    }

    fn mantissa_bits(self) -> u32 {
        u32::from(self.bits.saturating_sub(self.exponent_bits))
    }

    /// Mantissa bits `M` and the shift of a subnormal code in a row with exponent `row_exponent`:
    /// `row_exponent + M + 2^E - 2` (see the module docs).
    fn shape(self, row_exponent: u8) -> (u32, i32) {
        let m_bits = self.mantissa_bits().min(16);
        let e_span = (1i32 << self.exponent_bits.min(4)) - 2; // 2^E - 2, -1 for E = 0
        (m_bits, i32::from(row_exponent) + m_bits as i32 + e_span)
    }

    /// Decodes `code` in a row with exponent `row_exponent` (assumes [`FfCodec::check`] passed; codes above
    /// [`FfCodec::max_code`] are clamped).
    #[must_use]
    #[inline]
    pub fn decode(self, code: u16, row_exponent: u8) -> Frac {
        self.row_decoder(row_exponent).decode(u32::from(code))
    }

    /// The constants of [`FfCodec::decode`] for rows of exponent `row_exponent`, computed once for a row's
    /// entries.
    #[must_use]
    #[inline]
    pub fn row_decoder(self, row_exponent: u8) -> RowDecoder {
        let (m_bits, base) = self.shape(row_exponent);
        RowDecoder { max_code: u32::from(self.max_code()), m_bits, base }
    }

    /// Largest code whose decoded value is `<= exact` (`exact` in units of `2^-EXACT_SHIFT`).
    ///
    /// The decoding rule inverted gives the code directly (the writer calls this once per entry); a few steps
    /// confirm it against [`FfCodec::decode`], and a binary search takes over if they do not (rows at the
    /// extremes of the row exponent, where decoding clamps shifts).
    pub(crate) fn round_down(self, exact: u128, row_exponent: u8) -> u16 {
        let max = u32::from(self.max_code());
        let value = |c: u32| self.decode(c as u16, row_exponent).to_exact();
        let mut c = self.code_guess(exact, row_exponent).min(max);
        for _ in 0..4 {
            if value(c) > exact {
                c = c.saturating_sub(1);
            } else if c < max && value(c + 1) <= exact {
                c += 1;
            } else {
                return c as u16;
            }
        }
        self.round_down_search(exact, row_exponent)
    }

    /// [`FfCodec::decode`] inverted: with `v = floor(exact * 2^(base - EXACT_SHIFT))` in units of the row's
    /// subnormal step, `v < 2^M` is the subnormal code `v`; otherwise `x = floor(log2 v) - M + 1` and the mantissa
    /// is `floor(v / 2^(x-1)) - 2^M`. May exceed the largest code (the caller clamps).
    fn code_guess(self, exact: u128, row_exponent: u8) -> u32 {
        let (m_bits, base) = self.shape(row_exponent);
        let base = base.max(0) as u32;
        let v = if base >= EXACT_SHIFT {
            let up = (base - EXACT_SHIFT).min(127);
            if exact.leading_zeros() <= up {
                return u32::MAX;
            }
            exact << up
        } else {
            exact >> (EXACT_SHIFT - base).min(127)
        };
        if v < (1u128 << m_bits) {
            return v as u32;
        }
        let x = (127 - v.leading_zeros()) - m_bits + 1;
        if x >= 1 << self.exponent_bits.min(4) {
            return u32::MAX;
        }
        let mantissa = (v >> (x - 1)) as u32 - (1u32 << m_bits);
        (x << m_bits) | mantissa
    }

    /// [`FfCodec::round_down`] by binary search over the codes.
    fn round_down_search(self, exact: u128, row_exponent: u8) -> u16 {
        let (mut lo, mut hi) = (0u32, u32::from(self.max_code()));
        // Invariant: decode(lo) <= exact (decode(0) = 0); answer in [lo, hi].
        while lo < hi {
            let mid = lo + (hi - lo).div_ceil(2);
            if self.decode(mid as u16, row_exponent).to_exact() <= exact {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        lo as u16
    }
}

/// Row exponent the writer picks for a row whose largest entry is `max_exact`: `floor(-log2(max))`, clamped
/// to `0..=MAX_ROW_EXPONENT`.
pub(crate) fn row_exponent_for(max_exact: u128) -> u8 {
    if max_exact == 0 {
        return 0;
    }
    let bit_len = 128 - max_exact.leading_zeros(); // max in [2^(bit_len-1-100), 2^(bit_len-100))
    let e = EXACT_SHIFT as i32 + 1 - bit_len as i32;
    e.clamp(0, i32::from(MAX_ROW_EXPONENT)) as u8
}

/// Exact value of a finite, non-negative f32 in units of `2^-EXACT_SHIFT` (values below `2^-100` truncate;
/// saturates at `u128::MAX`). Negative and non-finite inputs give 0 (callers validate first).
#[must_use]
pub(crate) fn f32_to_exact(v: f32) -> u128 {
    if v.is_nan() || v <= 0.0 || !v.is_finite() {
        return 0;
    }
    let bits = v.to_bits();
    let exp = ((bits >> 23) & 0xff) as i32;
    let frac = bits & 0x7f_ffff;
    let (m, e) = if exp == 0 { (frac, -149) } else { (frac | 0x80_0000, exp - 150) };
    let s = e + EXACT_SHIFT as i32;
    if s >= 0 {
        if s > 100 {
            u128::MAX
        } else {
            u128::from(m) << s
        }
    } else if s < -127 {
        0
    } else {
        u128::from(m) >> (-s)
    }
}

/// Quantizes one row of form factors in place of `codes`: round down, then distribute the slack.
///
/// `values` must be finite and non-negative; `target` (exact, `2^-EXACT_SHIFT` units) is the sum the decoded
/// row may not exceed. Returns the row exponent. `codes.len()` must equal `values.len()`.
#[cfg(test)]
pub(crate) fn quantize_row(codec: FfCodec, values: &[f32], target: u128, codes: &mut [u16]) -> u8 {
    let max = values.iter().map(|&v| f32_to_exact(v)).max().unwrap_or(0);
    let e = row_exponent_for(max);
    quantize_row_with_exponent(codec, values, target, e, 0, codes);
    e
}

/// Row chunk length the writer quantizes at once (and the length of the quantizer's loss cache).
pub(crate) const QUANT_BLOCK: usize = 1024;

/// [`quantize_row`] with a given row exponent; returns the decoded sum (exact units).
///
/// Slack left after the threshold pass goes to the remaining entries in cyclic order from position `start`
/// (the writer passes the first receiver after the shooter), so that in a symmetric scene every column gets
/// the same share of bumps rather than the low-numbered patches getting them all.
pub(crate) fn quantize_row_with_exponent(
    codec: FfCodec,
    values: &[f32],
    target: u128,
    e: u8,
    start: usize,
    codes: &mut [u16],
) -> u128 {
    let mut sum: u128 = 0;
    for (c, &v) in codes.iter_mut().zip(values) {
        *c = codec.round_down(f32_to_exact(v), e);
        sum = sum.saturating_add(codec.decode(*c, e).to_exact());
    }
    // A row whose true sum is above the target (the writer accepts sums up to `1 + ROW_SUM_SLACK` and caps the
    // target at 1) can round down to more than the target: lower its largest code, one step at a time, until the
    // decoded sum fits (the excess is far below a top-binade step of any code, so this rarely takes two steps).
    while sum > target {
        let Some((k, _)) = codes.iter().enumerate().max_by_key(|&(k, &c)| (c, core::cmp::Reverse(k))) else {
            break;
        };
        let Some(c) = codes.get_mut(k) else { break };
        if *c == 0 {
            break;
        }
        let lower = codec.decode(*c - 1, e).to_exact();
        sum = sum - codec.decode(*c, e).to_exact() + lower;
        *c -= 1;
    }
    let mut slack = target.saturating_sub(sum);
    if slack == 0 {
        return sum;
    }
    // Fractional loss of entry k, in 1/2^16 of its code step: loss / step, or NO_BUMP. An entry gets at most
    // one bump, and only if the bumped value is at most twice the entry: below the float range a step can be
    // many times a tiny entry, and a transposed (shooting-form) row multiplies that by the area ratio.
    const NO_BUMP: u32 = u32::MAX;
    let step_of = |c: u16| -> u128 {
        codec.decode(c.saturating_add(1), e).to_exact().saturating_sub(codec.decode(c, e).to_exact())
    };
    let frac_loss = |c: u16, v: f32| -> u32 {
        if c >= codec.max_code() {
            return NO_BUMP;
        }
        let lo = codec.decode(c, e).to_exact();
        let step = step_of(c);
        let hi = lo + step;
        let exact = f32_to_exact(v);
        let loss = exact.saturating_sub(lo);
        if step == 0 || loss == 0 || hi.saturating_sub(exact) > exact {
            return NO_BUMP;
        }
        // loss < step, so the quotient fits in 16 bits; scale loss first without overflow (both < 2^101).
        let q = if loss < (1u128 << 110) { (loss << 16) / step } else { loss / (step >> 16).max(1) };
        q.min(0xffff) as u32
    };
    // The losses of the rounded-down codes, computed once (a 128-bit division each): the threshold search below
    // reads them 17 times. Entries past the cache (rows longer than the writer's blocks) are computed as needed.
    // A bump makes the entry's loss zero, and every pass below visits an entry once, before or after its bump,
    // so the cached loss of the rounded-down code is the one each pass needs.
    let mut cache = [NO_BUMP; QUANT_BLOCK];
    for ((slot, &c), &v) in cache.iter_mut().zip(codes.iter()).zip(values) {
        *slot = frac_loss(c, v);
    }
    let loss_of = |k: usize, c: u16, v: f32| cache.get(k).copied().unwrap_or_else(|| frac_loss(c, v));
    // Find the smallest threshold t such that bumping every entry with frac_loss >= t fits in the slack.
    let cost_at = |t: u32| -> u128 {
        let mut cost: u128 = 0;
        for (k, (&c, &v)) in codes.iter().zip(values).enumerate() {
            let f = loss_of(k, c, v);
            if f != NO_BUMP && f >= t {
                cost = cost.saturating_add(step_of(c));
            }
        }
        cost
    };
    let (mut lo, mut hi) = (1u32, 0x1_0000u32); // cost_at(0x10000) = 0 always fits
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if cost_at(mid) <= slack {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    let t = lo;
    for (k, (c, &v)) in codes.iter_mut().zip(values).enumerate() {
        let f = loss_of(k, *c, v);
        if f != NO_BUMP && f >= t {
            let step = step_of(*c);
            if step <= slack {
                *c += 1;
                slack -= step;
                sum += step;
            }
        }
    }
    // Entries below the threshold: hand out what is left in cyclic order from `start`.
    let len = codes.len();
    let start = if len == 0 { 0 } else { start % len };
    for k in (start..len).chain(0..start) {
        let (Some(c), Some(&v)) = (codes.get_mut(k), values.get(k)) else { continue };
        let f = loss_of(k, *c, v);
        if f != NO_BUMP && f < t {
            let step = step_of(*c);
            if step <= slack {
                *c += 1;
                slack -= step;
                sum += step;
            }
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The f32 decoder gives the `Frac` path's bits for every code of every standard codec at row exponents
    /// across the range, and takes the `Frac` path where its bit path would not be exact.
    #[test]
    fn f32_row_decoder_matches_the_frac_path() {
        let codecs = [
            FfCodec::FLOAT16,
            FfCodec::FLOAT8,
            FfCodec::LINEAR16,
            FfCodec::LINEAR8,
            FfCodec { bits: 16, exponent_bits: 2 },
            FfCodec { bits: 8, exponent_bits: 1 },
        ];
        for codec in codecs {
            for e in [0u8, 1, 7, 20, 40, 63, MAX_ROW_EXPONENT] {
                let row = codec.row_decoder(e);
                let d = F32RowDecoder::new(row);
                assert!(d.is_fast(), "{codec} row exponent {e}: the bit path should apply");
                for c in 0..=u32::from(codec.max_code()) + 3 {
                    let (got, want) = (d.decode(c), row.decode(c).to_f32());
                    assert_eq!(got.to_bits(), want.to_bits(), "{codec} e {e} code {c}: {got} vs {want}");
                    if c <= u32::from(codec.max_code()) {
                        let fast = d.decode_fast(c);
                        assert_eq!(
                            fast.to_bits(),
                            want.to_bits(),
                            "{codec} e {e} code {c}: fast {fast} vs {want}"
                        );
                    }
                }
            }
        }
        // A base beyond the f32 exponent range (not a valid row exponent): the Frac path, same values.
        let row = RowDecoder { max_code: 0xffff, m_bits: 12, base: 140 };
        let d = F32RowDecoder::new(row);
        assert!(!d.fast);
        for c in (0..=0xffffu32).step_by(13) {
            assert_eq!(d.decode(c).to_bits(), row.decode(c).to_f32().to_bits(), "code {c}");
        }
    }

    /// The inverted decoding rule agrees with the binary search at every code's value, one unit either side,
    /// and between codes, for every codec and row exponents across the range (0 and the largest included).
    #[test]
    fn round_down_matches_the_search() {
        for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8, FfCodec::LINEAR16, FfCodec::LINEAR8] {
            for e in [0u8, 1, 7, 20, 40, 63, MAX_ROW_EXPONENT] {
                let step = if codec.bits == 16 { 7 } else { 1 };
                for c in (0..=u32::from(codec.max_code())).step_by(step) {
                    let v = codec.decode(c as u16, e).to_exact();
                    let next = codec.decode((c + 1).min(u32::from(codec.max_code())) as u16, e).to_exact();
                    for x in
                        [v, v.saturating_sub(1), v + 1, v + (next.saturating_sub(v)) / 2, v.saturating_mul(3)]
                    {
                        let want = codec.round_down_search(x, e);
                        assert_eq!(codec.round_down(x, e), want, "{codec:?} e={e} code {c} exact {x}");
                        // The guess itself is exact: the confirming steps are one decode each, no search.
                        let guess = codec.code_guess(x, e).min(u32::from(codec.max_code()));
                        assert_eq!(guess, u32::from(want), "{codec:?} e={e} code {c} exact {x}: guess");
                    }
                }
                assert_eq!(codec.round_down(u128::MAX, e), codec.max_code());
            }
        }
    }

    #[test]
    fn float_codes_are_monotone_and_continuous() {
        for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8, FfCodec::LINEAR16, FfCodec::LINEAR8] {
            let mut prev = 0u128;
            for c in 1..=codec.max_code() {
                let v = codec.decode(c, 3).to_exact();
                assert!(v > prev, "{codec:?} code {c} not above code {}", c - 1);
                prev = v;
            }
            // The top code sits just below 2^(1-e).
            assert!(prev < 1u128 << (EXACT_SHIFT - 2), "{codec:?} top code {prev} reaches 2^-2");
        }
    }

    #[test]
    fn row_exponent_puts_max_in_top_binade() {
        assert_eq!(row_exponent_for(f32_to_exact(1.0)), 0);
        assert_eq!(row_exponent_for(f32_to_exact(0.5)), 1);
        assert_eq!(row_exponent_for(f32_to_exact(0.49)), 2);
        assert_eq!(row_exponent_for(f32_to_exact(1e-30)), MAX_ROW_EXPONENT);
    }

    /// Relative error bound of the row codec for entries in the normal range, absolute bound below it.
    fn check_row(codec: FfCodec, values: &[f32]) -> Result<(), TestCaseError> {
        let target = values.iter().fold(0u128, |s, &v| s + f32_to_exact(v)).min(1u128 << EXACT_SHIFT);
        let mut codes = [0u16; 64];
        let codes = &mut codes[..values.len()];
        let e = quantize_row(codec, values, target, codes);
        let mut sum = 0u128;
        let max = values.iter().copied().fold(0.0f32, f32::max);
        let m_bits = i32::from(codec.bits - codec.exponent_bits);
        let normal_floor = if codec.exponent_bits == 0 {
            f32::INFINITY
        } else {
            max * pow2_f32(-((1i32 << codec.exponent_bits) - 2))
        };
        for (&c, &v) in codes.iter().zip(values) {
            let d = codec.decode(c, e);
            sum += d.to_exact();
            // Slack never more than doubles an entry (a step below the float range can be many times it).
            prop_assert!(d.to_f32() <= 2.0 * v * (1.0 + 1e-6), "{codec:?} v={v} bumped to {}", d.to_f32());
            let err = (d.to_f32() - v).abs();
            if v >= normal_floor {
                // Relative error < 2^-M (one code step in the normal range), plus f32 rounding of the check.
                prop_assert!(
                    err <= v * pow2_f32(-m_bits) * (1.0 + 1e-6),
                    "{codec:?} v={v} d={} err={err}",
                    d.to_f32()
                );
            } else {
                let abs_bound = if codec.exponent_bits == 0 {
                    max * pow2_f32(-(i32::from(codec.bits) - 1))
                } else {
                    max * pow2_f32(-(m_bits + (1i32 << codec.exponent_bits) - 2))
                };
                prop_assert!(err <= abs_bound * (1.0 + 1e-6), "{codec:?} v={v} err={err} bound={abs_bound}");
            }
        }
        prop_assert!(sum <= target, "{codec:?} decoded sum above target");
        Ok(())
    }

    /// What the row rounding promises about a row's decoded sum (module docs of [`crate::codec`], "Row-sum
    /// rounding"): never above the target (the exact sum capped at 1), and short of it by less than the code
    /// step of any entry that was rounded down and could have been bumped, or else by no more than the losses
    /// `L` of the entries the rounding may not bump (those below half their step, which a bump would more than
    /// double): `target - sum <= L + min(step of rounded-down bumpable entries)`, and `< L + top step`.
    fn check_row_sum(codec: FfCodec, values: &[f32]) -> Result<(), TestCaseError> {
        let exact: u128 = values.iter().map(|&v| f32_to_exact(v)).sum();
        let target = exact.min(1u128 << EXACT_SHIFT);
        let mut codes = [0u16; 64];
        let codes = &mut codes[..values.len()];
        let e = quantize_row(codec, values, target, codes);
        let sum: u128 = codes.iter().map(|&c| codec.decode(c, e).to_exact()).sum();
        prop_assert!(sum <= target, "{codec:?}: decoded sum {sum} above target {target}");
        let (mut unbumpable_loss, mut min_step) = (0u128, u128::MAX);
        let mut top_step = 0u128;
        for (&c, &v) in codes.iter().zip(values) {
            let x = f32_to_exact(v);
            let d = codec.decode(c, e).to_exact();
            let step = codec.decode(c.saturating_add(1), e).to_exact().saturating_sub(d);
            top_step = top_step.max(step);
            if d < x {
                if c < codec.max_code() && d + step <= 2 * x {
                    min_step = min_step.min(step);
                } else {
                    unbumpable_loss += x - d;
                }
            }
        }
        let slack = target - sum;
        let allowed = unbumpable_loss + if min_step == u128::MAX { 0 } else { min_step };
        prop_assert!(slack <= allowed, "{codec:?}: short by {slack}, allowed {allowed}");
        prop_assert!(slack < unbumpable_loss + top_step.max(1), "{codec:?}: short by {slack} >= a top step");
        Ok(())
    }

    /// A row of `n` entries spread log-uniformly over `binades` binades below 1, scaled to sum below 1.
    fn random_row(rng: &mut proptest::test_runner::TestRng, n: usize, binades: f32, out: &mut [f32; 64]) {
        let unit =
            |rng: &mut proptest::test_runner::TestRng| (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for v in out[..n].iter_mut() {
            *v = libm::exp2f(-binades * unit(rng));
        }
        let s: f32 = out[..n].iter().sum();
        for v in out[..n].iter_mut() {
            *v /= s * 1.0001;
        }
    }

    /// The per-entry rounding error has no round-down bias, measured two ways over `R = 4000` random rows of
    /// 8 to 63 entries spread over 5 binades below each row's largest (all in the float codes' normal range, so
    /// every entry can go either way and no entry is too small to bump).
    ///
    /// 1. In absolute terms, per row `a_r = sum_k err_k / (n_r S_r)` with `S_r` the step of the row's top code
    ///    (every step is at most `S_r`). The row-sum rounding makes `sum_k err_k = -(target - sum)`, which is in
    ///    `(-S_r, 0]` here (`check_row_sum`: no unbumpable entries, and the shortfall is below some step), so
    ///    the mean of `a_r` lies in `(-mean(1 / n_r), 0]`: asserted. Rounding down alone gives
    ///    `-sum_k f_k s_k / (n_r S_r)`, about `-1/2` times the mean step ratio, asserted to fall outside.
    /// 2. In each entry's own steps, `e_k = err_k / s_k` in `(-1, 1]`. Rounding down alone gives `-f_k`, mean
    ///    `-1/2`. The row rounding bumps the entries whose fractional part is above a common threshold and
    ///    gives what is left of the row's slack (up to one large step) to entries with smaller steps, so small
    ///    entries are rounded up somewhat more often than down and large ones the other way; that moves no
    ///    energy out of the row, and the mean of `e_k` is not negative. Rows are independent and a row's mean
    ///    of `e_k` is in `[-1, 1]`, so by Hoeffding's inequality the mean over rows is within `x = 0.1` of its
    ///    expectation with probability `1 - 2 exp(-R x^2 / 2) = 1 - 4e-9`: asserted `>= -0.1` (and `<= -0.4`
    ///    for rounding down, `-1/2` within `x`, to show the statistic sees a round-down bias).
    #[test]
    fn rounding_error_has_no_systematic_sign() {
        use proptest::test_runner::{RngAlgorithm, TestRng};
        const ROWS: usize = 4000;
        for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8] {
            let mut rng = TestRng::deterministic_rng(RngAlgorithm::ChaCha);
            let (mut abs_row, mut abs_down, mut abs_floor) = (0.0f64, 0.0f64, 0.0f64);
            let (mut step_row, mut step_down, mut up, mut down) = (0.0f64, 0.0f64, 0usize, 0usize);
            let mut values = [0.0f32; 64];
            let mut codes = [0u16; 64];
            for _ in 0..ROWS {
                let n = 8 + (rng.next_u64() % 56) as usize;
                random_row(&mut rng, n, 5.0, &mut values);
                let values = &values[..n];
                let target: u128 = values.iter().map(|&v| f32_to_exact(v)).sum();
                let e = quantize_row(codec, values, target, &mut codes[..n]);
                let top = codes[..n].iter().copied().max().unwrap_or(0);
                let top_step = (codec.decode(top.saturating_add(1), e).to_exact()
                    - codec.decode(top.saturating_sub(u16::from(top == codec.max_code())), e).to_exact())
                    as f64;
                let (mut err_sum, mut down_sum) = (0.0f64, 0.0f64);
                let (mut in_steps, mut in_steps_down, mut counted) = (0.0f64, 0.0f64, 0usize);
                for (&c, &v) in codes.iter().zip(values) {
                    let x = f32_to_exact(v) as f64;
                    let c0 = codec.round_down(f32_to_exact(v), e);
                    let lo = codec.decode(c0, e).to_exact() as f64;
                    err_sum += codec.decode(c, e).to_exact() as f64 - x;
                    down_sum += lo - x;
                    if c0 == codec.max_code() {
                        continue; // the top code has no code above it to round to
                    }
                    counted += 1;
                    let step = codec.decode(c0 + 1, e).to_exact() as f64 - lo;
                    let d = codec.decode(c, e).to_exact() as f64;
                    in_steps += (d - x) / step;
                    in_steps_down += (lo - x) / step;
                    up += usize::from(d > x);
                    down += usize::from(d < x);
                }
                let r = ROWS as f64;
                abs_row += err_sum / (n as f64 * top_step) / r;
                abs_down += down_sum / (n as f64 * top_step) / r;
                abs_floor -= 1.0 / n as f64 / r;
                let counted = counted.max(1) as f64;
                step_row += in_steps / counted / r;
                step_down += in_steps_down / counted / r;
            }
            std::eprintln!(
                "{codec}: absolute {abs_row:.2e} top steps per entry (allowed [{abs_floor:.2e}, 0], rounding \
                 down {abs_down:.2e}); in own steps {step_row:.4} ({up} up, {down} down), rounding down {step_down:.4}"
            );
            assert!(abs_floor < abs_row && abs_row <= 0.0, "{codec}: absolute mean {abs_row:e}");
            assert!(
                abs_down < abs_floor,
                "{codec}: rounding down gives {abs_down:e}: the statistic is blind"
            );
            assert!(step_row >= -0.1, "{codec}: mean error {step_row} own steps");
            assert!(step_down <= -0.4, "{codec}: rounding down gives {step_down}: the statistic is blind");
        }
    }

    /// A row from `(mantissa, binade)` pairs: entries spread over many binades, then scaled so the row sums to at
    /// most 1; returns the entries and their count.
    fn spread_row(raw: &[(f32, i32)]) -> ([f32; 64], usize) {
        let mut values = [0.0f32; 64];
        let n = raw.len().min(64);
        for (v, &(m, k)) in values.iter_mut().zip(raw) {
            *v = m * pow2_f32(-k);
        }
        let s: f32 = values[..n].iter().sum();
        if s > 1.0 {
            for v in &mut values[..n] {
                *v /= s * 1.0001;
            }
        }
        (values, n)
    }

    proptest! {
        #[test]
        fn row_sum_is_within_a_step_below_its_target(
            raw in proptest::collection::vec((0.0f32..1.0, 0i32..30), 1..64),
        ) {
            let (values, n) = spread_row(&raw);
            for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8, FfCodec::LINEAR16, FfCodec::LINEAR8] {
                check_row_sum(codec, &values[..n])?;
            }
        }

        #[test]
        fn codec_error_bounds_hold_on_random_rows(
            raw in proptest::collection::vec((0.0f32..1.0, 0i32..30), 1..64),
        ) {
            let (values, n) = spread_row(&raw);
            for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8, FfCodec::LINEAR16, FfCodec::LINEAR8] {
                check_row(codec, &values[..n])?;
            }
        }

    }
}
