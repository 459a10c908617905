//! A pinhole camera: pixel -> primary ray.
//!
//! Pixel `(i, j)` (column from the left, row from the top) is sampled through its centre. With `f` the viewing
//! direction, `u` the up vector made orthogonal to `f`, and `r = f x u` the image's right, the ray direction is
//! `f + sx tan(fov_h / 2) r + sy tan(fov_v / 2) u` with `sx = 2 (i + 0.5) / width - 1` and
//! `sy = 1 - 2 (j + 0.5) / height`; the vertical field of view is given and the horizontal one follows from the
//! aspect ratio (square pixels).

use glam::DVec3;

use super::PictureError;

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Centre of projection (scene units).
    pub position: DVec3,
    /// Unit viewing direction.
    pub forward: DVec3,
    /// Unit up vector, orthogonal to `forward`.
    pub up: DVec3,
    /// Vertical field of view in degrees, in `(0, 180)`.
    pub vertical_fov_deg: f64,
}

impl Camera {
    /// A camera at `position` looking towards `target`, with `up` roughly up.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] if a vector is not finite, `target == position`, `up` is parallel to the view
    /// direction, or the field of view is not in `(0, 180)` degrees.
    pub fn look_at(
        position: DVec3,
        target: DVec3,
        up: DVec3,
        vertical_fov_deg: f64,
    ) -> Result<Self, PictureError> {
        if !(position.is_finite() && target.is_finite() && up.is_finite()) {
            return Err(PictureError::invalid("camera", "position, target and up must be finite"));
        }
        let forward = (target - position).try_normalize().ok_or_else(|| {
            PictureError::invalid("camera", format!("target {target} coincides with the position"))
        })?;
        let up = (up - forward * up.dot(forward)).try_normalize().ok_or_else(|| {
            PictureError::invalid("camera", format!("up {up} is parallel to the view direction"))
        })?;
        if !(vertical_fov_deg > 0.0 && vertical_fov_deg < 180.0) {
            return Err(PictureError::invalid(
                "camera field of view",
                format!("{vertical_fov_deg} degrees is not in (0, 180)"),
            ));
        }
        Ok(Camera { position, forward, up, vertical_fov_deg })
    }

    /// The Cornell box's published camera: at (278, 273, -800) looking along +z, up +y, focal length 35 mm on a
    /// 25 x 25 mm film, so a field of view of `2 atan(12.5 / 35)` = 39.3 degrees (Cornell University Program of
    /// Computer Graphics, "Cornell Box Data"; see `shared/data/cornell-box.md`).
    #[must_use]
    pub fn cornell_box() -> Self {
        Camera {
            position: DVec3::new(278.0, 273.0, -800.0),
            forward: DVec3::Z,
            up: DVec3::Y,
            vertical_fov_deg: 2.0 * (12.5f64 / 35.0).atan().to_degrees(),
        }
    }

    /// Parses `"px,py,pz;tx,ty,tz;ux,uy,uz;fov"`: position, target, up, vertical field of view in degrees.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] naming the part that does not parse, or as [`Camera::look_at`].
    pub fn parse(spec: &str) -> Result<Self, PictureError> {
        let parts: Vec<&str> = spec.split(';').map(str::trim).collect();
        if parts.len() != 4 {
            return Err(PictureError::invalid(
                "camera",
                format!(
                    "{spec:?} is not \"px,py,pz;tx,ty,tz;ux,uy,uz;fov_degrees\" (4 parts separated by ';')"
                ),
            ));
        }
        let vector = |name: &'static str, s: &str| -> Result<DVec3, PictureError> {
            let v: Vec<f64> = s
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| PictureError::invalid("camera", format!("{name} {s:?}: {e}")))?;
            match v.as_slice() {
                [x, y, z] => Ok(DVec3::new(*x, *y, *z)),
                _ => Err(PictureError::invalid(
                    "camera",
                    format!("{name} {s:?} needs 3 comma-separated numbers"),
                )),
            }
        };
        let fov: f64 = parts[3]
            .parse()
            .map_err(|e| PictureError::invalid("camera", format!("field of view {:?}: {e}", parts[3])))?;
        Camera::look_at(
            vector("position", parts[0])?,
            vector("target", parts[1])?,
            vector("up", parts[2])?,
            fov,
        )
    }

    /// Unit vector towards the image's right (`forward x up`).
    #[must_use]
    pub fn right(&self) -> DVec3 {
        self.forward.cross(self.up)
    }

    /// The primary ray through the centre of pixel `(column, row)` of a `width x height` image: (origin, unit
    /// direction).
    #[must_use]
    pub fn ray(&self, column: u32, row: u32, width: u32, height: u32) -> (DVec3, DVec3) {
        let tan_v = (self.vertical_fov_deg.to_radians() / 2.0).tan();
        let tan_h = tan_v * f64::from(width) / f64::from(height);
        let sx = 2.0 * (f64::from(column) + 0.5) / f64::from(width) - 1.0;
        let sy = 1.0 - 2.0 * (f64::from(row) + 0.5) / f64::from(height);
        let dir = self.forward + self.right() * (sx * tan_h) + self.up * (sy * tan_v);
        (self.position, dir.normalize())
    }
}
