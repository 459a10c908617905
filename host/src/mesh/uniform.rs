//! Uniform meshing: every polygon of every face cut into convex pieces whose edges are at most
//! `max_patch_edge`, with the edge limit raised when the mesh would exceed the patch budget (see the
//! [`crate::mesh`] docs for the cuts and the budget search).

use glam::DVec3;

use super::pieces::{centroid_quads, make_patch, quad_grid, triangle_grid};
use super::repair::{repair, RepairReport};
use super::MeshError;
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
    /// Repair the faces first ([`super::repair()`]): cut them where other faces meet them and cull what no point
    /// can see. `false` (`--no-repair`) meshes the faces as loaded.
    pub repair: bool,
}

impl MeshOptions {
    /// Uniform subdivision with the scene's own limits (its TOML file), or the defaults: an edge limit of the
    /// scene's largest bounding-box extent / [`DEFAULT_EDGE_DIVISIONS`] and [`DEFAULT_PATCH_BUDGET`].
    #[must_use]
    pub fn for_scene(scene: &Scene) -> MeshOptions {
        let (min, max) =
            crate::scene::bounding_box(scene.faces.iter().flat_map(|f| f.vertices.iter().copied()));
        let extent = (max - min).max_element();
        MeshOptions {
            subdivide: true,
            max_patch_edge: scene.meshing.max_patch_edge.unwrap_or(extent / DEFAULT_EDGE_DIVISIONS),
            patch_budget: scene.meshing.patch_budget.unwrap_or(DEFAULT_PATCH_BUDGET),
            repair: scene.meshing.repair.unwrap_or(true),
        }
    }

    /// One patch per face polygon (`--no-subdivide`; after repair, one per repaired polygon), with the scene's
    /// patch budget and repair setting.
    #[must_use]
    pub fn no_subdivide(scene: &Scene) -> MeshOptions {
        MeshOptions {
            subdivide: false,
            max_patch_edge: f64::INFINITY,
            patch_budget: scene.meshing.patch_budget.unwrap_or(DEFAULT_PATCH_BUDGET),
            repair: scene.meshing.repair.unwrap_or(true),
        }
    }
}

/// The patches of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Patches in face order.
    pub patches: Vec<Patch>,
    /// The edge limit actually used: the requested one, raised if needed to fit the budget (infinite for
    /// `--no-subdivide`).
    pub max_patch_edge: f64,
    /// What repair changed (`None` when [`MeshOptions::repair`] is off).
    pub repair: Option<RepairReport>,
}

/// Meshes `scene` into patches.
///
/// # Errors
/// [`MeshError::BudgetTooSmall`] if one patch per face polygon exceeds the budget, [`MeshError::BadMaxEdge`] for a
/// non-positive edge limit, [`MeshError::ZeroAreaPatch`] if a piece degenerates.
pub fn mesh(scene: &Scene, options: &MeshOptions) -> Result<Mesh, MeshError> {
    let repaired = options.repair.then(|| repair(scene));
    let polygons: Vec<(usize, usize, &Polygon)> = match &repaired {
        Some(r) => scene
            .faces
            .iter()
            .zip(&r.polygons)
            .flat_map(|(f, polys)| polys.iter().map(move |p| (f.index, f.material, p)))
            .collect(),
        None => scene
            .faces
            .iter()
            .flat_map(|f| f.polygons.iter().map(move |p| (f.index, f.material, p)))
            .collect(),
    };
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
    Ok(Mesh { patches, max_patch_edge: limit, repair: repaired.map(|r| r.report) })
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
