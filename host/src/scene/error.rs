//! What loading reports: [`SceneError`] when a scene cannot be loaded, [`SceneWarning`] for a problem that did
//! not stop loading. Both name the file, and the line and face where they apply.

use std::fmt;
use std::path::PathBuf;

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
