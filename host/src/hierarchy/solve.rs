//! The solve over links: Jacobi iteration with push-pull (Hanrahan, Salzman, Aupperle 1991, section 4). Each
//! sweep gathers `f * B_sender` at every link's receiver, pushes the gathered irradiance down to the leaves (a
//! cluster's to every surface in it, the isotropic approximation), sets `B = E + rho * gathered` at the leaves,
//! and pulls area-weighted averages back up.

use rayon::prelude::*;

use super::link::Link;
use super::span::Span;
use super::tree::{Kind, Tree, NONE};
use crate::rgb::{channel_max, channel_min, max_channel, Rgb};

/// The solved radiosity of every node, with its largest value over the leaves below.
pub(super) struct NodeRadiosity {
    /// Area-weighted mean radiosity per node (W/m^2).
    pub(super) b: Vec<Rgb>,
    /// The brightness of the leaves below each node.
    pub(super) spans: Vec<Span>,
    /// Sweeps run.
    pub(super) sweeps: usize,
    /// Relative change of the last sweep: `sum A |dB|` over `sum A B` (largest channel).
    pub(super) change: f64,
}

/// Reflectance per node (its surface's for surfaces, zero for clusters).
pub(super) fn reflectance(tree: &Tree) -> Vec<Rgb> {
    tree.nodes
        .iter()
        .map(|n| match &n.kind {
            Kind::Surface { rho, .. } => *rho,
            Kind::Cluster { .. } => Rgb::ZERO,
        })
        .collect()
}

/// Emission per node (its surface's for surfaces, zero for clusters).
pub(super) fn emission(tree: &Tree) -> Vec<Rgb> {
    tree.nodes
        .iter()
        .map(|n| match &n.kind {
            Kind::Surface { emission, .. } => *emission,
            Kind::Cluster { .. } => Rgb::ZERO,
        })
        .collect()
}

/// Area-weighted means and maxima from the leaves' values in `b`, in reverse index order.
pub(super) fn pull(tree: &Tree, b: &mut [Rgb], e: &[Rgb], spans: &mut [Span]) {
    for n in (0..tree.nodes.len()).rev() {
        let node = &tree.nodes[n];
        if node.children.is_empty() {
            spans[n] = Span { hi: b[n], lo: b[n], reflected: b[n] - e[n], mean: b[n], square: b[n] * b[n] };
            continue;
        }
        let (mut sum, mut hi, mut lo) = (Rgb::ZERO, Rgb::splat(f64::NEG_INFINITY), Rgb::splat(f64::INFINITY));
        let (mut refl, mut square) = (Rgb::ZERO, Rgb::ZERO);
        for &c in &node.children {
            let c = c as usize;
            sum += tree.nodes[c].area * b[c];
            square += tree.nodes[c].area * spans[c].square;
            refl += tree.nodes[c].area * spans[c].reflected;
            hi = channel_max(hi, spans[c].hi);
            lo = channel_min(lo, spans[c].lo);
        }
        b[n] = sum / node.area;
        spans[n] = Span { hi, lo, reflected: refl / node.area, mean: b[n], square: square / node.area };
    }
}

/// The brightness of pass 1: the emission alone.
pub(super) fn emission_bound(tree: &Tree) -> Vec<Span> {
    let e = emission(tree);
    let mut b = e.clone();
    let mut spans = vec![Span::ZERO; b.len()];
    pull(tree, &mut b, &e, &mut spans);
    spans
}

/// What the sweeps read of the links: every node's incoming transfers `(sender, f)`, grouped by receiver
/// (compressed rows), each group in the links' order. A sweep then gathers every node's irradiance on its own, in
/// parallel, adding the same terms in the same order as a pass over the links would. Built once per set of
/// links, for every solve on them.
pub(super) struct Incoming {
    /// Where each node's transfers start in `from` (one more entry than nodes).
    start: Vec<usize>,
    /// The transfers, `(sender, form factor)`.
    from: Vec<(u32, f64)>,
}

impl Incoming {
    /// Both directions of every link, grouped by receiver over `n` nodes.
    pub(super) fn new(n: usize, links: &[Link]) -> Incoming {
        let (start, from) = grouped(n, links, Group::ByReceiver);
        Incoming { start, from }
    }

    /// `gathered[k] = sum f * value[sender]` over node `k`'s transfers, for every node (from `zero`).
    fn gather<T>(&self, value: &[T], zero: T, gathered: &mut [T])
    where
        T: Copy + Send + Sync + std::ops::Add<Output = T>,
        f64: std::ops::Mul<T, Output = T>,
    {
        /// Nodes per parallel task: enough work per task to pay for it.
        const NODES_PER_TASK: usize = 64;
        gathered.par_iter_mut().with_min_len(NODES_PER_TASK).enumerate().for_each(|(k, g)| {
            *g = self.from[self.start[k]..self.start[k + 1]]
                .iter()
                .fold(zero, |sum, &(s, f)| sum + f * value[s as usize]);
        });
    }
}

/// Which end of a link [`grouped`] files its two directions under.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Group {
    /// `(sender, f)` under the receiver (gathering).
    ByReceiver,
    /// `(receiver, f)` under the sender (shooting).
    BySender,
}

/// Both directions of every link, each as the other end and the form factor at the receiver, grouped under one
/// end (`by`) in compressed rows over `n` nodes, each row in the links' order: the rows' starts (one more than
/// nodes) and the entries.
pub(super) fn grouped(n: usize, links: &[Link], by: Group) -> (Vec<usize>, Vec<(u32, f64)>) {
    let mut start = vec![0usize; n + 1];
    for l in links {
        start[l.a as usize + 1] += 1;
        start[l.b as usize + 1] += 1;
    }
    for k in 0..n {
        start[k + 1] += start[k];
    }
    let mut next = start.clone();
    let mut entries = vec![(0u32, 0.0f64); start[n]];
    for l in links {
        // (where, other end, form factor at the receiver) for a receiving at `a` from `b`, then the other way.
        for (receiver, sender, f) in [(l.a, l.b, l.f_ab), (l.b, l.a, l.f_ba)] {
            let (row, other) = match by {
                Group::ByReceiver => (receiver, sender),
                Group::BySender => (sender, receiver),
            };
            entries[next[row as usize]] = (other, f);
            next[row as usize] += 1;
        }
    }
    (start, entries)
}

/// Jacobi sweeps with emission `e` and reflectance `rho` per node (zero on clusters) until the relative change is
/// at most `tolerance` or `max_sweeps` ran, from the emission or, warm, from `start` (a radiosity per node of an
/// earlier solve of the same tree before refinement added nodes: a node it does not cover starts at its parent's).
pub(super) fn solve(
    tree: &Tree,
    incoming: &Incoming,
    (e, rho): (&[Rgb], &[Rgb]),
    start: Option<&[Rgb]>,
    tolerance: f64,
    max_sweeps: usize,
) -> NodeRadiosity {
    let n = tree.nodes.len();
    let e = e.to_vec();
    let mut b = e.clone();
    if let Some(start) = start {
        for k in 0..n {
            let parent = tree.nodes[k].parent;
            b[k] = match start.get(k) {
                Some(&s) => s,
                None if parent != NONE => b[parent as usize],
                None => e[k],
            };
        }
    }
    let mut spans = vec![Span::ZERO; n];
    pull(tree, &mut b, &e, &mut spans);
    let mut gathered = vec![Rgb::ZERO; n];
    let mut sweeps = 0;
    let mut change = f64::INFINITY;
    while sweeps < max_sweeps && change > tolerance {
        incoming.gather(&b, Rgb::ZERO, &mut gathered);
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
        pull(tree, &mut b, &e, &mut spans);
        // A radiosity that overflowed is divergence (NaN stops the loop and fails the solve), not a change of 0.
        change = if !total.is_finite() || !moved.is_finite() {
            f64::NAN
        } else if total > 0.0 {
            moved / total
        } else {
            0.0
        };
        sweeps += 1;
    }
    NodeRadiosity { b, spans, sweeps, change }
}

/// The propagated error bound: the solution of `e = c + rho H e` on the leaves (`c` per leaf from `source`, `H`
/// the links with push-pull, `rho` the largest channel of `rho`, the solve's reflectance), by the same Jacobi
/// sweeps as [`solve`]. An error of at most `c` in what each leaf gathers per bounce becomes at most `e` in its
/// radiosity. `None` if the sweeps do not settle to `tolerance` (the bound diverges: `rho` times a leaf's total
/// form factor reaches 1).
pub(super) fn propagate(
    tree: &Tree,
    incoming: &Incoming,
    (source, rho): (&[f64], &[Rgb]),
    tolerance: f64,
    max_sweeps: usize,
) -> Option<Vec<f64>> {
    let n = tree.nodes.len();
    let rho: Vec<f64> = rho.iter().map(|r| max_channel(*r)).collect();
    let mut e = source.to_vec();
    let mut gathered = vec![0.0; n];
    for _ in 0..max_sweeps {
        // Area means up the tree, so that links read a sender's average error.
        for k in (0..n).rev() {
            let node = &tree.nodes[k];
            if !node.children.is_empty() {
                e[k] =
                    node.children.iter().map(|&c| tree.nodes[c as usize].area * e[c as usize]).sum::<f64>()
                        / node.area;
            }
        }
        incoming.gather(&e, 0.0, &mut gathered);
        let (mut moved, mut total) = (0.0, 0.0);
        for k in 0..n {
            let node = &tree.nodes[k];
            if node.parent != NONE {
                gathered[k] += gathered[node.parent as usize];
            }
            if node.children.is_empty() {
                let new = source[k] + rho[k] * gathered[k];
                moved += node.area * (new - e[k]).abs();
                total += node.area * new;
                e[k] = new;
            }
        }
        if !total.is_finite() {
            return None;
        }
        if total == 0.0 || moved <= tolerance * total {
            return Some(e);
        }
    }
    None
}
