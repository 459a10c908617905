//! [`gauss_seidel`]: f64 Gauss-Seidel sweeps over the sparse matrix until the relative residual is below a
//! tolerance, with a sweep cap derived from the contraction bound.

use super::error::{check_finite, check_len, ReferenceError};
use super::system::{RadiositySystem, Solution};
use crate::metrics::relative_channels;
use crate::rgb::{channel_max, max_channel, Rgb};

/// Default relative residual Gauss-Seidel iterates to.
pub const DEFAULT_TOLERANCE: f64 = 1e-12;

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
    e: &[Rgb],
    options: &GaussSeidelOptions,
) -> Result<Solution, ReferenceError> {
    let n = system.len();
    check_len("emission", e, n)?;
    check_finite("emission", e)?;
    let tolerance = options.tolerance;
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(ReferenceError::InvalidTolerance(tolerance));
    }
    let q = system.contraction();
    let max_sweeps =
        options.max_sweeps.unwrap_or_else(|| gauss_seidel_sweep_bound(max_channel(q), tolerance));
    let scale = e.iter().fold(Rgb::ZERO, |scale, row| channel_max(scale, row.abs()));

    let mut b = e.to_vec();
    let mut residual = system.relative_residual(&b, e)?;
    let mut sweeps = 0;
    while max_channel(residual) > tolerance {
        if sweeps >= max_sweeps {
            return Err(ReferenceError::NotConverged { sweeps, residual: max_channel(residual), tolerance });
        }
        let mut change = Rgb::ZERO;
        for i in 0..n {
            let mut gathered = Rgb::ZERO;
            let mut self_ff = 0.0;
            for (j, f) in system.form_factors().row(i) {
                if j == i {
                    self_ff = f;
                } else {
                    gathered += f * b[j];
                }
            }
            let rho = system.rho()[i];
            let new = (e[i] + rho * gathered) / (1.0 - rho * self_ff);
            change = channel_max(change, (new - b[i]).abs());
            b[i] = new;
        }
        sweeps += 1;
        let bound = relative_channels(q * change, scale);
        if max_channel(bound) <= tolerance || sweeps >= max_sweeps {
            residual = system.relative_residual(&b, e)?;
        }
    }
    Ok(Solution { b, residual, sweeps })
}
