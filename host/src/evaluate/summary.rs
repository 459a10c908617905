//! The `bake` command's summary: the bake's stage report and its evaluation.

use std::fmt;

use serde::Serialize;

use super::{BakeErrors, Evaluation, TransferReport};
use crate::bake::{BakeReport, Baked};
use crate::metrics::ErrorReport;

/// What the `bake` command prints: what the bake did ([`BakeReport`]) and the error it introduced
/// ([`Evaluation`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeSummary<'a> {
    /// The bake's stage report.
    #[serde(flatten)]
    pub bake: &'a BakeReport,
    /// Error introduced by the bake.
    pub error: &'a BakeErrors,
    /// The transfer basis, if baked.
    pub transfer: Option<&'a TransferReport>,
    /// Largest relative residual of the f64 solves (the bake's and the evaluation's).
    pub reference_residual: f64,
}

impl BakeSummary<'_> {
    /// The summary of `baked` and its evaluation.
    #[must_use]
    pub fn new<'a>(baked: &'a Baked, evaluation: &'a Evaluation) -> BakeSummary<'a> {
        BakeSummary {
            bake: &baked.report,
            error: &evaluation.errors,
            transfer: evaluation.transfer.as_ref(),
            reference_residual: baked.residual.max(evaluation.residual),
        }
    }
}

impl fmt::Display for BakeSummary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.bake)?;
        let line = |name: &str, r: &ErrorReport| {
            format!(
                "  {name:<18} rel L2 {:.3e}  max rel {:.3e} (patch {})",
                r.rel_l2, r.max_rel, r.max_rel_patch
            )
        };
        writeln!(f, "error vs f64 (scene lights at default intensity)")?;
        writeln!(f, "{}", line("reciprocity", &self.error.reciprocity))?;
        writeln!(f, "{}", line("sparsify", &self.error.sparsify))?;
        writeln!(f, "{}", line("sparsify+quantize", &self.error.sparsify_quantize))?;
        if let Some(t) = self.transfer {
            writeln!(
                f,
                "transfer basis     {} bytes ({} groups x {} patches)",
                t.bytes,
                self.bake.groups.len(),
                self.bake.patches
            )?;
            writeln!(f, "{}", line("transfer relight", &t.vs_reference))?;
            writeln!(f, "{}", line("  quantization", &t.quantization))?;
        }
        write!(f, "reference residual {:.3e}", self.reference_residual)
    }
}
