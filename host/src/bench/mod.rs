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
//! count (`growth.rs`), with log-log least-squares exponents. Before all of these (so that its rows' peak memory
//! is measured while the process holds little) the hierarchical solver against the flat one, both judged by the
//! continuous path-traced reference ([`hierarchy`]), with the large generated scene's growth and its full size
//! ([`largescene`]), and the link construction's rays against raw Embree ([`linkrate`]). [`report`] writes
//! `REPORT.md`, `curves.csv`, `growth.csv` and the plots.
//!
//! Files: this module holds the options, the result types and [`run`]; `scenes.rs` runs one scene (mesh, exact
//! answer, bakes, every curve), `curves.rs` measures each kind of curve, [`device`] runs core's solver for one
//! device curve.

pub mod bakebench;
mod curves;
pub mod device;
mod faces;
pub mod fit;
mod growth;
pub mod hierarchy;
pub mod hierdevice;
pub mod largescene;
pub mod linkrate;
pub mod report;
pub mod roofline;
mod scenes;

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use firmware_sim::sim::Arith;
use thiserror::Error;

use crate::bake;
use crate::metrics;
use scenes::SceneSpec;
pub use scenes::{cornell_table, edge_for_patches};

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

/// What a curve runs: a device method on a baked table, or one of the host's f64 references.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CurveMethod {
    /// Core's progressive-refinement shooting from a cold start.
    Shooting,
    /// Core's Gauss-Seidel sweeps from a cold start.
    GaussSeidel,
    /// Core's Jacobi sweeps from a cold start.
    Jacobi,
    /// Shooting after the light change, from the converged default solution.
    WarmRelight,
    /// Shooting after the light change, from scratch.
    ColdRelight,
    /// Core's relight from the transfer basis stored in the table (one point).
    TransferBasis,
    /// The host's f64 dense LU (factor and solve; one point).
    DenseLu,
    /// The host's f64 Gauss-Seidel at decreasing residual tolerances.
    HostGaussSeidel,
}

impl CurveMethod {
    /// The name in `curves.csv`, labels and the report.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            CurveMethod::Shooting => "shooting",
            CurveMethod::GaussSeidel => "gauss-seidel",
            CurveMethod::Jacobi => "jacobi",
            CurveMethod::WarmRelight => "warm relight",
            CurveMethod::ColdRelight => "cold relight",
            CurveMethod::TransferBasis => "transfer basis",
            CurveMethod::DenseLu => "f64 dense LU",
            CurveMethod::HostGaussSeidel => "f64 gauss-seidel",
        }
    }

    /// A solve after the light change (warm or cold), measured on its own setting.
    #[must_use]
    pub const fn is_relight(self) -> bool {
        matches!(self, CurveMethod::WarmRelight | CurveMethod::ColdRelight)
    }

    /// A device iteration from a cold start at the default setting: shooting, Gauss-Seidel or Jacobi (what the
    /// report ranks; the transfer basis and the relights are compared in their own sections).
    #[must_use]
    pub const fn is_cold_iteration(self) -> bool {
        matches!(self, CurveMethod::Shooting | CurveMethod::GaussSeidel | CurveMethod::Jacobi)
    }
}

impl fmt::Display for CurveMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A device curve's setting within a scene: method, arithmetic, table codec and overshooting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DeviceRun {
    /// The method.
    pub method: CurveMethod,
    /// The arithmetic.
    pub arith: Arith,
    /// Form-factor code width of the table (16 or 8).
    pub bits: u32,
    /// Overshooting on (shooting only).
    pub overshoot: bool,
}

impl DeviceRun {
    /// `method` in `arith` on the `bits`-bit table, without overshooting.
    #[must_use]
    pub const fn new(method: CurveMethod, arith: Arith, bits: u32) -> Self {
        DeviceRun { method, arith, bits, overshoot: false }
    }

    /// Shooting in `arith` on the `bits`-bit table, with or without overshooting.
    #[must_use]
    pub const fn shooting(arith: Arith, bits: u32, overshoot: bool) -> Self {
        DeviceRun { method: CurveMethod::Shooting, arith, bits, overshoot }
    }
}

/// One curve: a method on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Scene name.
    pub scene: String,
    /// Method.
    pub method: CurveMethod,
    /// Arithmetic of a device method; `None` for the host's f64 methods (`f64` in the CSV and labels).
    pub arith: Option<Arith>,
    /// Form-factor code width of the table (16 or 8); `None` for the host's f64 matrix (`f64` in the CSV).
    pub bits: Option<u32>,
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
        match (self.arith, self.bits) {
            (Some(arith), Some(bits)) => format!(
                "{}{} {arith} {bits}-bit",
                self.method,
                if self.overshoot { " +overshoot" } else { "" }
            ),
            _ => self.method.to_string(),
        }
    }

    /// The arithmetic's text: `f32`, `fixed`, or `f64` for the host's methods.
    #[must_use]
    pub fn arith_name(&self) -> &'static str {
        self.arith.map_or("f64", Arith::name)
    }

    /// The codec's text: the code width (`16`, `8`), or `f64` for the host's methods.
    #[must_use]
    pub fn codec_name(&self) -> String {
        self.bits.map_or_else(|| "f64".to_string(), |b| b.to_string())
    }

    /// Whether this runs on the device (has work units).
    #[must_use]
    pub fn is_device(&self) -> bool {
        self.arith.is_some()
    }

    /// Whether this is the device curve `run`.
    #[must_use]
    pub fn is(&self, run: DeviceRun) -> bool {
        self.method == run.method
            && self.arith == Some(run.arith)
            && self.bits == Some(run.bits)
            && self.overshoot == run.overshoot
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

impl SceneResult {
    /// Table bytes of the `bits`-bit bake (0 if there is none).
    #[must_use]
    pub fn bytes_at(&self, bits: u32) -> usize {
        self.table_bytes.iter().find(|e| e.0 == bits).map_or(0, |e| e.1)
    }

    /// Table entries of the `bits`-bit bake (0 if there is none).
    #[must_use]
    pub fn entries_at(&self, bits: u32) -> usize {
        self.entries.iter().find(|e| e.0 == bits).map_or(0, |e| e.1)
    }
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
    /// Instructions per work unit (the cost model's bound) of each arithmetic.
    pub instr_per_unit: InstructionsPerUnit,
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
    /// The hierarchical solver against the flat one, judged by the continuous reference.
    pub hierarchy: hierarchy::HierarchySection,
    /// The large generated scene of the hierarchy section (the office at growing sizes).
    pub office: largescene::OfficeSection,
    /// The hierarchy's link construction against raw Embree (rays per second, thread scaling).
    pub link_rate: linkrate::LinkRate,
    /// Total wall time of the run, seconds.
    pub total_seconds: f64,
}

/// Model instructions per work unit of each arithmetic: the firmware cost model's bound for solver units, and
/// the measured rate of the transfer relight's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstructionsPerUnit {
    /// The `m4-f32` build's bound.
    pub f32: f64,
    /// The `m4-fixed` build's bound.
    pub fixed: f64,
    /// The `m4-f32` build's instructions per transfer-relight unit (COST.md's transfer section).
    pub transfer_f32: f64,
    /// The `m4-fixed` build's instructions per transfer-relight unit.
    pub transfer_fixed: f64,
}

impl InstructionsPerUnit {
    /// The bound of `arith`.
    #[must_use]
    pub fn of(&self, arith: Arith) -> f64 {
        match arith {
            Arith::F32 => self.f32,
            Arith::Fixed => self.fixed,
        }
    }

    /// Instructions per transfer-relight unit of `arith`.
    #[must_use]
    pub fn transfer_of(&self, arith: Arith) -> f64 {
        match arith {
            Arith::F32 => self.transfer_f32,
            Arith::Fixed => self.transfer_fixed,
        }
    }
}

/// Instructions per transfer-relight unit of firmware build `build` (`m4-f32`, `m4-fixed`): the `instr. per unit`
/// column of the first transfer-relight table in `firmware-sim/COST.md` (the uniform enclosure's, the largest
/// ratio over its relights).
///
/// # Errors
/// If the section, its column or the build's row is missing or does not parse.
pub fn transfer_per_unit(cost_md: &str, build: &str) -> Result<f64, BenchError> {
    let missing = |what: &str| BenchError::Options(format!("COST.md: transfer relight section: {what}"));
    let mut lines = cost_md.lines().skip_while(|l| !l.starts_with("## Transfer relight"));
    let header = lines.find(|l| l.starts_with("| build |")).ok_or_else(|| missing("no table"))?;
    let col =
        header.split('|').position(|c| c.trim() == "instr. per unit").ok_or_else(|| missing("no column"))?;
    let row = lines
        .take_while(|l| l.starts_with('|'))
        .find(|l| l.starts_with(&format!("| {build} |")))
        .ok_or_else(|| missing(&format!("no row for {build}")))?;
    row.split('|').nth(col).and_then(|c| c.trim().parse::<f64>().ok()).ok_or_else(|| missing("bad value"))
}

/// The firmware cost model's bound instructions per work unit for the `m4-f32` and `m4-fixed` builds, and their
/// transfer-relight rates, from the tables in `firmware-sim/COST.md`.
///
/// # Errors
/// If the table or a build's row is missing.
pub fn instructions_per_unit(cost_md: &str) -> Result<InstructionsPerUnit, BenchError> {
    Ok(InstructionsPerUnit {
        f32: bound_per_unit(cost_md, &format!("m4-{}", Arith::F32))?,
        fixed: bound_per_unit(cost_md, &format!("m4-{}", Arith::Fixed))?,
        transfer_f32: transfer_per_unit(cost_md, &format!("m4-{}", Arith::F32))?,
        transfer_fixed: transfer_per_unit(cost_md, &format!("m4-{}", Arith::Fixed))?,
    })
}

/// The bound instructions per work unit of firmware build `build` (`m4-f32`, `cornell-hier-m4-f32`, ...) from the cost
/// tables in `firmware-sim/COST.md` (every table there has the same columns).
///
/// # Errors
/// If no table header or no row for `build` is found, or its bound does not parse.
pub fn bound_per_unit(cost_md: &str, build: &str) -> Result<f64, BenchError> {
    let header = cost_md
        .lines()
        .find(|l| l.starts_with("| build |"))
        .ok_or_else(|| BenchError::Options("COST.md: no `| build |` table header".into()))?;
    let col = header
        .split('|')
        .position(|c| c.trim() == "bound instr. per unit")
        .ok_or_else(|| BenchError::Options("COST.md: no `bound instr. per unit` column".into()))?;
    let row = cost_md
        .lines()
        .find(|l| l.starts_with(&format!("| {build} |")))
        .ok_or_else(|| BenchError::Options(format!("COST.md: no row for build {build}")))?;
    row.split('|')
        .nth(col)
        .and_then(|c| c.trim().parse::<f64>().ok())
        .ok_or_else(|| BenchError::Options(format!("COST.md: bad bound per unit for {build}")))
}

/// The rate bound of firmware build `build` from the table of instructions per link, per node judged, per node
/// swept and per shot in `firmware-sim/COST.md`.
///
/// # Errors
/// If that table, its columns or a row for `build` are missing, or a value does not parse.
pub fn rate_bound(cost_md: &str, build: &str) -> Result<Rates, BenchError> {
    let bad = |what: &str| BenchError::Options(format!("COST.md: {what} (rate bound of {build})"));
    // The build's row in a table whose header has the rate columns (a build has rows in other tables too).
    let lines: Vec<&str> = cost_md.lines().collect();
    let row_in_table = |k: usize| {
        let rows = lines.get(k + 1..).unwrap_or(&[]).iter().take_while(|l| l.starts_with('|'));
        rows.copied().find(|l| l.starts_with(&format!("| {build} |")))
    };
    let (header, row) = lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.starts_with("| build |") && l.contains("instr. per link"))
        .find_map(|(k, header)| row_in_table(k).map(|row| (*header, row)))
        .ok_or_else(|| bad("no row in a table with an `instr. per link` column"))?;
    let col = |name: &str| {
        header.split('|').position(|c| c.trim() == name).ok_or_else(|| bad(&format!("no `{name}` column")))
    };
    let cells: Vec<&str> = row.split('|').collect();
    let value = |name: &str| {
        let k = col(name)?;
        cells.get(k).and_then(|c| c.trim().parse::<f64>().ok()).ok_or_else(|| bad("a value does not parse"))
    };
    Ok(Rates {
        per_link: value("instr. per link")?,
        per_judged: value("instr. per node judged")?,
        per_swept: value("instr. per node swept")?,
        per_shot: value("instr. per shot")?,
        scale: value("bound scale")?,
    })
}

/// A firmware build's rate bound on a hierarchical table (`firmware-sim/COST.md`): instructions per kind of
/// work, and the scale of the envelope over its calibration frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rates {
    /// Instructions per link applied.
    pub per_link: f64,
    /// Instructions per node judged in a round.
    pub per_judged: f64,
    /// Instructions per node entered or left by a sweep.
    pub per_swept: f64,
    /// Instructions per shot (its run's setup).
    pub per_shot: f64,
    /// The envelope's scale over the calibration frames.
    pub scale: f64,
}

/// The cost model as built in.
pub(crate) const COST_MD: &str = include_str!("../../../firmware-sim/COST.md");

/// Overshoot of the "with overshooting" curves: core's recommended `64 / 256`, a relaxation factor of 1.25.
pub const OVERSHOOT: u8 = radiosity_core::Config::<f32>::RECOMMENDED_OVERSHOOT;

/// Error levels the report states work and time for.
pub const LEVELS: [f64; 3] = [0.1, 0.01, 0.001];

fn log(options: &BenchOptions, msg: &str) {
    if options.verbose {
        eprintln!("bench: {msg}");
    }
}

/// The load average line of `/proc/loadavg`, labelled `when` ("at start", "at the end").
fn load_average(when: &str) -> String {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    format!(
        "load average {when} (1, 5, 15 min): {}",
        load.split_whitespace().take(3).collect::<Vec<_>>().join(", ")
    )
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
    vec![format!("CPU: {model}"), format!("logical CPUs available (nproc): {cpus}"), load_average("at start")]
}

/// Runs the bench and writes the report into `options.out` (see the module docs).
///
/// # Errors
/// See [`BenchError`].
pub fn run(options: &BenchOptions) -> Result<BenchResults, BenchError> {
    let t0 = Instant::now();
    let instr = instructions_per_unit(COST_MD)?;
    let machine = machine();
    let ff = scenes::form_factor_options();
    let specs: Vec<SceneSpec> = if options.quick {
        vec![SceneSpec::cornell(100), SceneSpec::furnace(54, 0.9)]
    } else {
        vec![
            SceneSpec::cornell(250),
            SceneSpec::cornell(1000),
            SceneSpec::cornell(4000),
            SceneSpec::furnace(216, 0.9),
            SceneSpec::furnace(216, 0.99),
        ]
    };
    // The hierarchy first: its rows report their peak memory, which is clearer while the process holds little
    // (the flat growth sizes below leave memory that the allocator keeps).
    let hierarchy = hierarchy::section(options)?;
    let office = largescene::section(options)?;
    let link_rate = linkrate::section(options)?;
    let mut scene_results = Vec::new();
    let mut curves = Vec::new();
    for spec in &specs {
        let (r, c) = scenes::run_scene(options, spec, &ff, instr, false)?;
        scene_results.push(r);
        curves.extend(c);
    }
    let growth = growth::series(options, &ff, instr, &scene_results, &curves)?;
    let mut bake = Vec::new();
    for target in if options.quick { vec![100] } else { vec![500, 2000] } {
        log(options, &format!("bake throughput: ~{target} patches"));
        bake.push(bakebench::bake_throughput(options, target)?);
    }
    let mut results = BenchResults {
        quick: options.quick,
        reps: options.reps,
        ff_samples: ff.samples_per_patch,
        ff_rays: ff.rays_per_pair,
        machine,
        instr_per_unit: instr,
        scenes: scene_results,
        curves,
        bake,
        growth,
        growth_limit_note: growth::note(options.quick),
        hierarchy,
        office,
        link_rate,
        total_seconds: t0.elapsed().as_secs_f64(),
    };
    results.machine.push(load_average("at the end"));
    report::write(&results, &options.out)?;
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_bounds_are_read_from_their_own_tables() {
        // A cost report of the committed shape: sections, each a one-rate table and then a rate table. Build
        // `x` has rows only in the second section, its one-rate row after the first rate table's header.
        let one_rate =
            "| build | calibration frames | LS overhead (instr.) | LS instr. per unit | bound overhead | \
                        bound instr. per unit |\n|---|---|---|---|---|---|\n";
        let rates = "| build | frames | overhead | instr. per link | instr. per node judged | instr. per node swept \
                     | instr. per shot | residual | bound overhead | bound scale |\n|---|---|---|---|---|---|---|---|---|---|\n";
        let md = format!(
            "{one_rate}| y | 37 | 10 | 70.0 | 10 | 80.0 |\n\n{rates}| y | 33 | 5 | 99.0 | 1.0 | 2.0 | 7.5 | 0.1 | 5 | 1.5 |\n\n\
             {one_rate}| x | 37 | 2227 | 74.19 | 2227 | 82.58 |\n\n\
             {rates}| x | 33 | 12121 | 82.5 | 45.2 | 65.2 | 70.5 | 3.4e-3 | 12121 | 1.204 |\n"
        );
        assert_eq!(bound_per_unit(&md, "x").unwrap(), 82.58);
        let rates = |per_link, per_judged, per_swept, per_shot, scale| Rates {
            per_link,
            per_judged,
            per_swept,
            per_shot,
            scale,
        };
        assert_eq!(rate_bound(&md, "x").unwrap(), rates(82.5, 45.2, 65.2, 70.5, 1.204));
        assert_eq!(rate_bound(&md, "y").unwrap(), rates(99.0, 1.0, 2.0, 7.5, 1.5));
        assert!(rate_bound(&md, "z").is_err());
        assert!(rate_bound("| build | a |\n| x | 1 |\n", "x").is_err());
        // The built-in report: the Cornell table's rates are those of the last row of its build (the rate
        // table closes the section that names the table).
        let r = rate_bound(COST_MD, "cornell-hier-m4-f32").unwrap();
        let row = COST_MD.lines().rfind(|l| l.starts_with("| cornell-hier-m4-f32 |")).unwrap();
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let want = [r.per_link, r.per_judged, r.per_swept, r.per_shot].map(|v| format!("{v:.1}"));
        assert_eq!(cells[4..8], want, "{row}");
        assert!(r.scale >= 1.0, "{}", r.scale);
    }
}
