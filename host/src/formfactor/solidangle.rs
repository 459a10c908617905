//! Points of a polygon drawn uniformly in the solid angle it subtends from a point: where a nearby sender's kernel
//! `cos θ_y / r²` is concentrated, the occlusion rays go. Spherical triangles are sampled by Arvo's area-preserving
//! map ("Stratified sampling of spherical triangles", SIGGRAPH 1995), so stratified unit-square samples stay
//! stratified in solid angle; a triangle's solid angle is Van Oosterom and Strackee's formula ("The solid angle of
//! a plane triangle", IEEE Trans. Biomed. Eng. 1983).

use glam::DVec3;

/// The solid angle of the triangle `(a, b, c)` seen from `x` (steradians, 0 from its plane).
pub(super) fn triangle_solid_angle(x: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (a, b, c) = (a - x, b - x, c - x);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c)).abs();
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    let omega = 2.0 * numerator.atan2(denominator);
    if omega.is_finite() {
        omega.max(0.0)
    } else {
        0.0
    }
}

/// A direction from the origin of the unit vectors `a`, `b`, `c` (a spherical triangle of area `omega`), uniform
/// in solid angle for `(u, v)` uniform in the unit square (Arvo 1995); `None` where the triangle is degenerate.
fn spherical_triangle_direction(a: DVec3, b: DVec3, c: DVec3, omega: f64, u: f64, v: f64) -> Option<DVec3> {
    // The angle at vertex a, between the great circles through (a, b) and (a, c).
    let (nab, nac) = (a.cross(b).try_normalize()?, a.cross(c).try_normalize()?);
    let cos_alpha = nab.dot(nac).clamp(-1.0, 1.0);
    let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
    if sin_alpha <= 0.0 {
        return None;
    }
    let alpha = cos_alpha.acos();
    let cos_c = a.dot(b).clamp(-1.0, 1.0);
    // The sub-triangle of area u * omega fixes the third vertex c' on the arc from a to c.
    let area = u * omega;
    let (s, t) = (area - alpha).sin_cos();
    let uu = t - cos_alpha;
    let vv = s + sin_alpha * cos_c;
    let q = (((vv * t - uu * s) * cos_alpha - vv) / ((vv * s + uu * t) * sin_alpha)).clamp(-1.0, 1.0);
    let c_perp = (c - c.dot(a) * a).try_normalize()?;
    let c_hat = q * a + (1.0 - q * q).max(0.0).sqrt() * c_perp;
    // Then uniformly along the arc from b to c' in the cosine of the angle from b.
    let z = (1.0 - v * (1.0 - c_hat.dot(b))).clamp(-1.0, 1.0);
    let towards = (c_hat - c_hat.dot(b) * b).try_normalize()?;
    (z * b + (1.0 - z * z).max(0.0).sqrt() * towards).try_normalize()
}

/// A point of the convex planar polygon `vertices` (normal `normal`) drawn uniformly in the solid angle it
/// subtends from `x`, for `(u, v)` uniform in the unit square, and that solid angle; `None` where it subtends
/// none (`x` in its plane) or the draw misses it by rounding.
pub(super) fn polygon_point(
    x: DVec3,
    vertices: &[DVec3],
    normal: DVec3,
    u: f64,
    v: f64,
) -> Option<(DVec3, f64)> {
    // The fan from the first vertex; each triangle's solid angle is recomputed in the second pass rather than
    // kept, so that polygons of any vertex count need no buffer.
    let triangles = vertices.len().checked_sub(2)?;
    let omega = |k: usize| triangle_solid_angle(x, vertices[0], vertices[k + 1], vertices[k + 2]);
    let total: f64 = (0..triangles).map(omega).sum();
    if total <= 0.0 || !total.is_finite() {
        return None;
    }
    // The triangle by its share of the solid angle, `u` rescaled within it.
    let mut pick = u * total;
    let mut k = 0;
    let mut chosen = omega(0);
    while k + 1 < triangles && pick >= chosen {
        pick -= chosen;
        k += 1;
        chosen = omega(k);
    }
    let u_in = (pick / chosen).clamp(0.0, 1.0);
    let (a, b, c) = (vertices[0], vertices[k + 1], vertices[k + 2]);
    let dir = |p: DVec3| (p - x).try_normalize();
    let direction = spherical_triangle_direction(dir(a)?, dir(b)?, dir(c)?, chosen, u_in, v)?;
    // Where the direction meets the polygon's plane.
    let along = normal.dot(direction);
    if along == 0.0 {
        return None;
    }
    let t = normal.dot(vertices[0] - x) / along;
    (t > 0.0 && t.is_finite()).then(|| (x + t * direction, total))
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::{polygon_point, triangle_solid_angle};
    use crate::rng::SplitMix64;

    /// A square of side `2a` centred at height `h` over the point subtends `4 asin(a^2 / (a^2 + h^2))`; drawn
    /// uniformly in solid angle, the share of draws that land in its centred inner square of side `a` is that
    /// square's solid angle over the whole one's. With n draws that share has standard error at most
    /// `sqrt(p (1 - p) / n)` (stratified draws do better), so 4 of them cannot be a false alarm.
    #[test]
    fn solid_angles_and_draws_match_closed_forms() {
        let (a, h) = (0.7, 0.4);
        let square = [DVec3::new(-a, -a, h), DVec3::new(a, -a, h), DVec3::new(a, a, h), DVec3::new(-a, a, h)];
        let exact = 4.0 * (a * a / (a * a + h * h)).asin();
        let x = DVec3::ZERO;
        let sum = triangle_solid_angle(x, square[0], square[1], square[2])
            + triangle_solid_angle(x, square[0], square[2], square[3]);
        assert!((sum - exact).abs() <= 1e-12 * exact, "{sum} vs {exact}");
        let inner = 4.0 * ((a * a / 4.0) / (a * a / 4.0 + h * h)).asin() / exact;
        let (side, mut hits, mut n) = (64usize, 0usize, 0usize);
        let mut rng = SplitMix64::new(7);
        for i in 0..side {
            for j in 0..side {
                let u = (i as f64 + rng.open_unit()) / side as f64;
                let v = (j as f64 + rng.open_unit()) / side as f64;
                let (p, omega) = polygon_point(x, &square, DVec3::Z, u, v).expect("a draw");
                assert!((omega - exact).abs() <= 1e-12 * exact);
                assert!((p.z - h).abs() <= 1e-12 && p.x.abs() <= a + 1e-12 && p.y.abs() <= a + 1e-12, "{p}");
                n += 1;
                if p.x.abs() <= a / 2.0 && p.y.abs() <= a / 2.0 {
                    hits += 1;
                }
            }
        }
        let fraction = hits as f64 / n as f64;
        let se = (inner * (1.0 - inner) / n as f64).sqrt();
        assert!((fraction - inner).abs() <= 4.0 * se, "{fraction} vs {inner} (se {se})");
        // From the polygon's own plane it subtends nothing.
        assert!(polygon_point(DVec3::new(3.0, 0.0, h), &square, DVec3::Z, 0.5, 0.5).is_none());
        // A polygon of many vertices (a regular 16-gon over the point): every draw lands on it, and its solid angle
        // is the fan's from another vertex order (triangles from the centre) to rounding.
        let n = 16;
        let ring: Vec<DVec3> = (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                DVec3::new(a * t.cos(), a * t.sin(), h)
            })
            .collect();
        let centre = DVec3::new(0.0, 0.0, h);
        let from_centre: f64 =
            (0..n).map(|k| triangle_solid_angle(x, centre, ring[k], ring[(k + 1) % n])).sum();
        for (u, v) in [(0.01, 0.5), (0.5, 0.5), (0.99, 0.3)] {
            let (p, omega) = polygon_point(x, &ring, DVec3::Z, u, v).expect("a draw on the 16-gon");
            assert!((omega - from_centre).abs() <= 1e-12 * from_centre, "{omega} vs {from_centre}");
            assert!((p.z - h).abs() <= 1e-12 && p.truncate().length() <= a + 1e-12, "{p}");
        }
    }
}
