//! Radiosity at chosen points of the continuous scene: the path tracer of [`super`] started from given points
//! instead of whole faces, for checks that look at where light changes fast (a contact line, a shadow edge),
//! which face averages hide.
//!
//! The estimator is the face estimator's with the starting point fixed: `B(x) = E_f + rho_f H(x)`, `H(x)` the
//! cosine-weighted average of the radiosity seen from `x` (module docs of [`super`]), with the same next-event
//! estimation, multiple importance sampling, Russian roulette and lifted ray origins; a point on (or within the
//! lift of) an edge of its face starts the lift's distance inside it. Its standard error is
//! `rho_f` times the sample standard deviation of the `H` samples over the square root of their count (no
//! strata here, so this is the estimator's own error, not a conservative bound). Deterministic for a seed: the
//! path of sample `n` of probe `k` draws from a generator keyed by `(seed, k, n)`, and batches are merged in a
//! fixed order whatever the thread count.

use glam::DVec3;
use rayon::prelude::*;

use super::tracer::{Moments, TraceScene};
use super::{reference_patches, MonteCarloError, BATCH_SIZE};
use crate::formfactor::{occluder_scene, FormFactorError};
use crate::lighting::PatchLighting;
use crate::limits::MAX_PATHS;
use crate::patch::Patch;
use crate::rgb::Rgb;
use crate::scene::Scene;

/// A point of a face where [`probe_radiosity`] estimates the radiosity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    /// The point, in scene units; it must lie on the face (within [`ON_FACE`] of the face's diameter).
    pub point: DVec3,
    /// The OBJ face (0-based, as [`Scene::faces`] holds them).
    pub face: usize,
}

/// The radiosity at one [`Probe`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeEstimate {
    /// Estimated radiosity (W/m^2 per channel).
    pub radiosity: Rgb,
    /// Its standard error, per channel.
    pub standard_error: Rgb,
    /// Paths traced.
    pub paths: u64,
}

/// How far off its face a probe may be, relative to the face's diameter (distance to the plane, and outside
/// the polygon's edges).
pub const ON_FACE: f64 = 1e-6;

/// Estimates the radiosity at every probe with `paths` paths each (Embree as the ray caster, robust mode).
///
/// # Errors
/// [`MonteCarloError::InvalidOption`] (checked before any ray) for zero paths or more than
/// [`crate::limits::MAX_PATHS`], a probe whose face does not exist, whose point is not finite, or which is not on
/// its face (naming the probe); meshing and Embree failures as [`super::continuous_reference`].
pub fn probe_radiosity(
    scene: &Scene,
    probes: &[Probe],
    paths: u64,
    seed: u64,
) -> Result<Vec<ProbeEstimate>, MonteCarloError> {
    let invalid = |name, problem: String| MonteCarloError::InvalidOption { name, problem };
    if paths == 0 || paths > MAX_PATHS {
        return Err(invalid("samples", format!("{paths} paths per probe is not in 1..={MAX_PATHS}")));
    }
    let patches = reference_patches(scene)?;
    let mut starts = Vec::with_capacity(probes.len());
    for (k, probe) in probes.iter().enumerate() {
        if probe.face >= scene.faces.len() {
            return Err(invalid(
                "probe",
                format!(
                    "probe {k}: face {} does not exist (the scene has {})",
                    probe.face,
                    scene.faces.len()
                ),
            ));
        }
        if !probe.point.is_finite() {
            return Err(invalid("probe", format!("probe {k}: point {} is not finite", probe.point)));
        }
        let patch = containing_polygon(&patches, probe).ok_or_else(|| {
            invalid(
                "probe",
                format!(
                    "probe {k}: point {} is not on face {} ({})",
                    probe.point,
                    probe.face,
                    scene.faces[probe.face].place()
                ),
            )
        })?;
        starts.push(patch);
    }
    let caster = occluder_scene(&patches, true).map_err(|e| match e {
        FormFactorError::Embree(e) => MonteCarloError::Embree(e),
        other => invalid("scene", other.to_string()),
    })?;
    let lift = f64::from(caster.offset());
    let points: Vec<DVec3> =
        probes.iter().zip(&starts).map(|(probe, &k)| inside_edges(&patches[k], probe.point, lift)).collect();
    let lighting = PatchLighting::new(scene, &patches);
    let traced = TraceScene::new(&patches, &lighting, scene.faces.len(), lift);
    let batch = BATCH_SIZE as u64;
    let tasks: Vec<(usize, u64)> =
        (0..probes.len()).flat_map(|k| (0..paths.div_ceil(batch)).map(move |b| (k, b * batch))).collect();
    let results: Vec<Moments> = tasks
        .par_iter()
        .map(|&(k, first)| {
            let count = (paths - first).min(batch) as usize;
            traced.trace_probe(&caster, seed, k, points[k], starts[k], first, count)
        })
        .collect::<Result<_, _>>()?;
    let mut moments = vec![Moments::default(); probes.len()];
    for (&(k, _), m) in tasks.iter().zip(results) {
        moments[k] = moments[k].merge(m);
    }
    Ok(moments
        .iter()
        .zip(&starts)
        .map(|(m, &patch)| {
            let (rho, emission) = (traced.rho(patch), traced.emission(patch));
            ProbeEstimate {
                radiosity: emission + rho * m.mean,
                standard_error: rho * m.standard_error(),
                paths: m.count,
            }
        })
        .collect())
}

/// `point` moved into `polygon` until it is at least `lift` from every edge (unmoved if it already is): a path
/// from a point on an edge, lifted off its face by `lift`, would start in the plane of the face meeting it there,
/// and its rays could slip past that face. The radiosity is continuous on a face, so the move changes the
/// estimate by the field's change over `lift` (the caster's offset, a tiny fraction of the scene's extent).
fn inside_edges(polygon: &Patch, point: DVec3, lift: f64) -> DVec3 {
    let v = &polygon.vertices;
    let mut p = point;
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        let inward = polygon.normal.cross(b - a).normalize_or_zero();
        let d = (p - a).dot(inward);
        if d < lift {
            p += (lift - d) * inward;
        }
    }
    p
}

/// The polygon of `probe.face` (among the unsubdivided `patches`) that holds the probe's point, if any: within
/// [`ON_FACE`] times the polygon's diameter of its plane and inside (or on) every edge of the convex polygon.
fn containing_polygon(patches: &[Patch], probe: &Probe) -> Option<usize> {
    patches.iter().enumerate().filter(|(_, p)| p.face == probe.face).find_map(|(k, p)| {
        let v = &p.vertices;
        let diameter = v.iter().flat_map(|a| v.iter().map(move |b| a.distance(*b))).fold(0.0, f64::max);
        let tolerance = ON_FACE * diameter;
        let plane = (probe.point - v[0]).dot(p.normal).abs();
        let inside = (0..v.len()).all(|i| {
            let (a, b) = (v[i], v[(i + 1) % v.len()]);
            let inward = p.normal.cross(b - a).normalize_or_zero();
            (probe.point - a).dot(inward) >= -tolerance
        });
        (plane <= tolerance && inside).then_some(k)
    })
}
