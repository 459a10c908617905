//! Hierarchical shooting's inner loops: a run of links applied to their receivers ([`apply_run`]), with the
//! receiver's table sections and the solver's buffers held in locals for the whole run and the entries read at
//! the table's fixed index and code widths; and a round's judging of nodes until one shoots ([`judge`]). The
//! rules are the solver's (module docs of [`hier`](super), "The scheme" and "Rounds").

use super::{add3, magnitude, HierBuffers};
use crate::format::{le, HierTable, NodeSections};
use crate::scalar::Scalar;
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

/// Adds `d` to entry `i` of `buf` (nothing past its end).
#[inline(always)]
fn add_at<S: Scalar>(buf: &mut [[S; 3]], i: usize, d: [S; 3]) {
    if let Some(v) = buf.get_mut(i) {
        *v = add3(*v, d);
    }
}

impl<S: Scalar> Targets<'_, '_, S> {
    /// Applies the entries of `receivers` and `codes` (widths `IB` and `CB` bytes).
    #[inline(always)]
    fn run<const IB: usize, const CB: usize>(
        &mut self,
        receivers: &[u8],
        codes: &[u8],
        decoder: S::LinkDecoder,
        power: [S; 3],
    ) {
        let (receivers, _) = receivers.as_chunks::<IB>();
        let (codes, _) = codes.as_chunks::<CB>();
        // The products' path chosen once per run: codes read at the codec's width need no clamp, and the
        // shooter's power and the row's shifts decide once whether fixed point's products can skip their checks.
        if S::link_fast(&decoder, &power) {
            for (r, c) in receivers.iter().zip(codes) {
                self.link::<IB>(le::<IB>(r), S::link_products_fast(power, le::<CB>(c), decoder));
            }
        } else {
            for (r, c) in receivers.iter().zip(codes) {
                self.link::<IB>(le::<IB>(r), S::link_products(power, le::<CB>(c), decoder));
            }
        }
    }

    /// Link `(r, F)` delivers the power `x = F U_s` to node `r`. An inner receiver adds it to its pending
    /// power (spread over its subtree by the next sweep). A leaf takes it at once: into its incident power, and the
    /// reflected `rho_l F U_s` into its own unshot power and, pending for the rest of its chain, into its
    /// parent's reflected entry.
    #[inline(always)]
    fn link<const IB: usize>(&mut self, r: u32, x: [S; 3]) {
        let n = &self.nodes;
        let (l, next) = n.leaf_starts(r);
        if next == l {
            add_at(self.pending, r.wrapping_sub(l) as usize, x);
            return;
        }
        let m = n.material(l) as usize;
        let rho = cached_rho::<S>(self.rho_cache, self.reflectance, m);
        let reflected = [x[0].mul_rho(rho[0]), x[1].mul_rho(rho[1]), x[2].mul_rho(rho[2])];
        add_at(self.incident, l as usize, x);
        add_at(self.unshot, r as usize, reflected);
        let p = n.parent::<IB>(r);
        if p != r {
            add_at(self.reflected, p.wrapping_sub(n.leaf_start(p)) as usize, reflected);
        }
    }
}

/// Applies the links at table positions `from..end` of `sender`'s run, each delivering `F power` to its
/// receiver (the solver's link rule), in one loop specialized for the table's index and code widths. Not
/// inlined: called once per shot (or budget), it keeps the stepping loop small.
#[inline(never)]
pub(super) fn apply_run<S: Scalar>(
    table: &HierTable<'_>,
    buf: &mut HierBuffers<'_, S>,
    rho_cache: &[[S::Rho; 3]; RHO_CACHE],
    (sender, from, end): (u32, u32, u32),
    power: [S; 3],
) {
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
    match (table.index_bytes(), table.codec().code_bytes()) {
        (2, 1) => t.run::<2, 1>(receivers, codes, decoder, power),
        (2, 2) => t.run::<2, 2>(receivers, codes, decoder, power),
        (4, 1) => t.run::<4, 1>(receivers, codes, decoder, power),
        (4, 2) => t.run::<4, 2>(receivers, codes, decoder, power),
        // Parse accepts no other widths.
        _ => {}
    }
}

/// Judges the nodes `from..stop` of a round in order, one work unit each, until one shoots: a node with links
/// whose unshot magnitude is neither below `threshold` nor within `tolerance` (the round rule, module docs of
/// [`hier`](super), "Rounds"). Returns the nodes judged (the shooter included) and the shooter with its unshot
/// power and its run's table positions, or `None` when none of them shoots.
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
