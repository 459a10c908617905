//! Which pieces no point of the scene can see: those whose front side looks only at back sides of faces (the
//! inside of a closed solid, the floor under a block without a bottom face) or at other such pieces.
//!
//! # Test
//! From each test point of a piece (its centroid, and the midpoints between the centroid and each vertex) rays go
//! out over the piece's front hemisphere in [`DIRECTIONS`] fixed directions (rings at fixed polar angles). A ray
//! *sees out* when it leaves the scene or its first hit (beyond the repair tolerance, in f64, against every
//! piece) is the front side of a piece not yet culled. A piece none of whose rays sees out is culled, and the
//! test is repeated on the remaining pieces until no more are culled, so that a piece that looks only at culled
//! pieces (a face of one solid inside another, or a nested solid) goes too. Culling only ever adds pieces and a
//! piece is culled only if all its rays are blocked given the pieces culled so far, so the result is the smallest
//! set closed under the rule, whatever the order.
//!
//! # Exactness
//! For a piece inside a region bounded only by back sides (a closed solid, or an open-bottomed solid standing on
//! it), every ray from every point is blocked, so such a piece is culled whatever the directions: exact for
//! resting and interpenetrating objects once the cuts have separated the inside from the outside. A visible piece
//! is kept as soon as one ray sees out; it could be culled by mistake only if all it can see of the scene's front
//! sides or the outside lies between the test directions of all its test points (a crack much narrower than the
//! piece), which leaves light it would exchange through that crack out.

use glam::DVec3;

use crate::scene::Polygon;

/// Polar angles (degrees from the normal) and number of directions of the rings of test directions; the
/// azimuths of ring `r` are offset by half a step from ring `r - 1`'s.
const RINGS: [(f64, usize); 4] = [(0.0, 1), (30.0, 6), (55.0, 10), (80.0, 12)];

/// Test directions per test point.
pub const DIRECTIONS: usize = 1 + 6 + 10 + 12;

/// A piece as rays see it.
struct Target<'a> {
    poly: &'a Polygon,
    /// Unit inward normals of the edges, in the plane.
    inward: Vec<DVec3>,
    radius: f64,
}

/// Which of `pieces` are culled (see the module docs). `tol` is the repair tolerance (a length).
pub(super) fn culled(pieces: &[Polygon], tol: f64) -> Vec<bool> {
    let targets: Vec<Target<'_>> = pieces
        .iter()
        .map(|poly| {
            let v = &poly.vertices;
            let inward =
                (0..v.len()).map(|e| poly.normal.cross(v[(e + 1) % v.len()] - v[e]).normalize()).collect();
            let radius = v.iter().map(|x| x.distance(poly.centroid)).fold(0.0, f64::max);
            Target { poly, inward, radius }
        })
        .collect();
    let mut hidden = vec![false; pieces.len()];
    loop {
        let mut changed = false;
        for k in 0..pieces.len() {
            if !hidden[k] && !sees_out(k, &targets, &hidden, tol) {
                hidden[k] = true;
                changed = true;
            }
        }
        if !changed {
            return hidden;
        }
    }
}

/// Whether some ray from a test point of piece `k` sees out.
fn sees_out(k: usize, targets: &[Target<'_>], hidden: &[bool], tol: f64) -> bool {
    let p = targets[k].poly;
    let n = p.normal;
    let u = n.any_orthonormal_vector();
    let w = n.cross(u);
    let points = std::iter::once(p.centroid).chain(p.vertices.iter().map(|&v| 0.5 * (p.centroid + v)));
    for x in points {
        for (r, &(polar, count)) in RINGS.iter().enumerate() {
            let (sin, cos) = polar.to_radians().sin_cos();
            for i in 0..count {
                let azimuth = std::f64::consts::TAU * (i as f64 + 0.5 * r as f64) / count as f64;
                let (sa, ca) = azimuth.sin_cos();
                let d = n * cos + (u * ca + w * sa) * sin;
                if ray_sees_out(k, x, d, targets, hidden, tol) {
                    return true;
                }
            }
        }
    }
    false
}

/// Whether the ray from `x` (on piece `k`) along unit `d` leaves the scene or first hits the front of a piece
/// that is not culled.
fn ray_sees_out(k: usize, x: DVec3, d: DVec3, targets: &[Target<'_>], hidden: &[bool], tol: f64) -> bool {
    let mut best: Option<(f64, usize)> = None;
    for (j, t) in targets.iter().enumerate() {
        if j == k {
            continue;
        }
        let to_center = t.poly.centroid - x;
        // Bounding sphere: the ray passes farther than the radius from the centroid.
        let along = to_center.dot(d);
        if along < -t.radius || (to_center - d * along).length() > t.radius + tol {
            continue;
        }
        let denom = d.dot(t.poly.normal);
        if denom == 0.0 {
            continue;
        }
        let dist = to_center.dot(t.poly.normal) / denom;
        if !(dist > tol && best.is_none_or(|(b, _)| dist < b)) {
            continue;
        }
        let hit = x + d * dist;
        let v = &t.poly.vertices;
        if t.inward.iter().enumerate().all(|(e, m)| m.dot(hit - v[e]) >= -tol) {
            best = Some((dist, j));
        }
    }
    match best {
        None => true,
        Some((_, j)) => d.dot(targets[j].poly.normal) < 0.0 && !hidden[j],
    }
}
