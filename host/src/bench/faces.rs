//! Per-face comparison with the continuous reference, shared by the hierarchy section and the device curves.

use crate::montecarlo::ContinuousReference;
use crate::patch::Patch;
use crate::rgb::Rgb;

/// Per-face errors against a reference: the worst face (its index) and the mean over faces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceErrors {
    /// Largest relative difference of a face's area-averaged radiosity (worst channel).
    pub worst: f64,
    /// The OBJ face where it is.
    pub worst_face: usize,
    /// Mean over the faces of the relative difference.
    pub mean: f64,
}

/// Area-averaged radiosity per OBJ face of `patches` carrying `b` (faces without patches are `None`), over the
/// whole face as `reference` has it: area the patches do not cover (fragments mesh repair culled, which no point
/// sees) counts with `B = E`, as in the continuous reference.
pub(super) fn face_means(patches: &[Patch], b: &[Rgb], reference: &ContinuousReference) -> Vec<Option<Rgb>> {
    let faces = reference.faces.iter().map(|f| f.face).max().map_or(0, |m| m + 1);
    let mut sums = vec![(0.0, Rgb::ZERO); faces];
    for (p, v) in patches.iter().zip(b) {
        if let Some(s) = sums.get_mut(p.face) {
            s.0 += p.area;
            s.1 += p.area * *v;
        }
    }
    for f in &reference.faces {
        let s = &mut sums[f.face];
        if s.0 > 0.0 {
            let hidden = (f.area - s.0).max(0.0);
            s.0 += hidden;
            s.1 += hidden * f.emission;
        }
    }
    sums.into_iter().map(|(a, s)| (a > 0.0).then(|| s / a)).collect()
}

/// Per-face errors of `got` against `want` over `faces` (the faces taken into account).
pub(super) fn face_errors(got: &[Option<Rgb>], want: &[Option<Rgb>], faces: &[usize]) -> FaceErrors {
    let mut out = FaceErrors { worst: 0.0, worst_face: 0, mean: 0.0 };
    let mut n = 0;
    for &f in faces {
        let (Some(g), Some(w)) = (got.get(f).copied().flatten(), want.get(f).copied().flatten()) else {
            continue;
        };
        let rel = ((g - w) / w).abs().max_element();
        if rel.is_finite() {
            if rel > out.worst {
                out.worst = rel;
                out.worst_face = f;
            }
            out.mean += rel;
            n += 1;
        }
    }
    if n > 0 {
        out.mean /= n as f64;
    }
    out
}
