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

use crate::base::{static_from_codes, static_radiosity};
use crate::format::{HierTable, Table, TransferSection};
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
        /// Elements (patches or leaves) in the table.
        needed: u32,
        /// Entries given.
        got: usize,
    },
    /// The table has more light groups than a transfer relight takes ([`MAX_TRANSFER_GROUPS`]).
    TooManyGroups {
        /// Light groups in the table.
        groups: u32,
        /// The most a relight takes.
        max: u32,
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
                write!(f, "transfer relight: output holds {got} elements, the table has {needed}")
            }
            TransferError::TooManyGroups { groups, max } => {
                write!(
                    f,
                    "transfer relight: the table has {groups} light groups, at most {max} are supported"
                )
            }
            TransferError::BadIntensity { group, channel } => {
                write!(f, "transfer relight: intensity of light group {group} channel {channel} not finite")
            }
        }
    }
}

impl core::error::Error for TransferError {}

/// A table whose elements can carry a transfer basis: flat tables ([`Table`], one element per patch) and
/// hierarchical tables ([`HierTable`], one per leaf). Both lay the section out alike ([`TransferSection`]).
pub trait TransferTable {
    /// The transfer basis section, `None` without one.
    fn transfer_section(&self) -> Option<TransferSection<'_>>;
    /// The static radiosity `E_s + rho G_s` of `element` (crate docs, "Static base"), `None` out of range.
    fn element_static<S: Scalar>(&self, element: u32) -> Option<[S; 3]>;
}

impl TransferTable for Table<'_> {
    fn transfer_section(&self) -> Option<TransferSection<'_>> {
        self.transfer()
    }
    fn element_static<S: Scalar>(&self, element: u32) -> Option<[S; 3]> {
        static_radiosity(self, element)
    }
}

impl TransferTable for HierTable<'_> {
    fn transfer_section(&self) -> Option<TransferSection<'_>> {
        self.transfer()
    }
    fn element_static<S: Scalar>(&self, element: u32) -> Option<[S; 3]> {
        let rho = self.reflectance(self.material(element)?)?;
        Some(static_from_codes(self.base_emission(element)?, self.base_irradiance(element)?, rho))
    }
}

/// Work units of one [`relight_transfer`] of `table`: `elements x (groups + 1)` (saturating; 0 without a
/// transfer section).
#[must_use]
pub fn transfer_cost<T: TransferTable>(table: &T) -> u32 {
    table.transfer_section().map_or(0, |t| t.elements().saturating_mul(t.groups().saturating_add(1)))
}

/// Most light groups a transfer relight takes: the per-group scales live on the stack.
pub const MAX_TRANSFER_GROUPS: u32 = 64;

/// Relights the whole table from its transfer basis: `out[i] = B_static_i + sum_g intensity[g] T_g,i`
/// (W/m^2, RGB, per channel), for every element `i` (patch of a flat table, leaf of a hierarchical one).
/// Returns the work units spent, [`transfer_cost`].
///
/// `intensity[g]` is light group `g`'s RGB intensity (the same multiplier as [`crate::Solver::set_light`]);
/// extra entries of `intensity` and `out` are ignored. The answer is for the table's reflectances: after
/// [`crate::Solver::set_reflectance`] use shooting. Never allocates; bounded work; see the module docs for
/// the error bound. In f32 each product is the response code's bits moved into an f32 times the intensity
/// scaled by the group's exponent (bit for bit the product with the decoded response).
///
/// # Errors
/// [`TransferError::NoTransferSection`], [`TransferError::TooManyGroups`],
/// [`TransferError::IntensityTooShort`], [`TransferError::OutputTooSmall`], [`TransferError::BadIntensity`];
/// `out` is untouched on error.
pub fn relight_transfer<S: Scalar, T: TransferTable>(
    table: &T,
    intensity: &[[S; 3]],
    out: &mut [[S; 3]],
) -> Result<u32, TransferError> {
    let Some(section) = table.transfer_section() else {
        return Err(TransferError::NoTransferSection);
    };
    let (n, groups) = (section.elements(), section.groups());
    if groups > MAX_TRANSFER_GROUPS {
        return Err(TransferError::TooManyGroups { groups, max: MAX_TRANSFER_GROUPS });
    }
    if intensity.len() < groups as usize {
        return Err(TransferError::IntensityTooShort { needed: groups, got: intensity.len() });
    }
    if out.len() < n as usize {
        return Err(TransferError::OutputTooSmall { needed: n, got: out.len() });
    }
    let mut scales = [[S::transfer_scale(S::ZERO, 0); 3]; MAX_TRANSFER_GROUPS as usize];
    for (g, (rgb, scale)) in intensity.iter().take(groups as usize).zip(scales.iter_mut()).enumerate() {
        let k = section.exponent(g as u32).unwrap_or([0; 3]);
        for (c, v) in rgb.iter().enumerate() {
            if !v.is_usable() {
                return Err(TransferError::BadIntensity { group: g as u32, channel: c as u8 });
            }
            scale[c] = S::transfer_scale(*v, k[c]);
        }
    }
    let scales = scales.get(..groups as usize).unwrap_or(&[]);
    for (i, o) in (0..n).zip(out.iter_mut()) {
        let mut b = table.element_static::<S>(i).unwrap_or([S::ZERO; 3]);
        let codes = section.codes_of(i).unwrap_or(&[]);
        for (code, scale) in codes.chunks_exact(6).zip(scales) {
            for c in 0..3 {
                let q = u16::from_le_bytes([code[2 * c], code[2 * c + 1]]);
                b[c] = b[c].add(S::transfer_term(q, scale[c]));
            }
        }
        *o = b;
    }
    Ok(transfer_cost(table))
}
