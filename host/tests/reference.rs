//! Tests of the f64 reference solvers and the error metrics.
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

use radiosity_host::metrics::{compare, luminance, MetricsError, FLOOR_FRACTION};
use radiosity_host::patch::FormFactorMatrix;
use radiosity_host::reference::{
    gauss_seidel, gauss_seidel_sweep_bound, solve_many, transfer_vectors, DenseLu, GaussSeidelOptions,
    LightGroupEmission, Method, RadiositySystem, ReferenceError, DEFAULT_TOLERANCE,
};

const EPS: f64 = f64::EPSILON;

/// A dense form-factor matrix, row by row.
type Dense = Vec<Vec<f64>>;

/// SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014).
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Uniform index in `0..n`.
    fn index(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize
    }
}

/// Compressed-row matrix from a dense one, dropping zeros.
fn csr(dense: &[Vec<f64>]) -> FormFactorMatrix {
    FormFactorMatrix::from_dense(dense).unwrap()
}

/// The test's own residual, independent of the library: `||E - (I - R F) B||_inf / ||E||_inf` per channel,
/// from the dense matrix.
fn dense_relative_residual(dense: &[Vec<f64>], rho: &[[f64; 3]], b: &[[f64; 3]], e: &[[f64; 3]]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (c, out) in out.iter_mut().enumerate() {
        let mut res: f64 = 0.0;
        let mut scale: f64 = 0.0;
        for i in 0..dense.len() {
            let gathered: f64 = dense[i].iter().zip(b).map(|(f, b)| f * b[c]).sum();
            res = res.max((e[i][c] - b[i][c] + rho[i][c] * gathered).abs());
            scale = scale.max(e[i][c].abs());
        }
        *out = res / scale;
    }
    out
}

/// Max-norm relative difference per channel, `||x - y||_inf / ||y||_inf`.
fn relative_diff(x: &[[f64; 3]], y: &[[f64; 3]]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        let num = x.iter().zip(y).map(|(x, y)| (x[c] - y[c]).abs()).fold(0.0, f64::max);
        let den = y.iter().map(|y| y[c].abs()).fold(0.0, f64::max);
        num / den
    })
}

/// Asserts `actual <= allowed` per channel, printing both and what was compared.
#[track_caller]
fn assert_within(what: &str, actual: [f64; 3], allowed: [f64; 3]) {
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
fn lu_tolerance(system: &RadiositySystem<'_>) -> [f64; 3] {
    let n = system.len().max(4) as f64;
    system.condition_bound().map(|kappa| 8.0 * n * EPS * kappa)
}

#[test]
fn two_patches_match_the_closed_form() {
    // B0 = E0 + r0 a B1 and B1 = E1 + r1 b B0 with a = F01, b = F10. Substituting:
    //   B0 = (E0 + r0 a E1) / (1 - r0 r1 a b),   B1 = (E1 + r1 b E0) / (1 - r0 r1 a b).
    let (a, b) = (0.6, 0.3);
    let ff = csr(&[vec![0.0, a], vec![b, 0.0]]);
    let rho = [[0.8, 0.5, 0.1], [0.7, 0.9, 0.0]];
    let e = [[10.0, 0.0, 3.0], [1.0, 2.0, 0.0]];
    let expected: Vec<[f64; 3]> = {
        let d = [0, 1, 2].map(|c| 1.0 - rho[0][c] * rho[1][c] * a * b);
        vec![
            [0, 1, 2].map(|c| (e[0][c] + rho[0][c] * a * e[1][c]) / d[c]),
            [0, 1, 2].map(|c| (e[1][c] + rho[1][c] * b * e[0][c]) / d[c]),
        ]
    };
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    let tol = lu_tolerance(&system);

    let lu = DenseLu::factor(system).unwrap().solve(&e).unwrap();
    assert_within("LU vs closed form", relative_diff(&lu.b, &expected), tol);
    assert_within(
        "LU residual",
        dense_relative_residual(&[vec![0.0, a], vec![b, 0.0]], &rho, &lu.b, &e),
        tol,
    );

    let gs = gauss_seidel(&system, &e, &GaussSeidelOptions::default()).unwrap();
    let gs_tol = system.condition_bound().map(|k| k * DEFAULT_TOLERANCE + tol[0]);
    assert_within("Gauss-Seidel vs closed form", relative_diff(&gs.b, &expected), gs_tol);
    assert!(gs.sweeps > 0, "Gauss-Seidel reported no sweeps");
}

/// Three patches that each see the other two with form factor `f`, uniform `rho`, only patch 0 emitting `E0`.
/// By symmetry `B1 = B2 = y` and `B0 = x`, with `p = rho f`:
///   `x = E0 + 2 p y`, `y = p (x + y)`, so `y = p x / (1 - p)` and `x (1 - p - 2 p^2) = E0 (1 - p)`;
///   `1 - p - 2 p^2 = (1 - 2p)(1 + p)`, hence `x = E0 (1 - p) / ((1 - 2p)(1 + p))`, `y = E0 p / ((1 - 2p)(1 + p))`.
fn three_patch_case(f: f64, rho: [f64; 3], e0: [f64; 3]) -> (Dense, [[f64; 3]; 3], Vec<[f64; 3]>) {
    let dense = vec![vec![0.0, f, f], vec![f, 0.0, f], vec![f, f, 0.0]];
    let x = [0, 1, 2].map(|c| {
        let p = rho[c] * f;
        e0[c] * (1.0 - p) / ((1.0 - 2.0 * p) * (1.0 + p))
    });
    let y = [0, 1, 2].map(|c| {
        let p = rho[c] * f;
        e0[c] * p / ((1.0 - 2.0 * p) * (1.0 + p))
    });
    (dense, [rho; 3], vec![x, y, y])
}

#[test]
fn three_patches_match_the_closed_form() {
    // Closed: 2 f = 1.
    let (dense, rho, expected) = three_patch_case(0.5, [0.9, 0.5, 0.99], [1.0, 4.0, 0.25]);
    let e = [[1.0, 4.0, 0.25], [0.0; 3], [0.0; 3]];
    let ff = csr(&dense);
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    let tol = lu_tolerance(&system);
    let lu = DenseLu::factor(system).unwrap().solve(&e).unwrap();
    assert_within("LU vs closed form", relative_diff(&lu.b, &expected), tol);
    assert_within("LU residual", dense_relative_residual(&dense, &rho, &lu.b, &e), tol);
    // The library's residual agrees with the test's own.
    assert_within("library residual", lu.residual, tol);
}

#[test]
fn open_scene_keeps_its_row_sums() {
    // Rows sum to 2 f = 0.6: 40% of the light escapes. Renormalizing the rows to 1 would give the closed case's
    // (much brighter) answer; the closed form for f = 0.3 is only met if the rows are used as given.
    let (dense, rho, expected) = three_patch_case(0.3, [0.9, 0.5, 0.99], [1.0, 4.0, 0.25]);
    let (_, _, closed) = three_patch_case(0.5, [0.9, 0.5, 0.99], [1.0, 4.0, 0.25]);
    let e = [[1.0, 4.0, 0.25], [0.0; 3], [0.0; 3]];
    let ff = csr(&dense);
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    for (c, q) in system.contraction().iter().enumerate() {
        assert_eq!(*q, rho[0][c] * (0.3 + 0.3), "contraction uses the open row sum");
    }
    let tol = lu_tolerance(&system);
    let lu = DenseLu::factor(system).unwrap().solve(&e).unwrap();
    assert_within("LU vs closed form (open)", relative_diff(&lu.b, &expected), tol);
    let gs = gauss_seidel(&system, &e, &GaussSeidelOptions::default()).unwrap();
    let gs_tol = system.condition_bound().map(|k| k * DEFAULT_TOLERANCE + tol[0]);
    assert_within("Gauss-Seidel vs closed form (open)", relative_diff(&gs.b, &expected), gs_tol);
    // The renormalized answer is far away: at least 10% brighter somewhere.
    assert!(relative_diff(&closed, &lu.b).iter().any(|&d| d > 0.1));
}

/// A closed white furnace: `n` patches with seeded random areas and `F_ij = A_j / A_total`, so every row sums
/// to 1 (up to rounding) and reciprocity `A_i F_ij = A_i A_j / A_total = A_j F_ji` holds exactly in real numbers.
fn furnace(n: usize, seed: u64) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut rng = SplitMix64(seed);
    let area: Vec<f64> = (0..n).map(|_| rng.range(0.1, 10.0)).collect();
    let total: f64 = area.iter().sum();
    let dense = (0..n).map(|_| area.iter().map(|a| a / total).collect()).collect();
    (area, dense)
}

#[test]
fn white_furnace_gives_e_over_one_minus_rho() {
    let n = 64;
    let (area, dense) = furnace(n, 7);
    let ff = csr(&dense);
    for rho_value in [0.5, 0.9, 0.99, 0.999] {
        let rho = vec![[rho_value; 3]; n];
        let system = RadiositySystem::new(&rho, &ff).unwrap();
        let tol = lu_tolerance(&system);
        let lu = DenseLu::factor(system).unwrap();
        assert_eq!(lu.factorization_count(), 1, "a grey scene needs one factorization");

        // Uniform emission: B = E / (1 - rho) everywhere.
        let e_uniform = vec![[1.0, 0.5, 2.0]; n];
        let expected: Vec<[f64; 3]> = e_uniform.iter().map(|e| e.map(|v| v / (1.0 - rho_value))).collect();
        let got = lu.solve(&e_uniform).unwrap();
        assert_within(&format!("furnace rho {rho_value}: LU"), relative_diff(&got.b, &expected), tol);
        assert_within(
            &format!("furnace rho {rho_value}: LU residual"),
            dense_relative_residual(&dense, &rho, &got.b, &e_uniform),
            tol,
        );

        // Uneven emission: B_i = E_i + rho * Ebar / (1 - rho), Ebar the area-weighted mean emission
        // (sum_j F_ij B_j is the area-weighted mean of B, which is Ebar / (1 - rho) by energy balance).
        let mut rng = SplitMix64(99);
        let e: Vec<[f64; 3]> = (0..n).map(|_| [rng.range(0.0, 5.0), 0.0, rng.range(0.0, 1.0)]).collect();
        let total: f64 = area.iter().sum();
        let ebar = [0, 1, 2].map(|c| area.iter().zip(&e).map(|(a, e)| a * e[c]).sum::<f64>() / total);
        let expected: Vec<[f64; 3]> =
            e.iter().map(|e| [0, 1, 2].map(|c| e[c] + rho_value * ebar[c] / (1.0 - rho_value))).collect();
        let got = lu.solve(&e).unwrap();
        // Channel 1 is dark (all zero): compare it exactly.
        assert!(got.b.iter().all(|b| b[1] == 0.0));
        let d = relative_diff(&got.b, &expected);
        assert_within(&format!("furnace rho {rho_value}, uneven E: LU"), [d[0], 0.0, d[2]], tol);

        // Gauss-Seidel. Its computed residual has a rounding floor of about (n + 2) eps / (1 - q) (summing n
        // terms of size up to ||B|| = ||E|| / (1 - q)), so ask for the larger of 1e-12 and that floor.
        let q = system.contraction()[0];
        let gs_tol = DEFAULT_TOLERANCE.max((n + 2) as f64 * EPS / (1.0 - q));
        let options = GaussSeidelOptions { tolerance: gs_tol, max_sweeps: None };
        let gs = gauss_seidel(&system, &e_uniform, &options).unwrap();
        let expected: Vec<[f64; 3]> = e_uniform.iter().map(|e| e.map(|v| v / (1.0 - rho_value))).collect();
        let allowed = system.condition_bound().map(|k| k * gs_tol + tol[0]);
        assert_within(
            &format!("furnace rho {rho_value}: Gauss-Seidel"),
            relative_diff(&gs.b, &expected),
            allowed,
        );
        assert!(gs.sweeps <= gauss_seidel_sweep_bound(q, gs_tol));
        println!(
            "furnace n={n} rho={rho_value}: LU error {:.2e}, Gauss-Seidel {} sweeps, error {:.2e}, residual {:.2e}",
            relative_diff(&lu.solve(&e_uniform).unwrap().b, &expected)[0],
            gs.sweeps,
            relative_diff(&gs.b, &expected)[0],
            gs.residual[0]
        );
    }
}

/// A seeded random sparse system: about `per_row` entries per row, row sums uniform in `[0.3, 1]` (a few rows
/// exactly 1 up to rounding), reflectances in `[0, 0.95)`, emission on about a quarter of the patches.
fn random_system(n: usize, per_row: usize, seed: u64) -> (Dense, Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let mut rng = SplitMix64(seed);
    let mut dense = vec![vec![0.0; n]; n];
    for (i, row) in dense.iter_mut().enumerate() {
        for _ in 0..per_row {
            let j = rng.index(n);
            if j != i {
                row[j] += rng.range(0.01, 1.0);
            }
        }
        let sum: f64 = row.iter().sum();
        if sum > 0.0 {
            let target = if i % 7 == 0 { 1.0 } else { rng.range(0.3, 1.0) };
            // Scale down by a hair so rounding cannot push a row sum above 1.
            let scale = target * (1.0 - 4.0 * n as f64 * EPS) / sum;
            row.iter_mut().for_each(|f| *f *= scale);
        }
    }
    let rho = (0..n).map(|_| [rng.range(0.0, 0.95), rng.range(0.0, 0.95), rng.range(0.0, 0.95)]).collect();
    let e = (0..n)
        .map(|_| {
            if rng.uniform() < 0.25 {
                [rng.range(0.0, 100.0), rng.range(0.0, 100.0), 1.0]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    (dense, rho, e)
}

#[test]
fn lu_and_gauss_seidel_agree_on_random_sparse_systems() {
    for (n, per_row, seed) in [(5, 3, 1), (40, 8, 2), (200, 12, 3), (600, 20, 4)] {
        let (dense, rho, mut e) = random_system(n, per_row, seed);
        e[0] = [1.0, 1.0, 1.0]; // at least one light per channel
        let ff = csr(&dense);
        let system = RadiositySystem::new(&rho, &ff).unwrap();
        let tol = lu_tolerance(&system);
        let lu = DenseLu::factor(system).unwrap().solve(&e).unwrap();
        let gs = gauss_seidel(&system, &e, &GaussSeidelOptions::default()).unwrap();
        // Residuals, recomputed independently of the library.
        assert_within(&format!("n={n}: LU residual"), dense_relative_residual(&dense, &rho, &lu.b, &e), tol);
        assert_within(
            &format!("n={n}: Gauss-Seidel residual"),
            dense_relative_residual(&dense, &rho, &gs.b, &e),
            [DEFAULT_TOLERANCE + tol[0]; 3],
        );
        // Both are within their bounds of the exact answer, so within the sum of the bounds of each other.
        let allowed = [0, 1, 2].map(|c| system.condition_bound()[c] * DEFAULT_TOLERANCE + 2.0 * tol[c]);
        assert_within(&format!("n={n}: LU vs Gauss-Seidel"), relative_diff(&gs.b, &lu.b), allowed);
        println!(
            "n={n} nnz={}: q={:.3?}, Gauss-Seidel {} sweeps, LU-GS {:.2e}",
            ff.nonzeros(),
            system.contraction(),
            gs.sweeps,
            relative_diff(&gs.b, &lu.b).iter().copied().fold(0.0, f64::max)
        );
    }
}

/// Gauss-Seidel recomputes the residual only when its a-priori bound (`q` times the sweep's largest change)
/// allows convergence. The stop must still be decided by the true residual, and the bound must not be so loose
/// that it costs sweeps: it may stop at most one sweep later than checking the true residual after every sweep.
/// Capping the sweeps at `k` reports the true residual after `k` sweeps, which finds that first sweep.
#[test]
fn gauss_seidel_skips_residual_passes_without_stopping_late() {
    for (n, per_row, seed) in [(40, 8, 2), (200, 12, 3), (600, 20, 4)] {
        let (dense, rho, mut e) = random_system(n, per_row, seed);
        e[0] = [1.0, 1.0, 1.0];
        let ff = csr(&dense);
        let system = RadiositySystem::new(&rho, &ff).unwrap();
        for tolerance in [1e-4, 1e-8, DEFAULT_TOLERANCE] {
            let gs = gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance, max_sweeps: None }).unwrap();
            assert!(gs.residual.iter().all(|&r| r <= tolerance), "n={n}: residual {:?}", gs.residual);
            let first = (1..=gs.sweeps)
                .find(|&k| {
                    let capped = GaussSeidelOptions { tolerance, max_sweeps: Some(k) };
                    gauss_seidel(&system, &e, &capped).is_ok()
                })
                .unwrap();
            assert!(
                gs.sweeps <= first + 1,
                "n={n} tol={tolerance:e}: stopped after {} sweeps, the true residual was below after {first}",
                gs.sweeps
            );
        }
    }
}

#[test]
fn method_choice_and_solve_many_reuse_one_factorization() {
    let (dense, rho, e) = random_system(30, 6, 11);
    let ff = csr(&dense);
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    let e2: Vec<[f64; 3]> = e.iter().map(|e| e.map(|v| 2.0 * v + 1.0)).collect();
    let lu = DenseLu::factor(system).unwrap();
    assert_eq!(lu.factorization_count(), 3, "three different reflectance channels");
    let many = lu.solve_many(&[&e, &e2]).unwrap();
    let one = [lu.solve(&e).unwrap(), lu.solve(&e2).unwrap()];
    let tol = lu_tolerance(&system);
    // One column at a time or together, faer may pick different (blocked) triangular-solve kernels, so the bits
    // can differ; each is within the LU bound of the exact answer, so within twice it of each other.
    let twice = tol.map(|t| 2.0 * t);
    assert_within("solve_many vs solve, rhs 1", relative_diff(&many[0].b, &one[0].b), twice);
    assert_within("solve_many vs solve, rhs 2", relative_diff(&many[1].b, &one[1].b), twice);
    let gs = solve_many(system, &[&e, &e2], &Method::GaussSeidel(GaussSeidelOptions::default())).unwrap();
    let allowed = [0, 1, 2].map(|c| system.condition_bound()[c] * DEFAULT_TOLERANCE + 2.0 * tol[c]);
    assert_within("solve_many LU vs GS, rhs 2", relative_diff(&gs[1].b, &many[1].b), allowed);
    assert_eq!(Method::for_size(10), Method::default());
    assert!(matches!(Method::for_size(1 << 20), Method::GaussSeidel(_)));
}

#[test]
fn transfer_vectors_are_linear() {
    let n = 80;
    let (dense, rho, _) = random_system(n, 10, 21);
    let ff = csr(&dense);
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    let mut rng = SplitMix64(5);
    let group_count = 3;
    let mut group = vec![None; n];
    let mut unit = vec![[0.0; 3]; n];
    let mut static_emission = vec![[0.0; 3]; n];
    for i in 0..n {
        match i % 8 {
            0..=2 => {
                group[i] = Some(i % 8);
                unit[i] = [rng.range(0.5, 2.0), rng.range(0.5, 2.0), rng.range(0.5, 2.0)];
            }
            3 => static_emission[i] = [0.3, 0.2, 0.1],
            _ => {}
        }
    }
    // One patch is both static and in a dynamic group.
    static_emission[0] = [1.0, 0.0, 0.5];
    let lights = LightGroupEmission {
        static_emission: &static_emission,
        unit_emission: &unit,
        group: &group,
        group_count,
    };
    let intensity = [[2.0, 0.5, 0.0], [0.0, 0.0, 0.0], [10.0, 3.0, 1.5]];
    let combined: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let mut e = static_emission[i];
            if let Some(g) = group[i] {
                for c in 0..3 {
                    e[c] += intensity[g][c] * unit[i][c];
                }
            }
            e
        })
        .collect();

    for method in [Method::default(), Method::GaussSeidel(GaussSeidelOptions::default())] {
        let tv = transfer_vectors(system, &lights, &method).unwrap();
        assert_eq!(tv.t.len(), group_count);
        let relit = tv.relight(&intensity).unwrap();
        let direct = solve_many(system, &[&combined], &method).unwrap().remove(0);
        // Each of the 1 + G solves is within `err` (relative to its own size) of exact; the sum of the scaled
        // vectors is within err * (||B_static|| + sum_g |I_g| ||T_g||), plus the direct solve's err * ||B||.
        let err = match method {
            Method::Dense { .. } => lu_tolerance(&system),
            Method::GaussSeidel(o) => {
                system.condition_bound().map(|k| k * o.tolerance + lu_tolerance(&system)[0])
            }
        };
        let inf = |v: &[[f64; 3]], c: usize| v.iter().map(|b| b[c].abs()).fold(0.0, f64::max);
        let allowed = [0, 1, 2].map(|c| {
            let parts = inf(&tv.b_static, c)
                + tv.t.iter().zip(&intensity).map(|(t, i)| i[c].abs() * inf(t, c)).sum::<f64>();
            err[c] * (parts / inf(&direct.b, c) + 1.0)
        });
        assert_within(&format!("{method:?}: relight vs direct"), relative_diff(&relit, &direct.b), allowed);
        // Group 1 at zero intensity contributes nothing, but its transfer vector is not zero.
        assert!(tv.t[1].iter().any(|t| t[0] > 0.0));
        // Unit intensity everywhere and static: B = B_static + sum_g T_g.
        let all_on = tv.relight(&[[1.0; 3]; 3]).unwrap();
        // Multiplying by 1 is exact; adding in the same order (static first, then group by group) gives the
        // same bits.
        let sum: Vec<[f64; 3]> = (0..n)
            .map(|i| [0, 1, 2].map(|c| tv.t.iter().fold(tv.b_static[i][c], |acc, t| acc + t[i][c])))
            .collect();
        assert_eq!(all_on, sum);
        assert!(tv.residual <= err.iter().copied().fold(DEFAULT_TOLERANCE, f64::max));
    }
}

#[test]
fn bad_inputs_are_refused_with_clear_errors() {
    let dense = vec![vec![0.0, 0.5], vec![0.5, 0.0]];
    let ff = csr(&dense);
    let good = [[0.5; 3]; 2];

    let short = [[0.5; 3]; 1];
    assert_eq!(
        RadiositySystem::new(&short, &ff).unwrap_err(),
        ReferenceError::LengthMismatch { what: "reflectance", expected: 2, found: 1 }
    );
    let err = RadiositySystem::new(&[[0.5; 3], [0.5, 1.0, 0.5]], &ff).unwrap_err();
    assert_eq!(err, ReferenceError::ReflectanceOutOfRange { patch: 1, channel: 1, value: 1.0 });
    assert_eq!(err.to_string(), "reflectance of patch 1, channel 1 is 1, outside [0, 1)");
    assert!(matches!(
        RadiositySystem::new(&[[-0.1, 0.5, 0.5], [0.5; 3]], &ff).unwrap_err(),
        ReferenceError::ReflectanceOutOfRange { patch: 0, channel: 0, .. }
    ));
    assert!(matches!(
        RadiositySystem::new(&[[0.5; 3], [0.5, 0.5, f64::NAN]], &ff).unwrap_err(),
        ReferenceError::NonFinite { what: "reflectance", patch: 1, channel: 2, .. }
    ));

    // Form factors: negative, row sum above 1 (NaN and a malformed structure cannot get past
    // `FormFactorMatrix::new`; host/tests/patch.rs tests those).
    let bad = csr(&[vec![0.0, -0.1], vec![0.5, 0.0]]);
    assert!(matches!(
        RadiositySystem::new(&good, &bad).unwrap_err(),
        ReferenceError::FormFactorOutOfRange { .. }
    ));
    let over = csr(&[vec![0.5, 0.5 + 1e-6], vec![0.5, 0.0]]);
    assert!(matches!(
        RadiositySystem::new(&good, &over).unwrap_err(),
        ReferenceError::RowSumTooLarge { row: 0, .. }
    ));
    // ... unless the caller allows that much slack; then rho * row sum must still stay below 1.
    RadiositySystem::with_row_sum_tolerance(&good, &over, 1e-5).unwrap();
    let rho_high = [[1.0 - 1e-7; 3], [0.5; 3]];
    assert!(matches!(
        RadiositySystem::with_row_sum_tolerance(&rho_high, &over, 1e-5).unwrap_err(),
        ReferenceError::NotContractive { patch: 0, .. }
    ));

    // Emission: wrong length, NaN.
    let system = RadiositySystem::new(&good, &ff).unwrap();
    let lu = DenseLu::factor(system).unwrap();
    assert!(matches!(
        lu.solve(&[[1.0; 3]]).unwrap_err(),
        ReferenceError::LengthMismatch { what: "emission", .. }
    ));
    let nan_e = [[1.0; 3], [0.0, f64::NAN, 0.0]];
    assert!(matches!(
        lu.solve(&nan_e).unwrap_err(),
        ReferenceError::NonFinite { what: "emission", patch: 1, channel: 1, .. }
    ));
    assert!(matches!(
        gauss_seidel(&system, &nan_e, &GaussSeidelOptions::default()).unwrap_err(),
        ReferenceError::NonFinite { .. }
    ));

    // Dense size limit: 2 patches with a limit of 1 would need 2^2 * 8 = 32 bytes per channel.
    assert_eq!(
        DenseLu::factor_with_limit(system, 1).unwrap_err(),
        ReferenceError::TooLargeForDense { n: 2, limit: 1, bytes: 32 }
    );

    // Gauss-Seidel: a cap that is too small is an error carrying the residual reached, not a result.
    let e = [[1.0; 3], [0.0; 3]];
    let err =
        gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance: 1e-12, max_sweeps: Some(2) }).unwrap_err();
    match err {
        ReferenceError::NotConverged { sweeps: 2, residual, tolerance } => {
            assert!(residual > tolerance && residual.is_finite())
        }
        other => panic!("expected NotConverged after 2 sweeps, got {other:?}"),
    }
    assert_eq!(
        gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance: 0.0, max_sweeps: None }).unwrap_err(),
        ReferenceError::InvalidTolerance(0.0)
    );

    // Light groups: out-of-range group, emission in no group, wrong intensity count.
    let unit = [[1.0; 3], [0.0; 3]];
    let zero = [[0.0; 3]; 2];
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[Some(1), None],
        group_count: 1,
    };
    assert_eq!(
        transfer_vectors(system, &lights, &Method::default()).unwrap_err(),
        ReferenceError::GroupOutOfRange { patch: 0, group: 1, group_count: 1 }
    );
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[None, None],
        group_count: 1,
    };
    assert_eq!(
        transfer_vectors(system, &lights, &Method::default()).unwrap_err(),
        ReferenceError::UngroupedEmission { patch: 0 }
    );
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[Some(0), None],
        group_count: 1,
    };
    let tv = transfer_vectors(system, &lights, &Method::default()).unwrap();
    assert!(matches!(tv.relight(&[]).unwrap_err(), ReferenceError::LengthMismatch { what: "intensity", .. }));
    assert!(matches!(
        tv.relight(&[[0.0, f64::INFINITY, 0.0]]).unwrap_err(),
        ReferenceError::NonFiniteIntensity { group: 0, channel: 1, .. }
    ));
}

#[test]
fn sweep_bound_follows_the_contraction() {
    // (1 + q) / (1 - q) q^(k + 1) <= tol: for q = 0.5, tol = 1e-12: 3 * 0.5^(k + 1) <= 1e-12 -> k + 1 >= 41.45,
    // so k = 41 and the bound is 42.
    assert_eq!(gauss_seidel_sweep_bound(0.5, 1e-12), 42);
    assert_eq!(gauss_seidel_sweep_bound(0.0, 1e-12), 1);
}

// ---------------------------------------------------------------------------------------------------------------
// Metrics

#[test]
fn identical_answers_have_zero_error() {
    let r = [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0], [5.0, 1.0, 0.5]];
    let report = compare(&r, &r, &[1.0, 2.0, 0.5]).unwrap();
    assert_eq!(
        (report.rel_l2, report.abs_rms, report.max_rel, report.luminance_rel_l2, report.luminance_max_rel),
        (0.0, 0.0, 0.0, 0.0, 0.0)
    );
    assert_eq!(report.patches, 3);
}

#[test]
fn known_perturbation_gives_the_hand_computed_error() {
    // Reference |r0| = |(1, 2, 2)| = 3, |r1| = |(0, 3, 4)| = 5; areas 1 and 3. Perturb patch 0 by (0.3, 0, 0.4),
    // |d0| = 0.5.
    //   relative L2  = sqrt(1 * 0.25) / sqrt(1 * 9 + 3 * 25) = 0.5 / sqrt(84)
    //   absolute RMS = sqrt(0.25 / 4) = 0.25
    //   floor        = 1e-3 * (1 * 3 + 3 * 5) / 4 = 4.5e-3 (below both patches: each is judged on its own)
    //   max relative = 0.5 / 3 at patch 0
    //   luminance: Y(d0) = 0.2126 * 0.3 + 0.0722 * 0.4 = 0.09266; Y(r0) = 0.2126 + 1.4304 + 0.1444 = 1.7874;
    //   Y(r1) = 2.1456 + 0.2888 = 2.4344; rel L2 = 0.09266 / sqrt(1.7874^2 + 3 * 2.4344^2);
    //   max rel = 0.09266 / 1.7874 at patch 0; floor_Y = 1e-3 * (1.7874 + 3 * 2.4344) / 4.
    let r = [[1.0, 2.0, 2.0], [0.0, 3.0, 4.0]];
    let b = [[1.3, 2.0, 2.4], [0.0, 3.0, 4.0]];
    let report = compare(&b, &r, &[1.0, 3.0]).unwrap();
    let expect = [
        ("rel_l2", report.rel_l2, 0.5 / 84f64.sqrt()),
        ("abs_rms", report.abs_rms, 0.25),
        ("floor", report.floor, 4.5e-3),
        ("max_rel", report.max_rel, 0.5 / 3.0),
        (
            "luminance_rel_l2",
            report.luminance_rel_l2,
            0.09266 / (1.7874f64.powi(2) + 3.0 * 2.4344f64.powi(2)).sqrt(),
        ),
        ("luminance_max_rel", report.luminance_max_rel, 0.09266 / 1.7874),
        ("luminance_floor", report.luminance_floor, 1e-3 * (1.7874 + 3.0 * 2.4344) / 4.0),
    ];
    // Each side is a handful (< 20) of roundings of numbers of order 1, and the 0.3 / 0.4 perturbation is
    // itself inexact in binary (relative 1e-16 of 2.4, i.e. ~1e-15 of 0.4); 1e-13 relative covers both.
    for (name, got, want) in expect {
        assert!((got - want).abs() <= 1e-13 * want.abs(), "{name}: got {got:e}, want {want:e}");
    }
    assert_eq!((report.max_rel_patch, report.luminance_max_rel_patch), (0, 0));
    assert!((luminance([1.0, 1.0, 1.0]) - 1.0).abs() <= 2.0 * EPS, "Rec. 709 weights sum to 1");
}

#[test]
fn dark_patch_floor_behaves_as_documented() {
    // A bright patch (1000 per channel) and a dark one (1e-6 per channel), equal areas. An error of 1e-3 in
    // the dark patch's red channel is 577 times its own radiosity, but the floor is
    // 1e-3 * mean |r| = 1e-3 * (1000 + 1e-6) * sqrt(3) / 2, so the max relative error is 1e-3 / floor.
    let r = [[1000.0; 3], [1e-6; 3]];
    let b = [[1000.0; 3], [1e-6 + 1e-3, 1e-6, 1e-6]];
    let report = compare(&b, &r, &[1.0, 1.0]).unwrap();
    let floor = FLOOR_FRACTION * (1000.0 + 1e-6) * 3f64.sqrt() / 2.0;
    assert!((report.floor - floor).abs() <= 1e-14 * floor, "floor {:e} vs {floor:e}", report.floor);
    let d = (b[1][0] - r[1][0]).abs();
    assert!((report.max_rel - d / floor).abs() <= 1e-12 * report.max_rel, "max_rel {:e}", report.max_rel);
    assert_eq!(report.max_rel_patch, 1);
    assert!(report.max_rel < 1e-2, "the floor keeps a dark patch from dominating");

    // A patch above the floor is judged against itself: the same absolute error on a patch at 10x the floor.
    let mid = floor * 10.0 / 3f64.sqrt();
    let r = [[1000.0; 3], [1e-6; 3], [mid; 3]];
    let b = [[1000.0; 3], [1e-6; 3], [mid + 0.01, mid, mid]];
    let report = compare(&b, &r, &[1.0, 1.0, 1e-9]).unwrap();
    assert_eq!(report.max_rel_patch, 2);
    let own = 0.01 / (mid * 3f64.sqrt());
    assert!((report.max_rel - own).abs() <= 1e-12 * own, "max_rel {:e} vs {own:e}", report.max_rel);

    // An all-dark reference: identical answers give 0, different ones an infinite relative error, a finite
    // absolute one.
    let dark = [[0.0; 3]; 2];
    assert_eq!(compare(&dark, &dark, &[1.0, 1.0]).unwrap().max_rel, 0.0);
    let lit = [[0.0; 3], [0.0, 2.0, 0.0]];
    let report = compare(&lit, &dark, &[1.0, 1.0]).unwrap();
    assert_eq!((report.rel_l2, report.max_rel), (f64::INFINITY, f64::INFINITY));
    assert_eq!(report.abs_rms, (4.0f64 / 2.0).sqrt());
}

#[test]
fn metrics_refuse_bad_input_and_serialize() {
    let r = [[1.0; 3], [2.0; 3]];
    assert_eq!(
        compare(&r[..1], &r, &[1.0, 1.0]).unwrap_err(),
        MetricsError::LengthMismatch { what: "device answer", expected: 2, found: 1 }
    );
    assert_eq!(
        compare(&r, &r, &[1.0]).unwrap_err(),
        MetricsError::LengthMismatch { what: "area", expected: 2, found: 1 }
    );
    assert!(matches!(
        compare(&[[1.0; 3], [f64::NAN, 0.0, 0.0]], &r, &[1.0, 1.0]).unwrap_err(),
        MetricsError::NonFinite { what: "device answer", patch: 1, channel: 0, .. }
    ));
    assert_eq!(compare(&r, &r, &[1.0, 0.0]).unwrap_err(), MetricsError::BadArea { patch: 1, value: 0.0 });
    let report = compare(&[[1.0; 3], [2.5, 2.0, 2.0]], &r, &[1.0, 1.0]).unwrap();
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["max_rel_patch"], 1);
    assert_eq!(json["rel_l2"].as_f64(), Some(report.rel_l2));
    let text = report.to_string();
    assert!(text.contains("relative L2") && text.contains("(patch 1, floor"), "{text}");
}

#[test]
fn empty_system_solves_to_nothing() {
    let ff = FormFactorMatrix::default();
    let system = RadiositySystem::new(&[], &ff).unwrap();
    assert!(system.is_empty());
    assert_eq!(DenseLu::factor(system).unwrap().solve(&[]).unwrap().b, Vec::<[f64; 3]>::new());
    let gs = gauss_seidel(&system, &[], &GaussSeidelOptions::default()).unwrap();
    assert_eq!((gs.b.len(), gs.sweeps, gs.residual), (0, 0, [0.0; 3]));
}
