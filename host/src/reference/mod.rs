//! The f64 reference: the exact answer every device result is compared with.
//!
//! The radiosity equation `B_i = E_i + rho_i * sum_j F_ij B_j` is solved per RGB channel as the linear system
//! `(I - R F) B = E`, where `R = diag(rho)` and `F` is the [`FormFactorMatrix`](crate::patch::FormFactorMatrix) (`F_ij` = fraction of the power
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
//! (intensity per channel, multiplied per channel). [`exact_transfer`] does this for a meshed scene's own
//! lighting and form factors, the answer `solve`, `check`, `relight` and the views compare with.
//!
//! # Why the system is well posed
//! [`RadiositySystem::new`] checks `0 <= rho < 1`, `F_ij >= 0`, row sums `s_i <= 1 + tolerance` and
//! `q = max_i rho_i s_i < 1`. Then `I - R F` is strictly diagonally dominant by rows (`|1 - rho_i F_ii| -
//! rho_i sum_{j != i} F_ij >= 1 - rho_i s_i > 0`), hence nonsingular, Gauss-Seidel converges with a contraction
//! factor of at most `q` in the max norm, and in the max norm `||I - R F|| <= 1 + q`, `||(I - R F)^-1|| <=
//! 1 / (1 - q)`, so the condition number is at most `(1 + q) / (1 - q)` ([`RadiositySystem::condition_bound`]).
//! These bounds are the classical ones for diagonally dominant systems (Golub and Van Loan, *Matrix
//! Computations*, 4th ed., sections 3.4.10 and 11.2; Varga, *Matrix Iterative Analysis*, ch. 3).
//!
//! # Where things are
//! Each submodule uses only those before it.
//! - `error`: [`ReferenceError`] and the shared input checks.
//! - `system`: [`RadiositySystem`] (validation, `(I - R F) b`, residuals), [`Solution`] and [`Radiosity`].
//! - `dense`: [`DenseLu`].
//! - `gauss_seidel`: [`gauss_seidel`] and its sweep bound.
//! - `method`: [`Method`] and [`solve_many`].
//! - `transfer`: [`LightGroupEmission`], [`TransferVectors`], [`transfer_vectors`] and [`exact_transfer`].

mod dense;
mod error;
mod gauss_seidel;
mod method;
mod system;
mod transfer;

pub use dense::{DenseLu, MAX_DENSE_PATCHES};
pub use error::ReferenceError;
pub use gauss_seidel::{gauss_seidel, gauss_seidel_sweep_bound, GaussSeidelOptions, DEFAULT_TOLERANCE};
pub use method::{solve_many, Method};
pub use system::{Radiosity, RadiositySystem, Solution, DEFAULT_ROW_SUM_TOLERANCE};
pub use transfer::{exact_transfer, transfer_vectors, LightGroupEmission, TransferVectors};
