//! The hierarchy section: the hierarchical solver against the flat one on the same scene, each judged by the
//! continuous path-traced reference (per OBJ face) and, for the hierarchy, by the dense f64 solve of its own
//! leaves (what its links get wrong, apart from the mesh), with what each costs (elements, links, bytes, seconds,
//! rays), and the growth of links and time with the leaf count.

use std::time::Instant;

pub use super::faces::FaceErrors;
use super::faces::{face_errors, face_means};
use super::fit::loglog_slope;
use super::{log, BenchError, BenchOptions};
use crate::formfactor::FormFactorOptions;
use crate::hierarchy::{
    dense_on_leaves, solve_hierarchical, HierarchyOptions, Refinement, ANSWER_SAMPLES_PER_PATCH,
    ANSWER_SENDER_WEIGHT, DEFAULT_MIN_AREA_FRACTION,
};
use crate::lighting::PatchLighting;
use crate::montecarlo::{continuous_reference, ContinuousReference, ReferenceOptions, SampleCount};
use crate::pipeline::{prepare, PrepareOptions};
use crate::reference::{exact_transfer, Method};
use crate::scene::Scene;

/// Largest leaf count at which the hierarchy is also compared with the dense solve of its leaves.
pub const DENSE_LIMIT: usize = 4096;

/// Relative standard error per face of the continuous reference the rows are judged by: the mesh-repair
/// issue's 0.1%, so that a face judged within 1% is not within it by the reference's noise.
pub const REFERENCE_TARGET: f64 = 0.001;

/// Most paths per face of that reference: the dim block side facing the open front needs about 2^25 paths for
/// 0.1% (at the path tracer's default cap of 2^20 they stop near 0.45%).
pub const REFERENCE_MAX_SAMPLES: u64 = 1 << 27;

/// Faces smaller than this share of the largest face are left out of the per-face errors (the targets
/// are stated for faces larger than 5% of the floor).
pub const SMALL_FACE: f64 = 0.05;

/// The finest Cornell row's epsilon and resolution limit (brightness refinement): the default resolution limit
/// ([`DEFAULT_MIN_AREA_FRACTION`]) caps the leaves however small epsilon is, below the 64,000, so this
/// row lets elements go down to a smaller share of the scene's area.
pub const FINEST: (f64, f64) = (0.000005, 0.000002);

/// Most links of the finest row (the default limit is below what it needs).
const FINEST_MAX_LINKS: usize = 40_000_000;

/// Bytes a link would take in a 16-bit table: two directions, each a 32-bit node index and a 16-bit code.
pub const LINK_BYTES: usize = 2 * (4 + 2);

/// Bytes an entry of the flat 16-bit table takes (a 16-bit receiver index and a 16-bit code).
pub const ENTRY_BYTES: usize = 2 + 2;

/// One solve of one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct HierarchyRow {
    /// Scene name.
    pub scene: String,
    /// `hierarchical (epsilon E)` or `flat (N patches)`.
    pub method: String,
    /// The hierarchy's epsilon (`None` for flat rows).
    pub epsilon: Option<f64>,
    /// The hierarchy's refinement (`None` for flat rows).
    pub refinement: Option<Refinement>,
    /// The hierarchy's [`HierarchyOptions::sender_weight`] (0 for flat rows).
    pub sender_weight: f64,
    /// Quadrature points per element of the links' (or the flat matrix's) form factors
    /// ([`crate::formfactor::FormFactorOptions::samples_per_patch`]).
    pub samples: usize,
    /// Leaves or patches.
    pub elements: usize,
    /// Links, or the flat matrix's nonzero entries.
    pub links: usize,
    /// Bytes of the links or entries at 16 bits ([`LINK_BYTES`], [`ENTRY_BYTES`]).
    pub bytes: usize,
    /// Whole solve, seconds (meshing, form factors or links, and the f64 solve).
    pub seconds: f64,
    /// Occlusion rays cast (flat rows: the final mesh's form factors; its adaptive passes cast more before).
    pub rays: u64,
    /// Against the dense f64 solve of the same leaves (hierarchical rows with at most [`DENSE_LIMIT`] leaves).
    pub vs_dense: Option<FaceErrors>,
    /// Against the continuous reference.
    pub vs_continuous: FaceErrors,
    /// The hierarchy's claimed error (see `HierarchyStats::claimed_error`).
    pub claimed: Option<f64>,
    /// The process's resident memory during the row, if the system reports it.
    pub memory: Option<RowMemory>,
}

/// The section's results: the rows, the reference they are judged by, and the fitted growth exponents.
#[derive(Clone, Debug, PartialEq)]
pub struct HierarchySection {
    /// The rows, per scene: hierarchical at decreasing epsilon, then flat.
    pub rows: Vec<HierarchyRow>,
    /// The continuous reference's cost and reach: scene, paths, seconds, largest relative standard error.
    pub references: Vec<(String, u64, f64, f64)>,
    /// Log-log slopes over the hierarchical rows of one scene and refinement (named together): links and seconds
    /// against leaves.
    pub exponents: Vec<(String, Option<f64>, Option<f64>)>,
    /// Log-log slopes over the flat rows of one scene: the mean and the worst face's error against the continuous
    /// reference, against the patch count (how fast the discretization error falls with the mesh; a slope near 0
    /// is a bias that refinement does not remove).
    pub discretization: Vec<(String, Option<f64>, Option<f64>)>,
    /// Device tables of the same scene, flat against hierarchical: error against model instructions
    /// ([`super::hierdevice`]).
    pub device: Vec<super::hierdevice::DeviceCurve>,
}

/// The faces the errors are taken over: lit ones (reference radiosity above zero) not smaller than
/// [`SMALL_FACE`] of the largest.
fn judged_faces(reference: &ContinuousReference) -> Vec<usize> {
    let largest = reference.faces.iter().map(|f| f.area).fold(0.0, f64::max);
    reference
        .faces
        .iter()
        .filter(|f| f.area >= SMALL_FACE * largest && f.radiosity.min_element() > 0.0)
        .map(|f| f.face)
        .collect()
}

/// The refinement's name as the CLI spells it.
fn refinement_label(refinement: Refinement) -> &'static str {
    match refinement {
        Refinement::Budgets => "budgets",
        Refinement::Brightness => "brightness",
    }
}

/// The refinement's name with the sender weight, if any (`brightness, sender weight 16`).
fn oracle_label(refinement: Refinement, sender_weight: f64, samples: usize) -> String {
    let mut label = refinement_label(refinement).to_owned();
    if sender_weight > 0.0 {
        label += &format!(", sender weight {sender_weight}");
    }
    if samples != FormFactorOptions::default().samples_per_patch {
        label += &format!(", {samples} quadrature points");
    }
    label
}

/// A field of `/proc/self/status` in bytes (`VmRSS`, `VmHWM`: given in kB).
fn status_bytes(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.strip_prefix(field).is_some_and(|r| r.starts_with(':')))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The process's resident memory during one row: what it held when the row started and its peak during it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowMemory {
    /// Resident set at the row's start (bytes): memory of earlier rows that the allocator kept is in it, and
    /// the row reuses it first.
    pub start: u64,
    /// Peak resident set during the row (bytes), the start included.
    pub peak: u64,
}

/// Starts a row's memory measurement: a new peak from the current resident set (Linux: `5` written to
/// `/proc/self/clear_refs`). `None` where the system does not report or reset it.
pub(super) fn begin_row() -> Option<u64> {
    std::fs::write("/proc/self/clear_refs", "5").ok()?;
    status_bytes("VmRSS")
}

/// The row's memory since [`begin_row`] returned `start`.
pub(super) fn end_row(start: Option<u64>) -> Option<RowMemory> {
    Some(RowMemory { start: start?, peak: status_bytes("VmHWM")? })
}

/// Runs the section on the Cornell box: the hierarchy with each refinement at several epsilons (quick: one each),
/// the flat solve at several patch budgets (full run: 500, its default, 2,000 and 4,000; quick: 100 and 200),
/// each judged by one continuous reference, and the device curves of the flat and the hierarchical device table
/// ([`super::hierdevice`]).
///
/// # Errors
/// Loading, meshing, the solves and the reference; a failure is the bench's.
pub fn section(options: &BenchOptions) -> Result<HierarchySection, BenchError> {
    const MIN_AREA: f64 = DEFAULT_MIN_AREA_FRACTION;
    const W: f64 = ANSWER_SENDER_WEIGHT;
    const Q: usize = 16;
    const A: usize = ANSWER_SAMPLES_PER_PATCH;
    // (refinement, epsilon, resolution limit as a share of the scene's area, sender weight, quadrature points)
    let epsilons: &[(Refinement, f64, f64, f64, usize)] = if options.quick {
        &[
            (Refinement::Budgets, 0.3, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.1, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.1, MIN_AREA, W, Q),
        ]
    } else {
        &[
            (Refinement::Budgets, 0.3, MIN_AREA, 0.0, Q),
            (Refinement::Budgets, 0.1, MIN_AREA, 0.0, Q),
            (Refinement::Budgets, 0.03, MIN_AREA, 0.0, Q),
            (Refinement::Budgets, 0.01, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.02, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.01, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.005, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.0025, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.0008, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.0005, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.0002, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.0001, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, 0.00002, MIN_AREA, 0.0, Q),
            (Refinement::Brightness, FINEST.0, FINEST.1, 0.0, Q),
            // The sender's unevenness charged at the bound itself, then at the f64 answers' weight.
            (Refinement::Brightness, 0.0005, MIN_AREA, 1.0, Q),
            (Refinement::Brightness, 0.005, MIN_AREA, W, Q),
            (Refinement::Brightness, 0.002, MIN_AREA, W, Q),
            (Refinement::Brightness, 0.001, MIN_AREA, W, Q),
            (Refinement::Brightness, 0.0005, MIN_AREA, W, Q),
            (Refinement::Brightness, 0.0002, MIN_AREA, W, Q),
            // The f64 answers' quadrature (a 2 x 2 rule) against the 4 x 4 rows above.
            (Refinement::Brightness, 0.002, MIN_AREA, W, A),
            (Refinement::Brightness, 0.001, MIN_AREA, W, A),
            (Refinement::Brightness, 0.0005, MIN_AREA, W, A),
            (Refinement::Brightness, 0.0002, MIN_AREA, W, A),
        ]
    };
    let flat_sizes: &[Option<usize>] =
        if options.quick { &[Some(100), Some(200)] } else { &[Some(500), None, Some(2000), Some(4000)] };
    let name = "cornell-box";
    let path = options.scenes.join(format!("{name}.obj"));
    let scene = Scene::load(&path)?;
    log(options, "hierarchy: continuous reference of the Cornell box");
    let target = if options.quick { 0.02 } else { REFERENCE_TARGET };
    let reference = continuous_reference(
        &scene,
        &ReferenceOptions {
            samples: SampleCount::TargetRelative {
                target,
                max_samples: if options.quick {
                    crate::montecarlo::DEFAULT_MAX_SAMPLES
                } else {
                    REFERENCE_MAX_SAMPLES
                },
            },
            progress: false,
            ..ReferenceOptions::default()
        },
    )
    .map_err(|e| BenchError::Options(format!("continuous reference: {e}")))?;
    let faces = reference.faces.iter().map(|f| f.face).max().map_or(0, |m| m + 1);
    let mut want = vec![None; faces];
    for f in &reference.faces {
        want[f.face] = Some(f.radiosity);
    }
    let judged = judged_faces(&reference);
    let worst_se = reference.faces.iter().map(|f| f.relative_standard_error).fold(0.0, f64::max);
    let mut rows = Vec::new();
    for &(refinement, epsilon, min_area_fraction, sender_weight, samples) in epsilons {
        let label = oracle_label(refinement, sender_weight, samples);
        let finer = if min_area_fraction == MIN_AREA {
            String::new()
        } else {
            format!(", elements down to {min_area_fraction:e} of the area")
        };
        log(options, &format!("hierarchy: {label} refinement, epsilon {epsilon}{finer}"));
        let memory = begin_row();
        let start = Instant::now();
        let max_links = if min_area_fraction == MIN_AREA {
            HierarchyOptions::default().max_links
        } else {
            FINEST_MAX_LINKS
        };
        let sol = solve_hierarchical(
            &scene,
            &HierarchyOptions {
                epsilon,
                refinement,
                min_area_fraction,
                max_links,
                sender_weight,
                form_factors: FormFactorOptions {
                    samples_per_patch: samples,
                    ..HierarchyOptions::default().form_factors
                },
                ..HierarchyOptions::default()
            },
        )
        .map_err(|e| {
            BenchError::Options(format!("hierarchical solve ({label}) at epsilon {epsilon}: {e}"))
        })?;
        let seconds = start.elapsed().as_secs_f64();
        let memory = end_row(memory);
        let got = face_means(&sol.leaves, &sol.b, &reference);
        let vs_dense = if sol.leaves.len() <= DENSE_LIMIT {
            let dense = dense_on_leaves(&scene, &sol)
                .map_err(|e| BenchError::Options(e.to_string()))?
                .relight(&PatchLighting::new(&scene, &sol.leaves).default_intensity)?;
            Some(face_errors(&got, &face_means(&sol.leaves, &dense, &reference), &judged))
        } else {
            None
        };
        let links = sol.stats.surface_links + sol.stats.cluster_links;
        rows.push(HierarchyRow {
            scene: name.to_owned(),
            method: format!("hierarchical, {label} (epsilon {epsilon}{finer})"),
            epsilon: Some(epsilon),
            refinement: Some(refinement),
            sender_weight,
            samples,
            elements: sol.leaves.len(),
            links,
            bytes: links * LINK_BYTES,
            seconds,
            rays: sol.stats.rays,
            vs_dense,
            vs_continuous: face_errors(&got, &want, &judged),
            claimed: sol.stats.claimed_error,
            memory,
        });
    }
    for &max_patches in flat_sizes {
        log(options, &format!("hierarchy: flat solve at {max_patches:?} patches"));
        let memory = begin_row();
        let start = Instant::now();
        let prepared =
            prepare(&path, &PrepareOptions { max_patches, ..PrepareOptions::quiet(false, 16, 16) })?;
        let l = &prepared.lighting;
        let tv = exact_transfer(l, &prepared.form_factors, &Method::for_size(prepared.patches.len()))?;
        let b = tv.relight(&l.default_intensity)?;
        let seconds = start.elapsed().as_secs_f64();
        let entries = prepared.form_factors.nonzeros();
        rows.push(HierarchyRow {
            scene: name.to_owned(),
            method: format!("flat ({} patches)", prepared.patches.len()),
            epsilon: None,
            refinement: None,
            sender_weight: 0.0,
            samples: 16,
            elements: prepared.patches.len(),
            links: entries,
            bytes: entries * ENTRY_BYTES,
            seconds,
            rays: prepared.stats.rays_cast,
            vs_dense: None,
            vs_continuous: face_errors(&face_means(&prepared.patches, &b, &reference), &want, &judged),
            claimed: None,
            memory: end_row(memory),
        });
    }
    let mut exponents = Vec::new();
    // One fit per oracle: a refinement with one sender weight and quadrature (the single weight-1 row fits
    // nothing).
    let mut oracles: Vec<(Refinement, f64, usize)> =
        rows.iter().filter_map(|r| r.refinement.map(|f| (f, r.sender_weight, r.samples))).collect();
    oracles.dedup();
    for (refinement, weight, samples) in oracles {
        let hierarchical: Vec<&HierarchyRow> = rows
            .iter()
            .filter(|r| r.refinement == Some(refinement) && r.sender_weight == weight && r.samples == samples)
            .collect();
        if hierarchical.len() >= 2 {
            let links: Vec<(f64, f64)> =
                hierarchical.iter().map(|r| (r.elements as f64, r.links as f64)).collect();
            let time: Vec<(f64, f64)> = hierarchical.iter().map(|r| (r.elements as f64, r.seconds)).collect();
            exponents.push((
                format!("{name}, {} refinement", oracle_label(refinement, weight, samples)),
                loglog_slope(&links),
                loglog_slope(&time),
            ));
        }
    }
    let flat: Vec<&HierarchyRow> = rows.iter().filter(|r| r.epsilon.is_none()).collect();
    let discretization = if flat.len() >= 2 {
        let mean: Vec<(f64, f64)> = flat.iter().map(|r| (r.elements as f64, r.vs_continuous.mean)).collect();
        let worst: Vec<(f64, f64)> =
            flat.iter().map(|r| (r.elements as f64, r.vs_continuous.worst)).collect();
        vec![(name.to_owned(), loglog_slope(&mean), loglog_slope(&worst))]
    } else {
        Vec::new()
    };
    let device = super::hierdevice::curves(options, &path, &scene, &reference, &want, &judged)?;
    Ok(HierarchySection {
        rows,
        device,
        references: vec![(name.to_owned(), reference.paths, reference.seconds, worst_se)],
        exponents,
        discretization,
    })
}
