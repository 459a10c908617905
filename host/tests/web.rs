//! The browser viewer (`radiosity view SCENE --web DIR`): the device core built as WebAssembly runs a relight
//! script bit for bit as the host simulator does (under Node.js), and the page relights the Cornell box in
//! headless Chromium (WebGL2 through SwiftShader) without console errors, within its per-frame budget, darkening
//! when its light slider goes to 0.
//!
//! Both build `radiosity-web` for `wasm32-unknown-unknown` (installing the target with rustup if missing) and use
//! the npm packages of `tests/web` and the system Chromium like the `.glb` checks (`common::web`); when those
//! cannot be had they print why and skip.

mod common;

use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::Duration;

use common::web::{chromium, node, serve, wasm, web};
use firmware_sim::device::{run_script, unit_light_power, Frame, NoMeter, Script};
use radiosity_core::{OwnedBuffers, Solver, Table};
use radiosity_host::bake::{bake, BakeInput, BakeOptions};
use radiosity_host::pipeline::Prepared;
use radiosity_host::reference::{exact_transfer, Method};
use radiosity_host::rgb::{luminance, Rgb};
use radiosity_host::web::{write_viewer, CostModel};
use serde_json::Value;

/// Relative convergence tolerance of the scripts here and of the page (its default, `viewer.js`).
const TOLERANCE: f32 = 1e-5;

fn scratch() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("web");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cornell() -> &'static Prepared {
    static CELL: OnceLock<Prepared> = OnceLock::new();
    CELL.get_or_init(common::coarse_cornell)
}

/// Skips the calling test (returns from it) with the reason, when `result` is an error.
macro_rules! or_skip {
    ($test:literal, $result:expr) => {
        match $result {
            Ok(v) => v,
            Err(why) => {
                eprintln!("SKIPPED {}: {why}", $test);
                return;
            }
        }
    };
}

/// The cost model the page quotes is the Cortex-M4F row of the generated report, read whole.
#[test]
fn cost_model_is_read_from_the_firmware_report() {
    let m = CostModel::cortex_m4().unwrap();
    assert_eq!(m.build, "m4-f32");
    assert!(m.per_unit > 0.0 && m.bound_per_unit >= m.per_unit, "{m:?}");
    assert!(m.bound_overhead >= m.overhead, "{m:?}");
    let row = "| m4-f32 | 37 | 7642 | 147.36 | 7642 | 185.14 | 121 | 0 |";
    assert_eq!(
        CostModel::from_report(row, "m4-f32"),
        Some(CostModel {
            build: "m4-f32",
            overhead: 7642.0,
            per_unit: 147.36,
            bound_overhead: 7642.0,
            bound_per_unit: 185.14
        })
    );
    assert_eq!(CostModel::from_report("| m4-f32 | 37 | x | 1 | 1 | 1 |", "m4-f32"), None);
    assert_eq!(CostModel::from_report(row, "m0-fixed"), None);
}

/// The same table and relight script (boot, budgets that end frames mid-solve, dimming, switching off, a
/// coloured light) through the host simulator's device loop and through the wasm build under Node.js: every
/// frame's units, outcome and every patch's radiosity agree bit for bit (WebAssembly's f32 is IEEE 754 with
/// round-to-nearest, as the host's); so does the transfer-basis relight of the last intensities.
#[test]
fn wasm_core_matches_the_host_simulator_bit_for_bit() {
    let dir = or_skip!("wasm_core_matches_the_host_simulator_bit_for_bit", web());
    let wasm = or_skip!("wasm_core_matches_the_host_simulator_bit_for_bit", wasm());
    let p = cornell();
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions { transfer: true, ..BakeOptions::default() }).unwrap();
    let table_path = scratch().join("bitexact.rft");
    std::fs::write(&table_path, &baked.table).unwrap();
    let table = Table::parse(&baked.table).unwrap();
    assert_eq!(table.group_count(), 1);

    let levels: [[f32; 3]; 6] = [[1.0; 3], [1.0; 3], [0.5; 3], [0.5; 3], [0.0; 3], [1.0, 0.5, 0.25]];
    let intensities: Vec<[[f32; 3]; 1]> = levels.iter().map(|&l| [l]).collect();
    let budgets = [700u32, 2000, 5000, 5000, 30_000, 100_000];
    let frames: Vec<Frame<'_>> =
        intensities.iter().zip(budgets).map(|(i, budget)| Frame { budget, intensity: i }).collect();
    let initial = [[1.0f32; 3]];
    let script = Script {
        name: "web",
        tolerance: TOLERANCE,
        initial: &initial,
        boot_budget: u32::MAX,
        frames: &frames,
    };

    let mut host = Vec::new();
    let mut store = OwnedBuffers::<f32>::for_table(&table);
    run_script(&table, store.buffers(), &script, &mut NoMeter, |record, solver: &Solver<'_, f32>| {
        let bits: Vec<String> = (0..solver.patch_count())
            .flat_map(|i| solver.radiosity(i).unwrap())
            .map(|v| format!("{:x}", v.to_bits()))
            .collect();
        host.push((record.used, record.light_units, record.outcome, bits));
    })
    .unwrap();

    let json = serde_json::json!({
        "tolerance": TOLERANCE,
        "initial": initial,
        "boot_budget": u32::MAX,
        "frames": frames.iter().map(|f| serde_json::json!({ "budget": f.budget, "intensity": f.intensity })).collect::<Vec<_>>(),
    });
    let script_path = scratch().join("bitexact.json");
    std::fs::write(&script_path, json.to_string()).unwrap();
    let args =
        ["bitexact.mjs", wasm.to_str().unwrap(), table_path.to_str().unwrap(), script_path.to_str().unwrap()];
    let out: Value = serde_json::from_str(&node(dir, &args, Duration::from_secs(120)).unwrap()).unwrap();
    let browser = out["frames"].as_array().unwrap();
    assert_eq!(browser.len(), host.len());
    let mut budget_spent = 0;
    for (k, (b, (used, light_units, outcome, bits))) in browser.iter().zip(&host).enumerate() {
        let code = match outcome {
            radiosity_core::Outcome::Converged { .. } => 0,
            radiosity_core::Outcome::BudgetSpent { .. } => 1,
            radiosity_core::Outcome::NoProgress { .. } => 2,
        };
        budget_spent += usize::from(code == 1);
        assert_eq!(b["used"], *used, "frame {k}: units used");
        assert_eq!(b["light_units"], *light_units, "frame {k}: light-change units");
        assert_eq!(b["outcome"], code, "frame {k}: outcome");
        let wasm_bits: Vec<&str> =
            b["bits"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
        assert_eq!(wasm_bits.len(), bits.len(), "frame {k}");
        let differ = wasm_bits.iter().zip(bits).filter(|(a, b)| **a != b.as_str()).count();
        assert_eq!(differ, 0, "frame {k}: {differ} of {} radiosity values differ in their bits", bits.len());
    }
    // The transfer-basis relight of the last intensities: the same units and bits as core's on the host.
    let mut answer = vec![[0.0f32; 3]; table.patch_count() as usize];
    let units = radiosity_core::relight_transfer(&table, &[*levels.last().unwrap()], &mut answer).unwrap();
    let t = &out["transfer"];
    assert_eq!(t["units"], units);
    let host_bits: Vec<String> = answer.iter().flatten().map(|v| format!("{:x}", v.to_bits())).collect();
    let wasm_bits: Vec<&str> = t["bits"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert_eq!(wasm_bits, host_bits, "transfer-basis relight");
    // The script exercised the bounded path: frames that ended with budget spent, a shot split across frames.
    assert!(
        budget_spent >= 2,
        "only {budget_spent} frames spent their budget: the script does not test resumption"
    );
    eprintln!(
        "{} frames, {} patches: wasm and host simulator agree bit for bit ({budget_spent} frames ended with budget \
         spent)",
        host.len(),
        table.patch_count()
    );
}

/// The page in headless Chromium: loads without console errors (nor failed requests), converges within the
/// budget it shows (read back per frame: never exceeded, and spent in full before convergence), reports the
/// error that the host computes from the page's own radiosity against the exact f64 answer, agrees with the host
/// simulator's converged answer within the convergence bound of core's docs, and moving the light slider to 0
/// darkens the picture and the radiosity as the exact answer does.
#[test]
fn viewer_relights_the_cornell_box_in_chromium() {
    let dir = or_skip!("viewer_relights_the_cornell_box_in_chromium", web());
    or_skip!("viewer_relights_the_cornell_box_in_chromium", chromium());
    let wasm = or_skip!("viewer_relights_the_cornell_box_in_chromium", wasm());
    let p = cornell();
    let site = scratch().join("site");
    let files = write_viewer(p, &site, wasm).unwrap();
    assert_eq!(files.files.len(), 5);
    let budget = 3000u32;
    let port = serve(vec![("/", site.clone())]);
    let url = format!("http://127.0.0.1:{port}/index.html?budget={budget}");
    let out = scratch();
    let text = node(dir, &["viewer.mjs", &url, out.to_str().unwrap()], Duration::from_secs(300)).unwrap();
    let r: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(r["errors"].as_array().unwrap().len(), 0, "the page reported errors: {}", r["errors"]);

    // The budget read back from the page: every frame within it, and it bound the work before convergence.
    let frames = r["frames"].as_array().unwrap();
    let mut spent = 0;
    for (k, f) in frames.iter().enumerate() {
        let (b, used) = (f["budget"].as_u64().unwrap(), f["used"].as_u64().unwrap());
        assert_eq!(b, u64::from(budget), "frame {k}: the page's budget");
        assert!(used <= b, "frame {k}: {used} units used of a budget of {b}");
        spent += usize::from(f["outcome"] == 1);
    }
    assert_eq!(r["stats"]["overBudget"], 0);
    assert!(spent >= 10, "only {spent} frames ended with their budget spent: the budget did not bind");

    // The exact answers before and after, and the page's radiosity.
    let l = &p.lighting;
    let exact = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len())).unwrap();
    let exact_before = exact.relight(&l.default_intensity).unwrap();
    let exact_after = exact.relight(&[Rgb::ZERO]).unwrap();
    let page = |phase: &str| -> Vec<Rgb> {
        let v: Vec<f64> =
            r[phase]["radiosity"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        v.chunks_exact(3).map(|c| Rgb::new(c[0], c[1], c[2])).collect()
    };
    let (before, after) = (page("before"), page("after"));
    assert_eq!(before.len(), p.patches.len());
    let area: Vec<f64> = p.patches.iter().map(|x| x.area).collect();
    let rel_l2 = |b: &[Rgb], e: &[Rgb]| {
        let (mut num, mut den) = (0.0, 0.0);
        for ((x, y), a) in b.iter().zip(e).zip(&area) {
            num += a * (*x - *y).length_squared();
            den += a * y.length_squared();
        }
        (num / den).sqrt()
    };
    let error = rel_l2(&before, &exact_before);
    let shown = r["before"]["errorVsExact"].as_f64().unwrap();
    assert!((shown - error).abs() <= 1e-9 * error, "the page shows error {shown}, its radiosity has {error}");

    // The host simulator's converged answer on the same table: both within n tol / ((1 - rho_max) A_min) of
    // the quantized system's solution (core's docs, "Error bounds: convergence"), so within twice that.
    let blob = std::fs::read(site.join("scene.rft")).unwrap();
    let table = Table::parse(&blob).unwrap();
    let tolerance = TOLERANCE * unit_light_power(&table);
    let mut store = OwnedBuffers::<f32>::for_table(&table);
    let config =
        radiosity_core::Config { tolerance, overshoot: radiosity_core::Config::<f32>::RECOMMENDED_OVERSHOOT };
    let mut solver = Solver::new(&table, store.buffers(), config).unwrap();
    assert!(matches!(solver.step(u32::MAX), radiosity_core::Outcome::Converged { .. }));
    let rho_max = p.scene.materials.iter().map(|m| m.reflectance.max_element()).fold(0.0, f64::max);
    let a_min = area.iter().copied().fold(f64::INFINITY, f64::min);
    let bound = 2.0 * f64::from(table.state_count()) * f64::from(tolerance) / ((1.0 - rho_max) * a_min);
    let mut worst = 0.0f64;
    for (i, b) in before.iter().enumerate() {
        let h = Rgb::from_array(solver.radiosity(i as u32).unwrap().map(f64::from));
        worst = worst.max((*b - h).abs().max_element());
    }
    assert!(worst <= bound, "page vs host simulator: {worst} W/m^2 apart, bound {bound}");

    // Light slider to 0: the picture and the radiosity darken as the exact answer does.
    let lum = |b: &[Rgb]| b.iter().zip(&area).map(|(x, a)| a * luminance(*x)).sum::<f64>();
    let expected = lum(&exact_after) / lum(&exact_before);
    let got = lum(&after) / lum(&before);
    assert!(got <= expected + 0.01, "radiosity after / before: {got}, the exact answer's {expected}");
    let mean = |phase: &str| -> Vec<f64> {
        r[phase]["mean"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    };
    let (m0, m1) = (mean("before"), mean("after"));
    for c in 0..3 {
        assert!(
            m0[c] > 20.0 * m1[c].max(0.5),
            "channel {c}: mean 8-bit value {} before, {} after",
            m0[c],
            m1[c]
        );
    }
    eprintln!(
        "page: {} frames at {budget} units/frame; converged error against the exact f64 answer {error:.3e}; page \
         vs host simulator {worst:.3e} W/m^2 (bound {bound:.3e}); light 0: luminance x {got:.4} (exact x \
         {expected:.4}), canvas mean {m0:.1?} -> {m1:.1?}",
        r["stats"]["frames"]
    );
}
