//! The form-factor codec of a bake: its choice by code width (step 6) and the check that the decoded rows are
//! still a physical system (step 7).

use radiosity_core::FfCodec;

use super::{shooting_form, BakeError, Decoded};

/// The form-factor codec for a code width: 16 -> [`FfCodec::FLOAT16`], 8 -> [`FfCodec::FLOAT8`].
///
/// # Errors
/// [`BakeError::BadBits`] for any other width.
pub fn codec_for_bits(bits: u32) -> Result<FfCodec, BakeError> {
    match bits {
        16 => Ok(FfCodec::FLOAT16),
        8 => Ok(FfCodec::FLOAT8),
        _ => Err(BakeError::BadBits(bits)),
    }
}

/// The slack on row sums above 1 that the shooting form of `codec`'s decoded rows may take, for a bake at
/// `row_sum_tolerance`.
///
/// The decoded rows' shooting form exceeds the original's row sums by the codec's rounding: an entry in the
/// float range is bumped up by at most one code step, at most `2^-M` of the entry for `M` mantissa bits (core's
/// crate docs, "Error bounds"), so its row sums may exceed `1 + row_sum_tolerance` by that factor (`2^-5` with
/// 8-bit codes); the stored rows the device shoots stay `<= 1`. Beyond that allowance, steps of tiny entries
/// (below the float range, where the writer may round up an entry that is at least half a step) scaled by large
/// sender/receiver area ratios are at work: the codec is too coarse for the scene
/// ([`BakeError::CodecTooCoarse`]).
#[must_use]
pub fn decoded_row_sum_tolerance(codec: FfCodec, row_sum_tolerance: f64) -> f64 {
    let mantissa_bits = i32::from(codec.bits.saturating_sub(codec.exponent_bits));
    row_sum_tolerance + 2f64.powi(-mantissa_bits) * (1.0 + row_sum_tolerance)
}

/// Step 7: every patch's decoded incoming form factors (the shooting form of the decoded rows) sum to at most
/// `1 + tolerance` ([`decoded_row_sum_tolerance`]).
///
/// # Errors
/// [`BakeError::CodecTooCoarse`] naming the first patch that exceeds it.
pub(super) fn check_codec(dec: &Decoded, codec: FfCodec, tolerance: f64) -> Result<(), BakeError> {
    let incoming = shooting_form(&dec.rows, &dec.area);
    for row in 0..incoming.n() {
        let sum: f64 = incoming.row(row).map(|(_, f)| f).sum();
        if sum > 1.0 + tolerance {
            let ratio = incoming.row(row).map(|(j, _)| dec.area[j] / dec.area[row]).fold(0.0, f64::max);
            return Err(BakeError::CodecTooCoarse {
                bits: codec.bits,
                patch: row,
                area: dec.area[row],
                sum,
                tolerance,
                ratio,
            });
        }
    }
    Ok(())
}
