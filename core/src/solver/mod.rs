//! Solver state in caller-supplied buffers (layer 4), bounded steps (layer 5) and relighting (layer 6).
//!
//! The state is [`Solver`], generic over the arithmetic ([`Scalar`]: `f32` or [`Fixed`](crate::Fixed)). It
//! holds its [`Table`] (a copy of the validated view; the blob stays where it is) and borrows every buffer from
//! the caller ([`Buffers`], sized by [`BufferSizes::of`]); nothing is allocated and nothing is sized for a
//! worst case. Each step takes a budget in work units (see the crate docs, "Cost model") and never spends more.
//!
//! Files, one concern each: `buffers` (memory and its sizes), `config` (settings, outcomes, errors), this file
//! (state, cold start, read-out), `selection` (block winners: which slot shoots next), `shoot` (progressive
//! refinement steps), `sweep` (Gauss-Seidel and Jacobi), `relight` (light and reflectance changes).

mod buffers;
mod config;
mod relight;
mod selection;
mod shoot;
mod sweep;

#[cfg(any(test, feature = "std"))]
pub use buffers::OwnedBuffers;
pub use buffers::{selection_len, BufferSizes, Buffers, StaticBuffers};
pub use config::{convergence_floor, Config, NoProgressReason, Outcome, SolverError, MAX_PATCHES};

use crate::base::{emission, static_radiosity_with};
use crate::codec::{decode_reflectance, Frac};
use crate::format::Table;
use crate::scalar::Scalar;
pub(crate) use buffers::block_shift;
use sweep::Sweep;

/// A row being applied: shooter, next entry position, end of row, and the power being shot.
#[derive(Clone, Copy, Debug)]
struct Shot<S> {
    shooter: u32,
    next: u32,
    end: u32,
    power: [S; 3],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SelectionState {
    /// Every block winner is current.
    Valid,
    /// Rebuilding block winners in order; the next block to scan (the ones below it are current).
    Rebuilding(u32),
}

/// Solver state: the current solution of one table, in the caller's buffers.
#[derive(Debug)]
pub struct Solver<'a, S: Scalar> {
    /// The table, held for the solver's lifetime (a copy of the validated view: the blob stays in place).
    table: Table<'a>,
    buf: Buffers<'a, S>,
    /// Slots: patches with run-time state (the table's state count); buffers are indexed by slot.
    slots: u32,
    patches: u32,
    groups: u32,
    materials: u32,
    config: Config<S>,
    shot: Option<Shot<S>>,
    selection: SelectionState,
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
pub(crate) const RHO_CACHE: usize = 16;

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

impl<'a, S: Scalar> Solver<'a, S> {
    /// Creates the solver for `table`: loads reflectances and default intensities, and sets the cold start
    /// (static base plus every light group at its default intensity, as unshot power).
    ///
    /// Cost: `O(patches + members)`, outside any budget. The selection is built by the first steps,
    /// inside their budgets.
    ///
    /// # Errors
    /// [`SolverError::BufferTooSmall`] naming the buffer.
    pub fn new(table: &Table<'a>, buffers: Buffers<'a, S>, config: Config<S>) -> Result<Self, SolverError> {
        let n = table.state_count();
        if n > MAX_PATCHES {
            return Err(SolverError::TooManyPatches { patches: n });
        }
        if let Some((buffer, needed, got)) = BufferSizes::of(table).shortfall(&buffers) {
            return Err(SolverError::BufferTooSmall { buffer, needed, got });
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
            table: *table,
            config,
            shot: None,
            selection: SelectionState::Rebuilding(0),
            block_shift: block_shift(n),
            blocks: selection_len(n),
            selected: None,
            sweep: None,
            shots: 0,
            entries: 0,
            rho_cache: [[S::Rho::default(); 3]; RHO_CACHE],
        };
        s.reset();
        Ok(s)
    }

    /// Resets to the cold start: table reflectances, default intensities, static base, lights as unshot power.
    pub fn reset(&mut self) {
        self.cold_start(true);
    }

    /// Cold start with the current intensities and reflectances: the solution is discarded and every light
    /// is unshot power again (no cancellation against old power, see [`Solver::set_light`]).
    pub fn restart(&mut self) {
        self.cold_start(false);
    }

    fn cold_start(&mut self, defaults: bool) {
        if defaults {
            self.load_defaults();
        }
        self.cold_state();
    }

    fn load_defaults(&mut self) {
        for m in 0..self.materials {
            if let Some(r) = self.buf.reflectance.get_mut(m as usize) {
                *r = self.table.reflectance(m).unwrap_or([0; 3]);
            }
        }
        for m in 0..RHO_CACHE as u32 {
            self.refresh_rho(m);
        }
        for g in 0..self.groups {
            if let Some(v) = self.buf.intensity.get_mut(g as usize) {
                let d = self.table.default_intensity(g).unwrap_or([0.0; 3]);
                *v = [S::from_f32(d[0]), S::from_f32(d[1]), S::from_f32(d[2])];
            }
        }
    }

    fn cold_state(&mut self) {
        let solved = self.table.base_solved();
        for i in 0..self.slots {
            let patch = self.table.slot_patch(i).unwrap_or(u32::MAX);
            let a: S = area(&self.table, patch);
            let e = self.table.base_emission(patch).unwrap_or([0; 3]);
            let g = self.table.base_irradiance(patch).unwrap_or([0; 3]);
            let rho = self.rho(i);
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
            self.add_group_emission(g, rgb);
        }
        self.shot = None;
        self.sweep = None;
        self.shots = 0;
        self.entries = 0;
        self.selection = SelectionState::Rebuilding(0);
        self.selected = None;
    }

    /// Adds `scale` times group `g`'s unit emission (times area) to power and unshot power; returns members.
    fn add_group_emission(&mut self, g: u32, scale: [S; 3]) -> u32 {
        let members = self.table.group_members(g).unwrap_or(0..0);
        let count = members.end.saturating_sub(members.start);
        for k in members {
            let Some(m) = self.table.member(k) else { continue };
            // Every member has a slot (checked by parse).
            let Some(slot) = self.table.slot_of(m.patch) else { continue };
            let a: S = area(&self.table, m.patch);
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
    fn rho(&self, slot: u32) -> [Frac; 3] {
        self.rho_of_material(self.table.slot_material(slot).unwrap_or(0))
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
    fn entry_rho(&self, slot: u32) -> [S::Rho; 3] {
        let m = self.table.slot_material(slot).unwrap_or(0);
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
    fn stateless_radiosity(&self, patch: u32) -> Option<[S; 3]> {
        static_radiosity_with(&self.table, patch, self.reflectance_code(self.table.material(patch)?))
    }

    /// The table this solver runs.
    #[must_use]
    pub fn table(&self) -> &Table<'a> {
        &self.table
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

    /// Power `Phi_i = B_i A_i` of `patch` (RGB), or `None` out of range or for another self.table. A patch without
    /// state has its static power `(E_s + rho G_s) A` (current reflectance).
    #[must_use]
    pub fn power(&self, patch: u32) -> Option<[S; 3]> {
        match self.table.slot_of(patch) {
            Some(slot) => self.buf.power.get(slot as usize).copied(),
            None => {
                let b = self.stateless_radiosity(patch)?;
                let a: S = area(&self.table, patch);
                Some(b.map(|x| x.mul(a)))
            }
        }
    }

    /// Unshot power of `patch` (RGB), or `None` out of range or for another self.table. Excludes a shot in flight.
    /// Zero for a patch without state.
    #[must_use]
    pub fn unshot(&self, patch: u32) -> Option<[S; 3]> {
        if patch >= self.patches {
            return None;
        }
        match self.table.slot_of(patch) {
            Some(slot) => self.buf.unshot.get(slot as usize).copied(),
            None => Some([S::ZERO; 3]),
        }
    }

    /// Radiosity `B_i = Phi_i / A_i` (W/m^2, RGB) of `patch`, or `None` out of range or for another self.table.
    ///
    /// A patch without run-time state shows its static base `E_s + rho G_s` (crate docs, "Run-time state"),
    /// `rho` its material's current reflectance; patches with state are read from the power buffer. The
    /// lookup of a patch's slot is a binary search when some patches have no state (`O(log state_count)`).
    #[must_use]
    pub fn radiosity(&self, patch: u32) -> Option<[S; 3]> {
        match self.table.slot_of(patch) {
            Some(slot) => {
                let p = self.buf.power.get(slot as usize).copied()?;
                let a: S = area(&self.table, patch);
                Some([p[0].div(a), p[1].div(a), p[2].div(a)])
            }
            None => self.stateless_radiosity(patch),
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
    pub fn total_unshot(&self) -> [S; 3] {
        let mut t = [S::ZERO; 3];
        if let Some((shot, row)) = self.shot.and_then(|s| Some((s, self.table.row_view(s.shooter)?))) {
            for (_, f) in row.entries_from(shot.next).take(shot.end.saturating_sub(shot.next) as usize) {
                for (tc, pc) in t.iter_mut().zip(shot.power) {
                    *tc = tc.add(pc.mul_frac(f));
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
    pub fn ambient(&self) -> [S; 3] {
        let unshot = self.total_unshot();
        let mut area_sum = S::ZERO;
        let mut rho_area = [S::ZERO; 3];
        for i in 0..self.slots {
            let a: S = area(&self.table, self.table.slot_patch(i).unwrap_or(u32::MAX));
            area_sum = area_sum.add(a);
            let rho = self.rho(i);
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
    pub fn radiosity_with_ambient(&self, patch: u32, ambient: [S; 3]) -> Option<[S; 3]> {
        let b = self.radiosity(patch)?;
        let Some(slot) = self.table.slot_of(patch) else { return Some(b) };
        let rho = self.rho(slot);
        Some([0, 1, 2].map(|c| b[c].add(ambient[c].mul_frac(rho[c]))))
    }
}
