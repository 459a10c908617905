//! Evaluation: how far a baked table's answers are from the exact ones, each source of error on its own.
//!
//! [`evaluate`] solves, once, the four f64 answers at the scene's default intensities that differ in one step
//! of the bake each, and compares them; the `bake` command's summary ([`BakeSummary`]), `radiosity check`
//! ([`crate::check`]) and the quantization regression ([`crate::regress`], through the check) all read the
//! same [`Evaluation`]:
//!
//! | answer | f64 solve of | field |
//! |---|---|---|
//! | exact | the scene's matrix `F` (`B = E + R F B`) | [`Evaluation::reference`] |
//! | reciprocal | the shooting form `A_j F_ji / A_i` of `F` ([`shooting_form`]) | [`Evaluation::reciprocal`] |
//! | sparsified | the shooting form of the sparsified rows | [`Evaluation::sparsified`] |
//! | decoded | everything decoded back from the table (form factors, reflectances, emission, f32 areas) | [`Evaluation::device`] |
//!
//! The shooting form is what shooting with stored rows converges to, so the sparsified and decoded answers
//! use it. The decoded answer is what the device converges to ([`Decoded::solution`]): with a solved static
//! base, the decoded base `E_s + rho G_s` (its codes: emission code `2^-11` relative) plus the f64 response to
//! the light groups on the decoded rows, so patches without run-time state get their base.
//!
//! Two views of the four answers ([`metrics::compare`]: area-weighted relative L2, max per-patch relative
//! error, luminance):
//! - [`Evaluation::errors`] ([`BakeErrors`], the bake's summary): each answer against the exact one;
//! - [`Evaluation::components`] (the decomposition of `check` and `regress`): each answer against the one a
//!   step before, so the components telescope: reciprocity (reciprocal vs exact), sparsification (sparsified vs
//!   reciprocal), quantization (decoded vs sparsified). [`form_factor_estimation`] adds the component of the
//!   form-factor estimate, [`table_vs_scene`] the one component a table without its bake allows, and
//!   [`discretization`] the one before them all: the exact answer, averaged per OBJ face, against the
//!   continuous path-traced reference ([`crate::montecarlo`]), which judges the mesh itself.
//!
//! With a transfer basis, [`Evaluation::transfer`] compares core's f32 transfer relight of the table with the
//! exact answer and with the f64 basis it was quantized from ([`TransferReport`]).

mod components;
mod discretization;
mod summary;
mod transfer;

use radiosity_core::{Table, TableError, TransferError};
use thiserror::Error;

pub use components::{
    form_factor_estimation, table_vs_scene, Component, FORM_FACTOR_ESTIMATION, ITERATION_TRUNCATION,
    QUANTIZATION, QUANTIZATION_CODES, QUANTIZATION_FORM_FACTORS, RECIPROCITY, SPARSIFICATION, TABLE_VS_SCENE,
};
pub use discretization::{discretization, Discretization, FaceDiscretization, DISCRETIZATION};
pub use summary::BakeSummary;
pub use transfer::TransferReport;

use crate::bake::{
    decode_table, decoded_row_sum_tolerance, default_method, shooting_form, solve_one, BakeInput,
    BakeOptions, Baked, Decoded,
};
use crate::lighting::PatchLighting;
use crate::metrics::{self, ErrorReport, MetricsError};
use crate::patch::FormFactorMatrix;
use crate::reference::{Method, Radiosity, ReferenceError};
use crate::rgb::Rgb;

/// How the f64 answers are solved.
#[derive(Clone, Debug, PartialEq)]
pub struct EvaluateOptions {
    /// Reference solver.
    pub method: Method,
    /// Slack on row sums above 1 ([`BakeOptions::row_sum_tolerance`]); the decoded table's solve adds its
    /// codec's rounding ([`decoded_row_sum_tolerance`]).
    pub row_sum_tolerance: f64,
}

impl EvaluateOptions {
    /// The evaluation of a bake of `patches` patches with `options`: the bake's solver and slack.
    #[must_use]
    pub fn for_bake(patches: usize, options: &BakeOptions) -> EvaluateOptions {
        EvaluateOptions {
            method: options.method.unwrap_or_else(|| default_method(patches)),
            row_sum_tolerance: options.row_sum_tolerance,
        }
    }
}

/// Why an evaluation failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum EvaluateError {
    /// An f64 solve failed.
    #[error("f64 reference solve ({what}): {source}")]
    Reference {
        /// Which solve.
        what: &'static str,
        /// The solver's error.
        source: ReferenceError,
    },
    /// The table does not parse.
    #[error("the table does not parse: {0}")]
    Parse(TableError),
    /// Core's transfer relight of the table failed.
    #[error("transfer relight of the written table: {0}")]
    Transfer(TransferError),
    /// The form-factor computation of the estimation component's reference matrix failed.
    #[error("reference form factors ({0}x samples and rays): {1}")]
    FormFactors(usize, String),
    /// Error metrics could not be computed (e.g. a non-finite answer).
    #[error("error metrics: {0}")]
    Metrics(#[from] MetricsError),
}

/// Each answer against the exact one (see the module docs): the error the bake introduced, on the scene's own
/// lights (every dynamic group at its default intensity).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BakeErrors {
    /// Shooting form of the original matrix vs the original (reciprocity of the input).
    pub reciprocity: ErrorReport,
    /// Sparsified matrix (f64) vs the original.
    pub sparsify: ErrorReport,
    /// Everything decoded from the written table vs the original.
    pub sparsify_quantize: ErrorReport,
}

/// The f64 answers of a bake and their comparisons (see the module docs).
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Patch areas (the scene's).
    pub area: Vec<f64>,
    /// f64 solve of the scene's matrix.
    pub reference: Radiosity,
    /// f64 solve of the shooting form of the scene's matrix.
    pub reciprocal: Radiosity,
    /// f64 solve of the shooting form of the sparsified matrix.
    pub sparsified: Radiosity,
    /// The table decoded into f64.
    pub decoded: Decoded,
    /// What the device converges to: [`Decoded::solution`] of the decoded table's f64 solve.
    pub device: Radiosity,
    /// Each answer against the exact one.
    pub errors: BakeErrors,
    /// Each answer against the one a step before: reciprocity, sparsification, quantization.
    pub components: Vec<Component>,
    /// The quantization component split by code ([`QUANTIZATION_FORM_FACTORS`], [`QUANTIZATION_CODES`]): the
    /// decoded form factors alone (the scene's reflectances and emission, f64) against the sparsified answer,
    /// and the rest of the decoded table against that. Not part of the telescoping decomposition, which the
    /// quantization component already closes.
    pub quantization_parts: Vec<Component>,
    /// The transfer relight's errors, if the table has a transfer basis.
    pub transfer: Option<TransferReport>,
    /// Largest relative residual of the f64 solves.
    pub residual: f64,
}

/// The exact answer: the f64 solve of `ff` with `lighting` at its default intensities, and its residual.
///
/// # Errors
/// [`EvaluateError::Reference`] if the solve fails.
pub fn exact(
    lighting: &PatchLighting,
    ff: &FormFactorMatrix,
    options: &EvaluateOptions,
) -> Result<(Radiosity, f64), EvaluateError> {
    let e = lighting.default_emission();
    solve_one(&lighting.rho, ff, &e, options.row_sum_tolerance, &options.method)
        .map_err(failed("original matrix"))
}

/// The decoded table and what the device converges to on it ([`Decoded::solution`] of its f64 solve), with
/// the solve's residual.
///
/// # Errors
/// [`EvaluateError::Reference`] if the solve fails (e.g. rows of a codec too coarse for the scene).
pub fn device_answer(
    table: &Table<'_>,
    options: &EvaluateOptions,
) -> Result<(Decoded, Radiosity, f64), EvaluateError> {
    let dec = decode_table(table);
    let tolerance = decoded_row_sum_tolerance(table.codec(), options.row_sum_tolerance);
    let shoot = shooting_form(&dec.rows, &dec.area);
    let (b, residual) =
        solve_one(&dec.rho, &shoot, &dec.rhs, tolerance, &options.method).map_err(failed("decoded table"))?;
    let b = dec.solution(b);
    Ok((dec, b, residual))
}

/// Evaluates `baked`, the bake of `input` (see the module docs).
///
/// # Errors
/// A failing f64 solve, a table that does not parse, a failing transfer relight, or a non-finite answer.
pub fn evaluate(
    input: &BakeInput<'_>,
    baked: &Baked,
    options: &EvaluateOptions,
) -> Result<Evaluation, EvaluateError> {
    let l = input.lighting;
    let area: Vec<f64> = input.patches.iter().map(|p| p.area).collect();
    let e = l.default_emission();
    let (tol, method) = (options.row_sum_tolerance, &options.method);
    let (reference, r0) = exact(l, input.form_factors, options)?;
    let full_shoot = shooting_form(input.form_factors, &area);
    let (reciprocal, r1) =
        solve_one(&l.rho, &full_shoot, &e, tol, method).map_err(failed("original, shooting form"))?;
    let sparse_shoot = shooting_form(&baked.sparse.matrix, &area);
    let (sparsified, r2) = solve_one(&l.rho, &sparse_shoot, &e, tol, method).map_err(failed("sparsified"))?;
    let table = Table::parse(&baked.table).map_err(EvaluateError::Parse)?;
    let (decoded, device, r3) = device_answer(&table, options)?;
    let errors = BakeErrors {
        reciprocity: metrics::compare(&reciprocal, &reference, &area)?,
        sparsify: metrics::compare(&sparsified, &reference, &area)?,
        sparsify_quantize: metrics::compare(&device, &reference, &area)?,
    };
    let components = vec![
        Component {
            name: RECIPROCITY.into(),
            compares: "f64, shooting form A_j F_ji / A_i of the full matrix vs the full matrix".into(),
            error: errors.reciprocity.clone(),
        },
        Component {
            name: SPARSIFICATION.into(),
            compares: format!(
                "f64, sparsified (threshold {}) vs full matrix, shooting form",
                baked.report.threshold
            ),
            error: metrics::compare(&sparsified, &reciprocal, &area)?,
        },
        Component {
            name: QUANTIZATION.into(),
            compares: format!("f64, decoded {} table vs sparsified f64 matrix", table.codec()),
            error: metrics::compare(&device, &sparsified, &area)?,
        },
    ];
    let quantization_parts = quantization_parts(
        l,
        &baked.static_radiosity,
        &decoded,
        [&device, &sparsified],
        &area,
        decoded_row_sum_tolerance(table.codec(), tol),
        method,
    )?;
    let transfer = match &baked.transfer {
        Some(tv) => Some(transfer::report(&table, tv, &l.default_intensity, &reference, &area)?),
        None => None,
    };
    Ok(Evaluation {
        area,
        reference,
        reciprocal,
        sparsified,
        decoded,
        device,
        errors,
        components,
        quantization_parts,
        transfer,
        residual: [r0, r1, r2, r3].into_iter().fold(0.0, f64::max),
    })
}

/// The quantization component split by code (see [`Evaluation::quantization_parts`]). What the device
/// converges to is the decoded static base plus the response to the light groups on the decoded rows
/// ([`Decoded::solution`]); with the codes undone, that is the bake's f64 static base `static_base` plus the
/// response of the decoded rows with the scene's reflectances to its dynamic emission (`lighting`, default
/// intensities), compared with `sparsified` (`[device, sparsified]`); `device` (everything decoded) is
/// compared with that.
///
/// # Errors
/// A failing f64 solve or non-finite answers.
fn quantization_parts(
    lighting: &PatchLighting,
    static_base: &[Rgb],
    decoded: &Decoded,
    [device, sparsified]: [&Radiosity; 2],
    area: &[f64],
    tolerance: f64,
    method: &Method,
) -> Result<Vec<Component>, EvaluateError> {
    let dynamic: Vec<Rgb> =
        lighting.default_emission().iter().zip(&lighting.static_emission).map(|(&e, &s)| e - s).collect();
    let shoot = shooting_form(&decoded.rows, &decoded.area);
    let (mut rows_only, _) = solve_one(&lighting.rho, &shoot, &dynamic, tolerance, method)
        .map_err(failed("decoded form factors alone"))?;
    for (b, &s) in rows_only.iter_mut().zip(static_base) {
        *b += s;
    }
    Ok(vec![
        Component {
            name: QUANTIZATION_FORM_FACTORS.into(),
            compares: "f64, decoded form factors with the scene's reflectance and emission vs sparsified"
                .into(),
            error: metrics::compare(&rows_only, sparsified, area)?,
        },
        Component {
            name: QUANTIZATION_CODES.into(),
            compares: "f64, decoded table vs decoded form factors alone (reflectance, emission, base codes)"
                .into(),
            error: metrics::compare(device, &rows_only, area)?,
        },
    ])
}

/// The error of the f64 solve named `what`.
fn failed(what: &'static str) -> impl Fn(ReferenceError) -> EvaluateError {
    move |source| EvaluateError::Reference { what, source }
}
