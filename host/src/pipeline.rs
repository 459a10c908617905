//! The host pipeline's first stages, shared by the commands: load a scene, mesh it into patches, and compute
//! form factors, reporting each stage on stderr.
//!
//! # Adaptive meshing
//! Unless `--no-subdivide` is given, the scene is first meshed uniformly ([`crate::mesh::mesh`]), then refined in
//! up to `refine_passes` passes (the scene's TOML, default [`crate::mesh::DEFAULT_REFINE_PASSES`]). Each pass
//! computes the form factors of the current mesh, solves it with the f64 reference at the scene's default light
//! intensities, scores every patch by how much its radiosity changes across it (radiosity gradient between
//! neighbours, light arriving through partly visible pairs = shadow boundaries, contact edges; see
//! [`crate::mesh::refine_scores`]) and splits the patches above the refinement tolerance, highest
//! `change * sqrt(area)` first, within an equal share of the patch budget left per remaining pass (so later
//! passes can still split the children of earlier ones). Evenly lit patches stay as the uniform mesh made them.
//! The form factors of the final mesh are the ones returned. Every patch keeps its parent face.
//!
//! # Cost, said before and after
//! With `verbose`, [`cost_estimate`] goes to stderr after meshing and before the first form factor (patches now
//! and at most, pairs and occlusion rays per pass, the table's size bound and the device's flash); after the
//! last pass, one line says the patches, passes, form factors and rays it took, and [`MeshStop::note`] why
//! refinement stopped where it did (budget spent, light resolved to the tolerance, or passes used up).
//!
//! # Repair
//! Meshing repairs the faces first unless [`PrepareOptions::repair`] is off or the scene's TOML says
//! `repair = false` ([`crate::mesh::repair()`]); with `verbose`, one `repair:` line per changed face goes to
//! stderr (after the loader's `warning:` lines), naming the face, the faces that meet it and the area culled.

use std::path::{Path, PathBuf};

use crate::formfactor::{
    compute_form_factors, rows_over_noise, ClosureReport, FormFactorOptions, FormFactorStats, RowExcess,
};
use crate::lighting::PatchLighting;
use crate::mesh::{
    mesh, refine, refine_scores, refinement_candidates, select_for_refinement, MeshOptions, RefineInput,
    RefineOptions, RepairReport, DEFAULT_PATCH_BUDGET,
};
use crate::patch::{Closure, FormFactorMatrix, Patch, ReciprocityChange, RowClamp};
use crate::reference::{solve_many, RadiositySystem};
use crate::scene::Scene;
use crate::text::counted;

/// How to turn a scene into patches and form factors.
#[derive(Clone, Debug)]
pub struct PrepareOptions {
    /// One patch per OBJ face polygon (after repair, per repaired piece) instead of uniform subdivision.
    pub no_subdivide: bool,
    /// Longest patch edge in scene units; `None` takes the scene's TOML value or the default.
    pub max_patch_edge: Option<f64>,
    /// Most patches; `None` takes the scene's TOML value or the default.
    pub max_patches: Option<usize>,
    /// Repair the faces before meshing (see [`crate::mesh::repair()`]); `false` (`--no-repair`) keeps them as
    /// loaded. When `true`, the scene's TOML may still turn repair off (`repair = false`).
    pub repair: bool,
    /// Form-factor estimator settings.
    pub form_factors: FormFactorOptions,
    /// Print stage summaries and warnings on stderr.
    pub verbose: bool,
}

impl PrepareOptions {
    /// Quiet settings (no progress bar, no stage summaries) with the scene's own meshing limits and the given
    /// estimator sample counts: what tests and batch tools use.
    #[must_use]
    pub fn quiet(no_subdivide: bool, samples_per_patch: usize, rays_per_pair: usize) -> PrepareOptions {
        PrepareOptions {
            no_subdivide,
            max_patch_edge: None,
            max_patches: None,
            repair: true,
            form_factors: FormFactorOptions {
                samples_per_patch,
                rays_per_pair,
                progress: false,
                ..FormFactorOptions::default()
            },
            verbose: false,
        }
    }
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
    /// Form factors between the patches (reciprocal, rows at most 1), their flags marking partly visible pairs.
    pub form_factors: FormFactorMatrix,
    /// Statistics of the form-factor computation (before rows above 1 were scaled).
    pub stats: FormFactorStats,
    /// Rows that summed to more than 1 (after reciprocity was enforced), within their sampling noise, and were
    /// scaled to 1.
    pub clamp: RowClamp,
    /// How far apart the two estimates of each pair's energy exchange were, before averaging.
    pub reciprocity_change: ReciprocityChange,
    /// The meshing passes: the uniform mesh, then one entry per refinement pass that split patches.
    pub mesh_passes: Vec<MeshPass>,
    /// What mesh repair changed (`None` when repair was off).
    pub repair: Option<RepairReport>,
    /// Why adaptive meshing stopped where it did (`None` with `--no-subdivide`).
    pub mesh_stop: Option<MeshStop>,
}

/// One meshing pass of [`prepare`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshPass {
    /// Patches after the pass.
    pub patches: usize,
    /// Patches the pass split (0 for the uniform mesh).
    pub split: usize,
    /// Patches the pass found worth splitting ([`crate::mesh::refinement_candidates`]); more than `split` when
    /// the budget held the pass back (0 for the uniform mesh).
    pub candidates: usize,
}

/// Why adaptive meshing stopped, so a mesh below its patch budget says why ([`MeshStop::note`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeshStop {
    /// The budget is spent: no split of a patch worth splitting fits in what is left (a split adds about 3).
    Budget {
        /// Patches still worth splitting.
        candidates: usize,
    },
    /// No patch's radiosity changes across it by more than the refinement tolerance: the mesh resolves the
    /// light to that tolerance, and more budget would not be spent.
    Converged {
        /// The refinement tolerance (fraction of the mean radiosity).
        tolerance: f64,
    },
    /// Every refinement pass ran (0 passes: refinement is off) and the last split every patch worth splitting;
    /// their children may still be worth splitting with more passes.
    Passes {
        /// Refinement passes allowed.
        passes: usize,
    },
}

impl MeshStop {
    /// One line for stderr: `patches` of `budget` patches (the budget set by `budget_source`) and why.
    #[must_use]
    pub fn note(&self, patches: usize, budget: usize, budget_source: &str) -> String {
        let head = format!("adaptive meshing: {patches} of {budget} patches (budget: {budget_source})");
        match *self {
            MeshStop::Budget { candidates: 0 } => format!("{head}: the budget is spent"),
            MeshStop::Budget { candidates } => format!(
                "{head}: the budget is spent ({} still worth splitting, none fits in what is left)",
                counted(candidates, "patch", "patches")
            ),
            MeshStop::Converged { tolerance } => format!(
                "{head}: below the budget because no patch's radiosity changes across it by more than {tolerance} \
                 of the mean radiosity (the refinement tolerance, `refine_tolerance` in the scene's TOML): the \
                 mesh resolves the light to that tolerance"
            ),
            MeshStop::Passes { passes: 0 } => format!(
                "{head}: below the budget because refinement is off (`refine_passes = 0` in the scene's TOML); \
                 the uniform mesh is sized by the longest patch edge (--max-patch-edge)"
            ),
            MeshStop::Passes { passes } => format!(
                "{head}: below the budget because all {} ran and the last split every patch worth \
                 splitting (more passes: `refine_passes` in the scene's TOML, at most {})",
                counted(passes, "refinement pass", "refinement passes"),
                crate::scene::MAX_REFINE_PASSES
            ),
        }
    }
}

/// Fewest flat-mesh patches per face polygon at which `bake` and `check` make a flat table by default: a 2 x 2
/// split of every face, the least with which the adaptive mesh can place a patch where light changes within a
/// face. A scene with more faces than its budget gives that many (a furnished floor of thousands of small boxes)
/// gets the hierarchy, which subdivides where its links ask and keeps small faces whole elsewhere.
pub const FLAT_PATCHES_PER_FACE: usize = 4;

/// Whether `scene`'s flat mesh has room for [`FLAT_PATCHES_PER_FACE`] patches on each of its faces within its
/// patch budget (the scene's TOML `patch_budget`, else [`DEFAULT_PATCH_BUDGET`]): the rule by which `bake` and
/// `check` choose their table when no option asks for one (flat if it has, hierarchical if not).
#[must_use]
pub fn flat_mesh_has_room(scene: &Scene) -> bool {
    let budget = scene.meshing.patch_budget.unwrap_or(DEFAULT_PATCH_BUDGET);
    scene.faces.len().saturating_mul(FLAT_PATCHES_PER_FACE) <= budget
}

/// Where a patch budget came from, for messages: the option, the scene's TOML, or the default.
fn budget_source(options: &PrepareOptions, scene: &Scene) -> String {
    match (options.max_patches, scene.meshing.patch_budget) {
        (Some(_), _) => "--max-patches".to_owned(),
        (None, Some(_)) => "the scene's TOML, `patch_budget`".to_owned(),
        (None, None) => format!("the default {DEFAULT_PATCH_BUDGET}; set it with --max-patches"),
    }
}

/// What a prepare and bake will cost at most, said before the first form factor: the patches now and at most
/// after refinement, the pairs and occlusion rays of the largest pass, the table's size bound
/// ([`crate::bake::table_bytes_bound`], 16-bit codes as the bake's default) and the most patches that bound
/// lets fit the flash of [`firmware_sim::qemu::MPS2_AN386`].
#[must_use]
pub fn cost_estimate(patches_now: usize, budget: usize, passes: usize, rays_per_pair: usize) -> String {
    let most = if passes == 0 { patches_now } else { budget.max(patches_now) };
    let pairs = most as u64 * most.saturating_sub(1) as u64 / 2;
    let board = firmware_sim::qemu::MPS2_AN386;
    let bytes = crate::bake::table_bytes_bound(most, 16);
    let refined = if passes == 0 {
        "no refinement".to_owned()
    } else {
        format!("at most {most} after {}", counted(passes, "refinement pass", "refinement passes"))
    };
    let size =
        if bytes >= 1_000_000 { format!("{:.1} MB", bytes as f64 / 1e6) } else { format!("{bytes} bytes") };
    format!(
        "cost estimate: {patches_now} patches now, {refined}; form factors of {most} patches: {}, at most {:.2e} \
         occlusion rays per pass; table at most {size} with 16-bit codes (every pair stored); the {} bytes of \
         flash of a {} hold at most {} patches by that bound ({}; sparse tables hold more, the bake prints the \
         actual size and fit)",
        counted(pairs as usize, "pair", "pairs"),
        pairs as f64 * rays_per_pair as f64,
        board.flash,
        board.name,
        crate::bake::patches_within(board.flash, 16),
        if bytes <= board.flash { "this mesh fits" } else { "this mesh may not fit" }
    )
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
    /// The reference solve of a refinement pass failed.
    #[error("solving {path} for adaptive refinement: {source}")]
    Solve {
        /// The scene file.
        path: PathBuf,
        /// What went wrong.
        source: crate::reference::ReferenceError,
    },
    /// Rows of the form factors sum to more than 1 by more than sampling noise explains
    /// ([`FormFactorStats::row_excess_allowed`]): the estimate is wrong, not noisy, and is not scaled to 1.
    #[error(
        "form factors of {path}: {count} rows sum to more than 1 by more than their sampling noise allows \
         ({rays} rays per pair, {samples} samples per patch), so the estimate is wrong, not noisy: {}{}",
        rows.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "),
        if *count > rows.len() { "; ..." } else { "" }
    )]
    RowExcess {
        /// The scene file.
        path: PathBuf,
        /// How many rows.
        count: usize,
        /// The worst rows (largest excess over its allowance first), at most [`ROW_EXCESS_LISTED`].
        rows: Vec<RowExcess>,
        /// Occlusion rays per pair of the estimate.
        rays: usize,
        /// Sample points per patch of the estimate.
        samples: usize,
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

/// Rows listed by [`PipelineError::RowExcess`].
pub const ROW_EXCESS_LISTED: usize = 5;

/// Loads `path`, meshes it and computes its form factors.
///
/// # Errors
/// [`PipelineError`] naming the stage that failed, and [`PipelineError::RowExcess`] if a row of the form factors
/// sums to more than 1 by more than sampling noise explains (rows within it are scaled to 1 and reported).
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
    mesh_options.repair &= options.repair;
    let meshed =
        mesh(&scene, &mesh_options).map_err(|source| PipelineError::Mesh { path: path.into(), source })?;
    if options.verbose {
        if let Some(report) = &meshed.repair {
            for note in report.notes(path) {
                eprintln!("repair: {note}");
            }
        }
        eprintln!(
            "{}: {}, {}, {} -> {} (max edge {})",
            path.display(),
            counted(scene.faces.len(), "face", "faces"),
            counted(scene.materials.len(), "material", "materials"),
            counted(scene.light_groups.len(), "light group", "light groups"),
            counted(meshed.patches.len(), "patch", "patches"),
            crate::scene::length(meshed.max_patch_edge)
        );
    }
    let refine_options = if options.no_subdivide {
        RefineOptions { passes: 0, ..RefineOptions::for_scene(&scene) }
    } else {
        RefineOptions::for_scene(&scene)
    };
    let budget = mesh_options.patch_budget;
    if options.verbose {
        let (n, passes) = (meshed.patches.len(), refine_options.passes);
        eprintln!("{}", cost_estimate(n, budget, passes, options.form_factors.rays_per_pair));
    }
    let (mut rays, mut seconds) = (0u64, 0f64);
    let repair = meshed.repair;
    let mut patches = meshed.patches;
    let mut mesh_passes = vec![MeshPass { patches: patches.len(), split: 0, candidates: 0 }];
    loop {
        let (estimate, stats) = compute_form_factors(&patches, &options.form_factors)
            .map_err(|source| PipelineError::FormFactors { path: path.into(), source })?;
        rays += stats.rays_cast;
        seconds += stats.elapsed.as_secs_f64();
        let mut form_factors = estimate.clone();
        let areas: Vec<f64> = patches.iter().map(|q| q.area).collect();
        let mut reciprocity_change = form_factors.enforce_reciprocity(&areas);
        if let Some(c) = &stats.closure {
            // A closed scene's matrix was made reciprocal (and then closed) inside the estimator already.
            reciprocity_change = reciprocity_change.max(c.reciprocity_change);
        }
        let mut over = rows_over_noise(&form_factors, &stats.row_excess_allowed, &patches);
        if !over.is_empty() {
            let count = over.len();
            over.truncate(ROW_EXCESS_LISTED);
            return Err(PipelineError::RowExcess {
                path: path.into(),
                count,
                rows: over,
                rays: options.form_factors.rays_per_pair,
                samples: options.form_factors.samples_per_patch,
            });
        }
        let clamp = form_factors.clamp_rows_to_one();
        let lighting = PatchLighting::new(&scene, &patches);
        let passes_done = mesh_passes.len() > refine_options.passes;
        let done = passes_done || patches.len() >= budget;
        let (split, candidates) = if done {
            (Vec::new(), 0)
        } else {
            let system = RadiositySystem::new(&lighting.rho, &form_factors)
                .map_err(|source| PipelineError::Solve { path: path.into(), source })?;
            let emission = lighting.default_emission();
            // The solution only scores where light changes fast, so the bake's solver choice serves (sparse
            // Gauss-Seidel to a 1e-12 residual above a thousand patches, where a dense LU per pass costs seconds).
            let solution = solve_many(system, &[&emission], &crate::bake::default_method(patches.len()))
                .map_err(|source| PipelineError::Solve { path: path.into(), source })?;
            let input = RefineInput {
                patches: &patches,
                radiosity: &solution[0].b,
                emission: &emission,
                reflectance: &lighting.rho,
                form_factors: &estimate,
            };
            let scores = refine_scores(&input);
            let passes_left = refine_options.passes + 1 - mesh_passes.len();
            let share = patches.len() + (budget - patches.len()) / passes_left.max(1);
            let candidates = refinement_candidates(&input, &scores, refine_options.tolerance);
            (select_for_refinement(&input, &scores, refine_options.tolerance, share), candidates)
        };
        if options.verbose {
            report_form_factors(&stats, reciprocity_change, &clamp);
            if stats.closure.is_none() && stats.escaped_rays > 0 {
                eprintln!(
                    "form factors: {}",
                    leak_note(path, &scene, &leaks(&patches, &stats.escapes_per_patch))
                );
            }
        }
        if split.is_empty() {
            let last = mesh_passes[mesh_passes.len() - 1];
            let mesh_stop = if options.no_subdivide {
                None
            } else if patches.len() >= budget
                || (passes_done && last.candidates > last.split)
                || candidates > 0
            {
                Some(MeshStop::Budget {
                    candidates: if passes_done { last.candidates - last.split } else { candidates },
                })
            } else if passes_done {
                Some(MeshStop::Passes { passes: refine_options.passes })
            } else {
                Some(MeshStop::Converged { tolerance: refine_options.tolerance })
            };
            if options.verbose {
                if mesh_passes.len() > 1 {
                    let counts: Vec<String> = mesh_passes.iter().map(|p| p.patches.to_string()).collect();
                    eprintln!("adaptive meshing: patches per pass {}", counts.join(" -> "));
                }
                if let Some(stop) = mesh_stop {
                    eprintln!("{}", stop.note(patches.len(), budget, &budget_source(options, &scene)));
                }
                eprintln!(
                    "cost: {} after {}, {} nonzero form factors, {rays} occlusion rays, {seconds:.2} s of form \
                     factors",
                    counted(patches.len(), "patch", "patches"),
                    counted(mesh_passes.len(), "form-factor pass", "form-factor passes"),
                    stats.nonzeros
                );
            }
            return Ok(Prepared {
                scene,
                patches,
                lighting,
                form_factors,
                stats,
                clamp,
                reciprocity_change,
                mesh_passes,
                repair,
                mesh_stop,
            });
        }
        patches =
            refine(&patches, &split).map_err(|source| PipelineError::Mesh { path: path.into(), source })?;
        mesh_passes.push(MeshPass { patches: patches.len(), split: split.len(), candidates });
        if options.verbose {
            eprintln!(
                "adaptive meshing pass {}: split {} where light changes fast -> {} (budget {budget})",
                mesh_passes.len() - 1,
                counted(split.len(), "patch", "patches"),
                counted(patches.len(), "patch", "patches")
            );
        }
    }
}

/// Faces listed by [`leak_note`].
pub const LEAKS_LISTED: usize = 5;

/// Where an open scene leaks: light that leaves a face and hits nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leak {
    /// The OBJ face (index in OBJ order).
    pub face: usize,
    /// Area of the face that sees the void: each patch's area times the fraction of its cosine-distributed
    /// rays that hit nothing (an estimate of `A_i (1 - sum_j F_ij)`), summed over the face's patches, in scene
    /// units squared.
    pub open_area: f64,
}

/// The faces from which light leaves the scene, most first (ties by face index), from the per-patch counts
/// of [`FormFactorStats::escapes_per_patch`].
#[must_use]
pub fn leaks(patches: &[Patch], escapes_per_patch: &[(u64, u64)]) -> Vec<Leak> {
    let mut per_face: Vec<Leak> = Vec::new();
    for (p, &(cast, escaped)) in patches.iter().zip(escapes_per_patch) {
        if escaped == 0 || cast == 0 {
            continue;
        }
        let open_area = p.area * escaped as f64 / cast as f64;
        match per_face.iter_mut().find(|l| l.face == p.face) {
            Some(l) => l.open_area += open_area,
            None => per_face.push(Leak { face: p.face, open_area }),
        }
    }
    per_face.sort_by(|a, b| b.open_area.total_cmp(&a.open_area).then(a.face.cmp(&b.face)));
    per_face
}

/// One line naming where the open scene at `path` leaks: the [`LEAKS_LISTED`] faces that lose the most light,
/// by OBJ line (or glTF node, mesh, primitive and triangles), with their share of the light lost ([`Leak::open_area`]).
#[must_use]
pub fn leak_note(path: &Path, scene: &Scene, leaks: &[Leak]) -> String {
    let total: f64 = leaks.iter().map(|l| l.open_area).sum();
    let listed: Vec<String> = leaks
        .iter()
        .take(LEAKS_LISTED)
        .map(|l| {
            let share = 100.0 * l.open_area / total;
            match scene.faces.get(l.face) {
                Some(f) if f.gltf.is_some() => format!("face {} ({}, {share:.0}%)", l.face, f.place()),
                f => format!("face {} ({}:{}, {share:.0}%)", l.face, path.display(), f.map_or(0, |f| f.line)),
            }
        })
        .collect();
    let more = if leaks.len() > LEAKS_LISTED {
        format!(" and {} more", counted(leaks.len() - LEAKS_LISTED, "face", "faces"))
    } else {
        String::new()
    };
    format!(
        "light leaves the scene from {}{more} (share of the light lost, at equal radiosity); it escapes through \
         whatever these faces look at (a missing wall, a gap, a face turned the wrong way)",
        listed.join(", ")
    )
}

fn report_form_factors(stats: &FormFactorStats, reciprocity_change: ReciprocityChange, clamp: &RowClamp) {
    eprintln!(
        "form factors: {} patches, {} nonzeros, row sums {:.6}..{:.6}, reciprocity error {:.2e}, {} rays in {:.2} s \
         ({:.2} Mrays/s; {} kernel evaluations {:.2} s, visibility {:.2} s)",
        stats.patches,
        stats.nonzeros,
        stats.estimate_row_sum_min,
        stats.estimate_row_sum_max,
        stats.reciprocity_error_max,
        stats.rays_cast,
        stats.elapsed.as_secs_f64(),
        stats.rays_per_second / 1e6,
        stats.kernel_evaluations,
        stats.kernel_time.as_secs_f64(),
        stats.visibility_time.as_secs_f64()
    );
    match &stats.closure {
        Some(ClosureReport { balance: Closure { refused: Some(r), .. }, .. }) => {
            eprintln!(
                "warning: form factors: closed scene (none of {} hemisphere rays escaped), but closing the rows \
                 would make the form factor between patches {} and {} {:.3e}: rows left as estimated (sums \
                 {:.6}..{:.6}; a patch that sees the back of a face, which absorbs, sums below 1 even in a \
                 closed scene; if none does, more --rays brings the sums closer to 1)",
                stats.escape_rays, r.row, r.col, r.form_factor, stats.row_sum_min, stats.row_sum_max
            );
        }
        Some(c) => eprintln!(
            "form factors: closed scene (none of {} hemisphere rays escaped): {} closed by correcting their \
             {} in proportion to their variance (largest change of an entry {:.2e}, {} zeroed), row sums now \
             {:.12}..{:.12}; {} left as estimated (off by up to {:.2e})",
            stats.escape_rays,
            counted(c.balance.rows_closed, "row", "rows"),
            counted(stats.partly_visible_entries, "partly visible entry", "partly visible entries"),
            c.balance.max_entry_change,
            counted(c.balance.entries_zeroed, "entry", "entries"),
            stats.row_sum_min,
            stats.row_sum_max,
            counted(c.balance.rows_left, "row", "rows"),
            c.balance.max_residual_left
        ),
        None if stats.escape_rays > 0 => eprintln!(
            "form factors: open scene ({} of {} hemisphere rays escaped): rows left as estimated",
            stats.escaped_rays, stats.escape_rays
        ),
        None => {}
    }
    let one_sided = if reciprocity_change.one_sided > 0 {
        format!(
            "; {} seen from one side only, {:.1e} of the exchanged energy, {} mirrored",
            counted(reciprocity_change.one_sided, "pair", "pairs"),
            reciprocity_change.one_sided_share,
            if reciprocity_change.one_sided == 1 { "was" } else { "were" }
        )
    } else {
        String::new()
    };
    eprintln!(
        "form factors: reciprocity enforced (each pair's two estimates averaged; largest relative difference \
         {:.2e}{one_sided})",
        reciprocity_change.max_change
    );
    if clamp.rows > 0 {
        eprintln!(
            "form factors: {} to more than 1 (within sampling noise; largest excess {:.2e}) and {} scaled to 1",
            if clamp.rows == 1 { "1 row summed".to_owned() } else { format!("{} rows summed", clamp.rows) },
            clamp.max_excess,
            if clamp.rows == 1 { "was" } else { "were" }
        );
    }
}
