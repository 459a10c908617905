//! The checked-in baseline: per scene and codec, each tracked component's values over the seeds, and how the
//! scene was prepared.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::RegressError;
use crate::pipeline::PrepareOptions;

/// How a scene is prepared for the regression (small, so the test is fast).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSettings {
    /// One patch per OBJ face.
    pub no_subdivide: bool,
    /// Longest patch edge (`None`: the scene's TOML or the default).
    pub max_patch_edge: Option<f64>,
    /// Most patches (`None`: the scene's TOML or the default).
    pub max_patches: Option<usize>,
    /// Sample points per patch.
    pub samples: usize,
    /// Occlusion rays per pair.
    pub rays: usize,
}

impl Default for SceneSettings {
    fn default() -> Self {
        SceneSettings {
            no_subdivide: false,
            max_patch_edge: None,
            max_patches: Some(400),
            samples: 4,
            rays: 4,
        }
    }
}

impl SceneSettings {
    /// The pipeline options for seed `seed`.
    #[must_use]
    pub fn prepare_options(&self, seed: u64) -> PrepareOptions {
        let mut options = PrepareOptions::quiet(self.no_subdivide, self.samples, self.rays);
        options.max_patch_edge = self.max_patch_edge;
        options.max_patches = self.max_patches;
        options.form_factors.seed = seed;
        options
    }
}

/// One metric of one component across seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stat {
    /// Value at each seed, in seed order.
    pub values: Vec<f64>,
    /// Mean over the seeds.
    pub mean: f64,
    /// Sample standard deviation over the seeds (the Monte Carlo noise), or, when every seed gave the same value,
    /// the root-mean-square deviation of [`Stat::jittered`] from it.
    pub noise: f64,
    /// Values at the form-factor jitters `1..=S` (seed 1), measured only when every seed gave the same value
    /// (module docs, "Scenes without Monte Carlo noise"); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub jittered: Vec<f64>,
}

impl Stat {
    pub(super) fn of(values: Vec<f64>) -> Stat {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 {
            values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Stat { values, mean, noise: var.sqrt(), jittered: Vec::new() }
    }

    /// Whether every seed gave the same value (no Monte Carlo noise to measure).
    pub(super) fn deterministic(&self) -> bool {
        self.values.windows(2).all(|w| w[0] == w[1])
    }

    /// Takes the noise from jittered values (see [`Stat::jittered`]).
    pub(super) fn with_jitter(mut self, jittered: Vec<f64>) -> Stat {
        let n = jittered.len().max(1) as f64;
        self.noise = (jittered.iter().map(|v| (v - self.mean) * (v - self.mean)).sum::<f64>() / n).sqrt();
        self.jittered = jittered;
        self
    }
}

/// A tracked component's two metrics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ComponentStats {
    /// Area-weighted relative L2.
    pub rel_l2: Stat,
    /// Max per-patch relative error.
    pub max_rel: Stat,
}

/// The baseline of one scene and codec.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// Scene file name in the scenes folder (`cornell-box.obj`, `cornell-box.glb`).
    pub scene: String,
    /// Form-factor code width (16 or 8).
    pub bits: u32,
    /// Codec name (for readers).
    pub codec: String,
    /// Patches the scene meshed into.
    pub patches: usize,
    /// Preparation settings.
    pub settings: SceneSettings,
    /// Tracked components by name (empty when the check fails, see `error`).
    pub components: BTreeMap<String, ComponentStats>,
    /// The check's error at the first seed, when the bake or check rejects this scene and codec (e.g. an 8-bit
    /// code that cannot hold a row's small entries): the regression then expects the same rejection.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The checked-in baseline file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Baseline {
    /// How to read and update this file.
    pub about: String,
    /// Seeds measured (`1..=seeds`).
    pub seeds: usize,
    /// Noise multiplier `k` for that many seeds (informative; recomputed when checking).
    pub k: f64,
    /// One entry per scene and codec.
    pub entries: Vec<Entry>,
}

/// The shipped scenes: the file names in `dir` that are scenes ([`crate::scene::is_scene_file`]: `*.obj`,
/// `*.gltf`, `*.glb`; files, not folders), sorted.
///
/// # Errors
/// [`RegressError::Io`] if the folder cannot be listed.
pub fn scene_files(dir: &Path) -> Result<Vec<String>, RegressError> {
    let io = |e: std::io::Error| RegressError::Io { path: dir.into(), message: e.to_string() };
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if crate::scene::is_scene_file(&path) && path.is_file() {
            if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
                names.push(name.to_string());
            }
        }
    }
    names.sort();
    Ok(names)
}

/// Reads a baseline file.
///
/// # Errors
/// [`RegressError::Io`] or [`RegressError::BadBaseline`].
pub fn read_baseline(path: &Path) -> Result<Baseline, RegressError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RegressError::Io { path: path.into(), message: e.to_string() })?;
    serde_json::from_str(&text)
        .map_err(|e| RegressError::BadBaseline { path: path.into(), message: e.to_string() })
}

/// Writes a baseline file (pretty JSON, trailing newline) atomically ([`crate::files::write_atomic`]); its
/// folder must exist ([`crate::files`] policy).
///
/// # Errors
/// [`RegressError::Io`].
pub fn write_baseline(path: &Path, baseline: &Baseline) -> Result<(), RegressError> {
    let mut text = serde_json::to_string_pretty(baseline)
        .map_err(|e| RegressError::Io { path: path.into(), message: e.to_string() })?;
    text.push('\n');
    crate::files::write_atomic(path, text.as_bytes())
        .map_err(|e| RegressError::Io { path: path.into(), message: e.to_string() })
}
