//! `radiosity check`: run the device solver on a baked table and trace its error to its sources.
//!
//! The device path is run exactly as firmware runs it: [`radiosity_core::Table::parse`] on the baked bytes,
//! [`radiosity_core::Solver`] in buffers of [`radiosity_core::BufferSizes::of`] the table, and every frame
//! through the firmware's own frame function, [`firmware_sim::device::run_frame`]: the light groups whose
//! intensity changed are set ([`radiosity_core::Solver::set_light`], warm start), then one step of shooting
//! with a fixed budget of work units. Every frame's radiosity is compared with the exact f64 answer for that frame's light intensities:
//! the transfer vectors of the scene's own (unsparsified, unquantized) form-factor matrix, relit
//! (`B = B_static + sum_g I_g T_g`). Metrics are [`crate::metrics::compare`] (area-weighted relative L2, max per-patch
//! relative error with its dark-patch floor, luminance).
//!
//! # Error decomposition
//! Each component compares two answers that differ in one step only, all at the scene's default intensities
//! (the f64 ones are [`crate::evaluate`]'s, solved once):
//!
//! | component | answer | against |
//! |---|---|---|
//! | discretization (optional) | f64 solve, averaged per face | continuous path-traced reference ([`crate::montecarlo`]), with its standard error |
//! | form-factor estimation | f64 solve, matrix at the chosen samples/rays | f64 solve, matrix at `ff_factor` times both |
//! | reciprocity | f64 solve, shooting form of the full matrix | f64 solve of the full matrix |
//! | sparsification | f64 solve, shooting form of the sparsified matrix | f64 solve, shooting form of the full matrix |
//! | quantization | f64 solve of the decoded table (decoded form factors, reflectances, emission, f32 areas) | the sparsified f64 solve above |
//! | iteration truncation | device (f32) after `frames` frames of `budget` units, cold start | device (f32) converged, same table |
//! | arithmetic (f32, fixed) | device converged | f64 solve of the decoded table |
//!
//! Under the quantization component the report splits it by code ([`crate::evaluate::Evaluation::quantization_parts`]):
//! the decoded form factors alone (the scene's reflectances and emission), against the sparsified answer, and
//! the reflectance, emission and static-base codes, against that. The two need not add up (norms), but say
//! which code to widen: a light's emission rounded by the emission code's `2^-11` moves every patch it lights
//! by that much, whatever the form-factor codes do.
//!
//! The discretization component ([`CheckOptions::continuous`], `check --continuous`) judges the mesh rather
//! than the table: the exact answer is exact for its mesh only. It is off by default (its path tracing costs
//! seconds); the report then lists, per face, the mesh answer, the reference, their relative difference and the
//! reference's standard error ([`crate::evaluate::Discretization`]).
//!
//! The components telescope: device minus exact is the sum of the differences of arithmetic, quantization,
//! sparsification and reciprocity (plus iteration truncation when frames are limited), so by the triangle
//! inequality the device's error is at most the sum of those components (each relative to its own reference,
//! which differ from the exact answer by no more than the components themselves).
//!
//! A table already baked is checked with [`check_table`] (`radiosity check TABLE.rft --scene SCENE.obj`):
//! the table is matched to the scene first ([`match_scene`]); see there which components it can separate.
//!
//! # Hierarchical tables
//! [`check_hierarchical`] (`radiosity check --method hierarchical`) bakes a hierarchical solution into a
//! hierarchical table (format version 5, [`crate::bake::bake_hierarchy`]) and runs core's hierarchical solver on
//! it through the same frame loop (the elements are the table's leaves). Every frame is compared with the
//! hierarchical f64 solve relit at the frame's intensities ([`crate::hierarchy::HierarchicalSolution::transfer`]),
//! and the components follow the table's steps instead of the flat table's:
//!
//! | component | answer | against |
//! |---|---|---|
//! | discretization (optional) | hierarchical f64 solve, averaged per face | continuous path-traced reference |
//! | hierarchy (links), up to [`crate::reference::MAX_DENSE_PATCHES`] leaves | hierarchical f64 solve | dense f64 solve of the same leaves ([`crate::hierarchy::dense_on_leaves`]) |
//! | table closure | f64 solve of the table's system (the bake's chain cap, or a closed scene's self-links) | hierarchical f64 solve |
//! | quantization | f64 solve of the decoded table ([`crate::bake::BakedHierarchy::decoded_radiosity`]) | f64 solve of the table's system |
//! | iteration truncation, arithmetic | as above | as above |
//!
//! Device minus hierarchical answer telescopes through closure, quantization and arithmetic (plus truncation);
//! the links' component is what the hierarchy itself gets wrong on its own leaves, the discretization what its
//! leaves get wrong against the scene. There is no form-factor estimation or sparsification component: the
//! refinement's leaves depend on its estimates (a finer estimate makes another tree), and a hierarchical table
//! keeps every link.
//!
//! The shooting form (`F~_ij = A_j F_ji / A_i`, [`crate::bake::shooting_form`]) is what shooting with stored rows
//! converges to, so the sparsification and quantization components use it on both sides. The "f64 solve of the
//! decoded table" is what the device converges to ([`crate::bake::Decoded::solution`]): with a solved static base, the
//! decoded base `E_s + rho G_s` (its codes: emission code `2^-11` relative) plus the f64 response to the light
//! groups on the decoded rows, so patches without run-time state get their base. The arithmetic component also
//! holds the solver's stopping tolerance. "Converged" means [`radiosity_core::Outcome::Converged`] at
//! the tolerance [`CheckOptions::tolerance`] times the largest per-channel emitted power.

mod device;
mod hier;
mod report;
mod table;

use std::path::Path;

use firmware_sim::sim::Arith;
use radiosity_core::FfCodec;
use thiserror::Error;

pub use device::device_converged;
pub use hier::{check_hierarchical, HIERARCHY_LINKS, TABLE_CLOSURE};
pub use report::{CheckReport, Frame, Setting};
pub use table::{check_table, check_table_file, form_factor_distance, match_scene, WRONG_SCENE_FRACTION};

use crate::bake::{
    bake, codec_for_bits, BakeError, BakeInput, BakeOptions, DEFAULT_ROW_SUM_TOLERANCE, DEFAULT_THRESHOLD,
};
use crate::evaluate::Discretization;
use crate::evaluate::{self, evaluate, EvaluateError, EvaluateOptions};
use crate::metrics::MetricsError;
use crate::montecarlo::{continuous_reference, validate_options, MonteCarloError, ReferenceOptions};
use crate::pipeline::{prepare, PipelineError, PrepareOptions, Prepared};
use crate::reference::{exact_transfer, Method, Radiosity, ReferenceError, TransferVectors};
use crate::rgb::Rgb;
use device::{device_part, Answers, DeviceTable};

/// Settings of a check.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckOptions {
    /// Form-factor code width, 16 or 8 ([`codec_for_bits`]); ignored when [`CheckOptions::codec`] is set.
    pub bits: u32,
    /// A codec to bake with in place of the one `bits` selects (any valid [`FfCodec`], e.g.
    /// [`FfCodec::LINEAR8`]; the quantization regression uses this to degrade a codec on purpose).
    pub codec: Option<FfCodec>,
    /// Sparsification threshold ([`BakeOptions::threshold`]).
    pub threshold: f64,
    /// Work units per frame.
    pub budget: u32,
    /// Frames per light setting; `None` runs each setting to convergence (at most [`MAX_FRAMES`] frames).
    pub frames: Option<usize>,
    /// Arithmetic paths to run, in report order ([`Arith::ALL`] for both).
    pub arith: Vec<Arith>,
    /// After the default lighting, relight: all dynamic groups to 0, back to default, then to the colour
    /// `(1, 0.2, 0.2)` times default.
    pub relight: bool,
    /// Solver tolerance as a fraction of the largest per-channel emitted power `sum_i E_i A_i`.
    pub tolerance: f64,
    /// When the fixed-point path runs and [`CheckOptions::tolerance`] is below fixed point's convergence floor
    /// for the table (Q32.32 rounds every receipt: core's `convergence_floor`), raise it to that floor for both
    /// paths (the report says so, [`CheckReport::tolerance_raised`]) instead of refusing. The command line sets
    /// it when `--tolerance` is not given.
    pub tolerance_floor: bool,
    /// The form-factor estimation component's reference uses this many times the samples and the rays.
    pub ff_factor: usize,
    /// Slack on row sums of the shooting form above 1 in the f64 solves ([`BakeOptions::row_sum_tolerance`]).
    pub row_sum_tolerance: f64,
    /// Add the discretization component: the continuous reference with these settings (`None`: skip it).
    pub continuous: Option<ReferenceOptions>,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            bits: 16,
            codec: None,
            threshold: DEFAULT_THRESHOLD,
            budget: 20_000,
            frames: None,
            arith: Arith::ALL.to_vec(),
            relight: false,
            tolerance: 1e-6,
            tolerance_floor: true,
            ff_factor: 4,
            row_sum_tolerance: DEFAULT_ROW_SUM_TOLERANCE,
            continuous: None,
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
    Pipeline(#[from] PipelineError),
    /// The bake failed.
    #[error(transparent)]
    Bake(#[from] BakeError),
    /// The evaluation's f64 answers failed.
    #[error(transparent)]
    Evaluate(#[from] EvaluateError),
    /// A frame's error could not be computed (e.g. a non-finite device answer).
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// The device solver rejected the table or a light change.
    #[error("device solver ({arith}): {error}")]
    Solver {
        /// Arithmetic path.
        arith: &'static str,
        /// Core's error.
        error: radiosity_core::SolverError,
    },
    /// Bad options.
    #[error("bad option: {0}")]
    Options(String),
    /// The continuous reference of the discretization component failed (or its options are bad).
    #[error(transparent)]
    MonteCarlo(#[from] MonteCarloError),
    /// The dense answer of a hierarchy's leaves (its links' component) failed.
    #[error(transparent)]
    Dense(#[from] crate::hierarchy::DenseError),
    /// The table file could not be read.
    #[error("reading table {path}: {message}")]
    ReadTable {
        /// The table file.
        path: std::path::PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// The table does not parse (damaged, truncated, another format version).
    #[error("table {path}: {error}")]
    BadTable {
        /// The table file.
        path: std::path::PathBuf,
        /// Core's parser error.
        error: radiosity_core::TableError,
    },
    /// The table was not baked from this scene (or with other meshing options).
    #[error("table {table} does not belong to scene {scene}: {detail}")]
    WrongScene {
        /// The table file.
        table: std::path::PathBuf,
        /// The scene file.
        scene: std::path::PathBuf,
        /// The first difference found ([`match_scene`]).
        detail: String,
    },
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
    check_options(options)?;
    let p = prepare(path, prepare_options)?;
    check(&p, prepare_options, options)
}

/// Checks every option that needs no computation (`check_scene`, `check_table_file` and `check_hierarchical`
/// call it first, so a bad option is reported at once; `radiosity check` before it reads the scene to choose
/// its table).
///
/// # Errors
/// [`CheckError::Options`] (or the bake's or reference's error) naming the option.
pub fn check_options(options: &CheckOptions) -> Result<(), CheckError> {
    if options.codec.is_none() {
        codec_for_bits(options.bits)?;
    }
    if !(0.0..1.0).contains(&options.threshold) {
        return Err(BakeError::BadThreshold(options.threshold).into());
    }
    if options.frames.is_some_and(|f| f > MAX_FRAMES) {
        return Err(CheckError::Options(format!(
            "--frames {} is more than {MAX_FRAMES}",
            options.frames.unwrap_or(0)
        )));
    }
    crate::limits::check_count(
        "--ff-factor",
        options.ff_factor,
        crate::limits::MAX_FF_FACTOR,
        "the reference \
        matrix costs that many times the samples and rays",
    )
    .map_err(|e| CheckError::Options(e.to_string()))?;
    if !(options.row_sum_tolerance.is_finite() && options.row_sum_tolerance >= 0.0) {
        return Err(CheckError::Options(format!(
            "--row-sum-tolerance {} must be finite and >= 0",
            options.row_sum_tolerance
        )));
    }
    if options.budget == 0 {
        return Err(CheckError::Options("--budget must be at least 1 work unit".into()));
    }
    if !(options.tolerance > 0.0 && options.tolerance < 1.0) {
        return Err(CheckError::Options(format!("tolerance {} not in (0, 1)", options.tolerance)));
    }
    if options.frames == Some(0) {
        return Err(CheckError::Options("--frames must be at least 1".into()));
    }
    if options.arith.is_empty() {
        return Err(CheckError::Options("no arithmetic path to run".into()));
    }
    if let Some(continuous) = &options.continuous {
        validate_options(continuous)?;
    }
    Ok(())
}

/// How a check solves its f64 answers: dense LU up to [`crate::reference::MAX_DENSE_PATCHES`] patches
/// ([`Method::for_size`]), at the check's row-sum slack.
fn evaluation_options(p: &Prepared, options: &CheckOptions) -> EvaluateOptions {
    EvaluateOptions {
        method: Method::for_size(p.patches.len()),
        row_sum_tolerance: options.row_sum_tolerance,
    }
}

/// The exact transfer vectors of the scene's matrix, which every frame is compared with (relit at the frame's
/// intensities).
fn exact_transfer_of(p: &Prepared, options: &EvaluateOptions) -> Result<TransferVectors, CheckError> {
    exact_transfer(&p.lighting, &p.form_factors, &options.method)
        .map_err(|source: ReferenceError| EvaluateError::Reference { what: "exact transfer", source }.into())
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
    check_options(options)?;
    let codec = match options.codec {
        Some(c) => c,
        None => codec_for_bits(options.bits)?,
    };
    let bake_options = BakeOptions {
        threshold: options.threshold,
        codec,
        row_sum_tolerance: options.row_sum_tolerance,
        ..BakeOptions::default()
    };
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &bake_options)?;
    let eval_options = evaluation_options(p, options);
    let exact = exact_transfer_of(p, &eval_options)?;
    let evaluation = evaluate(&input, &baked, &eval_options)?;
    let discretization = discretization_part(p, &evaluation.reference, options)?;
    let mut components: Vec<_> = discretization.iter().map(|d| d.component.clone()).collect();
    if options.ff_factor > 1 {
        components.push(evaluate::form_factor_estimation(
            p,
            prepare_options,
            options.ff_factor,
            &evaluation.reference,
            &eval_options,
        )?);
    }
    components.extend(evaluation.components.iter().cloned());
    let table = radiosity_core::Table::parse(&baked.table)
        .map_err(|error| CheckError::BadTable { path: "<baked>".into(), error })?;
    let answers = Answers {
        exact: &exact,
        default_intensity: &p.lighting.default_intensity,
        exact_is: EXACT_FLAT,
        max_power: max_power(&evaluation.decoded.emission, &evaluation.decoded.area),
        device: &evaluation.device,
        area: &evaluation.area,
        light_groups: &dynamic_group_names(p),
    };
    let report = device_part(DeviceTable::Flat(&table), baked.table.len(), &answers, options, components)?;
    Ok(CheckReport { discretization, quantization_parts: evaluation.quantization_parts.clone(), ..report })
}

/// What a flat check compares every frame with.
const EXACT_FLAT: &str = "exact f64 (scene matrix, transfer vectors relit)";

/// The largest per-channel power of `emission` (W/m^2) over elements of `area`: what
/// [`CheckOptions::tolerance`] is relative to.
fn max_power(emission: &[Rgb], area: &[f64]) -> f64 {
    (0..3).map(|c| emission.iter().zip(area).map(|(e, a)| e[c] * a).sum::<f64>()).fold(0.0, f64::max)
}

/// Names of the dynamic light groups of `p`, in table order.
fn dynamic_group_names(p: &Prepared) -> Vec<String> {
    p.lighting.dynamic_groups.iter().map(|&g| p.scene.light_groups[g].name.clone()).collect()
}

/// The discretization component of `p`, whose exact answer is `reference`, if `options` ask for it.
fn discretization_part(
    p: &Prepared,
    reference: &Radiosity,
    options: &CheckOptions,
) -> Result<Option<Discretization>, CheckError> {
    let Some(settings) = &options.continuous else { return Ok(None) };
    let continuous = continuous_reference(&p.scene, settings)?;
    Ok(Some(evaluate::discretization(&p.patches, reference, &continuous)?))
}
