//! `radiosity check` on the Cornell box (bake path and table path), wrong-scene tables, and the quantization
//! regression against the checked-in baseline (including a codec degraded on purpose).

use std::path::PathBuf;

use radiosity_core::{FfCodec, Table};
use radiosity_host::bake::{bake, BakeInput, BakeOptions};
use radiosity_host::check::{
    check, check_table, form_factor_distance, CheckError, CheckOptions, CheckReport, WRONG_SCENE_FRACTION,
};
use radiosity_host::evaluate::{QUANTIZATION, RECIPROCITY, SPARSIFICATION, TABLE_VS_SCENE};
use radiosity_host::mesh::{mesh, MeshOptions};
use radiosity_host::pipeline::{prepare, PrepareOptions, Prepared};
use radiosity_host::regress::{self, CheckSelection};
use radiosity_host::scene::Scene;

fn scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name)
}

/// Small, fast settings: the scene's default meshing, 4 samples and 4 rays per pair.
fn options(seed: u64) -> PrepareOptions {
    let mut options = PrepareOptions::quiet(false, 4, 4);
    options.form_factors.seed = seed;
    options
}

/// The Cornell box prepared at `options(1)`, with those options.
fn cornell() -> (PrepareOptions, Prepared) {
    let po = options(1);
    let p = prepare(&scene("cornell-box.obj"), &po).expect("prepare");
    (po, p)
}

fn component(r: &CheckReport, name: &str) -> f64 {
    r.components.iter().find(|c| c.name == name).unwrap_or_else(|| panic!("no component {name}")).error.rel_l2
}

fn bake_bytes(p: &Prepared, codec: FfCodec) -> Vec<u8> {
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    bake(&input, &BakeOptions { codec, ..BakeOptions::default() }).expect("bake").table
}

/// The Cornell box's decomposition: every component finite, 8-bit quantization coarser than 16-bit, 16-bit
/// quantization within the codec's bound, and the device error within the sum of its components.
#[test]
fn cornell_decomposition_is_consistent() {
    let (po, p) = cornell();
    let opts = CheckOptions { ff_factor: 2, ..CheckOptions::default() };
    let r16 = check(&p, &po, &opts).expect("check 16");
    let r8 =
        check(&p, &po, &CheckOptions { bits: 8, row_sum_tolerance: 1e-4 + 2f64.powi(-5), ..opts.clone() })
            .expect("check 8");
    for r in [&r16, &r8] {
        for c in &r.components {
            assert!(c.error.rel_l2.is_finite() && c.error.rel_l2 >= 0.0, "{}: {}", c.name, c.error.rel_l2);
            assert!(c.error.max_rel.is_finite(), "{}: {}", c.name, c.error.max_rel);
        }
    }
    // The decomposition plot: one group per arithmetic path, every component a bar of its own (L2 norms do not
    // add, so nothing is stacked), then the measured total, which is at most the components' sum (triangle
    // inequality, with the slack of the telescoping check below); and it draws.
    let plot = r16.decomposition_plot("Cornell box");
    let radiosity_host::picture::plot::Plot::GroupedBars { categories, components, .. } = &plot else {
        panic!("not bars")
    };
    assert_eq!(categories, &["f32", "fixed"]);
    let (total_name, total) = components.last().expect("a total bar");
    assert!(total_name.starts_with("total"), "{total_name}");
    for (k, arith) in categories.iter().enumerate() {
        let device = r16.settings.iter().find(|s| s.setting == 0 && s.arith.to_string() == *arith).unwrap();
        assert_eq!(total[k], device.error.rel_l2, "{arith}: the total bar is the measured device error");
        let sum: f64 = components[..components.len() - 1].iter().map(|(_, v)| v[k]).sum();
        assert!(
            total[k] <= sum * (1.0 + sum) * (1.0 + 1e-9) + 1e-12,
            "{arith}: total {} over sum {sum}",
            total[k]
        );
    }
    let own = |name: &str| components.iter().find(|(n, _)| n == name).map(|(_, v)| v.clone()).unwrap();
    assert_eq!(
        own("arithmetic"),
        [component(&r16, "arithmetic (f32)"), component(&r16, "arithmetic (fixed)")]
    );
    assert_eq!(own(QUANTIZATION), [component(&r16, QUANTIZATION); 2]);
    let svg = plot.to_svg(400, 300).expect("svg");
    assert!(svg.contains("<svg") && svg.contains("not the sum"), "the plot says the bars do not add");
    // Expected order: a 5-bit mantissa quantizes coarser than a 12-bit one.
    let (q16, q8) = (component(&r16, QUANTIZATION), component(&r8, QUANTIZATION));
    assert!(q8 > q16, "quantization 8-bit {q8} not above 16-bit {q16}");
    // Bound of the 16-bit component: emission codes round to 2^-11 relative, reflectance codes to 2^-17
    // absolute, form-factor codes to < 2^-12 relative (core's codec docs); a relative perturbation d of R F
    // moves B by at most d * rho_max / (1 - rho_max) relative (Neumann series of (I - R F)^-1).
    let rho_max = p.lighting.rho.iter().flat_map(|r| r.to_array()).fold(0.0, f64::max);
    let rho_min = p.lighting.rho.iter().flat_map(|r| r.to_array()).filter(|&r| r > 0.0).fold(1.0, f64::min);
    let d = 2f64.powi(-12) + 2f64.powi(-17) / rho_min;
    let bound = 2f64.powi(-11) + d * rho_max / (1.0 - rho_max);
    assert!(q16 <= bound, "16-bit quantization {q16} above its bound {bound}");
    // Device (converged, so no truncation) minus exact telescopes into arithmetic + quantization +
    // sparsification + reciprocity; each component is relative to its own reference, whose norm is within a
    // factor (1 + S) of the exact one (S = sum of the components), hence the slack S (1 + S), plus the f64
    // solves' rounding (8 n eps).
    for (arith, setting) in r16.settings.iter().map(|s| (s.arith, s)) {
        let s = component(&r16, &format!("arithmetic ({arith})"))
            + component(&r16, QUANTIZATION)
            + component(&r16, SPARSIFICATION)
            + component(&r16, RECIPROCITY);
        let allowed = s * (1.0 + s) + 8.0 * r16.patches as f64 * f64::EPSILON;
        assert!(setting.converged, "{arith} did not converge");
        assert!(
            setting.error.rel_l2 <= allowed,
            "{arith}: device error {} above the sum of its components {allowed}",
            setting.error.rel_l2
        );
    }
}

/// `check TABLE --scene SCENE`: the table baked from the scene checks with the same device answers as the
/// bake path, and its table-vs-scene component is within the sum of the components it merges.
#[test]
fn table_input_matches_bake_path() {
    let (po, p) = cornell();
    let opts = CheckOptions { ff_factor: 1, ..CheckOptions::default() };
    let from_scene = check(&p, &po, &opts).expect("check scene");
    let bytes = bake_bytes(&p, FfCodec::FLOAT16);
    let from_table = check_table(&bytes, &p, &opts).expect("check table");
    // Both name the light group, in the group list and the settings' intensity column.
    for report in [&from_scene, &from_table] {
        assert_eq!(report.light_groups, vec!["light".to_owned()]);
        let text = report.to_string();
        assert!(
            text.contains("light groups (table order): light\n") && text.contains("intensity (light)"),
            "{text}"
        );
    }
    // Same table bytes, same solver: identical device answers.
    for name in ["arithmetic (f32)", "arithmetic (fixed)"] {
        assert_eq!(component(&from_scene, name), component(&from_table, name), "{name}");
    }
    let merged = component(&from_scene, QUANTIZATION)
        + component(&from_scene, SPARSIFICATION)
        + component(&from_scene, RECIPROCITY);
    let t = component(&from_table, TABLE_VS_SCENE);
    assert!(t <= merged * (1.0 + merged) + 8.0 * p.patches.len() as f64 * f64::EPSILON, "{t} > {merged}");
    // A different seed for the scene's matrix is still the same scene. With one patch per face the seed only
    // moves the form factors (adaptive meshing would also move the patches, which is a different table).
    let fixed_mesh = |seed| PrepareOptions { no_subdivide: true, ..options(seed) };
    let p1 = prepare(&scene("cornell-box.obj"), &fixed_mesh(1)).expect("prepare seed 1");
    let p2 = prepare(&scene("cornell-box.obj"), &fixed_mesh(2)).expect("prepare seed 2");
    let bytes = bake_bytes(&p1, FfCodec::FLOAT16);
    let table = Table::parse(&bytes).expect("parse");
    let same = form_factor_distance(&table, &p2);
    println!("form-factor distance, same scene, other seed: {same:.3e}");
    assert!(same < WRONG_SCENE_FRACTION, "{same}");
    check_table(&bytes, &p2, &opts).expect("same scene, other seed");
}

/// Tables of another scene are rejected with a message naming the difference: a different patch count, and
/// the same patch attributes with other geometry (facing vs perpendicular squares).
#[test]
fn wrong_scene_tables_are_rejected() {
    let po = options(1);
    let cornell = prepare(&scene("cornell-box.obj"), &po).expect("prepare");
    let closed = prepare(&scene("cornell-box-closed.obj"), &po).expect("prepare");
    let opts = CheckOptions { ff_factor: 1, ..CheckOptions::default() };
    match check_table(&bake_bytes(&cornell, FfCodec::FLOAT16), &closed, &opts) {
        // Both meshes fill the same patch budget, so the first difference is a patch's area (or their count).
        Err(CheckError::WrongScene { detail, .. }) => assert!(detail.contains("patch"), "{detail}"),
        other => panic!("expected a wrong-scene error, got {other:?}"),
    }
    // Uniform meshes (a patch budget equal to the uniform mesh's count leaves adaptive refinement nothing to
    // split), so both pairs have the same patches and only their geometry differs.
    let uniform = |name: &str| {
        let s = Scene::load(scene(name)).expect("load");
        let n = mesh(&s, &MeshOptions::for_scene(&s)).expect("mesh").patches.len();
        prepare(&scene(name), &PrepareOptions { max_patches: Some(n), ..options(1) }).expect("prepare")
    };
    let facing = uniform("facing-squares.obj");
    let perpendicular = uniform("perpendicular-squares.obj");
    assert_eq!(facing.patches.len(), perpendicular.patches.len());
    match check_table(&bake_bytes(&facing, FfCodec::FLOAT16), &perpendicular, &opts) {
        Err(e @ CheckError::WrongScene { .. }) => {
            let msg = e.to_string();
            println!("{msg}");
            assert!(msg.contains("form factors differ"), "{msg}");
        }
        other => panic!("expected a wrong-scene error, got {other:?}"),
    }
    // Damaged bytes are a parse error, not a wrong scene.
    let mut bytes = bake_bytes(&facing, FfCodec::FLOAT16);
    bytes.truncate(bytes.len() / 2);
    assert!(matches!(check_table(&bytes, &facing, &opts), Err(CheckError::BadTable { .. })));
}

fn baseline() -> regress::Baseline {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/baseline/quantization.json");
    regress::read_baseline(&path).expect("baseline (regenerate: radiosity regress --update)")
}

/// The quantization regression: every shipped scene and codec within baseline + k * noise + floor, and every
/// shipped scene in the baseline. Prints the table (`cargo test -- --nocapture`).
#[test]
fn quantization_regression() {
    let b = baseline();
    let report =
        regress::check_baseline(&b, &scene(""), &CheckSelection::default()).expect("regression runs");
    println!("{report}");
    assert!(!report.rows.is_empty());
    assert!(report.passed(), "regression failed:\n{report}");
}

/// Degrading a codec on purpose (LINEAR8 in place of FLOAT16) is caught by the regression check, on the
/// quantization component or as a decoded table the f64 solve refuses.
#[test]
fn degraded_codec_is_caught() {
    let b = baseline();
    let selection = CheckSelection {
        scene: Some("cornell-box.obj".into()),
        bits: Some(16),
        codec: Some(FfCodec::LINEAR8),
    };
    let report = regress::check_baseline(&b, &scene(""), &selection).expect("regression runs");
    println!("{report}");
    assert!(!report.passed(), "LINEAR8 in place of FLOAT16 passed:\n{report}");
    // Caught either on the quantization component or, when the coarser codes push a decoded incoming row's sum
    // past 1, by the bake refusing the codec as too coarse for the scene; either way the failure names the codes.
    assert!(
        report.failures().iter().any(|r| r.component == QUANTIZATION
            || r.component.contains("(decoded table)")
            || r.component.contains("form-factor codes are too coarse")),
        "neither quantization nor the decoded table among the failures:\n{report}"
    );
    // The same selection with the baseline's own codec passes (the failure is the codec's doing).
    let honest = CheckSelection { codec: None, ..selection };
    assert!(regress::check_baseline(&b, &scene(""), &honest).expect("runs").passed());
}

/// `regress` ships every scene of the folder, glTF (`.gltf`, `.glb`, any case) as well as OBJ, and nothing
/// else (MTL, TOML, a glTF's `.bin` buffer); a shipped glTF scene missing from the baseline is a problem that
/// names it, like an OBJ one.
#[test]
fn regress_scans_gltf_scenes_too() {
    let dir = std::env::temp_dir().join(format!("radiosity-regress-scan-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["a.obj", "a.mtl", "a.toml", "b.gltf", "b.bin", "c.glb", "D.GLB", "e.png", "f.obj.txt"] {
        std::fs::write(dir.join(name), b"").unwrap();
    }
    std::fs::create_dir(dir.join("g.glb")).unwrap(); // a folder, not a scene
    let names = regress::scene_files(&dir).unwrap();
    assert_eq!(names, ["D.GLB", "a.obj", "b.gltf", "c.glb"]);
    // No entry to measure: the check only lists what the baseline lacks.
    let empty = regress::Baseline { about: String::new(), seeds: 5, k: 0.0, entries: Vec::new() };
    let report = regress::check_baseline(&empty, &dir, &CheckSelection::default()).unwrap();
    assert!(!report.passed());
    for name in &names {
        for bits in regress::CODECS {
            let want = format!("{name} ({bits}-bit) is shipped but not in the baseline");
            assert!(report.problems.iter().any(|p| p.starts_with(&want)), "{want}: {:?}", report.problems);
        }
    }
    assert_eq!(report.problems.len(), 2 * names.len(), "{:?}", report.problems);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The noise multiplier is the derived prediction-interval factor.
#[test]
fn noise_multiplier_is_derived() {
    let k = regress::noise_multiplier(5).expect("5 seeds");
    assert!((k - 4.604 * 1.2f64.sqrt()).abs() < 1e-12, "{k}");
    assert!(regress::noise_multiplier(1).is_none());
}

/// The discretization component is opt-in; with it, the check reports one row per OBJ face: the exact f64
/// answer of the mesh averaged over the face's patches by area, next to the continuous reference (the same
/// run `montecarlo::continuous_reference` gives for those options: it is deterministic), their relative
/// difference and the reference's standard error; the component itself (metrics over faces) comes first.
#[test]
fn discretization_component_compares_face_averages_with_the_continuous_reference() {
    use radiosity_host::evaluate::{exact, EvaluateOptions, DISCRETIZATION};
    use radiosity_host::metrics::compare;
    use radiosity_host::montecarlo::{continuous_reference, ReferenceOptions, SampleCount};
    use radiosity_host::reference::Method;
    use radiosity_host::rgb::Rgb;
    assert_eq!(CheckOptions::default().continuous, None, "off by default");
    let (po, p) = cornell();
    let continuous = ReferenceOptions {
        samples: SampleCount::PerFace(512),
        progress: false,
        ..ReferenceOptions::default()
    };
    let opts = CheckOptions {
        ff_factor: 1,
        arith: vec![firmware_sim::sim::Arith::F32],
        continuous: Some(continuous.clone()),
        ..CheckOptions::default()
    };
    let r = check(&p, &po, &opts).expect("check");
    let d = r.discretization.as_ref().expect("rows");
    assert_eq!(r.components[0], d.component);
    assert_eq!(d.component.name, DISCRETIZATION);
    let reference = continuous_reference(&p.scene, &continuous).unwrap();
    // The check's exact answer, solved the same way (dense LU at the check's slack).
    let eval = EvaluateOptions {
        method: Method::for_size(p.patches.len()),
        row_sum_tolerance: opts.row_sum_tolerance,
    };
    let (b, _) = exact(&p.lighting, &p.form_factors, &eval).unwrap();
    assert_eq!(d.faces.len(), p.scene.faces.len());
    let (mut mesh, mut area) = (Vec::new(), Vec::new());
    for (row, want) in d.faces.iter().zip(&reference.faces) {
        let (mut a, mut sum) = (0.0, Rgb::ZERO);
        for (q, v) in p.patches.iter().zip(&b) {
            if q.face == row.face {
                a += q.area;
                sum += q.area * *v;
            }
        }
        // Area the patches do not cover (culled by mesh repair: nothing sees it) counts with B = E, as in the
        // reference, which samples whole faces. Sums of the same terms in the same order: equal to the bit.
        let hidden = (want.area - a).max(0.0);
        assert_eq!(row.mesh, (sum + hidden * want.emission) / (a + hidden), "face {}", row.face);
        assert_eq!((row.reference, row.reference_standard_error), (want.radiosity, want.standard_error));
        assert_eq!(row.relative_difference, (row.mesh - row.reference) / row.reference);
        assert_eq!(row.source, p.scene.faces[row.face].place());
        mesh.push(row.mesh);
        area.push(a);
    }
    let faces: Vec<Rgb> = reference.faces.iter().map(|f| f.radiosity).collect();
    assert_eq!(d.component.error, compare(&mesh, &faces, &area).unwrap());
    let text = r.to_string();
    assert!(text.contains("discretization per face") && text.contains(&d.reference_summary), "{text}");
    assert!(text.contains(&format!("  {}\n", p.scene.faces[1].place())), "rows name their faces: {text}");
}

/// Bad options of the continuous reference are refused by the check before any work.
#[test]
fn check_refuses_bad_continuous_options() {
    use radiosity_host::montecarlo::{MonteCarloError, ReferenceOptions, SampleCount};
    let (po, p) = cornell();
    let continuous = ReferenceOptions { samples: SampleCount::PerFace(0), ..ReferenceOptions::default() };
    let opts = CheckOptions { continuous: Some(continuous), ..CheckOptions::default() };
    match check(&p, &po, &opts) {
        Err(CheckError::MonteCarlo(MonteCarloError::InvalidOption { name: "samples", .. })) => {}
        other => panic!("expected a samples error, got {:?}", other.map(|r| r.patches)),
    }
}
