//! Hierarchical shooting's inner loops: a run of links applied to their receivers ([`apply_run`]), with the
//! receiver's table sections and the solver's buffers held in locals for the whole run and the entries read at
//! the table's fixed index and code widths; and a round's judging of slots until one shoots ([`judge`]). The
//! rules are the solver's (module docs of [`hier`](super), "The scheme" and "Rounds").
//!
//! Receivers are slots (`docs/format.md`, "Hierarchical tables"): leaves below the leaf count, inner nodes
//! above it, and a run lists its leaf receivers first. So a run is applied as two loops without a per-link
//! test: its leaves (each link indexes the per-leaf buffers and its parent's entry directly), then its inner
//! nodes (each link indexes the per-inner-node buffer).

use super::{magnitude, HierBuffers};
use crate::format::{le, HierTable, NodeSections};
use crate::scalar::{Scalar, OUT_OF_RANGE};
use crate::solver::RHO_CACHE;

/// What a link writes to: the receiver's table sections and the solver's buffers, borrowed for one run.
struct Targets<'s, 'a, S: Scalar> {
    nodes: NodeSections<'a>,
    incident: &'s mut [[S; 3]],
    unshot: &'s mut [[S; 3]],
    pending: &'s mut [[S; 3]],
    reflected: &'s mut [[S; 3]],
    reflectance: &'s [[u16; 3]],
    rho_cache: &'s [[S::Rho; 3]; RHO_CACHE],
}

/// Material `m`'s reflectance decoded for products (`mul_rho`, bit for bit `mul_frac` of the decoded code):
/// from the cache, or decoded from `codes` for a material beyond it.
#[inline(always)]
pub(super) fn cached_rho<S: Scalar>(
    cache: &[[S::Rho; 3]; RHO_CACHE],
    codes: &[[u16; 3]],
    m: usize,
) -> [S::Rho; 3] {
    match cache.get(m) {
        Some(r) => *r,
        None => codes.get(m).copied().unwrap_or([0; 3]).map(S::rho),
    }
}

/// A run's arithmetic, chosen once per run: `FAST`, the products of fixed point's fast path (no per-product
/// checks, sums that wrap and flag instead of saturating, module docs of [`hier`](super), "Range"), else the
/// checked products and saturating sums; `SMALL` (with `FAST`), reflectance products without their check. f32
/// computes the same either way.
#[derive(Clone, Copy)]
struct Arith<const FAST: bool, const SMALL: bool>;

impl<const FAST: bool, const SMALL: bool> Arith<FAST, SMALL> {
    #[inline(always)]
    fn factor<S: Scalar>(code: u32, d: S::LinkDecoder) -> S::LinkFactor {
        if FAST {
            S::link_factor_fast(code, d)
        } else {
            S::link_factor(code, d)
        }
    }
    #[inline(always)]
    fn product<S: Scalar>(p: S, f: S::LinkFactor) -> S {
        if FAST {
            p.link_product_fast(f)
        } else {
            p.link_product(f)
        }
    }
    #[inline(always)]
    fn reflect<S: Scalar>(x: S, rho: S::Rho) -> S {
        if FAST && SMALL {
            x.mul_rho_small(rho)
        } else {
            x.mul_rho(rho)
        }
    }
    #[inline(always)]
    fn add<S: Scalar>(a: S, b: S, flag: &mut u32) -> S {
        if FAST {
            a.add_flagged(b, flag)
        } else {
            a.add(b)
        }
    }
}

impl<S: Scalar> Targets<'_, '_, S> {
    /// Applies the entries of `receivers` and `codes` (widths `IB` and `CB` bytes; receivers are slots, those
    /// below `leaves` first). Returns whether every sum stayed in range (module docs of [`hier`](super),
    /// "Range").
    #[inline(always)]
    fn run<const IB: usize, const CB: usize>(
        &mut self,
        receivers: &[u8],
        codes: &[u8],
        decoder: S::LinkDecoder,
        power: [S; 3],
        leaves: u32,
    ) -> bool {
        let (receivers, _) = receivers.as_chunks::<IB>();
        let (codes, _) = codes.as_chunks::<CB>();
        // Parse checked that a run's receivers increase, so its leaves are a prefix.
        let split = receivers.partition_point(|r| le::<IB>(r) < leaves);
        let (leaf_r, inner_r) = receivers.split_at(split);
        let (leaf_c, inner_c) = codes.split_at(split.min(codes.len()));
        // The products' path chosen once per run: codes read at the codec's width need no clamp, and the
        // shooter's power and the row's shifts decide once whether fixed point's products can skip their checks.
        // Likewise whether every product is small enough for fixed point's reflectance product to skip its check.
        // The fast products are below 2^61 raw in magnitude (powers below 2^49, factors below 2^12), and so are
        // their reflected parts: fixed point's sums wrap and flag instead of saturating.
        let mut flag = 0u32;
        let shot = (power, decoder);
        if S::link_fast(&decoder, &power) {
            if S::link_products_small(&decoder, &power) {
                self.leaf_links::<IB, CB, true, true>(leaf_r, leaf_c, leaves, shot, &mut flag);
            } else {
                self.leaf_links::<IB, CB, true, false>(leaf_r, leaf_c, leaves, shot, &mut flag);
            }
            self.inner_links::<IB, CB, true>(inner_r, inner_c, leaves, shot, &mut flag);
        } else {
            self.leaf_links::<IB, CB, false, false>(leaf_r, leaf_c, leaves, shot, &mut flag);
            self.inner_links::<IB, CB, false>(inner_r, inner_c, leaves, shot, &mut flag);
        }
        flag & OUT_OF_RANGE == 0
    }

    /// Links to inner nodes (receiver slots from `leaves` on): each adds `F U_s` (the shot's power times the
    /// code's factor) to its receiver's pending power, spread over its subtree by the next sweep.
    #[inline(always)]
    fn inner_links<const IB: usize, const CB: usize, const FAST: bool>(
        &mut self,
        receivers: &[[u8; IB]],
        codes: &[[u8; CB]],
        leaves: u32,
        (power, decoder): ([S; 3], S::LinkDecoder),
        flag: &mut u32,
    ) {
        for (r, c) in receivers.iter().zip(codes) {
            let f = Arith::<FAST, false>::factor::<S>(le::<CB>(c), decoder);
            if let Some(v) = self.pending.get_mut(le::<IB>(r).wrapping_sub(leaves) as usize) {
                for (v, p) in v.iter_mut().zip(power) {
                    *v = Arith::<FAST, false>::add(*v, Arith::<FAST, false>::product(p, f), flag);
                }
            }
        }
    }

    /// Links to leaves (receiver slots below `leaves`, each with its code): link `(l, F)` delivers the power
    /// `x = F U_s` (the shot's power times the code's factor) into leaf `l`'s incident power, and the reflected
    /// `rho_l F U_s` into its own unshot power and, pending for the rest of its chain, into its parent's
    /// reflected entry (a root leaf's parent index is the inner count, past the buffer: nothing). A link to
    /// an inner node adds `x` to its pending power instead ([`Targets::inner_links`]).
    ///
    /// Channel by channel, so that a channel's product, its reflected part and the three sums are all a link
    /// holds in registers at a time. A run's leaves are in leaf order, so neighbours mostly share a material:
    /// the reflectance is held while the material stays the same.
    #[inline(always)]
    fn leaf_links<const IB: usize, const CB: usize, const FAST: bool, const SMALL: bool>(
        &mut self,
        receivers: &[[u8; IB]],
        codes: &[[u8; CB]],
        leaves: u32,
        (power, decoder): ([S; 3], S::LinkDecoder),
        flag: &mut u32,
    ) {
        let n = leaves as usize;
        let (Some(incident), Some(unshot), Some(materials), Some(parents)) = (
            self.incident.get_mut(..n),
            self.unshot.get_mut(..n),
            self.nodes.materials().get(..n),
            self.nodes.leaf_parents::<IB>().get(..n),
        ) else {
            // Parse and the solver's buffer check make every one of them hold the leaves.
            return;
        };
        let mut material = u32::MAX;
        let mut rho = [S::Rho::default(); 3];
        for (r, c) in receivers.iter().zip(codes) {
            let l = le::<IB>(r) as usize;
            let (Some(h), Some(u), Some(m), Some(p)) =
                (incident.get_mut(l), unshot.get_mut(l), materials.get(l), parents.get(l))
            else {
                continue;
            };
            let f = Arith::<FAST, SMALL>::factor::<S>(le::<CB>(c), decoder);
            let m = le::<2>(m);
            if m != material {
                material = m;
                rho = cached_rho::<S>(self.rho_cache, self.reflectance, m as usize);
            }
            let channel = |c: usize, h: &mut S, u: &mut S, flag: &mut u32| {
                let x = Arith::<FAST, SMALL>::product(power[c], f);
                let y = Arith::<FAST, SMALL>::reflect::<S>(x, rho[c]);
                *h = Arith::<FAST, SMALL>::add(*h, x, flag);
                *u = Arith::<FAST, SMALL>::add(*u, y, flag);
                y
            };
            if let Some(up) = self.reflected.get_mut(le::<IB>(p) as usize) {
                for c in 0..3 {
                    let y = channel(c, &mut h[c], &mut u[c], flag);
                    up[c] = Arith::<FAST, SMALL>::add(up[c], y, flag);
                }
            } else {
                for c in 0..3 {
                    let _ = channel(c, &mut h[c], &mut u[c], flag);
                }
            }
        }
    }
}

/// Applies the links at table positions `from..end` of the run of the sender in slot `sender`, each delivering
/// `F power` to its receiver (the solver's link rule), in loops specialized for the table's index and code
/// widths. Not inlined: called once per shot (or budget), it keeps the stepping loop small. Returns whether
/// every sum stayed in range (module docs of [`hier`](super), "Range"); if not, the buffers hold wrapped
/// values.
#[inline(never)]
pub(super) fn apply_run<S: Scalar>(
    table: &HierTable<'_>,
    buf: &mut HierBuffers<'_, S>,
    rho_cache: &[[S::Rho; 3]; RHO_CACHE],
    (sender, from, end): (u32, u32, u32),
    power: [S; 3],
) -> bool {
    let (receivers, codes, row) = table.link_bytes(sender, from, end);
    let decoder = S::link_decoder(row);
    let mut t = Targets {
        nodes: table.node_sections(),
        incident: &mut *buf.incident,
        unshot: &mut *buf.unshot,
        pending: &mut *buf.pending,
        reflected: &mut *buf.reflected,
        reflectance: &*buf.reflectance,
        rho_cache,
    };
    let leaves = table.leaf_count();
    match (table.index_bytes(), table.codec().code_bytes()) {
        (2, 1) => t.run::<2, 1>(receivers, codes, decoder, power, leaves),
        (2, 2) => t.run::<2, 2>(receivers, codes, decoder, power, leaves),
        (4, 1) => t.run::<4, 1>(receivers, codes, decoder, power, leaves),
        (4, 2) => t.run::<4, 2>(receivers, codes, decoder, power, leaves),
        // Parse accepts no other widths.
        _ => true,
    }
}

/// Judges the slots `from..stop` of a round in order, one work unit each, until one shoots: a node with links
/// whose unshot magnitude is neither below `threshold` nor within `tolerance` (the round rule, module docs of
/// [`hier`](super), "Rounds"). Returns the slots judged (the shooter included) and the shooter's slot with its
/// unshot power and its run's table positions, or `None` when none of them shoots.
#[allow(clippy::type_complexity)]
pub(super) fn judge<S: Scalar>(
    table: &HierTable<'_>,
    unshot: &[[S; 3]],
    (from, stop): (u32, u32),
    threshold: S,
    tolerance: S,
) -> (u32, Option<(u32, [S; 3], core::ops::Range<u32>)>) {
    let mut k = from;
    while k < stop {
        let node = k;
        k += 1;
        let (start, end) = table.run_bounds(node);
        if end <= start {
            continue;
        }
        let u = unshot.get(node as usize).copied().unwrap_or([S::ZERO; 3]);
        let m = magnitude(u);
        if m < threshold || m <= tolerance {
            continue;
        }
        return (k - from, Some((node, u, start..end)));
    }
    (k - from, None)
}
