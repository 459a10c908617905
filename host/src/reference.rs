//! The f64 reference: the exact answer every device result is compared with.
//!
//! The radiosity equation `B_i = E_i + rho_i * sum_j F_ij B_j` is solved per RGB channel as the linear system
//! `(I - R F) B = E`, where `R = diag(rho)` and `F` is the [`FormFactorMatrix`] (`F_ij` = fraction of the power
//! leaving patch `i` that reaches patch `j`). Two solvers, cross-checked in the tests:
//!
//! - [`DenseLu`]: a dense LU factorization with partial pivoting (faer), one per distinct reflectance channel,
//!   reused for any number of right-hand sides. Memory: one `n x n` f64 matrix, `n^2 * 8` bytes, per distinct
//!   channel (one for a grey scene, three at most); at the default limit of [`MAX_DENSE_PATCHES`] = 4096 patches
//!   that is 128 MiB per channel, 384 MiB at most. Larger systems are refused with
//!   [`ReferenceError::TooLargeForDense`].
//! - [`gauss_seidel`]: f64 Gauss-Seidel sweeps over the sparse matrix (memory `O(n + nonzeros)`) until the
//!   relative residual is below a tolerance (default `1e-12`), with a sweep cap derived from the contraction
//!   bound; not converging is an error, never a silent result.
//!
//! Both report the relative residual `||E - (I - R F) B||_inf / ||E||_inf` per channel, recomputed from the
//! answer. Because the system is linear, relighting is a sum over light groups: [`transfer_vectors`] returns
//! `B_static` and the unit response `T_g` of every dynamic light group so that `B = B_static + sum_g I_g * T_g`
//! (intensity per channel, multiplied per channel).
//!
//! # Why the system is well posed
//! [`RadiositySystem::new`] checks `0 <= rho < 1`, `F_ij >= 0`, row sums `s_i <= 1 + tolerance` and
//! `q = max_i rho_i s_i < 1`. Then `I - R F` is strictly diagonally dominant by rows (`|1 - rho_i F_ii| -
//! rho_i sum_{j != i} F_ij >= 1 - rho_i s_i > 0`), hence nonsingular, Gauss-Seidel converges with a contraction
//! factor of at most `q` in the max norm, and in the max norm `||I - R F|| <= 1 + q`, `||(I - R F)^-1|| <=
//! 1 / (1 - q)`, so the condition number is at most `(1 + q) / (1 - q)` ([`RadiositySystem::condition_bound`]).
//! These bounds are the classical ones for diagonally dominant systems (Golub and Van Loan, *Matrix
//! Computations*, 4th ed., sections 3.4.10 and 11.2; Varga, *Matrix Iterative Analysis*, ch. 3).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::perm::PermRef;
use faer::{Mat, Par};
use thiserror::Error;

use crate::patch::FormFactorMatrix;

/// Largest system [`DenseLu::factor`] accepts: 4096 patches, `4096^2 * 8` bytes = 128 MiB per channel.
pub const MAX_DENSE_PATCHES: usize = 4096;

/// Default relative residual Gauss-Seidel iterates to.
pub const DEFAULT_TOLERANCE: f64 = 1e-12;

/// Default slack on form-factor row sums above 1.
///
/// A row sum adds up to `n` nonnegative f64 terms; rounding alone stays below `n * eps`, about `2.2e-12` for
/// `n = 10^4`. `1e-9` leaves room for larger scenes without admitting a physically wrong matrix (a row that sends
/// out more power than it has). Callers with noisy, estimated form factors pass their own tolerance to
/// [`RadiositySystem::with_row_sum_tolerance`].
pub const DEFAULT_ROW_SUM_TOLERANCE: f64 = 1e-9;

/// Everything that can go wrong building or solving a reference system.
#[derive(Clone, Debug, PartialEq, Error)]
#[non_exhaustive]
pub enum ReferenceError {
    /// An input slice has the wrong length.
    #[error("{what} has {found} entries, expected {expected}")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} of patch {patch}, channel {channel} is not finite ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Patch index.
        patch: usize,
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// The offending value.
        value: f64,
    },
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

/// Checks that every value of `values` is finite.
fn check_finite(what: &'static str, values: &[[f64; 3]]) -> Result<(), ReferenceError> {
    for (patch, v) in values.iter().enumerate() {
        for (channel, &value) in v.iter().enumerate() {
            if !value.is_finite() {
                return Err(ReferenceError::NonFinite { what, patch, channel, value });
            }
        }
    }
    Ok(())
}

/// Checks that `values` has one entry per patch.
fn check_len<T>(what: &'static str, values: &[T], n: usize) -> Result<(), ReferenceError> {
    if values.len() == n {
        Ok(())
    } else {
        Err(ReferenceError::LengthMismatch { what, expected: n, found: values.len() })
    }
}

/// A validated system `(I - R F) B = E`, without its right-hand side: reflectances and form factors.
///
/// Construction checks everything the solvers rely on (see the module docs); afterwards every solve is well posed.
#[derive(Clone, Copy, Debug)]
pub struct RadiositySystem<'a> {
    rho: &'a [[f64; 3]],
    ff: &'a FormFactorMatrix,
    /// `q` per channel: `max_i rho_i * s_i`.
    contraction: [f64; 3],
}

impl<'a> RadiositySystem<'a> {
    /// Validates `rho` and `ff` with the default row-sum slack [`DEFAULT_ROW_SUM_TOLERANCE`].
    ///
    /// # Errors
    /// See [`RadiositySystem::with_row_sum_tolerance`].
    pub fn new(rho: &'a [[f64; 3]], ff: &'a FormFactorMatrix) -> Result<Self, ReferenceError> {
        Self::with_row_sum_tolerance(rho, ff, DEFAULT_ROW_SUM_TOLERANCE)
    }

    /// Validates `rho` and `ff`, allowing row sums up to `1 + row_sum_tolerance`.
    ///
    /// # Errors
    /// A length mismatch, a non-finite or out-of-range reflectance, a negative form factor, a row sum above
    /// `1 + row_sum_tolerance`, or `rho_i * s_i >= 1` for some patch and channel. (The matrix's structure and
    /// finite values are guaranteed by [`FormFactorMatrix::new`].)
    pub fn with_row_sum_tolerance(
        rho: &'a [[f64; 3]],
        ff: &'a FormFactorMatrix,
        row_sum_tolerance: f64,
    ) -> Result<Self, ReferenceError> {
        if !(row_sum_tolerance.is_finite() && row_sum_tolerance >= 0.0) {
            return Err(ReferenceError::InvalidTolerance(row_sum_tolerance));
        }
        let n = ff.n();
        check_len("reflectance", rho, n)?;
        check_finite("reflectance", rho)?;
        for (patch, r) in rho.iter().enumerate() {
            for (channel, &value) in r.iter().enumerate() {
                if !(0.0..1.0).contains(&value) {
                    return Err(ReferenceError::ReflectanceOutOfRange { patch, channel, value });
                }
            }
        }
        let mut contraction = [0.0f64; 3];
        for (row, rho_row) in rho.iter().enumerate() {
            let mut sum = 0.0;
            for (col, value) in ff.row(row) {
                if value < 0.0 {
                    return Err(ReferenceError::FormFactorOutOfRange { row, col, value });
                }
                sum += value;
            }
            if sum > 1.0 + row_sum_tolerance {
                return Err(ReferenceError::RowSumTooLarge { row, sum, tolerance: row_sum_tolerance });
            }
            for (channel, (&r, q_max)) in rho_row.iter().zip(&mut contraction).enumerate() {
                let q = r * sum;
                if q >= 1.0 {
                    return Err(ReferenceError::NotContractive { patch: row, channel, rho: r, row_sum: sum });
                }
                *q_max = q_max.max(q);
            }
        }
        Ok(Self { rho, ff, contraction })
    }

    /// Number of patches.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ff.n()
    }

    /// Whether the system has no patches.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ff.n() == 0
    }

    /// Reflectance per patch.
    #[must_use]
    pub fn rho(&self) -> &'a [[f64; 3]] {
        self.rho
    }

    /// The form-factor matrix.
    #[must_use]
    pub fn form_factors(&self) -> &'a FormFactorMatrix {
        self.ff
    }

    /// The contraction factor `q = max_i rho_i * sum_j F_ij` per channel, below 1.
    #[must_use]
    pub fn contraction(&self) -> [f64; 3] {
        self.contraction
    }

    /// Upper bound on the max-norm condition number of `I - R F` per channel: `(1 + q) / (1 - q)`.
    #[must_use]
    pub fn condition_bound(&self) -> [f64; 3] {
        self.contraction.map(|q| (1.0 + q) / (1.0 - q))
    }

    /// `(I - R F) b`, the left-hand side applied to `b`.
    ///
    /// # Errors
    /// If `b` does not have one entry per patch.
    pub fn apply(&self, b: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, ReferenceError> {
        check_len("radiosity", b, self.len())?;
        Ok((0..self.len())
            .map(|i| {
                let mut gathered = [0.0; 3];
                for (j, f) in self.ff.row(i) {
                    for c in 0..3 {
                        gathered[c] += f * b[j][c];
                    }
                }
                let rho = self.rho[i];
                [0, 1, 2].map(|c| b[i][c] - rho[c] * gathered[c])
            })
            .collect())
    }

    /// Relative residual per channel, `||E - (I - R F) B||_inf / ||E||_inf` (0 for a channel where both the
    /// emission and the residual are zero, infinite where only the emission is).
    ///
    /// # Errors
    /// If `b` or `e` does not have one entry per patch.
    pub fn relative_residual(&self, b: &[[f64; 3]], e: &[[f64; 3]]) -> Result<[f64; 3], ReferenceError> {
        check_len("emission", e, self.len())?;
        let lhs = self.apply(b)?;
        let mut res = [0.0f64; 3];
        let mut scale = [0.0f64; 3];
        for (l, e) in lhs.iter().zip(e) {
            for c in 0..3 {
                res[c] = res[c].max((e[c] - l[c]).abs());
                scale[c] = scale[c].max(e[c].abs());
            }
        }
        Ok([0, 1, 2].map(|c| relative(res[c], scale[c])))
    }
}

/// `num / den` with `0 / 0 = 0` and `x / 0 = inf` for `x > 0`.
fn relative(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        num / den
    } else if num == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

/// A reference answer and how well it satisfies the equation.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// Radiosity per patch and channel.
    pub b: Vec<[f64; 3]>,
    /// Relative residual per channel, recomputed from `b` (see [`RadiositySystem::relative_residual`]).
    pub residual: [f64; 3],
    /// Gauss-Seidel sweeps performed (0 for the dense solver).
    pub sweeps: usize,
}

/// LU factors of one channel's matrix `I - R_c F`: `L` and `U` packed in one matrix, and the row permutation.
#[derive(Clone, Debug)]
struct ChannelLu {
    lu: Mat<f64>,
    perm_fwd: Vec<usize>,
    perm_bwd: Vec<usize>,
}

/// Dense LU factors of `I - R F`, one per distinct reflectance channel, reusable for any number of right-hand
/// sides.
///
/// Memory: `n^2 * 8` bytes per distinct channel (channels with identical reflectance share one factorization).
/// Factoring is `2/3 n^3` flops per distinct channel, each solve `2 n^2` per channel. Runs sequentially
/// (`Par::Seq`) so results are bit-for-bit reproducible.
#[derive(Clone, Debug)]
pub struct DenseLu<'a> {
    system: RadiositySystem<'a>,
    factors: Vec<ChannelLu>,
    /// Which entry of `factors` serves each channel.
    channel_factor: [usize; 3],
}

impl<'a> DenseLu<'a> {
    /// Factors `system` with the default limit [`MAX_DENSE_PATCHES`].
    ///
    /// # Errors
    /// See [`DenseLu::factor_with_limit`].
    pub fn factor(system: RadiositySystem<'a>) -> Result<Self, ReferenceError> {
        Self::factor_with_limit(system, MAX_DENSE_PATCHES)
    }

    /// Factors `system`, refusing more than `limit` patches (`limit^2 * 8` bytes per distinct channel).
    ///
    /// # Errors
    /// [`ReferenceError::TooLargeForDense`] above the limit; [`ReferenceError::SingularPivot`] if a pivot is zero
    /// or not finite (impossible for a validated system, but checked rather than assumed).
    pub fn factor_with_limit(system: RadiositySystem<'a>, limit: usize) -> Result<Self, ReferenceError> {
        let n = system.len();
        if n > limit {
            let bytes = (n as u128) * (n as u128) * 8;
            return Err(ReferenceError::TooLargeForDense { n, limit, bytes });
        }
        let mut factors: Vec<ChannelLu> = Vec::new();
        let mut channel_factor = [0usize; 3];
        for channel in 0..3 {
            // A grey scene (identical reflectance per channel) needs one factorization, not three.
            if let Some(same) = (0..channel).find(|&c| system.rho.iter().all(|r| r[c] == r[channel])) {
                channel_factor[channel] = channel_factor[same];
                continue;
            }
            channel_factor[channel] = factors.len();
            factors.push(Self::factor_channel(&system, channel)?);
        }
        Ok(Self { system, factors, channel_factor })
    }

    /// Builds and factors `I - R_c F` for one channel.
    fn factor_channel(system: &RadiositySystem<'_>, channel: usize) -> Result<ChannelLu, ReferenceError> {
        let n = system.len();
        let mut lu = Mat::<f64>::identity(n, n);
        for i in 0..n {
            let rho = system.rho[i][channel];
            for (j, f) in system.ff.row(i) {
                lu[(i, j)] -= rho * f;
            }
        }
        let mut perm_fwd = vec![0usize; n];
        let mut perm_bwd = vec![0usize; n];
        let par = Par::Seq;
        let mut buffer =
            MemBuffer::new(factor::lu_in_place_scratch::<usize, f64>(n, n, par, Default::default()));
        factor::lu_in_place(
            lu.as_mut(),
            &mut perm_fwd,
            &mut perm_bwd,
            par,
            MemStack::new(&mut buffer),
            Default::default(),
        );
        for index in 0..n {
            let pivot = lu[(index, index)];
            if pivot == 0.0 || !pivot.is_finite() {
                return Err(ReferenceError::SingularPivot { channel, index });
            }
        }
        Ok(ChannelLu { lu, perm_fwd, perm_bwd })
    }

    /// The system this factorization solves.
    #[must_use]
    pub fn system(&self) -> RadiositySystem<'a> {
        self.system
    }

    /// Number of distinct factorizations held (1 for a grey scene, at most 3).
    #[must_use]
    pub fn factorization_count(&self) -> usize {
        self.factors.len()
    }

    /// Solves for one emission vector.
    ///
    /// # Errors
    /// A length mismatch or a non-finite emission.
    pub fn solve(&self, e: &[[f64; 3]]) -> Result<Solution, ReferenceError> {
        let mut all = self.solve_many(&[e])?;
        Ok(all.remove(0))
    }

    /// Solves for several emission vectors with the same factorization.
    ///
    /// # Errors
    /// A length mismatch or a non-finite emission in any of them.
    pub fn solve_many(&self, rhs: &[&[[f64; 3]]]) -> Result<Vec<Solution>, ReferenceError> {
        let n = self.system.len();
        for e in rhs {
            check_len("emission", e, n)?;
            check_finite("emission", e)?;
        }
        let k = rhs.len();
        let mut out: Vec<Vec<[f64; 3]>> = vec![vec![[0.0; 3]; n]; k];
        let par = Par::Seq;
        let mut buffer = MemBuffer::new(solve::solve_in_place_scratch::<usize, f64>(n, k, par));
        for channel in 0..3 {
            let f = &self.factors[self.channel_factor[channel]];
            let mut x = Mat::<f64>::from_fn(n, k, |i, col| rhs[col][i][channel]);
            let perm = PermRef::new_checked(&f.perm_fwd, &f.perm_bwd, n);
            // `L` (unit lower, diagonal implied) and `U` (upper) are packed in one matrix; faer's triangular
            // solves read only their own triangle.
            solve::solve_in_place(
                f.lu.as_ref(),
                f.lu.as_ref(),
                perm,
                x.as_mut(),
                par,
                MemStack::new(&mut buffer),
            );
            for (col, b) in out.iter_mut().enumerate() {
                for (i, bi) in b.iter_mut().enumerate() {
                    bi[channel] = x[(i, col)];
                }
            }
        }
        out.into_iter()
            .zip(rhs)
            .map(|(b, e)| {
                let residual = self.system.relative_residual(&b, e)?;
                Ok(Solution { b, residual, sweeps: 0 })
            })
            .collect()
    }
}

/// Settings for [`gauss_seidel`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussSeidelOptions {
    /// Stop when every channel's relative residual is at or below this.
    pub tolerance: f64,
    /// Sweep cap; `None` derives it from the contraction bound (see [`gauss_seidel_sweep_bound`]).
    pub max_sweeps: Option<usize>,
}

impl Default for GaussSeidelOptions {
    fn default() -> Self {
        Self { tolerance: DEFAULT_TOLERANCE, max_sweeps: None }
    }
}

/// Sweeps after which Gauss-Seidel is guaranteed, in exact arithmetic, to reach relative residual `tolerance`
/// on a system with contraction factor `q`.
///
/// Starting from `B_0 = E`, the residual is `r_0 = R F E`, so `||r_0|| <= q ||E||`. Each sweep contracts the
/// error by at least `q` in the max norm, and `||r_k|| <= ||I - R F|| ||e_k|| <= (1 + q) q^k ||e_0||` with
/// `||e_0|| <= ||r_0|| / (1 - q)`: the relative residual after `k` sweeps is at most `(1 + q) / (1 - q) q^(k + 1)`.
/// The bound returned is the smallest such `k`, plus one. Reaching it without converging means rounding has put
/// a floor above the tolerance (about `eps / (1 - q)` times a small factor): a looser tolerance is needed.
#[must_use]
pub fn gauss_seidel_sweep_bound(q: f64, tolerance: f64) -> usize {
    if q <= 0.0 {
        return 1;
    }
    let k = ((tolerance * (1.0 - q) / (1.0 + q)).ln() / q.ln() - 1.0).ceil().max(0.0);
    // Beyond this the cap means nothing (q within ~1e-12 of 1); cap it so the loop stays finite.
    (k.min(1e9) as usize) + 1
}

/// Solves `(I - R F) B = E` by Gauss-Seidel sweeps in f64, all three channels per sweep.
///
/// Each sweep updates patches in index order, `B_i = (E_i + rho_i sum_{j != i} F_ij B_j) / (1 - rho_i F_ii)`.
/// Stops when every channel's relative residual (max norm, see [`RadiositySystem::relative_residual`]) is at or
/// below `options.tolerance`. The forward error then obeys `||B - B*|| / ||B*|| <= (1 + q) / (1 - q) * residual`.
///
/// The true residual costs a pass over the matrix, as much as a sweep, so it is recomputed only when a bound
/// says the sweep may have reached the tolerance, and at the sweep cap. The bound: row `i` was solved with the
/// new values of the patches before it and the old values of those after it, so after the sweep its residual
/// is `r_i = rho_i sum_{j > i} F_ij (B_j^old - B_j^new)` and `|r_i| <= rho_i s_i ||B^new - B^old||_inf <= q
/// ||B^new - B^old||_inf` (`F >= 0`, row sum `s_i`, per channel). The bound ignores rounding; the stop is
/// always decided by the recomputed residual.
///
/// # Errors
/// A length mismatch, a non-finite emission, an invalid tolerance, or [`ReferenceError::NotConverged`] (with the
/// sweeps done and the residual reached) when the cap is hit.
pub fn gauss_seidel(
    system: &RadiositySystem<'_>,
    e: &[[f64; 3]],
    options: &GaussSeidelOptions,
) -> Result<Solution, ReferenceError> {
    let n = system.len();
    check_len("emission", e, n)?;
    check_finite("emission", e)?;
    let tolerance = options.tolerance;
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(ReferenceError::InvalidTolerance(tolerance));
    }
    let q = system.contraction;
    let max_sweeps = options
        .max_sweeps
        .unwrap_or_else(|| gauss_seidel_sweep_bound(q.iter().copied().fold(0.0, f64::max), tolerance));
    let worst = |r: &[f64; 3]| r.iter().copied().fold(0.0, f64::max);
    let mut scale = [0.0f64; 3];
    for row in e {
        for c in 0..3 {
            scale[c] = scale[c].max(row[c].abs());
        }
    }

    let mut b = e.to_vec();
    let mut residual = system.relative_residual(&b, e)?;
    let mut sweeps = 0;
    while worst(&residual) > tolerance {
        if sweeps >= max_sweeps {
            return Err(ReferenceError::NotConverged { sweeps, residual: worst(&residual), tolerance });
        }
        let mut change = [0.0f64; 3];
        for i in 0..n {
            let mut gathered = [0.0; 3];
            let mut self_ff = 0.0;
            for (j, f) in system.ff.row(i) {
                if j == i {
                    self_ff = f;
                } else {
                    for c in 0..3 {
                        gathered[c] += f * b[j][c];
                    }
                }
            }
            let rho = system.rho[i];
            let new = [0, 1, 2].map(|c| (e[i][c] + rho[c] * gathered[c]) / (1.0 - rho[c] * self_ff));
            for c in 0..3 {
                change[c] = change[c].max((new[c] - b[i][c]).abs());
            }
            b[i] = new;
        }
        sweeps += 1;
        let bound = [0, 1, 2].map(|c| relative(q[c] * change[c], scale[c]));
        if worst(&bound) <= tolerance || sweeps >= max_sweeps {
            residual = system.relative_residual(&b, e)?;
        }
    }
    Ok(Solution { b, residual, sweeps })
}

/// Which reference solver to use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Dense LU ([`DenseLu`]) with the given patch limit.
    Dense {
        /// Largest patch count accepted.
        limit: usize,
    },
    /// Gauss-Seidel ([`gauss_seidel`]) with the given options.
    GaussSeidel(GaussSeidelOptions),
}

impl Default for Method {
    /// Dense LU with [`MAX_DENSE_PATCHES`].
    fn default() -> Self {
        Method::Dense { limit: MAX_DENSE_PATCHES }
    }
}

impl Method {
    /// Dense LU up to [`MAX_DENSE_PATCHES`] patches, default Gauss-Seidel above.
    #[must_use]
    pub fn for_size(n: usize) -> Self {
        if n <= MAX_DENSE_PATCHES {
            Method::default()
        } else {
            Method::GaussSeidel(GaussSeidelOptions::default())
        }
    }
}

/// Solves several right-hand sides with `method` (one factorization for all of them with the dense method).
///
/// # Errors
/// Any error of [`DenseLu::factor_with_limit`], [`DenseLu::solve_many`] or [`gauss_seidel`].
pub fn solve_many(
    system: RadiositySystem<'_>,
    rhs: &[&[[f64; 3]]],
    method: &Method,
) -> Result<Vec<Solution>, ReferenceError> {
    match method {
        Method::Dense { limit } => DenseLu::factor_with_limit(system, *limit)?.solve_many(rhs),
        Method::GaussSeidel(options) => rhs.iter().map(|e| gauss_seidel(&system, e, options)).collect(),
    }
}

/// Emission of a scene split into a static part and dynamic light groups.
#[derive(Clone, Copy, Debug)]
pub struct LightGroupEmission<'a> {
    /// Emission of the static lights, always on, per patch (W/m^2).
    pub static_emission: &'a [[f64; 3]],
    /// Emission per patch of its dynamic light group at unit intensity (W/m^2); zero for patches in no group.
    pub unit_emission: &'a [[f64; 3]],
    /// Dynamic light group of each patch (`None`: in no dynamic group).
    pub group: &'a [Option<usize>],
    /// Number of dynamic light groups.
    pub group_count: usize,
}

/// The exact answer for any relighting: `B = B_static + sum_g I_g * T_g`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferVectors {
    /// Radiosity from the static emission alone.
    pub b_static: Vec<[f64; 3]>,
    /// `t[g]`: radiosity from light group `g` at unit intensity (all other emission off).
    pub t: Vec<Vec<[f64; 3]>>,
    /// Largest relative residual over all the solves and channels.
    pub residual: f64,
    /// Gauss-Seidel sweeps over all the solves (0 for the dense solver).
    pub sweeps: usize,
}

impl TransferVectors {
    /// `B = B_static + sum_g I_g * T_g` for per-group, per-channel intensities `intensity[g]`.
    ///
    /// # Errors
    /// If `intensity` does not have one entry per group, or an intensity is not finite.
    pub fn relight(&self, intensity: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, ReferenceError> {
        check_len("intensity", intensity, self.t.len())?;
        for (group, v) in intensity.iter().enumerate() {
            for (channel, &value) in v.iter().enumerate() {
                if !value.is_finite() {
                    return Err(ReferenceError::NonFiniteIntensity { group, channel, value });
                }
            }
        }
        let mut b = self.b_static.clone();
        for (t, i) in self.t.iter().zip(intensity) {
            for (bp, tp) in b.iter_mut().zip(t) {
                for c in 0..3 {
                    bp[c] += i[c] * tp[c];
                }
            }
        }
        Ok(b)
    }
}

/// Computes `B_static` and one transfer vector `T_g` per dynamic light group.
///
/// Group `g`'s right-hand side is `unit_emission` on the patches of group `g` and zero elsewhere. With the dense
/// method all `1 + group_count` right-hand sides share one factorization.
///
/// # Errors
/// A length mismatch, non-finite emission, a group index out of range, unit emission on a patch in no group, or
/// any solver error.
pub fn transfer_vectors(
    system: RadiositySystem<'_>,
    lights: &LightGroupEmission<'_>,
    method: &Method,
) -> Result<TransferVectors, ReferenceError> {
    let n = system.len();
    check_len("static emission", lights.static_emission, n)?;
    check_len("unit emission", lights.unit_emission, n)?;
    check_len("light group membership", lights.group, n)?;
    check_finite("unit emission", lights.unit_emission)?;
    let mut rhs = vec![vec![[0.0; 3]; n]; lights.group_count];
    for (patch, (g, e)) in lights.group.iter().zip(lights.unit_emission).enumerate() {
        match *g {
            Some(group) if group >= lights.group_count => {
                return Err(ReferenceError::GroupOutOfRange {
                    patch,
                    group,
                    group_count: lights.group_count,
                });
            }
            Some(group) => rhs[group][patch] = *e,
            None if e.iter().any(|&v| v != 0.0) => return Err(ReferenceError::UngroupedEmission { patch }),
            None => {}
        }
    }
    let mut all: Vec<&[[f64; 3]]> = vec![lights.static_emission];
    all.extend(rhs.iter().map(Vec::as_slice));
    let solutions = solve_many(system, &all, method)?;
    let residual = solutions.iter().flat_map(|s| s.residual).fold(0.0, f64::max);
    let sweeps = solutions.iter().map(|s| s.sweeps).sum();
    let mut solutions = solutions.into_iter().map(|s| s.b);
    let b_static = solutions.next().unwrap_or_default();
    Ok(TransferVectors { b_static, t: solutions.collect(), residual, sweeps })
}
