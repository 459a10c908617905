//! `radiosity bench`: speed against error, for every relighting method, measured side by side in one run.
//!
//! For each benchmark scene (the Cornell box at three mesh sizes, the white furnace at two reflectances) the
//! bench prepares the scene, computes the exact f64 answer (transfer vectors, Gauss-Seidel to a relative residual
//! of `1e-12`), bakes tables with both codecs and runs every curve against that answer:
//!
//! - core shooting, f32 and fixed point, each codec, without and with overshooting (`overshoot = 64`, i.e. 1.25);
//! - core Gauss-Seidel and Jacobi on the same tables, f32 and fixed point;
//! - relighting after a light change (every dynamic group to `(1, 0.2, 0.2)` times its default): warm start from
//!   the converged default solution, against a cold solve of the new setting (f32 shooting, 16-bit table);
//! - the host's f64 references on the scene's own matrix: faer dense LU (factor and solve), and f64 Gauss-Seidel
//!   stopped at a series of residual tolerances.
//!
//! Device curves record error against work units at geometrically spaced checkpoints (see [`device`]); model
//! instructions are work units times the Cortex-M4 cost model's bound per unit (`firmware-sim/COST.md`, read at
//! build time); wall times are medians of repeated runs. Then the roofline ([`roofline`]), the bake throughput
//! against raw Embree ([`bakebench`]) and the growth of bake time, nonzeros, table bytes and work with the patch
//! count, with log-log least-squares exponents. [`report`] writes `REPORT.md`, `curves.csv`, `growth.csv` and
//! the plots.

pub mod bakebench;
pub mod device;
pub mod report;
pub mod roofline;

use std::path::{Path, PathBuf};
use std::time::Instant;

use radiosity_core::{Fixed, Scalar, Table};
use thiserror::Error;

use crate::bake::{self, bake, codec_for_bits, BakeInput, BakeOptions};
use crate::formfactor::{compute_form_factors, FormFactorOptions};
use crate::mesh::{mesh, MeshOptions};
use crate::metrics;
use crate::pipeline::{prepare, PrepareOptions, Prepared};
use crate::reference::{exact_transfer, gauss_seidel, DenseLu, GaussSeidelOptions, Method, RadiositySystem};
use crate::scene::Scene;
use device::{run_curve, DeviceCase, Start, Step, StopRule};

/// Why the bench failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BenchError {
    /// Loading, meshing or form factors failed.
    #[error(transparent)]
    Pipeline(#[from] crate::pipeline::PipelineError),
    /// A scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// A bake failed.
    #[error(transparent)]
    Bake(#[from] bake::BakeError),
    /// An f64 solve failed.
    #[error(transparent)]
    Reference(#[from] crate::reference::ReferenceError),
    /// A metric could not be computed.
    #[error(transparent)]
    Metrics(#[from] metrics::MetricsError),
    /// A plot could not be drawn or written.
    #[error(transparent)]
    Picture(#[from] crate::picture::PictureError),
    /// The device solver failed.
    #[error("device solver: {0}")]
    Solver(String),
    /// Embree failed.
    #[error("embree: {0}")]
    Embree(String),
    /// Bad options or an inconsistent setting.
    #[error("bench: {0}")]
    Options(String),
    /// A file could not be written.
    #[error("writing {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Settings of a bench run.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchOptions {
    /// Small scenes, one repetition, few growth sizes: a well-formed report in seconds (for `make test`).
    pub quick: bool,
    /// Output folder (`REPORT.md`, CSV files, plots).
    pub out: PathBuf,
    /// Folder holding `cornell-box.obj` and `furnace.obj`.
    pub scenes: PathBuf,
    /// Repetitions of every timed run (wall times are their medians).
    pub reps: usize,
    /// Print progress on stderr.
    pub verbose: bool,
}

impl BenchOptions {
    /// The full bench (3 repetitions) or the quick one (1), writing into `out`, scenes from the repository.
    #[must_use]
    pub fn new(quick: bool, out: PathBuf) -> Self {
        BenchOptions {
            quick,
            out,
            scenes: default_scenes_dir(),
            reps: if quick { 1 } else { 3 },
            verbose: false,
        }
    }
}

/// `scenes/` of the working directory if it exists, else the repository's (beside this crate).
#[must_use]
pub fn default_scenes_dir() -> PathBuf {
    let local = PathBuf::from("scenes");
    if local.join("cornell-box.obj").exists() {
        local
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes")
    }
}

/// One point of a curve: work (device methods only), model instructions, wall time, error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurvePoint {
    /// Work units (device methods; `None` for the host's f64 methods).
    pub work: Option<u64>,
    /// Model instructions on the Cortex-M4 (device methods).
    pub instructions: Option<f64>,
    /// Median wall time, seconds.
    pub seconds: f64,
    /// Relative L2 error against the exact answer.
    pub rel_l2: f64,
    /// Max per-patch relative error against the exact answer.
    pub max_rel: f64,
}

/// One curve: a method on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Scene name.
    pub scene: String,
    /// Method (`shooting`, `gauss-seidel`, `jacobi`, `warm relight`, `cold relight`, `f64 dense LU`,
    /// `f64 gauss-seidel`).
    pub method: String,
    /// Arithmetic (`f32`, `fixed`, `f64`).
    pub arith: String,
    /// Codec (`16`, `8`; `f64` for host methods).
    pub codec: String,
    /// Overshooting on (shooting only).
    pub overshoot: bool,
    /// Bytes the method needs for its matrix: the table, or the f64 matrix on the host.
    pub table_bytes: usize,
    /// Points in increasing work / time.
    pub points: Vec<CurvePoint>,
}

impl Curve {
    /// Short label for legends and tables.
    #[must_use]
    pub fn label(&self) -> String {
        if self.arith == "f64" {
            return self.method.clone();
        }
        format!(
            "{}{} {} {}-bit",
            self.method,
            if self.overshoot { " +overshoot" } else { "" },
            self.arith,
            self.codec
        )
    }

    /// Whether this runs on the device (has work units).
    #[must_use]
    pub fn is_device(&self) -> bool {
        self.arith != "f64"
    }

    /// The first point at or below `level` relative L2 error.
    #[must_use]
    pub fn reach(&self, level: f64) -> Option<&CurvePoint> {
        self.points.iter().find(|p| p.rel_l2 <= level)
    }

    /// The smallest error reached.
    #[must_use]
    pub fn floor(&self) -> f64 {
        self.points.iter().map(|p| p.rel_l2).fold(f64::INFINITY, f64::min)
    }
}

/// What was measured on one scene besides the curves.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneResult {
    /// Scene name.
    pub name: String,
    /// Patches.
    pub patches: usize,
    /// Nonzero form factors before sparsification.
    pub nonzeros: usize,
    /// Table entries (after sparsification), per codec bits.
    pub entries: Vec<(u32, usize)>,
    /// Table bytes per codec bits.
    pub table_bytes: Vec<(u32, usize)>,
    /// Form-factor seconds (threads: all) and bake seconds (16-bit).
    pub form_factor_seconds: f64,
    /// Bake seconds (sparsify, reference solves, quantize, write; 16-bit).
    pub bake_seconds: f64,
    /// Roofline per codec bits (f32).
    pub roofline: Vec<(u32, roofline::Roofline)>,
    /// Repetitions of the dense LU timing (fewer for large scenes).
    pub lu_reps: usize,
}

/// Bake throughput and thread scaling.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeThroughput {
    /// Scene and patch count.
    pub scene: String,
    /// Patches.
    pub patches: usize,
    /// Samples per patch and rays per pair used.
    pub samples: usize,
    /// Rays per pair.
    pub rays_per_pair: usize,
    /// Form factors: rays cast, seconds and rays/s on 1 and 2 threads.
    pub ff: Vec<(usize, u64, f64)>,
    /// Raw Embree: rays, seconds on 1 and 2 threads.
    pub raw: Vec<(usize, usize, f64)>,
    /// Where the form factors' time went, on 1 and 2 threads: threads, kernel evaluations, seconds of the kernel
    /// phase and of the visibility phase (medians; see [`crate::formfactor::FormFactorStats`]).
    pub phases: Vec<(usize, u64, f64, f64)>,
}

/// One size of the growth series.
#[derive(Clone, Debug, PartialEq)]
pub struct GrowthRow {
    /// Patches.
    pub patches: usize,
    /// Form-factor seconds (all threads).
    pub form_factor_seconds: f64,
    /// Bake seconds (16-bit).
    pub bake_seconds: f64,
    /// Nonzero form factors before sparsification.
    pub nonzeros: usize,
    /// Table entries after sparsification.
    pub entries: usize,
    /// Table bytes (16-bit).
    pub table_bytes: usize,
    /// Work units of f32 shooting (16-bit, no overshoot) to 1% error; `None` if not reached.
    pub work_to_1pct: Option<u64>,
}

/// Everything one run measured.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchResults {
    /// Quick mode.
    pub quick: bool,
    /// Repetitions.
    pub reps: usize,
    /// Form-factor settings of the benchmark scenes.
    pub ff_samples: usize,
    /// Rays per pair of the benchmark scenes.
    pub ff_rays: usize,
    /// Machine description lines.
    pub machine: Vec<String>,
    /// Instructions per work unit (bound) for f32 and fixed.
    pub instr_per_unit: (f64, f64),
    /// Per-scene results.
    pub scenes: Vec<SceneResult>,
    /// All curves.
    pub curves: Vec<Curve>,
    /// Bake throughput, at each measured mesh size.
    pub bake: Vec<BakeThroughput>,
    /// Growth series (Cornell box).
    pub growth: Vec<GrowthRow>,
    /// What the growth series covers (sizes and what runs at each).
    pub growth_limit_note: String,
    /// Total wall time of the run, seconds.
    pub total_seconds: f64,
}

/// The firmware cost model's bound instructions per work unit for the `m4-f32` and `m4-fixed` builds, from the
/// table in `firmware-sim/COST.md`.
///
/// # Errors
/// If the table or a build's row is missing.
pub fn instructions_per_unit(cost_md: &str) -> Result<(f64, f64), BenchError> {
    let header = cost_md
        .lines()
        .find(|l| l.starts_with("| build |"))
        .ok_or_else(|| BenchError::Options("COST.md: no `| build |` table header".into()))?;
    let col = header
        .split('|')
        .position(|c| c.trim() == "bound instr. per unit")
        .ok_or_else(|| BenchError::Options("COST.md: no `bound instr. per unit` column".into()))?;
    let value = |build: &str| -> Result<f64, BenchError> {
        let row = cost_md
            .lines()
            .find(|l| l.starts_with(&format!("| {build} |")))
            .ok_or_else(|| BenchError::Options(format!("COST.md: no row for build {build}")))?;
        row.split('|')
            .nth(col)
            .and_then(|c| c.trim().parse::<f64>().ok())
            .ok_or_else(|| BenchError::Options(format!("COST.md: bad bound per unit for {build}")))
    };
    Ok((value("m4-f32")?, value("m4-fixed")?))
}

/// The cost model as built in.
const COST_MD: &str = include_str!("../../../firmware-sim/COST.md");

/// Overshoot of the "with overshooting" curves: core's recommended `64 / 256`, a relaxation factor of 1.25.
pub const OVERSHOOT: u8 = radiosity_core::Config::<f32>::RECOMMENDED_OVERSHOOT;

/// Error levels the report states work and time for.
pub const LEVELS: [f64; 3] = [0.1, 0.01, 0.001];

struct SceneSpec {
    name: String,
    file: &'static str,
    target: usize,
    rho: Option<f64>,
}

fn log(options: &BenchOptions, msg: &str) {
    if options.verbose {
        eprintln!("bench: {msg}");
    }
}

/// The uniform-subdivision edge whose mesh of `scene` has the patch count closest to `target` (bisection on
/// the edge's logarithm; patch counts fall as the edge grows).
///
/// # Errors
/// If meshing fails.
pub fn edge_for_patches(scene: &Scene, target: usize) -> Result<(f64, usize), BenchError> {
    let base = MeshOptions::for_scene(scene);
    let count = |edge: f64| -> Result<usize, BenchError> {
        let o = MeshOptions { subdivide: true, max_patch_edge: edge, patch_budget: usize::MAX / 4 };
        mesh(scene, &o)
            .map(|m| m.patches.len())
            .map_err(|e| BenchError::Options(format!("meshing {}: {e}", scene.path.display())))
    };
    let (mut lo, mut hi) = ((base.max_patch_edge / 64.0).ln(), (base.max_patch_edge * 16.0).ln());
    let mut best = (base.max_patch_edge, count(base.max_patch_edge)?);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        let c = count(mid.exp())?;
        if c.abs_diff(target) < best.1.abs_diff(target) {
            best = (mid.exp(), c);
        }
        if c > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(best)
}

fn prepare_at(
    path: &Path,
    target: usize,
    ff: &FormFactorOptions,
    rho: Option<f64>,
) -> Result<Prepared, BenchError> {
    let scene = Scene::load(path)?;
    let (edge, count) = edge_for_patches(&scene, target)?;
    // A patch budget equal to the uniform mesh's count: adaptive refinement has nothing left to spend, so the
    // mesh is the uniform one of about `target` patches (the sizes the report compares).
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: Some(edge),
        max_patches: Some(count),
        form_factors: ff.clone(),
        verbose: false,
    };
    let mut p = prepare(path, &options)?;
    if let Some(r) = rho {
        for m in &mut p.scene.materials {
            m.reflectance = [r; 3];
        }
        for v in &mut p.lighting.rho {
            *v = [r; 3];
        }
    }
    Ok(p)
}

/// Size of the f64 CSR matrix the host methods read (values, column indices, row starts).
fn csr_bytes(p: &Prepared) -> usize {
    let ff = &p.form_factors;
    ff.values().len() * 8 + ff.columns().len() * 4 + ff.row_starts().len() * 8
}

struct SceneRun<'a> {
    options: &'a BenchOptions,
    name: &'a str,
    instr: (f64, f64),
    curves: Vec<Curve>,
}

impl SceneRun<'_> {
    #[allow(clippy::too_many_arguments)]
    fn device<S: Scalar>(
        &mut self,
        case: &DeviceCase<'_>,
        bits: u32,
        table_bytes: usize,
        method: &str,
        step: Step,
        start: &Start,
        exact: &[[f64; 3]],
        stop: &StopRule,
    ) -> Result<(), BenchError> {
        let arith = if core::any::type_name::<S>().contains("Fixed") { "fixed" } else { "f32" };
        let per_unit = if arith == "f32" { self.instr.0 } else { self.instr.1 };
        let t0 = Instant::now();
        let points = run_curve::<S>(case, step, start, exact, stop, self.options.reps)?;
        let curve = Curve {
            scene: self.name.to_string(),
            method: method.to_string(),
            arith: arith.to_string(),
            codec: bits.to_string(),
            overshoot: matches!(step, Step::Shooting(o) if o > 0),
            table_bytes,
            points: points
                .iter()
                .map(|p| CurvePoint {
                    work: Some(p.work),
                    instructions: Some(p.work as f64 * per_unit),
                    seconds: p.seconds,
                    rel_l2: p.rel_l2,
                    max_rel: p.max_rel,
                })
                .collect(),
        };
        log(
            self.options,
            &format!(
                "{}: {} -> {} points, final error {:.2e} ({:.1} s)",
                self.name,
                curve.label(),
                curve.points.len(),
                curve.floor(),
                t0.elapsed().as_secs_f64()
            ),
        );
        self.curves.push(curve);
        Ok(())
    }
}

impl SceneRun<'_> {
    /// The precomputed transfer basis: the same bake with the quantized response vectors `T_g` stored in the
    /// table, relit once by core's `relight_transfer` (f32 and fixed point) at the default intensities. One
    /// point per curve: its work is `patches x (groups + 1)` units, its error the quantization of `B_static` and
    /// `T_g` (no iteration), its bytes the table with the transfer section.
    fn transfer(
        &mut self,
        p: &Prepared,
        bake_options: &BakeOptions,
        bits: u32,
        exact: &[[f64; 3]],
        area: &[f64],
    ) -> Result<(), BenchError> {
        let options = BakeOptions { transfer: true, ..*bake_options };
        let baked =
            bake(&BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors), &options)?;
        let table = Table::parse(&baked.table).map_err(|e| BenchError::Solver(format!("table: {e:?}")))?;
        let intensity: Vec<[f64; 3]> = p.lighting.default_intensity.clone();
        self.transfer_curve::<f32>(&table, baked.table.len(), bits, &intensity, exact, area)?;
        self.transfer_curve::<Fixed>(&table, baked.table.len(), bits, &intensity, exact, area)
    }

    fn transfer_curve<S: Scalar>(
        &mut self,
        table: &Table<'_>,
        table_bytes: usize,
        bits: u32,
        intensity: &[[f64; 3]],
        exact: &[[f64; 3]],
        area: &[f64],
    ) -> Result<(), BenchError> {
        let arith = if core::any::type_name::<S>().contains("Fixed") { "fixed" } else { "f32" };
        let per_unit = if arith == "f32" { self.instr.0 } else { self.instr.1 };
        let intensity: Vec<[S; 3]> = intensity.iter().map(|v| v.map(|x| S::from_f32(x as f32))).collect();
        let mut out = vec![[S::ZERO; 3]; table.patch_count() as usize];
        let mut times = Vec::new();
        let mut work = 0;
        for _ in 0..self.options.reps.max(1) {
            let t0 = Instant::now();
            work = radiosity_core::transfer::relight_transfer(table, &intensity, &mut out)
                .map_err(|e| BenchError::Solver(format!("transfer relight: {e:?}")))?;
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let b: Vec<[f64; 3]> = out.iter().map(|v| v.map(|x| f64::from(x.to_f32()))).collect();
        let e = metrics::compare(&b, exact, area)?;
        let curve = Curve {
            scene: self.name.to_string(),
            method: "transfer basis".into(),
            arith: arith.into(),
            codec: bits.to_string(),
            overshoot: false,
            table_bytes,
            points: vec![CurvePoint {
                work: Some(u64::from(work)),
                instructions: Some(f64::from(work) * per_unit),
                seconds: times[times.len() / 2],
                rel_l2: e.rel_l2,
                max_rel: e.max_rel,
            }],
        };
        log(
            self.options,
            &format!(
                "{}: {} -> {} units, error {:.2e}, table {} bytes",
                self.name,
                curve.label(),
                work,
                e.rel_l2,
                table_bytes
            ),
        );
        self.curves.push(curve);
        Ok(())
    }
}

fn stop_rule(entries: usize, patches: usize, rho_max: f64, quick: bool) -> StopRule {
    // Enough passes over the table for Jacobi (the slowest, contraction rho_max per sweep) to reach the stop
    // error, times 4 as a margin (shooting's work units per entry were up to about 3 with the earlier
    // tournament tree; about 1.1 with block selection).
    let error: f64 = 3e-4;
    let passes = (error.ln() / rho_max.max(0.05).ln()).ceil() + 10.0;
    StopRule {
        first: (entries as u64 / 64).max(64),
        ratio: if quick { 1.6 } else { 1.3 },
        error,
        max_work: (passes * 4.0 * entries as f64) as u64,
        plateau: if quick { 3 } else { 5 },
        // A floor is only declared after the passes Jacobi needs to reach 10% (at least four passes; a pass is
        // entries + 2 units per patch), times 4 as a margin: at rho = 0.99 the error falls ~1% per
        // pass, which a fixed window would mistake for a plateau.
        plateau_after: ((0.1f64.ln() / rho_max.max(0.05).ln()).ceil().max(4.0) * 4.0) as u64
            * (entries + 2 * patches) as u64,
    }
}

/// The host's f64 curves: dense LU (one point) and Gauss-Seidel at decreasing residual tolerances.
fn host_curves(
    options: &BenchOptions,
    name: &str,
    p: &Prepared,
    exact: &[[f64; 3]],
) -> Result<(Vec<Curve>, usize), BenchError> {
    let l = &p.lighting;
    let e = l.default_emission();
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let system = RadiositySystem::new(&l.rho, &p.form_factors)?;
    let n = p.patches.len();
    let mut curves = Vec::new();
    // Dense LU: factor + solve; a factorization of thousands of patches takes seconds, so large scenes repeat less.
    let lu_reps = if n > 2000 { 1 } else { options.reps };
    let mut times = Vec::new();
    let mut b = Vec::new();
    for _ in 0..lu_reps {
        let t0 = Instant::now();
        let lu = DenseLu::factor(system)?;
        b = lu.solve(&e)?.b;
        times.push(t0.elapsed().as_secs_f64());
    }
    let err = metrics::compare(&b, exact, &area)?;
    curves.push(Curve {
        scene: name.into(),
        method: "f64 dense LU".into(),
        arith: "f64".into(),
        codec: "f64".into(),
        overshoot: false,
        table_bytes: n * n * 8,
        points: vec![CurvePoint {
            work: None,
            instructions: None,
            seconds: device::median(&mut times),
            rel_l2: err.rel_l2,
            max_rel: err.max_rel,
        }],
    });
    // f64 Gauss-Seidel stopped at residual tolerances 10^-1 .. 10^-8 (half decades).
    let mut points = Vec::new();
    let mut k = 2;
    while k <= 16 {
        let tolerance = 10f64.powf(-(k as f64) / 2.0);
        let mut times = Vec::new();
        let mut sol = None;
        for _ in 0..options.reps {
            let t0 = Instant::now();
            let s = gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance, max_sweeps: None })?;
            times.push(t0.elapsed().as_secs_f64());
            sol = Some(s);
        }
        if let Some(s) = sol {
            let err = metrics::compare(&s.b, exact, &area)?;
            points.push(CurvePoint {
                work: None,
                instructions: None,
                seconds: device::median(&mut times),
                rel_l2: err.rel_l2,
                max_rel: err.max_rel,
            });
            if err.rel_l2 < 1e-6 {
                break;
            }
        }
        k += if options.quick { 2 } else { 1 };
    }
    curves.push(Curve {
        scene: name.into(),
        method: "f64 gauss-seidel".into(),
        arith: "f64".into(),
        codec: "f64".into(),
        overshoot: false,
        table_bytes: csr_bytes(p),
        points,
    });
    Ok((curves, lu_reps))
}

/// The Cornell box meshed to about `target` patches (form factors at 4 samples and 4 rays), baked with `bits`-bit
/// codes, with the transfer section if `transfer`: the table the criterion benchmarks run on.
///
/// # Errors
/// If preparing or baking fails.
pub fn cornell_table(target: usize, bits: u32, transfer: bool) -> Result<bake::Baked, BenchError> {
    let ff = FormFactorOptions {
        samples_per_patch: 4,
        rays_per_pair: 4,
        progress: false,
        ..FormFactorOptions::default()
    };
    let p = prepare_at(&default_scenes_dir().join("cornell-box.obj"), target, &ff, None)?;
    let options = BakeOptions {
        codec: codec_for_bits(bits)?,
        row_sum_tolerance: 1e-2,
        transfer,
        ..BakeOptions::default()
    };
    Ok(bake(&BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors), &options)?)
}

/// Intensity per dynamic group after the light change: `(1, 0.2, 0.2)` times the default.
fn changed_intensity(p: &Prepared) -> Vec<[f64; 3]> {
    p.lighting.default_intensity.iter().map(|d| [d[0], d[1] * 0.2, d[2] * 0.2]).collect()
}

fn run_scene(
    options: &BenchOptions,
    spec: &SceneSpec,
    ff: &FormFactorOptions,
    instr: (f64, f64),
    growth_only: bool,
) -> Result<(SceneResult, Vec<Curve>), BenchError> {
    let path = options.scenes.join(spec.file);
    let t0 = Instant::now();
    let p = prepare_at(&path, spec.target, ff, spec.rho)?;
    let n = p.patches.len();
    log(
        options,
        &format!(
            "{}: {} patches, {} nonzeros, form factors {:.1} s",
            spec.name,
            n,
            p.form_factors.nonzeros(),
            t0.elapsed().as_secs_f64()
        ),
    );
    // The exact answer's transfer vectors on the scene's own matrix (f64 Gauss-Seidel to residual `1e-12`: the
    // forward error is at most `(1 + q) / (1 - q) * 1e-12`, `2e-10` at `q = 0.99`).
    let exact = Method::GaussSeidel(GaussSeidelOptions::default());
    let tv = exact_transfer(&p.lighting, &p.form_factors, &exact)?;
    let exact_default = tv.relight(&p.lighting.default_intensity)?;
    let changed = changed_intensity(&p);
    let exact_changed = tv.relight(&changed)?;
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let rho_max = p.lighting.rho.iter().flatten().copied().fold(0.0, f64::max);

    let mut run = SceneRun { options, name: &spec.name, instr, curves: Vec::new() };
    let mut result = SceneResult {
        name: spec.name.clone(),
        patches: n,
        nonzeros: p.form_factors.nonzeros(),
        entries: Vec::new(),
        table_bytes: Vec::new(),
        form_factor_seconds: p.stats.elapsed.as_secs_f64(),
        bake_seconds: 0.0,
        roofline: Vec::new(),
        lu_reps: 0,
    };
    let bits_list: &[u32] = if growth_only { &[16] } else { &[16, 8] };
    for &bits in bits_list {
        // Row-sum slack of the bake's f64 solves: the shooting form `A_j F_ji / A_i` of a matrix estimated with few
        // samples exceeds 1 by up to the estimator's reciprocity noise (~1e-3 here), more than the default 1e-4.
        let bake_options =
            BakeOptions { codec: codec_for_bits(bits)?, row_sum_tolerance: 1e-2, ..BakeOptions::default() };
        let tb = Instant::now();
        let baked =
            bake(&BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors), &bake_options)?;
        if bits == 16 {
            result.bake_seconds = tb.elapsed().as_secs_f64();
        }
        let table = Table::parse(&baked.table).map_err(|e| BenchError::Solver(format!("table: {e:?}")))?;
        let bytes = baked.table.len();
        result.entries.push((bits, table.entry_count() as usize));
        result.table_bytes.push((bits, bytes));
        let dec = bake::decode_table(&table);
        let max_power = (0..3)
            .map(|c| dec.emission.iter().zip(&dec.area).map(|(e, a)| e[c] * a).sum::<f64>())
            .fold(0.0, f64::max);
        // Converged = every unshot magnitude below 1e-6 of the emitted power (as `radiosity check`).
        let case = DeviceCase { table: &table, area: &area, tolerance: 1e-6 * max_power };
        let stop = stop_rule(table.entry_count() as usize, n, rho_max, options.quick);
        let cold = Start::Cold;
        let ex = &exact_default;
        if growth_only {
            let mut s = stop;
            s.error = 0.01;
            run.device::<f32>(&case, bits, bytes, "shooting", Step::Shooting(0), &cold, ex, &s)?;
            continue;
        }
        for (overshoot, _) in [(0u8, ()), (OVERSHOOT, ())] {
            run.device::<f32>(&case, bits, bytes, "shooting", Step::Shooting(overshoot), &cold, ex, &stop)?;
            run.device::<Fixed>(&case, bits, bytes, "shooting", Step::Shooting(overshoot), &cold, ex, &stop)?;
        }
        run.device::<f32>(&case, bits, bytes, "gauss-seidel", Step::GaussSeidel, &cold, ex, &stop)?;
        run.device::<Fixed>(&case, bits, bytes, "gauss-seidel", Step::GaussSeidel, &cold, ex, &stop)?;
        run.device::<f32>(&case, bits, bytes, "jacobi", Step::Jacobi, &cold, ex, &stop)?;
        run.device::<Fixed>(&case, bits, bytes, "jacobi", Step::Jacobi, &cold, ex, &stop)?;
        if bits == 16 {
            let to: Vec<[f32; 3]> = changed.iter().map(|v| v.map(|x| x as f32)).collect();
            let mut s = stop;
            s.first = 1;
            let ec = &exact_changed;
            run.device::<f32>(
                &case,
                bits,
                bytes,
                "warm relight",
                Step::Shooting(0),
                &Start::Warm(to.clone()),
                ec,
                &s,
            )?;
            run.device::<f32>(
                &case,
                bits,
                bytes,
                "cold relight",
                Step::Shooting(0),
                &Start::ColdAt(to),
                ec,
                &s,
            )?;
        }
        run.transfer(&p, &bake_options, bits, ex, &area)?;
        let tr = Instant::now();
        // Three rounds per repetition: each round is short (~1 s), and the ratios need several on a shared machine.
        let rounds = 3 * options.reps;
        let roof = roofline::measure::<f32>(&table, 1e-3 * max_power, rounds)?;
        log(
            options,
            &format!(
                "{}: roofline {bits}-bit: stream {:.1} M/s, GS {:.1} M/s, shooting {:.1} M/s ({:.0}%) ({:.1} s)",
                spec.name,
                roof.stream_entries_per_s / 1e6,
                roof.gauss_seidel_entries_per_s / 1e6,
                roof.shooting_entries_per_s / 1e6,
                100.0 * roof.shooting_fraction(),
                tr.elapsed().as_secs_f64()
            ),
        );
        result.roofline.push((bits, roof));
    }
    if !growth_only {
        let (host, lu_reps) = host_curves(options, &spec.name, &p, &exact_default)?;
        result.lu_reps = lu_reps;
        for c in &host {
            log(options, &format!("{}: {} -> final error {:.2e}", spec.name, c.label(), c.floor()));
        }
        run.curves.extend(host);
    }
    Ok((result, run.curves))
}

fn bake_throughput(options: &BenchOptions, target: usize) -> Result<BakeThroughput, BenchError> {
    let ffo = FormFactorOptions { progress: false, ..FormFactorOptions::default() };
    let path = options.scenes.join("cornell-box.obj");
    let scene = Scene::load(&path)?;
    let (edge, _) = edge_for_patches(&scene, target)?;
    let m =
        mesh(&scene, &MeshOptions { subdivide: true, max_patch_edge: edge, patch_budget: usize::MAX / 4 })
            .map_err(|e| BenchError::Options(format!("meshing: {e}")))?;
    // Interleaved rounds: form factors on 1 and 2 threads, then raw Embree on 1 and 2 threads, so both rates of
    // a ratio are measured minutes apart at most, not in separate blocks (the shared machine's speed drifts).
    // The first 1-thread run also gives the matrix whose pairs the raw rays join.
    let rounds = options.reps.clamp(1, 3);
    let run_ff = |threads: usize| {
        compute_form_factors(&m.patches, &FormFactorOptions { threads: Some(threads), ..ffo.clone() })
            .map_err(|e| BenchError::Options(format!("form factors: {e}")))
    };
    // Per thread count (index 0: 1 thread, 1: 2 threads): total, kernel-phase and visibility-phase seconds.
    let mut ff_times: [[Vec<f64>; 3]; 2] = Default::default();
    let (mut rays_cast, mut kernels) = ([0u64; 2], [0u64; 2]);
    let mut record = |slot: usize, stats: &crate::formfactor::FormFactorStats| {
        ff_times[slot][0].push(stats.elapsed.as_secs_f64());
        ff_times[slot][1].push(stats.kernel_time.as_secs_f64());
        ff_times[slot][2].push(stats.visibility_time.as_secs_f64());
        rays_cast[slot] = stats.rays_cast;
        kernels[slot] = stats.kernel_evaluations;
    };
    let (matrix, stats) = run_ff(1)?;
    record(0, &stats);
    let scene_rt = bakebench::occluder_scene(&m.patches, ffo.robust)?;
    let rays = bakebench::pair_rays(&m.patches, &matrix, ffo.rays_per_pair, scene_rt.offset());
    let mut raw_times: [Vec<f64>; 2] = Default::default();
    for round in 0..rounds {
        if round > 0 {
            record(0, &run_ff(1)?.1);
        }
        record(1, &run_ff(2)?.1);
        for (slot, threads) in [(0usize, 1usize), (1, 2)] {
            raw_times[slot].push(bakebench::time_occlusion(&scene_rt, &rays, threads)?.0);
        }
    }
    let mut ff = Vec::new();
    let mut phases = Vec::new();
    let mut raw = Vec::new();
    for (slot, threads) in [(0usize, 1usize), (1, 2)] {
        let [total, kernel, visibility] = &mut ff_times[slot];
        ff.push((threads, rays_cast[slot], device::median(total)));
        phases.push((threads, kernels[slot], device::median(kernel), device::median(visibility)));
        raw.push((threads, rays.len(), device::median(&mut raw_times[slot])));
    }
    Ok(BakeThroughput {
        scene: format!("cornell-box (~{target} patches)"),
        patches: m.patches.len(),
        samples: ffo.samples_per_patch,
        rays_per_pair: ffo.rays_per_pair,
        ff,
        raw,
        phases,
    })
}

/// Machine description: CPU model, logical CPUs, load average.
#[must_use]
pub fn machine() -> Vec<String> {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or("unknown CPU".to_string(), |s| s.trim().to_string());
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    vec![
        format!("CPU: {model}"),
        format!("logical CPUs available (nproc): {cpus}"),
        format!(
            "load average at start (1, 5, 15 min): {}",
            load.split_whitespace().take(3).collect::<Vec<_>>().join(", ")
        ),
    ]
}

/// Runs the bench and writes the report into `options.out` (see the module docs).
///
/// # Errors
/// See [`BenchError`].
pub fn run(options: &BenchOptions) -> Result<BenchResults, BenchError> {
    let t0 = Instant::now();
    let instr = instructions_per_unit(COST_MD)?;
    let machine = machine();
    // Form factors of the benchmark scenes: fewer samples and rays than the bake's default (16/16) so the
    // 4,000-patch mesh fits the run; every error is against the exact solve of the same matrix, so the
    // estimator's own noise does not enter the curves. The throughput section uses the defaults.
    let (samples, rays) = (4, 4);
    let ff = FormFactorOptions {
        samples_per_patch: samples,
        rays_per_pair: rays,
        progress: false,
        ..FormFactorOptions::default()
    };
    let cornell = |target: usize| SceneSpec {
        name: format!("cornell-{target}"),
        file: "cornell-box.obj",
        target,
        rho: None,
    };
    let furnace = |target: usize, rho: f64| SceneSpec {
        name: format!("furnace-rho{}", (rho * 100.0).round()),
        file: "furnace.obj",
        target,
        rho: Some(rho),
    };
    let specs: Vec<SceneSpec> = if options.quick {
        vec![cornell(100), furnace(54, 0.9)]
    } else {
        vec![cornell(250), cornell(1000), cornell(4000), furnace(216, 0.9), furnace(216, 0.99)]
    };
    let mut scenes = Vec::new();
    let mut curves = Vec::new();
    for spec in &specs {
        let (r, c) = run_scene(options, spec, &ff, instr, false)?;
        scenes.push(r);
        curves.extend(c);
    }
    // Growth: the Cornell scenes above plus sizes in between (shooting f32 16-bit to 1% only).
    let mut growth = Vec::new();
    let extra: &[usize] = if options.quick { &[50] } else { &[500, 2000, 8000, 16000] };
    let mut rows: Vec<(SceneResult, Vec<Curve>)> = scenes
        .iter()
        .filter(|s| s.name.starts_with("cornell"))
        .map(|s| (s.clone(), curves.iter().filter(|c| c.scene == s.name).cloned().collect()))
        .collect();
    for &target in extra {
        let spec = cornell(target);
        log(options, &format!("growth: {}", spec.name));
        rows.push(run_scene(options, &spec, &ff, instr, true)?);
    }
    for (s, c) in &rows {
        let shoot =
            c.iter().find(|c| c.method == "shooting" && c.arith == "f32" && c.codec == "16" && !c.overshoot);
        growth.push(GrowthRow {
            patches: s.patches,
            form_factor_seconds: s.form_factor_seconds,
            bake_seconds: s.bake_seconds,
            nonzeros: s.nonzeros,
            entries: s.entries.iter().find(|e| e.0 == 16).map_or(0, |e| e.1),
            table_bytes: s.table_bytes.iter().find(|e| e.0 == 16).map_or(0, |e| e.1),
            work_to_1pct: shoot.and_then(|c| c.reach(0.01)).and_then(|p| p.work),
        });
    }
    growth.sort_by_key(|g| g.patches);
    let mut bake = Vec::new();
    for target in if options.quick { vec![100] } else { vec![500, 2000] } {
        log(options, &format!("bake throughput: ~{target} patches"));
        bake.push(bake_throughput(options, target)?);
    }
    let results = BenchResults {
        quick: options.quick,
        reps: options.reps,
        ff_samples: samples,
        ff_rays: rays,
        machine,
        instr_per_unit: instr,
        scenes,
        curves,
        bake,
        growth,
        growth_limit_note: if options.quick {
            "quick mode: small sizes only".into()
        } else {
            "the sizes above 4,000 patches (about 8,000 and 16,000) run the growth measurements only: form \
             factors, bake, and f32 shooting (16-bit, no overshoot) to 1% error"
                .into()
        },
        total_seconds: t0.elapsed().as_secs_f64(),
    };
    let mut results = results;
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    results.machine.push(format!(
        "load average at the end (1, 5, 15 min): {}",
        load.split_whitespace().take(3).collect::<Vec<_>>().join(", ")
    ));
    report::write(&results, &options.out)?;
    Ok(results)
}
