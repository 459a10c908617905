//! Relight scripts through the device loop on the host, every frame against the exact f64 answer
//! (`radiosity relight`), on the Cornell box with one patch per face.

use std::path::{Path, PathBuf};

use radiosity_host::bake::{bake, BakeInput, BakeOptions};
use radiosity_host::evaluate::{evaluate, EvaluateOptions};
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::pipeline::{prepare, PrepareOptions, Prepared};
use radiosity_host::relight::{self, RelightError, RelightOptions};

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name)
}

fn prepared(name: &str) -> Prepared {
    let options = PrepareOptions {
        no_subdivide: true,
        max_patch_edge: None,
        max_patches: None,
        repair: true,
        form_factors: FormFactorOptions { progress: false, ..FormFactorOptions::default() },
        verbose: false,
    };
    prepare(&scene(name), &options).unwrap()
}

/// The relative L2 error the bake introduced at the default intensities (its evaluation's sparsify + quantize).
fn sparsify_quantize(input: &BakeInput<'_>, baked: &radiosity_host::bake::Baked) -> f64 {
    let options = EvaluateOptions::for_bake(input.patches.len(), &BakeOptions::default());
    evaluate(input, baked, &options).unwrap().errors.sparsify_quantize.rel_l2
}

/// A scripts file in a fresh temporary folder.
fn scripts_file(tag: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-relight-test-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scripts.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Tolerance of the scripts below (relative to the lights' total power at unit intensity).
const TOLERANCE: f64 = 1e-7;

const SCRIPTS: &str = r#"
[[script]]
name = "on-dim-colour"
description = "Dark, then on, dimmed and coloured; every frame has the budget to converge."
tolerance = 1e-7
budget = 2000000
initial = [[0.0, 0.0, 0.0]]
[[script.frame]]
intensity = [[1.0, 1.0, 1.0]]
[[script.frame]]
intensity = [[0.25, 0.25, 0.25]]
[[script.frame]]
intensity = [[1.0, 0.5, 0.1]]

[[script]]
name = "starved"
description = "On from dark with a budget far too small to converge."
tolerance = 1e-7
budget = 40
initial = [[0.0, 0.0, 0.0]]
[[script.frame]]
intensity = [[1.0, 1.0, 1.0]]
[[script.frame]]
repeat = 3
"#;

#[test]
fn converged_frames_match_f64_within_the_bake_error_and_starved_frames_do_not() {
    let p = prepared("cornell-box.obj");
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions::default()).unwrap();
    let error = sparsify_quantize(&input, &baked);
    let path = scripts_file("converge", SCRIPTS);
    let report =
        relight::relight(&p, &baked.table, Path::new("unused.rft"), &path, &RelightOptions::default())
            .unwrap();
    assert_eq!(report.frames.len(), 2 * (3 + 4), "3 + 4 frames, f32 and fixed");
    assert!(report.qemu.is_empty());

    // A converged frame differs from the exact answer by what the bake introduced (sparsify + quantize, measured
    // by the bake at the default intensities; relative errors scale with the light, so the same bound holds for
    // any intensity of the one group), plus the arithmetic (f32: ~n * 2^-24 per sum, ~1e-5 here) and the unshot
    // power left at the stopping tolerance: each patch may keep TOLERANCE of the light's power, n patches, and
    // it would have been amplified by at most 1 / (1 - rho_max) with rho_max < 0.8 in this scene.
    let n = p.patches.len() as f64;
    let bound = error + 1e-5 + n * TOLERANCE / (1.0 - 0.8);
    for r in report.frames.iter().filter(|r| r.script == "on-dim-colour") {
        assert!(r.converged, "{} frame {} ({}) did not converge", r.script, r.frame, r.arith);
        assert!(r.used < r.budget);
        assert!(
            r.error.rel_l2 <= bound,
            "{} frame {} ({}): error {:e} above the bound {bound:e}",
            r.script,
            r.frame,
            r.arith,
            r.error.rel_l2
        );
    }
    // Starved: with one patch per face a shot costs about one unit per receiving patch (~18 here), so 40 units
    // buy two shots a frame; eight shots cannot carry the interreflections of a box with walls of reflectance
    // up to 0.8, so the error after 4 frames stays far above the converged bound and the test sees it.
    let starved: Vec<_> = report
        .frames
        .iter()
        .filter(|r| r.script == "starved" && r.arith == firmware_sim::sim::Arith::F32)
        .collect();
    assert_eq!(starved.len(), 4);
    assert!(starved.iter().all(|r| !r.converged && r.used <= 40));
    let last = starved.last().unwrap();
    assert!(
        last.error.rel_l2 > 10.0 * bound,
        "starved error {:e} not above 10x {bound:e}",
        last.error.rel_l2
    );
    assert!(last.error.rel_l2 < starved[0].error.rel_l2, "error did not fall over the starved frames");
    // Error series for the plot: one per script and arithmetic, work increasing.
    let series = report.error_series();
    assert_eq!(series.len(), 4);
    for s in &series {
        assert!(s.points.windows(2).all(|w| w[1].0 > w[0].0), "{}: work not increasing", s.name);
    }
    // CSV: header plus one line per row.
    assert_eq!(report.to_csv().lines().count(), 1 + report.frames.len());

    // The same scripts naming the light group (`{ light = [...] }`) run the same frames, and the report names
    // the group.
    let named = scripts_file("named", &named_scripts(SCRIPTS));
    assert_ne!(named_scripts(SCRIPTS), SCRIPTS);
    let by_name =
        relight::relight(&p, &baked.table, Path::new("unused.rft"), &named, &RelightOptions::default())
            .unwrap();
    assert_eq!(by_name.frames, report.frames);
    assert_eq!(by_name.light_groups, vec!["light".to_owned()]);
    assert!(by_name.to_string().contains("light groups (table order): light\n"), "{by_name}");
}

/// `text` with every one-group intensity `[[r, g, b]]` written by name, `{ light = [r, g, b] }`.
fn named_scripts(text: &str) -> String {
    text.lines()
        .map(|line| match line.split_once(" = [[") {
            Some((key, rest)) => {
                format!("{key} = {{ light = [{}] }}", rest.strip_suffix("]]").unwrap_or(rest))
            }
            None => line.to_owned(),
        })
        .map(|line| line + "\n")
        .collect()
}

#[test]
fn a_table_of_another_scene_and_bad_scripts_are_refused_by_name() {
    let cornell = prepared("cornell-box.obj");
    let furnace = prepared("furnace.obj");
    let input =
        BakeInput::from_scene(&furnace.scene, &furnace.patches, &furnace.lighting, &furnace.form_factors);
    let furnace_table = bake(&input, &BakeOptions::default()).unwrap().table;
    let path = scripts_file("mismatch", SCRIPTS);
    let err =
        relight::relight(&cornell, &furnace_table, Path::new("t.rft"), &path, &RelightOptions::default())
            .unwrap_err();
    assert!(matches!(err, RelightError::Mismatch(_)), "{err}");
    assert!(err.to_string().contains("patches"), "{err}");

    let input =
        BakeInput::from_scene(&cornell.scene, &cornell.patches, &cornell.lighting, &cornell.form_factors);
    let table = bake(&input, &BakeOptions::default()).unwrap().table;
    let options = RelightOptions { only: Some("nope".into()), ..RelightOptions::default() };
    let err = relight::relight(&cornell, &table, Path::new("t.rft"), &path, &options).unwrap_err();
    assert!(err.to_string().contains("no script named \"nope\""), "{err}");
    let two_groups = scripts_file(
        "groups",
        "[[script]]\nname = \"x\"\ntolerance = 1e-4\nbudget = 10\ninitial = [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]\n\
         [[script.frame]]\nrepeat = 1\n",
    );
    let err = relight::relight(&cornell, &table, Path::new("t.rft"), &two_groups, &RelightOptions::default())
        .unwrap_err();
    assert!(matches!(err, RelightError::Scripts { .. }), "{err}");
    assert!(err.to_string().contains("the table has 1 light groups (\"light\")"), "{err}");
    // A name the scene does not have: the error lists the table's groups by their scene names.
    let unknown = scripts_file("unknown", &named_scripts(SCRIPTS).replace("light = [", "lamp = ["));
    let err = relight::relight(&cornell, &table, Path::new("t.rft"), &unknown, &RelightOptions::default())
        .unwrap_err();
    assert!(err.to_string().contains("the table has no light group \"lamp\""), "{err}");
    assert!(err.to_string().contains("its light groups: \"light\""), "{err}");
}

#[test]
fn device_answer_is_converged_and_close_to_f64() {
    let p = prepared("cornell-box.obj");
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions::default()).unwrap();
    let intensity: Vec<[f32; 3]> =
        p.lighting.default_intensity.iter().map(|v| v.as_vec3().to_array()).collect();
    let device = relight::device_answer(&baked.table, &intensity).unwrap();
    let exact = radiosity_host::view::solve_default(&p).unwrap();
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let e = radiosity_host::metrics::compare(&device, &exact, &area).unwrap();
    // As above, with the tolerance of device_answer.
    let n = p.patches.len() as f64;
    let bound =
        sparsify_quantize(&input, &baked) + 1e-5 + n * f64::from(relight::CONVERGED_TOLERANCE) / (1.0 - 0.8);
    assert!(e.rel_l2 <= bound, "device error {:e} above {bound:e}", e.rel_l2);
    assert!(relight::device_answer(&baked.table[..baked.table.len() - 1], &intensity).is_err());
}
