//! Links whose receiver-side spread a leaf below them contradicts: a surface-surface link held at an ancestor
//! gives every leaf below it the ancestor's average form factor, and its spread claims how far any point's may
//! stray from that average. The visibility part of the claim comes from the ancestor's own rays
//! ([`ElementRules::rays_per_pair`](crate::formfactor::ElementRules::rays_per_pair) of them): when all of them
//! pass, the link is taken as unoccluded and its spread holds only the kernel's range and one ray's resolution,
//! although an occluder the rays missed may shadow the leaves tucked against it (floor leaves beside a block,
//! towards the wall behind the block). Those leaves then gather the ancestor's transfer where they see almost
//! nothing, and brightness-weighted refinement, which judges the link by its own spread, never splits it.
//!
//! So for the surface links held at inner nodes, this estimates the own form factor towards the sender of the
//! leaves below (the link estimator's own kernel integral and occlusion rays, its seeded streams, so the answer
//! does not depend on threads), and takes the ancestor's `f` minus the leaf's estimate and minus that estimate's
//! own uncertainty as the deviation the leaf witnesses. A link is split at that end (moved towards the leaves;
//! the next pass checks the links that replace it) when one leaf's deviation
//! - contradicts the link's spread in the oracle's own terms: it exceeds the spread, and `link::link_error` with
//!   it in place of the spread (`A_r * max_c(rho_r * Bmax_s) * deviation`) exceeds the bound per link; or
//! - is more than the leaf may get wrong: in some channel the radiosity it reflects wrongly through the link,
//!   `rho_l * deviation * B_s` (the sender's mean, which the link carries), exceeds `epsilon` times the leaf's
//!   reflected radiosity. This is the budgets' relative rule (`budget`) applied to a measured deviation instead
//!   of a bound: brightness refinement's absolute bound lets dim leaves beside an occluder keep coarse links,
//!   and what they reflect too much then lights the dim surfaces facing them (the sides of the Cornell box's
//!   blocks turned from the light).
//!
//! Cost: a leaf is estimated only where the link could break either rule were the leaf to see nothing of the
//! sender (its whole `f` as the deviation), and a link's leaves only until one breaks a rule. A (leaf, sender)
//! estimate is kept in [`LeafEstimates`] across the passes: a link that no pass splits is checked again in every
//! pass (the solved radiosity, and so the rules, change), but its leaves' estimates do not (they are the seeded
//! estimator's, a function of the two nodes alone), so each is made once.
//!
//! Links whose shaft was clear (`shaft`: no face polygon can come between their ends) are not checked: no
//! occluder can shadow a leaf below them, and what is left of a leaf's deviation is the kernel's, which the
//! link's spread bounds at its probes. The relative rule's hold on such deviations of dim leaves is given up for
//! it: a little per-face accuracy for much less refinement time (`bench/REPORT.md` has the error against the
//! seconds; the closing notes of issue 18 compare the two).
//!
//! Links with a cluster at either end are not checked: their spread is Smits, Arvo and Greenberg's bound on any
//! point's form factor (`A_s / (pi d^2)`), which no leaf's overstatement can exceed, and a leaf's own estimate
//! towards a cluster would be a point-pair Monte Carlo estimate like the link's, no better than it.

use std::collections::HashMap;

use rayon::prelude::*;

use super::link::{Estimator, Link};
use super::span::Span;
use super::tree::{Kind, Tree};
use crate::raycast::RayCaster;
use crate::rgb::max_channel;

/// What the check found and what it cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Contradicted {
    /// The links to split, as `(link index, the end whose leaves contradict it)`, sorted by index, one per link.
    pub(super) links: Vec<(usize, u32)>,
    /// (Leaf, sender) pairs estimated.
    pub(super) estimated: u64,
    /// Occlusion rays cast.
    pub(super) rays: u64,
}

/// The (leaf, sender) estimates made so far, by node index (a node keeps its index once made: refinement
/// renumbers only the nodes it makes, `Tree::renumber_from`): the leaf's own form factor towards the sender and
/// its uncertainty, as [`contradicted`] uses them.
#[derive(Debug, Default)]
pub(super) struct LeafEstimates(HashMap<(u32, u32), (f64, f64)>);

/// One (leaf, sender) estimate: the pair and the leaf's own form factor with its uncertainty.
type LeafEstimate = ((u32, u32), (f64, f64));

/// One direction of a link to check: the receiving end `r` (a surface with children), the sender `s`, the
/// receiver's form factor `f` and its spread, and whether the oracle's bound could be exceeded at all.
#[derive(Clone, Copy)]
struct Direction {
    index: usize,
    r: u32,
    s: u32,
    f: f64,
    spread: f64,
    absolute: bool,
}

/// The links of `links` that a leaf below one of their ends contradicts (see the module docs), with `spans` the
/// solved brightness of the nodes, `threshold` the oracle's bound per link (W) and `epsilon` the error allowed
/// per leaf relative to its reflected radiosity. `known` holds the estimates of earlier calls on the same tree
/// (grown, not changed, since) and gets this call's; only the estimates made here are counted.
pub(super) fn contradicted<C: RayCaster + ?Sized>(
    tree: &Tree,
    estimator: &Estimator<'_, C>,
    spans: &[Span],
    threshold: f64,
    epsilon: f64,
    links: &[Link],
    known: &mut LeafEstimates,
) -> Contradicted {
    let weight = |r: u32, s: u32| max_channel(tree.nodes[r as usize].rho_max * spans[s as usize].hi);
    let mut directions = Vec::new();
    for (index, l) in links.iter().enumerate() {
        // A link whose shaft was clear (its visibility exact, `sigma` 0) has nothing between its ends that could
        // shadow a leaf below either.
        if tree.is_cluster(l.a) || tree.is_cluster(l.b) || l.pair(tree).clear {
            continue;
        }
        for (r, s, f, spread) in [(l.a, l.b, l.f_ab, l.spread_ab), (l.b, l.a, l.f_ba, l.spread_ba)] {
            let node = &tree.nodes[r as usize];
            if node.children.is_empty() || f <= 0.0 {
                continue;
            }
            // A leaf's deviation is at most `f` (it sees at least nothing): a link whose spread already admits
            // `f`, or whose whole transfer is within the bound, cannot be contradicted in the oracle's terms.
            let absolute = f > spread && node.area * weight(r, s) * f > threshold;
            directions.push(Direction { index, r, s, f, spread, absolute });
        }
    }
    let cache = &known.0;
    let found: Vec<(Contradicted, Vec<LeafEstimate>)> = directions
        .par_iter()
        .map(|d| {
            let mut out = Contradicted::default();
            let mut made = Vec::new();
            let Some(es) = tree.nodes[d.s as usize].element() else { return (out, made) };
            let bound = threshold / (tree.nodes[d.r as usize].area * weight(d.r, d.s));
            let sent = spans[d.s as usize].mean;
            for leaf in leaves_below(tree, d.r) {
                let node = &tree.nodes[leaf as usize];
                let Kind::Surface { element: el, rho, .. } = &node.kind else { continue };
                // What the leaf may reflect wrongly through this link, per channel, at most (were it to see
                // nothing of the sender), against its share of the budget: its reflected radiosity times
                // `epsilon`.
                let allowed = epsilon * spans[leaf as usize].reflected;
                if !d.absolute && !(*rho * d.f * sent).cmpgt(allowed).any() {
                    continue;
                }
                // The leaf's own form factor and its uncertainty: one standard error of the visible fraction
                // where it is partial, one ray's resolution where the rays saw all or nothing, none where the
                // shaft was clear (as the link estimator charges).
                let (own, uncertainty) = match cache.get(&(leaf, d.s)) {
                    Some(&known) => known,
                    None => {
                        out.estimated += 1;
                        let fresh = match estimator.factor(tree, (leaf, el), (d.s, es), false).map(|(e, _)| e)
                        {
                            Some(e) => {
                                out.rays += e.rays;
                                (e.link.f_ab, e.link.unoccluded_ab * e.link.sigma)
                            }
                            None => (0.0, 0.0),
                        };
                        made.push(((leaf, d.s), fresh));
                        fresh
                    }
                };
                let deviation = d.f - own - uncertainty;
                let absolute = d.absolute && deviation > d.spread && deviation > bound;
                let relative = deviation > 0.0 && (*rho * deviation * sent).cmpgt(allowed).any();
                if absolute || relative {
                    out.links.push((d.index, d.r));
                    return (out, made);
                }
            }
            (out, made)
        })
        .collect();
    let mut out = Contradicted::default();
    for (one, made) in found {
        known.0.extend(made);
        out.estimated += one.estimated;
        out.rays += one.rays;
        out.links.extend(one.links);
    }
    // Directions were listed by link index, so the first of a link's two is kept.
    out.links.dedup_by_key(|c| c.0);
    out
}

/// The leaves of the subtree of `n`, in depth-first order.
fn leaves_below(tree: &Tree, n: u32) -> impl Iterator<Item = u32> + '_ {
    let mut stack = vec![n];
    std::iter::from_fn(move || {
        while let Some(k) = stack.pop() {
            let children = &tree.nodes[k as usize].children;
            if children.is_empty() {
                return Some(k);
            }
            stack.extend(children.iter().rev());
        }
        None
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::{occluder_bvh, ElementRules, FormFactorOptions};
    use crate::hierarchy::link::{link_error, Limits, Pair, RefineCounts};
    use crate::hierarchy::refine_brightness;
    use crate::hierarchy::solve::emission_bound;
    use crate::hierarchy::tree::{Tree, NONE};
    use crate::hierarchy::DEFAULT_EPSILON;
    use crate::lighting::PatchLighting;
    use crate::mesh::{mesh, MeshOptions};
    use crate::patch::Patch;
    use crate::scene::Scene;

    /// A unit floor (face 0, y = 0, reflecting 0.5) under an emitting unit ceiling (face 1, y = 1, emitting 1),
    /// and a black plate (face 2) at y = 0.05 over the floor's half x < 0.5, reaching past it on every other
    /// side (to x = 0.55): a ray from a point of that half to any point of the ceiling crosses y = 0.05 at
    /// x <= 0.5 + 0.5 * 0.05 = 0.525, inside the plate, so that half sees none of the ceiling.
    const SHADOWED: &str = "v 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\n\
                            v 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\n\
                            v -1 0.05 -1\nv -1 0.05 2\nv 0.55 0.05 2\nv 0.55 0.05 -1\n\
                            usemtl grey\nf 1 2 3 4\nusemtl light\nf 5 6 7 8\nusemtl black\nf 9 10 11 12\n";
    const SHADOWED_MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\nKe 0 0 0\nnewmtl light\nKd 0 0 0\nKe 1 1 1\n\
                                newmtl black\nKd 0 0 0\nKe 0 0 0\n";

    fn roots() -> (Vec<Patch>, PatchLighting) {
        let dir = std::env::temp_dir().join(format!("radiosity-shadow-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("shadowed.mtl"), SHADOWED_MTL).unwrap();
        std::fs::write(dir.join("shadowed.obj"), format!("mtllib shadowed.mtl\n{SHADOWED}")).unwrap();
        let scene = Scene::load(dir.join("shadowed.obj")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let roots =
            mesh(&scene, &MeshOptions { patch_budget: usize::MAX, ..MeshOptions::no_subdivide(&scene) })
                .unwrap()
                .patches;
        let lighting = PatchLighting::new(&scene, &roots);
        (roots, lighting)
    }

    /// The form factor `leaf` gathers from `sender`'s polygon through the links on its chain (its own and its
    /// ancestors').
    fn chain_transfer(tree: &Tree, links: &[Link], leaf: u32, sender: u32) -> f64 {
        let from_sender = |mut n: u32| {
            while n != NONE {
                if n == sender {
                    return true;
                }
                n = tree.nodes[n as usize].parent;
            }
            false
        };
        let mut total = 0.0;
        let mut a = leaf;
        while a != NONE {
            for l in links {
                if l.a == a && from_sender(l.b) {
                    total += l.f_ab;
                } else if l.b == a && from_sender(l.a) {
                    total += l.f_ba;
                }
            }
            a = tree.nodes[a as usize].parent;
        }
        total
    }

    /// The floor's link to the ceiling, estimated with rays that all passed (as an ancestor's few rays can miss
    /// an occluder: here the plate is left out of its caster), spreads no further than the kernel's range. At
    /// the largest bound that brightness refinement keeps it under, the shadowed half's leaves gather the
    /// floor's whole average from the ceiling; once their own estimates contradict the link (by either rule),
    /// it is pushed down and they gather nothing, within one ray's resolution of their own unoccluded factor.
    #[test]
    fn a_shadowed_leaf_stops_gathering_its_ancestors_transfer() {
        let (roots, lighting) = roots();
        let rules = ElementRules::new(&FormFactorOptions { progress: false, ..FormFactorOptions::default() })
            .unwrap();
        let with_plate = occluder_bvh(&roots).unwrap();
        let without_plate = occluder_bvh(&roots[..2]).unwrap();
        let shadowing = Estimator::for_tests(&rules, &with_plate);
        let open = Estimator { caster: &without_plate, ..shadowing };
        let top = |tree: &Tree, face: u32| {
            (0..tree.nodes.len() as u32).find(|&k| tree.nodes[k as usize].root == face)
        };
        let n = rules.rays_per_pair() as f64;

        let mut gathered = Vec::new();
        // Without the check; with it, the leaves' reflected radiosity unknown (zero: the relative rule holds
        // them to any deviation); with it, their reflected radiosity unbounded (only the oracle's rule applies).
        for (check, reflected) in [(false, 0.0), (true, 0.0), (true, f64::INFINITY)] {
            let mut tree = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
            let (floor, ceiling) = (top(&tree, 0).unwrap(), top(&tree, 1).unwrap());
            tree.split(&rules, floor).unwrap();
            let link = open.estimate(&tree, Pair::new(floor, ceiling)).link;
            assert_eq!(link.visible, 1.0, "the floor's rays to the ceiling, with nothing between");
            let mut spans = emission_bound(&tree);
            for span in &mut spans {
                span.reflected = crate::rgb::Rgb::splat(reflected);
            }
            let threshold = link_error(&tree, &spans, &link, 0.0);
            let limits = Limits {
                threshold,
                min_area: 0.0,
                max_nodes: 10_000,
                max_links: 10_000,
                pieces: 1,
                sender_weight: 0.0,
            };
            let mut links = vec![link];
            let mut counts = RefineCounts::default();
            let mut known = LeafEstimates::default();
            // Each round pushes the contradicted links one level down; the tree has two levels below the floor.
            for _ in 0..4 {
                let found = if check {
                    contradicted(&tree, &shadowing, &spans, threshold, DEFAULT_EPSILON, &links, &mut known)
                        .links
                } else {
                    Vec::new()
                };
                let split = refine_brightness(
                    &mut tree,
                    &shadowing,
                    &mut spans,
                    &limits,
                    &found,
                    &mut links,
                    &mut counts,
                )
                .unwrap();
                if split == 0 {
                    break;
                }
            }
            let shadowed: Vec<u32> = leaves_below(&tree, floor)
                .filter(|&k| tree.nodes[k as usize].element().unwrap().patch().centroid.x < 0.5)
                .collect();
            assert!(!shadowed.is_empty());
            for leaf in shadowed {
                let own = rules.unoccluded(
                    tree.nodes[leaf as usize].element().unwrap(),
                    tree.nodes[ceiling as usize].element().unwrap(),
                );
                gathered.push((check, chain_transfer(&tree, &links, leaf, ceiling), own / n));
            }
        }
        for (check, transfer, bound) in gathered {
            if check {
                assert!(transfer <= bound, "with the check: gathers {transfer:.4}, bound {bound:.4}");
            } else {
                // Without it, the leaf keeps the floor's average: the failure the check exists for.
                assert!(transfer > bound, "without the check: gathers {transfer:.4}, bound {bound:.4}");
            }
        }
    }
}
