//! The smooth field (`SmoothShader`: radiosity interpolated across patches) sampled around a point, for the
//! tests that check what a light map or an engine shows against it (`render.rs`, `export.rs`).

use glam::DVec3;
use radiosity_host::picture::shading::SmoothShader;
use radiosity_host::rgb::Rgb;

/// The smooth field on the patches `on` at `q`: the shader on the first of them whose polygon contains `q` (`None`
/// when none does).
pub fn field_at(shader: &SmoothShader, b: &[Rgb], on: &[usize], q: DVec3) -> Option<Rgb> {
    let inside = on.iter().find(|&&m| shader.distance_in_plane(m, q) <= shader.tolerance())?;
    Some(shader.shade(b, *inside, q).unwrap())
}

/// Per-channel range (lowest, highest) of the smooth field over the points of the patches `on` within `reach` of
/// `q` in the plane spanned by the unit vectors `u` and `v`: `q` itself and 6 rings of 24 directions (points on
/// none of `on` are left out).
pub fn field_range(
    shader: &SmoothShader,
    b: &[Rgb],
    on: &[usize],
    q: DVec3,
    (u, v): (DVec3, DVec3),
    reach: f64,
) -> (Rgb, Rgb) {
    let (mut lo, mut hi) = (Rgb::INFINITY, Rgb::NEG_INFINITY);
    let mut add = |x: DVec3| {
        if let Some(f) = field_at(shader, b, on, x) {
            lo = lo.min(f);
            hi = hi.max(f);
        }
    };
    add(q);
    for ring in 1..=6 {
        let r = reach * f64::from(ring) / 6.0;
        for k in 0..24 {
            let a = std::f64::consts::TAU * f64::from(k) / 24.0;
            add(q + (u * a.cos() + v * a.sin()) * r);
        }
    }
    (lo, hi)
}
