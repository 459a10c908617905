//! Light leaks at the blocks' contact lines (issue 20, item 4): what the light map and the renderer's smooth
//! shading show on the floor just beside the Cornell box's blocks, against the continuous reference (point
//! probes of the path tracer) at the same points.
//!
//! Where a block stands on the floor, the floor's radiosity is continuous up to the contact line. A mesh whose
//! floor patches run under a block averages the lit floor with the hidden part (which sees only the backs of
//! the block's faces, so `B = E = 0` there): the floor beside the block comes out too dark, a dark seam along
//! the contact, and the smoothed light runs on under the block. Mesh repair cuts the floor along the contact
//! lines and culls the footprints, and the light map fills the footprint's texels from the nearest visible
//! patch, so neither shows.
//!
//! What is checked, per probe point `x` on the visible floor half a texel from a contact line: the displayed
//! value lies within the range the continuous field takes around `x`. Both displays are weighted means of patch
//! averages with non-negative weights (the smooth shader interpolates vertex values, each an area-weighted mean
//! of the patches around the vertex; the light map holds the shader's values at texel centres and is read
//! bilinearly, as an engine does), and a patch's average lies within the range of the field over the patch. So
//! the displayed value at `x` lies within the range of the field over the patches around `x`'s patch: within
//! two patch diameters `h` of `x`. That range is estimated from probes at `x` and at `h` and `2h` away from the
//! contact, and `h` along it on either side; each probe is allowed 3 standard errors. What this cannot
//! separate is the solve's own error in the patch averages (exact for the mesh, not for the continuous scene):
//! the bound includes the floor's face-average error against the continuous reference's face average, measured
//! in the same test. The unrepaired mesh is checked too and must fail (so the check can fail).

mod common;

use glam::DVec3;
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::montecarlo::{
    continuous_reference, probe_radiosity, Probe, ProbeEstimate, ReferenceOptions, SampleCount,
};
use radiosity_host::patch::Patch;
use radiosity_host::picture::lightmap::{bake_light_map, LightMap, LightMapOptions};
use radiosity_host::picture::shading::{ShadingOptions, SmoothShader};
use radiosity_host::pipeline::{prepare, PrepareOptions, Prepared};
use radiosity_host::rgb::{luminance, Rgb};
use radiosity_host::view::solve_default;

/// The floor's OBJ face in `scenes/cornell-box.obj`, and the blocks' four sides each.
const FLOOR: usize = 0;
const BLOCK_SIDES: [usize; 8] = [9, 10, 11, 12, 14, 15, 16, 17];

/// Paths per probe.
const PATHS: u64 = 4096;

/// The Cornell box at a coarse budget (400 patches, edges up to 140 mm) with the default form factors, solved.
fn solved(repair: bool) -> (Prepared, Vec<Rgb>) {
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: Some(140.0),
        max_patches: Some(400),
        repair,
        form_factors: FormFactorOptions { progress: false, ..FormFactorOptions::default() },
        verbose: false,
    };
    let p = prepare(&common::scene("cornell-box.obj"), &options).unwrap();
    let b = solve_default(&p).unwrap();
    (p, b)
}

/// Whether `x` lies in the convex patch `p` (within `tol` of its edges).
fn contains(p: &Patch, x: DVec3, tol: f64) -> bool {
    let v = &p.vertices;
    (0..v.len()).all(|i| {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        (x - a).dot(p.normal.cross(b - a).normalize()) >= -tol
    })
}

/// The floor patch holding `x`.
fn floor_patch(patches: &[Patch], x: DVec3) -> Option<usize> {
    patches.iter().position(|p| p.face == FLOOR && contains(p, x, 1e-9))
}

/// The light map's value at `x` on face `face`, read bilinearly from the texel centres as an engine does.
fn bilinear(map: &LightMap, face: usize, x: DVec3) -> Rgb {
    let rect = map.rects.iter().find(|r| r.face == face).unwrap();
    let (u, v) = rect.atlas_coords(x);
    let (fx, fy) = (u - 0.5, v - 0.5);
    let (i0, j0) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - i0, fy - j0);
    let texel = |i: f64, j: f64| {
        let c = map.atlas.pixels[j as usize * map.atlas.width as usize + i as usize];
        Rgb::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]))
    };
    texel(i0, j0) * ((1.0 - tx) * (1.0 - ty))
        + texel(i0 + 1.0, j0) * (tx * (1.0 - ty))
        + texel(i0, j0 + 1.0) * ((1.0 - tx) * ty)
        + texel(i0 + 1.0, j0 + 1.0) * (tx * ty)
}

/// One probe point beside a contact line, with what the displays show there and the probes around it.
struct Site {
    side: usize,
    point: DVec3,
    shaded: f64,
    mapped: f64,
    /// The light map read one texel further in, under the block (what bilinear filtering mixes in at the
    /// contact): a black fill would darken the contact, a bright one leak light.
    under: f64,
    /// Indices into the probe list: the point itself first, then its neighbourhood.
    probes: Vec<usize>,
}

/// The sites beside every block side's bottom edge on `prepared`'s floor (at a quarter, half and three quarters
/// of the edge, half a texel out), and the probes they need (appended to `probes`; only points on `visible`, the
/// repaired floor, which leaves out the blocks' footprints).
fn sites(
    prepared: &Prepared,
    b: &[Rgb],
    map: &LightMap,
    visible: &[Patch],
    probes: &mut Vec<Probe>,
) -> Vec<Site> {
    let shader = SmoothShader::new(&prepared.patches, &ShadingOptions::default()).unwrap();
    let scene = &prepared.scene;
    let floor_rect = map.rects.iter().find(|r| r.face == FLOOR).unwrap();
    let delta = 0.5 * floor_rect.texel_size;
    let mut out = Vec::new();
    for &side in &BLOCK_SIDES {
        let polygon = &scene.faces[side];
        let bottom: Vec<DVec3> = polygon.vertices.iter().copied().filter(|v| v.y.abs() < 1e-6).collect();
        assert_eq!(bottom.len(), 2, "face {side} stands on the floor along one edge");
        let n = DVec3::new(polygon.normal.x, 0.0, polygon.normal.z).normalize();
        for t in [0.25, 0.5, 0.75] {
            let point = bottom[0].lerp(bottom[1], t) + delta * n;
            let patch = floor_patch(&prepared.patches, point).expect("the floor beside a block is meshed");
            let h = {
                let v = &prepared.patches[patch].vertices;
                v.iter().flat_map(|a| v.iter().map(move |c| a.distance(*c))).fold(0.0, f64::max)
            };
            // The field's range around the point: the floor patches sharing a vertex with its patch (itself
            // included), probed at their centroids and near their corners (1% of the way in).
            let mut ids = Vec::new();
            let own = &prepared.patches[patch].vertices;
            for q in prepared.patches.iter().filter(|q| {
                q.face == FLOOR && q.vertices.iter().any(|v| own.iter().any(|w| v.distance(*w) < 1e-6 * h))
            }) {
                let c = q.vertices.iter().copied().sum::<DVec3>() / q.vertices.len() as f64;
                for x in std::iter::once(c).chain(q.vertices.iter().map(|v| v.lerp(c, 0.01))) {
                    if floor_patch(visible, x).is_none() {
                        continue; // under a block: not part of the floor anyone sees
                    }
                    ids.push(probes.len());
                    probes.push(Probe { point: x, face: FLOOR });
                }
            }
            ids.insert(0, probes.len());
            probes.push(Probe { point, face: FLOOR });
            out.push(Site {
                side,
                point,
                shaded: luminance(shader.shade(b, patch, point).unwrap()),
                mapped: luminance(bilinear(map, FLOOR, point)),
                under: luminance(bilinear(map, FLOOR, point - 2.0 * delta * n)),
                probes: ids,
            });
        }
    }
    out
}

/// What leaves the field's range around its site (widened by `margin`, a relative allowance for the solve's own
/// error), one line each; prints every site.
fn violations(label: &str, margin: f64, reference_sites: &[ProbeEstimate], sites: &[Site]) -> Vec<String> {
    let mut bad = Vec::new();
    for s in sites {
        let est: Vec<(f64, f64)> = s
            .probes
            .iter()
            .map(|&k| (luminance(reference_sites[k].radiosity), luminance(reference_sites[k].standard_error)))
            .collect();
        let lo = est.iter().map(|(v, se)| v - 3.0 * se).fold(f64::INFINITY, f64::min) * (1.0 - margin);
        let hi = est.iter().map(|(v, se)| v + 3.0 * se).fold(0.0, f64::max) * (1.0 + margin);
        let at = est[0].0;
        eprintln!(
            "{label} face {} at ({:.1}, {:.1}): reference {at:.4} range [{lo:.4}, {hi:.4}] shaded {:.4} map {:.4}",
            s.side, s.point.x, s.point.z, s.shaded, s.mapped
        );
        for (what, v) in
            [("shaded", s.shaded), ("light map", s.mapped), ("light map under the block", s.under)]
        {
            if !(lo..=hi).contains(&v) {
                bad.push(format!(
                    "{label}: {what} {v:.4} beside face {} at ({:.1}, {:.1}) outside [{lo:.4}, {hi:.4}] (reference {at:.4})",
                    s.side, s.point.x, s.point.z
                ));
            }
        }
    }
    bad
}

/// The repaired Cornell box shows the floor beside the blocks within the field's range (shaded, in the light
/// map, and through the light map's texels under the block); the unrepaired one does not (its dark seam).
#[test]
fn no_dark_seam_or_light_leak_beside_the_blocks() {
    let reference = continuous_reference(
        &radiosity_host::scene::Scene::load(common::scene("cornell-box.obj")).unwrap(),
        &ReferenceOptions {
            samples: SampleCount::PerFace(1 << 16),
            progress: false,
            ..ReferenceOptions::default()
        },
    )
    .unwrap();
    let floor_ref = &reference.faces[FLOOR];
    let mut results = Vec::new();
    let mut visible = Vec::new();
    for repair in [true, false] {
        let (prepared, b) = solved(repair);
        if repair {
            visible = prepared.patches.clone();
        }
        let shader = SmoothShader::new(&prepared.patches, &ShadingOptions::default()).unwrap();
        let map = bake_light_map(&prepared.patches, &shader, &b, &LightMapOptions::default()).unwrap();
        // The solve's own error on the floor: its face average (culled area at B = E = 0) against the reference's.
        let (mut area, mut sum) = (0.0, 0.0);
        for (p, v) in prepared.patches.iter().zip(&b) {
            if p.face == FLOOR {
                area += p.area;
                sum += p.area * luminance(*v);
            }
        }
        let mean = sum / floor_ref.area;
        let margin = (mean / luminance(floor_ref.radiosity) - 1.0).abs()
            + 3.0 * luminance(floor_ref.standard_error) / luminance(floor_ref.radiosity);
        eprintln!("repair {repair}: floor mean {mean:.4} vs reference {:.4}, margin {margin:.4}, area {area:.1} of {:.1}", luminance(floor_ref.radiosity), floor_ref.area);
        let mut probes = Vec::new();
        let sites = sites(&prepared, &b, &map, &visible, &mut probes);
        let estimates = probe_radiosity(&prepared.scene, &probes, PATHS, 1).unwrap();
        results.push(violations(if repair { "repaired" } else { "unrepaired" }, margin, &estimates, &sites));
    }
    assert!(results[0].is_empty(), "{}", results[0].join("\n"));
    assert!(!results[1].is_empty(), "the unrepaired mesh should show a seam or a leak");
}
