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
use rayon::prelude::*;

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
///
/// Rays find their first hit through a bounding-volume hierarchy over the pieces ([`Bvh`]), the pieces are
/// tested in parallel, and each round re-tests only the pieces whose witness (what their first ray that saw out
/// hit) was culled in the round before: a ray's first hit does not depend on what is culled, and culling only
/// blocks rays, so a piece whose witness stays is still visible by the same ray, and the earlier rays that were
/// blocked stay blocked. The result is the same set as testing every piece in every round.
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
    let bvh = Bvh::new(pieces, 2.0 * tol);
    let mut hidden = vec![false; pieces.len()];
    let mut witness: Vec<Sight> = vec![Sight::Hidden; pieces.len()];
    let mut test: Vec<usize> = (0..pieces.len()).collect();
    while !test.is_empty() {
        let found: Vec<Sight> = test.par_iter().map(|&k| sees_out(k, &targets, &bvh, &hidden, tol)).collect();
        let mut changed = false;
        for (&k, sight) in test.iter().zip(found) {
            if sight == Sight::Hidden {
                hidden[k] = true;
                changed = true;
            }
            witness[k] = sight;
        }
        if !changed {
            break;
        }
        test = (0..pieces.len())
            .filter(|&k| !hidden[k] && matches!(witness[k], Sight::Through(j) if hidden[j]))
            .collect();
    }
    hidden
}

/// What a piece's rays saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sight {
    /// No ray saw out.
    Hidden,
    /// A ray left the scene.
    Out,
    /// The first ray that saw out hit the front of this piece first.
    Through(usize),
}

/// What piece `k`'s first ray that sees out saw, or [`Sight::Hidden`] if none does.
fn sees_out(k: usize, targets: &[Target<'_>], bvh: &Bvh, hidden: &[bool], tol: f64) -> Sight {
    let p = targets[k].poly;
    let n = p.normal;
    let u = n.any_orthonormal_vector();
    let w = n.cross(u);
    let points = std::iter::once(p.centroid).chain(p.vertices.iter().map(|&v| 0.5 * (p.centroid + v)));
    let mut stack = Vec::new();
    for x in points {
        for (r, &(polar, count)) in RINGS.iter().enumerate() {
            let (sin, cos) = polar.to_radians().sin_cos();
            for i in 0..count {
                let azimuth = std::f64::consts::TAU * (i as f64 + 0.5 * r as f64) / count as f64;
                let (sa, ca) = azimuth.sin_cos();
                let d = n * cos + (u * ca + w * sa) * sin;
                match first_hit(k, x, d, targets, (bvh, &mut stack), tol) {
                    None => return Sight::Out,
                    Some(j) if d.dot(targets[j].poly.normal) < 0.0 && !hidden[j] => return Sight::Through(j),
                    Some(_) => {}
                }
            }
        }
    }
    Sight::Hidden
}

/// The first piece (other than `k`) that the ray from `x` along unit `d` hits beyond the tolerance: the nearest,
/// the lowest index among equally near ones; `None` if it leaves the scene. `stack` is the traversal's, reused.
fn first_hit(
    k: usize,
    x: DVec3,
    d: DVec3,
    targets: &[Target<'_>],
    (bvh, stack): (&Bvh, &mut Vec<usize>),
    tol: f64,
) -> Option<usize> {
    let mut best: Option<(f64, usize)> = None;
    bvh.visit(x, d, stack, |j| {
        let t = &targets[j];
        if j == k {
            return best.map(|b| b.0);
        }
        let to_center = t.poly.centroid - x;
        // Bounding sphere: the ray passes farther than the radius from the centroid.
        let along = to_center.dot(d);
        if along < -t.radius || (to_center - d * along).length() > t.radius + tol {
            return best.map(|b| b.0);
        }
        let denom = d.dot(t.poly.normal);
        if denom == 0.0 {
            return best.map(|b| b.0);
        }
        let dist = to_center.dot(t.poly.normal) / denom;
        let nearer = best.is_none_or(|(b, i)| dist < b || (dist == b && j < i));
        if dist > tol && nearer {
            let hit = x + d * dist;
            let v = &t.poly.vertices;
            if t.inward.iter().enumerate().all(|(e, m)| m.dot(hit - v[e]) >= -tol) {
                best = Some((dist, j));
            }
        }
        best.map(|b| b.0)
    });
    best.map(|(_, j)| j)
}

/// Pieces per leaf of [`Bvh`].
const LEAF_PIECES: usize = 4;

/// A bounding-volume hierarchy over pieces' boxes (grown by a margin), for first hits.
struct Bvh {
    /// Nodes; node 0 is the root.
    nodes: Vec<BvhNode>,
    /// Piece indices; a leaf covers `order[first..first + count]`.
    order: Vec<usize>,
}

/// One node of [`Bvh`]: its box, and its two children (`count == 0`) or its pieces.
struct BvhNode {
    lo: DVec3,
    hi: DVec3,
    /// The first child (the second is `first + 1`) or the first piece in `order`.
    first: usize,
    /// Pieces of a leaf; 0 for an inner node.
    count: usize,
}

impl Bvh {
    /// The hierarchy over `pieces`' bounding boxes grown by `margin` (median splits along the longest axis of the
    /// centroids).
    fn new(pieces: &[Polygon], margin: f64) -> Bvh {
        let boxes: Vec<(DVec3, DVec3)> = pieces
            .iter()
            .map(|p| {
                let (lo, hi) = crate::scene::bounding_box(p.vertices.iter().copied());
                (lo - DVec3::splat(margin), hi + DVec3::splat(margin))
            })
            .collect();
        let mut bvh = Bvh { nodes: Vec::new(), order: (0..pieces.len()).collect() };
        bvh.nodes.push(BvhNode { lo: DVec3::ZERO, hi: DVec3::ZERO, first: 0, count: 0 });
        let mut stack = vec![(0usize, 0usize, pieces.len())];
        while let Some((node, first, end)) = stack.pop() {
            let slice = &mut bvh.order[first..end];
            let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            let (mut clo, mut chi) = (lo, hi);
            for &i in slice.iter() {
                lo = lo.min(boxes[i].0);
                hi = hi.max(boxes[i].1);
                let c = 0.5 * (boxes[i].0 + boxes[i].1);
                clo = clo.min(c);
                chi = chi.max(c);
            }
            let extent = chi - clo;
            if end - first <= LEAF_PIECES || extent.max_element() <= 0.0 {
                bvh.nodes[node] = BvhNode { lo, hi, first, count: end - first };
                continue;
            }
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let mid = slice.len() / 2;
            let centre = |i: usize| boxes[i].0[axis] + boxes[i].1[axis];
            slice.select_nth_unstable_by(mid, |&a, &b| centre(a).total_cmp(&centre(b)));
            let child = bvh.nodes.len();
            bvh.nodes[node] = BvhNode { lo, hi, first: child, count: 0 };
            for _ in 0..2 {
                bvh.nodes.push(BvhNode { lo: DVec3::ZERO, hi: DVec3::ZERO, first: 0, count: 0 });
            }
            stack.push((child, first, first + mid));
            stack.push((child + 1, first + mid, end));
        }
        bvh
    }

    /// Calls `f` with every piece whose box the ray from `x` along `d` (t >= 0) passes through (`stack` holds the
    /// nodes to visit; its contents are replaced), skipping boxes
    /// that it enters beyond the distance `f` last returned (the nearest hit so far; `None`: none yet). Every
    /// piece a ray hits within the margin of its polygon is visited unless a hit at most as near was found.
    fn visit(&self, x: DVec3, d: DVec3, stack: &mut Vec<usize>, mut f: impl FnMut(usize) -> Option<f64>) {
        if self.order.is_empty() {
            return;
        }
        let inv = DVec3::ONE / d;
        let mut limit = f64::INFINITY;
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            match entry(node, x, d, inv) {
                Some(t) if t <= limit => {}
                _ => continue,
            }
            if node.count > 0 {
                for &i in &self.order[node.first..node.first + node.count] {
                    if let Some(b) = f(i) {
                        limit = b;
                    }
                }
            } else {
                stack.push(node.first + 1);
                stack.push(node.first);
            }
        }
    }
}

/// Where the ray from `x` along `d` (`inv` its componentwise inverse) enters `node`'s box at `t >= 0`, or `None`
/// if it misses it. An axis along which the ray does not move is tested by the origin alone.
fn entry(node: &BvhNode, x: DVec3, d: DVec3, inv: DVec3) -> Option<f64> {
    let (mut near, mut far) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if x[a] < node.lo[a] || x[a] > node.hi[a] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((node.lo[a] - x[a]) * inv[a], (node.hi[a] - x[a]) * inv[a]);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    (near <= far).then_some(near)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The culling test as first written: every ray against every piece, every piece again in every round.
    fn culled_by_every_piece(pieces: &[Polygon], tol: f64) -> Vec<bool> {
        let targets: Vec<Target<'_>> = pieces
            .iter()
            .map(|poly| {
                let v = &poly.vertices;
                let inward = (0..v.len())
                    .map(|e| poly.normal.cross(v[(e + 1) % v.len()] - v[e]).normalize())
                    .collect();
                let radius = v.iter().map(|x| x.distance(poly.centroid)).fold(0.0, f64::max);
                Target { poly, inward, radius }
            })
            .collect();
        let sees = |k: usize, x: DVec3, d: DVec3, hidden: &[bool]| {
            let mut best: Option<(f64, usize)> = None;
            for (j, t) in targets.iter().enumerate() {
                let to_center = t.poly.centroid - x;
                let along = to_center.dot(d);
                if j == k || along < -t.radius || (to_center - d * along).length() > t.radius + tol {
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
            best.is_none_or(|(_, j)| d.dot(targets[j].poly.normal) < 0.0 && !hidden[j])
        };
        let mut hidden = vec![false; pieces.len()];
        loop {
            let mut changed = false;
            for k in 0..pieces.len() {
                let p = targets[k].poly;
                let (n, u) = (p.normal, p.normal.any_orthonormal_vector());
                let w = n.cross(u);
                let mut out = false;
                let points =
                    std::iter::once(p.centroid).chain(p.vertices.iter().map(|&v| 0.5 * (p.centroid + v)));
                'points: for x in points {
                    for (r, &(polar, count)) in RINGS.iter().enumerate() {
                        let (sin, cos) = polar.to_radians().sin_cos();
                        for i in 0..count {
                            let azimuth = std::f64::consts::TAU * (i as f64 + 0.5 * r as f64) / count as f64;
                            let (sa, ca) = azimuth.sin_cos();
                            if sees(k, x, n * cos + (u * ca + w * sa) * sin, &hidden) {
                                out = true;
                                break 'points;
                            }
                        }
                    }
                }
                if !hidden[k] && !out {
                    hidden[k] = true;
                    changed = true;
                }
            }
            if !changed {
                return hidden;
            }
        }
    }

    /// The triangles of the box `lo..hi`, normals outward (inward if `inward`).
    fn box_triangles(lo: DVec3, hi: DVec3, inward: bool) -> Vec<Polygon> {
        let c = |i: usize| DVec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2]);
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let mut out = Vec::new();
        for q in quads {
            let mut v: Vec<DVec3> = q.iter().map(|&i| c(i)).collect();
            if inward {
                v.reverse();
            }
            let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
            out.extend(Polygon::with_normal(vec![v[0], v[1], v[2]], n));
            out.extend(Polygon::with_normal(vec![v[0], v[2], v[3]], n));
        }
        out
    }

    /// Random boxes in a room, some inside others (their faces see only the inside of the outer one, and some
    /// only pieces culled in an earlier round): the hierarchy's first hits and the witness rounds cull exactly the
    /// pieces that testing every piece against every piece in every round culls.
    #[test]
    fn culling_matches_testing_every_piece_against_every_piece() {
        for seed in 0..4 {
            let mut rng = SplitMix64::new(seed);
            let mut pieces = box_triangles(DVec3::splat(-1.0), DVec3::splat(11.0), true);
            for _ in 0..12 {
                let lo = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * 8.0;
                let size = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * 1.5 + DVec3::splat(0.5);
                pieces.extend(box_triangles(lo, lo + size, false));
                // A box inside it, and one inside that.
                pieces.extend(box_triangles(lo + 0.2 * size, lo + 0.8 * size, false));
                pieces.extend(box_triangles(lo + 0.4 * size, lo + 0.6 * size, true));
            }
            let tol = 1e-9;
            let fast = culled(&pieces, tol);
            assert!(fast.iter().any(|&h| h) && !fast.iter().all(|&h| h), "seed {seed}");
            assert_eq!(fast, culled_by_every_piece(&pieces, tol), "seed {seed}");
        }
    }
}
