//! The solvers against each other: dense LU and Gauss-Seidel on seeded random systems, the Gauss-Seidel
//! stop and sweep bound, one factorization for many right-hand sides, linear transfer vectors, the empty system.

use radiosity_host::patch::FormFactorMatrix;
use radiosity_host::reference::{
    gauss_seidel, gauss_seidel_sweep_bound, solve_many, transfer_vectors, DenseLu, GaussSeidelOptions,
    LightGroupEmission, Method, RadiositySystem, DEFAULT_TOLERANCE,
};
use radiosity_host::rgb::{max_channel, Rgb};

use super::{
    assert_within, csr, dense_relative_residual, lu_tolerance, relative_diff, Dense, Draw, SplitMix64, EPS,
};

/// A seeded random sparse system: about `per_row` entries per row, row sums uniform in `[0.3, 1]` (a few rows
/// exactly 1 up to rounding), reflectances in `[0, 0.95)`, emission on about a quarter of the patches.
fn random_system(n: usize, per_row: usize, seed: u64) -> (Dense, Vec<Rgb>, Vec<Rgb>) {
    let mut rng = SplitMix64::new(seed);
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
    let rho =
        (0..n).map(|_| Rgb::new(rng.range(0.0, 0.95), rng.range(0.0, 0.95), rng.range(0.0, 0.95))).collect();
    let e = (0..n)
        .map(|_| {
            if rng.uniform() < 0.25 {
                Rgb::new(rng.range(0.0, 100.0), rng.range(0.0, 100.0), 1.0)
            } else {
                Rgb::ZERO
            }
        })
        .collect();
    (dense, rho, e)
}

#[test]
fn lu_and_gauss_seidel_agree_on_random_sparse_systems() {
    for (n, per_row, seed) in [(5, 3, 1), (40, 8, 2), (200, 12, 3), (600, 20, 4)] {
        let (dense, rho, mut e) = random_system(n, per_row, seed);
        e[0] = Rgb::ONE; // at least one light per channel
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
            Rgb::splat(DEFAULT_TOLERANCE + tol[0]),
        );
        // Both are within their bounds of the exact answer, so within the sum of the bounds of each other.
        let allowed = system.condition_bound() * DEFAULT_TOLERANCE + 2.0 * tol;
        assert_within(&format!("n={n}: LU vs Gauss-Seidel"), relative_diff(&gs.b, &lu.b), allowed);
        println!(
            "n={n} nnz={}: q={:.3?}, Gauss-Seidel {} sweeps, LU-GS {:.2e}",
            ff.nonzeros(),
            system.contraction().to_array(),
            gs.sweeps,
            max_channel(relative_diff(&gs.b, &lu.b))
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
        e[0] = Rgb::ONE;
        let ff = csr(&dense);
        let system = RadiositySystem::new(&rho, &ff).unwrap();
        for tolerance in [1e-4, 1e-8, DEFAULT_TOLERANCE] {
            let gs = gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance, max_sweeps: None }).unwrap();
            assert!(gs.residual.cmple(Rgb::splat(tolerance)).all(), "n={n}: residual {}", gs.residual);
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
    let e2: Vec<Rgb> = e.iter().map(|e| e.map(|v| 2.0 * v + 1.0)).collect();
    let lu = DenseLu::factor(system).unwrap();
    assert_eq!(lu.factorization_count(), 3, "three different reflectance channels");
    let many = lu.solve_many(&[&e, &e2]).unwrap();
    let one = [lu.solve(&e).unwrap(), lu.solve(&e2).unwrap()];
    let tol = lu_tolerance(&system);
    // One column at a time or together, faer may pick different (blocked) triangular-solve kernels, so the bits
    // can differ; each is within the LU bound of the exact answer, so within twice it of each other.
    let twice = 2.0 * tol;
    assert_within("solve_many vs solve, rhs 1", relative_diff(&many[0].b, &one[0].b), twice);
    assert_within("solve_many vs solve, rhs 2", relative_diff(&many[1].b, &one[1].b), twice);
    let gs = solve_many(system, &[&e, &e2], &Method::GaussSeidel(GaussSeidelOptions::default())).unwrap();
    let allowed = system.condition_bound() * DEFAULT_TOLERANCE + 2.0 * tol;
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
    let mut rng = SplitMix64::new(5);
    let group_count = 3;
    let mut group = vec![None; n];
    let mut unit = vec![Rgb::ZERO; n];
    let mut static_emission = vec![Rgb::ZERO; n];
    for i in 0..n {
        match i % 8 {
            0..=2 => {
                group[i] = Some(i % 8);
                unit[i] = Rgb::new(rng.range(0.5, 2.0), rng.range(0.5, 2.0), rng.range(0.5, 2.0));
            }
            3 => static_emission[i] = Rgb::new(0.3, 0.2, 0.1),
            _ => {}
        }
    }
    // One patch is both static and in a dynamic group.
    static_emission[0] = Rgb::new(1.0, 0.0, 0.5);
    let lights = LightGroupEmission {
        static_emission: &static_emission,
        unit_emission: &unit,
        group: &group,
        group_count,
    };
    let intensity = [Rgb::new(2.0, 0.5, 0.0), Rgb::ZERO, Rgb::new(10.0, 3.0, 1.5)];
    let combined: Vec<Rgb> = (0..n)
        .map(|i| {
            let mut e = static_emission[i];
            if let Some(g) = group[i] {
                e += intensity[g] * unit[i];
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
        let inf = |v: &[Rgb], c: usize| v.iter().map(|b| b[c].abs()).fold(0.0, f64::max);
        let allowed = Rgb::from_array([0, 1, 2].map(|c| {
            let parts = inf(&tv.b_static, c)
                + tv.t.iter().zip(&intensity).map(|(t, i)| i[c].abs() * inf(t, c)).sum::<f64>();
            err[c] * (parts / inf(&direct.b, c) + 1.0)
        }));
        assert_within(&format!("{method:?}: relight vs direct"), relative_diff(&relit, &direct.b), allowed);
        // Group 1 at zero intensity contributes nothing, but its transfer vector is not zero.
        assert!(tv.t[1].iter().any(|t| t[0] > 0.0));
        // Unit intensity everywhere and static: B = B_static + sum_g T_g.
        let all_on = tv.relight(&[Rgb::ONE; 3]).unwrap();
        // Multiplying by 1 is exact; adding in the same order (static first, then group by group) gives the
        // same bits.
        let sum: Vec<Rgb> = (0..n).map(|i| tv.t.iter().fold(tv.b_static[i], |acc, t| acc + t[i])).collect();
        assert_eq!(all_on, sum);
        assert!(tv.residual <= DEFAULT_TOLERANCE.max(max_channel(err)));
    }
}

#[test]
fn sweep_bound_follows_the_contraction() {
    // (1 + q) / (1 - q) q^(k + 1) <= tol: for q = 0.5, tol = 1e-12: 3 * 0.5^(k + 1) <= 1e-12 -> k + 1 >= 41.45,
    // so k = 41 and the bound is 42.
    assert_eq!(gauss_seidel_sweep_bound(0.5, 1e-12), 42);
    assert_eq!(gauss_seidel_sweep_bound(0.0, 1e-12), 1);
}

#[test]
fn empty_system_solves_to_nothing() {
    let ff = FormFactorMatrix::default();
    let system = RadiositySystem::new(&[], &ff).unwrap();
    assert!(system.is_empty());
    assert_eq!(DenseLu::factor(system).unwrap().solve(&[]).unwrap().b, Vec::<Rgb>::new());
    let gs = gauss_seidel(&system, &[], &GaussSeidelOptions::default()).unwrap();
    assert_eq!((gs.b.len(), gs.sweeps, gs.residual), (0, 0, Rgb::ZERO));
}
