//! Ray queries behind one trait, so the form-factor estimator and the path tracer are independent of the ray
//! caster.
//!
//! [`RayCaster`] is what they ask of a scene: is anything on this segment, for batches of segments; what is the
//! closest surface along a ray ([`Hit`]); and the offset by which segments between two surface points are
//! shortened. Two casters implement it:
//! - [`crate::embree::TriangleScene`], Embree's BVH and packet traversal: the production caster.
//! - [`TriangleBvh`], a small pure-Rust BVH with an f64 ray-triangle test: no native library, so unit tests of
//!   everything that only needs ray queries run without Embree, and tests check Embree against it.
//!
//! # Semantics (Embree's, which every caster follows)
//! - A [`Ray`] covers `origin + t * direction` for `tnear < t <= tfar`: `tnear` is exclusive, `tfar`
//!   inclusive, so a segment that ends exactly on a surface hits it. [`Ray::segment`] therefore pulls both ends
//!   in by an absolute offset ([`offset_for`]), so a segment from a point on one surface to a point on another
//!   is tested only between the two surfaces, and a ray that starts on a surface does not hit it through rounding.
//! - A negative `tnear` counts as 0. A ray with `tnear > tfar`, a non-finite origin or direction, or NaN bounds
//!   is empty ([`Ray::is_empty`]): it is never occluded.
//! - Triangles are two-sided (no back-face culling); a hit on a triangle's edge or vertex counts; degenerate
//!   (zero-area) triangles are never hit.
//! - A closest hit ([`RayCaster::intersect`]) names the triangle by its index in the order the caster was given
//!   the triangles, with Embree's barycentric convention and a geometric normal from the vertex order. Which of
//!   two triangles at the same distance is reported (a ray through a shared edge) is unspecified.
//! - Casters differ only for rays that pass within rounding of a triangle's edge or end within rounding of a
//!   surface: Embree tests in `f32`, [`TriangleBvh`] in `f64` from the same `f32` data.

mod bvh;

pub(crate) use bvh::check_mesh;
pub use bvh::{MeshInputError, TriangleBvh};

use glam::Vec3;

/// A ray or segment for occlusion queries: the points `origin + t * direction` with `tnear < t <= tfar`.
///
/// A ray with `tnear > tfar`, a non-finite origin or direction, or NaN bounds is empty: it is never occluded and
/// hits nothing. A negative `tnear` is raised to 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3,
    /// Direction; need not be unit length (then `t` is in units of its length).
    pub direction: Vec3,
    /// Bound below which nothing is tested (exclusive), `>= 0`.
    pub tnear: f32,
    /// Largest `t` tested (inclusive).
    pub tfar: f32,
}

impl Ray {
    /// A ray from `origin` along `direction`, for `tnear < t <= tfar`.
    #[must_use]
    pub fn new(origin: Vec3, direction: Vec3, tnear: f32, tfar: f32) -> Self {
        Self { origin, direction, tnear, tfar }
    }

    /// The open segment from `from` to `to`, with `offset` (in scene units) cut from each end.
    ///
    /// Use [`RayCaster::offset`] for `offset`. The direction is `to - from`, so `t` runs from 0 at `from` to 1 at
    /// `to`; `tnear = offset / |to - from|` keeps a ray that starts on a surface from hitting that surface, and
    /// `tfar = 1 - offset / |to - from|` keeps the surface the segment ends on from counting as an occluder
    /// (`tfar` is inclusive). Occluders closer than `offset` to either end are missed. If the segment is shorter
    /// than `2 * offset`, it is empty (`tnear > tfar`) and never occluded.
    #[must_use]
    pub fn segment(from: Vec3, to: Vec3, offset: f32) -> Self {
        let direction = to - from;
        // In f64, so that the squares of large or tiny coordinates neither overflow nor underflow.
        let length = direction.as_dvec3().length() as f32;
        let cut = if length > 0.0 { offset / length } else { 1.0 };
        Self { origin: from, direction, tnear: cut, tfar: 1.0 - cut }
    }

    /// Whether the ray tests nothing: `tnear > tfar` (after raising a negative `tnear` to 0), a non-finite
    /// origin or direction, or NaN bounds. Casters never report such a ray as occluded (Embree's results for
    /// them would be undefined, so they are not passed to it).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        !(self.origin.is_finite()
            && self.direction.is_finite()
            && self.tnear.is_finite()
            && !self.tfar.is_nan())
            || self.tnear.max(0.0) > self.tfar
    }
}

/// Relative size of the segment offset ([`offset_for`]): `2^-13 ~ 1.2e-4` of the scene scale, about 1000 `f32`
/// ulps of the largest coordinate (Embree's hit distances are accurate to a few ulps of the coordinates
/// involved), and far below any patch size worth simulating.
pub const RELATIVE_OFFSET: f32 = 1.0 / 8192.0;

/// The scene's size for offsets: the largest of its bounding-box diagonal and its largest absolute coordinate
/// (rounding in `f32` grows with the coordinates' magnitude, not only with the scene's extent); 1 for an empty
/// or single-point scene.
#[must_use]
pub fn scene_scale(vertices: &[Vec3]) -> f32 {
    let Some(first) = vertices.first() else { return 1.0 };
    let (lo, hi) = vertices.iter().fold((*first, *first), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    // In f64: the squares of f32 coordinates above about 1e19 overflow f32 (the offset would become infinite and
    // every ray empty), and those below about 1e-19 underflow it.
    let diagonal = (hi.as_dvec3() - lo.as_dvec3()).length() as f32;
    let magnitude = lo.abs().max(hi.abs()).max_element();
    let scale = diagonal.max(magnitude);
    if scale > 0.0 {
        scale
    } else {
        1.0
    }
}

/// The power of two that brings a length `scale` into `[1, 2)`: `2^-e` with `2^e <= scale < 2^(e + 1)` (`e`
/// limited to the exponents of normal `f32` numbers; 1 for a non-finite or non-positive `scale`). Multiplying by it
/// is exact, so a scene and its rays scaled by it give the same hits; [`crate::embree::TriangleScene`] hands Embree
/// every scene and ray scaled by the `unit_factor` of its [`scene_scale`].
#[must_use]
pub fn unit_factor(scale: f32) -> f32 {
    if !(scale.is_finite() && scale > 0.0) {
        return 1.0;
    }
    let exponent = scale.log2().floor() as i32;
    // Correct `log2`'s rounding next to powers of two, so that the result depends on the exponent only.
    let exponent = if 2f32.powi(exponent) > scale { exponent - 1 } else { exponent };
    let exponent = if 2f32.powi(exponent + 1) <= scale { exponent + 1 } else { exponent };
    2f32.powi(-exponent.clamp(-126, 126))
}

/// The absolute offset (scene units) to cut from both ends of a segment between two surface points of a scene
/// with these vertices: [`RELATIVE_OFFSET`] times [`scene_scale`]. Every caster's [`RayCaster::offset`] is this,
/// so the same segments give the same rays whatever the caster.
#[must_use]
pub fn offset_for(vertices: &[Vec3]) -> f32 {
    scene_scale(vertices) * RELATIVE_OFFSET
}

/// The closest hit of a ray ([`RayCaster::intersect`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit point: `origin + t * direction`.
    pub t: f32,
    /// Index of the triangle hit, within its geometry (the order triangles were given in).
    pub primitive: u32,
    /// Geometry id (0 for the single mesh of [`crate::embree::Device::triangle_scene`] and of [`TriangleBvh`]).
    pub geometry: u32,
    /// Barycentric coordinates `(u, v)` of the hit: the point is `(1 - u - v) * p0 + u * p1 + v * p2`.
    pub barycentric: [f32; 2],
    /// Unit geometric normal, `normalize((p1 - p0) x (p2 - p0))`: it points to the side from which the triangle's
    /// vertices appear counter-clockwise.
    pub normal: Vec3,
}

/// Ray queries on a fixed triangle scene, from any number of threads (see the module docs for the
/// semantics every implementation follows).
pub trait RayCaster: Sync {
    /// The absolute offset (scene units) to cut from both ends of a segment between two surface points
    /// ([`offset_for`] of the scene's vertices); pass it to [`Ray::segment`].
    fn offset(&self) -> f32;

    /// Whether anything in the scene lies on `ray` (a hit with `tnear < t <= tfar`); `false` for an empty ray.
    fn occluded(&self, ray: &Ray) -> bool;

    /// Tests any number of rays; `occluded[k]` is set for `rays[k]`.
    ///
    /// # Panics
    /// If `occluded.len() != rays.len()`.
    fn occluded_many(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one output per ray");
        for (ray, out) in rays.iter().zip(occluded) {
            *out = self.occluded(ray);
        }
    }

    /// The closest hit on `ray` with `tnear < t <= tfar`, if any; `None` for an empty ray.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;
}
