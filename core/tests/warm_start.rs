//! Property test of the solver on random tables: budgets are never exceeded, and any history of light and
//! reflectance changes, warm-started, ends at the cold solve of the final settings (both arithmetic paths).
//! Tolerances as derived in `solver.rs`'s module docs.

mod common;

use common::{cold, config, radiosities, truncation, Arith, Scene, Store, TOL};
use proptest::prelude::*;
use radiosity_core::{Fixed, MemberSpec, NoProgressReason, Outcome, Table};

// ---- property test: budgets are never exceeded, and any warm-start history ends at the cold solve -------

#[derive(Clone, Debug)]
enum Op {
    Shoot(u32),
    GaussSeidel(u32),
    Jacobi(u32),
    Light(u32, [f32; 3]),
    Reflectance(u32, [f32; 3]),
}

fn op() -> impl Strategy<Value = Op> {
    let rgb = || (0.0f32..4.0, 0.0f32..4.0, 0.0f32..4.0).prop_map(|(a, b, c)| [a, b, c]);
    let rho = || (0.0f32..0.9, 0.0f32..0.9, 0.0f32..0.9).prop_map(|(a, b, c)| [a, b, c]);
    prop_oneof![
        4 => (0u32..60).prop_map(Op::Shoot),
        1 => (0u32..60).prop_map(Op::GaussSeidel),
        1 => (0u32..60).prop_map(Op::Jacobi),
        2 => (0u32..2, rgb()).prop_map(|(g, c)| Op::Light(g, c)),
        1 => (0u32..2, rho()).prop_map(|(m, c)| Op::Reflectance(m, c)),
    ]
}

fn random_scene() -> impl Strategy<Value = Scene> {
    (1usize..9)
        .prop_flat_map(|n| {
            (
                Just(n),
                proptest::collection::vec(0.5f32..2.0, n),
                proptest::collection::vec(proptest::collection::vec(0.0f32..1.0, n), n),
                proptest::collection::vec(0.2f32..1.0, n),
                proptest::collection::vec(0usize..n, 1..4),
                proptest::collection::vec(any::<bool>(), n),
            )
        })
        .prop_map(|(n, areas, weights, sums, members, stateful)| {
            let mut s = Scene::new(n);
            s.materials = vec![[0.5, 0.7, 0.3], [0.9, 0.2, 0.6]];
            // Run-time state for the group members and a random subset of the rest; the others (when there are
            // any) show a solved static base, and rows and receivers are by slot.
            let slots: Vec<usize> = (0..n).filter(|&i| stateful[i] || members.contains(&i)).collect();
            let slot_of = |i: usize| slots.iter().position(|&p| p == i);
            if slots.len() < n {
                s.base_solved = true;
                s.state = Some(slots.iter().map(|&p| p as u32).collect());
                s.rows = vec![Vec::new(); slots.len()];
            }
            for (i, (patch, &area)) in s.patches.iter_mut().zip(&areas).enumerate() {
                patch.area = area;
                patch.material = (i % 2) as u32;
                if slot_of(i).is_none() {
                    patch.base_emission = [0.3, 0.1, 0.2];
                    patch.base_irradiance = [0.2; 3];
                }
            }
            for (k, &i) in slots.iter().enumerate() {
                // Sparse: weights below 0.4 are dropped (and receivers without state); the rest scaled to the
                // row's sum.
                let kept: Vec<(u32, f32)> = weights[i]
                    .iter()
                    .enumerate()
                    .filter(|(_, &w)| w >= 0.4)
                    .filter_map(|(j, &w)| slot_of(j).map(|slot| (slot as u32, w)))
                    .collect();
                let total: f32 = kept.iter().map(|x| x.1).sum();
                s.rows[k] = kept.into_iter().map(|(j, w)| (j, w / total * sums[i] * 0.999)).collect();
            }
            s.groups = vec![
                (1, [1.0; 3], vec![MemberSpec { patch: members[0] as u32, emission: [1.0, 2.0, 0.5] }]),
                (
                    2,
                    [0.5; 3],
                    members.iter().map(|&p| MemberSpec { patch: p as u32, emission: [0.3; 3] }).collect(),
                ),
            ];
            s
        })
}

fn budget_and_warm_start<S: Arith>(scene: &Scene, ops: &[Op]) -> Result<(), TestCaseError> {
    let bytes = scene.write();
    let t = Table::parse(&bytes).unwrap();
    let n = t.patch_count() as usize;
    let mut store = Store::<S>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, config());
    let mut scratch = vec![[S::ZERO; 3]; n];
    let mut final_scene = scene.clone();
    for op in ops {
        let budget_check = |o: Outcome, b: u32| -> Result<(), TestCaseError> {
            prop_assert!(o.used() <= b, "budget {} exceeded: {:?}", b, o);
            Ok(())
        };
        match *op {
            Op::Shoot(b) => budget_check(solver.step(b), b)?,
            Op::GaussSeidel(b) => budget_check(solver.step_gauss_seidel(b), b)?,
            Op::Jacobi(b) => budget_check(solver.step_jacobi(&mut scratch, b), b)?,
            Op::Light(g, rgb) => {
                if solver.set_light(g, rgb).is_ok() {
                    final_scene.groups[g as usize].1 = rgb;
                }
            }
            Op::Reflectance(m, rgb) => {
                if solver.set_reflectance(m, rgb).is_ok() {
                    final_scene.materials[m as usize] = rgb;
                }
            }
        }
    }
    // Finish: a Jacobi sweep in progress first, then shooting.
    loop {
        match solver.step(1000) {
            Outcome::Converged { .. } => break,
            Outcome::BudgetSpent { .. } => {}
            Outcome::NoProgress { reason: NoProgressReason::JacobiInProgress, .. } => {
                let o = solver.step_jacobi(&mut scratch, 1000);
                prop_assert!(o.used() <= 1000);
            }
            other => prop_assert!(false, "{:?}", other),
        }
        prop_assert!(solver.shots() < 10_000_000);
    }
    let warm = radiosities(&solver, &t);
    let (cold, k) = cold::<S>(&final_scene);
    let area_min = scene.patches.iter().map(|p| p.area).fold(f32::INFINITY, f32::min);
    // rho_max 0.9 (materials and edits stay below 0.9).
    let shots = solver.shots().max(k);
    for (x, y) in warm.iter().zip(&cold) {
        for c in 0..3 {
            let tol = 2.0 * truncation(n, TOL, 0.9, area_min)
                + 2.0 * S::arith(y[c].max(x[c]), shots, 0.9, area_min);
            prop_assert!((x[c] - y[c]).abs() <= tol, "warm {} cold {} tol {}", x[c], y[c], tol);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn budget_never_exceeded_and_warm_start_matches_cold_f32(
        scene in random_scene(),
        ops in proptest::collection::vec(op(), 0..40),
    ) {
        budget_and_warm_start::<f32>(&scene, &ops)?;
    }

    #[test]
    fn budget_never_exceeded_and_warm_start_matches_cold_fixed(
        scene in random_scene(),
        ops in proptest::collection::vec(op(), 0..40),
    ) {
        budget_and_warm_start::<Fixed>(&scene, &ops)?;
    }
}
