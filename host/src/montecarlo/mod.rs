//! The continuous reference: a Monte Carlo path tracer of the diffuse scene that estimates the area-averaged
//! radiosity of every OBJ face with its standard error, independent of any mesh.
//!
//! The f64 solve is exact for its own mesh only: a patch that averages lit and shadowed area, or a mesh too
//! coarse for a fast change of light, is an error it cannot see. This estimate converges to the radiosity of the
//! continuous scene, so the difference between the two is the discretization error (the `check --continuous`
//! component, [`crate::check`]).
//!
//! # What is estimated
//! With the project's conventions (diffuse, one-sided faces, `B = E + rho * H`), the radiosity averaged over
//! face `f` is `B_f = E_f + rho_f * H_f`, where `H(x) = ∫ B(y(ω)) cos θ / π dω` is the cosine-weighted average of
//! the radiosity seen from `x` over its hemisphere (what `sum_j F_ij B_j` is for a patch) and `H_f` its mean over
//! the face. `E_f` and `rho_f` are the face's material at the scene's default light intensities
//! ([`crate::lighting::PatchLighting`]). The back of a face is black (it neither emits nor reflects), and a ray
//! that leaves the scene brings nothing back (open scenes).
//!
//! # Estimator
//! One sample of `H_f` is one path from a point `x_0` of the face:
//! - `x_0` is uniform on the face (by area over its polygons: a face the loader split into triangles is
//!   sampled and reported as one face), stratified: each batch of [`BATCH_SIZE`] paths of a face takes one
//!   jittered point per cell of a near-square grid over the face's area-preserving unit-square map, the cells
//!   in a random order (so a partial batch is unbiased too).
//! - At each vertex `x` of the path, with throughput `beta` (the reflectances met so far over the Russian
//!   roulette survival probabilities), the emission reaching `x` directly is estimated with two samples
//!   combined by the balance heuristic of multiple importance sampling (E. Veach and L. Guibas, "Optimally
//!   combining sampling techniques for Monte Carlo rendering", SIGGRAPH 1995):
//!   - next-event estimation: an emitting polygon `k` chosen with probability `P_k` proportional to its area
//!     times its largest emission channel, a uniform point `y` on it and a shadow ray, contributing
//!     `beta E_k (cos θ_x / π) / (p_light + p_cos)` with the solid-angle densities
//!     `p_light = P_k / A_k * r² / cos θ_y` and `p_cos = cos θ_x / π`;
//!   - the bounce: a cosine-distributed direction (density `p_cos`); if it hits the front of an emitter, that
//!     emission contributes `beta E (p_cos / (p_light + p_cos))`. The two weights sum to 1, so emission is
//!     counted once. Either alone would do in principle, but light sampling alone has infinite variance where
//!     a receiver touches an emitter (the kernel `cos cos / r²` is not square-integrable along a shared edge,
//!     as in `scenes/perpendicular-squares.obj`), and the bounce alone is slow for small lights.
//! - The bounce then continues from the surface hit with `beta *= rho`, and Russian roulette ends it with
//!   probability `1 - min(1, max channel of beta)` (dividing `beta` by the survival probability keeps it
//!   unbiased). A path ends when its bounce ray escapes, hits the back of a face, or is absorbed.
//!
//! # Rays
//! Rays start on surfaces, so their origins are lifted off the surface along its normal by the caster's
//! [`RayCaster::offset`] (and tested from `tnear = 0`), rather than cut along the ray as [`Ray::segment`]
//! does: a point within the offset of a concave edge (a wall standing on the floor, a furnace's corner) would
//! otherwise send rays that skip the neighbouring face and leak out of the scene. Shadow rays run between the
//! two lifted points. The shadow rays of one bounce of a batch go to [`RayCaster::occluded_many`] together
//! (Embree's 16-wide packets); bounce rays use [`RayCaster::intersect`].
//!
//! # Standard error and stopping
//! Per face, the standard error of `B_f` is `rho_f` times that of the mean of the `H` samples, from their
//! sample variance over all paths of the face (`s^2 / n`). Stratification makes the true variance of the mean
//! smaller than `s^2 / n` and never larger, so the reported error is conservative. With
//! [`SampleCount::PerFace`] every face gets that many paths. With [`SampleCount::TargetRelative`], every face
//! first gets [`FIRST_ROUND_SAMPLES`] (at most the cap), then rounds add batches to the faces whose relative
//! standard error (largest over the channels with `B > 0`) is above the target, as many as the current error
//! predicts (`n (rel / target)^2`, at least one batch, at most three times what the face has), until every face
//! meets it or reaches the cap; [`ContinuousReference::target_met`] says which happened. (A stopping rule that
//! looks at the estimates can bias them slightly: a face stops a little more often after a low variance
//! estimate. [`SampleCount::PerFace`] has no such effect, which is why the tests use it.)
//!
//! # Determinism
//! The path of sample `n` of face `f` draws from a generator keyed by `(seed, f, n)`, the strata of batch `b`
//! from one keyed by `(seed, f, b)`; each batch's moments are summed in sample order and batches are merged
//! in a fixed order, so the result is the same for any thread count.
//!
//! # Files
//! `tracer` (the scene as paths see it, one batch of paths) -> `report` (the result types, text and CSV) ->
//! this module (options, rounds, threads); `probe` starts the same paths from given points
//! ([`probe_radiosity`]).

mod probe;
mod report;
mod tracer;

use std::io::IsTerminal;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

pub use probe::{probe_radiosity, Probe, ProbeEstimate, ON_FACE};
pub use report::{ContinuousReference, FaceReference, FACE_CSV_HEADER};

use crate::embree::EmbreeError;
use crate::formfactor::FormFactorError;
use crate::lighting::PatchLighting;
use crate::limits::{MAX_PATHS, MAX_THREADS};
use crate::mesh::{mesh, MeshError, MeshOptions};
use crate::patch::Patch;
#[cfg(doc)]
use crate::raycast::Ray;
use crate::raycast::RayCaster;
use crate::rgb::Rgb;
use crate::scene::Scene;
use tracer::{Moments, TraceScene};

/// Paths per stratified batch: the unit of work handed to a thread, and the step by which
/// [`SampleCount::TargetRelative`] adds samples.
pub const BATCH_SIZE: usize = 256;

/// Paths per face in the first round of [`SampleCount::TargetRelative`] (before the cap): enough for the
/// sample variance that predicts the next round.
pub const FIRST_ROUND_SAMPLES: u64 = 4 * BATCH_SIZE as u64;

/// Default relative standard error per face ([`ReferenceOptions::default`], `radiosity reference`).
pub const DEFAULT_TARGET: f64 = 0.01;

/// Default cap on paths per face with a target standard error.
pub const DEFAULT_MAX_SAMPLES: u64 = 1 << 20;

/// How many paths each face gets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleCount {
    /// This many paths per face (at least 1).
    PerFace(u64),
    /// Add paths until the relative standard error of every face is at most `target` (in `(0, 1)`), or the face
    /// has `max_samples` paths.
    TargetRelative {
        /// Relative standard error to reach per face (largest over the channels).
        target: f64,
        /// Most paths per face (at least 1).
        max_samples: u64,
    },
}

/// Settings of [`continuous_reference`].
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOptions {
    /// Paths per face.
    pub samples: SampleCount,
    /// Seed of all random numbers; equal seeds give identical results whatever the thread count.
    pub seed: u64,
    /// Worker threads; `None` uses rayon's global pool.
    pub threads: Option<usize>,
    /// Show a progress bar on stderr (only when stderr is a terminal).
    pub progress: bool,
    /// Build the Embree scene with `RTC_SCENE_FLAG_ROBUST` (watertight edges: no ray slips between two
    /// triangles of a closed scene).
    pub robust: bool,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions {
            samples: SampleCount::TargetRelative { target: DEFAULT_TARGET, max_samples: DEFAULT_MAX_SAMPLES },
            seed: 1,
            threads: None,
            progress: true,
            robust: true,
        }
    }
}

/// Why the continuous reference could not be computed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MonteCarloError {
    /// An option is out of range.
    #[error("continuous reference option {name}: {problem}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// The scene's faces could not be turned into polygons.
    #[error("meshing the scene's faces: {0}")]
    Mesh(#[from] MeshError),
    /// Embree failed to build the scene.
    #[error("building the ray-casting scene: {0}")]
    Embree(#[from] EmbreeError),
    /// The caster does not hold the scene's occluder mesh: it reported a triangle index beyond it.
    #[error(
        "the ray caster reported triangle {primitive}, but the scene's occluder mesh has {triangles} triangles \
         (the caster must be built from occluder_mesh(reference_patches(scene)))"
    )]
    CasterMismatch {
        /// The triangle index reported.
        primitive: u32,
        /// Triangles of the occluder mesh.
        triangles: usize,
    },
    /// The rayon thread pool could not be built.
    #[error("building a thread pool of {threads} threads: {message}")]
    ThreadPool {
        /// Requested thread count.
        threads: usize,
        /// rayon's message.
        message: String,
    },
}

/// Checks `options`.
///
/// # Errors
/// [`MonteCarloError::InvalidOption`] for zero samples, a target that is not a number in `(0, 1)`, a zero cap,
/// samples or a cap above [`crate::limits::MAX_PATHS`], or threads outside `1..=`[`crate::limits::MAX_THREADS`].
pub fn validate_options(options: &ReferenceOptions) -> Result<(), MonteCarloError> {
    let invalid =
        |name, problem: &str| Err(MonteCarloError::InvalidOption { name, problem: problem.to_owned() });
    match options.samples {
        SampleCount::PerFace(0) => return invalid("samples", "must be at least 1 path per face"),
        SampleCount::TargetRelative { target, .. } if !(target > 0.0 && target < 1.0) => {
            return Err(MonteCarloError::InvalidOption {
                name: "target-se",
                problem: format!("{target} is not a relative standard error in (0, 1)"),
            });
        }
        SampleCount::TargetRelative { max_samples: 0, .. } => {
            return invalid("max-samples", "must be at least 1 path per face")
        }
        _ => {}
    }
    let paths = match options.samples {
        SampleCount::PerFace(n) => ("samples", n),
        SampleCount::TargetRelative { max_samples, .. } => ("max-samples", max_samples),
    };
    if paths.1 > MAX_PATHS {
        return Err(MonteCarloError::InvalidOption {
            name: paths.0,
            problem: format!("{} is more than {MAX_PATHS} paths per face", paths.1),
        });
    }
    if options.threads == Some(0) {
        return invalid("threads", "must be at least 1");
    }
    if let Some(t) = options.threads.filter(|&t| t > MAX_THREADS) {
        return Err(MonteCarloError::InvalidOption {
            name: "threads",
            problem: format!("{t} is more than {MAX_THREADS} worker threads"),
        });
    }
    Ok(())
}

/// The polygons the path tracer sees: one patch per face polygon (the unsubdivided mesh, whatever the scene's
/// patch budget), in face order. A caster for [`continuous_reference_with`] must hold their
/// [`crate::formfactor::occluder_mesh`] (e.g. [`crate::formfactor::occluder_bvh`] of them).
///
/// # Errors
/// [`MonteCarloError::Mesh`] if a polygon cannot be made a patch.
pub fn reference_patches(scene: &Scene) -> Result<Vec<Patch>, MonteCarloError> {
    // The faces as loaded: the tracer samples whole OBJ faces (a fragment no point can see gets B = E there).
    let options = MeshOptions {
        subdivide: false,
        max_patch_edge: f64::INFINITY,
        patch_budget: usize::MAX,
        repair: false,
    };
    Ok(mesh(scene, &options)?.patches)
}

/// The continuous reference of `scene` with Embree as the ray caster.
///
/// # Errors
/// [`MonteCarloError`] for bad options (checked first), a scene that cannot be meshed, or Embree or the thread
/// pool failing.
pub fn continuous_reference(
    scene: &Scene,
    options: &ReferenceOptions,
) -> Result<ContinuousReference, MonteCarloError> {
    validate_options(options)?;
    let patches = reference_patches(scene)?;
    let caster = crate::formfactor::occluder_scene(&patches, options.robust).map_err(|e| match e {
        FormFactorError::Embree(e) => MonteCarloError::Embree(e),
        other => MonteCarloError::InvalidOption { name: "scene", problem: other.to_string() },
    })?;
    estimate(&caster, scene, &patches, options)
}

/// The continuous reference of `scene` with the rays cast by `caster`, which must hold the
/// [`crate::formfactor::occluder_mesh`] of [`reference_patches`]`(scene)`. `options.robust` is Embree's and has no effect here.
///
/// # Errors
/// [`MonteCarloError`] for bad options (checked first), a scene that cannot be meshed, a caster that does not
/// hold the scene's mesh, or the thread pool failing.
pub fn continuous_reference_with<C: RayCaster + ?Sized>(
    caster: &C,
    scene: &Scene,
    options: &ReferenceOptions,
) -> Result<ContinuousReference, MonteCarloError> {
    validate_options(options)?;
    let patches = reference_patches(scene)?;
    estimate(caster, scene, &patches, options)
}

/// One batch of one round: paths `first..first + count` of `face`, batch index `batch`.
#[derive(Clone, Copy, Debug)]
struct Task {
    face: usize,
    batch: u64,
    first: u64,
    count: usize,
}

/// The rounds, on validated options.
fn estimate<C: RayCaster + ?Sized>(
    caster: &C,
    scene: &Scene,
    patches: &[Patch],
    options: &ReferenceOptions,
) -> Result<ContinuousReference, MonteCarloError> {
    let start = Instant::now();
    let lighting = PatchLighting::new(scene, patches);
    let faces = scene.faces.len();
    let traced = TraceScene::new(patches, &lighting, faces, f64::from(caster.offset()));
    // The first patch of each face carries its material (a split face's triangles share it).
    let mut first_patch = vec![usize::MAX; faces];
    for (k, p) in patches.iter().enumerate().rev() {
        first_patch[p.face] = k;
    }
    let (rho, emission): (Vec<Rgb>, Vec<Rgb>) =
        first_patch.iter().map(|&k| (traced.rho(k), traced.emission(k))).unzip();

    let mut moments = vec![Moments::default(); faces];
    let mut add: Vec<u64> = match options.samples {
        SampleCount::PerFace(n) => vec![n; faces],
        SampleCount::TargetRelative { max_samples, .. } => vec![FIRST_ROUND_SAMPLES.min(max_samples); faces],
    };
    let mut rounds = 0;
    let run = |tasks: &[Task], bar: &ProgressBar| -> Result<Vec<Moments>, MonteCarloError> {
        tasks
            .par_iter()
            .map(|t| {
                let m = traced.trace_batch(caster, options.seed, t.face, t.batch, t.first, t.count);
                bar.inc(1);
                m
            })
            .collect()
    };
    let pool = match options.threads {
        None => None,
        Some(threads) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| MonteCarloError::ThreadPool { threads, message: e.to_string() })?,
        ),
    };
    loop {
        let tasks = plan(&moments, &add);
        if tasks.is_empty() {
            break;
        }
        rounds += 1;
        let bar = progress_bar(options.progress, tasks.len(), rounds);
        let results = match &pool {
            None => run(&tasks, &bar)?,
            Some(pool) => pool.install(|| run(&tasks, &bar))?,
        };
        bar.finish_and_clear();
        for (task, m) in tasks.iter().zip(results) {
            moments[task.face] = moments[task.face].merge(m);
        }
        add = match options.samples {
            SampleCount::PerFace(_) => vec![0; faces],
            SampleCount::TargetRelative { target, max_samples } => (0..faces)
                .map(|f| next_round(&moments[f], rho[f], emission[f], target, max_samples))
                .collect(),
        };
    }
    let reports: Vec<FaceReference> = scene
        .faces
        .iter()
        .enumerate()
        .map(|(f, face)| {
            let m = &moments[f];
            FaceReference::new(
                f,
                face.place(),
                face.area,
                rho[f],
                emission[f],
                emission[f] + rho[f] * m.mean,
                rho[f] * m.standard_error(),
                m.count,
            )
        })
        .collect();
    let target = match options.samples {
        SampleCount::PerFace(_) => None,
        SampleCount::TargetRelative { target, .. } => Some(target),
    };
    let rays = moments.iter().map(|m| m.rays).sum();
    Ok(ContinuousReference::new(reports, target, options.seed, rounds, rays, start.elapsed()))
}

/// The batches that give face `f` `add[f]` more paths after the ones `moments[f]` holds (batch `b` holds paths
/// `b * BATCH_SIZE ..`), in face order.
fn plan(moments: &[Moments], add: &[u64]) -> Vec<Task> {
    let batch = BATCH_SIZE as u64;
    let mut tasks = Vec::new();
    for (face, (m, &n)) in moments.iter().zip(add).enumerate() {
        let (mut first, end) = (m.count, m.count + n);
        while first < end {
            let stop = ((first / batch + 1) * batch).min(end);
            tasks.push(Task { face, batch: first / batch, first, count: (stop - first) as usize });
            first = stop;
        }
    }
    tasks
}

/// Paths to add to a face with moments `m` (reflectance `rho`, emission `e`) to reach the relative standard
/// error `target` (see the module docs); 0 when it has or when it is at the cap.
fn next_round(m: &Moments, rho: Rgb, e: Rgb, target: f64, max_samples: u64) -> u64 {
    let relative = report::relative_error(e + rho * m.mean, rho * m.standard_error());
    if relative <= target || m.count >= max_samples {
        return 0;
    }
    let batch = BATCH_SIZE as u64;
    let predicted = (m.count as f64 * (relative / target).powi(2)).ceil();
    let wanted = (predicted - m.count as f64).clamp(batch as f64, 3.0 * m.count as f64) as u64;
    wanted.div_ceil(batch).saturating_mul(batch).min(max_samples - m.count)
}

/// A progress bar over the batches of round `round` on stderr, or a hidden one.
fn progress_bar(show: bool, batches: usize, round: usize) -> ProgressBar {
    if !(show && std::io::stderr().is_terminal()) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(batches as u64);
    let template =
        format!("continuous reference, round {round} {{bar:40}} {{pos}}/{{len}} batches, eta {{eta}}");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_follow_the_fixed_grid() {
        let m = Moments { count: 300, ..Moments::default() };
        let tasks = plan(&[Moments::default(), m], &[300, 600]);
        let spans: Vec<(usize, u64, u64, usize)> =
            tasks.iter().map(|t| (t.face, t.batch, t.first, t.count)).collect();
        assert_eq!(
            spans,
            vec![(0, 0, 0, 256), (0, 1, 256, 44), (1, 1, 300, 212), (1, 2, 512, 256), (1, 3, 768, 132)]
        );
    }

    #[test]
    fn rounds_grow_towards_the_target_and_stop_at_the_cap() {
        // Relative error 0.04 at 1024 paths against a target of 0.01: 16x the paths predicted, capped at 3x
        // what the face has.
        let m =
            Moments { count: 1024, mean: Rgb::ONE, m2: Rgb::splat(0.04 * 0.04 * 1023.0 * 1024.0), rays: 0 };
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.01, 1 << 20), 3 * 1024);
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.02, 1 << 20), 3 * 1024);
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.03, 1 << 20), 1024);
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.05, 1 << 20), 0);
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.01, 1500), 1500 - 1024);
        assert_eq!(next_round(&m, Rgb::ONE, Rgb::ZERO, 0.01, 1024), 0);
    }

    #[test]
    fn merged_moments_equal_one_pass() {
        let mut rng = crate::rng::SplitMix64::new(5);
        let xs: Vec<Rgb> = (0..100).map(|_| Rgb::new(rng.unit(), rng.unit() * 3.0, 1.0)).collect();
        let mut all = Moments::default();
        let (mut a, mut b) = (Moments::default(), Moments::default());
        for (k, x) in xs.iter().enumerate() {
            all.push_sample(*x);
            if k < 37 {
                a.push_sample(*x);
            } else {
                b.push_sample(*x);
            }
        }
        let merged = a.merge(b);
        assert_eq!(merged.count, all.count);
        // Both are sums of 100 terms of order 1 in different orders: equal to a few ulps of the sums.
        assert!((merged.mean - all.mean).abs().max_element() < 1e-14);
        assert!((merged.m2 - all.m2).abs().max_element() < 1e-12 * all.m2.max_element());
        assert_eq!(merged.standard_error().z, 0.0, "a constant channel has no error");
    }
}
