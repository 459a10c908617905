//! Hierarchical shooting (layer 5b): [`HierSolver`] relights a [`HierTable`] with bounded, resumable steps.
//!
//! Hierarchical radiosity (Hanrahan, Salzman, Aupperle, "A rapid hierarchical radiosity algorithm", SIGGRAPH
//! 1991) solved by progressive refinement shooting (Cohen, Chen, Wallace, Greenberg, SIGGRAPH 1988) over its
//! links, with push-pull done as power moves.
//!
//! # The scheme
//! - Every node `n` keeps `U_n`, the power emitted or reflected in `n`'s subtree that has not yet been shot
//!   through `n`'s own links. A leaf's new power is added to `U` of the leaf and of every ancestor that has
//!   links: the links of a leaf's chain (the leaf and its ancestors) each carry their part of the leaf's
//!   interactions ("pull" is these additions).
//! - A shot takes the node `s` with the largest unshot magnitude `|r| + |g| + |b|` (ties to the lower node),
//!   sets `U_s = 0` and walks its run: link `(r, F_sr)` delivers incident power `F_sr U_s` to node `r`, spread
//!   over the leaves below `r` by area ("push": leaf `l` receives `F_sr U_s A_l / A_r`, the irradiance of `r`
//!   taken as uniform over it). A leaf adds what it receives to its incident power `H_l`, reflects
//!   `rho_l` of it into its power `Phi_l` and into `U` along its chain up to `r`; the sum reflected below `r` is
//!   then added to `U` of `r`'s linked ancestors once.
//! - So the solver converges to the solution of `B_l = E_l + rho_l sum_{r in chain(l)} (1 / A_r) sum_s F_sr
//!   Phi_s`, `Phi_s` the power of the leaves below sender `s`: the linear system of the table's hierarchy.
//!   The table's chain bound (every leaf's chain of decoded run sums `<= 1`, checked by
//!   [`HierTable::parse`]) makes the power a leaf shoots at most the power it holds, and reflectances are
//!   `< 1`, so the total unshot magnitude shrinks geometrically and shooting converges.
//! - Light changes ([`HierSolver::set_light`]) and reflectance edits ([`HierSolver::set_reflectance`]) are
//!   injected as unshot power at the leaves, as the flat [`Solver`](crate::Solver) does; the static base as in
//!   the crate docs. Overshooting ([`Config::overshoot`]) works as in the flat solver: a shot sends
//!   `(1 + overshoot / 256) U_s` and leaves the excess as negative unshot power.
//!
//! # Work units
//! One unit each: a link decoded (its share of the shot computed); a leaf receiving pushed power (incident,
//! reflected and radiosity updated); a node visited on an upward walk (its unshot power updated and compared
//! with its selection block's winner); a selection block winner compared; a node scanned when a selection
//! block is rescanned (a block is marked for a rescan when its winner's unshot magnitude falls). An action
//! starts only if its worst case fits in what is left of the budget: a link 1, a leaf `1 + max_depth`, the pull
//! above a receiver `max_depth`, a selection block `B + 1` (`B` the block length); a step never spends more
//! than its budget and the next step resumes where it stopped. The sequence of actions does not depend on how
//! the budget is split, so runs with different budgets are bit-identical at every action boundary, and at
//! convergence.
//!
//! A link to a receiver with `k` leaves costs about `k (1 + d)` units, `d` the depth of those leaves below it:
//! the push is eager. Links to large clusters therefore cost in proportion to the leaves they light.
//!
//! Outside any budget, returned as work counts: [`HierSolver::set_light`] (members times their chain walks),
//! [`HierSolver::set_reflectance`] (leaves scanned plus chain walks); [`HierSolver::new`] and
//! [`HierSolver::reset`] are `O(leaves x depth + links)`.
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

#[cfg(any(test, feature = "std"))]
pub use buffers::HierOwnedBuffers;
pub use buffers::{HierBufferSizes, HierBuffers, HierStaticBuffers};

use crate::base::emission;
use crate::codec::{decode_reflectance, encode_reflectance, Frac};
use crate::format::HierTable;
use crate::scalar::Scalar;
use crate::solver::{
    block_shift, selection_len, Config, NoProgressReason, Outcome, SolverError, MAX_PATCHES,
};

/// Marks a selection block whose stored winner may no longer hold the block's largest unshot magnitude.
const RESCAN: u32 = 1 << 31;

/// A push in progress: the irradiance (incident power per unit area) being spread over `receiver`'s leaves.
#[derive(Clone, Copy, Debug)]
struct Push<S> {
    receiver: u32,
    irradiance: [S; 3],
    next_leaf: u32,
    end_leaf: u32,
    /// Power reflected below the receiver so far: added to its linked ancestors when the leaves are done.
    reflected: [S; 3],
}

/// Where the solver is in its sequence of actions.
#[derive(Clone, Copy, Debug)]
enum Phase<S> {
    /// Choosing the next shooter: blocks `< next_block` compared, the best so far.
    Selecting { next_block: u32, best: Option<u32> },
    /// Shooting `sender`'s `power` over its run: next link position, run end, the push of the current link.
    Shooting { sender: u32, power: [S; 3], next: u32, end: u32, push: Option<Push<S>> },
    /// Every node's unshot magnitude is within the tolerance (until a change).
    Converged,
}

/// Hierarchical solver state: the current solution of one [`HierTable`], in the caller's buffers.
#[derive(Debug)]
pub struct HierSolver<'a, S: Scalar> {
    table: HierTable<'a>,
    buf: HierBuffers<'a, S>,
    config: Config<S>,
    block_shift: u32,
    blocks: u32,
    phase: Phase<S>,
    shots: u32,
    links: u64,
}

fn add3<S: Scalar>(a: [S; 3], b: [S; 3]) -> [S; 3] {
    [a[0].add(b[0]), a[1].add(b[1]), a[2].add(b[2])]
}

fn magnitude<S: Scalar>(v: [S; 3]) -> S {
    v[0].abs().add(v[1].abs()).add(v[2].abs())
}

/// The smallest tolerance [`HierSolver::new`] accepts for `table` on arithmetic `S` (zero for f32). The flat
/// solver's argument ([`crate::convergence_floor`], the `scalar` module docs) with the rounded receipts of a
/// shot counted as the leaves its links reach times the chain walks that repeat each leaf's rounding:
/// `ceil(6 R D / (1 - rho_max))`, `R` the most leaves any run reaches (with multiplicity), `D` the longest
/// chain. `O(links + materials)`.
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
            block_shift: block_shift(nodes),
            blocks: selection_len(nodes),
            phase: Phase::Selecting { next_block: 0, best: None },
            shots: 0,
            links: 0,
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
        for b in 0..self.blocks {
            if let Some(w) = self.buf.selection.get_mut(b as usize) {
                *w = RESCAN;
            }
        }
        let solved = self.table.base_solved();
        for l in 0..self.table.leaf_count() {
            let a: S = self.leaf_area(l);
            let e = self.table.base_emission(l).unwrap_or([0; 3]);
            let g = self.table.base_irradiance(l).unwrap_or([0; 3]);
            let rho = self.rho(l);
            let h = [0, 1, 2].map(|c| emission::<S>(g[c]).mul(a));
            let p =
                [0, 1, 2].map(|c| emission::<S>(e[c]).mul(a).add(h[c].mul_frac(decode_reflectance(rho[c]))));
            if let Some(v) = self.buf.power.get_mut(l as usize) {
                *v = p;
            }
            if let Some(v) = self.buf.incident.get_mut(l as usize) {
                *v = h;
            }
            if !solved {
                self.add_to_chain(l, p);
            }
        }
        for g in 0..self.table.group_count() {
            let rgb = self.buf.intensity.get(g as usize).copied().unwrap_or([S::ZERO; 3]);
            self.add_group_emission(g, rgb);
        }
        self.phase = Phase::Selecting { next_block: 0, best: None };
        self.shots = 0;
        self.links = 0;
    }

    fn leaf_area(&self, leaf: u32) -> S {
        S::from_f32(self.table.leaf_area(leaf).unwrap_or(0.0))
    }

    /// Current reflectance codes of `leaf`'s material.
    fn rho(&self, leaf: u32) -> [u16; 3] {
        let m = self.table.material(leaf).unwrap_or(0);
        self.buf.reflectance.get(m as usize).copied().unwrap_or([0; 3])
    }

    /// Adds `scale` times group `g`'s unit emission (times area) to its members' power and chains; returns the
    /// work (one unit per member and per node walked).
    fn add_group_emission(&mut self, g: u32, scale: [S; 3]) -> u32 {
        let mut units = 0u32;
        for k in self.table.group_members(g).unwrap_or(0..0) {
            let Some(m) = self.table.member(k) else { continue };
            let a = self.leaf_area(m.patch);
            let d = [0, 1, 2].map(|c| scale[c].mul(emission::<S>(m.emission[c])).mul(a));
            if let Some(v) = self.buf.power.get_mut(m.patch as usize) {
                *v = add3(*v, d);
            }
            units = units.saturating_add(1 + self.add_to_chain(m.patch, d));
        }
        units
    }

    /// Adds `d` to the unshot power of `leaf` and every linked ancestor; returns the nodes walked.
    fn add_to_chain(&mut self, leaf: u32, d: [S; 3]) -> u32 {
        let Some(mut node) = self.table.leaf_node(leaf) else { return 0 };
        let mut walked = 0u32;
        // Bounded by the depth (parents precede children, checked by parse).
        for _ in 0..self.table.max_depth() {
            self.add_unshot(node, d);
            walked += 1;
            match self.table.parent(node) {
                Some(p) => node = p,
                None => break,
            }
        }
        walked
    }

    /// Selection rank of `node`'s unshot magnitude (see the flat solver's selection).
    fn rank(&self, node: u32) -> S::Rank {
        magnitude(self.buf.unshot.get(node as usize).copied().unwrap_or([S::ZERO; 3])).rank(node)
    }

    /// Adds `d` to `node`'s unshot power (if it has links: a node without links never shoots) and keeps its
    /// block's winner: a larger rank takes over; the winner falling marks the block for a rescan.
    fn add_unshot(&mut self, node: u32, d: [S; 3]) {
        if !self.table.has_links(node) {
            return;
        }
        let before = self.rank(node);
        if let Some(u) = self.buf.unshot.get_mut(node as usize) {
            *u = add3(*u, d);
        }
        self.touched(node, before);
    }

    /// Keeps `node`'s block winner current after its unshot power changed from rank `before`.
    fn touched(&mut self, node: u32, before: S::Rank) {
        let b = (node >> self.block_shift) as usize;
        let Some(&w) = self.buf.selection.get(b) else { return };
        if w & RESCAN != 0 {
            return;
        }
        let now = self.rank(node);
        let winner = if w == node {
            if now < before {
                RESCAN
            } else {
                node
            }
        } else if now > self.rank(w) {
            node
        } else {
            w
        };
        if let Some(s) = self.buf.selection.get_mut(b) {
            *s = winner;
        }
        // A change after the selection passed this block may make another node the best.
        if let Phase::Selecting { next_block, .. } = self.phase {
            if next_block > 0 {
                self.phase = Phase::Selecting { next_block: 0, best: None };
            }
        } else if let Phase::Converged = self.phase {
            self.phase = Phase::Selecting { next_block: 0, best: None };
        }
    }

    /// Nodes of selection block `b`.
    fn block_range(&self, b: u32) -> core::ops::Range<u32> {
        let n = self.table.node_count();
        let start = b << self.block_shift;
        start.min(n)..start.saturating_add(1 << self.block_shift).min(n)
    }

    /// Rescans block `b` and stores its winner (nodes without links hold zero); returns the nodes scanned.
    fn rescan(&mut self, b: u32) -> u32 {
        let range = self.block_range(b);
        let mut best = range.start;
        let mut best_rank = self.rank(best);
        for i in range.clone() {
            let r = self.rank(i);
            if r > best_rank {
                best = i;
                best_rank = r;
            }
        }
        if let Some(s) = self.buf.selection.get_mut(b as usize) {
            *s = best;
        }
        range.end - range.start
    }

    /// The largest action's cost: what a budget must at least hold for a step to make progress.
    fn largest_action(&self) -> u32 {
        (1u32 << self.block_shift).saturating_add(1).max(self.table.max_depth().saturating_add(1))
    }

    /// Runs shooting actions (module docs) until convergence or until the next action would not fit in
    /// `budget` work units.
    pub fn step(&mut self, budget: u32) -> Outcome {
        let mut used = 0u32;
        loop {
            let left = budget.saturating_sub(used);
            match self.phase {
                Phase::Converged => return Outcome::Converged { used },
                Phase::Selecting { next_block, best } => {
                    if next_block >= self.blocks {
                        let Some(s) = best else {
                            self.phase = Phase::Converged;
                            return Outcome::Converged { used };
                        };
                        let u = self.buf.unshot.get(s as usize).copied().unwrap_or([S::ZERO; 3]);
                        let m = magnitude(u);
                        if !m.is_usable() {
                            return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                        }
                        if m <= self.config.tolerance {
                            self.phase = Phase::Converged;
                            return Outcome::Converged { used };
                        }
                        // Starting a shot costs nothing beyond the selection: the shot power, what is left as
                        // unshot power and the block mark. With overshooting the shot sends
                        // `(1 + overshoot / 256) U_s` and leaves `-overshoot / 256 U_s`, as the flat solver does.
                        let range = self.table.run(s).unwrap_or(0..0);
                        let extra = Frac { mantissa: u32::from(self.config.overshoot), shift: 8 };
                        let u = u.map(|x| x.add(x.mul_frac(extra)));
                        if let Some(v) = self.buf.unshot.get_mut(s as usize) {
                            *v = [0, 1, 2].map(|c| v[c].sub(u[c]));
                        }
                        let b = (s >> self.block_shift) as usize;
                        if let Some(w) = self.buf.selection.get_mut(b) {
                            *w = RESCAN;
                        }
                        self.shots = self.shots.saturating_add(1);
                        self.phase = Phase::Shooting {
                            sender: s,
                            power: u,
                            next: range.start,
                            end: range.end,
                            push: None,
                        };
                        continue;
                    }
                    let b = next_block;
                    let needed = (1u32 << self.block_shift) + 1;
                    if left < needed {
                        return self.stop(used, needed);
                    }
                    let mut cost = 1;
                    let w = self.buf.selection.get(b as usize).copied().unwrap_or(RESCAN);
                    let w = if w & RESCAN != 0 {
                        cost += self.rescan(b);
                        self.buf.selection.get(b as usize).copied().unwrap_or(0)
                    } else {
                        w
                    };
                    // Nodes without links hold no unshot power: a block of them offers a zero magnitude.
                    let best = match best {
                        Some(x) if self.rank(x) >= self.rank(w) => Some(x),
                        _ => Some(w),
                    };
                    used += cost;
                    self.phase = Phase::Selecting { next_block: b + 1, best };
                }
                Phase::Shooting { sender, power, next, end, push: None } => {
                    if next >= end {
                        self.phase = Phase::Selecting { next_block: 0, best: None };
                        continue;
                    }
                    if left < 1 {
                        return self.stop(used, 1);
                    }
                    used += 1;
                    self.links = self.links.saturating_add(1);
                    let push = self.table.link(sender, next).and_then(|(r, f)| {
                        let area = S::from_f32(self.table.node_area(r)?);
                        let leaves = self.table.leaf_range(r)?;
                        Some(Push {
                            receiver: r,
                            irradiance: power.map(|p| p.mul_frac(f).div(area)),
                            next_leaf: leaves.start,
                            end_leaf: leaves.end,
                            reflected: [S::ZERO; 3],
                        })
                    });
                    self.phase = Phase::Shooting { sender, power, next: next + 1, end, push };
                }
                Phase::Shooting { sender, power, next, end, push: Some(mut p) } => {
                    let depth = self.table.max_depth();
                    if p.next_leaf < p.end_leaf {
                        let needed = depth.saturating_add(1);
                        if left < needed {
                            return self.stop(used, needed);
                        }
                        used += 1 + self.push_leaf(&mut p);
                        p.next_leaf += 1;
                    } else {
                        if left < depth {
                            return self.stop(used, depth);
                        }
                        let mut node = p.receiver;
                        for _ in 0..depth {
                            let Some(a) = self.table.parent(node) else { break };
                            self.add_unshot(a, p.reflected);
                            used += 1;
                            node = a;
                        }
                        self.phase = Phase::Shooting { sender, power, next, end, push: None };
                        continue;
                    }
                    if let Phase::Shooting { push, .. } = &mut self.phase {
                        *push = Some(p);
                    }
                }
            }
        }
    }

    /// Pushes the next leaf of `p`: incident and reflected power, and the reflected power up the leaf's chain
    /// to the receiver; returns the nodes walked.
    fn push_leaf(&mut self, p: &mut Push<S>) -> u32 {
        let l = p.next_leaf;
        let a = self.leaf_area(l);
        let rho = self.rho(l);
        let dh = p.irradiance.map(|q| q.mul(a));
        let dphi = [0, 1, 2].map(|c| dh[c].mul_frac(decode_reflectance(rho[c])));
        if let Some(v) = self.buf.incident.get_mut(l as usize) {
            *v = add3(*v, dh);
        }
        if let Some(v) = self.buf.power.get_mut(l as usize) {
            *v = add3(*v, dphi);
        }
        p.reflected = add3(p.reflected, dphi);
        let Some(mut node) = self.table.leaf_node(l) else { return 0 };
        let mut walked = 0;
        // The receiver is an ancestor-or-self of every leaf in its range (checked by parse).
        for _ in 0..self.table.max_depth() {
            self.add_unshot(node, dphi);
            walked += 1;
            if node == p.receiver {
                break;
            }
            match self.table.parent(node) {
                Some(q) => node = q,
                None => break,
            }
        }
        walked
    }

    /// The outcome of a step stopped before an action of `needed` units.
    fn stop(&self, used: u32, needed: u32) -> Outcome {
        if used == 0 {
            let needed = needed.max(self.largest_action());
            Outcome::NoProgress { used, reason: NoProgressReason::BudgetTooSmall { needed } }
        } else {
            Outcome::BudgetSpent { used }
        }
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
        Ok(self.add_group_emission(group, [0, 1, 2].map(|c| new[c].sub(old[c]))))
    }

    /// Sets the reflectance of `material` to `rgb` (each in `[0, 1)`, quantized by the reflectance codec): for
    /// every leaf of the material, `(rho_new - rho_old) H_l` is added to its power and injected as unshot
    /// power. Returns the work done (one unit per leaf scanned and per node walked), outside any budget.
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
        let mut units = 0u32;
        for l in 0..self.table.leaf_count() {
            units = units.saturating_add(1);
            if self.table.material(l) != Some(material) {
                continue;
            }
            let h = self.buf.incident.get(l as usize).copied().unwrap_or([S::ZERO; 3]);
            // rho_new H - rho_old H, each product rounded as a push rounds it.
            let d = [0, 1, 2].map(|c| {
                h[c].mul_frac(decode_reflectance(new[c])).sub(h[c].mul_frac(decode_reflectance(old[c])))
            });
            if let Some(v) = self.buf.power.get_mut(l as usize) {
                *v = add3(*v, d);
            }
            units = units.saturating_add(self.add_to_chain(l, d));
        }
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

    /// Power `Phi_l = B_l A_l` (RGB) of `leaf`.
    #[must_use]
    pub fn power(&self, leaf: u32) -> Option<[S; 3]> {
        self.buf.power.get(leaf as usize).copied().filter(|_| leaf < self.table.leaf_count())
    }

    /// Radiosity `B_l = Phi_l / A_l` (W/m^2, RGB) of `leaf`.
    #[must_use]
    pub fn radiosity(&self, leaf: u32) -> Option<[S; 3]> {
        let p = self.power(leaf)?;
        let a = self.leaf_area(leaf);
        Some(p.map(|x| x.div(a)))
    }

    /// Unshot power `U_n` (RGB) of `node` (excluding a shot in flight).
    #[must_use]
    pub fn unshot(&self, node: u32) -> Option<[S; 3]> {
        self.buf.unshot.get(node as usize).copied().filter(|_| node < self.table.node_count())
    }

    /// Shots started since the last cold start (saturating).
    #[must_use]
    pub fn shots(&self) -> u32 {
        self.shots
    }

    /// Links applied since the last cold start.
    #[must_use]
    pub fn links(&self) -> u64 {
        self.links
    }
}
