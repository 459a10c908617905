//! Scene loading: the shipped scenes load as stated, and every kind of bad input gets its error naming the file,
//! line and face.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::DVec3;
use proptest::prelude::*;
use radiosity_host::rgb::Rgb;
use radiosity_host::scene::{Scene, SceneError};

fn scenes() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

fn load(name: &str) -> Scene {
    let path = scenes().join(format!("{name}.obj"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{name} does not load: {e}"))
}

/// Sum of `A_i n_i` over all faces: zero for a closed, consistently oriented surface (divergence theorem).
fn vector_area(s: &Scene) -> DVec3 {
    s.faces.iter().flat_map(|f| f.polygons.iter()).map(|p| p.normal * p.area).sum()
}

/// Rounding bound for `vector_area` and area sums: each polygon's area has a relative rounding error of a few
/// machine epsilons per vertex (Newell's sum), so `16 * eps * n_vertices` times the total area bounds the sum.
fn area_tolerance(s: &Scene) -> f64 {
    let vertices: usize = s.faces.iter().flat_map(|f| f.polygons.iter()).map(|p| p.vertices.len()).sum();
    16.0 * f64::EPSILON * vertices as f64 * s.total_area()
}

fn material<'a>(s: &'a Scene, name: &str) -> &'a radiosity_host::scene::Material {
    s.materials.iter().find(|m| m.name == name).unwrap_or_else(|| panic!("no material {name}"))
}

/// The published Cornell box quads as `(surface, material, vertices)`, read from the table of the shared
/// reference data (`../shared/data/cornell-box.md`, beside the repository); a row listing several quads
/// (`; `-separated, the block sides) gives one entry per quad.
fn published_quads() -> Vec<(String, String, Vec<DVec3>)> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/cornell-box.md");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut quads = Vec::new();
    for line in text.lines().filter(|l| l.starts_with("| ") && l.contains('(')) {
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        let [surface, material, vertices] = cells[..] else { panic!("{}: bad row {line:?}", path.display()) };
        let surface = surface.split(" (").next().unwrap_or(surface);
        for quad in vertices.split(';') {
            let points = quad
                .split(')')
                .filter_map(|v| v.trim().strip_prefix('('))
                .map(|v| {
                    let c: Vec<f64> = v.split(',').map(|x| x.trim().parse().unwrap()).collect();
                    p(c[0], c[1], c[2])
                })
                .collect();
            quads.push((surface.to_owned(), material.to_owned(), points));
        }
    }
    quads
}

fn p(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

#[test]
fn cornell_box_loads_as_published() {
    let s = load("cornell-box");
    // 16 published quads, minus the ceiling, plus the ceiling in 4 pieces around the light: 19 faces.
    assert_eq!(s.faces.len(), 19);
    // Every published quad but the ceiling, in the data file's order, is the OBJ face listed here.
    let faces = [0, 1, 6, 7, 18, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17];
    let quads: Vec<_> = published_quads().into_iter().filter(|(surface, ..)| surface != "ceiling").collect();
    assert_eq!(quads.len(), faces.len(), "quads in the published data");
    let published: Vec<_> = faces.iter().zip(quads).map(|(&k, (_, mat, verts))| (k, mat, verts)).collect();
    for (k, mat, verts) in &published {
        let f = &s.faces[*k];
        assert_eq!(f.index, *k);
        assert_eq!(&f.vertices, verts, "face {k}: vertices differ from the published data");
        // The data file calls the light's material "emitter"; the OBJ's material is "light".
        let mat = if mat == "emitter" { "light" } else { mat.as_str() };
        assert_eq!(s.materials[f.material].name, mat, "face {k}");
    }
    // The ceiling: four white pieces in the plane y = 548.8 that, with the light, tile the published ceiling
    // (556 x 559.2) exactly; the loader already rejected any overlap between them.
    let ceiling: Vec<_> = s.faces.iter().filter(|f| f.object == "ceiling").collect();
    assert_eq!(ceiling.len(), 4);
    assert!(ceiling.iter().all(|f| s.materials[f.material].name == "white"));
    assert!(ceiling.iter().flat_map(|f| f.vertices.iter()).all(|v| v.y == 548.8));
    let tiled: f64 = ceiling.iter().map(|f| f.area).sum::<f64>() + s.faces[1].area;
    let ceiling_area = 556.0 * 559.2;
    assert!(
        (tiled - ceiling_area).abs() <= 16.0 * f64::EPSILON * 20.0 * ceiling_area,
        "{tiled} vs {ceiling_area}"
    );
    // Orientation: room surfaces face the room's centre, block faces face away from their block's centre.
    let room = p(278.0, 274.4, 279.6);
    for f in &s.faces {
        let c = f.polygons[0].centroid;
        let outward_from = match f.object.as_str() {
            "short_block" => Some(p(185.5, 82.5, 168.5)),
            "tall_block" => Some(p(368.5, 165.0, 351.5)),
            _ => None,
        };
        match outward_from {
            Some(centre) => assert!(f.normal.dot(c - centre) > 0.0, "face {} faces into its block", f.index),
            None => assert!(f.normal.dot(room - c) > 0.0, "face {} faces out of the room", f.index),
        }
    }
    // Materials as stated in the issue and the MTL comment.
    assert_eq!(material(&s, "white").reflectance, Rgb::new(0.725, 0.71, 0.68));
    assert_eq!(material(&s, "red").reflectance, Rgb::new(0.63, 0.065, 0.05));
    assert_eq!(material(&s, "green").reflectance, Rgb::new(0.14, 0.45, 0.091));
    assert_eq!(material(&s, "light").emission, Rgb::new(17.0, 11.8, 4.0));
    for m in ["white", "red", "green"] {
        assert_eq!(material(&s, m).emission, Rgb::ZERO, "{m} emits");
    }
    // One dynamic light group at unit intensity, and the TOML meshing limits.
    assert_eq!(s.light_groups.len(), 1);
    let g = &s.light_groups[0];
    assert_eq!((g.name.as_str(), g.dynamic, g.intensity), ("light", true, Rgb::ONE));
    assert_eq!(g.materials.iter().map(|&m| s.materials[m].name.as_str()).collect::<Vec<_>>(), ["light"]);
    assert_eq!(s.meshing.max_patch_edge, Some(100.0));
    assert_eq!(s.meshing.patch_budget, Some(1000));
    assert_eq!((s.meshing.refine_passes, s.meshing.refine_tolerance), (Some(2), Some(0.1)));
    // The red wall (published non-planar by ~3 mm) is split into two triangles with a warning.
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    let w = &s.warnings[0];
    assert_eq!((w.face, w.line), (Some(18), Some(s.faces[18].line)));
    let text = w.to_string();
    assert!(
        text.contains("cornell-box.obj") && text.contains("non-planar") && text.contains("2 triangles"),
        "{text}"
    );
    // The limits it states are the ones that apply: split within 1% of the diameter, refused beyond.
    assert!(text.contains("within 1% is split") && text.contains("beyond 1% is refused"), "{text}");
    let red = &s.faces[18];
    assert!(red.is_split());
    assert_eq!(red.polygons.len(), 2);
    assert!(s.faces.iter().filter(|f| f.index != 18).all(|f| !f.is_split()));
    // The fan covers the published quad: the triangles' vector areas add up to the quad's Newell vector area,
    // whose length is the area of its projection on the mean plane.
    let fan: DVec3 = red.polygons.iter().map(|t| t.normal * t.area).sum();
    assert!(
        (fan.dot(red.normal) - red.area).abs() <= red.area * 0.01,
        "split area {} vs {}",
        fan.length(),
        red.area
    );
    // Closure bookkeeping (divergence theorem): the surface misses the front wall (normal +z, area A_front) and
    // the blocks' bottoms (normal -y, the footprints, which the full floor covers instead), so
    // sum(A n) = (0, A_footprints, -A_front).
    let front_area = 0.5 * (552.8 + 556.0) * 548.8;
    let expected = p(0.0, s.faces[8].area + s.faces[13].area, -front_area);
    let open = vector_area(&s);
    assert!((open - expected).length() <= area_tolerance(&s), "sum A n = {open}, expected {expected}");
}

#[test]
fn cornell_box_closed_variant_is_closed() {
    let s = load("cornell-box-closed");
    // Divergence theorem: a closed, consistently oriented surface has zero total vector area.
    let v = vector_area(&s);
    assert!(v.length() <= area_tolerance(&s) + 1e-9 * s.total_area(), "sum A n = {v}; the box is not closed");
    let front = s.faces.iter().find(|f| f.object == "front_wall").expect("front wall");
    assert_eq!(front.normal, DVec3::Z);
    assert_eq!(s.materials[front.material].name, "white");
    // The floor excludes the two footprints (equal to the blocks' top faces projected down).
    let floor: f64 = s.faces.iter().filter(|f| f.object == "floor").map(|f| f.area).sum();
    let open = load("cornell-box");
    let expected = open.faces[0].area - open.faces[8].area - open.faces[13].area;
    assert!((floor - expected).abs() <= 1e-9 * expected, "floor {floor} vs {expected}");
    assert!(s.faces.iter().filter(|f| f.object == "floor").all(|f| f.normal == DVec3::Y));
}

#[test]
fn furnace_is_a_closed_inward_cube() {
    let s = load("furnace");
    assert_eq!(s.faces.len(), 6);
    for f in &s.faces {
        assert_eq!(f.area, 1.0);
        let inward = DVec3::splat(0.5) - f.polygons[0].centroid;
        assert!(
            (f.normal - inward * 2.0).length() < 1e-15,
            "face {} normal {} not inward",
            f.index,
            f.normal
        );
    }
    assert!(vector_area(&s).length() <= area_tolerance(&s));
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].reflectance, Rgb::splat(0.9));
    assert_eq!(s.materials[0].emission, Rgb::ONE);
    assert_eq!(s.light_groups.len(), 1);
    assert_eq!(s.light_groups[0].name, "furnace");
}

#[test]
fn analytic_pairs_have_the_stated_geometry() {
    let s = load("facing-squares");
    assert_eq!(s.faces.len(), 2);
    let (a, b) = (&s.faces[0], &s.faces[1]);
    assert_eq!((a.area, b.area), (1.0, 1.0));
    assert_eq!((a.normal, b.normal), (DVec3::Z, -DVec3::Z));
    assert_eq!(b.polygons[0].centroid - a.polygons[0].centroid, DVec3::Z);

    let s = load("perpendicular-squares");
    let (a, b) = (&s.faces[0], &s.faces[1]);
    assert_eq!((a.area, b.area), (1.0, 1.0));
    assert_eq!((a.normal, b.normal), (DVec3::Z, DVec3::X));
    let shared: Vec<_> = a.vertices.iter().filter(|v| b.vertices.contains(v)).collect();
    assert_eq!(shared, [&p(0., 0., 0.), &p(0., 1., 0.)]);
    // Implicit light group from the emitting material; no TOML file.
    assert_eq!(s.light_groups.len(), 1);
    assert_eq!((s.light_groups[0].name.as_str(), s.light_groups[0].dynamic), ("emitter", true));
    assert_eq!(s.meshing, Default::default());
}

// ---- bad input ------------------------------------------------------------------------------------------------

static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A fresh folder with `scene.obj`, `scene.mtl` and (if given) `scene.toml`.
fn write_scene(obj: &str, mtl: &str, toml: Option<&str>) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "radiosity-scene-test-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("scene.obj"), obj).unwrap();
    std::fs::write(dir.join("scene.mtl"), mtl).unwrap();
    if let Some(t) = toml {
        std::fs::write(dir.join("scene.toml"), t).unwrap();
    }
    dir.join("scene.obj")
}

const MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\n\nnewmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
/// A unit square in z = 0 (normal +z) followed by `rest`.
fn obj_with(rest: &str) -> String {
    format!("mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl grey\nf 1 2 3 4\n{rest}")
}

fn error_of(obj: &str, mtl: &str, toml: Option<&str>) -> (SceneError, String, PathBuf) {
    let path = write_scene(obj, mtl, toml);
    match Scene::load(&path) {
        Ok(s) => panic!("loaded, expected an error; faces {}", s.faces.len()),
        Err(e) => {
            let msg = e.to_string();
            std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
            (e, msg, path)
        }
    }
}

/// Asserts the message names `file` (in the scene's folder) and contains every piece of `expect`.
fn assert_message(msg: &str, file: &Path, expect: &[&str]) {
    assert!(msg.contains(&file.display().to_string()), "message does not name {}: {msg}", file.display());
    for e in expect {
        assert!(msg.contains(e), "message lacks {e:?}: {msg}");
    }
}

#[test]
fn missing_files() {
    let dir = std::env::temp_dir().join("radiosity-scene-test-does-not-exist");
    let e = Scene::load(dir.join("nothing.obj")).unwrap_err().to_string();
    assert!(e.starts_with("cannot read") && e.contains("nothing.obj"), "{e}");

    let path = write_scene(&obj_with("").replace("scene.mtl", "other.mtl"), MTL, None);
    let e = Scene::load(&path).unwrap_err();
    assert!(matches!(e, SceneError::Io { .. }), "{e}");
    assert_message(&e.to_string(), &path.with_file_name("other.mtl"), &["cannot read"]);
}

#[test]
fn a_single_value_colour_is_grey() {
    // Legal MTL: one number for all three channels. A later error still names its own line.
    let mtl = "newmtl grey\nKa 0\nKd 0.5\nKs 0\n\nnewmtl lamp\nKd 0.25\nKe 2\n";
    let path = write_scene(&obj_with("v 0 0 1\nv 1 0 1\nv 0 1 1\nusemtl lamp\nf 5 7 6\n"), mtl, None);
    let scene = Scene::load(&path).unwrap_or_else(|e| panic!("single-value Kd refused: {e}"));
    let by_name = |n: &str| scene.materials.iter().find(|m| m.name == n).unwrap().clone();
    assert_eq!(by_name("grey").reflectance.to_array(), [0.5; 3]);
    assert_eq!(by_name("grey").emission.to_array(), [0.0; 3]);
    assert_eq!(by_name("lamp").reflectance.to_array(), [0.25; 3]);
    assert_eq!(by_name("lamp").emission.to_array(), [2.0; 3]);
    let (e, msg, _) = error_of(&obj_with(""), "newmtl grey\nKd 0.5\nKe 1\nKe x\n", None);
    assert!(matches!(e, SceneError::Parse { line: 4, .. }), "{msg}");
    let (_, msg, _) = error_of(&obj_with(""), "newmtl grey\nKd 1.5\n", None);
    assert!(msg.contains(":2: material 'grey'") && msg.contains("outside [0, 1)"), "{msg}");
}

#[test]
fn syntax_errors_name_the_line() {
    let (e, msg, path) = error_of(&obj_with("v 1 2 x\n"), MTL, None);
    assert!(matches!(e, SceneError::Parse { line: 8, .. }), "{msg}");
    assert_message(&msg, &path, &[":8: parse error"]);

    // An index past the last vertex: tobj only notices when it builds the mesh, the binary search still finds it.
    let (e, msg, path) = error_of(&obj_with("f 1 2 9\nv 5 5 5\n"), MTL, None);
    assert!(matches!(e, SceneError::Parse { line: 8, .. }), "{msg}");
    assert_message(&msg, &path, &[":8:"]);

    let (e, msg, path) = error_of(&obj_with(""), "newmtl grey\nKd 0.5 0.5\n", None);
    assert!(matches!(e, SceneError::Parse { line: 2, .. }), "{msg}");
    assert_message(&msg, &path.with_file_name("scene.mtl"), &[":2: parse error"]);
    assert_message(&msg, &path.with_file_name("scene.mtl"), &["three numbers (r g b) or one (grey)"]);

    let (_, msg, path) =
        error_of(&obj_with(""), "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl grey\nKd 0.1 0.1 0.1\n", None);
    assert_message(&msg, &path.with_file_name("scene.mtl"), &[":3:", "'grey'", "defined twice"]);

    let mut bytes = obj_with("").into_bytes();
    bytes.extend_from_slice(b"# \xff\xfe\n");
    let path = write_scene("", MTL, None);
    std::fs::write(&path, bytes).unwrap();
    let msg = Scene::load(&path).unwrap_err().to_string();
    assert_message(&msg, &path, &[":8: not valid UTF-8"]);

    let (e, msg, path) = error_of("mtllib scene.mtl\nv 0 0 0\n", MTL, None);
    assert!(matches!(e, SceneError::NoFaces { .. }));
    assert_message(&msg, &path, &["no faces"]);
}

#[test]
fn missing_material() {
    let (e, msg, path) = error_of(&obj_with("v 0 0 1\nusemtl nosuch\nf 1 2 5\n"), MTL, None);
    assert!(matches!(e, SceneError::MissingMaterial { face: 1, line: 10, .. }), "{msg}");
    assert_message(&msg, &path, &[":10: face 1: material 'nosuch' is not defined"]);

    let (_, msg, path) = error_of("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", MTL, None);
    assert_message(&msg, &path, &[":4: face 0: no material"]);
}

#[test]
fn bad_material_values() {
    let mtl_err = |mtl: &str| {
        let (e, msg, path) = error_of(&obj_with(""), mtl, None);
        assert!(matches!(e, SceneError::BadMaterial { .. }), "{msg}");
        (msg, path.with_file_name("scene.mtl"))
    };
    let cases: [(&str, &[&str]); 6] = [
        ("newmtl grey\nKd 0.5 1.0 0.5\n", &[":2: material 'grey'", "Kd channel 1 = 1 is outside [0, 1)"]),
        ("newmtl grey\n\nKd -0.1 0.5 0.5\n", &[":3:", "Kd channel 0 = -0.1 is outside [0, 1)"]),
        ("newmtl grey\nKd 0.5 NaN 0.5\n", &[":2:", "Kd channel 1 is not finite"]),
        ("newmtl grey\nKd 0.5 0.5 0.5\nKe 1 -2 1\n", &[":3:", "Ke channel 1 = -2 is negative"]),
        ("newmtl grey\nKd 0.5 0.5 0.5\nKe inf 1 1\n", &[":3:", "Ke channel 0 is not finite"]),
        ("newmtl grey\nKs 0.5 0.5 0.5\n", &[":1:", "no reflectance (Kd)"]),
    ];
    for (mtl, expected) in cases {
        let (msg, f) = mtl_err(mtl);
        assert_message(&msg, &f, expected);
    }
}

#[test]
fn degenerate_faces() {
    let cases: [(&str, &str); 6] = [
        ("f 1 2 3 1\n", "vertices 0 and 3 coincide"),
        ("v 2 0 0\nf 1 2 5\n", "zero area"),
        ("f 1 2\n", "2 vertices (a face needs at least 3)"),
        ("l 1 3\n", "2 vertices"),
        ("v NaN 0 0\nf 1 2 5\n", "vertex 2 is not finite"),
        ("v 0.5 0.5 0\nv 0.5 0.5 0.0000000000001\nf 5 2 6\n", "coincide"),
    ];
    for (rest, expect) in cases {
        let (e, msg, path) = error_of(&obj_with(rest), MTL, None);
        assert!(matches!(e, SceneError::DegenerateFace { face: 1, .. }), "{rest:?}: {msg}");
        assert_message(&msg, &path, &["face 1: degenerate face", expect]);
    }
}

#[test]
fn non_convex_faces() {
    // An arrowhead (reflex vertex) and a pentagram (turns twice), both in the plane z = 2.
    let cases = [
        "v 0 0 2\nv 2 0 2\nv 1 0.5 2\nv 0 2 2\nf 5 6 7 8\n",
        "v 1 0 2\nv 0.2245 0.618 2\nv 1.2245 -0.1084 2\nv 0.5 0.5878 2\nv 0.7755 -0.1084 2\nf 5 6 7 8 9\n",
    ];
    for rest in cases {
        let (e, msg, path) = error_of(&obj_with(rest), MTL, None);
        assert!(matches!(e, SceneError::NonConvexFace { face: 1, .. }), "{rest:?}: {msg}");
        assert_message(&msg, &path, &["face 1: non-convex face"]);
    }
}

#[test]
fn non_planar_faces() {
    // A unit square at z = 3 with one corner lifted by h: mean-plane deviation h/4 on a diameter sqrt(2).
    let lifted = |h: f64| obj_with(&format!("v 0 0 3\nv 1 0 3\nv 1 1 {}\nv 0 1 3\nf 5 6 7 8\n", 3.0 + h));
    // h = 0.04: deviation 0.01 = 0.71% of the diameter, within the 1% limit: split with a warning.
    let s = Scene::load(write_scene(&lifted(0.04), MTL, None)).unwrap();
    let faces: Vec<_> = s.warnings.iter().filter(|w| w.face.is_some()).collect();
    assert_eq!(faces.len(), 1, "{:?}", s.warnings);
    assert_eq!((faces[0].face, faces[0].line), (Some(1), Some(12)));
    assert_eq!(s.faces[1].polygons.len(), 2);
    // h = 0.1: deviation 0.025 = 1.8% of the diameter: an error.
    let (e, msg, path) = error_of(&lifted(0.1), MTL, None);
    assert!(matches!(e, SceneError::NonPlanarFace { face: 1, line: 12, .. }), "{msg}");
    assert_message(&msg, &path, &[":12: face 1: non-planar face", "1% of the face diameter"]);
}

#[test]
fn overlapping_coplanar_faces() {
    let cases = [
        // Exact duplicate.
        ("f 1 2 3 4\n", 8),
        // Same square, back to back.
        ("f 4 3 2 1\n", 8),
        // Partly overlapping, shifted by half (and 1e-9 off the plane: coplanar within tolerance).
        ("v 0.5 0 0.000000001\nv 1.5 0 0\nv 1.5 1 0\nv 0.5 1 0\nf 5 6 7 8\n", 12),
    ];
    for (rest, line) in cases {
        let (e, msg, path) = error_of(&obj_with(rest), MTL, None);
        assert!(matches!(e, SceneError::OverlappingFaces { face_a: 0, face_b: 1, .. }), "{rest:?}: {msg}");
        assert_message(
            &msg,
            &path,
            &[&format!(":7: face 0 and line {line}: face 1 are coplanar and overlap")],
        );
    }
    // Coplanar neighbours that share an edge, and a parallel square 1e-3 above: both fine.
    let ok = obj_with("v 2 0 0\nv 2 1 0\nf 2 5 6 3\nv 0 0 0.001\nv 1 0 0.001\nv 1 1 0.001\nf 7 8 9\n");
    let s = Scene::load(write_scene(&ok, MTL, None)).unwrap();
    assert_eq!(s.faces.len(), 3);
}

#[test]
fn toml_errors() {
    let obj = obj_with("v 0 0 1\nv 0 1 1\nv 1 1 1\nusemtl lamp\nf 5 6 7\n");
    let toml_err = |toml: &str| {
        let (e, msg, path) = error_of(&obj, MTL, Some(toml));
        (e, msg, path.with_extension("toml"))
    };
    let group = |body: &str| format!("[[light_group]]\nname = \"g\"\n{body}\n");
    let cases: Vec<(String, &str)> = vec![
        (group("materials = [\"nosuch\"]"), "lists material 'nosuch', which no MTL file defines"),
        (group("materials = [\"grey\"]"), "lists material 'grey', which emits nothing"),
        (group("materials = []"), "lists no materials"),
        (group("materials = [\"lamp\"]\nintensity = -1.0"), "intensity -1"),
        (group("materials = [\"lamp\"]\nintensity = [1, 2]"), "intensity [1, 2]"),
        (group("materials = [\"lamp\"]") + &group("materials = [\"lamp\"]"), "defined twice"),
        (
            group("materials = [\"lamp\"]") + "[[light_group]]\nname = \"h\"\nmaterials = [\"lamp\"]\n",
            "material 'lamp' is in two light groups ('g' and 'h')",
        ),
        ("[meshing]\nmax_patch_edge = -1.0\n".to_owned(), "max_patch_edge = -1 must be finite and positive"),
        ("[meshing]\npatch_budget = 0\n".to_owned(), "patch_budget = 0 must be between 1 and 16384"),
        (
            "[meshing]\npatch_budget = 100000\n".to_owned(),
            "patch_budget = 100000 must be between 1 and 16384",
        ),
        ("[meshing]\nrefine_passes = 7\n".to_owned(), "refine_passes = 7 must be between 0 and 6"),
        ("[meshing]\nrefine_passes = -1\n".to_owned(), "refine_passes = -1 must be between 0 and 6"),
        (
            "[meshing]\nrefine_tolerance = 0.0\n".to_owned(),
            "refine_tolerance = 0 must be finite and positive",
        ),
    ];
    for (toml, expect) in &cases {
        let (e, msg, file) = toml_err(toml);
        assert!(matches!(e, SceneError::TomlInvalid { .. }), "{toml}: {msg}");
        assert_message(&msg, &file, &[expect]);
    }
    for toml in
        ["[meshing]\nmax_patch_edge = \n", "[meshing]\nmax_edge = 1.0\n", "[[light_group]]\nname = 3\n"]
    {
        let (e, msg, file) = toml_err(toml);
        assert!(matches!(e, SceneError::TomlParse { .. }), "{toml}: {msg}");
        assert_message(&msg, &file, &["line 2"]);
    }
    // A valid file: a static group with a grey intensity, and the meshing limits.
    let s = Scene::load(write_scene(
        &obj,
        MTL,
        Some("[meshing]\nmax_patch_edge = 0.25\npatch_budget = 64\n[[light_group]]\nname = \"sun\"\nmaterials = [\"lamp\"]\ndynamic = false\nintensity = 2\n"),
    ))
    .unwrap();
    assert_eq!(s.light_groups.len(), 1);
    let g = &s.light_groups[0];
    assert_eq!(
        (g.name.as_str(), g.dynamic, g.intensity, g.materials.clone()),
        ("sun", false, Rgb::splat(2.0), vec![1])
    );
    assert_eq!((s.meshing.max_patch_edge, s.meshing.patch_budget), (Some(0.25), Some(64)));
    // An emitting material the TOML file does not list gets its own dynamic group at unit intensity, after the
    // file's groups.
    let mtl2 = format!("{MTL}\nnewmtl lamp2\nKd 0.1 0.1 0.1\nKe 0 0 3\n");
    let obj2 = obj.replace("usemtl lamp\n", "usemtl lamp2\n");
    let s = Scene::load(write_scene(
        &obj2,
        &mtl2,
        Some("[[light_group]]\nname = \"sun\"\nmaterials = [\"lamp\"]\n"),
    ))
    .unwrap();
    let groups: Vec<_> = s.light_groups.iter().map(|g| (g.name.as_str(), g.dynamic, g.intensity)).collect();
    assert_eq!(groups, [("sun", true, Rgb::ONE), ("lamp2", true, Rgb::ONE)]);
    assert_eq!(s.light_group_of(2), Some(1));
    assert_eq!(s.light_group_of(0), None);
}

// ---- nothing panics ---------------------------------------------------------------------------------------------

fn obj_line() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        (-3i32..4).prop_map(|i| i.to_string()),
        Just("0.5".to_owned()),
        Just("NaN".to_owned()),
        Just("-inf".to_owned()),
        Just("1e308".to_owned()),
        Just("x".to_owned()),
    ];
    let idx = prop_oneof![
        (-6i64..8).prop_map(|i| i.to_string()),
        Just("1/2/3".to_owned()),
        Just("1//1".to_owned())
    ];
    prop_oneof![
        proptest::collection::vec(num, 0..5).prop_map(|v| format!("v {}", v.join(" "))),
        proptest::collection::vec(idx, 0..7).prop_map(|v| format!("f {}", v.join(" "))),
        prop_oneof![Just("usemtl grey"), Just("usemtl lamp"), Just("usemtl nope"), Just("usemtl")]
            .prop_map(str::to_owned),
        prop_oneof![Just("o a"), Just("g"), Just("mtllib scene.mtl"), Just("mtllib none.mtl"), Just("l 1 2")]
            .prop_map(str::to_owned),
        "[ -~]{0,12}",
    ]
}

fn mtl_line() -> impl Strategy<Value = String> {
    let key = prop_oneof![
        Just("Kd"),
        Just("Ke"),
        Just("Ka"),
        Just("Ns"),
        Just("newmtl"),
        Just("illum"),
        Just("map_Kd")
    ];
    let val = prop_oneof![Just("0.5"), Just("-1"), Just("2"), Just("nan"), Just("y"), Just("grey")];
    (key, proptest::collection::vec(val, 0..5)).prop_map(|(k, v)| format!("{k} {}", v.join(" ")))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    /// Random OBJ-like text gives a scene or an error, never a panic.
    #[test]
    fn random_input_never_panics(
        lines in proptest::collection::vec(obj_line(), 0..24),
        mtl_lines in proptest::collection::vec(mtl_line(), 0..6),
        mtl_garbage in "[ -~\n]{0,40}",
    ) {
        let obj = format!("mtllib scene.mtl\n{}\n", lines.join("\n"));
        let mtl = format!("{MTL}{}\n{mtl_garbage}", mtl_lines.join("\n"));
        let path = write_scene(&obj, &mtl, None);
        let _ = Scene::load(&path);
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    }
}

/// The unit square of `obj_with` and a facing lamp square above it, every coordinate times `k` and shifted by
/// `shift` along x.
fn two_squares(k: f64, shift: f64) -> String {
    let v = |x: f64, y: f64, z: f64| format!("v {} {} {}\n", x * k + shift, y * k, z * k);
    let mut obj = String::from("mtllib scene.mtl\n");
    for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
        obj += &v(x, y, 0.0);
    }
    for (x, y) in [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)] {
        obj += &v(x, y, 1.0);
    }
    obj + "usemtl grey\nf 1 2 3 4\nusemtl lamp\nf 5 6 7 8\n"
}

#[test]
fn scene_size_and_position_out_of_range_are_refused() {
    use radiosity_host::scene::{MAX_ORIGIN_DISTANCE, MAX_SCENE_SIZE};
    // In range, down to the limits: loads (every scene within them gives the same form factors, host/tests/embree.rs).
    for k in [1e-15, 1.0, 1e12, 0.5 * MAX_SCENE_SIZE] {
        let s = Scene::load(write_scene(&two_squares(k, 0.0), MTL, None)).unwrap();
        assert!(s.warnings.is_empty(), "{k:e}: {:?}", s.warnings);
    }
    for (k, expect) in
        [(1e30, "more than the largest size supported"), (1e-17, "less than the smallest size")]
    {
        let (e, msg, path) = error_of(&two_squares(k, 0.0), MTL, None);
        assert!(matches!(e, SceneError::Extent { .. }), "{k:e}: {msg}");
        assert_message(&msg, &path, &[expect, "across", "scale it"]);
    }
    // A unit scene 1e6 units from the origin: its rays' offsets would swallow it.
    let (e, msg, path) = error_of(&two_squares(1.0, 1e6), MTL, None);
    assert!(matches!(e, SceneError::Extent { .. }), "{msg}");
    assert_message(&msg, &path, &["from the origin", "move the scene nearer the origin"]);
    assert!(Scene::load(write_scene(&two_squares(1.0, 0.5 * MAX_ORIGIN_DISTANCE), MTL, None)).is_ok());
}

#[test]
fn light_groups_without_faces_and_scenes_without_emitters_warn() {
    // The lamp material is defined but no face uses it: its light group lights nothing, and nothing emits.
    let s = Scene::load(write_scene(&obj_with(""), MTL, None)).unwrap();
    let text: Vec<String> = s.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(text.len(), 2, "{text:?}");
    assert!(text[0].contains("scene.mtl:4: light group 'lamp' has no faces"), "{text:?}");
    assert!(text[1].contains("scene.obj: no face emits light"), "{text:?}");
    assert!(s.warnings.iter().all(|w| w.face.is_none()));
    // A TOML group of two materials, one of them used: no warning.
    let mtl = format!("{MTL}\nnewmtl spare\nKd 0.1 0.1 0.1\nKe 2 2 2\n");
    let toml = "[[light_group]]\nname = \"lights\"\nmaterials = [\"lamp\", \"spare\"]\n";
    let s = Scene::load(write_scene(&two_squares(1.0, 0.0), &mtl, Some(toml))).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // The same group with neither material used names both.
    let s = Scene::load(write_scene(&obj_with(""), &mtl, Some(toml))).unwrap();
    let first = s.warnings[0].to_string();
    assert!(
        first.contains("light group 'lights' has no faces") && first.contains("'lamp', 'spare'"),
        "{first}"
    );
    // The shipped scenes emit, and every light group has faces.
    for name in ["cornell-box", "furnace", "two-rooms", "hdr-boxes", "slab", "facing-squares"] {
        let s = load(name);
        assert!(s.warnings.iter().all(|w| w.face.is_some()), "{name}: {:?}", s.warnings);
    }
}

/// Two unit squares facing each other `gap` apart (the second at z = `gap`, wound to face -z, or +z with
/// `same_way`), the second shifted by `shift` along x.
fn facing_squares(gap: f64, same_way: bool, shift: f64) -> String {
    let (a, b) = (shift, 1.0 + shift);
    let order = if same_way { "f 5 8 7 6" } else { "f 5 6 7 8" };
    obj_with(&format!("v {a} 0 {gap}\nv {a} 1 {gap}\nv {b} 1 {gap}\nv {b} 0 {gap}\nusemtl lamp\n{order}\n"))
}

#[test]
fn faces_facing_across_a_gap_the_rays_cannot_resolve_warn() {
    // The scene is about 1.4 across: rays keep 1.4 / 8192 = 1.7e-4 off surfaces, so a gap below 3.5e-4 is
    // narrower than twice that.
    let s = Scene::load(write_scene(&facing_squares(1e-4, false, 0.0), MTL, None)).unwrap();
    let text: Vec<String> = s.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(text.len(), 1, "{text:?}");
    assert_eq!((s.warnings[0].face, s.warnings[0].line), (Some(0), Some(7)), "{text:?}");
    for expect in
        ["1 pair(s) of faces face each other", "twice the rays' offset", "face 1 (line 13)", "apart"]
    {
        assert!(text[0].contains(expect), "{expect:?} not in {text:?}");
    }
    // Wider than twice the offset, facing the same way, or side by side without overlap: no warning.
    for (gap, same_way, shift) in [(1e-3, false, 0.0), (1e-4, true, 0.0), (1e-4, false, 1.5)] {
        let s = Scene::load(write_scene(&facing_squares(gap, same_way, shift), MTL, None)).unwrap();
        assert!(s.warnings.is_empty(), "{gap} {same_way} {shift}: {:?}", s.warnings);
    }
}
