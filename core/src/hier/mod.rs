//! Hierarchical shooting (layer 5b): [`HierSolver`] relights a [`HierTable`] with bounded, resumable steps.
//!
//! Hierarchical radiosity (Hanrahan, Salzman, Aupperle, "A rapid hierarchical radiosity algorithm", SIGGRAPH
//! 1991) solved by progressive refinement shooting (Cohen, Chen, Wallace, Greenberg, SIGGRAPH 1988) over its
//! links, in rounds, with the paper's push-pull done lazily in one sweep over the tree per round.
//!
//! # The scheme
//! - Every node `n` with links keeps `U_n`, the power emitted or reflected in `n`'s subtree that has not yet
//!   been shot through `n`'s own links (a node without links never shoots; its entry is never read). A
//!   leaf's new power is added to `U` of the leaf and of every ancestor with links: the links of a leaf's
//!   chain (the leaf and its ancestors) each carry their part of the leaf's interactions.
//! - A shot of node `s` sets `U_s = 0` and walks its run: link `(r, F_sr)` delivers the power `F_sr U_s` to
//!   `r`. An inner receiver adds it to its **pending** power ([`HierBuffers::pending`]), to be spread over `r`
//!   uniformly (as the irradiance `pending / A_r`, one division per node and sweep rather than per link):
//!   nothing below or above `r` is touched, so a link costs the same whatever the size of its receiver. A leaf
//!   receiver takes it at once: into its incident power `H_l`, and the reflected
//!   `rho_l F_sr U_s` into its own unshot power and into its parent's **reflected** entry
//!   ([`HierBuffers::reflected`]), pending for the rest of its chain. So leaves need no pending entry.
//! - A **sweep** then makes the pending light count, in one pass over the nodes in preorder that keeps the
//!   path from a root to the current node as a stack of [`SweepFrame`]s ([`HierBuffers::path`], one per
//!   level of the tree). **Entering** a node pushes its frame: an inner node's chain irradiance is its
//!   parent frame's plus its own pending power over its area, and its subtree sum starts with its reflected
//!   entry (both taken);
//!   a leaf adds `dH = A_l e` to `H_l`, `e` its parent frame's chain irradiance, and starts its frame's
//!   subtree sum at `rho_l dH`. **Leaving** a node (once the preorder has passed its subtree) pops its frame:
//!   the power reflected in its subtree goes into its unshot power (if it has links) and into its parent's
//!   frame. A sweep leaves nothing pending, and the path lives in the solver's buffers, so a sweep stops and
//!   resumes between any two nodes.
//! - A leaf's power is not stored: it is `Phi_l = E_l A_l + rho_l H_l`, its emission (static, and every light
//!   group's members on it at their current intensities) plus its reflected incident power, computed on
//!   readout ([`HierSolver::power`], or [`HierSolver::power_into`] for every leaf at once). The solver itself
//!   needs only the changes of power, which it injects as unshot power when they happen.
//! - So the solver converges to the solution of `B_l = E_l + rho_l sum_{r in chain(l)} (1 / A_r) sum_s F_sr
//!   Phi_s`, `Phi_s` the power of the leaves below sender `s`: the linear system of the table's hierarchy.
//!   The table's chain bound (every leaf's chain of decoded run sums `<= 1`, checked by
//!   [`HierTable::parse`]) makes the power a leaf shoots at most the power it holds, and reflectances are
//!   `< 1`, so the total unshot magnitude shrinks geometrically and shooting converges.
//! - Light changes ([`HierSolver::set_light`]) and reflectance edits ([`HierSolver::set_reflectance`],
//!   `(rho_new - rho_old) H_l` per leaf of the material) are injected as unshot power at the leaves and their
//!   chains, as the flat [`Solver`](crate::Solver) does; the static base as in the crate docs. Overshooting
//!   ([`Config::overshoot`]) works as in the flat solver: a shot sends `(1 + overshoot / 256) U_s` and leaves
//!   the excess as negative unshot power.
//! - Leaves show the light of links that reach them at once, and of links to their ancestors from the
//!   sweep's entry of the leaf on: what a round shot shows after its sweep.
//!
//! # Memory
//! `[S; 3]` per leaf (`H_l`), per node (`U_n`), two per inner node (pending power, reflected power) and
//! one per light group (intensity), a [`SweepFrame`] per level of the tree and three reflectance codes per
//! material ([`HierBufferSizes::bytes`]): in f32, 24 bytes per leaf and 36 per inner node, where storing each
//! leaf's power and a pending entry per node (which carried the sweep's chain and subtree sums) took 48 and
//! 24. Leaves are indexed by leaf index and inner nodes by `node - leaf_start(node)`, both from the table,
//! so no node-to-entry map takes RAM. The alternatives weighed: entries only for nodes with links and for
//! nodes that links reach, numbered by slot sections the table would store (flash), save only the nodes
//! that neither send nor receive, few in baked tables; a pending entry per leaf instead of the parent's
//! reflected entry costs one per leaf where this costs one per inner node, and inner nodes are the fewer.
//!
//! # Rounds: which nodes shoot
//! Leaving nodes is where the unshot powers become current, so a sweep also finds the largest unshot
//! magnitude `|r| + |g| + |b|`, `M`. If `M` is within the tolerance, the solver has converged: every node's
//! unshot magnitude is `<= tolerance` and nothing is pending, the flat solver's convergence, so its remainder
//! bound holds. Otherwise a round judges the nodes in index order and shoots every node whose unshot
//! magnitude is at least `M / 64` (and above the tolerance), then sweeps. During a round a shot changes the
//! shooter's unshot power and, for links that reach leaves, those leaves' own unshot power; what reaches
//! inner nodes, and the chains above the leaves, stays pending. So a node is judged on its unshot power as of
//! the sweep before the round, plus what light changes and edits injected since, plus (a leaf) what this
//! round's earlier shots reflected from it: the rule judges the light reflected before the round, and light
//! reflected higher up waits for the next round, as it must (it is not yet computed).
//!
//! Why rounds: a sweep and a round's judging cost a fixed `3 N` units (`N` nodes) whatever is shot, so
//! sweeping after every shot of the largest node would cost `3 N` per shot; shooting every node within a
//! factor of the largest keeps the largest residuals first, as Southwell's rule does, and spreads the fixed
//! cost over many shots. The factor trades the two: a large share (`M / 4`) runs many rounds of few shots,
//! each paying `3 N` to move little, and a share too small shoots nodes whose power mostly arrives later, so
//! they shoot again. Against `M / 4`, `M / 64` cut the units to reach 1% on every scene tried, and smaller
//! shares gained on some and lost on others (the bake summary's "device" line shows the units for a scene);
//! the host's shooting solve uses the same share (`ROUND_SHARE`). The alternative, a sweep whenever the
//! pending power exceeds a share of the unshot power, judges the same stale unshot powers between sweeps and
//! needs a selection structure kept current per shot; rounds need neither (no selection buffer).
//!
//! # Work units
//! One unit each: a node judged in a round (a shot starts at no extra cost); a link applied (its power
//! computed and added to an inner receiver's pending, or to a leaf receiver's incident power, unshot power
//! and parent's reflected entry); a node entered by a sweep (chain irradiance summed; for a
//! leaf, incident power and reflected power updated); a node left by a sweep (reflected power summed into its
//! parent's frame and its unshot power, the largest magnitude kept). Every action is one unit, so a step
//! never spends more than its budget, any budget of one unit or more makes progress, and the next step
//! resumes where it stopped. The sequence of actions does not depend on how the budget is split, so runs with
//! different budgets are bit-identical at every action boundary, and at convergence.
//!
//! A round costs `3 N` units plus one per link of the nodes it shoots: a link costs one unit whatever the
//! receiver, and the sweep is paid once per round for all the links shot in it.
//!
//! Outside any budget, returned as work counts: [`HierSolver::set_light`] (members times their chain walks,
//! twice from a converged state), [`HierSolver::set_reflectance`] (leaves scanned plus chain walks); a change
//! during a sweep makes the sweep run again before convergence is judged. A light change to a converged
//! solver starts a round at once, without a sweep: nothing is pending, so that sweep would move nothing and
//! only find the largest unshot magnitude, which lies on the changed light's chains, walked again for it.
//! [`HierSolver::new`] and [`HierSolver::reset`] are `O(leaves x depth + links)`. Readout:
//! [`HierSolver::power`] and [`HierSolver::radiosity`] are `O(members)` per leaf, [`HierSolver::power_into`]
//! and [`HierSolver::radiosity_into`] `O(leaves + members)` for all.
//!
//! # Range
//! Fixed point's sums saturate ([`crate::scalar`]), except in shooting's link loops on runs whose products
//! take fixed point's fast path (FLOAT16-like rows shot with powers below `2^49` raw): a 64-bit saturating
//! sum costs a 32-bit core several instructions more than a wrapping one, and a link to a leaf makes nine
//! sums. There each sum wraps, and the run checks once, at its end, whether any sum left `[-2^62, 2^62)` raw
//! (`+-2^30` power units, half the type's range; the products are below `2^61`, so a wrapped sum lands
//! outside it too). If one did, the buffers hold wrapped values and the solver stops: every step reports
//! [`NoProgressReason::NotFinite`] until [`HierSolver::restart`] or [`HierSolver::reset`]. A saturating
//! sum's value would have been found unusable by the next sweep (unshot and pending power), or read out as
//! the largest value (incident power). f32 is unaffected: its sums overflow to infinity.
//!
//! # Example
//! ```
//! use radiosity_core::{
//!     hier_required_len, write_hier_table, Config, FfCodec, GroupSpec, HierOwnedBuffers, HierSolver, HierSpec,
//!     HierTable, MemberSpec, NodeSpec, Outcome, PatchSpec, RowsSpec,
//! };
//!
//! // Two unit squares facing each other, each a node over two leaves of area 1/2 (preorder: 0, 1, 2 and
//! // 3, 4, 5). One link each way between the squares: F = 1/4 of a square's power reaches the other (a power of
//! // two, so its code is exact).
//! let nodes = [None, Some(0), Some(0), None, Some(3), Some(3)].map(|parent| NodeSpec { parent });
//! let leaf = PatchSpec { area: 0.5, material: 0, base_emission: [0.0; 3], base_irradiance: [0.0; 3] };
//! let lamp = [MemberSpec { patch: 0, emission: [1.0; 3] }];
//! let spec = HierSpec {
//!     nodes: &nodes,
//!     leaves: &[leaf; 4],
//!     materials: &[[0.5; 3]],
//!     groups: &[GroupSpec { id: 1, default_intensity: [1.0; 3], members: &lamp }],
//!     // Runs by sender node: node 0 -> node 3, node 3 -> node 0.
//!     links: RowsSpec { row_start: &[0, 1, 1, 1, 2, 2, 2], receiver: &[3, 0], form_factor: &[0.25, 0.25] },
//!     codec: FfCodec::FLOAT16,
//!     base_solved: false,
//!     fingerprint: 0,
//!     transfer: None,
//! };
//! let mut blob = vec![0u8; hier_required_len(&spec)?];
//! write_hier_table(&spec, &mut blob)?;
//! let table = HierTable::parse(&blob)?;
//! let mut store = HierOwnedBuffers::<f32>::for_table(&table);
//! let mut solver = HierSolver::new(&table, store.buffers(), Config { tolerance: 1e-7, overshoot: 0 })?;
//! while let Outcome::BudgetSpent { .. } = solver.step(16) {}
//! // The lamp's square shoots 1/4 of its power (0.5 W) to the other square: 0.125 W over area 1, reflected at
//! // 0.5: B = 0.0625 on each of its leaves (leaf 2 is node 4); bounces between the squares multiply that by
//! // 1 / (1 - (0.5 * 0.25)^2).
//! let b = solver.radiosity(2).unwrap()[0];
//! assert!((b - 0.0625 / (1.0 - 0.015625)).abs() < 1e-6, "{b}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod buffers;
mod links;

#[cfg(any(test, feature = "std"))]
pub use buffers::HierOwnedBuffers;
pub use buffers::{HierBufferSizes, HierBuffers, HierStaticBuffers, SweepFrame};

use crate::base::emission;
use crate::codec::{decode_reflectance, encode_reflectance, Frac};
use crate::format::{slot_of, HierTable};
use crate::scalar::Scalar;
use crate::solver::{Config, NoProgressReason, Outcome, SolverError, MAX_PATCHES, RHO_CACHE};

/// A round shoots every node whose unshot magnitude is at least `1 / 2^ROUND_SHARE_SHIFT` of the largest
/// (module docs, "Rounds").
const ROUND_SHARE_SHIFT: u32 = 6;

/// Where the solver is in its sequence of actions.
#[derive(Clone, Copy, Debug)]
enum Phase<S> {
    /// Judging nodes `next..` of a round: those at or above `threshold` (and above the tolerance) shoot.
    Round { threshold: S, next: u32 },
    /// Shooting `sender`'s `power` over its run (next link position, run end), then back to the round.
    Shooting { sender: u32, power: [S; 3], next: u32, end: u32, threshold: S },
    /// A sweep: nodes `next..` still to enter in preorder, `depth` frames on the path; the largest unshot
    /// magnitude of the nodes left so far, whether all of them were usable, and whether a change since the
    /// sweep began may have raised a node already left (then a sweep runs again before it is trusted).
    Sweep { next: u32, depth: u32, largest: S, usable: bool, stale: bool },
    /// Every node's unshot magnitude is within the tolerance and nothing is pending (until a change).
    Converged,
    /// A shot's sum left the range (module docs, "Range"): the buffers hold wrapped values, and every step
    /// reports [`NoProgressReason::NotFinite`] until [`HierSolver::restart`] or [`HierSolver::reset`].
    OutOfRange,
}

/// Hierarchical solver state: the current solution of one [`HierTable`], in the caller's buffers.
#[derive(Debug)]
pub struct HierSolver<'a, S: Scalar> {
    table: HierTable<'a>,
    buf: HierBuffers<'a, S>,
    config: Config<S>,
    phase: Phase<S>,
    shots: u32,
    sweeps: u32,
    links: u64,
    judged: u64,
    /// Decoded reflectances of materials `0..RHO_CACHE` (kept current with the reflectance buffer), read by
    /// every link to a leaf; materials beyond it are decoded per link.
    rho_cache: [[S::Rho; 3]; RHO_CACHE],
}

fn add3<S: Scalar>(a: [S; 3], b: [S; 3]) -> [S; 3] {
    [a[0].add(b[0]), a[1].add(b[1]), a[2].add(b[2])]
}

fn magnitude<S: Scalar>(v: [S; 3]) -> S {
    v[0].abs().add(v[1].abs()).add(v[2].abs())
}

/// A round's threshold for the largest unshot magnitude `largest`: its `1 / 2^ROUND_SHARE_SHIFT`.
fn round_threshold<S: Scalar>(largest: S) -> S {
    largest.mul_frac(Frac { mantissa: 1, shift: ROUND_SHARE_SHIFT })
}

/// The smallest tolerance [`HierSolver::new`] accepts for `table` on arithmetic `S` (zero for f32). The flat
/// solver's argument ([`crate::convergence_floor`], the `scalar` module docs) with the rounded receipts of a
/// shot counted as the leaves its links reach times the chain walks that repeat each leaf's rounding:
/// `ceil(6 R D / (1 - rho_max))`, `R` the most leaves any run reaches (with multiplicity), `D` the longest
/// chain. The lazy push rounds less than that count (one rounding per link to an inner node and two per link
/// to a leaf, one per inner node and two per leaf and sweep, exact fixed-point sums down and up the tree), so
/// the floor stays sufficient. `O(links + materials)`.
#[must_use]
pub fn hier_convergence_floor<S: Scalar>(table: &HierTable<'_>) -> S {
    let mut most = 0u64;
    for s in 0..table.node_count() {
        let mut reach = 0u64;
        for k in table.run(s).unwrap_or(0..0) {
            let r = table.link(s, k).map_or(0, |(r, _)| r);
            reach = reach.saturating_add(table.leaf_range(r).map_or(0, |x| u64::from(x.end - x.start)));
        }
        most = most.max(reach);
    }
    let code_max = (0..table.material_count())
        .filter_map(|m| table.reflectance(m))
        .flat_map(|r| r.into_iter())
        .max()
        .map_or(0, u64::from);
    let units = most
        .saturating_mul(6 * u64::from(table.max_depth()))
        .saturating_mul(65536)
        .div_ceil(65536 - code_max.min(65535));
    S::convergence_floor(units)
}

impl<'a, S: Scalar> HierSolver<'a, S> {
    /// Creates the solver for `table`: loads reflectances and default intensities and sets the cold start
    /// (static base, every light group at its default intensity as unshot power).
    ///
    /// # Errors
    /// [`SolverError::TooManyPatches`] (more than [`MAX_PATCHES`] nodes), [`SolverError::BufferTooSmall`],
    /// [`SolverError::ToleranceBelowFloor`] ([`hier_convergence_floor`]).
    pub fn new(
        table: &HierTable<'a>,
        buffers: HierBuffers<'a, S>,
        config: Config<S>,
    ) -> Result<Self, SolverError> {
        let nodes = table.node_count();
        if nodes > MAX_PATCHES {
            return Err(SolverError::TooManyPatches { patches: nodes });
        }
        if let Some((buffer, needed, got)) = HierBufferSizes::of(table).shortfall(&buffers) {
            return Err(SolverError::BufferTooSmall { buffer, needed, got });
        }
        let floor = hier_convergence_floor::<S>(table);
        if config.tolerance < floor {
            return Err(SolverError::ToleranceBelowFloor {
                tolerance: config.tolerance.to_f32(),
                floor: floor.to_f32(),
            });
        }
        let mut s = HierSolver {
            table: *table,
            buf: buffers,
            config,
            phase: Phase::Converged,
            shots: 0,
            sweeps: 0,
            links: 0,
            judged: 0,
            rho_cache: [[S::Rho::default(); 3]; RHO_CACHE],
        };
        s.reset();
        Ok(s)
    }

    /// Resets to the cold start with the table's reflectances and default intensities.
    pub fn reset(&mut self) {
        for m in 0..self.table.material_count() {
            if let Some(r) = self.buf.reflectance.get_mut(m as usize) {
                *r = self.table.reflectance(m).unwrap_or([0; 3]);
            }
        }
        for m in 0..RHO_CACHE as u32 {
            self.refresh_rho(m);
        }
        for g in 0..self.table.group_count() {
            if let Some(v) = self.buf.intensity.get_mut(g as usize) {
                *v = self.table.default_intensity(g).unwrap_or([0.0; 3]).map(S::from_f32);
            }
        }
        self.restart();
    }

    /// Cold start with the current intensities and reflectances: the solution is discarded and every light is
    /// unshot power again.
    pub fn restart(&mut self) {
        for u in self.buf.unshot.iter_mut() {
            *u = [S::ZERO; 3];
        }
        for p in self.buf.pending.iter_mut().chain(self.buf.reflected.iter_mut()) {
            *p = [S::ZERO; 3];
        }
        let solved = self.table.base_solved();
        for l in 0..self.table.leaf_count() {
            let a: S = self.leaf_area(l);
            let g = self.table.base_irradiance(l).unwrap_or([0; 3]);
            let h = [0, 1, 2].map(|c| emission::<S>(g[c]).mul(a));
            if let Some(v) = self.buf.incident.get_mut(l as usize) {
                *v = h;
            }
            if !solved {
                self.add_to_chain(l, self.base_power(l));
            }
        }
        for g in 0..self.table.group_count() {
            let rgb = self.buf.intensity.get(g as usize).copied().unwrap_or([S::ZERO; 3]);
            self.add_group_emission(g, rgb);
        }
        // Nothing is pending, so the first sweep only finds the largest unshot magnitude for the first round.
        self.phase = Self::new_sweep();
        self.shots = 0;
        self.sweeps = 0;
        self.links = 0;
        self.judged = 0;
    }

    /// A sweep from the first node with nothing changed yet.
    fn new_sweep() -> Phase<S> {
        Phase::Sweep { next: 0, depth: 0, largest: S::ZERO, usable: true, stale: false }
    }

    /// Unshot power was injected outside a step: a converged solver judges again, and a sweep that already
    /// left some nodes is run again before its largest magnitude is trusted.
    fn changed(&mut self) {
        match &mut self.phase {
            Phase::Converged => self.phase = Self::new_sweep(),
            Phase::Sweep { next, stale, .. } if *next > 0 => *stale = true,
            _ => {}
        }
    }

    fn leaf_area(&self, leaf: u32) -> S {
        S::from_f32(self.table.leaf_area(leaf).unwrap_or(0.0))
    }

    /// Refreshes material `m`'s cached decoded reflectance from the reflectance buffer (nothing beyond the cache).
    fn refresh_rho(&mut self, m: u32) {
        let code = self.buf.reflectance.get(m as usize).copied().unwrap_or([0; 3]);
        if let Some(r) = self.rho_cache.get_mut(m as usize) {
            *r = code.map(S::rho);
        }
    }

    /// Current reflectance codes of `leaf`'s material.
    fn rho(&self, leaf: u32) -> [u16; 3] {
        let m = self.table.material(leaf).unwrap_or(0);
        self.buf.reflectance.get(m as usize).copied().unwrap_or([0; 3])
    }

    /// The power of `leaf` without its light-group emission: static emission `E_l A_l` plus the reflected
    /// `rho_l H_l` (static irradiance included in `H_l`).
    fn base_power(&self, leaf: u32) -> [S; 3] {
        let a = self.leaf_area(leaf);
        let e = self.table.base_emission(leaf).unwrap_or([0; 3]);
        let h = self.buf.incident.get(leaf as usize).copied().unwrap_or([S::ZERO; 3]);
        let rho = self.rho(leaf);
        [0, 1, 2].map(|c| emission::<S>(e[c]).mul(a).add(h[c].mul_frac(decode_reflectance(rho[c]))))
    }

    /// The power member `k` (of group `g`) emits at intensity `scale`: `scale e_k A_l`, and its leaf.
    fn member_power(&self, k: u32, scale: [S; 3]) -> Option<(u32, [S; 3])> {
        let m = self.table.member(k)?;
        let a = self.leaf_area(m.leaf);
        Some((m.leaf, [0, 1, 2].map(|c| scale[c].mul(S::from_f32(m.emission[c])).mul(a))))
    }

    /// Adds `scale` times group `g`'s unit emission (times area) to its members' chains; returns the work (one
    /// unit per member and per node walked).
    fn add_group_emission(&mut self, g: u32, scale: [S; 3]) -> u32 {
        let mut units = 0u32;
        for k in self.table.group_members(g).unwrap_or(0..0) {
            let Some((leaf, d)) = self.member_power(k, scale) else { continue };
            units = units.saturating_add(1 + self.add_to_chain(leaf, d));
        }
        units
    }

    /// Adds `d` to the unshot power of `leaf` and every sending ancestor; returns the nodes walked.
    fn add_to_chain(&mut self, leaf: u32, d: [S; 3]) -> u32 {
        self.walk_chain(leaf, |s, slot| s.add_unshot(slot, d))
    }

    /// Calls `f` with the slot of `leaf` and of each of its ancestors, leaf first; returns the nodes walked.
    fn walk_chain(&mut self, leaf: u32, mut f: impl FnMut(&mut Self, u32)) -> u32 {
        let Some(mut node) = self.table.leaf_node(leaf) else { return 0 };
        let mut walked = 0u32;
        // Bounded by the depth (parents precede children, checked by parse).
        for _ in 0..self.table.max_depth() {
            f(self, self.table.slot_unchecked(node));
            walked += 1;
            match self.table.parent(node) {
                Some(p) => node = p,
                None => break,
            }
        }
        walked
    }

    /// Whether the sender in `slot` has links.
    fn slot_has_links(&self, slot: u32) -> bool {
        let (start, end) = self.table.run_bounds(slot);
        end > start
    }

    /// Adds `d` to the unshot power of the node in `slot` if it has links (a node without links never shoots).
    fn add_unshot(&mut self, slot: u32, d: [S; 3]) {
        if !self.slot_has_links(slot) {
            return;
        }
        if let Some(u) = self.buf.unshot.get_mut(slot as usize) {
            *u = add3(*u, d);
        }
    }

    /// The unshot power of the node in `slot` (zero for a node without links: what links reaching such a leaf
    /// add to its entry is never read).
    fn unshot_of(&self, slot: u32) -> [S; 3] {
        if !self.slot_has_links(slot) {
            return [S::ZERO; 3];
        }
        self.buf.unshot.get(slot as usize).copied().unwrap_or([S::ZERO; 3])
    }

    /// Runs actions (module docs) until convergence or until `budget` work units are spent. Every action
    /// costs one unit, so any budget of at least one unit makes progress.
    pub fn step(&mut self, budget: u32) -> Outcome {
        let mut used = 0u32;
        loop {
            match self.phase {
                Phase::Converged => return Outcome::Converged { used },
                Phase::OutOfRange => {
                    return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                }
                _ => {}
            }
            if used >= budget {
                return if used == 0 {
                    Outcome::NoProgress { used, reason: NoProgressReason::BudgetTooSmall { needed: 1 } }
                } else {
                    Outcome::BudgetSpent { used }
                };
            }
            match self.phase {
                Phase::Converged | Phase::OutOfRange => {}
                Phase::Round { threshold, next } => {
                    let nodes = self.table.node_count();
                    if next >= nodes {
                        self.sweeps = self.sweeps.saturating_add(1);
                        self.phase = Self::new_sweep();
                        continue;
                    }
                    // As many nodes as the budget allows, one unit each, until one shoots.
                    let range = (next, nodes.min(next.saturating_add(budget - used)));
                    let tolerance = self.config.tolerance;
                    let (judged, shooter) =
                        links::judge(&self.table, self.buf.unshot, range, threshold, tolerance);
                    used += judged;
                    self.judged = self.judged.saturating_add(u64::from(judged));
                    let Some((sender, u, run)) = shooter else {
                        self.phase = Phase::Round { threshold, next: next + judged };
                        continue;
                    };
                    // With overshooting the shot sends `(1 + overshoot / 256) U_s` and leaves
                    // `-overshoot / 256 U_s`, as the flat solver does.
                    let extra = Frac { mantissa: u32::from(self.config.overshoot), shift: 8 };
                    let power = u.map(|x| x.add(x.mul_frac(extra)));
                    if let Some(v) = self.buf.unshot.get_mut(sender as usize) {
                        *v = [0, 1, 2].map(|c| v[c].sub(power[c]));
                    }
                    self.shots = self.shots.saturating_add(1);
                    self.phase = Phase::Shooting { sender, power, next: run.start, end: run.end, threshold };
                }
                Phase::Shooting { sender, power, next, end, threshold } => {
                    if next >= end {
                        self.phase = Phase::Round { threshold, next: sender + 1 };
                        continue;
                    }
                    // As many links as the budget allows, one unit each, in one loop over the run.
                    let count = (end - next).min(budget - used);
                    used += count;
                    self.links = self.links.saturating_add(u64::from(count));
                    let links = (sender, next, next + count);
                    if !links::apply_run(&self.table, &mut self.buf, &self.rho_cache, links, power) {
                        self.phase = Phase::OutOfRange;
                        return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                    }
                    self.phase = Phase::Shooting { sender, power, next: next + count, end, threshold };
                }
                Phase::Sweep { mut next, mut depth, mut largest, mut usable, stale } => {
                    // Enter and leave nodes while the budget lasts, one unit each: the top frame is left once
                    // the preorder has passed its subtree, else the next node is entered.
                    let nodes = self.table.node_count();
                    let mut left = budget - used;
                    let mut finished = false;
                    while left > 0 {
                        let top = depth.checked_sub(1).and_then(|d| self.buf.path.get(d as usize));
                        if top.is_some_and(|f| next >= f.end) {
                            match self.leave(depth) {
                                Some(m) if !m.is_usable() => usable = false,
                                Some(m) if m > largest => largest = m,
                                _ => {}
                            }
                            depth -= 1;
                        } else if next < nodes {
                            self.enter(next, depth);
                            next += 1;
                            depth += 1;
                        } else {
                            finished = true;
                            break;
                        }
                        left -= 1;
                    }
                    used = budget - left;
                    self.phase = Phase::Sweep { next, depth, largest, usable, stale };
                    if !finished {
                        continue;
                    }
                    if stale {
                        self.phase = Self::new_sweep();
                        continue;
                    }
                    if !usable {
                        return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                    }
                    if largest <= self.config.tolerance {
                        self.phase = Phase::Converged;
                        return Outcome::Converged { used };
                    }
                    self.phase = Phase::Round { threshold: round_threshold(largest), next: 0 };
                }
            }
        }
    }

    /// A sweep enters `node` (preorder; the path's top frame, at `depth - 1`, is its parent's, or the path is
    /// empty for a root) and pushes its frame (with the node's slot, and its subtree end, which says when to
    /// leave it). An
    /// inner node's chain irradiance is its parent's plus its own pending power over its area, and its subtree
    /// sum starts with its reflected entry (both taken, leaving zeros). A leaf takes
    /// its parent's chain irradiance, the irradiance of every link above it since the last sweep: incident
    /// power `dH = A_l e`, and its reflected power `rho_l dH` starts the frame's subtree sum.
    fn enter(&mut self, node: u32, depth: u32) {
        let above = depth
            .checked_sub(1)
            .and_then(|d| self.buf.path.get(d as usize))
            .map_or([S::ZERO; 3], |f| f.irradiance);
        // A leaf or an inner node, and its leaf or inner index, from two adjacent leaf starts.
        let nodes = self.table.node_sections();
        let (l, next) = nodes.leaf_starts(node);
        let leaf = next != l;
        let slot = slot_of(node, l, leaf, self.table.leaf_count());
        let end = if leaf { node.wrapping_add(1) } else { self.table.subtree_end_unchecked(node) };
        let area = S::from_f32(self.table.node_area_unchecked(node));
        let (e, reflected) = if leaf {
            // A leaf (its node's area is its own).
            let rho =
                links::cached_rho::<S>(&self.rho_cache, self.buf.reflectance, nodes.material(l) as usize);
            let dh = above.map(|q| q.mul(area));
            if let Some(v) = self.buf.incident.get_mut(l as usize) {
                *v = add3(*v, dh);
            }
            (above, [0, 1, 2].map(|c| dh[c].mul_rho(rho[c])))
        } else {
            let i = node.wrapping_sub(l) as usize;
            let take =
                |v: Option<&mut [S; 3]>| v.map_or([S::ZERO; 3], |v| core::mem::replace(v, [S::ZERO; 3]));
            let pending = take(self.buf.pending.get_mut(i)).map(|p| p.div(area));
            (add3(above, pending), take(self.buf.reflected.get_mut(i)))
        };
        if let Some(f) = self.buf.path.get_mut(depth as usize) {
            *f = SweepFrame { slot, end, irradiance: e, reflected };
        }
    }

    /// A sweep leaves the node of the top frame (at `depth - 1`) once its subtree is done: the power
    /// reflected in its subtree since the last sweep goes into its unshot power (if it has links) and into
    /// its parent's frame. Returns the node's unshot magnitude if it has links.
    fn leave(&mut self, depth: u32) -> Option<S> {
        let top = depth.checked_sub(1)?;
        let frame = *self.buf.path.get(top as usize)?;
        if let Some(parent) = top.checked_sub(1).and_then(|d| self.buf.path.get_mut(d as usize)) {
            parent.reflected = add3(parent.reflected, frame.reflected);
        }
        let (start, end) = self.table.run_bounds(frame.slot);
        if end <= start {
            return None;
        }
        let u = self.buf.unshot.get_mut(frame.slot as usize)?;
        *u = add3(*u, frame.reflected);
        Some(magnitude(*u))
    }

    /// Sets light `group` to intensity `rgb`: every member's emission change is injected as unshot power
    /// (warm start). Returns the work done (one unit per member and per node walked), outside any budget.
    ///
    /// # Errors
    /// [`SolverError::NoSuchGroup`], [`SolverError::BadValue`] (not finite).
    pub fn set_light(&mut self, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        if group >= self.table.group_count() {
            return Err(SolverError::NoSuchGroup { group });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !v.is_finite() {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        let new = rgb.map(S::from_f32);
        let old = self.intensity(group).unwrap_or([S::ZERO; 3]);
        if let Some(v) = self.buf.intensity.get_mut(group as usize) {
            *v = new;
        }
        let units = self.add_group_emission(group, [0, 1, 2].map(|c| new[c].sub(old[c])));
        Ok(units.saturating_add(self.light_changed(group)))
    }

    /// After light `group`'s change was added to its members' chains: a converged solver has nothing pending
    /// and every node's unshot magnitude within the tolerance, so the sweep that [`HierSolver::changed`] would
    /// start moves nothing and only finds the largest magnitude, which is then on the chains just changed. They
    /// are walked again for it (one unit per member and per node walked, returned) and the round starts at
    /// once, with the threshold that sweep would have set, or the solver stays converged when no magnitude
    /// exceeds the tolerance (what that sweep would have found). In any other phase, or with an unusable
    /// magnitude (for the sweep to report), [`HierSolver::changed`].
    fn light_changed(&mut self, group: u32) -> u32 {
        if !matches!(self.phase, Phase::Converged) {
            self.changed();
            return 0;
        }
        let (mut largest, mut usable, mut units) = (S::ZERO, true, 0u32);
        for k in self.table.group_members(group).unwrap_or(0..0) {
            let Some(m) = self.table.member(k) else { continue };
            // A node without links reads as zero unshot power, which never raises the largest.
            let walked = self.walk_chain(m.leaf, |s, slot| {
                let v = magnitude(s.unshot_of(slot));
                if !v.is_usable() {
                    usable = false;
                } else if v > largest {
                    largest = v;
                }
            });
            units = units.saturating_add(1 + walked);
        }
        if !usable {
            self.changed();
        } else if largest > self.config.tolerance {
            self.phase = Phase::Round { threshold: round_threshold(largest), next: 0 };
        }
        units
    }

    /// Sets the reflectance of `material` to `rgb` (each in `[0, 1)`, quantized by the reflectance codec): for
    /// every leaf of the material, `(rho_new - rho_old) H_l` is injected as unshot power (the leaf's power,
    /// read out as `E_l A_l + rho_l H_l`, changes by as much). Returns the work done (one unit per leaf scanned
    /// and per node walked), outside any budget.
    ///
    /// # Errors
    /// [`SolverError::NoSuchMaterial`], [`SolverError::BadValue`] (not in `[0, 1)`).
    pub fn set_reflectance(&mut self, material: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        if material >= self.table.material_count() {
            return Err(SolverError::NoSuchMaterial { material });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !(0.0..1.0).contains(v) {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        let old = self.buf.reflectance.get(material as usize).copied().unwrap_or([0; 3]);
        let new = rgb.map(encode_reflectance);
        if let Some(r) = self.buf.reflectance.get_mut(material as usize) {
            *r = new;
        }
        self.refresh_rho(material);
        let mut units = 0u32;
        for l in 0..self.table.leaf_count() {
            units = units.saturating_add(1);
            if self.table.material(l) != Some(material) {
                continue;
            }
            let h = self.buf.incident.get(l as usize).copied().unwrap_or([S::ZERO; 3]);
            // rho_new H - rho_old H, each product rounded as the readout rounds it.
            let d = [0, 1, 2].map(|c| {
                h[c].mul_frac(decode_reflectance(new[c])).sub(h[c].mul_frac(decode_reflectance(old[c])))
            });
            units = units.saturating_add(self.add_to_chain(l, d));
        }
        self.changed();
        Ok(units)
    }

    /// The table this solver runs.
    #[must_use]
    pub fn table(&self) -> &HierTable<'a> {
        &self.table
    }

    /// Current intensity of light `group`.
    #[must_use]
    pub fn intensity(&self, group: u32) -> Option<[S; 3]> {
        self.buf.intensity.get(group as usize).copied().filter(|_| group < self.table.group_count())
    }

    /// Power `Phi_l = B_l A_l` (RGB) of `leaf`: `E_l A_l + rho_l H_l`, its emission (static and every light
    /// group's members on it at their current intensities) plus its reflected incident power. `O(members)`
    /// (the member list is searched for the leaf); [`HierSolver::power_into`] reads every leaf in
    /// `O(leaves + members)` with the same bits.
    #[must_use]
    pub fn power(&self, leaf: u32) -> Option<[S; 3]> {
        if leaf >= self.table.leaf_count() {
            return None;
        }
        let mut p = self.base_power(leaf);
        for g in 0..self.table.group_count() {
            let scale = self.intensity(g).unwrap_or([S::ZERO; 3]);
            for k in self.table.group_members(g).unwrap_or(0..0) {
                match self.member_power(k, scale) {
                    Some((l, d)) if l == leaf => p = add3(p, d),
                    _ => {}
                }
            }
        }
        Some(p)
    }

    /// Writes the power of leaves `0..out.len()` (at most every leaf) into `out`, bit for bit what
    /// [`HierSolver::power`] returns for each, in `O(leaves + members)`. Returns the leaves written.
    pub fn power_into(&self, out: &mut [[S; 3]]) -> usize {
        let n = out.len().min(self.table.leaf_count() as usize);
        for (l, p) in out.iter_mut().take(n).enumerate() {
            *p = self.base_power(l as u32);
        }
        for g in 0..self.table.group_count() {
            let scale = self.intensity(g).unwrap_or([S::ZERO; 3]);
            for k in self.table.group_members(g).unwrap_or(0..0) {
                let Some((l, d)) = self.member_power(k, scale) else { continue };
                if let Some(p) = out.get_mut(l as usize).filter(|_| (l as usize) < n) {
                    *p = add3(*p, d);
                }
            }
        }
        n
    }

    /// Radiosity `B_l = Phi_l / A_l` (W/m^2, RGB) of `leaf`, from [`HierSolver::power`] (`O(members)`).
    #[must_use]
    pub fn radiosity(&self, leaf: u32) -> Option<[S; 3]> {
        let p = self.power(leaf)?;
        let a = self.leaf_area(leaf);
        Some(p.map(|x| x.div(a)))
    }

    /// Writes the radiosity of leaves `0..out.len()` (at most every leaf) into `out`, bit for bit what
    /// [`HierSolver::radiosity`] returns for each, in `O(leaves + members)`. Returns the leaves written.
    pub fn radiosity_into(&self, out: &mut [[S; 3]]) -> usize {
        let n = self.power_into(out);
        for (l, b) in out.iter_mut().take(n).enumerate() {
            let a = self.leaf_area(l as u32);
            *b = b.map(|x| x.div(a));
        }
        n
    }

    /// Unshot power `U_n` (RGB) of `node` (zero for a node without links): excluding a shot in flight, and
    /// the power reflected from what is still pending (shot since the last sweep entered the receiver).
    #[must_use]
    pub fn unshot(&self, node: u32) -> Option<[S; 3]> {
        self.table.slot(node).map(|slot| self.unshot_of(slot))
    }

    /// Shots started since the last cold start (saturating).
    #[must_use]
    pub fn shots(&self) -> u32 {
        self.shots
    }

    /// Sweeps (over the tree after a round of shots) started since the last cold start (saturating).
    #[must_use]
    pub fn sweeps(&self) -> u32 {
        self.sweeps
    }

    /// Links applied since the last cold start.
    #[must_use]
    pub fn links(&self) -> u64 {
        self.links
    }

    /// Nodes judged in rounds since the last cold start (saturating): with [`HierSolver::links`], what
    /// separates a step's units into its kinds of work (the rest are nodes entered or left by sweeps).
    #[must_use]
    pub fn judged(&self) -> u64 {
        self.judged
    }
}
