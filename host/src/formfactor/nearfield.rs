//! Which quadrature a pair of patches gets: the far-field rule, the plain rule, or the near-field rule that
//! splits the sender towards the receiver (with the sliver and nearly-parallel refinements); and the cheap exact
//! tests that come before (facing planes, a sender cut by the receiver's plane).

use glam::DVec3;

use super::kernel::{clip_above, polygon_area};
use super::quadrature::Quadrature;
use crate::patch::Patch;

/// If `to`'s plane cuts `polygon`, writes the part of `polygon` in front of it to `front` and returns true;
/// returns false if `polygon` lies wholly on one side (vertices within rounding of the plane count as on it, so a
/// shared edge is not a cut).
pub(super) fn clip_to_front(polygon: &[DVec3], to: &Patch, front: &mut Vec<DVec3>) -> bool {
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

/// Levels of splitting of the near-field quadrature: at most `4^NEAR_FIELD_DEPTH` pieces of the sending patch
/// (for triangles and quadrilaterals) near the receiver.
pub const NEAR_FIELD_DEPTH: usize = 3;

/// Most levels of splitting of the near-field quadrature, used while a piece is larger than the receiver.
pub const NEAR_FIELD_MAX_DEPTH: usize = 6;

/// Centroid of the vertices and the largest distance from it to a vertex.
pub(super) fn bounding_sphere(polygon: &[DVec3]) -> (DVec3, f64) {
    let c = polygon.iter().copied().sum::<DVec3>() / polygon.len() as f64;
    (c, polygon.iter().map(|v| v.distance(c)).fold(0.0, f64::max))
}

/// A pair is in the far field when the gap between the bounding spheres of `i` and `j` (for elements, between
/// `i`'s sphere and `j`'s polygon, `Receiver::gap`) is at least this many diameters of `i`: the kernel then varies on a scale `D` at least that many times `i`'s size `h`, and the
/// product Gauss-Legendre rule of half the order ([`far_field_order`]) suffices. Its relative error is about
/// `c (h / D)^(2m)` for `m` points per direction (Davis and Rabinowitz, "Methods of Numerical Integration",
/// 2nd ed., section 2.7: `f^(2m)` of a kernel falling like `D^-3` is about `(2m + 2)! / 2 D^-(2m)` times it);
/// with `m = 2`, `c` about 0.1 and `h / D <= 1/5` that is about `1.6e-4`, below the 16-bit codec's `2.4e-4`
/// and the visibility noise of the default 16 rays per pair. The test `far_field_rule_matches_the_full_rule`
/// checks that bound on the Cornell box; the share of pairs in the far field, and so the time saved, grows with
/// the patch count.
pub const FAR_FIELD_GAP: f64 = 5.0;

/// Points per direction of the far-field rule for a full rule of `order` points per direction: half, at least 2
/// (or the full order when that is smaller).
#[must_use]
pub fn far_field_order(order: usize) -> usize {
    order.div_ceil(2).max(2).min(order)
}

/// Whether `domain` is near the receiver: the gap between its bounding sphere and the receiver ([`Receiver::gap`])
/// is less than its own diameter, so that a fixed product rule over `domain` is inaccurate (its error grows like a
/// power of size / distance).
pub(super) fn near(domain: &[DVec3], receiver: &Receiver) -> bool {
    let (c, r) = bounding_sphere(domain);
    let gap = if receiver.polygon_gap {
        receiver.gap(c, r)
    } else {
        // The patch-to-patch estimator's sphere-to-sphere gap, in its own order of operations.
        c.distance(receiver.center) - receiver.radius - r
    };
    gap < 2.0 * r
}

/// Extra levels of splitting of the near-field quadrature towards a sliver receiver (`Receiver::sliver_width`),
/// beyond [`NEAR_FIELD_MAX_DEPTH`]: pieces down to `2^-(NEAR_FIELD_MAX_DEPTH + SLIVER_DEPTH)` of the sender's size.
pub const SLIVER_DEPTH: usize = 10;

/// If `polygon` is a sliver quadrilateral ([`sliver_width`]), cuts it
/// across its length into pieces about twice as long as it is wide (at most `2^SLIVER_DEPTH`), writes them to
/// `pieces` and returns true; returns false for anything else.
pub(super) fn sliver_strips(polygon: &[DVec3], pieces: &mut Vec<Vec<DVec3>>) -> bool {
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
pub(super) const PARALLEL_COSINE: f64 = 0.906;

/// A receiving patch as the near-field quadrature sees it.
pub(super) struct Receiver<'a> {
    /// Bounding sphere: centroid of the vertices and the largest distance from it to a vertex.
    pub(super) center: DVec3,
    pub(super) radius: f64,
    pub(super) vertices: &'a [DVec3],
    pub(super) normal: DVec3,
    /// Its width if it is a sliver ([`sliver_width`]).
    pub(super) sliver_width: Option<f64>,
    /// Whether the near and far fields are judged by the distance to the polygon ([`Receiver::gap`]; elements) or
    /// to its bounding sphere (the patch-to-patch estimator, whose values its regression baseline pins).
    pub(super) polygon_gap: bool,
}

/// `2 A / P` of a polygon (area over half the perimeter: the width of a long strip) if that is positive and less
/// than an eighth of its bounding radius, i.e. the polygon is a sliver (a strip longer than about 16 times its
/// width); `None` otherwise.
pub(super) fn sliver_width(polygon: &[DVec3]) -> Option<f64> {
    let perimeter: f64 =
        polygon.iter().zip(polygon.iter().cycle().skip(1)).map(|(a, b)| a.distance(*b)).sum();
    let width = 2.0 * polygon_area(polygon) / perimeter;
    let (_, radius) = bounding_sphere(polygon);
    (width > 0.0 && width < radius / 8.0).then_some(width)
}

impl<'a> Receiver<'a> {
    pub(super) fn new(patch: &'a Patch) -> Self {
        let (center, radius) = bounding_sphere(&patch.vertices);
        let sliver_width = sliver_width(&patch.vertices);
        Receiver {
            center,
            radius,
            vertices: &patch.vertices,
            normal: patch.normal,
            sliver_width,
            polygon_gap: false,
        }
    }

    /// [`Self::new`], judging near and far by the distance to the polygon ([`Self::gap`]).
    pub(super) fn by_polygon(patch: &'a Patch) -> Self {
        Receiver { polygon_gap: true, ..Self::new(patch) }
    }

    /// The gap between a sphere `(center, radius)` holding (a piece of) the sender and the receiver's polygon: the
    /// distance from the centre to the polygon less the radius, a lower bound of the distance from any point of
    /// the piece to the receiver. The point kernel `F_{x -> j}` is analytic wherever `x` is off `j`'s closure and
    /// varies on the scale of the distance to it, which is what a fixed rule's error depends on; the gap to `j`'s
    /// bounding sphere calls a small piece in the middle of a floor near every wall standing on that floor, and
    /// splits it for nothing.
    pub(super) fn gap(&self, center: DVec3, radius: f64) -> f64 {
        self.distance(center) - radius
    }

    /// Distance from `x` to the (convex, planar) receiver polygon.
    pub(super) fn distance(&self, x: DVec3) -> f64 {
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
    pub(super) fn boundary_distance(&self, x: DVec3) -> f64 {
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
pub(super) fn near_field_integral(
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
    let split =
        depth > 0 && near(domain, receiver) && (depth > NEAR_FIELD_MAX_DEPTH - NEAR_FIELD_DEPTH || larger);
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

/// Whether `j` can receive anything from `i` at all: some vertex of `j` lies above `i`'s plane and some vertex
/// of `i` lies in front of `j`'s plane (a cheap exact rejection before the per-point kernel).
pub(super) fn may_see(i: &Patch, j: &Patch) -> bool {
    let above =
        |from: &Patch, to: &Patch| to.vertices.iter().any(|v| from.normal.dot(*v - from.vertices[0]) > 0.0);
    above(i, j) && above(j, i)
}
