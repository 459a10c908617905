//! The dense f64 answer on a hierarchy's own leaves: every leaf-to-leaf form factor by the patch estimator, solved
//! exactly. Against it, the hierarchical answer shows what its links get wrong (the mesh is the same), which is
//! the yardstick of `relight`'s and `check`'s hierarchical tables and of the bench's "vs dense" column.

use thiserror::Error;

use super::HierarchicalSolution;
use crate::formfactor::{compute_form_factors, FormFactorError, FormFactorOptions};
use crate::lighting::PatchLighting;
use crate::reference::{
    transfer_vectors, LightGroupEmission, Method, RadiositySystem, ReferenceError, TransferVectors,
};
use crate::scene::Scene;

/// Why the dense answer of the leaves could not be computed.
#[derive(Debug, Error)]
pub enum DenseError {
    /// The leaf-to-leaf form factors failed.
    #[error("dense form factors of the leaves: {0}")]
    FormFactors(#[from] FormFactorError),
    /// The f64 solve of the dense system failed.
    #[error("dense solve of the leaves: {0}")]
    Reference(#[from] ReferenceError),
}

/// The dense f64 answer on `solution`'s leaves (of `scene`), split by light source as
/// [`HierarchicalSolution::transfer`] is (the static lights, then each dynamic group at unit intensity), in the
/// solution's leaf order. Dense LU up to [`crate::reference::MAX_DENSE_PATCHES`] leaves, Gauss-Seidel above
/// ([`Method::for_size`]); its form factors cost `leaves^2` estimates, so callers bound the leaf count.
///
/// The estimator's raw rows are kept, as the hierarchy's are: next to an adjacent neighbour its quadrature may
/// make a row sum a little above 1, and any excess that keeps `rho * row sum` below 1 leaves the system a
/// contraction, so the row-sum slack is half the way from the largest reflectance to that.
///
/// # Errors
/// [`DenseError`].
pub fn dense_on_leaves(
    scene: &Scene,
    solution: &HierarchicalSolution,
) -> Result<TransferVectors, DenseError> {
    let (ff, _) = compute_form_factors(
        &solution.leaves,
        &FormFactorOptions { progress: false, ..FormFactorOptions::default() },
    )?;
    let lighting = PatchLighting::new(scene, &solution.leaves);
    let rho_max = lighting.rho.iter().map(|r| r.max_element()).fold(0.0, f64::max);
    let system = RadiositySystem::with_row_sum_tolerance(&lighting.rho, &ff, 0.5 * (1.0 / rho_max - 1.0))?;
    Ok(transfer_vectors(
        system,
        &LightGroupEmission::of(&lighting),
        &Method::for_size(solution.leaves.len()),
    )?)
}
