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
//! One work unit per patch for the static base (decode `E_s`, `G_s`, `rho`: three multiply-adds; in a table
//! without static light, [`Table::has_static_base`] false, nothing is read and the base is 0) plus one per
//! patch and light group (decode an RGB code triple, three multiply-adds): [`transfer_cost`] `= patches x
//! (groups + 1)`, the same kind of unit as a form-factor entry applied by a shot (crate docs, "Cost model").
//! The pass runs outside any step budget; [`relight_transfer_range`] splits it into runs of elements (each
//! call's units are its elements x (groups + 1)), so a device can relight in chunks through a small buffer.

use core::fmt;

use crate::base::{static_or_zero, static_radiosity};
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
    /// The first element of a range relight is past the table's last element.
    RangeOutOfTable {
        /// The range's first element.
        first: u32,
        /// Elements (patches or leaves) in the table.
        elements: u32,
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
            TransferError::RangeOutOfTable { first, elements } => {
                write!(f, "transfer relight: range starts at element {first}, the table has {elements}")
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
    /// Whether any element has a static base; without one every [`TransferTable::element_static`] is 0.
    fn has_static_base(&self) -> bool;
}

impl TransferTable for Table<'_> {
    fn transfer_section(&self) -> Option<TransferSection<'_>> {
        self.transfer()
    }
    fn element_static<S: Scalar>(&self, element: u32) -> Option<[S; 3]> {
        static_radiosity(self, element)
    }
    fn has_static_base(&self) -> bool {
        Table::has_static_base(self)
    }
}

impl TransferTable for HierTable<'_> {
    fn transfer_section(&self) -> Option<TransferSection<'_>> {
        self.transfer()
    }
    fn element_static<S: Scalar>(&self, element: u32) -> Option<[S; 3]> {
        let rho = || self.reflectance(self.material(element)?);
        static_or_zero(self.base_emission(element)?, self.base_irradiance(element)?, rho)
    }
    fn has_static_base(&self) -> bool {
        HierTable::has_static_base(self)
    }
}

/// Work units of one [`relight_transfer`] of `table`: `elements x (groups + 1)` (saturating; 0 without a
/// transfer section).
#[must_use]
pub fn transfer_cost<T: TransferTable>(table: &T) -> u32 {
    table.transfer_section().map_or(0, |t| t.elements().saturating_mul(t.groups().saturating_add(1)))
}

/// Light groups whose scales a transfer relight prepares at a time, on the stack: a table with more groups
/// takes one pass over the elements per block of this many (the sums' order, and so their bits, unchanged).
pub const TRANSFER_GROUP_BLOCK: usize = 8;

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
/// [`TransferError::NoTransferSection`], [`TransferError::IntensityTooShort`], [`TransferError::OutputTooSmall`], [`TransferError::BadIntensity`];
/// `out` is untouched on error.
pub fn relight_transfer<S: Scalar, T: TransferTable>(
    table: &T,
    intensity: &[[S; 3]],
    out: &mut [[S; 3]],
) -> Result<u32, TransferError> {
    if let Some(n) = table.transfer_section().map(|t| t.elements()) {
        if out.len() < n as usize {
            return Err(TransferError::OutputTooSmall { needed: n, got: out.len() });
        }
    }
    relight_transfer_range(table, intensity, 0, out)
}

/// [`relight_transfer`] of the elements `first .. first + out.len()` only (clipped at the table's last
/// element): `out[k]` gets element `first + k`, bit for bit what [`relight_transfer`] writes for it. For a
/// device that streams its light map in chunks through a small buffer instead of holding every element's
/// radiosity at once. Returns the work units spent: `count x (groups + 1)` for the `count` elements relit.
///
/// # Errors
/// [`TransferError::RangeOutOfTable`] if `first` is past the last element, and as [`relight_transfer`]
/// (except [`TransferError::OutputTooSmall`]); `out` is untouched on error.
// Not inlined: its scales then sit near the top of its own small stack frame, where every load of one is a
// single instruction (deep in a large caller's frame each takes an extra address computation).
#[inline(never)]
pub fn relight_transfer_range<S: Scalar, T: TransferTable>(
    table: &T,
    intensity: &[[S; 3]],
    first: u32,
    out: &mut [[S; 3]],
) -> Result<u32, TransferError> {
    let Some(section) = table.transfer_section() else {
        return Err(TransferError::NoTransferSection);
    };
    let (n, groups) = (section.elements(), section.groups());
    if intensity.len() < groups as usize {
        return Err(TransferError::IntensityTooShort { needed: groups, got: intensity.len() });
    }
    if first > n {
        return Err(TransferError::RangeOutOfTable { first, elements: n });
    }
    let intensity = intensity.get(..groups as usize).unwrap_or(&[]);
    for (g, rgb) in intensity.iter().enumerate() {
        if let Some(c) = rgb.iter().position(|v| !v.is_usable()) {
            return Err(TransferError::BadIntensity { group: g as u32, channel: c as u8 });
        }
    }
    let count = out.len().min((n - first) as usize);
    let out = out.get_mut(..count).unwrap_or(&mut []);
    // The first block starts every element from its static base (alone when there are no groups); each block
    // adds its groups' terms in group order.
    let mut g0 = 0usize;
    loop {
        let block = intensity.get(g0..).unwrap_or(&[]);
        let block = block.get(..TRANSFER_GROUP_BLOCK).unwrap_or(block);
        let mut scales = [[S::transfer_scale(S::ZERO, 0); 3]; TRANSFER_GROUP_BLOCK];
        for (k, (rgb, scale)) in block.iter().zip(scales.iter_mut()).enumerate() {
            let e = section.exponent((g0 + k) as u32).unwrap_or([0; 3]);
            *scale = [0, 1, 2].map(|c| S::transfer_scale(rgb[c], e[c]));
        }
        let scales = scales.get(..block.len()).unwrap_or(&[]);
        let pass = Pass { table, section, first, g0, init: g0 == 0 };
        // One loop per path, chosen once per block: every product on the one-multiply path (the usual
        // intensities), or each product choosing its own.
        if scales.iter().flatten().all(S::transfer_fast) {
            // The block's size as a constant: its products unrolled with every scale in a register.
            const _: () = assert!(TRANSFER_GROUP_BLOCK == 8, "one arm per block size");
            match scales.len() {
                1 => pass.run_block::<S, 1>(out, scales),
                2 => pass.run_block::<S, 2>(out, scales),
                3 => pass.run_block::<S, 3>(out, scales),
                4 => pass.run_block::<S, 4>(out, scales),
                5 => pass.run_block::<S, 5>(out, scales),
                6 => pass.run_block::<S, 6>(out, scales),
                7 => pass.run_block::<S, 7>(out, scales),
                8 => pass.run_block::<S, 8>(out, scales),
                _ => pass.run(out, scales, S::transfer_term_fast),
            }
        } else {
            pass.run(out, scales, S::transfer_term);
        }
        g0 += block.len();
        if g0 >= intensity.len() {
            break;
        }
    }
    Ok((count as u32).saturating_mul(groups.saturating_add(1)))
}

/// One pass of [`relight_transfer_range`] over its elements for the block of groups from `g0`.
struct Pass<'t, 's, T> {
    table: &'t T,
    section: TransferSection<'s>,
    first: u32,
    /// The block's first group.
    g0: usize,
    /// The first block: start from the static base (read only if the table has one), not from `out`.
    init: bool,
}

impl<T: TransferTable> Pass<'_, '_, T> {
    /// [`Pass::run`] on the one-multiply path for a block of exactly `G` groups (the caller matches
    /// `scales.len()`; any other length writes nothing): the same products and sums in the same order, with the
    /// group loop unrolled.
    #[inline(never)]
    fn run_block<S: Scalar, const G: usize>(&self, out: &mut [[S; 3]], scales: &[[S::TransferScale; 3]]) {
        // A copy, so the scales stay in registers across the elements (behind a reference they are reloaded).
        let Ok(&scales) = <&[[S::TransferScale; 3]; G]>::try_from(scales) else {
            return;
        };
        let statics = self.statics();
        let per = self.section.groups() as usize * 6;
        let at = self.g0 * 6;
        let codes = self.section.codes_from(self.first).chunks_exact(per);
        for (k, (o, element)) in out.iter_mut().zip(codes).enumerate() {
            let mut b = self.start(statics, k, o);
            let block = element.get(at..).unwrap_or(&[]).as_chunks::<6>().0;
            if let Some(block) = block.get(..G).and_then(|b| <&[[u8; 6]; G]>::try_from(b).ok()) {
                for (code, scale) in block.iter().zip(&scales) {
                    // Two-byte arrays copied whole: one 16-bit load each.
                    for (c, &pair) in code.as_chunks::<2>().0.iter().enumerate() {
                        b[c] = b[c].add(S::transfer_term_fast(u16::from_le_bytes(pair), scale[c]));
                    }
                }
            }
            *o = b;
        }
    }

    /// Whether elements start from the static base: the first block of a table that has one.
    fn statics(&self) -> bool {
        self.init && self.table.has_static_base()
    }

    /// What element `first + k` starts from: its static base in the first block (`statics`; zero for a table
    /// without one), else `o`, what the earlier blocks left.
    #[inline(always)]
    fn start<S: Scalar>(&self, statics: bool, k: usize, o: &[S; 3]) -> [S; 3] {
        if statics {
            self.table.element_static::<S>(self.first + k as u32).unwrap_or([S::ZERO; 3])
        } else if self.init {
            [S::ZERO; 3]
        } else {
            *o
        }
    }

    /// `out[k] = (init ? B_static : out[k]) + sum over the block's groups of term(code, the group's scale)`
    /// per channel, for element `first + k`.
    #[inline(always)]
    fn run<S: Scalar>(
        &self,
        out: &mut [[S; 3]],
        scales: &[[S::TransferScale; 3]],
        term: impl Fn(u16, S::TransferScale) -> S,
    ) {
        let statics = self.statics();
        let start = |k: usize, o: &[S; 3]| self.start(statics, k, o);
        let per = self.section.groups() as usize * 6;
        if per == 0 {
            for (k, o) in out.iter_mut().enumerate() {
                *o = start(k, o);
            }
            return;
        }
        let at = self.g0 * 6;
        let codes = self.section.codes_from(self.first).chunks_exact(per);
        for (k, (o, element)) in out.iter_mut().zip(codes).enumerate() {
            let mut b = start(k, o);
            let block = element.get(at..at + 6 * scales.len()).unwrap_or(&[]);
            for (code, scale) in block.chunks_exact(6).zip(scales) {
                for (c, pair) in code.chunks_exact(2).enumerate() {
                    // A two-byte array copied whole: one 16-bit load where the target allows unaligned ones.
                    let q = u16::from_le_bytes(pair.try_into().unwrap_or([0; 2]));
                    b[c] = b[c].add(term(q, scale[c]));
                }
            }
            *o = b;
        }
    }
}
