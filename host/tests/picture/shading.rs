//! Smooth shading: per-patch radiosity to per-vertex values and back to any point of a patch.

use glam::DVec3;
use radiosity_host::patch::Patch;
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::picture::PictureError;
use radiosity_host::rgb::Rgb;

use super::{assert_close, linear_field, polygon, sample_points, Plane};

// Tolerance for reproducing a linear field: the vertex weights solve a 3x3 weighted least-squares system whose
// condition number is bounded by the shader's spread test (eigenvalue ratio >= 1e-3, so cond <~ 1e4 after the
// offsets' scale) and whose right-hand sides are sums of up to ~20 values of size ~10; so the rounding error is
// about cond * 20 * 10 * eps ~ 1e4 * 200 * 2.2e-16 ~ 5e-10. Interpolation adds a few eps.
const LINEAR_TOL: f64 = 1e-9;

#[test]
fn smooth_shading_reproduces_a_linear_field_on_a_subdivided_plane() {
    let plane = Plane::tilted();
    // A non-uniform grid; cells on the diagonal are split into two triangles.
    let xs = [0.0, 1.0, 2.5, 3.0, 4.5, 6.0];
    let ys = [0.0, 0.7, 2.0, 3.1, 4.0];
    let mut patches = Vec::new();
    for i in 0..xs.len() - 1 {
        for j in 0..ys.len() - 1 {
            let c = [
                plane.at(xs[i], ys[j]),
                plane.at(xs[i + 1], ys[j]),
                plane.at(xs[i + 1], ys[j + 1]),
                plane.at(xs[i], ys[j + 1]),
            ];
            if i == j {
                patches.push(polygon(0, 0, vec![c[0], c[1], c[2]]));
                patches.push(polygon(0, 0, vec![c[0], c[2], c[3]]));
            } else {
                patches.push(polygon(0, 0, c.to_vec()));
            }
        }
    }
    let radiosity = assert_reproduces_linear_field(&patches);
    // The plain area-weighted mean would not do this at the border: the corner patch's own value is not f(corner).
    assert!((radiosity[0][0] - linear_field(patches[0].vertices[0])[0]).abs() > 0.1);
}

#[test]
fn smooth_shading_reproduces_a_linear_field_on_a_pentagon_fan() {
    // A convex pentagon (mean value coordinates) surrounded by triangles.
    let plane = Plane::tilted();
    let ring: Vec<(f64, f64)> = (0..5)
        .map(|i| {
            let a = std::f64::consts::TAU * f64::from(i) / 5.0;
            (2.0 * a.cos(), 1.6 * a.sin())
        })
        .collect();
    let mut patches = vec![polygon(3, 1, ring.iter().map(|&(s, t)| plane.at(s, t)).collect())];
    for i in 0..5 {
        let (a, b) = (ring[i], ring[(i + 1) % 5]);
        let out = ((a.0 + b.0) * 1.4, (a.1 + b.1) * 1.4);
        patches.push(polygon(3, 1, vec![plane.at(b.0, b.1), plane.at(a.0, a.1), plane.at(out.0, out.1)]));
    }
    // Triangles above were listed clockwise in (s, t) relative to the pentagon; make them counter-clockwise
    // consistent with the pentagon's normal.
    let n0 = patches[0].normal;
    for p in patches.iter_mut().skip(1) {
        if p.normal.dot(n0) < 0.0 {
            let mut v = p.vertices.clone();
            v.reverse();
            *p = polygon(p.face, p.material, v);
        }
    }
    assert_reproduces_linear_field(&patches);
}

/// Smooth shading of `patches` given the linear field at their centroids reproduces the field at every sample
/// point; returns the centroid values.
fn assert_reproduces_linear_field(patches: &[Patch]) -> Vec<Rgb> {
    let radiosity: Vec<Rgb> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(patches, &ShadingOptions::default()).unwrap();
    for (k, p) in patches.iter().enumerate() {
        for point in sample_points(p) {
            let got = shader.shade(&radiosity, k, point).unwrap();
            assert_close(got, linear_field(point), LINEAR_TOL, &format!("patch {k} at {point}"));
        }
    }
    radiosity
}

/// Two unit-height quads side by side in the z = 0 plane, left one 1 wide, right one 3 wide (areas 1 and 3).
fn side_by_side(material_right: usize) -> Vec<Patch> {
    let v = |x: f64, y: f64| DVec3::new(x, y, 0.0);
    vec![
        polygon(0, 0, vec![v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)]),
        polygon(1, material_right, vec![v(1.0, 0.0), v(4.0, 0.0), v(4.0, 1.0), v(1.0, 1.0)]),
    ]
}

#[test]
fn smooth_shading_does_not_blend_across_a_material_boundary() {
    let radiosity = [Rgb::new(1.0, 2.0, 3.0), Rgb::new(10.0, 20.0, 30.0)];
    let shared = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(1.0, 0.5, 0.0), DVec3::new(1.0, 1.0, 0.0)];
    let apart = SmoothShader::new(&side_by_side(1), &ShadingOptions::default()).unwrap();
    for &p in &shared {
        assert_close(
            apart.shade(&radiosity, 0, p).unwrap(),
            radiosity[0],
            1e-12,
            "left patch on the boundary",
        );
        assert_close(
            apart.shade(&radiosity, 1, p).unwrap(),
            radiosity[1],
            1e-12,
            "right patch on the boundary",
        );
    }
    // Control: with one material the shared vertices take the area-weighted mean (1 * 1 + 3 * 10) / 4 = 7.75
    // (two neighbours in a row do not span the plane, so the fit falls back to the mean).
    let joined = SmoothShader::new(&side_by_side(0), &ShadingOptions::default()).unwrap();
    let mean = Rgb::new(7.75, 15.5, 23.25);
    for &p in &shared {
        assert_close(joined.shade(&radiosity, 0, p).unwrap(), mean, 1e-12, "left patch, same material");
        assert_close(joined.shade(&radiosity, 1, p).unwrap(), mean, 1e-12, "right patch, same material");
    }
}

#[test]
fn smooth_shading_does_not_blend_across_a_90_degree_crease() {
    let v = DVec3::new;
    // A floor (normal +z) and a wall (normal +x) meeting along the y axis at x = 0, z = 0.
    let patches = vec![
        polygon(0, 0, vec![v(0.0, 0.0, 0.0), v(2.0, 0.0, 0.0), v(2.0, 1.0, 0.0), v(0.0, 1.0, 0.0)]),
        polygon(1, 0, vec![v(0.0, 0.0, 0.0), v(0.0, 1.0, 0.0), v(0.0, 1.0, 2.0), v(0.0, 0.0, 2.0)]),
    ];
    assert!(
        (patches[0].normal - DVec3::Z).length() < 1e-12 && (patches[1].normal - DVec3::X).length() < 1e-12
    );
    let radiosity = [Rgb::ONE, Rgb::splat(10.0)];
    let edge = [v(0.0, 0.0, 0.0), v(0.0, 0.5, 0.0), v(0.0, 1.0, 0.0)];
    let sharp = SmoothShader::new(&patches, &ShadingOptions { crease_angle_deg: 30.0, ..Default::default() })
        .unwrap();
    for &p in &edge {
        assert_close(sharp.shade(&radiosity, 0, p).unwrap(), Rgb::ONE, 1e-12, "floor at the crease");
        assert_close(sharp.shade(&radiosity, 1, p).unwrap(), Rgb::splat(10.0), 1e-12, "wall at the crease");
    }
    // Control: a crease angle above 90 degrees lets them blend (equal areas: mean 5.5).
    let soft = SmoothShader::new(&patches, &ShadingOptions { crease_angle_deg: 120.0, ..Default::default() })
        .unwrap();
    assert_close(
        soft.shade(&radiosity, 0, edge[1]).unwrap(),
        Rgb::splat(5.5),
        1e-12,
        "floor, crease allowed",
    );
}

#[test]
fn smooth_shading_welds_vertices_within_the_tolerance_only() {
    // The right quad's left edge is moved by 1e-9 (scene size ~4: relative 2.5e-10 < 1e-6): still welded.
    let mut patches = side_by_side(0);
    for vtx in patches[1].vertices.iter_mut().filter(|p| p.x == 1.0) {
        vtx.x += 1e-9;
    }
    let radiosity = [Rgb::ONE, Rgb::splat(10.0)];
    let welded = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let p = DVec3::new(1.0, 0.0, 0.0);
    assert!((welded.shade(&radiosity, 0, p).unwrap()[0] - 7.75).abs() < 1e-6);
    // With a gap of 1e-3 (relative 2.5e-4 > 1e-6) they are separate surfaces.
    let mut apart = side_by_side(0);
    for vtx in apart[1].vertices.iter_mut().filter(|p| p.x == 1.0) {
        vtx.x += 1e-3;
    }
    let apart = vec![apart[0].clone(), polygon(1, 0, apart[1].vertices.clone())];
    let separate = SmoothShader::new(&apart, &ShadingOptions::default()).unwrap();
    assert_close(separate.shade(&radiosity, 0, p).unwrap(), Rgb::ONE, 1e-12, "not welded");
}

#[test]
fn smooth_shading_rejects_bad_input() {
    let patches = side_by_side(0);
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    assert!(matches!(shader.shade(&[Rgb::ONE], 0, DVec3::ZERO), Err(PictureError::Invalid { .. })));
    assert!(matches!(shader.shade(&[Rgb::ONE; 2], 2, DVec3::ZERO), Err(PictureError::Invalid { .. })));
    let err =
        shader.shade(&[Rgb::ONE, Rgb::new(f64::NAN, 0.0, 0.0)], 0, DVec3::new(1.0, 0.0, 0.0)).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { index: 1, .. }), "{err}");
    let mut bad = patches.clone();
    bad[1].vertices.truncate(2);
    let err = SmoothShader::new(&bad, &ShadingOptions::default()).unwrap_err();
    assert!(err.to_string().contains("patch 1"), "{err}");
}

#[test]
fn smooth_shading_joins_slightly_warped_quadrilaterals_at_shared_corners() {
    // Two quads sharing an edge; the far corner of each is lifted 1e-3 off the plane (scene size ~4: far above the
    // 4e-6 weld tolerance), like the sub-quads of the Cornell box's warped red wall. They still share vertices.
    let v = DVec3::new;
    let patches = vec![
        polygon(0, 0, vec![v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0), v(0.0, 1.0, 1e-3)]),
        polygon(1, 0, vec![v(1.0, 0.0, 0.0), v(2.0, 0.0, 0.0), v(2.0, 1.0, 1e-3), v(1.0, 1.0, 0.0)]),
    ];
    let radiosity = [Rgb::ONE, Rgb::splat(3.0)];
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    // Equal areas: the shared corners take the mean, 2.
    for p in [v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0)] {
        assert_close(
            shader.shade(&radiosity, 0, p).unwrap(),
            Rgb::splat(2.0),
            1e-9,
            "left quad at a shared corner",
        );
        assert_close(
            shader.shade(&radiosity, 1, p).unwrap(),
            Rgb::splat(2.0),
            1e-9,
            "right quad at a shared corner",
        );
    }
}
