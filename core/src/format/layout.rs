//! The byte layout: the postcard header, the payload sections' byte ranges, and the little-endian readers
//! that parse and the read views share (format module docs, and `docs/format.md`).

use serde::{Deserialize, Serialize};

/// The postcard-encoded header (the part before the payload).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Header {
    pub magic: [u8; 4],
    pub version: u16,
    pub patch_count: u32,
    pub state_count: u32,
    pub material_count: u32,
    pub group_count: u32,
    pub member_count: u32,
    pub entry_count: u32,
    pub ff_bits: u8,
    pub ff_exponent_bits: u8,
    pub index_bytes: u8,
    pub base_solved: bool,
    pub fingerprint: u64,
    pub transfer: bool,
}

/// The version prefix every format version keeps, decoded before the full header.
#[derive(Deserialize)]
pub(super) struct Prefix {
    pub magic: [u8; 4],
    pub version: u16,
}

/// Largest postcard header, in bytes (4 magic + varints: 3 for u16, 5 per u32, 10 per u64, 1 per u8/bool).
pub(crate) const MAX_HEADER_LEN: usize = 4 + 3 + 6 * 5 + 4 + 10 + 1;

/// Byte ranges of the payload sections, in payload order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Layout {
    pub area: usize,
    pub material: usize,
    pub base_emission: usize,
    pub base_irradiance: usize,
    pub reflectance: usize,
    pub group_id: usize,
    pub group_intensity: usize,
    pub group_start: usize,
    pub member_patch: usize,
    pub member_emission: usize,
    pub state_patch: usize,
    pub state_material: usize,
    pub row_start: usize,
    pub row_exponent: usize,
    pub entry_receiver: usize,
    pub entry_code: usize,
    pub transfer_exponent: usize,
    pub transfer_code: usize,
    /// End of the payload (start of the CRC).
    pub end: usize,
}

impl Layout {
    /// Section offsets relative to the payload start, or `None` on arithmetic overflow.
    pub(crate) fn new(h: &Header) -> Option<Layout> {
        let n = h.patch_count as usize;
        let s = h.state_count as usize;
        // The state map is present only when some patch has no state (identity otherwise).
        let sm = if h.state_count < h.patch_count { s } else { 0 };
        let m = h.material_count as usize;
        let g = h.group_count as usize;
        let mc = h.member_count as usize;
        let nnz = h.entry_count as usize;
        let ib = usize::from(h.index_bytes);
        let cb = usize::from(h.ff_bits / 8);
        // The optional transfer basis: per group 3 exponents, per (patch, group) 3 codes of 2 bytes.
        let (tg, tn) = if h.transfer { (g, n) } else { (0, 0) };
        let mut at = 0usize;
        let mut next = |len: Option<usize>| -> Option<usize> {
            let start = at;
            at = at.checked_add(len?)?;
            Some(start)
        };
        let l = Layout {
            area: next(n.checked_mul(4))?,
            material: next(n.checked_mul(2))?,
            base_emission: next(n.checked_mul(6))?,
            base_irradiance: next(n.checked_mul(6))?,
            reflectance: next(m.checked_mul(6))?,
            group_id: next(g.checked_mul(4))?,
            group_intensity: next(g.checked_mul(12))?,
            group_start: next(g.checked_add(1)?.checked_mul(4))?,
            member_patch: next(mc.checked_mul(ib))?,
            member_emission: next(mc.checked_mul(6))?,
            state_patch: next(sm.checked_mul(ib))?,
            state_material: next(sm.checked_mul(2))?,
            row_start: next(s.checked_add(1)?.checked_mul(4))?,
            row_exponent: next(Some(s))?,
            entry_receiver: next(nnz.checked_mul(ib))?,
            entry_code: next(nnz.checked_mul(cb))?,
            transfer_exponent: next(tg.checked_mul(3))?,
            transfer_code: next(tn.checked_mul(tg)?.checked_mul(6))?,
            end: 0,
        };
        Some(Layout { end: at, ..l })
    }
}

// Byte offsets use checked arithmetic: on 32-bit targets `usize` is 32 bits.
#[inline]
pub(super) fn le_u16(s: &[u8], i: usize) -> u16 {
    let Some(at) = i.checked_mul(2) else { return 0 };
    match s.get(at..at.saturating_add(2)) {
        Some(&[a, b]) => u16::from_le_bytes([a, b]),
        _ => 0,
    }
}

#[inline]
pub(super) fn le_u32(s: &[u8], i: usize) -> u32 {
    let Some(at) = i.checked_mul(4) else { return 0 };
    match s.get(at..at.saturating_add(4)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

pub(super) fn le_f32(s: &[u8], i: usize) -> f32 {
    f32::from_bits(le_u32(s, i))
}

/// The RGB triple of `u16` codes at element `i` of a section of triples.
pub(super) fn rgb16(s: &[u8], i: usize) -> [u16; 3] {
    let at = i.saturating_mul(3);
    [le_u16(s, at), le_u16(s, at.saturating_add(1)), le_u16(s, at.saturating_add(2))]
}
