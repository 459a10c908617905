//! The browser viewer: a self-contained folder in which the device core, built as WebAssembly
//! (`web/`, crate `radiosity-web`), relights the scene live in a WebGL2 page.
//!
//! [`write_viewer`] writes into a folder:
//! - `index.html` and `viewer.js` (this module's `index.html` / `viewer.js`, plain WebGL2, nothing fetched from
//!   elsewhere);
//! - `radiosity_web.wasm`, the caller's build of `radiosity-web` (the core as is, with a small C ABI);
//! - `scene.rft`, the table baked at default settings with its transfer section;
//! - `scene.json` ([`ViewerScene`]): the patch polygons (scene units), light-group and material names with their
//!   defaults, the camera, the tone map (that of `radiosity render --mode flat` through the same camera), the
//!   Cortex-M4 cost model (from `firmware-sim/COST.md`), and the exact
//!   f64 answer as transfer vectors `B = B_static + sum_g I_g T_g` on the scene's own form factors, for the live
//!   error (it holds for the scene's reflectances).
//!
//! The page needs only a static HTTP server (browsers refuse `fetch` from `file://`), e.g.
//! `python3 -m http.server -d DIR`.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::bake::{bake, BakeError, BakeInput, BakeOptions};
use crate::files::{write_atomic, FileError};
use crate::picture::PictureError;
use crate::pipeline::Prepared;
use crate::reference::{exact_transfer, Method, ReferenceError};
use crate::rgb::Rgb;
use crate::view::{default_camera, render_view, RenderMode, RenderOptions, ViewError};

/// The page (static HTML; it loads `viewer.js`).
const INDEX_HTML: &str = include_str!("index.html");
/// The page's script: loads the wasm, the table and `scene.json`, draws with WebGL2, steps every frame.
const VIEWER_JS: &str = include_str!("viewer.js");
/// The generated cost report of the firmware under QEMU, whose Cortex-M4F (f32) row the page quotes.
const COST_MD: &str = include_str!("../../../firmware-sim/COST.md");
/// The build of `COST.md` the page quotes: core in f32 on a Cortex-M4F.
const COST_BUILD: &str = "m4-f32";

/// Side in pixels of the view whose tone map the page uses: `radiosity render --mode flat` at its default size
/// (512 x 512) through the scene's camera picks its exposure from the visible pixels, and the page takes it, so
/// that its first view, at the scene's camera, is that picture.
pub const TONE_VIEW_SIZE: u32 = 512;

/// Why the viewer could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WebError {
    /// The table could not be baked.
    #[error("baking the table: {0}")]
    Bake(#[from] BakeError),
    /// The f64 reference solve failed.
    #[error("f64 reference: {0}")]
    Reference(#[from] ReferenceError),
    /// The camera could not be chosen.
    #[error(transparent)]
    View(#[from] ViewError),
    /// The tone map could not be chosen.
    #[error(transparent)]
    Picture(#[from] PictureError),
    /// A file could not be written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The WebAssembly file could not be read, or is not one.
    #[error("{path}: {why}")]
    Wasm {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// `scene.json` could not be encoded.
    #[error("encoding scene.json: {0}")]
    Json(#[from] serde_json::Error),
    /// `firmware-sim/COST.md` has no row for the quoted build (a report format change).
    #[error("firmware-sim/COST.md has no parsable row for build {0}")]
    CostModel(&'static str),
}

/// The Cortex-M4 cost model the page shows next to the budget: instructions `= overhead + per_unit * units`
/// (least squares over the calibration frames), bounded by `bound_overhead + bound_per_unit * units`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CostModel {
    /// The build (`m4-f32`).
    pub build: &'static str,
    /// Least-squares overhead per frame (instructions).
    pub overhead: f64,
    /// Least-squares instructions per work unit.
    pub per_unit: f64,
    /// Overhead of the upper bound (instructions).
    pub bound_overhead: f64,
    /// Instructions per work unit of the upper bound.
    pub bound_per_unit: f64,
}

impl CostModel {
    /// The row of `build` in a `COST.md` report (columns: build, calibration frames, LS overhead, LS per unit,
    /// bound overhead, bound per unit, ...), or `None`.
    #[must_use]
    pub fn from_report(report: &str, build: &'static str) -> Option<CostModel> {
        let row = report.lines().find(|l| l.split('|').nth(1).map(str::trim) == Some(build))?;
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let number = |k: usize| cells.get(k)?.parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0);
        Some(CostModel {
            build,
            overhead: number(3)?,
            per_unit: number(4)?,
            bound_overhead: number(5)?,
            bound_per_unit: number(6)?,
        })
    }

    /// The model of the Cortex-M4F (f32) build in this source tree's `firmware-sim/COST.md`.
    ///
    /// # Errors
    /// [`WebError::CostModel`] if the report has no such row.
    pub fn cortex_m4() -> Result<CostModel, WebError> {
        CostModel::from_report(COST_MD, COST_BUILD).ok_or(WebError::CostModel(COST_BUILD))
    }
}

/// A light group as the page shows it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewerGroup {
    /// Name (the scene's).
    pub name: String,
    /// Default intensity (RGB multiplier of the unit emission).
    pub default_intensity: [f64; 3],
}

/// A material as the page shows it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewerMaterial {
    /// Name (the MTL's).
    pub name: String,
    /// Reflectance of the scene (the table holds it quantized).
    pub reflectance: [f64; 3],
}

/// The camera the page starts from (the project's default camera of the scene).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewerCamera {
    /// Eye position (scene units).
    pub position: [f64; 3],
    /// Point the orbit turns around (scene units): the point of the viewing axis nearest the centre of the
    /// scene's bounding box, so the first view is the project's camera.
    pub target: [f64; 3],
    /// Up vector.
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    pub vertical_fov_deg: f64,
}

/// `scene.json`: what the page needs beside the table and the wasm.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewerScene {
    /// Patches (table order).
    pub patches: usize,
    /// Polygon of patch `i`: vertices `polygon_start[i] .. polygon_start[i + 1]` of `vertices`.
    pub polygon_start: Vec<u32>,
    /// Polygon vertices, `x, y, z` each (scene units), convex, counter-clockwise seen from the front.
    pub vertices: Vec<f32>,
    /// Unit normal of every patch, `x, y, z` each: the front side, which carries its radiosity.
    pub normal: Vec<f32>,
    /// Patch areas (scene units squared), for the area-weighted error.
    pub area: Vec<f64>,
    /// Dynamic light groups, table order.
    pub groups: Vec<ViewerGroup>,
    /// Materials, table order.
    pub materials: Vec<ViewerMaterial>,
    /// The starting camera.
    pub camera: ViewerCamera,
    /// Tone map of the default answer: exposure (1 / (W/m^2)) and white point, those of `radiosity render --mode
    /// flat` through the scene's camera at [`TONE_VIEW_SIZE`].
    pub tone: ToneMapJson,
    /// The Cortex-M4 cost model.
    pub cost: CostModel,
    /// Exact f64 radiosity from the static lights, `3 * patches` (W/m^2).
    pub b_static: Vec<f64>,
    /// `t[g]`: exact f64 radiosity from light group `g` at unit intensity, `3 * patches` each.
    pub t: Vec<Vec<f64>>,
}

/// The tone map in `scene.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ToneMapJson {
    /// Exposure (1 / (W/m^2)).
    pub scale: f64,
    /// Exposed luminance shown as white.
    pub white: f64,
}

/// What [`write_viewer`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewerFiles {
    /// The folder.
    pub dir: PathBuf,
    /// Every file written, in the folder.
    pub files: Vec<PathBuf>,
    /// Size of the table in bytes.
    pub table_bytes: usize,
    /// Patches of the scene.
    pub patches: usize,
}

fn flat(v: &[Rgb]) -> Vec<f64> {
    v.iter().flat_map(|c| c.to_array()).collect()
}

/// Checks that `bytes` start like a WebAssembly module (`\0asm`, version 1).
fn check_wasm(path: &Path, bytes: &[u8]) -> Result<(), WebError> {
    if bytes.get(..8) == Some(b"\0asm\x01\0\0\0") {
        Ok(())
    } else {
        Err(WebError::Wasm { path: path.to_path_buf(), why: "not a WebAssembly module".into() })
    }
}

/// Writes the viewer of `prepared` into `dir` (created if missing), with the wasm build of `radiosity-web` at
/// `wasm`. Bakes the table at default settings with a transfer section and solves the f64 transfer vectors.
///
/// # Errors
/// A bake, reference solve or camera that fails, an unreadable or invalid `wasm`, a file that cannot be written.
pub fn write_viewer(prepared: &Prepared, dir: &Path, wasm: &Path) -> Result<ViewerFiles, WebError> {
    let wasm_bytes =
        std::fs::read(wasm).map_err(|e| WebError::Wasm { path: wasm.to_path_buf(), why: e.to_string() })?;
    check_wasm(wasm, &wasm_bytes)?;
    let cost = CostModel::cortex_m4()?;
    let p = prepared;
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions { transfer: true, ..BakeOptions::default() })?;
    let exact = exact_transfer(&p.lighting, &p.form_factors, &Method::for_size(p.patches.len()))?;
    let b = exact.relight(&p.lighting.default_intensity)?;
    let camera = default_camera(p.surfaces())?;
    // The tone map of `radiosity render --mode flat` at its default size: the page's first view is that picture.
    let size = TONE_VIEW_SIZE;
    let view = render_view(
        p.surfaces(),
        &b,
        &RenderOptions { camera: Some(camera), width: size, height: size, mode: RenderMode::Flat },
    )?;
    let tone = view
        .tone
        .ok_or(WebError::Picture(PictureError::invalid("viewer tone map", "the flat view has none")))?;
    let (mut lo, mut hi) = (Rgb::INFINITY, Rgb::NEG_INFINITY);
    let mut polygon_start = vec![0u32];
    let mut vertices = Vec::new();
    for patch in &p.patches {
        for v in &patch.vertices {
            lo = lo.min(*v);
            hi = hi.max(*v);
            vertices.extend(v.as_vec3().to_array());
        }
        polygon_start.push((vertices.len() / 3) as u32);
    }
    let groups = p
        .lighting
        .dynamic_groups
        .iter()
        .zip(&p.lighting.default_intensity)
        .map(|(&g, d)| ViewerGroup {
            name: p.scene.light_groups[g].name.clone(),
            default_intensity: d.to_array(),
        })
        .collect::<Vec<_>>();
    let scene = ViewerScene {
        patches: p.patches.len(),
        polygon_start,
        vertices,
        normal: p.patches.iter().flat_map(|x| x.normal.as_vec3().to_array()).collect(),
        area: p.patches.iter().map(|x| x.area).collect(),
        materials: p
            .scene
            .materials
            .iter()
            .map(|m| ViewerMaterial { name: m.name.clone(), reflectance: m.reflectance.to_array() })
            .collect(),
        camera: ViewerCamera {
            position: camera.position.to_array(),
            target: {
                let to_centre = (lo + hi) / 2.0 - camera.position;
                let along = to_centre.dot(camera.forward).max(1e-3 * to_centre.length());
                (camera.position + camera.forward * along).to_array()
            },
            up: camera.up.to_array(),
            vertical_fov_deg: camera.vertical_fov_deg,
        },
        tone: ToneMapJson { scale: tone.scale, white: tone.white },
        cost,
        b_static: flat(&exact.b_static),
        t: exact.t.iter().map(|t| flat(t)).collect(),
        groups,
    };
    std::fs::create_dir_all(dir).map_err(|source| FileError::Io { path: dir.to_path_buf(), source })?;
    let json = serde_json::to_vec(&scene)?;
    let mut files = Vec::new();
    for (name, bytes) in [
        ("index.html", INDEX_HTML.as_bytes()),
        ("viewer.js", VIEWER_JS.as_bytes()),
        ("radiosity_web.wasm", &wasm_bytes),
        ("scene.rft", &baked.table),
        ("scene.json", &json),
    ] {
        let path = dir.join(name);
        write_atomic(&path, bytes)?;
        files.push(path);
    }
    Ok(ViewerFiles {
        dir: dir.to_path_buf(),
        files,
        table_bytes: baked.table.len(),
        patches: p.patches.len(),
    })
}
