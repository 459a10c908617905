//! Tests of the picture modules, one file per topic: tone mapping, sRGB and image files (`images`), smooth
//! shading (`shading`), light maps (`lightmap`), the false-colour ramp and its legend (`colour`), plots (`plot`)
//! and camera views (`view`). The helpers they share are here.

mod colour;
mod images;
mod lightmap;
mod plot;
mod shading;
mod view;

use std::path::PathBuf;

use glam::DVec3;
use radiosity_host::patch::Patch;
use radiosity_host::rgb::Rgb;

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
fn linear_field(p: DVec3) -> Rgb {
    Rgb::new(
        5.0 + 0.3 * p.x - 0.2 * p.y + 0.1 * p.z,
        9.0 - 0.1 * p.x + 0.4 * p.y + 0.05 * p.z,
        7.0 + 0.2 * p.x + 0.1 * p.y - 0.3 * p.z,
    )
}

fn assert_close(actual: Rgb, expected: Rgb, tol: f64, what: &str) {
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
