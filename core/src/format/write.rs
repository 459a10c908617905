//! The table writer: quantizes a [`TableSpec`] into a caller's buffer, in the layout [`Table::parse`] reads.
//!
//! Std-free so the host and the device share one implementation of the layout.
//!
//! [`Table::parse`]: crate::Table::parse

use core::fmt;

use super::layout::{Header, SectionSizes, MAX_HEADER_LEN};
use super::{FORMAT_VERSION, MAGIC};
use crate::codec::transfer::{encode_transfer, transfer_exponent_for, TRANSFER_MAX};
use crate::codec::{self, f32_to_exact, FfCodec, EXACT_SHIFT};
use crate::crc::crc32;

/// One patch as the writer takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchSpec {
    /// Area (scene units squared), finite and positive.
    pub area: f32,
    /// Index into [`TableSpec::materials`].
    pub material: u32,
    /// Static emission (W/m^2, RGB): the folded static lights.
    pub base_emission: [f32; 3],
    /// Static irradiance (W/m^2, RGB): `sum_j F_ij B_static_j`, the light arriving from the static solution
    /// (zero if the host does not solve the static lights; see [`TableSpec::base_solved`]).
    pub base_irradiance: [f32; 3],
}

/// One light-group member: a patch and its emission at unit intensity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemberSpec {
    /// The patch.
    pub patch: u32,
    /// Emission at unit intensity (W/m^2, RGB).
    pub emission: [f32; 3],
}

/// One light group as the writer takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupSpec<'a> {
    /// Identifier chosen by the host (e.g. a hash of the material name).
    pub id: u32,
    /// Intensity (RGB multiplier) the solver starts with.
    pub default_intensity: [f32; 3],
    /// Member patches.
    pub members: &'a [MemberSpec],
}

/// Form factors as compressed sparse shooter rows over the slots (the patches with run-time state, see
/// [`TableSpec::state`]; slot = patch when every patch has state): row `j` holds the receivers `i` with `F_ji`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowsSpec<'a> {
    /// `row_start[j]..row_start[j + 1]` index the entries of row `j`; length state count + 1.
    pub row_start: &'a [u32],
    /// Receiver slot of each entry (`<` state count), strictly increasing within a row.
    pub receiver: &'a [u32],
    /// `F_ji` of each entry, finite and in `[0, 1]`.
    pub form_factor: &'a [f32],
}

/// Everything a table holds, as borrowed slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableSpec<'a> {
    /// Patches.
    pub patches: &'a [PatchSpec],
    /// Reflectance (RGB, each in `[0, 1)`) per material.
    pub materials: &'a [[f32; 3]],
    /// Light groups (the lights that may change at run time).
    pub groups: &'a [GroupSpec<'a>],
    /// Form factors, rows and receivers indexed by slot.
    pub rows: RowsSpec<'a>,
    /// The patches with run-time state (crate docs, "Run-time state"): `None` gives every patch state (slot =
    /// patch); `Some(patches)` lists them strictly increasing, slot `s` being `patches[s]`. Every light-group
    /// member needs state, and leaving any patch out needs `base_solved` (a stateless patch shows its static
    /// base).
    pub state: Option<&'a [u32]>,
    /// Form-factor codec.
    pub codec: FfCodec,
    /// `true`: `base_irradiance` is the converged static solution, the solver starts with the static power
    /// already shot. `false`: the solver shoots the static emission itself.
    pub base_solved: bool,
    /// Scene fingerprint stored in the header (identifies the scene and meshing; 0 if none). Core does not
    /// interpret it.
    pub fingerprint: u64,
    /// Optional transfer basis (see [`crate::codec::transfer`]): the response `T_g` (W/m^2 at unit intensity, RGB,
    /// finite and `>= 0`) of every patch to every light group, patch-major: `transfer[i * groups + g]`,
    /// length patches x groups. Needs `base_solved`.
    pub transfer: Option<&'a [[f32; 3]]>,
}

/// Largest amount by which a row's sum may exceed 1 before the writer rejects it (f32 rounding of a closed
/// row computed in f64 is far below this; anything larger is a form-factor bug, never renormalized).
pub const ROW_SUM_SLACK: f32 = 1e-5;

/// What is wrong with a [`TableSpec`], or why it does not fit.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum WriteError {
    /// The output buffer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// A count does not fit the format (u32 counts, at most 65536 materials).
    TooMany {
        /// What is counted.
        what: &'static str,
    },
    /// `rows.row_start` has the wrong length, does not start at 0, decreases, or does not end at the entry
    /// count; or `receiver` and `form_factor` differ in length.
    BadRows,
    /// An index is out of range.
    IndexOutOfRange {
        /// What the index refers to.
        what: &'static str,
        /// Position of the offending item.
        position: usize,
        /// The index.
        index: u32,
    },
    /// A value is not finite or out of its range.
    BadValue {
        /// Which field.
        what: &'static str,
        /// Position of the offending item.
        position: usize,
        /// The value.
        value: f32,
    },
    /// A row's receivers are not strictly increasing.
    UnsortedRow {
        /// The row.
        row: usize,
    },
    /// A row's form factors sum to more than `1 + ROW_SUM_SLACK`.
    RowSumExceedsOne {
        /// The row.
        row: usize,
    },
    /// The codec parameters are not valid.
    BadCodec,
    /// The transfer basis does not have patches x groups responses.
    TransferLength {
        /// Responses needed.
        expected: usize,
        /// Responses given.
        got: usize,
    },
    /// A transfer basis is given but `base_solved` is false (the basis relights on the solved static base).
    TransferNeedsSolvedBase,
    /// Some patch is left without run-time state but `base_solved` is false: a stateless patch shows its
    /// static base, which must be the static solution. Give every patch state (`state: None`) or solve the base.
    StateNeedsSolvedBase,
    /// The state list is not strictly increasing.
    UnsortedState {
        /// Position of the first patch not above its predecessor.
        position: usize,
    },
    /// A light-group member is not in the state list.
    MemberWithoutState {
        /// Position of the member in its group.
        position: usize,
        /// The member's patch.
        patch: u32,
    },
    /// Hierarchical tables: the nodes are not in preorder (a parent after its child, or a subtree not
    /// contiguous).
    BadTree {
        /// The first node at fault.
        node: usize,
    },
    /// Hierarchical tables: the tree has a different number of leaves than the leaf list.
    LeafCount {
        /// Leaves in the tree (nodes without children).
        tree: usize,
        /// Leaves given.
        given: usize,
    },
    /// Hierarchical tables: the form factors on a leaf's chain (its run and its ancestors') sum to more than
    /// `1 + ROW_SUM_SLACK`.
    ChainSumExceedsOne {
        /// The leaf.
        leaf: usize,
    },
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            WriteError::BufferTooSmall { needed, got } => {
                write!(f, "buffer too small: {got} bytes, need {needed}")
            }
            WriteError::TooMany { what } => write!(f, "too many {what} for the table format"),
            WriteError::BadRows => {
                write!(f, "form-factor rows: row_start/receiver/form_factor lengths inconsistent")
            }
            WriteError::IndexOutOfRange { what, position, index } => {
                write!(f, "{what} at position {position}: index {index} out of range")
            }
            WriteError::BadValue { what, position, value } => {
                write!(f, "{what} at position {position}: value {value} not finite or out of range")
            }
            WriteError::UnsortedRow { row } => {
                write!(f, "form-factor row {row}: receivers not strictly increasing")
            }
            WriteError::RowSumExceedsOne { row } => write!(f, "form-factor row {row}: sum exceeds 1"),
            WriteError::BadCodec => write!(f, "form-factor codec parameters invalid"),
            WriteError::TransferLength { expected, got } => {
                write!(f, "transfer basis: {got} responses, expected {expected} (patches x light groups)")
            }
            WriteError::TransferNeedsSolvedBase => {
                write!(f, "transfer basis needs a solved static base (base_solved = true)")
            }
            WriteError::StateNeedsSolvedBase => write!(
                f,
                "patches without run-time state need a solved static base (base_solved = true); give every \
                 patch state otherwise"
            ),
            WriteError::UnsortedState { position } => {
                write!(f, "state list: patch at position {position} not above the previous one")
            }
            WriteError::MemberWithoutState { position, patch } => {
                write!(f, "light group member at position {position}: patch {patch} has no run-time state")
            }
            WriteError::BadTree { node } => {
                write!(f, "node {node}: nodes not in preorder (parents first, subtrees contiguous)")
            }
            WriteError::LeafCount { tree, given } => {
                write!(f, "the node tree has {tree} leaves, {given} leaves given")
            }
            WriteError::ChainSumExceedsOne { leaf } => {
                write!(f, "leaf {leaf}: form factors over the leaf and its ancestors sum to more than 1")
            }
        }
    }
}

impl core::error::Error for WriteError {}

pub(super) fn count(n: usize, what: &'static str) -> Result<u32, WriteError> {
    u32::try_from(n).map_err(|_| WriteError::TooMany { what })
}

fn header_of(spec: &TableSpec<'_>) -> Result<Header, WriteError> {
    spec.codec.check().map_err(|_| WriteError::BadCodec)?;
    let patch_count = count(spec.patches.len(), "patches")?;
    let state_count = match spec.state {
        Some(s) => count(s.len(), "patches with state")?,
        None => patch_count,
    };
    if spec.materials.len() > 0x1_0000 {
        return Err(WriteError::TooMany { what: "materials" });
    }
    let member_total = spec.groups.iter().try_fold(0usize, |s, g| s.checked_add(g.members.len()));
    Ok(Header {
        magic: MAGIC,
        version: FORMAT_VERSION,
        patch_count,
        state_count,
        material_count: count(spec.materials.len(), "materials")?,
        group_count: count(spec.groups.len(), "light groups")?,
        member_count: count(member_total.ok_or(WriteError::TooMany { what: "members" })?, "members")?,
        entry_count: count(spec.rows.receiver.len(), "form-factor entries")?,
        ff_bits: spec.codec.bits,
        ff_exponent_bits: spec.codec.exponent_bits,
        index_bytes: if patch_count <= 0x1_0000 { 2 } else { 4 },
        base_solved: spec.base_solved,
        fingerprint: spec.fingerprint,
        transfer: spec.transfer.is_some(),
    })
}

fn header_bytes(h: &Header, buf: &mut [u8; MAX_HEADER_LEN]) -> Result<usize, WriteError> {
    postcard::to_slice(h, buf).map(|s| s.len()).map_err(|_| WriteError::TooMany { what: "header bytes" })
}

/// Bytes [`write_table`] needs for `spec`.
///
/// # Errors
/// [`WriteError::TooMany`] or [`WriteError::BadCodec`] if the counts or codec do not fit the format.
pub fn required_len(spec: &TableSpec<'_>) -> Result<usize, WriteError> {
    let h = header_of(spec)?;
    let mut hb = [0u8; MAX_HEADER_LEN];
    let hl = header_bytes(&h, &mut hb)?;
    SectionSizes::of_header(&h, hl).map(|s| s.total()).ok_or(WriteError::TooMany { what: "bytes" })
}

pub(super) fn check_value(what: &'static str, position: usize, v: f32, ok: bool) -> Result<(), WriteError> {
    if ok {
        Ok(())
    } else {
        Err(WriteError::BadValue { what, position, value: v })
    }
}

pub(super) fn emission_codes(
    what: &'static str,
    position: usize,
    rgb: [f32; 3],
) -> Result<[u16; 3], WriteError> {
    let mut out = [0u16; 3];
    for (o, v) in out.iter_mut().zip(rgb) {
        *o = codec::encode_emission(v).ok_or(WriteError::BadValue { what, position, value: v })?;
    }
    Ok(out)
}

/// A cursor over the output buffer (the length was checked up front, writes past it are dropped).
pub(super) struct Out<'b> {
    pub(super) buf: &'b mut [u8],
    pub(super) at: usize,
}

impl Out<'_> {
    pub(super) fn bytes(&mut self, b: &[u8]) {
        if let Some(d) = self.buf.get_mut(self.at..self.at + b.len()) {
            d.copy_from_slice(b);
        }
        self.at += b.len();
    }
    pub(super) fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    pub(super) fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    pub(super) fn index(&mut self, v: u32, width: u8) {
        if width == 2 {
            self.u16(v as u16);
        } else {
            self.u32(v);
        }
    }
}

/// Checks the compressed-row shape of `rows` over `senders` rows: `senders + 1` offsets starting at 0, never
/// decreasing, ending at the entry count, and one form factor per receiver.
pub(super) fn check_row_offsets(rows: &RowsSpec<'_>, senders: usize) -> Result<(), WriteError> {
    if rows.row_start.len() != senders + 1 || rows.receiver.len() != rows.form_factor.len() {
        return Err(WriteError::BadRows);
    }
    let mut prev = 0u32;
    for (k, &s) in rows.row_start.iter().enumerate() {
        if (k == 0 && s != 0) || s < prev || s as usize > rows.receiver.len() {
            return Err(WriteError::BadRows);
        }
        prev = s;
    }
    if prev as usize != rows.receiver.len() {
        return Err(WriteError::BadRows);
    }
    Ok(())
}

/// Checks every patch (every leaf of a hierarchical table, named so in errors when `leaves`): area finite and
/// positive, material in range, static base within the emission code's range; and every material's reflectance
/// in `[0, 1)`.
pub(super) fn check_patches(
    patches: &[PatchSpec],
    materials: &[[f32; 3]],
    leaves: bool,
) -> Result<(), WriteError> {
    let [area, material, emission, irradiance] = if leaves {
        ["leaf area", "leaf material", "leaf base emission", "leaf base irradiance"]
    } else {
        ["patch area", "patch material", "patch base emission", "patch base irradiance"]
    };
    for (p, patch) in patches.iter().enumerate() {
        check_value(area, p, patch.area, patch.area.is_finite() && patch.area > 0.0)?;
        if patch.material as usize >= materials.len() {
            return Err(WriteError::IndexOutOfRange { what: material, position: p, index: patch.material });
        }
        emission_codes(emission, p, patch.base_emission)?;
        emission_codes(irradiance, p, patch.base_irradiance)?;
    }
    for (m, rho) in materials.iter().enumerate() {
        for &r in rho {
            check_value("material reflectance", m, r, (0.0..1.0).contains(&r))?;
        }
    }
    Ok(())
}

/// Checks every light group: default intensities finite, members below `n` and accepted by `member_ok`
/// (position within the group, member), member emissions within the emission code's range.
pub(super) fn check_groups(
    groups: &[GroupSpec<'_>],
    n: usize,
    member_ok: impl Fn(usize, &MemberSpec) -> Result<(), WriteError>,
) -> Result<(), WriteError> {
    for (g, group) in groups.iter().enumerate() {
        for &v in &group.default_intensity {
            check_value("light group default intensity", g, v, v.is_finite())?;
        }
        for (k, member) in group.members.iter().enumerate() {
            if member.patch as usize >= n {
                return Err(WriteError::IndexOutOfRange {
                    what: "light group member",
                    position: k,
                    index: member.patch,
                });
            }
            member_ok(k, member)?;
            emission_codes("light group member emission", k, member.emission)?;
        }
    }
    Ok(())
}

/// Validates `spec`, quantizes it and writes the table into `out`; returns the number of bytes written.
///
/// Form factors are quantized with `spec.codec` by the row rounding of [`crate::codec`] (decoded row sum
/// `<=` true sum, capped at 1); reflectances and emissions with their codecs.
///
/// # Errors
/// A [`WriteError`] naming the first bad field, or [`WriteError::BufferTooSmall`].
pub fn write_table(spec: &TableSpec<'_>, out: &mut [u8]) -> Result<usize, WriteError> {
    let h = header_of(spec)?;
    let needed = required_len(spec)?;
    if out.len() < needed {
        return Err(WriteError::BufferTooSmall { needed, got: out.len() });
    }
    let n = spec.patches.len();
    let slots = h.state_count as usize;
    if slots > n {
        return Err(WriteError::TooMany { what: "patches with state" });
    }
    if let Some(state) = spec.state {
        if slots < n && !spec.base_solved {
            return Err(WriteError::StateNeedsSolvedBase);
        }
        for (k, &p) in state.iter().enumerate() {
            if p as usize >= n {
                return Err(WriteError::IndexOutOfRange { what: "state patch", position: k, index: p });
            }
            if k > 0 && state[k - 1] >= p {
                return Err(WriteError::UnsortedState { position: k });
            }
        }
    }
    let rows = spec.rows;
    check_row_offsets(&rows, slots)?;
    // Validate everything before writing anything.
    check_patches(spec.patches, spec.materials, false)?;
    check_groups(spec.groups, n, |k, member| {
        if spec.state.is_some_and(|s| s.binary_search(&member.patch).is_err()) {
            return Err(WriteError::MemberWithoutState { position: k, patch: member.patch });
        }
        Ok(())
    })?;
    check_transfer(spec.transfer, n, spec.groups.len(), spec.base_solved)?;
    for j in 0..slots {
        let (s, e) = (rows.row_start[j] as usize, rows.row_start[j + 1] as usize);
        let mut sum = 0u128;
        for k in s..e {
            let (r, f) = (rows.receiver[k], rows.form_factor[k]);
            if r as usize >= slots {
                return Err(WriteError::IndexOutOfRange {
                    what: "form-factor receiver",
                    position: k,
                    index: r,
                });
            }
            if k > s && rows.receiver[k - 1] >= r {
                return Err(WriteError::UnsortedRow { row: j });
            }
            check_value("form factor", k, f, f.is_finite() && (0.0..=1.0).contains(&f))?;
            sum = sum.saturating_add(f32_to_exact(f));
        }
        if sum > f32_to_exact(1.0 + ROW_SUM_SLACK) {
            return Err(WriteError::RowSumExceedsOne { row: j });
        }
    }

    let mut hb = [0u8; MAX_HEADER_LEN];
    let hl = header_bytes(&h, &mut hb)?;
    let mut o = Out { buf: out, at: 0 };
    o.bytes(hb.get(..hl).unwrap_or(&[]));
    for p in spec.patches {
        o.u32(p.area.to_bits());
    }
    for p in spec.patches {
        o.u16(p.material as u16);
    }
    for (k, p) in spec.patches.iter().enumerate() {
        for c in emission_codes("patch base emission", k, p.base_emission)? {
            o.u16(c);
        }
    }
    for (k, p) in spec.patches.iter().enumerate() {
        for c in emission_codes("patch base irradiance", k, p.base_irradiance)? {
            o.u16(c);
        }
    }
    for rho in spec.materials {
        for &r in rho {
            o.u16(codec::encode_reflectance(r));
        }
    }
    for g in spec.groups {
        o.u32(g.id);
    }
    for g in spec.groups {
        for v in g.default_intensity {
            o.u32(v.to_bits());
        }
    }
    let mut start = 0u32;
    o.u32(0);
    for g in spec.groups {
        start += g.members.len() as u32;
        o.u32(start);
    }
    for g in spec.groups {
        for m in g.members {
            o.index(m.patch, h.index_bytes);
        }
    }
    for g in spec.groups {
        for (k, m) in g.members.iter().enumerate() {
            for c in emission_codes("light group member emission", k, m.emission)? {
                o.u16(c);
            }
        }
    }
    if let Some(state) = spec.state.filter(|_| slots < n) {
        for &p in state {
            o.index(p, h.index_bytes);
        }
        for &p in state {
            o.u16(spec.patches.get(p as usize).map_or(0, |q| q.material as u16));
        }
    }
    for &s in rows.row_start {
        o.u32(s);
    }
    // Row exponents and codes: quantize each row through a fixed scratch block, in chunks if the row is long.
    let exps_at = o.at;
    o.at += slots;
    for &r in rows.receiver {
        o.index(r, h.index_bytes);
    }
    let codes_at = o.at;
    for j in 0..slots {
        let (s, e) = (rows.row_start[j] as usize, rows.row_start[j + 1] as usize);
        let values = &rows.form_factor[s..e];
        let target = values
            .iter()
            .fold(0u128, |acc, &v| acc.saturating_add(f32_to_exact(v)))
            .min(1u128 << EXACT_SHIFT);
        let receivers = &rows.receiver[s..e];
        let at = codes_at + s * spec.codec.code_bytes();
        let exponent = quantize_row_into(spec.codec, values, receivers, j as u32, target, &mut o, at);
        if let Some(b) = o.buf.get_mut(exps_at + j) {
            *b = exponent;
        }
    }
    o.at = codes_at + rows.receiver.len() * spec.codec.code_bytes();
    if let Some(t) = spec.transfer {
        write_transfer(t, spec.groups.len(), &mut o);
    }
    let crc = crc32(o.buf.get(..o.at).unwrap_or(&[]));
    o.u32(crc);
    Ok(o.at)
}

/// Quantizes one row and writes its codes at byte offset `at`; returns the row exponent.
///
/// The row rounding needs the codes of a row at once, held in a stack block of `BLOCK` codes: longer rows are
/// quantized as consecutive chunks under one row exponent, each chunk rounded against what is left of the
/// row's target, so the decoded row sum stays `<= target`.
pub(super) fn quantize_row_into(
    codec: FfCodec,
    values: &[f32],
    receivers: &[u32],
    shooter: u32,
    target: u128,
    o: &mut Out<'_>,
    at: usize,
) -> u8 {
    const BLOCK: usize = codec::QUANT_BLOCK;
    let mut codes = [0u16; BLOCK];
    let max = values.iter().map(|&v| f32_to_exact(v)).max().unwrap_or(0);
    let e = codec::row_exponent_for(max);
    let mut remaining = target;
    let mut pos = at;
    for (chunk, chunk_receivers) in values.chunks(BLOCK).zip(receivers.chunks(BLOCK)) {
        let c = &mut codes[..chunk.len()];
        let chunk_sum = chunk.iter().fold(0u128, |acc, &v| acc.saturating_add(f32_to_exact(v)));
        let start = chunk_receivers.partition_point(|&r| r <= shooter);
        let decoded = codec::quantize_row_with_exponent(codec, chunk, chunk_sum.min(remaining), e, start, c);
        remaining = remaining.saturating_sub(decoded);
        write_codes(codec, c, o, pos);
        pos += chunk.len() * codec.code_bytes();
    }
    e
}

/// Checks an optional transfer basis of `elements x groups` responses (element-major): a solved base, the
/// length, every response finite and in `0..=TRANSFER_MAX`. Shared by the flat and hierarchical writers.
pub(super) fn check_transfer(
    transfer: Option<&[[f32; 3]]>,
    elements: usize,
    groups: usize,
    base_solved: bool,
) -> Result<(), WriteError> {
    let Some(t) = transfer else { return Ok(()) };
    if !base_solved {
        return Err(WriteError::TransferNeedsSolvedBase);
    }
    let expected = elements.checked_mul(groups).ok_or(WriteError::TooMany { what: "transfer responses" })?;
    if t.len() != expected {
        return Err(WriteError::TransferLength { expected, got: t.len() });
    }
    for (k, rgb) in t.iter().enumerate() {
        for &v in rgb {
            check_value("transfer response", k, v, v.is_finite() && (0.0..=TRANSFER_MAX).contains(&v))?;
        }
    }
    Ok(())
}

/// Writes the transfer section: per group and channel the step exponent of its largest response, then the
/// codes, patch-major (validated by the caller: `t.len() = patches x groups`, values in `[0, TRANSFER_MAX]`).
pub(super) fn write_transfer(t: &[[f32; 3]], groups: usize, o: &mut Out<'_>) {
    let exps_at = o.at;
    for g in 0..groups {
        for c in 0..3 {
            let max = t.iter().skip(g).step_by(groups).map(|v| v[c]).fold(0.0f32, f32::max);
            o.bytes(&[transfer_exponent_for(max) as u8]);
        }
    }
    for (k, rgb) in t.iter().enumerate() {
        let g = k % groups.max(1);
        for (c, &v) in rgb.iter().enumerate() {
            let exp = o.buf.get(exps_at + g * 3 + c).map_or(0, |&b| b as i8);
            o.u16(encode_transfer(v, exp));
        }
    }
}

fn write_codes(codec: FfCodec, codes: &[u16], o: &mut Out<'_>, at: usize) {
    let saved = o.at;
    o.at = at;
    for &c in codes {
        if codec.bits == 8 {
            o.bytes(&[c as u8]);
        } else {
            o.u16(c);
        }
    }
    o.at = saved;
}
