//! Points on a patch: the product Gauss-Legendre rule of the unoccluded form factors, the area-preserving
//! map of stratified points that the visibility rays start and end on, and cosine-distributed directions (the
//! escape rays; the path tracer of [`crate::montecarlo`] uses the same points and directions).

use glam::DVec3;

use crate::rng::SplitMix64;

/// Maps the unit square onto a convex polygon, preserving area (uniform in, uniform out), so a stratified set
/// in the square is a stratified set on the polygon.
#[derive(Clone, Debug)]
pub(crate) struct PolygonSampler {
    /// Parallelograms: `v0 + s (v1 - v0) + t (v3 - v0)`, exact strata.
    parallelogram: Option<[DVec3; 3]>,
    /// Otherwise: fan triangles `(v0, v_k, v_{k+1})` with their cumulative area fractions.
    fan: Vec<([DVec3; 3], f64)>,
}

impl PolygonSampler {
    /// The sampler of the convex polygon `v` (at least 3 vertices, nonzero area).
    pub(crate) fn new(v: &[DVec3]) -> Self {
        let size = v.iter().map(|p| (*p - v[0]).length()).fold(0.0, f64::max);
        if v.len() == 4 && (v[0] + v[2] - v[1] - v[3]).length() <= 1e-12 * size {
            return Self { parallelogram: Some([v[0], v[1] - v[0], v[3] - v[0]]), fan: Vec::new() };
        }
        let areas: Vec<f64> =
            (1..v.len() - 1).map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length()).collect();
        let total: f64 = areas.iter().sum();
        let mut cumulative = 0.0;
        let fan = (1..v.len() - 1)
            .zip(&areas)
            .map(|(k, a)| {
                cumulative += a / total;
                ([v[0], v[k], v[k + 1]], cumulative)
            })
            .collect();
        Self { parallelogram: None, fan }
    }

    /// The point for `(s, t)` in the open unit square.
    pub(crate) fn point(&self, s: f64, t: f64) -> DVec3 {
        if let Some([o, a, b]) = self.parallelogram {
            return o + a * s + b * t;
        }
        let mut lower = 0.0;
        for (k, (tri, upper)) in self.fan.iter().enumerate() {
            if s < *upper || k + 1 == self.fan.len() {
                // Rescale s within this triangle's share, then the area-preserving square-to-triangle map
                // (Shirley 1990; Turk, "Generating random points in triangles", Graphics Gems 1990).
                let u = ((s - lower) / (upper - lower)).clamp(0.0, 1.0);
                let r = u.sqrt();
                return tri[0] * (1.0 - r) + tri[1] * (r * (1.0 - t)) + tri[2] * (r * t);
            }
            lower = *upper;
        }
        self.fan[0].0[0]
    }

    /// `count` stratified points: a jittered `a × b` grid with `a * b >= count`; returns all `a * b` of them.
    pub(super) fn stratified(&self, count: usize, rng: &mut SplitMix64, out: &mut Vec<DVec3>) {
        let (a, b) = grid(count);
        out.clear();
        for row in 0..b {
            for col in 0..a {
                let s = (col as f64 + rng.open_unit()) / a as f64;
                let t = (row as f64 + rng.open_unit()) / b as f64;
                out.push(self.point(s, t));
            }
        }
    }
}

/// Gauss-Legendre nodes and weights on (0, 1), `n >= 1`: the roots of the Legendre polynomial `P_n` by Newton's
/// method from Tricomi's initial guesses `cos(π (k - 1/4) / (n + 1/2))`, weights `2 / ((1 - x²) P_n'(x)²)`
/// (Abramowitz and Stegun 25.4.29), mapped from (-1, 1).
pub(super) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut rule = Vec::with_capacity(n);
    for k in 1..=n {
        let mut x = (std::f64::consts::PI * (k as f64 - 0.25) / (n as f64 + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            // P_n(x) by the three-term recurrence, then P_n'(x) = n (x P_n - P_{n-1}) / (x² - 1).
            let (mut p_prev, mut p) = (1.0, x);
            for m in 2..=n {
                let next = ((2 * m - 1) as f64 * x * p - (m - 1) as f64 * p_prev) / m as f64;
                p_prev = p;
                p = next;
            }
            if n == 1 {
                p_prev = 1.0;
            }
            derivative = n as f64 * (x * p - p_prev) / (x * x - 1.0);
            let step = p / derivative;
            x -= step;
            if step.abs() <= 1e-15 {
                break;
            }
        }
        let weight = 2.0 / ((1.0 - x * x) * derivative * derivative);
        rule.push(((x + 1.0) / 2.0, weight / 2.0));
    }
    rule
}

/// Quadrature points on a patch with weights summing to 1 (area fractions).
#[derive(Clone, Debug)]
pub(super) struct Quadrature {
    pub(super) points: Vec<DVec3>,
    pub(super) weights: Vec<f64>,
}

impl Quadrature {
    /// The product rule `rule × rule` on a parallelogram, or on each fan triangle `(v0, v_k, v_{k+1})` through the
    /// collapsed map `v0 + s (v_k - v0) + s t (v_{k+1} - v_k)` (Jacobian `2 area_k s`) otherwise.
    pub(super) fn new(v: &[DVec3], rule: &[(f64, f64)]) -> Self {
        let mut points = Vec::new();
        let mut weights = Vec::new();
        let size = v.iter().map(|p| (*p - v[0]).length()).fold(0.0, f64::max);
        if v.len() == 4 && (v[0] + v[2] - v[1] - v[3]).length() <= 1e-12 * size {
            let (a, b) = (v[1] - v[0], v[3] - v[0]);
            for &(s, ws) in rule {
                for &(t, wt) in rule {
                    points.push(v[0] + a * s + b * t);
                    weights.push(ws * wt);
                }
            }
            return Self { points, weights };
        }
        let areas: Vec<f64> =
            (1..v.len() - 1).map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length()).collect();
        let total: f64 = areas.iter().sum();
        for (k, area) in (1..v.len() - 1).zip(&areas) {
            for &(s, ws) in rule {
                for &(t, wt) in rule {
                    points.push(v[0] + (v[k] - v[0]) * s + (v[k + 1] - v[k]) * (s * t));
                    weights.push(ws * wt * 2.0 * area * s / total);
                }
            }
        }
        Self { points, weights }
    }
}

/// An orthonormal tangent frame `(t1, t2)` around the unit normal `n`, with `t1 × t2 = n` (J. R. Frisvad's
/// construction without its singularity: T. Duff et al., "Building an orthonormal basis, revisited", JCGT 2017).
pub(crate) fn tangent_frame(n: DVec3) -> (DVec3, DVec3) {
    let sign = 1.0f64.copysign(n.z);
    let c = -1.0 / (sign + n.z);
    let d = n.x * n.y * c;
    let t1 = DVec3::new(1.0 + sign * n.x * n.x * c, sign * d, -sign * n.x);
    let t2 = DVec3::new(d, sign + n.y * n.y * c, -n.y);
    (t1, t2)
}

/// The cosine-distributed direction (density `cos θ / π` over the hemisphere of `n`) for `(s, t)` in the unit
/// square, `s < 1`: a uniform point of the unit disc (`r = √s`, `φ = 2π t`) lifted to the hemisphere (Malley's
/// method; e.g. Pharr, Jakob, Humphreys, *Physically Based Rendering*, 13.6.3). Unit length up to rounding;
/// `(t1, t2)` is the [`tangent_frame`] of `n`.
pub(crate) fn cosine_direction(n: DVec3, (t1, t2): (DVec3, DVec3), s: f64, t: f64) -> DVec3 {
    let (r, phi) = (s.sqrt(), std::f64::consts::TAU * t);
    t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * (1.0 - s).max(0.0).sqrt()
}

/// The smallest near-square grid `a × b >= count`.
pub(crate) fn grid(count: usize) -> (usize, usize) {
    let a = (count as f64).sqrt().round().max(1.0) as usize;
    (a, count.div_ceil(a))
}
