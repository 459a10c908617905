//! Work units to converge with shooting, shooting with overshoot, Gauss-Seidel and Jacobi on the same table,
//! on both arithmetic paths, with the error against a tight reference solve; then the work of warm starts
//! after relighting against cold solves.
//!
//! Run: `cargo run --release -p radiosity-core --example methods`
//!
//! Scene: the closed cube of the `codec_error` example (6 x 6 x 6 patches here, point-to-point form factors
//! scaled to closed rows), rho 0.8, one light patch, FLOAT16 table. Tolerance: unshot magnitude
//! `<= 1e-6` of the emitted power per patch.

use radiosity_core::{
    write_table, BufferSizes, Config, FfCodec, Fixed, GroupSpec, MemberSpec, Outcome, OwnedBuffers,
    PatchSpec, RowsSpec, Scalar, Solver, Table, TableSpec,
};

const K: usize = 6;
const RHO: f32 = 0.8;

fn table_bytes(as_group: bool) -> (Vec<u8>, usize) {
    let h = 1.0 / K as f32;
    let mut centre = Vec::new();
    let mut normal = Vec::new();
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            for a in 0..K {
                for b in 0..K {
                    let mut c = [0.0; 3];
                    c[axis] = side;
                    c[(axis + 1) % 3] = (a as f32 + 0.5) * h;
                    c[(axis + 2) % 3] = (b as f32 + 0.5) * h;
                    let mut nrm = [0.0; 3];
                    nrm[axis] = if side == 0.0 { 1.0 } else { -1.0 };
                    centre.push(c);
                    normal.push(nrm);
                }
            }
        }
    }
    let n = centre.len();
    let area = h * h;
    let (mut row_start, mut receiver, mut value) = (vec![0u32], Vec::new(), Vec::new());
    for i in 0..n {
        let mut row = Vec::new();
        for j in 0..n {
            let d = [0, 1, 2].map(|k| centre[j][k] - centre[i][k]);
            let r2: f32 = d.iter().map(|x| x * x).sum();
            let ci: f32 = (0..3).map(|k| normal[i][k] * d[k]).sum::<f32>() / r2.sqrt();
            let cj: f32 = -(0..3).map(|k| normal[j][k] * d[k]).sum::<f32>() / r2.sqrt();
            if i != j && ci > 0.0 && cj > 0.0 {
                row.push((j as u32, ci * cj * area / (std::f32::consts::PI * r2)));
            }
        }
        let s: f32 = row.iter().map(|x| x.1).sum();
        for (j, f) in row {
            receiver.push(j);
            value.push(f / s * (1.0 - 1e-6));
        }
        row_start.push(receiver.len() as u32);
    }
    let light = n - K * K / 2 - K / 2;
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
    let spec = TableSpec {
        patches: &patches,
        materials: &[[RHO; 3]],
        groups: if as_group { &groups } else { &[] },
        rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &value },
        codec: FfCodec::FLOAT16,
        base_solved: false,
        fingerprint: 0,
        transfer: None,
        state: None,
    };
    let mut bytes = vec![0u8; radiosity_core::required_len(&spec).unwrap()];
    write_table(&spec, &mut bytes).unwrap();
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
    println!(
        "cube {K}x{K} per face: {n} patches, {} entries, rho {RHO}, tolerance 1e-6 x emitted power",
        t.entry_count()
    );
    println!(
        "| method | path | tolerance / emitted | work units | rows shot | rel. L2 error vs tight solve |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, m) in [
        ("shooting", Method::Shoot(0)),
        ("shooting, overshoot 1.25", Method::Shoot(64)),
        ("Gauss-Seidel", Method::GaussSeidel),
        ("Jacobi", Method::Jacobi),
    ] {
        for path in ["f32", "fixed"] {
            let (units, shots, b, tol) = if path == "f32" {
                solve::<f32>(&t, m, emitted * 1e-6)
            } else {
                solve::<Fixed>(&t, m, emitted * 1e-6)
            };
            let (mut num, mut den) = (0.0f32, 0.0f32);
            for (x, r) in b.iter().zip(&reference) {
                num += (x - r) * (x - r);
                den += r * r;
            }
            let tol = tol / emitted;
            println!("| {name} | {path} | {tol:.1e} | {units} | {shots} | {:.2e} |", (num / den).sqrt());
        }
    }
    relight_cost();
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
fn relight_cost() {
    let (bytes, _) = table_bytes(true);
    let t = Table::parse(&bytes).unwrap();
    let mut store = OwnedBuffers::<f32>::for_table(&t);
    let buffers = store.buffers();
    let tolerance = 1e-6 / (K * K) as f32;
    let mut s = Solver::new(&t, buffers, Config { tolerance, overshoot: 0 }).unwrap();
    println!();
    println!("| shooting, f32, light group relit after convergence | work units |");
    println!("|---|---|");
    println!("| cold solve, intensity 1 | {} |", run_to_convergence(&mut s));
    for rgb in [[0.9f32, 0.9, 0.9], [0.0; 3], [1.0, 0.2, 0.2]] {
        let extra = s.set_light(0, rgb).unwrap();
        println!("| relight to {rgb:?} (set_light: {extra} units) | {} |", run_to_convergence(&mut s));
    }
    s.restart();
    println!("| cold solve (restart) at [1.0, 0.2, 0.2] | {} |", run_to_convergence(&mut s));
}
