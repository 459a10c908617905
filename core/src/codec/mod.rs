//! Quantization codecs: form factors, reflectance and emission, as small integer codes.
//!
//! Every decoded value is a *dyadic* number `mantissa * 2^-shift` ([`Frac`] for values in `[0, 1]`), so the
//! f32 path and the integer fixed-point path decode the same code to the same exact value, and the table
//! parser can sum a row's decoded form factors exactly in integer arithmetic.
//!
//! # Form-factor codes ([`FfCodec`])
//! A row (one shooter) stores a *row exponent* `e` (one byte, `0..=64`) and one code of `bits` = 8 or 16 bits
//! per entry. The code is a small unsigned float with `exponent_bits` = `E` exponent bits and
//! `M = bits - E` mantissa bits, placed below the row scale `2^-e`:
//! - field `x = code >> M`, `m = code & (2^M - 1)`;
//! - `x == 0` (subnormal): `value = m * 2^-(e + M + 2^E - 2)`;
//! - `x >= 1` (normal): `value = (2^M + m) * 2^-(e + M + 2^E - 1 - x)`.
//!
//! With `E = 0` this is a plain block-linear code `value = q * 2^-(e + bits - 1)`. In both cases code order is
//! value order, so rounding down is a binary search. The writer picks `e = floor(-log2(row max))`, so the row's
//! largest entry sits in the top binade `[2^-e, 2^(1-e))`.
//!
//! Worst-case error of one entry (round down, or bumped up by one code during slack distribution, so always
//! less than one code step):
//! - float code (`E >= 1`): relative error `< 2^-M` for entries `>= row_max * 2^-(2^E - 2)`; below that an
//!   absolute error `< row_max * 2^-(M + 2^E - 2)`.
//! - linear code (`E = 0`): absolute error `< row_max * 2^-(bits - 1)`.
//!
//! A bump never more than doubles an entry (see below), so a decoded entry is at most twice its true value.
//!
//! The `codec_error` example measures each codec on a closed cube (its generated
//! `core/examples/codec_error.md`); the crate docs ("Error bounds") say why [`FfCodec::FLOAT16`] (`E = 4, M = 12`) and [`FfCodec::FLOAT8`]
//! (`E = 3, M = 5`) are the defaults.
//!
//! # Row-sum rounding
//! The writer rounds every entry down, then spends the remaining slack (exact target minus decoded sum,
//! with the target capped at 1) on the entries whose fractional rounding loss is largest, one code step each,
//! never exceeding the target, and only on entries the step at most doubles: below the float range a step can
//! be many times a tiny entry, and the receiver's incoming (shooting-form) row multiplies the excess by the
//! sender's area over its own. So every row's decoded sum is `<=` its true sum and `<= 1`, which makes the
//! solver's iteration matrix `R F` have row sums `< 1` (reflectance codes are `< 1`): shooting converges. The
//! deficit is less than one code step plus the losses of entries smaller than half a step, which are only
//! rounded down. A row whose true sum is above 1 (the writer accepts up to `1 + ROW_SUM_SLACK`) can round down
//! to more than 1; its largest entry is then lowered by whole code steps until the decoded sum is `<= 1`.
//!
//! This is largest-remainder rounding (Hamilton's apportionment method) under the constraint `sum <= target`:
//! each entry ends on one of the two codes around it, the upper one for the entries with the largest
//! fractional parts that the slack pays for, so it is round to nearest except where the row sum forbids it.
//! It has no round-down bias (`rounding_error_has_no_systematic_sign`): the errors of a row add up to minus
//! its shortfall, bounded as above (`row_sum_is_within_a_step_below_its_target`), so the mean error is zero
//! to within a fraction of one step per row. Measured in each entry's own steps, small entries are rounded up
//! somewhat more often than down and large ones the other way (what is left of the slack after the threshold
//! pass, up to one large step, goes to entries with smaller steps); that moves energy between the entries of
//! a row, never out of it. Rounding to nearest and then fixing the row sum on the largest entries can leave
//! those more than one step off (half a step from the rounding, a whole one from the fix) and the row short by
//! up to a whole top step, where here every entry stays within one step and the row within the smallest step
//! that would fit. What the rounding costs a scene's answer is the form-factor part of the quantization
//! component of `radiosity check`; the reflectance and emission codes add their own.
//!
//! # Reflectance code
//! `u16` `q`, `rho = q / 65536`, round to nearest, so `0 <= rho <= 65535/65536 < 1` always; absolute error
//! `<= 2^-17` (7.6e-6) for inputs in `[0, 65535/65536]`.
//!
//! # Emission code (radiometric values: emission, irradiance)
//! `u16` with 6 exponent bits `x` and 10 mantissa bits `m`: `x == 0`: `m * 2^-40`; else
//! `(1024 + m) * 2^(x - 41)`. Range `[2^-30, (2 - 2^-10) * 2^32]` = `[9.3e-10, 8.6e9]` with relative error
//! `<= 2^-11` (4.9e-4, round to nearest); below `2^-30` absolute error `<= 2^-41`. Code 0 is exactly 0.
//!
//! # Transfer response code
//! See [`transfer`]: the 16-bit small float of the form-factor rows under a power-of-two scale per light group
//! and channel, for the transfer basis (crate docs, "Transfer basis").

mod ff;
mod radiometric;
pub mod transfer;

pub(crate) use ff::{f32_to_exact, pow2_f32, EXACT_SHIFT, QUANT_BLOCK};
pub(crate) use ff::{quantize_row_with_exponent, row_exponent_for};
pub use ff::{CodecParamError, F32RowDecoder, FfCodec, Frac, RowDecoder, MAX_ROW_EXPONENT};
pub use radiometric::{
    decode_emission, decode_emission_f32, decode_reflectance, encode_emission, encode_reflectance,
    EMISSION_MAX,
};
