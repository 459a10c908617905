//! [`TriangleBvh`]: a pure-Rust ray caster (occlusion and closest hits), a bounding-volume hierarchy over the
//! triangles with an f64 Möller-Trumbore test.
//!
//! It exists for tests and as the reference Embree is checked against, not for speed: nodes split at the
//! median centroid along their longest axis (no surface-area heuristic), one ray at a time, no SIMD.

use glam::{DVec3, Vec3};

use super::{offset_for, Hit, Ray, RayCaster};

/// Triangles per leaf at most (fewer where the centroids coincide and cannot be split).
const LEAF_SIZE: usize = 4;

/// What is wrong with the input mesh of [`TriangleBvh::new`].
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshInputError {
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {index} is not finite: {vertex:?}")]
    NonFiniteVertex {
        /// Index of the vertex.
        index: usize,
        /// The vertex.
        vertex: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {vertex}, but there are only {vertex_count} vertices")]
    VertexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// The vertex index it holds.
        vertex: u32,
        /// Number of vertices given.
        vertex_count: usize,
    },
}

/// One node: a box and either two children (`count == 0`: nodes `first` and `first + 1`) or the leaf's
/// triangles `first..first + count`.
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    first: u32,
    count: u32,
}

/// A pure-Rust ray caster over a triangle mesh, with the semantics of the module docs (those of
/// [`crate::embree::TriangleScene`]).
#[derive(Clone, Debug)]
pub struct TriangleBvh {
    /// The non-degenerate triangles in f64, in the order the leaves hold them.
    triangles: Vec<[DVec3; 3]>,
    /// Index of each of `triangles` in the input (what [`Hit::primitive`] reports).
    ids: Vec<u32>,
    nodes: Vec<Node>,
    offset: f32,
    /// Boxes are widened by this (scene units), so rounding in the box test never rejects a hit.
    pad: f64,
}

impl TriangleBvh {
    /// Builds the hierarchy over `triangles`, which refer to `vertices` by index (as
    /// [`crate::embree::Device::triangle_scene`] takes them). Degenerate triangles are dropped: they are never
    /// hit. An empty mesh occludes nothing.
    ///
    /// # Errors
    /// [`MeshInputError`] for a non-finite vertex or an index out of range.
    pub fn new(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Result<Self, MeshInputError> {
        check_mesh(vertices, triangles)?;
        let mut tris: Vec<([DVec3; 3], u32)> = triangles
            .iter()
            .zip(0u32..)
            .map(|(t, id)| (t.map(|k| vertices[k as usize].as_dvec3()), id))
            .filter(|([a, b, c], _)| (*b - *a).cross(*c - *a) != DVec3::ZERO)
            .collect();
        let scale = f64::from(super::scene_scale(vertices));
        let mut bvh = TriangleBvh {
            triangles: Vec::new(),
            ids: Vec::new(),
            nodes: Vec::new(),
            offset: offset_for(vertices),
            pad: 1e-9 * scale,
        };
        if !tris.is_empty() {
            bvh.nodes.push(Node { lo: DVec3::ZERO, hi: DVec3::ZERO, first: 0, count: 0 });
            let count = tris.len();
            bvh.build(0, &mut tris, 0, count);
        }
        (bvh.triangles, bvh.ids) = tris.into_iter().unzip();
        Ok(bvh)
    }

    /// Number of triangles the hierarchy holds (degenerate ones dropped).
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Fills node `node` with the triangles `tris[first..first + count]`, splitting it while it holds more than
    /// [`LEAF_SIZE`].
    fn build(&mut self, node: usize, tris: &mut [([DVec3; 3], u32)], first: usize, count: usize) {
        let part = &mut tris[first..first + count];
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let (mut clo, mut chi) = (lo, hi);
        for (t, _) in part.iter() {
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
            let c = centroid(t);
            clo = clo.min(c);
            chi = chi.max(c);
        }
        let (lo, hi) = (lo - DVec3::splat(self.pad), hi + DVec3::splat(self.pad));
        let extent = chi - clo;
        if count <= LEAF_SIZE || extent.max_element() <= 0.0 {
            self.nodes[node] = Node { lo, hi, first: first as u32, count: count as u32 };
            return;
        }
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let half = count / 2;
        part.select_nth_unstable_by(half, |a, b| centroid(&a.0)[axis].total_cmp(&centroid(&b.0)[axis]));
        let left = self.nodes.len();
        self.nodes[node] = Node { lo, hi, first: left as u32, count: 0 };
        let empty = Node { lo: DVec3::ZERO, hi: DVec3::ZERO, first: 0, count: 0 };
        self.nodes.push(empty);
        self.nodes.push(empty);
        self.build(left, tris, first, half);
        self.build(left + 1, tris, first + half, count - half);
    }
}

fn centroid(t: &[DVec3; 3]) -> DVec3 {
    (t[0] + t[1] + t[2]) / 3.0
}

/// Checks that every vertex is finite and every index refers to a vertex.
///
/// # Errors
/// The first problem found.
pub(crate) fn check_mesh(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Result<(), MeshInputError> {
    if let Some(index) = vertices.iter().position(|v| !v.is_finite()) {
        return Err(MeshInputError::NonFiniteVertex { index, vertex: vertices[index].to_array() });
    }
    for (triangle, t) in triangles.iter().enumerate() {
        if let Some(&vertex) = t.iter().find(|&&k| k as usize >= vertices.len()) {
            return Err(MeshInputError::VertexOutOfRange { triangle, vertex, vertex_count: vertices.len() });
        }
    }
    Ok(())
}

/// Whether the box `[lo, hi]` meets the ray for some `t` in `[tnear, tfar]` (slab test; a NaN from a zero
/// direction component on a slab's boundary does not constrain, so the test errs towards "meets").
fn meets_box(node: &Node, origin: DVec3, inverse: DVec3, tnear: f64, tfar: f64) -> bool {
    let (mut enter, mut exit) = (tnear, tfar);
    for axis in 0..3 {
        let t0 = (node.lo[axis] - origin[axis]) * inverse[axis];
        let t1 = (node.hi[axis] - origin[axis]) * inverse[axis];
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
    }
    enter <= exit
}

/// Möller-Trumbore, two-sided: a hit at `t` with `tnear < t <= tfar`, edges and vertices included.
fn hits_triangle(t: &[DVec3; 3], origin: DVec3, direction: DVec3, tnear: f64, tfar: f64) -> bool {
    triangle_hit(t, origin, direction, tnear, tfar).is_some()
}

/// Möller-Trumbore, two-sided: `(t, u, v)` of a hit with `tnear < t <= tfar` (edges and vertices included),
/// the point being `(1 - u - v) * t0 + u * t1 + v * t2`.
fn triangle_hit(
    t: &[DVec3; 3],
    origin: DVec3,
    direction: DVec3,
    tnear: f64,
    tfar: f64,
) -> Option<(f64, f64, f64)> {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = direction.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let s = origin - t[0];
    let u = s.dot(p) / det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = direction.dot(q) / det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let distance = e2.dot(q) / det;
    (distance > tnear && distance <= tfar).then_some((distance, u, v))
}

impl RayCaster for TriangleBvh {
    fn offset(&self) -> f32 {
        self.offset
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if ray.is_empty() || self.nodes.is_empty() {
            return false;
        }
        let (origin, direction) = (ray.origin.as_dvec3(), ray.direction.as_dvec3());
        let (tnear, tfar) = (f64::from(ray.tnear.max(0.0)), f64::from(ray.tfar));
        let inverse = DVec3::ONE / direction;
        let mut stack = vec![0usize];
        while let Some(k) = stack.pop() {
            let node = &self.nodes[k];
            if !meets_box(node, origin, inverse, tnear, tfar) {
                continue;
            }
            let first = node.first as usize;
            if node.count == 0 {
                stack.push(first);
                stack.push(first + 1);
            } else if self.triangles[first..first + node.count as usize]
                .iter()
                .any(|t| hits_triangle(t, origin, direction, tnear, tfar))
            {
                return true;
            }
        }
        false
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if ray.is_empty() || self.nodes.is_empty() {
            return None;
        }
        let (origin, direction) = (ray.origin.as_dvec3(), ray.direction.as_dvec3());
        let tnear = f64::from(ray.tnear.max(0.0));
        let mut tfar = f64::from(ray.tfar);
        let inverse = DVec3::ONE / direction;
        let mut best: Option<(usize, f64, f64, f64)> = None;
        let mut stack = vec![0usize];
        while let Some(k) = stack.pop() {
            let node = &self.nodes[k];
            // `tfar` shrinks to the closest hit so far (inclusive: an equally close triangle is still tested,
            // and the first one found is kept).
            if !meets_box(node, origin, inverse, tnear, tfar) {
                continue;
            }
            let first = node.first as usize;
            if node.count == 0 {
                stack.push(first);
                stack.push(first + 1);
                continue;
            }
            for k in first..first + node.count as usize {
                if let Some((t, u, v)) = triangle_hit(&self.triangles[k], origin, direction, tnear, tfar) {
                    if best.is_none_or(|(_, best_t, _, _)| t < best_t) {
                        best = Some((k, t, u, v));
                        tfar = t;
                    }
                }
            }
        }
        let (k, t, u, v) = best?;
        let [p0, p1, p2] = self.triangles[k];
        Some(Hit {
            t: t as f32,
            primitive: self.ids[k],
            geometry: 0,
            barycentric: [u as f32, v as f32],
            normal: (p1 - p0).cross(p2 - p0).normalize().as_vec3(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against testing every triangle: the hierarchy finds exactly the same hits, over random rays through a
    /// cloud of random triangles (the box test only skips work).
    #[test]
    fn hierarchy_matches_testing_every_triangle() {
        let mut rng = crate::rng::SplitMix64::new(3);
        let mut point = || Vec3::new(rng.unit() as f32, rng.unit() as f32, rng.unit() as f32) * 10.0;
        let vertices: Vec<Vec3> = (0..300).map(|_| point()).collect();
        let triangles: Vec<[u32; 3]> = (0..100).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
        let bvh = TriangleBvh::new(&vertices, &triangles).unwrap();
        assert_eq!(bvh.triangle_count(), 100);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..2000 {
            let (from, to) = (point(), point());
            let ray = Ray::segment(from, to, bvh.offset());
            let (o, d) = (ray.origin.as_dvec3(), ray.direction.as_dvec3());
            let every = bvh
                .triangles
                .iter()
                .any(|t| hits_triangle(t, o, d, f64::from(ray.tnear), f64::from(ray.tfar)));
            assert_eq!(bvh.occluded(&ray), every, "{ray:?}");
            if every {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses");
    }

    /// Closest hits against testing every triangle: the same triangle, distance and barycentrics, over random
    /// rays through a cloud of random triangles; ids name the input order, with a degenerate triangle dropped.
    #[test]
    fn closest_hit_matches_testing_every_triangle() {
        let mut rng = crate::rng::SplitMix64::new(4);
        let mut point = || Vec3::new(rng.unit() as f32, rng.unit() as f32, rng.unit() as f32) * 10.0;
        let mut vertices: Vec<Vec3> = (0..300).map(|_| point()).collect();
        vertices.extend([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
        let mut triangles: Vec<[u32; 3]> = vec![[300, 301, 302]];
        triangles.extend((0..100).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]));
        let bvh = TriangleBvh::new(&vertices, &triangles).unwrap();
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..2000 {
            let (from, to) = (point(), point());
            let ray = Ray::new(from, to - from, 0.0, 2.0);
            let (o, d) = (from.as_dvec3(), (to - from).as_dvec3());
            let nearest = triangles
                .iter()
                .enumerate()
                .filter_map(|(k, t)| {
                    let t = t.map(|i| vertices[i as usize].as_dvec3());
                    triangle_hit(&t, o, d, 0.0, 2.0).map(|h| (k, h))
                })
                .min_by(|a, b| a.1 .0.total_cmp(&b.1 .0));
            match (bvh.intersect(&ray), nearest) {
                (None, None) => misses += 1,
                (Some(hit), Some((k, (t, u, v)))) => {
                    hits += 1;
                    assert_eq!(hit.primitive as usize, k);
                    assert_eq!((hit.t, hit.barycentric), (t as f32, [u as f32, v as f32]));
                    let [p0, p1, p2] = triangles[k].map(|i| vertices[i as usize]);
                    assert!((hit.normal - (p1 - p0).cross(p2 - p0).normalize()).length() < 1e-6);
                }
                (got, want) => panic!("{ray:?}: {got:?} vs {want:?}"),
            }
        }
        assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses");
    }

    /// The interval conventions: `tnear` exclusive, `tfar` inclusive, both faces hit, empty rays never occluded,
    /// degenerate triangles dropped, bad input rejected.
    #[test]
    fn follows_the_embree_conventions() {
        let vertices = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0)];
        let bvh = TriangleBvh::new(&vertices, &[[0, 1, 2], [0, 1, 3]]).unwrap();
        assert_eq!(bvh.triangle_count(), 1, "the collinear triangle is dropped");
        let down = |tnear, tfar| Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, tnear, tfar);
        assert!(bvh.occluded(&down(0.0, 1.0)), "tfar inclusive");
        assert!(!bvh.occluded(&down(0.0, 0.999)));
        assert!(!bvh.occluded(&down(1.0, 2.0)), "tnear exclusive");
        assert!(bvh.occluded(&down(-5.0, 2.0)), "negative tnear counts as 0");
        let up = Ray::new(Vec3::new(0.25, 0.25, -1.0), Vec3::Z, 0.0, 2.0);
        assert!(bvh.occluded(&up), "two-sided");
        assert!(bvh.occluded(&Ray::new(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, 0.0, 2.0)), "edges count");
        assert!(!bvh.occluded(&down(0.6, 0.5)), "empty");
        assert!(!bvh.occluded(&Ray::new(Vec3::splat(f32::NAN), -Vec3::Z, 0.0, 2.0)));
        let empty = TriangleBvh::new(&[], &[]).unwrap();
        assert!(!empty.occluded(&down(0.0, 2.0)));
        assert_eq!(
            TriangleBvh::new(&vertices, &[[0, 1, 9]]).unwrap_err(),
            MeshInputError::VertexOutOfRange { triangle: 0, vertex: 9, vertex_count: 4 }
        );
        assert!(matches!(
            TriangleBvh::new(&[Vec3::splat(f32::INFINITY)], &[]).unwrap_err(),
            MeshInputError::NonFiniteVertex { index: 0, .. }
        ));
    }
}
