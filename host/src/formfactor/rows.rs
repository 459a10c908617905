//! The two passes over rows: unoccluded form factors (kernels, no rays) and visible fractions (rays), plus the
//! escape rays that decide whether the scene is closed. Each row's work is independent, so rows run in parallel
//! and the result does not depend on the thread count.

use std::time::Duration;

use glam::{DVec3, Vec3};
use indicatif::ProgressBar;

use super::kernel::{point_to_polygon_with, polygon_area};
use super::nearfield::{
    clip_to_front, may_see, near, near_field_integral, sliver_strips, Receiver, FAR_FIELD_GAP,
    NEAR_FIELD_MAX_DEPTH, SLIVER_DEPTH,
};
use super::options::{FormFactorOptions, ESCAPE_RAYS_PER_PATCH};
use super::quadrature::{cosine_direction, grid, tangent_frame, PolygonSampler, Quadrature};
use super::solidangle::polygon_point;
use crate::patch::Patch;
use crate::raycast::{unit_factor, Ray, RayCaster};
use crate::rng::SplitMix64;

/// Unoccluded rows, visibility rows, (escape rays cast, escaped) per patch (empty without closure detection),
/// and (kernel evaluations, wall time of the kernel phase, wall time of the visibility phase).
pub(super) type Phases = (Vec<Vec<(u32, f64)>>, Vec<Visibility>, Vec<(u64, u64)>, (u64, Duration, Duration));

pub(super) struct RowContext<'a, C: RayCaster + ?Sized> {
    pub(super) patches: &'a [Patch],
    pub(super) samplers: &'a [PolygonSampler],
    pub(super) quadratures: &'a [Quadrature],
    /// The lower-order rule of each patch for pairs in the far field ([`FAR_FIELD_GAP`]).
    pub(super) far_quadratures: &'a [Quadrature],
    /// Each patch as a receiver of the near-field quadrature.
    pub(super) receivers: &'a [Receiver<'a>],
    pub(super) rule: &'a [(f64, f64)],
    pub(super) scene: &'a C,
    pub(super) options: &'a FormFactorOptions,
    pub(super) progress: &'a ProgressBar,
    /// Diagonal of the patches' bounding box.
    pub(super) scene_size: f64,
}

impl<C: RayCaster + ?Sized> RowContext<'_, C> {
    /// `(rays cast, rays escaped)` for [`ESCAPE_RAYS_PER_PATCH`] escape rays from patch `i` ([`escaping_rays`]).
    pub(super) fn escaping_rays(&self, i: usize) -> (u64, u64) {
        let stream = (self.options.seed, i as u64);
        escaping_rays(
            &self.patches[i],
            &self.samplers[i],
            ESCAPE_RAYS_PER_PATCH,
            stream,
            self.scene,
            self.scene_size,
        )
    }

    /// `U_ij` for every `j` that `i` can see, sorted by `j`, and the kernel evaluations that took.
    pub(super) fn unoccluded_row(&self, i: usize) -> (Vec<(u32, f64)>, u64) {
        let patch_i = &self.patches[i];
        let mut scratch = PairScratch::default();
        let mut row = Vec::new();
        let mut kernels = 0u64;
        let sender = Sender {
            patch: patch_i,
            quadrature: &self.quadratures[i],
            far_quadrature: &self.far_quadratures[i],
            own: &self.receivers[i],
        };
        for (j, patch_j) in self.patches.iter().enumerate() {
            if j == i || !may_see(patch_i, patch_j) {
                continue;
            }
            let u = unoccluded_pair(
                &sender,
                patch_j,
                &self.receivers[j],
                self.rule,
                self.options.far_field,
                &mut scratch,
                &mut kernels,
            );
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
    pub(super) fn visibility_row(&self, i: usize, row: &[(u32, f64)], mut needed: Vec<u32>) -> Visibility {
        needed.extend(row.iter().map(|&(j, _)| j).filter(|&j| j as usize > i));
        needed.sort_unstable();
        needed.dedup();

        let patch_i = &self.patches[i];
        let offset = f64::from(self.scene.offset());
        let rays_per_pair = self.options.rays_per_pair;
        let mut result =
            Visibility { fractions: Vec::with_capacity(needed.len()), rays: 0, pairs_assumed_visible: 0 };
        let mut buffers = RayBuffers::default();
        for j in needed {
            let patch_j = &self.patches[j as usize];
            let mut rng = SplitMix64::for_stream(self.options.seed, i as u64, u64::from(j));
            let (fraction, rays) = visible_fraction(
                self.scene,
                (patch_i, &self.samplers[i]),
                (patch_j, &self.samplers[j as usize]),
                &mut rng,
                rays_per_pair,
                offset,
                &mut buffers,
            );
            result.rays += rays;
            if fraction.is_nan() {
                result.pairs_assumed_visible += 1;
            }
            result.fractions.push((j, fraction));
        }
        self.progress.inc(1);
        result
    }
}

/// The visible fractions a row computed: for pairs `(i, j)` with `j > i`, sorted by `j`.
pub(super) struct Visibility {
    pub(super) fractions: Vec<(u32, f64)>,
    pub(super) rays: u64,
    pub(super) pairs_assumed_visible: u64,
}

impl Visibility {
    /// The visible fraction of pair `(i, j)` (this row is `i < j`); 1 if `j` needed none, which cannot happen for
    /// an entry of either unoccluded row since phase 2 covers both.
    pub(super) fn fraction_for(&self, j: u32) -> f64 {
        match self.fractions.binary_search_by_key(&j, |&(c, _)| c) {
            Ok(k) => self.fractions[k].1,
            Err(_) => 1.0,
        }
    }
}

/// Visible fractions looked up in row-major order (rows ascending, columns ascending within a row) in O(1)
/// amortized: pair `(i, j)` lives in row `min(i, j)`, and both that row's own lookups (`j > i`) and the later rows'
/// lookups into it (`j < i`, with `i` ascending) ask for ascending keys, so a cursor per row only moves forward.
pub(super) struct FractionWalk<'a> {
    pub(super) visibility: &'a [Visibility],
    /// Per row `r`: the cursor of the lookups from rows below it (`j = r < i`).
    pub(super) below: Vec<usize>,
}

impl<'a> FractionWalk<'a> {
    pub(super) fn new(visibility: &'a [Visibility]) -> Self {
        FractionWalk { visibility, below: vec![0; visibility.len()] }
    }

    /// `v_ij` as [`Visibility::fraction_for`] gives it; `own` is row `i`'s cursor into its own fractions (start
    /// each row at 0).
    pub(super) fn get(&mut self, i: usize, j: usize, own: &mut usize) -> f64 {
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

pub(super) fn segment(x: DVec3, y: DVec3, offset: f64) -> Ray {
    // Offsets are computed in f64 from the f64 segment length, then the ray is handed to Embree in f32.
    let length = (y - x).length();
    let cut = if length > 0.0 { offset / length } else { 1.0 };
    let from: Vec3 = x.as_vec3();
    Ray::new(from, y.as_vec3() - from, cut as f32, (1.0 - cut) as f32)
}

/// Buffers of the per-pair kernel integral, reused across pairs.
#[derive(Default)]
pub(super) struct PairScratch {
    clipped: Vec<DVec3>,
    front: Vec<DVec3>,
    strips: Vec<Vec<DVec3>>,
}

/// The sending side of [`unoccluded_pair`] (the patch integrated over): its polygon, its full and far-field
/// rules, and itself as a near-field receiver (for its bounding sphere).
pub(super) struct Sender<'a> {
    pub(super) patch: &'a Patch,
    pub(super) quadrature: &'a Quadrature,
    pub(super) far_quadrature: &'a Quadrature,
    pub(super) own: &'a Receiver<'a>,
}

/// `U_ij`: the unoccluded form factor from `i` (integrated over with the rule its distance to `j` calls for) to
/// `j` (the exact point-to-polygon kernel), for a pair that passed [`may_see`]; counts kernel evaluations.
pub(super) fn unoccluded_pair(
    sender: &Sender,
    patch_j: &Patch,
    receiver: &Receiver,
    rule: &[(f64, f64)],
    far_field: bool,
    scratch: &mut PairScratch,
    kernels: &mut u64,
) -> f64 {
    let patch_i = sender.patch;
    let PairScratch { clipped, front, strips } = scratch;
    let mut kernel = |x: &DVec3| {
        *kernels += 1;
        point_to_polygon_with(*x, patch_i.normal, &patch_j.vertices, patch_j.normal, clipped)
    };
    // If j's plane cuts i, the kernel is zero on the part of i behind it and has a kink along the cut, which slows
    // the quadrature; integrate over the front part only (exactly clipped) instead.
    let domain: &[DVec3] =
        if clip_to_front(&patch_i.vertices, patch_j, front) { front } else { &patch_i.vertices };
    let is_near = near(domain, receiver);
    if is_near && sliver_strips(domain, strips) {
        // Near field of a sliver sender: the kernel varies on the scale of the sliver's width (its points are that
        // close to j) along its whole length, and near j's edges along it too; integrate over short pieces of it.
        strips
            .iter()
            .map(|piece| {
                near_field_integral(piece, receiver, rule, patch_i.normal, 0, SLIVER_DEPTH, &mut kernel)
            })
            .sum::<f64>()
            / patch_i.area
    } else if is_near {
        // Near field: j is closer to (part of) i than i's own size, so the kernel varies on a scale the fixed rule
        // cannot resolve; split the domain towards j.
        near_field_integral(
            domain,
            receiver,
            rule,
            patch_i.normal,
            NEAR_FIELD_MAX_DEPTH,
            SLIVER_DEPTH,
            &mut kernel,
        ) / patch_i.area
    } else if domain.len() == patch_i.vertices.len() && std::ptr::eq(domain, &patch_i.vertices[..]) {
        let own = sender.own;
        let gap = if receiver.polygon_gap {
            receiver.gap(own.center, own.radius)
        } else {
            own.center.distance(receiver.center) - own.radius - receiver.radius
        };
        let far = far_field && gap >= FAR_FIELD_GAP * 2.0 * own.radius;
        let Quadrature { points, weights } = if far { sender.far_quadrature } else { sender.quadrature };
        points.iter().zip(weights).map(|(x, w)| w * kernel(x)).sum()
    } else {
        let part = Quadrature::new(domain, rule);
        let fraction = polygon_area(domain) / patch_i.area;
        fraction * part.points.iter().zip(&part.weights).map(|(x, w)| w * kernel(x)).sum::<f64>()
    }
}

/// Buffers of [`visible_fraction`], reused across pairs.
#[derive(Default)]
pub(super) struct RayBuffers {
    origins: Vec<DVec3>,
    targets: Vec<DVec3>,
    rays: Vec<Ray>,
    weights: Vec<f64>,
    occluded: Vec<bool>,
    /// Near field: the cells of the unit square the solid-angle draws are stratified over, shuffled.
    cells: Vec<(usize, usize)>,
}

/// The kernel-weighted visible fraction of the pair `(i, j)` from `rays_per_pair` rays (see the module docs of
/// `formfactor`), and the rays cast; NaN when every ray fell where the kernel vanishes (no evidence either way).
pub(super) fn visible_fraction<C: RayCaster + ?Sized>(
    caster: &C,
    (patch_i, sampler_i): (&Patch, &PolygonSampler),
    (patch_j, sampler_j): (&Patch, &PolygonSampler),
    rng: &mut SplitMix64,
    rays_per_pair: usize,
    offset: f64,
    buffers: &mut RayBuffers,
) -> (f64, u64) {
    let RayBuffers { origins, targets, rays, weights, occluded, cells } = buffers;
    rays.clear();
    weights.clear();
    // Near field (the larger patch large for the distance between the two): the kernel is concentrated on the
    // parts of the larger that lie close to the smaller, which area-uniform points seldom reach; there the rays
    // go from stratified points of the smaller to points of the larger drawn uniformly in the solid angle it
    // subtends (`solidangle`), each weighted by that solid angle times the cosine at the smaller's point, which
    // estimates the same kernel-weighted fraction with the rays where the kernel is.
    let d2 = patch_i.centroid.distance_squared(patch_j.centroid);
    let (small, large) = if patch_i.area <= patch_j.area {
        ((patch_i, sampler_i), patch_j)
    } else {
        ((patch_j, sampler_j), patch_i)
    };
    if large.area > NEAR_FIELD_SOLID_ANGLE * d2 {
        small.1.stratified(rays_per_pair, rng, origins);
        rng.shuffle(origins);
        let (a, b) = grid(rays_per_pair);
        cells.clear();
        cells.extend((0..b).flat_map(|r| (0..a).map(move |c| (c, r))));
        rng.shuffle(cells);
        for (x, &(col, row)) in origins.iter().zip(cells.iter()).take(rays_per_pair) {
            let u = (col as f64 + rng.open_unit()) / a as f64;
            let v = (row as f64 + rng.open_unit()) / b as f64;
            let Some((y, omega)) = polygon_point(*x, &large.vertices, large.normal, u, v) else { continue };
            let d = y - *x;
            let (cos_x, cos_y) = (small.0.normal.dot(d), -large.normal.dot(d));
            let w = omega * cos_x.max(0.0) / d.length();
            if w > 0.0 && cos_y > 0.0 && w.is_finite() {
                rays.push(segment(*x, y, offset));
                weights.push(w);
            }
        }
        return weighted_fraction(caster, rays, weights, occluded);
    }
    // Stratified points on i paired with stratified points on j through random permutations of both (the pairs
    // are stratified in each patch and random across them).
    sampler_i.stratified(rays_per_pair, rng, origins);
    sampler_j.stratified(rays_per_pair, rng, targets);
    rng.shuffle(origins);
    rng.shuffle(targets);
    for (x, y) in origins.iter().zip(targets.iter()).take(rays_per_pair) {
        let d = *y - *x;
        let r2 = d.length_squared();
        // cos θ_x cos θ_y / r² (π cancels in the ratio); zero where either point is behind the other's plane,
        // where the integrand vanishes.
        let w = (patch_i.normal.dot(d) * -patch_j.normal.dot(d)).max(0.0) / (r2 * r2);
        if w > 0.0 && w.is_finite() {
            rays.push(segment(*x, *y, offset));
            weights.push(w);
        }
    }
    weighted_fraction(caster, rays, weights, occluded)
}

/// The larger patch's area over the squared distance between the centroids above which a pair's rays are drawn
/// in solid angle (`visible_fraction`): a patch that large for its distance subtends a sizeable solid angle, and
/// its kernel varies across it.
pub const NEAR_FIELD_SOLID_ANGLE: f64 = 0.05;

/// Casts `rays` and returns the weighted share of them that are not occluded and the rays cast; NaN when there
/// are none with weight (no evidence either way).
fn weighted_fraction<C: RayCaster + ?Sized>(
    caster: &C,
    rays: &[Ray],
    weights: &[f64],
    occluded: &mut Vec<bool>,
) -> (f64, u64) {
    occluded.clear();
    occluded.resize(rays.len(), false);
    caster.occluded_many(rays, occluded);
    let total: f64 = weights.iter().sum();
    let visible: f64 =
        weights.iter().zip(occluded.iter()).filter(|(_, &blocked)| !blocked).map(|(w, _)| w).sum();
    // Every ray fell where the kernel vanishes (j mostly behind i's horizon): NaN marks it, and the caller takes
    // the pair as visible.
    let fraction = if total > 0.0 { visible / total } else { f64::NAN };
    (fraction, rays.len() as u64)
}

/// `(rays cast, rays escaped)` for `count` cosine-distributed rays from stratified points of `p` (sampled by
/// `sampler`) in stratified directions (Malley's method: a stratified point on the unit disk lifted to the
/// hemisphere), each tested against everything in `scene` out to 4 times the scene's size `scene_size`; `(seed,
/// index)` name the random stream.
pub(crate) fn escaping_rays<C: RayCaster + ?Sized>(
    p: &Patch,
    sampler: &PolygonSampler,
    count: usize,
    (seed, index): (u64, u64),
    scene: &C,
    scene_size: f64,
) -> (u64, u64) {
    let mut rng = SplitMix64::for_stream(seed ^ 0x5EED_E5CA_9E00_0000, index, u64::MAX);
    let mut origins = Vec::new();
    sampler.stratified(count, &mut rng, &mut origins);
    rng.shuffle(&mut origins);
    let (a, b) = grid(count);
    let n = p.normal;
    let (t1, t2) = tangent_frame(n);
    // Directions of the scene's size (a power of two near it, exact) rather than unit length: in a scene of
    // size 1e30 a unit direction is 1e-30 of it, and a caster that scales the scene to unit size (Embree's)
    // would see directions whose squares underflow. `t` runs to 4 scene sizes.
    let length = 1.0 / unit_factor(scene_size as f32);
    let offset = scene.offset() / length;
    let far = 4.0 * scene_size as f32 / length;
    let mut rays = Vec::with_capacity(a * b);
    for (k, x) in origins.iter().enumerate() {
        let (s, t) =
            (((k % a) as f64 + rng.open_unit()) / a as f64, ((k / a) as f64 + rng.open_unit()) / b as f64);
        let dir = cosine_direction(n, (t1, t2), s, t);
        rays.push(Ray::new(x.as_vec3(), dir.normalize().as_vec3() * length, offset, far));
    }
    let mut occluded = vec![false; rays.len()];
    scene.occluded_many(&rays, &mut occluded);
    // A ray through a crack between triangles (f32 rounding at T-junctions of neighbouring faces' patches) is
    // not an opening: an escaped ray counts only if two rays from a nearby point, tilted by 1e-3 rad either
    // way (far wider than an f32 crack, far narrower than a real opening), escape too.
    let mut escaped = 0;
    for (ray, _) in rays.iter().zip(&occluded).filter(|(_, &o)| !o) {
        let d = ray.direction / length;
        let tilt = (t1 * 1e-3 + t2 * 1e-3).as_vec3();
        // Also from a point moved 1 % of the way to the centroid: a ray that starts within the ray offset of a
        // contact edge can slip past the touching face's edge, which is no opening either.
        let origin = (ray.origin.as_dvec3() * 0.99 + p.centroid * 0.01).as_vec3();
        let again = [
            Ray::new(origin, (d + tilt).normalize() * length, ray.tnear, ray.tfar),
            Ray::new(origin, (d - tilt).normalize() * length, ray.tnear, ray.tfar),
        ];
        if !scene.occluded(&again[0]) && !scene.occluded(&again[1]) {
            escaped += 1;
        }
    }
    (rays.len() as u64, escaped)
}
