//! Shooting's selection (block winners, see `Solver::step`) picks exactly the slot a full scan would pick: the
//! largest unshot magnitude `|r| + |g| + |b|`, ties to the lower slot. Checked against a naive shooter written
//! here with the same arithmetic (`Scalar` operations in the solver's order), so any difference in the shot
//! sequence shows up as a bit difference in the final powers or a different shot count.

mod common;

use common::{Scene, Store};
use proptest::prelude::*;
use radiosity_core::codec::decode_reflectance;
use radiosity_core::{Config, Frac, MemberSpec, Outcome, Scalar, Table};

const TOL: f32 = 1e-4;

/// Naive progressive refinement: a full scan for the shooter before every shot. Returns final power per slot
/// and shots, or `None` if it did not converge in `max_shots`.
fn naive(
    t: &Table<'_>,
    mut unshot: Vec<[f32; 3]>,
    mut power: Vec<[f32; 3]>,
    overshoot: u8,
) -> (Vec<[f32; 3]>, u32) {
    let s = t.state_count();
    let rho = |slot: u32| {
        let code = t.reflectance(t.slot_material(slot).unwrap()).unwrap();
        code.map(decode_reflectance)
    };
    let key = |u: [f32; 3]| u[0].abs().add(u[1].abs()).add(u[2].abs());
    let mut shots = 0;
    loop {
        let mut best = 0u32;
        for i in 1..s {
            if key(unshot[i as usize]) > key(unshot[best as usize]) {
                best = i;
            }
        }
        if s == 0 || key(unshot[best as usize]) <= TOL || shots > 100_000 {
            return (power, shots);
        }
        let u = unshot[best as usize];
        let extra = Frac { mantissa: u32::from(overshoot), shift: 8 };
        let p = u.map(|x| x.add(x.mul_frac(extra)));
        for c in 0..3 {
            unshot[best as usize][c] = unshot[best as usize][c].sub(p[c]);
        }
        shots += 1;
        for k in t.row(best).unwrap() {
            let (i, f) = t.entry(best, k).unwrap();
            let r = rho(i);
            for c in 0..3 {
                let received = p[c].mul_frac(f).mul_frac(r[c]);
                power[i as usize][c] = power[i as usize][c].add(received);
                unshot[i as usize][c] = unshot[i as usize][c].add(received);
            }
        }
    }
}

/// `n` patches, all with state; rows from `weights` (entries below `cut` dropped), scaled to `sums`; areas from
/// a few values (or all equal, `uniform`) so that equal keys (ties) occur; two light groups.
fn scene(
    n: usize,
    (areas, uniform): (&[u8], bool),
    weights: &[Vec<f32>],
    sums: &[f32],
    cut: f32,
    lights: &[usize],
) -> Scene {
    let mut s = Scene::new(n);
    s.materials = vec![[0.5, 0.7, 0.3], [0.9, 0.2, 0.6], [0.5, 0.5, 0.5]];
    for (i, p) in s.patches.iter_mut().enumerate() {
        if !uniform {
            p.area = [0.5, 1.0, 2.0][usize::from(areas[i] % 3)];
            p.material = (areas[i] / 3 % 3) as u32;
        }
    }
    for i in 0..n {
        let kept: Vec<(u32, f32)> =
            (0..n).filter(|&j| j != i && weights[i][j] >= cut).map(|j| (j as u32, weights[i][j])).collect();
        let total: f32 = kept.iter().map(|x| x.1).sum();
        s.rows[i] = kept.into_iter().map(|(j, w)| (j, w / total * sums[i])).collect();
    }
    s.groups = vec![
        (
            1,
            [1.0; 3],
            lights.iter().map(|&p| MemberSpec { patch: p as u32, emission: [1.0, 2.0, 0.5] }).collect(),
        ),
        (2, [0.25; 3], vec![MemberSpec { patch: lights[0] as u32, emission: [0.3; 3] }]),
    ];
    s
}

/// The selection's block size `B` for `n` slots: the smallest power of two with `B^2 >= n` (`Solver::step`).
fn block_size(n: usize) -> u32 {
    (0..).map(|k| 1u32 << k).find(|&b| (b as usize) * (b as usize) >= n).unwrap()
}

/// When to change the light: never, after a first solve, or after a step that builds only the first selection
/// block (the change must update the blocks already built and leave the others to the build).
#[derive(Clone, Copy, Debug)]
enum Relight {
    Never,
    Converged([f32; 3]),
    MidBuild([f32; 3]),
}

fn check(scene: &Scene, overshoot: u8, relight: Relight, budget: u32) -> Result<(), TestCaseError> {
    let bytes = scene.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<f32>::for_table(&t);
    let mut solver = common::solver(&mut store, &t, Config { tolerance: TOL, overshoot });
    // Solve once, then optionally change a light (negative and positive injections) and solve again: the
    // reference starts from the solver's state at that point.
    let converge = |solver: &mut radiosity_core::Solver<'_, f32>| -> Result<(), TestCaseError> {
        for _ in 0..1_000_000 {
            let o = solver.step(budget);
            prop_assert!(o.used() <= budget, "{o:?}");
            match o {
                Outcome::Converged { .. } => return Ok(()),
                Outcome::BudgetSpent { .. } => {}
                other => prop_assert!(false, "{other:?}"),
            }
        }
        prop_assert!(false, "no convergence");
        Ok(())
    };
    match relight {
        Relight::Never => {}
        Relight::Converged(rgb) => {
            converge(&mut solver)?;
            solver.set_light(0, rgb).unwrap();
        }
        Relight::MidBuild(rgb) => {
            // The first block is `B` slots (or all of them): a budget of exactly that builds it and stops.
            let first = block_size(t.state_count() as usize).min(t.state_count());
            prop_assert_eq!(solver.step(first).used(), first);
            solver.set_light(0, rgb).unwrap();
        }
    }
    let s = t.state_count();
    let unshot: Vec<[f32; 3]> = (0..s).map(|i| solver.unshot(i).unwrap()).collect();
    let power: Vec<[f32; 3]> = (0..s).map(|i| solver.power(i).unwrap()).collect();
    let shots_before = solver.shots();
    let (want, want_shots) = naive(&t, unshot, power, overshoot);
    converge(&mut solver)?;
    prop_assert_eq!(solver.shots() - shots_before, want_shots);
    for i in 0..s {
        prop_assert_eq!(solver.power(i).unwrap(), want[i as usize], "slot {}", i);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn shooting_selects_the_largest_unshot_power(
        (n, areas, weights, sums, cut, lights) in (1usize..40).prop_flat_map(|n| (
            Just(n),
            (proptest::collection::vec(any::<u8>(), n), any::<bool>()),
            proptest::collection::vec(proptest::collection::vec(0.01f32..1.0, n), n),
            proptest::collection::vec(0.3f32..0.95, n),
            0.0f32..0.9,
            proptest::collection::vec(0usize..n, 1..4),
        )),
        overshoot in prop_oneof![Just(0u8), Just(64), Just(200)],
        relight in prop_oneof![
            Just(Relight::Never),
            prop_oneof![Just([0.0f32, 0.0, 0.0]), Just([3.0, 0.1, 1.0])].prop_map(Relight::Converged),
            prop_oneof![Just([0.0f32, 0.0, 0.0]), Just([3.0, 0.1, 1.0])].prop_map(Relight::MidBuild),
        ],
        budget in prop_oneof![Just(None), (0u32..48).prop_map(Some)],
    ) {
        // The smallest budget that always progresses: an entry and its block's rescan, 1 + B.
        let block = block_size(n);
        let budget = budget.map_or(u32::MAX, |extra| block + 1 + extra);
        check(&scene(n, (&areas.0, areas.1), &weights, &sums, cut, &lights), overshoot, relight, budget)?;
    }
}
