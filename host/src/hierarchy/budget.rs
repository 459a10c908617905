//! Per-element error budgets. A leaf gathers through the links of all its ancestors, so the oracle charges every
//! leaf with what each link on its chain may get wrong there, and refines the links of largest charge on every
//! chain whose total exceeds the leaf's budget, until each leaf is within budget or nothing on its chain can be
//! split (the resolution or node limit).
//!
//! A link `(r, s)` charges a leaf `l` under `r` (in reflected radiosity, W/m^2, largest channel):
//! - a **receiver-side** part, for `r` a strict ancestor of `l` (the link's average form factor `f_rs` pushed down
//!   to `l`): `rho_l * B_s * |v K(l, s) - f_rs|`, with `K` the point kernel from `l`'s centroid to `s`'s polygon
//!   and `v` the link's visible fraction; where visibility is partial, `l` may lie anywhere across the shadow
//!   edge, so `rho_l * B_s * max(v, 1 - v) K` is added; where the rays saw all or nothing, `rho_l * B_s * K / n`
//!   (the fraction's resolution with `n` rays; 0 where a clear shaft made it exact) counts as random and adds in
//!   quadrature. Such deviations average
//!   out over `r` but not over a leaf: a leaf in a corner sees every far surface at a grazing angle, so it
//!   inherits an overestimate from each ancestor's links, and in a closed scene the leaves' total form factors
//!   then stray from 1, which interreflection amplifies (the white furnace comes out bright).
//! - a **sender-side** part, `rho_r * (A_s / A_r) * spread_sr * sigma_s`: the link carries the area average of
//!   `B` over `s`, while `r` weighs the parts of `s` by `F(y, r)`; the difference is their covariance over `s`,
//!   at most `A_s * spread_sr * sigma_s` (`|F(y, r) - f_sr| <= spread_sr`, `sigma_s` the area-weighted standard
//!   deviation of the leaves' `B` under `s`). It does not cancel over a face: the bright parts of a sender are
//!   the ones nearer the light, and they see the rest of the scene better, so links at coarse senders
//!   under-deliver everywhere (without this term the Cornell box's ceiling comes out dark).
//!
//! The receiver-side deviations `rho_l * B_s * (v K(l, s) - f_rs)` of one chain are added with their signs (their
//! sum's magnitude is charged): a leaf near a corner sees the near wall better and the far ones worse than its
//! ancestors on average, and its total stays near theirs. The shadow-edge and cluster bounds, which have no known
//! sign, add up as they are.
//!
//! A leaf's budget is `epsilon` times its reflected radiosity `B - E`, plus a floor of `epsilon` times
//! [`FLOOR_FRACTION`] of the scene's area-mean reflected radiosity (so that leaves in shadow do not refine without
//! end).

use rayon::prelude::*;

use super::link::{can_split, split_either, Estimator, Limits, Link, RefineCounts};
use super::pieces::refine;
use super::span::Span;
use super::tree::{Tree, NONE};
use super::HierarchyError;
use crate::formfactor::point_to_polygon;
use crate::raycast::RayCaster;
use crate::rgb::max_channel;

/// The budget floor's share of the scene's area-mean reflected radiosity.
pub(super) const FLOOR_FRACTION: f64 = 0.01;

/// The share of a leaf's budget below which a link's receiver-side bound is charged as it is.
const NEGLIGIBLE: f64 = 1e-3;

/// Most refinement rounds of one budget pass.
const MAX_ROUNDS: usize = 64;

/// The sender-side part of `link` at each end: `rho_r * (A_s / A_r) * spread_sr * sigma_s` for receiver `r`
/// and sender `s` (zero when `s` is a leaf: its radiosity is one value).
pub(super) fn systematic(tree: &Tree, spans: &[Span], link: &Link) -> (f64, f64) {
    let one = |r: u32, s: u32, spread_sr: f64| {
        let (nr, ns) = (&tree.nodes[r as usize], &tree.nodes[s as usize]);
        if ns.children.is_empty() {
            return 0.0;
        }
        max_channel(nr.rho_max * spans[s as usize].deviation()) * spread_sr * ns.area / nr.area
    };
    (one(link.a, link.b, link.spread_ba), one(link.b, link.a, link.spread_ab))
}

/// The receiver-side deviation estimate of `link` (held at a strict ancestor of `leaf`, which receives at
/// `receiver`) at the leaf, in reflected radiosity, as a signed part, a bound and a random part ([`Local`]): with the point kernel
/// `K` from the leaf's centroid to the sender's polygon, `rho * B_s * |v K - f_rs|` (what pushing the link's
/// average down to the leaf misses) plus, where the link's visibility is partial, `rho * B_s * max(v, 1 - v) K`
/// (the leaf may lie anywhere across the shadow edge); where the rays saw all or nothing, `rho * B_s * K / n` as
/// the random part (the fraction's resolution with `n` rays, the link's `sigma`; 0 for a clear shaft). With a cluster at either end, the bound
/// `rho * B_s * spread_rs`.
fn local(tree: &Tree, spans: &[Span], link: &Link, receiver: u32, leaf: u32) -> Local {
    let (s, f_rs, spread_rs) = if link.a == receiver {
        (link.b, link.f_ab, link.spread_ab)
    } else {
        (link.a, link.f_ba, link.spread_ba)
    };
    let (nl, ns) = (&tree.nodes[leaf as usize], &tree.nodes[s as usize]);
    let scale = max_channel(nl.rho_max * spans[s as usize].mean);
    match (nl.element(), ns.element(), tree.is_cluster(receiver)) {
        (Some(el), Some(es), false) => {
            let (pl, ps) = (el.patch(), es.patch());
            let k = point_to_polygon(pl.centroid, pl.normal, &ps.vertices, ps.normal);
            let v = link.visible;
            let (mut bound, mut random) = (0.0, 0.0);
            if v > 0.0 && v < 1.0 {
                bound = v.max(1.0 - v) * k;
            } else {
                random = k * link.sigma;
            }
            Local { signed: scale * (v * k - f_rs), bound: scale * bound, random: scale * random }
        }
        _ => Local { signed: 0.0, bound: scale * spread_rs, random: 0.0 },
    }
}

/// A receiver-side charge ([`local`]) in its three parts, in reflected radiosity.
struct Local {
    /// What pushing the link's average down misses at the leaf, `rho * B_s * (v K - f_rs)`, with its sign: the
    /// deviations of the links on one chain partly cancel (a leaf near a corner sees the near wall better and
    /// the far ones worse than its ancestors do, and its total stays near theirs), so a chain adds them signed.
    signed: f64,
    /// What has no known sign and adds up: the leaf's unknown place across a shadow edge, or a cluster's bound.
    bound: f64,
    /// The random part (the visible fraction's resolution), added in quadrature.
    random: f64,
}

/// The random part of a link held at the leaf itself: `rho * B_s * u * sigma_v`, with `u` the unoccluded form
/// factor and `sigma_v` the visible fraction's standard error, `sqrt(v (1 - v) / n)`, or its resolution `1 / n`
/// where the rays saw all or nothing, or 0 where a clear shaft made it exact (the link's `sigma`: what the form-factor estimate itself may get wrong; the variation within
/// the leaf is the mesh's, not the hierarchy's).
fn own_noise(tree: &Tree, spans: &[Span], link: &Link, leaf: u32) -> f64 {
    let (s, u) = if link.a == leaf {
        (link.b, link.unoccluded_ab)
    } else {
        (link.a, link.unoccluded_ab * tree.nodes[link.a as usize].area / tree.nodes[link.b as usize].area)
    };
    if tree.is_cluster(link.a) || tree.is_cluster(link.b) {
        return 0.0;
    }
    max_channel(tree.nodes[leaf as usize].rho_max * spans[s as usize].mean) * u * link.sigma
}

/// The charges on one leaf's chain: the total (deterministic parts added, random parts in quadrature), and every
/// splittable link's charge (its deterministic and random parts added; index, the end the leaf is under, whether
/// the receiver-side part dominates).
struct LeafCharge {
    /// Everything, for the claimed error.
    total: f64,
    /// The sender-side and random parts only: what does not average out over a receiver.
    persistent: f64,
    /// Without the leaf's own links' random parts, which refinement cannot reduce (only more rays could), for
    /// the budget.
    refinable: f64,
    links: Vec<(f64, usize, u32, bool)>,
}

/// The charge of every link on `leaf`'s chain. Receiver-side parts whose bound (`rho * B_s * spread`) is below
/// [`NEGLIGIBLE`] of the leaf's budget `allowed` are charged at that bound without evaluating the kernel.
fn charge_leaf(
    tree: &Tree,
    spans: &[Span],
    links: &[Link],
    ledger: &Ledger,
    allowed: f64,
    leaf: u32,
) -> LeafCharge {
    let mut out = LeafCharge { total: 0.0, persistent: 0.0, refinable: 0.0, links: Vec::new() };
    let (mut variance, mut own) = (0.0, 0.0);
    // The chain's signed deviations summed: the total takes their sum's magnitude instead of the sum of theirs.
    let mut signed = 0.0f64;
    let mut unsigned = 0.0f64;
    let mut n = leaf;
    let rho = tree.nodes[leaf as usize].rho_max;
    while n != NONE {
        for &k in &ledger.at[n as usize] {
            let link = &links[k];
            let (s, spread, sender) = if link.a == n {
                (ledger.sys[k].0, link.spread_ab, link.b)
            } else {
                (ledger.sys[k].1, link.spread_ba, link.a)
            };
            let (l, r) = if n == leaf {
                (0.0, own_noise(tree, spans, link, n))
            } else {
                let bound = max_channel(rho * spans[sender as usize].mean) * spread;
                if bound <= NEGLIGIBLE * allowed {
                    (bound, 0.0)
                } else {
                    let part = local(tree, spans, link, n, leaf);
                    signed += part.signed;
                    unsigned += part.signed.abs();
                    (part.signed.abs() + part.bound, part.random)
                }
            };
            out.total += s + l;
            out.persistent += s;
            // A leaf's own links: only their sender-side part can be refined away.
            let charge = if n == leaf {
                own += r * r;
                s
            } else {
                variance += r * r;
                s + l + r
            };
            if ledger.splittable[k] && charge > 0.0 {
                out.links.push((charge, k, n, n != leaf && l + r >= s));
            }
        }
        n = tree.nodes[n as usize].parent;
    }
    out.total += signed.abs() - unsigned;
    out.refinable = out.total + variance.sqrt();
    out.total += (variance + own).sqrt();
    out.persistent += (variance + own).sqrt();
    out
}

/// A leaf's budget: `epsilon` times its reflected radiosity plus the floor.
pub(super) fn budget(spans: &[Span], leaf: usize, epsilon: f64, floor: f64) -> f64 {
    epsilon * max_channel(spans[leaf].reflected).max(0.0) + floor
}

/// The floor of every leaf's budget: `epsilon * FLOOR_FRACTION` times the area-mean reflected radiosity.
pub(super) fn budget_floor(tree: &Tree, spans: &[Span], epsilon: f64) -> f64 {
    let (mut area, mut reflected) = (0.0, 0.0);
    for (n, node) in tree.nodes.iter().enumerate() {
        if node.children.is_empty() {
            area += node.area;
            reflected += node.area * max_channel(spans[n].reflected).max(0.0);
        }
    }
    if area > 0.0 {
        epsilon * FLOOR_FRACTION * reflected / area
    } else {
        0.0
    }
}

/// The links of a budget pass with what the rounds keep about them: which were split (dead until the pass
/// compacts them), the links at each node, their sender-side charges and whether an end can still be split.
struct Ledger {
    dead: Vec<bool>,
    at: Vec<Vec<usize>>,
    sys: Vec<(f64, f64)>,
    splittable: Vec<bool>,
}

impl Ledger {
    /// Records `links[from..]` (new links) and marks their ends dirty.
    fn add(
        &mut self,
        tree: &Tree,
        spans: &[Span],
        limits: &Limits,
        links: &[Link],
        from: usize,
        dirty: &mut [bool],
    ) {
        self.at.resize(tree.nodes.len(), Vec::new());
        let (sys, splittable): (Vec<(f64, f64)>, Vec<bool>) = links[from..]
            .par_iter()
            .map(|l| (systematic(tree, spans, l), can_split(tree, limits, l)))
            .unzip();
        self.sys.extend(sys);
        self.splittable.extend(splittable);
        self.dead.resize(links.len(), false);
        for (k, link) in links.iter().enumerate().skip(from) {
            for end in [link.a, link.b] {
                self.at[end as usize].push(k);
                dirty[end as usize] = true;
            }
        }
    }
}

/// Refines until every leaf's chain charge is within its budget, or no link on an over-budget chain can be split,
/// or [`MAX_ROUNDS`] rounds ran. Each round splits, for every leaf over budget, the links of largest charge on its
/// chain until what remains is within budget: at the receiver end when the receiver-side part dominates (the
/// link moves down to the children), at the sender end otherwise. Only leaves whose chain changed are charged
/// again. Returns the links split.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
pub(super) fn refine_budgets<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<Span>,
    limits: &Limits,
    epsilon: f64,
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
) -> Result<u64, HierarchyError> {
    let floor = budget_floor(tree, spans, epsilon);
    let mut ledger = Ledger { dead: Vec::new(), at: Vec::new(), sys: Vec::new(), splittable: Vec::new() };
    let mut dirty = vec![true; tree.nodes.len()];
    ledger.add(tree, spans, limits, links, 0, &mut dirty);
    let mut cached: Vec<Option<LeafCharge>> = Vec::new();
    let mut split = 0;
    for _ in 0..MAX_ROUNDS {
        // A leaf is charged again when a node on its chain gained or lost a link (parents come first).
        cached.resize_with(tree.nodes.len(), || None);
        dirty.resize(tree.nodes.len(), true);
        for n in 0..tree.nodes.len() {
            let parent = tree.nodes[n].parent;
            if parent != NONE && dirty[parent as usize] {
                dirty[n] = true;
            }
        }
        let stale: Vec<u32> = (0..tree.nodes.len() as u32)
            .filter(|&n| dirty[n as usize] && tree.nodes[n as usize].children.is_empty())
            .collect();
        let fresh: Vec<LeafCharge> = {
            let (tree, spans, links, ledger) = (&*tree, &*spans, &*links, &ledger);
            stale
                .par_iter()
                .map(|&l| {
                    let allowed = budget(spans, l as usize, epsilon, floor);
                    charge_leaf(tree, spans, links, ledger, allowed, l)
                })
                .collect()
        };
        for (&l, c) in stale.iter().zip(fresh) {
            cached[l as usize] = Some(c);
        }
        dirty.iter_mut().for_each(|d| *d = false);
        // For every leaf over budget, the largest charges on its chain until what remains is within budget.
        let mut chosen: Vec<(usize, u32, bool)> = Vec::new();
        for (leaf, c) in cached.iter().enumerate() {
            let Some(c) = c else { continue };
            if !tree.nodes[leaf].children.is_empty() {
                continue;
            }
            let allowed = budget(spans, leaf, epsilon, floor);
            if c.refinable <= allowed {
                continue;
            }
            let mut chain = c.links.clone();
            chain.sort_unstable_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
            let mut remaining = c.refinable;
            for (charge, k, r, local) in chain {
                if remaining <= allowed {
                    break;
                }
                chosen.push((k, r, local));
                remaining -= charge;
            }
        }
        if chosen.is_empty() {
            break;
        }
        chosen.sort_unstable_by_key(|&(k, ..)| k);
        chosen.dedup_by_key(|&mut (k, ..)| k);
        let mut candidates = Vec::new();
        for &(k, r, local) in &chosen {
            let link = links[k];
            let s = if link.a == r { link.b } else { link.a };
            // The receiver end moves the link down where the local part dominates; the sender end otherwise.
            let first = if local { r } else { s };
            if split_either(tree, estimator.rules, spans, limits, link.pair(tree), first, &mut candidates)? {
                ledger.dead[k] = true;
                dirty.resize(tree.nodes.len(), true);
                for end in [link.a, link.b] {
                    ledger.at[end as usize].retain(|&j| j != k);
                    dirty[end as usize] = true;
                }
                split += 1;
                counts.split += 1;
            }
        }
        let from = links.len();
        refine(tree, estimator, spans, limits, candidates, links, counts)?;
        dirty.resize(tree.nodes.len(), true);
        ledger.add(tree, spans, limits, links, from, &mut dirty);
    }
    let mut k = 0;
    links.retain(|_| {
        k += 1;
        !ledger.dead[k - 1]
    });
    Ok(split)
}

/// What every leaf's chain charges it when refinement ends (zero for inner nodes), in reflected radiosity: the
/// oracle's estimate of each leaf's gathering error, in all and in the parts that do not average out over a
/// receiver (sender-side and random).
pub(super) fn leaf_charges(
    tree: &Tree,
    spans: &[Span],
    limits: &Limits,
    links: &[Link],
    epsilon: f64,
) -> (Vec<f64>, Vec<f64>) {
    let floor = budget_floor(tree, spans, epsilon);
    let mut ledger = Ledger { dead: Vec::new(), at: Vec::new(), sys: Vec::new(), splittable: Vec::new() };
    let mut dirty = vec![false; tree.nodes.len()];
    ledger.add(tree, spans, limits, links, 0, &mut dirty);
    (0..tree.nodes.len() as u32)
        .into_par_iter()
        .map(|n| {
            if tree.nodes[n as usize].children.is_empty() {
                let allowed = budget(spans, n as usize, epsilon, floor);
                let c = charge_leaf(tree, spans, links, &ledger, allowed, n);
                (c.total, c.persistent)
            } else {
                (0.0, 0.0)
            }
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::super::span::Span;
    use super::super::tree::Tree;
    use super::systematic;
    use crate::formfactor::{occluder_bvh, ElementRules, FormFactorOptions};
    use crate::patch::Patch;
    use crate::rgb::Rgb;

    /// A square of side `side` from the origin corner at height `z`, facing up or down.
    fn square(face: usize, side: f64, z: f64, up: bool) -> Patch {
        let mut vertices = vec![
            DVec3::new(0.0, 0.0, z),
            DVec3::new(side, 0.0, z),
            DVec3::new(side, side, z),
            DVec3::new(0.0, side, z),
        ];
        if !up {
            vertices.reverse();
        }
        let normal = if up { DVec3::Z } else { -DVec3::Z };
        let centroid = DVec3::new(0.5 * side, 0.5 * side, z);
        Patch { face, material: 0, vertices, normal, area: side * side, centroid }
    }

    #[test]
    fn the_sender_side_charge_bounds_the_transfer_an_average_misses() {
        // Receiver: a half-unit square over one corner at z = 0.25 facing down; sender: a unit square at z = 0
        // facing up, split into four quarters with different radiosity, which see the receiver differently. The link carries the sender's average radiosity; the exact
        // transfer weighs each quarter by its own form factor to the receiver. The charge must cover the gap.
        let options =
            FormFactorOptions { progress: false, samples_per_patch: 64, ..FormFactorOptions::default() };
        let rules = ElementRules::new(&options).unwrap();
        let roots = [square(0, 0.5, 0.25, false), square(1, 1.0, 0.0, true)];
        let rho = [Rgb::splat(0.5); 2];
        let mut tree = Tree::new(&rules, &roots, &rho, &[Rgb::ZERO; 2]);
        let node_of = |face| {
            (1..3u32).find(|&n| tree.nodes[n as usize].element().unwrap().patch().face == face).unwrap()
        };
        let (receiver, sender) = (node_of(0), node_of(1));
        tree.split(&rules, sender).unwrap();
        let quarters = tree.nodes[sender as usize].children.clone();
        let caster = occluder_bvh(&roots).unwrap();
        let estimator = super::super::link::Estimator::for_tests(&rules, &caster);
        for brightness in [[1.0, 2.0, 3.0, 4.0], [0.0, 0.0, 0.0, 8.0], [5.0, 1.0, 1.0, 5.0]] {
            let mut spans = vec![Span::ZERO; tree.nodes.len()];
            let (mut mean, mut square) = (0.0, 0.0);
            for (&q, &b) in quarters.iter().zip(&brightness) {
                let v = Rgb::splat(b);
                spans[q as usize] = Span { hi: v, lo: v, reflected: v, mean: v, square: v * v };
                mean += 0.25 * b;
                square += 0.25 * b * b;
            }
            let (lo, hi) = brightness.iter().fold((f64::INFINITY, 0.0f64), |(l, h), &b| (l.min(b), h.max(b)));
            spans[sender as usize] = Span {
                hi: Rgb::splat(hi),
                lo: Rgb::splat(lo),
                reflected: Rgb::splat(mean),
                mean: Rgb::splat(mean),
                square: Rgb::splat(square),
            };
            let link = estimator.estimate(&tree, super::super::link::Pair::new(receiver, sender)).link;
            let (at_receiver, _) = systematic(&tree, &spans, &link);
            // The exact transfer per unit receiver area, through each quarter's own form factor (A_q F_qr = A_r
            // F_rq, the estimator's kernel integral).
            let receiver_element = tree.nodes[receiver as usize].element().unwrap();
            let exact: f64 = quarters
                .iter()
                .zip(&brightness)
                .map(|(&q, &b)| {
                    rules.unoccluded(receiver_element, tree.nodes[q as usize].element().unwrap()) * b
                })
                .sum();
            let missed = 0.5 * (exact - link.f_ab * mean).abs();
            assert!(missed > 0.0, "{brightness:?}: the average should miss something here");
            assert!(missed <= at_receiver, "{brightness:?}: missed {missed}, charged {at_receiver}");
        }
    }
}
