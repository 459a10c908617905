//! Views of a Cornell box through the camera, and a frame sequence that shares one exposure.

use glam::DVec3;
use radiosity_host::patch::Patch;
use radiosity_host::picture::render::Hit;
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::rgb::luminance;
use radiosity_host::rgb::Rgb;

use super::{decode_png, polygon, scratch_dir};

/// The Cornell box from the published data (shared/data/cornell-box.md) as patches: every quad split into
/// `n x n` bilinear sub-quads; the ceiling as four quads around the light's opening. Materials: 0 white, 1 red,
/// 2 green, 3 light. Returns the patches and their reflectances.
fn cornell_box(n: usize) -> (Vec<Patch>, Vec<Rgb>) {
    let v = DVec3::new;
    let white = (0, [0.725, 0.71, 0.68]);
    let red = (1, [0.63, 0.065, 0.05]);
    let green = (2, [0.14, 0.45, 0.091]);
    let light = (3, [0.78, 0.78, 0.78]);
    let y = 548.8;
    let mut quads = vec![
        (white, [v(552.8, 0.0, 0.0), v(0.0, 0.0, 0.0), v(0.0, 0.0, 559.2), v(549.6, 0.0, 559.2)]),
        (light, [v(343.0, y, 227.0), v(343.0, y, 332.0), v(213.0, y, 332.0), v(213.0, y, 227.0)]),
        (white, [v(556.0, y, 0.0), v(556.0, y, 227.0), v(0.0, y, 227.0), v(0.0, y, 0.0)]),
        (white, [v(556.0, y, 332.0), v(556.0, y, 559.2), v(0.0, y, 559.2), v(0.0, y, 332.0)]),
        (white, [v(556.0, y, 227.0), v(556.0, y, 332.0), v(343.0, y, 332.0), v(343.0, y, 227.0)]),
        (white, [v(213.0, y, 227.0), v(213.0, y, 332.0), v(0.0, y, 332.0), v(0.0, y, 227.0)]),
        (white, [v(549.6, 0.0, 559.2), v(0.0, 0.0, 559.2), v(0.0, y, 559.2), v(556.0, y, 559.2)]),
        (green, [v(0.0, 0.0, 559.2), v(0.0, 0.0, 0.0), v(0.0, y, 0.0), v(0.0, y, 559.2)]),
        (red, [v(552.8, 0.0, 0.0), v(549.6, 0.0, 559.2), v(556.0, y, 559.2), v(556.0, y, 0.0)]),
        (
            white,
            [v(130.0, 165.0, 65.0), v(82.0, 165.0, 225.0), v(240.0, 165.0, 272.0), v(290.0, 165.0, 114.0)],
        ),
        (
            white,
            [v(423.0, 330.0, 247.0), v(265.0, 330.0, 296.0), v(314.0, 330.0, 456.0), v(472.0, 330.0, 406.0)],
        ),
    ];
    let short = [v(290.0, 0.0, 114.0), v(130.0, 0.0, 65.0), v(82.0, 0.0, 225.0), v(240.0, 0.0, 272.0)];
    let short_top =
        [v(290.0, 165.0, 114.0), v(130.0, 165.0, 65.0), v(82.0, 165.0, 225.0), v(240.0, 165.0, 272.0)];
    let tall = [v(423.0, 0.0, 247.0), v(472.0, 0.0, 406.0), v(314.0, 0.0, 456.0), v(265.0, 0.0, 296.0)];
    let tall_top =
        [v(423.0, 330.0, 247.0), v(472.0, 330.0, 406.0), v(314.0, 330.0, 456.0), v(265.0, 330.0, 296.0)];
    for (b, t) in [(short, short_top), (tall, tall_top)] {
        for i in 0..4 {
            let j = (i + 1) % 4;
            // Published order for the sides: bottom i, top i, top j, bottom j (normal out of the block).
            quads.push((white, [b[i], t[i], t[j], b[j]]));
        }
    }
    let mut patches = Vec::new();
    let mut rho = Vec::new();
    for (face, ((material, reflectance), q)) in quads.iter().enumerate() {
        let at = |s: f64, t: f64| {
            q[0] * ((1.0 - s) * (1.0 - t)) + q[1] * (s * (1.0 - t)) + q[2] * (s * t) + q[3] * ((1.0 - s) * t)
        };
        let m = if *material == 3 { 1 } else { n };
        for i in 0..m {
            for j in 0..m {
                let (s0, s1) = (i as f64 / m as f64, (i + 1) as f64 / m as f64);
                let (t0, t1) = (j as f64 / m as f64, (j + 1) as f64 / m as f64);
                patches.push(polygon(face, *material, vec![at(s0, t0), at(s1, t0), at(s1, t1), at(s0, t1)]));
                rho.push(Rgb::from_array(*reflectance));
            }
        }
    }
    (patches, rho)
}

/// Brute-force closest hit against convex polygons (front and back faces).
fn closest_hit(patches: &[Patch], origin: DVec3, dir: DVec3) -> Option<Hit> {
    let mut best: Option<(f64, Hit)> = None;
    for (k, p) in patches.iter().enumerate() {
        let denom = dir.dot(p.normal);
        if denom.abs() < 1e-12 {
            continue;
        }
        let t = (p.vertices[0] - origin).dot(p.normal) / denom;
        if t <= 1e-6 || best.is_some_and(|(bt, _)| t >= bt) {
            continue;
        }
        let x = origin + dir * t;
        let n = p.vertices.len();
        // Inside if on the inner side of every edge (edges counter-clockwise about the normal); the sub-quads of
        // the slightly warped red wall are planar to ~0.05 mm, far below the 0.5 mm slack.
        let inside = (0..n).all(|i| {
            let (a, b) = (p.vertices[i], p.vertices[(i + 1) % n]);
            (b - a).cross(x - a).dot(p.normal) >= -0.5 * (b - a).length()
        });
        if inside {
            best = Some((t, Hit { patch: k, point: x }));
        }
    }
    best.map(|(_, h)| h)
}

/// A radiosity-like proxy for view tests (not a solution): emission on the light, then direct light from the
/// light's centre with cosines, inverse square and shadow rays, plus a small ambient term, times reflectance.
fn proxy_radiosity(patches: &[Patch], rho: &[Rgb]) -> Vec<Rgb> {
    let light: Vec<usize> = (0..patches.len()).filter(|&k| patches[k].material == 3).collect();
    let centre = patches[light[0]].centroid;
    let light_normal = patches[light[0]].normal;
    let area: f64 = light.iter().map(|&k| patches[k].area).sum();
    let emission = 40.0;
    patches
        .iter()
        .enumerate()
        .map(|(k, p)| {
            if p.material == 3 {
                return Rgb::splat(emission);
            }
            let d = centre - p.centroid;
            let r2 = d.length_squared();
            let dir = d / r2.sqrt();
            let cos_i = dir.dot(p.normal).max(0.0);
            let cos_l = (-dir).dot(light_normal).max(0.0);
            let visible =
                closest_hit(patches, p.centroid + p.normal * 1e-3, dir).is_none_or(|h| h.patch == light[0]);
            let irradiance =
                if visible { emission * area * cos_i * cos_l / (std::f64::consts::PI * r2) } else { 0.0 };
            rho[k].map(|r| r * (irradiance + 0.1))
        })
        .collect()
}

/// [`cornell_box`] with `n x n` sub-quads, its proxy radiosity and a smooth shader over its patches.
fn lit_cornell_box(n: usize) -> (Vec<Patch>, Vec<Rgb>, SmoothShader) {
    let (patches, rho) = cornell_box(n);
    let radiosity = proxy_radiosity(&patches, &rho);
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    (patches, radiosity, shader)
}

#[test]
fn cornell_box_view_looks_right() {
    use radiosity_host::picture::camera::Camera;
    use radiosity_host::picture::render::{render, Colouring, Frame};
    let (patches, radiosity, shader) = lit_cornell_box(4);
    let frame = Frame { camera: Camera::cornell_box(), width: 96, height: 96 };
    let trace = |o: DVec3, d: DVec3| closest_hit(&patches, o, d);
    let view = render(&frame, &trace, &shader, &radiosity, Colouring::Shaded, None).unwrap();
    let dir = scratch_dir("views");
    radiosity_host::picture::write_png(&dir.join("cornell-shaded.png"), &view.image).unwrap();
    let (w, h) = (frame.width as usize, frame.height as usize);
    let pixel =
        |k: usize| view.image.pixels[3 * k..3 * k + 3].iter().map(|&b| f64::from(b)).collect::<Vec<_>>();
    let (mut red_cols, mut green_cols, mut floor_under, mut ceiling_far) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for k in 0..w * h {
        assert!(view.linear[k].is_finite(), "pixel {k} not finite");
        let Some(p) = view.patch[k] else { continue };
        let (patch, c) = (&patches[p as usize], pixel(k));
        // No black pixel where a surface is visible: the proxy's ambient term lights every surface.
        assert!(c.iter().sum::<f64>() > 0.0, "pixel ({}, {}) black on patch {p}", k % w, k / w);
        let x = view.linear[k];
        match patch.material {
            1 => {
                assert!(c[0] > c[1] && c[0] > c[2], "red wall pixel ({}, {}) is {c:?}", k % w, k / w);
                red_cols.push(k % w);
            }
            2 => {
                assert!(c[1] > c[0] && c[1] > c[2], "green wall pixel ({}, {}) is {c:?}", k % w, k / w);
                green_cols.push(k % w);
            }
            _ => {}
        }
        let centroid = patch.centroid;
        // Floor patches (about 138 mm across) whose centres are within a patch of the light's footprint.
        if patch.face == 0 && (150.0..400.0).contains(&centroid.x) && (150.0..420.0).contains(&centroid.z) {
            floor_under.push(luminance(x));
        }
        if (2..6).contains(&patch.face) && centroid.z > 450.0 && !(100.0..456.0).contains(&centroid.x) {
            ceiling_far.push(luminance(x));
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mean_col = |v: &[usize]| v.iter().sum::<usize>() as f64 / v.len() as f64;
    assert!(
        red_cols.len() > 100 && green_cols.len() > 100,
        "walls barely visible: {} {}",
        red_cols.len(),
        green_cols.len()
    );
    // The published camera sees the red wall (x ~ 550) on the left and the green wall (x = 0) on the right.
    assert!(mean_col(&red_cols) < w as f64 / 3.0 && mean_col(&green_cols) > 2.0 * w as f64 / 3.0);
    assert!(!floor_under.is_empty() && !ceiling_far.is_empty());
    assert!(
        mean(&floor_under) > 2.0 * mean(&ceiling_far),
        "floor {} vs ceiling {}",
        mean(&floor_under),
        mean(&ceiling_far)
    );

    // By patch: neighbouring patches differ, and the image is not shaded.
    let by_patch = render(&frame, &trace, &shader, &radiosity, Colouring::ByPatch, None).unwrap();
    radiosity_host::picture::write_png(&dir.join("cornell-patches.png"), &by_patch.image).unwrap();
    assert!(by_patch.tone.is_none());
    // Error view: one patch of the floor is off by 10%; its pixels are at the bright end, all others at the dark end.
    let mut wrong = radiosity.clone();
    let target = patches.iter().position(|p| p.face == 0).unwrap() + 5;
    wrong[target] = wrong[target].map(|c| c * 1.1);
    let error = render(
        &frame,
        &trace,
        &shader,
        &wrong,
        Colouring::Error { reference: &radiosity, scale: None },
        None,
    )
    .unwrap();
    radiosity_host::picture::write_png(&dir.join("cornell-error.png"), &error.image).unwrap();
    let scale = error.error_scale.unwrap();
    assert!((scale.max - 0.1).abs() < 1e-12, "largest relative error {}", scale.max);
    let mut seen = 0;
    for k in 0..w * h {
        let Some(p) = error.patch[k] else { continue };
        let c = &error.image.pixels[3 * k..3 * k + 3];
        let expected = if p as usize == target { scale.colour(0.1) } else { scale.colour(0.0) };
        assert_eq!(c, expected, "pixel {k} on patch {p}");
        seen += usize::from(p as usize == target);
    }
    assert!(seen > 0, "the wrong patch is not visible");
    radiosity_host::picture::write_png(
        &dir.join("cornell-error-legend.png"),
        &scale.legend("relative error", 320, 64).unwrap(),
    )
    .unwrap();
}

#[test]
fn frame_sequence_shares_one_exposure() {
    use radiosity_host::picture::camera::Camera;
    use radiosity_host::picture::render::{colour_view, trace_view, write_frame_sequence, Colouring, Frame};
    let (patches, converged, shader) = lit_cornell_box(2);
    let frame = Frame { camera: Camera::cornell_box(), width: 40, height: 30 };
    let hits = trace_view(&frame, &|o, d| closest_hit(&patches, o, d)).unwrap();
    // A device converging: frame k has (k + 1) / 4 of the converged radiosity.
    let frames: Vec<Vec<Rgb>> =
        (0..4).map(|k| converged.iter().map(|b| b.map(|c| c * f64::from(k + 1) / 4.0)).collect()).collect();
    let dir = scratch_dir("frames");
    let (paths, tone) = write_frame_sequence(&hits, &shader, &frames, None, &dir, "relight").unwrap();
    assert_eq!(paths.len(), 4);
    assert!(paths[3].ends_with("relight-0003.png"), "{:?}", paths[3]);
    let last = colour_view(&hits, &shader, &converged, Colouring::Shaded, None).unwrap();
    assert_eq!(Some(tone), last.tone, "the sequence uses the last frame's exposure");
    let mut previous = -1.0;
    for (k, path) in paths.iter().enumerate() {
        let (w, h, pixels) = decode_png(&std::fs::read(path).unwrap());
        assert_eq!((w, h), (40, 30));
        let mean = pixels.iter().map(|&b| f64::from(b)).sum::<f64>() / pixels.len() as f64;
        assert!(mean > previous, "frame {k} (mean {mean}) is not brighter than the one before ({previous})");
        previous = mean;
        if k == 3 {
            assert_eq!(pixels, last.image.pixels, "the last frame is the converged view");
        }
    }
    assert!(write_frame_sequence(&hits, &shader, &[], None, &dir, "x").is_err());
}
