//! Work units to converge with shooting, shooting with overshoot, Gauss-Seidel and Jacobi on the same table,
//! on both arithmetic paths, with the error against a tight reference solve; then the work of warm starts
//! after relighting against cold solves.
//!
//! Run: `cargo run --release -p radiosity-core --example methods` (prints the tables and writes them to
//! `core/examples/methods.md`).
//!
//! Scene: the closed cube of `common` (6 x 6 patches per face here), rho 0.8, one light patch, FLOAT16 table.
//! Tolerance: unshot magnitude `<= 1e-6` of the emitted power per patch.

mod common;

use common::{rel_l2, Cube, Report};
use radiosity_core::{
    BufferSizes, Config, FfCodec, Fixed, GroupSpec, MemberSpec, Outcome, OwnedBuffers, PatchSpec, Scalar,
    Solver, Table,
};

const K: usize = 6;
const RHO: f32 = 0.8;

fn table_bytes(as_group: bool) -> (Vec<u8>, usize) {
    let cube = Cube::new(K);
    let (n, area) = (cube.n, cube.area);
    let light = cube.light(K);
    let patches: Vec<PatchSpec> = (0..n)
        .map(|i| PatchSpec {
            area,
            material: 0,
            base_emission: if i == light && !as_group { [1.0; 3] } else { [0.0; 3] },
            base_irradiance: [0.0; 3],
        })
        .collect();
    let members = [MemberSpec { patch: light as u32, emission: [1.0; 3] }];
    let groups = [GroupSpec { id: 1, default_intensity: [1.0; 3], members: &members }];
    let bytes = cube.table(&patches, RHO, if as_group { &groups } else { &[] }, FfCodec::FLOAT16);
    (bytes, n)
}

#[derive(Clone, Copy)]
enum Method {
    Shoot(u8),
    GaussSeidel,
    Jacobi,
}

/// Solves to `tolerance`, raised to the arithmetic's convergence floor where that is higher (the solver refuses
/// tolerances below it); returns units, rows shot, radiosities and the tolerance used.
fn solve<S: Scalar>(t: &Table<'_>, method: Method, tolerance: f32) -> (u64, u32, Vec<f32>, f32) {
    let tolerance = tolerance.max(radiosity_core::convergence_floor::<S>(t).to_f32());
    let sizes = BufferSizes::of(t);
    let mut store = OwnedBuffers::<S>::new(sizes);
    let mut scratch = vec![[S::ZERO; 3]; sizes.slots];
    let buffers = store.buffers();
    let overshoot = if let Method::Shoot(o) = method { o } else { 0 };
    let mut s = Solver::new(t, buffers, Config { tolerance: S::from_f32(tolerance), overshoot }).unwrap();
    let mut units = 0u64;
    loop {
        let o = match method {
            Method::Shoot(_) => s.step(10_000),
            Method::GaussSeidel => s.step_gauss_seidel(10_000),
            Method::Jacobi => s.step_jacobi(&mut scratch, 10_000),
        };
        units += u64::from(o.used());
        match o {
            Outcome::Converged { .. } => break,
            Outcome::BudgetSpent { .. } => {}
            other => panic!("{other:?}"),
        }
    }
    let b = (0..t.patch_count()).map(|i| s.radiosity(i).unwrap()[0].to_f32()).collect();
    (units, s.shots(), b, tolerance)
}

fn main() {
    let (bytes, n) = table_bytes(false);
    let t = Table::parse(&bytes).unwrap();
    let emitted = 1.0 / (K * K) as f32;
    let (_, _, reference, _) = solve::<f32>(&t, Method::GaussSeidel, emitted * 1e-9);
    let mut report = Report::new(
        "methods",
        &format!(
            "Solver cost and arithmetic error on a closed cube of {K} x {K} patches per face ({n} patches, {} \
             entries, rho {RHO}, one light, FLOAT16), tolerance `1e-6` of the emitted power, raised for fixed \
             point to its convergence floor; error: relative L2 of `B` against a solve to `1e-9`.",
            t.entry_count()
        ),
    );
    report.line("| method | path | tolerance / emitted | work units | rows shot | rel. L2 error |");
    report.line("|---|---|---|---|---|---|");
    for (name, m) in [
        ("shooting", Method::Shoot(0)),
        ("shooting, overshoot 1.25", Method::Shoot(64)),
        ("Gauss-Seidel", Method::GaussSeidel),
        ("Jacobi", Method::Jacobi),
    ] {
        let runs =
            [("f32", solve::<f32>(&t, m, emitted * 1e-6)), ("fixed", solve::<Fixed>(&t, m, emitted * 1e-6))];
        for (path, (units, shots, b, tol)) in runs {
            let (tol, error) = (tol / emitted, rel_l2(&b, &reference));
            report.line(&format!("| {name} | {path} | {tol:.1e} | {units} | {shots} | {error:.2e} |"));
        }
    }
    relight_cost(&mut report);
    report.write();
}

fn run_to_convergence(s: &mut Solver<'_, f32>) -> u64 {
    let mut units = 0u64;
    loop {
        let o = s.step(10_000);
        units += u64::from(o.used());
        if !matches!(o, Outcome::BudgetSpent { .. }) {
            return units;
        }
    }
}

/// Warm start against cold solve: the same cube with the light as a light group, relit after convergence.
fn relight_cost(report: &mut Report) {
    let (bytes, _) = table_bytes(true);
    let t = Table::parse(&bytes).unwrap();
    let mut store = OwnedBuffers::<f32>::for_table(&t);
    let buffers = store.buffers();
    let tolerance = 1e-6 / (K * K) as f32;
    let mut s = Solver::new(&t, buffers, Config { tolerance, overshoot: 0 }).unwrap();
    report.line("");
    report.line(
        "Warm starts: the same cube with the light as a light group, shooting, f32, relit after convergence.",
    );
    report.line("");
    report.line("| shooting, f32, light group relit after convergence | work units |");
    report.line("|---|---|");
    report.line(&format!("| cold solve, intensity 1 | {} |", run_to_convergence(&mut s)));
    for rgb in [[0.9f32, 0.9, 0.9], [0.0; 3], [1.0, 0.2, 0.2]] {
        let extra = s.set_light(0, rgb).unwrap();
        let units = run_to_convergence(&mut s);
        report.line(&format!("| relight to {rgb:?} (set_light: {extra} units) | {units} |"));
    }
    s.restart();
    report.line(&format!("| cold solve (restart) at [1.0, 0.2, 0.2] | {} |", run_to_convergence(&mut s)));
}
