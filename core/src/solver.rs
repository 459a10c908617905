//! Solver state in caller-supplied buffers, bounded steps (shooting, Gauss-Seidel, Jacobi) and relighting.
//!
//! The state is [`Solver`], generic over the arithmetic ([`Scalar`]: `f32` or [`Fixed`](crate::Fixed)). It
//! borrows every buffer from the caller ([`Buffers`]), sized by the table's counts; nothing is allocated and
//! nothing is sized for a worst case. Each step takes a budget in work units (see the crate docs, "Cost
//! model") and never spends more.

use core::fmt;

use crate::codec::{decode_emission, decode_reflectance, encode_reflectance, Frac};
use crate::scalar::Scalar;
use crate::table::Table;

/// Caller-supplied buffers. Every slice must hold at least the count named (extra elements are unused).
///
/// Per-patch state exists only for the patches with run-time state, the table's slots
/// ([`Table::state_count`], crate docs "Run-time state"); the other patches show their static base.
#[derive(Debug)]
pub struct Buffers<'b, S> {
    /// Power `Phi_i = B_i A_i` (RGB) per slot: state count.
    pub power: &'b mut [[S; 3]],
    /// Unshot power (RGB) per slot: state count.
    pub unshot: &'b mut [[S; 3]],
    /// Incident power `H_i = sum_j F_ji Phi_j` received so far (RGB) per slot, before reflection: state count.
    /// Reflectance edits need it.
    pub incident: &'b mut [[S; 3]],
    /// Selection: the slot with the largest unshot power of each block of consecutive slots, the length
    /// [`selection_len`] of the state count (about its square root).
    pub tree: &'b mut [u32],
    /// Current intensity (RGB) per light group: light group count.
    pub intensity: &'b mut [[S; 3]],
    /// Current reflectance codes (RGB) per material: material count.
    pub reflectance: &'b mut [[u16; 3]],
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config<S> {
    /// Converged when every patch's unshot power magnitude (`|r| + |g| + |b|`, power units) is at most this.
    /// [`Solver::new`] refuses a tolerance below the arithmetic's convergence floor for the table
    /// ([`SolverError::ToleranceBelowFloor`]; zero for f32). Reflectances raised later with `set_reflectance`
    /// raise the floor without a check.
    pub tolerance: S,
    /// Overshooting: a shot sends `(1 + overshoot / 256)` times the unshot power and leaves the excess as
    /// negative unshot power (0 = plain progressive refinement). Shooting only.
    pub overshoot: u8,
}

impl<S> Config<S> {
    /// The overshoot to use unless a measurement says otherwise: `64 / 256`, a relaxation factor of 1.25.
    ///
    /// Measured by `radiosity bench` (`bench/REPORT.md`): to reach 1% error, shooting with this overshoot needs
    /// 0.77 times the instructions of plain shooting on the Cornell box at 250, 1,000 and 4,000 patches and 0.59
    /// times on the white furnace at rho = 0.9, with the same converged error; the crate-level table shows the
    /// same on a closed cube (1,405,453 against 2,760,817 work units). Overshooting leaves negative unshot power
    /// behind, which later shots send back; convergence is still judged on the unshot magnitude.
    pub const RECOMMENDED_OVERSHOOT: u8 = 64;
}

/// What a step did, and what the caller should do next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use]
pub enum Outcome {
    /// Every patch's unshot power is within the tolerance. Further steps do nothing until a light or
    /// reflectance changes.
    Converged {
        /// Work units used.
        used: u32,
    },
    /// The budget ran out before convergence: call again with more budget (next frame).
    BudgetSpent {
        /// Work units used (never more than the budget).
        used: u32,
    },
    /// The step cannot make progress; more budget of the same kind will not help unless the reason says so.
    NoProgress {
        /// Work units used.
        used: u32,
        /// Why.
        reason: NoProgressReason,
    },
}

impl Outcome {
    /// Work units used.
    #[must_use]
    pub fn used(self) -> u32 {
        match self {
            Outcome::Converged { used }
            | Outcome::BudgetSpent { used }
            | Outcome::NoProgress { used, .. } => used,
        }
    }
}

/// Why a step made no progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoProgressReason {
    /// The budget is smaller than the smallest indivisible action (an entry with its block rescan, a block
    /// rebuild, a selection scan or a shot start).
    BudgetTooSmall {
        /// Units the next action needs.
        needed: u32,
    },
    /// The largest unshot power is not finite (f32) or saturated (fixed point): the state has overflowed.
    NotFinite,
    /// The table is not the one the solver was created with (CRC or counts differ).
    WrongTable,
    /// A Jacobi sweep is half done: finish it with [`Solver::step_jacobi`] before shooting or Gauss-Seidel.
    JacobiInProgress,
    /// The Jacobi scratch buffer is shorter than the state count.
    ScratchTooSmall,
}

/// Why the solver cannot be created or a change cannot be applied.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum SolverError {
    /// A buffer is shorter than the table needs.
    BufferTooSmall {
        /// Which buffer.
        buffer: &'static str,
        /// Elements needed.
        needed: u32,
        /// Elements given.
        got: usize,
    },
    /// The light group does not exist.
    NoSuchGroup {
        /// The group asked for.
        group: u32,
    },
    /// The material does not exist.
    NoSuchMaterial {
        /// The material asked for.
        material: u32,
    },
    /// An intensity is not finite, or a reflectance not in `[0, 1)`.
    BadValue {
        /// Channel (0 = red, 1 = green, 2 = blue).
        channel: u8,
    },
    /// The table is not the one the solver was created with.
    WrongTable,
    /// A Jacobi sweep is half done; changes would be lost by its end-of-sweep copy.
    JacobiInProgress,
    /// More patches with state than the solver supports ([`MAX_PATCHES`]).
    TooManyPatches {
        /// Patches with state in the table.
        patches: u32,
    },
    /// The tolerance is below the arithmetic's convergence floor for this table ([`Scalar::convergence_floor`]:
    /// fixed point rounds every receipt to its resolution, so unshot power cannot be driven below about
    /// `6 L 2^-32 / (1 - rho_max)`; the solver would shoot forever). Raise the tolerance or scale the units.
    ToleranceBelowFloor {
        /// The tolerance asked for, as f32.
        tolerance: f32,
        /// The floor, as f32.
        floor: f32,
    },
}

/// The smallest tolerance [`Solver::new`] accepts for `table` on arithmetic `S`: [`Scalar::convergence_floor`]
/// of `ceil(6 L / (1 - rho_max))`, `L` the longest row and `rho_max` the largest reflectance of any material and
/// channel (the convergence condition in the `scalar` module docs). Zero for f32. O(patches + materials).
#[must_use]
pub fn convergence_floor<S: Scalar>(table: &Table<'_>) -> S {
    S::convergence_floor(convergence_units(table))
}

/// `ceil(6 L / (1 - rho_max))` in integer arithmetic (`1 - rho_max >= 2^-16`).
fn convergence_units(table: &Table<'_>) -> u64 {
    let longest =
        (0..table.state_count()).filter_map(|i| table.row(i)).map(|r| r.len() as u64).max().unwrap_or(0);
    let code_max = (0..table.material_count())
        .filter_map(|m| table.reflectance(m))
        .flat_map(|r| r.into_iter())
        .max()
        .map_or(0, u64::from);
    // 1 - rho_max = (65536 - code_max) / 65536, with code_max <= 65535.
    (6 * longest * 65536).div_ceil(65536 - code_max.min(65535))
}

/// Largest state count the solver accepts.
pub const MAX_PATCHES: u32 = 1 << 30;

impl fmt::Display for SolverError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SolverError::BufferTooSmall { buffer, needed, got } => {
                write!(f, "solver buffer `{buffer}` too small: {got} elements, need {needed}")
            }
            SolverError::NoSuchGroup { group } => write!(f, "no light group {group} in the table"),
            SolverError::NoSuchMaterial { material } => write!(f, "no material {material} in the table"),
            SolverError::BadValue { channel } => {
                write!(f, "value of channel {channel} not finite or out of range")
            }
            SolverError::WrongTable => write!(f, "table differs from the one the solver was created with"),
            SolverError::JacobiInProgress => write!(f, "a Jacobi sweep is in progress; finish it first"),
            SolverError::TooManyPatches { patches } => {
                write!(f, "{patches} patches: more than the solver supports ({MAX_PATCHES})")
            }
            // No numbers: formatting floats would pull float formatting code (~20 KiB) into firmware that
            // prints its errors; the values are in the variant's fields.
            SolverError::ToleranceBelowFloor { .. } => write!(
                f,
                "tolerance below this arithmetic's convergence floor for this table (longest row and largest \
                 reflectance; `convergence_floor`): it could never be reached"
            ),
        }
    }
}

impl core::error::Error for SolverError {}

/// A row being applied: shooter, next entry position, end of row, and the power being shot.
#[derive(Clone, Copy, Debug)]
struct Shot<S> {
    shooter: u32,
    next: u32,
    end: u32,
    power: [S; 3],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TreeState {
    /// Every block winner is current.
    Valid,
    /// Rebuilding block winners in order; the next block to scan (the ones below it are current).
    Rebuilding(u32),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Jacobi only: zeroing the scratch buffer, next patch.
    Clear(u32),
    /// Visiting rows, next row.
    Rows(u32),
    /// End-of-sweep scan (Jacobi: copy scratch into unshot), next patch.
    Scan(u32),
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Sweep<S> {
    jacobi: bool,
    phase: Phase,
    max: S,
}

/// Solver state: the current solution of one table, in the caller's buffers.
#[derive(Debug)]
pub struct Solver<'b, S: Scalar> {
    buf: Buffers<'b, S>,
    /// Slots: patches with run-time state (the table's state count); buffers are indexed by slot.
    slots: u32,
    patches: u32,
    groups: u32,
    materials: u32,
    table_crc: u32,
    config: Config<S>,
    shot: Option<Shot<S>>,
    tree: TreeState,
    /// Selection blocks: `B = 1 << block_shift` slots each, `blocks = ceil(slots / B)` of them.
    block_shift: u32,
    blocks: u32,
    /// The selection made by the last scan, until the next change of unshot power.
    selected: Option<u32>,
    sweep: Option<Sweep<S>>,
    shots: u32,
    entries: u64,
    /// Decoded reflectances of materials `0..RHO_CACHE` (kept current with the reflectance buffer), read by
    /// every form-factor entry; materials beyond it are decoded per entry.
    rho_cache: [[S::Rho; 3]; RHO_CACHE],
}

/// Materials whose decoded reflectance the solver keeps (a table rarely has more).
const RHO_CACHE: usize = 16;

fn get3<S: Scalar>(s: &[[S; 3]], i: u32) -> [S; 3] {
    s.get(i as usize).copied().unwrap_or([S::ZERO; 3])
}

fn add3<S: Scalar>(s: &mut [[S; 3]], i: u32, d: [S; 3]) {
    if let Some(v) = s.get_mut(i as usize) {
        for (a, b) in v.iter_mut().zip(d) {
            *a = a.add(b);
        }
    }
}

fn magnitude<S: Scalar>(v: [S; 3]) -> S {
    v[0].abs().add(v[1].abs()).add(v[2].abs())
}

fn area<S: Scalar>(table: &Table<'_>, patch: u32) -> S {
    S::from_f32(table.area(patch).unwrap_or(0.0))
}

fn emission<S: Scalar>(code: u16) -> S {
    let (m, e) = decode_emission(code);
    S::from_dyadic(m, e)
}

/// Length of the [`Buffers::tree`] buffer for `state_count` slots: one selection block winner per block of
/// `B` consecutive slots, `B` the smallest power of two with `B * B >= state_count` (about `sqrt(n)` entries).
#[must_use]
pub fn selection_len(state_count: u32) -> u32 {
    state_count.div_ceil(1 << block_shift(state_count))
}

/// Selection block size exponent for `n` slots: the smallest `B = 2^shift` with `B * B >= n`, so a selection
/// scan (`ceil(n / B)` winners) and a block rescan (`B` slots) both cost about `sqrt(n)`.
fn block_shift(n: u32) -> u32 {
    let mut shift = 0;
    while (1u64 << (2 * shift)) < u64::from(n) {
        shift += 1;
    }
    shift
}

impl<'b, S: Scalar> Solver<'b, S> {
    /// Creates the solver for `table`: loads reflectances and default intensities, and sets the cold start
    /// (static base plus every light group at its default intensity, as unshot power).
    ///
    /// Cost: `O(patches + members)`, outside any budget. The selection is built by the first steps,
    /// inside their budgets.
    ///
    /// # Errors
    /// [`SolverError::BufferTooSmall`] naming the buffer.
    pub fn new(table: &Table<'_>, buffers: Buffers<'b, S>, config: Config<S>) -> Result<Self, SolverError> {
        let n = table.state_count();
        if n > MAX_PATCHES {
            return Err(SolverError::TooManyPatches { patches: n });
        }
        let block_shift = block_shift(n);
        let blocks = selection_len(n);
        let checks: [(&'static str, usize, u32); 6] = [
            ("power", buffers.power.len(), n),
            ("unshot", buffers.unshot.len(), n),
            ("incident", buffers.incident.len(), n),
            ("tree", buffers.tree.len(), blocks),
            ("intensity", buffers.intensity.len(), table.group_count()),
            ("reflectance", buffers.reflectance.len(), table.material_count()),
        ];
        for (buffer, got, needed) in checks {
            if got < needed as usize {
                return Err(SolverError::BufferTooSmall { buffer, needed, got });
            }
        }
        let floor = convergence_floor::<S>(table);
        if config.tolerance < floor {
            return Err(SolverError::ToleranceBelowFloor {
                tolerance: config.tolerance.to_f32(),
                floor: floor.to_f32(),
            });
        }
        let mut s = Solver {
            buf: buffers,
            slots: n,
            patches: table.patch_count(),
            groups: table.group_count(),
            materials: table.material_count(),
            table_crc: table.crc(),
            config,
            shot: None,
            tree: TreeState::Rebuilding(0),
            block_shift,
            blocks,
            selected: None,
            sweep: None,
            shots: 0,
            entries: 0,
            rho_cache: [[S::Rho::default(); 3]; RHO_CACHE],
        };
        s.reset(table);
        Ok(s)
    }

    fn same_table(&self, table: &Table<'_>) -> bool {
        table.crc() == self.table_crc
            && table.state_count() == self.slots
            && table.patch_count() == self.patches
            && table.group_count() == self.groups
            && table.material_count() == self.materials
    }

    /// Resets to the cold start: table reflectances, default intensities, static base, lights as unshot power.
    ///
    /// A different table is ignored (the state stays as it was).
    pub fn reset(&mut self, table: &Table<'_>) {
        self.cold_start(table, true);
    }

    /// Cold start with the current intensities and reflectances: the solution is discarded and every light
    /// is unshot power again (no cancellation against old power, see [`Solver::set_light`]).
    ///
    /// A different table is ignored (the state stays as it was).
    pub fn restart(&mut self, table: &Table<'_>) {
        self.cold_start(table, false);
    }

    fn cold_start(&mut self, table: &Table<'_>, defaults: bool) {
        if !self.same_table(table) {
            return;
        }
        if defaults {
            self.load_defaults(table);
        }
        self.cold_state(table);
    }

    fn load_defaults(&mut self, table: &Table<'_>) {
        for m in 0..self.materials {
            if let Some(r) = self.buf.reflectance.get_mut(m as usize) {
                *r = table.reflectance(m).unwrap_or([0; 3]);
            }
        }
        for m in 0..RHO_CACHE as u32 {
            self.refresh_rho(m);
        }
        for g in 0..self.groups {
            if let Some(v) = self.buf.intensity.get_mut(g as usize) {
                let d = table.default_intensity(g).unwrap_or([0.0; 3]);
                *v = [S::from_f32(d[0]), S::from_f32(d[1]), S::from_f32(d[2])];
            }
        }
    }

    fn cold_state(&mut self, table: &Table<'_>) {
        let solved = table.base_solved();
        for i in 0..self.slots {
            let patch = table.slot_patch(i).unwrap_or(u32::MAX);
            let a: S = area(table, patch);
            let e = table.base_emission(patch).unwrap_or([0; 3]);
            let g = table.base_irradiance(patch).unwrap_or([0; 3]);
            let rho = self.rho(table, i);
            let mut p = [S::ZERO; 3];
            let mut h = [S::ZERO; 3];
            for c in 0..3 {
                h[c] = emission::<S>(g[c]).mul(a);
                p[c] = emission::<S>(e[c]).mul(a).add(h[c].mul_frac(rho[c]));
            }
            if let Some(v) = self.buf.power.get_mut(i as usize) {
                *v = p;
            }
            if let Some(v) = self.buf.incident.get_mut(i as usize) {
                *v = h;
            }
            if let Some(v) = self.buf.unshot.get_mut(i as usize) {
                *v = if solved { [S::ZERO; 3] } else { p };
            }
        }
        for g in 0..self.groups {
            let rgb = get3(self.buf.intensity, g);
            self.add_group_emission(table, g, rgb);
        }
        self.shot = None;
        self.sweep = None;
        self.shots = 0;
        self.entries = 0;
        self.tree = TreeState::Rebuilding(0);
        self.selected = None;
    }

    /// Adds `scale` times group `g`'s unit emission (times area) to power and unshot power; returns members.
    fn add_group_emission(&mut self, table: &Table<'_>, g: u32, scale: [S; 3]) -> u32 {
        let members = table.group_members(g).unwrap_or(0..0);
        let count = members.end.saturating_sub(members.start);
        for k in members {
            let Some(m) = table.member(k) else { continue };
            // Every member has a slot (checked by parse).
            let Some(slot) = table.slot_of(m.patch) else { continue };
            let a: S = area(table, m.patch);
            let mut d = [S::ZERO; 3];
            for c in 0..3 {
                d[c] = scale[c].mul(emission::<S>(m.emission[c])).mul(a);
            }
            add3(self.buf.power, slot, d);
            add3(self.buf.unshot, slot, d);
        }
        count
    }

    /// Current reflectance of `slot` (read through the table's slot-ordered materials: no map lookup, this is
    /// on the per-entry path).
    fn rho(&self, table: &Table<'_>, slot: u32) -> [Frac; 3] {
        self.rho_of_material(table.slot_material(slot).unwrap_or(0))
    }

    /// Re-decodes material `m`'s cached reflectance from the reflectance buffer.
    fn refresh_rho(&mut self, m: u32) {
        let code = self.reflectance_code(m);
        if let Some(c) = self.rho_cache.get_mut(m as usize) {
            *c = code.map(S::rho);
        }
    }

    /// The reflectance of `slot` for the per-entry product: cached per material, decoded for the rare material
    /// beyond the cache.
    #[inline]
    fn entry_rho(&self, table: &Table<'_>, slot: u32) -> [S::Rho; 3] {
        let m = table.slot_material(slot).unwrap_or(0);
        match self.rho_cache.get(m as usize) {
            Some(r) => *r,
            None => self.reflectance_code(m).map(S::rho),
        }
    }

    fn rho_of_material(&self, m: u32) -> [Frac; 3] {
        self.reflectance_code(m).map(decode_reflectance)
    }

    /// Current reflectance codes of material `m` (0 outside the buffer).
    fn reflectance_code(&self, m: u32) -> [u16; 3] {
        self.buf.reflectance.get(m as usize).copied().unwrap_or([0; 3])
    }

    /// The radiosity of a patch without state: its static base `E_s + rho G_s` with the current reflectance.
    fn stateless_radiosity(&self, table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
        let e = table.base_emission(patch)?;
        let g = table.base_irradiance(patch)?;
        let rho = self.rho_of_material(table.material(patch)?);
        Some([0, 1, 2].map(|c| emission::<S>(e[c]).add(emission::<S>(g[c]).mul_frac(rho[c]))))
    }

    /// Number of patches (with or without state).
    #[must_use]
    pub fn patch_count(&self) -> u32 {
        self.patches
    }

    /// Number of patches with run-time state (the table's [`Table::state_count`]): the buffers' length.
    #[must_use]
    pub fn state_count(&self) -> u32 {
        self.slots
    }

    /// Rows started (shots, or row visits of a sweep) since the last reset; saturates at `u32::MAX`.
    #[must_use]
    pub fn shots(&self) -> u32 {
        self.shots
    }

    /// Form-factor entries applied since the last cold start (shooting and sweeps alike): the work that is
    /// proportional to table bytes read, for reports that compare methods per entry.
    #[must_use]
    pub fn entries(&self) -> u64 {
        self.entries
    }

    /// Power `Phi_i = B_i A_i` of `patch` (RGB), or `None` out of range or for another table. A patch without
    /// state has its static power `(E_s + rho G_s) A` (current reflectance).
    #[must_use]
    pub fn power(&self, table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
        if !self.same_table(table) {
            return None;
        }
        match table.slot_of(patch) {
            Some(slot) => self.buf.power.get(slot as usize).copied(),
            None => {
                let b = self.stateless_radiosity(table, patch)?;
                let a: S = area(table, patch);
                Some(b.map(|x| x.mul(a)))
            }
        }
    }

    /// Unshot power of `patch` (RGB), or `None` out of range or for another table. Excludes a shot in flight.
    /// Zero for a patch without state.
    #[must_use]
    pub fn unshot(&self, table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
        if !self.same_table(table) || patch >= self.patches {
            return None;
        }
        match table.slot_of(patch) {
            Some(slot) => self.buf.unshot.get(slot as usize).copied(),
            None => Some([S::ZERO; 3]),
        }
    }

    /// Radiosity `B_i = Phi_i / A_i` (W/m^2, RGB) of `patch`, or `None` out of range or for another table.
    ///
    /// A patch without run-time state shows its static base `E_s + rho G_s` (crate docs, "Run-time state"),
    /// `rho` its material's current reflectance; patches with state are read from the power buffer. The
    /// lookup of a patch's slot is a binary search when some patches have no state (`O(log state_count)`).
    #[must_use]
    pub fn radiosity(&self, table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
        if !self.same_table(table) {
            return None;
        }
        match table.slot_of(patch) {
            Some(slot) => {
                let p = self.buf.power.get(slot as usize).copied()?;
                let a: S = area(table, patch);
                Some([p[0].div(a), p[1].div(a), p[2].div(a)])
            }
            None => self.stateless_radiosity(table, patch),
        }
    }

    /// Current intensity of light `group`.
    #[must_use]
    pub fn intensity(&self, group: u32) -> Option<[S; 3]> {
        self.buf.intensity.get(group as usize).copied().filter(|_| group < self.groups)
    }

    /// Sum of all unshot power (RGB, power units), including the part of a shot in flight not yet delivered
    /// (its power times the form factors of the entries left). Cost `O(patches + row length)`.
    #[must_use]
    pub fn total_unshot(&self, table: &Table<'_>) -> [S; 3] {
        let mut t = [S::ZERO; 3];
        if let Some(shot) = self.shot {
            for k in shot.next..shot.end {
                if let Some((_, f)) = table.entry(shot.shooter, k) {
                    for (tc, pc) in t.iter_mut().zip(shot.power) {
                        *tc = tc.add(pc.mul_frac(f));
                    }
                }
            }
        }
        for u in self.buf.unshot.iter().take(self.slots as usize) {
            for c in 0..3 {
                t[c] = t[c].add(u[c]);
            }
        }
        t
    }

    /// The ambient term for display of an unconverged state (Cohen, Chen, Wallace, Greenberg, "A progressive
    /// refinement approach to fast radiosity image generation", SIGGRAPH 1988, section 3):
    /// `ambient = (sum of unshot power / total area) / (1 - rho_avg)`, `rho_avg` the area-weighted mean
    /// reflectance. Display `B_i + rho_i * ambient` ([`Solver::radiosity_with_ambient`]). Meant for closed
    /// scenes. Only patches with state take part (total area and mean reflectance are over them): unshot power
    /// never reaches the others. Cost `O(state count)`, outside any budget.
    #[must_use]
    pub fn ambient(&self, table: &Table<'_>) -> [S; 3] {
        if !self.same_table(table) {
            return [S::ZERO; 3];
        }
        let unshot = self.total_unshot(table);
        let mut area_sum = S::ZERO;
        let mut rho_area = [S::ZERO; 3];
        for i in 0..self.slots {
            let a: S = area(table, table.slot_patch(i).unwrap_or(u32::MAX));
            area_sum = area_sum.add(a);
            let rho = self.rho(table, i);
            for c in 0..3 {
                rho_area[c] = rho_area[c].add(a.mul_frac(rho[c]));
            }
        }
        let one = S::from_dyadic(1, 0);
        let mut out = [S::ZERO; 3];
        for c in 0..3 {
            let rho_avg = rho_area[c].div(area_sum);
            out[c] = unshot[c].div(area_sum).div(one.sub(rho_avg));
        }
        out
    }

    /// `B_i + rho_i * ambient` for `patch` (see [`Solver::ambient`]); a patch without state gets no ambient
    /// term (unshot power never reaches it).
    #[must_use]
    pub fn radiosity_with_ambient(&self, table: &Table<'_>, patch: u32, ambient: [S; 3]) -> Option<[S; 3]> {
        let b = self.radiosity(table, patch)?;
        let Some(slot) = table.slot_of(patch) else { return Some(b) };
        let rho = self.rho(table, slot);
        Some([0, 1, 2].map(|c| b[c].add(ambient[c].mul_frac(rho[c]))))
    }

    // ---- selection: block winners -------------------------------------------------------------------

    fn key(&self, i: u32) -> S {
        magnitude(get3(self.buf.unshot, i))
    }

    /// Selection rank of slot `i` ([`Scalar::rank`] of its unshot magnitude): an unusable magnitude (not
    /// finite for f32, saturated for fixed point) ranks above every usable one, so an overflow is selected and
    /// reported; otherwise the larger magnitude, ties to the lower slot.
    fn rank(&self, i: u32) -> S::Rank {
        self.key(i).rank(i)
    }

    /// Slots of block `b`.
    fn block_range(&self, b: u32) -> core::ops::Range<u32> {
        let start = b << self.block_shift;
        start.min(self.slots)..start.saturating_add(1 << self.block_shift).min(self.slots)
    }

    /// Scans block `b` for its winner and stores it; returns slots scanned (work units).
    fn rescan_block(&mut self, b: u32) -> u32 {
        let range = self.block_range(b);
        let len = range.end - range.start;
        let mut best = range.start;
        let mut best_rank = self.rank(best);
        for i in range.start + 1..range.end {
            let r = self.rank(i);
            if r > best_rank {
                best = i;
                best_rank = r;
            }
        }
        self.set_winner(b, best);
        len
    }

    /// Whether block `b`'s stored winner is current (its block is rebuilt).
    fn block_valid(&self, b: u32) -> bool {
        match self.tree {
            TreeState::Valid => true,
            TreeState::Rebuilding(next) => b < next,
        }
    }

    /// Records that `slot`'s unshot power changed (in any direction). The comparison with its block's winner
    /// is part of the change's own unit; returns the extra work units: the block's length when `slot` was the
    /// winner (it may have shrunk) and the block is rescanned, else 0.
    fn update_leaf(&mut self, slot: u32) -> u32 {
        self.selected = None;
        let b = slot >> self.block_shift;
        if !self.block_valid(b) {
            return 0;
        }
        let w = self.buf.tree.get(b as usize).copied().unwrap_or(slot);
        if w == slot {
            self.rescan_block(b)
        } else {
            if self.rank(slot) > self.rank(w) {
                self.set_winner(b, slot);
            }
            0
        }
    }

    /// The slot with the largest unshot magnitude (ties to the lower slot), from the block winners; returns it
    /// and the blocks scanned (work units).
    fn select(&self) -> (u32, u32) {
        let mut best = self.buf.tree.first().copied().unwrap_or(0);
        let mut best_rank = self.rank(best);
        for b in 1..self.blocks {
            let w = self.buf.tree.get(b as usize).copied().unwrap_or(0);
            let r = self.rank(w);
            if r > best_rank {
                best = w;
                best_rank = r;
            }
        }
        (best, self.blocks)
    }

    // ---- steps ----------------------------------------------------------------------------------------

    /// Applies entries of the shot in flight while the budget allows. Returns `true` when the row is done.
    /// `scratch`: Jacobi's receiving buffer; `None` sends received power to the unshot buffer and keeps the
    /// block winners current.
    ///
    /// Receivers are increasing within a row, so consecutive entries mostly fall in the same selection block:
    /// its winner and key are kept in locals and stored when the row moves to another block (a store and
    /// reload per entry would chain every entry to the previous one through memory).
    fn apply_shot(
        &mut self,
        table: &Table<'_>,
        budget: u32,
        used: &mut u32,
        mut scratch: Option<&mut [[S; 3]]>,
        per_entry: u32,
    ) -> bool {
        let Some(mut shot) = self.shot else { return true };
        // The block in the locals (`u32::MAX`: none), its winner and the winner's rank.
        let (mut block, mut winner, mut winner_rank) = (u32::MAX, 0u32, S::ZERO.rank(0));
        // Sweeps run with the selection invalid (rebuilt before the next shot): nothing to maintain. Shooting
        // applies entries only with every block built (`step` finishes a rebuild before resuming a row).
        let maintain = scratch.is_none() && self.tree == TreeState::Valid;
        let mut done = true;
        while shot.next < shot.end {
            if budget - *used < per_entry {
                done = false;
                break;
            }
            if let Some((i, f)) = table.entry(shot.shooter, shot.next) {
                let rho = self.entry_rho(table, i);
                let mut t = [S::ZERO; 3];
                let mut r = [S::ZERO; 3];
                for c in 0..3 {
                    t[c] = shot.power[c].mul_frac(f);
                    r[c] = t[c].mul_rho(rho[c]);
                }
                add3(self.buf.incident, i, t);
                add3(self.buf.power, i, r);
                *used += 1;
                match scratch.as_deref_mut() {
                    Some(s) => add3(s, i, r),
                    None if !maintain => add3(self.buf.unshot, i, r),
                    None => {
                        let before = get3(self.buf.unshot, i);
                        let after = [0, 1, 2].map(|c| before[c].add(r[c]));
                        if let Some(v) = self.buf.unshot.get_mut(i as usize) {
                            *v = after;
                        }
                        let b = i >> self.block_shift;
                        if b != block {
                            if block != u32::MAX {
                                self.set_winner(block, winner);
                            }
                            block = b;
                            winner = self.buf.tree.get(b as usize).copied().unwrap_or(i);
                            winner_rank = self.rank(winner);
                        }
                        let rank = magnitude(after).rank(i);
                        if i == winner {
                            // Each channel moved away from zero (or not at all): it stays the winner.
                            let grew = (0..3)
                                .all(|c| (before[c] >= S::ZERO) == (r[c] >= S::ZERO) || r[c] == S::ZERO);
                            if grew {
                                winner_rank = rank;
                            } else {
                                *used += self.rescan_block(b);
                                winner = self.buf.tree.get(b as usize).copied().unwrap_or(i);
                                winner_rank = self.rank(winner);
                            }
                        } else {
                            // One integer compare: whether a receiver overtakes its block's winner is
                            // data-dependent, and a compare-and-select keeps it off the branch predictor.
                            let above = rank > winner_rank;
                            winner = if above { i } else { winner };
                            winner_rank = if above { rank } else { winner_rank };
                        }
                    }
                }
            } else {
                *used += 1;
            }
            shot.next += 1;
            self.entries = self.entries.wrapping_add(1);
        }
        if block != u32::MAX {
            self.set_winner(block, winner);
        }
        self.selected = None;
        self.shot = if done { None } else { Some(shot) };
        done
    }

    fn set_winner(&mut self, b: u32, w: u32) {
        if let Some(t) = self.buf.tree.get_mut(b as usize) {
            *t = w;
        }
    }

    /// Starts shooting `shooter`'s unshot power times `omega_extra` (overshoot/256 extra).
    fn start_shot(&mut self, table: &Table<'_>, shooter: u32, overshoot: u8) -> u32 {
        let u = get3(self.buf.unshot, shooter);
        let extra = Frac { mantissa: u32::from(overshoot), shift: 8 };
        let power = u.map(|x| x.add(x.mul_frac(extra)));
        if let Some(v) = self.buf.unshot.get_mut(shooter as usize) {
            for c in 0..3 {
                v[c] = v[c].sub(power[c]);
            }
        }
        let row = table.row(shooter).unwrap_or(0..0);
        self.shot = Some(Shot { shooter, next: row.start, end: row.end, power });
        self.shots = self.shots.saturating_add(1);
        1 + self.update_leaf(shooter)
    }

    /// Worst-case units of one shooting entry: the entry and a rescan of the receiver's block (`1 + B`).
    fn shooting_entry_cost(&self) -> u32 {
        (1u32 << self.block_shift) + 1
    }

    /// Progressive-refinement shooting (Southwell iteration; Cohen et al. 1988) for at most `budget` work
    /// units: repeatedly shoot the patch with the largest unshot power, resuming a row cut short by the
    /// previous step.
    ///
    /// Selection keeps the winner of each block of `B` consecutive slots (`B` the power of two at or above
    /// `sqrt(n)`) and scans the `ceil(n / B)` winners for the largest. Cost: 1 unit per block winner scanned
    /// and per slot scanned when a block is rebuilt; per shot 1 unit plus a rescan of the shooter's block
    /// (`<= B`); per entry 1 unit, plus a rescan of the receiver's block when the receiver was its block's
    /// winner and its magnitude may have shrunk (a channel moved towards zero). An action runs only if its
    /// worst case fits in what is left of the budget: an entry `B + 1`, a block rebuild its length, a
    /// selection the block count, a shot start 1 plus its block's length. A selection made at the end of one
    /// step is kept for the next while nothing changes.
    pub fn step(&mut self, table: &Table<'_>, budget: u32) -> Outcome {
        let mut used = 0u32;
        if !self.same_table(table) {
            return Outcome::NoProgress { used, reason: NoProgressReason::WrongTable };
        }
        if self.sweep.is_some_and(|s| s.jacobi) {
            return Outcome::NoProgress { used, reason: NoProgressReason::JacobiInProgress };
        }
        // A Gauss-Seidel sweep left half done is abandoned (its in-flight row is finished below): shooting
        // works on the same residual.
        self.sweep = None;
        let worst = self.shooting_entry_cost();
        loop {
            if let TreeState::Rebuilding(mut b) = self.tree {
                while b < self.blocks {
                    let range = self.block_range(b);
                    let need = range.end - range.start;
                    if budget - used < need {
                        self.tree = TreeState::Rebuilding(b);
                        return self.spent(used, need);
                    }
                    used += self.rescan_block(b);
                    b += 1;
                }
                self.tree = TreeState::Valid;
            }
            if self.shot.is_some() {
                if !self.apply_shot(table, budget, &mut used, None, worst) {
                    return self.spent(used, worst);
                }
                continue;
            }
            if self.slots == 0 {
                return Outcome::Converged { used };
            }
            let w = match self.selected {
                Some(w) => w,
                None => {
                    if budget - used < self.blocks {
                        return self.spent(used, self.blocks);
                    }
                    let (w, units) = self.select();
                    used += units;
                    self.selected = Some(w);
                    w
                }
            };
            let key = self.key(w);
            if !key.is_usable() {
                return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
            }
            if key <= self.config.tolerance {
                return Outcome::Converged { used };
            }
            let range = self.block_range(w >> self.block_shift);
            let need = 1 + (range.end - range.start);
            if budget - used < need {
                return self.spent(used, need);
            }
            used += self.start_shot(table, w, self.config.overshoot);
        }
    }

    fn spent(&self, used: u32, needed: u32) -> Outcome {
        if used == 0 {
            Outcome::NoProgress { used, reason: NoProgressReason::BudgetTooSmall { needed } }
        } else {
            Outcome::BudgetSpent { used }
        }
    }

    /// Gauss-Seidel sweeps for at most `budget` work units, in residual form: each sweep shoots every
    /// patch's whole unshot power in index order, which is exactly a Gauss-Seidel sweep on `(I - R F) B = E`
    /// (each patch relaxed with the latest values of the others), reading shooter rows.
    ///
    /// Cost: 1 unit per row visited, 1 per entry, 1 per patch in the end-of-sweep convergence scan.
    pub fn step_gauss_seidel(&mut self, table: &Table<'_>, budget: u32) -> Outcome {
        self.sweep_step(table, None, budget)
    }

    /// Jacobi sweeps for at most `budget` work units, in residual form: each sweep shoots every patch's unshot
    /// power as it was at the start of the sweep, collecting what is received in `scratch` (state count
    /// elements, the same buffer on every call of a sweep), which becomes the unshot power at the end of the
    /// sweep: `B_{k+1} = E + R F B_k`.
    ///
    /// Cost: 1 unit per patch to clear `scratch`, 1 per row visited, 1 per entry, 1 per patch in the
    /// end-of-sweep copy and convergence scan.
    pub fn step_jacobi(&mut self, table: &Table<'_>, scratch: &mut [[S; 3]], budget: u32) -> Outcome {
        if scratch.len() < self.slots as usize {
            return Outcome::NoProgress { used: 0, reason: NoProgressReason::ScratchTooSmall };
        }
        self.sweep_step(table, Some(scratch), budget)
    }

    fn sweep_step(&mut self, table: &Table<'_>, mut scratch: Option<&mut [[S; 3]]>, budget: u32) -> Outcome {
        let mut used = 0u32;
        if !self.same_table(table) {
            return Outcome::NoProgress { used, reason: NoProgressReason::WrongTable };
        }
        if self.slots == 0 {
            // Nothing to sweep (and an empty sweep would cost no units, so it must not loop).
            return Outcome::Converged { used };
        }
        let jacobi = scratch.is_some();
        match self.sweep {
            Some(s) if s.jacobi == jacobi => {}
            Some(s) if s.jacobi => {
                return Outcome::NoProgress { used, reason: NoProgressReason::JacobiInProgress };
            }
            _ => {
                // Coming from shooting or a half-done Gauss-Seidel sweep: finish the row in flight into the
                // unshot buffer (the selection is not maintained from here on), then start a fresh sweep.
                self.tree = TreeState::Rebuilding(0);
                self.selected = None;
                if !self.apply_shot(table, budget, &mut used, None, 1) {
                    return self.spent(used, 1);
                }
                self.sweep = None;
            }
        }
        let mut sweep = self.sweep.unwrap_or(Sweep {
            jacobi,
            phase: if jacobi { Phase::Clear(0) } else { Phase::Rows(0) },
            max: S::ZERO,
        });
        loop {
            if used >= budget {
                self.sweep = Some(sweep);
                return self.spent(used, 1);
            }
            match sweep.phase {
                Phase::Clear(i) if i < self.slots => {
                    if let Some(s) = scratch.as_deref_mut().and_then(|s| s.get_mut(i as usize)) {
                        *s = [S::ZERO; 3];
                    }
                    used += 1;
                    sweep.phase = Phase::Clear(i + 1);
                }
                Phase::Clear(_) => sweep.phase = Phase::Rows(0),
                Phase::Rows(j) if j < self.slots => {
                    if self.shot.is_none() {
                        // Row visit: take the shooter's residual (Jacobi keeps it until the end-of-sweep copy).
                        let u = get3(self.buf.unshot, j);
                        if !jacobi {
                            if let Some(v) = self.buf.unshot.get_mut(j as usize) {
                                *v = [S::ZERO; 3];
                            }
                        }
                        let row = table.row(j).unwrap_or(0..0);
                        self.shot = Some(Shot { shooter: j, next: row.start, end: row.end, power: u });
                        self.shots = self.shots.saturating_add(1);
                        used += 1;
                    }
                    if !self.apply_shot(table, budget, &mut used, scratch.as_deref_mut(), 1) {
                        self.sweep = Some(sweep);
                        return self.spent(used, 1);
                    }
                    sweep.phase = Phase::Rows(j + 1);
                }
                Phase::Rows(_) => {
                    sweep.phase = Phase::Scan(0);
                    sweep.max = S::ZERO;
                }
                Phase::Scan(i) if i < self.slots => {
                    if let Some(s) = scratch.as_deref_mut().and_then(|s| s.get_mut(i as usize)) {
                        if let Some(v) = self.buf.unshot.get_mut(i as usize) {
                            *v = *s;
                        }
                    }
                    let k = self.key(i);
                    if k > sweep.max || !k.is_usable() {
                        sweep.max = k;
                    }
                    used += 1;
                    sweep.phase = Phase::Scan(i + 1);
                }
                Phase::Scan(_) => {
                    self.sweep = None;
                    if !sweep.max.is_usable() {
                        return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                    }
                    if sweep.max <= self.config.tolerance {
                        return Outcome::Converged { used };
                    }
                    sweep = Sweep {
                        jacobi,
                        phase: if jacobi { Phase::Clear(0) } else { Phase::Rows(0) },
                        max: S::ZERO,
                    };
                }
            }
        }
    }

    // ---- relighting -----------------------------------------------------------------------------------

    fn check_change(&self, table: &Table<'_>) -> Result<(), SolverError> {
        if !self.same_table(table) {
            return Err(SolverError::WrongTable);
        }
        if self.sweep.is_some_and(|s| s.jacobi) {
            return Err(SolverError::JacobiInProgress);
        }
        Ok(())
    }

    /// Sets light `group` to intensity `rgb`: the emission change (positive or negative) of every member is
    /// injected as unshot power, keeping the current solution as a warm start. Returns the work done (one
    /// unit per member plus any block rescan), outside any step budget.
    ///
    /// The injection cancels against the power already there, so with f32 a patch's absolute error after a
    /// change is about `2^-24` times the largest power it has held (dimming 1 -> 1e-6 leaves errors near
    /// 6e-8, not 6e-14); [`Solver::restart`] gives a cold start with the current settings when that matters. Fixed point has the same
    /// absolute resolution before and after.
    ///
    /// # Errors
    /// [`SolverError::NoSuchGroup`], [`SolverError::BadValue`] (not finite), [`SolverError::WrongTable`],
    /// [`SolverError::JacobiInProgress`].
    pub fn set_light(&mut self, table: &Table<'_>, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        self.check_change(table)?;
        if group >= self.groups {
            return Err(SolverError::NoSuchGroup { group });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !v.is_finite() {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        let new = rgb.map(S::from_f32);
        let old = self.intensity(group).unwrap_or([S::ZERO; 3]);
        let delta = [new[0].sub(old[0]), new[1].sub(old[1]), new[2].sub(old[2])];
        if let Some(v) = self.buf.intensity.get_mut(group as usize) {
            *v = new;
        }
        let mut units = self.add_group_emission(table, group, delta);
        for k in table.group_members(group).unwrap_or(0..0) {
            if let Some(slot) = table.member(k).and_then(|m| table.slot_of(m.patch)) {
                units = units.saturating_add(self.update_leaf(slot));
            }
        }
        Ok(units)
    }

    /// Sets the reflectance of `material` to `rgb` (each in `[0, 1)`, quantized by the reflectance codec):
    /// for every patch `i` of the material with state, `(rho_new - rho_old) H_i` (its incident power so far)
    /// is added to its power and injected as unshot power, so the solve converges to the cold solve of the
    /// edited scene restricted to the patches with state. Returns the work done (one unit per slot scanned
    /// plus block rescans), outside any step budget.
    ///
    /// Patches without state (crate docs, "Run-time state") show `E_s + rho_new G_s`: their own reflection of
    /// the static light changes, but nothing is propagated (what they reflect reaches no state), and the
    /// dynamic light they would have received is not there. The bake decides state with the table's
    /// reflectances: a receiver black in every channel gets no state, so making it reflect at run time shows
    /// only the static light on it; bake it with a nonzero reflectance if it must respond to dynamic lights.
    ///
    /// # Errors
    /// [`SolverError::NoSuchMaterial`], [`SolverError::BadValue`], [`SolverError::WrongTable`],
    /// [`SolverError::JacobiInProgress`].
    pub fn set_reflectance(
        &mut self,
        table: &Table<'_>,
        material: u32,
        rgb: [f32; 3],
    ) -> Result<u32, SolverError> {
        self.check_change(table)?;
        if material >= self.materials {
            return Err(SolverError::NoSuchMaterial { material });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !(0.0..1.0).contains(v) {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        let new_codes = rgb.map(encode_reflectance);
        let old_codes = self.buf.reflectance.get(material as usize).copied().unwrap_or([0; 3]);
        if let Some(r) = self.buf.reflectance.get_mut(material as usize) {
            *r = new_codes;
        }
        self.refresh_rho(material);
        let mut units = 0u32;
        for i in 0..self.slots {
            units = units.saturating_add(1);
            if table.slot_material(i) != Some(material) {
                continue;
            }
            let h = get3(self.buf.incident, i);
            let mut d = [S::ZERO; 3];
            for c in 0..3 {
                d[c] = h[c]
                    .mul_frac(decode_reflectance(new_codes[c]))
                    .sub(h[c].mul_frac(decode_reflectance(old_codes[c])));
            }
            add3(self.buf.power, i, d);
            add3(self.buf.unshot, i, d);
            units = units.saturating_add(self.update_leaf(i));
        }
        Ok(units)
    }
}
