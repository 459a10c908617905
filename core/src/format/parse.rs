//! [`Table::parse`]: the one checked constructor. It validates everything once; after it succeeds no accessor
//! can panic and the read views ([`super::view`]) rely on what it proved.

use super::error::{IndexArray, OffsetArray, QuantParam, TableError};
use super::layout::{le_f32, le_u16, le_u32, Header, Prefix, SectionSizes};
use super::{FORMAT_VERSION, HIER_FORMAT_VERSION, MAGIC};
use crate::codec::transfer::{TRANSFER_MAX_EXPONENT, TRANSFER_MIN_EXPONENT};
use crate::codec::{CodecParamError, FfCodec, EXACT_SHIFT, MAX_ROW_EXPONENT};
use crate::crc::crc32;

/// A validated, zero-copy view of a table blob.
#[derive(Clone, Copy, Debug)]
pub struct Table<'a> {
    pub(super) header: Header,
    /// Bytes of the postcard header (before the payload).
    pub(super) header_len: usize,
    pub(super) codec: FfCodec,
    pub(super) crc: u32,
    pub(super) area: &'a [u8],
    pub(super) material: &'a [u8],
    pub(super) base_emission: &'a [u8],
    pub(super) base_irradiance: &'a [u8],
    pub(super) reflectance: &'a [u8],
    pub(super) group_id: &'a [u8],
    pub(super) group_intensity: &'a [u8],
    pub(super) group_start: &'a [u8],
    pub(super) member_patch: &'a [u8],
    pub(super) member_emission: &'a [u8],
    /// Patch of each slot (empty when every patch has state: slot = patch).
    pub(super) state_patch: &'a [u8],
    /// Material of each slot (the patch material section when every patch has state).
    pub(super) state_material: &'a [u8],
    pub(super) row_start: &'a [u8],
    pub(super) row_exponent: &'a [u8],
    pub(super) entry_receiver: &'a [u8],
    pub(super) entry_code: &'a [u8],
    pub(super) transfer_exponent: &'a [u8],
    pub(super) transfer_code: &'a [u8],
    /// Whether any patch has a static base code other than 0 (found once, at parse).
    pub(super) static_base: bool,
}

/// Whether any byte of `a` or `b` is not 0 (a static base section with some light in it).
pub(super) fn any_nonzero(a: &[u8], b: &[u8]) -> bool {
    a.iter().chain(b).any(|&x| x != 0)
}

/// Checks the magic and that the version is `expected`; a table of the other layout (flat or hierarchical) is
/// named as such ([`TableError::HierarchicalTable`], [`TableError::FlatTable`]).
pub(super) fn check_prefix(bytes: &[u8], expected: u16) -> Result<(), TableError> {
    let mut found = [0u8; 4];
    for (d, s) in found.iter_mut().zip(bytes) {
        *d = *s;
    }
    let n = bytes.len().min(4);
    if found.get(..n) != MAGIC.get(..n) {
        return Err(TableError::BadMagic { found });
    }
    let (prefix, _) = postcard::take_from_bytes::<Prefix>(bytes).map_err(header_error)?;
    if prefix.magic != MAGIC {
        return Err(TableError::BadMagic { found: prefix.magic });
    }
    match prefix.version {
        v if v == expected => Ok(()),
        HIER_FORMAT_VERSION => Err(TableError::HierarchicalTable),
        FORMAT_VERSION => Err(TableError::FlatTable),
        found => Err(TableError::UnsupportedVersion { found, expected }),
    }
}

/// The form-factor codec of a header's parameters, and its index width checked (2 or 4 bytes).
pub(super) fn check_codec(ff_bits: u8, ff_exponent_bits: u8, index_bytes: u8) -> Result<FfCodec, TableError> {
    let codec = FfCodec { bits: ff_bits, exponent_bits: ff_exponent_bits };
    match codec.check() {
        Err(CodecParamError::Bits(b)) => {
            return Err(TableError::BadQuantParams { param: QuantParam::FfBits, value: u32::from(b) })
        }
        Err(CodecParamError::ExponentBits(b)) => {
            return Err(TableError::BadQuantParams { param: QuantParam::FfExponentBits, value: u32::from(b) })
        }
        Ok(()) => {}
    }
    if index_bytes != 2 && index_bytes != 4 {
        return Err(TableError::BadQuantParams {
            param: QuantParam::IndexBytes,
            value: u32::from(index_bytes),
        });
    }
    Ok(codec)
}

impl<'a> Table<'a> {
    /// Parses and validates a table blob.
    ///
    /// # Errors
    /// The first problem found, as a [`TableError`]. Checks run in this order: magic, version, header,
    /// quantization parameters, state count, length, CRC, then content (areas, materials, the state map,
    /// member offsets, member patches with state, intensities, row offsets, receivers, sorted rows, row
    /// exponents, row sums, the transfer section).
    pub fn parse(bytes: &'a [u8]) -> Result<Table<'a>, TableError> {
        check_prefix(bytes, FORMAT_VERSION)?;
        let (header, rest) = postcard::take_from_bytes::<Header>(bytes).map_err(header_error)?;
        let header_len = bytes.len() - rest.len();
        let codec = check_codec(header.ff_bits, header.ff_exponent_bits, header.index_bytes)?;
        if header.index_bytes == 2 && header.patch_count > 0x1_0000 {
            return Err(TableError::CountsTooLarge);
        }
        if header.state_count > header.patch_count {
            return Err(TableError::StateCountExceedsPatches {
                state_count: header.state_count,
                patch_count: header.patch_count,
            });
        }
        if header.material_count > 0x1_0000 {
            return Err(TableError::CountsTooLarge);
        }
        let sizes = SectionSizes::of_header(&header, header_len).ok_or(TableError::CountsTooLarge)?;
        let expected = sizes.total();
        if bytes.len() < expected {
            return Err(TableError::Truncated { expected, actual: bytes.len() });
        }
        if bytes.len() > expected {
            return Err(TableError::TrailingBytes { expected, actual: bytes.len() });
        }
        let body =
            bytes.get(..expected - 4).ok_or(TableError::Truncated { expected, actual: bytes.len() })?;
        let stored = le_u32(bytes.get(expected - 4..).unwrap_or(&[]), 0);
        let computed = crc32(body);
        if stored != computed {
            return Err(TableError::CrcMismatch { stored, computed });
        }
        // The sections, in blob order: each takes its size off the front of what is left of the payload.
        let mut rest = body.get(header_len..).unwrap_or(&[]);
        let mut take = |len: usize| {
            let (section, tail) = rest.split_at(len.min(rest.len()));
            rest = tail;
            section
        };
        let area = take(sizes.patch_area);
        let material = take(sizes.patch_material);
        let identity = header.state_count == header.patch_count;
        let table = Table {
            header,
            header_len,
            codec,
            crc: computed,
            area,
            material,
            base_emission: take(sizes.base_emission),
            base_irradiance: take(sizes.base_irradiance),
            reflectance: take(sizes.reflectance),
            group_id: take(sizes.group_id),
            group_intensity: take(sizes.group_intensity),
            group_start: take(sizes.group_start),
            member_patch: take(sizes.member_patch),
            member_emission: take(sizes.member_emission),
            state_patch: take(sizes.state_patch),
            // With every patch in state the slot materials are the patch material section itself.
            state_material: if identity { material } else { take(sizes.state_material) },
            row_start: take(sizes.row_start),
            row_exponent: take(sizes.row_exponent),
            entry_receiver: take(sizes.entry_receiver),
            entry_code: take(sizes.entry_code),
            transfer_exponent: take(sizes.transfer_exponent),
            transfer_code: take(sizes.transfer_code),
            static_base: false,
        };
        let table = Table { static_base: any_nonzero(table.base_emission, table.base_irradiance), ..table };
        table.validate()?;
        Ok(table)
    }

    /// Every content check of [`Table::parse`] after the CRC (the list in [`TableError`]).
    fn validate(&self) -> Result<(), TableError> {
        let n = self.header.patch_count;
        let slots = self.header.state_count;
        for p in 0..n {
            let a = le_f32(self.area, p as usize);
            if !(a.is_finite() && a > 0.0) {
                return Err(TableError::BadArea { patch: p });
            }
            let mat = u32::from(le_u16(self.material, p as usize));
            in_range(IndexArray::PatchMaterial, p, mat, self.header.material_count)?;
        }
        if slots < n {
            if !self.header.base_solved {
                return Err(TableError::StateWithoutSolvedBase);
            }
            let mut prev: Option<u32> = None;
            for slot in 0..slots {
                let p = self.index(self.state_patch, slot);
                in_range(IndexArray::StatePatch, slot, p, n)?;
                if prev.is_some_and(|q| q >= p) {
                    return Err(TableError::UnsortedStateMap { slot });
                }
                prev = Some(p);
                if le_u16(self.state_material, slot as usize) != le_u16(self.material, p as usize) {
                    return Err(TableError::StateMaterialMismatch { slot });
                }
            }
        }
        check_offsets(
            self.group_start,
            self.header.group_count,
            self.header.member_count,
            OffsetArray::GroupStart,
        )?;
        for k in 0..self.header.member_count {
            let p = self.index(self.member_patch, k);
            in_range(IndexArray::MemberPatch, k, p, n)?;
            if self.slot_of(p).is_none() {
                return Err(TableError::MemberWithoutState { position: k, patch: p });
            }
        }
        for g in 0..self.header.group_count {
            for c in 0..3 {
                if !le_f32(self.group_intensity, g as usize * 3 + c).is_finite() {
                    return Err(TableError::BadIntensity { group: g });
                }
            }
        }
        check_offsets(self.row_start, slots, self.header.entry_count, OffsetArray::RowStart)?;
        for row in 0..slots {
            let e = self.row_exponent.get(row as usize).copied().unwrap_or(0);
            if e > MAX_ROW_EXPONENT {
                return Err(TableError::BadQuantParams { param: QuantParam::RowExponent, value: row });
            }
            let (start, end) =
                (le_u32(self.row_start, row as usize), le_u32(self.row_start, row as usize + 1));
            let mut sum: u128 = 0;
            let mut prev: Option<u32> = None;
            for k in start..end {
                let r = self.index(self.entry_receiver, k);
                in_range(IndexArray::EntryReceiver, k, r, slots)?;
                if prev.is_some_and(|p| p >= r) {
                    return Err(TableError::UnsortedRow { row });
                }
                prev = Some(r);
                sum = sum.saturating_add(self.codec.decode(self.code(k), e).to_exact());
            }
            if sum > 1u128 << EXACT_SHIFT {
                return Err(TableError::RowSumExceedsOne { row });
            }
        }
        if self.header.transfer {
            if !self.header.base_solved {
                return Err(TableError::TransferWithoutSolvedBase);
            }
            check_transfer_exponents(self.transfer_exponent, self.header.group_count)?;
        }
        Ok(())
    }
}

/// Every transfer scale exponent (3 per group) in `TRANSFER_MIN_EXPONENT..=TRANSFER_MAX_EXPONENT`, or the
/// error naming the first group that is not (flat and hierarchical tables share the section's layout).
pub(super) fn check_transfer_exponents(s: &[u8], groups: u32) -> Result<(), TableError> {
    for g in 0..groups {
        for c in 0..3 {
            let k = s.get(g as usize * 3 + c).map_or(0, |&b| b as i8);
            if !(TRANSFER_MIN_EXPONENT..=TRANSFER_MAX_EXPONENT).contains(&k) {
                return Err(TableError::BadQuantParams { param: QuantParam::TransferExponent, value: g });
            }
        }
    }
    Ok(())
}

pub(super) fn header_error(e: postcard::Error) -> TableError {
    match e {
        postcard::Error::DeserializeUnexpectedEnd => TableError::TruncatedHeader,
        _ => TableError::BadHeader,
    }
}

/// `index` (read at `position` of `array`) is below `bound`, or the error that says where it is not.
pub(super) fn in_range(array: IndexArray, position: u32, index: u32, bound: u32) -> Result<(), TableError> {
    if index < bound {
        Ok(())
    } else {
        Err(TableError::IndexOutOfRange { array, position, index, bound })
    }
}

pub(super) fn check_offsets(s: &[u8], count: u32, total: u32, array: OffsetArray) -> Result<(), TableError> {
    let mut prev = 0u32;
    for k in 0..=count {
        let o = le_u32(s, k as usize);
        let bad = (k == 0 && o != 0) || o < prev || o > total || (k == count && o != total);
        if bad {
            return Err(TableError::NonMonotoneOffsets { array, position: k });
        }
        prev = o;
    }
    Ok(())
}
