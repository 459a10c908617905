//! Patch-to-patch form factors: an exact point-to-polygon kernel times visibility from Embree occlusion rays.
//!
//! # Estimator
//! For patches `i` and `j`,
//! `F_ij = (1 / A_i) ∫_i ∫_j cos θ_x cos θ_y / (π r²) V(x, y) dA_y dA_x`.
//! We split it into the unoccluded form factor, computed without rays, and a visible fraction estimated with rays:
//!
//! `F_ij ≈ U_ij · v̂_ij`,  `U_ij = Σ_k w_k F_{x_k → j}`,  `v̂_ij = Σ_r w_r V_r / Σ_r w_r`.
//!
//! - `F_{x → j}` is the differential-area-to-polygon form factor, computed exactly with Lambert's contour
//!   integral `F = (1 / 2π) Σ_edges γ_e n_x · (R_e × R_{e+1}) / |R_e × R_{e+1}|` (J. H. Lambert, *Photometria*, 1760;
//!   in graphics: T. Nishita and E. Nakamae, "Continuous tone representation of three-dimensional objects taking
//!   account of shading and interreflection", SIGGRAPH 1985; D. R. Baum, H. E. Rushmeier and J. M. Winget, "Improving
//!   radiosity solutions through the use of analytically determined form-factors", SIGGRAPH 1989), after clipping
//!   `j` to the half-space above `x`'s tangent plane. `j` only receives on its front side (`x` must lie in front
//!   of `j`'s plane).
//! - `x_k`, `w_k`: a product Gauss-Legendre rule over `i` (weights sum to 1), `samples_per_patch` points. If `j`'s
//!   plane cuts `i`, the rule covers only the part of `i` in front of it (clipped exactly, weights scaled by its
//!   area fraction): the kernel vanishes behind the plane with a kink along the cut, which would otherwise slow
//!   the rule down (on a cube with a box inside, reciprocity error 0.14 without the clip, 1.9e-5 with it).
//! - `v̂_ij`: `rays_per_pair` occlusion rays from stratified (jittered) points on `i` to stratified points on `j`,
//!   paired through random permutations, each weighted by the kernel `w_r = cos θ_x cos θ_y / r²` (π cancels).
//!   This ratio estimator converges to `∫∫ K V / ∫∫ K`, so `U_ij · v̂_ij → F_ij`; it is exact (1 or 0) when `j`
//!   is fully visible or fully hidden from `i`, whatever the ray count. Visibility and `w` are symmetric in `x` and
//!   `y`, so one estimate per unordered pair serves both `F_ij` and `F_ji` (`v̂_ij = v̂_ji`): each pair's rays are
//!   cast once, and reciprocity `A_i F_ij = A_j F_ji` holds up to the quadrature error of `U` alone.
//!
//! # Why this estimator (measured accuracy per ray)
//! Rays only decide visibility; the 1/r² geometry, which dominates the variance of plain area-sampling Monte Carlo
//! (the Embree tests' estimator), is integrated without rays. For an unoccluded pair the error is the quadrature
//! error of `U_ij` alone, whatever the ray count: Gauss-Legendre 4 × 4 (the default) is within 4e-7 of the
//! shared-edge closed form (tests), where 16 jittered points missed the facing-squares value by 1.3% and the
//! shared-edge value by 5.7%, and plain area sampling has a standard deviation of about 20% with 16 rays. On a
//! half-occluded pair (the worst case for visibility) `estimator_beats_area_sampling_per_ray` in
//! `host/tests/formfactor.rs` measures the RMS error over 16 seeds at 16, 64 and 256 rays: 1.4e-2, 6.9e-3,
//! 2.6e-3 (14%, 6.9%, 2.6% of F = 0.0999), against 3.6e-2, 1.5e-2, 6.0e-3 for area sampling with the same rays
//! (and exact visibility). A per-point variant (each Gauss point's own kernel-weighted visible fraction from its
//! share of the rays) measured 2.3e-2, 1.1e-2, 4.9e-3 and was dropped.
//!
//! # Closure and open scenes
//! In a closed scene the visible patches tile each point's hemisphere, so `Σ_j F_{x → j} = 1` for every
//! quadrature point wherever nothing is occluded: a convex closed scene (the white-furnace cube) has row sums of 1
//! up to the quadrature error of touching pairs (below 1e-8). Where occlusion occurs, visible fractions are
//! estimated per pair, so raw row sums deviate from 1 by visibility noise (closed Cornell box, 354 patches, 16
//! rays per pair: 0.9911..1.0065). The furnace at rho = 0.99 multiplies that by 100, so closed scenes are closed,
//! and open scenes never are:
//!
//! 1. **Detect closure from data** ([`ClosureMode::Detect`]): [`ESCAPE_RAYS_PER_PATCH`] cosine-distributed rays
//!    from stratified points of every patch are tested against the whole scene out to 4 times its size. The scene
//!    is closed only if none escapes. A ray through an f32 crack between neighbouring triangles, or one starting
//!    within the ray offset of a contact edge, is not an opening: an escaped ray counts only if two rays from a
//!    point 1 % nearer the patch centroid, tilted 1e-3 rad either way, escape too. The open Cornell box loses
//!    16 % of its escape rays; the closed one none.
//! 2. **Correct only what is noisy.** A pair whose visible fraction is exactly 0 or 1 is exact up to quadrature
//!    (the ratio estimator returns 0 or 1 whatever the ray count); only partly visible pairs carry visibility
//!    noise, with variance about `G² (1 - v) / (v R)` for `G = A_i F_ij`, visible fraction `v` and `R` rays. The
//!    matrix is made reciprocal (the two estimates of each pair averaged), then
//!    [`FormFactorMatrix::close_rows`] applies the generalized least-squares correction: the smallest change of
//!    the energy exchanges, weighted by those variances, that is symmetric (keeps reciprocity) and makes every row
//!    sum to 1. Fully visible entries do not move; rows without a partly visible entry keep their estimate.
//!    Closed Cornell box: rows then sum to 1 within 5.3e-6 (the 5 rows left untouched; the corrected ones within
//!    1e-15). The change is reported ([`ClosureReport`]), never silent.
//! 3. **Open scenes are never renormalized.** Any robustly escaping ray leaves every row as estimated: the missing
//!    part of the hemisphere is physics, and its error (visibility noise) stays visible in the reported row-sum
//!    range. The open Cornell box keeps row sums from 0.05 to 1.
//!
//! # Near field and shared edges
//! The point kernel `F_{x → j}` stays bounded (at most 1/2 for a point on an edge `j` shares with `i`, the
//! half-plane limit) and only its derivative is singular there, while the `1/r²` integrand of plain Monte Carlo
//! has unbounded variance near the edge. Gauss-Legendre points are strictly interior, so no kernel is ever
//! evaluated on the shared edge. A fixed rule over `i` is still poor when `j` is nearer to `i` than `i`'s own size
//! (a wall standing on a floor patch that runs under it, a small refined patch beside a large one): the kernel
//! then varies on the scale of the distance, not of the patch. Such near pairs are integrated with the rule on
//! pieces of `i`: split in 4 (a centroid fan for polygons of 5 or more vertices) wherever a piece's bounding sphere
//! is within its diameter of `j`'s, [`NEAR_FIELD_DEPTH`] levels, and further up to [`NEAR_FIELD_MAX_DEPTH`] while a
//! piece is still larger than `j`. Measured on the open Cornell box's uniform mesh (282 patches): largest
//! reciprocity error `|A_i F_ij - A_j F_ji| / (A_i F_ij)` 0.41 without the split, 5.7e-3 with it, for 1.9x the
//! form-factor time; on the adaptive mesh (999 patches, patches of 4 sizes side by side) 0.66 -> 0.145. The
//! pipeline then averages the two estimates. Perpendicular unit squares sharing an edge: error 6.5e-8 (2 x 2
//! points), 1.2e-10 (4 x 4, the closed form's own precision). Ray end points are jittered in open strata, so no
//! ray starts or ends on an edge either. Points coplanar with `j` get 0 (they cannot see `j`'s front).
//!
//! Two near-field shapes defeat a split driven by bounding spheres, and get their own rule
//! (`near_field_integral`, up to [`SLIVER_DEPTH`] more levels, pieces only along the feature, so the cost grows
//! like one over its width): a **sliver** (a strip much longer than wide) as receiver, seen from a large patch
//! only within a few widths of it, and as sender (cut into short pieces); and **nearly touching parallel faces**,
//! whose kernel falls from 1 to 1/2 within a few gaps of the receiver's edges. Measured on `scenes/slab.obj`
//! (unit squares 1 mm apart, 1 x 0.001 sides): sliver -> floor 0.49859226 against Howell's 0.49859202 (a sixth of
//! the floor's estimate was missing before, and reciprocity halved the sliver rows), floor -> ceiling within 1e-9
//! of the closed form (was 1.7e-3 high), rows within 1.5e-6 of 1.
//!
//! # Cost
//! The work runs in two parallel passes over rows: unoccluded form factors (each ordered pair costs
//! `samples_per_patch` kernel evaluations, a clip and a contour sum), then visible fractions (each unordered pair
//! with a nonzero kernel either way casts `rays_per_pair` rays, in 16-wide packets). No test for "nothing can
//! occlude this pair" is made (an exact one costs O(patches) per pair, more than the rays it saves at the default
//! ray count), so rays are cast even in convex scenes. Pairs facing away from each other cost only a plane test.
//! [`FormFactorStats`] counts the kernel evaluations and times both passes; `radiosity bench` reports them
//! (`bench/REPORT.md`, "Bake throughput"). Measured there on the Cornell box, 1 thread (report of a5cb192): 87-94
//! ns per kernel evaluation against 145-156 ns per occlusion ray; 5.1 evaluations per ray at 498 patches (near
//! pairs are split) and 1.7 at 1,998, where the kernel pass is 69% and 41% of the time.
//!
//! # Determinism
//! Quadrature points are deterministic; the rays of pair `(i, j)` come from a generator seeded by `(seed, i, j)`,
//! and each row is summed in a fixed order, so the matrix is identical for any thread count.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::embree::{Device, EmbreeError, Ray, SceneOptions, TriangleScene};
use crate::patch::{Closure, FormFactorMatrix, Patch, ReciprocityChange};

/// Entries with `F_ij` below this are left out of the reciprocity error (their relative error is dominated by
/// sampling noise and they carry little energy).
pub const RECIPROCITY_MIN_FACTOR: f64 = 1e-3;

/// Cosine-distributed rays cast from each patch into its hemisphere to decide whether the scene is closed
/// ([`ClosureMode::Detect`]).
pub const ESCAPE_RAYS_PER_PATCH: usize = 64;

/// Whether to close the rows of a closed scene (see the module docs, "Closure and open scenes").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ClosureMode {
    /// Cast [`ESCAPE_RAYS_PER_PATCH`] rays from every patch; if none escapes the scene, it is closed and its rows
    /// are closed by rescaling the partly visible pairs only. Any escaping ray leaves every row as estimated.
    #[default]
    Detect,
    /// Never change rows (the raw estimate, e.g. to measure visibility noise).
    Off,
}

/// Settings of [`compute_form_factors`].
#[derive(Clone, Debug, PartialEq)]
pub struct FormFactorOptions {
    /// Sample points on each patch `i` (the outer quadrature): a Gauss-Legendre `n × n` rule with
    /// `n = round(sqrt(samples_per_patch))` on parallelograms, and on each fan triangle of other polygons.
    pub samples_per_patch: usize,
    /// Occlusion rays per pair `(i, j)` that estimate the visible fraction: from stratified points on `i` to
    /// stratified points on `j`.
    pub rays_per_pair: usize,
    /// Seed of all random numbers; equal seeds give identical matrices whatever the thread count.
    pub seed: u64,
    /// Show a progress bar on stderr (only when stderr is a terminal).
    pub progress: bool,
    /// Worker threads; `None` uses rayon's global pool.
    pub threads: Option<usize>,
    /// Build the Embree scene with `RTC_SCENE_FLAG_ROBUST` (watertight edges, slower).
    pub robust: bool,
    /// Whether to detect a closed scene and close its rows.
    pub closure: ClosureMode,
    /// Integrate pairs in the far field ([`FAR_FIELD_GAP`]) with the lower-order rule ([`far_field_order`]);
    /// `false` uses the full rule everywhere (to measure what the far-field rule changes).
    pub far_field: bool,
}

impl Default for FormFactorOptions {
    fn default() -> Self {
        Self {
            samples_per_patch: 16,
            rays_per_pair: 16,
            seed: 1,
            progress: true,
            threads: None,
            robust: true,
            closure: ClosureMode::Detect,
            far_field: true,
        }
    }
}

/// Statistics of one form-factor computation.
#[derive(Clone, Debug, PartialEq)]
pub struct FormFactorStats {
    /// Number of patches.
    pub patches: usize,
    /// Stored nonzero entries.
    pub nonzeros: usize,
    /// Smallest row sum of the returned matrix (after closure, if the scene was closed).
    pub row_sum_min: f64,
    /// Largest row sum of the returned matrix (after closure, if the scene was closed).
    pub row_sum_max: f64,
    /// Smallest row sum of the estimate, before closure.
    pub estimate_row_sum_min: f64,
    /// Largest row sum of the estimate, before closure.
    pub estimate_row_sum_max: f64,
    /// `max |A_i F_ij - A_j F_ji| / (A_i F_ij)` over entries with `F_ij >= RECIPROCITY_MIN_FACTOR` (0 if none), of
    /// the estimate (before closure, which makes the matrix reciprocal).
    pub reciprocity_error_max: f64,
    /// Entries of pairs that are partly visible (visible fraction strictly between 0 and 1) or whose visibility
    /// could not be measured: the only entries that carry visibility noise.
    pub partly_visible_entries: usize,
    /// Rays cast to decide whether the scene is closed (0 with [`ClosureMode::Off`]).
    pub escape_rays: u64,
    /// Of those, rays that hit nothing.
    pub escaped_rays: u64,
    /// What closing the rows did; `None` if the scene is open or closure is off.
    pub closure: Option<ClosureReport>,
    /// Occlusion rays cast.
    pub rays_cast: u64,
    /// Rays cast per second of wall time (the whole computation, kernels included).
    pub rays_per_second: f64,
    /// Pairs with a nonzero unoccluded form factor whose rays all landed where the kernel vanishes (part of `j`
    /// below `i`'s horizon), so no visibility was measured and the pair was taken as unoccluded.
    pub pairs_assumed_visible: u64,
    /// Point-to-polygon kernel evaluations (Lambert's contour sum) of the unoccluded form factors.
    pub kernel_evaluations: u64,
    /// Wall time of the unoccluded form factors (the kernels; no rays).
    pub kernel_time: Duration,
    /// Wall time of the visible fractions (finding the pairs, sampling the ray end points, casting the rays).
    pub visibility_time: Duration,
    /// Wall time of the whole computation.
    pub elapsed: Duration,
}

/// How the rows of a closed scene were closed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosureReport {
    /// How far apart each pair's two estimates `A_i F_ij`, `A_j F_ji` were when they were averaged (the matrix is
    /// made reciprocal first, see [`FormFactorMatrix::enforce_reciprocity`]).
    pub reciprocity_change: ReciprocityChange,
    /// The balancing of the partly visible entries.
    pub balance: Closure,
}

/// A form-factor matrix with what the estimator knows about each entry.
#[derive(Clone, Debug)]
pub struct FormFactorEstimate {
    /// The form factors.
    pub matrix: FormFactorMatrix,
    /// Statistics.
    pub stats: FormFactorStats,
    /// One flag per stored entry of `matrix` (same order as `matrix.value`): the pair is partly visible, i.e. a
    /// shadow boundary crosses one of the two patches (or its visibility could not be measured).
    pub partly_visible: Vec<bool>,
}

/// What went wrong computing form factors.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FormFactorError {
    /// A patch cannot be used: fewer than 3 vertices, non-finite values, zero area or a non-unit normal.
    #[error("patch {patch}: {problem}")]
    InvalidPatch {
        /// Index of the patch.
        patch: usize,
        /// What is wrong with it.
        problem: String,
    },
    /// An option is out of range.
    #[error("form-factor option {name}: {problem}")]
    InvalidOption {
        /// The option's field name.
        name: &'static str,
        /// What is wrong with it.
        problem: &'static str,
    },
    /// Embree failed to build the occluder scene.
    #[error("building the occluder scene: {0}")]
    Embree(#[from] EmbreeError),
    /// The rayon thread pool could not be built.
    #[error("building a thread pool of {threads} threads: {message}")]
    ThreadPool {
        /// Requested thread count.
        threads: usize,
        /// rayon's message.
        message: String,
    },
    /// More patches than column indices can hold.
    #[error("{0} patches exceed the u32 column index of FormFactorMatrix")]
    TooManyPatches(usize),
}

/// Computes the form-factor matrix of `patches`, which are also the occluders.
///
/// # Errors
/// [`FormFactorError`] for invalid patches or options, or if Embree or the thread pool cannot be set up.
pub fn compute_form_factors(
    patches: &[Patch],
    options: &FormFactorOptions,
) -> Result<(FormFactorMatrix, FormFactorStats), FormFactorError> {
    estimate_form_factors(patches, options).map(|e| (e.matrix, e.stats))
}

/// As [`compute_form_factors`], and also says which entries are partly visible (what adaptive meshing uses to
/// find shadow boundaries).
///
/// # Errors
/// [`FormFactorError`] for invalid patches or options, or if Embree or the thread pool cannot be set up.
pub fn estimate_form_factors(
    patches: &[Patch],
    options: &FormFactorOptions,
) -> Result<FormFactorEstimate, FormFactorError> {
    let start = Instant::now();
    validate(patches, options)?;
    let scene = occluder_scene(patches, options.robust)?;
    let samplers: Vec<PolygonSampler> = patches.iter().map(|p| PolygonSampler::new(&p.vertices)).collect();
    let order = (options.samples_per_patch as f64).sqrt().round().max(1.0) as usize;
    let rule = gauss_legendre(order);
    let quadratures: Vec<Quadrature> = patches.iter().map(|p| Quadrature::new(&p.vertices, &rule)).collect();
    let far_rule = gauss_legendre(far_field_order(order));
    let far_quadratures: Vec<Quadrature> =
        patches.iter().map(|p| Quadrature::new(&p.vertices, &far_rule)).collect();
    let receivers: Vec<Receiver> = patches.iter().map(Receiver::new).collect();

    let progress = if options.progress && std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(2 * patches.len() as u64);
        if let Ok(style) = ProgressStyle::with_template(
            "form factors {bar:40} {pos}/{len} rows (kernels, then rays), eta {eta}",
        ) {
            bar.set_style(style);
        }
        bar
    } else {
        ProgressBar::hidden()
    };
    let context = RowContext {
        patches,
        samplers: &samplers,
        quadratures: &quadratures,
        far_quadratures: &far_quadratures,
        receivers: &receivers,
        rule: &rule,
        scene: &scene,
        options,
        progress: &progress,
        scene_size: {
            let (lo, hi) = patches
                .iter()
                .flat_map(|p| p.vertices.iter())
                .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), v| {
                    (lo.min(*v), hi.max(*v))
                });
            if patches.is_empty() {
                0.0
            } else {
                (hi - lo).length()
            }
        },
    };
    let compute = || -> Phases {
        // Phase 1: unoccluded form factors, no rays.
        let phase = Instant::now();
        let (unoccluded, kernels): (Vec<Vec<(u32, f64)>>, Vec<u64>) =
            (0..patches.len()).into_par_iter().map(|i| context.unoccluded_row(i)).unzip();
        let kernel_time = phase.elapsed();
        // Phase 2: one visible fraction per unordered pair that needs one, computed in the row of its smaller index.
        let phase = Instant::now();
        // For each i, the j > i whose row holds i (ascending): the transpose's upper part, one pass over the rows
        // (a binary search of every later row from each row costs O(n^2 log n) scattered reads).
        let mut later: Vec<Vec<u32>> = vec![Vec::new(); patches.len()];
        for (j, row) in unoccluded.iter().enumerate() {
            for &(i, _) in row.iter().take_while(|&&(i, _)| (i as usize) < j) {
                later[i as usize].push(j as u32);
            }
        }
        let visibility: Vec<Visibility> = later
            .into_par_iter()
            .enumerate()
            .map(|(i, later)| context.visibility_row(i, &unoccluded[i], later))
            .collect();
        let visibility_time = phase.elapsed();
        let escapes = match options.closure {
            ClosureMode::Off => (0, 0),
            ClosureMode::Detect => (0..patches.len())
                .into_par_iter()
                .map(|i| context.escaping_rays(i))
                .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1)),
        };
        let timing = (kernels.iter().sum::<u64>(), kernel_time, visibility_time);
        (unoccluded, visibility, escapes, timing)
    };
    let (
        unoccluded,
        visibility,
        (escape_rays, escaped_rays),
        (kernel_evaluations, kernel_time, visibility_time),
    ) = match options.threads {
        None => compute(),
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| FormFactorError::ThreadPool { threads, message: e.to_string() })?
            .install(compute),
    };
    progress.finish_and_clear();

    // Phase 3: F_ij = U_ij v_{min(i,j), max(i,j)}.
    let mut matrix =
        FormFactorMatrix { n: patches.len(), row_start: vec![0], col: Vec::new(), value: Vec::new() };
    let rays_cast = visibility.iter().map(|v| v.rays).sum();
    let pairs_assumed_visible = visibility.iter().map(|v| v.pairs_assumed_visible).sum();
    let fraction = |i: usize, j: usize| {
        let (lo, hi) = if i < j { (i, j) } else { (j, i) };
        visibility[lo].fraction_for(hi as u32)
    };
    let mut walk = FractionWalk::new(&visibility);
    for (i, row) in unoccluded.iter().enumerate() {
        let mut own = 0;
        for &(j, u) in row {
            let v = walk.get(i, j as usize, &mut own);
            let f = u * if v.is_nan() { 1.0 } else { v };
            if f > 0.0 {
                matrix.col.push(j);
                matrix.value.push(f);
            }
        }
        matrix.row_start.push(matrix.col.len());
    }
    let row_sum_range = |m: &FormFactorMatrix| {
        if m.n == 0 {
            return (0.0, 0.0);
        }
        (0..m.n)
            .map(|i| m.row_sum(i) + 0.0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s), hi.max(s)))
    };
    let (estimate_row_sum_min, estimate_row_sum_max) = row_sum_range(&matrix);
    let reciprocity_error_max = reciprocity_error(&matrix, patches);
    let closed = options.closure == ClosureMode::Detect && escape_rays > 0 && escaped_rays == 0;
    let closure = if closed {
        let areas: Vec<f64> = patches.iter().map(|p| p.area).collect();
        let reciprocity_change = matrix.enforce_reciprocity(&areas);
        // Variance of a pair's visible fraction from R kernel-weighted rays: about v (1 - v) / R, so that of
        // G_ij = A_i U_ij v is (A_i U_ij)^2 v (1 - v) / R = G_ij^2 (1 - v) / v / R; R is common to all pairs and
        // cancels. Pairs whose visibility was assumed (NaN) get the largest such weight, (1 - v) / v at v = 1/2.
        let balance = matrix.close_rows(&areas, |i, j| {
            let v = fraction(i, j);
            let g = areas[i]
                * lookup_unoccluded(&unoccluded, i, j)
                    .max(lookup_unoccluded(&unoccluded, j, i) * areas[j] / areas[i]);
            if v.is_nan() {
                g * g
            } else if v > 0.0 && v < 1.0 {
                let g = g * v;
                g * g * (1.0 - v) / v
            } else {
                0.0
            }
        });
        Some(ClosureReport { reciprocity_change, balance })
    } else {
        None
    };
    let mut partly_visible = Vec::with_capacity(matrix.nonzeros());
    let mut walk = FractionWalk::new(&visibility);
    for i in 0..matrix.n {
        let mut own = 0;
        for (j, _) in matrix.row(i) {
            let v = walk.get(i, j, &mut own);
            partly_visible.push(v.is_nan() || (v > 0.0 && v < 1.0));
        }
    }
    let elapsed = start.elapsed();
    let (row_sum_min, row_sum_max) = row_sum_range(&matrix);
    let stats = FormFactorStats {
        patches: patches.len(),
        nonzeros: matrix.nonzeros(),
        row_sum_min,
        row_sum_max,
        estimate_row_sum_min,
        estimate_row_sum_max,
        reciprocity_error_max,
        partly_visible_entries: partly_visible.iter().filter(|&&p| p).count(),
        escape_rays,
        escaped_rays,
        closure,
        rays_cast,
        rays_per_second: rays_cast as f64 / elapsed.as_secs_f64().max(1e-9),
        pairs_assumed_visible,
        kernel_evaluations,
        kernel_time,
        visibility_time,
        elapsed,
    };
    Ok(FormFactorEstimate { matrix, stats, partly_visible })
}

/// `U_ij` from the unoccluded rows (0 if absent).
fn lookup_unoccluded(rows: &[Vec<(u32, f64)>], i: usize, j: usize) -> f64 {
    rows[i].binary_search_by_key(&(j as u32), |&(c, _)| c).map_or(0.0, |k| rows[i][k].1)
}

/// `max |A_i F_ij - A_j F_ji| / (A_i F_ij)` over entries with `F_ij >= RECIPROCITY_MIN_FACTOR` (0 if none).
///
/// # Panics
/// If `patches.len() != matrix.n`.
#[must_use]
pub fn reciprocity_error(matrix: &FormFactorMatrix, patches: &[Patch]) -> f64 {
    assert_eq!(patches.len(), matrix.n, "one patch per matrix row");
    let lookup = |i: usize, j: usize| -> f64 {
        let range = matrix.row_start[i]..matrix.row_start[i + 1];
        match matrix.col[range.clone()].binary_search(&(j as u32)) {
            Ok(k) => matrix.value[range.start + k],
            Err(_) => 0.0,
        }
    };
    let mut worst = 0.0f64;
    for i in 0..matrix.n {
        for (j, f_ij) in matrix.row(i) {
            if f_ij < RECIPROCITY_MIN_FACTOR {
                continue;
            }
            let forward = patches[i].area * f_ij;
            let backward = patches[j].area * lookup(j, i);
            worst = worst.max((forward - backward).abs() / forward);
        }
    }
    worst
}

fn validate(patches: &[Patch], options: &FormFactorOptions) -> Result<(), FormFactorError> {
    if options.samples_per_patch == 0 {
        return Err(FormFactorError::InvalidOption {
            name: "samples_per_patch",
            problem: "must be at least 1",
        });
    }
    if options.rays_per_pair == 0 {
        return Err(FormFactorError::InvalidOption { name: "rays_per_pair", problem: "must be at least 1" });
    }
    if options.threads == Some(0) {
        return Err(FormFactorError::InvalidOption { name: "threads", problem: "must be at least 1" });
    }
    if u32::try_from(patches.len()).is_err() {
        return Err(FormFactorError::TooManyPatches(patches.len()));
    }
    for (index, p) in patches.iter().enumerate() {
        let invalid = |problem: String| FormFactorError::InvalidPatch { patch: index, problem };
        if p.vertices.len() < 3 {
            return Err(invalid(format!("{} vertices, a polygon needs at least 3", p.vertices.len())));
        }
        if let Some(k) = p.vertices.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!("vertex {k} is not finite: {}", p.vertices[k])));
        }
        if !(p.area.is_finite() && p.area > 0.0) {
            return Err(invalid(format!("area {} is not positive and finite", p.area)));
        }
        if !p.normal.is_finite() || (p.normal.length() - 1.0).abs() > 1e-6 {
            return Err(invalid(format!("normal {} is not a unit vector", p.normal)));
        }
    }
    Ok(())
}

/// The patches' polygons, fan-triangulated, as one Embree mesh: the occluders the estimator's visibility rays
/// are tested against (public so benchmarks can cast raw rays against exactly the same scene).
///
/// # Errors
/// If Embree fails to build the scene.
pub fn occluder_scene(patches: &[Patch], robust: bool) -> Result<TriangleScene, FormFactorError> {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for p in patches {
        let base = vertices.len() as u32;
        vertices.extend(p.vertices.iter().map(|v| v.as_vec3()));
        for k in 1..p.vertices.len().saturating_sub(1) as u32 {
            triangles.push([base, base + k, base + k + 1]);
        }
    }
    Ok(Device::new()?.triangle_scene(&vertices, &triangles, SceneOptions { robust })?)
}

/// Exact form factor from a differential area at `x` with unit normal `normal` to the convex `polygon` whose
/// front side faces `polygon_normal`, ignoring occlusion.
///
/// Lambert's contour integral (see the module docs for references) over `polygon` clipped to the half-space
/// `normal · (y - x) >= 0`. Zero if `x` is not strictly in front of the polygon's plane.
#[must_use]
pub fn point_to_polygon(x: DVec3, normal: DVec3, polygon: &[DVec3], polygon_normal: DVec3) -> f64 {
    let mut scratch = Vec::with_capacity(polygon.len() + 1);
    point_to_polygon_with(x, normal, polygon, polygon_normal, &mut scratch)
}

fn point_to_polygon_with(
    x: DVec3,
    normal: DVec3,
    polygon: &[DVec3],
    polygon_normal: DVec3,
    clipped: &mut Vec<DVec3>,
) -> f64 {
    let Some(&p0) = polygon.first() else { return 0.0 };
    let offset = x - p0;
    // Strictly in front, with a relative tolerance so points coplanar with the polygon (up to rounding) get 0.
    if polygon_normal.dot(offset) <= 1e-12 * offset.length() {
        return 0.0;
    }
    // Sutherland-Hodgman clip against the tangent plane at x: keep h = normal · (y - x) >= 0. A polygon wholly
    // above the plane (the common case) is its own clip.
    let height = |y: DVec3| normal.dot(y - x);
    let vertices: &[DVec3] = if polygon.iter().all(|&y| height(y) >= 0.0) {
        polygon
    } else {
        clip_above(polygon, height, clipped);
        clipped
    };
    let Some(&first) = vertices.first() else { return 0.0 };
    if vertices.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    let mut r0 = first - x;
    for &v in vertices[1..].iter().chain(std::iter::once(&first)) {
        let r1 = v - x;
        let c = r0.cross(r1);
        let c_len = c.length();
        if c_len != 0.0 {
            // (Zero: x is on the edge's line and the edge subtends no angle; x on the edge itself is excluded
            // above.)
            sum += edge_angle(c_len, r0.dot(r1)) * normal.dot(c) / c_len;
        }
        r0 = r1;
    }
    // The clipped polygon lies wholly above x's tangent plane and in front of itself, so every part of the
    // contour integral has the same sign; the orientation of the vertex order only flips that sign.
    sum.abs() / std::f64::consts::TAU
}

/// `atan2(y, x)` for `y >= 0`: the angle in `[0, π]` between two vectors from `y = |a × b|` and `x = a · b`.
///
/// The contour sum takes one per polygon edge and sample point; the platform's `atan2` had 29% of the bake's
/// profile samples (perf, Cornell box, 518 patches). This one reduces the argument to `|u| <= tan(π/16)` (swap to
/// `t = min/max <= 1`, then `atan t = c + atan((t - tan c) / (1 + t tan c))` for `c` in `{0, π/8, π/4}`, one
/// division in all) and sums the Taylor series `u - u³/3 + u⁵/5 - ...` through `u²¹/21`: the first omitted term
/// is below `tan(π/16)^22 / 23 = 1.6e-17` of `u`, so the result is within a few rounding errors of the exact
/// angle (the unit test bounds it at 4 ulp against `f64::atan2`; measured worst 2). `y = x = 0` gives 0; NaN
/// gives NaN.
#[inline]
fn edge_angle(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_8, PI};
    /// `tan(π/16)` and `tan(3π/16)`: the bounds between the three reduction centres.
    const TAN_PI_16: f64 = 0.198_912_367_379_658;
    const TAN_3PI_16: f64 = 0.668_178_637_919_298_9;
    /// `tan(π/8) = √2 - 1`.
    const TAN_PI_8: f64 = 0.414_213_562_373_095_05;
    let ax = x.abs();
    let swapped = y > ax;
    let (num, den) = if swapped { (ax, y) } else { (y, ax) };
    if den == 0.0 {
        return 0.0;
    }
    // With t = num / den: (t - tan c) / (1 + t tan c) = (num - den tan c) / (den + num tan c), one division.
    let (centre, top, bottom) = if num <= TAN_PI_16 * den {
        (0.0, num, den)
    } else if num <= TAN_3PI_16 * den {
        (FRAC_PI_8, num - TAN_PI_8 * den, den + TAN_PI_8 * num)
    } else {
        (FRAC_PI_4, num - den, num + den)
    };
    let u = top / bottom;
    // atan u = u + u³ p(u²), p(z) = Σ_{m=0..9} (-1)^(m+1) z^m / (2m + 3), in Estrin's form (a shallower
    // dependency chain than Horner's).
    let z = u * u;
    let (z2, z4) = (z * z, z * z * (z * z));
    let q0 = -1.0 / 3.0 + z * (1.0 / 5.0);
    let q1 = -1.0 / 7.0 + z * (1.0 / 9.0);
    let q2 = -1.0 / 11.0 + z * (1.0 / 13.0);
    let q3 = -1.0 / 15.0 + z * (1.0 / 17.0);
    let q4 = -1.0 / 19.0 + z * (1.0 / 21.0);
    let p = (q0 + q1 * z2) + (q2 + q3 * z2) * z4 + q4 * (z4 * z4);
    let a = centre + (u + u * z * p);
    let a = if swapped { FRAC_PI_2 - a } else { a };
    if x < 0.0 {
        PI - a
    } else {
        a
    }
}

/// Maps the unit square onto a convex polygon, preserving area (uniform in, uniform out), so a stratified set
/// in the square is a stratified set on the polygon.
#[derive(Clone, Debug)]
struct PolygonSampler {
    /// Parallelograms: `v0 + s (v1 - v0) + t (v3 - v0)`, exact strata.
    parallelogram: Option<[DVec3; 3]>,
    /// Otherwise: fan triangles `(v0, v_k, v_{k+1})` with their cumulative area fractions.
    fan: Vec<([DVec3; 3], f64)>,
}

impl PolygonSampler {
    fn new(v: &[DVec3]) -> Self {
        let size = v.iter().map(|p| (*p - v[0]).length()).fold(0.0, f64::max);
        if v.len() == 4 && (v[0] + v[2] - v[1] - v[3]).length() <= 1e-12 * size {
            return Self { parallelogram: Some([v[0], v[1] - v[0], v[3] - v[0]]), fan: Vec::new() };
        }
        let areas: Vec<f64> =
            (1..v.len() - 1).map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length()).collect();
        let total: f64 = areas.iter().sum();
        let mut cumulative = 0.0;
        let fan = (1..v.len() - 1)
            .zip(&areas)
            .map(|(k, a)| {
                cumulative += a / total;
                ([v[0], v[k], v[k + 1]], cumulative)
            })
            .collect();
        Self { parallelogram: None, fan }
    }

    /// The point for `(s, t)` in the open unit square.
    fn point(&self, s: f64, t: f64) -> DVec3 {
        if let Some([o, a, b]) = self.parallelogram {
            return o + a * s + b * t;
        }
        let mut lower = 0.0;
        for (k, (tri, upper)) in self.fan.iter().enumerate() {
            if s < *upper || k + 1 == self.fan.len() {
                // Rescale s within this triangle's share, then the area-preserving square-to-triangle map
                // (Shirley 1990; Turk, "Generating random points in triangles", Graphics Gems 1990).
                let u = ((s - lower) / (upper - lower)).clamp(0.0, 1.0);
                let r = u.sqrt();
                return tri[0] * (1.0 - r) + tri[1] * (r * (1.0 - t)) + tri[2] * (r * t);
            }
            lower = *upper;
        }
        self.fan[0].0[0]
    }

    /// `count` stratified points: a jittered `a × b` grid with `a * b >= count`; returns all `a * b` of them.
    fn stratified(&self, count: usize, rng: &mut SplitMix64, out: &mut Vec<DVec3>) {
        let (a, b) = grid(count);
        out.clear();
        for row in 0..b {
            for col in 0..a {
                let s = (col as f64 + rng.open_unit()) / a as f64;
                let t = (row as f64 + rng.open_unit()) / b as f64;
                out.push(self.point(s, t));
            }
        }
    }
}

/// Gauss-Legendre nodes and weights on (0, 1), `n >= 1`: the roots of the Legendre polynomial `P_n` by Newton's
/// method from Tricomi's initial guesses `cos(π (k - 1/4) / (n + 1/2))`, weights `2 / ((1 - x²) P_n'(x)²)`
/// (Abramowitz and Stegun 25.4.29), mapped from (-1, 1).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut rule = Vec::with_capacity(n);
    for k in 1..=n {
        let mut x = (std::f64::consts::PI * (k as f64 - 0.25) / (n as f64 + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            // P_n(x) by the three-term recurrence, then P_n'(x) = n (x P_n - P_{n-1}) / (x² - 1).
            let (mut p_prev, mut p) = (1.0, x);
            for m in 2..=n {
                let next = ((2 * m - 1) as f64 * x * p - (m - 1) as f64 * p_prev) / m as f64;
                p_prev = p;
                p = next;
            }
            if n == 1 {
                p_prev = 1.0;
            }
            derivative = n as f64 * (x * p - p_prev) / (x * x - 1.0);
            let step = p / derivative;
            x -= step;
            if step.abs() <= 1e-15 {
                break;
            }
        }
        let weight = 2.0 / ((1.0 - x * x) * derivative * derivative);
        rule.push(((x + 1.0) / 2.0, weight / 2.0));
    }
    rule
}

/// Quadrature points on a patch with weights summing to 1 (area fractions).
#[derive(Clone, Debug)]
struct Quadrature {
    points: Vec<DVec3>,
    weights: Vec<f64>,
}

impl Quadrature {
    /// The product rule `rule × rule` on a parallelogram, or on each fan triangle `(v0, v_k, v_{k+1})` through the
    /// collapsed map `v0 + s (v_k - v0) + s t (v_{k+1} - v_k)` (Jacobian `2 area_k s`) otherwise.
    fn new(v: &[DVec3], rule: &[(f64, f64)]) -> Self {
        let mut points = Vec::new();
        let mut weights = Vec::new();
        let size = v.iter().map(|p| (*p - v[0]).length()).fold(0.0, f64::max);
        if v.len() == 4 && (v[0] + v[2] - v[1] - v[3]).length() <= 1e-12 * size {
            let (a, b) = (v[1] - v[0], v[3] - v[0]);
            for &(s, ws) in rule {
                for &(t, wt) in rule {
                    points.push(v[0] + a * s + b * t);
                    weights.push(ws * wt);
                }
            }
            return Self { points, weights };
        }
        let areas: Vec<f64> =
            (1..v.len() - 1).map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length()).collect();
        let total: f64 = areas.iter().sum();
        for (k, area) in (1..v.len() - 1).zip(&areas) {
            for &(s, ws) in rule {
                for &(t, wt) in rule {
                    points.push(v[0] + (v[k] - v[0]) * s + (v[k + 1] - v[k]) * (s * t));
                    weights.push(ws * wt * 2.0 * area * s / total);
                }
            }
        }
        Self { points, weights }
    }
}

/// The smallest near-square grid `a × b >= count`.
fn grid(count: usize) -> (usize, usize) {
    let a = (count as f64).sqrt().round().max(1.0) as usize;
    (a, count.div_ceil(a))
}

/// SplitMix64 (G. Steele, D. Lea, C. Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014):
/// tiny, seedable from any 64-bit value, good enough for jitter.
#[derive(Clone, Debug)]
pub(crate) struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator for one stream, seeded from `seed` and the stream's coordinates.
    pub(crate) fn for_stream(seed: u64, a: u64, b: u64) -> Self {
        let mut g = Self(seed);
        let k1 = g.next_u64() ^ a;
        g = Self(k1);
        let k2 = g.next_u64() ^ b;
        Self(k2)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in the open interval (0, 1): never exactly on a stratum's boundary.
    pub(crate) fn open_unit(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }

    /// Fisher-Yates shuffle (the modulo bias of `% (k + 1)`, below 2^-50, is irrelevant here).
    fn shuffle<T>(&mut self, items: &mut [T]) {
        for k in (1..items.len()).rev() {
            items.swap(k, (self.next_u64() % (k as u64 + 1)) as usize);
        }
    }
}

/// Unoccluded rows, visibility rows, (escape rays cast, escaped), and (kernel evaluations, wall time of the
/// kernel phase, wall time of the visibility phase).
type Phases = (Vec<Vec<(u32, f64)>>, Vec<Visibility>, (u64, u64), (u64, Duration, Duration));

struct RowContext<'a> {
    patches: &'a [Patch],
    samplers: &'a [PolygonSampler],
    quadratures: &'a [Quadrature],
    /// The lower-order rule of each patch for pairs in the far field ([`FAR_FIELD_GAP`]).
    far_quadratures: &'a [Quadrature],
    /// Each patch as a receiver of the near-field quadrature.
    receivers: &'a [Receiver<'a>],
    rule: &'a [(f64, f64)],
    scene: &'a TriangleScene,
    options: &'a FormFactorOptions,
    progress: &'a ProgressBar,
    /// Diagonal of the patches' bounding box.
    scene_size: f64,
}

/// The visible fractions a row computed: for pairs `(i, j)` with `j > i`, sorted by `j`.
struct Visibility {
    fractions: Vec<(u32, f64)>,
    rays: u64,
    pairs_assumed_visible: u64,
}

/// Visible fractions looked up in row-major order (rows ascending, columns ascending within a row) in O(1)
/// amortized: pair `(i, j)` lives in row `min(i, j)`, and both that row's own lookups (`j > i`) and the later rows'
/// lookups into it (`j < i`, with `i` ascending) ask for ascending keys, so a cursor per row only moves forward.
struct FractionWalk<'a> {
    visibility: &'a [Visibility],
    /// Per row `r`: the cursor of the lookups from rows below it (`j = r < i`).
    below: Vec<usize>,
}

impl<'a> FractionWalk<'a> {
    fn new(visibility: &'a [Visibility]) -> Self {
        FractionWalk { visibility, below: vec![0; visibility.len()] }
    }

    /// `v_ij` as [`Visibility::fraction_for`] gives it; `own` is row `i`'s cursor into its own fractions (start
    /// each row at 0).
    fn get(&mut self, i: usize, j: usize, own: &mut usize) -> f64 {
        let (row, cursor, key) = if j > i {
            (&self.visibility[i].fractions, own, j)
        } else {
            (&self.visibility[j].fractions, &mut self.below[j], i)
        };
        while row.get(*cursor).is_some_and(|&(c, _)| (c as usize) < key) {
            *cursor += 1;
        }
        match row.get(*cursor) {
            Some(&(c, v)) if c as usize == key => v,
            _ => 1.0,
        }
    }
}

impl Visibility {
    /// The visible fraction of pair `(i, j)` (this row is `i < j`); 1 if `j` needed none, which cannot happen for
    /// an entry of either unoccluded row since phase 2 covers both.
    fn fraction_for(&self, j: u32) -> f64 {
        match self.fractions.binary_search_by_key(&j, |&(c, _)| c) {
            Ok(k) => self.fractions[k].1,
            Err(_) => 1.0,
        }
    }
}

impl RowContext<'_> {
    /// `(rays cast, rays escaped)` for [`ESCAPE_RAYS_PER_PATCH`] cosine-distributed rays from stratified points of
    /// patch `i` in stratified directions (Malley's method: a stratified point on the unit disk lifted to the
    /// hemisphere), each tested against everything out to 4 times the scene's size.
    fn escaping_rays(&self, i: usize) -> (u64, u64) {
        let p = &self.patches[i];
        let mut rng = SplitMix64::for_stream(self.options.seed ^ 0x5EED_E5CA_9E00_0000, i as u64, u64::MAX);
        let mut origins = Vec::new();
        self.samplers[i].stratified(ESCAPE_RAYS_PER_PATCH, &mut rng, &mut origins);
        rng.shuffle(&mut origins);
        let (a, b) = grid(ESCAPE_RAYS_PER_PATCH);
        // An orthonormal frame around the normal (Duff et al., "Building an orthonormal basis, revisited", 2017).
        let n = p.normal;
        let sign = 1.0f64.copysign(n.z);
        let c = -1.0 / (sign + n.z);
        let d = n.x * n.y * c;
        let t1 = DVec3::new(1.0 + sign * n.x * n.x * c, sign * d, -sign * n.x);
        let t2 = DVec3::new(d, sign + n.y * n.y * c, -n.y);
        let offset = self.scene.offset();
        let far = 4.0 * self.scene_size as f32;
        let mut rays = Vec::with_capacity(a * b);
        for (k, x) in origins.iter().enumerate() {
            let (s, t) = (
                ((k % a) as f64 + rng.open_unit()) / a as f64,
                ((k / a) as f64 + rng.open_unit()) / b as f64,
            );
            let (r, phi) = (s.sqrt(), std::f64::consts::TAU * t);
            let dir = t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * (1.0 - s).max(0.0).sqrt();
            rays.push(Ray::new(x.as_vec3(), dir.normalize().as_vec3(), offset, far));
        }
        let mut occluded = vec![false; rays.len()];
        self.scene.occluded_many(&rays, &mut occluded);
        // A ray through a crack between triangles (f32 rounding at T-junctions of neighbouring faces' patches) is
        // not an opening: an escaped ray counts only if two rays from a nearby point, tilted by 1e-3 rad either
        // way (far wider than an f32 crack, far narrower than a real opening), escape too.
        let mut escaped = 0;
        for (ray, _) in rays.iter().zip(&occluded).filter(|(_, &o)| !o) {
            let d = ray.direction;
            let tilt = (t1 * 1e-3 + t2 * 1e-3).as_vec3();
            // Also from a point moved 1 % of the way to the centroid: a ray that starts within the ray offset of a
            // contact edge can slip past the touching face's edge, which is no opening either.
            let origin = (ray.origin.as_dvec3() * 0.99 + p.centroid * 0.01).as_vec3();
            let again = [
                Ray::new(origin, (d + tilt).normalize(), ray.tnear, ray.tfar),
                Ray::new(origin, (d - tilt).normalize(), ray.tnear, ray.tfar),
            ];
            if !self.scene.occluded(&again[0]) && !self.scene.occluded(&again[1]) {
                escaped += 1;
            }
        }
        (rays.len() as u64, escaped)
    }

    /// `U_ij` for every `j` that `i` can see, sorted by `j`, and the kernel evaluations that took.
    fn unoccluded_row(&self, i: usize) -> (Vec<(u32, f64)>, u64) {
        let patch_i = &self.patches[i];
        let mut clipped = Vec::new();
        let mut front = Vec::new();
        let mut strips = Vec::new();
        let mut row = Vec::new();
        let mut kernels = 0u64;
        for (j, patch_j) in self.patches.iter().enumerate() {
            if j == i || !may_see(patch_i, patch_j) {
                continue;
            }
            let mut kernel = |x: &DVec3| {
                kernels += 1;
                point_to_polygon_with(*x, patch_i.normal, &patch_j.vertices, patch_j.normal, &mut clipped)
            };
            // If j's plane cuts i, the kernel is zero on the part of i behind it and has a kink along the cut,
            // which slows the quadrature; integrate over the front part only (exactly clipped) instead.
            let domain: &[DVec3] = if clip_to_front(&patch_i.vertices, patch_j, &mut front) {
                &front
            } else {
                &patch_i.vertices
            };
            let receiver = &self.receivers[j];
            let is_near = near(domain, receiver.center, receiver.radius);
            let u: f64 = if is_near && sliver_strips(domain, &mut strips) {
                // Near field of a sliver sender: the kernel varies on the scale of the sliver's width (its points
                // are that close to j) along its whole length, and near j's edges along it too; integrate over
                // short pieces of it.
                strips
                    .iter()
                    .map(|piece| {
                        near_field_integral(
                            piece,
                            receiver,
                            self.rule,
                            patch_i.normal,
                            0,
                            SLIVER_DEPTH,
                            &mut kernel,
                        )
                    })
                    .sum::<f64>()
                    / patch_i.area
            } else if is_near {
                // Near field: j is closer to (part of) i than i's own size, so the kernel varies on a scale the
                // fixed rule cannot resolve; split the domain towards j.
                near_field_integral(
                    domain,
                    receiver,
                    self.rule,
                    patch_i.normal,
                    NEAR_FIELD_MAX_DEPTH,
                    SLIVER_DEPTH,
                    &mut kernel,
                ) / patch_i.area
            } else if domain.len() == patch_i.vertices.len() && std::ptr::eq(domain, &patch_i.vertices[..]) {
                let own = &self.receivers[i];
                let gap = own.center.distance(receiver.center) - own.radius - receiver.radius;
                let far = self.options.far_field && gap >= FAR_FIELD_GAP * 2.0 * own.radius;
                let Quadrature { points, weights } =
                    if far { &self.far_quadratures[i] } else { &self.quadratures[i] };
                points.iter().zip(weights).map(|(x, w)| w * kernel(x)).sum()
            } else {
                let part = Quadrature::new(domain, self.rule);
                let fraction = polygon_area(domain) / patch_i.area;
                fraction * part.points.iter().zip(&part.weights).map(|(x, w)| w * kernel(x)).sum::<f64>()
            };
            if u > 0.0 {
                row.push((j as u32, u));
            }
        }
        self.progress.inc(1);
        (row, kernels)
    }

    /// Visible fractions of the pairs `(i, j)`, `j > i`, for which `U_ij > 0` or `U_ji > 0`.
    ///
    /// Visibility and the ray weight `cos θ_x cos θ_y / r²` are symmetric in `x` and `y`, so one estimate serves
    /// `F_ij` and `F_ji`: reciprocity then holds up to the quadrature error of `U`, and each pair costs its rays once.
    ///
    /// `row` is `i`'s unoccluded row; `needed` comes with the `j > i` whose unoccluded rows hold `i`.
    fn visibility_row(&self, i: usize, row: &[(u32, f64)], mut needed: Vec<u32>) -> Visibility {
        needed.extend(row.iter().map(|&(j, _)| j).filter(|&j| j as usize > i));
        needed.sort_unstable();
        needed.dedup();

        let patch_i = &self.patches[i];
        let offset = f64::from(self.scene.offset());
        let rays_per_pair = self.options.rays_per_pair;
        let mut result =
            Visibility { fractions: Vec::with_capacity(needed.len()), rays: 0, pairs_assumed_visible: 0 };
        let (mut origins, mut targets) = (Vec::new(), Vec::new());
        let (mut rays, mut weights, mut occluded) = (Vec::new(), Vec::new(), Vec::new());
        for j in needed {
            let patch_j = &self.patches[j as usize];
            // Stratified points on i paired with stratified points on j through random permutations of both (the
            // pairs are stratified in each patch and random across them).
            let mut rng = SplitMix64::for_stream(self.options.seed, i as u64, u64::from(j));
            self.samplers[i].stratified(rays_per_pair, &mut rng, &mut origins);
            self.samplers[j as usize].stratified(rays_per_pair, &mut rng, &mut targets);
            rng.shuffle(&mut origins);
            rng.shuffle(&mut targets);
            rays.clear();
            weights.clear();
            for (x, y) in origins.iter().zip(&targets).take(rays_per_pair) {
                let d = *y - *x;
                let r2 = d.length_squared();
                // cos θ_x cos θ_y / r² (π cancels in the ratio); zero where either point is behind the other's
                // plane, where the integrand vanishes.
                let w = (patch_i.normal.dot(d) * -patch_j.normal.dot(d)).max(0.0) / (r2 * r2);
                if w > 0.0 && w.is_finite() {
                    rays.push(segment(*x, *y, offset));
                    weights.push(w);
                }
            }
            occluded.clear();
            occluded.resize(rays.len(), false);
            self.scene.occluded_many(&rays, &mut occluded);
            result.rays += rays.len() as u64;
            let total: f64 = weights.iter().sum();
            let visible: f64 =
                weights.iter().zip(&occluded).filter(|(_, &blocked)| !blocked).map(|(w, _)| w).sum();
            let fraction = if total > 0.0 {
                visible / total
            } else {
                // Every ray fell where the kernel vanishes (j mostly behind i's horizon): no evidence either way;
                // NaN marks it, and the pair is taken as visible.
                result.pairs_assumed_visible += 1;
                f64::NAN
            };
            result.fractions.push((j, fraction));
        }
        self.progress.inc(1);
        result
    }
}

/// If `to`'s plane cuts `polygon`, writes the part of `polygon` in front of it to `front` and returns true;
/// returns false if `polygon` lies wholly on one side (vertices within rounding of the plane count as on it, so a
/// shared edge is not a cut).
fn clip_to_front(polygon: &[DVec3], to: &Patch, front: &mut Vec<DVec3>) -> bool {
    let height = |v: DVec3| to.normal.dot(v - to.vertices[0]);
    let scale = polygon.iter().map(|v| (*v - polygon[0]).length()).fold(0.0, f64::max);
    let tolerance = 1e-12 * scale;
    let any_front = polygon.iter().any(|v| height(*v) > tolerance);
    let any_behind = polygon.iter().any(|v| height(*v) < -tolerance);
    if !(any_front && any_behind) {
        return false;
    }
    clip_above(polygon, height, front);
    front.len() >= 3
}

/// Sutherland-Hodgman: writes to `out` the part of the convex `polygon` where `height >= 0` (cut points linear
/// in the height along each crossing edge).
fn clip_above(polygon: &[DVec3], height: impl Fn(DVec3) -> f64, out: &mut Vec<DVec3>) {
    out.clear();
    for (k, &a) in polygon.iter().enumerate() {
        let b = polygon[if k + 1 == polygon.len() { 0 } else { k + 1 }];
        let (ha, hb) = (height(a), height(b));
        if ha >= 0.0 {
            out.push(a);
        }
        if (ha >= 0.0) != (hb >= 0.0) {
            out.push(a + (b - a) * (ha / (ha - hb)));
        }
    }
}

/// Levels of splitting of the near-field quadrature: at most `4^NEAR_FIELD_DEPTH` pieces of the sending patch
/// (for triangles and quadrilaterals) near the receiver.
pub const NEAR_FIELD_DEPTH: usize = 3;

/// Most levels of splitting of the near-field quadrature, used while a piece is larger than the receiver.
pub const NEAR_FIELD_MAX_DEPTH: usize = 6;

/// Centroid of the vertices and the largest distance from it to a vertex.
fn bounding_sphere(polygon: &[DVec3]) -> (DVec3, f64) {
    let c = polygon.iter().copied().sum::<DVec3>() / polygon.len() as f64;
    (c, polygon.iter().map(|v| v.distance(c)).fold(0.0, f64::max))
}

/// Whether a receiver inside the sphere `(center, radius)` is nearer to `domain` than `domain`'s own diameter
/// (measured between bounding spheres, so conservative): then a fixed product rule over `domain` is inaccurate
/// (its error grows like a power of size / distance).
/// A pair is in the far field when the gap between the bounding spheres of `i` and `j` is at least this many
/// diameters of `i`: the kernel then varies on a scale `D` at least that many times `i`'s size `h`, and the
/// product Gauss-Legendre rule of half the order ([`far_field_order`]) suffices. Its relative error is about
/// `c (h / D)^(2m)` for `m` points per direction (Davis and Rabinowitz, "Methods of Numerical Integration",
/// 2nd ed., section 2.7: `f^(2m)` of a kernel falling like `D^-3` is about `(2m + 2)! / 2 D^-(2m)` times it);
/// with `m = 2`, `c` about 0.1 and `h / D <= 1/5` that is about `1.6e-4`, below the 16-bit codec's `2.4e-4`
/// and the visibility noise of the default 16 rays per pair. Measured on the Cornell box (282 patches) by the
/// test `far_field_rule_matches_the_full_rule`: 3% of the entries use it, worst relative change 8.2e-5. The
/// share grows with the patch count: at about 4,000 patches the form factors take 21 s instead of 35 s.
pub const FAR_FIELD_GAP: f64 = 5.0;

/// Points per direction of the far-field rule for a full rule of `order` points per direction: half, at least 2
/// (or the full order when that is smaller).
#[must_use]
pub fn far_field_order(order: usize) -> usize {
    order.div_ceil(2).max(2).min(order)
}

fn near(domain: &[DVec3], center: DVec3, radius: f64) -> bool {
    let (c, r) = bounding_sphere(domain);
    c.distance(center) - radius - r < 2.0 * r
}

/// Extra levels of splitting of the near-field quadrature towards a sliver receiver (`Receiver::sliver_width`),
/// beyond [`NEAR_FIELD_MAX_DEPTH`]: pieces down to `2^-(NEAR_FIELD_MAX_DEPTH + SLIVER_DEPTH)` of the sender's size.
pub const SLIVER_DEPTH: usize = 10;

/// If `polygon` is a sliver quadrilateral ([`sliver_width`]), cuts it
/// across its length into pieces about twice as long as it is wide (at most `2^SLIVER_DEPTH`), writes them to
/// `pieces` and returns true; returns false for anything else.
fn sliver_strips(polygon: &[DVec3], pieces: &mut Vec<Vec<DVec3>>) -> bool {
    let [a, b, c, d] = match polygon {
        &[a, b, c, d] => [a, b, c, d],
        _ => return false,
    };
    let Some(width) = sliver_width(polygon) else { return false };
    // The long sides: a -> b with d -> c, or b -> c with a -> d.
    let (p0, p1, q0, q1) = if a.distance(b) + d.distance(c) >= b.distance(c) + a.distance(d) {
        (a, b, d, c)
    } else {
        (b, c, a, d)
    };
    let length = 0.5 * (p0.distance(p1) + q0.distance(q1));
    let count = ((length / (2.0 * width)).ceil() as usize).clamp(1, 1 << SLIVER_DEPTH);
    pieces.clear();
    for k in 0..count {
        let (t0, t1) = (k as f64 / count as f64, (k + 1) as f64 / count as f64);
        pieces.push(vec![p0.lerp(p1, t0), p0.lerp(p1, t1), q0.lerp(q1, t1), q0.lerp(q1, t0)]);
    }
    true
}

/// `cos 25°`: a receiver whose normal is within 25° of the opposite of the sender's faces it, nearly parallel
/// (see [`near_field_integral`]; nearly coplanar neighbours, normals alike, are not meant).
const PARALLEL_COSINE: f64 = 0.906;

/// A receiving patch as the near-field quadrature sees it.
struct Receiver<'a> {
    /// Bounding sphere: centroid of the vertices and the largest distance from it to a vertex.
    center: DVec3,
    radius: f64,
    vertices: &'a [DVec3],
    normal: DVec3,
    /// Its width if it is a sliver ([`sliver_width`]).
    sliver_width: Option<f64>,
}

/// `2 A / P` of a polygon (area over half the perimeter: the width of a long strip) if that is positive and less
/// than an eighth of its bounding radius, i.e. the polygon is a sliver (a strip longer than about 16 times its
/// width); `None` otherwise.
fn sliver_width(polygon: &[DVec3]) -> Option<f64> {
    let perimeter: f64 =
        polygon.iter().zip(polygon.iter().cycle().skip(1)).map(|(a, b)| a.distance(*b)).sum();
    let width = 2.0 * polygon_area(polygon) / perimeter;
    let (_, radius) = bounding_sphere(polygon);
    (width > 0.0 && width < radius / 8.0).then_some(width)
}

impl<'a> Receiver<'a> {
    fn new(patch: &'a Patch) -> Self {
        let (center, radius) = bounding_sphere(&patch.vertices);
        let sliver_width = sliver_width(&patch.vertices);
        Receiver { center, radius, vertices: &patch.vertices, normal: patch.normal, sliver_width }
    }

    /// Distance from `x` to the (convex, planar) receiver polygon.
    fn distance(&self, x: DVec3) -> f64 {
        let height = self.normal.dot(x - self.vertices[0]);
        let p = x - height * self.normal;
        let n = self.vertices.len();
        let side = |k: usize| {
            let (a, b) = (self.vertices[k], self.vertices[(k + 1) % n]);
            (b - a).cross(p - a).dot(self.normal)
        };
        // Either winding: inside if on the same side of every edge.
        let inside = (0..n).all(|k| side(k) >= 0.0) || (0..n).all(|k| side(k) <= 0.0);
        if inside {
            return height.abs();
        }
        self.boundary_distance(x)
    }

    /// Distance from `x` to the receiver's boundary (its edges).
    fn boundary_distance(&self, x: DVec3) -> f64 {
        let n = self.vertices.len();
        (0..n)
            .map(|k| {
                let (a, b) = (self.vertices[k], self.vertices[(k + 1) % n]);
                let ab = b - a;
                let t = ((x - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                x.distance(a + t * ab)
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// `∫_domain kernel dA`, splitting the domain (4 children for triangles and quadrilaterals, a centroid fan
/// otherwise) wherever it is [`near`] the receiver, up to `depth` levels, and applying the product rule on each
/// piece. Pieces far from the receiver keep the plain rule, so the cost stays small.
///
/// A sliver receiver (a strip of width `w` much less than its length, [`Receiver::sliver_width`]) makes the
/// kernel vary on the scale `w` next to it, whatever its bounding sphere says: a floor under a 1 mm high side
/// of a 1 m slab sees that side only from within a few mm of the edge (`F(x) ~ (1 - x / sqrt(x² + w²)) / 2` at
/// distance `x`, whose integral is `w / 2` per unit of edge). Pieces larger than `w` whose centre is within
/// three radii of the sliver itself (the true distance to its polygon) are therefore split further, up to
/// `sliver_depth` more levels; only the pieces along the sliver split, so the cost grows like `1 / w`, not
/// `1 / w²`. Likewise a nearly parallel receiver facing the piece at a gap `g` much smaller than a piece (a
/// floor 1 mm under a ceiling) makes the kernel fall from 1 to 1/2 within a few `g` of the receiver's edges:
/// pieces more than twice their gap across and within their size of those edges are split further, within the
/// same extra levels.
/// Ordinary receivers are unaffected: a perpendicular one touching the piece is at about the piece's own size
/// from its centre.
fn near_field_integral(
    domain: &[DVec3],
    receiver: &Receiver,
    rule: &[(f64, f64)],
    sender_normal: DVec3,
    depth: usize,
    sliver_depth: usize,
    kernel: &mut impl FnMut(&DVec3) -> f64,
) -> f64 {
    let area = polygon_area(domain);
    if area.is_nan() || area <= 0.0 {
        // A degenerate piece (a clipped polygon can repeat a vertex, making an empty fan triangle) holds nothing;
        // its quadrature weights would be 0 / 0.
        return 0.0;
    }
    // Split near pieces for NEAR_FIELD_DEPTH levels, and further (up to NEAR_FIELD_MAX_DEPTH) while a piece is
    // still larger than the receiver (a small patch next to a large one).
    let (center, radius) = bounding_sphere(domain);
    let larger = radius > receiver.radius;
    let split = depth > 0
        && near(domain, receiver.center, receiver.radius)
        && (depth > NEAR_FIELD_MAX_DEPTH - NEAR_FIELD_DEPTH || larger);
    // Then towards a sliver, while a piece is wider than it and near it; and towards the edges of a nearly
    // parallel receiver facing the piece, closer than half the piece's size.
    let split_sliver = !split && sliver_depth > 0 && {
        let gap = receiver.distance(center);
        receiver.sliver_width.is_some_and(|w| radius > w && gap - radius < 2.0 * radius)
            || (2.0 * gap < radius
                && receiver.normal.dot(sender_normal) < -PARALLEL_COSINE
                && receiver.boundary_distance(center) < radius + gap)
    };
    if !(split || split_sliver) {
        let q = Quadrature::new(domain, rule);
        return area * q.points.iter().zip(&q.weights).map(|(x, w)| w * kernel(x)).sum::<f64>();
    }
    let (depth, sliver_depth) = if split { (depth - 1, sliver_depth) } else { (0, sliver_depth - 1) };
    let v = domain;
    let mid = |a: DVec3, b: DVec3| 0.5 * (a + b);
    let pieces: Vec<Vec<DVec3>> = match v.len() {
        3 => {
            let (ab, bc, ca) = (mid(v[0], v[1]), mid(v[1], v[2]), mid(v[2], v[0]));
            vec![vec![v[0], ab, ca], vec![ab, v[1], bc], vec![ca, bc, v[2]], vec![ab, bc, ca]]
        }
        4 => {
            let m = (v[0] + v[1] + v[2] + v[3]) * 0.25;
            let (e0, e1, e2, e3) = (mid(v[0], v[1]), mid(v[1], v[2]), mid(v[2], v[3]), mid(v[3], v[0]));
            vec![vec![v[0], e0, m, e3], vec![e0, v[1], e1, m], vec![m, e1, v[2], e2], vec![e3, m, e2, v[3]]]
        }
        n => {
            let c = v.iter().copied().sum::<DVec3>() / n as f64;
            (0..n).map(|k| vec![c, v[k], v[(k + 1) % n]]).collect()
        }
    };
    pieces
        .iter()
        .map(|p| near_field_integral(p, receiver, rule, sender_normal, depth, sliver_depth, kernel))
        .sum()
}

/// Area of a planar polygon.
fn polygon_area(polygon: &[DVec3]) -> f64 {
    let mut twice = DVec3::ZERO;
    for (k, &a) in polygon.iter().enumerate() {
        twice += a.cross(polygon[(k + 1) % polygon.len()]);
    }
    0.5 * twice.length()
}

/// Whether `j` can receive anything from `i` at all: some vertex of `j` lies above `i`'s plane and some vertex
/// of `i` lies in front of `j`'s plane (a cheap exact rejection before the per-point kernel).
fn may_see(i: &Patch, j: &Patch) -> bool {
    let above =
        |from: &Patch, to: &Patch| to.vertices.iter().any(|v| from.normal.dot(*v - from.vertices[0]) > 0.0);
    above(i, j) && above(j, i)
}

fn segment(x: DVec3, y: DVec3, offset: f64) -> Ray {
    // Offsets are computed in f64 from the f64 segment length, then the ray is handed to Embree in f32.
    let length = (y - x).length();
    let cut = if length > 0.0 { offset / length } else { 1.0 };
    let from: Vec3 = x.as_vec3();
    Ray::new(from, y.as_vec3() - from, cut as f32, (1.0 - cut) as f32)
}

#[cfg(test)]
mod tests {
    use super::edge_angle;

    /// Within 4 ulp of `f64::atan2` (relative to the angle) over angles from 1e-300 to π and lengths over 40
    /// decades: the argument reduction and the sum each round a few times, and the series' truncation is 1.6e-17
    /// of the reduced argument (see `edge_angle`).
    #[test]
    fn edge_angle_matches_atan2() {
        let mut worst: f64 = 0.0;
        let mut check = |y: f64, x: f64| {
            let (got, want) = (edge_angle(y, x), y.atan2(x));
            let err = (got - want).abs() / (want.abs() * f64::EPSILON).max(f64::MIN_POSITIVE);
            assert!(err <= 4.0, "edge_angle({y:e}, {x:e}) = {got:e}, atan2 {want:e}: {err:.1} ulp");
            worst = worst.max(err);
        };
        let steps = 200_000;
        for k in 0..=steps {
            let theta = std::f64::consts::PI * f64::from(k) / f64::from(steps);
            for scale in [1e-20, 1e-3, 1.0, 7.5e2, 1e20] {
                check(scale * theta.sin().abs(), scale * theta.cos());
            }
        }
        for e in -300..=0 {
            let tiny = 10f64.powi(e);
            check(tiny, 1.0);
            check(tiny, -1.0);
            check(1.0, tiny);
            check(1.0, -tiny);
        }
        assert_eq!(edge_angle(0.0, 0.0), 0.0);
        assert_eq!(edge_angle(0.0, 2.0), 0.0);
        assert_eq!(edge_angle(0.0, -2.0), std::f64::consts::PI);
        assert!(edge_angle(f64::NAN, 1.0).is_nan());
        // The bound is not loose by orders of magnitude: the reduction rounds, so some angles are off by an ulp.
        assert!(worst >= 0.5, "worst {worst} ulp");
    }
}
