//! The element tree: surface nodes (a face polygon and its subdivisions, made on demand) below clusters (a
//! bounding-volume hierarchy over the face polygons). Every node's parent has a smaller index, so one pass in
//! index order pushes from parents to children and one in reverse order pulls from children to parents.

use glam::DVec3;

use crate::formfactor::{Element, ElementRules};
use crate::mesh::{refine, MeshError};
use crate::patch::Patch;
use crate::rgb::{channel_max, Rgb};
use crate::rng::SplitMix64;
use crate::scene::bounding_box;

/// No node (the parent of a top node).
pub(super) const NONE: u32 = u32::MAX;

/// What a node is.
#[derive(Clone)]
pub(super) enum Kind {
    /// A group of face polygons: those at `order[first..end]` of the tree.
    Cluster { first: usize, end: usize },
    /// A planar convex piece of one face polygon, with its material's reflectance and emission.
    Surface { element: Box<Element>, rho: Rgb, emission: Rgb },
}

/// One node of the tree.
#[derive(Clone)]
pub(super) struct Node {
    /// The parent node, or [`NONE`].
    pub(super) parent: u32,
    /// The children (empty for a leaf); every child has a larger index than its parent.
    pub(super) children: Vec<u32>,
    /// Cluster or surface.
    pub(super) kind: Kind,
    /// Surface area (the sum over the polygons of a cluster).
    pub(super) area: f64,
    /// Centre and radius of a sphere holding the node.
    pub(super) center: DVec3,
    /// See `center`.
    pub(super) radius: f64,
    /// Largest reflectance per channel of any surface in the node.
    pub(super) rho_max: Rgb,
    /// The face polygon (index into the roots) a surface was cut from; [`NONE`] for a cluster.
    pub(super) root: u32,
    /// The node's name, whatever order refinement made it in: its index for the nodes made with the tree, and
    /// a hash of its parent's key and its place among the children for pieces ([`child_key`]). Random streams
    /// are keyed by it, so a pair's estimate does not depend on when (or in which piece) its nodes were made.
    pub(super) key: u64,
}

impl Node {
    /// The node's element if it is a surface.
    pub(super) fn element(&self) -> Option<&Element> {
        match &self.kind {
            Kind::Surface { element, .. } => Some(element),
            Kind::Cluster { .. } => None,
        }
    }
}

/// The key of child `k` of a node with key `parent` (the SplitMix64 finalizer of the two mixed, so that
/// children's keys do not collide with the small keys of the tree's first nodes or with each other's).
pub(super) fn child_key(parent: u64, k: usize) -> u64 {
    let mut z = parent.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k as u64 + 1);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The tree over a scene's face polygons.
#[derive(Clone)]
pub(super) struct Tree {
    /// All nodes; node 0 is the top.
    pub(super) nodes: Vec<Node>,
    /// The top-level surface node of every face polygon, in the order clusters cover them (each cluster covers a
    /// contiguous range).
    order: Vec<u32>,
    /// `prefix[k]`: the area of `order[..k]`, for sampling a cluster by area.
    prefix: Vec<f64>,
    /// The bounding box (least and greatest corner) of every node made with the tree (the clusters and the face
    /// polygons, which come before any node that refinement makes), for shaft culling.
    pub(super) boxes: Vec<(DVec3, DVec3)>,
}

/// The sphere around a point set: its bounding box's centre and half diagonal.
fn bounding_sphere<'a>(points: impl Iterator<Item = &'a DVec3>) -> (DVec3, f64) {
    let (lo, hi) = bounding_box(points.copied());
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

impl Tree {
    /// The tree over `roots` (one patch per face polygon) with their reflectance and emission: clusters split at
    /// the median centroid along the longest axis of their centroids' bounding box, down to single polygons.
    pub(super) fn new(rules: &ElementRules, roots: &[Patch], rho: &[Rgb], emission: &[Rgb]) -> Tree {
        let mut tree =
            Tree { nodes: Vec::new(), order: vec![NONE; roots.len()], prefix: Vec::new(), boxes: Vec::new() };
        let mut ids: Vec<usize> = (0..roots.len()).collect();
        tree.build(rules, roots, rho, emission, &mut ids, 0, NONE);
        let mut area = 0.0;
        tree.prefix.push(0.0);
        for &n in &tree.order {
            area += tree.nodes[n as usize].area;
            tree.prefix.push(area);
        }
        tree
    }

    /// Builds the subtree over `ids` (at `order[first..first + ids.len()]`) below `parent`; returns its index.
    #[allow(clippy::too_many_arguments)]
    fn build(
        &mut self,
        rules: &ElementRules,
        roots: &[Patch],
        rho: &[Rgb],
        emission: &[Rgb],
        ids: &mut [usize],
        first: usize,
        parent: u32,
    ) -> u32 {
        let index = self.nodes.len() as u32;
        if let [root] = ids {
            let patch = &roots[*root];
            let (center, radius) = bounding_sphere(patch.vertices.iter());
            self.boxes.push(bounding_box(patch.vertices.iter().copied()));
            self.nodes.push(Node {
                parent,
                children: Vec::new(),
                kind: Kind::Surface {
                    element: Box::new(rules.element(patch.clone())),
                    rho: rho[*root],
                    emission: emission[*root],
                },
                area: patch.area,
                center,
                radius,
                rho_max: rho[*root],
                root: *root as u32,
                key: u64::from(index),
            });
            self.order[first] = index;
            return index;
        }
        let (center, radius) = bounding_sphere(ids.iter().flat_map(|&k| roots[k].vertices.iter()));
        self.boxes.push(bounding_box(ids.iter().flat_map(|&k| roots[k].vertices.iter().copied())));
        self.nodes.push(Node {
            parent,
            children: Vec::new(),
            kind: Kind::Cluster { first, end: first + ids.len() },
            area: 0.0,
            center,
            radius,
            rho_max: Rgb::ZERO,
            root: NONE,
            key: u64::from(index),
        });
        let (lo, hi) = bounding_box(ids.iter().map(|&k| roots[k].centroid));
        let axis = (hi - lo).max_position();
        let mid = ids.len() / 2;
        // Ties broken by index so that the split depends on the input only.
        ids.select_nth_unstable_by(mid, |&a, &b| {
            roots[a].centroid[axis].total_cmp(&roots[b].centroid[axis]).then(a.cmp(&b))
        });
        let (left, right) = ids.split_at_mut(mid);
        let a = self.build(rules, roots, rho, emission, left, first, index);
        let b = self.build(rules, roots, rho, emission, right, first + mid, index);
        let area = self.nodes[a as usize].area + self.nodes[b as usize].area;
        let rho_max = channel_max(self.nodes[a as usize].rho_max, self.nodes[b as usize].rho_max);
        let node = &mut self.nodes[index as usize];
        node.children = vec![a, b];
        node.area = area;
        node.rho_max = rho_max;
        index
    }

    /// Whether `n` is a cluster.
    pub(super) fn is_cluster(&self, n: u32) -> bool {
        matches!(self.nodes[n as usize].kind, Kind::Cluster { .. })
    }

    /// Splits surface `n` into its children (edge midpoints of a triangle, a 2 x 2 grid of a quadrilateral, a
    /// quadrilateral per vertex of a larger polygon), if it has none yet; returns whether it has children now.
    /// Clusters always have children.
    ///
    /// # Errors
    /// [`MeshError::ZeroAreaPatch`] if a child degenerates.
    pub(super) fn split(&mut self, rules: &ElementRules, n: u32) -> Result<(), MeshError> {
        let node = &self.nodes[n as usize];
        if !node.children.is_empty() {
            return Ok(());
        }
        let Kind::Surface { element, rho, emission } = &node.kind else { return Ok(()) };
        let (rho, emission, root, key) = (*rho, *emission, node.root, node.key);
        let pieces = refine(std::slice::from_ref(element.patch()), &[0])?;
        let first = self.nodes.len() as u32;
        for (k, piece) in pieces.into_iter().enumerate() {
            let (center, radius) = bounding_sphere(piece.vertices.iter());
            self.nodes.push(Node {
                parent: n,
                children: Vec::new(),
                area: piece.area,
                center,
                radius,
                rho_max: rho,
                root,
                kind: Kind::Surface { element: Box::new(rules.element(piece)), rho, emission },
                key: child_key(key, k),
            });
        }
        let end = self.nodes.len() as u32;
        self.nodes[n as usize].children = (first..end).collect();
        Ok(())
    }

    /// Renumbers the nodes from `first` on (those made since the tree had `first` nodes) into the order that
    /// does not depend on the order of the splits that made them: generation by generation, the children of the
    /// older nodes by their parent's index, each parent's children in their own order. Every parent still
    /// precedes its children, and a parent's children stay contiguous. Returns the old index of each new place
    /// (`order[k - first]` is the node that is now `k`), for the caller to move what it keeps per node.
    pub(super) fn renumber_from(&mut self, first: usize) -> Vec<u32> {
        let count = self.nodes.len() - first;
        let mut order: Vec<u32> = Vec::with_capacity(count);
        // The first generation: children of nodes made before `first`, in their parents' index order.
        for n in 0..first {
            order.extend(self.nodes[n].children.iter().copied().filter(|&c| c as usize >= first));
        }
        let mut next = 0;
        while next < order.len() {
            let end = order.len();
            for k in next..end {
                let n = order[k] as usize;
                order.extend_from_slice(&self.nodes[n].children);
            }
            next = end;
        }
        debug_assert_eq!(order.len(), count, "every new node descends from an older one");
        let mut new_index: Vec<u32> = (0..self.nodes.len() as u32).collect();
        for (k, &old) in order.iter().enumerate() {
            new_index[old as usize] = (first + k) as u32;
        }
        let mut moved: Vec<Option<Node>> = self.nodes.drain(first..).map(Some).collect();
        for &old in &order {
            let node = moved[old as usize - first].take().expect("each node is placed once");
            self.nodes.push(node);
        }
        for node in &mut self.nodes {
            if node.parent != NONE {
                node.parent = new_index[node.parent as usize];
            }
            for c in &mut node.children {
                *c = new_index[*c as usize];
            }
        }
        order
    }

    /// An area-uniform random point of node `n` with the surface normal there.
    pub(super) fn sample(&self, n: u32, rng: &mut SplitMix64) -> (DVec3, DVec3) {
        let element = match &self.nodes[n as usize].kind {
            Kind::Surface { element, .. } => element,
            Kind::Cluster { first, end } => {
                let (a, b) = (self.prefix[*first], self.prefix[*end]);
                let target = a + rng.unit() * (b - a);
                // The first polygon whose running area passes the target.
                let k = self.prefix[first + 1..=*end].partition_point(|&p| p <= target).min(end - first - 1);
                match &self.nodes[self.order[first + k] as usize].kind {
                    Kind::Surface { element, .. } => element,
                    Kind::Cluster { .. } => unreachable!("order holds surface nodes only"),
                }
            }
        };
        let (s, t) = (rng.open_unit(), rng.open_unit());
        (element.point(s, t), element.patch().normal)
    }

    /// Whether `a` lies wholly behind the plane of surface `b` (a sphere test), so that they exchange nothing.
    pub(super) fn behind(&self, a: u32, b: u32) -> bool {
        let (a, b) = (&self.nodes[a as usize], &self.nodes[b as usize]);
        match b.element() {
            Some(e) => {
                let p = e.patch();
                p.normal.dot(a.center - p.centroid) <= -a.radius
            }
            None => false,
        }
    }
}
