//! The table format: a postcard header, little-endian payload sections borrowed in place, and a CRC-32.
//!
//! [`Table::parse`] is the one checked constructor: it validates everything once (see [`TableError`] for the
//! list), and after it succeeds no accessor can panic; accessors that take an index from the caller return
//! `Option`. The byte layout is documented in the crate docs ("Table layout").

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::codec::{CodecParamError, FfCodec, Frac, EXACT_SHIFT, MAX_ROW_EXPONENT};
use crate::crc::crc32;
use crate::transfer::{decode_transfer, TRANSFER_MAX_EXPONENT, TRANSFER_MIN_EXPONENT};

/// The four bytes every table starts with.
pub const MAGIC: [u8; 4] = *b"RFT\x1a";

/// The format version this crate reads and writes.
pub const FORMAT_VERSION: u16 = 3;

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
struct Prefix {
    magic: [u8; 4],
    version: u16,
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

/// What is wrong with a table blob. Every variant names the place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TableError {
    /// The blob does not start with [`MAGIC`].
    BadMagic {
        /// The first four bytes found (zero-padded if shorter).
        found: [u8; 4],
    },
    /// The blob is in a format version this crate does not read.
    UnsupportedVersion {
        /// Version in the blob.
        found: u16,
        /// Version this crate reads ([`FORMAT_VERSION`]).
        expected: u16,
    },
    /// The postcard header could not be decoded.
    BadHeader,
    /// The blob ends inside the header.
    TruncatedHeader,
    /// The blob is shorter than its header says.
    Truncated {
        /// Bytes the header implies.
        expected: usize,
        /// Bytes present.
        actual: usize,
    },
    /// The blob has bytes after the CRC.
    TrailingBytes {
        /// Bytes the header implies.
        expected: usize,
        /// Bytes present.
        actual: usize,
    },
    /// Counts whose sections do not fit in memory (arithmetic overflow) or exceed the index width.
    CountsTooLarge,
    /// Quantization parameters out of range.
    BadQuantParams {
        /// Which parameter.
        param: QuantParam,
        /// Its value.
        value: u32,
    },
    /// The CRC-32 over header and payload does not match the stored one.
    CrcMismatch {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// An offset array (row starts or group member starts) does not start at 0, decreases or does not end at
    /// the entry count.
    NonMonotoneOffsets {
        /// Which array.
        array: OffsetArray,
        /// Position in the array of the first bad offset.
        position: u32,
    },
    /// An index (patch, material) is out of range.
    IndexOutOfRange {
        /// Which index array.
        array: IndexArray,
        /// Position in the array.
        position: u32,
        /// The index found.
        index: u32,
        /// The exclusive upper bound.
        bound: u32,
    },
    /// A row's receivers are not strictly increasing.
    UnsortedRow {
        /// The row (shooter patch).
        row: u32,
    },
    /// A row's decoded form factors sum to more than 1.
    RowSumExceedsOne {
        /// The row (shooter patch).
        row: u32,
    },
    /// A patch area is not finite and positive.
    BadArea {
        /// The patch.
        patch: u32,
    },
    /// A light group's default intensity is not finite.
    BadIntensity {
        /// The light group.
        group: u32,
    },
    /// The table has a transfer basis but its static base is not solved: the basis relights as
    /// `B = B_static + sum_g I_g T_g` and needs `B_static` (see the crate docs, "Transfer basis").
    TransferWithoutSolvedBase,
    /// The state count exceeds the patch count.
    StateCountExceedsPatches {
        /// Patches with run-time state in the header.
        state_count: u32,
        /// Patches in the header.
        patch_count: u32,
    },
    /// Some patches have no run-time state but the static base is not solved: a patch without state shows its
    /// static base, which must then be the static solution (see the crate docs, "Run-time state").
    StateWithoutSolvedBase,
    /// The state map (slot -> patch) is not strictly increasing.
    UnsortedStateMap {
        /// The first slot whose patch is not above the previous slot's.
        slot: u32,
    },
    /// A slot's material differs from the material of its patch.
    StateMaterialMismatch {
        /// The slot.
        slot: u32,
    },
    /// A light-group member is a patch without run-time state (a dynamic emitter always has state).
    MemberWithoutState {
        /// Position in the member array.
        position: u32,
        /// The member's patch.
        patch: u32,
    },
}

/// The quantization parameter a [`TableError::BadQuantParams`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QuantParam {
    /// Form-factor code width (8 or 16).
    FfBits,
    /// Form-factor exponent bits (0..=4, below the code width).
    FfExponentBits,
    /// Index width in bytes (2 or 4).
    IndexBytes,
    /// A row exponent (0..=64); the value is the row.
    RowExponent,
    /// A transfer-basis step exponent (see [`crate::transfer`]); the value is the light group.
    TransferExponent,
}

/// The offset array a [`TableError::NonMonotoneOffsets`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OffsetArray {
    /// Form-factor row starts.
    RowStart,
    /// Light-group member starts.
    GroupStart,
}

/// The index array a [`TableError::IndexOutOfRange`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IndexArray {
    /// Patch materials.
    PatchMaterial,
    /// Light-group member patches.
    MemberPatch,
    /// Form-factor receivers (slots, bound: the state count).
    EntryReceiver,
    /// The state map: patch of each slot.
    StatePatch,
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TableError::BadMagic { found } => {
                write!(f, "not a radiosity table: magic {found:02x?}, expected {MAGIC:02x?}")
            }
            TableError::UnsupportedVersion { found, expected } => {
                write!(f, "unsupported table format version {found}, expected {expected}")
            }
            TableError::BadHeader => write!(f, "table header cannot be decoded"),
            TableError::TruncatedHeader => write!(f, "table truncated inside its header"),
            TableError::Truncated { expected, actual } => {
                write!(f, "table truncated: {actual} bytes, header implies {expected}")
            }
            TableError::TrailingBytes { expected, actual } => {
                write!(f, "table has trailing bytes: {actual} bytes, header implies {expected}")
            }
            TableError::CountsTooLarge => {
                write!(f, "table counts too large for this platform or index width")
            }
            TableError::BadQuantParams { param, value } => {
                write!(f, "bad quantization parameter {param:?}: {value}")
            }
            TableError::CrcMismatch { stored, computed } => {
                write!(f, "table CRC mismatch: stored {stored:#010x}, computed {computed:#010x}")
            }
            TableError::NonMonotoneOffsets { array, position } => {
                write!(
                    f,
                    "offsets in {array:?} not monotone or not ending at the count, at position {position}"
                )
            }
            TableError::IndexOutOfRange { array, position, index, bound } => {
                write!(f, "index {index} out of range (< {bound}) in {array:?} at position {position}")
            }
            TableError::UnsortedRow { row } => {
                write!(f, "form-factor row {row}: receivers not strictly increasing")
            }
            TableError::RowSumExceedsOne { row } => write!(f, "form-factor row {row}: decoded sum exceeds 1"),
            TableError::BadArea { patch } => write!(f, "patch {patch}: area not finite and positive"),
            TableError::BadIntensity { group } => {
                write!(f, "light group {group}: default intensity not finite")
            }
            TableError::TransferWithoutSolvedBase => {
                write!(f, "transfer basis present but the static base is not solved")
            }
            TableError::StateCountExceedsPatches { state_count, patch_count } => {
                write!(f, "state count {state_count} exceeds the patch count {patch_count}")
            }
            TableError::StateWithoutSolvedBase => {
                write!(f, "some patches have no run-time state but the static base is not solved")
            }
            TableError::UnsortedStateMap { slot } => {
                write!(f, "state map: patch of slot {slot} not above the previous slot's")
            }
            TableError::StateMaterialMismatch { slot } => {
                write!(f, "state map: material of slot {slot} differs from its patch's")
            }
            TableError::MemberWithoutState { position, patch } => {
                write!(f, "light-group member {position}: patch {patch} has no run-time state")
            }
        }
    }
}

impl core::error::Error for TableError {}

// Byte offsets use checked arithmetic: on 32-bit targets `usize` is 32 bits.
#[inline]
fn le_u16(s: &[u8], i: usize) -> u16 {
    let Some(at) = i.checked_mul(2) else { return 0 };
    match s.get(at..at.saturating_add(2)) {
        Some(&[a, b]) => u16::from_le_bytes([a, b]),
        _ => 0,
    }
}

#[inline]
fn le_u32(s: &[u8], i: usize) -> u32 {
    let Some(at) = i.checked_mul(4) else { return 0 };
    match s.get(at..at.saturating_add(4)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

fn le_f32(s: &[u8], i: usize) -> f32 {
    f32::from_bits(le_u32(s, i))
}

/// A validated, zero-copy view of a table blob.
#[derive(Clone, Copy, Debug)]
pub struct Table<'a> {
    header: Header,
    codec: FfCodec,
    crc: u32,
    area: &'a [u8],
    material: &'a [u8],
    base_emission: &'a [u8],
    base_irradiance: &'a [u8],
    reflectance: &'a [u8],
    group_id: &'a [u8],
    group_intensity: &'a [u8],
    group_start: &'a [u8],
    member_patch: &'a [u8],
    member_emission: &'a [u8],
    /// Patch of each slot (empty when every patch has state: slot = patch).
    state_patch: &'a [u8],
    /// Material of each slot (the patch material section when every patch has state).
    state_material: &'a [u8],
    row_start: &'a [u8],
    row_exponent: &'a [u8],
    entry_receiver: &'a [u8],
    entry_code: &'a [u8],
    transfer_exponent: &'a [u8],
    transfer_code: &'a [u8],
}

/// One light-group member: a patch and its emission at unit intensity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Member {
    /// The patch.
    pub patch: u32,
    /// Emission codes (RGB) at unit intensity, see [`crate::codec::decode_emission`].
    pub emission: [u16; 3],
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
        if prefix.version != FORMAT_VERSION {
            return Err(TableError::UnsupportedVersion { found: prefix.version, expected: FORMAT_VERSION });
        }
        let (header, rest) = postcard::take_from_bytes::<Header>(bytes).map_err(header_error)?;
        let header_len = bytes.len() - rest.len();
        let codec = FfCodec { bits: header.ff_bits, exponent_bits: header.ff_exponent_bits };
        match codec.check() {
            Err(CodecParamError::Bits(b)) => {
                return Err(TableError::BadQuantParams { param: QuantParam::FfBits, value: u32::from(b) })
            }
            Err(CodecParamError::ExponentBits(b)) => {
                return Err(TableError::BadQuantParams {
                    param: QuantParam::FfExponentBits,
                    value: u32::from(b),
                })
            }
            Ok(()) => {}
        }
        if header.index_bytes != 2 && header.index_bytes != 4 {
            return Err(TableError::BadQuantParams {
                param: QuantParam::IndexBytes,
                value: u32::from(header.index_bytes),
            });
        }
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
        let layout = Layout::new(&header).ok_or(TableError::CountsTooLarge)?;
        let expected = header_len
            .checked_add(layout.end)
            .and_then(|x| x.checked_add(4))
            .ok_or(TableError::CountsTooLarge)?;
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
        let payload = body.get(header_len..).unwrap_or(&[]);
        let sec = |a: usize, b: usize| payload.get(a..b).unwrap_or(&[]);
        let material = sec(layout.material, layout.base_emission);
        let identity = header.state_count == header.patch_count;
        let table = Table {
            header,
            codec,
            crc: computed,
            area: sec(layout.area, layout.material),
            material,
            base_emission: sec(layout.base_emission, layout.base_irradiance),
            base_irradiance: sec(layout.base_irradiance, layout.reflectance),
            reflectance: sec(layout.reflectance, layout.group_id),
            group_id: sec(layout.group_id, layout.group_intensity),
            group_intensity: sec(layout.group_intensity, layout.group_start),
            group_start: sec(layout.group_start, layout.member_patch),
            member_patch: sec(layout.member_patch, layout.member_emission),
            member_emission: sec(layout.member_emission, layout.state_patch),
            state_patch: sec(layout.state_patch, layout.state_material),
            state_material: if identity { material } else { sec(layout.state_material, layout.row_start) },
            row_start: sec(layout.row_start, layout.row_exponent),
            row_exponent: sec(layout.row_exponent, layout.entry_receiver),
            entry_receiver: sec(layout.entry_receiver, layout.entry_code),
            entry_code: sec(layout.entry_code, layout.transfer_exponent),
            transfer_exponent: sec(layout.transfer_exponent, layout.transfer_code),
            transfer_code: sec(layout.transfer_code, layout.end),
        };
        table.validate()?;
        Ok(table)
    }

    fn validate(&self) -> Result<(), TableError> {
        let n = self.header.patch_count;
        let slots = self.header.state_count;
        for p in 0..n {
            let a = le_f32(self.area, p as usize);
            if !(a.is_finite() && a > 0.0) {
                return Err(TableError::BadArea { patch: p });
            }
            let mat = u32::from(le_u16(self.material, p as usize));
            if mat >= self.header.material_count {
                return Err(TableError::IndexOutOfRange {
                    array: IndexArray::PatchMaterial,
                    position: p,
                    index: mat,
                    bound: self.header.material_count,
                });
            }
        }
        if slots < n {
            if !self.header.base_solved {
                return Err(TableError::StateWithoutSolvedBase);
            }
            let mut prev: Option<u32> = None;
            for slot in 0..slots {
                let p = self.index(self.state_patch, slot);
                if p >= n {
                    return Err(TableError::IndexOutOfRange {
                        array: IndexArray::StatePatch,
                        position: slot,
                        index: p,
                        bound: n,
                    });
                }
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
            if p >= n {
                return Err(TableError::IndexOutOfRange {
                    array: IndexArray::MemberPatch,
                    position: k,
                    index: p,
                    bound: n,
                });
            }
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
                if r >= slots {
                    return Err(TableError::IndexOutOfRange {
                        array: IndexArray::EntryReceiver,
                        position: k,
                        index: r,
                        bound: slots,
                    });
                }
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
            for g in 0..self.header.group_count {
                for c in 0..3 {
                    let k = self.transfer_exponent.get(g as usize * 3 + c).map_or(0, |&b| b as i8);
                    if !(TRANSFER_MIN_EXPONENT..=TRANSFER_MAX_EXPONENT).contains(&k) {
                        return Err(TableError::BadQuantParams {
                            param: QuantParam::TransferExponent,
                            value: g,
                        });
                    }
                }
            }
        }
        Ok(())
    }

    #[inline]
    fn index(&self, s: &[u8], k: u32) -> u32 {
        if self.header.index_bytes == 2 {
            u32::from(le_u16(s, k as usize))
        } else {
            le_u32(s, k as usize)
        }
    }

    #[inline]
    fn code(&self, k: u32) -> u16 {
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

    /// Whether the table carries the optional transfer basis (see [`crate::transfer`]).
    #[must_use]
    pub fn has_transfer(&self) -> bool {
        self.header.transfer
    }

    /// Transfer-basis step exponents `k` (RGB) of light `group`: its response codes decode to `code * 2^k`
    /// W/m^2 at unit intensity. `None` without a transfer section or out of range.
    #[must_use]
    pub fn transfer_exponent(&self, group: u32) -> Option<[i8; 3]> {
        (self.has_transfer() && group < self.group_count()).then(|| {
            let at = group as usize * 3;
            [0, 1, 2].map(|c| self.transfer_exponent.get(at + c).map_or(0, |&b| b as i8))
        })
    }

    /// Transfer-basis response codes (RGB) of `patch` to light `group` at unit intensity (see
    /// [`crate::transfer`]). `None` without a transfer section or out of range.
    #[must_use]
    pub fn transfer_code(&self, patch: u32, group: u32) -> Option<[u16; 3]> {
        if !self.has_transfer() || patch >= self.patch_count() || group >= self.group_count() {
            return None;
        }
        // patch < n, group < g and n * g * 6 bytes fit (checked by the layout), so no overflow.
        Some(rgb16(self.transfer_code, patch as usize * self.group_count() as usize + group as usize))
    }

    /// The decoded transfer response `T_g` (W/m^2 at unit intensity, RGB) of `patch` to light `group`.
    #[must_use]
    pub fn transfer_response(&self, patch: u32, group: u32) -> Option<[f32; 3]> {
        let code = self.transfer_code(patch, group)?;
        let k = self.transfer_exponent(group)?;
        Some([0, 1, 2].map(|c| decode_transfer(code[c], k[c])))
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

fn header_error(e: postcard::Error) -> TableError {
    match e {
        postcard::Error::DeserializeUnexpectedEnd => TableError::TruncatedHeader,
        _ => TableError::BadHeader,
    }
}

fn rgb16(s: &[u8], i: usize) -> [u16; 3] {
    let at = i.saturating_mul(3);
    [le_u16(s, at), le_u16(s, at.saturating_add(1)), le_u16(s, at.saturating_add(2))]
}

fn check_offsets(s: &[u8], count: u32, total: u32, array: OffsetArray) -> Result<(), TableError> {
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
