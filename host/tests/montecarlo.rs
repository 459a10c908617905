//! The continuous reference (`radiosity_host::montecarlo`) against closed forms: the white furnace, facing and
//! perpendicular unit squares, and parallel rectangles in an open scene; determinism across thread counts; bad
//! options; point probes (the furnace, a point opposite a square) and bad probes.
//!
//! Every comparison allows 3 standard errors of the estimate (the reference's own, per channel), plus the
//! closed form's tabulated precision where the expected value comes from a table: the chance that a correct
//! estimator lands outside 3 standard errors is 0.27 % per comparison. The standard error is that of the
//! per-face sample mean (conservative under stratification), so the bound does not shrink with luck.

mod common;

use std::path::PathBuf;

use radiosity_host::formfactor::occluder_bvh;
use radiosity_host::montecarlo::{
    continuous_reference, continuous_reference_with, probe_radiosity, reference_patches, ContinuousReference,
    MonteCarloError, Probe, ReferenceOptions, SampleCount,
};
use radiosity_host::rgb::Rgb;
use radiosity_host::scene::Scene;

/// Writes `obj` (with an `mtllib` line) and `mtl` into a fresh folder and loads the scene.
fn scene(name: &str, obj: &str, mtl: &str) -> Scene {
    let dir: PathBuf =
        std::env::temp_dir().join(format!("radiosity-montecarlo-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(format!("{name}.mtl")), mtl).unwrap();
    std::fs::write(dir.join(format!("{name}.obj")), format!("mtllib {name}.mtl\n{obj}")).unwrap();
    let s = Scene::load(dir.join(format!("{name}.obj"))).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    s
}

fn options(samples: u64) -> ReferenceOptions {
    ReferenceOptions {
        samples: SampleCount::PerFace(samples),
        progress: false,
        ..ReferenceOptions::default()
    }
}

/// Asserts that face `face` of `r` is within 3 standard errors plus `slack` of `expected` in every channel.
fn assert_within(r: &ContinuousReference, face: usize, expected: Rgb, slack: f64) {
    let f = &r.faces[face];
    for c in 0..3 {
        let (got, se) = (f.radiosity[c], f.standard_error[c]);
        let allowed = 3.0 * se + slack;
        assert!(
            (got - expected[c]).abs() <= allowed,
            "face {face} channel {c}: B {got} vs expected {}: difference {:.3e} > allowed {allowed:.3e} \
             (3 x SE {se:.3e} + {slack:.1e})",
            expected[c],
            (got - expected[c]).abs()
        );
    }
}

/// The white furnace: a closed cube, `rho` and `E` uniform, so `B = E / (1 - rho)` exactly on every face (the
/// continuous solution is uniform). At `rho = 0.9` (the shipped scene) and at `rho = 0.99` (a generated copy),
/// where paths are about a hundred bounces long.
#[test]
fn white_furnace_matches_e_over_one_minus_rho() {
    let shipped = Scene::load(common::scene("furnace.obj")).unwrap();
    let r = continuous_reference(&shipped, &options(4096)).unwrap();
    assert_eq!(r.faces.len(), 6);
    for f in 0..6 {
        assert_within(&r, f, Rgb::splat(10.0), 0.0);
        // The estimate means something: a few percent at this sample count.
        assert!(r.faces[f].relative_standard_error < 0.05, "{}", r.faces[f].relative_standard_error);
    }
    let obj =
        std::fs::read_to_string(common::scene("furnace.obj")).unwrap().replace("mtllib furnace.mtl", "");
    let s = scene("furnace99", &obj, "newmtl furnace\nKd 0.99 0.99 0.99\nKe 1 1 1\n");
    let r = continuous_reference(&s, &options(1024)).unwrap();
    for f in 0..6 {
        assert_within(&r, f, Rgb::splat(100.0), 0.0);
        assert!(r.faces[f].relative_standard_error < 0.1, "{}", r.faces[f].relative_standard_error);
    }
}

/// Facing unit squares at distance 1 with an emitter that reflects nothing: nothing comes back to the emitter,
/// so its `B` is its `E` exactly, and the receiver's area-averaged `B` is `rho F E` exactly, `F = 0.199825`
/// (Howell's catalog, directly opposed squares). The table's 6 decimals allow `rho E * 5e-7` more.
#[test]
fn facing_squares_first_bounce_matches_the_closed_form() {
    let obj = std::fs::read_to_string(common::scene("facing-squares.obj"))
        .unwrap()
        .replace("mtllib facing-squares.mtl", "");
    let s = scene("facing", &obj, "newmtl emitter\nKd 0 0 0\nKe 1 1 1\nnewmtl grey\nKd 0.5 0.5 0.5\n");
    let r = continuous_reference(&s, &options(20_000)).unwrap();
    assert_eq!(r.faces[0].radiosity, Rgb::ONE, "the emitter reflects nothing");
    assert_within(&r, 1, Rgb::splat(0.5 * 0.199825), 0.5 * 5e-7);
    assert!(r.faces[1].relative_standard_error < 0.01, "{}", r.faces[1].relative_standard_error);
}

/// Perpendicular unit squares sharing an edge, emitter reflecting nothing: the receiver's `B` is `rho F E`,
/// `F = 0.200044` (Howell's catalog, perpendicular rectangles with a common edge; 6 decimals). The receiver
/// touches the emitter, where light sampling alone has unbounded variance; this runs on the pure-Rust caster.
#[test]
fn perpendicular_squares_first_bounce_matches_the_closed_form() {
    let obj = std::fs::read_to_string(common::scene("perpendicular-squares.obj"))
        .unwrap()
        .replace("mtllib perpendicular-squares.mtl", "");
    let s = scene("perpendicular", &obj, "newmtl emitter\nKd 0 0 0\nKe 1 1 1\nnewmtl grey\nKd 0.5 0.5 0.5\n");
    let bvh = occluder_bvh(&reference_patches(&s).unwrap()).unwrap();
    let r = continuous_reference_with(&bvh, &s, &options(20_000)).unwrap();
    assert_eq!(r.faces[0].radiosity, Rgb::ONE);
    assert_within(&r, 1, Rgb::splat(0.5 * 0.200044), 0.5 * 5e-7);
    assert!(r.faces[1].relative_standard_error < 0.01, "{}", r.faces[1].relative_standard_error);
}

/// Howell's closed form for directly opposed parallel rectangles `a x b` at distance `c` (catalog C-11):
/// `F = 2 / (pi X Y) [ln sqrt((1 + X^2)(1 + Y^2) / (1 + X^2 + Y^2)) + X sqrt(1 + Y^2) atan(X / sqrt(1 + Y^2))
/// + Y sqrt(1 + X^2) atan(Y / sqrt(1 + X^2)) - X atan X - Y atan Y]`, `X = a / c`, `Y = b / c`.
fn parallel_rectangles(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (x2, y2) = (x * x, y * y);
    let bracket = (((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln()
        + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
        + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
        - x * x.atan()
        - y * y.atan();
    2.0 / (std::f64::consts::PI * x * y) * bracket
}

/// A two-patch open scene: 2 x 1 rectangles facing each other at distance 0.5, a coloured emitter that reflects
/// nothing, and a receiver that reflects per channel and emits a little itself (which cannot reach it back).
/// So `B_1 = E_1 + rho_1 F E_0` exactly per channel, with `F` from the closed form in f64 (exact to rounding).
#[test]
fn open_two_patch_scene_matches_the_closed_form_per_channel() {
    let obj = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 0 0 0.5\nv 2 0 0.5\nv 2 1 0.5\nv 0 1 0.5\n\
               usemtl light\nf 1 2 3 4\nusemtl paint\nf 5 8 7 6\n";
    let mtl = "newmtl light\nKd 0 0 0\nKe 3 2 1\nnewmtl paint\nKd 0.8 0.5 0.2\nKe 0.25 0.25 0.25\n";
    let s = scene("open", obj, mtl);
    let f = parallel_rectangles(2.0, 1.0, 0.5);
    // The closed form itself, against Howell's table entry for unit squares at distance 1.
    assert!((parallel_rectangles(1.0, 1.0, 1.0) - 0.199825).abs() < 5e-7);
    let r = continuous_reference(&s, &options(20_000)).unwrap();
    assert_eq!(r.faces[0].radiosity, Rgb::new(3.0, 2.0, 1.0));
    let expected = Rgb::splat(0.25) + Rgb::new(0.8, 0.5, 0.2) * f * Rgb::new(3.0, 2.0, 1.0);
    assert_within(&r, 1, expected, 0.0);
    assert!(r.faces[1].relative_standard_error < 0.01, "{}", r.faces[1].relative_standard_error);
}

/// The same seed gives the same answer, to the bit, on 1 and 2 threads (Cornell box, whose red wall the loader
/// splits into two triangles: it is still reported as one face).
#[test]
fn answers_do_not_depend_on_the_thread_count() {
    let s = Scene::load(common::scene("cornell-box.obj")).unwrap();
    let run = |threads| {
        let o = ReferenceOptions { threads: Some(threads), ..options(300) };
        continuous_reference(&s, &o).unwrap()
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.faces.len(), s.faces.len());
    assert_eq!(one.faces, two.faces);
    assert_eq!(one.rays, two.rays);
    assert!(one.faces.iter().all(|f| f.samples == 300));
    let other_seed = continuous_reference(&s, &ReferenceOptions { seed: 2, ..options(300) }).unwrap();
    assert_ne!(one.faces, other_seed.faces, "the seed matters");
    // A target standard error is met in rounds, and the stopping decisions are deterministic too.
    let target = |threads| {
        let o = ReferenceOptions {
            samples: SampleCount::TargetRelative { target: 0.05, max_samples: 1 << 16 },
            threads: Some(threads),
            ..options(1)
        };
        continuous_reference(&s, &o).unwrap()
    };
    let (one, two) = (target(1), target(2));
    assert_eq!(one.faces, two.faces);
    assert!(one.target_met && one.worst_relative_error() <= 0.05, "{}", one.summary());
}

/// Bad options are refused with an error naming the option, before any work.
#[test]
fn bad_options_are_refused() {
    let s = Scene::load(common::scene("facing-squares.obj")).unwrap();
    let refuse = |samples, threads| {
        let o = ReferenceOptions { samples, threads, ..options(1) };
        match continuous_reference(&s, &o) {
            Err(MonteCarloError::InvalidOption { name, problem }) => format!("{name}: {problem}"),
            other => panic!("{samples:?}, {threads:?}: expected an option error, got {other:?}"),
        }
    };
    assert!(refuse(SampleCount::PerFace(0), None).starts_with("samples"));
    let target = |target, max_samples| SampleCount::TargetRelative { target, max_samples };
    let nan = refuse(target(f64::NAN, 100), None);
    assert!(nan.starts_with("target-se") && nan.contains("NaN"), "{nan}");
    assert!(refuse(target(0.0, 100), None).starts_with("target-se"));
    assert!(refuse(target(1.5, 100), None).starts_with("target-se"));
    assert!(refuse(target(0.01, 0), None).starts_with("max-samples"));
    assert!(refuse(SampleCount::PerFace(10), Some(0)).starts_with("threads"));
    // Sizes beyond their documented limits (radiosity_host::limits).
    let limit = radiosity_host::limits::MAX_PATHS;
    assert!(refuse(SampleCount::PerFace(limit + 1), None).starts_with("samples"));
    assert!(refuse(target(0.01, limit + 1), None).starts_with("max-samples"));
    let threads = refuse(SampleCount::PerFace(10), Some(radiosity_host::limits::MAX_THREADS + 1));
    assert!(threads.starts_with("threads"), "{threads}");
}

/// The command line reports bad options as errors, naming the option.
#[test]
fn command_line_refuses_bad_options() {
    let run = |extra: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .arg("reference")
            .arg(common::scene("furnace.obj"))
            .args(extra)
            .output()
            .unwrap();
        (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (ok, err) = run(&["--samples", "0"]);
    assert!(!ok && err.contains("samples"), "{err}");
    let (ok, err) = run(&["--target-se", "NaN"]);
    assert!(!ok && err.contains("target-se") && err.contains("NaN"), "{err}");
    let (ok, csv) = {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .args(["reference", "--samples", "64", "--format", "csv", "-q"])
            .arg(common::scene("furnace.obj"))
            .output()
            .unwrap();
        (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned())
    };
    assert!(ok);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], radiosity_host::montecarlo::FACE_CSV_HEADER);
    assert_eq!(lines.len(), 7);
    // The last column names the face's place in its file: the first `f` statement is on line 18.
    assert!(
        lines[1].starts_with("0,1,0.9,0.9,0.9,1,1,1,") && lines[1].ends_with(",64,line 18"),
        "{}",
        lines[1]
    );
}

/// The differential-area-to-rectangle form factor, point over a corner of an `a x b` rectangle parallel to its
/// plane at distance `c` (Howell's catalog, B-3): `F = 1/(2 pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) +
/// B/sqrt(1+B^2) atan(A/sqrt(1+B^2))]`, `A = a / c`, `B = b / c`.
fn point_to_rectangle_corner(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

/// Point probes against closed forms: in the white furnace `B = E / (1 - rho)` at every point, corners and
/// edges included (where the lifted ray origins matter most); opposite the centre of the facing squares' emitter
/// (reflecting nothing) `B = rho E F`, `F` the point-to-square form factor (four corner rectangles of
/// 0.5 x 0.5 at distance 1), and at the receiver's corner one such rectangle of 1 x 1. Each within 3 standard
/// errors plus the rounding of the closed form.
#[test]
fn point_probes_match_closed_forms() {
    let furnace = Scene::load(common::scene("furnace.obj")).unwrap();
    let faces = &furnace.faces;
    // The furnace's faces: a corner of face 0, the midpoint of one of its edges, its centroid.
    let corners = reference_patches(&furnace).unwrap()[0].vertices.clone();
    let centroid = corners.iter().copied().sum::<glam::DVec3>() / corners.len() as f64;
    let probes: Vec<Probe> = [corners[0], 0.5 * (corners[1] + corners[2]), centroid]
        .into_iter()
        .map(|point| Probe { point, face: 0 })
        .collect();
    assert!(faces.len() == 6);
    let got = probe_radiosity(&furnace, &probes, 4096, 7).unwrap();
    for (k, e) in got.iter().enumerate() {
        assert_eq!(e.paths, 4096);
        for c in 0..3 {
            let allowed = 3.0 * e.standard_error[c];
            assert!(
                (e.radiosity[c] - 10.0).abs() <= allowed && allowed < 0.5,
                "furnace probe {k} channel {c}: B {} vs 10, 3 SE {allowed}",
                e.radiosity[c]
            );
        }
    }

    let obj = std::fs::read_to_string(common::scene("facing-squares.obj"))
        .unwrap()
        .replace("mtllib facing-squares.mtl", "");
    let s = scene("facing-probe", &obj, "newmtl emitter\nKd 0 0 0\nKe 1 1 1\nnewmtl grey\nKd 0.5 0.5 0.5\n");
    let probes = [
        Probe { point: glam::DVec3::new(0.5, 0.5, 1.0), face: 1 },
        Probe { point: glam::DVec3::new(0.0, 0.0, 1.0), face: 1 },
    ];
    let expected = [4.0 * point_to_rectangle_corner(0.5, 0.5, 1.0), point_to_rectangle_corner(1.0, 1.0, 1.0)];
    let got = probe_radiosity(&s, &probes, 20_000, 7).unwrap();
    for (k, (e, f)) in got.iter().zip(expected).enumerate() {
        for c in 0..3 {
            let (b, allowed) = (e.radiosity[c], 3.0 * e.standard_error[c] + 1e-12);
            assert!(
                (b - 0.5 * f).abs() <= allowed,
                "facing probe {k}: B {b} vs rho F E {}, 3 SE {allowed}",
                0.5 * f
            );
            assert!(e.standard_error[c] < 0.01 * b, "probe {k}: SE {} of {b}", e.standard_error[c]);
        }
    }
    // The same seed gives the same answer.
    assert_eq!(probe_radiosity(&s, &probes, 20_000, 7).unwrap(), got);
}

/// Probes off their face, on a face that does not exist, at a non-finite point, or with zero paths are refused
/// before any ray, naming the probe.
#[test]
fn bad_probes_are_refused() {
    let s = Scene::load(common::scene("facing-squares.obj")).unwrap();
    let on = Probe { point: glam::DVec3::new(0.5, 0.5, 1.0), face: 1 };
    let cases = [
        (vec![on, Probe { point: glam::DVec3::new(0.5, 0.5, 0.9), face: 1 }], 10, "probe 1: point"),
        (vec![Probe { point: glam::DVec3::new(1.5, 0.5, 1.0), face: 1 }], 10, "is not on face 1"),
        (vec![Probe { face: 2, ..on }], 10, "face 2 does not exist"),
        (vec![Probe { point: glam::DVec3::new(f64::NAN, 0.5, 1.0), face: 1 }], 10, "is not finite"),
        (vec![on], 0, "0 paths per probe"),
    ];
    for (probes, paths, expect) in cases {
        match probe_radiosity(&s, &probes, paths, 1) {
            Err(e @ MonteCarloError::InvalidOption { .. }) => {
                assert!(e.to_string().contains(expect), "{e} lacks {expect:?}");
            }
            other => panic!("{probes:?} with {paths} paths: expected an invalid option, got {other:?}"),
        }
    }
}
