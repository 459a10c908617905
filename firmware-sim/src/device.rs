//! The device loop, `no_std`: the one implementation the host simulator and the Cortex-M firmware both run.
//!
//! A relight [`Script`] is a list of [`Frame`]s. Each frame holds the absolute intensity (RGB) of every light
//! group and a budget in work units. [`run_frame`] applies the light groups whose intensity changed
//! ([`DeviceSolver::set_light`], outside the budget, as core documents) and then steps for at most the
//! frame's budget ([`DeviceSolver::step`]). [`run_script`] starts from the script's initial intensities,
//! solved to convergence (a device's boot), then runs every frame, timing each with a caller-supplied
//! [`Meter`] and handing a [`FrameRecord`] to the caller.
//!
//! # Two table formats, one loop
//! The loop is written once over two small traits: [`DeviceTable`] (what a table gives the loop: its light
//! groups, [`DeviceTable::unit_light_power`], and a solver on caller buffers) and [`DeviceSolver`] (what the
//! loop asks of a solver). Both are implemented for the flat format (version 3: [`Table`], [`Solver`]) and the
//! hierarchical one (version 5: [`HierTable`], [`HierSolver`]). The loop's **elements** are the flat table's
//! patches and the hierarchical table's leaves: the elements whose radiosity the device shows.
//!
//! The trace line ([`write_trace`]) is the firmware's semihosting output and the host simulator's comparison
//! key: it carries every number that must agree bit for bit (units, outcome, unshot power bits and a hash of
//! every element's radiosity bits). It is formatted here, once, so both sides print the same text. The unshot
//! power it carries is [`DeviceSolver::unshot_power`]: for a flat table core's `Solver::total_unshot` (as
//! before: the trace of a flat table is unchanged), for a hierarchical table the sum of every node's unshot
//! power (see [`DeviceSolver::unshot_power`] for what that sum counts).

use core::fmt;

use radiosity_core::codec::decode_emission_f32;
use radiosity_core::{
    relight_transfer_range, Buffers, Config, Fixed, HierBuffers, HierSolver, HierTable, Outcome, Scalar,
    Solver, SolverError, Table, TransferError, TransferTable,
};

/// One frame of a relight script.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<'a> {
    /// Work units [`DeviceSolver::step`] may spend this frame.
    pub budget: u32,
    /// Intensity (RGB multiplier of the unit emission) of every light group, in table order.
    pub intensity: &'a [[f32; 3]],
}

/// A relight script: a named sequence of frames, starting from solved initial intensities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Script<'a> {
    /// Name (letters, digits, `-`, `_`).
    pub name: &'a str,
    /// Convergence tolerance, relative: an element's (flat: patch's; hierarchical: node's) unshot power
    /// magnitude (`|r| + |g| + |b|`) may be at most this times [`DeviceTable::unit_light_power`] of the table.
    /// Relative, so one script fits tables in any units and either format.
    pub tolerance: f32,
    /// Intensity of every light group before frame 0; the device starts with this state solved.
    pub initial: &'a [[f32; 3]],
    /// Most work units the boot solve of the initial state may spend.
    pub boot_budget: u32,
    /// The frames.
    pub frames: &'a [Frame<'a>],
}

/// Exact bits of a solver number, for hashing and bit-exact comparison.
pub trait Bits: Scalar {
    /// The raw bits (f32: `to_bits`, zero-extended; [`Fixed`]: the `i64` as `u64`).
    fn bits(self) -> u64;
    /// Bytes hashed per value (4 for f32, 8 for [`Fixed`]).
    const BYTES: usize;
    /// Name of the arithmetic in traces and CSV (`f32` or `fixed`).
    const NAME: &'static str;
}

impl Bits for f32 {
    fn bits(self) -> u64 {
        u64::from(self.to_bits())
    }
    const BYTES: usize = 4;
    const NAME: &'static str = "f32";
}

impl Bits for Fixed {
    fn bits(self) -> u64 {
        self.0 as u64
    }
    const BYTES: usize = 8;
    const NAME: &'static str = "fixed";
}

/// FNV-1a, 64 bit (Fowler, Noll, Vo): a small deterministic hash for comparing radiosity bits across runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a(pub u64);

impl Fnv1a {
    /// The FNV-1a 64-bit offset basis.
    pub const NEW: Fnv1a = Fnv1a(0xcbf2_9ce4_8422_2325);

    /// Hashes the low `bytes` bytes of `v`, little-endian.
    pub fn write(&mut self, v: u64, bytes: usize) {
        for b in v.to_le_bytes().iter().take(bytes) {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// FNV-1a hash of every element's radiosity bits (element order, then R, G, B).
#[must_use]
pub fn radiosity_hash<D: DeviceSolver>(solver: &D) -> u64
where
    D::Scalar: Bits,
{
    let mut h = Fnv1a::NEW;
    for i in 0..solver.element_count() {
        for v in solver.element_radiosity(i).unwrap_or([D::Scalar::ZERO; 3]) {
            h.write(v.bits(), <D::Scalar as Bits>::BYTES);
        }
    }
    h.0
}

/// What the device loop asks of a solver: implemented for core's flat [`Solver`] and hierarchical
/// [`HierSolver`], each method the solver's own of the same name (documented there).
pub trait DeviceSolver {
    /// The solver's arithmetic.
    type Scalar: Scalar;
    /// Light groups of the solver's table.
    fn group_count(&self) -> u32;
    /// Current intensity of light `group`.
    fn intensity(&self, group: u32) -> Option<[Self::Scalar; 3]>;
    /// Sets light `group` to `rgb`; returns the work it took (outside any budget).
    ///
    /// # Errors
    /// The solver's [`SolverError`].
    fn set_light(&mut self, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError>;
    /// At most `budget` work units of solving.
    fn step(&mut self, budget: u32) -> Outcome;
    /// Back to the table's cold start (reflectances and default intensities).
    fn reset(&mut self);
    /// Elements whose radiosity the device shows: the flat table's patches, the hierarchical table's leaves.
    fn element_count(&self) -> u32;
    /// Radiosity (W/m^2, RGB) of `element`.
    fn element_radiosity(&self, element: u32) -> Option<[Self::Scalar; 3]>;
    /// The unshot power of the trace (RGB, power units, per channel a signed sum).
    ///
    /// - Flat: [`Solver::total_unshot`], the power not yet shot, including the rest of a shot in flight.
    /// - Hierarchical: the sum over every node, in node order, of [`HierSolver::unshot`]. A node's unshot
    ///   power is what its subtree reflected or emitted and has not yet shot through that node's own links,
    ///   and every linked node on a leaf's chain keeps its own share, so the sum counts a leaf's power once
    ///   per linked node above it (not a physical power: the flat sum's analogue as a progress measure, zero
    ///   when nothing is left to shoot). Excluded, as core's accessor excludes them: the rest of a shot in
    ///   flight and light still pending until the next sweep.
    fn unshot_power(&self) -> [Self::Scalar; 3];
}

impl<S: Scalar> DeviceSolver for Solver<'_, S> {
    type Scalar = S;
    fn group_count(&self) -> u32 {
        self.table().group_count()
    }
    fn intensity(&self, group: u32) -> Option<[S; 3]> {
        Solver::intensity(self, group)
    }
    fn set_light(&mut self, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        Solver::set_light(self, group, rgb)
    }
    fn step(&mut self, budget: u32) -> Outcome {
        Solver::step(self, budget)
    }
    fn reset(&mut self) {
        Solver::reset(self);
    }
    fn element_count(&self) -> u32 {
        self.patch_count()
    }
    fn element_radiosity(&self, element: u32) -> Option<[S; 3]> {
        self.radiosity(element)
    }
    fn unshot_power(&self) -> [S; 3] {
        self.total_unshot()
    }
}

impl<S: Scalar> DeviceSolver for HierSolver<'_, S> {
    type Scalar = S;
    fn group_count(&self) -> u32 {
        self.table().group_count()
    }
    fn intensity(&self, group: u32) -> Option<[S; 3]> {
        HierSolver::intensity(self, group)
    }
    fn set_light(&mut self, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        HierSolver::set_light(self, group, rgb)
    }
    fn step(&mut self, budget: u32) -> Outcome {
        HierSolver::step(self, budget)
    }
    fn reset(&mut self) {
        HierSolver::reset(self);
    }
    fn element_count(&self) -> u32 {
        self.table().leaf_count()
    }
    fn element_radiosity(&self, element: u32) -> Option<[S; 3]> {
        self.radiosity(element)
    }
    fn unshot_power(&self) -> [S; 3] {
        let mut t = [S::ZERO; 3];
        for n in 0..self.table().node_count() {
            let u = self.unshot(n).unwrap_or([S::ZERO; 3]);
            t = [t[0].add(u[0]), t[1].add(u[1]), t[2].add(u[2])];
        }
        t
    }
}

/// What the device loop asks of a table: implemented for the flat [`Table`] (version 3) and the hierarchical
/// [`HierTable`] (version 5). `'a` is the lifetime of the table's bytes, which its solver's buffers share.
pub trait DeviceTable<'a> {
    /// The solver's buffers for arithmetic `S` (core's [`Buffers`] or [`HierBuffers`]).
    type Buffers<S: Scalar + 'a>;
    /// The solver (core's [`Solver`] or [`HierSolver`]).
    type Solver<S: Scalar + 'a>: DeviceSolver<Scalar = S>;
    /// Light groups.
    fn group_count(&self) -> u32;
    /// The id of light `group` (what relight scripts name it by).
    fn group_id(&self, group: u32) -> Option<u32>;
    /// Total power the lights emit at unit intensity: the scale of [`Script::tolerance`] ([`unit_light_power`],
    /// [`hier_unit_light_power`]).
    fn unit_light_power(&self) -> f32;
    /// Creates the solver on `buffers`.
    ///
    /// # Errors
    /// The solver's constructor's [`SolverError`].
    fn solver<S: Scalar + 'a>(
        &self,
        buffers: Self::Buffers<S>,
        config: Config<S>,
    ) -> Result<Self::Solver<S>, SolverError>;
}

impl<'a> DeviceTable<'a> for Table<'a> {
    type Buffers<S: Scalar + 'a> = Buffers<'a, S>;
    type Solver<S: Scalar + 'a> = Solver<'a, S>;
    fn group_count(&self) -> u32 {
        Table::group_count(self)
    }
    fn group_id(&self, group: u32) -> Option<u32> {
        Table::group_id(self, group)
    }
    fn unit_light_power(&self) -> f32 {
        unit_light_power(self)
    }
    fn solver<S: Scalar + 'a>(
        &self,
        buffers: Buffers<'a, S>,
        config: Config<S>,
    ) -> Result<Solver<'a, S>, SolverError> {
        Solver::new(self, buffers, config)
    }
}

impl<'a> DeviceTable<'a> for HierTable<'a> {
    type Buffers<S: Scalar + 'a> = HierBuffers<'a, S>;
    type Solver<S: Scalar + 'a> = HierSolver<'a, S>;
    fn group_count(&self) -> u32 {
        HierTable::group_count(self)
    }
    fn group_id(&self, group: u32) -> Option<u32> {
        HierTable::group_id(self, group)
    }
    fn unit_light_power(&self) -> f32 {
        hier_unit_light_power(self)
    }
    fn solver<S: Scalar + 'a>(
        &self,
        buffers: HierBuffers<'a, S>,
        config: Config<S>,
    ) -> Result<HierSolver<'a, S>, SolverError> {
        HierSolver::new(self, buffers, config)
    }
}

/// What the device loop reports for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRecord<S> {
    /// Frame index in the script.
    pub frame: u32,
    /// Budget of the frame (work units).
    pub budget: u32,
    /// Units the step used (never more than the budget).
    pub used: u32,
    /// Units [`DeviceSolver::set_light`] reported for the light changes of the frame (outside the budget).
    pub light_units: u32,
    /// What the step returned.
    pub outcome: Outcome,
    /// Unshot power after the frame (RGB, power units): [`DeviceSolver::unshot_power`].
    pub unshot: [S; 3],
    /// [`radiosity_hash`] after the frame.
    pub hash: u64,
    /// Instructions the frame took (light changes and step), as the [`Meter`] measured; 0 without one.
    pub instructions: u64,
}

impl<S> FrameRecord<S> {
    /// Whether the frame ended converged.
    #[must_use]
    pub fn converged(&self) -> bool {
        matches!(self.outcome, Outcome::Converged { .. })
    }
}

/// Measures the cost of a frame (the firmware: instructions from SysTick; the host: nothing).
pub trait Meter {
    /// Starts a measurement.
    fn start(&mut self);
    /// Ends it and returns the count since [`Meter::start`].
    fn stop(&mut self) -> u64;
}

/// A [`Meter`] that measures nothing (always 0).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoMeter;

impl Meter for NoMeter {
    fn start(&mut self) {}
    fn stop(&mut self) -> u64 {
        0
    }
}

/// Why a script could not run.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum RunError {
    /// A light change was rejected by the solver.
    Solver {
        /// Frame (`None`: the initial intensities).
        frame: Option<u32>,
        /// The solver's error.
        error: SolverError,
    },
    /// The script has a different number of light groups than the table.
    GroupCount {
        /// Frame (`None`: the initial intensities).
        frame: Option<u32>,
        /// Light groups in the table.
        table: u32,
        /// Intensities in the script.
        script: usize,
    },
    /// The solver rejected the buffers.
    Buffers {
        /// The solver's error.
        error: SolverError,
    },
    /// The boot solve of the initial state did not converge within the boot budget.
    BootNotConverged {
        /// The step's last outcome.
        outcome: Outcome,
    },
    /// A transfer relight ([`run_transfer`]) was refused.
    Transfer {
        /// Frame (`None`: the initial intensities).
        frame: Option<u32>,
        /// Core's error.
        error: TransferError,
    },
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let at = |frame: Option<u32>| frame.map_or(-1, i64::from);
        match *self {
            RunError::Solver { frame, error } => write!(f, "frame {}: {error}", at(frame)),
            RunError::GroupCount { frame, table, script } => write!(
                f,
                "frame {}: {script} light-group intensities, the table has {table} light groups",
                at(frame)
            ),
            RunError::Buffers { error } => write!(f, "cannot create the solver: {error}"),
            RunError::BootNotConverged { outcome } => {
                write!(f, "boot solve of the initial intensities did not converge: {outcome:?}")
            }
            RunError::Transfer { frame, error } => write!(f, "frame {}: {error}", at(frame)),
        }
    }
}

impl core::error::Error for RunError {}

/// Sets every light group whose intensity differs from `intensity`; returns the units the changes cost.
///
/// # Errors
/// [`RunError::GroupCount`] if `intensity` does not have one entry per light group, [`RunError::Solver`] if a
/// change is rejected.
pub fn apply_intensities<D: DeviceSolver + ?Sized>(
    solver: &mut D,
    intensity: &[[f32; 3]],
    frame: Option<u32>,
) -> Result<u32, RunError> {
    let groups = solver.group_count();
    if intensity.len() != groups as usize {
        return Err(RunError::GroupCount { frame, table: groups, script: intensity.len() });
    }
    let mut units = 0u32;
    for (g, rgb) in (0u32..).zip(intensity) {
        let want = rgb.map(D::Scalar::from_f32);
        if solver.intensity(g) != Some(want) {
            let u = solver.set_light(g, *rgb).map_err(|error| RunError::Solver { frame, error })?;
            units = units.saturating_add(u);
        }
    }
    Ok(units)
}

/// Runs one frame: light changes, then at most `frame.budget` units of shooting. Returns the light-change
/// units and the step's outcome.
///
/// # Errors
/// As [`apply_intensities`].
pub fn run_frame<D: DeviceSolver + ?Sized>(
    solver: &mut D,
    frame: &Frame<'_>,
    index: u32,
) -> Result<(u32, Outcome), RunError> {
    let light_units = apply_intensities(solver, frame.intensity, Some(index))?;
    Ok((light_units, solver.step(frame.budget)))
}

/// Boot: resets the solver to the table's cold start, sets the script's initial intensities and solves to
/// convergence within `script.boot_budget` units. Returns the units spent.
///
/// # Errors
/// As [`apply_intensities`], or [`RunError::BootNotConverged`].
pub fn boot<D: DeviceSolver>(solver: &mut D, script: &Script<'_>) -> Result<u32, RunError> {
    solver.reset();
    apply_intensities(solver, script.initial, None)?;
    match solver.step(script.boot_budget) {
        Outcome::Converged { used } => Ok(used),
        outcome => Err(RunError::BootNotConverged { outcome }),
    }
}

/// Total power (`(|r| + |g| + |b|) * area`, summed over every member of every light group) the lights of a
/// flat table emit at unit intensity, in f32 in member order (the same sum on every platform): the scale of
/// [`Script::tolerance`].
#[must_use]
pub fn unit_light_power(table: &Table<'_>) -> f32 {
    let mut total = 0.0f32;
    for g in 0..table.group_count() {
        for k in table.group_members(g).unwrap_or(0..0) {
            if let Some(m) = table.member(k) {
                let e = m.emission.map(decode_emission_f32);
                total += (e[0] + e[1] + e[2]) * table.area(m.patch).unwrap_or(0.0);
            }
        }
    }
    total
}

/// [`unit_light_power`] of a hierarchical table: `(|r| + |g| + |b|) * area` of every member (its stored f32
/// emission at unit intensity, its leaf's area), summed in f32 in member order.
#[must_use]
pub fn hier_unit_light_power(table: &HierTable<'_>) -> f32 {
    let mut total = 0.0f32;
    for g in 0..table.group_count() {
        for k in table.group_members(g).unwrap_or(0..0) {
            if let Some(m) = table.member(k) {
                let e = m.emission.map(f32::abs);
                total += (e[0] + e[1] + e[2]) * table.leaf_area(m.leaf).unwrap_or(0.0);
            }
        }
    }
    total
}

/// The solver configuration of `script` on `table`: absolute tolerance `script.tolerance` times the table's
/// [`DeviceTable::unit_light_power`], core's recommended overshoot.
#[must_use]
pub fn script_config<'a, T: DeviceTable<'a>, S: Scalar>(table: &T, script: &Script<'_>) -> Config<S> {
    let tolerance = S::from_f32(script.tolerance * table.unit_light_power());
    Config { tolerance, overshoot: Config::<S>::RECOMMENDED_OVERSHOOT }
}

/// Creates a solver on `buffers` for `script` (absolute tolerance `script.tolerance` times the table's
/// [`DeviceTable::unit_light_power`]), boots it and runs every frame, timing each frame (light changes and
/// step) with `meter` and handing its record to `on_frame` together with the solver (whose state the caller
/// may read, outside the timing). Returns the boot units. The one device loop, for either table format.
///
/// # Errors
/// [`RunError::Buffers`], and as [`boot`] and [`run_frame`].
pub fn run_script<'a, T: DeviceTable<'a>, S: Bits + 'a, M: Meter>(
    table: &T,
    buffers: T::Buffers<S>,
    script: &Script<'_>,
    meter: &mut M,
    mut on_frame: impl FnMut(&FrameRecord<S>, &T::Solver<S>),
) -> Result<u32, RunError> {
    let mut solver =
        table.solver(buffers, script_config(table, script)).map_err(|error| RunError::Buffers { error })?;
    let solver = &mut solver;
    let boot_units = boot(solver, script)?;
    for (index, frame) in (0u32..).zip(script.frames) {
        meter.start();
        let result = run_frame(solver, frame, index);
        let instructions = meter.stop();
        let (light_units, outcome) = result?;
        let record = FrameRecord {
            frame: index,
            budget: frame.budget,
            used: outcome.used(),
            light_units,
            outcome,
            unshot: solver.unshot_power(),
            hash: radiosity_hash(solver),
            instructions,
        };
        on_frame(&record, solver);
    }
    Ok(boot_units)
}

/// One-letter outcome code of the trace: `c` converged, `b` budget spent, `n` no progress.
#[must_use]
pub fn outcome_code(outcome: Outcome) -> char {
    match outcome {
        Outcome::Converged { .. } => 'c',
        Outcome::BudgetSpent { .. } => 'b',
        Outcome::NoProgress { .. } => 'n',
    }
}

/// Writes the trace line of a frame (no newline):
/// `F,<arith>,<script>,<frame>,<budget>,<used>,<light_units>,<outcome>,<unshot r,g,b bits hex>,<hash hex>,<instructions>`.
///
/// Everything before the last field must agree bit for bit between the host simulator and the firmware.
///
/// # Errors
/// Those of `w`.
pub fn write_trace<S: Bits, W: fmt::Write>(w: &mut W, script: &str, r: &FrameRecord<S>) -> fmt::Result {
    write!(
        w,
        "F,{},{script},{},{},{},{},{},{:x},{:x},{:x},{:016x},{}",
        S::NAME,
        r.frame,
        r.budget,
        r.used,
        r.light_units,
        outcome_code(r.outcome),
        r.unshot[0].bits(),
        r.unshot[1].bits(),
        r.unshot[2].bits(),
        r.hash,
        r.instructions
    )
}

/// Elements one call of the transfer pass relights ([`relight_transfer_range`]): the size of the firmware's
/// chunk buffer, so its RAM does not grow with the table (a device streams its light map the same way).
pub const TRANSFER_CHUNK: usize = 64;

/// What the device loop reports for one transfer relight of the whole table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TransferRecord {
    /// The intensities relit: `None` the script's initial ones, `Some(k)` those of frame `k`.
    pub frame: Option<u32>,
    /// Work units of the relight (core's `transfer_cost`: elements x (groups + 1)).
    pub units: u32,
    /// Elements relit.
    pub elements: u32,
    /// Light groups.
    pub groups: u32,
    /// FNV-1a of every element's radiosity bits (element order, then R, G, B), as [`radiosity_hash`].
    pub hash: u64,
    /// Instructions of the relight calls, as the [`Meter`] measured (the hashing between calls excluded).
    pub instructions: u64,
}

/// The transfer pass of a script: relights `table` from its transfer basis ([`relight_transfer_range`],
/// through `chunk`, [`TRANSFER_CHUNK`] elements at a time on the firmware) at the script's initial
/// intensities and at every frame's whose intensities differ from the previous state's
/// ([`transfer_states`]), timing the relight calls with `meter` and handing each relight's
/// [`TransferRecord`] to `on_relight`. `intensity` holds the state's intensities in `S` (one entry per light
/// group). The peer of [`run_script`] for tables baked with the transfer basis: no solver state, every relight
/// exact up to quantization in one bounded pass.
///
/// # Errors
/// [`RunError::GroupCount`] if a state does not have one intensity per light group, [`RunError::Transfer`]
/// for core's refusal (no transfer section, a bad intensity) or an empty `chunk` or short `intensity`.
pub fn run_transfer<T: TransferTable, S: Bits, M: Meter>(
    table: &T,
    script: &Script<'_>,
    (chunk, intensity): (&mut [[S; 3]], &mut [[S; 3]]),
    meter: &mut M,
    mut on_relight: impl FnMut(&TransferRecord),
) -> Result<(), RunError> {
    let Some(section) = table.transfer_section() else {
        return Err(RunError::Transfer { frame: None, error: TransferError::NoTransferSection });
    };
    let (elements, groups) = (section.elements(), section.groups());
    if chunk.is_empty() {
        return Err(RunError::Transfer {
            frame: None,
            error: TransferError::OutputTooSmall { needed: elements.min(1), got: 0 },
        });
    }
    let Some(intensity) = intensity.get_mut(..groups as usize) else {
        return Err(RunError::Transfer {
            frame: None,
            error: TransferError::IntensityTooShort { needed: groups, got: intensity.len() },
        });
    };
    for (frame, rgb) in transfer_states(script) {
        if rgb.len() != groups as usize {
            return Err(RunError::GroupCount { frame, table: groups, script: rgb.len() });
        }
        for (dst, src) in intensity.iter_mut().zip(rgb) {
            *dst = src.map(S::from_f32);
        }
        let (mut units, mut instructions, mut hash) = (0u32, 0u64, Fnv1a::NEW);
        let mut first = 0u32;
        while first < elements {
            meter.start();
            let result = relight_transfer_range(table, intensity, first, chunk);
            instructions += meter.stop();
            units = units.saturating_add(result.map_err(|error| RunError::Transfer { frame, error })?);
            let count = chunk.len().min((elements - first) as usize);
            for v in chunk.iter().take(count).flatten() {
                hash.write(v.bits(), S::BYTES);
            }
            first += count as u32;
        }
        on_relight(&TransferRecord { frame, units, elements, groups, hash: hash.0, instructions });
    }
    Ok(())
}

/// The states [`run_transfer`] relights, in order: `(None, initial intensities)`, then `(Some(k), frame k's
/// intensities)` for every frame whose intensities differ from the state before it.
pub fn transfer_states<'s>(
    script: &'s Script<'_>,
) -> impl Iterator<Item = (Option<u32>, &'s [[f32; 3]])> + 's {
    let frames = (0u32..).zip(script.frames).map(|(k, f)| (Some(k), f.intensity));
    let mut previous: Option<&[[f32; 3]]> = None;
    core::iter::once((None, script.initial)).chain(frames).filter(move |&(_, rgb)| {
        let changed = previous != Some(rgb);
        previous = Some(rgb);
        changed
    })
}

/// Writes the trace line of a transfer relight (no newline):
/// `X,<arith>,<script>,<frame or -1>,<units>,<elements>,<groups>,<hash hex>,<instructions>`. As with
/// [`write_trace`], everything before the last field must agree bit for bit between host and firmware.
///
/// # Errors
/// Those of `w`.
pub fn write_transfer_trace<S: Bits, W: fmt::Write>(
    w: &mut W,
    script: &str,
    r: &TransferRecord,
) -> fmt::Result {
    write!(
        w,
        "X,{},{script},{},{},{},{},{:016x},{}",
        S::NAME,
        r.frame.map_or(-1, i64::from),
        r.units,
        r.elements,
        r.groups,
        r.hash,
        r.instructions
    )
}
