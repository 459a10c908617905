//! Light-map atlases: every face mapped without overlap, uncovered texels filled, bad input refused.

use glam::DVec3;
use radiosity_host::patch::Patch;
use radiosity_host::picture::lightmap::{bake_light_map, LightMapOptions};
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::rgb::Rgb;

use super::{assert_close, decode_png, linear_field, polygon, scratch_dir, Plane};

/// A closed box [0,4]x[0,3]x[0,2] with inward normals; faces 0 and 1 meshed into 2x2 patches. Materials per face.
fn box_patches() -> Vec<Patch> {
    let v = DVec3::new;
    let quads = [
        [v(0.0, 0.0, 0.0), v(4.0, 0.0, 0.0), v(4.0, 3.0, 0.0), v(0.0, 3.0, 0.0)], // floor z = 0
        [v(0.0, 0.0, 2.0), v(4.0, 0.0, 2.0), v(4.0, 3.0, 2.0), v(0.0, 3.0, 2.0)], // ceiling z = 2
        [v(0.0, 0.0, 0.0), v(0.0, 0.0, 2.0), v(0.0, 3.0, 2.0), v(0.0, 3.0, 0.0)], // x = 0
        [v(4.0, 0.0, 0.0), v(4.0, 3.0, 0.0), v(4.0, 3.0, 2.0), v(4.0, 0.0, 2.0)], // x = 4
        [v(0.0, 0.0, 0.0), v(4.0, 0.0, 0.0), v(4.0, 0.0, 2.0), v(0.0, 0.0, 2.0)], // y = 0
        [v(0.0, 3.0, 0.0), v(0.0, 3.0, 2.0), v(4.0, 3.0, 2.0), v(4.0, 3.0, 0.0)], // y = 3
    ];
    let mut patches = Vec::new();
    let inward = |mut vs: Vec<DVec3>| {
        let p = polygon(0, 0, vs.clone());
        if p.normal.dot(DVec3::new(2.0, 1.5, 1.0) - p.centroid) < 0.0 {
            vs.reverse();
        }
        vs
    };
    for (face, q) in quads.iter().enumerate() {
        if face < 2 {
            let at = |s: f64, t: f64| q[0] + (q[1] - q[0]) * s + (q[3] - q[0]) * t;
            for i in 0..2 {
                for j in 0..2 {
                    let (s0, s1, t0, t1) = (
                        f64::from(i) / 2.0,
                        f64::from(i + 1) / 2.0,
                        f64::from(j) / 2.0,
                        f64::from(j + 1) / 2.0,
                    );
                    patches.push(polygon(
                        face,
                        face % 3,
                        inward(vec![at(s0, t0), at(s0, t1), at(s1, t1), at(s1, t0)]),
                    ));
                }
            }
        } else {
            patches.push(polygon(face, face % 3, inward(q.to_vec())));
        }
    }
    patches
}

#[test]
fn light_map_maps_every_face_without_overlap() {
    let patches = box_patches();
    for p in &patches {
        let inward = DVec3::new(2.0, 1.5, 1.0) - p.centroid;
        assert!(p.normal.dot(inward) > 0.0, "test box: face {} normal points outward", p.face);
    }
    let radiosity: Vec<Rgb> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let options = LightMapOptions { texel_size: Some(0.25), padding: 2, ..Default::default() };
    let map = bake_light_map(&patches, &shader, &radiosity, &options).unwrap();
    let json = map.to_json("a.exr", "a.hdr", "a.png");
    let faces = json["faces"].as_array().unwrap();
    let mut seen: Vec<u64> = faces.iter().map(|f| f["face"].as_u64().unwrap()).collect();
    seen.sort_unstable();
    assert_eq!(seen, (0..6).collect::<Vec<u64>>(), "every face mapped exactly once");
    let (aw, ah) = (json["atlas"]["width"].as_u64().unwrap(), json["atlas"]["height"].as_u64().unwrap());
    let pad = json["padding"].as_u64().unwrap();
    let rects: Vec<[u64; 4]> = faces
        .iter()
        .map(|f| {
            let g = |k: &str| f[k].as_u64().unwrap();
            [g("x") - pad, g("y") - pad, g("width") + 2 * pad, g("height") + 2 * pad]
        })
        .collect();
    for (i, a) in rects.iter().enumerate() {
        assert!(a[0] + a[2] <= aw && a[1] + a[3] <= ah, "face {i} padded rectangle {a:?} outside {aw}x{ah}");
        for (j, b) in rects.iter().enumerate().skip(i + 1) {
            let disjoint =
                a[0] + a[2] <= b[0] || b[0] + b[2] <= a[0] || a[1] + a[3] <= b[1] || b[1] + b[3] <= a[1];
            assert!(disjoint, "faces {i} and {j} overlap: {a:?} {b:?}");
        }
    }
    // Sizes follow the texel size: the floor is 4 x 3 -> 16 x 12 texels (in some orientation).
    let floor = &map.rects[0];
    let mut dims = [floor.width, floor.height];
    dims.sort_unstable();
    assert_eq!(dims, [12, 16]);
    // Texels hold the shaded field at their centres: check via the JSON frame of every face.
    for r in &map.rects {
        let (u, v, o) = (r.u_axis, r.v_axis, r.origin);
        assert!(u.dot(v).abs() < 1e-12 && (u.cross(v) + r.normal).length() < 1e-12);
        for (i, j) in [(0, 0), (r.width - 1, r.height - 1), (r.width / 2, r.height / 3)] {
            let centre =
                o + u * ((f64::from(i) + 0.5) * r.texel_size) + v * ((f64::from(j) + 0.5) * r.texel_size);
            let (ax, ay) = r.atlas_coords(centre);
            assert!(
                (ax - f64::from(r.x + i) - 0.5).abs() < 1e-9 && (ay - f64::from(r.y + j) - 0.5).abs() < 1e-9
            );
            let texel = map.atlas.pixels[((r.y + j) * map.atlas.width + r.x + i) as usize];
            // Faces meshed into 2x2 patches reproduce the linear field: each texel is f(centre) up to the shading
            // tolerance and the f32 rounding of the atlas (values ~10: 10 * 2^-24 ~ 6e-7). A face that is a single
            // patch with no compatible neighbour (the walls: other material or across a crease) is flat.
            let expected = if r.patches > 1 {
                linear_field(centre)
            } else {
                let k = patches.iter().position(|p| p.face == r.face).unwrap();
                radiosity[k]
            };
            assert_close(
                Rgb::from_array(texel.map(f64::from)),
                expected,
                1e-6,
                &format!("face {} texel ({i}, {j})", r.face),
            );
        }
    }
    // Files: the PNG has the atlas size, the HDR reads back, the JSON parses.
    let dir = scratch_dir("lightmap");
    let [exr, hdr, png_path, json_path] = map.write(&dir.join("box"), None).unwrap();
    let (w, h, _) = decode_png(&std::fs::read(&png_path).unwrap());
    assert_eq!((u64::from(w), u64::from(h)), (aw, ah));
    let back = radiosity_host::picture::hdr::read_hdr(&hdr).unwrap();
    assert_eq!((back.width, back.height), (w, h));
    // The EXR holds the atlas exactly (f32 channels, lossless).
    assert_eq!(radiosity_host::picture::hdr::read_exr(&exr).unwrap(), map.atlas);
    let parsed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(parsed["faces"].as_array().unwrap().len(), 6);
    assert_eq!(parsed["atlas"]["png"], "box.png");
}

/// A square face meshed as two triangles along its diagonal, the first patch's first edge being that diagonal: the
/// chart is still the square (its frame follows the smallest rectangle around the face, not that edge), 8 x 8
/// texels of 0.5 for a side of 4, not the 12 x 6 of a frame along the diagonal.
#[test]
fn light_map_chart_frame_follows_the_smallest_rectangle() {
    let plane = Plane::tilted();
    let (a, b, c, d) = (plane.at(0.0, 0.0), plane.at(4.0, 0.0), plane.at(4.0, 4.0), plane.at(0.0, 4.0));
    let patches = vec![polygon(0, 0, vec![a, c, d]), polygon(0, 0, vec![c, a, b])];
    let radiosity: Vec<Rgb> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let options = LightMapOptions { texel_size: Some(0.5), padding: 1, ..Default::default() };
    let map = bake_light_map(&patches, &shader, &radiosity, &options).unwrap();
    let r = &map.rects[0];
    assert_eq!((r.width, r.height), (8, 8), "frame u = {}", r.u_axis);
    // Both triangles are one face, one chart: every texel of the rectangle lies on the square.
    for (i, j) in [(0, 0), (7, 0), (0, 7), (7, 7)] {
        let centre =
            r.origin + r.u_axis * ((f64::from(i) + 0.5) * 0.5) + r.v_axis * ((f64::from(j) + 0.5) * 0.5);
        assert!(
            (0..2).any(|k| shader.distance_in_plane(k, centre) == 0.0),
            "corner texel ({i}, {j}) off the face"
        );
    }
}

#[test]
fn light_map_refuses_a_face_without_patches() {
    let mut patches = box_patches();
    patches.retain(|p| p.face != 3);
    let radiosity = vec![Rgb::ONE; patches.len()];
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let err = bake_light_map(&patches, &shader, &radiosity, &LightMapOptions::default()).unwrap_err();
    assert!(err.to_string().contains("face 3 has no patch"), "{err}");
}

#[test]
fn light_map_of_a_triangle_fills_the_uncovered_texels_from_the_nearest_patch() {
    // One triangular face split at its edge midpoints into four triangles; a linear field.
    let plane = Plane::tilted();
    let (a, b, c) = (plane.at(0.0, 0.0), plane.at(4.0, 0.0), plane.at(1.0, 3.0));
    let (ab, bc, ca) = ((a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0);
    let tris = [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]];
    let patches: Vec<Patch> = tris.iter().map(|t| polygon(0, 0, t.to_vec())).collect();
    let radiosity: Vec<Rgb> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let options = LightMapOptions { texel_size: Some(0.125), padding: 3, ..Default::default() };
    let map = bake_light_map(&patches, &shader, &radiosity, &options).unwrap();
    assert_eq!(map.rects.len(), 1);
    let r = &map.rects[0];
    let corners = [a, b, c].map(linear_field);
    let (mut inside, mut outside) = (0, 0);
    for j in 0..r.height + 2 * map.padding {
        for i in 0..r.width + 2 * map.padding {
            let (x, y) = (r.x + i - map.padding, r.y + j - map.padding);
            let texel = Rgb::from_array(map.atlas.pixels[(y * map.atlas.width + x) as usize].map(f64::from));
            let (fi, fj) =
                (f64::from(i) - f64::from(map.padding) + 0.5, f64::from(j) - f64::from(map.padding) + 0.5);
            let centre = r.origin + r.u_axis * (fi * r.texel_size) + r.v_axis * (fj * r.texel_size);
            if (0..4).any(|k| shader.distance_in_plane(k, centre) == 0.0) {
                // Covered texels: the field itself (f32 atlas: values ~10, rounding 6e-7).
                assert_close(texel, linear_field(centre), 1e-6, &format!("texel ({i}, {j})"));
                inside += 1;
            } else {
                // Uncovered texels: a point of the triangle, so within the field's range over its corners.
                for ch in 0..3 {
                    let lo = corners.iter().map(|f| f[ch]).fold(f64::INFINITY, f64::min);
                    let hi = corners.iter().map(|f| f[ch]).fold(f64::NEG_INFINITY, f64::max);
                    assert!(texel[ch] >= lo - 1e-6 && texel[ch] <= hi + 1e-6, "texel ({i}, {j}) = {texel:?}");
                }
                outside += 1;
            }
        }
    }
    // The triangle covers about half its bounding rectangle (area 6 of 12 units^2 = 384 of 768 texels).
    assert!(inside > 300 && outside > 300, "{inside} covered, {outside} uncovered texels");
}
