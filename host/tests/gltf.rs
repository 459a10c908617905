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
use radiosity_host::scene::{Scene, SceneError};
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
        while self.bin.len() % 4 != 0 {
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
        self.accessors.push(json!({"bufferView": view, "componentType": 5125, "count": i.len(), "type": "SCALAR"}));
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
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while bin.len() % 4 != 0 {
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

/// The glTF form of a loaded scene, faces in the scene's order: one root node, one mesh, one primitive (indexed
/// triangles) per run of faces with one material, each face's polygons written as triangle fans from their first
/// vertex over vertices of their own.
fn writer_of(scene: &Scene) -> Writer {
    let mut w = Writer::default();
    for m in &scene.materials {
        w.material(&m.name, m.reflectance, m.emission);
    }
    let mut prims = Vec::new();
    for run in scene.faces.chunk_by(|a, b| a.material == b.material) {
        let mut pos: Vec<[f32; 3]> = Vec::new();
        let mut idx: Vec<u32> = Vec::new();
        for poly in run.iter().flat_map(|f| &f.polygons) {
            let first = pos.len() as u32;
            pos.extend(poly.vertices.iter().map(|v| [v.x as f32, v.y as f32, v.z as f32]));
            for k in 1..poly.vertices.len() as u32 - 1 {
                idx.extend([first, first + k, first + k + 1]);
            }
        }
        let p = w.positions(&pos);
        let i = w.indices(&idx);
        prims.push((p, Some(i), Some(run[0].material), TRIANGLES));
    }
    let mesh = w.mesh("scene", &prims);
    w.node(json!({"name": "root", "mesh": mesh}), true);
    w
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
    writer_of(&obj).write_gltf(&gltf_path);
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
            assert!(h.normal.dot(p.normal) > 1.0 - 1e-9, "face {}: normal {} vs {}", f.index, h.normal, p.normal);
            // |dA| <= |perimeter| * |dx|: each edge moves by at most the rounding of its ends.
            let perimeter: f64 = (0..p.vertices.len())
                .map(|k| p.vertices[k].distance(p.vertices[(k + 1) % p.vertices.len()]))
                .sum();
            assert_close(&format!("area of face {}", f.index), p.area, h.area, 2.0 * perimeter * F32_ROUNDOFF * size);
            g += 1;
        }
    }
    assert_eq!(g, gltf.faces.len(), "no extra glTF faces");
    assert!(gltf.faces.len() > obj.faces.len(), "the red wall is non-planar: its two triangles stay two faces");

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
