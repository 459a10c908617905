//! Device curves: core's solver (shooting, Gauss-Seidel, Jacobi; f32 and fixed point) run on a baked table, with
//! the error against the exact f64 answer recorded at geometrically spaced amounts of work.
//!
//! A curve is run once with errors measured at every checkpoint (outside the timer), which also decides where it
//! stops; the further repetitions replay the same budgets and only record the time, so the wall time of every
//! point is the median over all repetitions of exactly the same computation.

use std::time::Instant;

use radiosity_core::{Buffers, Config, NoProgressReason, Outcome, OwnedBuffers, Scalar, Solver, Table};

use super::BenchError;
use crate::metrics;
use crate::rgb::Rgb;

/// Which core step a curve uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Progressive-refinement shooting ([`Solver::step`]) with this overshoot (`Config::overshoot`, 256ths).
    Shooting(u8),
    /// Gauss-Seidel sweeps ([`Solver::step_gauss_seidel`]).
    GaussSeidel,
    /// Jacobi sweeps ([`Solver::step_jacobi`]).
    Jacobi,
}

/// How the solver state starts before the curve's first step.
#[derive(Clone, Debug, PartialEq)]
pub enum Start {
    /// Cold start at the table's default intensities.
    Cold,
    /// Converged at the default intensities (untimed), then every group set to `intensity` with
    /// [`Solver::set_light`]; the change's work units and time count as the curve's first work.
    Warm(Vec<[f32; 3]>),
    /// Every group set to `intensity`, then [`Solver::restart`]: a cold solve of the new setting.
    ColdAt(Vec<[f32; 3]>),
}

/// One checkpoint of a curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Work units spent so far (steps, plus a light change for warm starts).
    pub work: u64,
    /// Wall time of the steps so far (seconds): the median over the repetitions.
    pub seconds: f64,
    /// Area-weighted relative L2 error against the exact answer.
    pub rel_l2: f64,
    /// Max per-patch relative error against the exact answer.
    pub max_rel: f64,
}

/// A baked table with what a device run needs around it.
pub struct DeviceCase<'a> {
    /// The parsed table.
    pub table: &'a Table<'a>,
    /// Patch areas (scene's, f64) for the metrics.
    pub area: &'a [f64],
    /// Solver tolerance in power units (converged = every unshot magnitude below it).
    pub tolerance: f64,
}

/// When a curve stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    /// First checkpoint's work units.
    pub first: u64,
    /// Ratio between successive checkpoints' work.
    pub ratio: f64,
    /// Stop once the relative L2 error is at or below this.
    pub error: f64,
    /// Stop once this much work is spent.
    pub max_work: u64,
    /// Stop when the error has improved by less than 5% over this many checkpoints (an error floor)...
    pub plateau: usize,
    /// ... once at least this much work is spent (before, a slow start such as building the selection or a first sweep
    /// is not a floor).
    pub plateau_after: u64,
}

/// Solver buffers for a table (core's [`OwnedBuffers`]) plus Jacobi's scratch buffer.
pub struct Owned<S> {
    buffers: OwnedBuffers<S>,
    /// Jacobi's scratch buffer (one element per slot).
    pub scratch: Vec<[S; 3]>,
}

impl<S: Scalar> Owned<S> {
    /// Zeroed buffers of the sizes `table` needs ([`radiosity_core::BufferSizes::of`]).
    #[must_use]
    pub fn new(table: &Table<'_>) -> Self {
        let sizes = radiosity_core::BufferSizes::of(table);
        Owned { buffers: OwnedBuffers::new(sizes), scratch: vec![[S::from_f32(0.0); 3]; sizes.slots] }
    }

    /// The buffers, borrowed for a solver (the scratch buffer stays separate).
    pub fn split(&mut self) -> (Buffers<'_, S>, &mut [[S; 3]]) {
        (self.buffers.buffers(), &mut self.scratch)
    }
}

/// Radiosity of every patch, in f64.
pub fn radiosity<S: Scalar>(solver: &Solver<'_, S>, table: &Table<'_>) -> Vec<Rgb> {
    (0..table.patch_count())
        .map(|i| solver.radiosity(i).map_or(Rgb::NAN, |b| Rgb::from_array(b.map(|v| f64::from(v.to_f32())))))
        .collect()
}

fn solver_err(what: &'static str) -> impl Fn(radiosity_core::SolverError) -> BenchError {
    move |e| BenchError::Solver(format!("{what}: {e}"))
}

/// The firmware's light change ([`firmware_sim::device::apply_intensities`]): sets the groups whose intensity
/// differs; returns the units it cost.
fn apply_intensities<S: Scalar>(
    solver: &mut Solver<'_, S>,
    intensity: &[[f32; 3]],
) -> Result<u32, BenchError> {
    firmware_sim::device::apply_intensities(solver, intensity, None)
        .map_err(|e| BenchError::Solver(format!("set_light: {e}")))
}

/// One step of `step` for at most `budget` units.
pub fn do_step<S: Scalar>(
    solver: &mut Solver<'_, S>,
    step: Step,
    scratch: &mut [[S; 3]],
    budget: u32,
) -> Outcome {
    match step {
        Step::Shooting(_) => solver.step(budget),
        Step::GaussSeidel => solver.step_gauss_seidel(budget),
        Step::Jacobi => solver.step_jacobi(scratch, budget),
    }
}

/// Runs one curve `reps` times (at least once) against `exact`; see the module docs.
///
/// # Errors
/// A solver error (bad light change) or a metric error (non-finite answer).
pub fn run_curve<S: Scalar>(
    case: &DeviceCase<'_>,
    step: Step,
    start: &Start,
    exact: &[Rgb],
    stop: &StopRule,
    reps: usize,
) -> Result<Vec<Point>, BenchError> {
    let table = case.table;
    let overshoot = match step {
        Step::Shooting(o) => o,
        _ => 0,
    };
    // At least the arithmetic's convergence floor (fixed point at rho = 0.99 cannot reach 1e-6 of the power).
    let floor = radiosity_core::convergence_floor::<S>(table);
    let tolerance = S::from_f32(case.tolerance as f32);
    let config = Config { tolerance: if tolerance < floor { floor } else { tolerance }, overshoot };
    let mut budgets: Vec<(u32, bool)> = Vec::new();
    let mut points: Vec<Point> = Vec::new();
    let mut times: Vec<Vec<f64>> = Vec::new();
    for rep in 0..reps.max(1) {
        let mut owned = Owned::<S>::new(table);
        let (buffers, scratch) = owned.split();
        let mut solver = Solver::new(table, buffers, config).map_err(solver_err("creating the solver"))?;
        let mut work = 0u64;
        let mut seconds = 0.0;
        match start {
            Start::Cold => {}
            Start::Warm(intensity) => {
                while let Outcome::BudgetSpent { .. } = solver.step(u32::MAX) {}
                let t0 = Instant::now();
                work += u64::from(apply_intensities(&mut solver, intensity)?);
                seconds += t0.elapsed().as_secs_f64();
            }
            Start::ColdAt(intensity) => {
                apply_intensities(&mut solver, intensity)?;
                solver.restart();
            }
        }
        let mut rep_times = Vec::new();
        if rep == 0 {
            // Discover the schedule: checkpoints at geometrically growing work, errors measured untimed.
            let mut target = stop.first.max(work + 1) as f64;
            loop {
                let budget =
                    (target.round() as u64).saturating_sub(work).clamp(1, u64::from(u32::MAX)) as u32;
                let t0 = Instant::now();
                let o = do_step(&mut solver, step, scratch, budget);
                seconds += t0.elapsed().as_secs_f64();
                work += u64::from(o.used());
                if let Outcome::NoProgress { reason: NoProgressReason::BudgetTooSmall { needed }, .. } = o {
                    // Below the smallest action (e.g. right after a light change): not a checkpoint; retry with
                    // what the step asked for.
                    budgets.push((budget, false));
                    target = (work + u64::from(needed)) as f64;
                    continue;
                }
                budgets.push((budget, true));
                let b = radiosity(&solver, table);
                let e = metrics::compare(&b, exact, case.area)?;
                points.push(Point { work, seconds, rel_l2: e.rel_l2, max_rel: e.max_rel });
                rep_times.push(seconds);
                let k = points.len();
                let plateau = k > stop.plateau
                    && work >= stop.plateau_after
                    && points[k - 1].rel_l2 >= 0.95 * points[k - 1 - stop.plateau].rel_l2;
                if !matches!(o, Outcome::BudgetSpent { .. })
                    || e.rel_l2 <= stop.error
                    || work >= stop.max_work
                    || plateau
                {
                    break;
                }
                target = (target * stop.ratio).max(work as f64 + 1.0);
            }
        } else {
            for &(budget, checkpoint) in &budgets {
                let t0 = Instant::now();
                let o = do_step(&mut solver, step, scratch, budget);
                seconds += t0.elapsed().as_secs_f64();
                work += u64::from(o.used());
                if checkpoint {
                    rep_times.push(seconds);
                }
            }
            // The replay must be the same computation; a mismatch would be a determinism bug in core.
            if points.last().map(|p| p.work) != Some(work) {
                return Err(BenchError::Solver(format!(
                    "repetition {rep} of a {step:?} curve spent {work} work units, the first spent {:?}",
                    points.last().map(|p| p.work)
                )));
            }
        }
        times.push(rep_times);
    }
    for (k, p) in points.iter_mut().enumerate() {
        let mut ts: Vec<f64> = times.iter().map(|t| t[k]).collect();
        p.seconds = median(&mut ts);
    }
    Ok(points)
}

/// Median of `v` (mean of the middle two for even lengths); NaN for an empty slice.
#[must_use]
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}
