//! Meshing: a [`Scene`]'s faces turned into [`Patch`]es, plus the adjacency and refinement steps that adaptive
//! meshing builds on.
//!
//! # Patches and faces
//! Every patch keeps its parent face (`Patch::face`, the OBJ face index) and material, so results map back to
//! OBJ faces. Patches come out in face order: all patches of face 0, then of face 1, and so on.
//!
//! - **`--no-subdivide`** ([`MeshOptions::no_subdivide`]): one patch per planar face, so patch `k` is OBJ face `k`
//!   as long as no earlier face was split. A face the loader split into triangles for being non-planar (see
//!   [`crate::scene`]) gives one patch per triangle, all with the same `face`, in fan order; the patches after it
//!   shift by the number of extra triangles. Map patches to faces with `Patch::face`, never by position. (The
//!   shipped Cornell box puts its non-planar red wall last, so there patch `k` is face `k` for every other face.)
//! - **Uniform subdivision** ([`mesh`] with `subdivide: true`): each planar convex polygon of a face is cut into
//!   convex pieces whose edges are all at most `max_patch_edge`:
//!   - a polygon whose edges already fit stays one patch;
//!   - a triangle is cut into `k^2` triangles similar to it (regular subdivision),
//!     `k = ceil(longest edge / max_patch_edge)`, so every piece is as well-shaped as the triangle; or, when
//!     that gives fewer patches, into three quadrilaterals around its centroid (as for polygons with five or more
//!     vertices, below) that are then gridded. The regular subdivision is driven by the longest edge alone, so
//!     for a right or obtuse triangle (like the halves of the Cornell box's split red wall) the quadrilaterals
//!     need about half as many patches;
//!   - a quadrilateral is cut into an `nu x nv` grid of its bilinear parametrisation,
//!     `nu = ceil(max(|e0|, |e2|) / max_patch_edge)` and `nv` likewise for `e1`, `e3`. A grid line joins two
//!     points on opposite edges, so it is a straight chord and each cell (the intersection of two strips between
//!     chords of a convex polygon) is convex; a grid line's length interpolates linearly between the two opposite
//!     edges, so each cell edge is at most `max(|e0|, |e2|) / nu <= max_patch_edge`;
//!   - a polygon with five or more vertices is first cut into quadrilaterals (centroid, midpoint of the edge
//!     before vertex `i`, vertex `i`, midpoint of the edge after it), which are convex because the centroid lies
//!     inside the polygon, then each quadrilateral as above. (Should rounding ever make one non-convex, it is
//!     cut into two triangles instead.)
//! - **Patch budget:** if uniform subdivision at `max_patch_edge` would give more patches than `patch_budget`, the
//!   edge limit is raised (bisection on its logarithm) to the smallest value whose mesh fits; [`Mesh::max_patch_edge`]
//!   says which limit was used. If even one patch per polygon does not fit, meshing fails with
//!   [`MeshError::BudgetTooSmall`]. Adaptive refinement spends whatever budget the uniform mesh leaves.
//!
//! # Adaptive refinement
//! [`adjacency`] lists, for each patch, the patches of the same face that share a stretch of edge with it (T-
//! junctions included), which is what radiosity-gradient refinement compares. [`refine`] splits selected
//! patches into children (4 for triangles and quadrilaterals, one quadrilateral per vertex otherwise), keeping
//! `face`, `material` and the normal; the caller decides which patches to split (e.g. where `|B_i - B_j|` between
//! neighbours is large) and checks the budget.

use std::collections::HashSet;

use glam::DVec3;

use crate::patch::Patch;
use crate::scene::{Polygon, Scene};

/// Patch budget when neither the caller nor the scene's TOML file sets one.
pub const DEFAULT_PATCH_BUDGET: usize = 4096;
/// When the scene's TOML file sets no `max_patch_edge`, the default is the scene's largest bounding-box extent
/// divided by this (a box-shaped room's walls become about 8 x 8 patches).
pub const DEFAULT_EDGE_DIVISIONS: f64 = 8.0;

/// How to mesh a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshOptions {
    /// `false`: one patch per face polygon (`--no-subdivide`); `true`: uniform subdivision to `max_patch_edge`.
    pub subdivide: bool,
    /// Longest patch edge, in scene units (ignored when `subdivide` is false).
    pub max_patch_edge: f64,
    /// Most patches the mesh may have.
    pub patch_budget: usize,
}

impl MeshOptions {
    /// Uniform subdivision with the scene's own limits (its TOML file), or the defaults: an edge limit of the
    /// scene's largest bounding-box extent / [`DEFAULT_EDGE_DIVISIONS`] and [`DEFAULT_PATCH_BUDGET`].
    #[must_use]
    pub fn for_scene(scene: &Scene) -> MeshOptions {
        let (min, max) = scene
            .faces
            .iter()
            .flat_map(|f| f.vertices.iter())
            .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
        let extent = (max - min).max_element();
        MeshOptions {
            subdivide: true,
            max_patch_edge: scene.meshing.max_patch_edge.unwrap_or(extent / DEFAULT_EDGE_DIVISIONS),
            patch_budget: scene.meshing.patch_budget.unwrap_or(DEFAULT_PATCH_BUDGET),
        }
    }

    /// One patch per face (`--no-subdivide`), with the scene's patch budget.
    #[must_use]
    pub fn no_subdivide(scene: &Scene) -> MeshOptions {
        MeshOptions {
            subdivide: false,
            max_patch_edge: f64::INFINITY,
            patch_budget: scene.meshing.patch_budget.unwrap_or(DEFAULT_PATCH_BUDGET),
        }
    }
}

/// Why meshing or refinement failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The budget is smaller than one patch per face polygon.
    #[error(
        "patch budget {budget} cannot hold one patch per face: the scene needs at least {needed} patches \
         ({faces} faces, non-planar ones split into triangles)"
    )]
    BudgetTooSmall {
        /// The budget asked for.
        budget: usize,
        /// Patches needed at the least.
        needed: usize,
        /// Faces in the scene.
        faces: usize,
    },
    /// The edge limit is not a positive number.
    #[error("max patch edge {0} must be positive (and not NaN)")]
    BadMaxEdge(f64),
    /// A patch index given to [`refine`] does not exist.
    #[error("patch {index} does not exist (there are {len} patches)")]
    NoSuchPatch {
        /// The index given.
        index: usize,
        /// Number of patches.
        len: usize,
    },
    /// A piece came out with zero area (only possible when subdividing far below the scene's precision).
    #[error("face {face}: a patch came out with zero area (patches too small for f64 coordinates)")]
    ZeroAreaPatch {
        /// The face being meshed.
        face: usize,
    },
}

/// The patches of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Patches in face order.
    pub patches: Vec<Patch>,
    /// The edge limit actually used: the requested one, raised if needed to fit the budget (infinite for
    /// `--no-subdivide`).
    pub max_patch_edge: f64,
}

/// Meshes `scene` into patches.
///
/// # Errors
/// [`MeshError::BudgetTooSmall`] if one patch per face polygon exceeds the budget, [`MeshError::BadMaxEdge`] for a
/// non-positive edge limit, [`MeshError::ZeroAreaPatch`] if a piece degenerates.
pub fn mesh(scene: &Scene, options: &MeshOptions) -> Result<Mesh, MeshError> {
    let polygons: Vec<(usize, usize, &Polygon)> =
        scene.faces.iter().flat_map(|f| f.polygons.iter().map(move |p| (f.index, f.material, p))).collect();
    let needed = polygons.len();
    if options.patch_budget < needed {
        return Err(MeshError::BudgetTooSmall {
            budget: options.patch_budget,
            needed,
            faces: scene.faces.len(),
        });
    }
    let limit = if options.subdivide {
        let l0 = options.max_patch_edge;
        if l0.is_nan() || l0 <= 0.0 {
            return Err(MeshError::BadMaxEdge(l0));
        }
        let count =
            |l: f64| polygons.iter().map(|(_, _, p)| piece_count(p, l)).fold(0, usize::saturating_add);
        if count(l0) <= options.patch_budget {
            l0
        } else {
            // At the longest polygon edge every polygon is one piece, which fits (checked above); the count never
            // grows with the limit, so bisection finds the smallest limit that fits.
            let mut hi = polygons.iter().map(|(_, _, p)| p.max_edge()).fold(l0, f64::max);
            let mut lo = l0;
            for _ in 0..64 {
                let mid = (lo * hi).sqrt();
                if count(mid) <= options.patch_budget {
                    hi = mid;
                } else {
                    lo = mid;
                }
                if hi <= lo * (1.0 + 1e-12) {
                    break;
                }
            }
            hi
        }
    } else {
        f64::INFINITY
    };
    let mut patches = Vec::new();
    let mut pieces = Vec::new();
    for (face, material, poly) in polygons {
        pieces.clear();
        subdivide(face, poly, limit, &mut pieces)?;
        for vertices in pieces.drain(..) {
            patches.push(make_patch(face, material, vertices, poly.normal)?);
        }
    }
    Ok(Mesh { patches, max_patch_edge: limit })
}

fn make_patch(face: usize, material: usize, vertices: Vec<DVec3>, normal: DVec3) -> Result<Patch, MeshError> {
    let p = Polygon::with_normal(vertices, normal).ok_or(MeshError::ZeroAreaPatch { face })?;
    Ok(Patch { face, material, vertices: p.vertices, normal, area: p.area, centroid: p.centroid })
}

fn divisions(length: f64, limit: f64) -> usize {
    // At least 1; lengths are finite (validated faces), so the cast saturates only for absurd limits.
    ((length / limit).ceil() as usize).max(1)
}

/// Number of pieces [`subdivide`] makes of `p` at edge limit `limit`.
fn piece_count(p: &Polygon, limit: f64) -> usize {
    let v = &p.vertices;
    if p.max_edge() <= limit {
        return 1;
    }
    match v.len() {
        // Saturating: a tiny limit must not overflow the count (it only has to exceed the budget).
        3 => divisions(p.max_edge(), limit).saturating_pow(2).min(quads_count(p, limit)),
        4 => {
            let (nu, nv) = quad_divisions(v, limit);
            nu.saturating_mul(nv)
        }
        _ => quads_count(p, limit),
    }
}

/// Number of pieces of `p` cut into [`centroid_quads`] that are then subdivided.
fn quads_count(p: &Polygon, limit: f64) -> usize {
    centroid_quads(p)
        .iter()
        .map(|q| q.as_ref().map_or(1, |q| piece_count(q, limit)))
        .fold(0, usize::saturating_add)
}

fn quad_divisions(v: &[DVec3], limit: f64) -> (usize, usize) {
    let e = |i: usize| v[i].distance(v[(i + 1) % 4]);
    (divisions(e(0).max(e(2)), limit), divisions(e(1).max(e(3)), limit))
}

/// Cuts a convex polygon of face `face` into convex pieces with every edge at most `limit` (see the module
/// docs).
fn subdivide(face: usize, p: &Polygon, limit: f64, out: &mut Vec<Vec<DVec3>>) -> Result<(), MeshError> {
    let v = &p.vertices;
    if p.max_edge() <= limit {
        out.push(v.clone());
        return Ok(());
    }
    match v.len() {
        3 if divisions(p.max_edge(), limit).saturating_pow(2) <= quads_count(p, limit) => {
            let k = divisions(p.max_edge(), limit);
            triangle_grid(v[0], v[1], v[2], k, out);
        }
        4 => {
            let (nu, nv) = quad_divisions(v, limit);
            quad_grid(v, nu, nv, out);
        }
        _ => {
            for q in centroid_quads(p) {
                subdivide(face, &q.ok_or(MeshError::ZeroAreaPatch { face })?, limit, out)?;
            }
        }
    }
    Ok(())
}

/// The regular subdivision of triangle `abc` into `k^2` triangles similar to it, all with its orientation.
fn triangle_grid(a: DVec3, b: DVec3, c: DVec3, k: usize, out: &mut Vec<Vec<DVec3>>) {
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
fn quad_grid(v: &[DVec3], nu: usize, nv: usize, out: &mut Vec<Vec<DVec3>>) {
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
fn centroid_quads(p: &Polygon) -> Vec<Option<Polygon>> {
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
            let lo = p.vertices.iter().copied().fold(DVec3::splat(f64::INFINITY), DVec3::min);
            let hi = p.vertices.iter().copied().fold(DVec3::splat(f64::NEG_INFINITY), DVec3::max);
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

/// Splits the patches listed in `which` into children; the others are kept. Each split patch is replaced, in
/// place, by its children, so patches stay in face order (indices after a split patch shift).
///
/// A triangle gives 4 similar triangles (edge midpoints), a quadrilateral a 2 x 2 grid of its bilinear
/// parametrisation, a polygon with more vertices one quadrilateral per vertex (centroid, edge midpoints); all
/// convex. Children keep the parent's `face`, `material` and normal, and their areas add up to the parent's.
/// Repeated indices in `which` split a patch once.
///
/// # Errors
/// [`MeshError::NoSuchPatch`] if an index is out of range, [`MeshError::ZeroAreaPatch`] if a child degenerates.
pub fn refine(patches: &[Patch], which: &[usize]) -> Result<Vec<Patch>, MeshError> {
    let mut selected = HashSet::with_capacity(which.len());
    for &i in which {
        if i >= patches.len() {
            return Err(MeshError::NoSuchPatch { index: i, len: patches.len() });
        }
        selected.insert(i);
    }
    let mut out = Vec::with_capacity(patches.len() + 3 * selected.len());
    let mut pieces = Vec::new();
    for (i, p) in patches.iter().enumerate() {
        if !selected.contains(&i) {
            out.push(p.clone());
            continue;
        }
        let v = &p.vertices;
        pieces.clear();
        match v.len() {
            3 => triangle_grid(v[0], v[1], v[2], 2, &mut pieces),
            4 => quad_grid(v, 2, 2, &mut pieces),
            _ => {
                let poly = Polygon::with_normal(v.clone(), p.normal)
                    .ok_or(MeshError::ZeroAreaPatch { face: p.face })?;
                for q in centroid_quads(&poly) {
                    pieces.push(q.ok_or(MeshError::ZeroAreaPatch { face: p.face })?.vertices);
                }
            }
        }
        for vertices in pieces.drain(..) {
            out.push(make_patch(p.face, p.material, vertices, p.normal)?);
        }
    }
    Ok(out)
}

/// Most adaptive refinement passes a scene may ask for (each pass can halve a patch's edges once).
pub const MAX_REFINE_PASSES: usize = 6;
/// Adaptive refinement passes when the scene's TOML file sets none.
pub const DEFAULT_REFINE_PASSES: usize = 2;
/// Refinement tolerance when the scene's TOML file sets none: a patch is a candidate when light changes across it
/// by more than this fraction of the scene's mean radiosity.
pub const DEFAULT_REFINE_TOLERANCE: f64 = 0.1;

/// How adaptive refinement chooses patches to split (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineOptions {
    /// Refinement passes (0: keep the uniform mesh).
    pub passes: usize,
    /// A patch is a candidate when its estimated radiosity change exceeds `tolerance` times the area-weighted
    /// mean radiosity of the non-emitting patches.
    pub tolerance: f64,
}

impl RefineOptions {
    /// The scene's own settings (its TOML file), or [`DEFAULT_REFINE_PASSES`] and [`DEFAULT_REFINE_TOLERANCE`].
    #[must_use]
    pub fn for_scene(scene: &Scene) -> RefineOptions {
        RefineOptions {
            passes: scene.meshing.refine_passes.unwrap_or(DEFAULT_REFINE_PASSES),
            tolerance: scene.meshing.refine_tolerance.unwrap_or(DEFAULT_REFINE_TOLERANCE),
        }
    }
}

/// What one solved pass tells refinement, per patch. All radiosities are luminance-like: the mean of the three
/// channels (W/m^2).
#[derive(Clone, Copy, Debug)]
pub struct RefineInput<'a> {
    /// The current patches.
    pub patches: &'a [Patch],
    /// Radiosity per patch (the f64 reference solution of this mesh).
    pub radiosity: &'a [[f64; 3]],
    /// Emission per patch.
    pub emission: &'a [[f64; 3]],
    /// Reflectance per patch.
    pub reflectance: &'a [[f64; 3]],
    /// The form factors of this mesh, their flags marking partly visible pairs (shadow boundaries).
    pub form_factors: &'a crate::patch::FormFactorMatrix,
}

/// Why a patch is worth splitting: three estimates of how much its radiosity changes across it (W/m^2).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefineScore {
    /// Largest radiosity difference to a neighbour of the same face (the radiosity gradient).
    pub gradient: f64,
    /// Light the patch reflects from partly visible patches, `rho_i sum_j F_ij B_j` over partly visible pairs:
    /// how much a shadow boundary crossing it can change its radiosity.
    pub shadow: f64,
    /// Contact edges: for a patch touched by another face along a line in its plane (a block standing on the
    /// floor, two walls meeting), `rho_i max_j (1/2 - F_ij) |B_j - H_i|`, with `H_i` the irradiance: at the contact
    /// line the other face fills half the view (a half-plane's form factor is 1/2), far from it only `F_ij`.
    pub contact: f64,
}

impl RefineScore {
    /// The largest of the three estimates.
    #[must_use]
    pub fn change(&self) -> f64 {
        self.gradient.max(self.shadow).max(self.contact)
    }
}

fn luminance(c: &[f64; 3]) -> f64 {
    (c[0] + c[1] + c[2]) / 3.0
}

/// The [`RefineScore`] of every patch.
///
/// # Panics
/// If the slices and the matrix do not all have one entry per patch.
#[must_use]
pub fn refine_scores(input: &RefineInput<'_>) -> Vec<RefineScore> {
    let n = input.patches.len();
    assert!(
        input.radiosity.len() == n
            && input.emission.len() == n
            && input.reflectance.len() == n
            && input.form_factors.n() == n,
        "one value per patch"
    );
    let b: Vec<f64> = input.radiosity.iter().map(luminance).collect();
    let neighbours = adjacency(input.patches);
    let ff = input.form_factors;
    (0..n)
        .map(|i| {
            let rho = luminance(&input.reflectance[i]);
            let gradient = neighbours[i].iter().map(|&j| (b[i] - b[j]).abs()).fold(0.0, f64::max);
            let mut shadow = 0.0;
            let mut irradiance = 0.0;
            for ((j, f), &partly_visible) in ff.row(i).zip(ff.row_flags(i)) {
                irradiance += f * b[j];
                if partly_visible {
                    shadow += f * b[j];
                }
            }
            let mut contact = 0.0f64;
            for (j, f) in ff.row(i) {
                if touches(&input.patches[i], &input.patches[j]) {
                    contact = contact.max((0.5 - f).max(0.0) * (b[j] - irradiance).abs());
                }
            }
            RefineScore { gradient, shadow: rho * shadow, contact: rho * contact }
        })
        .collect()
}

/// Whether patch `other` (of another, non-parallel plane) has an edge lying in `patch`'s plane that crosses
/// `patch`: a contact edge. Tolerances are `1e-6` of the larger patch's size.
fn touches(patch: &Patch, other: &Patch) -> bool {
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

/// Chooses the patches to split in one refinement pass: those whose [`RefineScore::change`] exceeds
/// `tolerance` times the area-weighted mean radiosity of the non-emitting patches (of all patches if all emit), in decreasing order of
/// `change * sqrt(area)` (the area-weighted L2 error a constant patch makes is about the change across it times
/// the square root of its area), as long as the patches they add keep the mesh within `budget`.
///
/// # Panics
/// If `scores` or `input` do not match `input.patches`.
#[must_use]
pub fn select_for_refinement(
    input: &RefineInput<'_>,
    scores: &[RefineScore],
    tolerance: f64,
    budget: usize,
) -> Vec<usize> {
    let patches = input.patches;
    assert_eq!(scores.len(), patches.len(), "one score per patch");
    // Mean radiosity of the non-emitting patches (of all patches if every patch emits, as in a white furnace).
    let mean = |emitting_too: bool| {
        let (mut weighted, mut area) = (0.0, 0.0);
        for (i, p) in patches.iter().enumerate() {
            if emitting_too || luminance(&input.emission[i]) == 0.0 {
                weighted += luminance(&input.radiosity[i]) * p.area;
                area += p.area;
            }
        }
        if area > 0.0 {
            weighted / area
        } else {
            0.0
        }
    };
    let reference = if patches.iter().enumerate().any(|(i, _)| luminance(&input.emission[i]) == 0.0) {
        mean(false)
    } else {
        mean(true)
    };
    let threshold = tolerance * reference;
    let mut candidates: Vec<(usize, f64)> = scores
        .iter()
        .enumerate()
        .filter(|(_, s)| s.change() > threshold)
        .map(|(i, s)| (i, s.change() * patches[i].area.sqrt()))
        .collect();
    candidates.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let mut count = patches.len();
    let mut chosen = Vec::new();
    for (i, _) in candidates {
        let added = children(&patches[i]) - 1;
        if count + added <= budget {
            count += added;
            chosen.push(i);
        }
    }
    chosen.sort_unstable();
    chosen
}

/// Number of children [`refine`] makes of a patch.
fn children(p: &Patch) -> usize {
    match p.vertices.len() {
        3 | 4 => 4,
        n => Polygon::with_normal(p.vertices.clone(), p.normal).map_or(n, |poly| centroid_quads(&poly).len()),
    }
}

/// The patch areas of a mesh, sorted ascending: the patch-size distribution (e.g. for a histogram of an adaptive
/// mesh, where small patches sit where light changes fast).
#[must_use]
pub fn patch_area_distribution(patches: &[Patch]) -> Vec<f64> {
    let mut areas: Vec<f64> = patches.iter().map(|p| p.area).collect();
    areas.sort_by(f64::total_cmp);
    areas
}
