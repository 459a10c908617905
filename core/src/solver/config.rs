//! What a caller configures and gets back: [`Config`], [`Outcome`], the errors, and the tolerance floor.

use core::fmt;

use crate::format::Table;
use crate::scalar::Scalar;

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config<S> {
    /// Converged when every patch's unshot power magnitude (`|r| + |g| + |b|`, power units) is at most this.
    /// [`Solver::new`](super::Solver::new) refuses a tolerance below the arithmetic's convergence floor for the table
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
    /// Chosen from `radiosity bench` (`bench/REPORT.md`, "overshooting"), which measures the instructions to
    /// reach 1% error with and without it on the Cornell box and the white furnace, and from the `methods`
    /// example's table in the crate docs. Overshooting leaves negative unshot power behind, which later shots
    /// send back; convergence is still judged on the unshot magnitude.
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
    /// A Jacobi sweep is half done: finish it with [`Solver::step_jacobi`](super::Solver::step_jacobi) before shooting or Gauss-Seidel.
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
    /// A Jacobi sweep is half done; changes would be lost by its end-of-sweep copy. (The step outcome
    /// [`NoProgressReason::JacobiInProgress`] is the same condition met by a shooting or Gauss-Seidel step.)
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

/// The smallest tolerance [`Solver::new`](super::Solver::new) accepts for `table` on arithmetic `S`: [`Scalar::convergence_floor`]
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
