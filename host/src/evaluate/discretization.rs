//! The discretization component: the mesh's exact f64 answer, area-averaged per OBJ face, against the
//! continuous path-traced reference of [`crate::montecarlo`], with the reference's standard error beside it.
//!
//! The f64 solve is exact for its own mesh, so every other component is measured against it; this one says how
//! far that answer is from the scene itself (patches that average lit and hidden area, a mesh too coarse where
//! light changes fast). The comparison is per face because the reference is: face `f`'s mesh answer is
//! `sum_{p in f} A_p B_p / sum_{p in f} A_p` over its patches. Its metrics ([`metrics::compare`] over faces,
//! weighted by face area) include the reference's noise: [`Discretization::noise_rel_l2`] is the relative L2
//! of the reference's standard errors, what the component would read if the mesh were exact.

use std::fmt;

use serde::Serialize;

use super::{Component, EvaluateError};
use crate::input::check_len;
use crate::metrics::{self, MetricsError};
use crate::montecarlo::ContinuousReference;
use crate::patch::Patch;
use crate::rgb::{self, Rgb};

/// Component name of [`discretization`], as reports show it.
pub const DISCRETIZATION: &str = "discretization";

/// One face's row: mesh answer, reference, difference, and the reference's standard error.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaceDiscretization {
    /// Index of the face in load order (OBJ order for an OBJ file).
    pub face: usize,
    /// Where the face is in its file ([`Face::place`](crate::scene::Face::place)): `line 12` for an OBJ face,
    /// its node, mesh, primitive and triangles for a glTF face.
    pub source: String,
    /// Area of the face.
    pub area: f64,
    /// The mesh's f64 answer averaged over the face's patches (by area).
    pub mesh: Rgb,
    /// The continuous reference.
    pub reference: Rgb,
    /// `(mesh - reference) / reference` per channel (0 where both are 0; infinite, serialized as `null`, where
    /// only the reference is 0).
    pub relative_difference: Rgb,
    /// The reference's standard error per channel.
    pub reference_standard_error: Rgb,
    /// The reference's relative standard error (largest over the channels with nonzero radiosity).
    pub reference_relative_se: f64,
}

impl FaceDiscretization {
    /// The channel with the largest `|relative difference|`, and that difference in standard errors of the
    /// reference (infinite where the standard error is 0 and the difference is not).
    #[must_use]
    pub fn worst_channel(&self) -> (usize, f64) {
        let c = (0..3)
            .max_by(|&a, &b| self.relative_difference[a].abs().total_cmp(&self.relative_difference[b].abs()))
            .unwrap_or(0);
        let difference = (self.mesh[c] - self.reference[c]).abs();
        let se = self.reference_standard_error[c];
        let sigmas = if difference == 0.0 { 0.0 } else { difference / se };
        (c, sigmas)
    }
}

/// The discretization component with its per-face rows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Discretization {
    /// The component (metrics over faces: `patches` counts faces, `max_rel_patch` is a face index).
    pub component: Component,
    /// Per face, in OBJ order.
    pub faces: Vec<FaceDiscretization>,
    /// Area-weighted relative L2 of the reference's standard errors: the component's noise floor.
    pub noise_rel_l2: f64,
    /// The reference's own summary (paths, rays, time, target).
    pub reference_summary: String,
}

/// The rows as `radiosity check --continuous` and `radiosity solve --continuous` print them, after a blank line: per
/// face, the mesh and reference luminance, the relative difference per channel, the reference's relative standard
/// error and the worst channel's difference in standard errors.
impl fmt::Display for Discretization {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "\ndiscretization per face: f64 mesh answer (area-averaged) vs continuous reference; noise floor \
             (reference SE, rel L2) {:.3e}",
            self.noise_rel_l2
        )?;
        writeln!(f, "reference: {}", self.reference_summary)?;
        writeln!(
            f,
            "{:>5} {:>11} {:>11} {:>9} {:>9} {:>9} {:>9} {:>8}  source",
            "face", "mesh Y", "ref Y", "diff r", "diff g", "diff b", "rel SE", "|d|/SE"
        )?;
        for row in &self.faces {
            let (_, sigmas) = row.worst_channel();
            let diff = row.relative_difference;
            writeln!(
                f,
                "{:>5} {:>11.5e} {:>11.5e} {:>+9.3e} {:>+9.3e} {:>+9.3e} {:>9.2e} {:>8.1}  {}",
                row.face,
                rgb::luminance(row.mesh),
                rgb::luminance(row.reference),
                diff.x,
                diff.y,
                diff.z,
                row.reference_relative_se,
                sigmas,
                row.source
            )?;
        }
        Ok(())
    }
}

/// Compares the mesh answer `b` (one value per patch of `patches`) with `continuous`, face by face.
///
/// # Errors
/// [`EvaluateError::Metrics`] if `b` does not match `patches`, a patch names a face the reference does not
/// have (patches and reference of different scenes), an answer is not finite, or a face has no patches.
pub fn discretization(
    patches: &[Patch],
    b: &[Rgb],
    continuous: &ContinuousReference,
) -> Result<Discretization, EvaluateError> {
    let faces = continuous.faces.len();
    check_len("mesh answer", b, patches.len()).map_err(MetricsError::from)?;
    let needed = patches.iter().map(|p| p.face + 1).max().unwrap_or(0).max(faces);
    check_len("continuous reference faces", &continuous.faces, needed).map_err(MetricsError::from)?;
    let mut sums = vec![(0.0, Rgb::ZERO); faces];
    for (p, &v) in patches.iter().zip(b) {
        let s = &mut sums[p.face];
        s.0 += p.area;
        s.1 += p.area * v;
    }
    // A face's area the mesh does not cover (fragments mesh repair culled: no point of the scene sees them, so
    // they receive nothing and their radiosity is their emission) counts with `B = E`, as the continuous
    // reference, which samples the whole face, counts it.
    let mesh: Vec<Rgb> = sums
        .iter()
        .zip(&continuous.faces)
        .map(|(&(a, s), f)| {
            let hidden = (f.area - a).max(0.0);
            if a + hidden > 0.0 {
                (s + hidden * f.emission) / (a + hidden)
            } else {
                Rgb::ZERO
            }
        })
        .collect();
    let reference: Vec<Rgb> = continuous.faces.iter().map(|f| f.radiosity).collect();
    let area: Vec<f64> = sums.iter().map(|&(a, _)| a).collect();
    let error = metrics::compare(&mesh, &reference, &area)?;
    let rows: Vec<FaceDiscretization> = continuous
        .faces
        .iter()
        .zip(&mesh)
        .map(|(f, &m)| {
            let relative = |c: usize| {
                let (d, r) = (m[c] - f.radiosity[c], f.radiosity[c]);
                if d == 0.0 {
                    0.0
                } else if r == 0.0 {
                    f64::INFINITY
                } else {
                    d / r
                }
            };
            FaceDiscretization {
                face: f.face,
                source: f.source.clone(),
                area: f.area,
                mesh: m,
                reference: f.radiosity,
                relative_difference: Rgb::new(relative(0), relative(1), relative(2)),
                reference_standard_error: f.standard_error,
                reference_relative_se: f.relative_standard_error,
            }
        })
        .collect();
    let (mut noise, mut magnitude) = (0.0, 0.0);
    for f in &continuous.faces {
        noise += f.area * f.standard_error.length_squared();
        magnitude += f.area * f.radiosity.length_squared();
    }
    let noise_rel_l2 = if magnitude > 0.0 { (noise / magnitude).sqrt() } else { 0.0 };
    Ok(Discretization {
        component: Component {
            name: DISCRETIZATION.into(),
            compares:
                "f64 mesh answer averaged per face vs the continuous path-traced reference (metrics over \
                       faces; includes the reference's noise)"
                    .into(),
            error,
        },
        faces: rows,
        noise_rel_l2,
        reference_summary: continuous.summary(),
    })
}
