//! The cuts every mesh is made of: the regular subdivision of a triangle, the bilinear grid of a
//! quadrilateral, and one quadrilateral per vertex of a convex polygon around its centroid. Uniform meshing and
//! adaptive refinement both cut with these, and every piece becomes a [`Patch`] that keeps its face's normal.

use glam::DVec3;

use super::MeshError;
use crate::patch::Patch;
use crate::scene::Polygon;

/// A patch of face `face` from its vertices and the face's normal.
pub(super) fn make_patch(
    face: usize,
    material: usize,
    vertices: Vec<DVec3>,
    normal: DVec3,
) -> Result<Patch, MeshError> {
    let p = Polygon::with_normal(vertices, normal).ok_or(MeshError::ZeroAreaPatch { face })?;
    Ok(Patch { face, material, vertices: p.vertices, normal, area: p.area, centroid: p.centroid })
}

/// The regular subdivision of triangle `abc` into `k^2` triangles similar to it, all with its orientation.
pub(super) fn triangle_grid(a: DVec3, b: DVec3, c: DVec3, k: usize, out: &mut Vec<Vec<DVec3>>) {
    let kf = k as f64;
    // Point with barycentric coordinates (i/k, j/k) along ab and ac.
    let p = |i: usize, j: usize| a + (b - a) * (i as f64 / kf) + (c - a) * (j as f64 / kf);
    for j in 0..k {
        for i in 0..k - j {
            out.push(vec![p(i, j), p(i + 1, j), p(i, j + 1)]);
            if i + j + 1 < k {
                out.push(vec![p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
    }
}

/// The `nu x nv` grid of the bilinear parametrisation of quadrilateral `v`, cells in `v`'s orientation.
pub(super) fn quad_grid(v: &[DVec3], nu: usize, nv: usize, out: &mut Vec<Vec<DVec3>>) {
    let p = |i: usize, j: usize| {
        let (s, t) = (i as f64 / nu as f64, j as f64 / nv as f64);
        v[0] * ((1.0 - s) * (1.0 - t)) + v[1] * (s * (1.0 - t)) + v[2] * (s * t) + v[3] * ((1.0 - s) * t)
    };
    for j in 0..nv {
        for i in 0..nu {
            out.push(vec![p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
}

/// Cuts a convex polygon into one quadrilateral per vertex: (centroid, midpoint of the edge before vertex `i`,
/// vertex `i`, midpoint of the edge after it). A quadrilateral that rounding made non-convex is replaced by its
/// two triangles. `None` entries are pieces with zero area (never for a valid polygon).
pub(super) fn centroid_quads(p: &Polygon) -> Vec<Option<Polygon>> {
    let v = &p.vertices;
    let n = v.len();
    let c = p.centroid;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let before = 0.5 * (v[(i + n - 1) % n] + v[i]);
        let after = 0.5 * (v[i] + v[(i + 1) % n]);
        let quad = vec![c, before, v[i], after];
        if is_convex(&quad, p.normal) {
            out.push(Polygon::with_normal(quad, p.normal));
        } else {
            out.push(Polygon::with_normal(vec![c, before, v[i]], p.normal));
            out.push(Polygon::with_normal(vec![c, v[i], after], p.normal));
        }
    }
    out
}

/// Whether every turn of the polygon is strictly to the left around `normal`.
fn is_convex(v: &[DVec3], normal: DVec3) -> bool {
    let n = v.len();
    (0..n).all(|i| {
        let (a, b, c) = (v[(i + n - 1) % n], v[i], v[(i + 1) % n]);
        (b - a).cross(c - b).dot(normal) > 0.0
    })
}
