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
//! See [`crate::codec::transfer`]: FLOAT16 codes under a power-of-two scale per light group and channel.
//!
//! # Error bound of a relight
//! Against `B_static + sum_g I_g T_g` with the host's `T_g` and `B_static`, per patch and channel:
//! `sum_g |I_gc| max(2^-13 T_igc, 2^(K_gc - 27))` (response quantization) `+ 2^-11 E_s + (2^-11 + 2^-17) G_s`
//! (the static base's emission and irradiance codes and the reflectance code, see the crate docs, "Error
//! bounds") plus the arithmetic: in `f32` one rounding per product and per sum (`rho G_s` and `E_s + rho G_s`,
//! then `I_g T_g` and its addition for each group: `2 (groups + 1)` roundings, each within `2^-24` of the
//! magnitude `|B_static| + sum_g |I_gc| T_igc`); in fixed point at most `2^-32` per decode of `E_s` and `G_s`
//! and per product, and per group `(1 + |I_gc|) 2^-32` (the response's decode is multiplied by the intensity).
//!
//! # Cost
//! One work unit per patch for the static base (decode `E_s`, `G_s`, `rho`: three multiply-adds) plus one per
//! patch and light group (decode an RGB code triple, three multiply-adds): [`transfer_cost`] `= patches x
//! (groups + 1)`, the same kind of unit as a form-factor entry applied by a shot (crate docs, "Cost model").
//! The pass runs outside any step budget and is not resumable: its cost is known from the counts up front.

use core::fmt;

use crate::base::static_radiosity;
use crate::codec::transfer::decode_transfer_dyadic;
use crate::format::Table;
use crate::scalar::Scalar;

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
