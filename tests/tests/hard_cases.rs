//! Hard cases (issue 5, item 3) on the device path: a white furnace up to rho = 0.999, lights switched off and
//! on again, and damaged tables. Tables are written with core's writer from analytic form factors, so every
//! expected value is exact and every tolerance comes from the codecs' stated bounds (core's crate docs).

use radiosity_core::{
    required_len, write_table, Config, FfCodec, Fixed, GroupSpec, MemberSpec, Outcome, OwnedBuffers,
    PatchSpec, RowsSpec, Scalar, Solver, Table, TableError, TableSpec, FORMAT_VERSION, HIER_FORMAT_VERSION,
};

/// An analytic closed enclosure: `n` patches of equal area on a sphere, where `F_ij = A_j / A_total = 1/n` for
/// every pair, self included (Siegel and Howell, Thermal Radiation Heat Transfer, sphere-interior factors).
/// Every patch emits `e` (patches `0..half` as a dynamic light group `g`, the rest static with `e`) and reflects
/// `rho`. With `1/n` a power of two every form factor is exact in FLOAT16.
fn furnace_table(n: usize, rho: f32, e: f32, group: bool) -> Vec<u8> {
    let lit = if group { n / 2 } else { 0 };
    let patches: Vec<PatchSpec> = (0..n)
        .map(|i| PatchSpec {
            area: 1.0,
            material: 0,
            base_emission: if i < lit { [0.0; 3] } else { [e; 3] },
            base_irradiance: [0.0; 3],
        })
        .collect();
    let members: Vec<MemberSpec> =
        (0..lit).map(|i| MemberSpec { patch: i as u32, emission: [e; 3] }).collect();
    let groups = [GroupSpec { id: 7, default_intensity: [1.0; 3], members: &members }];
    let row_start: Vec<u32> = (0..=n).map(|i| (i * n) as u32).collect();
    let receiver: Vec<u32> = (0..n * n).map(|k| (k % n) as u32).collect();
    let form_factor = vec![1.0 / n as f32; n * n];
    let spec = TableSpec {
        patches: &patches,
        materials: &[[rho; 3]],
        groups: if group { &groups } else { &[] },
        rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec: FfCodec::FLOAT16,
        base_solved: false,
        fingerprint: 0,
        transfer: None,
        state: None,
    };
    let mut blob = vec![0u8; required_len(&spec).expect("furnace spec is valid")];
    let written = write_table(&spec, &mut blob).expect("furnace table writes");
    blob.truncate(written);
    blob
}

/// Converged radiosity of every patch and the work spent, from a cold start on arithmetic `S`.
fn solve_cold<S: Scalar>(table: &Table<'_>, tolerance: f32, changes: &[[f32; 3]]) -> (Vec<[f64; 3]>, u64) {
    let mut store = OwnedBuffers::<S>::for_table(table);
    let buffers = store.buffers();
    let config = Config { tolerance: S::from_f32(tolerance), overshoot: 0 };
    let mut solver = Solver::new(table, buffers, config).expect("buffers fit");
    let mut work = 0u64;
    let mut run = |solver: &mut Solver<'_, S>| loop {
        let o = solver.step(100_000);
        work += u64::from(o.used());
        match o {
            Outcome::BudgetSpent { .. } => {}
            Outcome::Converged { .. } => break,
            Outcome::NoProgress { reason, .. } => panic!("no progress: {reason:?}"),
        }
    };
    run(&mut solver);
    for &c in changes {
        solver.set_light(0, c).expect("group 0 exists");
        run(&mut solver);
    }
    let b = (0..table.patch_count())
        .map(|k| solver.radiosity(k).expect("patch in range").map(|v| f64::from(v.to_f32())))
        .collect();
    (b, work)
}

/// White furnace: `B = E / (1 - rho)` on both arithmetic paths.
///
/// Tolerance, relative, from the stated bounds: reflectance code absolute error `2^-17` moves `1/(1-rho)` by
/// `2^-17 / (1 - rho)` relative; emission code `2^-11` relative; form factors `1/16` exact; the stopping rule
/// leaves at most `n * tol / ((1 - rho) A)` per patch with `tol = 1e-7 * n e` power units, i.e. `n^2 1e-7 / (1 -
/// rho)` relative to `e`, which is `n^2 1e-7` of B; plus arithmetic: f32 accumulates each patch's power in about
/// `k = shots` additions (relative `k * 2^-24` worst case), fixed point one unit `2^-32` per receipt (negligible
/// at powers of `e = 100`). The test asserts the derived bound and the goal (0.5% at 0.99, 2% at 0.999).
#[test]
fn white_furnace_device_paths() {
    let n = 16usize;
    let e = 100.0f32;
    for rho in [0.5f32, 0.9, 0.99, 0.999] {
        let blob = furnace_table(n, rho, e, false);
        let table = Table::parse(&blob).expect("furnace table parses");
        let exact = f64::from(e) / (1.0 - f64::from(rho));
        let tol = 1e-7 * n as f32 * e;
        for (name, (b, work)) in
            [("f32", solve_cold::<f32>(&table, tol, &[])), ("fixed", solve_cold::<Fixed>(&table, tol, &[]))]
        {
            let shots = work as f64 / n as f64; // upper bound on shots (each costs more than n units)
            let bound = 2f64.powi(-17) / (1.0 - f64::from(rho))
                + 2f64.powi(-11)
                + (n * n) as f64 * 1e-7
                + if name == "f32" { shots * 2f64.powi(-24) } else { shots * 2f64.powi(-32) / f64::from(e) };
            let goal = if rho >= 0.999 {
                0.02
            } else if rho >= 0.99 {
                0.005
            } else {
                1.0
            };
            let worst =
                b.iter().flat_map(|v| v.iter()).map(|&v| (v - exact).abs() / exact).fold(0.0, f64::max);
            println!(
                "furnace rho {rho} {name}: work {work} units, max rel error {worst:.3e}, bound {bound:.3e}"
            );
            assert!(worst <= bound, "rho {rho} {name}: rel error {worst:.3e} > derived bound {bound:.3e}");
            assert!(worst <= goal, "rho {rho} {name}: rel error {worst:.3e} misses the goal {goal}");
        }
    }
}

/// Lights dimmed to zero, off and on again, then to a colour: the warm-started answer equals a cold solve of
/// the final setting within twice the stopping error (each side is within `n^2 1e-7` relative, see above).
#[test]
fn light_off_and_on_equals_cold_solve() {
    let n = 16usize;
    let blob = furnace_table(n, 0.9, 100.0, true);
    let table = Table::parse(&blob).expect("table parses");
    let tol = 1e-7 * n as f32 * 100.0;
    let bound = 2.0 * (n * n) as f64 * 1e-7 / (1.0 - 0.9) + 2.0 * 2f64.powi(-24) * 1e4;
    for (name, warm, cold) in [
        (
            "f32",
            solve_cold::<f32>(&table, tol, &[[0.0; 3], [0.0; 3], [1.0; 3], [1.0, 0.2, 0.2]]).0,
            solve_cold::<f32>(&table, tol, &[[1.0, 0.2, 0.2]]).0,
        ),
        (
            "fixed",
            solve_cold::<Fixed>(&table, tol, &[[0.0; 3], [0.0; 3], [1.0; 3], [1.0, 0.2, 0.2]]).0,
            solve_cold::<Fixed>(&table, tol, &[[1.0, 0.2, 0.2]]).0,
        ),
    ] {
        for (w, c) in warm.iter().zip(&cold) {
            for ch in 0..3 {
                let rel = (w[ch] - c[ch]).abs() / c[ch].abs();
                assert!(
                    rel <= bound,
                    "{name}: warm {} vs cold {} (rel {rel:.3e} > {bound:.3e})",
                    w[ch],
                    c[ch]
                );
            }
        }
    }
}

/// Damaged tables: every kind gets its own error, never a panic.
#[test]
fn corrupted_truncated_wrong_version_tables_are_clear_errors() {
    let blob = furnace_table(16, 0.5, 1.0, true);
    assert!(Table::parse(&blob).is_ok());
    // A flipped payload byte: the CRC catches it.
    let mut flipped = blob.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    assert!(
        matches!(Table::parse(&flipped), Err(TableError::CrcMismatch { .. })),
        "{:?}",
        Table::parse(&flipped).err()
    );
    // Truncated anywhere: never Ok, never a panic; past the header it says how many bytes are missing.
    for len in 0..blob.len() {
        assert!(Table::parse(&blob[..len]).is_err(), "truncated to {len} parsed");
    }
    assert!(matches!(Table::parse(&blob[..blob.len() - 1]), Err(TableError::Truncated { .. })));
    // Wrong version: the version is the varint after the 4-byte magic (1 byte while < 128).
    // The flat layout is FORMAT_VERSION, the hierarchical one HIER_FORMAT_VERSION (read by HierTable::parse).
    const { assert!(FORMAT_VERSION < 127 && HIER_FORMAT_VERSION < 126) };
    let mut old = blob.clone();
    old[4] = (FORMAT_VERSION.max(HIER_FORMAT_VERSION) + 1) as u8;
    match Table::parse(&old) {
        Err(TableError::UnsupportedVersion { .. }) => {}
        other => panic!("expected UnsupportedVersion, got {other:?}"),
    }
    old[4] = HIER_FORMAT_VERSION as u8;
    assert_eq!(Table::parse(&old).err(), Some(TableError::HierarchicalTable));
    // Wrong magic.
    let mut magic = blob.clone();
    magic[0] = b'X';
    assert!(matches!(Table::parse(&magic), Err(TableError::BadMagic { .. })));
    // Trailing bytes.
    let mut long = blob.clone();
    long.push(0);
    assert!(matches!(Table::parse(&long), Err(TableError::TrailingBytes { .. })));
}
