//! [`RadiositySystem`]: the validated system `(I - R F) B = E` without its right-hand side, its residual, and
//! the [`Solution`] every solver returns (see the [`crate::reference`] docs for why a validated system is well
//! posed).

use super::error::{check_finite, check_len, ReferenceError};
use crate::metrics::relative_channels;
use crate::patch::FormFactorMatrix;
use crate::rgb::{channel_max, Rgb};

/// Default slack on form-factor row sums above 1.
///
/// A row sum adds up to `n` nonnegative f64 terms; rounding alone stays below `n * eps`, about `2.2e-12` for
/// `n = 10^4`. `1e-9` leaves room for larger scenes without admitting a physically wrong matrix (a row that sends
/// out more power than it has). Callers with noisy, estimated form factors pass their own tolerance to
/// [`RadiositySystem::with_row_sum_tolerance`].
pub const DEFAULT_ROW_SUM_TOLERANCE: f64 = 1e-9;

/// A validated system `(I - R F) B = E`, without its right-hand side: reflectances and form factors.
///
/// Construction checks everything the solvers rely on (see the module docs); afterwards every solve is well posed.
#[derive(Clone, Copy, Debug)]
pub struct RadiositySystem<'a> {
    rho: &'a [Rgb],
    ff: &'a FormFactorMatrix,
    /// `q` per channel: `max_i rho_i * s_i`.
    contraction: Rgb,
}

impl<'a> RadiositySystem<'a> {
    /// Validates `rho` and `ff` with the default row-sum slack [`DEFAULT_ROW_SUM_TOLERANCE`].
    ///
    /// # Errors
    /// See [`RadiositySystem::with_row_sum_tolerance`].
    pub fn new(rho: &'a [Rgb], ff: &'a FormFactorMatrix) -> Result<Self, ReferenceError> {
        Self::with_row_sum_tolerance(rho, ff, DEFAULT_ROW_SUM_TOLERANCE)
    }

    /// Validates `rho` and `ff`, allowing row sums up to `1 + row_sum_tolerance`.
    ///
    /// # Errors
    /// A length mismatch, a non-finite or out-of-range reflectance, a negative form factor, a row sum above
    /// `1 + row_sum_tolerance`, or `rho_i * s_i >= 1` for some patch and channel. (The matrix's structure and
    /// finite values are guaranteed by [`FormFactorMatrix::new`].)
    pub fn with_row_sum_tolerance(
        rho: &'a [Rgb],
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
            for (channel, value) in r.to_array().into_iter().enumerate() {
                if !(0.0..1.0).contains(&value) {
                    return Err(ReferenceError::ReflectanceOutOfRange { patch, channel, value });
                }
            }
        }
        let mut contraction = Rgb::ZERO;
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
            for channel in 0..3 {
                let (r, q) = (rho_row[channel], rho_row[channel] * sum);
                if q >= 1.0 {
                    return Err(ReferenceError::NotContractive { patch: row, channel, rho: r, row_sum: sum });
                }
                contraction[channel] = contraction[channel].max(q);
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
    pub fn rho(&self) -> &'a [Rgb] {
        self.rho
    }

    /// The form-factor matrix.
    #[must_use]
    pub fn form_factors(&self) -> &'a FormFactorMatrix {
        self.ff
    }

    /// The contraction factor `q = max_i rho_i * sum_j F_ij` per channel, below 1.
    #[must_use]
    pub fn contraction(&self) -> Rgb {
        self.contraction
    }

    /// Upper bound on the max-norm condition number of `I - R F` per channel: `(1 + q) / (1 - q)`.
    #[must_use]
    pub fn condition_bound(&self) -> Rgb {
        self.contraction.map(|q| (1.0 + q) / (1.0 - q))
    }

    /// `(I - R F) b`, the left-hand side applied to `b`.
    ///
    /// # Errors
    /// If `b` does not have one entry per patch.
    pub fn apply(&self, b: &[Rgb]) -> Result<Vec<Rgb>, ReferenceError> {
        check_len("radiosity", b, self.len())?;
        Ok((0..self.len())
            .map(|i| {
                let mut gathered = Rgb::ZERO;
                for (j, f) in self.ff.row(i) {
                    gathered += f * b[j];
                }
                b[i] - self.rho[i] * gathered
            })
            .collect())
    }

    /// Relative residual per channel, `||E - (I - R F) B||_inf / ||E||_inf` (0 for a channel where both the
    /// emission and the residual are zero, infinite where only the emission is).
    ///
    /// # Errors
    /// If `b` or `e` does not have one entry per patch.
    pub fn relative_residual(&self, b: &[Rgb], e: &[Rgb]) -> Result<Rgb, ReferenceError> {
        check_len("emission", e, self.len())?;
        let lhs = self.apply(b)?;
        let mut res = Rgb::ZERO;
        let mut scale = Rgb::ZERO;
        for (&l, &e) in lhs.iter().zip(e) {
            res = channel_max(res, (e - l).abs());
            scale = channel_max(scale, e.abs());
        }
        Ok(relative_channels(res, scale))
    }
}

/// Radiosity per patch (W/m^2, RGB).
pub type Radiosity = Vec<Rgb>;

/// A reference answer and how well it satisfies the equation.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// Radiosity per patch and channel.
    pub b: Vec<Rgb>,
    /// Relative residual per channel, recomputed from `b` (see [`RadiositySystem::relative_residual`]).
    pub residual: Rgb,
    /// Gauss-Seidel sweeps performed (0 for the dense solver).
    pub sweeps: usize,
}
