//! Smooth shading: per-patch radiosity -> per-vertex values -> a value at any point of a patch.
//!
//! A radiosity solution is one value per patch; drawn flat it shows the mesh. Smooth shading reconstructs a
//! continuous field the usual way (Cohen and Wallace, "Radiosity and Realistic Image Synthesis", 1993, section 9.2,
//! "nodal averaging"), with two refinements:
//!
//! 1. **Vertices.** Patch corners closer than a tolerance (relative to the scene's bounding-box diagonal) are the
//!    same vertex. For each corner `v` of patch `p`, the neighbours are the patches `q` whose closed polygon touches
//!    `v` (sharing it as a corner, or with `v` on an edge: a T-junction of an adaptive mesh) and that are
//!    *compatible* with `p`: the same material and normals within the crease angle. Values never blend across a
//!    crease or a material boundary, because incompatible patches are never neighbours.
//! 2. **Vertex value.** An area-weighted least-squares fit of a linear function `a + g . (x - v)` in `p`'s plane to
//!    the neighbours' centroid values, evaluated at `v` (i.e. `a`). For neighbours placed symmetrically about `v`
//!    this is the plain area-weighted mean; unlike the mean it reproduces a linear field exactly, also on
//!    non-uniform meshes and at the border of a surface (where the mean would flatten the field). When the
//!    neighbours' centroids do not span the plane (a border vertex with two neighbours in a row, a corner with one),
//!    the fit takes in the compatible patches touching the neighbours' corners (a second ring); if that still does
//!    not span the plane, the vertex gets the area-weighted mean of its neighbours.
//!    The value is a fixed linear combination of patch values, so the weights are computed once by
//!    [`SmoothShader::new`] and each [`SmoothShader::shade`] call is a few multiply-adds per corner. Where the
//!    field changes abruptly (a shadow edge one patch away from a surface's border) the linear extrapolation can
//!    overshoot, even below zero, so each channel of a vertex value is bounded to `[min / 2, 2 max]` of the
//!    neighbour values it was fitted to; a smooth field (neighbours differing by well under a factor of two, as
//!    in a mesh fine enough for its lighting) never reaches the bounds.
//! 3. **Inside a patch.** Barycentric coordinates in triangles, bilinear interpolation in quadrilaterals (the
//!    inverse bilinear map solved by Newton's method), and mean value coordinates (M. S. Floater, "Mean value
//!    coordinates", Computer Aided Geometric Design 20(1), 2003) in convex polygons with more corners (and as the
//!    fallback for a quadrilateral whose inverse map does not converge). All three reproduce linear functions, so a
//!    linear field is reproduced exactly everywhere. Points are first projected onto the patch's plane, and points
//!    outside the polygon are moved to its nearest boundary point (no extrapolation). Results below zero (a fit
//!    extrapolating a steep gradient) are clamped to zero.
//!
//! Known limit: at a T-junction the large patch interpolates along its edge from its own corners while the small
//! patches use the fitted value at the junction, so the field can have a small step there.

use std::collections::HashMap;

use glam::{DMat3, DVec2, DVec3};

use super::PictureError;
use crate::patch::Patch;
use crate::rgb::{channel_max, channel_min, Rgb};
use crate::scene::bounding_box;

/// Options for [`SmoothShader::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadingOptions {
    /// Patches whose normals differ by more than this angle (degrees) never share vertex values.
    pub crease_angle_deg: f64,
    /// Vertex welding tolerance as a fraction of the scene's bounding-box diagonal.
    pub weld_tolerance: f64,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions { crease_angle_deg: 30.0, weld_tolerance: 1e-6 }
    }
}

/// One patch's plane frame and corners in that frame.
#[derive(Clone, Debug)]
struct Frame {
    origin: DVec3,
    u: DVec3,
    w: DVec3,
    corners: Vec<DVec2>,
}

impl Frame {
    fn project(&self, point: DVec3) -> DVec2 {
        let d = point - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.w))
    }
}

/// Smooth shading over a fixed set of patches: build once, then shade any per-patch radiosity.
#[derive(Clone, Debug)]
pub struct SmoothShader {
    frames: Vec<Frame>,
    /// Corner `k` of patch `p` is corner `corner_start[p] + k`.
    corner_start: Vec<usize>,
    /// Weights of corner `c` are `weights[weight_start[c]..weight_start[c + 1]]`.
    weight_start: Vec<usize>,
    weights: Vec<(u32, f64)>,
    tolerance: f64,
}

/// Uniform hash grid over patch bounding boxes, to find the patches touching a point.
struct Grid {
    cell: f64,
    cells: HashMap<(i64, i64, i64), Vec<u32>>,
}

impl Grid {
    fn key(&self, p: DVec3) -> (i64, i64, i64) {
        let k = (p / self.cell).floor();
        (k.x as i64, k.y as i64, k.z as i64)
    }

    fn build(patches: &[Patch], cell: f64, pad: f64) -> Grid {
        let mut grid = Grid { cell, cells: HashMap::new() };
        for (i, p) in patches.iter().enumerate() {
            let (lo, hi) = bounding_box(p.vertices.iter().copied());
            let (a, b) = (grid.key(lo - DVec3::splat(pad)), grid.key(hi + DVec3::splat(pad)));
            for x in a.0..=b.0 {
                for y in a.1..=b.1 {
                    for z in a.2..=b.2 {
                        grid.cells.entry((x, y, z)).or_default().push(i as u32);
                    }
                }
            }
        }
        grid
    }

    fn candidates(&self, p: DVec3) -> &[u32] {
        self.cells.get(&self.key(p)).map_or(&[], Vec::as_slice)
    }
}

/// Signed distances from a 2D point to the lines of a counter-clockwise convex polygon's edges (positive inside).
fn min_edge_distance(corners: &[DVec2], q: DVec2) -> f64 {
    let n = corners.len();
    (0..n)
        .map(|i| {
            let (a, b) = (corners[i], corners[(i + 1) % n]);
            let e = b - a;
            e.perp_dot(q - a) / e.length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Nearest point to `q` on segment `a..b`.
fn nearest_on_segment(a: DVec2, b: DVec2, q: DVec2) -> DVec2 {
    let e = b - a;
    let t = ((q - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
    a + e * t
}

impl SmoothShader {
    /// Builds the shader: welds vertices, finds each corner's compatible neighbours and fits their weights.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] naming the patch if one has fewer than 3 vertices, non-finite coordinates, a
    /// non-unit normal or a non-positive area, or if the options are out of range (crease angle outside
    /// `[0, 180]`, tolerance not in `(0, 1)`), or if all patches collapse to a point.
    pub fn new(patches: &[Patch], options: &ShadingOptions) -> Result<Self, PictureError> {
        if !(0.0..=180.0).contains(&options.crease_angle_deg) {
            return Err(PictureError::invalid(
                "crease angle",
                format!("{} degrees is not in [0, 180]", options.crease_angle_deg),
            ));
        }
        if !(options.weld_tolerance > 0.0 && options.weld_tolerance < 1.0) {
            return Err(PictureError::invalid(
                "weld tolerance",
                format!("{} is not in (0, 1) (a fraction of the scene size)", options.weld_tolerance),
            ));
        }
        for (i, p) in patches.iter().enumerate() {
            let bad = |reason: String| {
                PictureError::invalid("patch", format!("patch {i} (face {}): {reason}", p.face))
            };
            if p.vertices.len() < 3 {
                return Err(bad(format!("{} vertices, at least 3 needed", p.vertices.len())));
            }
            if p.vertices.iter().any(|v| !v.is_finite()) || !p.centroid.is_finite() {
                return Err(bad("non-finite coordinates".into()));
            }
            if !p.normal.is_finite() || (p.normal.length() - 1.0).abs() > 1e-6 {
                return Err(bad(format!("normal {} is not a unit vector", p.normal)));
            }
            if !(p.area.is_finite() && p.area > 0.0) {
                return Err(bad(format!("area {} is not positive", p.area)));
            }
        }
        let all: Vec<DVec3> = patches.iter().flat_map(|p| p.vertices.iter().copied()).collect();
        let (lo, hi) = bounding_box(all.iter().copied());
        let diagonal = (hi - lo).length();
        if patches.is_empty() || diagonal <= 0.0 || !diagonal.is_finite() {
            return Err(PictureError::invalid("patches", "no patches, or all patches collapse to one point"));
        }
        let tolerance = options.weld_tolerance * diagonal;
        let cos_crease = options.crease_angle_deg.to_radians().cos();

        let frames: Vec<Frame> = patches
            .iter()
            .map(|p| {
                let origin = p.vertices[0];
                let u = (p.vertices[1] - origin).normalize_or(p.normal.any_orthonormal_vector());
                let u = (u - p.normal * u.dot(p.normal)).normalize();
                let w = p.normal.cross(u);
                let mut frame = Frame { origin, u, w, corners: Vec::new() };
                frame.corners = p.vertices.iter().map(|&v| frame.project(v)).collect();
                frame
            })
            .collect();

        // Cell size: about one typical patch, but no finer than 1/128 of the scene, so a large patch covers a
        // bounded number of cells.
        let mut sizes: Vec<f64> = patches
            .iter()
            .map(|p| {
                let (a, b) = bounding_box(p.vertices.iter().copied());
                (b - a).length()
            })
            .collect();
        sizes.sort_by(f64::total_cmp);
        let cell = sizes[sizes.len() / 2].max(diagonal / 128.0).max(4.0 * tolerance);
        let grid = Grid::build(patches, cell, tolerance);

        let touches = |q: usize, v: DVec3| -> bool {
            let p = &patches[q];
            // A shared corner (welded within the tolerance), also of a slightly warped quadrilateral whose corners
            // are off its plane by more than the tolerance; otherwise `v` on the polygon (a T-junction).
            if p.vertices.iter().any(|&c| (c - v).length() <= tolerance) {
                return true;
            }
            if (v - p.vertices[0]).dot(p.normal).abs() > tolerance {
                return false;
            }
            min_edge_distance(&frames[q].corners, frames[q].project(v)) >= -tolerance
        };
        let compatible = |p: usize, q: usize| -> bool {
            patches[p].material == patches[q].material
                && patches[p].normal.dot(patches[q].normal) >= cos_crease
        };
        let neighbours = |p: usize, v: DVec3, out: &mut Vec<usize>| {
            for &q in grid.candidates(v) {
                let q = q as usize;
                if !out.contains(&q) && compatible(p, q) && touches(q, v) {
                    out.push(q);
                }
            }
        };

        let mut corner_start = Vec::with_capacity(patches.len() + 1);
        let mut weight_start = vec![0];
        let mut weights = Vec::new();
        let mut ring = Vec::new();
        for (p, patch) in patches.iter().enumerate() {
            corner_start.push(weight_start.len() - 1);
            for &v in &patch.vertices {
                ring.clear();
                neighbours(p, v, &mut ring);
                if !ring.contains(&p) {
                    // A patch always touches its own corners; keep it even if rounding said otherwise.
                    ring.push(p);
                }
                let fit = fit_weights(patches, &frames[p], v, &ring).or_else(|| {
                    let mut second = ring.clone();
                    for &q in &ring {
                        for &c in &patches[q].vertices {
                            neighbours(p, c, &mut second);
                        }
                    }
                    fit_weights(patches, &frames[p], v, &second)
                });
                match fit {
                    Some(ws) => weights.extend(ws),
                    None => {
                        let total: f64 = ring.iter().map(|&q| patches[q].area).sum();
                        weights.extend(ring.iter().map(|&q| (q as u32, patches[q].area / total)));
                    }
                }
                weight_start.push(weights.len());
            }
        }
        corner_start.push(weight_start.len() - 1);
        Ok(SmoothShader { frames, corner_start, weight_start, weights, tolerance })
    }

    /// Number of patches the shader was built for.
    #[must_use]
    pub fn patch_count(&self) -> usize {
        self.frames.len()
    }

    /// The welding tolerance in scene units.
    #[must_use]
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The patches and weights whose weighted sum is the value at corner `corner` of patch `patch`
    /// (weights sum to 1; some may be negative where the linear fit extrapolates).
    ///
    /// # Panics
    /// If `patch` or `corner` is out of range.
    #[must_use]
    pub fn corner_weights(&self, patch: usize, corner: usize) -> &[(u32, f64)] {
        let c = self.corner_start[patch] + corner;
        assert!(c < self.corner_start[patch + 1], "patch {patch} has no corner {corner}");
        &self.weights[self.weight_start[c]..self.weight_start[c + 1]]
    }

    fn check(&self, radiosity: &[Rgb], patch: usize) -> Result<(), PictureError> {
        if radiosity.len() != self.frames.len() {
            return Err(PictureError::invalid(
                "radiosity",
                format!("{} values for {} patches", radiosity.len(), self.frames.len()),
            ));
        }
        if patch >= self.frames.len() {
            return Err(PictureError::invalid(
                "patch index",
                format!("{patch} is out of range ({} patches)", self.frames.len()),
            ));
        }
        Ok(())
    }

    fn corner_value(&self, radiosity: &[Rgb], patch: usize, corner: usize) -> Result<Rgb, PictureError> {
        let mut sum = Rgb::ZERO;
        let mut lo = Rgb::INFINITY;
        let mut hi = Rgb::NEG_INFINITY;
        for &(q, w) in self.corner_weights(patch, corner) {
            let b = radiosity[q as usize];
            if let Some(v) = b.to_array().into_iter().find(|v| !v.is_finite()) {
                return Err(PictureError::NonFinite {
                    what: "radiosity of patch",
                    index: q as usize,
                    value: v,
                });
            }
            sum += w * b;
            lo = channel_min(lo, b);
            hi = channel_max(hi, b);
        }
        // Bound the extrapolation (see the module docs): never below half the smallest or above twice the largest
        // neighbour value. Only steep changes (shadow edges) reach the bounds; smooth fields never do.
        let bounded = |ch: usize| {
            let (a, b) = if lo[ch] >= 0.0 {
                (0.5 * lo[ch], 2.0 * hi[ch])
            } else {
                (2.0 * lo[ch], 2.0 * hi[ch].max(0.0))
            };
            sum[ch].clamp(a, b.max(a))
        };
        Ok(Rgb::new(bounded(0), bounded(1), bounded(2)))
    }

    /// The smoothed value at corner `corner` of patch `patch` (the fitted value within its bounds, see the module
    /// docs).
    ///
    /// # Errors
    /// [`PictureError::Invalid`] if `radiosity` does not have one value per patch or `patch` / `corner` is out of
    /// range; [`PictureError::NonFinite`] naming a neighbouring patch whose radiosity is NaN or infinite.
    pub fn vertex_value(&self, radiosity: &[Rgb], patch: usize, corner: usize) -> Result<Rgb, PictureError> {
        self.check(radiosity, patch)?;
        if corner >= self.frames[patch].corners.len() {
            return Err(PictureError::invalid(
                "corner index",
                format!("patch {patch} has no corner {corner}"),
            ));
        }
        self.corner_value(radiosity, patch, corner)
    }

    /// Distance from `point` (projected onto the patch's plane) to the patch polygon: 0 inside.
    ///
    /// # Panics
    /// If `patch` is out of range.
    #[must_use]
    pub fn distance_in_plane(&self, patch: usize, point: DVec3) -> f64 {
        let f = &self.frames[patch];
        let q = f.project(point);
        if min_edge_distance(&f.corners, q) >= 0.0 {
            return 0.0;
        }
        let n = f.corners.len();
        (0..n)
            .map(|i| (nearest_on_segment(f.corners[i], f.corners[(i + 1) % n], q) - q).length())
            .fold(f64::INFINITY, f64::min)
    }

    /// The smoothly interpolated radiosity at `point` on patch `patch` (see the module docs), clamped to `>= 0`.
    ///
    /// # Errors
    /// As [`SmoothShader::vertex_value`], and [`PictureError::NonFinite`] if `point` is not finite.
    pub fn shade(&self, radiosity: &[Rgb], patch: usize, point: DVec3) -> Result<Rgb, PictureError> {
        self.check(radiosity, patch)?;
        if let Some((index, &value)) = point.to_array().iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(PictureError::NonFinite { what: "shading point coordinate", index, value });
        }
        let f = &self.frames[patch];
        let mut q = f.project(point);
        let n = f.corners.len();
        if min_edge_distance(&f.corners, q) < 0.0 {
            q = (0..n)
                .map(|i| nearest_on_segment(f.corners[i], f.corners[(i + 1) % n], q))
                .min_by(|a, b| (*a - q).length_squared().total_cmp(&(*b - q).length_squared()))
                .unwrap_or(q);
        }
        let lambda = interpolation_weights(&f.corners, q);
        let mut out = Rgb::ZERO;
        for (k, &l) in lambda.iter().enumerate() {
            if l == 0.0 {
                continue;
            }
            out += l * self.corner_value(radiosity, patch, k)?;
        }
        Ok(out.map(|v| v.max(0.0)))
    }
}

/// Area-weighted least-squares linear fit at `v` over the centroids of `ring`, in `frame`'s plane. Returns the
/// weights of the patches, or `None` if the centroids do not span the plane.
fn fit_weights(patches: &[Patch], frame: &Frame, v: DVec3, ring: &[usize]) -> Option<Vec<(u32, f64)>> {
    let pts: Vec<(usize, f64, DVec2)> = ring
        .iter()
        .map(|&q| {
            let d = patches[q].centroid - v;
            (q, patches[q].area, DVec2::new(d.dot(frame.u), d.dot(frame.w)))
        })
        .collect();
    let total: f64 = pts.iter().map(|p| p.1).sum();
    let mean = pts.iter().map(|p| p.2 * p.1).sum::<DVec2>() / total;
    // Weighted covariance of the centroid offsets; its eigenvalue ratio says whether they span the plane.
    let (mut cxx, mut cxy, mut cyy) = (0.0, 0.0, 0.0);
    for &(_, a, x) in &pts {
        let d = x - mean;
        cxx += a * d.x * d.x;
        cxy += a * d.x * d.y;
        cyy += a * d.y * d.y;
    }
    let tr = cxx + cyy;
    let det = cxx * cyy - cxy * cxy;
    let disc = (0.25 * tr * tr - det).max(0.0).sqrt();
    let (lmax, lmin) = (0.5 * tr + disc, 0.5 * tr - disc);
    // Below 1e-3 the spread in one direction is under ~3% of the other: the fit's slope across it (and so the
    // extrapolated vertex value) would be dominated by rounding and noise.
    if !(lmax > 0.0 && lmin > 1e-3 * lmax) {
        return None;
    }
    let mut m = DMat3::ZERO;
    for &(_, a, x) in &pts {
        let r = DVec3::new(1.0, x.x, x.y);
        m += DMat3::from_cols(r * r.x, r * r.y, r * r.z) * a;
    }
    let inv = m.inverse();
    if !inv.is_finite() {
        return None;
    }
    let coef = inv.x_axis; // M is symmetric: first row of M^-1 = first column.
    Some(pts.iter().map(|&(q, a, x)| (q as u32, a * coef.dot(DVec3::new(1.0, x.x, x.y)))).collect())
}

/// Interpolation weights of the corners of a convex polygon at a point inside it (see the module docs).
fn interpolation_weights(c: &[DVec2], q: DVec2) -> Vec<f64> {
    match c.len() {
        3 => {
            let area = (c[1] - c[0]).perp_dot(c[2] - c[0]);
            let l1 = (c[2] - c[1]).perp_dot(q - c[1]) / area;
            let l2 = (c[0] - c[2]).perp_dot(q - c[2]) / area;
            vec![l1, l2, 1.0 - l1 - l2]
        }
        4 => match inverse_bilinear(c, q) {
            Some((s, t)) => vec![(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t],
            None => mean_value_weights(c, q),
        },
        _ => mean_value_weights(c, q),
    }
}

/// Solves `x(s, t) = q` for the bilinear map of a quadrilateral `x(s, t) = c0 + s e1 + t e2 + s t e3` by Newton's
/// method from the centre. `None` if it does not converge (a degenerate quadrilateral).
fn inverse_bilinear(c: &[DVec2], q: DVec2) -> Option<(f64, f64)> {
    let e1 = c[1] - c[0];
    let e2 = c[3] - c[0];
    let e3 = c[0] - c[1] + c[2] - c[3];
    let scale = e1.length().max(e2.length());
    let (mut s, mut t) = (0.5, 0.5);
    for _ in 0..32 {
        let r = c[0] + e1 * s + e2 * t + e3 * (s * t) - q;
        if r.length() <= 1e-13 * scale {
            return Some((s.clamp(0.0, 1.0), t.clamp(0.0, 1.0)));
        }
        let js = e1 + e3 * t;
        let jt = e2 + e3 * s;
        let det = js.perp_dot(jt);
        if det.abs() <= f64::EPSILON * scale * scale {
            return None;
        }
        // Cramer's rule for [js jt] [ds dt]^T = r.
        s -= r.perp_dot(jt) / det;
        t -= js.perp_dot(r) / det;
    }
    None
}

/// Mean value coordinates (Floater 2003) of `q` in a convex polygon, handling points on corners and edges.
fn mean_value_weights(c: &[DVec2], q: DVec2) -> Vec<f64> {
    let n = c.len();
    let d: Vec<DVec2> = c.iter().map(|&v| v - q).collect();
    let r: Vec<f64> = d.iter().map(|v| v.length()).collect();
    let scale = r.iter().copied().fold(0.0, f64::max);
    let mut w = vec![0.0; n];
    for i in 0..n {
        if r[i] <= 1e-12 * scale {
            w[i] = 1.0;
            return w;
        }
    }
    // tan(alpha_i / 2) for the angle alpha_i between d_i and d_{i+1}; on an edge (alpha = pi) interpolate linearly.
    let mut tan_half = vec![0.0; n];
    for i in 0..n {
        let j = (i + 1) % n;
        let cross = d[i].perp_dot(d[j]);
        let dot = d[i].dot(d[j]);
        if cross.abs() <= 1e-12 * r[i] * r[j] && dot < 0.0 {
            w[i] = r[j] / (r[i] + r[j]);
            w[j] = r[i] / (r[i] + r[j]);
            return w;
        }
        tan_half[i] = cross / (r[i] * r[j] + dot);
    }
    for i in 0..n {
        let prev = (i + n - 1) % n;
        w[i] = (tan_half[prev] + tan_half[i]) / r[i];
    }
    let total: f64 = w.iter().sum();
    w.iter().map(|x| x / total).collect()
}
