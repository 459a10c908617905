//! Leaves whose links gather more than all there is: where an ancestor's average form factor overstates what a
//! leaf sees (a leaf in a corner sees the far surfaces at grazing angles, worse than its ancestor does on
//! average), the leaf's total form factor (its row sum: the links on its chain, pushed down) exceeds 1. Its power
//! then leaves through more links than it has, which a closed scene amplifies, and which the device's table must
//! cap (`bake::hier`). Brightness-weighted refinement does not see it, since it judges each link alone against
//! an absolute bound, and every overstatement on such a chain is small and dim. This finds, for every leaf over
//! `1 + tolerance`, the links on its chain (held at strict ancestors) whose average overstates the leaf's own
//! point form factor most, until their overstatements cover the excess: splitting those at the ancestor moves
//! them down towards the leaf.

use rayon::prelude::*;

use super::link::Link;
use super::tree::{Tree, NONE};
use crate::formfactor::point_to_polygon;

/// The links to split at their end on a leaf's chain, as `(link index, that end)`, sorted and without repeats:
/// for each leaf whose row sum exceeds `1 + tolerance`, the surface links at its strict ancestors in decreasing
/// order of `f_ns - v K(l, s)` (the ancestor's average minus the visible point kernel from the leaf's centroid to
/// the sender's polygon, when positive) until those cover the excess.
pub(super) fn overstated(tree: &Tree, links: &[Link], tolerance: f64) -> Vec<(usize, u32)> {
    let mut at: Vec<Vec<usize>> = vec![Vec::new(); tree.nodes.len()];
    for (k, l) in links.iter().enumerate() {
        at[l.a as usize].push(k);
        at[l.b as usize].push(k);
    }
    let (sum, _) = leaf_row_sums(tree, links);
    // Each leaf's choice depends on the leaf alone; they are made in parallel and put in order below.
    let mut chosen: Vec<(usize, u32)> = (0..tree.nodes.len())
        .into_par_iter()
        .flat_map_iter(|n| {
            let node = &tree.nodes[n];
            let excess = sum[n] - 1.0 - tolerance;
            let mut picked = Vec::new();
            if !node.children.is_empty() || excess <= 0.0 {
                return picked;
            }
            let Some(el) = node.element() else { return picked };
            let pl = el.patch();
            let mut over: Vec<(f64, usize, u32)> = Vec::new();
            let mut a = node.parent;
            while a != NONE {
                for &k in &at[a as usize] {
                    let link = &links[k];
                    let (s, f) = if link.a == a { (link.b, link.f_ab) } else { (link.a, link.f_ba) };
                    let Some(es) = tree.nodes[s as usize].element() else { continue };
                    let ps = es.patch();
                    let seen =
                        link.visible * point_to_polygon(pl.centroid, pl.normal, &ps.vertices, ps.normal);
                    if f > seen {
                        over.push((f - seen, k, a));
                    }
                }
                a = tree.nodes[a as usize].parent;
            }
            over.sort_unstable_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
            let mut covered = 0.0;
            for (o, k, a) in over {
                if covered >= excess {
                    break;
                }
                picked.push((k, a));
                covered += o;
            }
            picked
        })
        .collect();
    chosen.sort_unstable();
    chosen.dedup_by_key(|c| c.0);
    chosen
}

/// Every node's total form factor (its links' and its ancestors', pushed down like irradiance), and the smallest
/// and largest over the leaves.
pub(super) fn leaf_row_sums(tree: &Tree, links: &[Link]) -> (Vec<f64>, (f64, f64)) {
    let mut sum = vec![0.0; tree.nodes.len()];
    for l in links {
        sum[l.a as usize] += l.f_ab;
        sum[l.b as usize] += l.f_ba;
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..tree.nodes.len() {
        let node = &tree.nodes[k];
        if node.parent != NONE {
            sum[k] += sum[node.parent as usize];
        }
        if node.children.is_empty() {
            lo = lo.min(sum[k]);
            hi = hi.max(sum[k]);
        }
    }
    (sum, (lo, hi))
}
