//! Components of the error decomposition that `check` and `regress` report (see the module docs of
//! [`crate::evaluate`] and [`crate::check`]).

use serde::Serialize;

use super::{failed, EvaluateError, EvaluateOptions};
use crate::bake::solve_one;
use crate::formfactor::compute_form_factors;
use crate::metrics::{self, ErrorReport};
use crate::pipeline::{PrepareOptions, Prepared};
use crate::reference::Radiosity;

/// Component names, as they appear in reports and the regression baseline.
pub const FORM_FACTOR_ESTIMATION: &str = "form-factor estimation";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const RECIPROCITY: &str = "reciprocity";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const SPARSIFICATION: &str = "sparsification";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const QUANTIZATION: &str = "quantization";
/// Part of [`QUANTIZATION`]: the form-factor codes alone ([`super::Evaluation::quantization_parts`]).
pub const QUANTIZATION_FORM_FACTORS: &str = "of which form factors";
/// Part of [`QUANTIZATION`]: the reflectance and emission codes ([`super::Evaluation::quantization_parts`]).
pub const QUANTIZATION_CODES: &str = "of which rho, emission";
/// See [`FORM_FACTOR_ESTIMATION`].
pub const ITERATION_TRUNCATION: &str = "iteration truncation";
/// See [`FORM_FACTOR_ESTIMATION`] (table input only).
pub const TABLE_VS_SCENE: &str = "table vs scene matrix";

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

/// The form-factor estimation component: the exact answer `reference` of `p` (prepared with
/// `prepare_options`) against the f64 solve of a matrix estimated with `factor` times the samples and the rays
/// (reciprocity enforced and rows clamped to 1, as the pipeline does).
///
/// # Errors
/// [`EvaluateError::FormFactors`] if the finer estimate fails, and the errors of the solve and the metrics.
pub fn form_factor_estimation(
    p: &Prepared,
    prepare_options: &PrepareOptions,
    factor: usize,
    reference: &Radiosity,
    options: &EvaluateOptions,
) -> Result<Component, EvaluateError> {
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let coarse = &prepare_options.form_factors;
    let mut fine = coarse.clone();
    fine.samples_per_patch *= factor;
    fine.rays_per_pair *= factor;
    fine.progress = false;
    let (mut hi, _) = compute_form_factors(&p.patches, &fine)
        .map_err(|e| EvaluateError::FormFactors(factor, e.to_string()))?;
    hi.enforce_reciprocity(&area);
    hi.clamp_rows_to_one();
    let e = p.lighting.default_emission();
    let (b_hi, _) = solve_one(&p.lighting.rho, &hi, &e, options.row_sum_tolerance, &options.method)
        .map_err(failed("finer form-factor estimate"))?;
    Ok(Component {
        name: FORM_FACTOR_ESTIMATION.into(),
        compares: format!(
            "f64, matrix at {} samples/{} rays vs at {} samples/{} rays",
            coarse.samples_per_patch, coarse.rays_per_pair, fine.samples_per_patch, fine.rays_per_pair
        ),
        error: metrics::compare(reference, &b_hi, &area)?,
    })
}

/// The one component of a table checked without its bake: the device's f64 answer on the decoded table
/// against the exact answer of the scene's matrix (see [`crate::check::check_table`]).
///
/// # Errors
/// The metrics' errors.
pub fn table_vs_scene(
    device: &Radiosity,
    reference: &Radiosity,
    area: &[f64],
) -> Result<Component, EvaluateError> {
    Ok(Component {
        name: TABLE_VS_SCENE.into(),
        compares:
            "f64, decoded table vs the scene's f64 matrix (sparsification + quantization + reciprocity \
                   + estimate differences)"
                .into(),
        error: metrics::compare(device, reference, area)?,
    })
}
