//! The solver's memory: [`Buffers`] (borrowed slices), [`BufferSizes`] (the one place their lengths are
//! derived from a table), [`StaticBuffers`] (const-capacity storage for firmware) and, with the `std` feature,
//! [`OwnedBuffers`] (heap storage for host code and tests).

use crate::format::Table;
use crate::scalar::Scalar;

/// Caller-supplied buffers. Every slice must hold at least the count [`BufferSizes::of`] the table names
/// (extra elements are unused).
///
/// Per-patch state exists only for the patches with run-time state, the table's slots
/// ([`Table::state_count`], crate docs "Run-time state"); the other patches show their static base.
#[derive(Debug)]
pub struct Buffers<'b, S> {
    /// Power `Phi_i = B_i A_i` (RGB) per slot: [`BufferSizes::slots`].
    pub power: &'b mut [[S; 3]],
    /// Unshot power (RGB) per slot: [`BufferSizes::slots`].
    pub unshot: &'b mut [[S; 3]],
    /// Incident power `H_i = sum_j F_ji Phi_j` received so far (RGB) per slot, before reflection:
    /// [`BufferSizes::slots`]. Reflectance edits need it.
    pub incident: &'b mut [[S; 3]],
    /// Selection: the slot with the largest unshot power of each block of consecutive slots
    /// ([`BufferSizes::selection`], about the square root of the slots).
    pub selection: &'b mut [u32],
    /// Current intensity (RGB) per light group: [`BufferSizes::groups`].
    pub intensity: &'b mut [[S; 3]],
    /// Current reflectance codes (RGB) per material: [`BufferSizes::materials`].
    pub reflectance: &'b mut [[u16; 3]],
}

/// How many elements each solver buffer needs for a table. Every buffer size in the project (host, tests,
/// the firmware's build script) comes from here.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct BufferSizes {
    /// Slots, the patches with run-time state: [`Buffers::power`], [`Buffers::unshot`],
    /// [`Buffers::incident`], and the scratch buffer of [`Solver::step_jacobi`](crate::Solver::step_jacobi).
    pub slots: usize,
    /// Selection block winners ([`Buffers::selection`]): [`selection_len`] of the slots.
    pub selection: usize,
    /// Light groups ([`Buffers::intensity`]).
    pub groups: usize,
    /// Materials ([`Buffers::reflectance`]).
    pub materials: usize,
}

impl BufferSizes {
    /// The sizes `table` needs.
    #[must_use]
    pub fn of(table: &Table<'_>) -> BufferSizes {
        BufferSizes {
            slots: table.state_count() as usize,
            selection: selection_len(table.state_count()) as usize,
            groups: table.group_count() as usize,
            materials: table.material_count() as usize,
        }
    }

    /// Bytes of RAM the buffers take with arithmetic `S` (the Jacobi scratch buffer not included).
    #[must_use]
    pub fn bytes<S>(&self) -> usize {
        let rgb = core::mem::size_of::<[S; 3]>();
        self.slots * 3 * rgb + self.selection * 4 + self.groups * rgb + self.materials * 6
    }

    /// The first buffer of `buffers` shorter than these sizes: `(name, needed, given)`.
    pub(crate) fn shortfall<S>(&self, buffers: &Buffers<'_, S>) -> Option<(&'static str, u32, usize)> {
        let checks: [(&'static str, usize, usize); 6] = [
            ("power", buffers.power.len(), self.slots),
            ("unshot", buffers.unshot.len(), self.slots),
            ("incident", buffers.incident.len(), self.slots),
            ("selection", buffers.selection.len(), self.selection),
            ("intensity", buffers.intensity.len(), self.groups),
            ("reflectance", buffers.reflectance.len(), self.materials),
        ];
        checks
            .into_iter()
            .find(|&(_, got, needed)| got < needed)
            .map(|(name, got, needed)| (name, needed as u32, got))
    }
}

/// Length of the [`Buffers::selection`] buffer for `state_count` slots: one selection block winner per block
/// of `B` consecutive slots, `B` the smallest power of two with `B * B >= state_count` (about `sqrt(n)`
/// entries).
#[must_use]
pub const fn selection_len(state_count: u32) -> u32 {
    state_count.div_ceil(1 << block_shift(state_count))
}

/// Selection block size exponent for `n` slots: the smallest `B = 2^shift` with `B * B >= n`, so a selection
/// scan (`ceil(n / B)` winners) and a block rescan (`B` slots) both cost about `sqrt(n)`.
pub(crate) const fn block_shift(n: u32) -> u32 {
    let mut shift = 0;
    while (1u64 << (2 * shift)) < n as u64 {
        shift += 1;
    }
    shift
}

/// Solver buffers with capacities fixed at compile time, for firmware: `SLOTS`, `SELECTION`, `GROUPS` and
/// `MATERIALS` are a table's [`BufferSizes`] (a build script writes them as constants). Place it in a
/// `static` (it is `const`-constructible) so the RAM shows in the link map.
#[derive(Debug)]
pub struct StaticBuffers<
    S,
    const SLOTS: usize,
    const SELECTION: usize,
    const GROUPS: usize,
    const MATERIALS: usize,
> {
    power: [[S; 3]; SLOTS],
    unshot: [[S; 3]; SLOTS],
    incident: [[S; 3]; SLOTS],
    selection: [u32; SELECTION],
    intensity: [[S; 3]; GROUPS],
    reflectance: [[u16; 3]; MATERIALS],
}

impl<S: Scalar, const SLOTS: usize, const SELECTION: usize, const GROUPS: usize, const MATERIALS: usize>
    StaticBuffers<S, SLOTS, SELECTION, GROUPS, MATERIALS>
{
    /// Zeroed buffers.
    #[must_use]
    pub const fn new() -> Self {
        StaticBuffers {
            power: [[S::ZERO; 3]; SLOTS],
            unshot: [[S::ZERO; 3]; SLOTS],
            incident: [[S::ZERO; 3]; SLOTS],
            selection: [0; SELECTION],
            intensity: [[S::ZERO; 3]; GROUPS],
            reflectance: [[0; 3]; MATERIALS],
        }
    }

    /// The capacities, as [`BufferSizes`] (compare with [`BufferSizes::of`] of the table to be run).
    #[must_use]
    pub const fn sizes(&self) -> BufferSizes {
        BufferSizes { slots: SLOTS, selection: SELECTION, groups: GROUPS, materials: MATERIALS }
    }

    /// The buffers, borrowed for one solver.
    pub fn buffers(&mut self) -> Buffers<'_, S> {
        let StaticBuffers { power, unshot, incident, selection, intensity, reflectance } = self;
        Buffers { power, unshot, incident, selection, intensity, reflectance }
    }
}

impl<S: Scalar, const SLOTS: usize, const SELECTION: usize, const GROUPS: usize, const MATERIALS: usize>
    Default for StaticBuffers<S, SLOTS, SELECTION, GROUPS, MATERIALS>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Solver buffers on the heap, sized for one table: the host's and the tests' storage (`std` feature only;
/// the device uses [`StaticBuffers`] or its own slices).
#[cfg(any(test, feature = "std"))]
#[derive(Clone, Debug)]
pub struct OwnedBuffers<S> {
    power: std::vec::Vec<[S; 3]>,
    unshot: std::vec::Vec<[S; 3]>,
    incident: std::vec::Vec<[S; 3]>,
    selection: std::vec::Vec<u32>,
    intensity: std::vec::Vec<[S; 3]>,
    reflectance: std::vec::Vec<[u16; 3]>,
}

#[cfg(any(test, feature = "std"))]
impl<S: Scalar> OwnedBuffers<S> {
    /// Zeroed buffers of `sizes`.
    #[must_use]
    pub fn new(sizes: BufferSizes) -> Self {
        OwnedBuffers {
            power: std::vec![[S::ZERO; 3]; sizes.slots],
            unshot: std::vec![[S::ZERO; 3]; sizes.slots],
            incident: std::vec![[S::ZERO; 3]; sizes.slots],
            selection: std::vec![0; sizes.selection],
            intensity: std::vec![[S::ZERO; 3]; sizes.groups],
            reflectance: std::vec![[0; 3]; sizes.materials],
        }
    }

    /// Zeroed buffers of the sizes `table` needs.
    #[must_use]
    pub fn for_table(table: &Table<'_>) -> Self {
        Self::new(BufferSizes::of(table))
    }

    /// The buffers, borrowed for one solver.
    pub fn buffers(&mut self) -> Buffers<'_, S> {
        let OwnedBuffers { power, unshot, incident, selection, intensity, reflectance } = self;
        Buffers { power, unshot, incident, selection, intensity, reflectance }
    }
}
