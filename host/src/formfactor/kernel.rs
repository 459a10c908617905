//! The exact point-to-polygon kernel: Lambert's contour integral over a polygon clipped to the half-space above
//! a point's tangent plane, with the fast `edge_angle` it takes per edge, and the polygon helpers it shares with
//! the quadrature.

use glam::DVec3;

/// Exact form factor from a differential area at `x` with unit normal `normal` to the convex `polygon` whose
/// front side faces `polygon_normal`, ignoring occlusion.
///
/// Lambert's contour integral (see the module docs for references) over `polygon` clipped to the half-space
/// `normal · (y - x) >= 0`. Zero if `x` is not strictly in front of the polygon's plane.
#[must_use]
pub fn point_to_polygon(x: DVec3, normal: DVec3, polygon: &[DVec3], polygon_normal: DVec3) -> f64 {
    // Grown (allocated) only if the polygon has to be clipped.
    let mut scratch = Vec::new();
    point_to_polygon_with(x, normal, polygon, polygon_normal, &mut scratch)
}

/// [`point_to_polygon`] with a caller's buffer for the clipped polygon (no allocation once it has grown).
pub(crate) fn point_to_polygon_with(
    x: DVec3,
    normal: DVec3,
    polygon: &[DVec3],
    polygon_normal: DVec3,
    clipped: &mut Vec<DVec3>,
) -> f64 {
    let Some(&p0) = polygon.first() else { return 0.0 };
    let offset = x - p0;
    // Strictly in front, with a relative tolerance so points coplanar with the polygon (up to rounding) get 0.
    if polygon_normal.dot(offset) <= 1e-12 * offset.length() {
        return 0.0;
    }
    // Sutherland-Hodgman clip against the tangent plane at x: keep h = normal · (y - x) >= 0. A polygon wholly
    // above the plane (the common case) is its own clip.
    let height = |y: DVec3| normal.dot(y - x);
    let vertices: &[DVec3] = if polygon.iter().all(|&y| height(y) >= 0.0) {
        polygon
    } else {
        clip_above(polygon, height, clipped);
        clipped
    };
    let Some(&first) = vertices.first() else { return 0.0 };
    if vertices.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    let mut r0 = first - x;
    for &v in vertices[1..].iter().chain(std::iter::once(&first)) {
        let r1 = v - x;
        let c = r0.cross(r1);
        let c_len = c.length();
        if c_len != 0.0 {
            // (Zero: x is on the edge's line and the edge subtends no angle; x on the edge itself is excluded
            // above.)
            sum += edge_angle(c_len, r0.dot(r1)) * normal.dot(c) / c_len;
        }
        r0 = r1;
    }
    // The clipped polygon lies wholly above x's tangent plane and in front of itself, so every part of the
    // contour integral has the same sign; the orientation of the vertex order only flips that sign.
    sum.abs() / std::f64::consts::TAU
}

/// `atan2(y, x)` for `y >= 0`: the angle in `[0, π]` between two vectors from `y = |a × b|` and `x = a · b`.
///
/// The contour sum takes one per polygon edge and sample point, where the platform's `atan2` was a large share
/// of the bake's profile. This one reduces the argument to `|u| <= tan(π/16)` (swap to
/// `t = min/max <= 1`, then `atan t = c + atan((t - tan c) / (1 + t tan c))` for `c` in `{0, π/8, π/4}`, one
/// division in all) and sums the Taylor series `u - u³/3 + u⁵/5 - ...` through `u²¹/21`: the first omitted term
/// is below `tan(π/16)^22 / 23 = 1.6e-17` of `u`, so the result is within a few rounding errors of the exact
/// angle (the unit test bounds it at 4 ulp against `f64::atan2`). `y = x = 0` gives 0; NaN
/// gives NaN.
#[inline]
pub(super) fn edge_angle(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_8, PI};
    /// `tan(π/16)` and `tan(3π/16)`: the bounds between the three reduction centres.
    const TAN_PI_16: f64 = 0.198_912_367_379_658;
    const TAN_3PI_16: f64 = 0.668_178_637_919_298_9;
    /// `tan(π/8) = √2 - 1`.
    const TAN_PI_8: f64 = 0.414_213_562_373_095_05;
    let ax = x.abs();
    let swapped = y > ax;
    let (num, den) = if swapped { (ax, y) } else { (y, ax) };
    if den == 0.0 {
        return 0.0;
    }
    // With t = num / den: (t - tan c) / (1 + t tan c) = (num - den tan c) / (den + num tan c), one division.
    let (centre, top, bottom) = if num <= TAN_PI_16 * den {
        (0.0, num, den)
    } else if num <= TAN_3PI_16 * den {
        (FRAC_PI_8, num - TAN_PI_8 * den, den + TAN_PI_8 * num)
    } else {
        (FRAC_PI_4, num - den, num + den)
    };
    let u = top / bottom;
    // atan u = u + u³ p(u²), p(z) = Σ_{m=0..9} (-1)^(m+1) z^m / (2m + 3), in Estrin's form (a shallower
    // dependency chain than Horner's).
    let z = u * u;
    let (z2, z4) = (z * z, z * z * (z * z));
    let q0 = -1.0 / 3.0 + z * (1.0 / 5.0);
    let q1 = -1.0 / 7.0 + z * (1.0 / 9.0);
    let q2 = -1.0 / 11.0 + z * (1.0 / 13.0);
    let q3 = -1.0 / 15.0 + z * (1.0 / 17.0);
    let q4 = -1.0 / 19.0 + z * (1.0 / 21.0);
    let p = (q0 + q1 * z2) + (q2 + q3 * z2) * z4 + q4 * (z4 * z4);
    let a = centre + (u + u * z * p);
    let a = if swapped { FRAC_PI_2 - a } else { a };
    if x < 0.0 {
        PI - a
    } else {
        a
    }
}

/// Sutherland-Hodgman: writes to `out` the part of the convex `polygon` where `height >= 0` (cut points linear
/// in the height along each crossing edge).
pub(super) fn clip_above(polygon: &[DVec3], height: impl Fn(DVec3) -> f64, out: &mut Vec<DVec3>) {
    out.clear();
    for (k, &a) in polygon.iter().enumerate() {
        let b = polygon[if k + 1 == polygon.len() { 0 } else { k + 1 }];
        let (ha, hb) = (height(a), height(b));
        if ha >= 0.0 {
            out.push(a);
        }
        if (ha >= 0.0) != (hb >= 0.0) {
            out.push(a + (b - a) * (ha / (ha - hb)));
        }
    }
}

/// Area of a planar polygon.
pub(super) fn polygon_area(polygon: &[DVec3]) -> f64 {
    let mut twice = DVec3::ZERO;
    for (k, &a) in polygon.iter().enumerate() {
        twice += a.cross(polygon[(k + 1) % polygon.len()]);
    }
    0.5 * twice.length()
}

#[cfg(test)]
mod tests {
    use super::edge_angle;

    /// Within 4 ulp of `f64::atan2` (relative to the angle) over angles from 1e-300 to π and lengths over 40
    /// decades: the argument reduction and the sum each round a few times, and the series' truncation is 1.6e-17
    /// of the reduced argument (see `edge_angle`).
    #[test]
    fn edge_angle_matches_atan2() {
        let mut worst: f64 = 0.0;
        let mut check = |y: f64, x: f64| {
            let (got, want) = (edge_angle(y, x), y.atan2(x));
            let err = (got - want).abs() / (want.abs() * f64::EPSILON).max(f64::MIN_POSITIVE);
            assert!(err <= 4.0, "edge_angle({y:e}, {x:e}) = {got:e}, atan2 {want:e}: {err:.1} ulp");
            worst = worst.max(err);
        };
        let steps = 200_000;
        for k in 0..=steps {
            let theta = std::f64::consts::PI * f64::from(k) / f64::from(steps);
            for scale in [1e-20, 1e-3, 1.0, 7.5e2, 1e20] {
                check(scale * theta.sin().abs(), scale * theta.cos());
            }
        }
        for e in -300..=0 {
            let tiny = 10f64.powi(e);
            check(tiny, 1.0);
            check(tiny, -1.0);
            check(1.0, tiny);
            check(1.0, -tiny);
        }
        assert_eq!(edge_angle(0.0, 0.0), 0.0);
        assert_eq!(edge_angle(0.0, 2.0), 0.0);
        assert_eq!(edge_angle(0.0, -2.0), std::f64::consts::PI);
        assert!(edge_angle(f64::NAN, 1.0).is_nan());
        // The bound is not loose by orders of magnitude: the reduction rounds, so some angles are off by an ulp.
        assert!(worst >= 0.5, "worst {worst} ulp");
    }
}
