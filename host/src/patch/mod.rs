//! Patches and form-factor matrices: the types shared by meshing, form factors, the reference solver and baking.
//!
//! Units follow the scene (the Cornell box is in millimetres); areas are in scene units squared. Form factors are
//! dimensionless. Conventions (diffuse, RGB, `F_ij` = fraction of the power leaving `i` that reaches `j`) are the
//! ones stated in `radiosity-core`'s crate docs.

use glam::DVec3;

/// One patch: a planar convex polygon carrying one radiosity value per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch {
    /// Index of the OBJ face this patch came from (0-based, in OBJ order over all objects).
    pub face: usize,
    /// Index of the patch's material in the scene's material list.
    pub material: usize,
    /// Polygon vertices, counter-clockwise seen from the side the normal points to.
    pub vertices: Vec<DVec3>,
    /// Unit normal (the side that emits and receives light).
    pub normal: DVec3,
    /// Area of the polygon.
    pub area: f64,
    /// Centroid of the polygon.
    pub centroid: DVec3,
}

mod closure;
mod matrix;

pub use closure::{Closure, RefusedClosure, CLOSURE_TOLERANCE};
pub use matrix::{FormFactorMatrix, MatrixError, ReciprocityChange, RowClamp};
