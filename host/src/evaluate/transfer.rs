//! The transfer relight of a table with a transfer basis, against the exact answer and against its own f64
//! basis.

use radiosity_core::Table;
use serde::Serialize;

use super::EvaluateError;
use crate::inspect::SectionBytes;
use crate::metrics::{self, ErrorReport};
use crate::reference::TransferVectors;
use crate::rgb::Rgb;

/// The transfer basis of a bake (see [`crate::bake::BakeOptions::transfer`]) and its relight's errors.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransferReport {
    /// Bytes of the transfer sections (scale exponents and response codes).
    pub bytes: usize,
    /// Core's f32 transfer relight at the default intensities vs the f64 solve of the original matrix (what
    /// the device shows against the exact answer).
    pub vs_reference: ErrorReport,
    /// The same relight vs f64 `B_static + sum_g I_g T_g` on the table's own (sparsified) matrix: the
    /// quantization of the basis and the static base alone.
    pub quantization: ErrorReport,
}

/// Relights `table` with core's f32 transfer relight at `intensity` and compares it with the f64 reference
/// `b_ref` (original matrix) and with the f64 basis `tv` it was quantized from.
pub(super) fn report(
    table: &Table<'_>,
    tv: &TransferVectors,
    intensity: &[Rgb],
    b_ref: &[Rgb],
    area: &[f64],
) -> Result<TransferReport, EvaluateError> {
    let i_f32: Vec<[f32; 3]> = intensity.iter().map(|v| v.as_vec3().to_array()).collect();
    let mut out = vec![[0.0f32; 3]; table.patch_count() as usize];
    radiosity_core::relight_transfer(table, &i_f32, &mut out).map_err(EvaluateError::Transfer)?;
    let relit: Vec<Rgb> = out.iter().map(|b| Rgb::from_array(b.map(f64::from))).collect();
    // The f64 basis at the intensities the device was given (f32-rounded), so only the basis's quantization
    // and the static base's codes separate the two.
    let i_used: Vec<Rgb> = i_f32.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
    let exact = tv
        .relight(&i_used)
        .map_err(|source| EvaluateError::Reference { what: "transfer relight", source })?;
    Ok(TransferReport {
        bytes: SectionBytes::of(table).transfer,
        vs_reference: metrics::compare(&relit, b_ref, area)?,
        quantization: metrics::compare(&relit, &exact, area)?,
    })
}
