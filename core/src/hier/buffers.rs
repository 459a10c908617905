//! The hierarchical solver's memory: [`HierBuffers`] (borrowed slices), [`HierBufferSizes`] (the one place
//! their lengths are derived from a table), [`HierStaticBuffers`] (const-capacity storage for firmware) and,
//! with the `std` feature, [`HierOwnedBuffers`].

use crate::format::HierTable;
use crate::scalar::Scalar;

/// Caller-supplied buffers of a [`HierSolver`](super::HierSolver). Every slice must hold at least the count
/// [`HierBufferSizes::of`] names (extra elements are unused).
#[derive(Debug)]
pub struct HierBuffers<'b, S> {
    /// Power `Phi_l = B_l A_l` (RGB) per leaf: [`HierBufferSizes::leaves`].
    pub power: &'b mut [[S; 3]],
    /// Incident power `H_l` received so far (RGB) per leaf, before reflection (reflectance edits need it):
    /// [`HierBufferSizes::leaves`].
    pub incident: &'b mut [[S; 3]],
    /// Unshot power `U_n` (RGB) per node: power reflected or emitted in the node's subtree and not yet shot
    /// through the node's own links: [`HierBufferSizes::nodes`].
    pub unshot: &'b mut [[S; 3]],
    /// Pending (RGB) per node: between sweeps, the irradiance (incident power per unit area) the node's links
    /// delivered since the last sweep; during a sweep's pull, the power reflected in its subtree:
    /// [`HierBufferSizes::nodes`].
    pub pending: &'b mut [[S; 3]],
    /// Current intensity (RGB) per light group: [`HierBufferSizes::groups`].
    pub intensity: &'b mut [[S; 3]],
    /// Current reflectance codes (RGB) per material: [`HierBufferSizes::materials`].
    pub reflectance: &'b mut [[u16; 3]],
}

/// How many elements each hierarchical solver buffer needs for a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct HierBufferSizes {
    /// Leaves: [`HierBuffers::power`], [`HierBuffers::incident`].
    pub leaves: usize,
    /// Nodes: [`HierBuffers::unshot`], [`HierBuffers::pending`].
    pub nodes: usize,
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
            groups: table.group_count() as usize,
            materials: table.material_count() as usize,
        }
    }

    /// Bytes of RAM the buffers take with arithmetic `S`.
    #[must_use]
    pub fn bytes<S>(&self) -> usize {
        let rgb = core::mem::size_of::<[S; 3]>();
        self.leaves * 2 * rgb + self.nodes * 2 * rgb + self.groups * rgb + self.materials * 6
    }

    /// The first buffer of `buffers` shorter than these sizes: `(name, needed, given)`.
    pub(crate) fn shortfall<S>(&self, b: &HierBuffers<'_, S>) -> Option<(&'static str, u32, usize)> {
        let checks: [(&'static str, usize, usize); 6] = [
            ("power", b.power.len(), self.leaves),
            ("incident", b.incident.len(), self.leaves),
            ("unshot", b.unshot.len(), self.nodes),
            ("pending", b.pending.len(), self.nodes),
            ("intensity", b.intensity.len(), self.groups),
            ("reflectance", b.reflectance.len(), self.materials),
        ];
        checks
            .into_iter()
            .find(|&(_, got, needed)| got < needed)
            .map(|(name, got, needed)| (name, needed as u32, got))
    }
}

/// Hierarchical solver buffers with capacities fixed at compile time, for firmware (a table's
/// [`HierBufferSizes`] as constants). `const`-constructible, so it can live in a `static`.
#[derive(Debug)]
pub struct HierStaticBuffers<
    S,
    const LEAVES: usize,
    const NODES: usize,
    const GROUPS: usize,
    const MATERIALS: usize,
> {
    power: [[S; 3]; LEAVES],
    incident: [[S; 3]; LEAVES],
    unshot: [[S; 3]; NODES],
    pending: [[S; 3]; NODES],
    intensity: [[S; 3]; GROUPS],
    reflectance: [[u16; 3]; MATERIALS],
}

impl<S: Scalar, const LEAVES: usize, const NODES: usize, const GROUPS: usize, const MATERIALS: usize>
    HierStaticBuffers<S, LEAVES, NODES, GROUPS, MATERIALS>
{
    /// Zeroed buffers.
    #[must_use]
    pub const fn new() -> Self {
        HierStaticBuffers {
            power: [[S::ZERO; 3]; LEAVES],
            incident: [[S::ZERO; 3]; LEAVES],
            unshot: [[S::ZERO; 3]; NODES],
            pending: [[S::ZERO; 3]; NODES],
            intensity: [[S::ZERO; 3]; GROUPS],
            reflectance: [[0; 3]; MATERIALS],
        }
    }

    /// The capacities, as [`HierBufferSizes`].
    #[must_use]
    pub const fn sizes(&self) -> HierBufferSizes {
        HierBufferSizes { leaves: LEAVES, nodes: NODES, groups: GROUPS, materials: MATERIALS }
    }

    /// The buffers, borrowed for one solver.
    pub fn buffers(&mut self) -> HierBuffers<'_, S> {
        let HierStaticBuffers { power, incident, unshot, pending, intensity, reflectance } = self;
        HierBuffers { power, incident, unshot, pending, intensity, reflectance }
    }
}

impl<S: Scalar, const LEAVES: usize, const NODES: usize, const GROUPS: usize, const MATERIALS: usize> Default
    for HierStaticBuffers<S, LEAVES, NODES, GROUPS, MATERIALS>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Hierarchical solver buffers on the heap (`std` feature only).
#[cfg(any(test, feature = "std"))]
#[derive(Clone, Debug)]
pub struct HierOwnedBuffers<S> {
    power: std::vec::Vec<[S; 3]>,
    incident: std::vec::Vec<[S; 3]>,
    unshot: std::vec::Vec<[S; 3]>,
    pending: std::vec::Vec<[S; 3]>,
    intensity: std::vec::Vec<[S; 3]>,
    reflectance: std::vec::Vec<[u16; 3]>,
}

#[cfg(any(test, feature = "std"))]
impl<S: Scalar> HierOwnedBuffers<S> {
    /// Zeroed buffers of `sizes`.
    #[must_use]
    pub fn new(sizes: HierBufferSizes) -> Self {
        HierOwnedBuffers {
            power: std::vec![[S::ZERO; 3]; sizes.leaves],
            incident: std::vec![[S::ZERO; 3]; sizes.leaves],
            unshot: std::vec![[S::ZERO; 3]; sizes.nodes],
            pending: std::vec![[S::ZERO; 3]; sizes.nodes],
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
        let HierOwnedBuffers { power, incident, unshot, pending, intensity, reflectance } = self;
        HierBuffers { power, incident, unshot, pending, intensity, reflectance }
    }
}
