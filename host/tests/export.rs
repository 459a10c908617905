//! The `.glb` export of the Cornell box, checked three ways: read back here (the light map, where an engine samples
//! it, gives the radiosity back within its 8-bit steps), by the Khronos glTF validator (zero errors), and rendered
//! by three.js in headless Chromium (per-face mean colours against the project's own render of the same camera).
//!
//! The last two install what they need with `npm ci` in `tests/web/` (from its package-lock.json) and use the
//! system Chromium (`scripts/deps.sh` installs both); when npm, the packages or Chromium cannot be had they print
//! why and skip.

mod common;

use common::field::field_range;
use common::picture::{decode_png, display_range};
use common::web::{node, serve, web};

use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use glam::DVec3;
use radiosity_host::picture::camera::Camera;
use radiosity_host::picture::glb::irradiance_atlas;
use radiosity_host::picture::hdr::read_exr;
use radiosity_host::picture::lightmap::{bake_light_map, LightMap, LightMapOptions};
use radiosity_host::picture::render::{colour_view, trace_view, Colouring, Frame, ViewHits};
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::picture::tonemap::{srgb_decode, srgb_encode};
use radiosity_host::picture::{write_png, RgbImage};
use radiosity_host::pipeline::Prepared;
use radiosity_host::rgb::Rgb;
use radiosity_host::view::{export_glb, solve_default, ExportFiles, PatchTracer};
use serde_json::Value;

/// Side of the compared pictures, in pixels.
const SIZE: u32 = 128;

struct Exported {
    prepared: Prepared,
    b: Vec<Rgb>,
    files: ExportFiles,
    /// The light map the export baked (rebuilt with the same options: the bake is deterministic).
    map: LightMap,
    shader: SmoothShader,
}

fn scratch() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("export");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The coarse Cornell box, solved and exported once for the whole file.
fn exported() -> &'static Exported {
    static CELL: OnceLock<Exported> = OnceLock::new();
    CELL.get_or_init(|| {
        let prepared = common::coarse_cornell();
        let b = solve_default(&prepared).unwrap();
        let options = LightMapOptions::default();
        let files =
            export_glb(prepared.surfaces(), &b, &scratch().join("cornell-box.glb"), &options).unwrap();
        let shader = SmoothShader::new(&prepared.patches, &ShadingOptions::default()).unwrap();
        let map = bake_light_map(&prepared.patches, &shader, &b, &options).unwrap();
        Exported { prepared, b, files, map, shader }
    })
}

/// The JSON and binary chunks of a `.glb`, after checking its header.
fn parse_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(word(4), 2, "container version");
    assert_eq!(word(8), bytes.len(), "total length");
    let json_len = word(12);
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let at = 20 + json_len;
    let bin_len = word(at);
    assert_eq!(&bytes[at + 4..at + 8], b"BIN\0");
    assert_eq!(at + 8 + bin_len, bytes.len());
    (json, bytes[at + 8..].to_vec())
}

fn view_bytes<'a>(json: &Value, bin: &'a [u8], view: usize) -> &'a [u8] {
    let v = &json["bufferViews"][view];
    let offset = v["byteOffset"].as_u64().unwrap_or(0) as usize;
    &bin[offset..offset + v["byteLength"].as_u64().unwrap() as usize]
}

/// An accessor's values as f64 (FLOAT or UNSIGNED_INT components, tightly packed).
fn accessor(json: &Value, bin: &[u8], index: u64) -> Vec<f64> {
    let a = &json["accessors"][index as usize];
    let bytes = view_bytes(json, bin, a["bufferView"].as_u64().unwrap() as usize);
    bytes
        .chunks_exact(4)
        .map(|c| {
            let raw = c.try_into().unwrap();
            match a["componentType"].as_u64().unwrap() {
                5126 => f64::from(f32::from_le_bytes(raw)),
                5125 => f64::from(u32::from_le_bytes(raw)),
                other => panic!("component type {other}"),
            }
        })
        .collect()
}

/// The largest change of the linear value an 8-bit sRGB code `c` stands for, rounding half a code either way.
fn half_step(c: u8) -> f64 {
    let at = |v: f64| srgb_decode((v / 255.0).clamp(0.0, 1.0));
    let c = f64::from(c);
    (at(c + 0.5) - at(c)).max(at(c) - at(c - 0.5))
}

/// The embedded light map of a `.glb` (decoded 8-bit sRGB codes).
fn embedded_light_map(json: &Value, bin: &[u8]) -> RgbImage {
    let image = &json["images"][0];
    assert_eq!(image["mimeType"], "image/png");
    decode_png(view_bytes(json, bin, image["bufferView"].as_u64().unwrap() as usize))
}

/// What an engine computes at atlas point `(ax, ay)` of a surface with reflectance `rho` and emission `e`: the light
/// map decoded and filtered bilinearly (clamped to the edge), times `scale` (the light map's intensity) and `rho`,
/// plus `e`, in W/m^2; and the bound of the 8-bit steps of the texels read, times `rho`.
fn engine_value(png: &RgbImage, scale: f64, rho: Rgb, e: Rgb, ax: f64, ay: f64) -> (Rgb, Rgb) {
    let footprint = radiosity_host::picture::lightmap::Footprint::at(ax, ay);
    let (mut irradiance, mut step) = (Rgb::ZERO, Rgb::ZERO);
    for (&(x, y), &weight) in footprint.texels.iter().zip(&footprint.weights) {
        let (x, y) =
            (x.clamp(0, i64::from(png.width) - 1) as u32, y.clamp(0, i64::from(png.height) - 1) as u32);
        let code = png.get(x, y);
        irradiance += weight * Rgb::from_array(code.map(|c| srgb_decode(f64::from(c) / 255.0))) * scale;
        step += weight * Rgb::from_array(code.map(half_step)) * scale;
    }
    (rho * irradiance + e, rho * step)
}

/// What an engine does with the file, redone from its bytes: at the centroid of every triangle, the embedded
/// light map (8-bit sRGB, decoded, filtered bilinearly at the triangle's interpolated TEXCOORD_1, times the
/// MOZ_lightmap intensity) times the base colour plus the emission gives the light map's radiosity there, within
/// the 8-bit steps of the texels read (times the reflectance); the UV lands on the point of the face it belongs
/// to; the materials carry the scene's reflectances; the EXR beside holds the same irradiance in full.
#[test]
fn glb_light_map_gives_the_radiosity_back_where_engines_sample_it() {
    let e = exported();
    let (json, bin) = parse_glb(&std::fs::read(&e.files.glb).unwrap());
    assert!(json["extensionsUsed"].as_array().unwrap().iter().any(|x| x == "MOZ_lightmap"));
    let png = embedded_light_map(&json, &bin);
    assert_eq!((png.width, png.height), (e.map.atlas.width, e.map.atlas.height));
    let (w, h) = (f64::from(png.width), f64::from(png.height));
    let materials = &e.prepared.scene.materials;
    let mut checked = 0;
    let mut worst = 0.0f64;
    for prim in json["meshes"][0]["primitives"].as_array().unwrap() {
        let mat = &json["materials"][prim["material"].as_u64().unwrap() as usize];
        let m = materials.iter().find(|m| m.name == mat["name"].as_str().unwrap()).unwrap();
        let base = mat["pbrMetallicRoughness"]["baseColorFactor"].as_array().unwrap();
        let rho = Rgb::new(base[0].as_f64().unwrap(), base[1].as_f64().unwrap(), base[2].as_f64().unwrap());
        assert_eq!(rho, m.reflectance, "material {}", m.name);
        let lightmap = &mat["extensions"]["MOZ_lightmap"];
        assert_eq!(lightmap["texCoord"], 1);
        let scale = lightmap["intensity"].as_f64().unwrap();
        assert_eq!(scale, e.files.irradiance_scale);
        let attributes = &prim["attributes"];
        let positions = accessor(&json, &bin, attributes["POSITION"].as_u64().unwrap());
        let uvs = accessor(&json, &bin, attributes["TEXCOORD_1"].as_u64().unwrap());
        let indices = accessor(&json, &bin, prim["indices"].as_u64().unwrap());
        for tri in indices.chunks_exact(3) {
            let (mut q, mut uv) = (DVec3::ZERO, (0.0, 0.0));
            for &k in tri {
                let k = k as usize;
                q += DVec3::new(positions[3 * k], positions[3 * k + 1], positions[3 * k + 2]) / 3.0;
                uv = (uv.0 + uvs[2 * k] / 3.0, uv.1 + uvs[2 * k + 1] / 3.0);
            }
            let (ax, ay) = (uv.0 * w, uv.1 * h);
            // The face the triangle belongs to: the patch whose polygon holds the centroid on the right side.
            let patch = (0..e.prepared.patches.len())
                .filter(|&i| {
                    e.prepared.patches[i].material == materials.iter().position(|x| x.name == m.name).unwrap()
                })
                .find(|&i| {
                    e.shader.distance_in_plane(i, q) < 1e-3
                        && (q - e.prepared.patches[i].centroid).dot(e.prepared.patches[i].normal).abs() < 1e-2
                })
                .unwrap_or_else(|| panic!("no patch of {} at {q}", m.name));
            let rect = e.map.rects.iter().find(|r| r.face == e.prepared.patches[patch].face).unwrap();
            let (ex, ey) = rect.atlas_coords(q);
            assert!(
                (ex - ax).abs() < 1e-3 && (ey - ay).abs() < 1e-3,
                "UV of {q}: ({ax}, {ay}) vs ({ex}, {ey})"
            );
            // The engine's value, and the bound of its 8-bit steps.
            let (engine, step) = engine_value(&png, scale, rho, m.emission, ax, ay);
            let expected = e.map.bilinear(ax, ay);
            // f32 atlas and UVs: a relative 1e-5 of the largest radiosity.
            let allowed = step + Rgb::splat(1e-5 * scale);
            let off = (engine - expected).abs();
            assert!(
                off.cmple(allowed).all(),
                "{} at {q}: engine {engine}, light map {expected}, allowed {allowed}",
                m.name
            );
            worst = worst.max((off / allowed.max(Rgb::splat(1e-30))).max_element());
            checked += 1;
        }
    }
    assert_eq!(checked, e.files.triangles);
    eprintln!("{checked} triangles: engine vs light map at most {worst:.2} of the 8-bit bound");
    let exr = read_exr(&e.files.exr).unwrap();
    assert_eq!(exr, irradiance_atlas(&e.prepared.patches, materials, &e.map).unwrap());
}

#[test]
fn glb_passes_the_khronos_gltf_validator() {
    let e = exported();
    let dir = match web() {
        Ok(dir) => dir,
        Err(why) => {
            eprintln!("SKIPPED glb_passes_the_khronos_gltf_validator: {why}");
            return;
        }
    };
    let out = node(dir, &["validate.mjs", e.files.glb.to_str().unwrap()], Duration::from_secs(120)).unwrap();
    let report: Value = serde_json::from_str(&out).unwrap();
    let issues = &report["issues"];
    for m in issues["messages"].as_array().unwrap() {
        eprintln!(
            "validator: severity {} {} at {}: {}",
            m["severity"], m["code"], m["pointer"], m["message"]
        );
    }
    assert_eq!(issues["numErrors"], 0, "the validator found errors:\n{out}");
    // The validator read what was written: every triangle, two UV sets, the embedded image.
    let info = &report["info"];
    assert_eq!(info["totalTriangleCount"], e.files.triangles as u64, "{info}");
    assert_eq!(info["maxUVs"], 2, "{info}");
    assert_eq!(info["hasTextures"], true, "{info}");
    eprintln!(
        "validator: {} errors, {} warnings, {} infos, {} hints",
        issues["numErrors"], issues["numWarnings"], issues["numInfos"], issues["numHints"]
    );
}

/// Per-channel range of the smooth field over the points of face `face`'s patches within `reach` of `q`, in the
/// plane of the face's light-map rectangle.
fn face_field_range(e: &Exported, face: usize, q: DVec3, reach: f64) -> (Rgb, Rgb) {
    let rect = e.map.rects.iter().find(|r| r.face == face).unwrap();
    let on: Vec<usize> =
        (0..e.prepared.patches.len()).filter(|&i| e.prepared.patches[i].face == face).collect();
    field_range(&e.shader, &e.b, &on, q, (rect.u_axis, rect.v_axis), reach)
}

/// three.js, given the `.glb` and set up as README tells (Lambert materials of the file's colours and emission,
/// light map from MOZ_lightmap on UV channel 1 with its intensity, no lights, the project's tone map as a custom
/// tone mapping with exposure x pi, since three.js shows radiance B / pi), renders the Cornell box from the
/// published camera in headless Chromium (SwiftShader). Regions are the faces, over the pixels whose 3 x 3
/// neighbourhood sees only that face in the project's render (edges rasterize differently from ray casting);
/// per region and channel the mean 8-bit colours are compared, two steps:
///
/// 1. **three.js does what the file says**: the screenshot against the engine's arithmetic redone here (the
///    embedded PNG decoded and filtered bilinearly at each pixel's hit point, times the intensity and the base
///    colour, plus the emission, tone mapped and rounded), within 1.5 codes: 1 for two roundings of nearly
///    equal values falling on either side of a half code, 0.5 for the GPU's own arithmetic (its float UV
///    interpolation and its 8-bit sub-texel filter weights). A wrong UV set, colour space, intensity, exposure
///    or material model (MeshStandardMaterial's specular share, about 4%, is 2 to 4 codes) fails this step.
/// 2. **the file shows what the project renders**: that redone engine value against the project's `render` of
///    the same camera. The project's pixel shows the smooth field `f` at its hit point; the engine shows the
///    light map filtered there, whose texels hold `f` at points within 3 texels of it (see the light-map
///    filtering test in render.rs), each off by at most half an 8-bit sRGB step of the light map (times the
///    reflectance). So both lie in the displayed range of `[lo - d, hi + d]`, `lo` / `hi` the range of `f`
///    within 3 texels and `d` that step; the tone map is monotone in each channel, so that range is spanned by
///    the display values at its corners. The tolerance is the region's mean displayed range plus 1 code (the
///    two roundings).
///
/// The screenshot and the project's render then differ by at most the sum of the two tolerances.
#[test]
fn three_js_renders_the_glb_as_the_project_does() {
    let e = exported();
    let dir = match web() {
        Ok(dir) => dir,
        Err(why) => {
            eprintln!("SKIPPED three_js_renders_the_glb_as_the_project_does: {why}");
            return;
        }
    };
    if let Err(why) = common::web::chromium() {
        eprintln!("SKIPPED three_js_renders_the_glb_as_the_project_does: {why}");
        return;
    }
    // The project's render (as `radiosity render`: ray cast, smooth shading, tone map from the visible pixels).
    let camera = Camera::cornell_box();
    let tracer = PatchTracer::new(&e.prepared.patches).unwrap();
    let frame = Frame { camera, width: SIZE, height: SIZE };
    let hits: ViewHits = trace_view(&frame, &|o, d| tracer.closest_hit(o, d)).unwrap();
    let view = colour_view(&hits, &e.shader, &e.b, Colouring::Shaded, None).unwrap();
    let tone = view.tone.unwrap();
    let out = scratch();
    write_png(&out.join("project-render.png"), &view.image).unwrap();

    let port = serve(vec![("/out/", out.clone()), ("/", dir.to_path_buf())]);
    let target = camera.position + camera.forward;
    let v = |x: DVec3| format!("{},{},{}", x.x, x.y, x.z);
    let url = format!(
        "http://127.0.0.1:{port}/page.html?glb=/out/cornell-box.glb&exposure={}&white={}&camera={};{};{};{}",
        tone.scale * std::f64::consts::PI,
        tone.white,
        v(camera.position),
        v(target),
        v(camera.up),
        camera.vertical_fov_deg
    );
    let shot = out.join("three-js-render.png");
    let _ = std::fs::remove_file(&shot);
    let size = SIZE.to_string();
    let started = Instant::now();
    node(dir, &["render.mjs", &url, shot.to_str().unwrap(), &size, &size], Duration::from_secs(120)).unwrap();
    eprintln!("three.js render in Chromium: {:.1} s", started.elapsed().as_secs_f64());
    let browser = decode_png(&std::fs::read(&shot).unwrap());
    assert_eq!((browser.width, browser.height), (SIZE, SIZE));

    // Regions: the faces, interior pixels only.
    let face_at = |x: i64, y: i64| -> Option<usize> {
        if x < 0 || y < 0 || x >= i64::from(SIZE) || y >= i64::from(SIZE) {
            return None;
        }
        hits.hits[(y * i64::from(SIZE) + x) as usize].map(|h| e.prepared.patches[h.patch].face)
    };
    struct Region {
        pixels: usize,
        browser: Rgb,
        engine: Rgb,
        project: Rgb,
        range: Rgb,
    }
    let (json, bin) = parse_glb(&std::fs::read(&e.files.glb).unwrap());
    let png = embedded_light_map(&json, &bin);
    let scale = e.files.irradiance_scale;
    let mut regions: std::collections::BTreeMap<usize, Region> = Default::default();
    let reach = 3.0 * e.map.texel_size;
    let materials = &e.prepared.scene.materials;
    for y in 0..i64::from(SIZE) {
        for x in 0..i64::from(SIZE) {
            let Some(face) = face_at(x, y) else { continue };
            if !(-1..=1).all(|dy| (-1..=1).all(|dx| face_at(x + dx, y + dy) == Some(face))) {
                continue;
            }
            let hit = hits.hits[(y * i64::from(SIZE) + x) as usize].unwrap();
            let m = &materials[e.prepared.patches[hit.patch].material];
            let (lo, hi) = face_field_range(e, face, hit.point, reach);
            // Half an 8-bit step of the light map at the brightest value in reach, times the reflectance.
            let h_hi = ((hi - m.emission) / m.reflectance.max(Rgb::splat(1e-12))).max(Rgb::ZERO);
            let code = (h_hi / e.files.irradiance_scale).map(|v| (255.0 * srgb_encode(v)).round());
            let d = m.reflectance * code.map(|c| half_step(c as u8)) * e.files.irradiance_scale;
            let (a, b) = ((lo - d).max(Rgb::ZERO), hi + d);
            let (dmin, dmax) = display_range(&tone, a, b);
            let rect = e.map.rects.iter().find(|r| r.face == face).unwrap();
            let (ax, ay) = rect.atlas_coords(hit.point);
            let (engine, _) = engine_value(&png, scale, m.reflectance, m.emission, ax, ay);
            let zero = Region {
                pixels: 0,
                browser: Rgb::ZERO,
                engine: Rgb::ZERO,
                project: Rgb::ZERO,
                range: Rgb::ZERO,
            };
            let r = regions.entry(face).or_insert(zero);
            r.pixels += 1;
            r.browser += Rgb::from_array(browser.get(x as u32, y as u32).map(f64::from));
            r.engine += Rgb::from_array(tone.map_srgb8(engine).unwrap().map(f64::from));
            r.project += Rgb::from_array(view.image.get(x as u32, y as u32).map(f64::from));
            r.range += dmax - dmin;
        }
    }
    let mut failures = Vec::new();
    let mut compared = 0;
    for (face, r) in &regions {
        if r.pixels < 16 {
            continue;
        }
        let n = r.pixels as f64;
        let (browser, engine, project) = (r.browser / n, r.engine / n, r.project / n);
        let (allowed_gpu, allowed_map) = (Rgb::splat(1.5), r.range / n + Rgb::splat(1.0));
        let (off_gpu, off_map, off) =
            ((browser - engine).abs(), (engine - project).abs(), (browser - project).abs());
        let name = &materials[e.prepared.patches.iter().find(|p| p.face == *face).unwrap().material].name;
        let f = |c: Rgb| format!("{:5.1} {:5.1} {:5.1}", c.x, c.y, c.z);
        let line = format!(
            "face {face:2} ({name:5}, {:4} px): three.js {} | engine redone {} (off {}, allowed {}) | \
             project {} (off {}, allowed {}) | three.js - project {}",
            r.pixels,
            f(browser),
            f(engine),
            f(off_gpu),
            f(allowed_gpu),
            f(project),
            f(off_map),
            f(allowed_map),
            f(off)
        );
        eprintln!("{line}");
        if !off_gpu.cmple(allowed_gpu).all() || !off_map.cmple(allowed_map).all() {
            failures.push(line);
        }
        compared += 1;
    }
    assert!(compared >= 8, "only {compared} faces large enough to compare");
    assert!(failures.is_empty(), "three.js and the project's render differ:\n{}", failures.join("\n"));
}
