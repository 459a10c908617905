//! Light groups: the emitting materials whose intensity changes together. The TOML file's `[[light_group]]`
//! tables come first, in file order; every emitting material no table lists becomes its own dynamic group,
//! named after the material, at intensity 1.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use super::config::TomlGroup;
use super::error::{SceneError, SceneWarning};
use super::face::Face;
use super::material::Material;
use super::obj::MaterialSource;
use crate::rgb::Rgb;

/// A light group: emitting materials whose intensity changes together.
#[derive(Clone, Debug, PartialEq)]
pub struct LightGroup {
    /// Name (from the TOML file, or the material's name for an implicit group).
    pub name: String,
    /// Indices of the group's materials in [`Scene::materials`](super::Scene::materials).
    pub materials: Vec<usize>,
    /// Whether the group's intensity can change at run time (a static group is folded into the base).
    pub dynamic: bool,
    /// Default intensity per RGB channel, multiplying the materials' `Ke`.
    pub intensity: Rgb,
}

pub(super) fn build_light_groups(
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
                    "light group '{}' lists material '{name}', which no MTL file defines (nor, for a glTF \
                     scene, the glTF file)",
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
            None => Rgb::ONE,
            Some(toml::Value::Array(a)) if a.len() == 3 => {
                match (number(&a[0]), number(&a[1]), number(&a[2])) {
                    (Some(r), Some(g), Some(b)) => Rgb::new(r, g, b),
                    _ => Rgb::NAN,
                }
            }
            Some(v) => number(v).map_or(Rgb::NAN, Rgb::splat),
        };
        if !(intensity.is_finite() && intensity.cmpge(Rgb::ZERO).all()) {
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
                intensity: Rgb::ONE,
            });
        }
    }
    Ok(out)
}

/// Warnings about light that the scene cannot emit: a light group none of whose materials any face uses (it would
/// light nothing, whatever its intensity), and a scene with no emitting face at all (every radiosity is 0).
/// `file` is the scene file; `sources` says where each material is defined (MTL file and line; empty for glTF,
/// whose warnings then name the scene file).
pub(super) fn light_warnings(
    file: &Path,
    sources: &HashMap<String, MaterialSource>,
    groups: &[LightGroup],
    materials: &[Material],
    faces: &[Face],
) -> Vec<SceneWarning> {
    let used: HashSet<usize> = faces.iter().map(|f| f.material).collect();
    let mut warnings = Vec::new();
    for g in groups {
        if g.materials.iter().any(|m| used.contains(m)) {
            continue;
        }
        let names: Vec<String> = g.materials.iter().map(|&m| format!("'{}'", materials[m].name)).collect();
        // Name the MTL file and line of the group's first material, where the user defined the emitter.
        let source = materials.get(g.materials[0]).and_then(|m| sources.get(&m.name));
        warnings.push(SceneWarning {
            file: source.map_or_else(|| file.to_path_buf(), |s| s.file.clone()),
            line: source.map(|s| s.newmtl_line),
            face: None,
            message: format!(
                "light group '{}' has no faces: no face uses its emitting material{} {}, so it lights nothing",
                g.name,
                if names.len() == 1 { "" } else { "s" },
                names.join(", ")
            ),
        });
    }
    if !faces.iter().any(|f| materials[f.material].is_emitter()) {
        warnings.push(SceneWarning {
            file: file.to_path_buf(),
            line: None,
            face: None,
            message: "no face emits light (no face's material has a nonzero Ke, or glTF emission): every radiosity \
                      is 0"
                .to_owned(),
        });
    }
    warnings
}
