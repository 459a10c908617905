//! Faces: the `f` statements of the OBJ file (or the triangles of a glTF file, see [`super::gltf`]) turned into
//! validated [`Face`]s, each made of planar convex [`Polygon`]s.
//!
//! A face is rejected when it has fewer than three vertices, non-finite or repeated vertices, zero area
//! (degenerate), is not convex, or is too far from planar; a slightly non-planar face is split into a triangle
//! fan with a [`SceneWarning`].
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

use std::f64::consts::TAU;
use std::fmt;
use std::ops::Range;
use std::path::Path;

use glam::DVec3;

use super::error::{length, SceneError, SceneWarning};
use super::material::Material;
use super::obj::ObjData;
use super::polygon::{diameter, newell, Polygon};

/// Largest distance of a vertex from the face's mean plane, relative to the face diameter, for a planar face.
pub const PLANAR_TOLERANCE: f64 = 1e-6;
/// Largest distance of a vertex from the face's mean plane, relative to the face diameter, for a face that is
/// split into triangles with a warning; beyond it the face is an error.
pub const NON_PLANAR_LIMIT: f64 = 1e-2;
/// Relative size below which vertices coincide (times the diameter) or an area is zero (times the diameter
/// squared).
pub const DEGENERATE_TOLERANCE: f64 = 1e-9;

/// Where a face of a glTF scene comes from: the node that places the mesh, the mesh, its primitive and the
/// primitive's triangles (numbered as the file lists them, after strips and fans are expanded).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GltfPlace {
    /// Node index in the file.
    pub node: usize,
    /// The node's name, if it has one.
    pub node_name: Option<String>,
    /// Mesh index in the file.
    pub mesh: usize,
    /// The mesh's name, if it has one.
    pub mesh_name: Option<String>,
    /// Primitive index within the mesh.
    pub primitive: usize,
    /// The primitive's triangles that make up the face: one, or a fan joined into one polygon.
    pub triangles: Range<usize>,
}

impl fmt::Display for GltfPlace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let named = |f: &mut fmt::Formatter<'_>, what: &str, name: &Option<String>, index: usize| match name {
            Some(n) => write!(f, "{what} '{n}' ({index})"),
            None => write!(f, "{what} {index}"),
        };
        named(f, "node", &self.node_name, self.node)?;
        write!(f, ", ")?;
        named(f, "mesh", &self.mesh_name, self.mesh)?;
        write!(f, ", primitive {}, ", self.primitive)?;
        if self.triangles.len() == 1 {
            write!(f, "triangle {}", self.triangles.start)
        } else {
            write!(f, "triangles {}..={}", self.triangles.start, self.triangles.end.saturating_sub(1))
        }
    }
}

/// One face (an OBJ `f` statement, or one triangle or joined fan of a glTF primitive), validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// Index of the face in load order (0-based): for an OBJ file, over all objects, the k-th `f` statement has
    /// index k; for a glTF file, see the `scene::gltf` module.
    pub index: usize,
    /// Line of the face's `f` statement in the OBJ file (1-based); 0 for a face of a glTF file (see
    /// [`Face::gltf`]).
    pub line: usize,
    /// Where the face is in a glTF file; `None` for an OBJ face.
    pub gltf: Option<GltfPlace>,
    /// Name of the OBJ object or group (`o` / `g`) the face belongs to, `"unnamed_object"` or empty if none; for
    /// a glTF face the name of the node that places it (`node N` if unnamed).
    pub object: String,
    /// Index of the face's material in [`Scene::materials`](super::Scene::materials).
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
    /// Where the face is in its file, for messages: `line 12` for an OBJ face, the node, mesh, primitive and
    /// triangles for a glTF face.
    #[must_use]
    pub fn place(&self) -> String {
        match &self.gltf {
            Some(p) => p.to_string(),
            None => format!("line {}", self.line),
        }
    }

    /// Whether the face was split into triangles because it is not planar.
    #[must_use]
    pub fn is_split(&self) -> bool {
        self.polygons.len() != 1 || self.polygons.first().is_some_and(|p| p.vertices != self.vertices)
    }
}

/// Builds and checks every face of the OBJ file, in OBJ order.
pub(super) fn build_faces(
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

/// Builds and checks one face from its vertices in order; errors name `file`, `line` and face `index`.
pub(super) fn build_face(
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
            line: Some(line),
            face: Some(index),
            message: format!(
                "non-planar face (a vertex is {} from the mean plane, {:.3}% of the face diameter {}) split into \
                 {} triangles (a face within {PLANAR_TOLERANCE:e} of its diameter of its mean plane is kept whole, \
                 one within {}% is split like this one, one beyond {}% is refused)",
                length(deviation),
                100.0 * deviation / d,
                length(d),
                tris.len(),
                100.0 * NON_PLANAR_LIMIT,
                100.0 * NON_PLANAR_LIMIT
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
    Ok(Face {
        index,
        line,
        gltf: None,
        object: object.to_owned(),
        material,
        vertices,
        normal,
        area,
        polygons,
    })
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
