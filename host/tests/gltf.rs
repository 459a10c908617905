//! glTF 2.0 scenes: the Cornell box written as glTF loads to the same scene as the OBJ and solves to the same
//! radiosity; node transforms, mirroring, strips and fans, textures, emission strength, `.glb`; and every error
//! names the file and the node, mesh, primitive and triangle (or buffer, image, material) at fault.
//!
//! The files are written by the small glTF writer below (JSON plus a `.bin` buffer, or one `.glb`), from
//! numbers the tests choose or from the OBJ scene as loaded.

mod common;

use std::path::{Path, PathBuf};

use glam::DVec3;
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::reference::{exact_transfer, Method};
use radiosity_host::rgb::Rgb;
use radiosity_host::scene::{Scene, SceneError, SceneGltf};
use serde_json::{json, Value};

/// glTF's `mode` numbers.
const TRIANGLES: u32 = 4;
const TRIANGLE_STRIP: u32 = 5;
const TRIANGLE_FAN: u32 = 6;
const LINES: u32 = 1;

/// A fresh folder for one test's files.
fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-gltf-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A minimal glTF writer: one binary buffer, accessors, meshes, nodes, materials, images.
#[derive(Default, Clone)]
struct Writer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
    nodes: Vec<Value>,
    materials: Vec<Value>,
    textures: Vec<Value>,
    images: Vec<Value>,
    roots: Vec<usize>,
}

impl Writer {
    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()}));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    /// A VEC3 float accessor of positions.
    fn positions(&mut self, p: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = p.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let fold = |f: fn(f32, f32) -> f32, init: f32| {
            (0..3).map(|c| p.iter().map(|v| v[c]).fold(init, f)).collect::<Vec<f32>>()
        };
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5126, "count": p.len(), "type": "VEC3",
            "min": fold(f32::min, f32::INFINITY), "max": fold(f32::max, f32::NEG_INFINITY),
        }));
        self.accessors.len() - 1
    }

    /// A SCALAR unsigned-int accessor of vertex indices.
    fn indices(&mut self, i: &[u32]) -> usize {
        let bytes: Vec<u8> = i.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(json!({"bufferView": view, "componentType": 5125, "count": i.len(), "type": "SCALAR"}));
        self.accessors.len() - 1
    }

    /// A diffuse material; emission is written as a factor in [0, 1] times KHR_materials_emissive_strength.
    fn material(&mut self, name: &str, rho: Rgb, emission: Rgb) -> usize {
        let strength = emission.max_element();
        let mut m = json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": [rho.x, rho.y, rho.z, 1.0], "metallicFactor": 0.0},
        });
        if strength > 0.0 {
            let f = emission / strength;
            m["emissiveFactor"] = json!([f.x, f.y, f.z]);
            m["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": strength}});
        }
        self.materials.push(m);
        self.materials.len() - 1
    }

    /// A PNG image in the buffer, used as a texture; returns the texture index.
    fn png_texture(&mut self, png: &[u8]) -> usize {
        let view = self.view(png);
        self.images.push(json!({"bufferView": view, "mimeType": "image/png"}));
        self.textures.push(json!({"source": self.images.len() - 1}));
        self.textures.len() - 1
    }

    /// A mesh of primitives `(positions accessor, indices accessor, material, mode)`.
    fn mesh(&mut self, name: &str, primitives: &[(usize, Option<usize>, Option<usize>, u32)]) -> usize {
        let prims: Vec<Value> = primitives
            .iter()
            .map(|&(pos, ind, mat, mode)| {
                let mut p = json!({"attributes": {"POSITION": pos}, "mode": mode});
                if let Some(i) = ind {
                    p["indices"] = json!(i);
                }
                if let Some(m) = mat {
                    p["material"] = json!(m);
                }
                p
            })
            .collect();
        self.meshes.push(json!({"name": name, "primitives": prims}));
        self.meshes.len() - 1
    }

    /// A node (the JSON object as given); a root of the scene if `root`.
    fn node(&mut self, node: Value, root: bool) -> usize {
        self.nodes.push(node);
        if root {
            self.roots.push(self.nodes.len() - 1);
        }
        self.nodes.len() - 1
    }

    fn json(&self, buffer_uri: Option<&str>) -> Value {
        let mut buffer = json!({"byteLength": self.bin.len()});
        if let Some(uri) = buffer_uri {
            buffer["uri"] = json!(uri);
        }
        let mut root = json!({
            "asset": {"version": "2.0", "generator": "radiosity host/tests/gltf.rs"},
            "scene": 0,
            "scenes": [{"nodes": self.roots}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "materials": self.materials,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [buffer],
            "extensionsUsed": ["KHR_materials_emissive_strength"],
        });
        if !self.images.is_empty() {
            root["images"] = json!(self.images);
            root["textures"] = json!(self.textures);
        }
        root
    }

    /// Writes `path` (`NAME.gltf`) and its buffer `NAME.bin`.
    fn write_gltf(&self, path: &Path) {
        let bin = path.with_extension("bin");
        std::fs::write(&bin, &self.bin).unwrap();
        let uri = bin.file_name().unwrap().to_str().unwrap().to_owned();
        std::fs::write(path, serde_json::to_string_pretty(&self.json(Some(&uri))).unwrap()).unwrap();
    }

    /// Writes `path` as binary glTF: header, JSON chunk (space padded), BIN chunk (zero padded).
    fn write_glb(&self, path: &Path) {
        let mut json = serde_json::to_vec(&self.json(None)).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        std::fs::write(path, out).unwrap();
    }
}

/// The unit square in z = 0, counter-clockwise seen from +z, as a fan (0, 1, 2), (0, 2, 3).
const SQUARE: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
const SQUARE_FAN: [u32; 6] = [0, 1, 2, 0, 2, 3];

/// A writer with one grey emitting material ("lamp") and one mesh, the unit square, not yet placed by a node.
fn square_writer() -> (Writer, usize) {
    let mut w = Writer::default();
    let m = w.material("lamp", Rgb::splat(0.5), Rgb::splat(1.0));
    let p = w.positions(&SQUARE);
    let i = w.indices(&SQUARE_FAN);
    let mesh = w.mesh("square", &[(p, Some(i), Some(m), TRIANGLES)]);
    (w, mesh)
}

/// Writes `w` as `NAME.gltf` in a fresh folder and loads it.
fn load(tag: &str, w: &Writer) -> Result<Scene, SceneError> {
    let path = temp_dir(tag).join(format!("{tag}.gltf"));
    w.write_gltf(&path);
    Scene::load(&path)
}

/// The error of loading `w`, as text, checked to name the file.
fn error(tag: &str, w: &Writer) -> String {
    let e = load(tag, w).expect_err("the scene must be refused").to_string();
    assert!(e.contains(&format!("{tag}.gltf")), "the error names the file: {e}");
    e
}

fn assert_close(what: &str, a: f64, b: f64, tol: f64) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b}, difference {:e} > allowed {tol:e}", (a - b).abs());
}

/// f32 unit roundoff: a coordinate written as f32 is within this times its size of the f64 one.
const F32_ROUNDOFF: f64 = f32::EPSILON as f64 / 2.0;

#[test]
fn cornell_box_as_gltf_loads_and_solves_like_the_obj() {
    let obj_path = common::scene("cornell-box.obj");
    let obj = Scene::load(&obj_path).unwrap();
    let dir = temp_dir("cornell");
    let gltf_path = dir.join("cornell-box.gltf");
    let converted = SceneGltf::of(&obj).unwrap();
    let (json, bin) = converted.to_gltf("cornell-box.bin").unwrap();
    std::fs::write(dir.join("cornell-box.bin"), bin).unwrap();
    std::fs::write(&gltf_path, json).unwrap();
    std::fs::copy(common::scene("cornell-box.toml"), dir.join("cornell-box.toml")).unwrap();
    let gltf = Scene::load(&gltf_path).unwrap();

    // Materials: same names and order; values to f32 rounding (the file stores f32 factors, emission as a
    // factor times a strength: two roundings).
    assert_eq!(obj.materials.len(), gltf.materials.len());
    for (a, b) in obj.materials.iter().zip(&gltf.materials) {
        assert_eq!(a.name, b.name);
        for c in 0..3 {
            assert_close(&a.name, a.reflectance[c], b.reflectance[c], F32_ROUNDOFF * a.reflectance[c]);
            assert_close(&a.name, a.emission[c], b.emission[c], 3.0 * F32_ROUNDOFF * a.emission[c]);
        }
    }
    // Light groups from the same TOML, by material name.
    assert_eq!(obj.light_groups, gltf.light_groups);
    assert_eq!(obj.meshing, gltf.meshing);

    // Faces: each planar OBJ face comes back as one face (its fan joined), a non-planar one (split with a
    // warning) as one face per triangle; vertices to f32 rounding, areas to a few roundings of the area.
    let size = obj.faces.iter().flat_map(|f| &f.vertices).fold(0.0_f64, |m, v| m.max(v.abs().max_element()));
    let mut g = 0;
    let mut groups = Vec::new(); // glTF faces of each OBJ face
    for f in &obj.faces {
        let n = f.polygons.len();
        groups.push(g..g + n);
        for p in &f.polygons {
            let h = &gltf.faces[g];
            assert_eq!(h.material, f.material, "face {}", f.index);
            assert_eq!(h.vertices.len(), p.vertices.len(), "face {} (glTF face {g})", f.index);
            for (u, v) in p.vertices.iter().zip(&h.vertices) {
                assert!((*u - *v).abs().max_element() <= F32_ROUNDOFF * size, "face {}: {u} vs {v}", f.index);
            }
            assert!(
                h.normal.dot(p.normal) > 1.0 - 1e-9,
                "face {}: normal {} vs {}",
                f.index,
                h.normal,
                p.normal
            );
            // |dA| <= |perimeter| * |dx|: each edge moves by at most the rounding of its ends.
            let perimeter: f64 = (0..p.vertices.len())
                .map(|k| p.vertices[k].distance(p.vertices[(k + 1) % p.vertices.len()]))
                .sum();
            assert_close(
                &format!("area of face {}", f.index),
                p.area,
                h.area,
                2.0 * perimeter * F32_ROUNDOFF * size,
            );
            g += 1;
        }
    }
    assert_eq!(g, gltf.faces.len(), "no extra glTF faces");
    assert!(
        gltf.faces.len() > obj.faces.len(),
        "the red wall is non-planar: its two triangles stay two faces"
    );

    // Mesh repair cuts the floor where the blocks stand on it, in both; its notes name glTF faces by index
    // (a glTF face has no line).
    let notes = |scene: &Scene, path: &Path| -> Vec<String> {
        radiosity_host::mesh::repair(scene).report.notes(path).iter().map(ToString::to_string).collect()
    };
    let (obj_notes, gltf_notes) = (notes(&obj, &obj_path), notes(&gltf, &gltf_path));
    assert_eq!(obj_notes.len(), gltf_notes.len());
    assert!(obj_notes.iter().all(|n| n.contains("cornell-box.obj:")), "{obj_notes:?}");
    assert!(
        gltf_notes.iter().all(|n| n.contains("cornell-box.gltf: face ") && !n.contains("(line ")),
        "{gltf_notes:?}"
    );

    // Solve both (flat, 200 patches, the estimator's default sample counts) and compare each OBJ face's
    // area-weighted mean radiosity.
    let options = PrepareOptions { max_patches: Some(200), ..PrepareOptions::quiet(false, 16, 16) };
    let solve = |path: &Path| {
        let p = prepare(path, &options).unwrap();
        let l = &p.lighting;
        let tv = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len())).unwrap();
        let b = tv.relight(&l.default_intensity).unwrap();
        (p, b)
    };
    let (po, bo) = solve(&obj_path);
    let (pg, bg) = solve(&gltf_path);
    assert_eq!(po.patches.len(), pg.patches.len(), "the same mesh");
    let mean = |patches: &[radiosity_host::patch::Patch], b: &[Rgb], faces: std::ops::Range<usize>| {
        let (mut sum, mut area) = (Rgb::ZERO, 0.0);
        for (q, &x) in patches.iter().zip(b) {
            if faces.contains(&q.face) {
                sum += q.area * x;
                area += q.area;
            }
        }
        sum / area
    };
    let b_max = bo.iter().map(|b| b.max_element()).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for (f, group) in obj.faces.iter().zip(&groups) {
        let a = mean(&po.patches, &bo, f.index..f.index + 1);
        let b = mean(&pg.patches, &bg, group.clone());
        worst = worst.max((a - b).abs().max_element() / b_max);
    }
    eprintln!("largest per-face radiosity difference, relative to the largest radiosity: {worst:e}");
    assert!(worst <= RADIOSITY_TOLERANCE, "{worst:e} > {RADIOSITY_TOLERANCE:e}");
}

/// Allowed per-face radiosity difference between the OBJ and the glTF Cornell box, relative to the largest
/// radiosity: the glTF file holds the OBJ's f64 numbers rounded to f32 (unit roundoff u = 2^-24), and the
/// solve is linear in them with small condition numbers. Emission is a factor times a strength (up to 3u);
/// reflectance is off by u, which the bounces amplify by at most 1 / (1 - rho_max) = 3.6; vertices move by u
/// times the scene's size, which changes the area and form factors of a patch 1/8 of the scene across by about
/// 8u. Together about 15u: the tolerance is 16u = 9.5e-7. The mesher and the form-factor sampling make the
/// same choices for both (same patch count, same sample points to rounding); a choice that differed (a ray on
/// the other side of an edge, a patch split differently) would move radiosity by percent, far above it.
/// Measured: 1.8e-8 (0.3u).
const RADIOSITY_TOLERANCE: f64 = 16.0 * F32_ROUNDOFF;

/// The faces of a scene as (vertices, area, normal), for comparisons.
fn face_at(scene: &Scene, k: usize) -> (&[DVec3], f64, DVec3) {
    let f = &scene.faces[k];
    (&f.vertices, f.area, f.normal)
}

fn assert_vec(what: &str, a: DVec3, b: DVec3) {
    assert!((a - b).abs().max_element() <= 1e-12 * (1.0 + b.abs().max_element()), "{what}: {a} vs {b}");
}

#[test]
fn node_transforms_are_composed_down_the_hierarchy() {
    let (mut w, mesh) = square_writer();
    w.node(json!({"name": "plain", "mesh": mesh}), true);
    // Scale (2, 3, 1), then 90 degrees about +x, then translation (10, 0, 0).
    let s = std::f64::consts::FRAC_1_SQRT_2;
    w.node(
        json!({"name": "trs", "mesh": mesh, "translation": [10.0, 0.0, 0.0], "rotation": [s, 0.0, 0.0, s],
               "scale": [2.0, 3.0, 1.0]}),
        true,
    );
    // A child translated by (0, 0, 1) under a parent that scales by 2 and moves by (0, 20, 0) (a matrix,
    // column-major).
    let child = w.node(json!({"name": "child", "mesh": mesh, "translation": [0.0, 0.0, 1.0]}), false);
    w.node(
        json!({"name": "parent", "children": [child],
               "matrix": [2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 20.0, 0.0, 1.0]}),
        true,
    );
    let scene = load("transforms", &w).unwrap();
    assert_eq!(scene.faces.len(), 3, "one face per instance (each square's fan joined)");
    let (v, area, n) = face_at(&scene, 0);
    assert_eq!(v.len(), 4);
    assert_close("area of the plain square", area, 1.0, 1e-12);
    assert_vec("normal of the plain square", n, DVec3::Z);
    let (v, area, n) = face_at(&scene, 1);
    assert_close("area of the TRS square", area, 6.0, 1e-12);
    assert_vec("normal of the TRS square (+z turned about +x)", n, DVec3::NEG_Y);
    assert_vec("corner (1, 1, 0) of the TRS square", v[2], DVec3::new(12.0, 0.0, 3.0));
    let (v, area, n) = face_at(&scene, 2);
    assert_close("area of the child square", area, 4.0, 1e-12);
    assert_vec("normal of the child square", n, DVec3::Z);
    assert_vec("corner (1, 1, 0) of the child square", v[2], DVec3::new(2.0, 22.0, 2.0));
    let place = scene.faces[2].gltf.as_ref().unwrap();
    assert_eq!((place.node, place.mesh, place.primitive, place.triangles.clone()), (2, 0, 0, 0..2));
    assert_eq!(scene.faces[2].object, "child");
    assert_eq!(scene.faces[2].place(), "node 'child' (2), mesh 'square' (0), primitive 0, triangles 0..=1");
}

#[test]
fn mirroring_nodes_keep_faces_facing_where_the_file_says() {
    let (mut w, mesh) = square_writer();
    // Mirrored in x: the square still faces +z.
    w.node(json!({"mesh": mesh, "scale": [-1.0, 1.0, 1.0]}), true);
    // Mirrored in z: it now faces -z.
    w.node(json!({"mesh": mesh, "scale": [1.0, 1.0, -1.0], "translation": [3.0, 0.0, 0.0]}), true);
    // Mirrored twice (parent and child): a rotation, facing +z again.
    let child = w.node(json!({"mesh": mesh, "scale": [1.0, 1.0, -1.0]}), false);
    w.node(json!({"children": [child], "scale": [1.0, 1.0, -1.0], "translation": [0.0, 3.0, 0.0]}), true);
    let scene = load("mirror", &w).unwrap();
    let normals: Vec<DVec3> = scene.faces.iter().map(|f| f.normal).collect();
    assert_eq!(normals.len(), 3, "each mirrored square's fan is still joined: {normals:?}");
    assert_vec("mirrored in x", normals[0], DVec3::Z);
    assert_vec("mirrored in z", normals[1], DVec3::NEG_Z);
    assert_vec("mirrored twice", normals[2], DVec3::Z);
    for f in &scene.faces {
        assert_close("area", f.area, 1.0, 1e-12);
        assert_eq!(f.vertices.len(), 4);
    }
}

#[test]
fn strips_fans_and_unindexed_triangles_are_surfaces() {
    let mut w = Writer::default();
    let m = w.material("lamp", Rgb::splat(0.5), Rgb::splat(1.0));
    let p = w.positions(&SQUARE);
    let strip = w.indices(&[0, 1, 3, 2]);
    let fan = w.indices(&[0, 1, 2, 3]);
    let flat: Vec<[f32; 3]> = SQUARE_FAN.iter().map(|&i| SQUARE[i as usize]).collect();
    let q = w.positions(&flat);
    let strip_mesh = w.mesh("strip", &[(p, Some(strip), Some(m), TRIANGLE_STRIP)]);
    let fan_mesh = w.mesh("fan", &[(p, Some(fan), Some(m), TRIANGLE_FAN)]);
    let flat_mesh = w.mesh("unindexed", &[(q, None, Some(m), TRIANGLES)]);
    w.node(json!({"mesh": strip_mesh}), true);
    w.node(json!({"mesh": fan_mesh, "translation": [2.0, 0.0, 0.0]}), true);
    w.node(json!({"mesh": flat_mesh, "translation": [4.0, 0.0, 0.0]}), true);
    let scene = load("modes", &w).unwrap();
    let summary: Vec<(usize, usize)> =
        scene.faces.iter().map(|f| (f.gltf.as_ref().unwrap().node, f.vertices.len())).collect();
    // The strip's second triangle does not start at the first vertex and the unindexed triangles share no
    // index: two triangles each. The fan is joined into the square.
    assert_eq!(summary, [(0, 3), (0, 3), (1, 4), (2, 3), (2, 3)]);
    for f in &scene.faces {
        assert_vec("normal", f.normal, DVec3::Z);
    }
    assert_close("total area", scene.total_area(), 3.0, 1e-12);
}

#[test]
fn glb_and_gltf_with_a_bin_file_load_the_same_scene() {
    let obj = Scene::load(common::scene("cornell-box.obj")).unwrap();
    let w = SceneGltf::of(&obj).unwrap();
    let dir = temp_dir("glb");
    let (json, bin) = w.to_gltf("box.bin").unwrap();
    std::fs::write(dir.join("box.bin"), bin).unwrap();
    std::fs::write(dir.join("box.gltf"), json).unwrap();
    std::fs::write(dir.join("box.glb"), w.to_glb().unwrap()).unwrap();
    let a = Scene::load(dir.join("box.gltf")).unwrap();
    let b = Scene::load(dir.join("box.glb")).unwrap();
    assert_eq!(a.faces, b.faces);
    assert_eq!(a.materials, b.materials);
    assert_eq!(a.light_groups, b.light_groups);
    assert_eq!(b.faces.len(), obj.faces.len() + 1);
}

/// A 2 x 1 RGB PNG with 8-bit sRGB texels.
fn png(texels: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, 2, 1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header().unwrap().write_image_data(texels).unwrap();
    out
}

#[test]
fn textures_multiply_by_their_linear_mean_and_emission_by_its_strength() {
    let (mut w, mesh) = square_writer();
    // sRGB 255 is linear 1, 0 is 0, 128 is ((128 / 255 + 0.055) / 1.055)^2.4 = 0.21586050011389926
    // (IEC 61966-2-1); the mean over the two texels is taken in linear values.
    let t = w.png_texture(&png(&[255, 0, 128, 0, 0, 128]));
    w.materials[0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([0.8, 0.8, 0.8, 1.0]);
    w.materials[0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": t});
    w.materials[0]["emissiveFactor"] = json!([1.0, 0.5, 0.25]);
    w.materials[0]["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}});
    w.node(json!({"mesh": mesh}), true);
    let scene = load("texture", &w).unwrap();
    let m = &scene.materials[0];
    let f = 0.8_f32 as f64;
    assert_vec("reflectance", m.reflectance, DVec3::new(f * 0.5, 0.0, f * 0.21586050011389926));
    assert_eq!(m.emission, DVec3::new(8.0, 4.0, 2.0), "W/m^2, as MTL Ke");
    assert_eq!(scene.light_groups.len(), 1);
    assert_eq!(scene.light_groups[0].name, "lamp", "an emitting material is a light group named after it");
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);

    // The same image as a file beside the scene, named by a relative URI: the same mean.
    let (mut w, mesh) = square_writer();
    w.images.push(json!({"uri": "texture.png"}));
    w.textures.push(json!({"source": 0}));
    w.materials[0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    w.node(json!({"mesh": mesh}), true);
    let dir = temp_dir("external-texture");
    std::fs::write(dir.join("texture.png"), png(&[255, 0, 128, 0, 0, 128])).unwrap();
    w.write_gltf(&dir.join("external.gltf"));
    let external = Scene::load(dir.join("external.gltf")).unwrap();
    assert_vec(
        "reflectance",
        external.materials[0].reflectance,
        DVec3::new(0.25, 0.0, 0.5 * 0.21586050011389926),
    );
    std::fs::remove_file(dir.join("texture.png")).unwrap();
    let e = Scene::load(dir.join("external.gltf")).unwrap_err().to_string();
    assert!(
        e.contains("base colour texture 0, image 0 (") && e.contains("texture.png'): cannot be decoded"),
        "{e}"
    );

    let (mut w, mesh) = square_writer();
    let t = w.png_texture(b"not a PNG at all");
    w.materials[0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": t});
    w.node(json!({"mesh": mesh}), true);
    let e = error("bad-texture", &w);
    assert!(e.contains("material 'lamp' (0), base colour texture 0, image 0: cannot be decoded"), "{e}");
}

#[test]
fn metallic_and_double_sided_materials_are_warned_about() {
    let (mut w, mesh) = square_writer();
    w.materials[0]["pbrMetallicRoughness"] = json!({"baseColorFactor": [0.5, 0.5, 0.5, 1.0]});
    w.materials[0]["doubleSided"] = json!(true);
    w.node(json!({"mesh": mesh}), true);
    let scene = load("warnings", &w).unwrap();
    let text: Vec<String> = scene.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(text.len(), 2, "{text:?}");
    assert!(text[0].contains("material 'lamp' (0): metallicFactor is 1"), "{text:?}");
    assert!(text[1].contains("material 'lamp' (0): double-sided"), "{text:?}");
}

/// The square placed by node 0 ("n"), with indices and positions as given.
fn square_with(positions: &[[f32; 3]], indices: &[u32]) -> Writer {
    let mut w = Writer::default();
    let m = w.material("lamp", Rgb::splat(0.5), Rgb::splat(1.0));
    let p = w.positions(positions);
    let i = w.indices(indices);
    let mesh = w.mesh("square", &[(p, Some(i), Some(m), TRIANGLES)]);
    w.node(json!({"name": "n", "mesh": mesh}), true);
    w
}

const AT: &str = "node 'n' (0), mesh 'square' (0), primitive 0";

#[test]
fn geometry_errors_name_node_mesh_primitive_and_triangle() {
    let e = error("degenerate", &square_with(&SQUARE, &[0, 1, 2, 0, 2, 2]));
    assert!(e.contains(&format!("{AT}, triangle 1: degenerate triangle: vertices 1 and 2 coincide")), "{e}");

    let mut nan = SQUARE;
    nan[3][1] = f32::NAN;
    let e = error("nan", &square_with(&nan, &SQUARE_FAN));
    assert!(e.contains(&format!("{AT}, triangle 1: vertex 2 (index 3) is not finite")), "{e}");

    let e = error("index", &square_with(&SQUARE, &[0, 1, 2, 0, 2, 7]));
    assert!(
        e.contains(&format!("{AT}, triangle 1: vertex 2: index 7 out of range (POSITION has 4 vertices)")),
        "{e}"
    );

    let e = error("count", &square_with(&SQUARE, &[0, 1, 2, 0, 2]));
    assert!(e.contains(&format!("{AT}: 5 vertices for TRIANGLES, not a multiple of 3")), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.meshes[0]["primitives"][0]["mode"] = json!(LINES);
    let e = error("lines", &w);
    assert!(e.contains(&format!("{AT}: mode Lines is not a surface")), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.meshes[0]["primitives"][0].as_object_mut().unwrap().remove("material");
    let e = error("no-material", &w);
    assert!(e.contains(&format!("{AT}: no material")), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.meshes[0]["primitives"][0]["attributes"] = json!({"NORMAL": 0});
    let e = error("no-position", &w);
    // The glTF reader's schema check finds this one first, and names the JSON path.
    assert!(
        e.contains("not a valid glTF 2.0 file")
            && e.contains("meshes[0].primitives[0].attributes[\"POSITION\"]"),
        "{e}"
    );

    // Accessors the `gltf` crate's reader would panic on (found by `damaged_files_never_panic`).
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.meshes[0]["primitives"][0]["attributes"]["POSITION"] = json!(9);
    let e = error("no-accessor", &w);
    assert!(e.contains("meshes[0].primitives[0].attributes: accessor 9 does not exist (2 accessors)"), "{e}");
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.accessors[0]["count"] = json!(0);
    let e = error("empty", &w);
    assert!(e.contains(&format!("{AT}: POSITION (accessor 0) has no elements")), "{e}");
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.accessors[1]["componentType"] = json!(5126);
    let e = error("float-indices", &w);
    assert!(
        e.contains(&format!("{AT}: indices (accessor 1) is F32 Scalar; it must be Scalar of [U8, U16, U32]")),
        "{e}"
    );

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.nodes[0]["scale"] = json!([1.0, 1.0, 0.0]);
    let e = error("singular", &w);
    assert!(e.contains("node 'n' (0): transform (composed with its parents') has determinant 0"), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.nodes[0]["scale"] = json!([1e30, 1e30, 1e30]);
    let e = error("huge", &w);
    assert!(e.contains("more than the largest size supported"), "{e}");

    // Two instances of the square in one place: duplicate faces.
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.node(json!({"name": "twin", "mesh": 0}), true);
    let e = error("overlap", &w);
    assert!(
        e.contains(&format!("face 0 ({AT}, triangles 0..=1) and face 1 (node 'twin' (1), mesh 'square' (0)"))
            && e.contains("coplanar and overlap"),
        "{e}"
    );
}

#[test]
fn material_and_hierarchy_errors_name_what_is_wrong() {
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.materials[0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([1.0, 0.5, 0.5, 1.0]);
    let e = error("white", &w);
    assert!(
        e.contains("material 'lamp' (0): reflectance (base colour) channel 0 = 1 is outside [0, 1)"),
        "{e}"
    );

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.material("lamp", Rgb::splat(0.5), Rgb::ZERO);
    let e = error("twins", &w);
    assert!(e.contains("material 'lamp' (1): the name is also material 0's"), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.materials[0]["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": -2.0}});
    let e = load("strength", &w).expect_err("negative strength").to_string();
    assert!(e.contains("strength.gltf") && e.contains("emissiveStrength"), "{e}");

    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.nodes[0]["matrix"] =
        json!([1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    let e = error("projective", &w);
    assert!(
        e.contains("node 'n' (0): matrix's last row is [0.5, 0, 0, 1], not (0, 0, 0, 1): not affine"),
        "{e}"
    );

    // Node 0 is a root and also the child of node 1, which is its child: a cycle.
    let mut w = square_with(&SQUARE, &SQUARE_FAN);
    w.nodes[0]["children"] = json!([1]);
    w.node(json!({"name": "loop", "children": [0]}), false);
    let e = error("cycle", &w);
    assert!(e.contains("node 'n' (0): is a root of scene 0 and also a child of node 1"), "{e}");
}

#[test]
fn broken_files_are_refused_naming_the_file() {
    let dir = temp_dir("broken");
    let w = square_with(&SQUARE, &SQUARE_FAN);

    let glb = dir.join("cut.glb");
    w.write_glb(&glb);
    let bytes = std::fs::read(&glb).unwrap();
    std::fs::write(&glb, &bytes[..bytes.len() / 2]).unwrap();
    let e = Scene::load(&glb).unwrap_err().to_string();
    assert!(e.contains("cut.glb: not a valid glTF 2.0 file"), "{e}");

    let json = dir.join("syntax.gltf");
    std::fs::write(&json, "{\"asset\": {\"version\": \"2.0\"}, ").unwrap();
    let e = Scene::load(&json).unwrap_err().to_string();
    assert!(e.contains("syntax.gltf: not a valid glTF 2.0 file"), "{e}");

    let missing = dir.join("nobin.gltf");
    w.write_gltf(&missing);
    std::fs::remove_file(missing.with_extension("bin")).unwrap();
    let e = Scene::load(&missing).unwrap_err().to_string();
    assert!(e.contains("nobin.gltf: buffer 0 (") && e.contains("nobin.bin'): cannot be read"), "{e}");

    let short = dir.join("short.gltf");
    w.write_gltf(&short);
    std::fs::write(short.with_extension("bin"), &w.bin[..w.bin.len() - 8]).unwrap();
    let e = Scene::load(&short).unwrap_err().to_string();
    assert!(e.contains("short.gltf: buffer 0 (") && e.contains("less than its byteLength"), "{e}");

    let mut none = w.json(Some("none.bin"));
    none.as_object_mut().unwrap().remove("scenes");
    none.as_object_mut().unwrap().remove("scene");
    std::fs::write(dir.join("none.bin"), &w.bin).unwrap();
    std::fs::write(dir.join("none.gltf"), none.to_string()).unwrap();
    let e = Scene::load(dir.join("none.gltf")).unwrap_err().to_string();
    assert!(e.contains("none.gltf: scenes: the file has no scene"), "{e}");
}

/// The ```json block of `docs/scene-format.md` (the light material of the Cornell box as glTF).
fn doc_material() -> Value {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/scene-format.md"))
        .unwrap();
    let block = text.split("```json\n").nth(1).expect("a ```json block").split("```").next().unwrap();
    serde_json::from_str(block).unwrap()
}

#[test]
fn the_documented_light_material_emits_what_the_mtl_ke_says() {
    let (mut w, mesh) = square_writer();
    w.materials[0] = doc_material();
    w.node(json!({"mesh": mesh}), true);
    let scene = load("doc-material", &w).unwrap();
    let obj = Scene::load(common::scene("cornell-box.obj")).unwrap();
    let light = obj.materials.iter().find(|m| m.name == "light").unwrap();
    let m = &scene.materials[0];
    assert_eq!(m.name, "light");
    for c in 0..3 {
        // The factor is written to 7 digits (relative 1e-7 of 1), then both are rounded to f32.
        assert_close("emission", m.emission[c], light.emission[c], 2e-7 * light.emission.max_element());
        assert_close("reflectance", m.reflectance[c], light.reflectance[c], F32_ROUNDOFF);
    }
}

#[test]
fn the_command_line_solves_a_glb_scene() {
    let (mut w, mesh) = square_writer();
    // The lamp square facing up, and a grey square 1 above it facing down.
    let grey = w.material("grey", Rgb::splat(0.5), Rgb::ZERO);
    let p = w.positions(&SQUARE);
    let i = w.indices(&SQUARE_FAN);
    let down = w.mesh("down", &[(p, Some(i), Some(grey), TRIANGLES)]);
    w.node(json!({"mesh": mesh}), true);
    w.node(json!({"mesh": down, "scale": [1.0, 1.0, -1.0], "translation": [0.0, 0.0, 1.0]}), true);
    let path = temp_dir("cli").join("pair.glb");
    w.write_glb(&path);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(["solve", path.to_str().unwrap(), "--no-subdivide", "--no-repair", "--format", "csv"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows: Vec<Vec<f64>> =
        stdout.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 2, "{stdout}");
    // Facing unit squares 1 apart: F = 0.199825 (closed form); the grey one's radiosity is 0.5 * F * B_lamp
    // (it sees nothing else). A square facing the wrong way would get 0.
    let (lamp, grey) = (rows[0][15], rows[1][15]);
    assert_close("form factor from the solve", grey / (0.5 * lamp), 0.199825, 1e-3);
}

/// The per-face reports name a glTF face by its place in the file (node, mesh, primitive, triangles), as the
/// loader's errors do, where an OBJ face shows its line: the continuous reference's CSV (last column, quoted as
/// it holds commas), its text table and its JSON, for a `.glb` of two squares placed by two nodes.
#[test]
fn per_face_reports_name_gltf_faces_by_node_mesh_primitive_and_triangles() {
    let (mut w, mesh) = square_writer();
    let grey = w.material("grey", Rgb::splat(0.5), Rgb::ZERO);
    let p = w.positions(&SQUARE);
    let i = w.indices(&SQUARE_FAN);
    let down = w.mesh("down", &[(p, Some(i), Some(grey), TRIANGLES)]);
    w.node(json!({"mesh": mesh}), true);
    w.node(
        json!({"name": "top", "mesh": down, "scale": [1.0, 1.0, -1.0], "translation": [0.0, 0.0, 1.0]}),
        true,
    );
    let path = temp_dir("source").join("pair.glb");
    w.write_glb(&path);
    let want = [
        "node 0, mesh 'square' (0), primitive 0, triangles 0..=1",
        "node 'top' (1), mesh 'down' (1), primitive 0, triangles 0..=1",
    ];
    let scene = Scene::load(&path).unwrap();
    let places: Vec<String> = scene.faces.iter().map(|f| f.place()).collect();
    assert_eq!(places, want, "the loader's names");
    let run = |format: &str| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .args(["reference", path.to_str().unwrap(), "--samples", "16", "-q", "--format", format])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let csv = run("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], radiosity_host::montecarlo::FACE_CSV_HEADER);
    assert!(rows[0].ends_with(",samples,source"), "{}", rows[0]);
    assert_eq!(rows.len(), 3, "{csv}");
    for (k, (row, place)) in rows[1..].iter().zip(want).enumerate() {
        assert!(row.starts_with(&format!("{k},")), "{row}");
        assert!(row.ends_with(&format!(",16,\"{place}\"")), "row {k} names its face: {row}");
    }
    let text = run("text");
    for place in want {
        assert!(text.lines().any(|l| l.ends_with(&format!("  {place}"))), "{place} in {text}");
    }
    let json: Value = serde_json::from_str(&run("json")).unwrap();
    let sources: Vec<&str> =
        json["faces"].as_array().unwrap().iter().map(|f| f["source"].as_str().unwrap()).collect();
    assert_eq!(sources, want);
}

/// `scenes/cornell-box.glb` is what `radiosity convert scenes/cornell-box.obj -o scenes/cornell-box.glb` writes
/// now (regenerate it with that command when the writer changes), and loads: with the Cornell box's TOML beside
/// it, as the same scene as the OBJ (`cornell_box_as_gltf_loads_and_solves_like_the_obj` compares the two), and
/// `radiosity solve` takes it as the README's tour shows. The `.gltf` + `.bin` form loads as the same scene.
#[test]
fn the_shipped_cornell_box_glb_is_what_convert_writes() {
    let obj = Scene::load(common::scene("cornell-box.obj")).unwrap();
    let shipped = std::fs::read(common::scene("cornell-box.glb")).unwrap();
    let now = SceneGltf::of(&obj).unwrap().to_glb().unwrap();
    assert!(now == shipped, "scenes/cornell-box.glb is stale: run `radiosity convert scenes/cornell-box.obj -o scenes/cornell-box.glb`");
    let dir = temp_dir("convert");
    let convert = |out: &Path| {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .args(["convert", "-q", common::scene("cornell-box.obj").to_str().unwrap(), "-o"])
            .arg(out)
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        String::from_utf8(run.stdout).unwrap()
    };
    let printed = convert(&dir.join("box.glb"));
    assert!(printed.contains("box.glb") && printed.contains("19 faces, 4 materials"), "{printed}");
    assert_eq!(std::fs::read(dir.join("box.glb")).unwrap(), shipped, "the command writes the same bytes");
    convert(&dir.join("box.gltf"));
    let glb = Scene::load(common::scene("cornell-box.glb")).unwrap();
    let gltf =
        Scene::load_with_toml(&dir.join("box.gltf"), Some(&common::scene("cornell-box.toml"))).unwrap();
    assert_eq!(
        (&glb.faces, &glb.materials, &glb.light_groups),
        (&gltf.faces, &gltf.materials, &gltf.light_groups)
    );
    assert_eq!(glb.light_groups, obj.light_groups, "cornell-box.toml is read beside the .glb");
    // Anything but .glb or .gltf is refused before any work.
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(["convert", common::scene("cornell-box.obj").to_str().unwrap(), "-o"])
        .arg(dir.join("box.obj"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("box.obj") && err.contains(".glb or .gltf"), "{err}");

    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args([
            "solve",
            common::scene("cornell-box.glb").to_str().unwrap(),
            "--no-subdivide",
            "--format",
            "csv",
            "-q",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = String::from_utf8(out.stdout).unwrap();
    assert!(csv.lines().count() > glb.faces.len(), "a row per patch: {csv}");
}

/// Damaged files must give an error or a scene, never a panic: a small two-square `.glb` and `.gltf` cut at
/// every length and with seeded byte changes (anywhere in the `.glb`; digits of the `.gltf`'s JSON, where
/// counts, offsets and indices live). This found two panics inside the `gltf` crate (an attribute's accessor
/// index out of range in its schema check, an accessor of count 0 in its reader), which the loader now checks
/// for first. A one-off run of 40,000 rounds found no other.
#[test]
fn damaged_files_never_panic() {
    let (mut w, mesh) = square_writer();
    w.node(json!({"mesh": mesh}), true);
    w.node(json!({"mesh": mesh, "translation": [0.0, 0.0, 1.0], "scale": [1.0, 1.0, -1.0]}), true);
    let dir = temp_dir("damaged");
    let glb_path = dir.join("ok.glb");
    w.write_glb(&glb_path);
    let glb = std::fs::read(&glb_path).unwrap();
    let gltf_path = dir.join("ok.gltf");
    w.write_gltf(&gltf_path);
    let json = std::fs::read(&gltf_path).unwrap();
    assert!(Scene::load(&glb_path).is_ok() && Scene::load(&gltf_path).is_ok(), "the undamaged files load");
    let (mut loaded, mut refused) = (0, 0);
    let mut try_bytes = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        match Scene::load(&path) {
            Ok(_) => loaded += 1,
            Err(e) => {
                assert!(e.to_string().contains(name), "{e}");
                refused += 1;
            }
        }
    };
    for len in 0..glb.len() {
        try_bytes("cut.glb", &glb[..len]);
    }
    let mut rng = radiosity_host::rng::SplitMix64::new(23);
    let digits = b"0123456789-.e";
    for it in 0..2000 {
        let mut g = glb.clone();
        let k = (rng.next_u64() % g.len() as u64) as usize;
        g[k] = rng.next_u64() as u8;
        try_bytes("flip.glb", &g);
        let mut j = json.clone();
        let k = (rng.next_u64() % j.len() as u64) as usize;
        if j[k].is_ascii_digit() {
            // A digit changed, or replaced by a number at a type's limit (counts, offsets, indices).
            if it % 3 == 0 {
                let big: &[u8] = [&b"4294967295"[..], b"99999999999", b"0", b"65536", b"3"][it % 5];
                j.splice(k..k + 1, big.iter().copied());
            } else {
                j[k] = digits[(rng.next_u64() % digits.len() as u64) as usize];
            }
        }
        try_bytes("flip.gltf", &j);
    }
    eprintln!("damaged files: {loaded} loaded, {refused} refused");
    assert!(refused > glb.len(), "most damage is refused");
}

/// Buffer and image URIs that the `gltf` crate would panic on (a percent escape that is not UTF-8 once decoded)
/// or read without end (a device such as `/dev/zero`, as a path or a `file:` URI) are refused, naming the URI.
#[test]
fn uris_that_are_not_utf8_or_not_files_are_refused() {
    let (mut w, mesh) = square_writer();
    w.node(json!({"mesh": mesh}), true);
    let dir = temp_dir("uri");
    std::fs::write(dir.join("square.bin"), &w.bin).unwrap();
    let load = |name: &str, doc: &Value| {
        let path = dir.join(name);
        std::fs::write(&path, serde_json::to_vec(doc).unwrap()).unwrap();
        let e = Scene::load(&path).expect_err("refused").to_string();
        assert!(e.contains(name), "{e}");
        e
    };
    let e = load("percent.gltf", &w.json(Some("%FF%FE.bin")));
    assert!(e.contains("buffer 0") && e.contains("'%FF%FE.bin' is not UTF-8"), "{e}");
    for uri in ["/dev/zero", "file:///dev/zero", "file:/dev/zero", "."] {
        let e = load("device.gltf", &w.json(Some(uri)));
        assert!(e.contains(&format!("URI '{uri}' names")) && e.contains("not a regular file"), "{uri}: {e}");
    }
    // The same for an image: the base colour texture's image named by URI.
    let mut doc = w.json(Some("square.bin"));
    doc["images"] = json!([{"uri": "/dev/zero"}]);
    doc["textures"] = json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    let e = load("image.gltf", &doc);
    assert!(e.contains("base colour texture 0, image 0") && e.contains("not a regular file"), "{e}");
    doc["images"] = json!([{"uri": "%C0.png"}]);
    let e = load("image.gltf", &doc);
    assert!(e.contains("'%C0.png' is not UTF-8"), "{e}");
}

/// The glTF fuzz target's inputs replayed (`host/fuzz`, target `gltf`, which writes its bytes as a `.glb` and
/// loads it): its seeds (`scripts/fuzz.sh` seeds it with `scenes/*.glb`) and every input that once crashed it
/// (kept in `host/fuzz/regressions/gltf/`, if any), and the shipped Cornell box cut at 64 lengths and with 256
/// seeded byte changes. Each must load or be refused naming the file, never panic.
#[test]
fn fuzz_seeds_and_regressions_load_without_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut inputs: Vec<(String, Vec<u8>)> = Vec::new();
    for dir in [root.join("../scenes"), root.join("fuzz/regressions/gltf")] {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for path in entries.map(|e| e.unwrap().path()) {
            let seed = dir.ends_with("gltf") || path.extension().is_some_and(|e| e == "glb");
            if seed && path.is_file() {
                inputs.push((path.display().to_string(), std::fs::read(&path).unwrap()));
            }
        }
    }
    let glb = std::fs::read(common::scene("cornell-box.glb")).unwrap();
    assert!(inputs.iter().any(|(_, bytes)| *bytes == glb), "the Cornell box is a seed");
    for k in 0..64 {
        inputs.push((format!("cut {k}"), glb[..k * glb.len() / 64].to_vec()));
    }
    let mut rng = radiosity_host::rng::SplitMix64::new(64);
    for k in 0..256 {
        let mut g = glb.clone();
        for _ in 0..1 + k % 4 {
            let at = (rng.next_u64() % g.len() as u64) as usize;
            g[at] = rng.next_u64() as u8;
        }
        inputs.push((format!("flip {k}"), g));
    }
    let path = temp_dir("fuzz-replay").join("scene.glb");
    for (what, bytes) in &inputs {
        std::fs::write(&path, bytes).unwrap();
        if let Err(e) = Scene::load_with_toml(&path, None) {
            assert!(e.to_string().contains("scene.glb"), "{what}: {e}");
        }
    }
}
