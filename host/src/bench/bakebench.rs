//! Bake throughput: form-factor rays per second against raw Embree occlusion queries on the same scene, and
//! thread scaling.
//!
//! The raw rays are built like the form-factor estimator's visibility rays: for every pair of patches `i < j`
//! with a nonzero form factor, `rays_per_pair` segments between random points of the two patches, kept where
//! both points face each other (the estimator's kernel is nonzero there), shortened at both ends by the
//! scene's offset, and tested with [`TriangleScene::occluded_many`] (packets of 16) on an occluder scene built
//! from the patches exactly as the estimator builds it (triangle fans, the same robust flag). They are the same
//! kind and number of rays, not the estimator's exact random numbers.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::BenchError;
use crate::embree::{Ray, TriangleScene};
use crate::formfactor;
use crate::patch::{FormFactorMatrix, Patch};
use crate::rng::SplitMix64;

/// The occluder scene of `patches`, built by the form-factor estimator's own [`formfactor::occluder_scene`].
///
/// # Errors
/// If Embree fails.
pub fn occluder_scene(patches: &[Patch], robust: bool) -> Result<TriangleScene, BenchError> {
    formfactor::occluder_scene(patches, robust).map_err(|e| BenchError::Embree(e.to_string()))
}

/// A uniformly random point of a convex polygon: a fan triangle chosen by area, then a uniform point in it.
fn point_in(p: &Patch, rng: &mut SplitMix64) -> DVec3 {
    let v = &p.vertices;
    let tri_area = |k: usize| (v[k] - v[0]).cross(v[k + 1] - v[0]).length() * 0.5;
    let total: f64 = (1..v.len() - 1).map(tri_area).sum();
    let mut pick = rng.unit() * total;
    let mut k = 1;
    while k + 2 < v.len() && pick > tri_area(k) {
        pick -= tri_area(k);
        k += 1;
    }
    let (r, t) = (rng.unit().sqrt(), rng.unit());
    v[0] * (1.0 - r) + v[k] * (r * (1.0 - t)) + v[k + 1] * (r * t)
}

/// Rays between pairs with a nonzero form factor (see the module docs).
#[must_use]
pub fn pair_rays(patches: &[Patch], ff: &FormFactorMatrix, rays_per_pair: usize, offset: f32) -> Vec<Ray> {
    let mut rng = SplitMix64::new(0x5EED);
    let mut rays = Vec::new();
    for i in 0..ff.n() {
        for (j, _) in ff.row(i).filter(|&(j, f)| j > i && f > 0.0) {
            let (pi, pj) = (&patches[i], &patches[j]);
            for _ in 0..rays_per_pair {
                let (x, y) = (point_in(pi, &mut rng), point_in(pj, &mut rng));
                let d = y - x;
                if pi.normal.dot(d) > 0.0 && pj.normal.dot(d) < 0.0 {
                    rays.push(Ray::segment(x.as_vec3(), y.as_vec3(), offset));
                }
            }
        }
    }
    rays
}

/// Seconds to test every ray on `threads` threads (chunks of 1024 rays in a rayon pool of that size).
///
/// # Errors
/// If the thread pool cannot be built.
pub fn time_occlusion(
    scene: &TriangleScene,
    rays: &[Ray],
    threads: usize,
) -> Result<(f64, usize), BenchError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| BenchError::Options(format!("thread pool of {threads}: {e}")))?;
    let t0 = Instant::now();
    let blocked: usize = pool.install(|| {
        rays.par_chunks(1024)
            .map(|chunk| {
                let mut out = vec![false; chunk.len()];
                scene.occluded_many(chunk, &mut out);
                out.iter().filter(|&&b| b).count()
            })
            .sum()
    });
    Ok((t0.elapsed().as_secs_f64(), blocked))
}
