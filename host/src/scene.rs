//! Scene loading: a Wavefront OBJ + MTL pair (and an optional `NAME.toml` beside the OBJ) turned into validated
//! faces, materials and light groups.
//!
//! # Format
//! - Geometry: OBJ `v` and `f` statements, read with `tobj` without triangulation, so every face is the polygon
//!   the file wrote. Faces are numbered 0, 1, 2, ... in OBJ order over all objects: [`Scene::faces`]`[k]` is the
//!   k-th `f` statement of the file. A face's normal follows its vertex order (counter-clockwise seen from the
//!   side the normal points to, the right-hand rule); only that side emits and receives light.
//! - Materials: MTL `Kd` is the reflectance (per channel, in `[0, 1)`, required), `Ke` the emission as radiant
//!   exitance in W/m^2 (per channel, finite and `>= 0`, default 0).
//! - `NAME.toml` (optional, beside `NAME.obj`):
//!   ```toml
//!   [meshing]
//!   max_patch_edge = 100.0   # scene units; largest patch edge after uniform subdivision
//!   patch_budget = 2000      # most patches the mesh may have (uniform plus adaptive)
//!   refine_passes = 3        # adaptive refinement passes after uniform subdivision (0: uniform only)
//!   refine_tolerance = 0.05  # refine where radiosity changes by more than this times the mean radiosity
//!
//!   [[light_group]]
//!   name = "light"
//!   materials = ["light"]    # emitting materials that belong to the group
//!   dynamic = true           # false: folded into the static base at bake time (default true)
//!   intensity = [1.0, 1.0, 1.0]  # default intensity, RGB or one number (default 1)
//!   ```
//!   Every material with a nonzero `Ke` that no `[[light_group]]` lists becomes its own dynamic light group,
//!   named after the material, at intensity 1.
//!
//! # Validation
//! [`Scene::load`] returns a [`SceneError`] naming the file, the line and (for faces) the face index, for: a
//! missing or unreadable file, an OBJ/MTL/TOML syntax error, a face without a defined material, a reflectance
//! outside `[0, 1)`, a negative or non-finite value, a face with fewer than three vertices, non-finite or
//! repeated vertices or zero area (degenerate), a non-convex face, a face too far from planar, and coplanar faces
//! that overlap with positive area (duplicates included). Nothing in this module panics on any input.
//!
//! `tobj` reports no line numbers: after a syntax error the loader finds its line by re-parsing prefixes of the
//! file (binary search), and it maps faces to lines by scanning the `f` statements itself. It also checks MTL
//! colour statements (`Ka`, `Kd`, `Ks`, `Ke`: exactly three numbers) before `tobj` sees them, because `tobj`
//! panics on fewer than three.
//!
//! # Tolerances (all relative to the size of the face, its diameter `d` = largest vertex-to-vertex distance)
//! - Planar: every vertex within [`PLANAR_TOLERANCE`]` * d` of the face's mean plane (Newell normal through the
//!   vertex mean). f64 arithmetic is exact to ~1e-16 relative, so 1e-6 is there to accept faces whose
//!   coordinates were rounded to about six significant digits when the file was written.
//! - Non-planar but within [`NON_PLANAR_LIMIT`]` * d` (1 %): the face is split into a triangle fan from its first
//!   vertex, with a [`SceneWarning`]. The published Cornell box's red wall deviates by 0.80 mm from its mean
//!   plane (its fourth vertex is 3.2 mm off the plane of the other three) on a diameter of 783.5 mm, i.e. 0.10 %.
//!   Beyond 1 % the face is an error: its shape is then not what the file meant.
//! - Degenerate: two vertices closer than [`DEGENERATE_TOLERANCE`]` * d`, or an area below
//!   [`DEGENERATE_TOLERANCE`]` * d^2`.
//! - Coplanar overlap: two polygons are coplanar when each one's vertices lie within [`PLANAR_TOLERANCE`]` * d`
//!   (the larger `d` of the two) of the other's plane; they overlap when the area of their intersection exceeds
//!   [`OVERLAP_TOLERANCE`] times the smaller area (faces that only share an edge intersect in zero area up to
//!   rounding, ~1e-16 relative).

use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::f64::consts::TAU;
use std::fmt;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::Deserialize;

/// Largest distance of a vertex from the face's mean plane, relative to the face diameter, for a planar face.
pub const PLANAR_TOLERANCE: f64 = 1e-6;
/// Largest distance of a vertex from the face's mean plane, relative to the face diameter, for a face that is
/// split into triangles with a warning; beyond it the face is an error.
pub const NON_PLANAR_LIMIT: f64 = 1e-2;
/// Relative size below which vertices coincide (times the diameter) or an area is zero (times the diameter
/// squared).
pub const DEGENERATE_TOLERANCE: f64 = 1e-9;
/// Intersection area of two coplanar polygons, relative to the smaller polygon's area, above which they overlap.
pub const OVERLAP_TOLERANCE: f64 = 1e-6;

/// A planar convex polygon with its unit normal, area and area centroid.
#[derive(Clone, Debug, PartialEq)]
pub struct Polygon {
    /// Vertices, counter-clockwise seen from the side the normal points to.
    pub vertices: Vec<DVec3>,
    /// Unit normal.
    pub normal: DVec3,
    /// Area.
    pub area: f64,
    /// Area centroid.
    pub centroid: DVec3,
}

impl Polygon {
    /// A polygon from its vertices, with the normal and area from Newell's method and the area centroid from a
    /// triangle fan. `None` if the area is zero or a value is not finite.
    #[must_use]
    pub fn new(vertices: Vec<DVec3>) -> Option<Polygon> {
        let n = newell(&vertices);
        let len = n.length();
        if !(len.is_finite() && len > 0.0) {
            return None;
        }
        let normal = n / len;
        Polygon::with_normal(vertices, normal)
    }

    /// A polygon from its vertices and a known unit normal (e.g. its parent's, so that pieces of a face keep the
    /// face's normal exactly). `None` if the area along `normal` is not positive or a value is not finite.
    #[must_use]
    pub fn with_normal(vertices: Vec<DVec3>, normal: DVec3) -> Option<Polygon> {
        let area = 0.5 * newell(&vertices).dot(normal);
        if !(area.is_finite() && area > 0.0) || vertices.len() < 3 {
            return None;
        }
        let centroid = area_centroid(&vertices, normal)?;
        Some(Polygon { vertices, normal, area, centroid })
    }

    /// Largest distance between two vertices.
    #[must_use]
    pub fn diameter(&self) -> f64 {
        diameter(&self.vertices)
    }

    /// Longest edge.
    #[must_use]
    pub fn max_edge(&self) -> f64 {
        edges(&self.vertices).map(|(a, b)| a.distance(b)).fold(0.0, f64::max)
    }
}

/// Twice the vector area of a polygon (Newell's method): for a planar polygon, the normal times twice the area.
fn newell(v: &[DVec3]) -> DVec3 {
    // Newell's method (Sutherland, Sproull, Schumacker 1974): sum of cross products of consecutive vertices,
    // taken relative to the first vertex to limit cancellation.
    let Some(&o) = v.first() else { return DVec3::ZERO };
    let mut n = DVec3::ZERO;
    for (a, b) in edges(v) {
        n += (a - o).cross(b - o);
    }
    n
}

/// Area centroid of a planar polygon by a triangle fan from the first vertex.
fn area_centroid(v: &[DVec3], normal: DVec3) -> Option<DVec3> {
    let o = *v.first()?;
    let mut sum = DVec3::ZERO;
    let mut total = 0.0;
    for w in v.windows(2).skip(1) {
        let a = 0.5 * (w[0] - o).cross(w[1] - o).dot(normal);
        sum += a * (o + w[0] + w[1]) / 3.0;
        total += a;
    }
    if total > 0.0 && total.is_finite() {
        Some(sum / total)
    } else {
        None
    }
}

/// Consecutive vertex pairs, closing the loop.
fn edges(v: &[DVec3]) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
    v.iter().enumerate().map(move |(i, &a)| (a, v[(i + 1) % v.len()]))
}

fn diameter(v: &[DVec3]) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in v.iter().enumerate() {
        for b in &v[i + 1..] {
            d = d.max(a.distance(*b));
        }
    }
    d
}

/// One OBJ face, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// Index of the face in OBJ order (0-based, over all objects): the k-th `f` statement has index k.
    pub index: usize,
    /// Line of the face's `f` statement in the OBJ file (1-based).
    pub line: usize,
    /// Name of the OBJ object or group (`o` / `g`) the face belongs to; `"unnamed_object"` or empty if none.
    pub object: String,
    /// Index of the face's material in [`Scene::materials`].
    pub material: usize,
    /// Vertices as written in the OBJ file.
    pub vertices: Vec<DVec3>,
    /// Unit normal of the face's mean plane (Newell's method), on the side its vertex order gives.
    pub normal: DVec3,
    /// Area of the face (sum of the areas of its polygons).
    pub area: f64,
    /// The planar convex polygons that make up the face: the face itself when it is planar, or the triangles of
    /// a fan from its first vertex when it was split for being non-planar (see [`Face::is_split`]).
    pub polygons: Vec<Polygon>,
}

impl Face {
    /// Whether the face was split into triangles because it is not planar.
    #[must_use]
    pub fn is_split(&self) -> bool {
        self.polygons.len() != 1 || self.polygons.first().is_some_and(|p| p.vertices != self.vertices)
    }
}

/// A diffuse material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the MTL `newmtl` statement.
    pub name: String,
    /// Reflectance per RGB channel (`Kd`), each in `[0, 1)`.
    pub reflectance: [f64; 3],
    /// Emission per RGB channel (`Ke`), radiant exitance in W/m^2, each finite and `>= 0`.
    pub emission: [f64; 3],
}

impl Material {
    /// Whether the material emits light (any channel of `Ke` above zero).
    #[must_use]
    pub fn is_emitter(&self) -> bool {
        self.emission.iter().any(|&e| e > 0.0)
    }
}

/// A light group: emitting materials whose intensity changes together.
#[derive(Clone, Debug, PartialEq)]
pub struct LightGroup {
    /// Name (from the TOML file, or the material's name for an implicit group).
    pub name: String,
    /// Indices of the group's materials in [`Scene::materials`].
    pub materials: Vec<usize>,
    /// Whether the group's intensity can change at run time (a static group is folded into the base).
    pub dynamic: bool,
    /// Default intensity per RGB channel, multiplying the materials' `Ke`.
    pub intensity: [f64; 3],
}

/// Meshing limits from the scene's TOML file; `None` where the file does not set them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeshingLimits {
    /// Longest patch edge after uniform subdivision, in scene units.
    pub max_patch_edge: Option<f64>,
    /// Most patches the mesh may have.
    pub patch_budget: Option<usize>,
    /// Adaptive refinement passes after uniform subdivision (0: uniform only); see [`crate::mesh`].
    pub refine_passes: Option<usize>,
    /// Smallest radiosity change across a patch, relative to the scene's mean radiosity, that makes the patch a
    /// candidate for refinement; see [`crate::mesh`].
    pub refine_tolerance: Option<f64>,
}

/// A problem in the input that did not stop loading.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneWarning {
    /// File the warning is about.
    pub file: PathBuf,
    /// Line in that file (1-based).
    pub line: usize,
    /// Face index in OBJ order.
    pub face: usize,
    /// What happened.
    pub message: String,
}

impl fmt::Display for SceneWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: face {}: {}", self.file.display(), self.line, self.face, self.message)
    }
}

/// A loaded, validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The OBJ file the scene came from.
    pub path: PathBuf,
    /// Faces in OBJ order.
    pub faces: Vec<Face>,
    /// Materials of all MTL files, in the order they were defined.
    pub materials: Vec<Material>,
    /// Light groups: first those of the TOML file in its order, then one per emitting material it does not
    /// list, in material order.
    pub light_groups: Vec<LightGroup>,
    /// Meshing limits from the TOML file.
    pub meshing: MeshingLimits,
    /// Problems that did not stop loading (e.g. non-planar faces split into triangles). Not printed here.
    pub warnings: Vec<SceneWarning>,
}

/// Why a scene could not be loaded. Every variant names the file, and the line and face where it applies.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// A file is missing or unreadable.
    #[error("cannot read {}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file is not valid UTF-8.
    #[error("{}:{line}: not valid UTF-8", file.display())]
    NotUtf8 {
        /// The file.
        file: PathBuf,
        /// First line with invalid bytes.
        line: usize,
    },
    /// A syntax error in the OBJ or an MTL file.
    #[error("{}:{line}: parse error: {problem}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// Line of the error (1-based).
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// The OBJ file has no faces.
    #[error("{}: the scene has no faces", file.display())]
    NoFaces {
        /// The OBJ file.
        file: PathBuf,
    },
    /// A face uses a material no MTL file defines, or no material at all.
    #[error("{}:{line}: face {face}: {problem}", file.display())]
    MissingMaterial {
        /// The OBJ file.
        file: PathBuf,
        /// Line of the face.
        line: usize,
        /// Face index in OBJ order.
        face: usize,
        /// Which material is missing.
        problem: String,
    },
    /// A material's value is missing, out of range, negative or not finite.
    #[error("{}:{line}: material '{material}': {problem}", file.display())]
    BadMaterial {
        /// The MTL file.
        file: PathBuf,
        /// Line of the offending statement (or of `newmtl` when a statement is missing).
        line: usize,
        /// Material name.
        material: String,
        /// What is wrong.
        problem: String,
    },
    /// A face is degenerate: fewer than three vertices, non-finite or repeated vertices, or zero area.
    #[error("{}:{line}: face {face}: degenerate face: {problem}", file.display())]
    DegenerateFace {
        /// The OBJ file.
        file: PathBuf,
        /// Line of the face.
        line: usize,
        /// Face index in OBJ order.
        face: usize,
        /// What is wrong.
        problem: String,
    },
    /// A face is not convex.
    #[error("{}:{line}: face {face}: non-convex face: {problem}", file.display())]
    NonConvexFace {
        /// The OBJ file.
        file: PathBuf,
        /// Line of the face.
        line: usize,
        /// Face index in OBJ order.
        face: usize,
        /// Where the polygon is not convex.
        problem: String,
    },
    /// A face is further from planar than [`NON_PLANAR_LIMIT`] allows.
    #[error(
        "{}:{line}: face {face}: non-planar face: a vertex is {deviation:.4} from the face's mean plane, more than \
         the limit {limit:.4} (1% of the face diameter)",
        file.display()
    )]
    NonPlanarFace {
        /// The OBJ file.
        file: PathBuf,
        /// Line of the face.
        line: usize,
        /// Face index in OBJ order.
        face: usize,
        /// Largest distance of a vertex from the mean plane, in scene units.
        deviation: f64,
        /// The allowed distance, in scene units.
        limit: f64,
    },
    /// Two coplanar faces overlap with positive area (or are duplicates).
    #[error(
        "{}:{line_a}: face {face_a} and line {line_b}: face {face_b} are coplanar and overlap (area {area:.6e}; \
         duplicate or overlapping faces)",
        file.display()
    )]
    OverlappingFaces {
        /// The OBJ file.
        file: PathBuf,
        /// First face index.
        face_a: usize,
        /// Line of the first face.
        line_a: usize,
        /// Second face index.
        face_b: usize,
        /// Line of the second face.
        line_b: usize,
        /// Area of the intersection, in scene units squared.
        area: f64,
    },
    /// The TOML file does not parse.
    #[error("{}: {message}", file.display())]
    TomlParse {
        /// The TOML file.
        file: PathBuf,
        /// The parser's message, with line and column.
        message: String,
    },
    /// The TOML file parses but says something invalid about the scene.
    #[error("{}: {problem}", file.display())]
    TomlInvalid {
        /// The TOML file.
        file: PathBuf,
        /// What is wrong.
        problem: String,
    },
}

impl Scene {
    /// Loads `NAME.obj`, the MTL files it names (relative to its folder) and `NAME.toml` if it exists.
    ///
    /// # Errors
    /// A [`SceneError`] naming the file, line and face of the first problem found.
    pub fn load(obj_path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        let obj_path = obj_path.as_ref();
        let toml_path = obj_path.with_extension("toml");
        let toml = if toml_path.is_file() { Some(toml_path) } else { None };
        Scene::load_with_toml(obj_path, toml.as_deref())
    }

    /// Loads `obj_path` and its MTL files, and takes light groups and meshing limits from `toml_path` if given.
    ///
    /// # Errors
    /// A [`SceneError`] naming the file, line and face of the first problem found.
    pub fn load_with_toml(obj_path: &Path, toml_path: Option<&Path>) -> Result<Scene, SceneError> {
        let text = read_text(obj_path)?;
        let obj = load_obj(obj_path, &text)?;
        let materials = check_materials(&obj)?;
        let mut warnings = Vec::new();
        let faces = build_faces(obj_path, &obj, &materials, &mut warnings)?;
        check_overlaps(obj_path, &faces)?;
        let settings = match toml_path {
            Some(p) => {
                let t = read_text(p)?;
                toml::from_str::<TomlScene>(&t)
                    .map_err(|e| SceneError::TomlParse { file: p.to_path_buf(), message: e.to_string() })?
            }
            None => TomlScene::default(),
        };
        let toml_file = toml_path.map_or_else(|| obj_path.with_extension("toml"), Path::to_path_buf);
        let meshing = check_meshing(&toml_file, settings.meshing.as_ref())?;
        let light_groups = build_light_groups(&toml_file, &settings.light_group, &materials)?;
        Ok(Scene { path: obj_path.to_path_buf(), faces, materials, light_groups, meshing, warnings })
    }

    /// Total area of all faces.
    #[must_use]
    pub fn total_area(&self) -> f64 {
        self.faces.iter().map(|f| f.area).sum()
    }

    /// The light group a material belongs to, if any (an index into [`Scene::light_groups`]).
    #[must_use]
    pub fn light_group_of(&self, material: usize) -> Option<usize> {
        self.light_groups.iter().position(|g| g.materials.contains(&material))
    }
}

fn read_text(path: &Path) -> Result<String, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io { file: path.to_path_buf(), source })?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = e.as_bytes().get(..valid).map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count()) + 1;
        SceneError::NotUtf8 { file: path.to_path_buf(), line }
    })
}

/// What the loader reads from a face's `f` statement besides the geometry.
struct FaceStatement {
    line: usize,
    /// The name given by the last `usemtl` before the face, if any.
    usemtl: Option<String>,
}

/// Where a material is defined, for messages.
#[derive(Clone)]
struct MaterialSource {
    file: PathBuf,
    newmtl_line: usize,
    kd_line: Option<usize>,
    ke_line: Option<usize>,
}

struct ObjData {
    file: PathBuf,
    models: Vec<tobj::Model>,
    materials: Vec<tobj::Material>,
    statements: Vec<FaceStatement>,
    sources: HashMap<String, MaterialSource>,
}

fn load_options() -> tobj::LoadOptions {
    // Faces as written (no triangulation), one index per vertex; points and lines are kept so that they are
    // reported as degenerate faces instead of vanishing.
    tobj::LoadOptions { single_index: true, triangulate: false, ignore_points: false, ignore_lines: false }
}

/// Smallest number of leading lines of `text` for which `fails` holds: the line of the first syntax error for a
/// parser that fails as soon as it has read a bad line (tobj reports no line numbers). Binary search over prefixes,
/// only run after a parse has failed.
fn first_failing_line(text: &str, fails: impl Fn(&str) -> bool) -> usize {
    let ends: Vec<usize> =
        text.match_indices('\n').map(|(i, _)| i + 1).chain(std::iter::once(text.len())).collect();
    let (mut lo, mut hi) = (1, ends.len());
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if text.get(..ends[mid - 1]).is_some_and(&fails) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

fn load_obj(obj_path: &Path, text: &str) -> Result<ObjData, SceneError> {
    let dir = obj_path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mtl_error: RefCell<Option<SceneError>> = RefCell::new(None);
    let sources: RefCell<HashMap<String, MaterialSource>> = RefCell::new(HashMap::new());
    let loader = |p: &Path| -> tobj::MTLLoadResult {
        let path = dir.join(p);
        let result = read_text(&path).and_then(|mtl| {
            scan_mtl(&path, &mtl, &mut sources.borrow_mut())?;
            tobj::load_mtl_buf(&mut mtl.as_bytes()).map_err(|e| SceneError::Parse {
                file: path.clone(),
                line: first_failing_line(&mtl, |s| tobj::load_mtl_buf(&mut s.as_bytes()).is_err()),
                problem: e.to_string(),
            })
        });
        result.map_err(|e| {
            let mut slot = mtl_error.borrow_mut();
            if slot.is_none() {
                *slot = Some(e);
            }
            tobj::LoadError::OpenFileFailed
        })
    };
    let loaded = tobj::load_obj_buf(&mut text.as_bytes(), &load_options(), loader);
    if let Some(e) = mtl_error.into_inner() {
        return Err(e);
    }
    let (models, materials) = loaded.map_err(|e| SceneError::Parse {
        file: obj_path.to_path_buf(),
        line: first_failing_line(text, |s| {
            tobj::load_obj_buf(&mut s.as_bytes(), &load_options(), |_| Err(tobj::LoadError::OpenFileFailed))
                .is_err()
        }),
        problem: e.to_string(),
    })?;
    // No MTL file loaded at all gives an error here; faces then fail as missing materials, which names them.
    let materials = materials.unwrap_or_default();
    let mut statements = Vec::new();
    let mut usemtl = None;
    for (i, line) in text.lines().enumerate() {
        match line.split_whitespace().next() {
            Some("f" | "l") => statements.push(FaceStatement { line: i + 1, usemtl: usemtl.clone() }),
            // Same name extraction as tobj: everything after the first space, trimmed.
            Some("usemtl") => usemtl = line.split_once(' ').map(|(_, n)| n.trim().to_owned()),
            _ => {}
        }
    }
    Ok(ObjData { file: obj_path.to_path_buf(), models, materials, statements, sources: sources.into_inner() })
}

/// Records where each material of an MTL file is defined; rejects duplicate names.
fn scan_mtl(
    path: &Path,
    text: &str,
    sources: &mut HashMap<String, MaterialSource>,
) -> Result<(), SceneError> {
    let mut current: Option<String> = None;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim();
        match trimmed.split_whitespace().next() {
            Some("newmtl") => {
                let name = trimmed.get(6..).unwrap_or("").trim().to_owned();
                if let Some(old) = sources.get(&name) {
                    return Err(SceneError::BadMaterial {
                        file: path.to_path_buf(),
                        line: line_no,
                        material: name,
                        problem: format!(
                            "defined twice (first at {}:{})",
                            old.file.display(),
                            old.newmtl_line
                        ),
                    });
                }
                sources.insert(
                    name.clone(),
                    MaterialSource {
                        file: path.to_path_buf(),
                        newmtl_line: line_no,
                        kd_line: None,
                        ke_line: None,
                    },
                );
                current = Some(name);
            }
            // tobj panics on a colour with fewer than three numbers and ignores extra ones: check them here.
            Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) => {
                let values: Vec<&str> = trimmed.split_whitespace().skip(1).collect();
                if values.len() != 3 || values.iter().any(|v| v.parse::<f64>().is_err()) {
                    return Err(SceneError::Parse {
                        file: path.to_path_buf(),
                        line: line_no,
                        problem: format!("{key} needs exactly three numbers, got {:?}", values.join(" ")),
                    });
                }
                if let Some(src) = current.as_ref().and_then(|n| sources.get_mut(n)) {
                    match key {
                        "Kd" => src.kd_line = Some(line_no),
                        "Ke" => src.ke_line = Some(line_no),
                        _ => {}
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

fn check_materials(obj: &ObjData) -> Result<Vec<Material>, SceneError> {
    let mut out = Vec::with_capacity(obj.materials.len());
    for m in &obj.materials {
        let src = obj.sources.get(&m.name).cloned().unwrap_or(MaterialSource {
            file: obj.file.clone(),
            newmtl_line: 0,
            kd_line: None,
            ke_line: None,
        });
        let bad = |line: Option<usize>, problem: String| SceneError::BadMaterial {
            file: src.file.clone(),
            line: line.unwrap_or(src.newmtl_line),
            material: m.name.clone(),
            problem,
        };
        let Some(kd) = m.diffuse else {
            return Err(bad(None, "no reflectance (Kd) given".to_owned()));
        };
        let ke = m.emissive.unwrap_or([0.0; 3]);
        for (c, &r) in kd.iter().enumerate() {
            if !r.is_finite() {
                return Err(bad(src.kd_line, format!("reflectance Kd channel {c} is not finite ({r})")));
            }
            if !(0.0..1.0).contains(&r) {
                return Err(bad(src.kd_line, format!("reflectance Kd channel {c} = {r} is outside [0, 1)")));
            }
        }
        for (c, &e) in ke.iter().enumerate() {
            if !e.is_finite() {
                return Err(bad(src.ke_line, format!("emission Ke channel {c} is not finite ({e})")));
            }
            if e < 0.0 {
                return Err(bad(src.ke_line, format!("emission Ke channel {c} = {e} is negative")));
            }
        }
        out.push(Material { name: m.name.clone(), reflectance: kd, emission: ke });
    }
    Ok(out)
}

fn build_faces(
    file: &Path,
    obj: &ObjData,
    materials: &[Material],
    warnings: &mut Vec<SceneWarning>,
) -> Result<Vec<Face>, SceneError> {
    let mut faces = Vec::new();
    for model in &obj.models {
        let mesh = &model.mesh;
        let n_faces =
            if mesh.face_arities.is_empty() { mesh.indices.len() / 3 } else { mesh.face_arities.len() };
        let mut offset = 0usize;
        for k in 0..n_faces {
            let arity = mesh.face_arities.get(k).map_or(3, |&a| a as usize);
            let index = faces.len();
            let Some(statement) = obj.statements.get(index) else {
                return Err(SceneError::Parse {
                    file: file.to_path_buf(),
                    line: 0,
                    problem: "the OBJ reader found more faces than `f` statements".to_owned(),
                });
            };
            let line = statement.line;
            let degenerate = |problem: String| SceneError::DegenerateFace {
                file: file.to_path_buf(),
                line,
                face: index,
                problem,
            };
            let mut vertices = Vec::with_capacity(arity);
            for &vi in mesh.indices.get(offset..offset + arity).unwrap_or(&[]) {
                let p = mesh.positions.get(3 * vi as usize..3 * vi as usize + 3);
                match p {
                    Some(&[x, y, z]) => vertices.push(DVec3::new(x, y, z)),
                    _ => return Err(degenerate("vertex index out of range".to_owned())),
                }
            }
            offset += arity;
            let material = match mesh.material_id {
                Some(m) if m < materials.len() => m,
                _ => {
                    let problem = match &statement.usemtl {
                        Some(name) => format!("material '{name}' is not defined in any MTL file"),
                        None => "no material (no `usemtl` before the face)".to_owned(),
                    };
                    return Err(SceneError::MissingMaterial {
                        file: file.to_path_buf(),
                        line,
                        face: index,
                        problem,
                    });
                }
            };
            let face = build_face(file, index, line, &model.name, material, vertices, warnings)?;
            faces.push(face);
        }
    }
    if faces.len() != obj.statements.len() {
        return Err(SceneError::Parse {
            file: file.to_path_buf(),
            line: obj.statements.get(faces.len()).map_or(0, |s| s.line),
            problem: "face statement not understood by the OBJ reader".to_owned(),
        });
    }
    if faces.is_empty() {
        return Err(SceneError::NoFaces { file: file.to_path_buf() });
    }
    Ok(faces)
}

fn build_face(
    file: &Path,
    index: usize,
    line: usize,
    object: &str,
    material: usize,
    vertices: Vec<DVec3>,
    warnings: &mut Vec<SceneWarning>,
) -> Result<Face, SceneError> {
    let degenerate =
        |problem: String| SceneError::DegenerateFace { file: file.to_path_buf(), line, face: index, problem };
    let n = vertices.len();
    if n < 3 {
        return Err(degenerate(format!("{n} vertices (a face needs at least 3)")));
    }
    if let Some(i) = vertices.iter().position(|v| !v.is_finite()) {
        return Err(degenerate(format!("vertex {i} is not finite ({})", vertices[i])));
    }
    let d = diameter(&vertices);
    if !(d.is_finite() && d > 0.0) {
        return Err(degenerate("all vertices coincide".to_owned()));
    }
    for i in 0..n {
        for j in i + 1..n {
            if vertices[i].distance(vertices[j]) <= DEGENERATE_TOLERANCE * d {
                return Err(degenerate(format!("vertices {i} and {j} coincide ({})", vertices[i])));
            }
        }
    }
    let nv = newell(&vertices);
    let area_estimate = 0.5 * nv.length();
    if area_estimate.is_nan() || area_estimate <= DEGENERATE_TOLERANCE * d * d {
        return Err(degenerate(format!("zero area (vertices are collinear; diameter {d})")));
    }
    let normal = nv / nv.length();
    let mean = vertices.iter().copied().sum::<DVec3>() / n as f64;
    let deviation = vertices.iter().map(|v| (*v - mean).dot(normal).abs()).fold(0.0, f64::max);
    check_convex(&vertices, normal, d).map_err(|problem| SceneError::NonConvexFace {
        file: file.to_path_buf(),
        line,
        face: index,
        problem,
    })?;
    let polygons = if deviation <= PLANAR_TOLERANCE * d {
        let p = Polygon::with_normal(vertices.clone(), normal)
            .ok_or_else(|| degenerate("zero area".to_owned()))?;
        vec![p]
    } else if deviation <= NON_PLANAR_LIMIT * d {
        let mut tris = Vec::with_capacity(n - 2);
        for k in 1..n - 1 {
            let tri = vec![vertices[0], vertices[k], vertices[k + 1]];
            // A fan triangle over collinear vertices has no area and is left out; the others cover the face.
            if let Some(p) = Polygon::new(tri) {
                if p.area > DEGENERATE_TOLERANCE * d * d {
                    tris.push(p);
                }
            }
        }
        if tris.is_empty() {
            return Err(degenerate("zero area".to_owned()));
        }
        warnings.push(SceneWarning {
            file: file.to_path_buf(),
            line,
            face: index,
            message: format!(
                "non-planar face (a vertex is {deviation:.4} from the mean plane, {:.3}% of the face diameter \
                 {d:.4}; planar means <= {PLANAR_TOLERANCE:e} of it) split into {} triangles",
                100.0 * deviation / d,
                tris.len()
            ),
        });
        tris
    } else {
        return Err(SceneError::NonPlanarFace {
            file: file.to_path_buf(),
            line,
            face: index,
            deviation,
            limit: NON_PLANAR_LIMIT * d,
        });
    };
    let area = polygons.iter().map(|p| p.area).sum();
    Ok(Face { index, line, object: object.to_owned(), material, vertices, normal, area, polygons })
}

/// Checks that a polygon, projected on the plane with unit normal `normal`, is convex and simple: every turn is
/// to the left (collinear vertices allowed) and the turns add up to one full turn.
fn check_convex(v: &[DVec3], normal: DVec3, d: f64) -> Result<(), String> {
    let n = v.len();
    let flat = |p: DVec3| p - normal * p.dot(normal);
    let mut total = 0.0;
    for i in 0..n {
        let a = flat(v[(i + n - 1) % n]);
        let b = flat(v[i]);
        let c = flat(v[(i + 1) % n]);
        let (e1, e2) = (b - a, c - b);
        let cross = e1.cross(e2).dot(normal);
        let dot = e1.dot(e2);
        // Relative tolerance: |e1||e2| <= d^2; a cross product this small is a straight (collinear) vertex.
        if cross < -DEGENERATE_TOLERANCE * d * d {
            return Err(format!("turns the wrong way at vertex {i} ({})", v[i]));
        }
        if cross.abs() <= DEGENERATE_TOLERANCE * d * d && dot < 0.0 {
            return Err(format!("folds back on itself at vertex {i} ({})", v[i]));
        }
        total += cross.atan2(dot);
    }
    // A convex simple polygon turns exactly once; a star-shaped self-intersecting one turns twice or more.
    if (total - TAU).abs() > 1e-6 {
        return Err(format!("self-intersecting (the boundary turns {:.3} times)", total / TAU));
    }
    Ok(())
}

struct PolyRef<'a> {
    face: &'a Face,
    poly: &'a Polygon,
    min: DVec3,
    max: DVec3,
    d: f64,
}

fn check_overlaps(file: &Path, faces: &[Face]) -> Result<(), SceneError> {
    let mut items: Vec<PolyRef<'_>> = faces
        .iter()
        .flat_map(|f| f.polygons.iter().map(move |p| (f, p)))
        .map(|(face, poly)| {
            let min = poly.vertices.iter().copied().fold(DVec3::splat(f64::INFINITY), DVec3::min);
            let max = poly.vertices.iter().copied().fold(DVec3::splat(f64::NEG_INFINITY), DVec3::max);
            PolyRef { face, poly, min, max, d: poly.diameter() }
        })
        .collect();
    // Sweep along x: only pairs whose bounding boxes meet can overlap.
    items.sort_by(|a, b| a.min.x.total_cmp(&b.min.x));
    let max_d = items.iter().map(|p| p.d).fold(0.0, f64::max);
    for (i, a) in items.iter().enumerate() {
        let reach = a.max.x + PLANAR_TOLERANCE * max_d;
        for b in items[i + 1..].iter().take_while(|b| b.min.x <= reach) {
            if std::ptr::eq(a.face, b.face) {
                continue;
            }
            let tol = PLANAR_TOLERANCE * a.d.max(b.d);
            if (a.min - b.max).max_element() > tol || (b.min - a.max).max_element() > tol {
                continue;
            }
            if !coplanar(a.poly, b.poly, tol) {
                continue;
            }
            let area = overlap_area(a.poly, b.poly);
            if area > OVERLAP_TOLERANCE * a.poly.area.min(b.poly.area) {
                let (x, y) = if a.face.index < b.face.index { (a.face, b.face) } else { (b.face, a.face) };
                return Err(SceneError::OverlappingFaces {
                    file: file.to_path_buf(),
                    face_a: x.index,
                    line_a: x.line,
                    face_b: y.index,
                    line_b: y.line,
                    area,
                });
            }
        }
    }
    Ok(())
}

fn coplanar(a: &Polygon, b: &Polygon, tol: f64) -> bool {
    let off =
        |p: &Polygon, q: &Polygon| q.vertices.iter().all(|v| (*v - p.centroid).dot(p.normal).abs() <= tol);
    off(a, b) && off(b, a)
}

/// Area of the intersection of two coplanar convex polygons: `a` clipped by each edge of `b`
/// (Sutherland and Hodgman, "Reentrant polygon clipping", CACM 1974), in `a`'s plane.
fn overlap_area(a: &Polygon, b: &Polygon) -> f64 {
    let n = a.normal;
    let u = n.any_orthonormal_vector();
    let w = n.cross(u);
    let to2 = |p: &DVec3| glam::DVec2::new(p.dot(u), p.dot(w));
    let subject: Vec<glam::DVec2> = a.vertices.iter().map(to2).collect();
    let mut clip: Vec<glam::DVec2> = b.vertices.iter().map(to2).collect();
    // Both counter-clockwise in (u, w), i.e. seen from `a.normal`; `b` may face the other way.
    if b.normal.dot(n) < 0.0 {
        clip.reverse();
    }
    let clipped = clip_convex(subject, &clip);
    area2(&clipped).max(0.0)
}

/// Clips polygon `subject` by the convex counter-clockwise polygon `clip`.
fn clip_convex(mut subject: Vec<glam::DVec2>, clip: &[glam::DVec2]) -> Vec<glam::DVec2> {
    for i in 0..clip.len() {
        let (p, q) = (clip[i], clip[(i + 1) % clip.len()]);
        let e = q - p;
        let side = |x: glam::DVec2| e.perp_dot(x - p);
        let input = std::mem::take(&mut subject);
        for j in 0..input.len() {
            let (s, t) = (input[j], input[(j + 1) % input.len()]);
            let (ss, st) = (side(s), side(t));
            if ss >= 0.0 {
                subject.push(s);
            }
            if (ss >= 0.0) != (st >= 0.0) {
                let r = ss / (ss - st);
                subject.push(s + (t - s) * r);
            }
        }
        if subject.is_empty() {
            break;
        }
    }
    subject
}

/// Signed area of a 2D polygon (shoelace formula), positive when counter-clockwise.
fn area2(p: &[glam::DVec2]) -> f64 {
    0.5 * (0..p.len()).map(|i| p[i].perp_dot(p[(i + 1) % p.len()])).sum::<f64>()
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlScene {
    meshing: Option<TomlMeshing>,
    #[serde(default)]
    light_group: Vec<TomlGroup>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlMeshing {
    max_patch_edge: Option<f64>,
    patch_budget: Option<i64>,
    refine_passes: Option<i64>,
    refine_tolerance: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlGroup {
    name: String,
    materials: Vec<String>,
    #[serde(default = "default_dynamic")]
    dynamic: bool,
    /// One number (grey) or an RGB array; checked in `build_light_groups`.
    intensity: Option<toml::Value>,
}

fn default_dynamic() -> bool {
    true
}

fn check_meshing(file: &Path, m: Option<&TomlMeshing>) -> Result<MeshingLimits, SceneError> {
    let invalid = |problem: String| SceneError::TomlInvalid { file: file.to_path_buf(), problem };
    let Some(m) = m else { return Ok(MeshingLimits::default()) };
    if let Some(e) = m.max_patch_edge {
        if !(e.is_finite() && e > 0.0) {
            return Err(invalid(format!("meshing.max_patch_edge = {e} must be finite and positive")));
        }
    }
    let patch_budget = match m.patch_budget {
        None => None,
        Some(b) => match usize::try_from(b) {
            Ok(b) if b >= 1 => Some(b),
            _ => return Err(invalid(format!("meshing.patch_budget = {b} must be at least 1"))),
        },
    };
    let refine_passes = match m.refine_passes {
        None => None,
        Some(n) => match usize::try_from(n) {
            Ok(n) if n <= crate::mesh::MAX_REFINE_PASSES => Some(n),
            _ => {
                return Err(invalid(format!(
                    "meshing.refine_passes = {n} must be between 0 and {}",
                    crate::mesh::MAX_REFINE_PASSES
                )))
            }
        },
    };
    if let Some(t) = m.refine_tolerance {
        if !(t.is_finite() && t > 0.0) {
            return Err(invalid(format!("meshing.refine_tolerance = {t} must be finite and positive")));
        }
    }
    Ok(MeshingLimits {
        max_patch_edge: m.max_patch_edge,
        patch_budget,
        refine_passes,
        refine_tolerance: m.refine_tolerance,
    })
}

fn build_light_groups(
    file: &Path,
    groups: &[TomlGroup],
    materials: &[Material],
) -> Result<Vec<LightGroup>, SceneError> {
    let invalid = |problem: String| SceneError::TomlInvalid { file: file.to_path_buf(), problem };
    let mut out: Vec<LightGroup> = Vec::new();
    let mut taken: HashMap<usize, String> = HashMap::new();
    let mut names: HashSet<String> = HashSet::new();
    for g in groups {
        if g.name.trim().is_empty() {
            return Err(invalid("a light group has an empty name".to_owned()));
        }
        if !names.insert(g.name.clone()) {
            return Err(invalid(format!("light group '{}' is defined twice", g.name)));
        }
        if g.materials.is_empty() {
            return Err(invalid(format!("light group '{}' lists no materials", g.name)));
        }
        let mut members = Vec::new();
        for name in &g.materials {
            let Some(m) = materials.iter().position(|m| &m.name == name) else {
                return Err(invalid(format!(
                    "light group '{}' lists material '{name}', which no MTL file defines",
                    g.name
                )));
            };
            if !materials[m].is_emitter() {
                return Err(invalid(format!(
                    "light group '{}' lists material '{name}', which emits nothing (Ke = 0)",
                    g.name
                )));
            }
            if let Some(other) = taken.insert(m, g.name.clone()) {
                return Err(invalid(format!(
                    "material '{name}' is in two light groups ('{other}' and '{}')",
                    g.name
                )));
            }
            members.push(m);
        }
        let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
        let intensity = match &g.intensity {
            None => [1.0; 3],
            Some(toml::Value::Array(a)) if a.len() == 3 => {
                match (number(&a[0]), number(&a[1]), number(&a[2])) {
                    (Some(r), Some(g), Some(b)) => [r, g, b],
                    _ => [f64::NAN; 3],
                }
            }
            Some(v) => number(v).map_or([f64::NAN; 3], |x| [x; 3]),
        };
        if intensity.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(invalid(format!(
                "light group '{}' has intensity {}; it must be one number or an array of 3, each finite and >= 0",
                g.name,
                g.intensity.as_ref().map_or_else(String::new, ToString::to_string)
            )));
        }
        out.push(LightGroup { name: g.name.clone(), materials: members, dynamic: g.dynamic, intensity });
    }
    for (m, mat) in materials.iter().enumerate() {
        if mat.is_emitter() && !taken.contains_key(&m) {
            if names.contains(&mat.name) {
                return Err(invalid(format!(
                    "light group '{0}' does not list the emitting material '{0}', whose implicit group would \
                     have the same name",
                    mat.name
                )));
            }
            names.insert(mat.name.clone());
            out.push(LightGroup {
                name: mat.name.clone(),
                materials: vec![m],
                dynamic: true,
                intensity: [1.0; 3],
            });
        }
    }
    Ok(out)
}
