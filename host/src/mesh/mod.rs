//! Meshing: a [`Scene`](crate::scene::Scene)'s faces turned into [`Patch`](crate::patch::Patch)es, plus the
//! adjacency and refinement steps that adaptive meshing builds on.
//!
//! # Repair
//! Unless [`MeshOptions::repair`] is off (`--no-repair`, or `repair = false` in the scene's TOML), the faces are
//! repaired first ([`repair()`], module [`mod@repair`]): cut where other faces touch or pass through them, and
//! the pieces no point can see (the floor under a block, a wall inside another solid) culled. Everything below
//! then works on the repaired polygons; [`Mesh::repair`] says what changed.
//!
//! # Patches and faces
//! Every patch keeps its parent face (`Patch::face`, the OBJ face index) and material, so results map back to
//! OBJ faces. Patches come out in face order: all patches of face 0, then of face 1, and so on.
//!
//! - **`--no-subdivide`** ([`MeshOptions::no_subdivide`]): one patch per planar face, so patch `k` is OBJ face `k`
//!   as long as no earlier face was split. A face the loader split into triangles for being non-planar (see
//!   [`crate::scene`]) gives one patch per triangle, all with the same `face`, in fan order; the patches after it
//!   shift by the number of extra triangles; a face that repair cut gives one patch per piece it kept (none if
//!   all of it was culled). Map patches to faces with `Patch::face`, never by position. (The
//!   shipped Cornell box puts its non-planar red wall last, so with `--no-repair` patch `k` is face `k` for every
//!   other face; repaired, its floor, face 0, is several pieces and the faces after it shift.)
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
//!
//! # Where things are
//! Each submodule uses only those before it; all of them read the scene ([`crate::scene`]), which knows nothing
//! of meshing (the scene file's refinement limit, [`crate::scene::MAX_REFINE_PASSES`], is the scene's).
//! - `repair`: faces cut where others meet them, hidden pieces culled ([`repair()`], [`RepairReport`]).
//! - `pieces`: the cuts (triangle grid, quadrilateral grid, centroid quadrilaterals) and pieces -> patches.
//! - `uniform`: [`mesh`], [`MeshOptions`] and the patch-budget search.
//! - `adjacency`: neighbours within a face ([`adjacency`]) and contact edges between faces.
//! - `refine`: refinement scores, the choice of patches to split, and [`refine`] itself.

mod adjacency;
mod pieces;
mod refine;
pub mod repair;
mod uniform;

pub use adjacency::adjacency;
pub use refine::{
    patch_area_distribution, refine, refine_scores, refinement_candidates, select_for_refinement,
    RefineInput, RefineOptions, RefineScore, DEFAULT_REFINE_PASSES, DEFAULT_REFINE_TOLERANCE,
};
pub use repair::{repair, FaceRepair, Meeting, RepairReport, Repaired, REPAIR_TOLERANCE};
pub use uniform::{mesh, Mesh, MeshOptions, DEFAULT_EDGE_DIVISIONS, DEFAULT_PATCH_BUDGET};

/// Why meshing or refinement failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The budget is smaller than one patch per face polygon.
    #[error(
        "patch budget {budget} cannot hold one patch per face: the scene needs at least {needed} patches \
         ({faces} faces, non-planar ones split into triangles, repaired ones into pieces)"
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
