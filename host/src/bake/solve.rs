//! The f64 solves a bake's product needs (steps 2 and 4: static base and transfer basis), on the shooting form
//! of the stored rows, and the solver choice they (and [`crate::evaluate`]) use.

use crate::lighting::PatchLighting;
use crate::patch::FormFactorMatrix;
use crate::reference::{
    solve_many, transfer_vectors, GaussSeidelOptions, LightGroupEmission, Method, Radiosity, RadiositySystem,
    ReferenceError, TransferVectors,
};
use crate::rgb::{max_channel, Rgb};

/// Largest patch count for which a bake solves with dense LU by default.
pub const DENSE_BAKE_LIMIT: usize = 1024;

/// The bake's default reference solver: dense LU up to [`DENSE_BAKE_LIMIT`] patches, Gauss-Seidel above. A
/// bake and its evaluation solve four different matrices (original, its shooting form, sparsified, decoded)
/// with up to three distinct reflectance channels each; at `n` in the thousands that is a dozen `O(n^3)`
/// factorizations, while a sparse Gauss-Seidel sweep costs `O(nonzeros)`.
#[must_use]
pub fn default_method(n: usize) -> Method {
    if n <= DENSE_BAKE_LIMIT {
        Method::Dense { limit: DENSE_BAKE_LIMIT }
    } else {
        Method::GaussSeidel(GaussSeidelOptions::default())
    }
}

/// The shooting form `F~_ij = A_j F_ji / A_i` of shooter rows `ff` with patch areas `area`: the matrix whose
/// gathering solve `B = E + R F~ B` is what shooting with `ff` converges to. Equal to `ff` when `ff` is
/// reciprocal.
///
/// # Panics
/// If `area` is shorter than `ff.n()`, or an area is zero (the shooting form would not be finite).
#[must_use]
pub fn shooting_form(ff: &FormFactorMatrix, area: &[f64]) -> FormFactorMatrix {
    let n = ff.n();
    let mut count = vec![0usize; n + 1];
    for &j in ff.columns() {
        count[j as usize + 1] += 1;
    }
    for k in 0..n {
        count[k + 1] += count[k];
    }
    let row_start = count.clone();
    let mut col = vec![0u32; ff.nonzeros()];
    let mut value = vec![0.0; ff.nonzeros()];
    let mut flags = vec![false; ff.nonzeros()];
    // Rows of `ff` in increasing order fill each transposed row with increasing columns.
    for i in 0..n {
        for ((&j, &f), &flag) in ff.row_columns(i).iter().zip(ff.row_values(i)).zip(ff.row_flags(i)) {
            let j = j as usize;
            let at = count[j];
            col[at] = i as u32;
            value[at] = area[i] * f / area[j];
            flags[at] = flag;
            count[j] += 1;
        }
    }
    FormFactorMatrix::with_flags(n, row_start, col, value, flags)
        .expect("the transpose of a valid matrix is valid (finite values over positive areas)")
}

/// The irradiance `G_i = sum_j F_ij B_j` that gathering rows `ff` bring from radiosity `b` (with the shooting
/// form of stored rows: what the device's shooting deposits).
#[must_use]
pub fn gather(ff: &FormFactorMatrix, b: &[Rgb]) -> Vec<Rgb> {
    (0..ff.n())
        .map(|i| {
            let mut g = Rgb::ZERO;
            for (j, f) in ff.row(i) {
                g += f * b[j];
            }
            g
        })
        .collect()
}

/// Solves `B = E + R F B` for each right-hand side (one factorization for all with the dense method), rows of
/// `ff` allowed to sum to `1 + row_sum_tolerance`; returns each solution and the largest relative residual.
///
/// # Errors
/// The reference solver's.
fn solve_set(
    rho: &[Rgb],
    ff: &FormFactorMatrix,
    rhs: &[&[Rgb]],
    row_sum_tolerance: f64,
    method: &Method,
) -> Result<(Vec<Radiosity>, f64), ReferenceError> {
    let system = RadiositySystem::with_row_sum_tolerance(rho, ff, row_sum_tolerance)?;
    let solutions = solve_many(system, rhs, method)?;
    let residual = solutions.iter().map(|s| s.residual).fold(0.0, |worst: f64, r| worst.max(max_channel(r)));
    Ok((solutions.into_iter().map(|s| s.b).collect(), residual))
}

/// [`solve_set`] with one right-hand side.
///
/// # Errors
/// The reference solver's.
pub(crate) fn solve_one(
    rho: &[Rgb],
    ff: &FormFactorMatrix,
    e: &[Rgb],
    row_sum_tolerance: f64,
    method: &Method,
) -> Result<(Radiosity, f64), ReferenceError> {
    let (mut b, residual) = solve_set(rho, ff, &[e], row_sum_tolerance, method)?;
    Ok((b.pop().unwrap_or_default(), residual))
}

/// The transfer basis of `lighting` on gathering rows `shoot` (step 4).
///
/// # Errors
/// The reference solver's.
pub(crate) fn transfer_basis(
    lighting: &PatchLighting,
    shoot: &FormFactorMatrix,
    row_sum_tolerance: f64,
    method: &Method,
) -> Result<TransferVectors, ReferenceError> {
    let system = RadiositySystem::with_row_sum_tolerance(&lighting.rho, shoot, row_sum_tolerance)?;
    transfer_vectors(system, &LightGroupEmission::of(lighting), method)
}
