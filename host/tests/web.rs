//! The browser viewer (`radiosity view SCENE --web DIR`): the device core built as WebAssembly runs a relight
//! script bit for bit as the host simulator does (under Node.js), and the page relights the Cornell box in
//! headless Chromium (WebGL2 through SwiftShader) without console errors, within its per-frame budget, darkening
//! when its light slider goes to 0; its first view is `radiosity render --mode flat`'s picture of the same camera,
//! and its colour and reflectance controls relight as the exact answer and the host simulator do.
//!
//! Both build `radiosity-web` for `wasm32-unknown-unknown` (installing the target with rustup if missing) and use
//! the npm packages of `tests/web` and the system Chromium like the `.glb` checks (`common::web`); when those
//! cannot be had they print why and skip.

mod common;

use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::Duration;

use common::picture::{decode_png, display_range};
use common::web::{chromium, node, serve, wasm, web};
use firmware_sim::device::{run_script, unit_light_power, Frame, NoMeter, Script};
use radiosity_core::{OwnedBuffers, Solver, Table};
use radiosity_host::bake::{bake, decode_table, BakeInput, BakeOptions, Decoded};
use radiosity_host::evaluate::{device_answer, EvaluateOptions};
use radiosity_host::picture::tonemap::srgb_decode;
use radiosity_host::picture::{write_png, ToneMap};
use radiosity_host::pipeline::Prepared;
use radiosity_host::reference::{exact_transfer, Method};
use radiosity_host::rgb::{luminance, Rgb};
use radiosity_host::view::{render_view, RenderMode, RenderOptions};
use radiosity_host::web::{write_viewer, CostModel, TONE_VIEW_SIZE};
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

/// The canvas's side in the browser test: the size whose flat render gave the page its tone map.
const CANVAS: u32 = TONE_VIEW_SIZE;
/// The colour the browser test gives light group 0 (sRGB; linear 1, 0.216, 0.0513).
const COLOUR: &str = "#ff8040";
/// The browser test's reflectance edit: the white material's red channel to this value (from 0.725).
const REFLECTANCE: f64 = 0.3;

/// One phase of `viewer.mjs`'s output: the page's state once converged.
struct Phase {
    /// The solver's radiosity, per patch.
    radiosity: Vec<Rgb>,
    /// Light group 0's intensity as the page gave it to the solver.
    intensity: [f64; 3],
    /// Every material's reflectance as the page gave it to the solver (the table's until edited).
    reflectance: Vec<[f64; 3]>,
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn phase(r: &Value, name: &str) -> Phase {
    let p = &r[name];
    let rgb = |v: &Value| -> [f64; 3] { numbers(v).try_into().unwrap() };
    Phase {
        radiosity: numbers(&p["radiosity"]).chunks_exact(3).map(|c| Rgb::new(c[0], c[1], c[2])).collect(),
        intensity: rgb(&p["intensity"]),
        reflectance: p["reflectance"].as_array().unwrap().iter().map(rgb).collect(),
    }
}

/// The host simulator's converged answer on `table` (f32, the page's tolerance and overshoot), driven through the
/// same sequence of warm starts as the page: converge at the defaults, then per change set it and converge.
/// A change of the solver's settings, as a page control makes it.
type Change<'a> = dyn Fn(&mut Solver<'_, f32>) + 'a;

fn host_simulator(table: &Table<'_>, changes: &[&Change<'_>]) -> Vec<Rgb> {
    let tolerance = TOLERANCE * unit_light_power(table);
    let mut store = OwnedBuffers::<f32>::for_table(table);
    let config =
        radiosity_core::Config { tolerance, overshoot: radiosity_core::Config::<f32>::RECOMMENDED_OVERSHOOT };
    let mut solver = Solver::new(table, store.buffers(), config).unwrap();
    assert!(matches!(solver.step(u32::MAX), radiosity_core::Outcome::Converged { .. }));
    for change in changes {
        change(&mut solver);
        assert!(matches!(solver.step(u32::MAX), radiosity_core::Outcome::Converged { .. }));
    }
    (0..solver.patch_count()).map(|i| Rgb::from_array(solver.radiosity(i).unwrap().map(f64::from))).collect()
}

/// A certified bound, per patch and channel, of how far `b` is from `q`, the exact (f64) solution of the decoded
/// table's own system `dec` (the device's intensities and reflectances), from `b`'s residual alone.
///
/// In power units (`Phi = B A`) the system is `Phi = A rhs + K Phi` with `K_ji = rho_j F_ij >= 0` (`F_ij` the
/// decoded fraction of `i`'s power reaching `j`); decoded rows sum to at most 1 (core's docs), so every column of
/// `K` sums to at most `rho_max < 1`. With `r` the residual of `b` in radiosity units, `d = Phi_q - Phi_b` solves
/// `d = A r + K d`, so `|d| <= y* = (I - K)^-1 A |r|` componentwise. The iteration `y <- A |r| + K y` from 0 rises
/// to `y*`; after it stops with last change `D >= 0`, `y* - y = (I - K)^-1 K D`, whose 1-norm is at most
/// `rho_max ||D||_1 / (1 - rho_max)` and whose entry `j` is at most `rho_j max_i F_ij ||D||_1 / (1 - rho_max)`.
/// So `|q_j - b_j| <= (y_j + rho_j max_i F_ij ||D||_1 / (1 - rho_max)) / A_j`. Nothing here trusts the solver's
/// own convergence test.
fn certified_distance(dec: &Decoded, b: &[Rgb]) -> Vec<Rgb> {
    let n = b.len();
    let response: Vec<Rgb> = b.iter().zip(&dec.base).map(|(x, s)| *x - *s).collect();
    let (mut gathered, mut largest_in) = (vec![Rgb::ZERO; n], vec![0.0f64; n]);
    for (i, b) in response.iter().enumerate() {
        for (j, f) in dec.rows.row(i) {
            gathered[j] += f * dec.area[i] * *b;
            largest_in[j] = largest_in[j].max(f);
        }
    }
    // |r| in power units.
    let residual: Vec<Rgb> = (0..n)
        .map(|j| (dec.rhs[j] + dec.rho[j] * gathered[j] / dec.area[j] - response[j]).abs() * dec.area[j])
        .collect();
    let rho_max = dec.rho.iter().fold(Rgb::ZERO, |m, r| m.max(*r));
    let mut y = vec![Rgb::ZERO; n];
    let mut change = Rgb::ZERO;
    for _ in 0..500 {
        let mut next = residual.clone();
        for (i, yi) in y.iter().enumerate() {
            for (j, f) in dec.rows.row(i) {
                next[j] += dec.rho[j] * f * *yi;
            }
        }
        change = next.iter().zip(&y).map(|(a, b)| *a - *b).sum();
        y = next;
        if change.max_element() <= 1e-12 * y.iter().copied().sum::<Rgb>().max_element() {
            break;
        }
    }
    let tail = change / (Rgb::ONE - rho_max);
    (0..n).map(|j| (y[j] + dec.rho[j] * largest_in[j] * tail) / dec.area[j]).collect()
}

/// Largest per-channel difference of two answers.
fn worst_difference(a: &[Rgb], b: &[Rgb]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (*x - *y).abs().max_element()).fold(0.0, f64::max)
}

/// The page in headless Chromium: loads without console errors (nor failed requests), converges within the
/// budget it shows (read back per frame: never exceeded, and spent in full before convergence), reports the
/// error that the host computes from the page's own radiosity against the exact f64 answer, agrees with the host
/// simulator's converged answer within the convergence bound of core's docs, shows at first what `radiosity
/// render --mode flat` shows from the same camera (see [`first_view_matches_the_flat_render`]), relights through
/// its colour input and reflectance slider as the exact answer and the host simulator do (see
/// [`colour_and_reflectance_controls_relight`]), and moving the light slider to 0 darkens the picture and the
/// radiosity as the exact answer does.
///
/// Convergence bound: the page and the host simulator each stop with every patch's unshot magnitude `<= tol`,
/// so each is within `c = n tol / ((1 - rho_max) A_min)` per patch and channel of the solution of the table's own
/// (quantized) system (core's docs, "Error bounds: convergence"); they are within `2 c` of each other.
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
    let url = format!("http://127.0.0.1:{port}/index.html?budget={budget}&size={CANVAS}x{CANVAS}");
    let out = scratch();
    let white = p.scene.materials.iter().position(|m| m.name == "white").unwrap();
    let args = [
        "viewer.mjs",
        &url,
        out.to_str().unwrap(),
        COLOUR,
        &white.to_string(),
        "0",
        &REFLECTANCE.to_string(),
    ];
    let text = node(dir, &args, Duration::from_secs(300)).unwrap();
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
    let first_converged = frames.iter().position(|f| f["outcome"] == 0).unwrap() + 1;

    // The exact answers before and after, and the page's radiosity.
    let l = &p.lighting;
    let exact = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len())).unwrap();
    let exact_before = exact.relight(&l.default_intensity).unwrap();
    let exact_after = exact.relight(&[Rgb::ZERO]).unwrap();
    let (before, after) = (phase(&r, "before"), phase(&r, "after"));
    assert_eq!(before.radiosity.len(), p.patches.len());
    let area: Vec<f64> = p.patches.iter().map(|x| x.area).collect();
    let rel_l2 = |b: &[Rgb], e: &[Rgb]| {
        let (mut num, mut den) = (0.0, 0.0);
        for ((x, y), a) in b.iter().zip(e).zip(&area) {
            num += a * (*x - *y).length_squared();
            den += a * y.length_squared();
        }
        (num / den).sqrt()
    };
    let error = rel_l2(&before.radiosity, &exact_before);
    let shown = r["before"]["errorVsExact"].as_f64().unwrap();
    assert!((shown - error).abs() <= 1e-9 * error, "the page shows error {shown}, its radiosity has {error}");

    // The host simulator's converged answer on the same table.
    let blob = std::fs::read(site.join("scene.rft")).unwrap();
    let table = Table::parse(&blob).unwrap();
    let tolerance = f64::from(TOLERANCE * unit_light_power(&table));
    let a_min = area.iter().copied().fold(f64::INFINITY, f64::min);
    let convergence = |reflectance: &[[f64; 3]]| {
        let rho_max = reflectance.iter().flatten().copied().fold(0.0, f64::max);
        f64::from(table.state_count()) * tolerance / ((1.0 - rho_max) * a_min)
    };
    let c = convergence(&before.reflectance);
    let host = host_simulator(&table, &[]);
    let worst = worst_difference(&before.radiosity, &host);
    assert!(worst <= 2.0 * c, "page vs host simulator: {worst} W/m^2 apart, bound {}", 2.0 * c);

    // The table's own f64 answer, and the page's certified distance from it.
    let decoded = decode_table(&table);
    let options = EvaluateOptions::for_bake(p.patches.len(), &BakeOptions::default());
    let (_, q, _) = device_answer(&table, &options).unwrap();
    let certified = certified_distance(&decoded, &before.radiosity);
    for (i, ((b, q), e)) in before.radiosity.iter().zip(&q).zip(&certified).enumerate() {
        assert!(
            (*b - *q).abs().cmple(*e).all(),
            "patch {i}: page {b}, table's f64 answer {q}, certified {e}"
        );
    }
    let largest = certified.iter().map(|e| e.max_element()).fold(0.0, f64::max);
    eprintln!(
        "page vs the table's f64 answer: at most {:.3e} W/m^2, certified from its residual {largest:.3e} (core's \
         a-priori convergence bound c = {c:.3e}); table's f64 answer vs exact: {:.3e} W/m^2 at most",
        worst_difference(&before.radiosity, &q),
        worst_difference(&q, &exact_before)
    );
    first_view_matches_the_flat_render(p, &site, &out, &before.radiosity, &exact_before, &q, &certified);
    colour_and_reflectance_controls_relight(&r, &table, &decoded, &exact, &before, &certified, white);

    // Light slider to 0: the picture and the radiosity darken as the exact answer does.
    let lum = |b: &[Rgb]| b.iter().zip(&area).map(|(x, a)| a * luminance(*x)).sum::<f64>();
    let expected = lum(&exact_after) / lum(&exact_before);
    let got = lum(&after.radiosity) / lum(&before.radiosity);
    assert!(got <= expected + 0.01, "radiosity after / before: {got}, the exact answer's {expected}");
    let mean = |phase: &str| numbers(&r[phase]["mean"]);
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
        "page: {} frames at {budget} units/frame, first converged at frame {first_converged}; converged error \
         against the exact f64 answer {error:.3e}; page vs host simulator {worst:.3e} W/m^2 (bound {:.3e}); \
         light 0: luminance x {got:.4} (exact x {expected:.4}), canvas mean {m0:.1?} -> {m1:.1?}",
        r["stats"]["frames"],
        2.0 * c
    );
}

/// The page's first view against the project's render of the same camera and size.
///
/// **What "first view" means.** The page opens at the scene's camera (`scene.json`, the camera `radiosity render`
/// uses) and runs one bounded step per animation frame, so its first frames show the partial answer of shooting
/// from dark. The frame compared is the latest one drawn once the solver has converged at the default
/// intensities, before any input (the first converged frame's number at the test's 3,000 units per frame is
/// printed); the canvas and the radiosity read back are that frame's, read in the same task. The canvas is `CANVAS` pixels square (`?size=`).
///
/// **Same mode.** The page draws every patch in one colour (its radiosity, tone mapped), so it is compared with
/// `radiosity render --mode flat` (the library's [`render_view`] with [`RenderMode::Flat`], what the command
/// calls) at the same size, whose tone map the page was given (asserted equal here). Regions are the patches,
/// over the pixels whose 3 x 3 neighbourhood in the render sees only that patch (the GPU rasterizes edges
/// differently from ray casting); regions under 16 pixels are left out. Per region and channel the mean 8-bit
/// colours are compared, two steps:
///
/// 1. **the page draws what it computed**: the screenshot against the project's tone map of the page's own
///    radiosity (read back), within 1.5 codes: 1 for two roundings of nearly equal values falling on either side
///    of a half code, 0.5 for the GPU's float arithmetic. A wrong camera, tone map, sRGB encoding or patch order
///    fails this step.
/// 2. **what it computed is the render's answer within the table's accuracy**: the render shows the exact f64
///    answer `E`; the page shows its converged table answer `P`, within `e` ([`certified_distance`], from `P`'s
///    residual propagated through the table's system; core's a-priori bound `n tol / ((1 - rho_max) A_min)`,
///    printed, is far looser and would allow any colour) of `Q`, the f64 solution of the table's own system (what `radiosity check` calls the device's
///    answer). So both lie in the box from `min(E, Q - e)` to `max(E, Q + e)` per channel (clamped at 0), whose
///    display values span `[lo, hi]` (the tone map is monotone per channel: `common::picture::display_range`);
///    the 8-bit pixels differ by at most `hi - lo` plus 1 for the two roundings plus 0.5 for the GPU's
///    arithmetic. The box's width is the table's quantization error (`|Q - E|`, from the host alone) and the
///    certified convergence error; nothing in it is fitted to the page's pixels.
fn first_view_matches_the_flat_render(
    p: &Prepared,
    site: &std::path::Path,
    out: &std::path::Path,
    page: &[Rgb],
    exact: &[Rgb],
    table_answer: &[Rgb],
    certified: &[Rgb],
) {
    let options = RenderOptions { camera: None, width: CANVAS, height: CANVAS, mode: RenderMode::Flat };
    let view = render_view(p.surfaces(), exact, &options).unwrap();
    write_png(&out.join("project-flat.png"), &view.image).unwrap();
    let tone: ToneMap = view.tone.unwrap();
    let json: Value = serde_json::from_slice(&std::fs::read(site.join("scene.json")).unwrap()).unwrap();
    assert_eq!(json["tone"]["scale"].as_f64().unwrap(), tone.scale, "the page's exposure");
    assert_eq!(json["tone"]["white"].as_f64().unwrap(), tone.white, "the page's white point");
    let shot = decode_png(&std::fs::read(out.join("viewer-before.png")).unwrap());
    assert_eq!((shot.width, shot.height), (CANVAS, CANVAS), "the page's canvas");

    let n = CANVAS as i64;
    let patch_at = |x: i64, y: i64| -> Option<u32> {
        (x >= 0 && y >= 0 && x < n && y < n).then(|| view.patch[(y * n + x) as usize]).flatten()
    };
    // Per patch: pixels, and the sums of the screenshot's and the render's codes.
    let mut regions: std::collections::BTreeMap<u32, (usize, Rgb, Rgb)> = Default::default();
    for y in 0..n {
        for x in 0..n {
            let Some(patch) = patch_at(x, y) else { continue };
            if !(-1..=1).all(|dy| (-1..=1).all(|dx| patch_at(x + dx, y + dy) == Some(patch))) {
                continue;
            }
            let code = |img: &radiosity_host::picture::RgbImage| {
                Rgb::from_array(img.get(x as u32, y as u32).map(f64::from))
            };
            let r = regions.entry(patch).or_insert((0, Rgb::ZERO, Rgb::ZERO));
            r.0 += 1;
            r.1 += code(&shot);
            r.2 += code(&view.image);
        }
    }
    let mut failures = Vec::new();
    let (mut compared, mut pixels) = (0, 0);
    let (mut worst_own, mut worst, mut sum, mut worst_allowed, mut least_margin) =
        (0.0f64, 0.0f64, 0.0, 0.0f64, f64::INFINITY);
    for (&patch, &(count, shot_sum, render_sum)) in &regions {
        if count < 16 {
            continue;
        }
        let i = patch as usize;
        let (browser, project) = (shot_sum / count as f64, render_sum / count as f64);
        let own = Rgb::from_array(tone.map_srgb8(page[i]).unwrap().map(f64::from));
        let a = exact[i].min(table_answer[i] - certified[i]).max(Rgb::ZERO);
        let b = exact[i].max(table_answer[i] + certified[i]);
        let (lo, hi) = display_range(&tone, a, b);
        let allowed = hi - lo + Rgb::splat(1.5);
        let (off_own, off) = ((browser - own).abs(), (browser - project).abs());
        worst_own = worst_own.max(off_own.max_element());
        worst = worst.max(off.max_element());
        worst_allowed = worst_allowed.max(allowed.max_element());
        least_margin = least_margin.min((allowed - off).min_element());
        sum += off.x + off.y + off.z;
        compared += 1;
        pixels += count;
        if !off_own.cmple(Rgb::splat(1.5)).all() || !off.cmple(allowed).all() {
            failures.push(format!(
                "patch {i} ({count} px): page {browser:.1}, its own answer displayed {own:.0} (off {off_own:.1}, \
                 allowed 1.5), render {project:.1} (off {off:.1}, allowed {allowed:.2})"
            ));
        }
    }
    assert!(compared >= 100, "only {compared} patches large enough to compare");
    assert!(
        failures.is_empty(),
        "the page's first view and the flat render differ:\n{}",
        failures.join("\n")
    );
    eprintln!(
        "first view vs `render --mode flat` ({CANVAS}x{CANVAS}): {compared} patches, {pixels} interior pixels; page \
         vs its own answer displayed at most {worst_own:.2} codes (allowed 1.5); page vs render mean {:.3} codes, \
         at most {worst:.2} (allowed per patch at most {worst_allowed:.2}, least margin {least_margin:.2})",
        sum / (3.0 * compared as f64)
    );
}

/// The colour input and a reflectance slider, changed by input events on the page's elements (`viewer.mjs`).
///
/// **Colour.** The page decodes `#ff8040` from sRGB and multiplies light group 0's default intensity by it (`k`
/// per channel, read back from the page and checked against the decoding here). Against the host simulator set
/// to the same intensity after converging at the defaults, as the page did: per patch and channel within
/// `e_P + e_H`, each answer's certified distance ([`certified_distance`]) from the table's system at that
/// intensity. Against the exact f64 answer relit with that intensity: the table's system and the exact one are
/// linear in the intensity and the scene has no static light (asserted), so with `Q` the table's f64 solution,
/// `Q_k - E_k = k (Q_1 - E_1)` and `|Q_1 - E_1| <= |P_1 - E_1| + e_P1`; hence per patch and channel
/// `|P_k - E_k| <= e_Pk + k (|P_1 - E_1| + e_P1) + 2^-24 |E_k|`, the last term the f32 rounding of the intensity
/// the solver is given.
///
/// **Reflectance.** The white material's red channel set to [`REFLECTANCE`] (read back: the other channels stay
/// the table's). The exact transfer vectors hold for the scene's reflectances only, so the page is checked
/// against the host simulator's `set_reflectance` on the same table after the same colour change: within
/// `e_P + e_H` of each other, certified on the table's system with the edited reflectance.
fn colour_and_reflectance_controls_relight(
    r: &Value,
    table: &Table<'_>,
    decoded: &Decoded,
    exact: &radiosity_host::reference::TransferVectors,
    before: &Phase,
    certified_before: &[Rgb],
    material: usize,
) {
    let exact_before = exact.relight(&[Rgb::from_array(before.intensity)]).unwrap();
    assert!(exact.b_static.iter().all(|b| *b == Rgb::ZERO), "the scene has a static light");
    let (colour, edited) = (phase(r, "colour"), phase(r, "reflectance"));
    let code = |at: usize| f64::from(u8::from_str_radix(&COLOUR[at..at + 2], 16).unwrap());
    let k = Rgb::new(code(1), code(3), code(5)).map(|v| srgb_decode(v / 255.0));
    let default = Rgb::from_array(before.intensity);
    let intensity = Rgb::from_array(colour.intensity);
    assert!(
        (intensity - default * k).abs().max_element() <= 1e-12 * default.max_element(),
        "the page's intensity {intensity} for colour {COLOUR}, expected {}",
        default * k
    );
    let f32s = |v: [f64; 3]| v.map(|x| x as f32);
    let set_colour = |s: &mut Solver<'_, f32>| {
        s.set_light(0, f32s(colour.intensity)).unwrap();
    };
    // The table's system at the page's intensity: every right-hand side is light group 0's (no static light).
    let mut system = decoded.clone();
    let scale =
        Rgb::from_array(colour.intensity.map(|v| f64::from(v as f32))) / Rgb::from_array(before.intensity);
    for rhs in &mut system.rhs {
        *rhs *= scale;
    }
    let host = host_simulator(table, &[&set_colour]);
    let (e_page, e_host) =
        (certified_distance(&system, &colour.radiosity), certified_distance(&system, &host));
    let (mut worst_host, mut largest_colour) = (0.0f64, 0.0f64);
    for i in 0..host.len() {
        let off = (colour.radiosity[i] - host[i]).abs();
        let allowed = e_page[i] + e_host[i];
        largest_colour = largest_colour.max(allowed.max_element());
        assert!(
            off.cmple(allowed).all(),
            "coloured light, patch {i}: page vs host simulator {off}, certified {allowed}"
        );
        worst_host = worst_host.max(off.max_element());
    }
    let exact_k = exact.relight(&[default * k]).unwrap();
    let (mut worst_ratio, mut worst_exact) = (0.0f64, 0.0f64);
    for i in 0..exact_k.len() {
        let allowed = e_page[i]
            + k * ((before.radiosity[i] - exact_before[i]).abs() + certified_before[i])
            + exact_k[i].abs() * f64::from(f32::EPSILON / 2.0);
        let off = (colour.radiosity[i] - exact_k[i]).abs();
        assert!(
            off.cmple(allowed).all(),
            "coloured light, patch {i}: page {}, exact {}, allowed {allowed}",
            colour.radiosity[i],
            exact_k[i]
        );
        worst_exact = worst_exact.max(off.max_element());
        worst_ratio = worst_ratio.max((off / allowed).max_element());
    }
    let shown = r["colour"]["errorVsExact"].as_f64().unwrap();

    // The reflectance slider: only the edited channel moved.
    let mut expected = colour.reflectance.clone();
    expected[material][0] = REFLECTANCE;
    assert_eq!(edited.reflectance, expected, "the reflectances the page gave the solver");
    let set_reflectance = |s: &mut Solver<'_, f32>| {
        s.set_reflectance(material as u32, f32s(edited.reflectance[material])).unwrap();
    };
    let host_edited = host_simulator(table, &[&set_colour, &set_reflectance]);
    let rho = Rgb::from_array(f32s(edited.reflectance[material]).map(f64::from));
    for (i, r) in system.rho.iter_mut().enumerate() {
        if table.material(i as u32) == Some(material as u32) {
            *r = rho;
        }
    }
    let (e_page, e_host) =
        (certified_distance(&system, &edited.radiosity), certified_distance(&system, &host_edited));
    let (mut worst_edited, mut largest_edited) = (0.0f64, 0.0f64);
    for i in 0..host_edited.len() {
        let off = (edited.radiosity[i] - host_edited[i]).abs();
        let allowed = e_page[i] + e_host[i];
        assert!(
            off.cmple(allowed).all(),
            "reflectance edit, patch {i}: page vs host simulator {off}, certified {allowed}"
        );
        worst_edited = worst_edited.max(off.max_element());
        largest_edited = largest_edited.max(allowed.max_element());
    }
    // The edit shows: the white surfaces lost red against green.
    let red_share = |b: &[Rgb]| b.iter().map(|x| x.x).sum::<f64>() / b.iter().map(|x| x.y).sum::<f64>();
    assert!(
        red_share(&edited.radiosity) < red_share(&colour.radiosity),
        "the red reflectance edit shows no change"
    );
    eprintln!(
        "colour {COLOUR} (k = {k:.4}): page vs exact relit at most {worst_exact:.3e} W/m^2 ({worst_ratio:.3} of its \
         bound; error shown {shown:.3e}), vs host simulator {worst_host:.3e} (certified at most {largest_colour:.3e}); white red \
         reflectance -> {REFLECTANCE}: page vs host simulator {worst_edited:.3e} W/m^2 (certified at most \
         {largest_edited:.3e})"
    );
}
