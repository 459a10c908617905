//! Read views of a parsed [`Table`]: counts, per-patch and per-group accessors, and the rows of form-factor
//! entries. Accessors that take an index from the caller return `Option`; a [`Row`] is proven in bounds by
//! [`Table::parse`], so iterating its entries checks nothing per entry.

use super::layout::{le_f32, le_u16, le_u32, rgb16, SectionSizes, TransferSection};
use super::parse::Table;
use crate::codec::{FfCodec, Frac, RowDecoder};

/// One light-group member: a patch and its emission at unit intensity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Member {
    /// The patch.
    pub patch: u32,
    /// Emission codes (RGB) at unit intensity, see [`crate::codec::decode_emission`].
    pub emission: [u16; 3],
}

impl<'a> Table<'a> {
    #[inline]
    pub(super) fn index(&self, s: &[u8], k: u32) -> u32 {
        if self.header.index_bytes == 2 {
            u32::from(le_u16(s, k as usize))
        } else {
            le_u32(s, k as usize)
        }
    }

    #[inline]
    pub(super) fn code(&self, k: u32) -> u16 {
        if self.codec.bits == 8 {
            u16::from(self.entry_code.get(k as usize).copied().unwrap_or(0))
        } else {
            le_u16(self.entry_code, k as usize)
        }
    }

    /// Number of patches.
    #[must_use]
    pub fn patch_count(&self) -> u32 {
        self.header.patch_count
    }

    /// Number of patches with run-time state, the slots `0..state_count` (see the crate docs, "Run-time
    /// state"); equal to [`Table::patch_count`] when every patch has state.
    #[must_use]
    #[inline]
    pub fn state_count(&self) -> u32 {
        self.header.state_count
    }

    /// Whether every patch has run-time state (slot `s` is patch `s`).
    #[must_use]
    pub fn every_patch_has_state(&self) -> bool {
        self.header.state_count == self.header.patch_count
    }

    /// The patch of `slot`, or `None` if `slot >= state_count`.
    #[must_use]
    pub fn slot_patch(&self, slot: u32) -> Option<u32> {
        if slot >= self.state_count() {
            None
        } else if self.every_patch_has_state() {
            Some(slot)
        } else {
            Some(self.index(self.state_patch, slot))
        }
    }

    /// The slot of `patch`, or `None` if the patch has no run-time state or is out of range. A binary search
    /// over the state map (`O(log state_count)`) when some patch has no state, else the identity.
    #[must_use]
    pub fn slot_of(&self, patch: u32) -> Option<u32> {
        if patch >= self.patch_count() {
            return None;
        }
        if self.every_patch_has_state() {
            return Some(patch);
        }
        // The map is strictly increasing (checked by parse), so bisection finds the patch if present.
        let (mut lo, mut hi) = (0u32, self.state_count());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let p = self.index(self.state_patch, mid);
            if p == patch {
                return Some(mid);
            }
            if p < patch {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        None
    }

    /// Material of the patch of `slot` (read from the slot-ordered section: no map lookup), or `None` out of
    /// range.
    #[must_use]
    #[inline]
    pub fn slot_material(&self, slot: u32) -> Option<u32> {
        (slot < self.state_count()).then(|| u32::from(le_u16(self.state_material, slot as usize)))
    }

    /// Number of materials.
    #[must_use]
    pub fn material_count(&self) -> u32 {
        self.header.material_count
    }

    /// Number of light groups.
    #[must_use]
    pub fn group_count(&self) -> u32 {
        self.header.group_count
    }

    /// Number of stored form-factor entries.
    #[must_use]
    #[inline]
    pub fn entry_count(&self) -> u32 {
        self.header.entry_count
    }

    /// The form-factor codec.
    #[must_use]
    pub fn codec(&self) -> FfCodec {
        self.codec
    }

    /// Whether the static base irradiance is a converged solution (see the crate docs, "Static base").
    #[must_use]
    pub fn base_solved(&self) -> bool {
        self.header.base_solved
    }

    /// The scene fingerprint the host stored: identifies the scene and meshing the table was baked from (the
    /// host's `bake::scene_fingerprint`; 0 if the writer was given none). Core does not interpret it.
    #[must_use]
    pub fn fingerprint(&self) -> u64 {
        self.header.fingerprint
    }

    /// Whether any patch has a static base (emission or irradiance code other than 0); without one every
    /// patch's static radiosity is 0 and the transfer relight skips it.
    #[must_use]
    pub fn has_static_base(&self) -> bool {
        self.static_base
    }

    /// Whether the table carries the optional transfer basis (see [`crate::transfer`]).
    #[must_use]
    pub fn has_transfer(&self) -> bool {
        self.header.transfer
    }

    /// The transfer basis section, `None` without one.
    #[must_use]
    pub fn transfer(&self) -> Option<TransferSection<'a>> {
        self.has_transfer().then(|| {
            TransferSection::new(
                self.transfer_exponent,
                self.transfer_code,
                self.patch_count(),
                self.group_count(),
            )
        })
    }

    /// Transfer-basis scale exponents `k` (RGB) of light `group`: its response codes decode to `f(q) 2^k`
    /// W/m^2 at unit intensity. `None` without a transfer section or out of range.
    #[must_use]
    pub fn transfer_exponent(&self, group: u32) -> Option<[i8; 3]> {
        self.transfer()?.exponent(group)
    }

    /// Transfer-basis response codes (RGB) of `patch` to light `group` at unit intensity (see
    /// [`crate::transfer`]). `None` without a transfer section or out of range.
    #[must_use]
    pub fn transfer_code(&self, patch: u32, group: u32) -> Option<[u16; 3]> {
        self.transfer()?.code(patch, group)
    }

    /// The decoded transfer response `T_g` (W/m^2 at unit intensity, RGB) of `patch` to light `group`.
    #[must_use]
    pub fn transfer_response(&self, patch: u32, group: u32) -> Option<[f32; 3]> {
        self.transfer()?.response(patch, group)
    }

    /// The CRC-32 of the blob (identifies the table; solver state remembers it).
    #[must_use]
    pub fn crc(&self) -> u32 {
        self.crc
    }

    /// Area of `patch`, or `None` if out of range.
    #[must_use]
    pub fn area(&self, patch: u32) -> Option<f32> {
        (patch < self.patch_count()).then(|| le_f32(self.area, patch as usize))
    }

    /// Material of `patch`, or `None` if out of range.
    #[must_use]
    pub fn material(&self, patch: u32) -> Option<u32> {
        (patch < self.patch_count()).then(|| u32::from(le_u16(self.material, patch as usize)))
    }

    /// Static base emission codes (RGB) of `patch`.
    #[must_use]
    pub fn base_emission(&self, patch: u32) -> Option<[u16; 3]> {
        (patch < self.patch_count()).then(|| rgb16(self.base_emission, patch as usize))
    }

    /// Static base irradiance codes (RGB) of `patch`.
    #[must_use]
    pub fn base_irradiance(&self, patch: u32) -> Option<[u16; 3]> {
        (patch < self.patch_count()).then(|| rgb16(self.base_irradiance, patch as usize))
    }

    /// Reflectance codes (RGB) of `material`.
    #[must_use]
    pub fn reflectance(&self, material: u32) -> Option<[u16; 3]> {
        (material < self.material_count()).then(|| rgb16(self.reflectance, material as usize))
    }

    /// Identifier (e.g. a name hash chosen by the host) of light `group`.
    #[must_use]
    pub fn group_id(&self, group: u32) -> Option<u32> {
        (group < self.group_count()).then(|| le_u32(self.group_id, group as usize))
    }

    /// The light group with identifier `id`, if any (linear scan over the groups).
    #[must_use]
    pub fn find_group(&self, id: u32) -> Option<u32> {
        (0..self.group_count()).find(|&g| le_u32(self.group_id, g as usize) == id)
    }

    /// Default RGB intensity of light `group`.
    #[must_use]
    pub fn default_intensity(&self, group: u32) -> Option<[f32; 3]> {
        (group < self.group_count()).then(|| {
            let g = group as usize * 3;
            [
                le_f32(self.group_intensity, g),
                le_f32(self.group_intensity, g + 1),
                le_f32(self.group_intensity, g + 2),
            ]
        })
    }

    /// Range of member positions of light `group` (for [`Table::member`]).
    #[must_use]
    pub fn group_members(&self, group: u32) -> Option<core::ops::Range<u32>> {
        (group < self.group_count())
            .then(|| le_u32(self.group_start, group as usize)..le_u32(self.group_start, group as usize + 1))
    }

    /// Member at `position` (see [`Table::group_members`]).
    #[must_use]
    pub fn member(&self, position: u32) -> Option<Member> {
        (position < self.header.member_count).then(|| Member {
            patch: self.index(self.member_patch, position),
            emission: rgb16(self.member_emission, position as usize),
        })
    }

    /// Range of entry positions of the row of shooter `slot` (for [`Table::entry`]); `None` if
    /// `slot >= state_count`. Only patches with state have rows (see [`Table::slot_of`]).
    #[must_use]
    pub fn row(&self, slot: u32) -> Option<core::ops::Range<u32>> {
        (slot < self.state_count())
            .then(|| le_u32(self.row_start, slot as usize)..le_u32(self.row_start, slot as usize + 1))
    }

    /// Row exponent of the row of shooter `slot`.
    #[must_use]
    #[inline]
    pub fn row_exponent(&self, slot: u32) -> Option<u8> {
        (slot < self.state_count()).then(|| self.row_exponent.get(slot as usize).copied().unwrap_or(0))
    }

    /// Receiver slot and raw code of entry `position`.
    #[must_use]
    #[inline]
    pub fn entry_code(&self, position: u32) -> Option<(u32, u16)> {
        (position < self.entry_count())
            .then(|| (self.index(self.entry_receiver, position), self.code(position)))
    }

    /// Receiver slot and decoded form factor of entry `position` in the row of shooter `slot`.
    #[must_use]
    #[inline]
    pub fn entry(&self, slot: u32, position: u32) -> Option<(u32, Frac)> {
        let e = self.row_exponent(slot)?;
        let (r, c) = self.entry_code(position)?;
        Some((r, self.codec.decode(c, e)))
    }

    /// Decoded sum of the row of shooter `slot` as f32 (for reports).
    #[must_use]
    pub fn row_sum(&self, slot: u32) -> Option<f32> {
        let range = self.row(slot)?;
        Some(range.filter_map(|k| self.entry(slot, k)).map(|(_, f)| f.to_f32()).sum())
    }
}

/// The entries of one shooter row, proven in range by [`Table::parse`] (receivers are slots `< state_count`,
/// strictly increasing; the decoded sum is `<= 1`). From [`Table::row_view`].
#[derive(Clone, Copy, Debug)]
pub struct Row<'a> {
    /// Receiver indices of the row, `index_bytes` each.
    receivers: &'a [u8],
    /// Form-factor codes of the row, `codec.code_bytes()` each.
    codes: &'a [u8],
    index_bytes: usize,
    codec: FfCodec,
    exponent: u8,
    /// Table position of the row's first entry.
    start: u32,
}

impl<'a> Row<'a> {
    /// A row over its receiver and code bytes (proven in range by the caller's parse).
    pub(super) fn new(
        receivers: &'a [u8],
        codes: &'a [u8],
        index_bytes: usize,
        codec: FfCodec,
        exponent: u8,
        start: u32,
    ) -> Self {
        Row { receivers, codes, index_bytes, codec, exponent, start }
    }

    /// Table positions of the row's entries.
    #[must_use]
    pub fn positions(&self) -> core::ops::Range<u32> {
        let len = (self.receivers.len() / self.index_bytes.max(1)) as u32;
        self.start..self.start + len
    }

    /// The row's exponent (the codec's per-row scale, see [`crate::codec`]).
    #[must_use]
    pub fn exponent(&self) -> u8 {
        self.exponent
    }

    /// Receiver slots and decoded form factors of the entries from table position `position` to the row's
    /// end (none if `position` is past it; the row's start if before it).
    #[must_use]
    pub fn entries_from(&self, position: u32) -> Entries<'a> {
        let skip = position.saturating_sub(self.start) as usize;
        let cb = self.codec.code_bytes();
        let receivers = self.receivers.get(skip.saturating_mul(self.index_bytes)..).unwrap_or(&[]);
        let codes = self.codes.get(skip.saturating_mul(cb)..).unwrap_or(&[]);
        Entries {
            receivers: receivers.chunks_exact(self.index_bytes.max(1)),
            codes: codes.chunks_exact(cb.max(1)),
            decoder: self.codec.row_decoder(self.exponent),
        }
    }

    /// All entries of the row.
    #[must_use]
    pub fn entries(&self) -> Entries<'a> {
        self.entries_from(self.start)
    }
}

/// Little-endian value of a fixed-width field (`N <= 4`).
#[inline(always)]
pub(crate) fn le<const N: usize>(b: &[u8]) -> u32 {
    let mut v = [0u8; 4];
    if let (Some(dst), Some(src)) = (v.get_mut(..N), b.get(..N)) {
        dst.copy_from_slice(src);
    }
    u32::from_le_bytes(v)
}

/// Iterator over a [`Row`]'s entries: `(receiver slot, decoded form factor)`.
#[derive(Clone, Debug)]
pub struct Entries<'a> {
    receivers: core::slice::ChunksExact<'a, u8>,
    codes: core::slice::ChunksExact<'a, u8>,
    decoder: RowDecoder,
}

impl Iterator for Entries<'_> {
    type Item = (u32, Frac);

    #[inline]
    fn next(&mut self) -> Option<(u32, Frac)> {
        let r = self.receivers.next()?;
        let c = self.codes.next()?;
        // The widths are the table's (2 or 4 index bytes, 1 or 2 code bytes); parse checked both.
        let receiver = match *r {
            [a, b] => u32::from(u16::from_le_bytes([a, b])),
            [a, b, c, d] => u32::from_le_bytes([a, b, c, d]),
            _ => 0,
        };
        let code = match *c {
            [a] => u32::from(a),
            [a, b] => u32::from(u16::from_le_bytes([a, b])),
            _ => 0,
        };
        Some((receiver, self.decoder.decode(code)))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.receivers.size_hint()
    }
}

impl<'a> Table<'a> {
    /// The row of shooter `slot` as a view whose entries need no further checks, or `None` if
    /// `slot >= state_count`.
    #[must_use]
    #[inline]
    pub fn row_view(&self, slot: u32) -> Option<Row<'a>> {
        let range = self.row(slot)?;
        let ib = usize::from(self.header.index_bytes);
        let cb = self.codec.code_bytes();
        let (s, e) = (range.start as usize, range.end as usize);
        Some(Row {
            receivers: self.entry_receiver.get(s.checked_mul(ib)?..e.checked_mul(ib)?)?,
            codes: self.entry_code.get(s.checked_mul(cb)?..e.checked_mul(cb)?)?,
            index_bytes: ib,
            codec: self.codec,
            exponent: self.row_exponent.get(slot as usize).copied().unwrap_or(0),
            start: range.start,
        })
    }

    /// Bytes of each section of the blob (what `radiosity inspect` reports).
    #[must_use]
    pub fn section_sizes(&self) -> SectionSizes {
        // `parse` accepted this header, so its sizes are known not to overflow.
        SectionSizes::of_header(&self.header, self.header_len).unwrap_or_default()
    }
}
