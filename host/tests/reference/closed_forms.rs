//! Closed forms: two and three patches, an open scene, the white furnace `B = E / (1 - rho)`.

use radiosity_host::reference::{
    gauss_seidel, gauss_seidel_sweep_bound, DenseLu, GaussSeidelOptions, RadiositySystem, DEFAULT_TOLERANCE,
};
use radiosity_host::rgb::Rgb;

use super::{
    assert_within, csr, dense_relative_residual, lu_tolerance, relative_diff, Dense, Draw, SplitMix64, EPS,
};

#[test]
fn two_patches_match_the_closed_form() {
    // B0 = E0 + r0 a B1 and B1 = E1 + r1 b B0 with a = F01, b = F10. Substituting:
    //   B0 = (E0 + r0 a E1) / (1 - r0 r1 a b),   B1 = (E1 + r1 b E0) / (1 - r0 r1 a b).
    let (a, b) = (0.6, 0.3);
    let ff = csr(&[vec![0.0, a], vec![b, 0.0]]);
    let rho = [Rgb::new(0.8, 0.5, 0.1), Rgb::new(0.7, 0.9, 0.0)];
    let e = [Rgb::new(10.0, 0.0, 3.0), Rgb::new(1.0, 2.0, 0.0)];
    let expected: Vec<Rgb> = {
        let d = 1.0 - rho[0] * rho[1] * a * b;
        vec![(e[0] + rho[0] * a * e[1]) / d, (e[1] + rho[1] * b * e[0]) / d]
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
fn three_patch_case(f: f64, rho: Rgb, e0: Rgb) -> (Dense, [Rgb; 3], Vec<Rgb>) {
    let dense = vec![vec![0.0, f, f], vec![f, 0.0, f], vec![f, f, 0.0]];
    let p = rho * f;
    let x = e0 * (1.0 - p) / ((1.0 - 2.0 * p) * (1.0 + p));
    let y = e0 * p / ((1.0 - 2.0 * p) * (1.0 + p));
    (dense, [rho; 3], vec![x, y, y])
}

#[test]
fn three_patches_match_the_closed_form() {
    // Closed: 2 f = 1.
    let (dense, rho, expected) = three_patch_case(0.5, Rgb::new(0.9, 0.5, 0.99), Rgb::new(1.0, 4.0, 0.25));
    let e = [Rgb::new(1.0, 4.0, 0.25), Rgb::ZERO, Rgb::ZERO];
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
    let (dense, rho, expected) = three_patch_case(0.3, Rgb::new(0.9, 0.5, 0.99), Rgb::new(1.0, 4.0, 0.25));
    let (_, _, closed) = three_patch_case(0.5, Rgb::new(0.9, 0.5, 0.99), Rgb::new(1.0, 4.0, 0.25));
    let e = [Rgb::new(1.0, 4.0, 0.25), Rgb::ZERO, Rgb::ZERO];
    let ff = csr(&dense);
    let system = RadiositySystem::new(&rho, &ff).unwrap();
    assert_eq!(system.contraction(), rho[0] * (0.3 + 0.3), "contraction uses the open row sum");
    let tol = lu_tolerance(&system);
    let lu = DenseLu::factor(system).unwrap().solve(&e).unwrap();
    assert_within("LU vs closed form (open)", relative_diff(&lu.b, &expected), tol);
    let gs = gauss_seidel(&system, &e, &GaussSeidelOptions::default()).unwrap();
    let gs_tol = system.condition_bound().map(|k| k * DEFAULT_TOLERANCE + tol[0]);
    assert_within("Gauss-Seidel vs closed form (open)", relative_diff(&gs.b, &expected), gs_tol);
    // The renormalized answer is far away: at least 10% brighter somewhere.
    assert!(relative_diff(&closed, &lu.b).cmpgt(Rgb::splat(0.1)).any());
}

/// A closed white furnace: `n` patches with seeded random areas and `F_ij = A_j / A_total`, so every row sums
/// to 1 (up to rounding) and reciprocity `A_i F_ij = A_i A_j / A_total = A_j F_ji` holds exactly in real numbers.
fn furnace(n: usize, seed: u64) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut rng = SplitMix64::new(seed);
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
        let rho = vec![Rgb::splat(rho_value); n];
        let system = RadiositySystem::new(&rho, &ff).unwrap();
        let tol = lu_tolerance(&system);
        let lu = DenseLu::factor(system).unwrap();
        assert_eq!(lu.factorization_count(), 1, "a grey scene needs one factorization");

        // Uniform emission: B = E / (1 - rho) everywhere.
        let e_uniform = vec![Rgb::new(1.0, 0.5, 2.0); n];
        let expected: Vec<Rgb> = e_uniform.iter().map(|e| e.map(|v| v / (1.0 - rho_value))).collect();
        let got = lu.solve(&e_uniform).unwrap();
        assert_within(&format!("furnace rho {rho_value}: LU"), relative_diff(&got.b, &expected), tol);
        assert_within(
            &format!("furnace rho {rho_value}: LU residual"),
            dense_relative_residual(&dense, &rho, &got.b, &e_uniform),
            tol,
        );

        // Uneven emission: B_i = E_i + rho * Ebar / (1 - rho), Ebar the area-weighted mean emission
        // (sum_j F_ij B_j is the area-weighted mean of B, which is Ebar / (1 - rho) by energy balance).
        let mut rng = SplitMix64::new(99);
        let e: Vec<Rgb> = (0..n).map(|_| Rgb::new(rng.range(0.0, 5.0), 0.0, rng.range(0.0, 1.0))).collect();
        let total: f64 = area.iter().sum();
        let ebar = area.iter().zip(&e).map(|(&a, &e)| a * e).sum::<Rgb>() / total;
        let expected: Vec<Rgb> = e.iter().map(|&e| e + rho_value * ebar / (1.0 - rho_value)).collect();
        let got = lu.solve(&e).unwrap();
        // Channel 1 is dark (all zero): compare it exactly.
        assert!(got.b.iter().all(|b| b[1] == 0.0));
        let d = relative_diff(&got.b, &expected);
        assert_within(&format!("furnace rho {rho_value}, uneven E: LU"), Rgb::new(d[0], 0.0, d[2]), tol);

        // Gauss-Seidel. Its computed residual has a rounding floor of about (n + 2) eps / (1 - q) (summing n
        // terms of size up to ||B|| = ||E|| / (1 - q)), so ask for the larger of 1e-12 and that floor.
        let q = system.contraction()[0];
        let gs_tol = DEFAULT_TOLERANCE.max((n + 2) as f64 * EPS / (1.0 - q));
        let options = GaussSeidelOptions { tolerance: gs_tol, max_sweeps: None };
        let gs = gauss_seidel(&system, &e_uniform, &options).unwrap();
        let expected: Vec<Rgb> = e_uniform.iter().map(|e| e.map(|v| v / (1.0 - rho_value))).collect();
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
