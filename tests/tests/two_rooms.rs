//! Run-time state only where a dynamic light reaches (`scenes/two-rooms.obj`): room A is lit by the dynamic
//! light group `lamp`, room B, which room A cannot see, by the static light `fixture`. The bake gives run-time
//! state to room A's patches only; core's f32 solve of every patch (room B's from the static base) matches the
//! f64 reference within bounds derived from the codecs' stated errors (core's crate docs, "Error bounds").

use std::path::PathBuf;

use radiosity_core::{Config, Outcome, OwnedBuffers, Solver, Table};
use radiosity_host::bake::{bake, decode_table, shooting_form, BakeInput, BakeOptions};
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::reference::{DenseLu, RadiositySystem};
use radiosity_host::rgb::max_channel;

/// Faces `0..ROOM_A_FACES` of the OBJ are room A (floor, four walls, four ceiling strips, the lamp panel).
const ROOM_A_FACES: usize = 10;

#[test]
fn only_the_dynamically_lit_room_carries_state() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/two-rooms.obj");
    let options = PrepareOptions::quiet(false, 4, 4);
    let p = prepare(&path, &options).expect("prepare two-rooms");
    let n = p.patches.len();
    let room_a = p.patches.iter().filter(|q| q.face < ROOM_A_FACES).count();
    let baked = bake(
        &BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors),
        &BakeOptions::default(),
    )
    .expect("bake");
    let table = Table::parse(&baked.table).expect("parse");

    // State: exactly room A's patches (all of them reflect, so nothing is dropped), fewer than all.
    println!("{n} patches, {room_a} in room A, state count {}", table.state_count());
    assert_eq!(table.patch_count() as usize, n);
    assert_eq!(table.state_count() as usize, room_a);
    assert!(room_a < n);
    assert_eq!(baked.report.runtime_state.reachable, room_a);
    assert_eq!(baked.report.runtime_state.entries_to_stateless, 0);
    for (i, q) in p.patches.iter().enumerate() {
        assert_eq!(table.slot_of(i as u32).is_some(), q.face < ROOM_A_FACES, "patch {i} (face {})", q.face);
    }
    assert_eq!(baked.capacities.buffers.slots, room_a);

    // The f64 reference: the shooting form of the sparsified matrix the table was quantized from, all lights
    // at their default intensities.
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let shoot = shooting_form(&baked.sparse.matrix, &area);
    let system = RadiositySystem::new(&p.lighting.rho, &shoot).expect("system");
    let b_ref =
        DenseLu::factor(system).expect("factor").solve(&p.lighting.default_emission()).expect("solve").b;

    // Core's f32 solve, buffers of the baked capacities (room A only).
    let lamp_power: f64 = (0..n).map(|i| p.lighting.unit_emission[i][0] * area[i]).sum();
    let tolerance = 1e-7 * lamp_power;
    let mut store = OwnedBuffers::<f32>::new(baked.capacities.buffers);
    let buffers = store.buffers();
    let mut solver =
        Solver::new(&table, buffers, Config { tolerance: tolerance as f32, overshoot: 0 }).expect("solver");
    while let Outcome::BudgetSpent { .. } = solver.step(1_000_000) {}
    assert!(matches!(solver.step(1_000_000), Outcome::Converged { .. }));
    let shots = f64::from(solver.shots());

    // Room A (state): with every form factor within 2^-12 of its value (FLOAT16 entries >= row max / 2^14,
    // checked below), emissions within 2^-11, reflectances within 2^-17, the perturbation of `(I - R F) B = E`
    // is at most `2^-11 E_max + (2^-12 + 2^-17) B_max` per patch (rho F B <= B), amplified by at most
    // `1 / (1 - rho_max)` (row sums <= 1); plus the stopping rule, `s tol / ((1 - rho_max) A_min)` for `s`
    // patches with state, and f32 accumulation, `3/2 eps_32 (shots + 1 / (1 - rho_max))` of B_max (the
    // arithmetic term of core's solver tests).
    let in_a = |i: usize| p.patches[i].face < ROOM_A_FACES;
    let max_over = |f: &dyn Fn(usize) -> f64| (0..n).filter(|&i| in_a(i)).map(f).fold(0.0, f64::max);
    let rho_max = max_over(&|i| max_channel(p.lighting.rho[i]));
    let e_max = max_over(&|i| max_channel(p.lighting.unit_emission[i]));
    let b_max = max_over(&|i| max_channel(b_ref[i]));
    let a_min = max_over(&|i| 1.0 / area[i]).recip();
    let eps32 = f64::from(f32::EPSILON);
    let bound_a = (2f64.powi(-11) * e_max + (2f64.powi(-12) + 2f64.powi(-17)) * b_max) / (1.0 - rho_max)
        + room_a as f64 * tolerance / ((1.0 - rho_max) * a_min)
        + 1.5 * eps32 * (shots + 1.0 / (1.0 - rho_max)) * b_max;
    for slot in 0..table.state_count() {
        let row = table.row(slot).expect("row");
        let row_max =
            row.clone().filter_map(|k| table.entry(slot, k)).map(|(_, f)| f.to_f32()).fold(0.0, f32::max);
        for k in row {
            let (_, f) = table.entry(slot, k).expect("entry");
            assert!(f.to_f32() >= row_max / 16384.0, "slot {slot}: entry below row max / 2^14");
        }
    }

    let (mut worst_a, mut worst_b) = (0.0f64, 0.0f64);
    for i in 0..n {
        let b = solver.radiosity(i as u32).expect("every patch has a radiosity");
        for c in 0..3 {
            let err = (f64::from(b[c]) - b_ref[i][c]).abs();
            let bound = if in_a(i) {
                worst_a = worst_a.max(err / bound_a);
                bound_a
            } else {
                // Room B (no state): the static base `E_s + rho G_s` from codes, `G_s = sum_j F~_ij B_j` on the
                // same matrix: emission and irradiance codes within 2^-11, reflectance within 2^-17, and a few f32
                // roundings (two products and a sum: 4 eps_32 of B).
                let g: f64 = shoot.row(i).map(|(j, f)| f * b_ref[j][c]).sum();
                let (es, rho) = (p.lighting.static_emission[i][c], p.lighting.rho[i][c]);
                let bound = 2f64.powi(-11) * es
                    + (2f64.powi(-11) * rho + 2f64.powi(-17)) * g
                    + 4.0 * eps32 * b_ref[i][c];
                worst_b = worst_b.max(err / bound);
                bound
            };
            assert!(
                err <= bound,
                "patch {i} (face {}) channel {c}: f32 {} vs f64 {}: {err:.3e} > {bound:.3e}",
                p.patches[i].face,
                b[c],
                b_ref[i][c]
            );
        }
        // Room B is lit (by the static light) and room A only by the lamp: both rooms show their light.
        assert!(b_ref[i][0] > 0.0, "patch {i} unlit");
    }
    // Against the f64 solve of the decoded table itself (what the device converges to: room B's decoded base,
    // room A's response to the lamp on the decoded rows) only the stopping rule and f32 accumulation remain.
    let dec = decode_table(&table);
    let dec_shoot = shooting_form(&dec.rows, &dec.area);
    let dec_system =
        RadiositySystem::with_row_sum_tolerance(&dec.rho, &dec_shoot, 1e-3).expect("decoded system");
    let b_dec = dec.solution(DenseLu::factor(dec_system).expect("factor").solve(&dec.rhs).expect("solve").b);
    let bound_arith = room_a as f64 * tolerance / ((1.0 - rho_max) * a_min)
        + 1.5 * eps32 * (shots + 1.0 / (1.0 - rho_max)) * b_max;
    let mut worst_dec = 0.0f64;
    for (i, want) in b_dec.iter().enumerate() {
        let b = solver.radiosity(i as u32).expect("radiosity");
        for c in 0..3 {
            let err = (f64::from(b[c]) - want[c]).abs();
            worst_dec = worst_dec.max(err / bound_arith);
            assert!(err <= bound_arith, "patch {i} channel {c}: f32 {} vs decoded f64 {}", b[c], want[c]);
        }
    }
    println!("vs the decoded table: bound {bound_arith:.3e}, worst error {worst_dec:.3} of it");
    println!(
        "room A bound {bound_a:.3e} (B_max {b_max:.3e}, {shots} shots): worst error {worst_a:.3} of it; \
         room B: worst error {worst_b:.3} of its per-patch bound"
    );
}
