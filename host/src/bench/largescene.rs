//! The large generated scene of the hierarchy section: the open-plan office of `scenes/make_office.py` at growing
//! numbers of workstations, solved hierarchically with brightness refinement (the device tables' refinement),
//! with what each size costs (leaves, links, bytes, seconds, rays) and how links and time grow with
//! the leaves, and how far each material's area-averaged radiosity is from the continuous (path-traced) reference
//! of the same scene. Per material, not per face: the dense solve does not reach these leaf counts, and a
//! reference accurate on each of thousands of small faces would take hours, where a few thousand paths per face
//! pin down every material's average.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use super::fit::loglog_slope;
use super::hierarchy::{begin_row, end_row, RowMemory, LINK_BYTES};
use super::{log, BenchError, BenchOptions};
use crate::hierarchy::{solve_hierarchical, HierarchicalSolution, HierarchyOptions, Refinement};
use crate::montecarlo::{continuous_reference, ContinuousReference, ReferenceOptions, SampleCount};
use crate::rgb::Rgb;
use crate::scene::Scene;

/// The epsilon of every office row (brightness refinement): coarse enough that the larger sizes stay within a
/// few minutes on two cores.
pub const OFFICE_EPSILON: f64 = 0.05;

/// Paths per face of the office's continuous reference (full run): the furniture's materials, hundreds of faces
/// each, are then known to a fraction of a percent, the room's few large faces to a few percent (the report
/// prints each material's standard error).
pub const OFFICE_REFERENCE_SAMPLES: u64 = 8192;

/// Workstations of the full office (`make_office.py`'s default: 105,072 triangles), solved once beside the
/// growth rows.
pub const FULL_OFFICE: (usize, usize) = (17, 21);

/// The full office's epsilon: at [`OFFICE_EPSILON`], by the growth rows' links per leaf, it would need about ten
/// times the default link limit; 0.9 is coarse enough to solve within this machine's memory (the report has
/// its links, seconds and peak).
pub const FULL_OFFICE_EPSILON: f64 = 0.9;

/// Most links of the full office's solve (the default limit is below what it needs).
pub const FULL_OFFICE_MAX_LINKS: usize = 40_000_000;

/// Paths per face of the full office's reference: an eighth of [`OFFICE_REFERENCE_SAMPLES`], since its thousands
/// of faces per furniture material average the noise down (the report prints each material's standard error).
pub const FULL_OFFICE_REFERENCE_SAMPLES: u64 = 1024;

/// One material's area-averaged radiosity against the continuous reference.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialError {
    /// The material's name.
    pub name: String,
    /// Signed relative difference `(B - B_ref) / B_ref` of the channel where it is largest in magnitude.
    pub error: f64,
    /// The reference's relative standard error of that average (same channel).
    pub reference_se: f64,
}

/// One size of the office.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeRow {
    /// Rows and columns of workstations.
    pub workstations: (usize, usize),
    /// The solve's epsilon (brightness refinement).
    pub epsilon: f64,
    /// Paths per face of the row's continuous reference.
    pub samples: u64,
    /// Input triangles.
    pub triangles: usize,
    /// What the solve gave, or why it stopped (its error message).
    pub outcome: Result<OfficeSolve, String>,
}

/// The costs of one solved size.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeSolve {
    /// Leaves.
    pub leaves: usize,
    /// Tree nodes (clusters and surfaces).
    pub nodes: usize,
    /// Links (surface-surface and with a cluster).
    pub links: usize,
    /// Bytes of the links at 16 bits ([`LINK_BYTES`]).
    pub bytes: usize,
    /// Whole solve, seconds (loading, tree, refinement, the f64 solves).
    pub seconds: f64,
    /// Occlusion rays cast.
    pub rays: u64,
    /// Every material that does not emit, against the continuous reference, in the scene's order.
    pub materials: Vec<MaterialError>,
    /// The continuous reference's wall time, seconds.
    pub reference_seconds: f64,
    /// The process's resident memory during the solve, if the system reports it.
    pub memory: Option<RowMemory>,
}

impl OfficeSolve {
    /// The material farthest from the reference.
    #[must_use]
    pub fn worst_material(&self) -> Option<&MaterialError> {
        self.materials.iter().max_by(|a, b| a.error.abs().total_cmp(&b.error.abs()))
    }

    /// The median over the materials of the error's magnitude.
    #[must_use]
    pub fn median_material(&self) -> Option<f64> {
        let mut e: Vec<f64> = self.materials.iter().map(|m| m.error.abs()).collect();
        e.sort_by(f64::total_cmp);
        e.get(e.len() / 2).copied()
    }
}

/// Each non-emitting material's area-averaged radiosity in `solution` (its leaves) against `reference` (its
/// faces), with the reference's standard error of that average.
fn material_errors(
    scene: &Scene,
    solution: &HierarchicalSolution,
    reference: &ContinuousReference,
) -> Vec<MaterialError> {
    let n = scene.materials.len();
    let (mut area, mut got) = (vec![0.0; n], vec![Rgb::ZERO; n]);
    for (leaf, b) in solution.leaves.iter().zip(&solution.b) {
        let m = scene.faces[leaf.face].material;
        area[m] += leaf.area;
        got[m] += leaf.area * *b;
    }
    let (mut ref_area, mut want, mut var) = (vec![0.0; n], vec![Rgb::ZERO; n], vec![Rgb::ZERO; n]);
    for f in &reference.faces {
        let m = scene.faces[f.face].material;
        ref_area[m] += f.area;
        want[m] += f.area * f.radiosity;
        let se = f.area * f.standard_error;
        var[m] += se * se;
    }
    let mut out = Vec::new();
    for (m, material) in scene.materials.iter().enumerate() {
        if material.is_emitter() || area[m] <= 0.0 || ref_area[m] <= 0.0 {
            continue;
        }
        let (g, w) = (got[m] / area[m], want[m] / ref_area[m]);
        let se = var[m].map(f64::sqrt) / ref_area[m];
        let mut best: Option<(f64, f64)> = None;
        for c in 0..3 {
            if w[c] > 0.0 {
                let e = (g[c] - w[c]) / w[c];
                if best.is_none_or(|(b, _)| e.abs() > b.abs()) {
                    best = Some((e, se[c] / w[c]));
                }
            }
        }
        if let Some((error, reference_se)) = best {
            out.push(MaterialError { name: material.name.clone(), error, reference_se });
        }
    }
    out
}

/// The office rows and their growth.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeSection {
    /// The epsilon of every growth row.
    pub epsilon: f64,
    /// Paths per face of the growth rows' continuous reference.
    pub samples: u64,
    /// The growth rows, smallest first.
    pub rows: Vec<OfficeRow>,
    /// The full office ([`FULL_OFFICE`] at [`FULL_OFFICE_EPSILON`]; full run only), not in the growth fits.
    pub full: Option<OfficeRow>,
    /// Log-log slopes over the solved rows: links and seconds against leaves.
    pub links_exponent: Option<f64>,
    /// See `links_exponent`.
    pub seconds_exponent: Option<f64>,
}

/// Writes the office with `rows x columns` workstations into `dir` with the scene's own generator (`python3
/// scenes/make_office.py`), returning the OBJ's path.
///
/// # Errors
/// [`BenchError::Options`] naming the command if it cannot run or fails.
fn generate(scenes: &Path, dir: &Path, (rows, columns): (usize, usize)) -> Result<PathBuf, BenchError> {
    let script = scenes.join("make_office.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(dir)
        .arg(rows.to_string())
        .arg(columns.to_string())
        .output()
        .map_err(|e| BenchError::Options(format!("running python3 {}: {e}", script.display())))?;
    if !out.status.success() {
        return Err(BenchError::Options(format!(
            "python3 {} {} {rows} {columns} failed: {}",
            script.display(),
            dir.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    Ok(dir.join("office.obj"))
}

/// Generates the office with `size` workstations, solves it at `epsilon` (brightness refinement; `max_links` or
/// the default limit) and judges it by its continuous reference at `samples` paths per face. A solve that fails
/// (e.g. more links than the limit) is the row's outcome, not an error.
///
/// # Errors
/// Generating or loading the scene; its reference.
fn office_row(
    options: &BenchOptions,
    size: (usize, usize),
    epsilon: f64,
    max_links: Option<usize>,
    samples: u64,
) -> Result<OfficeRow, BenchError> {
    log(options, &format!("hierarchy: office with {} x {} workstations, epsilon {epsilon}", size.0, size.1));
    let dir = std::env::temp_dir().join(format!(
        "radiosity-bench-office-{}-{}x{}",
        std::process::id(),
        size.0,
        size.1
    ));
    std::fs::create_dir_all(&dir)
        .map_err(|e| BenchError::Options(format!("creating {}: {e}", dir.display())))?;
    // The scene is read whole into memory, so its folder goes before the solve (and on any error).
    let loaded = generate(&options.scenes, &dir, size).and_then(|obj| Ok(Scene::load(&obj)?));
    let _ = std::fs::remove_dir_all(&dir);
    let scene = loaded?;
    let triangles = scene.faces.len();
    let memory = begin_row();
    let start = Instant::now();
    let defaults = HierarchyOptions::default();
    let solved = solve_hierarchical(
        &scene,
        &HierarchyOptions {
            epsilon,
            refinement: Refinement::Brightness,
            max_links: max_links.unwrap_or(defaults.max_links),
            ..defaults
        },
    );
    let seconds = start.elapsed().as_secs_f64();
    let memory = end_row(memory);
    let outcome = match solved {
        Ok(sol) => {
            log(options, "hierarchy: office's continuous reference");
            let reference = continuous_reference(
                &scene,
                &ReferenceOptions {
                    samples: SampleCount::PerFace(samples),
                    progress: false,
                    ..ReferenceOptions::default()
                },
            )
            .map_err(|e| BenchError::Options(format!("the office's continuous reference: {e}")))?;
            let links = sol.stats.surface_links + sol.stats.cluster_links;
            Ok(OfficeSolve {
                leaves: sol.leaves.len(),
                nodes: sol.stats.clusters + sol.stats.surfaces,
                links,
                bytes: links * LINK_BYTES,
                seconds,
                rays: sol.stats.rays,
                materials: material_errors(&scene, &sol, &reference),
                reference_seconds: reference.seconds,
                memory,
            })
        }
        Err(e) => Err(e.to_string()),
    };
    Ok(OfficeRow { workstations: size, epsilon, samples, triangles, outcome })
}

/// Runs the office rows (full run: 1 x 1, 2 x 2, 3 x 4 and 5 x 6 workstations, then the full office at its own
/// epsilon; quick: 1 x 1 at a coarse epsilon). A size whose solve fails (e.g. more links than the limit) is
/// reported with its error, and the larger sizes are not tried.
///
/// # Errors
/// Generating or loading a scene.
pub fn section(options: &BenchOptions) -> Result<OfficeSection, BenchError> {
    let (sizes, epsilon, samples): (&[(usize, usize)], f64, u64) = if options.quick {
        (&[(1, 1)], 0.5, 64)
    } else {
        (&[(1, 1), (2, 2), (3, 4), (5, 6)], OFFICE_EPSILON, OFFICE_REFERENCE_SAMPLES)
    };
    let mut rows = Vec::new();
    for &size in sizes {
        let row = office_row(options, size, epsilon, None, samples)?;
        let failed = row.outcome.is_err();
        rows.push(row);
        if failed {
            break;
        }
    }
    let full = (!options.quick)
        .then(|| {
            office_row(
                options,
                FULL_OFFICE,
                FULL_OFFICE_EPSILON,
                Some(FULL_OFFICE_MAX_LINKS),
                FULL_OFFICE_REFERENCE_SAMPLES,
            )
        })
        .transpose()?;
    let solved: Vec<&OfficeSolve> = rows.iter().filter_map(|r| r.outcome.as_ref().ok()).collect();
    let slope = |y: &dyn Fn(&OfficeSolve) -> f64| {
        (solved.len() >= 2)
            .then(|| loglog_slope(&solved.iter().map(|s| (s.leaves as f64, y(s))).collect::<Vec<_>>()))
            .flatten()
    };
    Ok(OfficeSection {
        epsilon,
        samples,
        full,
        links_exponent: slope(&|s| s.links as f64),
        seconds_exponent: slope(&|s| s.seconds),
        rows,
    })
}
