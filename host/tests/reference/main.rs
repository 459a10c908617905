//! Tests of the f64 reference solvers and the error metrics, one file per topic: closed forms (`closed_forms`),
//! the solvers against each other (`solvers`), refused inputs (`errors`) and the metrics (`metrics`).
//!
//! Tolerances follow from the method, never from tuning:
//! - Dense LU with partial pivoting is backward stable: the computed `B` solves `(A + dA) B = E` with
//!   `||dA|| <= c n eps ||A||`; we take `c = 8` (faer's own test convention, `eps * 8 * n`). For the strictly
//!   diagonally dominant matrices here the growth factor is at most 2 (Golub and Van Loan, 4th ed., 3.4.10), so
//!   this is generous. The relative forward error is then at most `8 n eps * kappa` and the relative residual at
//!   most `8 n eps * kappa` too (`||r|| <= ||dA|| ||B||`, `||B|| <= ||E|| / (1 - q)`, `||A|| <= 1 + q`), where
//!   `kappa = (1 + q) / (1 - q)` is the max-norm condition bound of `I - R F` and `q = max rho_i * row_sum_i`.
//! - Gauss-Seidel stops at relative residual `tol`, so its forward error is at most `kappa * tol`.
//! - Closed forms evaluated in f64 add a few roundings (at most 8, each `eps`), amplified by at most `kappa`.

mod closed_forms;
mod errors;
mod metrics;
mod solvers;

use radiosity_host::patch::FormFactorMatrix;
use radiosity_host::reference::RadiositySystem;
use radiosity_host::rgb::Rgb;
use radiosity_host::rng::SplitMix64;

const EPS: f64 = f64::EPSILON;

/// A dense form-factor matrix, row by row.
type Dense = Vec<Vec<f64>>;

/// Draws for the random test systems, on the host's generator ([`SplitMix64`]).
trait Draw {
    /// Uniform in `[0, 1)` with 53 random bits.
    fn uniform(&mut self) -> f64;
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    /// Uniform index in `0..n`.
    fn index(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize
    }
}

impl Draw for SplitMix64 {
    fn uniform(&mut self) -> f64 {
        self.unit()
    }
}

/// Compressed-row matrix from a dense one, dropping zeros.
fn csr(dense: &[Vec<f64>]) -> FormFactorMatrix {
    FormFactorMatrix::from_dense(dense).unwrap()
}

/// The test's own residual, independent of the library: `||E - (I - R F) B||_inf / ||E||_inf` per channel,
/// from the dense matrix.
fn dense_relative_residual(dense: &[Vec<f64>], rho: &[Rgb], b: &[Rgb], e: &[Rgb]) -> Rgb {
    let mut out = Rgb::ZERO;
    for c in 0..3 {
        let mut res: f64 = 0.0;
        let mut scale: f64 = 0.0;
        for i in 0..dense.len() {
            let gathered: f64 = dense[i].iter().zip(b).map(|(f, b)| f * b[c]).sum();
            res = res.max((e[i][c] - b[i][c] + rho[i][c] * gathered).abs());
            scale = scale.max(e[i][c].abs());
        }
        out[c] = res / scale;
    }
    out
}

/// Max-norm relative difference per channel, `||x - y||_inf / ||y||_inf`.
fn relative_diff(x: &[Rgb], y: &[Rgb]) -> Rgb {
    Rgb::from_array([0, 1, 2].map(|c| {
        let num = x.iter().zip(y).map(|(x, y)| (x[c] - y[c]).abs()).fold(0.0, f64::max);
        let den = y.iter().map(|y| y[c].abs()).fold(0.0, f64::max);
        num / den
    }))
}

/// Asserts `actual <= allowed` per channel, printing both and what was compared.
#[track_caller]
fn assert_within(what: &str, actual: Rgb, allowed: Rgb) {
    for c in 0..3 {
        assert!(
            actual[c] <= allowed[c],
            "{what}, channel {c}: relative error {:e} exceeds the allowed {:e}",
            actual[c],
            allowed[c]
        );
    }
}

/// `8 n eps kappa` per channel: the LU bound from the module docs (with `n >= 4` for the closed forms' own
/// roundings).
fn lu_tolerance(system: &RadiositySystem<'_>) -> Rgb {
    let n = system.len().max(4) as f64;
    system.condition_bound().map(|kappa| 8.0 * n * EPS * kappa)
}
