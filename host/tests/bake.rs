//! Tests of baking, inspecting and firmware capacities, on form-factor matrices built directly (a furnace with
//! analytic form factors, random reciprocal open scenes).
//!
//! Error bounds used below, from core's crate docs ("Error bounds"):
//! - FLOAT16 form factors: relative error `< 2^-12` for entries `>= row max / 2^14` (so for every entry of a
//!   uniform row), rounding never up, so a decoded row sum is `>= (1 - 2^-12)` times the true one;
//! - reflectance: absolute error `<= 2^-17`; emission and irradiance codes: relative `<= 2^-11`;
//! - shooting converged at tolerance `tau` (power units): per-patch error `<= n tau / ((1 - rho_max) A_min)`;
//! - f32 arithmetic: each of the `k` additions into a patch's power rounds by at most `eps_32 / 2` relative to
//!   the running value (`<= B A`), so at most `k eps_32 / 2` relative, `k` = shots until convergence.

// Dense matrices and RGB channels read clearer with index loops (`w[i][j]`, `g[c]`).
#![allow(clippy::needless_range_loop)]

use glam::DVec3;
use radiosity_core::{Buffers, Config, FfCodec, Outcome, Solver, SolverError, Table};
use radiosity_host::bake::{
    bake, codec_for_bits, group_id, reachable_patches, sparsify, BakeError, BakeInput, BakeOptions, Baked,
};
use radiosity_host::inspect::{inspect, inspect_file, InspectError};
use radiosity_host::lighting::PatchLighting;
use radiosity_host::patch::{FormFactorMatrix, Patch};
use radiosity_host::rng::SplitMix64;

const EPS32: f64 = f32::EPSILON as f64;

/// A square patch of side `sqrt(area)` in the z = 0 plane (only area and material matter to a bake).
fn patch(k: usize, area: f64, material: usize) -> Patch {
    let s = area.sqrt();
    let o = DVec3::new(k as f64 * 2.0 * s, 0.0, 0.0);
    let vertices = vec![o, o + DVec3::X * s, o + DVec3::new(s, s, 0.0), o + DVec3::Y * s];
    Patch { face: k, material, vertices, normal: DVec3::Z, area, centroid: o + DVec3::new(s, s, 0.0) / 2.0 }
}

fn dense_to_csr(rows: &[Vec<f64>]) -> FormFactorMatrix {
    FormFactorMatrix::from_dense(rows).unwrap()
}

/// A scene: patches, per-material reflectance, lighting and group names, and its form factors.
struct TestScene {
    patches: Vec<Patch>,
    materials: Vec<[f64; 3]>,
    lighting: PatchLighting,
    names: Vec<String>,
    ff: FormFactorMatrix,
}

impl TestScene {
    fn input(&self) -> BakeInput<'_> {
        BakeInput {
            patches: &self.patches,
            materials: self.materials.clone(),
            lighting: &self.lighting,
            group_names: self.names.clone(),
            form_factors: &self.ff,
        }
    }

    fn bake(&self, threshold: f64, codec: FfCodec) -> Baked {
        let options = BakeOptions { threshold, codec, ..BakeOptions::default() };
        bake(&self.input(), &options).expect("bake")
    }
}

/// Lighting with no emission; patches take their material's reflectance.
fn dark_lighting(patches: &[Patch], materials: &[[f64; 3]], groups: usize) -> PatchLighting {
    let n = patches.len();
    PatchLighting {
        rho: patches.iter().map(|p| materials[p.material]).collect(),
        static_emission: vec![[0.0; 3]; n],
        unit_emission: vec![[0.0; 3]; n],
        group: vec![None; n],
        dynamic_groups: (0..groups).collect(),
        default_intensity: vec![[1.0; 3]; groups],
    }
}

/// The white furnace: `n` equal patches of area 1 in a closed box where every patch sees every other one
/// equally, `F_ij = 1 / (n - 1)` for `j != i` (rows sum to 1, reciprocal). Every patch emits `e` in one dynamic
/// light group at default intensity 1, reflectance `rho`. Exact answer `B = e / (1 - rho)`.
fn furnace(n: usize, rho: f64, e: f64) -> TestScene {
    let patches: Vec<Patch> = (0..n).map(|k| patch(k, 1.0, 0)).collect();
    let materials = vec![[rho; 3]];
    let f = 1.0 / (n - 1) as f64;
    let rows: Vec<Vec<f64>> =
        (0..n).map(|i| (0..n).map(|j| if i == j { 0.0 } else { f }).collect()).collect();
    let mut lighting = dark_lighting(&patches, &materials, 1);
    lighting.unit_emission = vec![[e; 3]; n];
    lighting.group = vec![Some(0); n];
    TestScene { patches, materials, lighting, names: vec!["sky".into()], ff: dense_to_csr(&rows) }
}

/// A random open, exactly reciprocal scene: areas in `[0.5, 2)`, symmetric couplings `w_ij` with probability
/// `density`, `F_ij = w_ij / A_i` scaled so the largest row sum is 0.9 (so `A_i F_ij = A_j F_ji`).
fn random_scene(seed: u64, n: usize, density: f64) -> TestScene {
    let mut rng = SplitMix64::new(seed);
    let materials: Vec<[f64; 3]> =
        (0..4).map(|_| [0.2 + 0.6 * rng.unit(), 0.2 + 0.6 * rng.unit(), 0.2 + 0.6 * rng.unit()]).collect();
    let area: Vec<f64> = (0..n).map(|_| 0.5 + 1.5 * rng.unit()).collect();
    let mut w = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            if rng.unit() < density {
                // Spread over three decades so sparsification has small entries to drop.
                let v = 10f64.powf(-3.0 * rng.unit());
                w[i][j] = v;
                w[j][i] = v;
            }
        }
    }
    let max_sum = (0..n).map(|i| w[i].iter().sum::<f64>() / area[i]).fold(0.0, f64::max);
    let scale = 0.9 / max_sum;
    let rows: Vec<Vec<f64>> = (0..n).map(|i| w[i].iter().map(|x| x * scale / area[i]).collect()).collect();
    let patches: Vec<Patch> = (0..n).map(|k| patch(k, area[k], k % materials.len())).collect();
    let lighting = dark_lighting(&patches, &materials, 0);
    TestScene { patches, materials, lighting, names: Vec::new(), ff: dense_to_csr(&rows) }
}

/// `random_scene` with patch 0 a static light, patches 1 and 2 dynamic group `lamp`, patch 3 group `sun`.
fn lit_scene(seed: u64, n: usize, density: f64, lamp_intensity: [f64; 3]) -> TestScene {
    let mut s = random_scene(seed, n, density);
    s.lighting.static_emission[0] = [40.0, 30.0, 20.0];
    s.lighting.dynamic_groups = vec![0, 1];
    s.lighting.default_intensity = vec![lamp_intensity, [0.5, 0.5, 0.5]];
    s.names = vec!["lamp".into(), "sun".into()];
    for (k, g, e) in [(1, 0, [100.0, 90.0, 80.0]), (2, 0, [100.0, 90.0, 80.0]), (3, 1, [10.0, 20.0, 30.0])] {
        s.lighting.group[k] = Some(g);
        s.lighting.unit_emission[k] = e;
    }
    s
}

/// Removes one element from one buffer.
type Shrink = fn(&mut Owned);

/// Buffers sized from vectors, for a solver in f32.
struct Owned {
    power: Vec<[f32; 3]>,
    unshot: Vec<[f32; 3]>,
    incident: Vec<[f32; 3]>,
    selection: Vec<u32>,
    intensity: Vec<[f32; 3]>,
    reflectance: Vec<[u16; 3]>,
}

impl Owned {
    fn new(patches: usize, groups: usize, materials: usize) -> Owned {
        Owned {
            power: vec![[0.0; 3]; patches],
            unshot: vec![[0.0; 3]; patches],
            incident: vec![[0.0; 3]; patches],
            selection: vec![0; radiosity_core::selection_len(patches as u32) as usize],
            intensity: vec![[0.0; 3]; groups],
            reflectance: vec![[0; 3]; materials],
        }
    }

    fn buffers(&mut self) -> Buffers<'_, f32> {
        Buffers {
            power: &mut self.power,
            unshot: &mut self.unshot,
            incident: &mut self.incident,
            selection: &mut self.selection,
            intensity: &mut self.intensity,
            reflectance: &mut self.reflectance,
        }
    }
}

fn owned_for(table: &Table<'_>) -> Owned {
    Owned::new(table.state_count() as usize, table.group_count() as usize, table.material_count() as usize)
}

#[test]
fn furnace_bake_converges_on_device_to_closed_form() {
    let (n, rho, e) = (24, 0.9, 1.0);
    let scene = furnace(n, rho, e);
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    assert_eq!(baked.report.nonzeros_after, n * (n - 1));
    let table = Table::parse(&baked.table).expect("parse");
    let tau = 1e-5f32;
    let mut owned = owned_for(&table);
    let mut solver = Solver::new(&table, owned.buffers(), Config { tolerance: tau, overshoot: 0 }).unwrap();
    let mut converged = false;
    for _ in 0..100_000 {
        match solver.step(1024) {
            Outcome::Converged { .. } => {
                converged = true;
                break;
            }
            Outcome::BudgetSpent { .. } => {}
            other => panic!("solver made no progress: {other:?}"),
        }
    }
    assert!(converged, "furnace did not converge");
    let exact = e / (1.0 - rho);
    // Bound (module docs): form factors rho 2^-12 / (1 - rho); reflectance 2^-17 / (1 - rho); emission 2^-11;
    // convergence n tau / ((1 - rho) A_min) / B; f32 rounding k eps_32 / 2 with k = shots.
    let shots = f64::from(solver.shots());
    let bound = rho * 2f64.powi(-12) / (1.0 - rho)
        + 2f64.powi(-17) / (1.0 - rho)
        + 2f64.powi(-11)
        + n as f64 * f64::from(tau) / (1.0 - rho) / exact
        + shots * EPS32 / 2.0;
    let worst = (0..n as u32)
        .flat_map(|i| solver.radiosity(i).unwrap())
        .map(|c| (f64::from(c) - exact).abs() / exact)
        .fold(0.0, f64::max);
    eprintln!("furnace n={n} rho={rho}: device max rel error {worst:.3e}, bound {bound:.3e}, {shots} shots");
    for i in 0..n as u32 {
        let b = solver.radiosity(i).unwrap();
        for c in b {
            let rel = (f64::from(c) - exact).abs() / exact;
            assert!(
                rel <= bound,
                "patch {i}: B = {c}, exact {exact}, rel error {rel:.3e} > bound {bound:.3e}"
            );
        }
    }
    // The bake's own f64 error report agrees with the same bound (no f32 solve involved).
    let q = &baked.report.error.sparsify_quantize;
    assert!(q.max_rel <= bound, "decoded f64 solve max rel {:.3e} > {bound:.3e}", q.max_rel);
}

#[test]
fn threshold_zero_drops_nothing() {
    let scene = random_scene(1, 40, 0.3);
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let s = sparsify(&scene.ff, &area, 0.0).unwrap();
    assert_eq!(s.matrix, scene.ff);
    assert!(s.dropped.iter().all(|&d| d == 0.0));
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    assert_eq!(baked.report.nonzeros_before, baked.report.nonzeros_after);
    assert_eq!(baked.report.energy_dropped.total, 0.0);
    assert_eq!(
        baked.report.error.sparsify.rel_l2, 0.0,
        "an unsparsified reciprocal matrix must give the same B"
    );
}

#[test]
fn energy_dropped_is_the_sum_of_dropped_form_factors() {
    let scene = lit_scene(2, 60, 0.4, [1.0; 3]);
    let n = scene.ff.n();
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let t = 0.05;
    let s = sparsify(&scene.ff, &area, t).unwrap();
    // Recount from the two matrices: which entries are gone, per row and per receiver.
    let mut lost = vec![0.0; n];
    let mut lost_in = vec![0.0; n];
    let mut incoming = vec![0.0; n];
    let mut kept_entries = Vec::new();
    for i in 0..n {
        let kept: Vec<(usize, f64)> = s.matrix.row(i).collect();
        for (j, f) in scene.ff.row(i) {
            incoming[j] += area[i] * f;
            match kept.iter().find(|&&(k, _)| k == j) {
                Some(&(_, v)) => {
                    assert_eq!(v, f, "row {i}: kept entry {j} changed (renormalized?)");
                    kept_entries.push((i, j, f));
                }
                None => {
                    lost[i] += f;
                    lost_in[j] += area[i] * f;
                }
            }
        }
        assert_eq!(kept.len(), s.matrix.row(i).count());
    }
    assert_eq!(
        kept_entries.len(),
        s.matrix.nonzeros(),
        "the sparsified matrix has entries not in the original"
    );
    // Sums of the same nonnegative terms in another order agree within (terms) * eps of the sum.
    let tol = |sum: f64| n as f64 * f64::EPSILON * sum;
    let mut total = 0.0;
    for i in 0..n {
        let row_sum = scene.ff.row_sum(i);
        assert!(
            (s.dropped[i] - lost[i]).abs() <= tol(row_sum),
            "row {i}: reported {} vs {}",
            s.dropped[i],
            lost[i]
        );
        assert!(lost[i] <= t * row_sum + tol(row_sum), "row {i}: dropped {} > t * sum", lost[i]);
        assert!((s.dropped_incoming[i] - lost_in[i]).abs() <= tol(incoming[i]), "receiver {i}");
        assert!(
            lost_in[i] <= t * incoming[i] + tol(incoming[i]),
            "receiver {i}: dropped {} > t * in",
            lost_in[i]
        );
        total += lost[i];
    }
    // Greedy: every kept entry would overflow its row's or its receiver's budget.
    for &(i, j, f) in &kept_entries {
        let row_full = lost[i] + f > t * scene.ff.row_sum(i) - tol(1.0);
        let receiver_full = lost_in[j] + area[i] * f > t * incoming[j] - tol(incoming[j]);
        assert!(row_full || receiver_full, "entry ({i}, {j}) = {f} could have been dropped");
    }
    assert!(total > 0.0, "threshold {t} dropped nothing: the test scene does not exercise sparsify");
    let baked = scene.bake(t, FfCodec::FLOAT16);
    let e = &baked.report.energy_dropped;
    let tol = scene.ff.nonzeros() as f64 * f64::EPSILON * total;
    assert!((e.total - total).abs() <= tol, "report total {} vs {total}", e.total);
    assert!(e.max_row_fraction <= t && e.max_receiver_fraction <= t, "{e:?}");
    assert_eq!(baked.report.nonzeros_after, s.matrix.nonzeros());
    assert!(baked.report.error.sparsify.rel_l2 > 0.0);
}

#[test]
fn eight_bit_error_exceeds_sixteen_bit() {
    let scene = lit_scene(3, 50, 0.3, [1.0; 3]);
    let b16 = scene.bake(0.0, codec_for_bits(16).unwrap());
    let b8 = scene.bake(0.0, codec_for_bits(8).unwrap());
    let (e16, e8) = (&b16.report.error.sparsify_quantize, &b8.report.error.sparsify_quantize);
    assert!(e8.rel_l2 > e16.rel_l2, "8-bit rel L2 {:.3e} <= 16-bit {:.3e}", e8.rel_l2, e16.rel_l2);
    assert!(e8.max_rel > e16.max_rel, "8-bit max rel {:.3e} <= 16-bit {:.3e}", e8.max_rel, e16.max_rel);
    assert!(b8.table.len() < b16.table.len());
    assert_eq!(b16.report.table_bytes.entry_codes, 2 * b16.report.nonzeros_after);
    assert_eq!(b8.report.table_bytes.entry_codes, b8.report.nonzeros_after);
    assert!(matches!(codec_for_bits(12), Err(BakeError::BadBits(12))));
}

#[test]
fn static_light_is_folded_into_the_base() {
    // The dynamic `lamp` defaults to 0 and `sun` to 0.5: set sun to 0 too, so only the static light is on.
    let mut scene = lit_scene(4, 40, 0.3, [0.0; 3]);
    scene.lighting.default_intensity[1] = [0.0; 3];
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    assert!(baked.report.base_solved);
    let table = Table::parse(&baked.table).unwrap();
    assert!(table.base_solved());
    let mut owned = owned_for(&table);
    let mut solver = Solver::new(&table, owned.buffers(), Config { tolerance: 1e-6, overshoot: 0 }).unwrap();
    let n = table.state_count();
    // The only work left is building the selection (n slots scanned) and one selection scan; nothing is shot.
    let build = n + radiosity_core::selection_len(n);
    match solver.step(build) {
        Outcome::Converged { used } => assert_eq!(used, build, "only the selection's build and scan"),
        other => panic!("expected Converged at once, got {other:?}"),
    }
    assert_eq!(solver.shots(), 0);
    // The device radiosity is (E_s + rho G_s) from codes: per patch error <= 2^-11 E_s + (2^-11 rho + 2^-17) G_s
    // plus a few f32 roundings (products, area division: 8 eps_32 of B).
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let shoot = radiosity_host::bake::shooting_form(&baked.sparse.matrix, &area);
    for i in 0..n as usize {
        let b = solver.radiosity(i as u32).unwrap();
        let mut g = [0.0; 3];
        for (j, f) in shoot.row(i) {
            for c in 0..3 {
                g[c] += f * baked.static_radiosity[j][c];
            }
        }
        for c in 0..3 {
            let exact = baked.static_radiosity[i][c];
            let es = scene.lighting.static_emission[i][c];
            let rho = scene.lighting.rho[i][c];
            let bound =
                2f64.powi(-11) * es + (2f64.powi(-11) * rho + 2f64.powi(-17)) * g[c] + 8.0 * EPS32 * exact;
            let err = (f64::from(b[c]) - exact).abs();
            assert!(
                err <= bound,
                "patch {i} channel {c}: device {} vs f64 {exact}: {err:.3e} > {bound:.3e}",
                b[c]
            );
        }
    }
    // The static light reaches patches other than itself (the scene is connected enough).
    assert!(baked.static_radiosity.iter().skip(1).any(|b| b[0] > 0.0));
}

#[test]
fn inspect_reports_the_baked_counts() {
    let scene = lit_scene(5, 30, 0.4, [1.0; 3]);
    let baked = scene.bake(0.01, FfCodec::FLOAT8);
    let r = inspect(&baked.table).expect("inspect");
    assert_eq!(r.counts.patches, 30);
    assert_eq!(r.counts.materials, scene.materials.len());
    assert_eq!(r.counts.groups, 2);
    assert_eq!(r.counts.members, 3);
    assert_eq!(r.counts.entries, baked.report.nonzeros_after);
    assert_eq!(r.codec, "FLOAT8");
    assert_eq!(r.ff_bits, 8);
    assert!(r.base_solved);
    assert_eq!(r.static_emitters, 1);
    assert_eq!(
        r.groups.iter().map(|g| (g.id, g.members)).collect::<Vec<_>>(),
        [(group_id("lamp"), 2), (group_id("sun"), 1)]
    );
    assert_eq!(r.bytes, baked.report.table_bytes);
    assert_eq!(r.bytes.total, baked.table.len());
    assert_eq!(r.bytes.header + r.bytes.payload + r.bytes.crc, r.bytes.total);
    assert!(
        r.bytes.header >= 4 + 1 + 7,
        "header {} bytes: magic plus at least one byte per field",
        r.bytes.header
    );
    assert_eq!(r.row_len.max as usize, baked.capacities.max_row_len);
    let lens: Vec<usize> = (0..30).map(|i| baked.sparse.matrix.row(i).count()).collect();
    assert_eq!(r.row_len.min as usize, *lens.iter().min().unwrap());
    // Decoded row sums never exceed the true (f64) row sums of the kept entries, and are within the FLOAT8
    // bound 2^-5 (relative per entry, for entries >= max / 2^6) plus the small entries below it.
    let true_max = (0..30).map(|i| baked.sparse.matrix.row_sum(i)).fold(0.0, f64::max);
    assert!(r.row_sum.max <= true_max * (1.0 + f64::from(f32::EPSILON)));
    assert!(r.row_sum.max > 0.0);
    let text = r.to_string();
    assert!(text.contains("valid") && text.contains("FLOAT8"), "{text}");
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["counts"]["entries"], baked.report.nonzeros_after);
    let report_json = serde_json::to_value(&baked.report).unwrap();
    assert_eq!(report_json["nonzeros_after"], baked.report.nonzeros_after);
}

#[test]
fn inspect_rejects_truncated_and_corrupted_tables_with_context() {
    let scene = lit_scene(6, 20, 0.4, [1.0; 3]);
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    let len = baked.table.len();
    let err = inspect(&baked.table[..len - 10]).unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with("<bytes>: invalid table: table truncated"), "{msg}");
    assert!(msg.contains(&format!("{} bytes, header implies {len}", len - 10)), "{msg}");

    let mut bad = baked.table.clone();
    bad[len / 2] ^= 0x40;
    let msg = inspect(&bad).unwrap_err().to_string();
    assert!(msg.contains("CRC mismatch"), "{msg}");

    let dir = std::env::temp_dir().join(format!("radiosity-bake-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cut.rft");
    std::fs::write(&path, &baked.table[..3]).unwrap();
    let err = inspect_file(&path).unwrap_err();
    assert!(matches!(err, InspectError::Table { .. }));
    let msg = err.to_string();
    assert!(
        msg.starts_with(&path.display().to_string())
            && msg.contains("invalid table: table truncated inside its header"),
        "{msg}"
    );
    let missing = inspect_file(&dir.join("missing.rft")).unwrap_err().to_string();
    assert!(missing.contains("missing.rft: cannot read"), "{missing}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn capacities_size_the_solver_exactly() {
    let scene = lit_scene(7, 25, 0.4, [1.0; 3]);
    let baked = scene.bake(0.01, FfCodec::FLOAT16);
    let cap = &baked.capacities;
    let table = Table::parse(&baked.table).unwrap();
    assert_eq!((cap.patches, cap.groups, cap.members, cap.entries), (25, 2, 3, baked.report.nonzeros_after));
    assert_eq!(cap.table_bytes, baked.table.len());
    let exact = || Owned {
        power: vec![[0.0; 3]; cap.buffers.slots],
        unshot: vec![[0.0; 3]; cap.buffers.slots],
        incident: vec![[0.0; 3]; cap.buffers.slots],
        selection: vec![0; cap.buffers.selection],
        intensity: vec![[0.0; 3]; cap.buffers.groups],
        reflectance: vec![[0; 3]; cap.buffers.materials],
    };
    let config = Config { tolerance: 1e-4, overshoot: 0 };
    let mut owned = exact();
    let mut solver = Solver::new(&table, owned.buffers(), config).expect("exact capacities must suffice");
    let mut converged = false;
    for _ in 0..10_000 {
        if let Outcome::Converged { .. } = solver.step(256) {
            converged = true;
            break;
        }
    }
    assert!(converged);
    // One element less in any buffer fails with core's error naming that buffer.
    let shrink: [(&str, Shrink); 6] = [
        ("power", |o| {
            o.power.pop();
        }),
        ("unshot", |o| {
            o.unshot.pop();
        }),
        ("incident", |o| {
            o.incident.pop();
        }),
        ("selection", |o| {
            o.selection.pop();
        }),
        ("intensity", |o| {
            o.intensity.pop();
        }),
        ("reflectance", |o| {
            o.reflectance.pop();
        }),
    ];
    for (name, f) in shrink {
        let mut o = exact();
        f(&mut o);
        match Solver::new(&table, o.buffers(), config) {
            Err(SolverError::BufferTooSmall { buffer, .. }) => assert_eq!(buffer, name),
            other => panic!("{name} one short: expected BufferTooSmall, got {:?}", other.map(|_| ())),
        }
    }
    assert_eq!(cap.buffers, radiosity_core::BufferSizes::of(&table));
    let b = cap.buffers;
    assert_eq!(cap.buffer_bytes_f32, 3 * 12 * b.slots + 4 * b.selection + 12 * b.groups + 6 * b.materials);
    let json = serde_json::to_value(cap).unwrap();
    assert_eq!(json["entries"], cap.entries);
    assert_eq!(json["buffers"]["selection"], cap.buffers.selection);
}

#[test]
fn reachability_stops_at_black_patches_and_disconnected_parts() {
    // Patches 0..4: 0 is the dynamic light, 0 -> 1 -> 2 (1 is black) and 0 -> 3; 4 is not connected.
    let patches: Vec<Patch> = (0..5).map(|k| patch(k, 1.0, usize::from(k == 1))).collect();
    let materials = vec![[0.5; 3], [0.0; 3]];
    let rows = vec![
        vec![0.0, 0.3, 0.0, 0.3, 0.0],
        vec![0.3, 0.0, 0.3, 0.0, 0.0],
        vec![0.0, 0.3, 0.0, 0.0, 0.0],
        vec![0.3, 0.0, 0.0, 0.0, 0.0],
        vec![0.0; 5],
    ];
    let mut lighting = dark_lighting(&patches, &materials, 1);
    lighting.group[0] = Some(0);
    lighting.unit_emission[0] = [1.0; 3];
    let scene =
        TestScene { patches, materials, lighting, names: vec!["lamp".into()], ff: dense_to_csr(&rows) };
    let reach = reachable_patches(&scene.ff, &scene.lighting.group, &scene.lighting.rho);
    assert_eq!(reach, [true, false, false, true, false]);
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    assert_eq!(baked.report.runtime_state.reachable, 2);
    // Row 0's entry to the black patch 1 has no receiver on the device; nothing else is dropped.
    assert_eq!(baked.report.runtime_state.entries_to_stateless, 1);
    assert!(baked.report.to_string().contains("runtime state      2 of 5 patches"), "{}", baked.report);
    // The table keeps state for patches 0 and 3 only, and the firmware buffers are sized by them.
    let table = Table::parse(&baked.table).unwrap();
    assert_eq!((table.patch_count(), table.state_count()), (5, 2));
    assert_eq!([0, 1].map(|s| table.slot_patch(s)), [Some(0), Some(3)]);
    assert_eq!((baked.capacities.patches, baked.capacities.state, baked.capacities.buffers.slots), (5, 2, 2));
    assert_eq!(table.entry_count(), 2);
    let mut owned = owned_for(&table);
    let mut solver = Solver::new(&table, owned.buffers(), Config { tolerance: 1e-9, overshoot: 0 }).unwrap();
    while let Outcome::BudgetSpent { .. } = solver.step(100) {}
    // Only the lamp and patch 3 light up: the others show their (dark) static base.
    let b: Vec<f32> = (0..5).map(|i| solver.radiosity(i).unwrap()[0]).collect();
    assert!(b[0] > 1.0 && b[3] > 0.0, "{b:?}");
    assert_eq!([b[1], b[2], b[4]], [0.0; 3]);
}

#[test]
fn bad_inputs_are_named() {
    let scene = lit_scene(8, 10, 0.5, [1.0; 3]);
    let options = BakeOptions { threshold: 1.0, ..BakeOptions::default() };
    let err = bake(&scene.input(), &options).unwrap_err();
    assert_eq!(err.to_string(), "sparsification threshold 1 not in [0, 1)");
    let mut input = scene.input();
    input.group_names.pop();
    let err = bake(&input, &BakeOptions::default()).unwrap_err().to_string();
    assert!(err.contains("2 dynamic light groups but 2 default intensities and 1 names"), "{err}");
    let mut input = scene.input();
    input.materials[0] = [0.1; 3];
    let err = bake(&input, &BakeOptions::default()).unwrap_err().to_string();
    assert!(err.contains("patch 0: lighting reflectance"), "{err}");
}

/// The error a bake introduces grows with the threshold and with fewer bits, on the same scene. Prints the
/// summary line per setting (`cargo test -p radiosity-host --test bake error_grows -- --nocapture`).
#[test]
fn error_grows_with_threshold_and_fewer_bits() {
    let scene = lit_scene(2, 60, 0.4, [1.0; 3]);
    let mut previous: Option<(f64, f64)> = None;
    for t in [0.0, 1e-3, 1e-2, 5e-2] {
        let b16 = scene.bake(t, FfCodec::FLOAT16).report;
        let b8 = scene.bake(t, FfCodec::FLOAT8).report;
        for r in [&b16, &b8] {
            eprintln!(
                "t={t:<6} {:<7} nnz {} -> {}  bytes {} ({:.2}/entry)  dropped total {:.3e} area-weighted {:.3e}  \
                 sparsify rel L2 {:.3e} max {:.3e}  +quantize rel L2 {:.3e} max {:.3e}",
                r.codec,
                r.nonzeros_before,
                r.nonzeros_after,
                r.table_bytes.total,
                r.bytes_per_entry,
                r.energy_dropped.total,
                r.energy_dropped.area_weighted,
                r.error.sparsify.rel_l2,
                r.error.sparsify.max_rel,
                r.error.sparsify_quantize.rel_l2,
                r.error.sparsify_quantize.max_rel
            );
        }
        let (e16, e8) = (b16.error.sparsify_quantize.rel_l2, b8.error.sparsify_quantize.rel_l2);
        assert!(e8 > e16, "t = {t}: 8-bit {e8:.3e} <= 16-bit {e16:.3e}");
        assert!(b8.table_bytes.total < b16.table_bytes.total);
        if let Some((p_err, p_bytes)) = previous {
            let s = b16.error.sparsify.rel_l2;
            assert!(s > p_err, "t = {t}: sparsify error {s:.3e} did not grow from {p_err:.3e}");
            assert!((b16.table_bytes.total as f64) < p_bytes, "t = {t}: table did not shrink");
        }
        previous = Some((b16.error.sparsify.rel_l2, b16.table_bytes.total as f64));
    }
}

/// The solved static base is a fixed point of the device's shooting when the stored rows are not reciprocal
/// (estimated form factors; sparsification): with the decoded table, `H_i = sum_j F'_ji Phi'_j` (what shooting
/// would deliver) equals the stored incident power `A_i G'_i`, within the codes' bounds. Gathering with `F_ij`
/// instead of the shooting form would miss by the reciprocity error (here up to 10%).
#[test]
fn static_base_is_a_fixed_point_of_shooting_without_reciprocity() {
    use radiosity_core::codec::{decode_emission_f32, decode_reflectance};
    let mut scene = lit_scene(9, 40, 0.4, [1.0; 3]);
    // Perturb every entry by up to 5%, as a Monte Carlo estimate would (row sums stay <= 0.9 * 1.05).
    let mut rng = SplitMix64::new(99);
    scene.ff.map_values(|_, _, f| f * (0.95 + 0.1 * rng.unit()));
    let baked = scene.bake(0.05, FfCodec::FLOAT16);
    assert!(baked.report.error.reciprocity.rel_l2 > 1e-3, "the input must not be reciprocal");
    assert!(baked.report.energy_dropped.max_row_fraction > 0.01, "sparsify must drop entries");
    let table = Table::parse(&baked.table).unwrap();
    let n = table.patch_count() as usize;
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let shoot = radiosity_host::bake::shooting_form(&baked.sparse.matrix, &area);
    let b = &baked.static_radiosity;
    let g: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let mut g = [0.0; 3];
            for (j, f) in shoot.row(i) {
                for c in 0..3 {
                    g[c] += f * b[j][c];
                }
            }
            g
        })
        .collect();
    let dec = |codes: [u16; 3]| codes.map(|c| f64::from(decode_emission_f32(c)));
    let rho_of = |i: usize| {
        let r = table.reflectance(table.material(i as u32).unwrap()).unwrap();
        r.map(|c| f64::from(decode_reflectance(c).to_f32()))
    };
    // Decoded power Phi'_j = A_j (E'_j + rho'_j G'_j) and its bound against A_j B_j:
    // A_j (2^-11 E_j + 2^-11 rho_j G_j + 2^-17 G_j).
    let mut phi = vec![[0.0; 3]; n];
    let mut phi_err = vec![[0.0; 3]; n];
    for j in 0..n {
        let (e, gs, rho) = (
            dec(table.base_emission(j as u32).unwrap()),
            dec(table.base_irradiance(j as u32).unwrap()),
            rho_of(j),
        );
        for c in 0..3 {
            phi[j][c] = area[j] * (e[c] + rho[c] * gs[c]);
            let (es, r) = (scene.lighting.static_emission[j][c], scene.lighting.rho[j][c]);
            phi_err[j][c] = area[j] * (2f64.powi(-11) * (es + r * g[j][c]) + 2f64.powi(-17) * g[j][c]);
        }
    }
    let mut h = vec![[0.0; 3]; n];
    let mut h_err = vec![[0.0; 3]; n];
    for j in 0..n as u32 {
        let row_max = baked.sparse.matrix.row(j as usize).map(|(_, f)| f).fold(0.0, f64::max);
        for k in table.row(j).unwrap() {
            let (i, f) = table.entry(j, k).unwrap();
            let f = f64::from(f.to_f32());
            // FLOAT16: relative error < 2^-12 for entries >= row max / 2^14 (all entries here: the couplings
            // span 3 decades and areas a factor 4).
            let f_true = baked.sparse.matrix.row(j as usize).find(|&(r, _)| r == i as usize).unwrap().1;
            assert!(f_true >= row_max / 16384.0);
            for c in 0..3 {
                h[i as usize][c] += f * phi[j as usize][c];
                h_err[i as usize][c] +=
                    f_true * (2f64.powi(-12) * area[j as usize] * b[j as usize][c] + phi_err[j as usize][c]);
            }
        }
    }
    for i in 0..n {
        let stored = dec(table.base_irradiance(i as u32).unwrap());
        for c in 0..3 {
            let exact = area[i] * g[i][c];
            // Stored irradiance: 2^-11 relative; f64 sums: 1e-12 relative is far above n eps.
            let bound = 2f64.powi(-11) * exact + h_err[i][c] + 1e-12 * exact;
            let diff = (h[i][c] - area[i] * stored[c]).abs();
            assert!(
                diff <= bound,
                "patch {i} channel {c}: shooting gives {} but the base holds {}: {diff:.3e} > {bound:.3e}",
                h[i][c],
                area[i] * stored[c]
            );
        }
    }
}

/// Form factor between parallel, directly opposed unit squares at distance 1 (Howell's catalog, C-11, with
/// `X = Y = 1`): `F = 2 / (pi X Y) [ln sqrt((1 + X^2)(1 + Y^2) / (1 + X^2 + Y^2)) + X sqrt(1 + Y^2)
/// atan(X / sqrt(1 + Y^2)) + Y sqrt(1 + X^2) atan(Y / sqrt(1 + X^2)) - X atan X - Y atan Y]` = 0.199825.
fn opposed_unit_squares() -> f64 {
    let (x, y) = (1.0f64, 1.0f64);
    let (x2, y2) = (x * x, y * y);
    2.0 / (std::f64::consts::PI * x * y)
        * (((1.0 + x2) * (1.0 + y2) / (1.0 + x2 + y2)).sqrt().ln()
            + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
            + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
            - x * x.atan()
            - y * y.atan())
}

/// The shipped furnace scene (`scenes/furnace.obj`, a unit cube, rho 0.9, Ke 1) through scene loading,
/// `PatchLighting::new` and `BakeInput::from_scene`, with its analytic form factors (opposite faces from
/// Howell C-11, adjacent faces `(1 - F_opp) / 4` by closure and symmetry): the device reaches `B = 10`.
#[test]
fn shipped_furnace_scene_bakes_and_relights_to_closed_form() {
    use radiosity_host::mesh::{mesh, MeshOptions};
    use radiosity_host::scene::Scene;
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/furnace.obj");
    let scene = Scene::load(&path).expect("load furnace");
    let patches = mesh(&scene, &MeshOptions::no_subdivide(&scene)).expect("mesh").patches;
    assert_eq!(patches.len(), 6);
    let f_opp = opposed_unit_squares();
    assert!((f_opp - 0.199825).abs() < 1e-6, "C-11 gives {f_opp}");
    let f_adj = (1.0 - f_opp) / 4.0;
    let rows: Vec<Vec<f64>> = patches
        .iter()
        .enumerate()
        .map(|(i, p)| {
            patches
                .iter()
                .enumerate()
                .map(|(j, q)| match p.normal.dot(q.normal) {
                    _ if i == j => 0.0,
                    d if d < -0.5 => f_opp,
                    _ => f_adj,
                })
                .collect()
        })
        .collect();
    let ff = dense_to_csr(&rows);
    let lighting = PatchLighting::new(&scene, &patches);
    let input = BakeInput::from_scene(&scene, &patches, &lighting, &ff);
    assert_eq!(
        input.group_names,
        lighting.dynamic_groups.iter().map(|&g| scene.light_groups[g].name.clone()).collect::<Vec<_>>()
    );
    let baked = bake(&input, &BakeOptions::default()).expect("bake");
    assert_eq!(
        baked.report.nonzeros_after, 30,
        "threshold 1e-3 must keep all entries of a 5-entry row of ~0.2"
    );
    let table = Table::parse(&baked.table).unwrap();
    let tau = 1e-6f32;
    let mut owned = owned_for(&table);
    let mut solver = Solver::new(&table, owned.buffers(), Config { tolerance: tau, overshoot: 0 }).unwrap();
    let mut converged = false;
    for _ in 0..10_000 {
        match solver.step(64) {
            Outcome::Converged { .. } => {
                converged = true;
                break;
            }
            Outcome::BudgetSpent { .. } => {}
            other => panic!("no progress: {other:?}"),
        }
    }
    assert!(converged);
    let (rho, exact) = (0.9, 10.0);
    // As in the synthetic furnace test, plus 2^-11 for a static base's irradiance code (if the scene's group is
    // static) and 1e-9 relative for the f64 closure of the analytic rows.
    let bound = rho * 2f64.powi(-12) / (1.0 - rho)
        + 2f64.powi(-17) / (1.0 - rho)
        + 2.0 * 2f64.powi(-11)
        + 6.0 * f64::from(tau) / (1.0 - rho) / exact
        + f64::from(solver.shots()) * EPS32 / 2.0
        + 1e-9 / (1.0 - rho);
    for i in 0..6 {
        for c in solver.radiosity(i).unwrap() {
            let rel = (f64::from(c) - exact).abs() / exact;
            assert!(rel <= bound, "face {i}: B = {c}, rel error {rel:.3e} > {bound:.3e}");
        }
    }
}

/// Dense LU and Gauss-Seidel give the same bake report. Gauss-Seidel stops at relative residual `1e-12`, so its
/// relative forward error is at most `kappa * 1e-12` with `kappa = (1 + q) / (1 - q) <= 19` (`q <= 0.9` here),
/// and LU's is `8 n eps kappa`; an error metric built from both answers moves by at most a few times that,
/// far below `1e-9`. The decoded inputs do not depend on the solver except through `G_s`, which the decoded
/// solve does not use.
#[test]
fn gauss_seidel_and_dense_bakes_agree() {
    use radiosity_host::reference::{GaussSeidelOptions, Method};
    let scene = lit_scene(10, 60, 0.3, [1.0; 3]);
    let run = |method| {
        let options = BakeOptions { threshold: 1e-2, method: Some(method), ..BakeOptions::default() };
        bake(&scene.input(), &options).unwrap().report
    };
    let dense = run(Method::Dense { limit: 100 });
    let gs = run(Method::GaussSeidel(GaussSeidelOptions::default()));
    for (a, b) in [
        (dense.error.sparsify.rel_l2, gs.error.sparsify.rel_l2),
        (dense.error.sparsify_quantize.rel_l2, gs.error.sparsify_quantize.rel_l2),
        (dense.error.sparsify_quantize.max_rel, gs.error.sparsify_quantize.max_rel),
    ] {
        assert!((a - b).abs() <= 1e-9, "dense {a:.6e} vs Gauss-Seidel {b:.6e}");
    }
    assert!(gs.reference_residual <= 1e-12 && dense.reference_residual <= 1e-12);
}

/// A codec too coarse for the scene's area ratios is refused with its own error. A sliver (area 2^-10) receives
/// from six unit-area patches whose rows hold one tiny entry to it, 0.55 of an 8-bit code step below the float
/// range (row max 1/2: exponent 1, step 2^-(1 + 5 + 6) = 2^-12), next to an entry whose rounding loss leaves
/// slack for one such step. The writer may bump the tiny entry to a whole step (it at most doubles it), which
/// is harmless in the stored rows (sums stay <= 1) but in the sliver's incoming row each step counts 2^10
/// times: 6 * 2^-12 * 2^10 = 1.5 decoded against 0.825 true, beyond the 8-bit allowance (1 + 2^-5 + the
/// row-sum tolerance). 16-bit codes bake the same scene. (The meshed case: `coarse_codec_is_refused_with_the_
/// reason` in tests/tests/verification.rs, the slab.)
#[test]
fn coarse_codec_is_refused_on_a_synthetic_sliver() {
    let (k, sliver) = (6usize, 2f64.powi(-10));
    let mut patches = vec![patch(0, sliver, 0)];
    patches.extend((1..=k).map(|i| patch(i, 1.0, 0)));
    let n = k + 1;
    let step = 2f64.powi(-12);
    let mut rows = vec![vec![0.0; n]; n];
    for i in 1..=k {
        let (next, prev) = (i % k + 1, (i + k - 2) % k + 1);
        rows[i][next] = 0.5;
        rows[i][prev] = 0.25 + 0.9 * 2f64.powi(-7);
        rows[i][0] = 0.55 * step;
        // Reciprocity: A_0 F_0i = A_i F_i0.
        rows[0][i] = rows[i][0] / sliver;
    }
    let materials = vec![[0.5; 3]];
    let mut lighting = dark_lighting(&patches, &materials, 1);
    lighting.group[1] = Some(0);
    lighting.unit_emission[1] = [1.0; 3];
    let scene =
        TestScene { patches, materials, lighting, names: vec!["lamp".into()], ff: dense_to_csr(&rows) };
    let options = |codec| BakeOptions { threshold: 0.0, codec, ..BakeOptions::default() };
    let err = bake(&scene.input(), &options(FfCodec::FLOAT8)).expect_err("8-bit codes must be refused");
    let msg = err.to_string();
    println!("{msg}");
    assert!(matches!(err, BakeError::CodecTooCoarse { bits: 8, patch: 0, .. }), "{msg}");
    assert!(msg.contains("decode to a sum of 1.500") && msg.contains("1024 times its area"), "{msg}");
    assert!(msg.contains("--bits 16"), "{msg}");
    bake(&scene.input(), &options(FfCodec::FLOAT16)).expect("16-bit bake");
}
