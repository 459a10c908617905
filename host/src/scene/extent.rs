//! The scene's size and position, checked against the range in which every later stage works in its number
//! types. Checked once at load, before any work, so a scene out of range gets a clear error instead of a bake
//! that is silently wrong or fails at the end.
//!
//! - Occlusion rays are cast in `f32` in the scene's units ([`crate::raycast`]; Embree sees each scene scaled
//!   by a power of two to unit size, so its own float tolerances hold at any size) and the table stores patch
//!   areas as `f32`. A patch area of up to [`MAX_SCENE_SIZE`]² fits `f32` with a margin of 300, and a patch a
//!   millionth of a scene [`MIN_SCENE_SIZE`] across still has a normal `f32` area (about 1e-42 would not be).
//!   In between, results do not depend on the unit: a scene scaled by a power of two gives the same form factors
//!   bit for bit (the f64 kernels use tolerances relative to each patch's size).
//! - Rays are cut short at both ends by an offset that grows with the largest coordinate
//!   ([`crate::raycast::scene_scale`]), because `f32` rounding grows with it. A scene further from the origin
//!   than [`MAX_ORIGIN_DISTANCE`] times its own size would have offsets above 1 % of its size, so occluders near
//!   a ray's ends would be missed; such a scene must be moved nearer the origin.

use std::path::Path;

use glam::DVec3;

use super::error::{length, SceneError};
use super::face::Face;

/// Smallest scene size (bounding-box diagonal, scene units) accepted.
pub const MIN_SCENE_SIZE: f64 = 1e-15;

/// Largest scene size (bounding-box diagonal, scene units) accepted.
pub const MAX_SCENE_SIZE: f64 = 1e18;

/// Largest distance of a vertex coordinate from the origin, in multiples of the scene size, accepted.
pub const MAX_ORIGIN_DISTANCE: f64 = 100.0;

/// The axis-aligned bounding box `(min, max)` of `points` (`(+inf, -inf)` for none).
pub fn bounding_box(points: impl IntoIterator<Item = DVec3>) -> (DVec3, DVec3) {
    points.into_iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

/// Checks the faces' bounding box against [`MIN_SCENE_SIZE`], [`MAX_SCENE_SIZE`] and [`MAX_ORIGIN_DISTANCE`].
pub(super) fn check_extent(file: &Path, faces: &[Face]) -> Result<(), SceneError> {
    let (lo, hi) = bounding_box(faces.iter().flat_map(|f| f.vertices.iter().copied()));
    if faces.is_empty() {
        return Ok(());
    }
    let size = (hi - lo).length();
    let far = lo.abs().max(hi.abs()).max_element();
    let problem = if size > MAX_SCENE_SIZE {
        format!(
            "the scene is {} across (bounding-box diagonal), more than the largest size supported, \
             {MAX_SCENE_SIZE:e} (the table stores patch areas as f32); scale it to smaller units",
            length(size)
        )
    } else if size < MIN_SCENE_SIZE {
        format!(
            "the scene is {} across (bounding-box diagonal), less than the smallest size supported, \
             {MIN_SCENE_SIZE:e} (small patches' areas would underflow the table's f32); scale it to larger units",
            length(size)
        )
    } else if far > MAX_ORIGIN_DISTANCE * size {
        format!(
            "a vertex coordinate is {} from the origin, more than {MAX_ORIGIN_DISTANCE} times the scene's size {} \
             (f32 rays would lose the scene's detail to rounding); move the scene nearer the origin",
            length(far),
            length(size)
        )
    } else {
        return Ok(());
    };
    Err(SceneError::Extent { file: file.to_path_buf(), problem })
}
