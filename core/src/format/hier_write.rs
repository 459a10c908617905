//! The hierarchical table writer: quantizes a [`HierSpec`] into a caller's buffer, in the layout
//! [`HierTable::parse`](super::HierTable::parse) reads (`docs/format.md`, "Hierarchical tables").
//!
//! Std-free, no allocation: what the writer derives per node (subtree ends, leaf starts, inner node areas) it
//! computes in place in the output buffer.

use super::hier::{
    check_slots, check_tree, read_index, slot_of, HierHeader, HierSectionSizes, PathSum, MAX_HIER_HEADER_LEN,
};
use super::layout::{le_f32, le_u32};
use super::write::{
    check_groups, check_patches, check_row_offsets, check_transfer, check_value, count, emission_codes,
    quantize_row_into, write_transfer, GroupSpec, Out, PatchSpec, RowsSpec, WriteError, ROW_SUM_SLACK,
};
use super::{TableError, HIER_FORMAT_VERSION, MAGIC};
use crate::codec::{self, f32_to_exact, FfCodec, EXACT_SHIFT};
use crate::crc::crc32;

/// One node of the hierarchy as the writer takes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeSpec {
    /// The parent node (an index below this node's), or `None` for a root.
    pub parent: Option<u32>,
}

/// Everything a hierarchical table holds, as borrowed slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HierSpec<'a> {
    /// The nodes in preorder: every parent before its children and every subtree a contiguous range (a
    /// depth-first order). A node without children is a leaf; the leaves, in node order, are `leaves`.
    pub nodes: &'a [NodeSpec],
    /// The leaves in node order: area, material, static base (as [`PatchSpec`]). An inner node's area is
    /// derived: the sum of its children's.
    pub leaves: &'a [PatchSpec],
    /// Reflectance (RGB, each in `[0, 1)`) per material.
    pub materials: &'a [[f32; 3]],
    /// Light groups; a member's [`MemberSpec::patch`](super::MemberSpec::patch) is a leaf index.
    pub groups: &'a [GroupSpec<'a>],
    /// Links grouped by sender node (CSR over the nodes, `row_start` of length nodes + 1): receiver nodes
    /// strictly increasing within a run, and the shooter factor `F_sender->receiver`: the fraction of the power
    /// leaving the sender's subtree that arrives on the receiver node.
    pub links: RowsSpec<'a>,
    /// Form-factor codec.
    pub codec: FfCodec,
    /// Whether the static base irradiance is the converged static solution (crate docs, "Static base").
    pub base_solved: bool,
    /// Scene fingerprint stored in the header (not interpreted by core).
    pub fingerprint: u64,
    /// Optional transfer basis (see [`crate::transfer`]): the response `T_g` (W/m^2 at unit intensity, RGB,
    /// finite and `>= 0`) of every leaf to every light group, leaf-major: `transfer[leaf * groups + g]`.
    /// Needs `base_solved`.
    pub transfer: Option<&'a [[f32; 3]]>,
}

fn header_of(spec: &HierSpec<'_>) -> Result<HierHeader, WriteError> {
    spec.codec.check().map_err(|_| WriteError::BadCodec)?;
    let node_count = count(spec.nodes.len(), "nodes")?;
    if node_count == u32::MAX {
        return Err(WriteError::TooMany { what: "nodes" });
    }
    if spec.materials.len() > 0x1_0000 {
        return Err(WriteError::TooMany { what: "materials" });
    }
    let member_total = spec.groups.iter().try_fold(0usize, |s, g| s.checked_add(g.members.len()));
    Ok(HierHeader {
        magic: MAGIC,
        version: HIER_FORMAT_VERSION,
        leaf_count: count(spec.leaves.len(), "leaves")?,
        node_count,
        material_count: count(spec.materials.len(), "materials")?,
        group_count: count(spec.groups.len(), "light groups")?,
        member_count: count(member_total.ok_or(WriteError::TooMany { what: "members" })?, "members")?,
        link_count: count(spec.links.receiver.len(), "links")?,
        ff_bits: spec.codec.bits,
        ff_exponent_bits: spec.codec.exponent_bits,
        index_bytes: if node_count <= 0x1_0000 { 2 } else { 4 },
        base_solved: spec.base_solved,
        fingerprint: spec.fingerprint,
        transfer: spec.transfer.is_some(),
    })
}

fn header_bytes(h: &HierHeader, buf: &mut [u8; MAX_HIER_HEADER_LEN]) -> Result<usize, WriteError> {
    postcard::to_slice(h, buf).map(|s| s.len()).map_err(|_| WriteError::TooMany { what: "header bytes" })
}

fn sizes_of(spec: &HierSpec<'_>) -> Result<(HierHeader, HierSectionSizes), WriteError> {
    let h = header_of(spec)?;
    let mut hb = [0u8; MAX_HIER_HEADER_LEN];
    let hl = header_bytes(&h, &mut hb)?;
    let sizes = HierSectionSizes::of_header(&h, hl).ok_or(WriteError::TooMany { what: "bytes" })?;
    Ok((h, sizes))
}

/// Bytes [`write_hier_table`] needs for `spec`.
///
/// # Errors
/// [`WriteError::TooMany`] or [`WriteError::BadCodec`] if the counts or codec do not fit the format.
pub fn hier_required_len(spec: &HierSpec<'_>) -> Result<usize, WriteError> {
    sizes_of(spec).map(|(_, s)| s.total())
}

/// The parent of node `k` in `spec`, `k` itself for a root (the stored convention).
fn parent_of(spec: &HierSpec<'_>, k: u32) -> u32 {
    spec.nodes.get(k as usize).and_then(|n| n.parent).unwrap_or(k)
}

fn read_u32(buf: &[u8], at: usize, i: u32) -> u32 {
    le_u32(buf.get(at..).unwrap_or(&[]), i as usize)
}

fn write_u32(buf: &mut [u8], at: usize, i: u32, v: u32) {
    let p = at + 4 * i as usize;
    if let Some(d) = buf.get_mut(p..p + 4) {
        d.copy_from_slice(&v.to_le_bytes());
    }
}

/// Validates `spec`, quantizes it and writes the hierarchical table into `out`; returns the bytes written.
///
/// Each sender's run is quantized with `spec.codec` by the row rounding of [`crate::codec`], against a target
/// capped so that the decoded sums along every leaf's chain stay `<= 1` (the bound
/// [`HierTable::parse`](super::HierTable::parse) checks): nodes are visited in preorder and a run's target
/// is `min(its true sum, 1 - the decoded sums of its ancestors' runs)`. The runs are stored in slot order and
/// their receivers as slots, each run's leaf receivers first (in the spec's order), then its inner ones.
///
/// # Errors
/// A [`WriteError`] naming the first bad field, or [`WriteError::BufferTooSmall`].
pub fn write_hier_table(spec: &HierSpec<'_>, out: &mut [u8]) -> Result<usize, WriteError> {
    let (h, sizes) = sizes_of(spec)?;
    let needed = sizes.total();
    if out.len() < needed {
        return Err(WriteError::BufferTooSmall { needed, got: out.len() });
    }
    let nn = spec.nodes.len();
    let n = spec.leaves.len();
    for (k, node) in spec.nodes.iter().enumerate() {
        if node.parent.is_some_and(|p| p as usize >= k) {
            return Err(WriteError::BadTree { node: k });
        }
    }
    let links = spec.links;
    check_row_offsets(&links, nn)?;
    check_patches(spec.leaves, spec.materials, true)?;
    check_groups(spec.groups, n, |_, _| Ok(()))?;
    check_transfer(spec.transfer, n, spec.groups.len(), spec.base_solved)?;
    for j in 0..nn {
        let (s, e) = (links.row_start[j] as usize, links.row_start[j + 1] as usize);
        for k in s..e {
            let (r, f) = (links.receiver[k], links.form_factor[k]);
            if r as usize >= nn {
                return Err(WriteError::IndexOutOfRange { what: "link receiver", position: k, index: r });
            }
            if k > s && links.receiver[k - 1] >= r {
                return Err(WriteError::UnsortedRow { row: j });
            }
            check_value("form factor", k, f, f.is_finite() && (0.0..=1.0).contains(&f))?;
        }
    }

    let mut hb = [0u8; MAX_HIER_HEADER_LEN];
    let hl = header_bytes(&h, &mut hb)?;
    let ib = h.index_bytes;
    let mut o = Out { buf: out, at: 0 };
    o.bytes(hb.get(..hl).unwrap_or(&[]));
    for leaf in spec.leaves {
        o.u16(leaf.material as u16);
    }
    for (k, leaf) in spec.leaves.iter().enumerate() {
        for c in emission_codes("leaf base emission", k, leaf.base_emission)? {
            o.u16(c);
        }
    }
    for (k, leaf) in spec.leaves.iter().enumerate() {
        for c in emission_codes("leaf base irradiance", k, leaf.base_irradiance)? {
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
            o.index(m.patch, ib);
        }
    }
    for g in spec.groups {
        for m in g.members {
            for c in m.emission {
                o.bytes(&c.to_le_bytes());
            }
        }
    }
    let parent_at = o.at;
    for k in 0..nn as u32 {
        o.index(parent_of(spec, k), ib);
    }
    // Subtree ends: children come after their parents, so a backward pass sees a node's whole subtree
    // before the node itself.
    let end_at = o.at;
    for k in 0..nn as u32 {
        o.u32(k + 1);
    }
    for k in (0..nn as u32).rev() {
        let p = parent_of(spec, k);
        if p != k {
            let e = read_u32(o.buf, end_at, k).max(read_u32(o.buf, end_at, p));
            write_u32(o.buf, end_at, p, e);
        }
    }
    // Leaf starts and the leaf-node map, forward (writes past the leaf count are dropped; check_tree reports
    // the count).
    let leaf_start_at = o.at;
    let area_at = leaf_start_at + 4 * (nn + 1);
    let leaf_node_at = area_at + 4 * nn;
    let mut leaves = 0u32;
    for k in 0..nn as u32 {
        write_u32(o.buf, leaf_start_at, k, leaves);
        if read_u32(o.buf, end_at, k) == k + 1 {
            if (leaves as usize) < n {
                let p = leaf_node_at + usize::from(ib) * leaves as usize;
                let bytes = k.to_le_bytes();
                if let Some(d) = o.buf.get_mut(p..p + usize::from(ib)) {
                    d.copy_from_slice(bytes.get(..usize::from(ib)).unwrap_or(&[]));
                }
            }
            leaves += 1;
        }
    }
    write_u32(o.buf, leaf_start_at, nn as u32, leaves);
    if leaves as usize != n {
        return Err(WriteError::LeafCount { tree: leaves as usize, given: n });
    }
    let tree = {
        let buf = &*o.buf;
        check_tree(
            nn as u32,
            n as u32,
            |k| read_index(buf.get(parent_at..).unwrap_or(&[]), ib, k),
            |k| read_u32(buf, end_at, k),
            |k| read_u32(buf, leaf_start_at, k),
            |l| read_index(buf.get(leaf_node_at..).unwrap_or(&[]), ib, l),
        )
    };
    match tree {
        Ok(()) => {}
        Err(TableError::BadTree { node, .. }) => return Err(WriteError::BadTree { node: node as usize }),
        Err(_) => return Err(WriteError::BadTree { node: nn }),
    }
    // Areas: leaves as given, inner nodes the f32 sum of their children (backward again, from zero).
    for k in 0..nn as u32 {
        write_u32(o.buf, area_at, k, 0);
    }
    let area = |buf: &[u8], k: u32| le_f32(buf.get(area_at..).unwrap_or(&[]), k as usize);
    let mut leaf = n;
    for k in (0..nn as u32).rev() {
        if read_u32(o.buf, end_at, k) == k + 1 {
            leaf = leaf.saturating_sub(1);
            let a = spec.leaves.get(leaf).map_or(0.0, |l| l.area);
            write_u32(o.buf, area_at, k, a.to_bits());
        }
        let p = parent_of(spec, k);
        if p != k {
            let sum = area(o.buf, p) + area(o.buf, k);
            write_u32(o.buf, area_at, p, sum.to_bits());
        }
    }
    o.at = leaf_node_at + usize::from(ib) * n;
    let is_leaf = |buf: &[u8], k: u32| read_u32(buf, end_at, k) == k + 1;
    let slot = |buf: &[u8], k: u32| slot_of(k, read_u32(buf, leaf_start_at, k), is_leaf(buf, k), n as u32);
    // Each leaf's parent as an inner index (the inner count for a root leaf), then the inner nodes.
    let leaf_parent_at = o.at;
    for k in 0..nn as u32 {
        if is_leaf(o.buf, k) {
            let p = parent_of(spec, k);
            let v = if p == k { (nn - n) as u32 } else { slot(o.buf, p) - n as u32 };
            o.index(v, ib);
        }
    }
    let inner_node_at = o.at;
    for k in 0..nn as u32 {
        if !is_leaf(o.buf, k) {
            o.index(k, ib);
        }
    }
    let slots = {
        let buf = &*o.buf;
        check_slots(
            nn as u32,
            n as u32,
            |k| read_index(buf.get(parent_at..).unwrap_or(&[]), ib, k),
            |k| read_u32(buf, end_at, k),
            |k| read_u32(buf, leaf_start_at, k),
            |l| read_index(buf.get(leaf_parent_at..).unwrap_or(&[]), ib, l),
            |i| read_index(buf.get(inner_node_at..).unwrap_or(&[]), ib, i),
        )
    };
    if slots.is_err() {
        return Err(WriteError::BadTree { node: nn });
    }

    // The chain bound on the true factors, before quantizing.
    let one = 1u128 << EXACT_SHIFT;
    let true_sum = |j: u32| -> Result<u128, WriteError> {
        let (s, e) = (links.row_start[j as usize] as usize, links.row_start[j as usize + 1] as usize);
        Ok(links.form_factor[s..e].iter().fold(0u128, |acc, &v| acc.saturating_add(f32_to_exact(v))))
    };
    let mut path = PathSum::default();
    let mut leaf = 0usize;
    for k in 0..nn as u32 {
        path.pop_to_parent_of(k, |j| parent_of(spec, j), true_sum)?;
        path.push(k, true_sum(k)?);
        if read_u32(o.buf, end_at, k) == k + 1 {
            if path.sum > f32_to_exact(1.0 + ROW_SUM_SLACK) {
                return Err(WriteError::ChainSumExceedsOne { leaf });
            }
            leaf += 1;
        }
    }

    // Run starts in slot order: the leaves' runs, then the inner nodes'.
    let run_at = o.at;
    let len = |k: u32| links.row_start[k as usize + 1] - links.row_start[k as usize];
    let mut start = 0u32;
    o.u32(0);
    for leaves_first in [true, false] {
        for k in 0..nn as u32 {
            if is_leaf(o.buf, k) == leaves_first {
                start += len(k);
                o.u32(start);
            }
        }
    }
    let exps_at = o.at;
    o.at += nn;
    let receivers_at = o.at;
    o.at += usize::from(ib) * links.receiver.len();
    let codes_at = o.at;
    let codec = spec.codec;
    let cb = codec.code_bytes();
    // Where node `k`'s run starts in the link sections, and its slot.
    let placed = |buf: &[u8], k: u32| {
        let s = slot(buf, k);
        (read_u32(buf, run_at, s) as usize, s as usize)
    };
    // Decoded sum of a run already written (its exponent and codes are in the buffer).
    let decoded = |buf: &[u8], j: u32| -> Result<u128, WriteError> {
        let (p, sj) = placed(buf, j);
        let e = buf.get(exps_at + sj).copied().unwrap_or(0);
        let mut sum = 0u128;
        for k in p..p + len(j) as usize {
            let code = match buf.get(codes_at + k * cb..codes_at + (k + 1) * cb) {
                Some(&[a]) => u16::from(a),
                Some(&[a, b]) => u16::from_le_bytes([a, b]),
                _ => 0,
            };
            sum = sum.saturating_add(codec.decode(code, e).to_exact());
        }
        Ok(sum)
    };
    let mut path = PathSum::default();
    for k in 0..nn as u32 {
        path.pop_to_parent_of(k, |j| parent_of(spec, j), |j| decoded(o.buf, j))?;
        let (s, e) = (links.row_start[k as usize] as usize, links.row_start[k as usize + 1] as usize);
        let (p, sk) = placed(o.buf, k);
        let target = true_sum(k)?.min(one.saturating_sub(path.sum));
        let at = codes_at + p * cb;
        let exponent =
            quantize_row_into(codec, &links.form_factor[s..e], &links.receiver[s..e], k, target, &mut o, at);
        if let Some(b) = o.buf.get_mut(exps_at + sk) {
            *b = exponent;
        }
        // Receivers as slots, leaves first; the codes (written in the spec's order) moved along, stably.
        let receivers = &links.receiver[s..e];
        let mut w = 0usize;
        for (j, &r) in receivers.iter().enumerate() {
            if is_leaf(o.buf, r) {
                if let Some(run) = o.buf.get_mut(at + w * cb..at + (j + 1) * cb) {
                    run.rotate_right(cb);
                }
                w += 1;
            }
        }
        let mut q = receivers_at + usize::from(ib) * p;
        for leaves_first in [true, false] {
            for &r in receivers {
                if is_leaf(o.buf, r) != leaves_first {
                    continue;
                }
                let v = slot(o.buf, r).to_le_bytes();
                if let Some(d) = o.buf.get_mut(q..q + usize::from(ib)) {
                    d.copy_from_slice(v.get(..usize::from(ib)).unwrap_or(&[]));
                }
                q += usize::from(ib);
            }
        }
        path.push(k, decoded(o.buf, k)?);
    }
    o.at = codes_at + links.receiver.len() * cb;
    if let Some(t) = spec.transfer {
        write_transfer(t, spec.groups.len(), &mut o);
    }
    let crc = crc32(o.buf.get(..o.at).unwrap_or(&[]));
    o.u32(crc);
    Ok(o.at)
}
