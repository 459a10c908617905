//! `radiosity check`: run the device solver on a baked table and trace its error to its sources.
//!
//! The device path is run exactly as firmware runs it: [`radiosity_core::Table::parse`] on the baked bytes,
//! [`radiosity_core::Solver`] in buffers of the baked [`Capacities`], [`radiosity_core::Solver::step`] (shooting)
//! with a fixed budget of work units per frame, and [`radiosity_core::Solver::set_light`] for relighting (warm
//! start). Every frame's radiosity is compared with the exact f64 answer for that frame's light intensities:
//! the transfer vectors of the scene's own (unsparsified, unquantized) form-factor matrix, relit
//! (`B = B_static + sum_g I_g T_g`). Metrics are [`metrics::compare`] (area-weighted relative L2, max per-patch
//! relative error with its dark-patch floor, luminance).
//!
//! # Error decomposition
//! Each component compares two answers that differ in one step only, all at the scene's default intensities:
//!
//! | component | answer | against |
//! |---|---|---|
//! | form-factor estimation | f64 solve, matrix at the chosen samples/rays | f64 solve, matrix at `ff_factor` times both |
//! | sparsification | f64 solve, shooting form of the sparsified matrix | f64 solve, shooting form of the full matrix |
//! | quantization | f64 solve of the decoded table (decoded form factors, reflectances, emission, f32 areas) | the sparsified f64 solve above |
//! | iteration truncation | device (f32) after `frames` frames of `budget` units, cold start | device (f32) converged, same table |
//! | arithmetic (f32, fixed) | device converged | f64 solve of the decoded table |
//!
//! The shooting form (`F~_ij = A_j F_ji / A_i`, [`bake::shooting_form`]) is what shooting with stored rows
//! converges to, so the sparsification and quantization components use it on both sides. The arithmetic
//! component also holds the quantization of the static irradiance the bake stores (emission code, `2^-11`
//! relative) and the solver's stopping tolerance. "Converged" means [`radiosity_core::Outcome::Converged`] at
//! the tolerance [`CheckOptions::tolerance`] times the largest per-channel emitted power.

use std::fmt;
use std::path::Path;

use radiosity_core::{Buffers, Config, Fixed, Outcome, Scalar, Solver, Table};
use serde::Serialize;
use thiserror::Error;

use crate::bake::{self, bake, codec_for_bits, BakeInput, BakeOptions, Capacities};
use crate::formfactor::compute_form_factors;
use crate::metrics::{self, ErrorReport};
use crate::patch::FormFactorMatrix;
use crate::pipeline::{prepare, PrepareOptions, Prepared};
use crate::reference::{solve_many, transfer_vectors, LightGroupEmission, Method, RadiositySystem};

/// Arithmetic paths of the device solver to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Arith {
    /// `f32` (FPU devices).
    F32,
    /// Q32.32 fixed point (FPU-less devices).
    Fixed,
    /// Both.
    Both,
}

/// Settings of a check.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckOptions {
    /// Form-factor code width, 16 or 8 ([`codec_for_bits`]).
    pub bits: u32,
    /// Sparsification threshold ([`BakeOptions::threshold`]).
    pub threshold: f64,
    /// Work units per frame.
    pub budget: u32,
    /// Frames per light setting; `None` runs each setting to convergence (at most [`MAX_FRAMES`] frames).
    pub frames: Option<usize>,
    /// Arithmetic paths.
    pub arith: Arith,
    /// After the default lighting, relight: all dynamic groups to 0, back to default, then to the colour
    /// `(1, 0.2, 0.2)` times default.
    pub relight: bool,
    /// Solver tolerance as a fraction of the largest per-channel emitted power `sum_i E_i A_i`.
    pub tolerance: f64,
    /// The form-factor estimation component's reference uses this many times the samples and the rays.
    pub ff_factor: usize,
    /// Slack on row sums of the shooting form above 1 in the f64 solves ([`BakeOptions::row_sum_tolerance`]).
    pub row_sum_tolerance: f64,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            bits: 16,
            threshold: bake::DEFAULT_THRESHOLD,
            budget: 20_000,
            frames: None,
            arith: Arith::Both,
            relight: false,
            tolerance: 1e-6,
            ff_factor: 4,
            row_sum_tolerance: bake::DEFAULT_ROW_SUM_TOLERANCE,
        }
    }
}

/// Most frames per light setting when running to convergence.
pub const MAX_FRAMES: usize = 100_000;

/// Why a check failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CheckError {
    /// Loading, meshing or form factors failed.
    #[error(transparent)]
    Pipeline(#[from] crate::pipeline::PipelineError),
    /// The bake failed.
    #[error(transparent)]
    Bake(#[from] bake::BakeError),
    /// An f64 solve failed.
    #[error(transparent)]
    Reference(#[from] crate::reference::ReferenceError),
    /// A metric could not be computed (e.g. a non-finite device answer).
    #[error(transparent)]
    Metrics(#[from] metrics::MetricsError),
    /// The form-factor computation of the reference matrix failed.
    #[error("reference form factors ({0}x samples and rays): {1}")]
    FormFactors(usize, String),
    /// The baked table does not parse (a bug in the writer).
    #[error("baked table does not parse: {0:?}")]
    Table(radiosity_core::TableError),
    /// The device solver rejected the table or a light change.
    #[error("device solver ({arith}): {error:?}")]
    Solver {
        /// Arithmetic path.
        arith: &'static str,
        /// Core's error.
        error: radiosity_core::SolverError,
    },
    /// Bad options.
    #[error("bad option: {0}")]
    Options(String),
}

/// One component of the error decomposition.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Component {
    /// Name (`form-factor estimation`, `sparsification`, ...).
    pub name: String,
    /// What is compared with what.
    pub compares: String,
    /// The error.
    pub error: ErrorReport,
}

/// One device frame compared with the exact answer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// Arithmetic path (`f32` or `fixed`).
    pub arith: &'static str,
    /// Light setting (0 = default, then the relight sequence).
    pub setting: usize,
    /// Frame within the setting (from 1).
    pub frame: usize,
    /// Work units this frame.
    pub work: u32,
    /// Work units since the setting began (light-change cost excluded; see `relight_work`).
    pub work_total: u64,
    /// Outcome of the frame's step: `converged`, `budget`, or `no progress: REASON`.
    pub outcome: String,
    /// Relative L2 error against the exact answer.
    pub rel_l2: f64,
    /// Max per-patch relative error against the exact answer.
    pub max_rel: f64,
    /// Luminance relative L2 error against the exact answer.
    pub luminance_rel_l2: f64,
}

/// Summary of one light setting on one arithmetic path.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Setting {
    /// Arithmetic path.
    pub arith: &'static str,
    /// Index of the setting.
    pub setting: usize,
    /// Intensity of every dynamic group in this setting.
    pub intensity: Vec<[f64; 3]>,
    /// Work units [`Solver::set_light`] reported for the change (0 for the cold start).
    pub relight_work: u64,
    /// Frames run.
    pub frames: usize,
    /// Work units in the step budgets.
    pub work: u64,
    /// Whether the last frame converged.
    pub converged: bool,
    /// Error of the last frame against the exact answer.
    pub error: ErrorReport,
}

/// The result of a check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CheckReport {
    /// Patches.
    pub patches: usize,
    /// Table entries.
    pub entries: usize,
    /// Table bytes.
    pub table_bytes: usize,
    /// Codec name.
    pub codec: String,
    /// Work units per frame.
    pub budget: u32,
    /// Frames per setting (`None`: to convergence).
    pub frames_per_setting: Option<usize>,
    /// Solver tolerance in power units.
    pub tolerance: f64,
    /// The error decomposition.
    pub components: Vec<Component>,
    /// Every light setting on every arithmetic path.
    pub settings: Vec<Setting>,
    /// Every frame.
    pub frames: Vec<Frame>,
}

fn scale(v: [f64; 3], s: [f64; 3]) -> [f64; 3] {
    [v[0] * s[0], v[1] * s[1], v[2] * s[2]]
}

/// Prepares the scene at `path` and checks it (see [`check`]).
///
/// # Errors
/// See [`CheckError`].
pub fn check_scene(
    path: &Path,
    prepare_options: &PrepareOptions,
    options: &CheckOptions,
) -> Result<CheckReport, CheckError> {
    let p = prepare(path, prepare_options)?;
    check(&p, prepare_options, options)
}

/// Bakes a prepared scene, runs the device on it and decomposes the error (see the module docs).
///
/// `prepare_options` must be those `p` was prepared with: its form-factor options, scaled by
/// [`CheckOptions::ff_factor`], give the reference matrix of the form-factor component.
///
/// # Errors
/// See [`CheckError`].
pub fn check(
    p: &Prepared,
    prepare_options: &PrepareOptions,
    options: &CheckOptions,
) -> Result<CheckReport, CheckError> {
    if options.budget == 0 {
        return Err(CheckError::Options("--budget must be at least 1 work unit".into()));
    }
    if !(options.tolerance > 0.0 && options.tolerance < 1.0) {
        return Err(CheckError::Options(format!("tolerance {} not in (0, 1)", options.tolerance)));
    }
    let l = &p.lighting;
    let n = p.patches.len();
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let bake_options = BakeOptions {
        threshold: options.threshold,
        codec: codec_for_bits(options.bits)?,
        row_sum_tolerance: options.row_sum_tolerance,
        ..BakeOptions::default()
    };
    let baked = bake(&BakeInput::from_scene(&p.scene, &p.patches, l, &p.form_factors), &bake_options)?;
    let table = Table::parse(&baked.table).map_err(CheckError::Table)?;
    let method = Method::for_size(n);
    let e_default = l.default_emission();
    let solve =
        |rho: &[[f64; 3]], ff: &FormFactorMatrix, e: &[[f64; 3]]| -> Result<Vec<[f64; 3]>, CheckError> {
            let system = RadiositySystem::with_row_sum_tolerance(rho, ff, bake_options.row_sum_tolerance)?;
            let mut s = solve_many(system, &[e], &method)?;
            Ok(s.pop().map(|s| s.b).unwrap_or_default())
        };

    // Exact answer per light setting: transfer vectors of the scene's own matrix.
    let lights = LightGroupEmission {
        static_emission: &l.static_emission,
        unit_emission: &l.unit_emission,
        group: &l.group,
        group_count: l.dynamic_groups.len(),
    };
    let tv = transfer_vectors(RadiositySystem::new(&l.rho, &p.form_factors)?, &lights, &method)?;

    let mut components = Vec::new();
    // 1. Form-factor estimation.
    if options.ff_factor > 1 {
        let mut ffo = prepare_options.form_factors.clone();
        ffo.samples_per_patch *= options.ff_factor;
        ffo.rays_per_pair *= options.ff_factor;
        ffo.progress = false;
        let (mut hi, _) = compute_form_factors(&p.patches, &ffo)
            .map_err(|e| CheckError::FormFactors(options.ff_factor, e.to_string()))?;
        hi.clamp_rows_to_one();
        let b_lo = solve(&l.rho, &p.form_factors, &e_default)?;
        let b_hi = solve(&l.rho, &hi, &e_default)?;
        components.push(Component {
            name: "form-factor estimation".into(),
            compares: format!(
                "f64, matrix at {} samples/{} rays vs at {} samples/{} rays",
                prepare_options.form_factors.samples_per_patch,
                prepare_options.form_factors.rays_per_pair,
                ffo.samples_per_patch,
                ffo.rays_per_pair
            ),
            error: metrics::compare(&b_lo, &b_hi, &area)?,
        });
    }
    // 2. Sparsification.
    let b_full = solve(&l.rho, &bake::shooting_form(&p.form_factors, &area), &e_default)?;
    let b_sparse = solve(&l.rho, &bake::shooting_form(&baked.sparse.matrix, &area), &e_default)?;
    components.push(Component {
        name: "sparsification".into(),
        compares: format!("f64, sparsified (threshold {}) vs full matrix, shooting form", options.threshold),
        error: metrics::compare(&b_sparse, &b_full, &area)?,
    });
    // 3. Quantization.
    let dec = crate::bake::decode_table(&table);
    let b_dec = solve(&dec.rho, &bake::shooting_form(&dec.rows, &dec.area), &dec.emission)?;
    components.push(Component {
        name: "quantization".into(),
        compares: format!("f64, decoded {} table vs sparsified f64 matrix", bake::codec_name(table.codec())),
        error: metrics::compare(&b_dec, &b_sparse, &area)?,
    });

    // Device runs.
    let max_power = (0..3)
        .map(|c| dec.emission.iter().zip(&dec.area).map(|(e, a)| e[c] * a).sum::<f64>())
        .fold(0.0, f64::max);
    let tolerance = options.tolerance * max_power;
    let groups = l.dynamic_groups.len();
    let default = l.default_intensity.clone();
    let mut schedule = vec![default.clone()];
    if options.relight {
        schedule.push(vec![[0.0; 3]; groups]);
        schedule.push(default.clone());
        schedule.push(default.iter().map(|&d| scale(d, [1.0, 0.2, 0.2])).collect());
    }
    let exact: Vec<Vec<[f64; 3]>> = schedule.iter().map(|s| tv.relight(s)).collect::<Result<_, _>>()?;
    let run = Run {
        table: &table,
        caps: &baked.capacities,
        area: &area,
        schedule: &schedule,
        exact: &exact,
        options,
    };
    let mut settings = Vec::new();
    let mut frames = Vec::new();
    let paths: &[&'static str] = match options.arith {
        Arith::F32 => &["f32"],
        Arith::Fixed => &["fixed"],
        Arith::Both => &["f32", "fixed"],
    };
    for &path in paths {
        let (converged, truncated) = if path == "f32" {
            run.device::<f32>(path, tolerance, &mut settings, &mut frames)?
        } else {
            run.device::<Fixed>(path, tolerance, &mut settings, &mut frames)?
        };
        if path == "f32" {
            components.push(Component {
                name: "iteration truncation".into(),
                compares: match options.frames {
                    Some(f) => format!(
                        "f32 after {f} frames of {} units vs f32 converged, same table",
                        options.budget
                    ),
                    None => {
                        "f32 run to convergence in frames vs f32 converged in one step, same table".into()
                    }
                },
                error: metrics::compare(&truncated, &converged, &area)?,
            });
        }
        components.push(Component {
            name: format!("arithmetic ({path})"),
            compares: format!("{path} converged vs f64 solve of the decoded table"),
            error: metrics::compare(&converged, &b_dec, &area)?,
        });
    }
    Ok(CheckReport {
        patches: n,
        entries: table.entry_count() as usize,
        table_bytes: baked.table.len(),
        codec: bake::codec_name(table.codec()),
        budget: options.budget,
        frames_per_setting: options.frames,
        tolerance,
        components,
        settings,
        frames,
    })
}

/// Per-patch RGB radiosity.
type Radiosity = Vec<[f64; 3]>;

struct Run<'r> {
    table: &'r Table<'r>,
    caps: &'r Capacities,
    area: &'r [f64],
    schedule: &'r [Vec<[f64; 3]>],
    exact: &'r [Vec<[f64; 3]>],
    options: &'r CheckOptions,
}

fn radiosity<S: Scalar>(solver: &Solver<'_, S>, table: &Table<'_>, n: usize) -> Vec<[f64; 3]> {
    (0..n as u32)
        .map(|i| {
            solver.radiosity(table, i).map(|b| b.map(|v| f64::from(v.to_f32()))).unwrap_or([f64::NAN; 3])
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
        arith: &'static str,
        tolerance: f64,
        settings: &mut Vec<Setting>,
        frames: &mut Vec<Frame>,
    ) -> Result<(Radiosity, Radiosity), CheckError> {
        let (table, caps, n) = (self.table, self.caps, self.area.len());
        let err = |error| CheckError::Solver { arith, error };
        let zero = S::from_f32(0.0);
        let new_buffers = || {
            (
                vec![[zero; 3]; caps.power],
                vec![[zero; 3]; caps.unshot],
                vec![[zero; 3]; caps.incident],
                vec![0u32; caps.tree],
                vec![[zero; 3]; caps.intensity],
                vec![[0u16; 3]; caps.reflectance],
            )
        };
        let config = Config { tolerance: S::from_f32(tolerance as f32), overshoot: 0 };

        // Converged reference of this arithmetic: one unbounded step sequence, cold start.
        let converged = {
            let (mut p, mut u, mut h, mut t, mut i, mut r) = new_buffers();
            let buffers = Buffers {
                power: &mut p,
                unshot: &mut u,
                incident: &mut h,
                tree: &mut t,
                intensity: &mut i,
                reflectance: &mut r,
            };
            let mut solver = Solver::new(table, buffers, config).map_err(err)?;
            while let Outcome::BudgetSpent { .. } = solver.step(table, u32::MAX) {}
            radiosity(&solver, table, n)
        };

        let (mut p, mut u, mut h, mut t, mut i, mut r) = new_buffers();
        let buffers = Buffers {
            power: &mut p,
            unshot: &mut u,
            incident: &mut h,
            tree: &mut t,
            intensity: &mut i,
            reflectance: &mut r,
        };
        let mut solver = Solver::new(table, buffers, config).map_err(err)?;
        let mut truncated = Vec::new();
        for (s, (intensity, exact)) in self.schedule.iter().zip(self.exact).enumerate() {
            let mut relight_work = 0u64;
            if s > 0 {
                for (g, rgb) in intensity.iter().enumerate() {
                    let rgb = rgb.map(|v| v as f32);
                    relight_work += u64::from(solver.set_light(table, g as u32, rgb).map_err(err)?);
                }
            }
            let limit = self.options.frames.unwrap_or(MAX_FRAMES);
            let (mut work, mut count, mut converged_now) = (0u64, 0usize, false);
            let mut last = None;
            while count < limit {
                let o = solver.step(table, self.options.budget);
                count += 1;
                work += u64::from(o.used());
                let b = radiosity(&solver, table, n);
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
        Ok((converged, truncated))
    }
}

impl fmt::Display for CheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "table: {} patches, {} entries, {} bytes, codec {}; budget {} units/frame, frames {}, tolerance {:.3e}",
            self.patches,
            self.entries,
            self.table_bytes,
            self.codec,
            self.budget,
            self.frames_per_setting.map_or("to convergence".to_string(), |n| n.to_string()),
            self.tolerance
        )?;
        writeln!(f, "\nerror decomposition (default intensities)")?;
        writeln!(f, "{:<24} {:>10} {:>10} {:>10}  compares", "component", "rel L2", "max rel", "lum L2")?;
        for c in &self.components {
            writeln!(
                f,
                "{:<24} {:>10.3e} {:>10.3e} {:>10.3e}  {}",
                c.name, c.error.rel_l2, c.error.max_rel, c.error.luminance_rel_l2, c.compares
            )?;
        }
        writeln!(
            f,
            "\ndevice vs exact f64 (scene matrix, transfer vectors relit), last frame of each setting"
        )?;
        writeln!(
            f,
            "{:<6} {:<3} {:<24} {:>7} {:>12} {:>10} {:>10} {:>10} {:>10}",
            "arith",
            "#",
            "intensity (group 0)",
            "frames",
            "work",
            "relight",
            "rel L2",
            "max rel",
            "converged"
        )?;
        for s in &self.settings {
            let i = s
                .intensity
                .first()
                .map_or("-".to_string(), |v| format!("({:.2}, {:.2}, {:.2})", v[0], v[1], v[2]));
            writeln!(
                f,
                "{:<6} {:<3} {:<24} {:>7} {:>12} {:>10} {:>10.3e} {:>10.3e} {:>10}",
                s.arith,
                s.setting,
                i,
                s.frames,
                s.work,
                s.relight_work,
                s.error.rel_l2,
                s.error.max_rel,
                s.converged
            )?;
        }
        writeln!(f, "\nfirst frames of setting 0 (all frames: --format json)")?;
        writeln!(f, "{:<6} {:>6} {:>12} {:>10} {:>10}", "arith", "frame", "work", "rel L2", "max rel")?;
        for fr in self.frames.iter().filter(|fr| fr.setting == 0 && (fr.frame <= 4 || fr.frame % 16 == 0)) {
            writeln!(
                f,
                "{:<6} {:>6} {:>12} {:>10.3e} {:>10.3e}",
                fr.arith, fr.frame, fr.work_total, fr.rel_l2, fr.max_rel
            )?;
        }
        Ok(())
    }
}

/// Command-line options of `radiosity check` (after the scene arguments).
#[derive(Clone, Debug, clap::Args)]
pub struct CheckArgs {
    /// Form-factor code width: 16 or 8 (others are rejected by the bake).
    #[arg(long, default_value_t = 16)]
    pub bits: u32,
    /// Sparsification threshold: largest fraction of a row's energy that may be dropped.
    #[arg(long, default_value_t = bake::DEFAULT_THRESHOLD)]
    pub threshold: f64,
    /// Work units per frame.
    #[arg(long, value_name = "UNITS", default_value_t = CheckOptions::default().budget)]
    pub budget: u32,
    /// Frames per light setting (default: run each setting to convergence).
    #[arg(long, value_name = "N")]
    pub frames: Option<usize>,
    /// Arithmetic paths of the device solver.
    #[arg(long, value_enum, default_value_t = ArithArg::Both)]
    pub arith: ArithArg,
    /// Relight after the default setting: all dynamic groups to 0, back to default, then (1, 0.2, 0.2) x default.
    #[arg(long)]
    pub relight: bool,
    /// Solver tolerance as a fraction of the largest per-channel emitted power.
    #[arg(long, default_value_t = CheckOptions::default().tolerance)]
    pub tolerance: f64,
    /// The form-factor component's reference matrix uses this many times the samples and rays (1: skip).
    #[arg(long, value_name = "K", default_value_t = CheckOptions::default().ff_factor)]
    pub ff_factor: usize,
    /// Slack on row sums of the shooting form `A_j F_ji / A_i` above 1 in the f64 solves (estimated form factors
    /// are not exactly reciprocal).
    #[arg(long, value_name = "S", default_value_t = bake::DEFAULT_ROW_SUM_TOLERANCE)]
    pub row_sum_tolerance: f64,
}

/// `--arith` values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ArithArg {
    /// `f32`.
    F32,
    /// Q32.32 fixed point.
    Fixed,
    /// Both.
    Both,
}

impl CheckArgs {
    /// The [`CheckOptions`] these arguments select.
    #[must_use]
    pub fn options(&self) -> CheckOptions {
        CheckOptions {
            bits: self.bits,
            threshold: self.threshold,
            budget: self.budget,
            frames: self.frames,
            arith: match self.arith {
                ArithArg::F32 => Arith::F32,
                ArithArg::Fixed => Arith::Fixed,
                ArithArg::Both => Arith::Both,
            },
            relight: self.relight,
            tolerance: self.tolerance,
            ff_factor: self.ff_factor,
            row_sum_tolerance: self.row_sum_tolerance,
        }
    }
}
