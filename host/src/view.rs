//! Pictures of a solved scene: the glue between the solvers (the flat pipeline's [`Prepared`], the hierarchy's
//! leaves), the Embree module and the picture library. A picture is made of [`Surfaces`]: the scene and the
//! patches whose radiosity it shows, a flat mesh's patches or a hierarchical solve's leaves alike.
//!
//! - [`PatchTracer`]: the patches, fan-triangulated into one Embree mesh, answering closest-hit queries in the
//!   picture module's terms (patch index and hit point).
//! - [`solve_default`]: the f64 radiosity of the scene's default light intensities, as `radiosity solve` computes it.
//! - [`render_view`] / [`render_scene`]: a view through a pinhole camera, smoothly shaded, coloured by patch, or
//!   coloured by error against a reference (with a legend strip below the picture).
//! - [`default_camera`]: the Cornell box's published camera for scenes named `cornell-box*`, else an automatic view
//!   of the bounding box.
//! - [`write_light_map`]: the per-face light-map atlas (`.exr`, `.hdr`, `.png`, `.json`).
//! - [`export_glb`]: the scene as binary glTF 2.0 with the light map embedded (and its `.exr` beside it).

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::embree::{Device, EmbreeError, Ray, SceneOptions, TriangleScene};
use crate::patch::Patch;
use crate::picture::camera::Camera;
use crate::picture::lightmap::{bake_light_map, LightMapOptions};
use crate::picture::render::{render, Colouring, Frame, Hit, View};
use crate::picture::shading::{ShadingOptions, SmoothShader};
use crate::picture::{PictureError, RgbImage};
use crate::pipeline::Prepared;
use crate::reference::{exact_transfer, Method, ReferenceError};
use crate::rgb::Rgb;
use crate::scene::Scene;

/// Errors of the view glue; each wraps the module that failed.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// Building the Embree scene failed.
    #[error("ray tracing the patches: {0}")]
    Embree(#[from] EmbreeError),
    /// A picture could not be made or written.
    #[error(transparent)]
    Picture(#[from] PictureError),
    /// The f64 reference solve failed.
    #[error("f64 reference solve: {0}")]
    Reference(#[from] ReferenceError),
}

/// What a picture is made of: the scene (its file name picks [`default_camera`], its materials go into a `.glb`)
/// and the patches whose radiosity the picture shows, each keeping its face: the flat pipeline's adaptive mesh
/// ([`Prepared::surfaces`]) or a hierarchical solve's leaves
/// ([`HierarchicalSolution::leaves`](crate::hierarchy::HierarchicalSolution::leaves)).
#[derive(Clone, Copy, Debug)]
pub struct Surfaces<'a> {
    /// The scene the patches were made from.
    pub scene: &'a Scene,
    /// The patches; radiosity vectors given with them have one value per patch, in this order.
    pub patches: &'a [Patch],
}

impl Prepared {
    /// The scene and its adaptive mesh, for pictures.
    #[must_use]
    pub fn surfaces(&self) -> Surfaces<'_> {
        Surfaces { scene: &self.scene, patches: &self.patches }
    }
}

/// Most surfaces a primary ray passes through from behind before it gives up (see [`PatchTracer::closest_hit`]).
const MAX_BACK_FACES: usize = 16;

/// The patches as one Embree triangle mesh: each convex patch polygon is fan-triangulated, and triangle `t` maps
/// back to patch `triangle_patch[t]`.
#[derive(Debug)]
pub struct PatchTracer {
    scene: TriangleScene,
    triangle_patch: Vec<u32>,
    normals: Vec<DVec3>,
}

impl PatchTracer {
    /// Builds the mesh of `patches`.
    ///
    /// # Errors
    /// [`ViewError::Embree`] if a vertex is not finite or Embree fails to build the scene.
    pub fn new(patches: &[Patch]) -> Result<Self, ViewError> {
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        let mut triangle_patch = Vec::new();
        for (index, p) in patches.iter().enumerate() {
            let base = vertices.len() as u32;
            vertices.extend(p.vertices.iter().map(|v| v.as_vec3()));
            for k in 1..p.vertices.len().saturating_sub(1) as u32 {
                triangles.push([base, base + k, base + k + 1]);
                triangle_patch.push(index as u32);
            }
        }
        let scene = Device::new()?.triangle_scene(&vertices, &triangles, SceneOptions { robust: true })?;
        Ok(PatchTracer { scene, triangle_patch, normals: patches.iter().map(|p| p.normal).collect() })
    }

    /// The closest patch whose front side (the side its normal points to, the side that carries its radiosity)
    /// faces the ray, and the hit point.
    ///
    /// Surfaces seen from behind are skipped (back-face culling, continuing the ray just past them), so a camera
    /// outside a closed room sees through the wall facing it into the room. After `MAX_BACK_FACES` back faces in
    /// a row the ray counts as a miss.
    #[must_use]
    pub fn closest_hit(&self, origin: DVec3, direction: DVec3) -> Option<Hit> {
        let o = origin.as_vec3();
        let d = direction.as_vec3();
        let mut tnear = 0.0f32;
        for _ in 0..MAX_BACK_FACES {
            let hit = self.scene.intersect(&Ray::new(o, d, tnear, f32::INFINITY))?;
            let patch = *self.triangle_patch.get(hit.primitive as usize)? as usize;
            let point = origin + direction * f64::from(hit.t);
            if self.normals[patch].dot(direction) < 0.0 {
                return Some(Hit { patch, point });
            }
            // Step past the back face by the scene's intersection offset (in units of the direction's length).
            tnear = hit.t + self.scene.offset() / d.length().max(f32::MIN_POSITIVE);
        }
        None
    }
}

/// The f64 radiosity of every patch at the scene's default light intensities: transfer vectors by
/// [`Method::for_size`], relit with the default intensities (exactly what `radiosity solve` prints).
///
/// # Errors
/// [`ViewError::Reference`] if the system is invalid or the solve fails.
pub fn solve_default(prepared: &Prepared) -> Result<Vec<Rgb>, ViewError> {
    let l = &prepared.lighting;
    let tv = exact_transfer(l, &prepared.form_factors, &Method::for_size(prepared.patches.len()))?;
    Ok(tv.relight(&l.default_intensity)?)
}

/// What a rendered view shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RenderMode<'a> {
    /// Smoothly shaded radiosity, tone mapped ([`Colouring::Shaded`]).
    Shaded,
    /// One radiosity value per patch, tone mapped ([`Colouring::Flat`]): what the browser viewer draws.
    Flat,
    /// A distinct colour per patch, showing the mesh ([`Colouring::ByPatch`]).
    Patches,
    /// Per-patch relative error of the rendered radiosity against `reference`, false-coloured, with a legend
    /// strip appended below the picture ([`Colouring::Error`]).
    Error {
        /// The reference radiosity (e.g. the f64 solve), one value per patch.
        reference: &'a [Rgb],
    },
}

/// How to render a view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions<'a> {
    /// The camera; `None` takes [`default_camera`].
    pub camera: Option<Camera>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// What to show.
    pub mode: RenderMode<'a>,
}

/// Height in pixels of the legend strip of error views.
pub const LEGEND_HEIGHT: u32 = 48;

/// Narrowest legend strip (pixels); narrower views get a legend this wide and the picture is padded black.
pub const LEGEND_MIN_WIDTH: u32 = 256;

/// The default camera for a scene: the Cornell box's published camera ([`Camera::cornell_box`]) when the scene
/// file's stem starts with `cornell-box`, else [`auto_camera`] of the patches.
///
/// # Errors
/// As [`auto_camera`].
pub fn default_camera(surfaces: Surfaces<'_>) -> Result<Camera, ViewError> {
    let cornell =
        surfaces.scene.path.file_stem().is_some_and(|s| s.to_string_lossy().starts_with("cornell-box"));
    if cornell {
        Ok(Camera::cornell_box())
    } else {
        auto_camera(surfaces.patches)
    }
}

/// A view of the whole bounding box of `patches`: looking along +z (the Cornell box's convention: the scene's
/// open side faces -z) at the box centre, up +y, a 40 degree vertical field of view, from far enough that the
/// bounding sphere fits the vertical field: distance `r / sin(fov / 2)` from the centre, `r` half the diagonal.
///
/// # Errors
/// [`ViewError::Picture`] if there are no patches or the box is degenerate (a single point).
pub fn auto_camera(patches: &[Patch]) -> Result<Camera, ViewError> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for v in patches.iter().flat_map(|p| &p.vertices) {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    if patches.is_empty() {
        return Err(PictureError::invalid("automatic camera", "the scene has no patches").into());
    }
    let centre = (lo + hi) / 2.0;
    let radius = (hi - lo).length() / 2.0;
    let fov = 40.0f64;
    let distance = radius / (fov.to_radians() / 2.0).sin();
    Ok(Camera::look_at(centre - DVec3::Z * distance, centre, DVec3::Y, fov)?)
}

/// Renders a view of `surfaces` with per-patch radiosity `b` and returns the picture with its per-pixel data.
///
/// Shaded views smooth `b` across compatible neighbours ([`SmoothShader`], default options), flat views show
/// each patch's own `b`; both tone map with the picture module's default (an exposure from a percentile of the visible luminances, extended Reinhard, sRGB).
/// Error views colour by `b`'s error against the reference; the returned image has the legend appended.
///
/// # Errors
/// [`ViewError::Embree`] building the ray-tracing scene; [`ViewError::Picture`] for a bad size, a bad camera,
/// `b` or the reference of the wrong length, or a non-finite value (naming the patch or pixel).
pub fn render_view(
    surfaces: Surfaces<'_>,
    b: &[Rgb],
    options: &RenderOptions<'_>,
) -> Result<View, ViewError> {
    let camera = match options.camera {
        Some(c) => c,
        None => default_camera(surfaces)?,
    };
    let frame = Frame { camera, width: options.width, height: options.height };
    let tracer = PatchTracer::new(surfaces.patches)?;
    let shader = SmoothShader::new(surfaces.patches, &ShadingOptions::default())?;
    let colouring = match options.mode {
        RenderMode::Shaded => Colouring::Shaded,
        RenderMode::Flat => Colouring::Flat,
        RenderMode::Patches => Colouring::ByPatch,
        RenderMode::Error { reference } => Colouring::Error { reference, scale: None },
    };
    let trace = |o: DVec3, d: DVec3| tracer.closest_hit(o, d);
    let mut view = render(&frame, &trace, &shader, b, colouring, None)?;
    if let Some(scale) = view.error_scale {
        let legend =
            scale.legend("relative error of B", options.width.max(LEGEND_MIN_WIDTH), LEGEND_HEIGHT)?;
        view.image = stack(&view.image, &legend);
    }
    Ok(view)
}

/// Renders a view (see [`render_view`]) and returns only the picture.
///
/// # Errors
/// As [`render_view`].
pub fn render_scene(
    surfaces: Surfaces<'_>,
    b: &[Rgb],
    options: &RenderOptions<'_>,
) -> Result<RgbImage, ViewError> {
    Ok(render_view(surfaces, b, options)?.image)
}

/// `top` above `bottom` (widths are equal for legends made at the view's width; narrower rows are padded black).
fn stack(top: &RgbImage, bottom: &RgbImage) -> RgbImage {
    let width = top.width.max(bottom.width);
    let mut out = RgbImage::new(width, top.height + bottom.height);
    for (image, y0) in [(top, 0), (bottom, top.height)] {
        for y in 0..image.height {
            for x in 0..image.width {
                out.put(x, y0 + y, image.get(x, y));
            }
        }
    }
    out
}

/// What [`write_light_map`] wrote: the files and the atlas's resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct LightMapFiles {
    /// `<stem>.exr`, `<stem>.hdr`, `<stem>.png` and `<stem>.json`.
    pub paths: [PathBuf; 4],
    /// Atlas width in texels.
    pub width: u32,
    /// Atlas height in texels.
    pub height: u32,
    /// Texel edge length in scene units.
    pub texel_size: f64,
}

/// Bakes the light map of `surfaces` with radiosity `b` (smooth shading, resolution from `options`) and writes
/// `<stem>.exr`, `<stem>.hdr`, `<stem>.png` and `<stem>.json`. Every OBJ face gets a rectangle.
///
/// # Errors
/// [`ViewError::Picture`] if a face has no patch, `b` has the wrong length or holds a non-finite value, the
/// texel size gives a face or the atlas more texels than allowed, or a file cannot be written.
pub fn write_light_map(
    surfaces: Surfaces<'_>,
    b: &[Rgb],
    stem: &Path,
    options: &LightMapOptions,
) -> Result<LightMapFiles, ViewError> {
    let shader = SmoothShader::new(surfaces.patches, &ShadingOptions::default())?;
    let map = bake_light_map(surfaces.patches, &shader, b, options)?;
    let paths = map.write(stem, None)?;
    Ok(LightMapFiles { paths, width: map.atlas.width, height: map.atlas.height, texel_size: map.texel_size })
}

/// What [`export_glb`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportFiles {
    /// The `.glb` file.
    pub glb: PathBuf,
    /// Beside it, the same light map in full precision: `<glb stem>.exr`, the irradiance atlas (W/m^2, RGB
    /// 32-bit float) that the embedded PNG encodes in 8 bits.
    pub exr: PathBuf,
    /// Atlas width in texels.
    pub width: u32,
    /// Atlas height in texels.
    pub height: u32,
    /// Texel edge length in scene units.
    pub texel_size: f64,
    /// Irradiance (W/m^2) of a light-map texel of linear value 1: the light map's intensity.
    pub irradiance_scale: f64,
    /// Triangles in the file.
    pub triangles: usize,
}

/// Bakes the light map of `surfaces` with radiosity `b` (as [`write_light_map`]) and writes the scene as binary
/// glTF 2.0 to `path` with the light map embedded ([`crate::picture::glb`]), and its irradiance atlas beside it
/// as OpenEXR (`path` with extension `.exr`). The tone map suggested in the file is the light map's default
/// ([`ToneMap::from_percentile`](crate::picture::ToneMap::from_percentile) over the chart texels).
///
/// # Errors
/// As [`write_light_map`]; [`ViewError::Picture`] also if a face mixes materials.
pub fn export_glb(
    surfaces: Surfaces<'_>,
    b: &[Rgb],
    path: &Path,
    options: &LightMapOptions,
) -> Result<ExportFiles, ViewError> {
    use crate::picture::{glb, hdr, ToneMap};
    let shader = SmoothShader::new(surfaces.patches, &ShadingOptions::default())?;
    let map = bake_light_map(surfaces.patches, &shader, b, options)?;
    let tone = ToneMap::from_percentile(
        &map.face_luminances(),
        ToneMap::DEFAULT_PERCENTILE,
        ToneMap::DEFAULT_WHITE,
    )?;
    let file = glb::encode_glb(surfaces.patches, &surfaces.scene.materials, &map, tone)?;
    let exr = path.with_extension("exr");
    hdr::write_exr(&exr, &file.irradiance)?;
    crate::picture::write_file(path, &file.bytes)?;
    Ok(ExportFiles {
        glb: path.to_path_buf(),
        exr,
        width: map.atlas.width,
        height: map.atlas.height,
        texel_size: map.texel_size,
        irradiance_scale: file.irradiance_scale,
        triangles: file.triangles,
    })
}
