//! Solver tests on hand-made tables, run on both arithmetic paths (f32 and Q32.32 fixed point).
//!
//! Tolerances are sums of three derived terms:
//! - quantization: from the codec bounds (form factors `< 2^-12` relative for FLOAT16 entries in the normal
//!   range, row-sum deficit `< 2^-15` for the furnace rows, reflectance `<= 2^-17` absolute);
//! - truncation: converged means every patch's unshot magnitude `<= tol`, so at most `n * tol` power per channel
//!   is left; spread through `(I - R F)^-1` it changes a patch by at most `n * tol / ((1 - rho_max) * A_min)`;
//! - arithmetic: f32 rounds each receipt (two products and a sum, `3 * 2^-24` relative) and each hop of a path
//!   (mean path length `1 / (1 - rho)`), so `3 * 2^-24 * (K + 1 / (1 - rho)) * B` for `K` shots; fixed point
//!   rounds each product to nearest (at most `2 * 2^-32` power per receipt, sums exact), so
//!   `2 * 2^-32 * K / ((1 - rho) * A_min)`.

mod common;

use common::{
    assert_close, cold, compare, config, converge, radiosities, truncation, Arith, Scene, Store, FIXED_EPS,
    TOL,
};
use radiosity_core::{Config, Fixed, MemberSpec, NoProgressReason, Outcome, Scalar, SolverError, Table};

/// Two patches, areas 1 and 2, `F_12 = 0.4`, `F_21 = 0.2`, rho 0.5 and 0.8, patch 1 a light group member with
/// unit emission at default intensity `intensity`.
fn two_patch_scene(intensity: f32) -> Scene {
    let mut s = Scene::new(2);
    s.patches[1].area = 2.0;
    s.patches[1].material = 1;
    s.materials = vec![[0.5; 3], [0.8; 3]];
    s.rows = vec![vec![(1, 0.4)], vec![(0, 0.2)]];
    s.groups = vec![(7, [intensity; 3], vec![MemberSpec { patch: 0, emission: [1.0; 3] }])];
    s
}

/// Two patches, areas 1 and 2, `F_12 = 0.4`, `F_21 = 0.2` (reciprocity), rho 0.5 and 0.8, `E_1 = 1` from a
/// light group. By hand: `B_1 = 1 / (1 - rho_1 rho_2 F_12 F_21)`, `B_2 = rho_2 F_21 B_1`.
fn two_patch<S: Arith>() {
    let bytes = two_patch_scene(1.0).write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 100, 1_000_000);
    let b = radiosities(&solver, &t);
    let p = 0.5 * 0.8 * 0.4 * 0.2;
    let b1 = 1.0 / (1.0 - p);
    let b2 = 0.8 * 0.2 * b1;
    // Quantization: dp/p <= 2 * 2^-12 (both form factors) + 2^-17 / 0.8 (rho_2; 0.5 is exact), first order
    // with a 1% allowance for the second-order terms.
    let dp = 2.0 * 2f32.powi(-12) + 2f32.powi(-17) / 0.8;
    let q1 = b1 * p / (1.0 - p) * dp * 1.01;
    let q2 = b2 * (2f32.powi(-12) + 2f32.powi(-17) / 0.8 + q1 / b1) * 1.01;
    let rest = |bv: f32| truncation(2, TOL, 0.8, 1.0) + S::arith(bv, solver.shots(), 0.8, 1.0);
    for (x1, x2) in b[0].iter().zip(&b[1]) {
        assert_close("B_1", *x1, b1, q1 + rest(b1));
        assert_close("B_2", *x2, b2, q2 + rest(b2));
    }
}

/// The two-patch system with its light at intensity `scale` (1e-6 .. 1e6, the emission range the project
/// must handle), cold start: the answer scales linearly. Tolerances as in `two_patch`, with the convergence tolerance scaled
/// too (but not below the fixed-point convergence floor) and the intensity's representation error.
fn two_patch_scaled<S: Arith>(scale: f32) {
    let bytes = two_patch_scene(scale).write();
    let t = Table::parse(&bytes).unwrap();
    // At least the smallest tolerance with guaranteed convergence (`radiosity_core::scalar`), which the solver
    // enforces: `6 L 2^-32 / (1 - rho_max)` for fixed point, from the table's reflectance codes.
    let tol = (TOL * scale).max(radiosity_core::convergence_floor::<S>(&t).to_f32());
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, Config { tolerance: S::from_f32(tol), overshoot: 0 });
    converge(&mut solver, 100, 1_000_000);
    let b = radiosities(&solver, &t);
    let p = 0.5 * 0.8 * 0.4 * 0.2;
    let b1 = scale / (1.0 - p);
    let b2 = 0.8 * 0.2 * b1;
    let dp = 2.0 * 2f32.powi(-12) + 2f32.powi(-17) / 0.8;
    let q1 = b1 * p / (1.0 - p) * dp * 1.01 + S::input(scale) / (1.0 - p);
    let q2 = b2 * (2f32.powi(-12) + 2f32.powi(-17) / 0.8) * 1.01 + 0.16 * q1;
    let rest = |bv: f32| truncation(2, tol, 0.8, 1.0) + S::arith(bv, solver.shots(), 0.8, 1.0);
    for (x1, x2) in b[0].iter().zip(&b[1]) {
        assert_close("B_1", *x1, b1, q1 + rest(b1));
        assert_close("B_2", *x2, b2, q2 + rest(b2));
    }
}

/// Three patches of area 1 with dyadic form factors (exact in FLOAT16): `F_12 = 0.25`, `F_13 = 0.5`,
/// `F_23 = 0.125`, rho = 0.5, 0.25, 0.75, `E = (1, 0.5, 0.25)` on patch 1. By hand (substitution):
/// `B = (1021, 76, 390) / 914` times `E`.
fn three_patch_scene() -> Scene {
    let mut s = Scene::new(3);
    s.materials = vec![[0.5; 3], [0.25; 3], [0.75; 3]];
    for i in 0..3 {
        s.patches[i].material = i as u32;
    }
    s.patches[0].base_emission = [1.0, 0.5, 0.25];
    s.rows = vec![vec![(1, 0.25), (2, 0.5)], vec![(0, 0.25), (2, 0.125)], vec![(0, 0.5), (1, 0.125)]];
    s
}

const THREE_B: [f32; 3] = [1021.0 / 914.0, 76.0 / 914.0, 390.0 / 914.0];
const THREE_E: [f32; 3] = [1.0, 0.5, 0.25];

fn check_three<S: Arith>(b: &[[f32; 3]], shots: u32, extra: f32) {
    for (i, bi) in b.iter().enumerate() {
        for c in 0..3 {
            let want = THREE_B[i] * THREE_E[c];
            let tol = truncation(3, TOL, 0.75, 1.0) + S::arith(want, shots, 0.75, 1.0) + extra;
            assert_close("three-patch B", bi[c], want, tol);
        }
    }
}

fn three_patch<S: Arith>() {
    let bytes = three_patch_scene().write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 7, 1_000_000);
    check_three::<S>(&radiosities(&solver, &t), solver.shots(), 0.0);
}

/// Shooting with overshoot, Gauss-Seidel and Jacobi reach the same answer.
fn three_patch_other_methods<S: Arith>() {
    let bytes = three_patch_scene().write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, Config { tolerance: S::from_f32(TOL), overshoot: 64 });
    converge(&mut solver, 5, 1_000_000);
    check_three::<S>(&radiosities(&solver, &t), solver.shots(), 0.0);

    for jacobi in [false, true] {
        let mut store = Store::<S>::for_table(&t);
        let mut solver = common::solver(&mut store, &t, config());
        let mut scratch = vec![[S::ZERO; 3]; 3];
        let mut total = 0u64;
        loop {
            let o = if jacobi { solver.step_jacobi(&mut scratch, 4) } else { solver.step_gauss_seidel(4) };
            assert!(o.used() <= 4, "{o:?}");
            total += u64::from(o.used());
            match o {
                Outcome::Converged { .. } => break,
                Outcome::BudgetSpent { .. } => {}
                other => panic!("{other:?}"),
            }
            assert!(total < 1_000_000);
        }
        check_three::<S>(&radiosities(&solver, &t), solver.shots(), 0.0);
        // The result is converged for shooting too: its step finds nothing to shoot after the tree rebuild.
        // 3 slots in blocks of 2: rebuilding the blocks (2 + 1 units), then scanning their 2 winners.
        assert_eq!(solver.step(100), Outcome::Converged { used: 5 });
    }
}

/// A static base solved by the host: the solver starts converged and only builds its tree.
fn static_base_costs_nothing<S: Arith>() {
    let mut s = three_patch_scene();
    s.base_solved = true;
    let g = [214.0 / 914.0, 304.0 / 914.0, 520.0 / 914.0]; // G_i = sum_j F_ij B_j, by hand
    for (patch, gi) in s.patches.iter_mut().zip(g) {
        patch.base_irradiance = THREE_E.map(|e| e * gi);
    }
    let bytes = s.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    assert_eq!(
        solver.step(100),
        Outcome::Converged { used: 5 },
        "only the block rebuild (3) and selection (2)"
    );
    assert_eq!(solver.shots(), 0);
    // The irradiance went through the emission code: relative error <= 2^-11, times rho <= 0.75.
    let b = radiosities(&solver, &t);
    for (i, bi) in b.iter().enumerate() {
        for c in 0..3 {
            let want = THREE_B[i] * THREE_E[c];
            assert_close("static base B", bi[c], want, 2f32.powi(-11) * want + S::arith(want, 1, 0.75, 1.0));
        }
    }
}

/// White furnace: 7 patches of area 1, `F_ij = 1/6` for `j != i` (closed, reciprocal), uniform rho, `E = 1`:
/// `B = E / (1 - rho)`. The writer hands out row slack cyclically from the shooter, so the quantized matrix
/// is circulant like the exact one: B stays uniform, `B = E / (1 - rho_q s_q)` with the decoded row sum `s_q`.
fn furnace<S: Arith>(rho: f32) {
    let n = 7;
    let mut s = Scene::new(n);
    s.materials = vec![[rho; 3]];
    for i in 0..n {
        s.patches[i].base_emission = [1.0; 3];
        s.rows[i] = (0..n as u32).filter(|&j| j != i as u32).map(|j| (j, 1.0 / 6.0)).collect();
    }
    let bytes = s.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 1000, 50_000_000);
    let b = radiosities(&solver, &t);
    let rho_q = radiosity_core::codec::decode_reflectance(t.reflectance(0).unwrap()[0]).to_f32();
    let s_q = t.row_sum(0).unwrap();
    let exact = 1.0 / (1.0 - rho);
    let quantized = 1.0 / (1.0 - rho_q * s_q);
    // Solver error against the quantized system (s_q summed in f32: 6 terms, 6 * 2^-24 relative).
    let solve_tol = truncation(n, TOL, rho, 1.0)
        + S::arith(quantized, solver.shots(), rho, 1.0)
        + quantized * quantized * rho * 6.0 * f32::EPSILON / 2.0;
    // Quantization: row-sum deficit < 2^-15 (one top-binade step of 1/6, whose row exponent is 3), and
    // |rho_q - rho| <= 2^-17: dB = B^2 (rho * ds + drho).
    let quant_tol = exact * exact * (rho * 2f32.powi(-15) + 2f32.powi(-17)) * 1.01;
    for bi in &b {
        for &x in bi {
            assert_close("furnace B vs quantized system", x, quantized, solve_tol);
            assert_close("furnace B vs E/(1-rho)", x, exact, solve_tol + quant_tol);
        }
    }
}

/// Ambient term (Cohen et al. 1988): in a furnace with exact form factors (n = 5, F = 1/4) and rho = 0.5,
/// the area-weighted mean of `B + rho * ambient` is exactly `E / (1 - rho)` at any point of the solve.
fn ambient_in_furnace<S: Arith>() {
    let n = 5;
    let mut s = Scene::new(n);
    for i in 0..n {
        s.patches[i].base_emission = [1.0; 3];
        s.rows[i] = (0..n as u32).filter(|&j| j != i as u32).map(|j| (j, 0.25)).collect();
    }
    let bytes = s.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    for _ in 0..3 {
        let o = solver.step(9);
        assert!(matches!(o, Outcome::BudgetSpent { .. }), "{o:?}");
        let amb = solver.ambient();
        let mean: f32 =
            (0..n as u32).map(|i| solver.radiosity_with_ambient(i, amb).unwrap()[0].to_f32()).sum::<f32>()
                / n as f32;
        let plain: f32 =
            (0..n as u32).map(|i| solver.radiosity(i).unwrap()[0].to_f32()).sum::<f32>() / n as f32;
        assert!(plain < 1.9, "state should be unconverged, mean B {plain}");
        // Arithmetic only: a handful of shots on values <= 2.
        assert_close("ambient-corrected mean", mean, 2.0, S::arith(2.0, solver.shots() + 8, 0.5, 1.0));
    }
}

/// The scene for relighting: three-patch system plus a light group on patch 1 (and static emission on 0).
fn relight_scene(intensity: [f32; 3], rho1: [f32; 3]) -> Scene {
    let mut s = three_patch_scene();
    s.materials[1] = rho1;
    s.groups = vec![(42, intensity, vec![MemberSpec { patch: 1, emission: [2.0, 1.0, 3.0] }])];
    s
}

/// Warm starts (dim to zero and back, change colour, edit a reflectance) converge to the cold solves.
fn relighting<S: Arith>() {
    let base = relight_scene([1.0; 3], [0.25; 3]);
    let bytes = base.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 50, 10_000_000);
    let (cold_default, k0) = cold::<S>(&base);
    // Two converged solves differ by at most the sum of their truncation and arithmetic terms. rho_max 0.75.
    let tol =
        |shots: u32| move |b: f32| 2.0 * truncation(3, TOL, 0.75, 1.0) + 2.0 * S::arith(b, shots, 0.75, 1.0);

    solver.set_light(0, [0.0; 3]).unwrap();
    converge(&mut solver, 50, 10_000_000);
    let (cold_off, _) = cold::<S>(&relight_scene([0.0; 3], [0.25; 3]));
    compare("dimmed to zero", &radiosities(&solver, &t), &cold_off, tol(solver.shots()));

    solver.set_light(0, [1.0; 3]).unwrap();
    converge(&mut solver, 50, 10_000_000);
    compare("back to default", &radiosities(&solver, &t), &cold_default, tol(solver.shots().max(k0)));

    solver.set_light(0, [0.5, 2.0, 0.0]).unwrap();
    converge(&mut solver, 50, 10_000_000);
    let (cold_colour, k1) = cold::<S>(&relight_scene([0.5, 2.0, 0.0], [0.25; 3]));
    compare("colour change", &radiosities(&solver, &t), &cold_colour, tol(solver.shots().max(k1)));

    // Reflectance edit mid-solve (not converged), then converge: same as the cold solve of the edited scene.
    solver.set_light(0, [1.0; 3]).unwrap();
    let _ = solver.step(7);
    solver.set_reflectance(1, [0.9, 0.0, 0.6]).unwrap();
    converge(&mut solver, 50, 10_000_000);
    let (cold_edit, k2) = cold::<S>(&relight_scene([1.0; 3], [0.9, 0.0, 0.6]));
    let k_edit = solver.shots().max(k2);
    let tol_edit = move |b: f32| 2.0 * truncation(3, TOL, 0.9, 1.0) + 2.0 * S::arith(b, k_edit, 0.9, 1.0);
    compare("reflectance edit", &radiosities(&solver, &t), &cold_edit, tol_edit);
}

/// Same inputs and budgets give bit-identical states.
fn determinism<S: Arith>() {
    let bytes = relight_scene([1.0; 3], [0.25; 3]).write();
    let t = Table::parse(&bytes).unwrap();
    let run = || {
        let mut store = Store::<S>::for_table(&t);
        let mut solver =
            common::solver(&mut store, &t, Config { tolerance: S::from_f32(TOL), overshoot: 32 });
        let mut log = Vec::new();
        for k in 0..40u32 {
            log.push(solver.step(3 + k % 5));
            if k % 7 == 0 {
                solver.set_light(0, [k as f32 * 0.1, 1.0, 0.0]).unwrap();
            }
            if k == 20 {
                solver.set_reflectance(2, [0.5, 0.1, 0.2]).unwrap();
            }
        }
        let state: Vec<_> = (0..3).map(|i| (solver.power(i), solver.unshot(i))).collect();
        format!("{log:?} {state:?}")
    };
    assert_eq!(run(), run());
}

/// Splitting work across steps does not change the result: shots resume mid-row and the block selection
/// picks the same shooter whether rebuilt or updated, so any budget partition gives bit-identical states.
fn budget_partition_invariance<S: Arith>() {
    let bytes = relight_scene([1.0; 3], [0.25; 3]).write();
    let t = Table::parse(&bytes).unwrap();
    let run = |budget: u32, gauss_seidel: bool| {
        let mut store = Store::<S>::for_table(&t);
        let mut solver = common::solver(&mut store, &t, config());
        let mut steps = 0;
        loop {
            let o = if gauss_seidel { solver.step_gauss_seidel(budget) } else { solver.step(budget) };
            assert!(o.used() <= budget, "{o:?}");
            steps += 1;
            if matches!(o, Outcome::Converged { .. }) {
                break;
            }
            assert!(steps < 10_000_000, "{o:?}");
        }
        let state: Vec<_> = (0..3).map(|i| (solver.power(i), solver.unshot(i))).collect();
        (format!("{state:?}"), steps)
    };
    for gs in [false, true] {
        let (whole, one_step) = run(1_000_000, gs);
        assert_eq!(one_step, 1);
        // 3 units is the smallest shooting budget here (1 entry + a 2-node tree path), so rows get split.
        let (split, many) = run(3, gs);
        assert!(many > 10);
        assert_eq!(split, whole, "gauss-seidel: {gs}");
    }
}

/// `restart` after relighting gives exactly the state of a cold solve of a table with those settings.
fn restart_is_cold<S: Arith>() {
    let bytes = relight_scene([1.0; 3], [0.25; 3]).write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 50, 10_000_000);
    solver.set_light(0, [1e-3, 0.0, 2.0]).unwrap();
    solver.set_reflectance(1, [0.9, 0.0, 0.6]).unwrap();
    solver.restart();
    converge(&mut solver, 50, 10_000_000);
    let edited_bytes = relight_scene([1e-3, 0.0, 2.0], [0.9, 0.0, 0.6]).write();
    let edited = Table::parse(&edited_bytes).unwrap();
    let mut cold_store = Store::<S>::for_table(&edited);
    let mut cold = common::solver(&mut cold_store, &edited, config());
    converge(&mut cold, 50, 10_000_000);
    // Same codes, same intensities, same operations: bit-identical.
    let a: Vec<_> = (0..3).map(|i| solver.power(i)).collect();
    let b: Vec<_> = (0..3).map(|i| cold.power(i)).collect();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
}

/// Two closed pairs that cannot see each other, each like [`two_patch_scene`] (areas 1 and 2, `F_01 = 0.4`,
/// `F_10 = 0.2`, rho 0.5 and 0.8): pair (0, 1) lit by a static unit emission on patch 0 (solved base, `G_i`
/// by hand: `B_0 = 1 / 0.968`, `B_1 = 0.16 / 0.968`), pair (2, 3) by a light group on patch 2. With `partial`,
/// only the dynamic pair has state (slots 0, 1 = patches 2, 3); otherwise every patch has.
fn two_rooms_scene(partial: bool) -> Scene {
    let mut s = Scene::new(4);
    s.base_solved = true;
    s.materials = vec![[0.5; 3], [0.8; 3]];
    for (i, p) in s.patches.iter_mut().enumerate() {
        p.material = (i % 2) as u32;
        p.area = if i % 2 == 0 { 1.0 } else { 2.0 };
    }
    s.patches[0].base_emission = [1.0; 3];
    s.patches[0].base_irradiance = [0.4 * 0.16 / 0.968; 3];
    s.patches[1].base_irradiance = [0.2 / 0.968; 3];
    s.groups = vec![(7, [1.0; 3], vec![MemberSpec { patch: 2, emission: [1.0; 3] }])];
    if partial {
        s.state = Some(vec![2, 3]);
        s.rows = vec![vec![(1, 0.4)], vec![(0, 0.2)]];
    } else {
        s.rows = vec![vec![(1, 0.4)], vec![(0, 0.2)], vec![(3, 0.4)], vec![(2, 0.2)]];
    }
    s
}

/// A table whose static-only pair has no state solves like the table giving every patch state: the dynamic
/// pair bit for bit (same rows, same shots), the stateless pair its static base; buffers hold the slots only.
fn stateless_patches_show_the_static_base<S: Arith>() {
    let (full_bytes, part_bytes) = (two_rooms_scene(false).write(), two_rooms_scene(true).write());
    let (full, part) = (Table::parse(&full_bytes).unwrap(), Table::parse(&part_bytes).unwrap());
    assert_eq!((part.patch_count(), part.state_count()), (4, 2));
    let mut sizes = radiosity_core::BufferSizes::of(&part);
    assert_eq!(sizes.slots, 2, "buffers hold the slots only");
    sizes.selection -= 1;
    let mut short = Store::<S>::new(sizes);
    let err = radiosity_core::Solver::new(&part, short.buffers(), config()).err();
    assert_eq!(err, Some(SolverError::BufferTooSmall { buffer: "selection", needed: 1, got: 0 }));
    let mut store = Store::<S>::for_table(&part);
    let mut solver = common::solver(&mut store, &part, config());
    let mut full_store = Store::<S>::for_table(&full);
    let mut full_solver = common::solver(&mut full_store, &full, config());
    let units = converge(&mut solver, 50, 100_000);
    let full_units = converge(&mut full_solver, 50, 100_000);
    assert!(units < full_units, "fewer slots to select from: {units} vs {full_units}");
    assert_eq!(solver.shots(), full_solver.shots());
    let (b, b_full) = (radiosities(&solver, &part), radiosities(&full_solver, &full));
    assert_eq!(b[2..], b_full[2..], "the dynamic pair");
    let want = [1.0 / 0.968, 0.16 / 0.968];
    for i in 0..2 {
        // Stateless: exactly the decoded static base, E_s + rho G_s (as the transfer basis decodes it).
        let base = radiosity_core::static_radiosity::<S>(&part, i as u32).unwrap().map(|x| x.to_f32());
        assert_eq!(b[i], base, "patch {i}");
        assert_eq!(solver.unshot(i as u32), Some([S::ZERO; 3]));
        for c in 0..3 {
            // Through the emission codes (2^-11 relative each) and, with state, one division by the area.
            let q = 2f32.powi(-10) * want[i];
            assert_close("static pair", b[i][c], want[i], q + S::arith(want[i], 1, 0.8, 1.0));
            assert_close("static pair vs full", b[i][c], b_full[i][c], S::arith(want[i], 2, 0.8, 1.0) * 2.0);
            // The dynamic pair solves the same system (by hand, up to FLOAT16 and the tolerance).
            let q = 2f32.powi(-11) * want[i] + truncation(2, TOL, 0.8, 1.0);
            assert_close(
                "dynamic pair",
                b[i + 2][c],
                want[i],
                q + S::arith(want[i], solver.shots(), 0.8, 1.0),
            );
        }
    }
    assert_eq!(solver.radiosity(4), None);
    assert_eq!(solver.power(4), None, "out of range");
    // A light change touches the slots only; a reflectance edit changes a stateless patch's reflection of the
    // static light (E_s + rho' G_s) without propagating it.
    solver.set_light(0, [2.0; 3]).unwrap();
    solver.set_reflectance(1, [0.4; 3]).unwrap();
    converge(&mut solver, 50, 100_000);
    let b2 = radiosities(&solver, &part);
    assert_eq!(b2[0], b[0]);
    let rho_q =
        radiosity_core::codec::decode_reflectance(radiosity_core::codec::encode_reflectance(0.4)).to_f32();
    let g1 = 0.2 / 0.968;
    assert_close(
        "stateless after an edit",
        b2[1][0],
        rho_q * g1,
        2f32.powi(-11) * g1 + S::arith(g1, 1, 0.8, 1.0),
    );
    // Dynamic pair at intensity 2 with rho_1 = 0.4: B_2 = 2 / (1 - 0.5 * 0.4 * 0.4 * 0.2) = 2 / 0.984.
    let want2 = 2.0 / 0.984;
    let tol =
        2f32.powi(-10) * want2 + truncation(2, TOL, 0.8, 1.0) + S::arith(want2, solver.shots() + 8, 0.8, 1.0);
    assert_close("dynamic pair relit", b2[2][0], want2, tol);
}

macro_rules! both_paths {
    ($($name:ident => $body:expr;)*) => {
        mod f32_path {
            use super::*;
            $(#[test] fn $name() { type S = f32; $body })*
        }
        mod fixed_path {
            use super::*;
            $(#[test] fn $name() { type S = Fixed; $body })*
        }
    };
}

both_paths! {
    two_patch_by_hand => two_patch::<S>();
    two_patch_dim_light => two_patch_scaled::<S>(1e-6);
    two_patch_bright_light => two_patch_scaled::<S>(1e6);
    three_patch_by_hand => three_patch::<S>();
    gauss_seidel_jacobi_overshoot => three_patch_other_methods::<S>();
    static_base => static_base_costs_nothing::<S>();
    white_furnace_0_5 => furnace::<S>(0.5);
    white_furnace_0_9 => furnace::<S>(0.9);
    white_furnace_0_99 => furnace::<S>(0.99);
    ambient => ambient_in_furnace::<S>();
    warm_start_equals_cold_solve => relighting::<S>();
    deterministic => determinism::<S>();
    restart_after_dimming => restart_is_cold::<S>();
    stateless_patches => stateless_patches_show_the_static_base::<S>();
    budget_partition => budget_partition_invariance::<S>();
    light_change_during_scan => light_change_during_the_scan::<S>();
}

#[test]
fn small_budgets_and_wrong_tables_are_reported() {
    let bytes = three_patch_scene().write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<f32>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    // 3 slots: blocks of B = 2 (slots 0-1 and 2). Rebuild: 2 + 1 units; selection: 2 blocks; a shot start:
    // 1 + its block's rescan (2 for patch 0, the light); an entry: 1 + B = 3 at worst.
    assert_eq!(
        solver.step(0),
        Outcome::NoProgress { used: 0, reason: NoProgressReason::BudgetTooSmall { needed: 2 } }
    );
    assert_eq!(solver.step(2), Outcome::BudgetSpent { used: 2 });
    assert_eq!(solver.step(2), Outcome::BudgetSpent { used: 1 }, "block 1, then the selection does not fit");
    assert_eq!(
        solver.step(1),
        Outcome::NoProgress { used: 0, reason: NoProgressReason::BudgetTooSmall { needed: 2 } }
    );
    assert_eq!(solver.step(4), Outcome::BudgetSpent { used: 2 }, "the selection; the shot needs 3");
    assert_eq!(
        solver.step(2),
        Outcome::NoProgress { used: 0, reason: NoProgressReason::BudgetTooSmall { needed: 3 } }
    );
    assert_eq!(solver.shots(), 0);
    assert_eq!(solver.step(3), Outcome::BudgetSpent { used: 3 }, "the selection is kept: the shot starts");
    assert_eq!(solver.shots(), 1);
    assert_eq!(solver.set_light(0, [1.0; 3]), Err(SolverError::NoSuchGroup { group: 0 }));
    let lit_bytes = relight_scene([1.0; 3], [0.25; 3]).write();
    let lit = Table::parse(&lit_bytes).unwrap();
    let mut lit_store = Store::<f32>::for_table(&lit);
    let mut lit_solver = common::solver(&mut lit_store, &lit, config());
    assert_eq!(lit_solver.set_light(0, [1.0, f32::NAN, 1.0]), Err(SolverError::BadValue { channel: 1 }));
    assert_eq!(lit_solver.set_light(0, [f32::INFINITY, 1.0, 1.0]), Err(SolverError::BadValue { channel: 0 }));
    assert_eq!(lit_solver.set_reflectance(0, [0.5, 0.5, -0.1]), Err(SolverError::BadValue { channel: 2 }));
    assert!(solver.set_reflectance(0, [1.0, 0.0, 0.0]).is_err(), "reflectance 1 is rejected");
    assert!(solver.set_reflectance(3, [0.1; 3]).is_err(), "no material 3");
}

/// An empty table converges at once under every method, whatever the tolerance (an empty sweep costs no
/// units, so it must not be repeated).
#[test]
fn empty_table_converges() {
    let bytes = Scene::new(0).write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<f32>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, Config { tolerance: 0.0, overshoot: 0 });
    let mut scratch: Vec<[f32; 3]> = Vec::new();
    assert_eq!(solver.step(10), Outcome::Converged { used: 0 });
    assert_eq!(solver.step_gauss_seidel(10), Outcome::Converged { used: 0 });
    assert_eq!(solver.step_jacobi(&mut scratch, 10), Outcome::Converged { used: 0 });
}

/// A tolerance the arithmetic could never reach is refused when the solver is made, not discovered by a solver
/// that shoots forever: below fixed point's floor `ceil(6 L / (1 - rho_max))` resolution steps (two patches,
/// rows of one entry, rho_max code 52429: 6 * 65536 / 13107 = 30.0002, so 31 steps), and negative for f32.
#[test]
fn unreachable_tolerances_are_refused() {
    let bytes = two_patch_scene(1.0).write();
    let t = Table::parse(&bytes).unwrap();
    let floor = radiosity_core::convergence_floor::<Fixed>(&t);
    assert_eq!(floor.to_f32(), 31.0 * FIXED_EPS);
    assert_eq!(radiosity_core::convergence_floor::<f32>(&t), 0.0);
    let below = Fixed::from_f32(30.0 * FIXED_EPS);
    let mut fixed = Store::<Fixed>::for_table(&t);
    match radiosity_core::Solver::new(&t, fixed.buffers(), Config { tolerance: below, overshoot: 0 }) {
        Err(SolverError::ToleranceBelowFloor { tolerance, floor: f }) => {
            assert_eq!((tolerance, f), (below.to_f32(), floor.to_f32()));
        }
        other => panic!("expected ToleranceBelowFloor, got {other:?}"),
    }
    let mut solver = common::solver(&mut fixed, &t, Config { tolerance: floor, overshoot: 0 });
    converge(&mut solver, 100, 1_000_000);
    let mut f = Store::<f32>::for_table(&t);
    let refused = radiosity_core::Solver::new(&t, f.buffers(), Config { tolerance: -1e-30, overshoot: 0 });
    assert!(matches!(refused, Err(SolverError::ToleranceBelowFloor { .. })), "{refused:?}");
}

/// A light change during a Gauss-Seidel sweep's end-of-sweep scan, after the changed slot was scanned: the sweep
/// must not report convergence on the old magnitudes. Two patches, rows of one entry each: a sweep costs 2 row
/// visits, 2 entries and 2 scan units, so a budget of 5 stops after scanning slot 0, the light's member. Found by
/// `properties.rs` (the solver answered with the light at its previous intensity).
fn light_change_during_the_scan<S: Arith>() {
    let bytes = two_patch_scene(1.0).write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    converge(&mut solver, 100, 1_000_000);
    assert_eq!(solver.step_gauss_seidel(5), Outcome::BudgetSpent { used: 5 });
    solver.set_light(0, [4.0; 3]).unwrap();
    let o = solver.step_gauss_seidel(1);
    assert!(matches!(o, Outcome::BudgetSpent { used: 1 }), "the scan starts over: {o:?}");
    let mut steps = 0;
    while !matches!(solver.step_gauss_seidel(100), Outcome::Converged { .. }) {
        steps += 1;
        assert!(steps < 10_000);
    }
    for i in 0..2 {
        let u = solver.unshot(i).unwrap();
        let magnitude = u.iter().map(|x| x.to_f32().abs()).sum::<f32>();
        assert!(magnitude <= TOL, "slot {i}: unshot {magnitude} above the tolerance after Converged");
    }
    // B_1 = 4 / (1 - rho_1 rho_2 F_12 F_21), as in `two_patch` (quantization and truncation well inside 1e-3).
    assert_close("B_1 at the new intensity", solver.radiosity(0).unwrap()[0].to_f32(), 4.0 / 0.968, 1e-3);
}
