//! Patch-to-patch form factors: an exact point-to-polygon kernel times visibility from occlusion rays.
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
//!   the rule down (the test `reciprocity_holds_within_quadrature_error` covers a cube with a box inside).
//! - `v̂_ij`: `rays_per_pair` occlusion rays from stratified (jittered) points on `i` to stratified points on `j`,
//!   paired through random permutations, each weighted by the kernel `w_r = cos θ_x cos θ_y / r²` (π cancels).
//!   This ratio estimator converges to `∫∫ K V / ∫∫ K`, so `U_ij · v̂_ij → F_ij`; it is exact (1 or 0) when `j`
//!   is fully visible or fully hidden from `i`, whatever the ray count. Visibility and `w` are symmetric in `x` and
//!   `y`, so one estimate per unordered pair serves both `F_ij` and `F_ji` (`v̂_ij = v̂_ji`): each pair's rays are
//!   cast once, and reciprocity `A_i F_ij = A_j F_ji` holds up to the quadrature error of `U` alone.
//!   In the near field (the larger patch's area above [`NEAR_FIELD_SOLID_ANGLE`] times the squared distance
//!   between the centroids) the kernel is concentrated on the part of the larger patch close to the smaller, which
//!   area-uniform points seldom reach: a chair seat's underside over a much larger floor patch, hidden right below
//!   it by the chair's base, had its few rays land on the floor's far, visible parts, and its row summed to well
//!   over 1 (the test `a_hidden_near_field_is_found_at_the_default_ray_count` has the case). There the rays go from stratified points `x` of the smaller patch to points of the larger drawn
//!   uniformly in the solid angle `Ω(x)` it subtends from `x` (Arvo's spherical-triangle sampling, `solidangle`),
//!   each weighted by `Ω(x) cos θ_x`: the same ratio `∫∫ K V / ∫∫ K` (the kernel over the sampling density), with
//!   the rays where the kernel is.
//!
//! # Why this estimator
//! Rays only decide visibility; the 1/r² geometry, which dominates the variance of plain area-sampling Monte Carlo
//! (the Embree tests' estimator), is integrated without rays. For an unoccluded pair the error is the quadrature
//! error of `U_ij` alone, whatever the ray count: the default Gauss-Legendre 4 × 4 rule matches the facing-squares
//! and shared-edge closed forms to the tolerances the tests assert, where jittered points and plain area sampling
//! are off by percents. On a half-occluded pair (the worst case for visibility) the test
//! `estimator_beats_area_sampling_per_ray` in `host/tests/formfactor.rs` compares the RMS error over seeds at
//! 16, 64 and 256 rays against area sampling with the same rays (and exact visibility). A per-point variant (each
//! Gauss point's own kernel-weighted visible fraction from its share of the rays) was less accurate and dropped.
//!
//! # Closure and open scenes
//! In a closed scene the visible patches tile each point's hemisphere, so `Σ_j F_{x → j} = 1` for every
//! quadrature point wherever nothing is occluded: a convex closed scene (the white-furnace cube) has row sums of 1
//! up to the quadrature error of touching pairs. Where occlusion occurs, visible fractions are estimated per pair,
//! so raw row sums deviate from 1 by visibility noise, which a furnace at rho = 0.99 multiplies by 100. So closed
//! scenes are closed, and open scenes never are:
//!
//! 1. **Detect closure from data** ([`ClosureMode::Detect`]): [`ESCAPE_RAYS_PER_PATCH`] cosine-distributed rays
//!    from stratified points of every patch are tested against the whole scene out to 4 times its size. The scene
//!    is closed only if none escapes. A ray through an f32 crack between neighbouring triangles, or one starting
//!    within the ray offset of a contact edge, is not an opening: an escaped ray counts only if two rays from a
//!    point 1 % nearer the patch centroid, tilted 1e-3 rad either way, escape too.
//! 2. **Correct only what is noisy.** A pair whose visible fraction is exactly 0 or 1 is exact up to quadrature
//!    (the ratio estimator returns 0 or 1 whatever the ray count); only partly visible pairs carry visibility
//!    noise, with variance about `G² (1 - v) / (v R)` for `G = A_i F_ij`, visible fraction `v` and `R` rays. The
//!    matrix is made reciprocal (the two estimates of each pair averaged), then
//!    [`FormFactorMatrix::close_rows`] applies the generalized least-squares correction: the smallest change of
//!    the energy exchanges, weighted by those variances, that is symmetric (keeps reciprocity) and makes every row
//!    sum to 1. Fully visible entries do not move; rows without a partly visible entry keep their estimate. The
//!    change is reported ([`ClosureReport`]), never silent.
//! 3. **Open scenes are never renormalized.** Any robustly escaping ray leaves every row as estimated: the missing
//!    part of the hemisphere is physics, and its error (visibility noise) stays visible in the reported row-sum
//!    range.
//!
//! # Rows above 1
//! A row of an estimate may sum to a little more than 1 through sampling alone. [`FormFactorStats`] carries,
//! per row, how much (`row_excess_allowed`: a 6-sigma bound on the visibility noise from the ray count, plus
//! the quadrature error that the pair's two estimates show), and the pipeline scales rows within it to 1 (and
//! says so) but refuses an estimate with a row beyond it ([`rows_over_noise`] names the rows and faces): such a
//! row means lost occlusion or a broken kernel, not noise.
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
//! piece is still larger than `j` (`near_field_pairs_are_reciprocal` tests the effect on reciprocity). Elements
//! ([`ElementRules`], the hierarchy's, often far smaller than what they exchange with) measure the gap to `j`'s
//! polygon instead: a small element in the middle of a floor is far from the walls standing on it, though inside
//! their bounding spheres. The
//! pipeline then averages the two estimates. Ray end points are jittered in open strata, so no ray starts or ends
//! on an edge either. Points coplanar with `j` get 0 (they cannot see `j`'s front).
//!
//! Two near-field shapes defeat a split driven by bounding spheres, and get their own rule
//! (`near_field_integral`, up to [`SLIVER_DEPTH`] more levels, pieces only along the feature, so the cost grows
//! like one over its width): a **sliver** (a strip much longer than wide) as receiver, seen from a large patch
//! only within a few widths of it, and as sender (cut into short pieces); and **nearly touching parallel faces**,
//! whose kernel falls from 1 to 1/2 within a few gaps of the receiver's edges (`scenes/slab.obj`: unit squares
//! 1 mm apart, against Howell's closed forms).
//!
//! # Cost
//! The work runs in two parallel passes over rows: unoccluded form factors (each ordered pair costs
//! `samples_per_patch` kernel evaluations, a clip and a contour sum), then visible fractions (each unordered pair
//! with a nonzero kernel either way casts `rays_per_pair` rays, in 16-wide packets with Embree). No test for
//! "nothing can occlude this pair" is made (an exact one costs O(patches) per pair, more than the rays it saves at
//! the default ray count), so rays are cast even in convex scenes. (The hierarchical solver makes one, through its
//! cluster tree: `hierarchy::shaft`.) Pairs facing away from each other cost only a
//! plane test. [`FormFactorStats`] counts the kernel evaluations and times both passes; `radiosity bench` reports
//! them (`bench/REPORT.md`, "Bake throughput").
//!
//! # Determinism
//! Quadrature points are deterministic; the rays of pair `(i, j)` come from a generator seeded by `(seed, i, j)`,
//! and each row is summed in a fixed order, so the matrix is identical for any thread count (and for any caster
//! that agrees on every ray).
//!
//! # Files
//! `options` (settings) -> `kernel` (Lambert's contour sum, `edge_angle`) -> `quadrature` (Gauss-Legendre
//! rules, stratified points) -> `nearfield` (far-, near-field and sliver rules) -> `rows` (the row passes and
//! escape rays, over any [`RayCaster`]; the per-pair functions `unoccluded_pair` and `visible_fraction`, with
//! `solidangle`'s draws in the near field) ->
//! `element` (the same per-pair estimates for elements made on the fly, for the hierarchy) -> this module
//! (checks, assembly, closure, statistics).

mod element;
mod kernel;
mod nearfield;
mod options;
mod quadrature;
mod rows;
mod solidangle;

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

pub use element::{Element, ElementRules};
pub use kernel::point_to_polygon;
pub(crate) use kernel::point_to_polygon_with;
pub use nearfield::{far_field_order, FAR_FIELD_GAP, NEAR_FIELD_DEPTH, NEAR_FIELD_MAX_DEPTH, SLIVER_DEPTH};
pub use options::{ClosureMode, FormFactorOptions, ESCAPE_RAYS_PER_PATCH};
pub(crate) use quadrature::{cosine_direction, grid, tangent_frame, PolygonSampler};
pub use rows::NEAR_FIELD_SOLID_ANGLE;

use crate::embree::{Device, EmbreeError, SceneOptions, TriangleScene};
use crate::patch::{Closure, FormFactorMatrix, Patch, ReciprocityChange};
use crate::raycast::{MeshInputError, RayCaster, TriangleBvh};
use nearfield::Receiver;
use quadrature::{gauss_legendre, Quadrature};
use rows::{FractionWalk, Phases, RowContext, Visibility};

/// Entries with `F_ij` below this are left out of the reciprocity error (their relative error is dominated by
/// sampling noise and they carry little energy).
pub const RECIPROCITY_MIN_FACTOR: f64 = 1e-3;

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
    /// `(rays cast, rays that hit nothing)` per patch they left (empty with [`ClosureMode::Off`]): where an
    /// open scene leaks.
    pub escapes_per_patch: Vec<(u64, u64)>,
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
    /// Per row, how far above 1 the row's sum may lie from sampling alone (`row_excess_allowed`); a row that
    /// sums to more than `1 + allowed` is not noise, and the pipeline refuses it.
    pub row_excess_allowed: Vec<f64>,
}

/// A row of the form factors whose sum exceeds 1 by more than its sampling noise allows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowExcess {
    /// The patch (row).
    pub patch: usize,
    /// Its OBJ face.
    pub face: usize,
    /// The row's sum.
    pub sum: f64,
    /// How far above 1 sampling noise could have put it.
    pub allowed: f64,
}

impl std::fmt::Display for RowExcess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "patch {} (face {}) sums to {:.6}, noise allows up to {:.6}",
            self.patch,
            self.face,
            self.sum,
            1.0 + self.allowed
        )
    }
}

/// The rows of `form_factors` whose sum exceeds `1 + allowed[i]` (`allowed`: [`FormFactorStats::row_excess_allowed`]
/// of the estimate, after any change that keeps within it, such as averaging for reciprocity), the worst (largest
/// sum minus allowance) first. `patches` name each row's face.
///
/// # Panics
/// If `patches` is shorter than the matrix.
#[must_use]
pub fn rows_over_noise(
    form_factors: &FormFactorMatrix,
    allowed: &[f64],
    patches: &[Patch],
) -> Vec<RowExcess> {
    let mut rows: Vec<RowExcess> = (0..form_factors.n())
        .filter_map(|i| {
            let sum = form_factors.row_sum(i);
            let allowed = allowed.get(i).copied().unwrap_or(0.0);
            (sum > 1.0 + allowed).then(|| RowExcess { patch: i, face: patches[i].face, sum, allowed })
        })
        .collect();
    rows.sort_by(|a, b| (b.sum - b.allowed).total_cmp(&(a.sum - a.allowed)));
    rows
}

/// Standard deviations of visibility noise a row's excess over 1 may reach before it counts as an error (see
/// `row_excess_allowed`): a Gaussian 6-sigma event has a probability of about 1e-9 per row.
pub const ROW_EXCESS_SIGMAS: f64 = 6.0;

/// Rounding allowance of a row sum in `row_excess_allowed` (a row of thousands of entries summed in f64).
pub const ROW_EXCESS_ROUNDING: f64 = 1e-9;

/// Diagonal of the bounding box of `patches` (0 for none).
fn bounding_diagonal(patches: &[Patch]) -> f64 {
    let (lo, hi) = crate::scene::bounding_box(patches.iter().flat_map(|p| p.vertices.iter().copied()));
    if patches.is_empty() {
        0.0
    } else {
        (hi - lo).length()
    }
}

/// The closure test of the module docs ("Closure and open scenes") on `patches` as a whole: about `rays` escape
/// rays spread over them by area (at least [`ESCAPE_RAYS_PER_PATCH`] from each), cast at `caster`. Returns
/// `(rays cast, rays escaped)`: the scene is closed if none escaped. For solvers that do not mesh the scene into
/// patches first (the hierarchy tests its face polygons), so that a large polygon gets as many rays as the
/// patches it would be cut into.
pub fn escape_test<C: RayCaster + ?Sized>(
    patches: &[Patch],
    caster: &C,
    seed: u64,
    rays: usize,
) -> (u64, u64) {
    let total_area: f64 = patches.iter().map(|p| p.area).sum();
    let size = bounding_diagonal(patches);
    (0..patches.len())
        .into_par_iter()
        .map(|i| {
            let p = &patches[i];
            let share =
                if total_area > 0.0 { (rays as f64 * p.area / total_area).ceil() as usize } else { 0 };
            let sampler = PolygonSampler::new(&p.vertices);
            rows::escaping_rays(p, &sampler, share.max(ESCAPE_RAYS_PER_PATCH), (seed, i as u64), caster, size)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// How far above 1 each row of an estimate may sum from sampling alone:
/// `ROW_EXCESS_ROUNDING + q_i + ROW_EXCESS_SIGMAS * sigma_i`, where
/// - `sigma_i² = Σ_j U_ij² ṽ_ij (1 - ṽ_ij) / R` is the variance of the row's visibility noise: each pair's
///   visible fraction is estimated from `R = rays_per_pair` rays, a binomial variance evaluated at
///   `ṽ = (v R + 1/2) / (R + 1)` (Jeffreys' estimate), not at the estimate `v` itself, because a pair all of whose
///   few rays agreed (`v` = 0 or 1) may still be partly visible; a pair whose visibility could not be measured
///   counts with the largest variance, `U² / 4`;
/// - `q_i = Σ_j |F_ij - A_j F_ji / A_i|` is the row's quadrature error as the data show it: the two estimates of
///   each pair's exchange come from different rules (`samples_per_patch` points on `i`, on `j`), and their
///   disagreement is what averaging them for reciprocity moves the row by (at most half of it).
///
/// `unoccluded` are the rows of `U`, `fraction(i, j)` the pair's visible fraction (NaN if not measured), and
/// `matrix` the estimate `F_ij = U_ij v_ij` before any reciprocity or closure.
fn row_excess_allowed(
    matrix: &FormFactorMatrix,
    unoccluded: &[Vec<(u32, f64)>],
    fraction: impl Fn(usize, usize) -> f64,
    areas: &[f64],
    rays_per_pair: usize,
) -> Vec<f64> {
    let rays = rays_per_pair.max(1) as f64;
    (0..matrix.n())
        .map(|i| {
            let variance: f64 = unoccluded[i]
                .iter()
                .map(|&(j, u)| {
                    let v = fraction(i, j as usize);
                    if v.is_nan() {
                        return u * u / 4.0;
                    }
                    let v = (v * rays + 0.5) / (rays + 1.0);
                    u * u * v * (1.0 - v) / rays
                })
                .sum();
            let quadrature: f64 = matrix
                .row_columns(i)
                .iter()
                .zip(matrix.row_values(i))
                .map(|(&j, &f)| (f - areas[j as usize] * matrix.get(j as usize, i) / areas[i]).abs())
                .sum();
            ROW_EXCESS_ROUNDING + quadrature + ROW_EXCESS_SIGMAS * variance.sqrt()
        })
        .collect()
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
    /// The pure-Rust caster could not be built over the occluders.
    #[error("building the occluder hierarchy: {0}")]
    Occluders(#[from] MeshInputError),
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

/// Computes the form-factor matrix of `patches`, which are also the occluders, with Embree as the ray caster.
///
/// The matrix flags the entries of partly visible pairs ([`FormFactorMatrix::row_flags`]): what adaptive
/// meshing uses to find shadow boundaries.
///
/// # Errors
/// [`FormFactorError`] for invalid patches or options, or if Embree or the thread pool cannot be set up.
pub fn compute_form_factors(
    patches: &[Patch],
    options: &FormFactorOptions,
) -> Result<(FormFactorMatrix, FormFactorStats), FormFactorError> {
    let start = Instant::now();
    validate(patches, options)?;
    let scene = occluder_scene(patches, options.robust)?;
    estimate(&scene, patches, options, start)
}

/// As [`compute_form_factors`], with the occlusion rays cast by `caster`, which must hold the patches'
/// occluders ([`occluder_mesh`]; e.g. [`occluder_bvh`], the pure-Rust caster). `options.robust` is Embree's and
/// has no effect here. Casters that agree on every ray give identical matrices.
///
/// # Errors
/// [`FormFactorError`] for invalid patches or options, or if the thread pool cannot be set up.
pub fn compute_form_factors_with<C: RayCaster + ?Sized>(
    caster: &C,
    patches: &[Patch],
    options: &FormFactorOptions,
) -> Result<(FormFactorMatrix, FormFactorStats), FormFactorError> {
    let start = Instant::now();
    validate(patches, options)?;
    estimate(caster, patches, options, start)
}

/// The estimator proper, on validated input; `start` is when the computation began (for the statistics).
fn estimate<C: RayCaster + ?Sized>(
    caster: &C,
    patches: &[Patch],
    options: &FormFactorOptions,
    start: Instant,
) -> Result<(FormFactorMatrix, FormFactorStats), FormFactorError> {
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
        scene: caster,
        options,
        progress: &progress,
        scene_size: bounding_diagonal(patches),
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
        let escapes: Vec<(u64, u64)> = match options.closure {
            ClosureMode::Off => Vec::new(),
            ClosureMode::Detect => {
                (0..patches.len()).into_par_iter().map(|i| context.escaping_rays(i)).collect()
            }
        };
        let timing = (kernels.iter().sum::<u64>(), kernel_time, visibility_time);
        (unoccluded, visibility, escapes, timing)
    };
    let (unoccluded, visibility, escapes, (kernel_evaluations, kernel_time, visibility_time)) =
        match options.threads {
            None => compute(),
            Some(threads) => rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| FormFactorError::ThreadPool { threads, message: e.to_string() })?
                .install(compute),
        };
    progress.finish_and_clear();
    let escape_rays = escapes.iter().map(|e| e.0).sum::<u64>();
    let escaped_rays = escapes.iter().map(|e| e.1).sum::<u64>();

    // Phase 3: F_ij = U_ij v_{min(i,j), max(i,j)}, flagged where the pair is partly visible (or its visibility
    // was assumed). Visibility is one estimate per pair, so the flags of (i, j) and (j, i) agree, and they stay
    // right through the reciprocity and closure transforms below.
    let (mut row_start, mut col, mut value, mut flags) = (vec![0], Vec::new(), Vec::new(), Vec::new());
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
                col.push(j);
                value.push(f);
                flags.push(v.is_nan() || (v > 0.0 && v < 1.0));
            }
        }
        row_start.push(col.len());
    }
    let mut matrix = FormFactorMatrix::with_flags(patches.len(), row_start, col, value, flags)
        .expect("rows of ascending columns below the patch count, finite positive values");
    let row_sum_range = |m: &FormFactorMatrix| {
        if m.n() == 0 {
            return (0.0, 0.0);
        }
        (0..m.n())
            .map(|i| m.row_sum(i) + 0.0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s), hi.max(s)))
    };
    let (estimate_row_sum_min, estimate_row_sum_max) = row_sum_range(&matrix);
    let reciprocity_error_max = reciprocity_error(&matrix, patches);
    let areas: Vec<f64> = patches.iter().map(|p| p.area).collect();
    let row_excess_allowed =
        row_excess_allowed(&matrix, &unoccluded, fraction, &areas, options.rays_per_pair);
    let closed = options.closure == ClosureMode::Detect && escape_rays > 0 && escaped_rays == 0;
    let closure = if closed {
        let reciprocity_change = matrix.enforce_reciprocity(&areas);
        // Variance of a pair's visible fraction from R kernel-weighted rays: about v (1 - v) / R, so that of
        // G_ij = A_i U_ij v is (A_i U_ij)^2 v (1 - v) / R = G_ij^2 (1 - v) / v / R. Pairs whose visibility was
        // assumed (NaN) get the largest such weight, (1 - v) / v at v = 1/2.
        let rays = options.rays_per_pair as f64;
        let balance = matrix.close_rows(&areas, |i, j| {
            let v = fraction(i, j);
            let g = areas[i]
                * lookup_unoccluded(&unoccluded, i, j)
                    .max(lookup_unoccluded(&unoccluded, j, i) * areas[j] / areas[i]);
            if v.is_nan() {
                g * g / rays
            } else if v > 0.0 && v < 1.0 {
                let g = g * v;
                g * g * (1.0 - v) / v / rays
            } else {
                0.0
            }
        });
        Some(ClosureReport { reciprocity_change, balance })
    } else {
        None
    };
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
        partly_visible_entries: matrix.flags().iter().filter(|&&p| p).count(),
        escape_rays,
        escaped_rays,
        escapes_per_patch: escapes,
        closure,
        rays_cast,
        rays_per_second: rays_cast as f64 / elapsed.as_secs_f64().max(1e-9),
        pairs_assumed_visible,
        kernel_evaluations,
        kernel_time,
        visibility_time,
        elapsed,
        row_excess_allowed,
    };
    Ok((matrix, stats))
}

/// `U_ij` from the unoccluded rows (0 if absent).
fn lookup_unoccluded(rows: &[Vec<(u32, f64)>], i: usize, j: usize) -> f64 {
    rows[i].binary_search_by_key(&(j as u32), |&(c, _)| c).map_or(0.0, |k| rows[i][k].1)
}

/// `max |A_i F_ij - A_j F_ji| / (A_i F_ij)` over entries with `F_ij >= RECIPROCITY_MIN_FACTOR` (0 if none).
///
/// # Panics
/// If `patches.len() != matrix.n()`.
#[must_use]
pub fn reciprocity_error(matrix: &FormFactorMatrix, patches: &[Patch]) -> f64 {
    assert_eq!(patches.len(), matrix.n(), "one patch per matrix row");
    let mut worst = 0.0f64;
    for (i, j, f_ij) in matrix.entries() {
        if f_ij < RECIPROCITY_MIN_FACTOR {
            continue;
        }
        let forward = patches[i].area * f_ij;
        let backward = patches[j].area * matrix.get(j, i);
        worst = worst.max((forward - backward).abs() / forward);
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

/// The patches' polygons, fan-triangulated, as one mesh (vertices in `f32`, triangles by index): the occluders
/// the estimator's visibility rays are tested against, whatever the caster.
#[must_use]
pub fn occluder_mesh(patches: &[Patch]) -> (Vec<glam::Vec3>, Vec<[u32; 3]>) {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for p in patches {
        let base = vertices.len() as u32;
        vertices.extend(p.vertices.iter().map(|v| v.as_vec3()));
        for k in 1..p.vertices.len().saturating_sub(1) as u32 {
            triangles.push([base, base + k, base + k + 1]);
        }
    }
    (vertices, triangles)
}

/// The [`occluder_mesh`] as an Embree scene, the production caster (public so benchmarks can cast raw rays
/// against exactly the same scene).
///
/// # Errors
/// If Embree fails to build the scene.
pub fn occluder_scene(patches: &[Patch], robust: bool) -> Result<TriangleScene, FormFactorError> {
    let (vertices, triangles) = occluder_mesh(patches);
    Ok(Device::new()?.triangle_scene(&vertices, &triangles, SceneOptions { robust })?)
}

/// The [`occluder_mesh`] as the pure-Rust caster, for [`compute_form_factors_with`] without Embree.
///
/// # Errors
/// [`FormFactorError::Occluders`] for a non-finite vertex.
pub fn occluder_bvh(patches: &[Patch]) -> Result<TriangleBvh, FormFactorError> {
    let (vertices, triangles) = occluder_mesh(patches);
    Ok(TriangleBvh::new(&vertices, &triangles)?)
}
