//! The host pipeline's first stages, shared by the commands: load a scene, mesh it into patches, and compute
//! form factors, reporting each stage on stderr.

use std::path::{Path, PathBuf};

use crate::formfactor::{compute_form_factors, FormFactorOptions, FormFactorStats};
use crate::lighting::PatchLighting;
use crate::mesh::{mesh, MeshOptions};
use crate::patch::{FormFactorMatrix, Patch, RowClamp};
use crate::scene::Scene;

/// How to turn a scene into patches and form factors.
#[derive(Clone, Debug)]
pub struct PrepareOptions {
    /// One patch per OBJ face (patch `k` is face `k`) instead of uniform subdivision.
    pub no_subdivide: bool,
    /// Longest patch edge in scene units; `None` takes the scene's TOML value or the default.
    pub max_patch_edge: Option<f64>,
    /// Most patches; `None` takes the scene's TOML value or the default.
    pub max_patches: Option<usize>,
    /// Form-factor estimator settings.
    pub form_factors: FormFactorOptions,
    /// Print stage summaries and warnings on stderr.
    pub verbose: bool,
}

/// A scene meshed into patches, with its form factors and per-patch lighting attributes.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// The loaded scene.
    pub scene: Scene,
    /// Its patches.
    pub patches: Vec<Patch>,
    /// Reflectance and emission per patch.
    pub lighting: PatchLighting,
    /// Form factors between the patches.
    pub form_factors: FormFactorMatrix,
    /// Statistics of the form-factor computation (before rows above 1 were scaled).
    pub stats: FormFactorStats,
    /// Rows that summed to more than 1 (after reciprocity was enforced) and were scaled to 1.
    pub clamp: RowClamp,
    /// Largest relative difference between the two estimates of a pair's energy exchange, before averaging.
    pub reciprocity_change: f64,
}

/// Why the pipeline stopped; the message names the stage and the input.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// Meshing failed.
    #[error("meshing {path}: {source}")]
    Mesh {
        /// The scene file.
        path: PathBuf,
        /// What went wrong.
        source: crate::mesh::MeshError,
    },
    /// Form factors could not be computed.
    #[error("form factors of {path}: {source}")]
    FormFactors {
        /// The scene file.
        path: PathBuf,
        /// What went wrong.
        source: crate::formfactor::FormFactorError,
    },
}

/// Loads `path`, meshes it and computes its form factors.
///
/// # Errors
/// [`PipelineError`] naming the stage that failed.
pub fn prepare(path: &Path, options: &PrepareOptions) -> Result<Prepared, PipelineError> {
    let scene = Scene::load(path)?;
    if options.verbose {
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
    }
    let mut mesh_options =
        if options.no_subdivide { MeshOptions::no_subdivide(&scene) } else { MeshOptions::for_scene(&scene) };
    if let Some(edge) = options.max_patch_edge {
        mesh_options.max_patch_edge = edge;
    }
    if let Some(budget) = options.max_patches {
        mesh_options.patch_budget = budget;
    }
    let meshed =
        mesh(&scene, &mesh_options).map_err(|source| PipelineError::Mesh { path: path.into(), source })?;
    if options.verbose {
        eprintln!(
            "{}: {} faces, {} materials, {} light groups -> {} patches (max edge {:.4})",
            path.display(),
            scene.faces.len(),
            scene.materials.len(),
            scene.light_groups.len(),
            meshed.patches.len(),
            meshed.max_patch_edge
        );
    }
    let (mut form_factors, stats) = compute_form_factors(&meshed.patches, &options.form_factors)
        .map_err(|source| PipelineError::FormFactors { path: path.into(), source })?;
    let areas: Vec<f64> = meshed.patches.iter().map(|q| q.area).collect();
    let reciprocity_change = form_factors.enforce_reciprocity(&areas);
    let clamp = form_factors.clamp_rows_to_one();
    if options.verbose {
        eprintln!(
            "form factors: {} nonzeros, row sums {:.6}..{:.6}, reciprocity error {:.2e}, {} rays in {:.2} s \
             ({:.2} Mrays/s)",
            stats.nonzeros,
            stats.row_sum_min,
            stats.row_sum_max,
            stats.reciprocity_error_max,
            stats.rays_cast,
            stats.elapsed.as_secs_f64(),
            stats.rays_per_second / 1e6
        );
        eprintln!(
            "form factors: reciprocity enforced (each pair's two estimates averaged; largest relative \
             difference {reciprocity_change:.2e})"
        );
        if clamp.rows > 0 {
            eprintln!(
                "form factors: {} rows summed to more than 1 (visibility noise; largest excess {:.2e}) and were \
                 scaled to 1",
                clamp.rows, clamp.max_excess
            );
        }
    }
    let lighting = PatchLighting::new(&scene, &meshed.patches);
    Ok(Prepared { scene, patches: meshed.patches, lighting, form_factors, stats, clamp, reciprocity_change })
}
