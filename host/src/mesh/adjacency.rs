//! How patches meet: neighbours within a face that share a stretch of edge (what the radiosity gradient
//! compares), and contact edges where another face's edge lies in a patch's plane.

use glam::DVec3;

use crate::patch::Patch;

/// For each patch, the patches of the same face that share a stretch of edge of positive length with it (a
/// T-junction counts), sorted by index.
///
/// Two edges are shared when they are collinear and their overlap is longer than `1e-9` times the larger of the
/// two patches' sizes (the same relative tolerance the scene loader uses for coincident vertices).
#[must_use]
pub fn adjacency(patches: &[Patch]) -> Vec<Vec<usize>> {
    let mut out = vec![Vec::new(); patches.len()];
    let boxes: Vec<(DVec3, DVec3, f64)> = patches
        .iter()
        .map(|p| {
            let (lo, hi) = crate::scene::bounding_box(p.vertices.iter().copied());
            (lo, hi, (hi - lo).length())
        })
        .collect();
    // Sweep along x within each face: sort by (face, min x).
    let mut order: Vec<usize> = (0..patches.len()).collect();
    order.sort_by(|&a, &b| patches[a].face.cmp(&patches[b].face).then(boxes[a].0.x.total_cmp(&boxes[b].0.x)));
    for (k, &a) in order.iter().enumerate() {
        for &b in &order[k + 1..] {
            if patches[b].face != patches[a].face {
                break;
            }
            let tol = crate::scene::DEGENERATE_TOLERANCE * boxes[a].2.max(boxes[b].2);
            if boxes[b].0.x > boxes[a].1.x + tol {
                break;
            }
            if (boxes[a].0 - boxes[b].1).max_element() > tol || (boxes[b].0 - boxes[a].1).max_element() > tol
            {
                continue;
            }
            if share_edge(&patches[a].vertices, &patches[b].vertices, tol) {
                out[a].push(b);
                out[b].push(a);
            }
        }
    }
    for n in &mut out {
        n.sort_unstable();
    }
    out
}

fn share_edge(a: &[DVec3], b: &[DVec3], tol: f64) -> bool {
    let edges = |v: &[DVec3]| (0..v.len()).map(|i| (v[i], v[(i + 1) % v.len()])).collect::<Vec<_>>();
    let eb = edges(b);
    edges(a).into_iter().any(|(p0, p1)| {
        let len = p0.distance(p1);
        if len <= tol {
            return false;
        }
        let u = (p1 - p0) / len;
        eb.iter().any(|&(q0, q1)| {
            let off = |q: DVec3| (q - p0 - u * (q - p0).dot(u)).length();
            if off(q0) > tol || off(q1) > tol {
                return false;
            }
            let (t0, t1) = ((q0 - p0).dot(u), (q1 - p0).dot(u));
            let overlap = t0.max(t1).min(len) - t0.min(t1).max(0.0);
            overlap > tol
        })
    })
}

/// Whether patch `other` (of another, non-parallel plane) has an edge lying in `patch`'s plane that crosses
/// `patch`: a contact edge. Tolerances are `1e-6` of the larger patch's size.
pub(super) fn touches(patch: &Patch, other: &Patch) -> bool {
    if patch.face == other.face || patch.normal.dot(other.normal).abs() > 1.0 - 1e-9 {
        return false;
    }
    let size = |p: &Patch| p.vertices.iter().map(|v| v.distance(p.centroid)).fold(0.0, f64::max);
    let tol = 1e-6 * size(patch).max(size(other));
    let height = |v: DVec3| patch.normal.dot(v - patch.centroid);
    let m = other.vertices.len();
    (0..m).any(|k| {
        let (a, b) = (other.vertices[k], other.vertices[(k + 1) % m]);
        if height(a).abs() > tol || height(b).abs() > tol {
            return false;
        }
        // Clip the segment a-b to the convex polygon (Cyrus-Beck): keep the part inside every edge's half-plane.
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        let v = &patch.vertices;
        for e in 0..v.len() {
            let (p, q) = (v[e], v[(e + 1) % v.len()]);
            let inward = patch.normal.cross(q - p);
            let (fa, fb) = (inward.dot(a - p), inward.dot(b - p));
            let scale = inward.length();
            let (fa, fb) = (fa / scale, fb / scale);
            if fa < -tol && fb < -tol {
                return false;
            }
            if (fa < -tol) != (fb < -tol) {
                let t = fa / (fa - fb);
                if fa < -tol {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
            }
        }
        (t1 - t0) * a.distance(b) > tol
    })
}
