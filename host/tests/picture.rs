//! Tests of the picture modules: tone mapping and sRGB, PNG / HDR / PFM files, smooth shading, light maps, the
//! false-colour ramp and its legend, and plots.

use std::path::PathBuf;

use glam::DVec3;
use radiosity_host::patch::Patch;
use radiosity_host::picture::colormap::{lab_to_linear_srgb, patch_colour, ramp, ramp_lab, ErrorScale};
use radiosity_host::picture::hdr::{
    decode_hdr, decode_pfm, encode_hdr, encode_pfm, memory_path, rgbe_decode, rgbe_encode, LinearImage,
};
use radiosity_host::picture::lightmap::{bake_light_map, LightMapOptions};
use radiosity_host::picture::plot::{Plot, Series};
use radiosity_host::picture::render::Hit;
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::picture::tonemap::{luminance, srgb_decode, srgb_encode, srgb_encode_u8};
use radiosity_host::picture::{encode_png, PictureError, RgbImage, ToneMap};

// ---------------------------------------------------------------------------------------------------------------
// Helpers

/// A patch from a counter-clockwise convex polygon (normal, area and centroid computed here).
fn polygon(face: usize, material: usize, vertices: Vec<DVec3>) -> Patch {
    let v0 = vertices[0];
    let mut twice_area = DVec3::ZERO;
    let mut weighted = DVec3::ZERO;
    for i in 1..vertices.len() - 1 {
        let c = (vertices[i] - v0).cross(vertices[i + 1] - v0);
        twice_area += c;
        weighted += (v0 + vertices[i] + vertices[i + 1]) / 3.0 * c.length();
    }
    let area = twice_area.length() / 2.0;
    Patch {
        face,
        material,
        normal: twice_area.normalize(),
        area,
        centroid: weighted / (2.0 * area),
        vertices,
    }
}

/// A directory for a test's files under Cargo's per-target scratch directory (kept, so pictures can be looked at).
fn scratch_dir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("picture").join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// A tilted plane frame in 3D: point of the plane at 2D coordinates (s, t).
struct Plane {
    origin: DVec3,
    a: DVec3,
    b: DVec3,
}

impl Plane {
    fn tilted() -> Self {
        let n = DVec3::new(0.3, -0.5, 0.8).normalize();
        let a = n.any_orthonormal_vector();
        Plane { origin: DVec3::new(10.0, -3.0, 7.0), a, b: n.cross(a) }
    }
    fn at(&self, s: f64, t: f64) -> DVec3 {
        self.origin + self.a * s + self.b * t
    }
}

/// A linear field, different per channel.
fn linear_field(p: DVec3) -> [f64; 3] {
    [
        5.0 + 0.3 * p.x - 0.2 * p.y + 0.1 * p.z,
        9.0 - 0.1 * p.x + 0.4 * p.y + 0.05 * p.z,
        7.0 + 0.2 * p.x + 0.1 * p.y - 0.3 * p.z,
    ]
}

fn assert_close(actual: [f64; 3], expected: [f64; 3], tol: f64, what: &str) {
    for ch in 0..3 {
        assert!(
            (actual[ch] - expected[ch]).abs() <= tol,
            "{what}: channel {ch}: got {}, expected {}, difference {:e} > tolerance {tol:e}",
            actual[ch],
            expected[ch],
            (actual[ch] - expected[ch]).abs()
        );
    }
}

/// Points inside a convex polygon: its corners, edge midpoints, the centroid, and blends towards corners.
fn sample_points(p: &Patch) -> Vec<DVec3> {
    let n = p.vertices.len();
    let mut pts = p.vertices.clone();
    for i in 0..n {
        pts.push((p.vertices[i] + p.vertices[(i + 1) % n]) / 2.0);
        pts.push(p.centroid * 0.7 + p.vertices[i] * 0.3);
        pts.push(p.centroid * 0.2 + p.vertices[i] * 0.5 + p.vertices[(i + 1) % n] * 0.3);
    }
    pts.push(p.centroid);
    pts
}

// ---------------------------------------------------------------------------------------------------------------
// Tone mapping and sRGB

#[test]
fn srgb_encodes_known_values() {
    assert_eq!(srgb_encode(0.0), 0.0);
    assert_eq!(srgb_encode_u8(0.0), 0);
    assert!((srgb_encode(1.0) - 1.0).abs() <= 4.0 * f64::EPSILON, "1.0 -> {}", srgb_encode(1.0));
    assert_eq!(srgb_encode_u8(1.0), 255);
    // The breakpoint belongs to the linear segment: 12.92 * 0.0031308 = 0.040449936.
    assert_eq!(srgb_encode(0.003_130_8), 12.92 * 0.003_130_8);
    // Just above it the power segment starts; IEC 61966-2-1's rounded constants make the two segments meet to
    // within about 1e-8 (a step far below one 8-bit level, 1/255).
    let above = srgb_encode(0.003_130_8 + 1e-12);
    assert!((above - 0.040_449_936).abs() < 1e-7, "power segment at the breakpoint: {above}");
    // 0.5 linear -> 0.7354 encoded -> 187.5 -> 188 (the value every sRGB table gives).
    assert!((srgb_encode(0.5) - 0.735_356_983_9).abs() < 1e-9, "0.5 -> {}", srgb_encode(0.5));
    assert_eq!(srgb_encode_u8(0.5), 188);
    assert_eq!(srgb_encode_u8(0.18), 118);
    // Out of range clamps; NaN maps to black.
    assert_eq!(srgb_encode_u8(-1.0), 0);
    assert_eq!(srgb_encode_u8(7.0), 255);
    assert_eq!(srgb_encode_u8(f64::NAN), 0);
    // decode inverts encode (both are smooth and monotone; rounding error a few ulps).
    for i in 0..=1000 {
        let x = f64::from(i) / 1000.0;
        assert!((srgb_decode(srgb_encode(x)) - x).abs() < 1e-12, "round trip at {x}");
    }
}

#[test]
fn tone_map_is_monotone_and_finite_from_0_to_1e6() {
    let tone = ToneMap::new(1.0 / 50.0, 4.0).unwrap();
    let mut previous = [-1.0; 3];
    let mut previous_y = -1.0;
    // 0, then 1e-6 .. 1e6 logarithmically (4 samples per decade of 12 decades... 100 per decade).
    let values = std::iter::once(0.0).chain((0..=1200).map(|i| 10f64.powf(-6.0 + f64::from(i) / 100.0)));
    for v in values {
        for colour in [[v, v, v], [v, 0.5 * v, 0.1 * v], [0.0, v, 0.0]] {
            let out = tone.map_linear(colour).unwrap();
            assert!(out.iter().all(|c| c.is_finite() && (0.0..=1.0).contains(c)), "{colour:?} -> {out:?}");
        }
        let grey = tone.map_linear([v, v, v]).unwrap();
        for ch in 0..3 {
            assert!(grey[ch] >= previous[ch], "not monotone at {v}: {grey:?} after {previous:?}");
        }
        let y = luminance(tone.map_linear([v, 0.5 * v, 0.1 * v]).unwrap());
        assert!(y >= previous_y, "coloured luminance not monotone at {v}");
        previous = grey;
        previous_y = y;
    }
    // The white point maps to exactly white: exposed luminance 4 -> L_d = 4 (1 + 4 / 16) / 5 = 1.
    let white = tone.map_linear([200.0; 3]).unwrap();
    assert_close(white, [1.0; 3], 1e-12, "white point");
    assert_eq!(tone.map_srgb8([200.0; 3]).unwrap(), [255; 3]);
    assert_eq!(tone.map_srgb8([0.0; 3]).unwrap(), [0; 3]);
    // Hue is kept below saturation: channel ratios survive.
    let c = tone.map_linear([10.0, 5.0, 1.0]).unwrap();
    assert!((c[1] / c[0] - 0.5).abs() < 1e-12 && (c[2] / c[0] - 0.1).abs() < 1e-12, "{c:?}");
}

#[test]
fn tone_map_refuses_nan_and_infinity() {
    let tone = ToneMap::new(1.0, 4.0).unwrap();
    assert!(matches!(tone.map_linear([0.0, f64::NAN, 1.0]), Err(PictureError::NonFinite { index: 1, .. })));
    assert!(matches!(
        tone.map_linear([f64::INFINITY, 0.0, 1.0]),
        Err(PictureError::NonFinite { index: 0, .. })
    ));
    let mut image = vec![[1.0; 3]; 6];
    image[4][2] = f64::NAN;
    let err = tone.map_image(&image, 3, 2).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { what: "pixel", index: 4, .. }), "{err}");
    assert!(err.to_string().contains("pixel 4"), "{err}");
    assert!(matches!(tone.map_image(&image, 4, 2), Err(PictureError::Invalid { .. })));
    let err = ToneMap::from_percentile(&[1.0, 2.0, f64::NAN], 0.9, 4.0).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { index: 2, .. }), "{err}");
    assert!(ToneMap::new(f64::NAN, 4.0).is_err());
    assert!(ToneMap::new(1.0, 0.5).is_err());
    assert!(ToneMap::from_percentile(&[], 0.9, 4.0).is_err());
}

#[test]
fn percentile_exposure_puts_the_percentile_on_exposed_luminance_one() {
    // Luminances 1..=100: the nearest-rank 95th percentile is 95.
    let lums: Vec<f64> = (1..=100).map(f64::from).collect();
    let tone = ToneMap::from_percentile(&lums, 0.95, 4.0).unwrap();
    assert!((tone.scale - 1.0 / 95.0).abs() < 1e-15, "scale {}", tone.scale);
    // Exposed luminance 1 displays as (1 + 1 / 16) / 2; four times the percentile is white.
    assert_close(tone.map_linear([95.0; 3]).unwrap(), [17.0 / 32.0; 3], 1e-12, "95th percentile");
    assert_close(tone.map_linear([4.0 * 95.0; 3]).unwrap(), [1.0; 3], 1e-12, "4x the 95th percentile");
    assert!(tone.map_linear([4.0 * 94.0; 3]).unwrap()[0] < 1.0);
    // An unlit scene has all zeros: scale 1, nothing fails.
    assert_eq!(ToneMap::from_percentile(&[0.0; 5], 0.95, 4.0).unwrap().scale, 1.0);
}

// ---------------------------------------------------------------------------------------------------------------
// Image files

#[test]
fn png_decodes_with_the_stated_size_and_pixels() {
    let mut image = RgbImage::new(7, 3);
    for y in 0..3 {
        for x in 0..7 {
            image.put(x, y, [(x * 30) as u8, (y * 80) as u8, 200]);
        }
    }
    let (w, h, pixels) = decode_png(&encode_png(&image).unwrap());
    assert_eq!((w, h), (7, 3));
    assert_eq!(pixels, image.pixels);
}

#[test]
fn hdr_round_trip_within_the_rgbe_quantization_step() {
    let (w, h) = (13u32, 5u32);
    let mut image = LinearImage::new(w, h);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        // Magnitudes 1e-4 .. 1e4 and unequal channels.
        let m = 10f32.powf(-4.0 + 8.0 * i as f32 / (w * h) as f32);
        *p = [m, m * 0.37, m * (i % 3) as f32 * 0.5];
    }
    image.pixels[0] = [0.0; 3];
    let bytes = encode_hdr(&image).unwrap();
    let back = decode_hdr(&bytes, &memory_path()).unwrap();
    assert_eq!((back.width, back.height), (w, h));
    for (i, (a, b)) in image.pixels.iter().zip(&back.pixels).enumerate() {
        // RGBE keeps 8 mantissa bits under the shared exponent of the largest channel: writing truncates and
        // reading takes the middle of the step, so each channel is within half a step, max/256 (module docs),
        // plus f32 rounding of the decoded value.
        let max = a.iter().copied().fold(0.0f32, f32::max);
        for ch in 0..3 {
            let tol = f64::from(max) / 256.0 * (1.0 + 1e-6);
            let d = (f64::from(a[ch]) - f64::from(b[ch])).abs();
            assert!(d <= tol, "pixel {i} channel {ch}: {} -> {} (difference {d:e} > {tol:e})", a[ch], b[ch]);
        }
    }
    // Zero stays exactly zero, and a header problem is named.
    assert_eq!(back.pixels[0], [0.0; 3]);
    let bad = decode_hdr(b"P6\n", &memory_path()).unwrap_err();
    assert!(bad.to_string().contains("#?RADIANCE"), "{bad}");
    let truncated = decode_hdr(&bytes[..bytes.len() - 10], &memory_path()).unwrap_err();
    assert!(truncated.to_string().contains("scanline 4"), "{truncated}");
    // Single pixels: 1.0 encodes as mantissa 128 at exponent 1 (1 = 0.5 * 2^1).
    assert_eq!(rgbe_encode([1.0, 0.5, 0.0]), [128, 64, 0, 129]);
    assert_eq!(rgbe_decode([128, 64, 0, 129]), [128.5 / 128.0, 64.5 / 128.0, 0.5 / 128.0]);
}

#[test]
fn hdr_reader_accepts_run_length_encoded_scanlines() {
    // One 8-pixel row in the new RLE form: marker 2 2 0 8, then per channel a run of 8 equal bytes (128 + 8).
    let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 8\n".to_vec();
    bytes.extend_from_slice(&[2, 2, 0, 8]);
    for value in [128u8, 64, 32] {
        bytes.extend_from_slice(&[128 + 8, value]);
    }
    // Exponent channel as literals: count 8, then 8 bytes.
    bytes.push(8);
    bytes.extend_from_slice(&[129; 8]);
    let image = decode_hdr(&bytes, &memory_path()).unwrap();
    assert_eq!(image.pixels, vec![rgbe_decode([128, 64, 32, 129]); 8]);
}

#[test]
fn pfm_round_trip_is_exact_and_bottom_up() {
    let (w, h) = (4u32, 3u32);
    let mut image = LinearImage::new(w, h);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        *p = [i as f32 * 1.5e3, -(i as f32) * 0.25, 1.0 / (i as f32 + 1.0)];
    }
    let bytes = encode_pfm(&image).unwrap();
    let header = b"PF\n4 3\n-1.0\n";
    assert_eq!(&bytes[..header.len()], header);
    // The first stored pixel is the bottom-left one (row 2 from the top).
    let first = f32::from_le_bytes(bytes[header.len()..header.len() + 4].try_into().unwrap());
    assert_eq!(first, image.pixels[(2 * w) as usize][0]);
    assert_eq!(decode_pfm(&bytes, &memory_path()).unwrap(), image);
    assert!(decode_pfm(&bytes[..bytes.len() - 1], &memory_path()).is_err());
    let mut nan = image.clone();
    nan.pixels[5][1] = f32::NAN;
    assert!(matches!(encode_pfm(&nan), Err(PictureError::NonFinite { index: 5, .. })));
}

// ---------------------------------------------------------------------------------------------------------------
// Smooth shading

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
    let radiosity: Vec<[f64; 3]> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    for (k, p) in patches.iter().enumerate() {
        for point in sample_points(p) {
            let got = shader.shade(&radiosity, k, point).unwrap();
            assert_close(got, linear_field(point), LINEAR_TOL, &format!("patch {k} at {point}"));
        }
    }
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
    let radiosity: Vec<[f64; 3]> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    for (k, p) in patches.iter().enumerate() {
        for point in sample_points(p) {
            let got = shader.shade(&radiosity, k, point).unwrap();
            assert_close(got, linear_field(point), LINEAR_TOL, &format!("patch {k} at {point}"));
        }
    }
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
    let radiosity = [[1.0, 2.0, 3.0], [10.0, 20.0, 30.0]];
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
    let mean = [7.75, 15.5, 23.25];
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
    let radiosity = [[1.0; 3], [10.0; 3]];
    let edge = [v(0.0, 0.0, 0.0), v(0.0, 0.5, 0.0), v(0.0, 1.0, 0.0)];
    let sharp = SmoothShader::new(&patches, &ShadingOptions { crease_angle_deg: 30.0, ..Default::default() })
        .unwrap();
    for &p in &edge {
        assert_close(sharp.shade(&radiosity, 0, p).unwrap(), [1.0; 3], 1e-12, "floor at the crease");
        assert_close(sharp.shade(&radiosity, 1, p).unwrap(), [10.0; 3], 1e-12, "wall at the crease");
    }
    // Control: a crease angle above 90 degrees lets them blend (equal areas: mean 5.5).
    let soft = SmoothShader::new(&patches, &ShadingOptions { crease_angle_deg: 120.0, ..Default::default() })
        .unwrap();
    assert_close(soft.shade(&radiosity, 0, edge[1]).unwrap(), [5.5; 3], 1e-12, "floor, crease allowed");
}

#[test]
fn smooth_shading_welds_vertices_within_the_tolerance_only() {
    // The right quad's left edge is moved by 1e-9 (scene size ~4: relative 2.5e-10 < 1e-6): still welded.
    let mut patches = side_by_side(0);
    for vtx in patches[1].vertices.iter_mut().filter(|p| p.x == 1.0) {
        vtx.x += 1e-9;
    }
    let radiosity = [[1.0; 3], [10.0; 3]];
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
    assert_close(separate.shade(&radiosity, 0, p).unwrap(), [1.0; 3], 1e-12, "not welded");
}

#[test]
fn smooth_shading_rejects_bad_input() {
    let patches = side_by_side(0);
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    assert!(matches!(shader.shade(&[[1.0; 3]], 0, DVec3::ZERO), Err(PictureError::Invalid { .. })));
    assert!(matches!(shader.shade(&[[1.0; 3]; 2], 2, DVec3::ZERO), Err(PictureError::Invalid { .. })));
    let err = shader.shade(&[[1.0; 3], [f64::NAN, 0.0, 0.0]], 0, DVec3::new(1.0, 0.0, 0.0)).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { index: 1, .. }), "{err}");
    let mut bad = patches.clone();
    bad[1].vertices.truncate(2);
    let err = SmoothShader::new(&bad, &ShadingOptions::default()).unwrap_err();
    assert!(err.to_string().contains("patch 1"), "{err}");
}

// ---------------------------------------------------------------------------------------------------------------
// Light maps

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
    let radiosity: Vec<[f64; 3]> = patches.iter().map(|p| linear_field(p.centroid)).collect();
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let options = LightMapOptions { texel_size: Some(0.25), padding: 2, ..Default::default() };
    let map = bake_light_map(&patches, &shader, &radiosity, &options).unwrap();
    let json = map.to_json("a.hdr", "a.png");
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
        let (u, v, o) =
            (DVec3::from_array(r.u_axis), DVec3::from_array(r.v_axis), DVec3::from_array(r.origin));
        assert!(u.dot(v).abs() < 1e-12 && (u.cross(v) + DVec3::from_array(r.normal)).length() < 1e-12);
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
            assert_close(texel.map(f64::from), expected, 1e-6, &format!("face {} texel ({i}, {j})", r.face));
        }
    }
    // Files: the PNG has the atlas size, the HDR reads back, the JSON parses.
    let dir = scratch_dir("lightmap");
    let [hdr, png_path, json_path] = map.write(&dir.join("box"), None).unwrap();
    let (w, h, _) = decode_png(&std::fs::read(&png_path).unwrap());
    assert_eq!((u64::from(w), u64::from(h)), (aw, ah));
    let back = radiosity_host::picture::hdr::read_hdr(&hdr).unwrap();
    assert_eq!((back.width, back.height), (w, h));
    let parsed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(parsed["faces"].as_array().unwrap().len(), 6);
    assert_eq!(parsed["atlas"]["png"], "box.png");
}

#[test]
fn light_map_refuses_a_face_without_patches() {
    let mut patches = box_patches();
    patches.retain(|p| p.face != 3);
    let radiosity = vec![[1.0; 3]; patches.len()];
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let err = bake_light_map(&patches, &shader, &radiosity, &LightMapOptions::default()).unwrap_err();
    assert!(err.to_string().contains("face 3 has no patch"), "{err}");
}

// ---------------------------------------------------------------------------------------------------------------
// False colour

/// CIE L* of a linear sRGB colour (IEC 61966-2-1 Y row, CIE 15 lightness).
fn lightness(rgb: [f64; 3]) -> f64 {
    let y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    let d: f64 = 6.0 / 29.0;
    let f = if y > d * d * d { y.cbrt() } else { y / (3.0 * d * d) + 4.0 / 29.0 };
    116.0 * f - 16.0
}

#[test]
fn false_colour_ramp_is_in_gamut_and_lightness_increases() {
    let mut previous = f64::NEG_INFINITY;
    for i in 0..=1024 {
        let t = f64::from(i) / 1024.0;
        let raw = lab_to_linear_srgb(ramp_lab(t));
        assert!(raw.iter().all(|c| (-1e-9..=1.0 + 1e-9).contains(c)), "t = {t}: out of gamut {raw:?}");
        let l = lightness(ramp(t));
        // L* rises by 70 over the ramp, 70 / 1024 ~ 0.068 per step; require at least a quarter of that.
        assert!(l > previous + 0.017, "t = {t}: L* {l} after {previous}");
        // And it is the designed L*. The IEC 61966-2-1 matrix and the Y weights are given to 4 decimals, so the
        // Lab -> RGB -> Y round trip holds to ~1e-4 relative in Y, i.e. (116 / 3) * 1e-4 ~ 4e-3 in L*.
        assert!((l - ramp_lab(t)[0]).abs() < 1e-2, "t = {t}: L* {l} vs designed {}", ramp_lab(t)[0]);
        previous = l;
    }
}

#[test]
fn patch_colours_are_in_gamut_and_distinct_for_neighbours() {
    for i in 0..2000 {
        let h = (i as f64 * 2.399_963_229_728_653) % std::f64::consts::TAU;
        let l = [55.0, 65.0, 75.0][i % 3];
        let raw = lab_to_linear_srgb([l, 30.0 * h.cos(), 30.0 * h.sin()]);
        assert!(raw.iter().all(|c| (0.0..=1.0).contains(c)), "patch {i}: out of gamut {raw:?}");
        let (a, b) = (patch_colour(i), patch_colour(i + 1));
        let distance: i32 = (0..3).map(|k| (i32::from(a[k]) - i32::from(b[k])).abs()).sum();
        assert!(distance > 30, "patches {i} and {} look alike: {a:?} {b:?}", i + 1);
    }
}

#[test]
fn error_scale_and_legend() {
    let log = ErrorScale::new(1e-4, 1e-1, true).unwrap();
    assert_eq!(log.ticks(), vec![1e-4, 1e-3, 1e-2, 1e-1]);
    assert!((log.position(1e-3) - 1.0 / 3.0).abs() < 1e-12);
    assert_eq!(log.position(1e-9), 0.0);
    assert_eq!(log.position(5.0), 1.0);
    let lin = ErrorScale::new(0.0, 0.03, false).unwrap();
    // Range 0.03 / 5 = 0.006 -> the next 1-2-5 step is 0.01.
    let ticks = lin.ticks();
    assert_eq!(ticks.len(), 4, "{ticks:?}");
    for (k, t) in ticks.iter().enumerate() {
        assert!((t - 0.01 * k as f64).abs() < 1e-15, "{ticks:?}");
    }
    assert!(ErrorScale::new(0.0, 1.0, true).is_err());
    assert!(ErrorScale::new(1.0, 1.0, false).is_err());
    let json = log.legend_json("relative error");
    assert_eq!(json["ticks"].as_array().unwrap().len(), 4);

    let legend = log.legend("relative error of B", 360, 72).unwrap();
    let (w, h, pixels) = decode_png(&encode_png(&legend).unwrap());
    assert_eq!((w, h), (360, 72));
    // The bar's left end is dark violet, its right end bright yellow, read at the bar's middle row.
    let font_px = (72 / 6).clamp(10, 18);
    let (x0, x1, y) = (3 * font_px + 2, 360 - 3 * font_px - 3, (font_px + 8 + 72 - font_px - 14) / 2);
    let px = |x: i32| {
        let i = 3 * (y as usize * 360 + x as usize);
        [pixels[i], pixels[i + 1], pixels[i + 2]]
    };
    let (left, right) = (px(x0), px(x1));
    assert!(left[2] > left[1] && u32::from(left[0]) + u32::from(left[1]) < 200, "left end {left:?}");
    assert!(right[0] > 200 && right[1] > 200 && right[2] < 150, "right end {right:?}");
    // Tick labels are drawn: the strip below the bar has dark (text) pixels.
    let dark_below = (y as usize + 20..72)
        .flat_map(|yy| (0..360).map(move |xx| 3 * (yy * 360 + xx)))
        .filter(|&i| pixels[i] < 100 && pixels[i + 1] < 100 && pixels[i + 2] < 100)
        .count();
    assert!(dark_below > 30, "no tick labels drawn ({dark_below} dark pixels)");
}

// ---------------------------------------------------------------------------------------------------------------
// Plots

/// Minimal XML well-formedness check: balanced, properly nested tags under one root. Returns (root name, text).
fn parse_xml(doc: &str) -> (String, String) {
    let mut stack: Vec<String> = Vec::new();
    let mut root = None;
    let mut text = String::new();
    let mut rest = doc;
    while let Some(start) = rest.find('<') {
        text.push_str(&rest[..start]);
        text.push(' ');
        rest = &rest[start..];
        if rest.starts_with("<?") {
            rest = &rest[rest.find("?>").expect("unterminated <?") + 2..];
            continue;
        }
        if rest.starts_with("<!--") {
            rest = &rest[rest.find("-->").expect("unterminated comment") + 3..];
            continue;
        }
        let end = rest.find('>').expect("unterminated tag");
        let tag = &rest[1..end];
        rest = &rest[end + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().unwrap_or_else(|| panic!("closing </{name}> without an open tag"));
            assert_eq!(open, name.trim(), "mismatched closing tag");
        } else {
            let name = tag.split_whitespace().next().unwrap_or("").trim_end_matches('/').to_string();
            assert!(!name.is_empty(), "empty tag");
            if stack.is_empty() {
                assert!(root.is_none(), "second root element <{name}>");
                root = Some(name.clone());
            }
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
    }
    assert!(stack.is_empty(), "unclosed tags {stack:?}");
    assert!(rest.trim().is_empty(), "text after the root element");
    let text = text.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", "\"").replace("&amp;", "&");
    (root.expect("no root element"), text)
}

fn sample_plots() -> Vec<(Plot, Vec<&'static str>)> {
    let series = |name: &str, c: f64, rate: f64| Series {
        name: name.into(),
        points: (0..8).map(|k| (10f64.powi(k), c * (-rate * f64::from(k)).exp())).collect(),
    };
    vec![
        (
            Plot::ErrorWork {
                title: "Cornell box: error against work".into(),
                x_label: "work units".into(),
                y_label: "relative L2 error".into(),
                series: vec![series("gathering", 0.5, 1.0), series("shooting <f32> & q8", 0.3, 1.7)],
            },
            vec!["gathering", "shooting <f32> & q8", "work units", "relative L2 error", "error against work"],
        ),
        (
            Plot::StackedBars {
                title: "Error decomposition".into(),
                y_label: "relative L2 error".into(),
                categories: vec!["f64".into(), "q16".into(), "q8".into()],
                components: vec![
                    ("form factors".into(), vec![0.01, 0.01, 0.01]),
                    ("quantization".into(), vec![0.0, 0.002, 0.02]),
                    ("truncation".into(), vec![0.001, 0.001, 0.001]),
                ],
            },
            vec!["form factors", "quantization", "truncation", "q16", "relative L2 error"],
        ),
        (
            Plot::Histogram {
                title: "Patch sizes".into(),
                x_label: "patch area (mm^2)".into(),
                values: (0..300).map(|i| 10f64.powf(2.0 + f64::from(i % 37) / 10.0)).collect(),
                bins: 12,
            },
            vec!["patch area (mm^2)", "patches", "Patch sizes"],
        ),
    ]
}

#[test]
fn plots_are_well_formed_svg_and_decodable_png() {
    let dir = scratch_dir("plots");
    for (k, (plot, expected)) in sample_plots().into_iter().enumerate() {
        let svg = plot.to_svg(640, 420).unwrap();
        let (root, text) = parse_xml(&svg);
        assert_eq!(root, "svg");
        for e in expected {
            assert!(text.contains(e), "plot {k}: SVG text lacks {e:?}");
        }
        assert!(svg.contains("<polyline") || svg.contains("<rect"), "plot {k} draws nothing");
        let (svg_path, png_path) = plot.write(&dir.join(format!("plot{k}")), 640, 420).unwrap();
        assert_eq!(
            std::fs::read_to_string(&svg_path).unwrap(),
            svg,
            "plot {k}: the written SVG is the rendered one"
        );
        let (w, h, pixels) = decode_png(&std::fs::read(&png_path).unwrap());
        assert_eq!((w, h), (640, 420));
        // Not blank: some pixels are neither white nor black (the coloured series).
        let coloured =
            pixels.chunks_exact(3).filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60).count();
        assert!(coloured > 100, "plot {k} PNG has only {coloured} coloured pixels");
    }
}

#[test]
fn plot_data_is_validated_and_histogram_counts_add_up() {
    let bad = Plot::ErrorWork {
        title: "t".into(),
        x_label: "x".into(),
        y_label: "y".into(),
        series: vec![Series { name: "s".into(), points: vec![(1.0, 0.5), (10.0, 0.0)] }],
    };
    let err = bad.to_svg(100, 100).unwrap_err();
    assert!(err.to_string().contains("series \"s\" point 1"), "{err}");
    let bars = Plot::StackedBars {
        title: "t".into(),
        y_label: "y".into(),
        categories: vec!["a".into(), "b".into()],
        components: vec![("c".into(), vec![1.0])],
    };
    assert!(bars.validate().unwrap_err().to_string().contains("component \"c\" has 1 values for 2"));
    let values: Vec<f64> = (1..=1000).map(f64::from).collect();
    let hist = Plot::Histogram { title: "h".into(), x_label: "x".into(), values, bins: 3 };
    let (edges, counts) = hist.histogram_bins().unwrap();
    assert_eq!(counts.iter().sum::<usize>(), 1000);
    // Edges at 1, 10, 100, 1000: bins [1,10) has 9, [10,100) has 90, [100,1000] has 901 (the maximum goes last).
    assert!((edges[1] - 10.0).abs() < 1e-9 && (edges[2] - 100.0).abs() < 1e-9);
    assert_eq!(counts, vec![9, 90, 901]);
}

// ---------------------------------------------------------------------------------------------------------------
// Views

/// The Cornell box from the published data (shared/data/cornell-box.md) as patches: every quad split into
/// `n x n` bilinear sub-quads; the ceiling as four quads around the light's opening. Materials: 0 white, 1 red,
/// 2 green, 3 light. Returns the patches and their reflectances.
fn cornell_box(n: usize) -> (Vec<Patch>, Vec<[f64; 3]>) {
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
                rho.push(*reflectance);
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
fn proxy_radiosity(patches: &[Patch], rho: &[[f64; 3]]) -> Vec<[f64; 3]> {
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
                return [emission; 3];
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

#[test]
fn cornell_box_view_looks_right() {
    use radiosity_host::picture::camera::Camera;
    use radiosity_host::picture::render::{render, Colouring, Frame};
    let (patches, rho) = cornell_box(4);
    let radiosity = proxy_radiosity(&patches, &rho);
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
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
        assert!(view.linear[k].iter().all(|c| c.is_finite()), "pixel {k} not finite");
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
    let (patches, rho) = cornell_box(2);
    let converged = proxy_radiosity(&patches, &rho);
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    let frame = Frame { camera: Camera::cornell_box(), width: 40, height: 30 };
    let hits = trace_view(&frame, &|o, d| closest_hit(&patches, o, d)).unwrap();
    // A device converging: frame k has (k + 1) / 4 of the converged radiosity.
    let frames: Vec<Vec<[f64; 3]>> =
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

#[test]
fn light_map_of_a_triangle_fills_the_uncovered_texels_from_the_nearest_patch() {
    // One triangular face split at its edge midpoints into four triangles; a linear field.
    let plane = Plane::tilted();
    let (a, b, c) = (plane.at(0.0, 0.0), plane.at(4.0, 0.0), plane.at(1.0, 3.0));
    let (ab, bc, ca) = ((a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0);
    let tris = [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]];
    let patches: Vec<Patch> = tris.iter().map(|t| polygon(0, 0, t.to_vec())).collect();
    let radiosity: Vec<[f64; 3]> = patches.iter().map(|p| linear_field(p.centroid)).collect();
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
            let texel = map.atlas.pixels[(y * map.atlas.width + x) as usize].map(f64::from);
            let (fi, fj) =
                (f64::from(i) - f64::from(map.padding) + 0.5, f64::from(j) - f64::from(map.padding) + 0.5);
            let centre = DVec3::from_array(r.origin)
                + DVec3::from_array(r.u_axis) * (fi * r.texel_size)
                + DVec3::from_array(r.v_axis) * (fj * r.texel_size);
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

#[test]
fn smooth_shading_joins_slightly_warped_quadrilaterals_at_shared_corners() {
    // Two quads sharing an edge; the far corner of each is lifted 1e-3 off the plane (scene size ~4: far above the
    // 4e-6 weld tolerance), like the sub-quads of the Cornell box's warped red wall. They still share vertices.
    let v = DVec3::new;
    let patches = vec![
        polygon(0, 0, vec![v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0), v(0.0, 1.0, 1e-3)]),
        polygon(1, 0, vec![v(1.0, 0.0, 0.0), v(2.0, 0.0, 0.0), v(2.0, 1.0, 1e-3), v(1.0, 1.0, 0.0)]),
    ];
    let radiosity = [[1.0; 3], [3.0; 3]];
    let shader = SmoothShader::new(&patches, &ShadingOptions::default()).unwrap();
    // Equal areas: the shared corners take the mean, 2.
    for p in [v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0)] {
        assert_close(shader.shade(&radiosity, 0, p).unwrap(), [2.0; 3], 1e-9, "left quad at a shared corner");
        assert_close(
            shader.shade(&radiosity, 1, p).unwrap(),
            [2.0; 3],
            1e-9,
            "right quad at a shared corner",
        );
    }
}
