//! The solved hierarchy as data: the tree renumbered in preorder (every node before its subtree, each subtree a
//! contiguous range of nodes, so the leaves below a node are contiguous too) and its links, which is what a device
//! table is written from and what a solve outside this module can run on.

use super::link::Link;
use super::tree::{Tree, NONE};

/// A node of [`LinkNetwork`].
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkNode {
    /// The parent, `None` for the top node (node 0); always a smaller index than the node.
    pub parent: Option<u32>,
    /// One past the last node of the subtree: the node's descendants are the nodes after it up to here (none
    /// for a leaf, whose `subtree_end` is its index plus one).
    pub subtree_end: u32,
    /// Surface area (for a cluster, the sum over its surfaces).
    pub area: f64,
    /// Whether the node is a cluster (receives isotropically: every surface below it gets the same irradiance).
    pub cluster: bool,
    /// For a leaf, its index in [`super::HierarchicalSolution::leaves`] (and `rho`, `emission`, `b`).
    pub leaf: Option<u32>,
}

/// A link of [`LinkNetwork`]: `a` gathers `f_ab * B_b` per unit area and `b` gathers `f_ba * B_a`, with
/// `A_a f_ab = A_b f_ba` (reciprocity). In shooting terms (see [`LinkNetwork::sender_runs`]), `A_a f_ab / A_b` is
/// the share of `b`'s power that reaches `a`, and `A_b f_ba / A_a` the share of `a`'s that reaches `b`.
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
    /// Nodes, in preorder from the top (children in the solver's order).
    pub nodes: Vec<NetworkNode>,
    /// Links, in the solve's order, between nodes of [`Self::nodes`].
    pub links: Vec<NetworkLink>,
}

impl LinkNetwork {
    /// The network of `tree` and `links`, with `leaf_index[n]` the answer's index of leaf node `n`.
    pub(super) fn new(tree: &Tree, links: &[Link], leaf_index: &[u32]) -> LinkNetwork {
        // Preorder by an explicit stack (children pushed in reverse so the first child comes out first).
        let mut order: Vec<u32> = Vec::with_capacity(tree.nodes.len());
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            order.push(n);
            stack.extend(tree.nodes[n as usize].children.iter().rev());
        }
        let mut new_index = vec![NONE; tree.nodes.len()];
        for (k, &old) in order.iter().enumerate() {
            new_index[old as usize] = k as u32;
        }
        let mut nodes: Vec<NetworkNode> = order
            .iter()
            .enumerate()
            .map(|(k, &old)| {
                let node = &tree.nodes[old as usize];
                NetworkNode {
                    parent: (node.parent != NONE).then(|| new_index[node.parent as usize]),
                    subtree_end: k as u32 + 1,
                    area: node.area,
                    cluster: tree.is_cluster(old),
                    leaf: (node.children.is_empty() && leaf_index[old as usize] != NONE)
                        .then(|| leaf_index[old as usize]),
                }
            })
            .collect();
        // Children come after their parents: a reverse pass carries every subtree's end up.
        for k in (1..nodes.len()).rev() {
            let (end, parent) = (nodes[k].subtree_end, nodes[k].parent);
            if let Some(p) = parent {
                let p = &mut nodes[p as usize];
                p.subtree_end = p.subtree_end.max(end);
            }
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

    /// The children of node `n`, in order: the first follows `n`, each next one follows the previous one's
    /// subtree.
    pub fn children(&self, n: u32) -> impl Iterator<Item = u32> + '_ {
        let end = self.nodes[n as usize].subtree_end;
        std::iter::successors(Some(n + 1).filter(|&c| c < end), move |&c| {
            Some(self.nodes[c as usize].subtree_end).filter(|&next| next < end)
        })
    }

    /// The links grouped by sender, in shooting form: `runs[s]` lists `(r, F_sr)` for every link at `s`, with
    /// `F_sr = A_r f_rs / A_s` the share of `s`'s power that reaches `r` (so `r`'s incident power grows by `F_sr`
    /// times the power `s` shoots), receivers in increasing order. Taken from the receiver's own factor, so that
    /// shooting reproduces the gathering system exactly whether or not a link's two estimates are reciprocal.
    pub fn sender_runs(&self) -> Vec<Vec<(u32, f64)>> {
        let mut runs = vec![Vec::new(); self.nodes.len()];
        for l in &self.links {
            let (area_a, area_b) = (self.nodes[l.a as usize].area, self.nodes[l.b as usize].area);
            runs[l.b as usize].push((l.a, l.f_ab * area_a / area_b));
            runs[l.a as usize].push((l.b, l.f_ba * area_b / area_a));
        }
        for run in &mut runs {
            run.sort_by_key(|&(r, _)| r);
        }
        runs
    }
}
