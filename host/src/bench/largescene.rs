//! The large generated scene of the hierarchy section: the open-plan office of `scenes/make_office.py` at growing
//! numbers of workstations, solved hierarchically with brightness refinement (the device tables' refinement),
//! with what each size costs (leaves, links, bytes, seconds, rays) and how links and time grow with
//! the leaves. No error column: the dense solve does not reach these leaf counts, and the continuous reference
//! would need hours for a hundred thousand faces.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use super::fit::loglog_slope;
use super::hierarchy::LINK_BYTES;
use super::{log, BenchError, BenchOptions};
use crate::hierarchy::{solve_hierarchical, HierarchyOptions, Refinement};
use crate::scene::Scene;

/// The epsilon of every office row (brightness refinement): coarse enough that the larger sizes stay within a
/// few minutes on two cores.
pub const OFFICE_EPSILON: f64 = 0.05;

/// One size of the office.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeRow {
    /// Rows and columns of workstations.
    pub workstations: (usize, usize),
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
}

/// The office rows and their growth.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeSection {
    /// The epsilon of every row.
    pub epsilon: f64,
    /// The rows, smallest first.
    pub rows: Vec<OfficeRow>,
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

/// Runs the office rows (full run: 1 x 1, 2 x 2, 3 x 4 and 5 x 6 workstations; quick: 1 x 1 at a coarse
/// epsilon). A size whose solve fails (e.g. more links than the limit) is reported with its error, and the
/// larger sizes are not tried.
///
/// # Errors
/// Generating or loading a scene.
pub fn section(options: &BenchOptions) -> Result<OfficeSection, BenchError> {
    let (sizes, epsilon): (&[(usize, usize)], f64) =
        if options.quick { (&[(1, 1)], 0.5) } else { (&[(1, 1), (2, 2), (3, 4), (5, 6)], OFFICE_EPSILON) };
    let mut rows = Vec::new();
    for &size in sizes {
        log(options, &format!("hierarchy: office with {} x {} workstations", size.0, size.1));
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
        let start = Instant::now();
        let solved = solve_hierarchical(
            &scene,
            &HierarchyOptions { epsilon, refinement: Refinement::Brightness, ..HierarchyOptions::default() },
        );
        let seconds = start.elapsed().as_secs_f64();
        let outcome = solved
            .map(|sol| {
                let links = sol.stats.surface_links + sol.stats.cluster_links;
                OfficeSolve {
                    leaves: sol.leaves.len(),
                    nodes: sol.stats.clusters + sol.stats.surfaces,
                    links,
                    bytes: links * LINK_BYTES,
                    seconds,
                    rays: sol.stats.rays,
                }
            })
            .map_err(|e| e.to_string());
        let failed = outcome.is_err();
        rows.push(OfficeRow { workstations: size, triangles, outcome });
        if failed {
            break;
        }
    }
    let solved: Vec<&OfficeSolve> = rows.iter().filter_map(|r| r.outcome.as_ref().ok()).collect();
    let slope = |y: &dyn Fn(&OfficeSolve) -> f64| {
        (solved.len() >= 2)
            .then(|| loglog_slope(&solved.iter().map(|s| (s.leaves as f64, y(s))).collect::<Vec<_>>()))
            .flatten()
    };
    Ok(OfficeSection {
        epsilon,
        links_exponent: slope(&|s| s.links as f64),
        seconds_exponent: slope(&|s| s.seconds),
        rows,
    })
}
