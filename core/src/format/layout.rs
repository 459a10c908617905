//! The byte layout: the postcard header, the size of every section ([`SectionSizes`]), and the little-endian readers
//! that parse and the read views share (format module docs, and `docs/format.md`).

use serde::{Deserialize, Serialize};

use crate::codec::transfer::decode_transfer;

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

/// Bytes of each part of a table blob, in blob order (format module docs, "Payload sections").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SectionSizes {
    /// The postcard header.
    pub header: usize,
    /// Patch areas (`f32` per patch).
    pub patch_area: usize,
    /// Patch materials (`u16` per patch).
    pub patch_material: usize,
    /// Static emission codes (3 x `u16` per patch).
    pub base_emission: usize,
    /// Static irradiance codes (3 x `u16` per patch).
    pub base_irradiance: usize,
    /// Material reflectance codes (3 x `u16` per material).
    pub reflectance: usize,
    /// Light-group ids (`u32` per group).
    pub group_id: usize,
    /// Light-group default intensities (3 x `f32` per group).
    pub group_intensity: usize,
    /// Light-group member starts (`u32` per group, plus one).
    pub group_start: usize,
    /// Member patches (an index per member).
    pub member_patch: usize,
    /// Member unit emission codes (3 x `u16` per member).
    pub member_emission: usize,
    /// The state map's patch per slot (0 when every patch has state).
    pub state_patch: usize,
    /// The state map's material per slot (0 when every patch has state).
    pub state_material: usize,
    /// Row starts (`u32` per slot, plus one).
    pub row_start: usize,
    /// Row exponents (`u8` per slot).
    pub row_exponent: usize,
    /// Entry receivers (an index per entry).
    pub entry_receiver: usize,
    /// Entry form-factor codes.
    pub entry_code: usize,
    /// Transfer scale exponents (3 x `i8` per group; 0 without the transfer basis).
    pub transfer_exponent: usize,
    /// Transfer response codes (3 x `u16` per patch and group; 0 without the transfer basis).
    pub transfer_code: usize,
    /// The CRC-32.
    pub crc: usize,
}

impl SectionSizes {
    /// The sizes a header implies, or `None` on arithmetic overflow (of a section or of the whole blob).
    pub(crate) fn of_header(h: &Header, header_len: usize) -> Option<SectionSizes> {
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
        let sizes = SectionSizes {
            header: header_len,
            patch_area: n.checked_mul(4)?,
            patch_material: n.checked_mul(2)?,
            base_emission: n.checked_mul(6)?,
            base_irradiance: n.checked_mul(6)?,
            reflectance: m.checked_mul(6)?,
            group_id: g.checked_mul(4)?,
            group_intensity: g.checked_mul(12)?,
            group_start: g.checked_add(1)?.checked_mul(4)?,
            member_patch: mc.checked_mul(ib)?,
            member_emission: mc.checked_mul(6)?,
            state_patch: sm.checked_mul(ib)?,
            state_material: sm.checked_mul(2)?,
            row_start: s.checked_add(1)?.checked_mul(4)?,
            row_exponent: s,
            entry_receiver: nnz.checked_mul(ib)?,
            entry_code: nnz.checked_mul(cb)?,
            transfer_exponent: tg.checked_mul(3)?,
            transfer_code: tn.checked_mul(tg)?.checked_mul(6)?,
            crc: 4,
        };
        sizes.parts().into_iter().try_fold(0usize, usize::checked_add)?;
        Some(sizes)
    }

    /// Every part's size in blob order: the header, the payload sections, the CRC.
    fn parts(&self) -> [usize; 20] {
        [
            self.header,
            self.patch_area,
            self.patch_material,
            self.base_emission,
            self.base_irradiance,
            self.reflectance,
            self.group_id,
            self.group_intensity,
            self.group_start,
            self.member_patch,
            self.member_emission,
            self.state_patch,
            self.state_material,
            self.row_start,
            self.row_exponent,
            self.entry_receiver,
            self.entry_code,
            self.transfer_exponent,
            self.transfer_code,
            self.crc,
        ]
    }

    /// Everything between header and CRC.
    #[must_use]
    pub fn payload(&self) -> usize {
        self.parts().into_iter().skip(1).take(18).fold(0, usize::saturating_add)
    }

    /// The whole blob.
    #[must_use]
    pub fn total(&self) -> usize {
        self.parts().into_iter().fold(0, usize::saturating_add)
    }
}

// Byte offsets cannot overflow: on 32-bit targets `usize` is 32 bits, and an index is checked against the
// element count (`len / width`) before it is scaled.
#[inline]
pub(super) fn le_u16(s: &[u8], i: usize) -> u16 {
    // `i < len / 2` makes `2 i + 2 <= len`: one comparison, and the compiler drops the slice's own checks.
    if i >= s.len() / 2 {
        return 0;
    }
    let at = 2 * i;
    match s.get(at..at + 2) {
        Some(&[a, b]) => u16::from_le_bytes([a, b]),
        _ => 0,
    }
}

#[inline]
pub(super) fn le_u32(s: &[u8], i: usize) -> u32 {
    // As `le_u16`: one comparison bounds the read.
    if i >= s.len() / 4 {
        return 0;
    }
    let at = 4 * i;
    match s.get(at..at + 4) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

pub(super) fn le_f32(s: &[u8], i: usize) -> f32 {
    f32::from_bits(le_u32(s, i))
}

/// The RGB triple of `u16` codes at element `i` of a section of triples.
pub(super) fn rgb16(s: &[u8], i: usize) -> [u16; 3] {
    // One range check for the three values.
    let at = i.saturating_mul(6);
    match s.get(at..at.saturating_add(6)) {
        Some(&[r0, r1, g0, g1, b0, b1]) => {
            [u16::from_le_bytes([r0, r1]), u16::from_le_bytes([g0, g1]), u16::from_le_bytes([b0, b1])]
        }
        _ => [0; 3],
    }
}

/// A table's transfer basis section (`docs/format.md`): per light group three scale exponents, per element
/// (a flat table's patch, a hierarchical table's leaf) and group three response codes, element-major. Flat and
/// hierarchical tables lay it out alike; both hand out this view once parsed.
#[derive(Clone, Copy, Debug)]
pub struct TransferSection<'a> {
    exponents: &'a [u8],
    codes: &'a [u8],
    elements: u32,
    groups: u32,
}

impl<'a> TransferSection<'a> {
    /// The view over a parsed table's sections (sizes checked by the parser).
    pub(super) fn new(exponents: &'a [u8], codes: &'a [u8], elements: u32, groups: u32) -> Self {
        TransferSection { exponents, codes, elements, groups }
    }

    /// Elements (patches or leaves) the section has responses for.
    #[must_use]
    pub fn elements(&self) -> u32 {
        self.elements
    }

    /// Light groups.
    #[must_use]
    pub fn groups(&self) -> u32 {
        self.groups
    }

    /// Scale exponents `K` (RGB) of light `group`: its codes decode to `f(q) 2^K` W/m^2 at unit intensity
    /// ([`crate::codec::transfer`]); `None` out of range.
    #[must_use]
    pub fn exponent(&self, group: u32) -> Option<[i8; 3]> {
        (group < self.groups).then(|| {
            let at = group as usize * 3;
            [0, 1, 2].map(|c| self.exponents.get(at + c).map_or(0, |&b| b as i8))
        })
    }

    /// Response codes (RGB) of `element` to light `group`; `None` out of range.
    #[must_use]
    pub fn code(&self, element: u32, group: u32) -> Option<[u16; 3]> {
        // element < n, group < g and n * g * 6 bytes fit (checked by the layout), so no overflow.
        (element < self.elements && group < self.groups)
            .then(|| rgb16(self.codes, element as usize * self.groups as usize + group as usize))
    }

    /// The response codes of every element from `element` on (element-major, as [`TransferSection::codes_of`]
    /// of each in turn); empty from the last element on.
    #[must_use]
    pub fn codes_from(&self, element: u32) -> &'a [u8] {
        let at = (element as usize).saturating_mul(self.groups as usize * 6);
        self.codes.get(at..).unwrap_or(&[])
    }

    /// Every response code of `element` (3 x `u16` little-endian per group, groups in order): one slice for
    /// the transfer relight's inner loop; `None` out of range.
    #[must_use]
    pub fn codes_of(&self, element: u32) -> Option<&'a [u8]> {
        if element >= self.elements {
            return None;
        }
        let per = self.groups as usize * 6;
        let at = element as usize * per;
        self.codes.get(at..at + per)
    }

    /// The decoded response `T_g` (W/m^2 at unit intensity, RGB) of `element` to light `group`.
    #[must_use]
    pub fn response(&self, element: u32, group: u32) -> Option<[f32; 3]> {
        let code = self.code(element, group)?;
        let k = self.exponent(group)?;
        Some([0, 1, 2].map(|c| decode_transfer(code[c], k[c])))
    }
}
