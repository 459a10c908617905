//! Hierarchical tables (format version 5, `docs/format.md`, "Hierarchical tables"): the header,
//! [`HierTable::parse`] (the one checked constructor: after it succeeds no accessor panics) and the read views.
//!
//! The node tree is stored in preorder (every parent before its children, every subtree a contiguous range of
//! nodes `node..subtree_end`), so the leaves below any node are a contiguous range of leaves too: a push from
//! a node to its leaves is one loop over a range, and the chain of a leaf is a walk over parent indices.
//!
//! Links are stored by **slot**: the leaves first (slot `l` is leaf `l`), then the inner nodes in node order
//! (slot `n + i` is inner node `i`, `n` the leaf count). Runs are in slot order and receivers are slots, so
//! shooting tells a leaf receiver from an inner one by one comparison and indexes the solver's per-leaf and
//! per-inner-node buffers directly, and a run's leaf receivers (smaller slots) come before its inner ones.

use serde::{Deserialize, Serialize};

use super::error::{IndexArray, OffsetArray, QuantParam, TableError, TreeFault};
use super::layout::{le_f32, le_u16, le_u32, rgb16, TransferSection};
use super::parse::{
    check_codec, check_offsets, check_prefix, check_transfer_exponents, header_error, in_range,
};
use super::view::{le, Row};
use super::HIER_FORMAT_VERSION;
use crate::codec::{FfCodec, Frac, RowDecoder, EMISSION_MAX, EXACT_SHIFT, MAX_ROW_EXPONENT};
use crate::crc::crc32;

/// The postcard-encoded header of a hierarchical table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct HierHeader {
    pub magic: [u8; 4],
    pub version: u16,
    pub leaf_count: u32,
    pub node_count: u32,
    pub material_count: u32,
    pub group_count: u32,
    pub member_count: u32,
    pub link_count: u32,
    pub ff_bits: u8,
    pub ff_exponent_bits: u8,
    pub index_bytes: u8,
    pub base_solved: bool,
    pub fingerprint: u64,
    pub transfer: bool,
}

/// Largest postcard header, in bytes (4 magic + varints: 3 for u16, 5 per u32, 1 per u8/bool, 10 for u64).
pub(crate) const MAX_HIER_HEADER_LEN: usize = 4 + 3 + 6 * 5 + 4 + 10 + 1;

/// Bytes of each part of a hierarchical table blob, in blob order (`docs/format.md`, "Hierarchical tables").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HierSectionSizes {
    /// The postcard header.
    pub header: usize,
    /// Leaf materials (`u16` per leaf).
    pub leaf_material: usize,
    /// Static emission codes (3 x `u16` per leaf).
    pub base_emission: usize,
    /// Static irradiance codes (3 x `u16` per leaf).
    pub base_irradiance: usize,
    /// Material reflectance codes (3 x `u16` per material).
    pub reflectance: usize,
    /// Light-group ids (`u32` per group).
    pub group_id: usize,
    /// Light-group default intensities (3 x `f32` per group).
    pub group_intensity: usize,
    /// Light-group member starts (`u32` per group, plus one).
    pub group_start: usize,
    /// Member leaves (an index per member).
    pub member_leaf: usize,
    /// Member unit emission (3 x `f32` per member).
    pub member_emission: usize,
    /// Parent of each node (an index per node; a root is its own parent).
    pub node_parent: usize,
    /// End of each node's subtree (`u32` per node).
    pub node_end: usize,
    /// First leaf of each node's subtree (`u32` per node, plus one).
    pub node_leaf_start: usize,
    /// Node areas (`f32` per node).
    pub node_area: usize,
    /// Node of each leaf (an index per leaf).
    pub leaf_node: usize,
    /// Inner index of each leaf's parent, the inner count for a root leaf (an index per leaf).
    pub leaf_parent: usize,
    /// Node of each inner node (an index per inner node).
    pub inner_node: usize,
    /// Link run starts (`u32` per slot, plus one).
    pub run_start: usize,
    /// Link run exponents (`u8` per slot).
    pub run_exponent: usize,
    /// Link receivers (a slot per link).
    pub link_receiver: usize,
    /// Link form-factor codes.
    pub link_code: usize,
    /// Transfer scale exponents (3 x `i8` per group; 0 without the transfer basis).
    pub transfer_exponent: usize,
    /// Transfer response codes (3 x `u16` per leaf and group, leaf-major; 0 without the transfer basis).
    pub transfer_code: usize,
    /// The CRC-32.
    pub crc: usize,
}

impl HierSectionSizes {
    /// The sizes a header implies, or `None` on arithmetic overflow.
    pub(crate) fn of_header(h: &HierHeader, header_len: usize) -> Option<HierSectionSizes> {
        let n = h.leaf_count as usize;
        let nn = h.node_count as usize;
        let g = h.group_count as usize;
        let ib = usize::from(h.index_bytes);
        // The optional transfer basis: per group 3 exponents, per (leaf, group) 3 codes of 2 bytes.
        let (tg, tn) = if h.transfer { (g, n) } else { (0, 0) };
        // More leaves than nodes is a bad tree (parse reports it); the inner section is then empty.
        let inner = nn.saturating_sub(n);
        let sizes = HierSectionSizes {
            header: header_len,
            leaf_material: n.checked_mul(2)?,
            base_emission: n.checked_mul(6)?,
            base_irradiance: n.checked_mul(6)?,
            reflectance: (h.material_count as usize).checked_mul(6)?,
            group_id: g.checked_mul(4)?,
            group_intensity: g.checked_mul(12)?,
            group_start: g.checked_add(1)?.checked_mul(4)?,
            member_leaf: (h.member_count as usize).checked_mul(ib)?,
            member_emission: (h.member_count as usize).checked_mul(12)?,
            node_parent: nn.checked_mul(ib)?,
            node_end: nn.checked_mul(4)?,
            node_leaf_start: nn.checked_add(1)?.checked_mul(4)?,
            node_area: nn.checked_mul(4)?,
            leaf_node: n.checked_mul(ib)?,
            leaf_parent: n.checked_mul(ib)?,
            inner_node: inner.checked_mul(ib)?,
            run_start: nn.checked_add(1)?.checked_mul(4)?,
            run_exponent: nn,
            link_receiver: (h.link_count as usize).checked_mul(ib)?,
            link_code: (h.link_count as usize).checked_mul(usize::from(h.ff_bits / 8))?,
            transfer_exponent: tg.checked_mul(3)?,
            transfer_code: tn.checked_mul(tg)?.checked_mul(6)?,
            crc: 4,
        };
        sizes.parts().into_iter().try_fold(0usize, usize::checked_add)?;
        Some(sizes)
    }

    fn parts(&self) -> [usize; 24] {
        [
            self.header,
            self.leaf_material,
            self.base_emission,
            self.base_irradiance,
            self.reflectance,
            self.group_id,
            self.group_intensity,
            self.group_start,
            self.member_leaf,
            self.member_emission,
            self.node_parent,
            self.node_end,
            self.node_leaf_start,
            self.node_area,
            self.leaf_node,
            self.leaf_parent,
            self.inner_node,
            self.run_start,
            self.run_exponent,
            self.link_receiver,
            self.link_code,
            self.transfer_exponent,
            self.transfer_code,
            self.crc,
        ]
    }

    /// The whole blob.
    #[must_use]
    pub fn total(&self) -> usize {
        self.parts().into_iter().fold(0, usize::saturating_add)
    }
}

/// A validated, zero-copy view of a hierarchical table blob (format version [`HIER_FORMAT_VERSION`]).
#[derive(Clone, Copy, Debug)]
pub struct HierTable<'a> {
    header: HierHeader,
    header_len: usize,
    codec: FfCodec,
    crc: u32,
    /// Longest chain (a leaf and its ancestors), in nodes.
    max_depth: u32,
    /// Longest link run.
    longest_run: u32,
    /// Whether any leaf has a static base code other than 0 (found once, at parse).
    static_base: bool,
    leaf_material: &'a [u8],
    base_emission: &'a [u8],
    base_irradiance: &'a [u8],
    reflectance: &'a [u8],
    group_id: &'a [u8],
    group_intensity: &'a [u8],
    group_start: &'a [u8],
    member_leaf: &'a [u8],
    member_emission: &'a [u8],
    node_parent: &'a [u8],
    node_end: &'a [u8],
    node_leaf_start: &'a [u8],
    node_area: &'a [u8],
    leaf_node: &'a [u8],
    leaf_parent: &'a [u8],
    inner_node: &'a [u8],
    run_start: &'a [u8],
    run_exponent: &'a [u8],
    link_receiver: &'a [u8],
    link_code: &'a [u8],
    transfer_exponent: &'a [u8],
    transfer_code: &'a [u8],
}

/// The node sections of a [`HierTable`] that hierarchical shooting's inner loops read (a leaf receiver's
/// material and parent, a sweep's leaf starts): reads with the same results as the table's accessors
/// ([`HierTable::leaf_start`], [`HierTable::material`]) for nodes and leaves in range, without the count checks
/// an index validated by parse does not need (out of range still reads 0).
#[derive(Clone, Copy, Debug)]
pub(crate) struct NodeSections<'a> {
    leaf_start: &'a [u8],
    leaf_parent: &'a [u8],
    material: &'a [u8],
}

/// Entry `i` of a section of `N`-byte little-endian values (`N` is 2 or 4), 0 past its end: one comparison
/// against the section's entry count.
#[inline(always)]
fn entry<const N: usize>(s: &[u8], i: u32) -> u32 {
    let (entries, _) = s.as_chunks::<N>();
    entries.get(i as usize).map_or(0, |b| le::<N>(b))
}

/// Entries `i` and `i + 1` of a section of 4-byte little-endian values with one comparison (`(0, 0)` past its
/// end).
#[inline(always)]
fn pair(s: &[u8], i: u32) -> (u32, u32) {
    let (entries, _) = s.as_chunks::<4>();
    let i = i as usize;
    match entries.get(i..i.wrapping_add(2)) {
        Some([a, b]) => (le::<4>(a), le::<4>(b)),
        _ => (0, 0),
    }
}

impl<'a> NodeSections<'a> {
    /// `(leaf_start(node), leaf_start(node + 1))` with one comparison (`(0, 0)` past the section): they differ
    /// exactly when `node` is a leaf (leaf starts count the leaves before each node, validated by parse), so
    /// this tells a leaf from an inner node and gives its leaf or inner index without the subtree end.
    #[inline(always)]
    pub(crate) fn leaf_starts(&self, node: u32) -> (u32, u32) {
        pair(self.leaf_start, node)
    }

    /// The leaves' parents as inner indices (the inner count for a root leaf), entries of `IB` bytes.
    #[inline(always)]
    pub(crate) fn leaf_parents<const IB: usize>(&self) -> &'a [[u8; IB]] {
        self.leaf_parent.as_chunks::<IB>().0
    }

    /// The leaves' materials, 2-byte entries.
    #[inline(always)]
    pub(crate) fn materials(&self) -> &'a [[u8; 2]] {
        self.material.as_chunks::<2>().0
    }

    /// Material of `leaf`.
    #[inline(always)]
    pub(crate) fn material(&self, leaf: u32) -> u32 {
        entry::<2>(self.material, leaf)
    }
}

/// Reads index `k` of an index section of `width` bytes (0 past its end).
#[inline]
pub(crate) fn read_index(s: &[u8], width: u8, k: u32) -> u32 {
    if width == 2 {
        u32::from(le_u16(s, k as usize))
    } else {
        le_u32(s, k as usize)
    }
}

/// The path from a root down to the node last visited in preorder, as the running sum of the decoded run sums
/// of its nodes and its length. Moving to the next node in preorder pops the nodes that are not its ancestors
/// (each node is pushed and popped once over a whole pass), so a pass over every node costs `O(nodes)` run
/// sums without per-node memory. Shared by the parser (the chain bound) and the writer (the chain cap).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PathSum {
    /// Sum of the run sums on the path (exact units, `2^-EXACT_SHIFT`).
    pub sum: u128,
    /// Nodes on the path.
    pub depth: u32,
    prev: Option<u32>,
}

impl PathSum {
    /// Pops the path back to the parent of `node` (`parent(node) == node` for a root: pops everything); the
    /// caller then [`PathSum::push`]es `node`. Needs nodes visited in preorder of a well-formed tree.
    pub fn pop_to_parent_of<E>(
        &mut self,
        node: u32,
        parent: impl Fn(u32) -> u32,
        mut run_sum: impl FnMut(u32) -> Result<u128, E>,
    ) -> Result<(), E> {
        let p = parent(node);
        let Some(mut j) = self.prev else { return Ok(()) };
        // Bounded by the depth: every step pops one node of the path.
        for _ in 0..=self.depth {
            if j == p && p != node {
                break;
            }
            self.sum = self.sum.saturating_sub(run_sum(j)?);
            self.depth = self.depth.saturating_sub(1);
            let pj = parent(j);
            if pj == j || self.depth == 0 {
                break;
            }
            j = pj;
        }
        Ok(())
    }

    /// Appends `node` with its run sum to the path.
    pub fn push(&mut self, node: u32, run_sum: u128) {
        self.sum = self.sum.saturating_add(run_sum);
        self.depth = self.depth.saturating_add(1);
        self.prev = Some(node);
    }
}

/// A light-group member of a hierarchical table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HierMember {
    /// The leaf (its index among the leaves).
    pub leaf: u32,
    /// Emission at unit intensity (W/m^2, RGB), stored as `f32`: a group's few members cost little, and an
    /// emission code's rounding (relative `2^-11`) would bias the whole answer by as much.
    pub emission: [f32; 3],
}

impl<'a> HierTable<'a> {
    /// Parses and validates a hierarchical table blob.
    ///
    /// # Errors
    /// The first problem found, as a [`TableError`]: [`TableError::FlatTable`] for a flat (version 3) table,
    /// then, in order, the header, quantization parameters, length and CRC checks of [`Table::parse`](super::Table::parse), then
    /// content: leaf materials, member offsets and leaves, intensities, the tree ([`TableError::BadTree`]:
    /// subtree ends, parents, leaf numbering), node areas, run offsets, then node by node in preorder: the run's
    /// exponent, receivers and order, and at each leaf the chain bound ([`TableError::ChainSumExceedsOne`]).
    pub fn parse(bytes: &'a [u8]) -> Result<HierTable<'a>, TableError> {
        check_prefix(bytes, HIER_FORMAT_VERSION)?;
        let (header, rest) = postcard::take_from_bytes::<HierHeader>(bytes).map_err(header_error)?;
        let header_len = bytes.len() - rest.len();
        let codec = check_codec(header.ff_bits, header.ff_exponent_bits, header.index_bytes)?;
        // Node indices and subtree ends go up to the node count; u32::MAX is never a valid node.
        if (header.index_bytes == 2 && header.node_count > 0x1_0000)
            || header.material_count > 0x1_0000
            || header.node_count == u32::MAX
        {
            return Err(TableError::CountsTooLarge);
        }
        let sizes = HierSectionSizes::of_header(&header, header_len).ok_or(TableError::CountsTooLarge)?;
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
        let mut rest = body.get(header_len..).unwrap_or(&[]);
        let mut take = |len: usize| {
            let (section, tail) = rest.split_at(len.min(rest.len()));
            rest = tail;
            section
        };
        let mut table = HierTable {
            header,
            header_len,
            codec,
            crc: computed,
            max_depth: 0,
            longest_run: 0,
            static_base: false,
            leaf_material: take(sizes.leaf_material),
            base_emission: take(sizes.base_emission),
            base_irradiance: take(sizes.base_irradiance),
            reflectance: take(sizes.reflectance),
            group_id: take(sizes.group_id),
            group_intensity: take(sizes.group_intensity),
            group_start: take(sizes.group_start),
            member_leaf: take(sizes.member_leaf),
            member_emission: take(sizes.member_emission),
            node_parent: take(sizes.node_parent),
            node_end: take(sizes.node_end),
            node_leaf_start: take(sizes.node_leaf_start),
            node_area: take(sizes.node_area),
            leaf_node: take(sizes.leaf_node),
            leaf_parent: take(sizes.leaf_parent),
            inner_node: take(sizes.inner_node),
            run_start: take(sizes.run_start),
            run_exponent: take(sizes.run_exponent),
            link_receiver: take(sizes.link_receiver),
            link_code: take(sizes.link_code),
            transfer_exponent: take(sizes.transfer_exponent),
            transfer_code: take(sizes.transfer_code),
        };
        table.static_base = super::parse::any_nonzero(table.base_emission, table.base_irradiance);
        table.validate()?;
        Ok(table)
    }

    fn validate(&mut self) -> Result<(), TableError> {
        let n = self.header.leaf_count;
        let nn = self.header.node_count;
        for l in 0..n {
            let mat = u32::from(le_u16(self.leaf_material, l as usize));
            in_range(IndexArray::PatchMaterial, l, mat, self.header.material_count)?;
        }
        check_offsets(
            self.group_start,
            self.header.group_count,
            self.header.member_count,
            OffsetArray::GroupStart,
        )?;
        for k in 0..self.header.member_count {
            in_range(IndexArray::MemberPatch, k, self.index(self.member_leaf, k), n)?;
            for c in 0..3 {
                let v = le_f32(self.member_emission, k as usize * 3 + c);
                if !(0.0..=EMISSION_MAX).contains(&v) {
                    return Err(TableError::BadMemberEmission { member: k });
                }
            }
        }
        for g in 0..self.header.group_count {
            for c in 0..3 {
                if !le_f32(self.group_intensity, g as usize * 3 + c).is_finite() {
                    return Err(TableError::BadIntensity { group: g });
                }
            }
        }
        check_tree(
            nn,
            n,
            |k| self.index(self.node_parent, k),
            |k| le_u32(self.node_end, k as usize),
            |k| le_u32(self.node_leaf_start, k as usize),
            |l| self.index(self.leaf_node, l),
        )?;
        check_slots(
            nn,
            n,
            |k| self.index(self.node_parent, k),
            |k| le_u32(self.node_end, k as usize),
            |k| le_u32(self.node_leaf_start, k as usize),
            |l| self.index(self.leaf_parent, l),
            |i| self.index(self.inner_node, i),
        )?;
        self.check_areas()?;
        check_offsets(self.run_start, nn, self.header.link_count, OffsetArray::RowStart)?;
        let one = 1u128 << EXACT_SHIFT;
        let mut path = PathSum::default();
        let mut max_depth = 0;
        let mut longest = 0;
        for k in 0..nn {
            let parent = |j| self.index(self.node_parent, j);
            path.pop_to_parent_of(k, parent, |j| self.checked_run_sum(j))?;
            path.push(k, self.checked_run_sum(k)?);
            max_depth = max_depth.max(path.depth);
            longest = longest.max(self.run(k).map_or(0, |r| r.end - r.start));
            if self.is_leaf(k) && path.sum > one {
                return Err(TableError::ChainSumExceedsOne {
                    leaf: le_u32(self.node_leaf_start, k as usize),
                });
            }
        }
        self.max_depth = max_depth;
        self.longest_run = longest;
        if self.header.transfer {
            if !self.header.base_solved {
                return Err(TableError::TransferWithoutSolvedBase);
            }
            check_transfer_exponents(self.transfer_exponent, self.header.group_count)?;
        }
        Ok(())
    }

    /// Areas finite and positive, and each inner node's area the sum of its children's to within f32
    /// rounding: the writer sums the `c` children in f32 in one order and this check in another; each order
    /// rounds `c - 1` partial sums of positive terms, each by at most `2^-24` of the total, so the two differ by
    /// at most `2 (c - 1) 2^-24` of it. The tolerance `(2 c + 2) 2^-24` of the stored area leaves four roundings
    /// for the comparison itself.
    fn check_areas(&self) -> Result<(), TableError> {
        let nn = self.header.node_count;
        for k in 0..nn {
            let a = le_f32(self.node_area, k as usize);
            if !(a.is_finite() && a > 0.0) {
                return Err(TableError::BadArea { patch: k });
            }
        }
        for k in 0..nn {
            let end = self.subtree_end_raw(k);
            let (mut c, mut sum, mut count) = (k + 1, 0.0f32, 0u32);
            // The tree is checked: the child chain ends exactly at `end` and moves forward at every step.
            while c < end {
                sum += le_f32(self.node_area, c as usize);
                count += 1;
                c = self.subtree_end_raw(c);
            }
            let a = le_f32(self.node_area, k as usize);
            let tol = a * (2.0 * count as f32 + 2.0) * (1.0 / 16_777_216.0);
            // Finite positive children: the sum is finite or +inf, never NaN.
            if count > 0 && (a - sum).abs() > tol {
                return Err(TableError::NodeAreaMismatch { node: k });
            }
        }
        Ok(())
    }

    /// Decoded sum of `node`'s run (exact units), checking its exponent, receivers (slots) and order.
    fn checked_run_sum(&self, node: u32) -> Result<u128, TableError> {
        let e = self.run_exponent.get(self.slot_unchecked(node) as usize).copied().unwrap_or(0);
        if e > MAX_ROW_EXPONENT {
            return Err(TableError::BadQuantParams { param: QuantParam::RowExponent, value: node });
        }
        let range = self.run(node).unwrap_or(0..0);
        let mut sum: u128 = 0;
        let mut prev: Option<u32> = None;
        for k in range {
            let r = self.index(self.link_receiver, k);
            in_range(IndexArray::LinkReceiver, k, r, self.header.node_count)?;
            if prev.is_some_and(|p| p >= r) {
                return Err(TableError::UnsortedRow { row: node });
            }
            prev = Some(r);
            sum = sum.saturating_add(self.codec.decode(self.code(k), e).to_exact());
        }
        Ok(sum)
    }

    #[inline]
    fn index(&self, s: &[u8], k: u32) -> u32 {
        read_index(s, self.header.index_bytes, k)
    }

    #[inline]
    fn code(&self, k: u32) -> u16 {
        if self.codec.bits == 8 {
            u16::from(self.link_code.get(k as usize).copied().unwrap_or(0))
        } else {
            le_u16(self.link_code, k as usize)
        }
    }

    #[inline]
    fn subtree_end_raw(&self, node: u32) -> u32 {
        le_u32(self.node_end, node as usize)
    }

    /// The slot of `node` (leaf index for a leaf, leaf count plus inner index for an inner node), from two
    /// adjacent leaf starts; some value out of range.
    #[inline]
    pub(crate) fn slot_unchecked(&self, node: u32) -> u32 {
        let (l, next) = pair(self.node_leaf_start, node);
        slot_of(node, l, next != l, self.header.leaf_count)
    }
}

/// The slot of `node` (`docs/format.md`, "Slots") from its leaf start `l` (the leaves before it), whether it
/// is a leaf, and the leaf count: `l` for a leaf, `leaves + node - l` (its inner index after the leaves) for an
/// inner node. The one place the numbering is written; the parser, the writer and the solver's sweep call it.
#[inline(always)]
pub(crate) fn slot_of(node: u32, l: u32, leaf: bool, leaves: u32) -> u32 {
    if leaf {
        l
    } else {
        leaves.wrapping_add(node.wrapping_sub(l))
    }
}

/// The slot checks of [`HierTable::parse`] (and of the writer, on what it wrote), after [`check_tree`]: the
/// leaf-parent section gives every leaf its parent's inner index (`node - leaf_start(node)`, the inner count
/// for a root leaf) and the inner-node section lists the inner nodes in node order. Cost `O(nodes)`.
pub(crate) fn check_slots(
    nodes: u32,
    leaves: u32,
    parent: impl Fn(u32) -> u32,
    end: impl Fn(u32) -> u32,
    leaf_start: impl Fn(u32) -> u32,
    leaf_parent: impl Fn(u32) -> u32,
    inner_node: impl Fn(u32) -> u32,
) -> Result<(), TableError> {
    let inner = nodes.saturating_sub(leaves);
    let mut i = 0u32;
    for k in 0..nodes {
        if end(k) == k + 1 {
            let p = parent(k);
            // A parent's inner index is its slot less the leaf count.
            let want = if p == k { inner } else { slot_of(p, leaf_start(p), false, 0) };
            if leaf_parent(leaf_start(k)) != want {
                return Err(TableError::BadTree { node: k, fault: TreeFault::LeafParent });
            }
        } else {
            if inner_node(i) != k {
                return Err(TableError::BadTree { node: k, fault: TreeFault::InnerNode });
            }
            i += 1;
        }
    }
    Ok(())
}

/// The tree checks of [`HierTable::parse`] (and of the writer, on what it wrote), over accessors of the
/// stored arrays: every subtree end in `node + 1..=nodes`; the roots' chain `0, end(0), end(end(0)), ...`
/// ends at `nodes` with every root its own parent; every node's child chain `node + 1, end(node + 1), ...`
/// stays inside its subtree and names `node` as parent. Together these make the subtrees a laminar family in
/// preorder with every stored parent the true one (each node starts exactly one interval of one chain).
/// Then the leaves (nodes whose subtree is themselves) are numbered in node order: `leaf_start(node)` is the
/// number of leaves before `node` and `leaf_node` lists them. Cost `O(nodes)`.
pub(crate) fn check_tree(
    nodes: u32,
    leaves: u32,
    parent: impl Fn(u32) -> u32,
    end: impl Fn(u32) -> u32,
    leaf_start: impl Fn(u32) -> u32,
    leaf_node: impl Fn(u32) -> u32,
) -> Result<(), TableError> {
    let bad = |node, fault| Err(TableError::BadTree { node, fault });
    for k in 0..nodes {
        let e = end(k);
        if e <= k || e > nodes {
            return bad(k, TreeFault::SubtreeEnd);
        }
    }
    let mut c = 0;
    while c < nodes {
        if parent(c) != c {
            return bad(c, TreeFault::Parent);
        }
        c = end(c);
    }
    for k in 0..nodes {
        let ek = end(k);
        let mut c = k + 1;
        while c < ek {
            if parent(c) != k {
                return bad(c, TreeFault::Parent);
            }
            let ec = end(c);
            if ec > ek {
                return bad(c, TreeFault::SubtreeEnd);
            }
            c = ec;
        }
    }
    let mut count = 0u32;
    for k in 0..nodes {
        if leaf_start(k) != count {
            return bad(k, TreeFault::LeafStart);
        }
        if end(k) == k + 1 {
            if count >= leaves || leaf_node(count) != k {
                return bad(k, TreeFault::LeafNode);
            }
            count += 1;
        }
    }
    if leaf_start(nodes) != count {
        return bad(nodes, TreeFault::LeafStart);
    }
    if count != leaves {
        return bad(nodes, TreeFault::LeafNode);
    }
    Ok(())
}

impl<'a> HierTable<'a> {
    /// Number of leaves (the elements whose radiosity is the answer).
    #[must_use]
    pub fn leaf_count(&self) -> u32 {
        self.header.leaf_count
    }

    /// Number of nodes (leaves included).
    #[must_use]
    pub fn node_count(&self) -> u32 {
        self.header.node_count
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

    /// Number of links.
    #[must_use]
    pub fn link_count(&self) -> u32 {
        self.header.link_count
    }

    /// The form-factor codec.
    #[must_use]
    pub fn codec(&self) -> FfCodec {
        self.codec
    }

    /// Whether the static base irradiance is a converged solution (crate docs, "Static base").
    #[must_use]
    pub fn base_solved(&self) -> bool {
        self.header.base_solved
    }

    /// The scene fingerprint the host stored (not interpreted by core).
    #[must_use]
    pub fn fingerprint(&self) -> u64 {
        self.header.fingerprint
    }

    /// The CRC-32 of the blob.
    #[must_use]
    pub fn crc(&self) -> u32 {
        self.crc
    }

    /// Nodes on the longest chain (a leaf and its ancestors): the worst case of an upward walk.
    #[must_use]
    pub fn max_depth(&self) -> u32 {
        self.max_depth
    }

    /// Links in the longest run.
    #[must_use]
    pub fn longest_run(&self) -> u32 {
        self.longest_run
    }

    /// Bytes of each section of the blob.
    #[must_use]
    pub fn section_sizes(&self) -> HierSectionSizes {
        HierSectionSizes::of_header(&self.header, self.header_len).unwrap_or_default()
    }

    /// Parent of `node`, or `None` for a root or out of range.
    #[must_use]
    #[inline]
    pub fn parent(&self, node: u32) -> Option<u32> {
        if node >= self.node_count() {
            return None;
        }
        let p = self.index(self.node_parent, node);
        (p != node).then_some(p)
    }

    /// End of `node`'s subtree: its descendants are the nodes `node + 1..subtree_end`.
    #[must_use]
    #[inline]
    pub fn subtree_end(&self, node: u32) -> Option<u32> {
        (node < self.node_count()).then(|| self.subtree_end_raw(node))
    }

    /// Whether `node` is a leaf (has no children); `false` out of range.
    #[must_use]
    #[inline]
    pub fn is_leaf(&self, node: u32) -> bool {
        node < self.node_count() && self.subtree_end_raw(node) == node + 1
    }

    /// The leaves below `node` (itself if a leaf), a contiguous range of leaf indices.
    #[must_use]
    #[inline]
    pub fn leaf_range(&self, node: u32) -> Option<core::ops::Range<u32>> {
        let end = self.subtree_end(node)?;
        Some(le_u32(self.node_leaf_start, node as usize)..le_u32(self.node_leaf_start, end as usize))
    }

    /// The number of leaves before `node` in preorder (`leaf_range(node).start`, one read); 0 out of range.
    #[must_use]
    #[inline]
    pub fn leaf_start(&self, node: u32) -> u32 {
        if node < self.node_count() {
            le_u32(self.node_leaf_start, node as usize)
        } else {
            0
        }
    }

    /// Area of `node` (scene units squared; an inner node's is the sum of its children's).
    #[must_use]
    #[inline]
    pub fn node_area(&self, node: u32) -> Option<f32> {
        (node < self.node_count()).then(|| le_f32(self.node_area, node as usize))
    }

    /// The node of `leaf`.
    #[must_use]
    #[inline]
    pub fn leaf_node(&self, leaf: u32) -> Option<u32> {
        (leaf < self.leaf_count()).then(|| self.index(self.leaf_node, leaf))
    }

    /// Area of `leaf`.
    #[must_use]
    #[inline]
    pub fn leaf_area(&self, leaf: u32) -> Option<f32> {
        self.node_area(self.leaf_node(leaf)?)
    }

    /// Material of `leaf`.
    #[must_use]
    #[inline]
    pub fn material(&self, leaf: u32) -> Option<u32> {
        (leaf < self.leaf_count()).then(|| u32::from(le_u16(self.leaf_material, leaf as usize)))
    }

    /// Static base emission codes (RGB) of `leaf`.
    #[must_use]
    pub fn base_emission(&self, leaf: u32) -> Option<[u16; 3]> {
        (leaf < self.leaf_count()).then(|| rgb16(self.base_emission, leaf as usize))
    }

    /// Static base irradiance codes (RGB) of `leaf`.
    #[must_use]
    pub fn base_irradiance(&self, leaf: u32) -> Option<[u16; 3]> {
        (leaf < self.leaf_count()).then(|| rgb16(self.base_irradiance, leaf as usize))
    }

    /// Reflectance codes (RGB) of `material`.
    #[must_use]
    pub fn reflectance(&self, material: u32) -> Option<[u16; 3]> {
        (material < self.material_count()).then(|| rgb16(self.reflectance, material as usize))
    }

    /// Identifier of light `group`.
    #[must_use]
    pub fn group_id(&self, group: u32) -> Option<u32> {
        (group < self.group_count()).then(|| le_u32(self.group_id, group as usize))
    }

    /// The light group with identifier `id`, if any (linear scan).
    #[must_use]
    pub fn find_group(&self, id: u32) -> Option<u32> {
        (0..self.group_count()).find(|&g| le_u32(self.group_id, g as usize) == id)
    }

    /// Default RGB intensity of light `group`.
    #[must_use]
    pub fn default_intensity(&self, group: u32) -> Option<[f32; 3]> {
        (group < self.group_count()).then(|| {
            let g = group as usize * 3;
            [0, 1, 2].map(|c| le_f32(self.group_intensity, g + c))
        })
    }

    /// Range of member positions of light `group` (for [`HierTable::member`]).
    #[must_use]
    pub fn group_members(&self, group: u32) -> Option<core::ops::Range<u32>> {
        (group < self.group_count())
            .then(|| le_u32(self.group_start, group as usize)..le_u32(self.group_start, group as usize + 1))
    }

    /// Member at `position`: its leaf and its emission at unit intensity.
    #[must_use]
    pub fn member(&self, position: u32) -> Option<HierMember> {
        (position < self.header.member_count).then(|| HierMember {
            leaf: self.index(self.member_leaf, position),
            emission: [0, 1, 2].map(|c| le_f32(self.member_emission, position as usize * 3 + c)),
        })
    }

    /// Number of inner nodes (nodes with children): `node_count - leaf_count`.
    #[must_use]
    pub fn inner_count(&self) -> u32 {
        self.header.node_count - self.header.leaf_count
    }

    /// The slot of `node`: its leaf index for a leaf, `leaf_count` plus its inner index (the inner nodes
    /// before it) for an inner node. Runs are stored in slot order and link receivers are slots.
    #[must_use]
    #[inline]
    pub fn slot(&self, node: u32) -> Option<u32> {
        (node < self.node_count()).then(|| self.slot_unchecked(node))
    }

    /// The node of `slot` (the inverse of [`HierTable::slot`]).
    #[must_use]
    #[inline]
    pub fn slot_node(&self, slot: u32) -> Option<u32> {
        if slot < self.leaf_count() {
            Some(self.index(self.leaf_node, slot))
        } else if slot < self.node_count() {
            Some(self.index(self.inner_node, slot - self.leaf_count()))
        } else {
            None
        }
    }

    /// Range of link positions of sender `node`'s run.
    #[must_use]
    #[inline]
    pub fn run(&self, node: u32) -> Option<core::ops::Range<u32>> {
        let s = self.slot(node)? as usize;
        Some(le_u32(self.run_start, s)..le_u32(self.run_start, s + 1))
    }

    /// Whether sender `node` has links.
    #[must_use]
    #[inline]
    pub fn has_links(&self, node: u32) -> bool {
        self.run(node).is_some_and(|r| r.end > r.start)
    }

    /// Exponent of sender `node`'s run.
    #[must_use]
    pub fn run_exponent(&self, node: u32) -> Option<u8> {
        let s = self.slot(node)? as usize;
        Some(self.run_exponent.get(s).copied().unwrap_or(0))
    }

    /// Receiver node and decoded shooter form factor `F_sender->receiver` of link `position` in `sender`'s run.
    #[must_use]
    pub fn link(&self, sender: u32, position: u32) -> Option<(u32, Frac)> {
        let e = self.run_exponent(sender)?;
        if position >= self.link_count() {
            return None;
        }
        let receiver = self.slot_node(self.index(self.link_receiver, position))?;
        Some((receiver, self.codec.decode(self.code(position), e)))
    }

    /// Decoded sum of `node`'s run as f32 (for reports).
    #[must_use]
    pub fn run_sum(&self, node: u32) -> Option<f32> {
        let range = self.run(node)?;
        Some(range.filter_map(|k| self.link(node, k)).map(|(_, f)| f.to_f32()).sum())
    }

    /// Whether any leaf has a static base (emission or irradiance code other than 0); without one every
    /// leaf's static radiosity is 0 and the transfer relight skips it.
    #[must_use]
    pub fn has_static_base(&self) -> bool {
        self.static_base
    }

    /// Whether the table carries the optional transfer basis (see [`crate::transfer`]).
    #[must_use]
    pub fn has_transfer(&self) -> bool {
        self.header.transfer
    }

    /// The transfer basis section (per leaf), `None` without one.
    #[must_use]
    pub fn transfer(&self) -> Option<TransferSection<'a>> {
        self.has_transfer().then(|| {
            TransferSection::new(
                self.transfer_exponent,
                self.transfer_code,
                self.leaf_count(),
                self.group_count(),
            )
        })
    }

    /// The receiver and code bytes of the links at table positions `from..end` (empty when the range is empty or
    /// not inside the link sections), with the decoder of the run exponent of the sender in slot `sender`: the
    /// entries [`HierTable::run_view`]'s [`Row::entries_from`] reads for positions inside the sender's run,
    /// without reading the run's bounds again.
    #[must_use]
    #[inline]
    pub(crate) fn link_bytes(&self, sender: u32, from: u32, end: u32) -> (&'a [u8], &'a [u8], RowDecoder) {
        let ib = usize::from(self.header.index_bytes);
        let cb = self.codec.code_bytes();
        let (s, e) = (from as usize, (end as usize).max(from as usize));
        let receivers = self.link_receiver.get(s.saturating_mul(ib)..e.saturating_mul(ib)).unwrap_or(&[]);
        let codes = self.link_code.get(s.saturating_mul(cb)..e.saturating_mul(cb)).unwrap_or(&[]);
        let exponent = self.run_exponent.get(sender as usize).copied().unwrap_or(0);
        (receivers, codes, self.codec.row_decoder(exponent))
    }

    /// The run of the sender in `slot` as table positions `(start, end)` (what [`HierTable::run`] gives for
    /// its node), read with one comparison; for a round's judging of every slot.
    #[must_use]
    #[inline(always)]
    pub(crate) fn run_bounds(&self, slot: u32) -> (u32, u32) {
        pair(self.run_start, slot)
    }

    /// The end of `node`'s subtree, read without `node`'s own range check (0 past the section).
    #[inline(always)]
    pub(crate) fn subtree_end_unchecked(&self, node: u32) -> u32 {
        entry::<4>(self.node_end, node)
    }

    /// The area of `node`, read without `node`'s own range check (0 past the section).
    #[inline(always)]
    pub(crate) fn node_area_unchecked(&self, node: u32) -> f32 {
        f32::from_bits(entry::<4>(self.node_area, node))
    }

    /// The node sections a link's receiver is resolved with, for hierarchical shooting's inner loop.
    #[must_use]
    #[inline]
    pub(crate) fn node_sections(&self) -> NodeSections<'a> {
        NodeSections {
            leaf_start: self.node_leaf_start,
            leaf_parent: self.leaf_parent,
            material: self.leaf_material,
        }
    }

    /// Bytes per node index (2 or 4, checked by parse).
    #[must_use]
    #[inline]
    pub(crate) fn index_bytes(&self) -> u8 {
        self.header.index_bytes
    }

    /// Sender `node`'s run as a [`Row`] whose entries (receiver **slot**, [`HierTable::slot_node`] gives its
    /// node; decoded factor) need no further checks.
    #[must_use]
    #[inline]
    pub fn run_view(&self, node: u32) -> Option<Row<'a>> {
        let range = self.run(node)?;
        let ib = usize::from(self.header.index_bytes);
        let cb = self.codec.code_bytes();
        let (s, e) = (range.start as usize, range.end as usize);
        Some(Row::new(
            self.link_receiver.get(s.checked_mul(ib)?..e.checked_mul(ib)?)?,
            self.link_code.get(s.checked_mul(cb)?..e.checked_mul(cb)?)?,
            ib,
            self.codec,
            self.run_exponent(node).unwrap_or(0),
            range.start,
        ))
    }
}
