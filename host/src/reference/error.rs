//! [`ReferenceError`]: everything that can go wrong building or solving a reference system, and the input
//! checks (lengths, finiteness) every solver shares.

use thiserror::Error;

use crate::input::InputError;
pub(crate) use crate::input::{check_finite, check_len};

/// Everything that can go wrong building or solving a reference system.
#[derive(Clone, Debug, PartialEq, Error)]
#[non_exhaustive]
pub enum ReferenceError {
    /// An input slice has the wrong length or a value is NaN or infinite.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A reflectance is outside `[0, 1)`.
    #[error("reflectance of patch {patch}, channel {channel} is {value}, outside [0, 1)")]
    ReflectanceOutOfRange {
        /// Patch index.
        patch: usize,
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// The offending value.
        value: f64,
    },
    /// A form factor is negative (the matrix's constructor already rejects NaN and infinities).
    #[error("form factor F[{row}][{col}] = {value} is not a finite nonnegative number")]
    FormFactorOutOfRange {
        /// Row (emitting patch).
        row: usize,
        /// Column (receiving patch).
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// A row sends out more power than it has.
    #[error("form-factor row {row} sums to {sum}, more than 1 + {tolerance}")]
    RowSumTooLarge {
        /// Row (emitting patch).
        row: usize,
        /// Its sum.
        sum: f64,
        /// The slack allowed above 1.
        tolerance: f64,
    },
    /// `rho_i * sum_j F_ij >= 1`: the patch would amplify light and the system is not solvable as posed.
    #[error("patch {patch}, channel {channel}: rho {rho} times row sum {row_sum} is not below 1")]
    NotContractive {
        /// Patch index.
        patch: usize,
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// Reflectance.
        rho: f64,
        /// Form-factor row sum.
        row_sum: f64,
    },
    /// The dense solver was asked for more patches than its limit.
    #[error("{n} patches is too many for the dense solver (limit {limit}; it would need {bytes} bytes per channel)")]
    TooLargeForDense {
        /// Patch count.
        n: usize,
        /// The limit.
        limit: usize,
        /// `n^2 * 8`: the bytes one channel's matrix would take.
        bytes: u128,
    },
    /// LU produced a zero or non-finite pivot (cannot happen for a validated system; reported, not hidden).
    #[error("LU factorization of channel {channel} has a zero or non-finite pivot at {index}")]
    SingularPivot {
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// Pivot index.
        index: usize,
    },
    /// Gauss-Seidel reached its sweep cap above the tolerance.
    #[error("Gauss-Seidel did not converge: relative residual {residual:e} after {sweeps} sweeps (tolerance {tolerance:e})")]
    NotConverged {
        /// Sweeps performed.
        sweeps: usize,
        /// Largest per-channel relative residual reached.
        residual: f64,
        /// The tolerance asked for.
        tolerance: f64,
    },
    /// A tolerance is not a positive finite number.
    #[error("tolerance {0} is not a positive finite number")]
    InvalidTolerance(f64),
    /// A patch names a light group that does not exist.
    #[error("patch {patch} is in light group {group}, but there are only {group_count} groups")]
    GroupOutOfRange {
        /// Patch index.
        patch: usize,
        /// Group named.
        group: usize,
        /// Number of dynamic groups.
        group_count: usize,
    },
    /// A light group's intensity is NaN or infinite.
    #[error("intensity of light group {group}, channel {channel} is not finite ({value})")]
    NonFiniteIntensity {
        /// Light group index.
        group: usize,
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// The offending value.
        value: f64,
    },
    /// A patch has unit emission but belongs to no dynamic light group, so its light would be lost.
    #[error("patch {patch} has unit emission but is in no dynamic light group")]
    UngroupedEmission {
        /// Patch index.
        patch: usize,
    },
}
