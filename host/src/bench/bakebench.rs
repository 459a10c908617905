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

use super::device::median;
use super::edge_for_patches;
use super::{BakeThroughput, BenchError, BenchOptions};
use crate::embree::{Ray, TriangleScene};
use crate::formfactor::{self, compute_form_factors, FormFactorOptions};
use crate::mesh::{mesh, MeshOptions};
use crate::patch::{FormFactorMatrix, Patch};
use crate::rng::SplitMix64;
use crate::scene::Scene;

/// The occluder scene of `patches`, built by the form-factor estimator's own [`formfactor::occluder_scene`].
///
/// # Errors
/// If Embree fails.
pub fn occluder_scene(patches: &[Patch], robust: bool) -> Result<TriangleScene, BenchError> {
    formfactor::occluder_scene(patches, robust).map_err(|e| BenchError::Embree(e.to_string()))
}

/// A uniformly random point of a convex polygon: a fan triangle chosen by area, then a uniform point in it.
pub(super) fn point_in(p: &Patch, rng: &mut SplitMix64) -> DVec3 {
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

/// Form-factor rays per second against raw Embree on the Cornell box meshed to about `target` patches (form
/// factors at the bake default), on 1 and 2 threads, with the form factors' phase times.
///
/// # Errors
/// If meshing, the form factors or Embree fail.
pub fn bake_throughput(options: &BenchOptions, target: usize) -> Result<BakeThroughput, BenchError> {
    let ffo = FormFactorOptions { progress: false, ..FormFactorOptions::default() };
    let path = options.scenes.join("cornell-box.obj");
    let scene = Scene::load(&path)?;
    let (edge, _) = edge_for_patches(&scene, target)?;
    let mesh_options = MeshOptions {
        subdivide: true,
        max_patch_edge: edge,
        patch_budget: usize::MAX / 4,
        ..MeshOptions::for_scene(&scene)
    };
    let m = mesh(&scene, &mesh_options).map_err(|e| BenchError::Options(format!("meshing: {e}")))?;
    // Interleaved rounds: form factors on 1 and 2 threads, then raw Embree on 1 and 2 threads, so both rates of
    // a ratio are measured minutes apart at most, not in separate blocks (the shared machine's speed drifts).
    // The first 1-thread run also gives the matrix whose pairs the raw rays join.
    let rounds = options.reps.clamp(1, 3);
    let run_ff = |threads: usize| {
        compute_form_factors(&m.patches, &FormFactorOptions { threads: Some(threads), ..ffo.clone() })
            .map_err(|e| BenchError::Options(format!("form factors: {e}")))
    };
    // Per thread count (index 0: 1 thread, 1: 2 threads): total, kernel-phase and visibility-phase seconds.
    let mut ff_times: [[Vec<f64>; 3]; 2] = Default::default();
    let (mut rays_cast, mut kernels) = ([0u64; 2], [0u64; 2]);
    let mut record = |slot: usize, stats: &crate::formfactor::FormFactorStats| {
        ff_times[slot][0].push(stats.elapsed.as_secs_f64());
        ff_times[slot][1].push(stats.kernel_time.as_secs_f64());
        ff_times[slot][2].push(stats.visibility_time.as_secs_f64());
        rays_cast[slot] = stats.rays_cast;
        kernels[slot] = stats.kernel_evaluations;
    };
    let (matrix, stats) = run_ff(1)?;
    record(0, &stats);
    let scene_rt = occluder_scene(&m.patches, ffo.robust)?;
    let rays = pair_rays(&m.patches, &matrix, ffo.rays_per_pair, scene_rt.offset());
    let mut raw_times: [Vec<f64>; 2] = Default::default();
    for round in 0..rounds {
        if round > 0 {
            record(0, &run_ff(1)?.1);
        }
        record(1, &run_ff(2)?.1);
        for (slot, threads) in [(0usize, 1usize), (1, 2)] {
            raw_times[slot].push(time_occlusion(&scene_rt, &rays, threads)?.0);
        }
    }
    let mut ff = Vec::new();
    let mut phases = Vec::new();
    let mut raw = Vec::new();
    for (slot, threads) in [(0usize, 1usize), (1, 2)] {
        let [total, kernel, visibility] = &mut ff_times[slot];
        ff.push((threads, rays_cast[slot], median(total)));
        phases.push((threads, kernels[slot], median(kernel), median(visibility)));
        raw.push((threads, rays.len(), median(&mut raw_times[slot])));
    }
    Ok(BakeThroughput {
        scene: format!("cornell-box (~{target} patches)"),
        patches: m.patches.len(),
        samples: ffo.samples_per_patch,
        rays_per_pair: ffo.rays_per_pair,
        ff,
        raw,
        phases,
    })
}
