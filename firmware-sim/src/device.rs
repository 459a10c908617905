//! The device loop, `no_std`: the one implementation the host simulator and the Cortex-M firmware both run.
//!
//! A relight [`Script`] is a list of [`Frame`]s. Each frame holds the absolute intensity (RGB) of every light
//! group and a budget in work units. [`run_frame`] applies the light groups whose intensity changed
//! ([`Solver::set_light`], outside the budget, as core documents) and then shoots for at most the frame's
//! budget ([`Solver::step`]). [`run_script`] starts from the script's initial intensities, solved to
//! convergence (a device's boot), then runs every frame, timing each with a caller-supplied [`Meter`] and
//! handing a [`FrameRecord`] to the caller.
//!
//! The trace line ([`write_trace`]) is the firmware's semihosting output and the host simulator's comparison
//! key: it carries every number that must agree bit for bit (units, outcome, unshot power bits and a hash of
//! every patch's radiosity bits). It is formatted here, once, so both sides print the same text.

use core::fmt;

use radiosity_core::codec::decode_emission_f32;
use radiosity_core::{Buffers, Config, Fixed, Outcome, Scalar, Solver, SolverError, Table};

/// One frame of a relight script.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<'a> {
    /// Work units [`Solver::step`] may spend this frame.
    pub budget: u32,
    /// Intensity (RGB multiplier of the unit emission) of every light group, in table order.
    pub intensity: &'a [[f32; 3]],
}

/// A relight script: a named sequence of frames, starting from solved initial intensities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Script<'a> {
    /// Name (letters, digits, `-`, `_`).
    pub name: &'a str,
    /// Convergence tolerance, relative: a patch's unshot power magnitude (`|r| + |g| + |b|`) may be at most
    /// this times [`unit_light_power`] of the table. Relative, so one script fits tables in any units.
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

/// FNV-1a hash of every patch's radiosity bits (patch order, then R, G, B).
#[must_use]
pub fn radiosity_hash<S: Bits>(solver: &Solver<'_, S>) -> u64 {
    let mut h = Fnv1a::NEW;
    for i in 0..solver.patch_count() {
        for v in solver.radiosity(i).unwrap_or([S::ZERO; 3]) {
            h.write(v.bits(), S::BYTES);
        }
    }
    h.0
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
    /// Units [`Solver::set_light`] reported for the light changes of the frame (outside the budget).
    pub light_units: u32,
    /// What the step returned.
    pub outcome: Outcome,
    /// Total unshot power after the frame (RGB, power units), including a shot in flight.
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
        }
    }
}

impl core::error::Error for RunError {}

/// Sets every light group whose intensity differs from `intensity`; returns the units the changes cost.
///
/// # Errors
/// [`RunError::GroupCount`] if `intensity` does not have one entry per light group, [`RunError::Solver`] if a
/// change is rejected.
pub fn apply_intensities<S: Scalar>(
    solver: &mut Solver<'_, S>,
    intensity: &[[f32; 3]],
    frame: Option<u32>,
) -> Result<u32, RunError> {
    let groups = solver.table().group_count();
    if intensity.len() != groups as usize {
        return Err(RunError::GroupCount { frame, table: groups, script: intensity.len() });
    }
    let mut units = 0u32;
    for (g, rgb) in (0u32..).zip(intensity) {
        let want = rgb.map(S::from_f32);
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
pub fn run_frame<S: Scalar>(
    solver: &mut Solver<'_, S>,
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
pub fn boot<S: Scalar>(solver: &mut Solver<'_, S>, script: &Script<'_>) -> Result<u32, RunError> {
    solver.reset();
    apply_intensities(solver, script.initial, None)?;
    match solver.step(script.boot_budget) {
        Outcome::Converged { used } => Ok(used),
        outcome => Err(RunError::BootNotConverged { outcome }),
    }
}

/// Total power (`(|r| + |g| + |b|) * area`, summed over every member of every light group) the lights emit at
/// unit intensity, in f32 in member order (the same sum on every platform): the scale of [`Script::tolerance`].
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

/// Creates a solver on `buffers` for `script` (absolute tolerance `script.tolerance * unit_light_power`), boots
/// it and runs every frame, timing each frame (light changes and step) with `meter` and handing its record to
/// `on_frame` together with the solver (whose state the caller may read, outside the timing). Returns the boot
/// units.
///
/// # Errors
/// [`RunError::Buffers`], and as [`boot`] and [`run_frame`].
pub fn run_script<'a, S: Bits, M: Meter>(
    table: &Table<'a>,
    buffers: Buffers<'a, S>,
    script: &Script<'_>,
    meter: &mut M,
    mut on_frame: impl FnMut(&FrameRecord<S>, &Solver<'_, S>),
) -> Result<u32, RunError> {
    let tolerance = S::from_f32(script.tolerance * unit_light_power(table));
    let overshoot = Config::<S>::RECOMMENDED_OVERSHOOT;
    let mut solver = Solver::new(table, buffers, Config { tolerance, overshoot })
        .map_err(|error| RunError::Buffers { error })?;
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
            unshot: solver.total_unshot(),
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
