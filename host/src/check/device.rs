//! The device part of a check: the solver run on the table exactly as the firmware runs it, frame by frame.

use firmware_sim::device::{self, DeviceSolver, RunError};
use firmware_sim::sim::Arith;
use radiosity_core::{
    hier_convergence_floor, Config, Fixed, HierOwnedBuffers, HierSolver, HierTable, Outcome, OwnedBuffers,
    Scalar, Solver, SolverError, Table,
};

use super::{CheckError, CheckOptions, CheckReport, Frame, Setting, MAX_FRAMES};
use crate::evaluate::{Component, EvaluateError, ITERATION_TRUNCATION};
use crate::metrics;
use crate::reference::{Radiosity, TransferVectors};
use crate::rgb::Rgb;

/// The answers the device is compared with.
pub(super) struct Answers<'a> {
    /// The exact transfer vectors (every frame is compared with them, relit), in the table's element order.
    pub(super) exact: &'a TransferVectors,
    /// What they are the answer of, for the report (e.g. "scene matrix, transfer vectors relit").
    pub(super) exact_is: &'a str,
    /// The scene's default intensities (the first light setting).
    pub(super) default_intensity: &'a [Rgb],
    /// The largest per-channel power the elements emit at the default intensities (the decoded table's for a flat
    /// check, the solve's for a hierarchical one): what [`CheckOptions::tolerance`] is relative to.
    pub(super) max_power: f64,
    /// The decoded table's f64 answer (what the device converges to).
    pub(super) device: &'a Radiosity,
    /// Element areas (patches or leaves, table order).
    pub(super) area: &'a [f64],
    /// Names of the dynamic light groups, in table order.
    pub(super) light_groups: &'a [String],
}

/// The factor over fixed point's convergence floor a raised (or suggested) tolerance gets.
const FLOOR_MARGIN: f64 = 1.01;

/// The table a check runs the device on: flat (format version 3) or hierarchical (version 5).
#[derive(Clone, Copy)]
pub(super) enum DeviceTable<'t> {
    /// Core's [`Solver`] on a flat table.
    Flat(&'t Table<'t>),
    /// Core's [`HierSolver`] on a hierarchical table.
    Hier(&'t HierTable<'t>),
}

impl DeviceTable<'_> {
    /// Runs `f` on a new solver of arithmetic `S` for the table (cold start), in buffers sized for it.
    fn with_solver<S: Scalar, R>(
        self,
        config: Config<S>,
        f: impl FnOnce(&mut dyn DeviceSolver<Scalar = S>) -> Result<R, CheckError>,
        err: impl Fn(SolverError) -> CheckError,
    ) -> Result<R, CheckError> {
        match self {
            DeviceTable::Flat(table) => {
                let mut store = OwnedBuffers::<S>::for_table(table);
                f(&mut Solver::new(table, store.buffers(), config).map_err(err)?)
            }
            DeviceTable::Hier(table) => {
                let mut store = HierOwnedBuffers::<S>::for_table(table);
                f(&mut HierSolver::new(table, store.buffers(), config).map_err(err)?)
            }
        }
    }

    /// The smallest tolerance (power units) fixed point converges to on this table (core's
    /// `convergence_floor`, `hier_convergence_floor`).
    fn fixed_floor(self) -> f64 {
        match self {
            DeviceTable::Flat(table) => f64::from(radiosity_core::convergence_floor::<Fixed>(table).to_f32()),
            DeviceTable::Hier(table) => f64::from(hier_convergence_floor::<Fixed>(table).to_f32()),
        }
    }

    /// Table entries: the flat table's stored form factors, or the hierarchical table's links.
    fn entries(self) -> usize {
        match self {
            DeviceTable::Flat(table) => table.entry_count() as usize,
            DeviceTable::Hier(table) => table.link_count() as usize,
        }
    }

    /// The form-factor codec's name.
    fn codec(self) -> String {
        match self {
            DeviceTable::Flat(table) => table.codec().to_string(),
            DeviceTable::Hier(table) => table.codec().to_string(),
        }
    }
}

/// Runs the device paths on `table` and finishes the report (iteration truncation and arithmetic components
/// after `components`): every light setting on every path, each frame compared with the exact answer relit,
/// the converged answer of each path compared with the decoded table's f64 answer.
pub(super) fn device_part(
    table: DeviceTable<'_>,
    table_bytes: usize,
    answers: &Answers<'_>,
    options: &CheckOptions,
    mut components: Vec<Component>,
) -> Result<CheckReport, CheckError> {
    let (max_power, area) = (answers.max_power, answers.area);
    let mut tolerance = options.tolerance * max_power;
    let mut tolerance_raised = false;
    let default = answers.default_intensity.to_vec();
    let groups = default.len();
    let mut schedule = vec![default.clone()];
    if options.relight {
        schedule.push(vec![Rgb::ZERO; groups]);
        schedule.push(default.clone());
        schedule.push(default.iter().map(|&d| d * Rgb::new(1.0, 0.2, 0.2)).collect());
    }
    let exact: Vec<Vec<Rgb>> = schedule
        .iter()
        .map(|s| answers.exact.relight(s))
        .collect::<Result<_, _>>()
        .map_err(|source| EvaluateError::Reference { what: "exact transfer relight", source })?;
    let run = Run { table, area, schedule: &schedule, exact: &exact, options };
    let mut settings = Vec::new();
    let mut frames = Vec::new();
    if options.arith.contains(&Arith::Fixed) {
        let floor = table.fixed_floor();
        if tolerance < floor && options.tolerance_floor {
            // A margin over the floor, so that its rounding to the solver's scalar stays above it.
            tolerance = floor * FLOOR_MARGIN;
            tolerance_raised = true;
        } else if tolerance < floor {
            return Err(CheckError::Options(format!(
                "--tolerance {} ({tolerance:.3e} power units) is below fixed point's convergence floor for this \
                 table ({floor:.3e} power units: Q32.32 rounds every receipt, see core's `convergence_floor`); use \
                 --tolerance {:.1e} or more, or --arith f32",
                options.tolerance,
                (floor / max_power * FLOOR_MARGIN).max(f64::MIN_POSITIVE)
            )));
        }
    }
    for &arith in &options.arith {
        let (converged, truncated) = match arith {
            Arith::F32 => run.device::<f32>(arith, tolerance, &mut settings, &mut frames)?,
            Arith::Fixed => run.device::<Fixed>(arith, tolerance, &mut settings, &mut frames)?,
        };
        if arith == Arith::F32 {
            components.push(Component {
                name: ITERATION_TRUNCATION.into(),
                compares: match options.frames {
                    Some(f) => format!(
                        "f32 after {f} frames of {} units vs f32 converged, same table",
                        options.budget
                    ),
                    None => {
                        "f32 run to convergence in frames vs f32 converged in one step, same table".into()
                    }
                },
                error: metrics::compare(&truncated, &converged, area)?,
            });
        }
        components.push(Component {
            name: format!("arithmetic ({arith})"),
            compares: format!("{arith} converged vs f64 solve of the decoded table"),
            error: metrics::compare(&converged, answers.device, area)?,
        });
    }
    Ok(CheckReport {
        method: match table {
            DeviceTable::Flat(_) => "flat",
            DeviceTable::Hier(_) => "hierarchical",
        }
        .into(),
        exact: answers.exact_is.into(),
        patches: area.len(),
        entries: table.entries(),
        table_bytes,
        codec: table.codec(),
        light_groups: answers.light_groups.to_vec(),
        budget: options.budget,
        frames_per_setting: options.frames,
        tolerance,
        tolerance_raised,
        components,
        quantization_parts: Vec::new(),
        settings,
        frames,
        discretization: None,
    })
}

/// Converged device radiosity of `table` from a cold start at its default intensities, on arithmetic `S`, with
/// solver tolerance `tolerance` (power units, [`Config::tolerance`]); `None` with the reason if the solver
/// stops without converging ([`Outcome::NoProgress`], e.g. a saturated fixed-point value).
///
/// # Errors
/// [`CheckError::Solver`] if the solver rejects the table.
pub fn device_converged<S: Scalar>(
    table: &Table<'_>,
    tolerance: f64,
) -> Result<Result<Radiosity, radiosity_core::NoProgressReason>, CheckError> {
    let mut store = OwnedBuffers::<S>::for_table(table);
    let buffers = store.buffers();
    let config =
        Config { tolerance: S::from_f32(tolerance as f32), overshoot: Config::<S>::RECOMMENDED_OVERSHOOT };
    let mut solver =
        Solver::new(table, buffers, config).map_err(|error| CheckError::Solver { arith: "device", error })?;
    loop {
        match solver.step(u32::MAX) {
            Outcome::BudgetSpent { .. } => {}
            Outcome::Converged { .. } => return Ok(Ok(elements(&solver))),
            Outcome::NoProgress { reason, .. } => return Ok(Err(reason)),
        }
    }
}

struct Run<'r> {
    table: DeviceTable<'r>,
    area: &'r [f64],
    schedule: &'r [Vec<Rgb>],
    exact: &'r [Vec<Rgb>],
    options: &'r CheckOptions,
}

/// The radiosity of every element the device shows (patches or leaves, table order).
fn elements<S: Scalar>(solver: &dyn DeviceSolver<Scalar = S>) -> Vec<Rgb> {
    (0..solver.element_count())
        .map(|i| {
            solver
                .element_radiosity(i)
                .map_or(Rgb::NAN, |b| Rgb::from_array(b.map(|v| f64::from(v.to_f32()))))
        })
        .collect()
}

fn outcome_name(o: Outcome) -> String {
    match o {
        Outcome::Converged { .. } => "converged".into(),
        Outcome::BudgetSpent { .. } => "budget".into(),
        Outcome::NoProgress { reason, .. } => format!("no progress: {reason:?}"),
    }
}

impl Run<'_> {
    /// Runs every light setting on arithmetic `S`; returns (converged answer at default lighting from a cold
    /// solve, answer after the first setting's frames).
    fn device<S: Scalar>(
        &self,
        arith: Arith,
        tolerance: f64,
        settings: &mut Vec<Setting>,
        frames: &mut Vec<Frame>,
    ) -> Result<(Radiosity, Radiosity), CheckError> {
        let table = self.table;
        let err = |error| CheckError::Solver { arith: arith.name(), error };
        let config = Config {
            tolerance: S::from_f32(tolerance as f32),
            overshoot: Config::<S>::RECOMMENDED_OVERSHOOT,
        };

        // Converged reference of this arithmetic: one unbounded step sequence, cold start.
        let converged = table.with_solver(
            config,
            |solver| {
                while let Outcome::BudgetSpent { .. } = solver.step(u32::MAX) {}
                Ok(elements(solver))
            },
            err,
        )?;
        let truncated =
            table.with_solver(config, |solver| self.settings(solver, arith, settings, frames), err)?;
        Ok((converged, truncated))
    }

    /// The light settings in order on `solver` (cold), frame by frame as the firmware runs them; returns the
    /// answer after the first setting's frames.
    fn settings<S: Scalar>(
        &self,
        solver: &mut dyn DeviceSolver<Scalar = S>,
        arith: Arith,
        settings: &mut Vec<Setting>,
        frames: &mut Vec<Frame>,
    ) -> Result<Radiosity, CheckError> {
        let err = |error| CheckError::Solver { arith: arith.name(), error };
        let mut truncated = Vec::new();
        for (s, (intensity, exact)) in self.schedule.iter().zip(self.exact).enumerate() {
            // The firmware's frame loop: groups whose intensity changed are set, then one bounded step.
            let intensity_f32: Vec<[f32; 3]> = intensity.iter().map(|rgb| rgb.as_vec3().to_array()).collect();
            let mut relight_work = 0u64;
            let limit = self.options.frames.unwrap_or(MAX_FRAMES);
            let (mut work, mut count, mut converged_now) = (0u64, 0usize, false);
            let mut last = None;
            while count < limit {
                let frame = device::Frame { budget: self.options.budget, intensity: &intensity_f32 };
                let (light_units, o) =
                    device::run_frame(solver, &frame, count as u32).map_err(|e| match e {
                        RunError::Solver { error, .. } | RunError::Buffers { error } => err(error),
                        other => CheckError::Options(other.to_string()),
                    })?;
                relight_work += u64::from(light_units);
                count += 1;
                work += u64::from(o.used());
                let b = elements(solver);
                let e = metrics::compare(&b, exact, self.area)?;
                frames.push(Frame {
                    arith,
                    setting: s,
                    frame: count,
                    work: o.used(),
                    work_total: work,
                    outcome: outcome_name(o),
                    rel_l2: e.rel_l2,
                    max_rel: e.max_rel,
                    luminance_rel_l2: e.luminance_rel_l2,
                });
                last = Some((b, e));
                converged_now = matches!(o, Outcome::Converged { .. });
                if self.options.frames.is_none() && !matches!(o, Outcome::BudgetSpent { .. }) {
                    break;
                }
            }
            let Some((b, error)) = last else {
                return Err(CheckError::Options("--frames must be at least 1".into()));
            };
            if s == 0 {
                truncated = b;
            }
            settings.push(Setting {
                arith,
                setting: s,
                intensity: intensity.clone(),
                relight_work,
                frames: count,
                work,
                converged: converged_now,
                error,
            });
        }
        Ok(truncated)
    }
}
