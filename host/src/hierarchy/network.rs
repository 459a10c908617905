//! The solved hierarchy as data: the tree renumbered breadth-first (every parent before its children, the
//! children of a node contiguous) and its links, which is what a device table is written from and what a solve
//! outside this module can run on.

use std::ops::Range;

use super::link::Link;
use super::tree::{Tree, NONE};

/// A node of [`LinkNetwork`].
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkNode {
    /// The parent, `None` for the top node (node 0); always a smaller index than the node.
    pub parent: Option<u32>,
    /// The children: a contiguous range of larger indices, empty for a leaf.
    pub children: Range<u32>,
    /// Surface area (for a cluster, the sum over its surfaces).
    pub area: f64,
    /// Whether the node is a cluster (receives isotropically: every surface below it gets the same irradiance).
    pub cluster: bool,
    /// For a leaf, its index in [`super::HierarchicalSolution::leaves`] (and `rho`, `emission`, `b`).
    pub leaf: Option<u32>,
}

/// A link of [`LinkNetwork`]: `a` gathers `f_ab * B_b` per unit area and `b` gathers `f_ba * B_a`, with
/// `A_a f_ab = A_b f_ba` (reciprocity). In shooting terms (see [`LinkNetwork::sender_runs`]), `f_ab` is also the
/// share of `a`'s power that reaches `b`, and `f_ba` the share of `b`'s that reaches `a`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NetworkLink {
    /// One end (a node index).
    pub a: u32,
    /// The other end.
    pub b: u32,
    /// The form factor from `a` to `b`, averaged over `a`.
    pub f_ab: f64,
    /// The form factor from `b` to `a`, averaged over `b`.
    pub f_ba: f64,
}

/// The tree and the links the hierarchical solve ended with. The radiosity equation on it: every node `n`
/// gathers `g_n = sum f_nm B_m` over its links, a leaf `l` reflects `rho_l` times the sum of `g` over itself and
/// its ancestors (push), and an inner node's `B` is the area mean of its children's (pull).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkNetwork {
    /// Nodes, breadth-first from the top.
    pub nodes: Vec<NetworkNode>,
    /// Links, in the solve's order, between nodes of [`Self::nodes`].
    pub links: Vec<NetworkLink>,
}

impl LinkNetwork {
    /// The network of `tree` and `links`, with `leaf_index[n]` the answer's index of leaf node `n`.
    pub(super) fn new(tree: &Tree, links: &[Link], leaf_index: &[u32]) -> LinkNetwork {
        // Breadth-first order: the top first, then each node's children together.
        let mut order: Vec<u32> = vec![0];
        let mut new_index = vec![NONE; tree.nodes.len()];
        new_index[0] = 0;
        let mut k = 0;
        while k < order.len() {
            for &c in &tree.nodes[order[k] as usize].children {
                new_index[c as usize] = order.len() as u32;
                order.push(c);
            }
            k += 1;
        }
        let mut nodes = Vec::with_capacity(order.len());
        let mut next_child = 1u32;
        for &old in &order {
            let node = &tree.nodes[old as usize];
            let count = node.children.len() as u32;
            nodes.push(NetworkNode {
                parent: (node.parent != NONE).then(|| new_index[node.parent as usize]),
                children: if count == 0 { 0..0 } else { next_child..next_child + count },
                area: node.area,
                cluster: tree.is_cluster(old),
                leaf: (node.children.is_empty() && leaf_index[old as usize] != NONE)
                    .then(|| leaf_index[old as usize]),
            });
            next_child += count;
        }
        let links = links
            .iter()
            .map(|l| NetworkLink {
                a: new_index[l.a as usize],
                b: new_index[l.b as usize],
                f_ab: l.f_ab,
                f_ba: l.f_ba,
            })
            .collect();
        LinkNetwork { nodes, links }
    }

    /// The links grouped by sender, in shooting form: `runs[s]` lists `(r, F_sr)` for every link at `s`, with
    /// `F_sr = A_r f_rs / A_s` the share of `s`'s power that reaches `r` (so `r`'s incident power grows by
    /// `F_sr` times the power `s` shoots), receivers in increasing order. By reciprocity `F_sr` is the link's
    /// form factor averaged over `s`, so a link gives each end the other's entry.
    pub fn sender_runs(&self) -> Vec<Vec<(u32, f64)>> {
        let mut runs = vec![Vec::new(); self.nodes.len()];
        for l in &self.links {
            runs[l.b as usize].push((l.a, l.f_ba));
            runs[l.a as usize].push((l.b, l.f_ab));
        }
        for run in &mut runs {
            run.sort_by_key(|&(r, _)| r);
        }
        runs
    }
}
