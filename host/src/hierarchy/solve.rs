//! The solve over links: Jacobi iteration with push-pull (Hanrahan, Salzman, Aupperle 1991, section 4). Each
//! sweep gathers `f * B_sender` at every link's receiver, pushes the gathered irradiance down to the leaves (a
//! cluster's to every surface in it, the isotropic approximation), sets `B = E + rho * gathered` at the leaves,
//! and pulls area-weighted averages back up.

use super::link::Link;
use super::tree::{Kind, Tree, NONE};
use crate::rgb::{channel_max, max_channel, Rgb};

/// The solved radiosity of every node, with its largest value over the leaves below.
pub(super) struct NodeRadiosity {
    /// Area-weighted mean radiosity per node (W/m^2).
    pub(super) b: Vec<Rgb>,
    /// Largest leaf radiosity per channel below each node.
    pub(super) b_max: Vec<Rgb>,
    /// Sweeps run.
    pub(super) sweeps: usize,
    /// Relative change of the last sweep: `sum A |dB|` over `sum A B` (largest channel).
    pub(super) change: f64,
}

/// Emission per node (its surface's for surfaces, zero for clusters).
fn emission(tree: &Tree) -> Vec<Rgb> {
    tree.nodes
        .iter()
        .map(|n| match &n.kind {
            Kind::Surface { emission, .. } => *emission,
            Kind::Cluster { .. } => Rgb::ZERO,
        })
        .collect()
}

/// Area-weighted means and maxima from the leaves' values in `b`, in reverse index order.
fn pull(tree: &Tree, b: &mut [Rgb], b_max: &mut [Rgb]) {
    for n in (0..tree.nodes.len()).rev() {
        let node = &tree.nodes[n];
        if node.children.is_empty() {
            b_max[n] = b[n];
            continue;
        }
        let (mut sum, mut hi) = (Rgb::ZERO, Rgb::splat(f64::NEG_INFINITY));
        for &c in &node.children {
            let c = c as usize;
            sum += tree.nodes[c].area * b[c];
            hi = channel_max(hi, b_max[c]);
        }
        b[n] = sum / node.area;
        b_max[n] = hi;
    }
}

/// The brightness bound of pass 1: each node's largest emission below it.
pub(super) fn emission_bound(tree: &Tree) -> Vec<Rgb> {
    let mut b = emission(tree);
    let mut b_max = vec![Rgb::ZERO; b.len()];
    pull(tree, &mut b, &mut b_max);
    b_max
}

/// Jacobi sweeps until the relative change is at most `tolerance` or `max_sweeps` ran.
pub(super) fn solve(tree: &Tree, links: &[Link], tolerance: f64, max_sweeps: usize) -> NodeRadiosity {
    let n = tree.nodes.len();
    let e = emission(tree);
    let rho: Vec<Rgb> = tree
        .nodes
        .iter()
        .map(|n| match &n.kind {
            Kind::Surface { rho, .. } => *rho,
            Kind::Cluster { .. } => Rgb::ZERO,
        })
        .collect();
    let mut b = e.clone();
    let mut b_max = vec![Rgb::ZERO; n];
    pull(tree, &mut b, &mut b_max);
    let mut gathered = vec![Rgb::ZERO; n];
    let mut sweeps = 0;
    let mut change = f64::INFINITY;
    while sweeps < max_sweeps && change > tolerance {
        gathered.iter_mut().for_each(|g| *g = Rgb::ZERO);
        for link in links {
            gathered[link.a as usize] += link.f_ab * b[link.b as usize];
            gathered[link.b as usize] += link.f_ba * b[link.a as usize];
        }
        // Push in index order: a parent's total is final before its children add it.
        let (mut moved, mut total) = (0.0, 0.0);
        for k in 0..n {
            let node = &tree.nodes[k];
            if node.parent != NONE {
                let above = gathered[node.parent as usize];
                gathered[k] += above;
            }
            if node.children.is_empty() {
                let new = e[k] + rho[k] * gathered[k];
                moved += node.area * max_channel((new - b[k]).abs());
                total += node.area * max_channel(new);
                b[k] = new;
            }
        }
        pull(tree, &mut b, &mut b_max);
        change = if total > 0.0 { moved / total } else { 0.0 };
        sweeps += 1;
    }
    NodeRadiosity { b, b_max, sweeps, change }
}
