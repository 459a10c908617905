//! Tests of the safe Embree wrapper: occlusion between facing quads, occluders, rays that start or end on
//! surfaces, packets against single rays, closest hits, errors, a Monte Carlo form factor, and agreement with the
//! pure-Rust caster (occlusion, closest hits and form factors on the Cornell box).

use glam::Vec3;
use radiosity_host::embree::{Device, EmbreeError, Ray, SceneOptions, TriangleScene};
use radiosity_host::raycast::{MeshInputError, RayCaster};
use radiosity_host::rng::SplitMix64;

/// Exact form factor between two facing, aligned unit squares at distance 1 (closed form for parallel
/// rectangles; e.g. Howell's catalogue of configuration factors, C-11).
const F_FACING_UNIT_SQUARES: f64 = 0.199825;

/// Appends the quad `a, b, c, d` (counter-clockwise seen from its normal side) as two triangles.
fn push_quad(vertices: &mut Vec<Vec3>, triangles: &mut Vec<[u32; 3]>, quad: [Vec3; 4]) {
    let base = vertices.len() as u32;
    vertices.extend_from_slice(&quad);
    triangles.push([base, base + 1, base + 2]);
    triangles.push([base, base + 2, base + 3]);
}

/// Unit square at height `z`, facing up (`up = true`) or down.
fn square_at(z: f32, up: bool) -> [Vec3; 4] {
    let q = [Vec3::new(0.0, 0.0, z), Vec3::new(1.0, 0.0, z), Vec3::new(1.0, 1.0, z), Vec3::new(0.0, 1.0, z)];
    if up {
        q
    } else {
        [q[0], q[3], q[2], q[1]]
    }
}

/// The floor square (z = 0, facing up) and the ceiling square (z = 1, facing down), plus `extra` quads.
fn facing_quads(extra: &[[Vec3; 4]], options: SceneOptions) -> TriangleScene {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    push_quad(&mut vertices, &mut triangles, square_at(0.0, true));
    push_quad(&mut vertices, &mut triangles, square_at(1.0, false));
    for quad in extra {
        push_quad(&mut vertices, &mut triangles, *quad);
    }
    Device::new().unwrap().triangle_scene(&vertices, &triangles, options).unwrap()
}

/// A plate at z = 0.5 covering x in [0.25, 0.75] (all of y), between the facing quads.
const PLATE: [Vec3; 4] = [
    Vec3::new(0.25, 0.0, 0.5),
    Vec3::new(0.75, 0.0, 0.5),
    Vec3::new(0.75, 1.0, 0.5),
    Vec3::new(0.25, 1.0, 0.5),
];

fn point_on_square(rng: &mut SplitMix64, z: f32) -> Vec3 {
    Vec3::new(rng.unit() as f32, rng.unit() as f32, z)
}

#[test]
fn segment_between_facing_quads_is_unoccluded() {
    for options in [SceneOptions::default(), SceneOptions { robust: true }] {
        let scene = facing_quads(&[], options);
        let ray = Ray::segment(Vec3::new(0.5, 0.5, 0.0), Vec3::new(0.5, 0.5, 1.0), scene.offset());
        assert!(!scene.occluded(&ray));
        assert_eq!(scene.intersect(&ray), None);
    }
}

#[test]
fn occluder_between_quads_blocks_segment() {
    // A plate at z = 0.5 covering x in [0.25, 0.75]: segments through its middle are blocked, segments at
    // x = 0.1 pass beside it.
    let plate = PLATE;
    let scene = facing_quads(&[plate], SceneOptions::default());
    let blocked = Ray::segment(Vec3::new(0.5, 0.5, 0.0), Vec3::new(0.5, 0.5, 1.0), scene.offset());
    assert!(scene.occluded(&blocked));
    let beside = Ray::segment(Vec3::new(0.1, 0.5, 0.0), Vec3::new(0.1, 0.5, 1.0), scene.offset());
    assert!(!scene.occluded(&beside));

    // The closest hit is the plate (triangles 4 and 5) at half the segment, seen from below: the plate is
    // counter-clockwise seen from +z, so its normal is +z.
    let hit = scene.intersect(&blocked).expect("the plate is hit");
    assert!(hit.primitive == 4 || hit.primitive == 5, "hit triangle {}", hit.primitive);
    assert_eq!(hit.geometry, 0);
    // The plate is at t = 0.5 exactly; Embree's t is accurate to a few f32 ulps.
    assert!((hit.t - 0.5).abs() < 1e-6, "t = {}", hit.t);
    assert!((hit.normal - Vec3::Z).length() < 1e-6, "normal {:?}", hit.normal);
    let [u, v] = hit.barycentric;
    assert!((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v) && u + v <= 1.0 + 1e-6);
}

#[test]
fn closest_hit_reports_primitive_barycentrics_and_orientation() {
    // Two triangles at z = 1 and z = 2, both counter-clockwise seen from -z (normal -z); a ray up from the
    // origin region hits the nearer one.
    let vertices = [
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(0.0, 1.0, 2.0),
        Vec3::new(1.0, 0.0, 2.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 1.0, 1.0),
        Vec3::new(1.0, 0.0, 1.0),
    ];
    let scene = Device::new()
        .unwrap()
        .triangle_scene(&vertices, &[[0, 1, 2], [3, 4, 5]], Default::default())
        .unwrap();
    let ray = Ray::new(Vec3::new(0.25, 0.5, 0.0), Vec3::Z, 0.0, f32::INFINITY);
    let hit = scene.intersect(&ray).unwrap();
    assert_eq!(hit.primitive, 1);
    assert!((hit.t - 1.0).abs() < 1e-6);
    // Point = (1 - u - v) p0 + u p1 + v p2 with p1 = (0, 1), p2 = (1, 0): u = y = 0.5, v = x = 0.25.
    assert!((hit.barycentric[0] - 0.5).abs() < 1e-6 && (hit.barycentric[1] - 0.25).abs() < 1e-6);
    assert!((hit.normal + Vec3::Z).length() < 1e-6, "normal {:?}", hit.normal);
    // A ray pointing away misses everything.
    assert_eq!(scene.intersect(&Ray::new(Vec3::ZERO, -Vec3::Z, 0.0, f32::INFINITY)), None);
}

#[test]
fn rays_starting_on_a_surface_do_not_hit_it() {
    // Segments from random points on the floor square to random points on the ceiling square, in a scene of
    // just those two squares: neither end surface may count. Also rays leaving the floor upwards and sideways
    // at grazing angles with only tnear = offset. The offset is RELATIVE_OFFSET (2^-13) of the scene scale,
    // about 1000 f32 ulps of the coordinates, so rounding in Embree's hit distance cannot reach past it.
    let mut rng = SplitMix64::new(7);
    for options in [SceneOptions::default(), SceneOptions { robust: true }] {
        let scene = facing_quads(&[], options);
        let offset = scene.offset();
        for _ in 0..2000 {
            let from = point_on_square(&mut rng, 0.0);
            let to = point_on_square(&mut rng, 1.0);
            assert!(!scene.occluded(&Ray::segment(from, to, offset)), "{from} -> {to}");
            // A unit-length direction leaving the floor, elevation down to ~0.6 degrees.
            let elevation = 0.01 + 1.5 * rng.unit() as f32;
            let azimuth = std::f32::consts::TAU * rng.unit() as f32;
            let dir =
                Vec3::new(elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin());
            // Stop before the ceiling plane so only the floor could be hit.
            let tfar = 0.9 / dir.z;
            assert!(!scene.occluded(&Ray::new(from, dir, offset, tfar)), "{from} along {dir}");
        }
    }
}

#[test]
fn segment_ending_exactly_on_target_is_not_occluded() {
    let scene = facing_quads(&[], SceneOptions::default());
    // Ends at the centre, on an edge and on a corner of the ceiling square.
    for to in [Vec3::new(0.5, 0.5, 1.0), Vec3::new(0.5, 1.0, 1.0), Vec3::new(1.0, 1.0, 1.0)] {
        let from = Vec3::new(0.5, 0.5, 0.0);
        assert!(!scene.occluded(&Ray::segment(from, to, scene.offset())), "segment to {to}");
    }
    // Why the shortening matters: Embree's tfar is inclusive, so the same segment with tfar = 1 exactly hits the
    // ceiling at t = 1 (all coordinates here are exact in f32, so the hit distance is exactly 1).
    let raw = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::Z, scene.offset(), 1.0);
    assert!(scene.occluded(&raw));
}

#[test]
fn packets_agree_with_single_rays() {
    let plate = PLATE;
    let scene = facing_quads(&[plate], SceneOptions::default());
    let mut rng = SplitMix64::new(11);
    let rays: Vec<Ray> = (0..37)
        .map(|_| Ray::segment(point_on_square(&mut rng, 0.0), point_on_square(&mut rng, 1.0), scene.offset()))
        .collect();
    let single: Vec<bool> = rays.iter().map(|r| scene.occluded(r)).collect();
    // Both outcomes occur, so the comparison means something.
    assert!(single.iter().any(|&o| o) && single.iter().any(|&o| !o));
    let mut many = vec![false; rays.len()];
    scene.occluded_many(&rays, &mut many);
    assert_eq!(single, many);
    // A partial packet: lanes beyond the slice are inactive and report nothing.
    let bits = scene.occluded16(&rays[..5]);
    assert_eq!(bits >> 5, 0);
    for (k, &o) in single[..5].iter().enumerate() {
        assert_eq!(bits & (1 << k) != 0, o);
    }
    // An empty segment (shorter than twice the offset) is never occluded.
    let tiny =
        Ray::segment(Vec3::new(0.5, 0.5, 0.5), Vec3::new(0.5, 0.5, 0.5 + scene.offset()), scene.offset());
    assert!(!scene.occluded(&tiny));
    assert_eq!(scene.occluded16(&[tiny]), 0);
    // Invalid rays (NaN origin, infinite direction) never reach Embree and hit nothing, even aimed at the plate.
    let nan = Ray::new(Vec3::new(f32::NAN, 0.5, 0.0), Vec3::Z, 0.0, 1.0);
    let inf = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::new(0.0, 0.0, f32::INFINITY), 0.0, 1.0);
    for ray in [nan, inf] {
        assert!(!scene.occluded(&ray));
        assert_eq!(scene.intersect(&ray), None);
        assert_eq!(scene.occluded16(&[ray, ray]), 0);
    }
}

#[test]
fn scene_is_shared_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<TriangleScene>();
    assert_send_sync::<Device>();
    let plate = PLATE;
    let scene = facing_quads(&[plate], SceneOptions::default());
    let counts: Vec<usize> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                let scene = &scene;
                s.spawn(move || {
                    (0..1000)
                        .filter(|k| {
                            let x = (*k as f32 + 0.5) / 1000.0;
                            scene.occluded(&Ray::segment(
                                Vec3::new(x, 0.5, 0.0),
                                Vec3::new(x, 0.5, 1.0),
                                scene.offset(),
                            ))
                        })
                        .count()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    // x in (0.25, 0.75) is blocked: 500 of the 1000 midpoints.
    assert_eq!(counts, vec![500; 4]);
}

#[test]
fn bad_input_and_embree_errors_are_reported() {
    let device = Device::new().unwrap();
    let err =
        device.triangle_scene(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 3]], Default::default()).unwrap_err();
    assert_eq!(
        err,
        EmbreeError::Input(MeshInputError::VertexOutOfRange { triangle: 0, vertex: 3, vertex_count: 3 })
    );
    assert!(err.to_string().contains("triangle 0 refers to vertex 3"), "{err}");
    let err = device
        .triangle_scene(
            &[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Y],
            &[[0, 1, 2]],
            Default::default(),
        )
        .unwrap_err();
    assert!(matches!(err, EmbreeError::Input(MeshInputError::NonFiniteVertex { index: 1, .. })), "{err}");
    // Embree itself rejects a thread count that is not a number; the error names Embree's code and the config,
    // and passes on Embree's own message (there is no device yet to carry an error callback).
    let err = Device::with_config("threads=abc").unwrap_err();
    assert!(err.to_string().contains("RTC_ERROR_") && err.to_string().contains("threads=abc"), "{err}");
    assert!(err.to_string().contains("integer expected"), "Embree's message is lost: {err}");
    // An empty scene is valid and occludes nothing.
    let empty = device.triangle_scene(&[], &[], Default::default()).unwrap();
    assert!(!empty.occluded(&Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY)));
}

#[test]
fn monte_carlo_form_factor_of_facing_unit_squares() {
    // F = (1/A_i) int_i int_j cos(t_i) cos(t_j) / (pi r^2) V dA_j dA_i. With x uniform on i and y uniform on j
    // (both of area 1) one sample is g = cos cos / (pi r^2) * V, an unbiased estimate of F. The visibility comes
    // from Embree (16-wide packets); the standard error is the sample standard deviation / sqrt(n).
    let scene = facing_quads(&[], SceneOptions::default());
    let mut rng = SplitMix64::new(2024);
    let n = 1 << 15;
    let mut sum = 0.0f64;
    let mut sum_sq = 0.0f64;
    let mut visible = 0usize;
    let mut rays = Vec::with_capacity(16);
    let mut kernels = Vec::with_capacity(16);
    for _ in 0..n / 16 {
        rays.clear();
        kernels.clear();
        for _ in 0..16 {
            let x = [rng.unit(), rng.unit(), 0.0];
            let y = [rng.unit(), rng.unit(), 1.0];
            let d = [y[0] - x[0], y[1] - x[1], y[2] - x[2]];
            let r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            // cos at both ends is d_z / r; distance is 1 between the planes.
            kernels.push(d[2] * d[2] / (std::f64::consts::PI * r2 * r2));
            let from = Vec3::new(x[0] as f32, x[1] as f32, 0.0);
            let to = Vec3::new(y[0] as f32, y[1] as f32, 1.0);
            rays.push(Ray::segment(from, to, scene.offset()));
        }
        let blocked = scene.occluded16(&rays);
        for (k, g) in kernels.iter().enumerate() {
            let g = if blocked & (1 << k) == 0 { *g } else { 0.0 };
            visible += usize::from(blocked & (1 << k) == 0);
            sum += g;
            sum_sq += g * g;
        }
    }
    let n = n as f64;
    let mean = sum / n;
    let variance = (sum_sq / n - mean * mean) * n / (n - 1.0);
    let standard_error = (variance / n).sqrt();
    assert_eq!(visible as f64, n, "nothing lies between the squares");
    assert!(
        (mean - F_FACING_UNIT_SQUARES).abs() <= 3.0 * standard_error,
        "estimate {mean} vs exact {F_FACING_UNIT_SQUARES}: difference {} > 3 standard errors ({standard_error})",
        (mean - F_FACING_UNIT_SQUARES).abs()
    );
}

/// The Cornell box's uniform mesh as the form-factor estimator sees it.
fn cornell_patches() -> Vec<radiosity_host::patch::Patch> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.obj");
    let scene = radiosity_host::scene::Scene::load(path).expect("load");
    radiosity_host::mesh::mesh(&scene, &radiosity_host::mesh::MeshOptions::for_scene(&scene))
        .expect("mesh")
        .patches
}

/// Whether `ray` is on the edge of a decision for `caster`: nudging its origin by `nudge` along an axis, or
/// pulling either end in by `nudge`, changes the answer. Two casters that round differently may disagree only
/// on such rays.
fn borderline(caster: &dyn RayCaster, ray: &Ray, nudge: f32) -> bool {
    let answer = caster.occluded(ray);
    let length = ray.direction.length();
    let mut variants = vec![
        Ray { tnear: ray.tnear + nudge / length, ..*ray },
        Ray { tfar: ray.tfar - nudge / length, ..*ray },
        Ray { tnear: (ray.tnear - nudge / length).max(0.0), ..*ray },
        Ray { tfar: ray.tfar + nudge / length, ..*ray },
    ];
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        for sign in [-1.0, 1.0] {
            variants.push(Ray { origin: ray.origin + axis * (sign * nudge), ..*ray });
        }
    }
    variants.iter().any(|v| caster.occluded(v) != answer)
}

/// Embree against the pure-Rust caster on the Cornell box's occluders: segments between random points of random
/// patches that face each other (the estimator's rays) and between random points of the box's volume. They follow the same
/// conventions, so they may only disagree on rays within rounding of an edge or an end (`borderline`, with a
/// nudge of 1e-6 of the scene size: Embree's f32 tests are accurate to a few ulps, about 1e-7 of it).
#[test]
fn embree_agrees_with_the_pure_rust_caster_on_the_cornell_box() {
    let patches = cornell_patches();
    let embree = radiosity_host::formfactor::occluder_scene(&patches, true).unwrap();
    let bvh = radiosity_host::formfactor::occluder_bvh(&patches).unwrap();
    assert_eq!(RayCaster::offset(&embree), bvh.offset(), "both casters cut segments alike");
    let (vertices, _) = radiosity_host::formfactor::occluder_mesh(&patches);
    let (lo, hi) = vertices.iter().fold((vertices[0], vertices[0]), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    let mut rng = SplitMix64::new(17);
    let on_patch = |rng: &mut SplitMix64| {
        let p = &patches[(rng.unit() * patches.len() as f64) as usize];
        let (s, t) = (rng.unit(), rng.unit());
        let v = &p.vertices;
        // A point of the fan triangle (v0, v1, v2) or (v0, v2, v3), uniformly enough for a test.
        let k = if v.len() > 3 && rng.unit() < 0.5 { 2 } else { 1 };
        let (s, t) = if s + t > 1.0 { (1.0 - s, 1.0 - t) } else { (s, t) };
        (p.normal, v[0] + (v[k] - v[0]) * s + (v[k + 1] - v[0]) * t)
    };
    let mut rays = Vec::new();
    while rays.len() < 100_000 {
        // Only pairs of points that face each other, as the estimator casts them (its kernel is zero
        // elsewhere): a segment within a face's plane grazes it, and its answer is rounding either way.
        let ((nx, x), (ny, y)) = (on_patch(&mut rng), on_patch(&mut rng));
        if nx.dot(y - x) > 0.0 && ny.dot(x - y) > 0.0 {
            rays.push(Ray::segment(x.as_vec3(), y.as_vec3(), bvh.offset()));
        }
    }
    for _ in 0..50_000 {
        let mut inside =
            || lo + (hi - lo) * Vec3::new(rng.unit() as f32, rng.unit() as f32, rng.unit() as f32);
        let (a, b) = (inside(), inside());
        rays.push(Ray::new(a, b - a, 0.0, 1.0));
    }
    let mut by_embree = vec![false; rays.len()];
    embree.occluded_many(&rays, &mut by_embree);
    let mut by_bvh = vec![false; rays.len()];
    bvh.occluded_many(&rays, &mut by_bvh);
    let nudge = 1e-6 * (hi - lo).length();
    let mut disagree = 0;
    for ((ray, &e), &b) in rays.iter().zip(&by_embree).zip(&by_bvh) {
        if e != b {
            disagree += 1;
            assert!(borderline(&bvh, ray, nudge), "Embree {e}, pure Rust {b} on a clear-cut ray {ray:?}");
        }
    }
    let blocked = by_bvh.iter().filter(|&&b| b).count();
    println!("{} rays, {blocked} blocked, {disagree} disagreements (all borderline)", rays.len());
    assert!(
        blocked > rays.len() / 20 && blocked < rays.len() * 19 / 20,
        "{blocked} of {} blocked",
        rays.len()
    );
}

/// The closest hit of `ray` by `caster`, as (triangle, hit or not).
fn closest(caster: &dyn RayCaster, ray: &Ray) -> Option<u32> {
    caster.intersect(ray).map(|h| h.primitive)
}

/// Whether `ray`'s closest triangle is on the edge of a decision for `caster` (as `borderline` for occlusion):
/// nudging its origin by `nudge` along an axis or its direction by `nudge` of its length changes the triangle
/// reported (or whether any is). Rays through a shared edge, or grazing a face, are such rays.
fn borderline_hit(caster: &dyn RayCaster, ray: &Ray, nudge: f32) -> bool {
    let answer = closest(caster, ray);
    let length = ray.direction.length();
    [Vec3::X, Vec3::Y, Vec3::Z].iter().flat_map(|&axis| [axis * nudge, -axis * nudge]).any(|d| {
        closest(caster, &Ray { origin: ray.origin + d, ..*ray }) != answer
            || closest(caster, &Ray { direction: ray.direction + d * length, ..*ray }) != answer
    })
}

/// Closest hits of Embree against the pure-Rust caster on the Cornell box: from random points of random
/// patches in random directions of their front hemisphere (the path tracer's bounce rays) and between random
/// points of the box's volume. The same triangle, or a borderline ray (`borderline_hit`, nudge 1e-6 of the
/// scene size as above); on the same triangle the hit agrees to f32 rounding: distance within 1e-5 of the scene
/// size (a few hundred ulps of Embree's f32 arithmetic), normals and barycentrics within 1e-4.
#[test]
fn closest_hits_agree_with_the_pure_rust_caster_on_the_cornell_box() {
    let patches = cornell_patches();
    let embree = radiosity_host::formfactor::occluder_scene(&patches, true).unwrap();
    let bvh = radiosity_host::formfactor::occluder_bvh(&patches).unwrap();
    let (vertices, _) = radiosity_host::formfactor::occluder_mesh(&patches);
    let (lo, hi) = vertices.iter().fold((vertices[0], vertices[0]), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    let size = (hi - lo).length();
    let mut rng = SplitMix64::new(23);
    let mut rays = Vec::new();
    while rays.len() < 40_000 {
        let p = &patches[(rng.unit() * patches.len() as f64) as usize];
        let v = &p.vertices;
        let (s, t) = (rng.unit(), rng.unit());
        let (s, t) = if s + t > 1.0 { (1.0 - s, 1.0 - t) } else { (s, t) };
        let x = v[0] + (v[1] - v[0]) * s + (v[2] - v[0]) * t;
        let d = glam::DVec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
        let d = if d.dot(p.normal) < 0.0 { -d } else { d };
        rays.push(Ray::new(x.as_vec3(), d.as_vec3(), bvh.offset(), f32::INFINITY));
    }
    for _ in 0..20_000 {
        let mut inside =
            || lo + (hi - lo) * Vec3::new(rng.unit() as f32, rng.unit() as f32, rng.unit() as f32);
        let (a, b) = (inside(), inside());
        rays.push(Ray::new(a, b - a, 0.0, f32::INFINITY));
    }
    let (mut hits, mut disagree) = (0, 0);
    for ray in &rays {
        let (e, b) = (embree.intersect(ray), bvh.intersect(ray));
        match (e, b) {
            (Some(e), Some(b)) if e.primitive == b.primitive => {
                hits += 1;
                let length = ray.direction.length();
                assert!((e.t - b.t).abs() * length <= 1e-5 * size, "{ray:?}: {e:?} vs {b:?}");
                assert!((e.normal - b.normal).length() <= 1e-4, "{ray:?}: {e:?} vs {b:?}");
                for k in 0..2 {
                    assert!((e.barycentric[k] - b.barycentric[k]).abs() <= 1e-4, "{ray:?}: {e:?} vs {b:?}");
                }
            }
            (None, None) => {}
            _ => {
                disagree += 1;
                assert!(
                    borderline_hit(&bvh, ray, 1e-6 * size),
                    "Embree {e:?}, pure Rust {b:?} on a clear-cut ray {ray:?}"
                );
            }
        }
    }
    println!("{} rays, {hits} hit the same triangle, {disagree} disagreements (all borderline)", rays.len());
    // The box is open at the front, so some rays escape; most hit, so the comparison means something.
    assert!(hits > rays.len() / 2, "{hits} of {} rays hit the same triangle", rays.len());
}

/// Form factors of the Cornell box with Embree and with the pure-Rust caster: the rays are the same (same
/// seeds, same offset), so the matrices differ only where a ray is borderline (see the test above), which
/// changes one pair's visible fraction by one ray's weight. Asserted: at most 1 in 1000 entries differ at all,
/// and no entry by more than half its value (a pair's weight can sit on few rays).
#[test]
fn form_factors_agree_with_both_casters() {
    use radiosity_host::formfactor::{compute_form_factors, compute_form_factors_with, FormFactorOptions};
    let patches = cornell_patches();
    let options = FormFactorOptions { progress: false, ..FormFactorOptions::default() };
    let (embree, embree_stats) = compute_form_factors(&patches, &options).unwrap();
    let bvh = radiosity_host::formfactor::occluder_bvh(&patches).unwrap();
    let (pure, pure_stats) = compute_form_factors_with(&bvh, &patches, &options).unwrap();
    assert_eq!(embree_stats.rays_cast, pure_stats.rays_cast);
    assert_eq!(embree.n(), pure.n());
    let (mut differ, mut worst) = (0usize, 0.0f64);
    for i in 0..embree.n() {
        let columns = embree.row_columns(i).iter().chain(pure.row_columns(i)).copied();
        let mut columns: Vec<u32> = columns.collect();
        columns.sort_unstable();
        columns.dedup();
        for j in columns {
            let (e, p) = (embree.get(i, j as usize), pure.get(i, j as usize));
            if e != p {
                differ += 1;
                worst = worst.max((e - p).abs() / e.max(p));
            }
        }
    }
    println!("{} entries, {differ} differ, worst relative difference {worst:.2e}", embree.nonzeros());
    assert!(differ * 1000 <= embree.nonzeros(), "{differ} of {} entries differ", embree.nonzeros());
    assert!(worst <= 0.5, "worst relative difference {worst}");
}

/// The closed Cornell box meshed coarsely (walls in about 6 x 6 patches), with every length times `k`.
fn closed_cornell_scaled(k: f64) -> Vec<radiosity_host::patch::Patch> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box-closed.obj");
    let scene = radiosity_host::scene::Scene::load(path).expect("load");
    let mut options = radiosity_host::mesh::MeshOptions::for_scene(&scene);
    options.max_patch_edge = 140.0;
    let mut patches = radiosity_host::mesh::mesh(&scene, &options).expect("mesh").patches;
    for p in &mut patches {
        p.vertices.iter_mut().for_each(|v| *v *= k);
        p.centroid *= k;
        p.area *= k * k;
    }
    patches
}

/// Form factors do not depend on the scene's unit: Embree sees every scene scaled to unit size by a power of two,
/// and the f64 kernels' tolerances are relative, so the closed Cornell box scaled by a power of two (here up to
/// 2^100 ~ 1.3e30 and down to 2^-50 ~ 8.9e-16) gives the same matrix bit for bit, closed as at scale 1; scaled by
/// 1e12 or 1e-15 (inexact in binary) it stays closed, with every entry within a few rays' weight. Without the
/// scaling, Embree's f32 triangle tests overflowed or flushed to zero at these sizes: occlusion was lost and the
/// closed box looked open.
#[test]
fn form_factors_do_not_depend_on_the_scene_unit() {
    use radiosity_host::formfactor::{compute_form_factors, FormFactorOptions};
    let options =
        FormFactorOptions { samples_per_patch: 4, rays_per_pair: 8, progress: false, ..Default::default() };
    let (reference, stats) = compute_form_factors(&closed_cornell_scaled(1.0), &options).unwrap();
    assert!(
        stats.closure.is_some() && stats.escaped_rays == 0,
        "the closed box at scale 1 is closed: {stats:?}"
    );
    for exponent in [100, 40, -50] {
        let k = 2f64.powi(exponent);
        let (m, s) = compute_form_factors(&closed_cornell_scaled(k), &options).unwrap();
        assert_eq!(
            s.escaped_rays, 0,
            "2^{exponent}: {} of {} escape rays escaped",
            s.escaped_rays, s.escape_rays
        );
        assert_eq!(m, reference, "2^{exponent}: the matrix differs from scale 1");
    }
    for k in [1e12, 1e-15] {
        let (m, s) = compute_form_factors(&closed_cornell_scaled(k), &options).unwrap();
        assert_eq!(s.escaped_rays, 0, "{k:e}: {} of {} escape rays escaped", s.escaped_rays, s.escape_rays);
        assert!(s.closure.is_some(), "{k:e}: not closed");
        let mut worst = 0.0f64;
        for (i, j, f) in reference.entries() {
            worst = worst.max((m.get(i, j) - f).abs());
        }
        // One ray of 8 flipping by rounding moves a pair's visible fraction by about 1/8 of its entry; the largest
        // entries are below 0.5.
        assert!(worst < 0.07, "{k:e}: largest entry difference from scale 1 {worst:.3e}");
        // Rows without a partly visible entry are left as estimated: off by their quadrature error only.
        assert!((s.row_sum_max - 1.0).abs() < 1e-3 && (s.row_sum_min - 1.0).abs() < 1e-3, "{k:e}: {s:?}");
    }
}

/// A row that sums to well above 1 is an error, not visibility noise: with occlusion lost (a caster that holds
/// no occluders, as Embree was at extreme scales), the rows of patches that see the Cornell box's blocks and
/// what lies behind them sum to more than 1 by more than their sampling noise allows, and `rows_over_noise`
/// names them with their faces; the same estimate with the scene's occluders has no such row.
#[test]
fn rows_above_one_beyond_sampling_noise_are_named() {
    use radiosity_host::formfactor::FormFactorOptions;
    use radiosity_host::formfactor::{compute_form_factors, compute_form_factors_with, rows_over_noise};
    use radiosity_host::raycast::TriangleBvh;
    let patches = closed_cornell_scaled(1.0);
    let options =
        FormFactorOptions { samples_per_patch: 4, rays_per_pair: 8, progress: false, ..Default::default() };
    let (good, stats) = compute_form_factors(&patches, &options).unwrap();
    assert_eq!(rows_over_noise(&good, &stats.row_excess_allowed, &patches), []);
    let nothing = TriangleBvh::new(&[], &[]).unwrap();
    let (lost, stats) = compute_form_factors_with(&nothing, &patches, &options).unwrap();
    let over = rows_over_noise(&lost, &stats.row_excess_allowed, &patches);
    assert!(over.len() > 10, "{} rows over their noise", over.len());
    let worst = over[0];
    assert!(worst.sum - 1.0 > 2.0 * worst.allowed, "{worst:?}");
    assert_eq!(worst.face, patches[worst.patch].face);
    assert!(over.windows(2).all(|w| w[0].sum - w[0].allowed >= w[1].sum - w[1].allowed), "worst first");
    let text = worst.to_string();
    assert!(text.contains(&format!("patch {} (face {})", worst.patch, worst.face)), "{text}");
}

/// Closest hits do not depend on the scene's unit either, whatever the length of the ray's direction: bounce
/// rays as the path tracer casts them (unit directions, from points lifted off a patch by the caster's offset)
/// and rays whose direction is of the scene's size, in the closed Cornell box scaled by `k`. For a power of two
/// (2^100 ~ 1.3e30 down to 2^-50 ~ 8.9e-16) every hit is the scale-1 hit: the same triangle and barycentrics,
/// and `t` times `k` (unit directions) or the same `t` (scaled directions), bit for bit. For 1e12 and 1e-15
/// (inexact in binary) at most 1 ray in 1000 hits another triangle (a ray through a shared edge), and `t` agrees
/// to 1e-5 of the scene size. Before Embree saw directions scaled as well as the scene, a unit direction at
/// 2^100 was about 1e-30 of Embree's unit scene and every bounce ray missed.
#[test]
fn closest_hits_do_not_depend_on_the_scene_unit() {
    let base = closed_cornell_scaled(1.0);
    let mut rng = SplitMix64::new(29);
    // (patch, point, unit direction into the front hemisphere) in scale-1 units, f64.
    let mut starts = Vec::new();
    while starts.len() < 20_000 {
        let p = &base[(rng.unit() * base.len() as f64) as usize];
        let v = &p.vertices;
        let (s, t) = (rng.unit(), rng.unit());
        let (s, t) = if s + t > 1.0 { (1.0 - s, 1.0 - t) } else { (s, t) };
        let x = v[0] + (v[1] - v[0]) * s + (v[2] - v[0]) * t;
        let d = glam::DVec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).normalize();
        let d = if d.dot(p.normal) < 0.0 { -d } else { d };
        starts.push((p.normal, x, d));
    }
    let rays = |k: f64, offset: f32, scaled: bool| -> Vec<Ray> {
        starts
            .iter()
            .map(|&(n, x, d)| {
                // Lifted as the path tracer lifts its origins; the offset is `k` times scale 1's.
                let origin = (x * k + n * f64::from(offset)).as_vec3();
                let direction = if scaled { (d * k).as_vec3() } else { d.as_vec3() };
                Ray::new(origin, direction, 0.0, f32::INFINITY)
            })
            .collect()
    };
    let reference_scene = radiosity_host::formfactor::occluder_scene(&base, true).unwrap();
    let unit_offset = RayCaster::offset(&reference_scene);
    let size =
        f64::from(radiosity_host::raycast::scene_scale(&radiosity_host::formfactor::occluder_mesh(&base).0));
    let reference: Vec<_> =
        rays(1.0, unit_offset, false).iter().map(|r| reference_scene.intersect(r)).collect();
    assert!(reference.iter().all(Option::is_some), "the closed box: every bounce ray hits");
    for k in [2f64.powi(100), 2f64.powi(40), 2f64.powi(-50), 1e12, 1e-15] {
        let patches = closed_cornell_scaled(k);
        let scene = radiosity_host::formfactor::occluder_scene(&patches, true).unwrap();
        let exact = k.log2().fract() == 0.0;
        if exact {
            assert_eq!(RayCaster::offset(&scene), (f64::from(unit_offset) * k) as f32, "{k:e}");
        }
        for scaled in [false, true] {
            let mut other = 0;
            for (ray, expected) in rays(k, RayCaster::offset(&scene), scaled).iter().zip(&reference) {
                let expected = expected.unwrap();
                let Some(hit) = scene.intersect(ray) else {
                    panic!("{k:e}, scaled directions {scaled}: {ray:?} hits nothing (scale 1: {expected:?})");
                };
                // The hit's distance in scale-1 units.
                let t = if scaled { f64::from(hit.t) } else { f64::from(hit.t) / k };
                if exact {
                    assert_eq!(
                        (hit.primitive, hit.barycentric, t),
                        (expected.primitive, expected.barycentric, f64::from(expected.t)),
                        "{k:e}, scaled directions {scaled}: {ray:?}"
                    );
                    assert!((hit.normal - expected.normal).length() <= 1e-6, "{hit:?} vs {expected:?}");
                } else if hit.primitive != expected.primitive {
                    other += 1;
                } else {
                    assert!(
                        (t - f64::from(expected.t)).abs() <= 1e-5 * size,
                        "{k:e}: {hit:?} vs {expected:?}"
                    );
                }
            }
            assert!(
                other * 1000 <= starts.len(),
                "{k:e}, scaled directions {scaled}: {other} other triangles"
            );
        }
    }
}
