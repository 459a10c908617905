//! [`Method`]: the choice between the dense and the iterative solver, and [`solve_many`], which solves several
//! right-hand sides with it.

use super::dense::{DenseLu, MAX_DENSE_PATCHES};
use super::error::ReferenceError;
use super::gauss_seidel::{gauss_seidel, GaussSeidelOptions};
use super::system::{RadiositySystem, Solution};
use crate::rgb::Rgb;

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
    rhs: &[&[Rgb]],
    method: &Method,
) -> Result<Vec<Solution>, ReferenceError> {
    match method {
        Method::Dense { limit } => DenseLu::factor_with_limit(system, *limit)?.solve_many(rhs),
        Method::GaussSeidel(options) => rhs.iter().map(|e| gauss_seidel(&system, e, options)).collect(),
    }
}
