//! Rendering the real Cornell box (real form factors, f64 solve) and checking from the pixels what a person would
//! see; the light-map atlas of the same solve.

mod common;

use common::field::{field_at, field_range};

use std::path::PathBuf;
use std::sync::OnceLock;

use glam::DVec3;
use radiosity_host::picture::camera::Camera;
use radiosity_host::picture::render::View;
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::picture::tonemap::srgb_decode;
use radiosity_host::picture::write_png;
use radiosity_host::pipeline::Prepared;
use radiosity_host::rgb::{luminance, Rgb};
use radiosity_host::view::{
    render_view, solve_default, write_light_map, PatchTracer, RenderMode, RenderOptions, LEGEND_HEIGHT,
};

const SIZE: u32 = 64;

/// The coarse Cornell box of `common` and its f64 solution, prepared once for the whole file.
fn cornell() -> &'static (Prepared, Vec<Rgb>) {
    static CELL: OnceLock<(Prepared, Vec<Rgb>)> = OnceLock::new();
    CELL.get_or_init(|| {
        let p = common::coarse_cornell();
        let b = solve_default(&p).unwrap();
        (p, b)
    })
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("render");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The coarse Cornell box with radiosity `b` rendered `SIZE` x `SIZE` from the default camera in `mode`, and
/// written to the scratch file `name` for a person to look at.
fn render_to(b: &[Rgb], mode: RenderMode<'_>, name: &str) -> View {
    let options = RenderOptions { camera: None, width: SIZE, height: SIZE, mode };
    let view = render_view(cornell().0.surfaces(), b, &options).unwrap();
    write_png(&scratch(name), &view.image).unwrap();
    view
}

fn material_name(p: &Prepared, patch: usize) -> &str {
    &p.scene.materials[p.patches[patch].material].name
}

/// Linear luminance of an 8-bit sRGB pixel (what the viewer's screen shows, up to the display's scale).
fn pixel_luminance(rgb: [u8; 3]) -> f64 {
    luminance(Rgb::from_array(rgb.map(|c| srgb_decode(f64::from(c) / 255.0))))
}

#[test]
fn cornell_box_looks_right() {
    let (p, b) = cornell();
    let view = render_to(b, RenderMode::Shaded, "cornell-shaded.png");
    assert_eq!((view.image.width, view.image.height), (SIZE, SIZE));

    // The published camera sees the box's open side: most of the picture is the box.
    let visible = view.patch.iter().filter(|p| p.is_some()).count();
    assert!(visible > (SIZE * SIZE / 2) as usize, "only {visible} of {} pixels see the box", SIZE * SIZE);

    // Every pixel that sees a surface is finite and not black: every surface of the closed room behind the open
    // side receives at least indirect light, so a black pixel would be a shading or tone-mapping fault.
    for (k, (lin, patch)) in view.linear.iter().zip(&view.patch).enumerate() {
        assert!(lin.is_finite(), "pixel {k}: radiosity {lin:?}");
        if patch.is_some() {
            let px = view.image.get(k as u32 % SIZE, k as u32 / SIZE);
            assert_ne!(px, [0, 0, 0], "pixel {k} sees patch {patch:?} but is black");
        }
    }

    // Every pixel of the red wall is red-dominant and every pixel of the green wall green-dominant (smooth
    // shading never blends across a material boundary, so no pixel of a wall carries another wall's colour).
    let mut red = 0;
    let mut green = 0;
    for (k, patch) in view.patch.iter().enumerate() {
        let Some(patch) = patch else { continue };
        let [r, g, bl] = view.image.get(k as u32 % SIZE, k as u32 / SIZE);
        match material_name(p, *patch as usize) {
            "red" => {
                red += 1;
                assert!(r > g && r > bl, "red wall pixel {k} is {:?}", [r, g, bl]);
            }
            "green" => {
                green += 1;
                assert!(g > r && g > bl, "green wall pixel {k} is {:?}", [r, g, bl]);
            }
            _ => {}
        }
    }
    // Each side wall covers a strip of roughly 1/8 of the picture width from this camera.
    assert!(red > 50 && green > 50, "red wall {red} pixels, green wall {green} pixels");

    // The floor below the light against the ceiling's far corners. Hit points come from the same tracer and
    // camera as the render, so each pixel is classified by where its ray lands.
    let tracer = PatchTracer::new(&p.patches).unwrap();
    let camera = Camera::cornell_box();
    let mut under_light = Vec::new();
    let mut far_corners = Vec::new();
    for k in 0..SIZE * SIZE {
        let (x, y) = (k % SIZE, k / SIZE);
        let (o, d) = camera.ray(x, y, SIZE, SIZE);
        let Some(hit) = tracer.closest_hit(o, d) else { continue };
        assert_eq!(
            Some(hit.patch as u32),
            view.patch[k as usize],
            "pixel {k}: tracer differs from the render"
        );
        let n = p.patches[hit.patch].normal;
        let q = hit.point;
        let lum = pixel_luminance(view.image.get(x, y));
        // The light spans x 213..343, z 227..332 at y 548.8 (scenes/cornell-box.obj); floor at y = 0.
        if n.dot(DVec3::Y) > 0.99
            && q.y < 1.0
            && (213.0..=343.0).contains(&q.x)
            && (227.0..=332.0).contains(&q.z)
        {
            under_light.push(lum);
        }
        // Ceiling (y = 548.8, normal down) within 100 mm of the back wall (z = 559.2) and a side wall.
        if n.dot(DVec3::NEG_Y) > 0.99 && q.y > 548.0 && q.z > 459.0 && !(100.0..=456.0).contains(&q.x) {
            far_corners.push(lum);
        }
    }
    assert!(!under_light.is_empty() && !far_corners.is_empty(), "{under_light:?} {far_corners:?}");
    let floor_min = under_light.iter().copied().fold(f64::INFINITY, f64::min);
    let corner_max = far_corners.iter().copied().fold(0.0, f64::max);
    assert!(
        floor_min > corner_max,
        "floor below the light (darkest pixel {floor_min:.4}) is not brighter than the ceiling's far corners \
         (brightest pixel {corner_max:.4})"
    );
}

/// The flat view (`render --mode flat`, what the browser viewer draws): every pixel shows its patch's own
/// radiosity, tone mapped with the view's tone map, so every patch is one colour.
#[test]
fn flat_view_shows_each_patch_radiosity() {
    let (_, b) = cornell();
    let view = render_to(b, RenderMode::Flat, "cornell-flat.png");
    let tone = view.tone.unwrap();
    let mut seen = 0;
    for (k, patch) in view.patch.iter().enumerate() {
        let Some(patch) = patch else { continue };
        assert_eq!(view.linear[k], b[*patch as usize], "pixel {k}");
        assert_eq!(
            view.image.get(k as u32 % SIZE, k as u32 / SIZE),
            tone.map_srgb8(b[*patch as usize]).unwrap()
        );
        seen += 1;
    }
    assert!(seen > (SIZE * SIZE / 2) as usize, "only {seen} pixels see the box");
}

#[test]
fn patch_and_error_views() {
    let (_, b) = cornell();
    let view = render_to(b, RenderMode::Patches, "cornell-patches.png");
    // Neighbouring patches get distinct colours, so the mesh shows: many distinct colours in the picture.
    let mut colours: Vec<[u8; 3]> = (0..SIZE * SIZE).map(|k| view.image.get(k % SIZE, k / SIZE)).collect();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 20, "only {} colours in the by-patch view", colours.len());

    // Error view: the reference is `b`, the rendered values are `b` with one visible patch doubled. That patch's
    // pixels must show the largest error colour, every other patch the zero-error colour, and the legend is below.
    let target = view.patch.iter().flatten().copied().nth(SIZE as usize * 10).unwrap() as usize;
    let mut wrong = b.clone();
    wrong[target] = wrong[target].map(|v| 2.0 * v);
    let err = render_to(&wrong, RenderMode::Error { reference: b }, "cornell-error.png");
    assert_eq!(err.image.height, SIZE + LEGEND_HEIGHT);
    let scale = err.error_scale.unwrap();
    for (k, patch) in err.patch.iter().enumerate() {
        let Some(patch) = patch else { continue };
        let px = err.image.get(k as u32 % SIZE, k as u32 / SIZE);
        let expected = if *patch as usize == target { scale.colour(1.0) } else { scale.colour(0.0) };
        assert_eq!(px, expected, "pixel {k} on patch {patch}");
    }
    assert_ne!(scale.colour(1.0), scale.colour(0.0));
}

#[test]
fn light_map_maps_every_face() {
    let (p, b) = cornell();
    let stem = scratch("cornell-lightmap");
    let paths = write_light_map(p.surfaces(), b, &stem, &Default::default()).unwrap().paths;
    for path in &paths {
        assert!(std::fs::metadata(path).unwrap().len() > 0, "{} is empty", path.display());
    }
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&paths[3]).unwrap()).unwrap();
    let width = json["atlas"]["width"].as_u64().unwrap();
    let height = json["atlas"]["height"].as_u64().unwrap();
    let faces = json["faces"].as_array().unwrap();
    let mut seen = vec![false; p.scene.faces.len()];
    for f in faces {
        let face = f["face"].as_u64().unwrap() as usize;
        assert!(face < seen.len() && !seen[face], "face {face} out of range or mapped twice");
        seen[face] = true;
        let (x, y, w, h) = (
            f["x"].as_u64().unwrap(),
            f["y"].as_u64().unwrap(),
            f["width"].as_u64().unwrap(),
            f["height"].as_u64().unwrap(),
        );
        assert!(
            w > 0 && h > 0 && x + w <= width && y + h <= height,
            "face {face}: rect {x},{y} {w}x{h} in {width}x{height}"
        );
    }
    let missing: Vec<usize> = seen.iter().enumerate().filter(|(_, s)| !**s).map(|(i, _)| i).collect();
    assert!(missing.is_empty(), "faces without a light-map rectangle: {missing:?}");
}

/// Points of a patch where a filter is tried: its corners, three points on every edge, and its centroid.
fn probe_points(patch: &radiosity_host::patch::Patch) -> Vec<DVec3> {
    let n = patch.vertices.len();
    let mut out = vec![patch.centroid];
    for k in 0..n {
        let (a, c) = (patch.vertices[k], patch.vertices[(k + 1) % n]);
        out.extend([0.0, 0.25, 0.5, 0.75].map(|t| a + (c - a) * t));
    }
    out
}

/// The Cornell box's atlas filtered as a GPU does (bilinear, no mip maps) at points all over every face, corners
/// and edges included: the filter reads only texels of the face's own padded chart rectangle (never an unused texel
/// or another chart's), and the value lies within the smooth field's range over the filter's reach on the chart, so
/// gutters hold the chart's own light (a black or foreign gutter texel at a face's edge or corner pulls the value
/// out of that range). The reach: the four texel centres read lie within sqrt(2) texels of the point, and a gutter
/// texel holds the field at the nearest point of a patch, at most 1.5 texels further (half a texel of gutter plus
/// the under-one-texel gap between the face and its rectangle's rounded-up side): 3 texels in all.
/// The four ceiling faces around the light (one plane, one material, sharing edges) are one chart, so both
/// sides of every edge between them read the same texels: no seam (drawn as four charts, the two sides of an
/// edge differed by up to 9% of the value at a corner of the light, in the 12 mm texels of this test); the
/// light, the floor and the walls are charts of their own.
#[test]
fn light_map_filtering_stays_in_each_chart_and_agrees_across_coplanar_faces() {
    use radiosity_host::picture::lightmap::{bake_light_map, Footprint, LightMapOptions};
    let (p, b) = cornell();
    let shader = SmoothShader::new(&p.patches, &ShadingOptions::default()).unwrap();
    let map = bake_light_map(&p.patches, &shader, b, &LightMapOptions::default()).unwrap();
    let reach = 3.0 * map.texel_size;
    let peak = b.iter().fold(0.0f64, |m, v| m.max(v.max_element()));
    let members =
        |face: usize| -> Vec<usize> { (0..p.patches.len()).filter(|&i| p.patches[i].face == face).collect() };
    let within = |s: Rgb, (lo, hi): (Rgb, Rgb)| {
        // Slack: the rings sample the disc, not every point of it (a quarter of the range), and the atlas is f32.
        let slack = (hi - lo) * 0.25 + Rgb::splat(1e-6 * peak);
        s.cmpge(lo - slack).all() && s.cmple(hi + slack).all()
    };
    let mut probes = 0;
    for rect in &map.rects {
        let (px, py, pw, ph) = rect.padded(map.padding);
        // The field's range is taken over the whole chart: a texel in a hole of the chart (the ceiling's light)
        // holds the nearest of the chart's patches, which may belong to a neighbouring face of the chart.
        let chart: Vec<usize> =
            map.rects.iter().filter(|r| r.chart == rect.chart).flat_map(|r| members(r.face)).collect();
        for &m in &members(rect.face) {
            for q in probe_points(&p.patches[m]) {
                let (ax, ay) = rect.atlas_coords(q);
                let footprint = Footprint::at(ax, ay);
                for (&(x, y), &w) in footprint.texels.iter().zip(&footprint.weights) {
                    let inside = x >= i64::from(px)
                        && y >= i64::from(py)
                        && x < i64::from(px + pw)
                        && y < i64::from(py + ph);
                    assert!(
                        w == 0.0 || inside,
                        "face {}: filter at {q} reads texel ({x}, {y}) outside its padded rectangle {:?}",
                        rect.face,
                        rect.padded(map.padding)
                    );
                }
                let s = map.bilinear(ax, ay);
                let range = field_range(&shader, b, &chart, q, (rect.u_axis, rect.v_axis), reach);
                assert!(
                    within(s, range),
                    "face {} at {q}: filtered {s} outside the field's range {range:?} over {reach} mm",
                    rect.face
                );
                probes += 1;
            }
        }
    }
    assert!(probes > 1000, "only {probes} points probed");
    // Seams between the four ceiling faces around the light (faces 2..=5: one plane, one material).
    let ceiling: Vec<usize> = (2..=5).collect();
    let rect_of = |face: usize| map.rects.iter().find(|r| r.face == face).unwrap();
    let mut seam_points = 0;
    let mut worst_seam = 0.0f64;
    for &fa in &ceiling {
        for &m in &members(fa) {
            for q in probe_points(&p.patches[m]).into_iter().skip(1) {
                for &fb in ceiling.iter().filter(|&&f| f != fa) {
                    let on_b = members(fb);
                    if field_at(&shader, b, &on_b, q).is_none() {
                        continue;
                    }
                    let (ra, rb) = (rect_of(fa), rect_of(fb));
                    let (xa, ya) = ra.atlas_coords(q);
                    let (xb, yb) = rb.atlas_coords(q);
                    let (sa, sb) = (map.bilinear(xa, ya), map.bilinear(xb, yb));
                    // Only the f64 rounding of the two faces' (identical) frames may differ.
                    let allowed = Rgb::splat(1e-9 * peak);
                    assert!(
                        (sa - sb).abs().cmple(allowed).all(),
                        "faces {fa} and {fb} at {q}: {sa} vs {sb} (allowed {allowed})"
                    );
                    worst_seam = worst_seam.max(((sa - sb).abs() / sa.max(sb)).max_element());
                    seam_points += 1;
                }
            }
        }
    }
    assert!(seam_points > 10, "only {seam_points} points on edges shared by ceiling faces");
    let chart = |face: usize| rect_of(face).chart;
    assert!(ceiling.iter().all(|&f| chart(f) == chart(2)), "the ceiling is not one chart");
    let others: Vec<usize> = [0, 1, 6, 7, 8].map(chart).to_vec();
    assert!(
        others.iter().enumerate().all(|(i, c)| *c != chart(2) && !others[..i].contains(c)),
        "floor, light, back, green and red walls share charts: {others:?}"
    );
    eprintln!(
        "{probes} points probed, {seam_points} on ceiling seams (largest relative difference between the two \
         faces' samples {worst_seam:.2e}); texel {:.2} mm",
        map.texel_size
    );
}
