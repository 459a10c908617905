//! Tests of the patch-to-patch form factors against closed forms, closure, reciprocity, occlusion, convergence
//! and determinism. Patches are built in code; one closed room with hanging lamps goes through the pipeline.

use glam::DVec3;
use radiosity_host::formfactor::{
    compute_form_factors_with, occluder_bvh, point_to_polygon, ClosureMode, FormFactorError,
    FormFactorOptions, FormFactorStats,
};
use radiosity_host::patch::{FormFactorMatrix, Patch};
use radiosity_host::pipeline::{prepare, PrepareOptions};

/// Facing, aligned unit squares at distance 1 (closed form for parallel rectangles, Howell's catalogue C-11).
const F_FACING: f64 = 0.199_824_855_6;
/// Perpendicular unit squares sharing an edge (closed form, Howell's catalogue C-14).
const F_PERPENDICULAR: f64 = 0.200_043_776_2;

/// A patch from a convex polygon given counter-clockwise seen from its front.
fn patch(face: usize, vertices: Vec<DVec3>) -> Patch {
    let n = vertices.len();
    let mut twice_area = DVec3::ZERO;
    for k in 0..n {
        twice_area += vertices[k].cross(vertices[(k + 1) % n]);
    }
    let centroid = vertices.iter().copied().sum::<DVec3>() / n as f64;
    Patch {
        face,
        material: 0,
        area: 0.5 * twice_area.length(),
        normal: twice_area.normalize(),
        centroid,
        vertices,
    }
}

/// Parallelogram `origin + s a + t b`, `s, t` in [0, 1], front side `a x b`.
fn quad(face: usize, origin: DVec3, a: DVec3, b: DVec3) -> Patch {
    patch(face, vec![origin, origin + a, origin + a + b, origin + b])
}

/// Floor `[0,1]^2` at z = 0 facing up, ceiling at z = 1 facing down.
fn facing_squares() -> Vec<Patch> {
    vec![quad(0, DVec3::ZERO, DVec3::X, DVec3::Y), quad(1, DVec3::Z, DVec3::Y, DVec3::X)]
}

/// Floor `[0,1]^2` facing up and the wall x = 0 facing +x, sharing the edge along y.
fn perpendicular_squares() -> Vec<Patch> {
    vec![quad(0, DVec3::ZERO, DVec3::X, DVec3::Y), quad(1, DVec3::ZERO, DVec3::Y, DVec3::Z)]
}

fn quiet(samples_per_patch: usize, rays_per_pair: usize, seed: u64) -> FormFactorOptions {
    FormFactorOptions {
        samples_per_patch,
        rays_per_pair,
        seed,
        progress: false,
        ..FormFactorOptions::default()
    }
}

/// The estimate with the pure-Rust caster: these tests need occlusion only, not Embree (the cross-check against
/// Embree is in `host/tests/embree.rs`).
fn compute(
    patches: &[Patch],
    options: &FormFactorOptions,
) -> Result<(FormFactorMatrix, FormFactorStats), FormFactorError> {
    compute_form_factors_with(&occluder_bvh(patches)?, patches, options)
}

fn entry(m: &FormFactorMatrix, i: usize, j: usize) -> f64 {
    m.get(i, j)
}

fn relative_error(value: f64, exact: f64) -> f64 {
    (value - exact).abs() / exact
}

fn defaults() -> FormFactorOptions {
    FormFactorOptions { progress: false, ..FormFactorOptions::default() }
}

#[test]
fn point_kernel_matches_closed_form() {
    // Differential area on the axis of a coaxial square of half-side a at height h, facing it:
    // F = 4 / (2π) * ( X / sqrt(1 + X^2) * atan(Y / sqrt(1 + X^2)) + (same with X, Y swapped) ), X = Y = a / h
    // (Howell's catalogue B-3, split into 4 corner rectangles).
    let (a, h) = (0.5, 1.0);
    let x = a / h;
    let s = (1.0f64 + x * x).sqrt();
    let exact = 4.0 * 2.0 * (x / s) * (x / s).atan() / (2.0 * std::f64::consts::PI);
    let square = vec![DVec3::new(-a, -a, h), DVec3::new(-a, a, h), DVec3::new(a, a, h), DVec3::new(a, -a, h)];
    let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &square, -DVec3::Z);
    // Pure f64 arithmetic on ~20 operations: a relative error of a few hundred eps at most.
    assert!(relative_error(f, exact) < 1e-13, "{f} vs {exact}");
    // Seen from behind, or facing away: zero.
    assert_eq!(point_to_polygon(DVec3::ZERO, DVec3::Z, &square, DVec3::Z), 0.0);
    assert_eq!(point_to_polygon(DVec3::ZERO, -DVec3::Z, &square, -DVec3::Z), 0.0);
    // Half of the square below the tangent plane (tilted point normal +x at the square's edge x = -a) is
    // clipped away: the remaining half sees F of a point at the corner-edge of a tilted configuration, which must
    // be strictly between 0 and the full value.
    let tilted = point_to_polygon(DVec3::ZERO, DVec3::new(1.0, 0.0, 1.0).normalize(), &square, -DVec3::Z);
    assert!(tilted > 0.0 && tilted < 1.0);
}

/// Both entries of a two-patch matrix are within relative `tolerance` of the closed form `exact`.
fn assert_pair_within(m: &FormFactorMatrix, exact: f64, tolerance: f64) {
    for (i, j) in [(0, 1), (1, 0)] {
        let f = entry(m, i, j);
        assert!(relative_error(f, exact) < tolerance, "F_{i}{j} = {f} vs {exact}");
    }
}

#[test]
fn facing_unit_squares_at_default_settings() {
    let (m, stats) = compute(&facing_squares(), &defaults()).unwrap();
    // Target from the issue: within 0.5%.
    assert_pair_within(&m, F_FACING, 0.005);
    assert_eq!(stats.patches, 2);
    assert_eq!(stats.nonzeros, 2);
    assert!(stats.rays_cast > 0);
    assert!(stats.row_sum_max < 1.0, "an open scene loses energy");
}

#[test]
fn perpendicular_squares_sharing_an_edge_at_default_settings() {
    let (m, _) = compute(&perpendicular_squares(), &defaults()).unwrap();
    assert_pair_within(&m, F_PERPENDICULAR, 0.005);
}

#[test]
fn error_falls_as_samples_grow() {
    // Shared-edge pair (the hardest near field), nothing occludes: the error is the Gauss-Legendre quadrature error
    // of the unoccluded form factor, deterministic, for 2 x 2, 4 x 4 and 8 x 8 points. It must fall at each step,
    // by at least 10x (a rule exact for polynomials of degree 2n - 1 on a kernel whose derivative is only weakly
    // singular at the edge; measured: about 1000x per step).
    let errors: Vec<f64> = [4, 16, 64]
        .iter()
        .map(|&samples| {
            let (m, _) = compute(&perpendicular_squares(), &quiet(samples, 16, 1)).unwrap();
            (entry(&m, 0, 1) - F_PERPENDICULAR).abs()
        })
        .collect();
    println!("|error| for 4, 16, 64 samples per patch: {errors:?}");
    // F_PERPENDICULAR has 10 significant digits (within 5e-11 of the true value): an error below 2e-10 is at the
    // constant's own precision (plus rounding), so it need only stay there. The near-field split (on for this
    // touching pair) measured 6.5e-8, 1.2e-10, 1.2e-10.
    let floor = 2e-10;
    assert!(errors[0] > 10.0 * errors[1].max(floor / 10.0), "{errors:?}");
    assert!(errors[1] > 10.0 * errors[2] || errors[2] <= floor, "{errors:?}");
}

/// The inside of the unit cube, each face split into `k x k` patches, all facing inwards.
fn furnace_cube(k: usize) -> Vec<Patch> {
    let mut patches = Vec::new();
    let step = 1.0 / k as f64;
    // (origin, a, b) with a x b pointing into the cube.
    let faces = [
        (DVec3::ZERO, DVec3::X, DVec3::Y), // z = 0, normal +z
        (DVec3::Z, DVec3::Y, DVec3::X),    // z = 1, normal -z
        (DVec3::ZERO, DVec3::Y, DVec3::Z), // x = 0, normal +x
        (DVec3::X, DVec3::Z, DVec3::Y),    // x = 1, normal -x
        (DVec3::ZERO, DVec3::Z, DVec3::X), // y = 0, normal +y
        (DVec3::Y, DVec3::X, DVec3::Z),    // y = 1, normal -y
    ];
    for (face, (origin, a, b)) in faces.into_iter().enumerate() {
        for s in 0..k {
            for t in 0..k {
                let o = origin + a * (s as f64 * step) + b * (t as f64 * step);
                patches.push(quad(face, o, a * step, b * step));
            }
        }
    }
    patches
}

#[test]
fn closed_cube_rows_sum_to_one() {
    let patches = furnace_cube(3);
    let (m, stats) = compute(&patches, &defaults()).unwrap();
    assert_eq!(stats.patches, 54);
    // Nothing occludes inside a convex box, so with one set of sample points per patch the kernels would sum to
    // 1 exactly. Pairs that touch (across the cube's edges) are integrated with their own near-field points, so
    // a row sums to 1 up to those pairs' quadrature error: at most the 4 x 4 rule's error on the shared-edge pair
    // (3.8e-7 without the split, see `error_falls_as_samples_grow`) for each of the row's few touching pairs.
    // The issue requires 1e-4 (the furnace at rho = 0.99 multiplies row-sum error by 100).
    for i in 0..m.n() {
        let sum = m.row_sum(i);
        assert!((sum - 1.0).abs() < 4.0 * 3.8e-7, "row {i} sums to {sum}");
    }
    assert!((stats.row_sum_min - 1.0).abs() < 1e-4 && (stats.row_sum_max - 1.0).abs() < 1e-4, "{stats:?}");
    // Coplanar patches of the same face never see each other.
    for i in 0..m.n() {
        for (j, _) in m.row(i) {
            assert_ne!(patches[i].face, patches[j].face, "coplanar pair {i}, {j}");
        }
    }
}

#[test]
fn reciprocity_holds_within_quadrature_error() {
    // A 2 x 1 floor and a 1 x 0.5 wall sharing an edge: unequal areas, no occlusion, so each F is the
    // Gauss-Legendre quadrature of the exact point kernel over its own patch, and the only source of
    // non-reciprocity is that quadrature error. Estimate it per entry as the change from the default 4 x 4 rule to
    // 8 x 8 (which converges far faster than that change, see `error_falls_as_samples_grow`); reciprocity must then
    // hold within twice the summed error estimates of the two sides.
    let patches = vec![
        quad(0, DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::Y),
        quad(1, DVec3::ZERO, DVec3::Y, DVec3::new(0.0, 0.0, 0.5)),
    ];
    let (m, stats) = compute(&patches, &defaults()).unwrap();
    let (fine, _) = compute(&patches, &quiet(64, 16, 1)).unwrap();
    let e_01 = (entry(&m, 0, 1) - entry(&fine, 0, 1)).abs();
    let e_10 = (entry(&m, 1, 0) - entry(&fine, 1, 0)).abs();
    let forward = patches[0].area * entry(&m, 0, 1);
    let backward = patches[1].area * entry(&m, 1, 0);
    let tolerance = 2.0 * (patches[0].area * e_01 + patches[1].area * e_10) + 64.0 * f64::EPSILON;
    assert!(
        (forward - backward).abs() <= tolerance,
        "A0 F01 = {forward}, A1 F10 = {backward}, allowed {tolerance}"
    );
    // The reported statistic is the same quantity (relative to A_i F_ij, worst of both directions).
    let reported = (forward - backward).abs() / forward.min(backward);
    assert!((stats.reciprocity_error_max - reported).abs() <= 1e-12, "{stats:?} vs {reported}");
}

/// Floor and ceiling unit squares with a plate at z = 0.5 over x in [0, 0.5] (facing down, so the floor sees its
/// front and the ceiling its back).
fn half_blocked() -> Vec<Patch> {
    let mut patches = facing_squares();
    patches.push(quad(2, DVec3::new(0.0, 0.0, 0.5), DVec3::Y, DVec3::new(0.5, 0.0, 0.0)));
    patches
}

#[test]
fn half_blocking_plate_halves_the_form_factor() {
    // A segment from x on the floor to y on the ceiling crosses z = 0.5 at its midpoint, which the plate covers
    // exactly when x_1 + y_1 < 1. Mirroring both points in x = 0.5 swaps that set with x_1 + y_1 > 1 and keeps the
    // kernel, so exactly half of F is blocked: F = F_FACING / 2.
    let exact = F_FACING / 2.0;
    let rays = 1 << 14;
    let options = quiet(16, rays, 5);
    let (m, stats) = compute(&half_blocked(), &options).unwrap();
    let f = entry(&m, 0, 1);
    // Error bound: F = U v, U the unoccluded value (quadrature error ~1e-7, negligible), v the ratio estimate
    // sum w V / sum w over R rays. The squares are near each other (area over squared distance 1), so the rays go
    // from uniform points x of one square to points of the other drawn uniformly in the solid angle Omega(x) it
    // subtends, with w = Omega(x) cos theta_x. Its variance is about E[w^2 (V - v)^2] / (R E[w]^2), and
    // (V - v)^2 = 1/4 exactly since v = 1/2 and V is 0 or 1. E[w] is the mean over x of the projected solid angle,
    // pi F_FACING, and w <= Omega(centre) = 4 asin(1/5) < 1, so E[w^2] <= E[w]: Var(v) <= 1 / (4 R pi F_FACING)
    // (stratification only lowers it).
    // Four standard deviations of U v, U = F_FACING:
    let tolerance = 4.0 * F_FACING * (1.0 / (4.0 * rays as f64 * std::f64::consts::PI * F_FACING)).sqrt();
    assert!((f - exact).abs() < tolerance, "F = {f}, exact {exact}, allowed {tolerance}");
    // One visible fraction serves both directions: F_10 / U_10 = F_01 / U_01 to rounding, where U is the same
    // quadrature without the plate (same points, same kernel).
    let (unoccluded, _) = compute(&facing_squares(), &options).unwrap();
    let (u01, u10) = (entry(&unoccluded, 0, 1), entry(&unoccluded, 1, 0));
    assert!(
        (f * u10 - entry(&m, 1, 0) * u01).abs() <= 4.0 * f64::EPSILON * f * u10,
        "{f} {}",
        entry(&m, 1, 0)
    );
    // The ceiling sees only the plate's back: nothing; the floor sees its front.
    assert_eq!(entry(&m, 1, 2), 0.0);
    assert!(entry(&m, 0, 2) > 0.0);
    assert!(stats.rays_cast >= rays as u64);
}

#[test]
fn same_seed_same_matrix_for_any_thread_count() {
    let patches = furnace_cube(2).into_iter().chain(half_blocked()).collect::<Vec<_>>();
    let run = |threads| {
        let options = FormFactorOptions { threads: Some(threads), ..quiet(9, 18, 42) };
        compute(&patches, &options).unwrap()
    };
    let (one, stats_one): (FormFactorMatrix, FormFactorStats) = run(1);
    let (two, _) = run(2);
    assert_eq!(one, two);
    assert!(stats_one.rays_cast > 0);
    let (other_seed, _) =
        compute(&patches, &FormFactorOptions { threads: Some(2), ..quiet(9, 18, 43) }).unwrap();
    assert_ne!(one, other_seed, "the seed matters");
}

#[test]
fn bad_patches_and_options_are_rejected() {
    let mut patches = facing_squares();
    patches[1].vertices.truncate(2);
    let err = compute(&patches, &defaults()).unwrap_err();
    assert!(err.to_string().contains("patch 1: 2 vertices"), "{err}");
    let mut patches = facing_squares();
    patches[0].area = 0.0;
    let err = compute(&patches, &defaults()).unwrap_err();
    assert!(err.to_string().contains("patch 0: area 0"), "{err}");
    let err = compute(&facing_squares(), &quiet(0, 1, 1)).unwrap_err();
    assert!(err.to_string().contains("samples_per_patch"), "{err}");
}

/// A small patch facing down over a large floor, with a plate lying just above the floor right below it (a chair
/// seat's underside, the floor, the chair's base): the floor's kernel is concentrated below the seat, where the
/// plate hides it. The plate is parallel to the floor and its shadow from every point of the seat lies on the
/// floor, so the hidden part of the floor subtends, from each point, exactly the plate's own solid angle: the
/// exact form factor is `U(seat, floor) - U(seat, plate)`, both unoccluded quadratures. At the default 16 rays the
/// visible fraction is noisy, but little biased, and its noise is bounded: area-uniform points on the floor seldom
/// fall in the shadow (it is a few percent of the floor's area), so without rays drawn in solid angle most seeds
/// saw the floor as all visible and the rest as mostly hidden. The mean over seeds is within 4 standard errors plus
/// the ratio estimator's own bias at 16 rays, and the spread within what rays drawn in solid angle allow.
#[test]
fn a_hidden_near_field_is_found_at_the_default_ray_count() {
    let seat = quad(0, DVec3::new(-0.15, -0.15, 0.5), DVec3::Y * 0.3, DVec3::X * 0.3);
    let floor = quad(1, DVec3::new(-1.5, -1.5, 0.0), DVec3::X * 3.0, DVec3::Y * 3.0);
    let plate = quad(2, DVec3::new(-0.3, -0.3, 0.07), DVec3::X * 0.6, DVec3::Y * 0.6);
    let (open, _) = compute(&[seat.clone(), floor.clone()], &quiet(16, 16, 1)).unwrap();
    let patches = [seat, floor, plate];
    let (first, _) = compute(&patches, &quiet(16, 16, 1)).unwrap();
    let exact = entry(&open, 0, 1) - entry(&first, 0, 2);
    assert!(exact > 0.2 && exact < 0.8 * entry(&open, 0, 1), "the plate hides a sizeable share: {exact}");
    let seeds = 256;
    let values: Vec<f64> =
        (0..seeds).map(|seed| entry(&compute(&patches, &quiet(16, 16, seed)).unwrap().0, 0, 1)).collect();
    let mean = values.iter().sum::<f64>() / seeds as f64;
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64).sqrt();
    let se = sd / (seeds as f64).sqrt();
    // The ratio estimator's bias: about `CV^2 / R` of the value, CV the weights' coefficient of variation. The
    // weights are the solid angle (nearly constant over the seat, the floor filling most of its hemisphere) times
    // the cosine at the seat of a direction uniform in that solid angle: over a hemisphere, mean 1/2 and variance
    // 1/12, so CV^2 = 1/3.
    let bias = exact / 3.0 / 16.0;
    let allowed = 4.0 * se + bias;
    println!("F(seat, floor): mean {mean:.4} over {seeds} seeds (sd {sd:.4}), exact {exact:.4}, allowed {allowed:.4}");
    assert!(
        (mean - exact).abs() <= allowed,
        "mean {mean} vs exact {exact} (standard error {se}, bias {bias})"
    );
    // And each estimate's spread: the ratio's variance is about E[w^2 (V - v)^2] / (R E[w]^2) <= (1 + CV^2) / R
    // times the largest (V - v)^2, max(v, 1 - v)^2 (stratification lowers it), so F's standard deviation is at most
    // U sqrt((4/3) / 16) max(v, 1 - v); the sample's own standard deviation is off by about 1 / sqrt(2 (n - 1))
    // of itself, and 4 of those are allowed. Area-uniform rays spread wider than this bound here.
    let (u, v) = (entry(&open, 0, 1), exact / entry(&open, 0, 1));
    let spread =
        u * (4.0 / 3.0 / 16.0f64).sqrt() * v.max(1.0 - v) * (1.0 + 4.0 / (2.0 * (seeds - 1) as f64).sqrt());
    assert!(sd <= spread, "standard deviation {sd} over seeds > {spread}");
}

#[test]
fn estimator_beats_area_sampling_per_ray() {
    // Accuracy per ray on the half-blocked pair (exact F = F_FACING / 2): RMS error over 16 seeds of
    // (a) this module's estimator with R rays per pair, and (b) plain area sampling (x, y uniform on the squares,
    // F ~ mean of cos cos / (pi r^2) V), with the same R visibility rays, the estimator of the Embree tests.
    // The kernel-times-visibility estimator must be more accurate per ray, and its error must fall as rays grow
    // (each 4x step should halve it, 1/sqrt(R); 16 seeds keep the RMS estimate within about 20%).
    let exact = F_FACING / 2.0;
    let patches = half_blocked();
    let seeds = 16;
    let mut previous = f64::INFINITY;
    for rays in [16usize, 64, 256] {
        let ours = (0..seeds)
            .map(|seed| {
                let (m, _) = compute(&patches, &quiet(16, rays, seed)).unwrap();
                (entry(&m, 0, 1) - exact).powi(2)
            })
            .sum::<f64>()
            / seeds as f64;
        let plain =
            (0..seeds).map(|seed| (area_sampling(rays, seed) - exact).powi(2)).sum::<f64>() / seeds as f64;
        println!(
            "rays per pair {rays:4}: rms error estimator {:.2e}, area sampling {:.2e}",
            ours.sqrt(),
            plain.sqrt()
        );
        assert!(ours < plain, "rays {rays}: {} vs {}", ours.sqrt(), plain.sqrt());
        assert!(ours.sqrt() < 0.75 * previous, "rays {rays}: {} after {previous}", ours.sqrt());
        previous = ours.sqrt();
    }
}

/// Plain area-sampling estimate of F(floor -> ceiling) with the half plate, visibility decided analytically
/// (the plate blocks exactly when the midpoint's x < 0.5), so only the estimator's own variance is measured.
fn area_sampling(samples: usize, seed: u64) -> f64 {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
    let mut unit = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut sum = 0.0;
    for _ in 0..samples {
        let (x0, x1, y0, y1) = (unit(), unit(), unit(), unit());
        if x0 + y0 < 1.0 {
            continue;
        }
        let r2 = (x0 - y0).powi(2) + (x1 - y1).powi(2) + 1.0;
        sum += 1.0 / (std::f64::consts::PI * r2 * r2);
    }
    sum / samples as f64
}

#[test]
fn closure_error_of_an_occluded_closed_scene_is_visibility_noise() {
    // The furnace cube (4 x 4 per face) with a box floating inside (outward faces): closed, but pairs are partly
    // occluded, so rows sum to 1 only up to the visibility estimate. That error must shrink as rays grow (16 -> 256
    // is 16x the rays, 1/sqrt(R) predicts 4x; we require 2x), while reciprocity, which shares one visibility
    // estimate per pair, stays at the quadrature level of the unoccluded factors whatever the rays.
    let patches = cube_with_box();
    let closure =
        |stats: &FormFactorStats| (stats.row_sum_min - 1.0).abs().max((stats.row_sum_max - 1.0).abs());
    // The raw estimate: closure off.
    let raw = |samples, rays| FormFactorOptions { closure: ClosureMode::Off, ..quiet(samples, rays, 3) };
    let (coarse_matrix, coarse) = compute(&patches, &raw(16, 16)).unwrap();
    let (_, fine) = compute(&patches, &raw(16, 256)).unwrap();
    println!("16 rays per pair: {coarse:?}");
    println!("256 rays per pair: {fine:?}");
    assert!(
        closure(&coarse) > 2.0 * closure(&fine),
        "closure error {} -> {}",
        closure(&coarse),
        closure(&fine)
    );
    assert!(closure(&fine) > 0.0, "occlusion makes closure inexact");
    // Same quadrature, so the same reciprocity error with either ray count (to rounding).
    assert!((coarse.reciprocity_error_max - fine.reciprocity_error_max).abs() < 1e-9, "{coarse:?} {fine:?}");
    // And that error is the quadrature error: the rays do not depend on samples_per_patch, so rerunning with the
    // 8 x 8 rule changes each entry by (about) its 4 x 4 quadrature error; reciprocity, a difference of two entries'
    // errors, must stay within the sum of the two largest relative changes.
    let (finer_quadrature, _) = compute(&patches, &raw(64, 16)).unwrap();
    let mut worst_change = 0.0f64;
    for i in 0..coarse_matrix.n() {
        for (j, f) in coarse_matrix.row(i) {
            if f >= radiosity_host::formfactor::RECIPROCITY_MIN_FACTOR {
                worst_change = worst_change.max((f - entry(&finer_quadrature, i, j)).abs() / f);
            }
        }
    }
    println!("largest relative change 4x4 -> 8x8 points: {worst_change:e}");
    assert!(
        coarse.reciprocity_error_max <= 2.0 * worst_change + 1e-12,
        "{coarse:?} vs change {worst_change}"
    );
}

/// The furnace cube (4 x 4 per face) with a box floating inside: closed, with partly occluded pairs.
fn cube_with_box() -> Vec<Patch> {
    let mut patches = furnace_cube(4);
    let (lo, e) = (0.3, 0.3);
    let corner = DVec3::splat(lo);
    let box_faces = [
        (corner + DVec3::Z * e, DVec3::X * e, DVec3::Y * e),
        (corner, DVec3::Y * e, DVec3::X * e),
        (corner, DVec3::Z * e, DVec3::Y * e),
        (corner + DVec3::X * e, DVec3::Y * e, DVec3::Z * e),
        (corner, DVec3::X * e, DVec3::Z * e),
        (corner + DVec3::Y * e, DVec3::Z * e, DVec3::X * e),
    ];
    for (f, (o, a, b)) in box_faces.into_iter().enumerate() {
        patches.push(quad(6 + f, o, a, b));
    }
    patches
}

fn lookup(m: &FormFactorMatrix, i: usize, j: usize) -> f64 {
    entry(m, i, j)
}

#[test]
fn closed_scene_rows_are_closed_reciprocally_and_only_noisy_entries_move() {
    let patches = cube_with_box();
    let raw_options = FormFactorOptions { closure: ClosureMode::Off, ..quiet(16, 16, 5) };
    let (raw_matrix, raw_stats) = compute(&patches, &raw_options).unwrap();
    let (closed, closed_stats) = compute(&patches, &quiet(16, 16, 5)).unwrap();
    let report = closed_stats.closure.expect("no hemisphere ray escapes a closed cube: detected as closed");
    println!("raw {raw_stats:?}\nclosed {closed_stats:?}");
    assert_eq!(closed_stats.escaped_rays, 0);
    // The raw estimate is off by visibility noise (see the test above), the closed matrix is not: the correction
    // solves the row constraints to CG tolerance 1e-14, so the rows it closes sum to 1 within rounding over a row
    // of ~100 entries (1e-12). Rows with no partly visible entry are left as estimated: exact up to the
    // quadrature error of touching pairs (bound as in `closed_cube_rows_sum_to_one`). All far inside 1e-4.
    assert!((raw_stats.row_sum_min - 1.0).abs() > 1e-4 || (raw_stats.row_sum_max - 1.0).abs() > 1e-4);
    assert!(report.balance.max_residual < 1e-12, "{report:?}");
    for i in 0..closed.n() {
        let sum = closed.row_sum(i);
        assert!((sum - 1.0).abs() < 4.0 * 3.8e-7, "row {i} sums to {sum}");
    }
    // Reciprocal: A_i F_ij = A_j F_ji up to rounding.
    for i in 0..closed.n() {
        for (j, f) in closed.row(i) {
            let (g, h) = (patches[i].area * f, patches[j].area * lookup(&closed, j, i));
            assert!((g - h).abs() <= 1e-12 * g.max(h), "pair {i},{j}: {g} vs {h}");
        }
    }
    // Exact entries (fully visible pairs) keep their reciprocity-averaged estimate: only partly visible ones move.
    let areas: Vec<f64> = patches.iter().map(|p| p.area).collect();
    let mut averaged = raw_matrix.clone();
    averaged.enforce_reciprocity(&areas);
    let mut partly_visible = 0;
    for i in 0..closed.n() {
        for ((j, f), &flagged) in closed.row(i).zip(closed.row_flags(i)) {
            if flagged {
                partly_visible += 1;
            } else {
                let before = lookup(&averaged, i, j);
                assert!((f - before).abs() <= 1e-15 * before.max(1e-300) * 4.0, "exact entry {i},{j} moved");
            }
        }
    }
    assert_eq!(partly_visible, closed_stats.partly_visible_entries);
    assert!(partly_visible > 0, "the box shadows part of the cube");
}

#[test]
fn open_scene_is_detected_and_never_renormalized() {
    // The same cube with its top face (z = 1) removed: rays escape, rows must be left exactly as estimated.
    let patches: Vec<Patch> =
        cube_with_box().into_iter().filter(|p| !(p.normal.z < -0.5 && p.centroid.z > 0.99)).collect();
    let (raw, _) =
        compute(&patches, &FormFactorOptions { closure: ClosureMode::Off, ..quiet(16, 16, 5) }).unwrap();
    let (detected, stats) = compute(&patches, &quiet(16, 16, 5)).unwrap();
    assert!(stats.escaped_rays > 0 && stats.closure.is_none(), "{stats:?}");
    assert_eq!(raw, detected);
    // A floor patch sees the missing ceiling: its row is far below 1.
    assert!(stats.row_sum_min < 0.9, "{stats:?}");
}

#[test]
fn near_field_pairs_are_reciprocal() {
    // A small wall patch (0.1 x 0.1) standing on a unit floor at the middle of its edge x = 0: the floor's 4 x 4
    // rule alone would sample the kernel towards the small patch, which peaks within 0.1 of the contact, at no
    // point closer than 0.07, and missed it (tens of % before the near-field split). With the split, each side is
    // within its quadrature error, estimated as the change to the 16 x 16 rule; reciprocity must hold within twice
    // the sum of those. The small side's rule sees a smooth kernel (error at rounding level, < 1e-9); the floor's
    // split pieces bottom out at 1/64 of the floor, still only ~6x smaller than their distance to the wall's far
    // edge, so its error is a regression bound from measurement (2.1e-3 measured; 2.6e-2 with 3 levels only): 5e-3.
    let patches = vec![
        quad(0, DVec3::ZERO, DVec3::X, DVec3::Y),
        quad(1, DVec3::new(0.0, 0.45, 0.0), DVec3::Y * 0.1, DVec3::Z * 0.1),
    ];
    let (m, _) = compute(&patches, &defaults()).unwrap();
    let (fine, _) = compute(&patches, &quiet(256, 16, 1)).unwrap();
    let e_01 = (entry(&m, 0, 1) - entry(&fine, 0, 1)).abs();
    let e_10 = (entry(&m, 1, 0) - entry(&fine, 1, 0)).abs();
    let (forward, backward) = (patches[0].area * entry(&m, 0, 1), patches[1].area * entry(&m, 1, 0));
    println!("A0 F01 {forward} A1 F10 {backward}, errors {e_01} {e_10}");
    println!("relative errors {} {}", e_01 / entry(&m, 0, 1), e_10 / entry(&m, 1, 0));
    assert!(e_10 / entry(&m, 1, 0) < 1e-9 && e_01 / entry(&m, 0, 1) < 5e-3, "{e_01} {e_10}");
    let tolerance = 2.0 * (patches[0].area * e_01 + patches[1].area * e_10) + 64.0 * f64::EPSILON;
    assert!((forward - backward).abs() <= tolerance, "{forward} vs {backward}, allowed {tolerance}");
}

/// The far-field rule (half the Gauss-Legendre order for pairs whose gap is at least `FAR_FIELD_GAP` diameters of
/// the integrated patch) changes no unoccluded form factor by more than its error estimate, `0.1 (h / D)^4`
/// with `h / D <= 1 / FAR_FIELD_GAP` (1.6e-4 relative), on the Cornell box's initial mesh; visibility uses
/// the same seed and rays, so the matrices differ only where the rule was used. Prints how many pairs used it.
#[test]
fn far_field_rule_matches_the_full_rule() {
    use radiosity_host::formfactor::FAR_FIELD_GAP;
    let scene = radiosity_host::scene::Scene::load(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.obj"),
    )
    .expect("load");
    // The faces as published: the repaired floor's pieces are long and skewed (a 149.5 x 498 triangle, quads across
    // the floor), and on the skewed cells of their grids the 2 x 2 rule is off by more than this estimate.
    let options = radiosity_host::mesh::MeshOptions {
        repair: false,
        ..radiosity_host::mesh::MeshOptions::for_scene(&scene)
    };
    let mesh = radiosity_host::mesh::mesh(&scene, &options).expect("mesh");
    let patches = mesh.patches;
    let run = |far_field| {
        let options = FormFactorOptions { far_field, closure: ClosureMode::Off, ..quiet(16, 4, 5) };
        compute(&patches, &options).unwrap().0
    };
    let (far, full) = (run(true), run(false));
    let bound = 0.1 * FAR_FIELD_GAP.powi(-4);
    let (mut changed, mut worst) = (0usize, 0.0f64);
    for i in 0..patches.len() {
        for (j, f) in full.row(i) {
            let g = entry(&far, i, j);
            let rel = (g - f).abs() / f;
            if rel > 0.0 {
                changed += 1;
            }
            worst = worst.max(rel);
        }
    }
    println!(
        "{} patches, {} of {} entries changed, worst relative change {worst:.2e}",
        patches.len(),
        changed,
        full.nonzeros()
    );
    assert!(changed > 0, "no pair used the far-field rule");
    assert!(worst <= bound, "worst relative change {worst:.3e} > {bound:.1e}");
}

/// The kernel counter counts what the rules evaluate: unit squares 20 apart are in the far field (gap >=
/// `FAR_FIELD_GAP` diameters), so each direction takes the 2 x 2 rule, or 4 x 4 with the far-field rule off; and
/// the two phase timers fit in the whole computation's time.
#[test]
fn kernel_evaluations_follow_the_rules() {
    let far = vec![
        quad(0, DVec3::ZERO, DVec3::X, DVec3::Y),
        quad(1, DVec3::new(0.0, 0.0, 20.0), DVec3::Y, DVec3::X),
    ];
    let (_, stats) = compute(&far, &quiet(16, 16, 1)).unwrap();
    assert_eq!(stats.kernel_evaluations, 2 * 4);
    assert!(stats.kernel_time + stats.visibility_time <= stats.elapsed);
    let full = FormFactorOptions { far_field: false, ..quiet(16, 16, 1) };
    let (_, stats) = compute(&far, &full).unwrap();
    assert_eq!(stats.kernel_evaluations, 2 * 16);
    // Facing squares 1 apart are in each other's near field: the rule runs on pieces split towards the other.
    let (_, stats) = compute(&facing_squares(), &quiet(16, 16, 1)).unwrap();
    assert!(stats.kernel_evaluations > 2 * 16, "{}", stats.kernel_evaluations);
}

/// A room (4 x 2.5 x 3 m, closed) with a lamp panel hanging 1 cm below the ceiling and a small panel floating
/// at desk height, both facing down: the kind of scene a newcomer writes first. The panels' backs make many
/// pairs partly visible in a closed scene, and closing the rows by correcting those entries once asked for
/// changes of 1e8 (the least-squares system of the correction was nearly singular), which the row check then
/// refused. A closure that would make a form factor above 1 is now refused instead, the rows left as estimated
/// ([`radiosity_host::patch::Closure::refused`]), and every entry stays a form factor.
#[test]
fn a_closed_room_with_hanging_lamps_bakes() {
    let dir = std::env::temp_dir().join(format!("radiosity-ff-room-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut obj = String::from("mtllib room.mtl\n");
    let mut quad = |mtl: &str, v: [[f64; 3]; 4]| {
        obj += &format!("usemtl {mtl}\n");
        for p in v {
            obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        obj += "f -4 -3 -2 -1\n";
    };
    let (x, y, z) = (4.0, 2.5, 3.0);
    quad("floor", [[0.0, 0.0, 0.0], [0.0, 0.0, z], [x, 0.0, z], [x, 0.0, 0.0]]);
    quad("wall", [[0.0, y, 0.0], [x, y, 0.0], [x, y, z], [0.0, y, z]]);
    quad("wall", [[0.0, 0.0, 0.0], [x, 0.0, 0.0], [x, y, 0.0], [0.0, y, 0.0]]);
    quad("wall", [[0.0, 0.0, z], [0.0, y, z], [x, y, z], [x, 0.0, z]]);
    quad("wall", [[0.0, 0.0, 0.0], [0.0, y, 0.0], [0.0, y, z], [0.0, 0.0, z]]);
    quad("wall", [[x, 0.0, 0.0], [x, 0.0, z], [x, y, z], [x, y, 0.0]]);
    let h = y - 0.01;
    quad("ceiling_lamp", [[1.5, h, 1.0], [2.5, h, 1.0], [2.5, h, 2.0], [1.5, h, 2.0]]);
    quad("desk_lamp", [[0.5, 1.0, 0.5], [0.8, 1.0, 0.5], [0.8, 1.0, 0.8], [0.5, 1.0, 0.8]]);
    std::fs::write(dir.join("room.obj"), obj).unwrap();
    std::fs::write(
        dir.join("room.mtl"),
        "newmtl wall\nKd 0.6\nnewmtl floor\nKd 0.4 0.35 0.3\nnewmtl ceiling_lamp\nKd 0.5\nKe 10 10 10\n\
         newmtl desk_lamp\nKd 0.5\nKe 20 15 8\n",
    )
    .unwrap();
    std::fs::write(dir.join("room.toml"), "[meshing]\npatch_budget = 300\n").unwrap();
    let p = prepare(&dir.join("room.obj"), &PrepareOptions::quiet(false, 16, 16));
    std::fs::remove_dir_all(&dir).unwrap();
    let p = p.unwrap_or_else(|e| panic!("{e}"));
    let m = &p.form_factors;
    for i in 0..m.n() {
        for (j, f) in m.row(i) {
            assert!((0.0..=1.0).contains(&f), "F[{i}][{j}] = {f}");
        }
    }
    assert!(p.stats.closure.is_some(), "a closed scene");
}
