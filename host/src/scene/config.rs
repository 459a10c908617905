//! The optional `NAME.toml` beside `NAME.obj`: meshing limits and light groups (see the [`crate::scene`]
//! docs for the format). This module parses the file and checks the meshing limits; the light groups are
//! resolved against the materials in [`super::light_group`].

use std::path::Path;

use serde::Deserialize;

use super::error::SceneError;

/// Most adaptive refinement passes a scene may ask for (each pass can halve a patch's edges once).
pub const MAX_REFINE_PASSES: usize = 6;

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
    /// Whether meshing repairs the faces first (cuts where faces meet, culls hidden pieces; default on); see
    /// [`crate::mesh::repair()`].
    pub repair: Option<bool>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TomlScene {
    pub(super) meshing: Option<TomlMeshing>,
    #[serde(default)]
    pub(super) light_group: Vec<TomlGroup>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TomlMeshing {
    max_patch_edge: Option<f64>,
    patch_budget: Option<i64>,
    refine_passes: Option<i64>,
    refine_tolerance: Option<f64>,
    repair: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TomlGroup {
    pub(super) name: String,
    pub(super) materials: Vec<String>,
    #[serde(default = "default_dynamic")]
    pub(super) dynamic: bool,
    /// One number (grey) or an RGB array; checked in `build_light_groups`.
    pub(super) intensity: Option<toml::Value>,
}

fn default_dynamic() -> bool {
    true
}

/// Parses the TOML file `file` whose text is `text`.
pub(super) fn parse_config(file: &Path, text: &str) -> Result<TomlScene, SceneError> {
    toml::from_str::<TomlScene>(text)
        .map_err(|e| SceneError::TomlParse { file: file.to_path_buf(), message: e.to_string() })
}

/// Checks the `[meshing]` table (absent: no limits set).
pub(super) fn check_meshing(file: &Path, m: Option<&TomlMeshing>) -> Result<MeshingLimits, SceneError> {
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
            Ok(b) if (1..=crate::limits::MAX_PATCHES).contains(&b) => Some(b),
            _ => {
                return Err(invalid(format!(
                    "meshing.patch_budget = {b} must be between 1 and {} (form factors cost time and memory \
                     growing with its square)",
                    crate::limits::MAX_PATCHES
                )))
            }
        },
    };
    let refine_passes = match m.refine_passes {
        None => None,
        Some(n) => match usize::try_from(n) {
            Ok(n) if n <= MAX_REFINE_PASSES => Some(n),
            _ => {
                return Err(invalid(format!(
                    "meshing.refine_passes = {n} must be between 0 and {}",
                    MAX_REFINE_PASSES
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
        repair: m.repair,
    })
}
