//! What loading reports: [`SceneError`] when a scene cannot be loaded, [`SceneWarning`] for a problem that did
//! not stop loading. Both name the file, and the line and face where they apply.

use std::fmt;
use std::path::PathBuf;

/// A problem in the input that did not stop loading.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneWarning {
    /// File the warning is about.
    pub file: PathBuf,
    /// Line in that file (1-based), if it is about one line.
    pub line: Option<usize>,
    /// Face index (in OBJ order, or glTF load order), if it is about one face.
    pub face: Option<usize>,
    /// What happened.
    pub message: String,
}

impl fmt::Display for SceneWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some(face) = self.face {
            write!(f, ": face {face}")?;
        }
        write!(f, ": {}", self.message)
    }
}

/// A length (or any value in scene units) for a message: four decimals for lengths from 1e-3 to 1e6, four
/// significant digits in scientific notation otherwise (so a scene in tiny or huge units does not print 0.0000).
#[must_use]
pub(crate) fn length(value: f64) -> String {
    if value == 0.0 || (1e-3..1e6).contains(&value.abs()) {
        format!("{value:.4}")
    } else {
        format!("{value:.4e}")
    }
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
    /// A face is further from planar than [`NON_PLANAR_LIMIT`](super::NON_PLANAR_LIMIT) allows.
    #[error(
        "{}:{line}: face {face}: non-planar face: a vertex is {} from the face's mean plane, more than \
         the limit {} (1% of the face diameter)",
        file.display(), length(*deviation), length(*limit)
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
    /// The scene's size or position is outside the range supported (see
    /// [`MIN_SCENE_SIZE`](super::MIN_SCENE_SIZE), [`MAX_SCENE_SIZE`](super::MAX_SCENE_SIZE),
    /// [`MAX_ORIGIN_DISTANCE`](super::MAX_ORIGIN_DISTANCE)).
    #[error("{}: {problem}", file.display())]
    Extent {
        /// The OBJ file.
        file: PathBuf,
        /// What is out of range, by how much, and what to do.
        problem: String,
    },
    /// A glTF file cannot be read as glTF 2.0: not JSON or GLB, truncated, or invalid against the schema (the
    /// problem names the JSON path, e.g. `meshes[0].primitives[1].indices`).
    #[error("{}: not a valid glTF 2.0 file: {problem}", file.display())]
    GltfParse {
        /// The glTF file.
        file: PathBuf,
        /// What the glTF reader found wrong.
        problem: String,
    },
    /// A problem at one place of a glTF scene: a buffer, image, material, node, or a triangle of a primitive of
    /// a mesh instanced by a node.
    #[error("{}: {place}: {problem}", file.display())]
    Gltf {
        /// The glTF file.
        file: PathBuf,
        /// Where: e.g. `node 'lamp' (3), mesh 'quad' (0), primitive 1, triangle 5`.
        place: String,
        /// What is wrong.
        problem: String,
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
