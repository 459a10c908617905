//! Shaft culling (Haines and Wallace, "Shaft culling for efficient ray-cast radiosity", Eurographics Workshop on
//! Rendering 1991): before occlusion rays are cast between two surfaces, the convex hull of the pair (which holds
//! every segment from a point of one to a point of the other) is tested against the scene's face polygons,
//! through the cluster tree's bounding spheres. When no polygon other than the two surfaces' own reaches into
//! the hull, nothing can block any ray between them: the pair is wholly visible, exactly, and no ray is cast.
//!
//! The hull of two convex planar polygons `P` and `Q` is bounded by the plane of `P` (where all of `Q` lies on
//! one side of it), that of `Q`, and planes through an edge of one polygon and a vertex of the other: a facet
//! meets each polygon in a face of it (a vertex, an edge, or the whole polygon), and a facet with points of
//! both that is neither polygon's plane holds an edge of one of them and a vertex of the other. Every candidate
//! is kept only if all points of both polygons lie on one side of it, so whatever the rounding, a kept plane
//! bounds the hull and the test stays conservative; a polygon is outside when all its vertices are on the far
//! side of one kept plane.

use glam::DVec3;

use super::tree::{Kind, Tree};
use crate::scene::bounding_box;

/// How far (relative to the scene's bounding radius) a vertex may lie inside a hull plane and still count as on
/// it: a polygon that only touches the hull (a face in the plane of one end, a neighbour sharing an edge with
/// it) meets no segment between interior points of the two ends, and a rounding error of the plane must not
/// make it an occluder.
const SLACK: f64 = 1e-9;

/// A hull's bounding planes `(n, d)` with `|n| = 1`: a point `x` is inside when `n . x <= d` for every plane.
struct Shaft {
    planes: Vec<(DVec3, f64)>,
    slack: f64,
}

impl Shaft {
    /// The hull of the convex planar polygons `p` (normal `np`) and `q` (normal `nq`), points within `slack` of
    /// a plane counting as on it.
    fn new(p: &[DVec3], np: DVec3, q: &[DVec3], nq: DVec3, slack: f64) -> Shaft {
        let mut shaft = Shaft { planes: Vec::with_capacity(2 * p.len() * q.len() + 2), slack };
        shaft.consider(np, p[0], p, q);
        shaft.consider(nq, q[0], p, q);
        for (from, to) in [(p, q), (q, p)] {
            for (k, &a) in from.iter().enumerate() {
                let edge = from[(k + 1) % from.len()] - a;
                for &v in to {
                    shaft.consider(edge.cross(v - a), a, p, q);
                }
            }
        }
        shaft
    }

    /// Keeps the plane through `origin` with normal `n` (any length) if every point of `p` and `q` lies on one
    /// side of it (within the slack), oriented so that they lie inside.
    fn consider(&mut self, n: DVec3, origin: DVec3, p: &[DVec3], q: &[DVec3]) {
        let length = n.length();
        if !(length > 0.0 && length.is_finite()) {
            return;
        }
        let d = n.dot(origin);
        match sides(n, d, p.iter().chain(q), self.slack * length) {
            (false, _) => self.planes.push((n / length, d / length)),
            (true, false) => self.planes.push((-n / length, -d / length)),
            (true, true) => {}
        }
    }

    /// Whether every vertex of a polygon lies outside one of the hull's planes or on it.
    fn outside(&self, vertices: &[DVec3]) -> bool {
        self.planes.iter().any(|&(n, d)| vertices.iter().all(|v| n.dot(*v) - d >= -self.slack))
    }
}

/// Whether some of `points` lie above the plane `n . x = d` by more than `slack` (`n . x - d > slack`), and
/// whether some lie below it by more than `slack`; it stops looking once both are found (most candidate planes
/// of a hull have points on both sides).
fn sides<'a>(n: DVec3, d: f64, points: impl Iterator<Item = &'a DVec3>, slack: f64) -> (bool, bool) {
    let (mut above, mut below) = (false, false);
    for x in points {
        let s = n.dot(*x) - d;
        above |= s > slack;
        below |= s < -slack;
        if above && below {
            break;
        }
    }
    (above, below)
}

/// Whether every one of `points` lies on one side of the plane through `origin` with unit normal `normal`, or on
/// it (within `slack`): then a polygon in that plane meets the hull of the points at most on its boundary (the
/// hull's own planes miss a polygon that passes by one of its edges, and this test is cheaper).
fn separated<'a>(normal: DVec3, origin: DVec3, points: impl Iterator<Item = &'a DVec3>, slack: f64) -> bool {
    let (above, below) = sides(normal, normal.dot(origin), points, slack);
    !(above && below)
}

/// Whether no face polygon of the tree other than those that surfaces `a` and `b` were cut from reaches into the
/// convex hull of the two, so that nothing between them blocks any ray: they see each other wholly. Conservative:
/// `false` says only that something may be in the way. The occluders are the tree's face polygons, so rays must be
/// cast at a caster holding no others.
///
/// The tree's clusters and polygons are first tested against the pair's bounding box (which holds the hull; one
/// that only touches it, within the slack, meets no segment between interior points); a polygon whose box reaches
/// into it is tested by its own plane, and only if that does not separate it, by the hull's planes (made once).
pub(super) fn clear(tree: &Tree, a: u32, b: u32) -> bool {
    /// Deeper than any median-split cluster tree (its depth is about the logarithm of the polygon count).
    const STACK: usize = 64;
    let (na, nb) = (&tree.nodes[a as usize], &tree.nodes[b as usize]);
    let (Some(ea), Some(eb)) = (na.element(), nb.element()) else { return false };
    let (pa, pb) = (ea.patch(), eb.patch());
    let slack = SLACK * tree.nodes[0].radius;
    let (lo, hi) = bounding_box(pa.vertices.iter().chain(&pb.vertices).copied());
    let (lo, hi) = (lo + DVec3::splat(slack), hi - DVec3::splat(slack));
    if !lo.cmplt(hi).all() {
        // Flat within the slack: the two are (nearly) coplanar and exchange (almost) nothing; let rays decide.
        return false;
    }
    let reaches = |n: u32| {
        let (l, h) = tree.boxes[n as usize];
        l.cmplt(hi).all() && h.cmpgt(lo).all()
    };
    let mut shaft: Option<Shaft> = None;
    let mut stack = [0u32; STACK];
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let n = stack[top];
        if !reaches(n) {
            continue;
        }
        let node = &tree.nodes[n as usize];
        match &node.kind {
            Kind::Cluster { .. } => {
                if top + node.children.len() > STACK {
                    return false;
                }
                for &c in &node.children {
                    stack[top] = c;
                    top += 1;
                }
            }
            // A face polygon (the cluster tree's leaves; its subdivisions are not visited).
            Kind::Surface { element, .. } => {
                if node.root == na.root || node.root == nb.root {
                    continue;
                }
                let polygon = element.patch();
                if separated(
                    polygon.normal,
                    polygon.vertices[0],
                    pa.vertices.iter().chain(&pb.vertices),
                    slack,
                ) {
                    continue;
                }
                let shaft = shaft.get_or_insert_with(|| {
                    Shaft::new(&pa.vertices, pa.normal, &pb.vertices, pb.normal, slack)
                });
                if shaft.planes.is_empty() || !shaft.outside(&polygon.vertices) {
                    return false;
                }
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::testing::cornell_polygons;

    /// A unit square in the plane `z = h` with its normal.
    fn square(x: f64, y: f64, h: f64, size: f64, up: bool) -> (Vec<DVec3>, DVec3) {
        let v = vec![
            DVec3::new(x, y, h),
            DVec3::new(x + size, y, h),
            DVec3::new(x + size, y + size, h),
            DVec3::new(x, y + size, h),
        ];
        let n = if up { DVec3::Z } else { -DVec3::Z };
        if up {
            (v, n)
        } else {
            (v.into_iter().rev().collect(), n)
        }
    }

    #[test]
    fn the_hull_of_two_facing_squares_is_their_box() {
        let (p, np) = square(0.0, 0.0, 0.0, 1.0, true);
        let (q, nq) = square(0.0, 0.0, 1.0, 1.0, false);
        let shaft = Shaft::new(&p, np, &q, nq, 1e-12);
        let inside = |x: DVec3| shaft.planes.iter().all(|&(n, d)| n.dot(x) - d <= 1e-12);
        let misses =
            |v: &[DVec3], n: DVec3| shaft.outside(v) || separated(n, v[0], p.iter().chain(&q), 1e-12);
        assert!(inside(DVec3::new(0.5, 0.5, 0.5)));
        assert!(inside(DVec3::new(0.0, 1.0, 0.3)), "a point on a side face");
        for outside in [
            DVec3::new(1.01, 0.5, 0.5),
            DVec3::new(0.5, -0.01, 0.5),
            DVec3::new(0.5, 0.5, 1.01),
            DVec3::new(0.5, 0.5, -0.01),
        ] {
            assert!(!inside(outside), "{outside} is outside the box");
        }
        // A small square in the middle blocks; one beside the box, or one in a side plane, does not.
        let (middle, up) = square(0.4, 0.4, 0.5, 0.2, true);
        assert!(!misses(&middle, up));
        assert!(misses(&square(1.1, 0.4, 0.5, 0.2, true).0, up));
        let side = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(1.0, 1.0, 0.0), DVec3::new(1.0, 1.0, 1.0)];
        assert!(misses(&side, DVec3::X));
        // A polygon crossing the box though none of its vertices is inside.
        let crossing = [DVec3::new(-1.0, 0.5, 0.5), DVec3::new(2.0, 0.5, 0.5), DVec3::new(0.5, 2.0, 0.5)];
        assert!(!misses(&crossing, DVec3::Z));
        // One passing by the vertical edge at x = y = 1, outside the box: no plane of the box has all its vertices
        // outside, its own plane has all of the box on one side.
        let by_the_edge =
            [DVec3::new(1.5, 0.55, 0.5), DVec3::new(0.55, 1.5, 0.5), DVec3::new(1.0, 1.05, 0.9)];
        let normal = (by_the_edge[1] - by_the_edge[0]).cross(by_the_edge[2] - by_the_edge[0]).normalize();
        assert!(misses(&by_the_edge, normal));
        assert!(!shaft.outside(&by_the_edge));
        // Moved to pass through the edge, it blocks.
        let through = by_the_edge.map(|v| v - DVec3::new(0.05, 0.05, 0.0));
        assert!(!misses(&through, normal));
    }

    #[test]
    fn the_hull_of_two_offset_squares_is_slanted() {
        // A floor square and a ceiling square shifted by 2: the hull is a slanted prism, and a point below the
        // ceiling square but not between the two is outside it.
        let (p, np) = square(0.0, 0.0, 0.0, 1.0, true);
        let (q, nq) = square(2.0, 0.0, 1.0, 1.0, false);
        let shaft = Shaft::new(&p, np, &q, nq, 1e-12);
        let inside = |x: DVec3| shaft.planes.iter().all(|&(n, d)| n.dot(x) - d <= 1e-12);
        assert!(inside(DVec3::new(1.5, 0.5, 0.5)));
        assert!(!inside(DVec3::new(2.5, 0.5, 0.1)));
        assert!(!inside(DVec3::new(0.5, 0.5, 0.9)));
        assert!(inside(DVec3::new(0.5, 0.5, 0.0)));
    }

    /// On the Cornell box, a shaft found clear lets every ray between the two surfaces through (16 random point
    /// pairs on each of thousands of such pairs), and both kinds occur: pairs with a block between them and pairs
    /// without. Rays that leave or reach a surface at a grazing angle (a cosine under 0.01, where the kernel and
    /// so the ray's weight in a visible fraction vanish) are left out: in single precision such a ray can clip
    /// the face polygon it starts or ends on.
    #[test]
    fn a_clear_shaft_on_the_cornell_box_has_nothing_in_the_way() {
        use crate::formfactor::occluder_scene;
        use crate::raycast::Ray;
        use crate::rgb::Rgb;
        use crate::rng::SplitMix64;
        let (roots, lighting, rules) = cornell_polygons();
        let mut tree = Tree::new(&rules, &roots, &lighting.rho, &vec![Rgb::ZERO; roots.len()]);
        let caster = occluder_scene(&roots, true).unwrap();
        // Split every face polygon twice so that pairs of pieces of the same walls and of the blocks occur.
        let faces: Vec<u32> = (0..tree.nodes.len() as u32).filter(|&n| !tree.is_cluster(n)).collect();
        for &f in &faces {
            tree.split(&rules, f).unwrap();
            for c in tree.nodes[f as usize].children.clone() {
                tree.split(&rules, c).unwrap();
            }
        }
        let leaves: Vec<u32> =
            (0..tree.nodes.len() as u32).filter(|&n| tree.nodes[n as usize].children.is_empty()).collect();
        let mut rng = SplitMix64::for_stream(7, 0, 0);
        let (mut clear_pairs, mut blocked_pairs) = (0, 0);
        for (i, &a) in leaves.iter().enumerate() {
            for &b in &leaves[i + 1..] {
                if tree.behind(a, b)
                    || tree.behind(b, a)
                    || tree.nodes[a as usize].root == tree.nodes[b as usize].root
                {
                    continue;
                }
                if !clear(&tree, a, b) {
                    blocked_pairs += 1;
                    continue;
                }
                clear_pairs += 1;
                let rays: Vec<Ray> = (0..16)
                    .filter_map(|_| {
                        let (x, nx) = tree.sample(a, &mut rng);
                        let (y, ny) = tree.sample(b, &mut rng);
                        let d = (y - x).normalize();
                        (nx.dot(d).abs().min(ny.dot(d).abs()) >= 0.01)
                            .then(|| Ray::segment(x.as_vec3(), y.as_vec3(), caster.offset()))
                    })
                    .collect();
                let mut occluded = vec![false; rays.len()];
                caster.occluded_many(&rays, &mut occluded);
                assert!(!occluded.contains(&true), "a ray between {a} and {b} is blocked in a clear shaft");
            }
        }
        assert!(clear_pairs > 1000 && blocked_pairs > 1000, "{clear_pairs} clear, {blocked_pairs} not");
    }
}
