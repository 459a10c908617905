//! The hierarchy's link construction against raw Embree: occlusion rays per second of the whole refinement (the
//! tree, every pair's estimate and split, every pass; the solves between passes excluded,
//! [`crate::hierarchy::HierarchicalSolution::refine_seconds`]) on 1 and 2 threads, against as many raw occlusion
//! rays of the same kind on the same occluders, timed in interleaved rounds like the bake throughput: issue 7's
//! bake targets (at least 70% of raw Embree's rate, 1 -> 2 threads at least 1.8x) applied to the hierarchy.
//!
//! Both with shaft culling (the default: pairs that nothing can come between cast no rays) and without it, so
//! that the ratio of the culled run, which counts only the rays it cast, can be read against the unculled one's
//! and its seconds against the unculled seconds.
//!
//! The raw rays join uniformly random points of the two leaves of each leaf-to-leaf link of the solve, the links
//! taken in turn until there are as many rays as refinement cast, kept where both points face each other and
//! shortened at both ends by the scene's offset, as the estimator's visibility rays are: the same kind and number
//! of rays between the elements refinement linked, not its exact random numbers.

use super::bakebench::{occluder_scene, point_in, time_occlusion};
use super::device::median;
use super::{log, BenchError, BenchOptions};
use crate::embree::Ray;
use crate::formfactor::FormFactorOptions;
use crate::hierarchy::{solve_hierarchical, HierarchicalSolution, HierarchyOptions, Refinement};
use crate::mesh::{mesh, MeshOptions};
use crate::rng::SplitMix64;
use crate::scene::Scene;

/// The epsilon of the measured solve (brightness refinement of the Cornell box): a few million rays, long enough
/// to time, short enough for several rounds.
pub const LINK_RATE_EPSILON: f64 = 0.01;

/// Link construction on 1 and 2 threads: threads, occlusion rays cast, median seconds.
pub type RefineRuns = Vec<(usize, u64, f64)>;

/// Raw Embree on 1 and 2 threads: threads, rays, median seconds.
pub type RawRuns = Vec<(usize, usize, f64)>;

/// Link construction against raw Embree.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkRate {
    /// Brightness refinement's epsilon.
    pub epsilon: f64,
    /// Leaves of the solve.
    pub leaves: usize,
    /// Links of the solve.
    pub links: usize,
    /// Refinement with shaft culling on 1 and 2 threads: threads, occlusion rays cast, median seconds of link
    /// construction.
    pub refine: RefineRuns,
    /// Raw Embree on 1 and 2 threads, on as many rays as `refine` cast: threads, rays, median seconds.
    pub raw: RawRuns,
    /// The same without shaft culling ([`HierarchyOptions::shaft_culling`] off): refinement, then raw Embree on
    /// as many rays as it cast.
    pub unculled: (RefineRuns, RawRuns),
    /// Timed rounds.
    pub rounds: usize,
}

impl LinkRate {
    /// Refinement's rays per second over raw Embree's on `threads` threads, with shaft culling (`culled`) or
    /// without, if both were measured.
    #[must_use]
    pub fn ratio(&self, culled: bool, threads: usize) -> Option<f64> {
        let (refine, raw) = self.runs(culled);
        let r = refine.iter().find(|r| r.0 == threads)?;
        let w = raw.iter().find(|w| w.0 == threads)?;
        (r.2 > 0.0 && w.2 > 0.0).then(|| (r.1 as f64 / r.2) / (w.1 as f64 / w.2))
    }

    /// Speed-up from 1 to 2 threads, with shaft culling or without: of refinement, of raw Embree.
    #[must_use]
    pub fn scaling(&self, culled: bool) -> (Option<f64>, Option<f64>) {
        let (refine, raw) = self.runs(culled);
        let s = |v: &[(usize, f64)]| {
            let one = v.iter().find(|x| x.0 == 1)?.1;
            let two = v.iter().find(|x| x.0 == 2)?.1;
            (two > 0.0).then(|| one / two)
        };
        (
            s(&refine.iter().map(|r| (r.0, r.2)).collect::<Vec<_>>()),
            s(&raw.iter().map(|r| (r.0, r.2)).collect::<Vec<_>>()),
        )
    }

    /// The refinement and raw rows with shaft culling or without.
    #[must_use]
    pub fn runs(&self, culled: bool) -> (&RefineRuns, &RawRuns) {
        if culled {
            (&self.refine, &self.raw)
        } else {
            (&self.unculled.0, &self.unculled.1)
        }
    }
}

/// The raw rays of `solution` (see the module docs): `count` of them.
fn link_rays(solution: &HierarchicalSolution, count: usize, offset: f32) -> Vec<Ray> {
    let net = &solution.network;
    let pairs: Vec<(usize, usize)> = net
        .links
        .iter()
        .filter_map(|l| {
            Some((net.nodes[l.a as usize].leaf? as usize, net.nodes[l.b as usize].leaf? as usize))
        })
        .collect();
    let mut rays = Vec::with_capacity(count);
    if pairs.is_empty() {
        return rays;
    }
    let mut rng = SplitMix64::new(0x11_4B5);
    // Each link is tried in turn; a pair that faces away at every try would never give a ray, so the tries are
    // bounded too.
    let mut tries = 0usize;
    while rays.len() < count && tries < 64 * count {
        let (i, j) = pairs[tries % pairs.len()];
        tries += 1;
        let (pi, pj) = (&solution.leaves[i], &solution.leaves[j]);
        let (x, y) = (point_in(pi, &mut rng), point_in(pj, &mut rng));
        let d = y - x;
        if pi.normal.dot(d) > 0.0 && pj.normal.dot(d) < 0.0 {
            rays.push(Ray::segment(x.as_vec3(), y.as_vec3(), offset));
        }
    }
    rays
}

/// Link construction's rays per second against raw Embree on the Cornell box (brightness refinement at
/// [`LINK_RATE_EPSILON`]; quick: epsilon 0.1, one round), on 1 and 2 threads.
///
/// # Errors
/// Loading the scene, the solve, or Embree.
pub fn section(options: &BenchOptions) -> Result<LinkRate, BenchError> {
    log(options, "hierarchy: link construction against raw Embree");
    let scene = Scene::load(options.scenes.join("cornell-box.obj"))?;
    let epsilon = if options.quick { 0.1 } else { LINK_RATE_EPSILON };
    let rounds = if options.quick { 1 } else { options.reps.clamp(1, 3) };
    let solve = |threads: usize, shaft_culling: bool| {
        solve_hierarchical(
            &scene,
            &HierarchyOptions {
                epsilon,
                refinement: Refinement::Brightness,
                form_factors: FormFactorOptions {
                    threads: Some(threads),
                    progress: false,
                    ..FormFactorOptions::default()
                },
                progress: false,
                shaft_culling,
                ..HierarchyOptions::default()
            },
        )
        .map_err(|e| BenchError::Options(format!("hierarchical solve of the Cornell box: {e}")))
    };
    // The occluders the solve casts against: its face polygons, as `solve_hierarchical` builds them.
    let roots = mesh(&scene, &MeshOptions { patch_budget: usize::MAX, ..MeshOptions::no_subdivide(&scene) })
        .map_err(|e| BenchError::Options(format!("meshing: {e}")))?
        .patches;
    let occluders = occluder_scene(&roots, true)?;
    let mut measured = Vec::new();
    for shaft_culling in [true, false] {
        let first = solve(1, shaft_culling)?;
        let rays = link_rays(&first, first.stats.rays as usize, occluders.offset());
        let mut refine_times: [Vec<f64>; 2] = [vec![first.refine_seconds], Vec::new()];
        let mut raw_times: [Vec<f64>; 2] = Default::default();
        for round in 0..rounds {
            if round > 0 {
                refine_times[0].push(solve(1, shaft_culling)?.refine_seconds);
            }
            let two = solve(2, shaft_culling)?;
            if two.stats != first.stats {
                return Err(BenchError::Options(
                    "the hierarchical solve on 2 threads differs from the one on 1 thread".to_owned(),
                ));
            }
            refine_times[1].push(two.refine_seconds);
            for (slot, threads) in [(0usize, 1usize), (1, 2)] {
                raw_times[slot].push(time_occlusion(&occluders, &rays, threads)?.0);
            }
        }
        let mut refine = Vec::new();
        let mut raw = Vec::new();
        for (slot, threads) in [(0usize, 1usize), (1, 2)] {
            refine.push((threads, first.stats.rays, median(&mut refine_times[slot])));
            raw.push((threads, rays.len(), median(&mut raw_times[slot])));
        }
        measured.push((first, refine, raw));
    }
    let (unculled_first, unculled_refine, unculled_raw) = measured.pop().expect("two runs");
    let (first, refine, raw) = measured.pop().expect("two runs");
    drop(unculled_first);
    Ok(LinkRate {
        epsilon,
        leaves: first.leaves.len(),
        links: first.stats.surface_links + first.stats.cluster_links,
        refine,
        raw,
        unculled: (unculled_refine, unculled_raw),
        rounds,
    })
}
