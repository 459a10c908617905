//! Mesh repair: faces cut where other faces meet them, and the pieces no point of the scene can see culled, so
//! that no patch averages lit and hidden area (a floor patch half under a block, a wall half inside another).
//!
//! # Method
//! 1. **Meetings** (`cut`). For every pair of face polygons of different faces whose bounding boxes meet (a sweep
//!    along x), the part of one that lies in the other's plane is found: an edge of it lying there with the rest
//!    on one side (a *contact*: a block standing on the floor, a wall ending on another, a T-junction where a
//!    face's edge ends inside another face), or the chord where it passes through the plane (a *crossing*:
//!    interpenetrating solids). Clipped to the other polygon, it is a meeting segment when it runs through that
//!    polygon's interior; segments along a polygon's own edges (faces that share an edge, a wall standing on the
//!    floor's border) are no cut. Coplanar polygons are never cut: the loader rejects coplanar overlaps, and
//!    coplanar neighbours (a light in a ceiling, faces that meet at a T-vertex on a shared edge) share area only
//!    along edges, which constant elements do not need to match vertex by vertex.
//! 2. **Cuts** (`cut`). Each polygon with meeting segments is cut by their lines (each line across the whole
//!    piece it crosses, so every piece stays convex): pieces are exact, their vertices points of the polygon's
//!    edges or of the lines, in its plane, their areas summing to the polygon's to rounding.
//! 3. **Culling** (`cull`). Pieces whose front side sees only back sides of faces (or culled pieces) are removed:
//!    the floor inside a block's footprint, a face's part inside another solid. Exact for resting and
//!    interpenetrating objects; see `cull` for the test and when it could be wrong.
//! 4. **Merging** (`cut`). Neighbouring kept pieces of a polygon are merged back while their union is convex and
//!    the edge between them is no meeting segment, so a line's extension beyond its segment does not leave
//!    needless slivers; contact and intersection lines stay piece boundaries.
//!
//! Faces that nothing meets keep their polygons exactly as loaded. Pieces stay pieces of their OBJ face
//! (`Patch::face` is still the face index), so per-face results add up over them; a face can have several
//! polygons after repair, as a non-planar face split into triangles does.
//!
//! # Tolerance
//! All tests use one length, [`REPAIR_TOLERANCE`] times the scene size (the diagonal of its bounding box): a vertex
//! within it of a plane lies in the plane, a point within it of a line or an edge lies on it, a segment shorter
//! than it is a point. Relative to the scene rather than to each face, because faces that meet may differ in size
//! by orders of magnitude and their coordinates are rounded alike. At `1e-6` it accepts coordinates written with six
//! or more significant digits (as [`crate::scene::PLANAR_TOLERANCE`] does per face) and is still millions of times
//! the f64 rounding of the computed points (a few `eps` of the coordinates).
//!
//! # Report
//! [`RepairReport`] lists every face that changed: the faces that meet it (by index and OBJ line, contact or
//! crossing), its pieces, and the area culled; [`RepairReport::notes`] words it per face for the command line.

mod cull;
mod cut;

use std::collections::BTreeSet;
use std::path::Path;

use glam::DVec3;

use crate::scene::{bounding_box, Polygon, Scene, SceneWarning};

pub use cull::DIRECTIONS as CULL_DIRECTIONS;
pub use cut::Meeting;

use cut::{meeting, merge, split, Line, Segment, STRAIGHT};

/// The repair tolerance relative to the scene size (the diagonal of its bounding box); see the module docs.
pub const REPAIR_TOLERANCE: f64 = 1e-6;

/// A scene's face polygons after repair, and what was changed.
#[derive(Clone, Debug, PartialEq)]
pub struct Repaired {
    /// Per face (indexed like [`Scene::faces`]): its planar convex polygons after repair; the face's own
    /// polygons when nothing met it, none when all of it was culled.
    pub polygons: Vec<Vec<Polygon>>,
    /// What was changed.
    pub report: RepairReport,
}

/// What repair changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RepairReport {
    /// The tolerance used, in scene units ([`REPAIR_TOLERANCE`] times the scene size).
    pub tolerance: f64,
    /// Every face that was cut or culled, in face order.
    pub faces: Vec<FaceRepair>,
}

/// How repair changed one face.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceRepair {
    /// Face index in OBJ order.
    pub face: usize,
    /// Line of the face's `f` statement.
    pub line: usize,
    /// The faces that meet this one inside it: (face index, its OBJ line, how), sorted.
    pub met_by: Vec<(usize, usize, Meeting)>,
    /// Distinct cut lines.
    pub lines: usize,
    /// Area of the face as loaded.
    pub area: f64,
    /// Area culled (the sum of the culled pieces' areas).
    pub culled_area: f64,
    /// Pieces culled.
    pub culled_pieces: usize,
    /// Polygons the face has after repair.
    pub polygons: usize,
}

impl RepairReport {
    /// Total area culled.
    #[must_use]
    pub fn culled_area(&self) -> f64 {
        self.faces.iter().map(|f| f.culled_area).sum()
    }

    /// One note per changed face, naming the face and the faces that meet it by OBJ line (by index alone for a
    /// glTF scene), for `file` (the scene's file).
    #[must_use]
    pub fn notes(&self, file: &Path) -> Vec<SceneWarning> {
        self.faces
            .iter()
            .map(|f| {
                let names =
                    |kind: Meeting| {
                        let list: Vec<String> =
                            f.met_by
                                .iter()
                                .filter(|m| m.2 == kind)
                                // A glTF face has no line (0): its index names it.
                                .map(|&(face, line, _)| {
                                    if line > 0 {
                                        format!("{face} (line {line})")
                                    } else {
                                        face.to_string()
                                    }
                                })
                                .collect();
                        list.join(", ")
                    };
                let mut parts = Vec::new();
                let contacts = names(Meeting::Contact);
                if !contacts.is_empty() {
                    parts.push(format!("touched by faces {contacts}"));
                }
                let crossings = names(Meeting::Crossing);
                if !crossings.is_empty() {
                    parts.push(format!("crossed by faces {crossings}"));
                }
                let mut message = format!(
                    "repaired: {}; cut along {} line{} into {} piece{}",
                    parts.join("; "),
                    f.lines,
                    if f.lines == 1 { "" } else { "s" },
                    f.polygons,
                    if f.polygons == 1 { "" } else { "s" },
                );
                if f.culled_pieces > 0 {
                    message += &format!(
                        "; culled {} piece{} no point of the scene can see (area {:.6e} of {:.6e}, {:.3}%)",
                        f.culled_pieces,
                        if f.culled_pieces == 1 { "" } else { "s" },
                        f.culled_area,
                        f.area,
                        100.0 * f.culled_area / f.area
                    );
                }
                let line = (f.line > 0).then_some(f.line);
                SceneWarning { file: file.to_path_buf(), line, face: Some(f.face), message }
            })
            .collect()
    }
}

/// One face polygon during repair.
struct Item<'a> {
    face: usize,
    poly: &'a Polygon,
    min: DVec3,
    max: DVec3,
}

/// The cut lines of one polygon: each line with the meeting segments on it.
#[derive(Default)]
struct Cuts {
    lines: Vec<(Line, Vec<Segment>)>,
    met_by: BTreeSet<(usize, Meeting)>,
}

/// Repairs `scene`'s faces (see the module docs).
#[must_use]
pub fn repair(scene: &Scene) -> Repaired {
    let items: Vec<Item<'_>> = scene
        .faces
        .iter()
        .flat_map(|f| f.polygons.iter().map(move |p| (f.index, p)))
        .map(|(face, poly)| {
            let (min, max) = bounding_box(poly.vertices.iter().copied());
            Item { face, poly, min, max }
        })
        .collect();
    let lo = items.iter().fold(DVec3::splat(f64::INFINITY), |m, i| m.min(i.min));
    let hi = items.iter().fold(DVec3::splat(f64::NEG_INFINITY), |m, i| m.max(i.max));
    let tol = REPAIR_TOLERANCE * (hi - lo).length();

    // 1. Meetings: a sweep along x over bounding boxes grown by the tolerance.
    let mut cuts: Vec<Cuts> = items.iter().map(|_| Cuts::default()).collect();
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|&a, &b| items[a].min.x.total_cmp(&items[b].min.x));
    for (k, &a) in order.iter().enumerate() {
        for &b in &order[k + 1..] {
            if items[b].min.x > items[a].max.x + tol {
                break;
            }
            let (ia, ib) = (&items[a], &items[b]);
            if ia.face == ib.face
                || (ia.min - ib.max).max_element() > tol
                || (ib.min - ia.max).max_element() > tol
            {
                continue;
            }
            for (p, q) in [(a, b), (b, a)] {
                if let Some((segment, kind)) = meeting(items[p].poly, items[q].poly, tol) {
                    let c = &mut cuts[p];
                    c.met_by.insert((items[q].face, kind));
                    let n = items[p].poly.normal;
                    match c.lines.iter_mut().find(|(l, _)| l.contains(&segment, tol)) {
                        Some((_, segments)) => segments.push(segment),
                        None => c.lines.push((Line::through(&segment, n), vec![segment])),
                    }
                }
            }
        }
    }

    // 2. Cuts: every polygon cut by its lines into convex pieces.
    let mut pieces: Vec<Polygon> = Vec::new();
    let mut owner: Vec<usize> = Vec::new();
    for (k, item) in items.iter().enumerate() {
        let mut cells = vec![item.poly.vertices.clone()];
        for (line, _) in &cuts[k].lines {
            let mut next = Vec::with_capacity(cells.len() + 1);
            for cell in cells {
                match split(&cell, line, tol) {
                    Some((a, b)) => next.extend([a, b]),
                    None => next.push(cell),
                }
            }
            cells = next;
        }
        if cuts[k].lines.is_empty() {
            pieces.push(item.poly.clone());
            owner.push(k);
            continue;
        }
        for cell in cells {
            // A cell of zero area (lines within rounding of each other) is no piece.
            if let Some(p) = Polygon::with_normal(cell, item.poly.normal) {
                pieces.push(p);
                owner.push(k);
            }
        }
    }

    // 3. Culling.
    let hidden = cull::culled(&pieces, tol);

    // 4. Merging, per polygon, and the report per face.
    let straight = STRAIGHT * (hi - lo).length();
    let mut polygons: Vec<Vec<Polygon>> = vec![Vec::new(); scene.faces.len()];
    let mut changed: Vec<Option<FaceRepair>> = vec![None; scene.faces.len()];
    // Pieces were made polygon by polygon, so each polygon's are one run of `pieces`.
    let mut runs = vec![0usize; items.len() + 1];
    for &k in &owner {
        runs[k + 1] += 1;
    }
    for k in 0..items.len() {
        runs[k + 1] += runs[k];
    }
    for (k, item) in items.iter().enumerate() {
        let mine = runs[k]..runs[k + 1];
        let kept: Vec<&Polygon> = mine.clone().filter(|&i| !hidden[i]).map(|i| &pieces[i]).collect();
        let culled: Vec<&Polygon> = mine.filter(|&i| hidden[i]).map(|i| &pieces[i]).collect();
        let out = &mut polygons[item.face];
        if cuts[k].lines.is_empty() && culled.is_empty() {
            out.push(item.poly.clone());
            continue;
        }
        let segments: Vec<Segment> = cuts[k].lines.iter().flat_map(|(_, s)| s.iter().copied()).collect();
        let n = item.poly.normal;
        let cells = merge_all(
            kept.iter().map(|p| p.vertices.clone()).collect(),
            |a, b| merge(a, b, n, tol, straight, &segments, &item.poly.vertices),
            tol,
        );
        let before = out.len();
        out.extend(cells.into_iter().filter_map(|c| Polygon::with_normal(c, n)));
        let face = &scene.faces[item.face];
        let entry = changed[item.face].get_or_insert_with(|| FaceRepair {
            face: face.index,
            line: face.line,
            met_by: Vec::new(),
            lines: 0,
            area: face.area,
            culled_area: 0.0,
            culled_pieces: 0,
            polygons: 0,
        });
        for &(other, kind) in &cuts[k].met_by {
            let m = (other, scene.faces[other].line, kind);
            if !entry.met_by.contains(&m) {
                entry.met_by.push(m);
            }
        }
        entry.met_by.sort_unstable();
        entry.lines += cuts[k].lines.len();
        entry.culled_area += culled.iter().map(|p| p.area).sum::<f64>();
        entry.culled_pieces += culled.len();
        entry.polygons += out.len() - before;
    }
    for (f, entry) in changed.iter_mut().enumerate() {
        if let Some(e) = entry {
            e.polygons = polygons[f].len();
        }
    }
    Repaired {
        polygons,
        report: RepairReport { tolerance: tol, faces: changed.into_iter().flatten().collect() },
    }
}

/// Merges neighbouring `cells` of one polygon: while some pair merges (`merge(a, b)`, `a` the one earlier in the
/// list), the first such pair in list order (by the earlier cell's place, then the later one's) is replaced by its
/// union at the earlier place, and the last cell moves into the later place. Cells whose boxes are farther apart
/// than `tol` share no edge and are never tried, and the pairs that merge are kept in a set updated only where the
/// last merge changed a cell or moved one, so a polygon cut into thousands of cells (a floor that many objects
/// stand on) is merged in about `cells^2` box tests instead of `cells^3` merge attempts, with the same result as
/// trying every pair again after each merge.
fn merge_all(
    mut cells: Vec<Vec<DVec3>>,
    merge: impl Fn(&[DVec3], &[DVec3]) -> Option<Vec<DVec3>>,
    tol: f64,
) -> Vec<Vec<DVec3>> {
    let grown = |c: &[DVec3]| {
        let (lo, hi) = bounding_box(c.iter().copied());
        (lo - DVec3::splat(tol), hi + DVec3::splat(tol))
    };
    let mut boxes: Vec<(DVec3, DVec3)> = cells.iter().map(|c| grown(c)).collect();
    let near = |a: &(DVec3, DVec3), b: &(DVec3, DVec3)| a.0.cmple(b.1).all() && b.0.cmple(a.1).all();
    // Mergeable pairs (earlier, later) and, per cell, the cells it is paired with there.
    let mut pairs: BTreeSet<(usize, usize)> = BTreeSet::new();
    let mut partners: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); cells.len()];
    for i in 0..cells.len() {
        for j in i + 1..cells.len() {
            if near(&boxes[i], &boxes[j]) && merge(&cells[i], &cells[j]).is_some() {
                pairs.insert((i, j));
                partners[i].insert(j);
                partners[j].insert(i);
            }
        }
    }
    while let Some(&(i, j)) = pairs.iter().next() {
        // The set holds only pairs that merged when tested, and `merge` depends on the two cells alone.
        let Some(union) = merge(&cells[i], &cells[j]) else {
            pairs.remove(&(i, j));
            continue;
        };
        let last = cells.len() - 1;
        for p in [i, j, last] {
            for q in std::mem::take(&mut partners[p]) {
                pairs.remove(&(p.min(q), p.max(q)));
                partners[q].remove(&p);
            }
        }
        boxes[i] = grown(&union);
        cells[i] = union;
        cells.swap_remove(j);
        boxes.swap_remove(j);
        partners.swap_remove(j);
        let changed: &[usize] = if j < cells.len() { &[i, j] } else { &[i] };
        for &p in changed {
            for q in 0..cells.len() {
                if q == p || !near(&boxes[p], &boxes[q]) {
                    continue;
                }
                let (a, b) = (p.min(q), p.max(q));
                if merge(&cells[a], &cells[b]).is_some() {
                    pairs.insert((a, b));
                    partners[a].insert(b);
                    partners[b].insert(a);
                }
            }
        }
    }
    cells
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The merge loop as first written: after every merge, every pair is tried again from the start.
    fn merge_every_pair(
        mut cells: Vec<Vec<DVec3>>,
        merge: impl Fn(&[DVec3], &[DVec3]) -> Option<Vec<DVec3>>,
    ) -> Vec<Vec<DVec3>> {
        'merging: loop {
            for i in 0..cells.len() {
                for j in i + 1..cells.len() {
                    if let Some(u) = merge(&cells[i], &cells[j]) {
                        cells[i] = u;
                        cells.swap_remove(j);
                        continue 'merging;
                    }
                }
            }
            return cells;
        }
    }

    /// A unit square cut by random lines, some of whose stretches are meeting segments (kept as edges): the
    /// merging gives the same cells, vertex for vertex, as trying every pair after each merge.
    #[test]
    fn merging_cells_matches_trying_every_pair_after_each_merge() {
        let n = DVec3::Z;
        let square = vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        let tol = 1e-9;
        for seed in 0..20 {
            let mut rng = SplitMix64::new(seed);
            let mut point = || DVec3::new(rng.unit(), rng.unit(), 0.0);
            let mut cells = vec![square.clone()];
            let mut segments = Vec::new();
            for k in 0..12 {
                let segment = Segment { a: point(), b: point() };
                let line = Line::through(&segment, n);
                let mut next = Vec::new();
                for cell in cells {
                    match split(&cell, &line, tol) {
                        Some((a, b)) => next.extend([a, b]),
                        None => next.push(cell),
                    }
                }
                cells = next;
                if k % 3 == 0 {
                    segments.push(segment);
                }
            }
            let merge = |a: &[DVec3], b: &[DVec3]| merge(a, b, n, tol, 1e-9, &segments, &square);
            let fast = merge_all(cells.clone(), merge, tol);
            assert!(fast.len() < cells.len(), "seed {seed}: nothing merged out of {} cells", cells.len());
            assert_eq!(fast, merge_every_pair(cells, merge), "seed {seed}");
        }
    }
}
