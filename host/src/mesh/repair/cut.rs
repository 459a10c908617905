//! Where faces meet and how a polygon is cut there: the segment along which another polygon meets a polygon's
//! interior, the cut of a convex polygon by a line, and the merge of neighbouring pieces whose union is convex.
//!
//! All tests take the repair tolerance `tol` (a length, [`super::REPAIR_TOLERANCE`] times the scene size): a point
//! within `tol` of a plane lies in it, a point within `tol` of a line lies on it.

use glam::DVec3;

use crate::scene::Polygon;

/// How another polygon meets a polygon's interior.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Meeting {
    /// An edge of the other polygon lies in this polygon's plane, inside it, and the rest of the other polygon is
    /// on one side (a block standing on the floor, a wall ending on another): a contact line.
    Contact,
    /// The other polygon passes through this polygon's plane inside it (interpenetrating solids, a wall through
    /// another): an intersection line.
    Crossing,
}

/// A segment in a polygon's plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Segment {
    pub(super) a: DVec3,
    pub(super) b: DVec3,
}

/// Where polygon `q` meets the interior of polygon `p`, if it does along a segment: the part of `q` that lies in
/// `p`'s plane (an edge of `q` there, or the chord where `q` crosses it), clipped to `p` shrunk by `tol`, when it is
/// longer than `tol` and its line has vertices of `p` more than `tol` away on both sides (so it is no edge of `p`
/// and cuts `p` in two). Coplanar polygons (every vertex of `q` within `tol` of `p`'s plane) give `None`: the loader
/// rejects coplanar overlaps, and coplanar polygons that share an edge need no cut.
pub(super) fn meeting(p: &Polygon, q: &Polygon, tol: f64) -> Option<(Segment, Meeting)> {
    let n = p.normal;
    let height = |v: DVec3| {
        let h = (v - p.centroid).dot(n);
        if h.abs() <= tol {
            0.0
        } else {
            h
        }
    };
    let s: Vec<f64> = q.vertices.iter().map(|&v| height(v)).collect();
    let above = s.iter().any(|&h| h > 0.0);
    let below = s.iter().any(|&h| h < 0.0);
    let on = s.iter().filter(|&&h| h == 0.0).count();
    let kind = match (above, below) {
        (false, false) => return None,
        (true, true) => Meeting::Crossing,
        _ if on >= 2 => Meeting::Contact,
        _ => return None,
    };
    // The points of `q` in `p`'s plane: its vertices there and its edges' crossings, projected into the plane.
    let flat = |x: DVec3| x - n * (x - p.centroid).dot(n);
    let m = q.vertices.len();
    let mut points = Vec::with_capacity(m);
    for i in 0..m {
        let (a, b) = (q.vertices[i], q.vertices[(i + 1) % m]);
        let (sa, sb) = (s[i], s[(i + 1) % m]);
        if sa == 0.0 {
            points.push(flat(a));
        }
        if sa * sb < 0.0 {
            points.push(flat(a + (b - a) * (sa / (sa - sb))));
        }
    }
    // `q` is convex, so these points lie on one segment: its ends are the two farthest apart.
    let (mut a, mut b, mut len) = (DVec3::ZERO, DVec3::ZERO, 0.0);
    for (i, &x) in points.iter().enumerate() {
        for &y in &points[i + 1..] {
            if x.distance(y) > len {
                (a, b, len) = (x, y, x.distance(y));
            }
        }
    }
    if len <= tol {
        return None;
    }
    // Clip to `p` shrunk by `tol` (Cyrus and Beck, "Generalized two- and three-dimensional clipping", 1978): a
    // segment along an edge of `p`, or one that only reaches `p` within `tol` of its boundary, is no cut.
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let v = &p.vertices;
    for e in 0..v.len() {
        let (p0, p1) = (v[e], v[(e + 1) % v.len()]);
        let inward = n.cross(p1 - p0).normalize();
        let (fa, fb) = (inward.dot(a - p0) - tol, inward.dot(b - p0) - tol);
        if fa < 0.0 && fb < 0.0 {
            return None;
        }
        if fa < 0.0 {
            t0 = t0.max(fa / (fa - fb));
        } else if fb < 0.0 {
            t1 = t1.min(fa / (fa - fb));
        }
    }
    if (t1 - t0) * len <= tol {
        return None;
    }
    let segment = Segment { a: a + (b - a) * t0, b: a + (b - a) * t1 };
    let line = Line::through(&segment, n);
    let sides = v.iter().map(|&x| line.side(x));
    let (lo, hi) = sides.fold((0.0f64, 0.0f64), |(lo, hi), d| (lo.min(d), hi.max(d)));
    (lo < -tol && hi > tol).then_some((segment, kind))
}

/// A line in a polygon's plane: the points `x` with `m . (x - a) = 0`, `m` a unit vector in the plane.
#[derive(Clone, Copy, Debug)]
pub(super) struct Line {
    a: DVec3,
    m: DVec3,
}

impl Line {
    /// The line through `s` in the plane with unit normal `n`.
    pub(super) fn through(s: &Segment, n: DVec3) -> Line {
        Line { a: s.a, m: n.cross((s.b - s.a).normalize()) }
    }

    /// Signed distance of `x` (in the plane) from the line.
    pub(super) fn side(&self, x: DVec3) -> f64 {
        self.m.dot(x - self.a)
    }

    /// Whether both ends of `s` lie within `tol` of the line.
    pub(super) fn contains(&self, s: &Segment, tol: f64) -> bool {
        self.side(s.a).abs() <= tol && self.side(s.b).abs() <= tol
    }
}

/// Cuts the convex polygon `v` by `line` into the pieces on its two sides, or `None` if no vertex lies more than
/// `tol` from the line on one of them. Vertices within `tol` of the line belong to both pieces; an edge whose ends
/// lie more than `tol` away on opposite sides gets a new vertex where it crosses the line (a point of the edge,
/// so it stays in the polygon's plane).
pub(super) fn split(v: &[DVec3], line: &Line, tol: f64) -> Option<(Vec<DVec3>, Vec<DVec3>)> {
    let d: Vec<f64> = v
        .iter()
        .map(|&x| {
            let s = line.side(x);
            if s.abs() <= tol {
                0.0
            } else {
                s
            }
        })
        .collect();
    if !(d.iter().any(|&s| s > 0.0) && d.iter().any(|&s| s < 0.0)) {
        return None;
    }
    let (mut plus, mut minus) = (Vec::new(), Vec::new());
    let n = v.len();
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        let (da, db) = (d[i], d[(i + 1) % n]);
        if da >= 0.0 {
            plus.push(a);
        }
        if da <= 0.0 {
            minus.push(a);
        }
        if da * db < 0.0 {
            let x = a + (b - a) * (da / (da - db));
            plus.push(x);
            minus.push(x);
        }
    }
    Some((plus, minus))
}

/// Distance below which a vertex that a merge leaves between two collinear edges is dropped: vertices are made by
/// at most a few interpolations between input vertices, each off by a few `eps` times the coordinates, so a
/// vertex that was made on a straight edge is within `64 eps` of the scene size of it (and one that is not may stay:
/// a collinear vertex is harmless, dropping a real corner would change the area).
pub(super) const STRAIGHT: f64 = 64.0 * f64::EPSILON;

/// The union of the convex polygons `a` and `b` (counter-clockwise around `n`) if they share a whole edge (its
/// ends within `tol`), that edge is not part of any of `keep` (contact and intersection segments, which must
/// stay piece boundaries), and the union is convex. Vertices of the union between collinear edges (within
/// `straight`) are dropped unless they are in `corners` (the polygon's own vertices).
pub(super) fn merge(
    a: &[DVec3],
    b: &[DVec3],
    n: DVec3,
    tol: f64,
    straight: f64,
    keep: &[Segment],
    corners: &[DVec3],
) -> Option<Vec<DVec3>> {
    let (na, nb) = (a.len(), b.len());
    let close = |x: DVec3, y: DVec3| x.distance(y) <= tol;
    let (i, j) = (0..na)
        .flat_map(|i| (0..nb).map(move |j| (i, j)))
        .find(|&(i, j)| close(a[i], b[(j + 1) % nb]) && close(a[(i + 1) % na], b[j]))?;
    let shared = Segment { a: a[i], b: a[(i + 1) % na] };
    let line = Line::through(&shared, n);
    let len = shared.a.distance(shared.b);
    let dir = (shared.b - shared.a) / len;
    for s in keep {
        if line.contains(s, tol) {
            let (u, w) = ((s.a - shared.a).dot(dir), (s.b - shared.a).dot(dir));
            if u.max(w).min(len) - u.min(w).max(0.0) > tol {
                return None;
            }
        }
    }
    // a[i+1], ..., a[i] around `a`, then b[j+2], ..., b[j-1] around `b`.
    let mut union: Vec<DVec3> = (1..=na).map(|k| a[(i + k) % na]).collect();
    union.extend((2..nb).map(|k| b[(j + k) % nb]));
    let m = union.len();
    let turn = |k: usize| {
        let (p, q, r) = (union[(k + m - 1) % m], union[k], union[(k + 1) % m]);
        // Signed distance of `r` from the line through `p` and `q`, and whether `r` goes on forward.
        let e = q - p;
        (e.cross(r - q).dot(n) / e.length(), e.dot(r - q) > 0.0)
    };
    if (0..m).any(|k| turn(k).0 < -tol) {
        return None;
    }
    let mut out = Vec::with_capacity(m);
    for (k, &x) in union.iter().enumerate() {
        let (dist, forward) = turn(k);
        let is_corner = corners.iter().any(|&c| close(c, x));
        if !(dist.abs() <= straight && forward && !is_corner) {
            out.push(x);
        }
    }
    (out.len() >= 3).then_some(out)
}
