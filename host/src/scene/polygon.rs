//! Planar convex polygons: the shape every validated face is made of and every patch is cut from.
//!
//! [`Polygon`] carries its unit normal, area and area centroid. The normal and area come from Newell's method
//! (the vector area, robust for any planar polygon), the centroid from a triangle fan.

use glam::DVec3;

/// A planar convex polygon with its unit normal, area and area centroid.
#[derive(Clone, Debug, PartialEq)]
pub struct Polygon {
    /// Vertices, counter-clockwise seen from the side the normal points to.
    pub vertices: Vec<DVec3>,
    /// Unit normal.
    pub normal: DVec3,
    /// Area.
    pub area: f64,
    /// Area centroid.
    pub centroid: DVec3,
}

impl Polygon {
    /// A polygon from its vertices, with the normal and area from Newell's method and the area centroid from a
    /// triangle fan. `None` if the area is zero or a value is not finite.
    #[must_use]
    pub fn new(vertices: Vec<DVec3>) -> Option<Polygon> {
        let n = newell(&vertices);
        let len = n.length();
        if !(len.is_finite() && len > 0.0) {
            return None;
        }
        let normal = n / len;
        Polygon::with_normal(vertices, normal)
    }

    /// A polygon from its vertices and a known unit normal (e.g. its parent's, so that pieces of a face keep the
    /// face's normal exactly). `None` if the area along `normal` is not positive or a value is not finite.
    #[must_use]
    pub fn with_normal(vertices: Vec<DVec3>, normal: DVec3) -> Option<Polygon> {
        let area = 0.5 * newell(&vertices).dot(normal);
        if !(area.is_finite() && area > 0.0) || vertices.len() < 3 {
            return None;
        }
        let centroid = area_centroid(&vertices, normal)?;
        Some(Polygon { vertices, normal, area, centroid })
    }

    /// Largest distance between two vertices.
    #[must_use]
    pub fn diameter(&self) -> f64 {
        diameter(&self.vertices)
    }

    /// Longest edge.
    #[must_use]
    pub fn max_edge(&self) -> f64 {
        edges(&self.vertices).map(|(a, b)| a.distance(b)).fold(0.0, f64::max)
    }
}

/// Twice the vector area of a polygon (Newell's method): for a planar polygon, the normal times twice the area.
pub(super) fn newell(v: &[DVec3]) -> DVec3 {
    // Newell's method (Sutherland, Sproull, Schumacker 1974): sum of cross products of consecutive vertices,
    // taken relative to the first vertex to limit cancellation.
    let Some(&o) = v.first() else { return DVec3::ZERO };
    let mut n = DVec3::ZERO;
    for (a, b) in edges(v) {
        n += (a - o).cross(b - o);
    }
    n
}

/// Area centroid of a planar polygon by a triangle fan from the first vertex.
fn area_centroid(v: &[DVec3], normal: DVec3) -> Option<DVec3> {
    let o = *v.first()?;
    let mut sum = DVec3::ZERO;
    let mut total = 0.0;
    for w in v.windows(2).skip(1) {
        let a = 0.5 * (w[0] - o).cross(w[1] - o).dot(normal);
        sum += a * (o + w[0] + w[1]) / 3.0;
        total += a;
    }
    if total > 0.0 && total.is_finite() {
        Some(sum / total)
    } else {
        None
    }
}

/// Consecutive vertex pairs, closing the loop.
fn edges(v: &[DVec3]) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
    v.iter().enumerate().map(move |(i, &a)| (a, v[(i + 1) % v.len()]))
}

/// Largest distance between two vertices.
pub(super) fn diameter(v: &[DVec3]) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in v.iter().enumerate() {
        for b in &v[i + 1..] {
            d = d.max(a.distance(*b));
        }
    }
    d
}
