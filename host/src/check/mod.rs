//! `radiosity check`: run the device solver on a baked table and trace its error to its sources.
//!
//! The device path is run exactly as firmware runs it: [`radiosity_core::Table::parse`] on the baked bytes,
//! [`radiosity_core::Solver`] in buffers of [`radiosity_core::BufferSizes::of`] the table, and every frame
//! through the firmware's own frame function, [`firmware_sim::device::run_frame`]: the light groups whose
//! intensity changed are set ([`radiosity_core::Solver::set_light`], warm start), then one step of shooting
//! with a fixed budget of work units. Every frame's radiosity is compared with the exact f64 answer for that frame's light intensities:
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
//! | reciprocity | f64 solve, shooting form of the full matrix | f64 solve of the full matrix |
//! | sparsification | f64 solve, shooting form of the sparsified matrix | f64 solve, shooting form of the full matrix |
//! | quantization | f64 solve of the decoded table (decoded form factors, reflectances, emission, f32 areas) | the sparsified f64 solve above |
//! | iteration truncation | device (f32) after `frames` frames of `budget` units, cold start | device (f32) converged, same table |
//! | arithmetic (f32, fixed) | device converged | f64 solve of the decoded table |
//!
//! The components telescope: device minus exact is the sum of the differences of arithmetic, quantization,
//! sparsification and reciprocity (plus iteration truncation when frames are limited), so by the triangle
//! inequality the device's error is at most the sum of those components (each relative to its own reference,
//! which differ from the exact answer by no more than the components themselves).
//!
//! A table already baked is checked with [`check_table`] (`radiosity check TABLE.rft --scene SCENE.obj`):
//! the table is matched to the scene first ([`match_scene`]); see there which components it can separate.
//!
//! The shooting form (`F~_ij = A_j F_ji / A_i`, [`bake::shooting_form`]) is what shooting with stored rows
//! converges to, so the sparsification and quantization components use it on both sides. The "f64 solve of the
//! decoded table" is what the device converges to ([`bake::Decoded::solution`]): with a solved static base, the
//! decoded base `E_s + rho G_s` (its codes: emission code `2^-11` relative) plus the f64 response to the light
//! groups on the decoded rows, so patches without run-time state get their base. The arithmetic component also
//! holds the solver's stopping tolerance. "Converged" means [`radiosity_core::Outcome::Converged`] at
//! the tolerance [`CheckOptions::tolerance`] times the largest per-channel emitted power.

use std::fmt;
use std::path::Path;

use firmware_sim::device::{self, RunError};
use radiosity_core::{Config, FfCodec, Fixed, Outcome, OwnedBuffers, Scalar, Solver, Table};
use serde::Serialize;
use thiserror::Error;

use crate::bake::{self, bake, codec_for_bits, BakeInput, BakeOptions};
use crate::formfactor::compute_form_factors;
use crate::metrics::{self, ErrorReport};
use crate::patch::FormFactorMatrix;
use crate::pipeline::{prepare, PrepareOptions, Prepared};
use crate::reference::{exact_transfer, solve_many, Method, Radiosity, RadiositySystem, TransferVectors};

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
            codec: None,
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

impl CheckReport {
    /// The error decomposition as stacked bars: one bar per arithmetic path (`f32`, `fixed`), one segment per
    /// component (relative L2 of `B`, area-weighted), the path's own arithmetic component on top. The shared
    /// components (form-factor estimation, sparsification, quantization, ...) appear in every bar.
    #[must_use]
    pub fn decomposition_plot(&self, title: &str) -> crate::picture::plot::Plot {
        let arith: Vec<String> = self
            .components
            .iter()
            .filter_map(|c| c.name.strip_prefix("arithmetic (").and_then(|r| r.strip_suffix(')')))
            .map(str::to_string)
            .collect();
        let mut components: Vec<(String, Vec<f64>)> = self
            .components
            .iter()
            .filter(|c| !c.name.starts_with("arithmetic ("))
            .map(|c| (c.name.clone(), vec![c.error.rel_l2; arith.len()]))
            .collect();
        let own: Vec<f64> = arith
            .iter()
            .map(|a| {
                let name = format!("arithmetic ({a})");
                self.components.iter().find(|c| c.name == name).map_or(0.0, |c| c.error.rel_l2)
            })
            .collect();
        components.push(("arithmetic".into(), own));
        crate::picture::plot::Plot::StackedBars {
            title: title.into(),
            y_label: "relative L2 error of B (area-weighted)".into(),
            categories: arith,
            components,
        }
    }
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

fn check_options(options: &CheckOptions) -> Result<(), CheckError> {
    if options.budget == 0 {
        return Err(CheckError::Options("--budget must be at least 1 work unit".into()));
    }
    if !(options.tolerance > 0.0 && options.tolerance < 1.0) {
        return Err(CheckError::Options(format!("tolerance {} not in (0, 1)", options.tolerance)));
    }
    if options.frames == Some(0) {
        return Err(CheckError::Options("--frames must be at least 1".into()));
    }
    Ok(())
}

/// The scene-side answers every check compares with.
struct SceneAnswers {
    area: Vec<f64>,
    method: Method,
    row_sum_tolerance: f64,
    e_default: Vec<[f64; 3]>,
    tv: TransferVectors,
}

impl SceneAnswers {
    fn new(p: &Prepared, options: &CheckOptions) -> Result<SceneAnswers, CheckError> {
        let l = &p.lighting;
        let method = Method::for_size(p.patches.len());
        let tv = exact_transfer(l, &p.form_factors, &method)?;
        Ok(SceneAnswers {
            area: p.patches.iter().map(|q| q.area).collect(),
            method,
            row_sum_tolerance: options.row_sum_tolerance,
            e_default: l.default_emission(),
            tv,
        })
    }

    /// f64 solve of `B = E + R F B`.
    fn solve(
        &self,
        rho: &[[f64; 3]],
        ff: &FormFactorMatrix,
        e: &[[f64; 3]],
    ) -> Result<Radiosity, CheckError> {
        let system = RadiositySystem::with_row_sum_tolerance(rho, ff, self.row_sum_tolerance)?;
        let mut s = solve_many(system, &[e], &self.method)?;
        Ok(s.pop().map(|s| s.b).unwrap_or_default())
    }
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
    let l = &p.lighting;
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
    let baked = bake(&BakeInput::from_scene(&p.scene, &p.patches, l, &p.form_factors), &bake_options)?;
    let table = Table::parse(&baked.table).map_err(CheckError::Table)?;
    let answers = SceneAnswers::new(p, options)?;
    let area = &answers.area;
    let e_default = &answers.e_default;

    let mut components = Vec::new();
    // 1. Form-factor estimation.
    let b_full = answers.solve(&l.rho, &p.form_factors, e_default)?;
    if options.ff_factor > 1 {
        let mut ffo = prepare_options.form_factors.clone();
        ffo.samples_per_patch *= options.ff_factor;
        ffo.rays_per_pair *= options.ff_factor;
        ffo.progress = false;
        let (mut hi, _) = compute_form_factors(&p.patches, &ffo)
            .map_err(|e| CheckError::FormFactors(options.ff_factor, e.to_string()))?;
        hi.enforce_reciprocity(area);
        hi.clamp_rows_to_one();
        let b_hi = answers.solve(&l.rho, &hi, e_default)?;
        components.push(Component {
            name: FORM_FACTOR_ESTIMATION.into(),
            compares: format!(
                "f64, matrix at {} samples/{} rays vs at {} samples/{} rays",
                prepare_options.form_factors.samples_per_patch,
                prepare_options.form_factors.rays_per_pair,
                ffo.samples_per_patch,
                ffo.rays_per_pair
            ),
            error: metrics::compare(&b_full, &b_hi, area)?,
        });
    }
    // 2. Reciprocity: what shooting with stored rows converges to, against the scene's matrix.
    let b_full_shoot = answers.solve(&l.rho, &bake::shooting_form(&p.form_factors, area), e_default)?;
    components.push(Component {
        name: RECIPROCITY.into(),
        compares: "f64, shooting form A_j F_ji / A_i of the full matrix vs the full matrix".into(),
        error: metrics::compare(&b_full_shoot, &b_full, area)?,
    });
    // 3. Sparsification.
    let b_sparse = answers.solve(&l.rho, &bake::shooting_form(&baked.sparse.matrix, area), e_default)?;
    components.push(Component {
        name: SPARSIFICATION.into(),
        compares: format!("f64, sparsified (threshold {}) vs full matrix, shooting form", options.threshold),
        error: metrics::compare(&b_sparse, &b_full_shoot, area)?,
    });
    // 4. Quantization.
    let dec = crate::bake::decode_table(&table);
    let b_dec =
        dec.solution(answers.solve(&dec.rho, &bake::shooting_form(&dec.rows, &dec.area), &dec.rhs)?);
    components.push(Component {
        name: QUANTIZATION.into(),
        compares: format!("f64, decoded {} table vs sparsified f64 matrix", table.codec()),
        error: metrics::compare(&b_dec, &b_sparse, area)?,
    });
    device_part(p, &table, baked.table.len(), &answers, &dec, &b_dec, options, components)
}

/// Reads the table at `table_path`, prepares the scene at `scene_path` and checks the table against it (see
/// [`check_table`]).
///
/// # Errors
/// [`CheckError::ReadTable`] if the file cannot be read, [`CheckError::BadTable`] if it does not parse, and
/// everything [`check_table`] returns.
pub fn check_table_file(
    table_path: &Path,
    scene_path: &Path,
    prepare_options: &PrepareOptions,
    options: &CheckOptions,
) -> Result<CheckReport, CheckError> {
    let bytes = std::fs::read(table_path)
        .map_err(|e| CheckError::ReadTable { path: table_path.into(), message: e.to_string() })?;
    // Parse first: a damaged table is reported before the (slower) scene preparation.
    Table::parse(&bytes).map_err(|error| CheckError::BadTable { path: table_path.into(), error })?;
    let p = prepare(scene_path, prepare_options)?;
    check_table(&bytes, &p, options).map_err(|e| match e {
        CheckError::WrongScene { detail, .. } => {
            CheckError::WrongScene { table: table_path.into(), scene: scene_path.into(), detail }
        }
        e => e,
    })
}

/// Checks an existing table (bytes of an `.rft`) against the prepared scene it was baked from.
///
/// The table is first matched with the scene ([`match_scene`]); a table baked from another scene, or with other
/// meshing options, is a [`CheckError::WrongScene`]. The decomposition then has the components that the table
/// alone allows plus one that needs the scene's matrix:
///
/// | component | answer | against |
/// |---|---|---|
/// | table vs scene matrix | f64 solve of the decoded table | f64 solve of the scene's matrix (this run's estimate) |
/// | iteration truncation | as [`check`] | |
/// | arithmetic (f32, fixed) | as [`check`] | |
///
/// The first one holds sparsification, quantization, reciprocity and the difference between the bake's
/// form-factor estimate and this run's (equal when the sample counts and seed match the bake's); separating
/// them needs the bake's unsparsified f64 matrix, which the table does not keep, so for the separate
/// components bake again (`radiosity check SCENE`). [`CheckOptions::bits`], `codec` and `threshold` are the
/// table's own here and ignored; `ff_factor` is not used.
///
/// # Errors
/// [`CheckError::BadTable`] for bytes that do not parse, [`CheckError::WrongScene`] for a table of another
/// scene, and the errors of [`check`].
pub fn check_table(bytes: &[u8], p: &Prepared, options: &CheckOptions) -> Result<CheckReport, CheckError> {
    check_options(options)?;
    let table =
        Table::parse(bytes).map_err(|error| CheckError::BadTable { path: "<bytes>".into(), error })?;
    match_scene(&table, p).map_err(|detail| CheckError::WrongScene {
        table: "<table>".into(),
        scene: p.scene.path.clone(),
        detail,
    })?;
    let answers = SceneAnswers::new(p, options)?;
    let dec = crate::bake::decode_table(&table);
    let b_dec =
        dec.solution(answers.solve(&dec.rho, &bake::shooting_form(&dec.rows, &dec.area), &dec.rhs)?);
    let b_full = answers.solve(&p.lighting.rho, &p.form_factors, &answers.e_default)?;
    let components = vec![Component {
        name: TABLE_VS_SCENE.into(),
        compares:
            "f64, decoded table vs the scene's f64 matrix (sparsification + quantization + reciprocity \
                   + estimate differences)"
                .into(),
        error: metrics::compare(&b_dec, &b_full, &answers.area)?,
    }];
    device_part(p, &table, bytes.len(), &answers, &dec, &b_dec, options, components)
}

/// Whether `table` was baked from the patches of `p`; on a mismatch, the first difference found.
///
/// Compared, in order: patch count, material count, dynamic light group count, every patch's area (the table
/// stores f32, so equal means within `2^-23` relative, twice f32's rounding), every patch's material, every
/// material's reflectance code (the code the writer makes of the scene's `Kd`), every group's id (FNV-1a of
/// its name) and member patches, every patch's static emission (within the emission code's `2^-11`
/// relative rounding, [`radiosity_core::codec`]), and the form factors themselves: more than
/// [`WRONG_SCENE_FRACTION`] of the transported energy on other receivers is another geometry.
///
/// # Errors
/// A sentence naming the first difference, the patch, material or group, and both values.
pub fn match_scene(table: &Table<'_>, p: &Prepared) -> Result<(), String> {
    use radiosity_core::codec::{decode_emission_f32, encode_reflectance};
    let l = &p.lighting;
    let (n_t, n_s) = (table.patch_count() as usize, p.patches.len());
    if n_t != n_s {
        return Err(format!(
            "the table has {n_t} patches, the scene meshes into {n_s} (a different scene, or meshing options \
             other than the bake's: --no-subdivide, --max-patch-edge, --max-patches)"
        ));
    }
    let (m_t, m_s) = (table.material_count() as usize, p.scene.materials.len());
    if m_t != m_s {
        return Err(format!("the table has {m_t} materials, the scene {m_s}"));
    }
    let (g_t, g_s) = (table.group_count() as usize, l.dynamic_groups.len());
    if g_t != g_s {
        return Err(format!("the table has {g_t} dynamic light groups, the scene {g_s}"));
    }
    for (i, q) in p.patches.iter().enumerate() {
        let a = f64::from(table.area(i as u32).unwrap_or(f32::NAN));
        let within = (a - q.area).abs() <= q.area * f64::from(f32::EPSILON);
        if !within {
            return Err(format!(
                "patch {i} (face {}): area {a} in the table, {} in the scene",
                q.face, q.area
            ));
        }
        let m = table.material(i as u32).map_or(usize::MAX, |m| m as usize);
        if m != q.material {
            return Err(format!(
                "patch {i} (face {}): material {m} in the table, {} (`{}`) in the scene",
                q.face, q.material, p.scene.materials[q.material].name
            ));
        }
        let e_t = table.base_emission(i as u32).unwrap_or([u16::MAX; 3]).map(decode_emission_f32);
        for (c, (&t, &s)) in e_t.iter().zip(&l.static_emission[i]).enumerate() {
            let t = f64::from(t);
            let within = (t - s).abs() <= s * 2f64.powi(-11) + 2f64.powi(-41);
            if !within {
                return Err(format!(
                    "patch {i} (face {}): static emission {t} in the table, {s} in the scene (channel {c})",
                    q.face
                ));
            }
        }
    }
    for (k, mat) in p.scene.materials.iter().enumerate() {
        let want = mat.reflectance.map(|r| encode_reflectance(r as f32));
        let got = table.reflectance(k as u32).unwrap_or([u16::MAX; 3]);
        if want != got {
            let dec = got.map(|c| f64::from(c) / 65536.0);
            return Err(format!(
                "material {k} (`{}`): reflectance {dec:?} in the table, {:?} in the scene",
                mat.name, mat.reflectance
            ));
        }
    }
    // Form factors: a table of the same scene differs from this run's matrix by sparsification (at most the
    // fraction `t` of a row, 1e-3 by default), quantization (< 2^-5 of an entry at 8 bits) and the difference
    // between two Monte Carlo estimates (a few percent of a row at the default ray counts); another geometry
    // with the same patch attributes (facing vs perpendicular squares) sends a row's energy to other receivers,
    // which moves about twice the row sum. Half the transported energy separates the two cases by a factor of
    // about ten on either side.
    let fraction = form_factor_distance(table, p);
    if fraction > WRONG_SCENE_FRACTION {
        return Err(format!(
            "the table's form factors differ from the scene's by {:.1}% of the transported energy \
             (area-weighted sum of |F_table - F_scene| over all rows; a table of this scene differs by a few \
             percent at most): same patch counts, areas and materials, but other geometry",
            100.0 * fraction
        ));
    }
    for (g, &sg) in l.dynamic_groups.iter().enumerate() {
        let name = &p.scene.light_groups[sg].name;
        let id = table.group_id(g as u32).unwrap_or(0);
        if id != bake::group_id(name) {
            return Err(format!(
                "dynamic light group {g}: id {id:#010x} in the table, {:#010x} (`{name}`) in the scene",
                bake::group_id(name)
            ));
        }
        let members: Vec<u32> = table
            .group_members(g as u32)
            .unwrap_or(0..0)
            .filter_map(|k| table.member(k).map(|m| m.patch))
            .collect();
        let want: Vec<u32> = (0..n_s).filter(|&i| l.group[i] == Some(g)).map(|i| i as u32).collect();
        if members != want {
            return Err(format!(
                "dynamic light group {g} (`{name}`): {} member patches in the table, {} in the scene",
                members.len(),
                want.len()
            ));
        }
    }
    Ok(())
}

/// Runs the device paths on `table` and finishes the report (iteration truncation and arithmetic components).
#[allow(clippy::too_many_arguments)]
fn device_part(
    p: &Prepared,
    table: &Table<'_>,
    table_bytes: usize,
    answers: &SceneAnswers,
    dec: &bake::Decoded,
    b_dec: &Radiosity,
    options: &CheckOptions,
    mut components: Vec<Component>,
) -> Result<CheckReport, CheckError> {
    let l = &p.lighting;
    let n = p.patches.len();
    let area = &answers.area;
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
    let exact: Vec<Vec<[f64; 3]>> =
        schedule.iter().map(|s| answers.tv.relight(s)).collect::<Result<_, _>>()?;
    let run = Run { table, area, schedule: &schedule, exact: &exact, options };
    let mut settings = Vec::new();
    let mut frames = Vec::new();
    let paths: &[&'static str] = match options.arith {
        Arith::F32 => &["f32"],
        Arith::Fixed => &["fixed"],
        Arith::Both => &["f32", "fixed"],
    };
    if paths.contains(&"fixed") {
        let floor = f64::from(radiosity_core::convergence_floor::<Fixed>(table).to_f32());
        if tolerance < floor {
            return Err(CheckError::Options(format!(
                "--tolerance {} ({tolerance:.3e} power units) is below fixed point's convergence floor for this \
                 table ({floor:.3e} power units: Q32.32 rounds every receipt, see core's `convergence_floor`); use \
                 --tolerance {:.1e} or more, or --arith f32",
                options.tolerance,
                (floor / max_power * 1.01).max(f64::MIN_POSITIVE)
            )));
        }
    }
    for &path in paths {
        let (converged, truncated) = if path == "f32" {
            run.device::<f32>(path, tolerance, &mut settings, &mut frames)?
        } else {
            run.device::<Fixed>(path, tolerance, &mut settings, &mut frames)?
        };
        if path == "f32" {
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
            name: format!("arithmetic ({path})"),
            compares: format!("{path} converged vs f64 solve of the decoded table"),
            error: metrics::compare(&converged, b_dec, area)?,
        });
    }
    Ok(CheckReport {
        patches: n,
        entries: table.entry_count() as usize,
        table_bytes,
        codec: table.codec().to_string(),
        budget: options.budget,
        frames_per_setting: options.frames,
        tolerance,
        components,
        settings,
        frames,
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
    let n = table.patch_count() as usize;
    let mut store = OwnedBuffers::<S>::for_table(table);
    let buffers = store.buffers();
    let config =
        Config { tolerance: S::from_f32(tolerance as f32), overshoot: Config::<S>::RECOMMENDED_OVERSHOOT };
    let mut solver =
        Solver::new(table, buffers, config).map_err(|error| CheckError::Solver { arith: "device", error })?;
    loop {
        match solver.step(u32::MAX) {
            Outcome::BudgetSpent { .. } => {}
            Outcome::Converged { .. } => return Ok(Ok(radiosity(&solver, n))),
            Outcome::NoProgress { reason, .. } => return Ok(Err(reason)),
        }
    }
}

/// The area-weighted distance between the table's decoded form factors and the scene's:
/// `sum_i A_i sum_j |F_table_ij - F_scene_ij| / sum_i A_i s_i` (`s_i` the scene's row sums; rows beyond the
/// shorter of the two are ignored). Only what the table stores is compared: rows and receivers of patches with
/// run-time state (core's crate docs, "Run-time state"). See [`match_scene`].
#[must_use]
pub fn form_factor_distance(table: &Table<'_>, p: &Prepared) -> f64 {
    let dec = bake::decode_table(table);
    let (mut moved, mut total) = (0.0, 0.0);
    for i in 0..p.patches.len().min(dec.rows.n()) {
        if !dec.state[i] {
            continue;
        }
        let stored = |&(j, _): &(usize, f64)| dec.state.get(j) == Some(&true);
        let mut row: std::collections::BTreeMap<usize, f64> =
            p.form_factors.row(i).filter(stored).map(|(j, f)| (j, -f)).collect();
        let scene_sum: f64 = row.values().map(|f| -f).sum();
        for (j, f) in dec.rows.row(i) {
            *row.entry(j).or_insert(0.0) += f;
        }
        moved += p.patches[i].area * row.values().map(|d| d.abs()).sum::<f64>();
        total += p.patches[i].area * scene_sum;
    }
    if total > 0.0 {
        moved / total
    } else {
        0.0
    }
}

/// A table whose form factors differ from the scene's by more than this fraction of the transported energy
/// (area-weighted sum of `|F_table - F_scene|` over `sum_i A_i s_i`) belongs to another scene ([`match_scene`]).
pub const WRONG_SCENE_FRACTION: f64 = 0.5;

/// Component names, as they appear in reports and the regression baseline.
pub const FORM_FACTOR_ESTIMATION: &str = "form-factor estimation";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const RECIPROCITY: &str = "reciprocity";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const SPARSIFICATION: &str = "sparsification";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const QUANTIZATION: &str = "quantization";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const ITERATION_TRUNCATION: &str = "iteration truncation";
/// See [`FORM_FACTOR_ESTIMATION`] (table input only).
pub const TABLE_VS_SCENE: &str = "table vs scene matrix";

struct Run<'r> {
    table: &'r Table<'r>,
    area: &'r [f64],
    schedule: &'r [Vec<[f64; 3]>],
    exact: &'r [Vec<[f64; 3]>],
    options: &'r CheckOptions,
}

fn radiosity<S: Scalar>(solver: &Solver<'_, S>, n: usize) -> Vec<[f64; 3]> {
    (0..n as u32)
        .map(|i| solver.radiosity(i).map(|b| b.map(|v| f64::from(v.to_f32()))).unwrap_or([f64::NAN; 3]))
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
        let (table, n) = (self.table, self.area.len());
        let err = |error| CheckError::Solver { arith, error };
        let config = Config {
            tolerance: S::from_f32(tolerance as f32),
            overshoot: Config::<S>::RECOMMENDED_OVERSHOOT,
        };

        // Converged reference of this arithmetic: one unbounded step sequence, cold start.
        let converged = {
            let mut store = OwnedBuffers::<S>::for_table(table);
            let mut solver = Solver::new(table, store.buffers(), config).map_err(err)?;
            while let Outcome::BudgetSpent { .. } = solver.step(u32::MAX) {}
            radiosity(&solver, n)
        };

        let mut store = OwnedBuffers::<S>::for_table(table);
        let mut solver = Solver::new(table, store.buffers(), config).map_err(err)?;
        let mut truncated = Vec::new();
        for (s, (intensity, exact)) in self.schedule.iter().zip(self.exact).enumerate() {
            // The firmware's frame loop: groups whose intensity changed are set, then one bounded step.
            let intensity_f32: Vec<[f32; 3]> = intensity.iter().map(|rgb| rgb.map(|v| v as f32)).collect();
            let mut relight_work = 0u64;
            let limit = self.options.frames.unwrap_or(MAX_FRAMES);
            let (mut work, mut count, mut converged_now) = (0u64, 0usize, false);
            let mut last = None;
            while count < limit {
                let frame = device::Frame { budget: self.options.budget, intensity: &intensity_f32 };
                let (light_units, o) =
                    device::run_frame(&mut solver, &frame, count as u32).map_err(|e| match e {
                        RunError::Solver { error, .. } | RunError::Buffers { error } => err(error),
                        other => CheckError::Options(other.to_string()),
                    })?;
                relight_work += u64::from(light_units);
                count += 1;
                work += u64::from(o.used());
                let b = radiosity(&solver, n);
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
