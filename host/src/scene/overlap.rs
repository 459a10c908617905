//! Coplanar overlap: two faces that lie in one plane and cover a common area of positive size (duplicates
//! included) are an error.
//!
//! Two polygons are coplanar when each one's vertices lie within [`PLANAR_TOLERANCE`]` * d` (the larger diameter
//! `d` of the two) of the other's plane; they overlap when the area of their intersection exceeds
//! [`OVERLAP_TOLERANCE`] times the smaller area (faces that only share an edge intersect in zero area up to
//! rounding, ~1e-16 relative). A sweep along x keeps the pair tests to polygons whose bounding boxes meet.

use std::path::Path;

use glam::DVec3;

use super::error::{length, SceneError, SceneWarning};
use super::face::{Face, PLANAR_TOLERANCE};
use super::polygon::Polygon;

/// Intersection area of two coplanar polygons, relative to the smaller polygon's area, above which they overlap.
pub const OVERLAP_TOLERANCE: f64 = 1e-6;

struct PolyRef<'a> {
    face: &'a Face,
    poly: &'a Polygon,
    min: DVec3,
    max: DVec3,
    d: f64,
}

/// Every polygon of `faces` with its bounding box, in increasing order of the box's smallest x (the sweep's
/// order).
fn sweep_order(faces: &[Face]) -> Vec<PolyRef<'_>> {
    let mut items: Vec<PolyRef<'_>> = faces
        .iter()
        .flat_map(|f| f.polygons.iter().map(move |p| (f, p)))
        .map(|(face, poly)| {
            let (min, max) = super::bounding_box(poly.vertices.iter().copied());
            PolyRef { face, poly, min, max, d: poly.diameter() }
        })
        .collect();
    items.sort_by(|a, b| a.min.x.total_cmp(&b.min.x));
    items
}

/// Fails on the first pair of coplanar faces that overlap with positive area.
pub(super) fn check_overlaps(file: &Path, faces: &[Face]) -> Result<(), SceneError> {
    // Sweep along x: only pairs whose bounding boxes meet can overlap.
    let items = sweep_order(faces);
    let max_d = items.iter().map(|p| p.d).fold(0.0, f64::max);
    for (i, a) in items.iter().enumerate() {
        let reach = a.max.x + PLANAR_TOLERANCE * max_d;
        for b in items[i + 1..].iter().take_while(|b| b.min.x <= reach) {
            if std::ptr::eq(a.face, b.face) {
                continue;
            }
            let tol = PLANAR_TOLERANCE * a.d.max(b.d);
            if (a.min - b.max).max_element() > tol || (b.min - a.max).max_element() > tol {
                continue;
            }
            if !coplanar(a.poly, b.poly, tol) {
                continue;
            }
            let area = overlap_area(a.poly, b.poly);
            if area > OVERLAP_TOLERANCE * a.poly.area.min(b.poly.area) {
                let (x, y) = if a.face.index < b.face.index { (a.face, b.face) } else { (b.face, a.face) };
                if x.gltf.is_some() || y.gltf.is_some() {
                    return Err(SceneError::Gltf {
                        file: file.to_path_buf(),
                        place: format!(
                            "face {} ({}) and face {} ({})",
                            x.index,
                            x.place(),
                            y.index,
                            y.place()
                        ),
                        problem: format!(
                            "coplanar and overlap (area {area:.6e}; duplicate or overlapping faces)"
                        ),
                    });
                }
                return Err(SceneError::OverlappingFaces {
                    file: file.to_path_buf(),
                    face_a: x.index,
                    line_a: x.line,
                    face_b: y.index,
                    line_b: y.line,
                    area,
                });
            }
        }
    }
    Ok(())
}

/// Cosine between two faces' normals below which they count as facing each other (antiparallel within about
/// 0.8 degrees).
const FACING_COSINE: f64 = -0.9999;

/// Warns once if some pairs of faces face each other across a gap narrower than twice the rays' offset (the
/// scene's size over 8192, [`crate::raycast::offset_for`]): rays between surfaces start and end that far off them,
/// in the form factors, the hierarchy and the path-traced reference alike, so light in such a gap is resolved
/// differently by each (a lamp's arm 1 mm under its emitting head got all of its light in one and none in the
/// other). Parallel facing polygons with a gap in `(0, 2 offset)` whose outlines overlap in projection are
/// counted; the warning names the narrowest pair.
pub(super) fn narrow_gaps(file: &Path, faces: &[Face]) -> Option<SceneWarning> {
    let vertices: Vec<glam::Vec3> = faces
        .iter()
        .flat_map(|f| f.polygons.iter())
        .flat_map(|p| p.vertices.iter().map(|v| v.as_vec3()))
        .collect();
    let reach = 2.0 * f64::from(crate::raycast::offset_for(&vertices));
    let items = sweep_order(faces);
    let (mut pairs, mut narrowest): (usize, Option<(f64, &Face, &Face)>) = (0, None);
    for (i, a) in items.iter().enumerate() {
        for b in items[i + 1..].iter().take_while(|b| b.min.x <= a.max.x + reach) {
            if std::ptr::eq(a.face, b.face)
                || (a.min - b.max).max_element() > reach
                || (b.min - a.max).max_element() > reach
                || a.poly.normal.dot(b.poly.normal) > FACING_COSINE
            {
                continue;
            }
            // `b` wholly in front of `a` within the reach (with antiparallel normals, `a` is then in front of
            // `b`), the gap measured along `a`'s normal at `b`'s vertices.
            let gaps = b.poly.vertices.iter().map(|v| (*v - a.poly.centroid).dot(a.poly.normal));
            let (lo, hi) = gaps.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), g| (l.min(g), h.max(g)));
            if !(lo > 0.0 && hi < reach) {
                continue;
            }
            if overlap_area(a.poly, b.poly) <= OVERLAP_TOLERANCE * a.poly.area.min(b.poly.area) {
                continue;
            }
            pairs += 1;
            let (x, y) = if a.face.index < b.face.index { (a.face, b.face) } else { (b.face, a.face) };
            if narrowest.is_none_or(|(g, ..)| lo < g) {
                narrowest = Some((lo, x, y));
            }
        }
    }
    let (gap, x, y) = narrowest?;
    Some(SceneWarning {
        file: file.to_path_buf(),
        line: (x.line > 0).then_some(x.line),
        face: Some(x.index),
        message: format!(
            "{pairs} pair(s) of faces face each other across a gap narrower than {} (twice the rays' offset, the \
             scene's size / {}), the narrowest this one and face {} ({}) {} apart: rays start and end the offset \
             off surfaces, so light inside such a gap is not resolved (widen the gap, or join the faces)",
            length(reach),
            1.0 / crate::raycast::RELATIVE_OFFSET,
            y.index,
            y.place(),
            length(gap)
        ),
    })
}

fn coplanar(a: &Polygon, b: &Polygon, tol: f64) -> bool {
    let off =
        |p: &Polygon, q: &Polygon| q.vertices.iter().all(|v| (*v - p.centroid).dot(p.normal).abs() <= tol);
    off(a, b) && off(b, a)
}

/// Area of the intersection of two coplanar convex polygons: `a` clipped by each edge of `b`
/// (Sutherland and Hodgman, "Reentrant polygon clipping", CACM 1974), in `a`'s plane.
fn overlap_area(a: &Polygon, b: &Polygon) -> f64 {
    let n = a.normal;
    let u = n.any_orthonormal_vector();
    let w = n.cross(u);
    let to2 = |p: &DVec3| glam::DVec2::new(p.dot(u), p.dot(w));
    let subject: Vec<glam::DVec2> = a.vertices.iter().map(to2).collect();
    let mut clip: Vec<glam::DVec2> = b.vertices.iter().map(to2).collect();
    // Both counter-clockwise in (u, w), i.e. seen from `a.normal`; `b` may face the other way.
    if b.normal.dot(n) < 0.0 {
        clip.reverse();
    }
    let clipped = clip_convex(subject, &clip);
    area2(&clipped).max(0.0)
}

/// Clips polygon `subject` by the convex counter-clockwise polygon `clip`.
fn clip_convex(mut subject: Vec<glam::DVec2>, clip: &[glam::DVec2]) -> Vec<glam::DVec2> {
    for i in 0..clip.len() {
        let (p, q) = (clip[i], clip[(i + 1) % clip.len()]);
        let e = q - p;
        let side = |x: glam::DVec2| e.perp_dot(x - p);
        let input = std::mem::take(&mut subject);
        for j in 0..input.len() {
            let (s, t) = (input[j], input[(j + 1) % input.len()]);
            let (ss, st) = (side(s), side(t));
            if ss >= 0.0 {
                subject.push(s);
            }
            if (ss >= 0.0) != (st >= 0.0) {
                let r = ss / (ss - st);
                subject.push(s + (t - s) * r);
            }
        }
        if subject.is_empty() {
            break;
        }
    }
    subject
}

/// Signed area of a 2D polygon (shoelace formula), positive when counter-clockwise.
fn area2(p: &[glam::DVec2]) -> f64 {
    0.5 * (0..p.len()).map(|i| p[i].perp_dot(p[(i + 1) % p.len()])).sum::<f64>()
}
