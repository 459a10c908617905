//! The command line's option types: every clap derive of the `radiosity` binary lives here or in `main.rs`;
//! the library takes plain option structs.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use firmware_sim::sim::Arith;
use radiosity_host::bake;
use radiosity_host::bench::BenchOptions;
use radiosity_host::check::CheckOptions;
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::montecarlo::{self, ReferenceOptions, SampleCount};
use radiosity_host::picture::lightmap::LightMapOptions;
use radiosity_host::pipeline::PrepareOptions;
use radiosity_host::regress::{RegressOptions, DEFAULT_SEEDS};

/// The f64 solver of `solve`, `bake`, `render`, `lightmap` and `export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SolveMethod {
    /// The full patch-to-patch form-factor matrix of the adaptive mesh, solved exactly (also `dense`: the
    /// reference the hierarchy is judged against).
    #[value(alias = "dense")]
    Flat,
    /// Hierarchical radiosity with clustering (links refined to `--epsilon`).
    Hierarchical,
}

/// How `radiosity solve --method hierarchical` solves the system on its links.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum HierarchySolverArg {
    /// Jacobi sweeps over all links with push-pull.
    Gathering,
    /// Progressive refinement: the elements with the most unshot power shoot over their links first.
    Shooting,
}

impl From<HierarchySolverArg> for radiosity_host::hierarchy::HierarchySolver {
    fn from(s: HierarchySolverArg) -> Self {
        match s {
            HierarchySolverArg::Gathering => radiosity_host::hierarchy::HierarchySolver::Gathering,
            HierarchySolverArg::Shooting => radiosity_host::hierarchy::HierarchySolver::Shooting,
        }
    }
}

/// What the hierarchy's passes after the direct-light pass refine for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefinementArg {
    /// Every element within `--epsilon` of its own reflected light, dark corners included: the most accurate,
    /// and the most links per element.
    Budgets,
    /// Every link's power error within 1% of `--epsilon` times the brightest face's emitted power
    /// (brightness-weighted refinement against the solved light): far fewer links per element (the bake summary
    /// prints them), larger relative errors where the light is dim. For device tables.
    Brightness,
}

impl From<RefinementArg> for radiosity_host::hierarchy::Refinement {
    fn from(r: RefinementArg) -> Self {
        match r {
            RefinementArg::Budgets => radiosity_host::hierarchy::Refinement::Budgets,
            RefinementArg::Brightness => radiosity_host::hierarchy::Refinement::Brightness,
        }
    }
}

/// The hierarchical method's settings, shared by `solve`, `bake`, `check`, `render`, `lightmap` and `export` (each rejects
/// them with `--method flat`).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct HierarchyArgs {
    /// Hierarchical only: error bound, in (0, 1) (smaller is more accurate and costs more elements and links).
    /// The direct-light refinement and `--refinement brightness` allow each link to misplace 1% of it times
    /// the brightest face's emitted power; `--refinement budgets` allows each element that share of the light
    /// it reflects [default: 0.0005 for the brightness refinement of `solve`, `render`, `lightmap` and
    /// `export` (`bench/REPORT.md`, "Hierarchy against flat", has the error and seconds per epsilon); 0.03
    /// otherwise (device tables: `bake`, `check`)].
    #[arg(long, value_name = "E")]
    pub epsilon: Option<f64>,
    /// Hierarchical only: what the passes after the direct-light pass refine for: `budgets` (every element
    /// within `--epsilon` of its own reflected light) or `brightness` (every link within an absolute power
    /// bound: far fewer links; the default).
    #[arg(long, value_enum)]
    pub refinement: Option<RefinementArg>,
    /// Hierarchical only: most links refinement may hold (accepted and pending together); a scene that needs
    /// more stops with an error naming why it needed them, before memory runs out (a link costs a few hundred
    /// bytes at the peak) [default: 10000000].
    #[arg(long, value_name = "N")]
    pub max_links: Option<usize>,
    /// Hierarchical only: refine in N independent pieces, split by receiver subtree, each on its own copy of
    /// the tree, in parallel, and merge them; the answer is the same bit for bit for every N (the split a run
    /// on several machines will use). On one machine 1 is as fast (each wave's estimates run on every thread
    /// anyway) [default: 1].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub pieces: Option<u32>,
}

/// The method of the commands whose product is an f64 answer (`solve`, `render`, `lightmap`, `export`): the one
/// asked for, else the flat mesh's when a meshing option asks for a mesh (`--no-subdivide`, `--max-patches`,
/// `--max-patch-edge`), else the hierarchy.
pub fn answer_method(method: Option<SolveMethod>, scene: &SceneArgs) -> SolveMethod {
    method.unwrap_or(if scene.asks_for_a_mesh() { SolveMethod::Flat } else { SolveMethod::Hierarchical })
}

/// The table of `bake` and `check`: the one asked for; else flat when a flat setting asks for it (`flat_setting`:
/// a meshing option, or a flat table's own setting such as `--threshold`), hierarchical when a hierarchy setting
/// does; else by the scene ([`radiosity_host::pipeline::flat_mesh_has_room`]), loaded to count its faces, with a
/// note on stderr (unless `--quiet`) when that picks the hierarchy.
///
/// # Errors
/// The scene's load error, when the scene decides.
pub fn table_method(
    method: Option<SolveMethod>,
    scene: &SceneArgs,
    flat_setting: bool,
    hierarchy: &HierarchyArgs,
) -> Result<SolveMethod, radiosity_host::scene::SceneError> {
    if let Some(m) = method {
        return Ok(m);
    }
    if flat_setting || scene.asks_for_a_mesh() {
        return Ok(SolveMethod::Flat);
    }
    if hierarchy.any() {
        return Ok(SolveMethod::Hierarchical);
    }
    let loaded = radiosity_host::scene::Scene::load(&scene.scene)?;
    if radiosity_host::pipeline::flat_mesh_has_room(&loaded) {
        return Ok(SolveMethod::Flat);
    }
    if !scene.quiet {
        eprintln!(
            "note: {} has {} faces, more than its flat mesh's patch budget ({}) can split {} ways each: making \
             the hierarchical table (--method flat for the flat one)",
            scene.scene.display(),
            loaded.faces.len(),
            loaded.meshing.patch_budget.unwrap_or(radiosity_host::mesh::DEFAULT_PATCH_BUDGET),
            radiosity_host::pipeline::FLAT_PATCHES_PER_FACE
        );
    }
    Ok(SolveMethod::Hierarchical)
}

impl HierarchyArgs {
    /// Whether any hierarchical setting was given (an error with `--method flat`).
    pub fn any(&self) -> bool {
        self.epsilon.is_some()
            || self.refinement.is_some()
            || self.max_links.is_some()
            || self.pieces.is_some()
    }
}

/// Output format of a command whose output is a table (one CSV row per patch, face, pair or frame).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Human-readable text (the default).
    #[default]
    Text,
    /// Comma-separated values with a header line.
    Csv,
    /// JSON.
    Json,
}

/// Output format of a command whose output is a report with no one table to put in CSV (`bake`, `inspect`,
/// `check`, `regress`): `--format csv` is refused by the parser, naming the formats it accepts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ReportFormat {
    /// Human-readable text (the default).
    #[default]
    Text,
    /// JSON: everything the text shows.
    Json,
}

/// Command-line options of `radiosity check` (after the scene arguments).
#[derive(Clone, Debug, clap::Args)]
pub struct CheckArgs {
    /// Form-factor code width: 16 or 8 (others are rejected by the bake).
    #[arg(long, default_value_t = 16)]
    pub bits: u32,
    /// Flat tables only: sparsification threshold, the largest fraction of a row's energy that may be dropped
    /// [default: 0.001].
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Work units per frame.
    #[arg(long, value_name = "UNITS", default_value_t = CheckOptions::default().budget)]
    pub budget: u32,
    /// Frames per light setting, at most 100000 (default: run each setting to convergence).
    #[arg(long, value_name = "N")]
    pub frames: Option<usize>,
    /// Arithmetic paths of the device solver.
    #[arg(long, value_enum, default_value_t = ArithArg::Both)]
    pub arith: ArithArg,
    /// Relight after the default setting: all dynamic groups to 0, back to default, then (1, 0.2, 0.2) x default.
    #[arg(long)]
    pub relight: bool,
    /// Solver tolerance as a fraction of the largest per-channel emitted power [default: 0.000001, raised to
    /// fixed point's convergence floor for the table when that is higher and fixed point runs; a tolerance
    /// given below the floor is refused].
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Flat tables only: the form-factor component's reference matrix uses this many times the samples and rays
    /// (1: skip; at most 64) [default: 4].
    #[arg(long, value_name = "K")]
    pub ff_factor: Option<usize>,
    /// Flat tables only: slack on row sums of the shooting form `A_j F_ji / A_i` above 1 in the f64 solves
    /// (estimated form factors are not exactly reciprocal) [default: 0.0001].
    #[arg(long, value_name = "S")]
    pub row_sum_tolerance: Option<f64>,
    /// The discretization component (`--continuous`).
    #[command(flatten)]
    pub reference: ContinuousArgs,
}

/// `--continuous` and its reference's settings (`check`, `solve`).
#[derive(Clone, Debug, clap::Args)]
pub struct ContinuousArgs {
    /// Add the discretization component: path trace the continuous scene (as `radiosity reference`) and
    /// compare the mesh's f64 answer with it per face (area-averaged). Costs seconds, so it is off by default.
    #[arg(long)]
    pub continuous: bool,
    /// With --continuous: the reference's relative standard error per face.
    #[arg(long, value_name = "X", requires = "continuous", conflicts_with = "reference_samples",
          default_value_t = CHECK_REFERENCE_SE)]
    pub reference_se: f64,
    /// With --continuous: paths per face for the reference instead of a target standard error (at most 2^30).
    #[arg(long, value_name = "N", requires = "continuous")]
    pub reference_samples: Option<u64>,
}

impl ContinuousArgs {
    /// The continuous reference's settings (`None` without `--continuous`), on `scene`'s threads, with its
    /// progress bar unless `--quiet`.
    #[must_use]
    pub fn options(&self, scene: &SceneArgs) -> Option<ReferenceOptions> {
        self.continuous.then(|| ReferenceOptions {
            samples: match self.reference_samples {
                Some(n) => SampleCount::PerFace(n),
                None => SampleCount::TargetRelative {
                    target: self.reference_se,
                    max_samples: montecarlo::DEFAULT_MAX_SAMPLES,
                },
            },
            threads: scene.threads,
            progress: !scene.quiet,
            ..ReferenceOptions::default()
        })
    }
}

/// Default relative standard error of the `--continuous` reference (`check`, `solve`): well below the percent-level
/// differences the discretization component is meant to show.
pub const CHECK_REFERENCE_SE: f64 = 0.002;

/// `--arith` values: one arithmetic path, or both.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ArithArg {
    /// `f32`.
    F32,
    /// Q32.32 fixed point.
    Fixed,
    /// Both.
    Both,
}

impl ArithArg {
    /// The arithmetic paths this value selects, in report order.
    #[must_use]
    pub fn paths(self) -> &'static [Arith] {
        match self {
            ArithArg::F32 => &[Arith::F32],
            ArithArg::Fixed => &[Arith::Fixed],
            ArithArg::Both => &Arith::ALL,
        }
    }
}

impl CheckArgs {
    /// The [`CheckOptions`] these arguments select (the continuous reference runs on `scene`'s threads, with
    /// its progress bar unless `--quiet`).
    #[must_use]
    pub fn options(&self, scene: &SceneArgs) -> CheckOptions {
        let continuous = self.reference.options(scene);
        CheckOptions {
            bits: self.bits,
            codec: None,
            threshold: self.threshold.unwrap_or(bake::DEFAULT_THRESHOLD),
            budget: self.budget,
            frames: self.frames,
            arith: self.arith.paths().to_vec(),
            relight: self.relight,
            tolerance: self.tolerance.unwrap_or(CheckOptions::default().tolerance),
            tolerance_floor: self.tolerance.is_none(),
            ff_factor: self.ff_factor.unwrap_or(CheckOptions::default().ff_factor),
            row_sum_tolerance: self.row_sum_tolerance.unwrap_or(bake::DEFAULT_ROW_SUM_TOLERANCE),
            continuous,
        }
    }

    /// Whether a flat table's own setting was given (`--threshold`, `--ff-factor`, `--row-sum-tolerance`).
    pub fn has_flat_settings(&self) -> bool {
        self.threshold.is_some() || self.ff_factor.is_some() || self.row_sum_tolerance.is_some()
    }

    /// The error for a flat table's setting given with `--method hierarchical`.
    ///
    /// # Errors
    /// Naming the settings that do not apply.
    pub fn reject_flat_settings(&self) -> Result<(), String> {
        if self.has_flat_settings() {
            return Err(
                "--threshold, --ff-factor and --row-sum-tolerance apply to flat tables only (a hierarchical \
                        table keeps every link, and its form factors are the refinement's own)"
                    .into(),
            );
        }
        Ok(())
    }
}

/// Command-line options of `radiosity regress`.
#[derive(Clone, Debug, clap::Args)]
pub struct RegressArgs {
    /// Re-measure everything and write the baseline (prints old and new values side by side).
    #[arg(long)]
    pub update: bool,
    /// The baseline file.
    #[arg(long, default_value = "tests/baseline/quantization.json")]
    pub baseline: PathBuf,
    /// The folder of shipped scenes (`*.obj`, `*.gltf`, `*.glb`).
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Seeds measured by `--update` (the noise estimate; 2..=11).
    #[arg(long, default_value_t = DEFAULT_SEEDS)]
    pub seeds: usize,
    /// Only this scene file (check only), e.g. `cornell-box.obj`.
    #[arg(long)]
    pub scene: Option<String>,
}

impl RegressArgs {
    /// The library's options.
    pub fn options(&self) -> RegressOptions {
        RegressOptions {
            update: self.update,
            baseline: self.baseline.clone(),
            scenes: self.scenes.clone(),
            seeds: self.seeds,
            scene: self.scene.clone(),
        }
    }
}

/// Command-line options of `radiosity bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Small scenes and one repetition: checks that the report is produced (seconds, not minutes).
    #[arg(long)]
    pub quick: bool,
    /// Output folder for REPORT.md, the CSV files and the plots (created, with its parents, if missing).
    #[arg(long, default_value = "bench")]
    pub out: PathBuf,
    /// Repetitions of every timed run, 1 to 100 (default: 3, or 1 with --quick).
    #[arg(long, value_name = "N")]
    pub reps: Option<usize>,
}

impl BenchArgs {
    /// The [`BenchOptions`] these arguments select (progress on stderr).
    #[must_use]
    pub fn options(&self) -> BenchOptions {
        let mut o = BenchOptions::new(self.quick, self.out.clone());
        if let Some(r) = self.reps {
            o.reps = r.max(1);
        }
        o.verbose = true;
        o
    }
}

/// Precomputed diffuse lighting for small devices: scenes in, quantized form-factor tables out, every answer
/// checked against an exact f64 solve.
#[derive(Parser)]
#[command(name = "radiosity", version, about, long_about = None)]
pub struct Cli {
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Subcommand)]
pub enum Command {
    /// Print the form factors F_ij of a scene (the fraction of power leaving patch i that reaches patch j).
    ///
    /// `--format csv` prints `i,j,f_ij` for every nonzero pair in f64; `text` prints statistics.
    Formfactors {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Bake a scene into a table for the device: form factors, sparsify, fold static lights, quantize, write.
    ///
    /// Prints a summary (sizes, energy dropped, error of sparsify + quantize against the f64 solve) and writes
    /// TABLE plus, beside it, TABLE.capacities.json (the counts and buffer sizes a firmware build needs; the
    /// firmware's build script derives the same sizes from the table itself with core's `BufferSizes::of`).
    Bake {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output table file (.rft); its folder must exist. Written atomically, as every output file (a
        /// temporary file beside it, renamed over it when complete).
        #[arg(short, long, value_name = "TABLE")]
        output: PathBuf,
        /// Bits per form-factor code: 16 (small float, relative error < 2^-12) or 8 (< 2^-5).
        #[arg(long, default_value_t = 16)]
        bits: u32,
        /// Sparsification threshold (flat tables): the largest fraction of a row's (and a receiver's) energy
        /// that may be dropped. The dropped energy goes back to the row's kept entries, so every row keeps its
        /// sum [default: 0.001].
        #[arg(long)]
        threshold: Option<f64>,
        /// `flat`: a table of patch-to-patch form factors over the adaptive mesh (format version 3);
        /// `hierarchical`: the hierarchical solve's tree and links (format version 5), relit by core's
        /// hierarchical solver; the summary then measures a cold relight of it on the host. Default: flat when
        /// a flat setting is given (a meshing option, `--threshold`), hierarchical when a hierarchy setting is;
        /// else flat if the scene's patch budget holds a 2 x 2 split of each of its faces, hierarchical if not
        /// (a scene of many small faces; a note on stderr says so).
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (its default refinement here: `brightness`).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        /// Also store the transfer basis (the response of every patch, or every leaf of a hierarchical table, to
        /// every dynamic light group), so the device can relight as B = B_static + sum_g I_g T_g in one pass;
        /// the summary reports its bytes and relight error.
        #[arg(long)]
        transfer: bool,
        /// Output format of the summary (`text` or `json`; JSON adds the paths written as `files`).
        #[arg(long, value_enum, default_value_t = ReportFormat::Text)]
        format: ReportFormat,
    },
    /// Validate a table with the device's own parser and print its header and statistics.
    Inspect {
        /// The table file (.rft).
        table: PathBuf,
        /// The scene the table was baked from (.obj, .gltf or .glb, with its .toml): names the light groups, whose ids are
        /// hashes of their names.
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Output format (`text` or `json`).
        #[arg(long, value_enum, default_value_t = ReportFormat::Text)]
        format: ReportFormat,
    },
    /// Run the main job on the bundled Cornell box: bake it at its default (adaptive) mesh, validate the table,
    /// render it (view, light-map atlas, the .glb export, device error map, mesh histogram), then bake a table
    /// within 400 patches for a Cortex-M4 and run the "lights-on" relight script on it, on the host and under
    /// QEMU, printing every frame's error against f64 next to the instructions it took. Everything lands in the
    /// output folder.
    Demo {
        /// Folder for the outputs (created, with its parents, if missing).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Run the relight script on the host only: no Cortex-M4 firmware build, no QEMU (`make demo QEMU=0`).
        #[arg(long)]
        no_qemu: bool,
    },
    /// Solve the scene in f64 and print the patch table:
    /// `patch,face,cx,cy,cz,nx,ny,nz,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b`. `--method hierarchical`
    /// (the default) links clusters and elements where the light needs them, refined until no link may
    /// misplace more light than `--epsilon` allows (the patches are then the hierarchy's leaves); `--method
    /// flat` (or `dense`, the default when a meshing option is given) solves the adaptive mesh's full
    /// form-factor matrix exactly (dense LU up to 4096 patches, Gauss-Seidel above). With `--continuous`, every face's area-averaged answer against the
    /// path-traced continuous scene follows (as `check --continuous`: how far this mesh or hierarchy is from the
    /// scene's exact answer), after the text summary, in the JSON as `discretization`, or on stderr after CSV.
    Solve {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output format: `csv` the patch table; `text` a summary (patches, residual, mean radiosity, the mean
        /// response to each dynamic light group); `json` the summary and the patch table with each patch's
        /// vertices (`patch_table`).
        #[arg(long, value_enum, default_value_t = Format::Csv)]
        format: Format,
        /// Solver: `hierarchical` (links between clusters and elements; `--max-patches`, `--max-patch-edge`
        /// and `--no-subdivide` do not apply to it) or `flat`, also `dense` (a form factor for every pair of
        /// patches of the adaptive mesh) [default: hierarchical; flat when a meshing option is given].
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (default: brightness refinement at epsilon 0.0005).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        /// Hierarchical only: `gathering` (Jacobi sweeps over all links, the default) or `shooting`
        /// (progressive refinement, the order a device relights in); both reach the same answer.
        #[arg(long, value_enum)]
        solver: Option<HierarchySolverArg>,
        #[command(flatten)]
        reference: ContinuousArgs,
    },
    /// Path trace the continuous scene (no mesh) and print every face's (OBJ face, or glTF triangle or joined fan) area-averaged radiosity with its
    /// standard error: the answer that `solve`'s mesh answer should approach as the mesh is refined.
    ///
    /// Next-event estimation to the emitters and cosine-weighted bounces, combined by multiple importance
    /// sampling, with Russian roulette (method: the `montecarlo` module docs). `--format csv` prints
    /// `face,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b,se_r,se_g,se_b,samples`. Deterministic for a seed,
    /// whatever `--threads`.
    Reference(ReferenceArgs),
    /// Solve the scene in f64 (as `solve`) and render a view of it to a PNG (smoothly shaded, flat: one radiosity
    /// per patch, or one colour per patch to show the mesh). Prints the output path.
    Render {
        #[command(flatten)]
        scene: SceneArgs,
        /// Solver: `hierarchical` (the patches shown are the hierarchy's leaves; not with `--mode error`, which
        /// compares a flat device table with the flat solve) or `flat`, also `dense` (the adaptive mesh's full
        /// form-factor matrix) [default: hierarchical; flat with `--mode error` or a meshing option].
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (default: brightness refinement at epsilon 0.0005).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        /// Camera as "px,py,pz;tx,ty,tz;ux,uy,uz;fov_degrees" (position; target; up; vertical field of view).
        /// Default: the published Cornell camera for scenes named cornell-box*, else a view of the bounding box.
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Image width in pixels (at most 16384, and 4096 x 4096 pixels in all).
        #[arg(long, default_value_t = 512)]
        width: u32,
        /// Image height in pixels (at most 16384, and 4096 x 4096 pixels in all).
        #[arg(long, default_value_t = 512)]
        height: u32,
        /// What the picture shows.
        #[arg(long, value_enum, default_value_t = RenderModeArg::Shaded)]
        mode: RenderModeArg,
        /// Table for `--mode error` only (baked from SCENE with the same meshing options; default: bake one).
        #[arg(long, value_name = "TABLE")]
        table: Option<PathBuf>,
        /// Output PNG file; its folder must exist.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Run relight scripts on a table the way the device runs them and print every frame's error against the
    /// exact f64 answer for that frame's light intensities.
    ///
    /// The device loop (the code the firmware links) runs on the host in f32 and Q32.32 fixed point; with
    /// `--qemu` the Cortex-M4 firmware is also built with the same table and scripts and run under
    /// qemu-system-arm (mps2-an386, -icount shift=0), adding the instructions each frame took, flash and RAM use,
    /// and a bit-for-bit comparison of every frame with the host run.
    Relight {
        #[command(flatten)]
        scene: SceneArgs,
        /// The table baked from SCENE with the same meshing options (default: bake one at default settings).
        #[arg(long, value_name = "TABLE")]
        table: Option<PathBuf>,
        /// Relight scripts (TOML, format in docs/relight-scripts.md; default: SCENE's stem + .relight.toml).
        #[arg(long, value_name = "FILE")]
        scripts: Option<PathBuf>,
        /// Only the script of this name.
        #[arg(long, value_name = "NAME")]
        script: Option<String>,
        /// Also build the Cortex-M4 firmware and run it under QEMU (needs `make deps`).
        #[arg(long)]
        qemu: bool,
        /// Render the f32 device answer of every frame of the first selected script to DIR/SCRIPT-NNNN.png (DIR
        /// is created, with its parents, if missing).
        #[arg(long, value_name = "DIR")]
        frames: Option<PathBuf>,
        /// Size of the frame pictures (pixels, square; at most 4096).
        #[arg(long, default_value_t = 256)]
        frame_size: u32,
        /// Write the per-frame rows as CSV to FILE (its folder must exist).
        #[arg(long, value_name = "FILE")]
        csv: Option<PathBuf>,
        /// Plot error against cumulative work units per script to STEM.svg and STEM.png (their folder must
        /// exist; frames with every light off, whose relative error is undefined, are left out and counted in the
        /// legend).
        #[arg(long, value_name = "STEM")]
        plot: Option<PathBuf>,
        /// Output format (`text`: a table per frame; `csv`: the per-frame rows; `json`: everything). With `csv`
        /// and `json` the paths of the files written (`--frames`, `--csv`, `--plot`) go to stderr.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Solve the scene in f64 (as `solve`) and write its light-map atlas: STEM.exr (linear radiosity in W/m^2,
    /// RGB 32-bit float), STEM.hdr (the same in Radiance RGBE), STEM.png (tone mapped, sRGB) and STEM.json (the
    /// face -> atlas rectangle map, every face). Prints the paths and the
    /// atlas's size; `--texel-size` or `--face-texels` sets the resolution.
    Lightmap {
        #[command(flatten)]
        scene: SceneArgs,
        /// Solver: `hierarchical` (the light map is shaded from the hierarchy's leaves) or `flat`, also `dense`
        /// (the adaptive mesh's full form-factor matrix) [default: hierarchical; flat when a meshing option is
        /// given].
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (default: brightness refinement at epsilon 0.0005).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        /// Output path without extension (its folder must exist).
        #[arg(short, long, value_name = "STEM")]
        output: PathBuf,
        #[command(flatten)]
        light_map: LightMapArgs,
    },
    /// Solve the scene in f64 (as `solve`), bake its light map (as `lightmap`) and write the scene as binary
    /// glTF 2.0 that game engines and three.js load as it is.
    ///
    /// OUT.glb holds the patches (positions in scene units, normals), TEXCOORD_1 = the light-map UVs (TEXCOORD_0
    /// is the same set, as glTF requires it first), one material per scene material (baseColorFactor = the
    /// reflectance, emissiveFactor = the emission as radiance E / pi) and the light map embedded as an 8-bit sRGB
    /// PNG of the irradiance (B - E) / reflectance, scaled so that its brightest texel is 255: the light map's
    /// intensity (MOZ_lightmap "intensity" in every material, and extras.radiosity.light_map.irradiance_scale)
    /// turns it back into W/m^2. OUT.exr beside it holds the same irradiance atlas in 32-bit float. See README,
    /// "Light maps in game engines", for three.js and Bevy.
    Export {
        #[command(flatten)]
        scene: SceneArgs,
        /// Solver: `hierarchical` (the file's patches are the hierarchy's leaves, and its light map is shaded
        /// from them) or `flat`, also `dense` (the adaptive mesh's full form-factor matrix) [default:
        /// hierarchical; flat when a meshing option is given].
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (default: brightness refinement at epsilon 0.0005).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        /// The .glb file to write (its folder must exist); the .exr goes beside it.
        #[arg(short, long, value_name = "OUT.glb")]
        output: PathBuf,
        #[command(flatten)]
        light_map: LightMapArgs,
    },
    /// Write a scene as glTF 2.0, to load as the same scene: OUT.glb, or OUT.gltf with its buffer OUT.bin.
    ///
    /// One node, one mesh, one primitive per run of faces with one material, every face's polygon as a triangle
    /// fan (the loader joins it back); materials keep their names, reflectance as baseColorFactor, emission in
    /// W/m^2 as emissiveFactor times KHR_materials_emissive_strength. Positions in the scene's units, as f32.
    /// Light groups and meshing limits stay in NAME.toml, which the loader reads beside NAME.glb as beside
    /// NAME.obj (copy it along). No meshing, no solve: `scenes/cornell-box.glb` is
    /// `radiosity convert scenes/cornell-box.obj -o scenes/cornell-box.glb`.
    Convert {
        /// The scene: an OBJ file (its MTL files are read too) or a glTF 2.0 file, with its NAME.toml if any.
        scene: PathBuf,
        /// The file to write, .glb or .gltf (with NAME.bin beside it); its folder must exist.
        #[arg(short, long, value_name = "OUT.glb")]
        output: PathBuf,
        /// Do not print the scene's warnings.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Write a browser viewer of the scene: the device core, built as WebAssembly, relights it live in a
    /// WebGL2 page.
    ///
    /// DIR gets index.html, viewer.js, radiosity_web.wasm (the --wasm file), scene.rft (the table baked at default
    /// settings, with its transfer section) and scene.json (patch polygons, light groups, materials, camera, tone
    /// map, the Cortex-M4F cost model of firmware-sim/COST.md, and the exact f64 transfer vectors for the live
    /// error). Nothing is fetched from elsewhere, but browsers do not run WebAssembly from file:// pages: serve
    /// the folder with any static server, e.g. `python3 -m http.server -d DIR`, and open the address it prints.
    /// The page: drag to orbit, a slider and a colour per light group (intensity) and sliders per material
    /// (reflectance), the budget in work units per frame (each animation frame runs one bounded step), a plot of
    /// the error against work since the last change, and the transfer-basis relight. `make web` builds the wasm and writes out/web.
    View {
        #[command(flatten)]
        scene: SceneArgs,
        /// The folder to write the viewer into (created if missing).
        #[arg(long, value_name = "DIR")]
        web: PathBuf,
        /// The WebAssembly build of the radiosity-web crate (`cargo build -p radiosity-web --release --target
        /// wasm32-unknown-unknown --target-dir target/web`, as `make web` runs it).
        #[arg(
            long,
            value_name = "FILE",
            default_value = "target/web/wasm32-unknown-unknown/release/radiosity_web.wasm"
        )]
        wasm: PathBuf,
    },
    /// Bake the scene, run the device solver on the table (f32 and fixed point, a budget per frame, optional
    /// relighting) and compare every frame with the exact f64 answer; print the error decomposition.
    ///
    /// `radiosity check TABLE.rft --scene SCENE.obj` checks an existing table instead: it must have been baked
    /// from SCENE with the same meshing options (else a clear error naming the first difference).
    ///
    /// `--method hierarchical` bakes a hierarchical table instead and runs core's hierarchical solver on it, every
    /// frame against the hierarchical f64 solve; the decomposition then has the hierarchy's links (against a
    /// dense solve of the same leaves), the table's closure, the codes, iteration and arithmetic.
    Check {
        /// The scene's OBJ or glTF (.gltf, .glb) file, or a table (.rft) together with `--scene`.
        #[command(flatten)]
        scene: SceneArgs,
        /// With a table as the first argument: the scene it was baked from.
        #[arg(long = "scene", id = "table_scene", value_name = "SCENE")]
        table_scene: Option<PathBuf>,
        /// The table to bake and check: `flat` (patch-to-patch form factors of the adaptive mesh) or
        /// `hierarchical` (the hierarchical solve's tree and links, relit by core's hierarchical solver; every
        /// frame is compared with the hierarchical f64 solve, and the decomposition adds the links against a
        /// dense solve of the same leaves, up to 4096 leaves, and the table's closure). Default: as `bake`'s
        /// (flat with a table file or a flat setting, hierarchical with a hierarchy setting, else by the
        /// scene's faces against its patch budget).
        #[arg(long, value_enum)]
        method: Option<SolveMethod>,
        /// Settings of `--method hierarchical` (its default refinement here: `brightness`, as `bake`'s).
        #[command(flatten)]
        hierarchy: HierarchyArgs,
        #[command(flatten)]
        check: CheckArgs,
        /// Also plot the error decomposition to STEM.svg and STEM.png (their folder must exist): per arithmetic
        /// path, every component as its own bar on a log axis beside the measured total (L2 norms do not add).
        #[arg(long, value_name = "STEM")]
        plot: Option<PathBuf>,
        /// Output format (`text` or `json`; with `json` the plot's paths go to stderr).
        #[arg(long, value_enum, default_value_t = ReportFormat::Text)]
        format: ReportFormat,
    },
    /// Quantization regression: recompute every shipped scene's error components (16- and 8-bit codecs) and
    /// compare them with the checked-in baseline (fails when one exceeds baseline + k * noise);
    /// `--update` re-measures and rewrites the baseline, printing old and new values side by side.
    Regress {
        #[command(flatten)]
        regress: RegressArgs,
        /// Output format (`text` or `json`).
        #[arg(long, value_enum, default_value_t = ReportFormat::Text)]
        format: ReportFormat,
    },
    /// Measure speed against error for every relighting method (core shooting with and without overshooting,
    /// Gauss-Seidel, Jacobi, warm and cold relighting, the precomputed transfer basis, f64 dense LU and
    /// Gauss-Seidel), the roofline and the bake throughput; write REPORT.md,
    /// CSV files and plots into the output folder. Run it from a release build.
    Bench(BenchArgs),
}

/// The light map's resolution (`lightmap`, `export`).
#[derive(Clone, Debug, clap::Args)]
pub struct LightMapArgs {
    /// Texel edge length in scene units (a face `L` units across gets about `L / LENGTH` texels); the
    /// default sizes texels by `--face-texels` instead.
    #[arg(long, value_name = "LENGTH", conflicts_with = "face_texels")]
    pub texel_size: Option<f64>,
    /// Texels across the largest face when no `--texel-size` is given (1 to 4096; smaller faces get
    /// proportionally fewer, at least one). Every face is at most 4096 texels across and the atlas at most
    /// 4096 x 4096 texels in all.
    #[arg(long, value_name = "N", default_value_t = LightMapOptions::default().max_face_texels)]
    pub face_texels: u32,
}

/// Command-line options of `radiosity reference`.
#[derive(Clone, Debug, clap::Args)]
pub struct ReferenceArgs {
    /// The scene: an OBJ file (its MTL files are read too) or a glTF 2.0 file (.gltf with its buffers and
    /// images, or .glb); an optional NAME.toml beside it is read too.
    pub scene: PathBuf,
    /// Paths per face (instead of a target standard error), at most 2^30.
    #[arg(long, value_name = "N", conflicts_with_all = ["target_se", "max_samples"])]
    pub samples: Option<u64>,
    /// Relative standard error to reach on every face (its worst channel); paths are added in rounds until
    /// every face reaches it or has `--max-samples` [default: 0.01].
    #[arg(long, value_name = "X")]
    pub target_se: Option<f64>,
    /// Most paths per face with a target standard error, at most 2^30.
    #[arg(long, value_name = "N", default_value_t = montecarlo::DEFAULT_MAX_SAMPLES)]
    pub max_samples: u64,
    /// Seed of the random numbers; equal seeds give identical results on any thread count.
    #[arg(long, default_value_t = ReferenceOptions::default().seed)]
    pub seed: u64,
    /// Worker threads, at most 1024 (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Output format (`text`: a table and a summary; `csv`: one row per face; `json`: everything).
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
    /// Write the output to FILE (its folder must exist) instead of standard output.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// No progress bar or summary on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

impl ReferenceArgs {
    /// The library's options these arguments select.
    #[must_use]
    pub fn options(&self) -> ReferenceOptions {
        let samples = match self.samples {
            Some(n) => SampleCount::PerFace(n),
            None => SampleCount::TargetRelative {
                target: self.target_se.unwrap_or(montecarlo::DEFAULT_TARGET),
                max_samples: self.max_samples,
            },
        };
        ReferenceOptions {
            samples,
            seed: self.seed,
            threads: self.threads,
            progress: !self.quiet,
            ..ReferenceOptions::default()
        }
    }
}

/// `render --mode`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RenderModeArg {
    /// Smoothly shaded radiosity, tone mapped.
    Shaded,
    /// One radiosity value per patch, tone mapped (what the browser viewer of `view --web` draws).
    Flat,
    /// One colour per patch (the mesh).
    Patches,
    /// The device's converged f32 answer on a table (`--table`, or one baked at default settings), false-coloured
    /// by its relative error against the exact f64 answer, with a legend.
    Error,
}

/// Options shared by the commands that read a scene. The meshing options (`--no-subdivide`, `--max-patch-edge`,
/// `--max-patches`) shape the flat solve's mesh; in `solve`, `render`, `lightmap` and `export`, whose default is
/// the hierarchy, giving one selects the flat solve.
#[derive(Args)]
pub struct SceneArgs {
    /// The scene: an OBJ file (its MTL files are read too) or a glTF 2.0 file (.gltf with its buffers and
    /// images, or .glb); an optional NAME.toml beside it is read too.
    pub scene: PathBuf,
    /// One patch per face polygon: with `--no-repair` (and no non-planar face before it) patch k is face k,
    /// so results can be checked against hand computations; the `face` column maps patches to faces always.
    #[arg(long)]
    pub no_subdivide: bool,
    /// Longest patch edge after uniform subdivision, in scene units (default: the scene's TOML, or 1/8 of its
    /// extent).
    #[arg(long, value_name = "LENGTH")]
    pub max_patch_edge: Option<f64>,
    /// Most patches the mesh may have, at most 16384 (default: the scene's TOML, or 4096).
    #[arg(long, value_name = "N")]
    pub max_patches: Option<usize>,
    /// Mesh the faces as loaded: no cuts where faces touch or pass through each other, no culling of what no
    /// point can see (by default each changed face is reported on stderr, by OBJ line or glTF face index).
    #[arg(long)]
    pub no_repair: bool,
    /// Sample points on each patch for the form-factor integral (1 to 1024; default 16, and 4 for the
    /// hierarchy's f64 answers of `solve`, `render`, `lightmap` and `export`, whose links need less).
    #[arg(long, value_name = "N")]
    pub samples: Option<usize>,
    /// Occlusion rays per patch pair (1 to 16384).
    #[arg(long, value_name = "N", default_value_t = FormFactorOptions::default().rays_per_pair)]
    pub rays: usize,
    /// Seed of the form-factor sampling; equal seeds give identical results on any thread count.
    #[arg(long, default_value_t = FormFactorOptions::default().seed)]
    pub seed: u64,
    /// Worker threads, at most 1024 (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// No progress bar or stage summaries on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

impl SceneArgs {
    /// Whether a meshing option asks for the flat solve's adaptive mesh (`--no-subdivide`, `--max-patches`,
    /// `--max-patch-edge`; the hierarchy subdivides where its epsilon asks instead).
    pub fn asks_for_a_mesh(&self) -> bool {
        self.no_subdivide || self.max_patches.is_some() || self.max_patch_edge.is_some()
    }

    /// The pipeline options these arguments select.
    pub fn prepare_options(&self) -> PrepareOptions {
        PrepareOptions {
            no_subdivide: self.no_subdivide,
            max_patch_edge: self.max_patch_edge,
            max_patches: self.max_patches,
            repair: !self.no_repair,
            form_factors: FormFactorOptions {
                samples_per_patch: self.samples.unwrap_or(FormFactorOptions::default().samples_per_patch),
                rays_per_pair: self.rays,
                seed: self.seed,
                progress: !self.quiet,
                threads: self.threads,
                ..FormFactorOptions::default()
            },
            verbose: !self.quiet,
        }
    }
}
