//! Device tables of one scene, flat against hierarchical: core's f32 shooting from a cold start at the
//! default intensities on the Cornell box's flat device table (the `demo`'s: the adaptive mesh within
//! [`FLAT_PATCHES`] patches, baked at the bake's defaults) and on its hierarchical table (the `demo`'s:
//! brightness refinement at [`HIER_EPSILON`], 16-bit codes), with the error at geometrically spaced amounts
//! of work against each table's own f64 answer and, per OBJ face, against the continuous reference (the
//! common yardstick: the two tables solve different discretizations of the same scene). Work becomes model
//! instructions through the firmware's cost model (`firmware-sim/COST.md`, measured under QEMU): the bound
//! per unit of the `m4-f32` build for the flat table; for the hierarchical one the rate bound (per link, per
//! node judged, per node swept and per shot, scaled to the envelope of its calibration frames) of
//! `cornell-hier-m4-f32`, this same table as `firmware-sim/tables/cornell-box-hier.rft` run on the f32
//! firmware, whose runs are as long as the curve's (the committed test table's, `hier-m4-f32`, holds runs of
//! at most 4 links), applied to the links, nodes judged, nodes swept and shots the solver counts. They cost
//! different amounts, and the mix changes along a run, so one rate per unit would not bound every stretch of
//! it.

use radiosity_core::{
    hier_convergence_floor, Config, HierOwnedBuffers, HierSolver, HierTable, NoProgressReason, Outcome,
    Solver, Table,
};

use super::device::{radiosity, Owned};
use super::faces::{face_errors, face_means, FaceErrors};
use super::{bound_per_unit, log, rate_bound, BenchError, BenchOptions, Rates, COST_MD};
use crate::bake::{bake, bake_hierarchy, BakeInput, BakeOptions};
use crate::evaluate::{evaluate, EvaluateOptions, QUANTIZATION};
use crate::formfactor::FormFactorOptions;
use crate::hierarchy::{solve_hierarchical, HierarchyOptions, Refinement};
use crate::metrics;
use crate::montecarlo::ContinuousReference;
use crate::patch::Patch;
use crate::pipeline::{prepare, PrepareOptions};
use crate::reference::{exact_transfer, Method};
use crate::rgb::{max_channel, Rgb};
use crate::scene::Scene;

/// Patch budget of the flat device table (the `demo`'s table for a Cortex-M4).
pub const FLAT_PATCHES: usize = 400;

/// Epsilon of the hierarchical device table (the `demo`'s), with brightness refinement.
pub const HIER_EPSILON: f64 = 0.02;

/// Work units of the first checkpoint; each later one is [`RATIO`] times the previous.
const FIRST_UNITS: u64 = 1_000;

/// Ratio between successive checkpoints' work.
const RATIO: f64 = 1.5;

/// Most work units of a curve (a curve ends earlier when its solver converges).
const MAX_UNITS: u64 = 50_000_000;

/// The solvers' convergence tolerance, relative to the emitted power (every node's or patch's unshot power below
/// it ends the curve): far below the 16-bit codes' error floor.
const TOLERANCE: f64 = 1e-7;

/// One checkpoint of a device curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DevicePoint {
    /// Work units spent so far.
    pub units: u64,
    /// Of them, by kind (hierarchical tables; `None` for a flat table, whose units are all alike).
    pub work: Option<HierWork>,
    /// Model instructions: the curve's [`CostModel`] applied to the work so far.
    pub instructions: f64,
    /// Area-weighted relative L2 error against the table's own f64 answer.
    pub own: f64,
    /// Per OBJ face against the continuous reference.
    pub faces: FaceErrors,
}

/// The kinds of a hierarchical solver's work so far (the rest of its units are nodes swept).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HierWork {
    /// Links applied.
    pub links: u64,
    /// Nodes judged in rounds.
    pub judged: u64,
    /// Shots started.
    pub shots: u64,
}

/// One table's curve.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceCurve {
    /// What the table is (method, elements).
    pub name: String,
    /// Patches or leaves.
    pub elements: usize,
    /// Table bytes.
    pub bytes: usize,
    /// The firmware build whose cost model turns units into instructions.
    pub build: String,
    /// That build's bound.
    pub model: CostModel,
    /// Whether the solver converged (to `TOLERANCE`) before `MAX_UNITS`.
    pub converged: bool,
    /// The table's quantization component (same measure as `own`): the f64 answer of its decoded codes
    /// against the f64 answer of the system they were rounded from, the part of the converged floor that is
    /// not f32 arithmetic.
    pub quantization: f64,
    /// The checkpoints.
    pub points: Vec<DevicePoint>,
}

/// A firmware build's bound on instructions for an amount of work (`firmware-sim/COST.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CostModel {
    /// The bound instructions per work unit.
    PerUnit(f64),
    /// The rate bound: `scale (per_link links + per_judged judged + per_swept swept + per_shot shots)`
    /// (without the per-frame overhead: a curve is one run, not frames).
    Rates(Rates),
}

impl CostModel {
    /// Model instructions for `units` work units, of the kinds `work` (all units nodes swept if `None`
    /// under the rate bound, all alike under the bound per unit).
    #[must_use]
    pub fn instructions(&self, units: u64, work: Option<HierWork>) -> f64 {
        match *self {
            CostModel::PerUnit(r) => units as f64 * r,
            CostModel::Rates(r) => {
                let w = work.unwrap_or(HierWork { links: 0, judged: 0, shots: 0 });
                let links = w.links.min(units);
                let judged = w.judged.min(units - links);
                let swept = units - links - judged;
                r.scale
                    * (r.per_link.max(0.0) * links as f64
                        + r.per_judged.max(0.0) * judged as f64
                        + r.per_swept.max(0.0) * swept as f64
                        + r.per_shot.max(0.0) * w.shots as f64)
            }
        }
    }
}

impl std::fmt::Display for CostModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CostModel::PerUnit(r) => write!(f, "{r:.2} per unit"),
            CostModel::Rates(r) => write!(
                f,
                "{:.1} per link, {:.1} per node judged, {:.1} per node swept, {:.1} per shot, x {:.3}",
                r.per_link, r.per_judged, r.per_swept, r.per_shot, r.scale
            ),
        }
    }
}

impl DeviceCurve {
    /// Model instructions at the first checkpoint whose error against the table's own answer is at most `level`.
    #[must_use]
    pub fn instructions_to(&self, level: f64) -> Option<f64> {
        self.points.iter().find(|p| p.own <= level).map(|p| p.instructions)
    }
}

/// Emitted power (largest channel) of patches with emission `e`: what the tolerance is relative to.
fn emitted(patches: &[Patch], e: &[Rgb]) -> f64 {
    patches.iter().zip(e).map(|(p, e)| p.area * max_channel(*e)).sum()
}

/// Steps `step` (at most the given units, returning the outcome) from a cold start, recording a checkpoint with
/// `measure` at geometrically growing work until it converges or reaches [`MAX_UNITS`]; returns the points and
/// whether it converged.
fn checkpoints(
    mut step: impl FnMut(u32) -> Outcome,
    mut measure: impl FnMut(u64) -> Result<DevicePoint, BenchError>,
) -> Result<(Vec<DevicePoint>, bool), BenchError> {
    let (mut units, mut target, mut points) = (0u64, FIRST_UNITS as f64, Vec::new());
    while units < MAX_UNITS {
        let budget = (target.round() as u64).saturating_sub(units).clamp(1, u64::from(u32::MAX)) as u32;
        let outcome = step(budget);
        units += u64::from(outcome.used());
        match outcome {
            Outcome::NoProgress { reason: NoProgressReason::BudgetTooSmall { needed }, .. } => {
                target = (units + u64::from(needed)) as f64;
                continue;
            }
            Outcome::NoProgress { reason, .. } => {
                return Err(BenchError::Solver(format!("device curve: no progress ({reason:?})")));
            }
            Outcome::Converged { .. } => {
                points.push(measure(units)?);
                return Ok((points, true));
            }
            Outcome::BudgetSpent { .. } => points.push(measure(units)?),
        }
        target = (target * RATIO).max(units as f64 + 1.0);
    }
    Ok((points, false))
}

/// The two curves on the scene at `path` (loaded as `scene`), judged per face against `reference`.
///
/// # Errors
/// Preparing, baking or solving either table, or a solver that makes no progress.
pub(super) fn curves(
    options: &BenchOptions,
    path: &std::path::Path,
    scene: &Scene,
    reference: &ContinuousReference,
    want: &[Option<Rgb>],
    judged: &[usize],
) -> Result<Vec<DeviceCurve>, BenchError> {
    Ok(vec![
        flat(options, path, reference, want, judged)?,
        hierarchical(options, scene, reference, want, judged)?,
    ])
}

fn flat(
    options: &BenchOptions,
    path: &std::path::Path,
    reference: &ContinuousReference,
    want: &[Option<Rgb>],
    judged: &[usize],
) -> Result<DeviceCurve, BenchError> {
    log(options, &format!("device curves: flat table within {FLAT_PATCHES} patches"));
    let p = prepare(
        path,
        &PrepareOptions { max_patches: Some(FLAT_PATCHES), ..PrepareOptions::quiet(false, 16, 16) },
    )?;
    let l = &p.lighting;
    let baked =
        bake(&BakeInput::from_scene(&p.scene, &p.patches, l, &p.form_factors), &BakeOptions::default())?;
    let exact = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len()))?
        .relight(&l.default_intensity)?;
    let table = Table::parse(&baked.table).map_err(|e| BenchError::Solver(format!("flat table: {e:?}")))?;
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let e: Vec<Rgb> = l.default_emission();
    let floor = radiosity_core::convergence_floor::<f32>(&table);
    let tolerance = ((TOLERANCE * emitted(&p.patches, &e)) as f32).max(floor);
    let mut owned = Owned::<f32>::new(&table);
    let (buffers, _) = owned.split();
    let mut solver = Solver::new(&table, buffers, Config { tolerance, overshoot: 0 })
        .map_err(|e| BenchError::Solver(format!("flat table: {e}")))?;
    let build = "m4-f32";
    let model = CostModel::PerUnit(bound_per_unit(COST_MD, build)?);
    let solver = std::cell::RefCell::new(&mut solver);
    let (points, converged) = checkpoints(
        |budget| solver.borrow_mut().step(budget),
        |units| {
            let b = radiosity(&solver.borrow(), &table);
            Ok(DevicePoint {
                units,
                work: None,
                instructions: model.instructions(units, None),
                own: metrics::compare(&b, &exact, &area)?.rel_l2,
                faces: face_errors(&face_means(&p.patches, &b, reference), want, judged),
            })
        },
    )?;
    let input = BakeInput::from_scene(&p.scene, &p.patches, l, &p.form_factors);
    let evaluation =
        evaluate(&input, &baked, &EvaluateOptions::for_bake(p.patches.len(), &BakeOptions::default()))
            .map_err(|e| BenchError::Solver(format!("flat table: {e}")))?;
    let quantization = evaluation
        .components
        .iter()
        .find(|c| c.name == QUANTIZATION)
        .map(|c| c.error.rel_l2)
        .ok_or_else(|| BenchError::Solver("flat table: no quantization component".to_owned()))?;
    Ok(DeviceCurve {
        quantization,
        name: format!("flat ({} patches)", p.patches.len()),
        elements: p.patches.len(),
        bytes: baked.table.len(),
        build: build.to_owned(),
        model,
        converged,
        points,
    })
}

fn hierarchical(
    options: &BenchOptions,
    scene: &Scene,
    reference: &ContinuousReference,
    want: &[Option<Rgb>],
    judged: &[usize],
) -> Result<DeviceCurve, BenchError> {
    log(options, &format!("device curves: hierarchical table at epsilon {HIER_EPSILON}"));
    let sol = solve_hierarchical(
        scene,
        &HierarchyOptions {
            epsilon: HIER_EPSILON,
            refinement: Refinement::Brightness,
            form_factors: FormFactorOptions { progress: false, ..FormFactorOptions::default() },
            ..HierarchyOptions::default()
        },
    )
    .map_err(|e| BenchError::Options(format!("hierarchical solve at epsilon {HIER_EPSILON}: {e}")))?;
    let baked = bake_hierarchy(scene, &sol, 16, false)?;
    let table = HierTable::parse(&baked.table)
        .map_err(|e| BenchError::Solver(format!("hierarchical table: {e:?}")))?;
    let leaves: Vec<Patch> = baked.solution_leaf.iter().map(|&k| sol.leaves[k].clone()).collect();
    let e: Vec<Rgb> = baked.solution_leaf.iter().map(|&k| sol.emission[k]).collect();
    let area: Vec<f64> = leaves.iter().map(|q| q.area).collect();
    let floor = hier_convergence_floor::<f32>(&table);
    let tolerance = ((TOLERANCE * emitted(&leaves, &e)) as f32).max(floor);
    let mut buffers = HierOwnedBuffers::<f32>::for_table(&table);
    let mut solver = HierSolver::new(&table, buffers.buffers(), Config { tolerance, overshoot: 0 })
        .map_err(|e| BenchError::Solver(format!("hierarchical table: {e}")))?;
    let build = "cornell-hier-m4-f32";
    let model = CostModel::Rates(rate_bound(COST_MD, build)?);
    let mut out = vec![[0.0f32; 3]; leaves.len()];
    let solver = std::cell::RefCell::new(&mut solver);
    let (points, converged) = checkpoints(
        |budget| solver.borrow_mut().step(budget),
        |units| {
            solver.borrow().radiosity_into(&mut out);
            let b: Vec<Rgb> = out.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
            let s = solver.borrow();
            let work = Some(HierWork { links: s.links(), judged: s.judged(), shots: u64::from(s.shots()) });
            Ok(DevicePoint {
                units,
                work,
                instructions: model.instructions(units, work),
                own: metrics::compare(&b, &baked.radiosity, &area)?.rel_l2,
                faces: face_errors(&face_means(&leaves, &b, reference), want, judged),
            })
        },
    )?;
    let quantization =
        metrics::compare(&baked.decoded_radiosity(&sol.network)?, &baked.radiosity, &area)?.rel_l2;
    Ok(DeviceCurve {
        quantization,
        name: format!("hierarchical ({} leaves, epsilon {HIER_EPSILON})", leaves.len()),
        elements: leaves.len(),
        bytes: baked.table.len(),
        build: build.to_owned(),
        model,
        converged,
        points,
    })
}
