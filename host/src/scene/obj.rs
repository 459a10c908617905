//! Reading the OBJ file and its MTL files with `tobj`, plus what `tobj` does not report: the line of a syntax
//! error, the line and `usemtl` name of every face statement, and where each material is defined.
//!
//! `tobj` reports no line numbers: after a syntax error the loader finds its line by re-parsing prefixes of the
//! file (binary search), and it maps faces to lines by scanning the `f` statements itself. It also checks MTL
//! colour statements (`Ka`, `Kd`, `Ks`, `Ke`: three numbers, or one for grey) before `tobj` sees them, because
//! `tobj` panics on fewer than three: a single value is handed to it as three equal ones.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::error::SceneError;

/// Reads a text file, naming it (and the first line with invalid UTF-8) in the error.
pub(super) fn read_text(path: &Path) -> Result<String, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io { file: path.to_path_buf(), source })?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = e.as_bytes().get(..valid).map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count()) + 1;
        SceneError::NotUtf8 { file: path.to_path_buf(), line }
    })
}

/// What the loader reads from a face's `f` statement besides the geometry.
pub(super) struct FaceStatement {
    /// Line of the statement (1-based).
    pub(super) line: usize,
    /// The name given by the last `usemtl` before the face, if any.
    pub(super) usemtl: Option<String>,
}

/// Where a material is defined, for messages.
#[derive(Clone)]
pub(super) struct MaterialSource {
    /// The MTL file.
    pub(super) file: PathBuf,
    /// Line of the `newmtl` statement.
    pub(super) newmtl_line: usize,
    /// Line of the `Kd` statement, if any.
    pub(super) kd_line: Option<usize>,
    /// Line of the `Ke` statement, if any.
    pub(super) ke_line: Option<usize>,
}

/// An OBJ file as `tobj` read it, with what the loader found out about its lines.
pub(super) struct ObjData {
    /// The OBJ file.
    pub(super) file: PathBuf,
    /// The objects, with faces as written (not triangulated).
    pub(super) models: Vec<tobj::Model>,
    /// The materials of all MTL files, in definition order.
    pub(super) materials: Vec<tobj::Material>,
    /// One entry per `f` (or `l`) statement, in file order.
    pub(super) statements: Vec<FaceStatement>,
    /// Where each material is defined, by name.
    pub(super) sources: HashMap<String, MaterialSource>,
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

/// Reads the OBJ text `text` of `obj_path` and the MTL files it names (relative to its folder).
pub(super) fn load_obj(obj_path: &Path, text: &str) -> Result<ObjData, SceneError> {
    let dir = obj_path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mtl_error: RefCell<Option<SceneError>> = RefCell::new(None);
    let sources: RefCell<HashMap<String, MaterialSource>> = RefCell::new(HashMap::new());
    let loader = |p: &Path| -> tobj::MTLLoadResult {
        let path = dir.join(p);
        let result = read_text(&path).and_then(|mtl| {
            let mtl = scan_mtl(&path, &mtl, &mut sources.borrow_mut())?;
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

/// Records where each material of an MTL file is defined; rejects duplicate names and colours that are not one
/// or three numbers. Returns the text for tobj, in which a single-value colour (`Kd 0.5`, legal MTL: grey) is
/// written out as three equal numbers; every line keeps its number.
fn scan_mtl(
    path: &Path,
    text: &str,
    sources: &mut HashMap<String, MaterialSource>,
) -> Result<String, SceneError> {
    let mut current: Option<String> = None;
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        out.push_str(line);
        out.push('\n');
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
            // tobj panics on a colour with fewer than three numbers and ignores extra ones: check them here, and
            // give it a grey value as three numbers.
            Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) => {
                let values: Vec<&str> = trimmed.split_whitespace().skip(1).collect();
                if !matches!(values.len(), 1 | 3) || values.iter().any(|v| v.parse::<f64>().is_err()) {
                    return Err(SceneError::Parse {
                        file: path.to_path_buf(),
                        line: line_no,
                        problem: format!(
                            "{key} needs three numbers (r g b) or one (grey), got {:?}",
                            values.join(" ")
                        ),
                    });
                }
                if let [grey] = values[..] {
                    out.truncate(out.len() - line.len() - 1);
                    out.push_str(&format!("{key} {grey} {grey} {grey}\n"));
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
    Ok(out)
}
