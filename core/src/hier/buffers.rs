//! The hierarchical solver's memory: [`HierBuffers`] (borrowed slices), [`HierBufferSizes`] (the one place
//! their lengths and their bytes are derived from a table), [`HierStaticBuffers`] (const-capacity storage for
//! firmware) and, with the `std` feature, [`HierOwnedBuffers`].
//!
//! What is stored, and why nothing else (the module docs of [`hier`](super) say how it is used):
//! - per leaf, its incident power `H_l` (reflectance edits need it; the leaf's power is computed from it on
//!   readout, `Phi_l = E_l A_l + rho_l H_l`, so it is not stored);
//! - per node, its unshot power (read for the nodes with links only), indexed by slot (leaves first, then the
//!   inner nodes, `docs/format.md`), so a link to a leaf writes the leaf's entries at one index;
//! - per inner node (a node with children), the irradiance its incoming links left pending for its subtree,
//!   and the power reflected by its children from links that reached them directly, pending for its chain;
//! - per level of the tree, one [`SweepFrame`]: a sweep's path from a root to the node it visits, which
//!   carries the chain sums down and the subtree sums up, so no node needs a buffer entry for them;
//! - per light group its intensity, per material its reflectance codes.
//!
//! Leaves are indexed by leaf index and inner nodes by inner index, `node - leaf_start(node)` (the inner
//! nodes before `node`), both read from the table, so no node-to-entry map takes RAM.

use crate::format::HierTable;
use crate::scalar::Scalar;

/// One node on the path of a sweep (root first): the node's slot, the irradiance summed down its chain since
/// the last sweep, and the power reflected in the part of its subtree visited so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepFrame<S> {
    pub(crate) slot: u32,
    /// The end of `node`'s subtree (the sweep leaves the node when it reaches it).
    pub(crate) end: u32,
    pub(crate) irradiance: [S; 3],
    pub(crate) reflected: [S; 3],
}

impl<S: Scalar> SweepFrame<S> {
    /// An unused frame (what buffers start with; a sweep overwrites a frame before it reads it).
    pub const EMPTY: SweepFrame<S> =
        SweepFrame { slot: 0, end: 0, irradiance: [S::ZERO; 3], reflected: [S::ZERO; 3] };
}

/// Caller-supplied buffers of a [`HierSolver`](super::HierSolver). Every slice must hold at least the count
/// [`HierBufferSizes::of`] names (extra elements are unused).
#[derive(Debug)]
pub struct HierBuffers<'b, S> {
    /// Incident power `H_l` received so far (RGB) per leaf, before reflection: [`HierBufferSizes::leaves`].
    pub incident: &'b mut [[S; 3]],
    /// Unshot power `U_n` (RGB) per node, indexed by slot ([`HierTable::slot`]): power reflected or emitted in
    /// the node's subtree and not yet shot through its links (read only for nodes with links):
    /// [`HierBufferSizes::nodes`].
    pub unshot: &'b mut [[S; 3]],
    /// Pending power (RGB) per inner node: what the node's incoming links delivered since the last sweep
    /// entered it (the sweep spreads it over the node's area): [`HierBufferSizes::inner`].
    pub pending: &'b mut [[S; 3]],
    /// Pending reflected power (RGB) per inner node: what its leaf children reflected from links that reached
    /// them directly since the last sweep entered it, still to be summed up its chain:
    /// [`HierBufferSizes::inner`].
    pub reflected: &'b mut [[S; 3]],
    /// A sweep's path, one frame per level: [`HierBufferSizes::depth`].
    pub path: &'b mut [SweepFrame<S>],
    /// Current intensity (RGB) per light group: [`HierBufferSizes::groups`].
    pub intensity: &'b mut [[S; 3]],
    /// Current reflectance codes (RGB) per material: [`HierBufferSizes::materials`].
    pub reflectance: &'b mut [[u16; 3]],
}

/// How many elements each hierarchical solver buffer needs for a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct HierBufferSizes {
    /// Leaves: [`HierBuffers::incident`].
    pub leaves: usize,
    /// Nodes: [`HierBuffers::unshot`].
    pub nodes: usize,
    /// Inner nodes (nodes with children, `nodes - leaves`): [`HierBuffers::pending`],
    /// [`HierBuffers::reflected`].
    pub inner: usize,
    /// Longest chain (a leaf and its ancestors, [`HierTable::max_depth`]): [`HierBuffers::path`].
    pub depth: usize,
    /// Light groups: [`HierBuffers::intensity`].
    pub groups: usize,
    /// Materials: [`HierBuffers::reflectance`].
    pub materials: usize,
}

impl HierBufferSizes {
    /// The sizes `table` needs.
    #[must_use]
    pub fn of(table: &HierTable<'_>) -> HierBufferSizes {
        HierBufferSizes {
            leaves: table.leaf_count() as usize,
            nodes: table.node_count() as usize,
            inner: table.node_count().saturating_sub(table.leaf_count()) as usize,
            depth: table.max_depth() as usize,
            groups: table.group_count() as usize,
            materials: table.material_count() as usize,
        }
    }

    /// Bytes of RAM the buffers take with arithmetic `S`:
    /// `rgb (leaves + nodes + 2 inner + groups) + frame depth + 6 materials`, `rgb` the size of `[S; 3]` and
    /// `frame` that of a [`SweepFrame`]: in f32 (12-byte `rgb`, 32-byte frame), 24 bytes per leaf and 36 per
    /// inner node.
    #[must_use]
    pub fn bytes<S>(&self) -> usize {
        let rgb = core::mem::size_of::<[S; 3]>();
        let frame = core::mem::size_of::<SweepFrame<S>>();
        (self.leaves + self.nodes + 2 * self.inner + self.groups) * rgb
            + self.depth * frame
            + self.materials * core::mem::size_of::<[u16; 3]>()
    }

    /// The first buffer of `buffers` shorter than these sizes: `(name, needed, given)`.
    pub(crate) fn shortfall<S>(&self, b: &HierBuffers<'_, S>) -> Option<(&'static str, u32, usize)> {
        let checks: [(&'static str, usize, usize); 7] = [
            ("incident", b.incident.len(), self.leaves),
            ("unshot", b.unshot.len(), self.nodes),
            ("pending", b.pending.len(), self.inner),
            ("reflected", b.reflected.len(), self.inner),
            ("path", b.path.len(), self.depth),
            ("intensity", b.intensity.len(), self.groups),
            ("reflectance", b.reflectance.len(), self.materials),
        ];
        checks
            .into_iter()
            .find(|&(_, got, needed)| got < needed)
            .map(|(name, got, needed)| (name, needed as u32, got))
    }
}

/// Hierarchical solver buffers with capacities fixed at compile time, for firmware: a table's
/// [`HierBufferSizes`] as constants, one generic per field of the same name (`LEAVES = leaves`,
/// `NODES = nodes`, `INNER = inner`, `DEPTH = depth`, `GROUPS = groups`,
/// `MATERIALS = materials`). `const`-constructible, so it can live in a `static`.
#[derive(Debug)]
pub struct HierStaticBuffers<
    S,
    const LEAVES: usize,
    const NODES: usize,
    const INNER: usize,
    const DEPTH: usize,
    const GROUPS: usize,
    const MATERIALS: usize,
> {
    incident: [[S; 3]; LEAVES],
    unshot: [[S; 3]; NODES],
    pending: [[S; 3]; INNER],
    reflected: [[S; 3]; INNER],
    path: [SweepFrame<S>; DEPTH],
    intensity: [[S; 3]; GROUPS],
    reflectance: [[u16; 3]; MATERIALS],
}

impl<
        S: Scalar,
        const LEAVES: usize,
        const NODES: usize,
        const INNER: usize,
        const DEPTH: usize,
        const GROUPS: usize,
        const MATERIALS: usize,
    > HierStaticBuffers<S, LEAVES, NODES, INNER, DEPTH, GROUPS, MATERIALS>
{
    /// Zeroed buffers.
    #[must_use]
    pub const fn new() -> Self {
        HierStaticBuffers {
            incident: [[S::ZERO; 3]; LEAVES],
            unshot: [[S::ZERO; 3]; NODES],
            pending: [[S::ZERO; 3]; INNER],
            reflected: [[S::ZERO; 3]; INNER],
            path: [SweepFrame::EMPTY; DEPTH],
            intensity: [[S::ZERO; 3]; GROUPS],
            reflectance: [[0; 3]; MATERIALS],
        }
    }

    /// The capacities, as [`HierBufferSizes`].
    #[must_use]
    pub const fn sizes(&self) -> HierBufferSizes {
        HierBufferSizes {
            leaves: LEAVES,
            nodes: NODES,
            inner: INNER,
            depth: DEPTH,
            groups: GROUPS,
            materials: MATERIALS,
        }
    }

    /// The buffers, borrowed for one solver.
    pub fn buffers(&mut self) -> HierBuffers<'_, S> {
        let HierStaticBuffers { incident, unshot, pending, reflected, path, intensity, reflectance } = self;
        HierBuffers { incident, unshot, pending, reflected, path, intensity, reflectance }
    }
}

impl<
        S: Scalar,
        const LEAVES: usize,
        const NODES: usize,
        const INNER: usize,
        const DEPTH: usize,
        const GROUPS: usize,
        const MATERIALS: usize,
    > Default for HierStaticBuffers<S, LEAVES, NODES, INNER, DEPTH, GROUPS, MATERIALS>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Hierarchical solver buffers on the heap (`std` feature only).
#[cfg(any(test, feature = "std"))]
#[derive(Clone, Debug)]
pub struct HierOwnedBuffers<S> {
    incident: std::vec::Vec<[S; 3]>,
    unshot: std::vec::Vec<[S; 3]>,
    pending: std::vec::Vec<[S; 3]>,
    reflected: std::vec::Vec<[S; 3]>,
    path: std::vec::Vec<SweepFrame<S>>,
    intensity: std::vec::Vec<[S; 3]>,
    reflectance: std::vec::Vec<[u16; 3]>,
}

#[cfg(any(test, feature = "std"))]
impl<S: Scalar> HierOwnedBuffers<S> {
    /// Zeroed buffers of `sizes`.
    #[must_use]
    pub fn new(sizes: HierBufferSizes) -> Self {
        HierOwnedBuffers {
            incident: std::vec![[S::ZERO; 3]; sizes.leaves],
            unshot: std::vec![[S::ZERO; 3]; sizes.nodes],
            pending: std::vec![[S::ZERO; 3]; sizes.inner],
            reflected: std::vec![[S::ZERO; 3]; sizes.inner],
            path: std::vec![SweepFrame::EMPTY; sizes.depth],
            intensity: std::vec![[S::ZERO; 3]; sizes.groups],
            reflectance: std::vec![[0; 3]; sizes.materials],
        }
    }

    /// Zeroed buffers of the sizes `table` needs.
    #[must_use]
    pub fn for_table(table: &HierTable<'_>) -> Self {
        Self::new(HierBufferSizes::of(table))
    }

    /// The buffers, borrowed for one solver.
    pub fn buffers(&mut self) -> HierBuffers<'_, S> {
        let HierOwnedBuffers { incident, unshot, pending, reflected, path, intensity, reflectance } = self;
        HierBuffers { incident, unshot, pending, reflected, path, intensity, reflectance }
    }

    /// Bytes these buffers hold with their current lengths, counted from the vectors themselves (a check on
    /// [`HierBufferSizes::bytes`]).
    #[must_use]
    pub fn held_bytes(&self) -> usize {
        core::mem::size_of_val(self.incident.as_slice())
            + core::mem::size_of_val(self.unshot.as_slice())
            + core::mem::size_of_val(self.pending.as_slice())
            + core::mem::size_of_val(self.reflected.as_slice())
            + core::mem::size_of_val(self.path.as_slice())
            + core::mem::size_of_val(self.intensity.as_slice())
            + core::mem::size_of_val(self.reflectance.as_slice())
    }
}
