//! Tests of baking, inspecting and firmware capacities, on form-factor matrices built directly (a furnace with
//! analytic form factors, random reciprocal open scenes).
//!
//! Error bounds used below, from core's crate docs ("Error bounds"):
//! - FLOAT16 form factors: relative error `< 2^-12` for entries `>= row max / 2^14` (so for every entry of a
//!   uniform row), rounding never up, so a decoded row sum is `>= (1 - 2^-12)` times the true one;
//! - reflectance: absolute error `<= 2^-17`; emission and irradiance codes: relative `<= 2^-11`;
//! - shooting converged at tolerance `tau` (power units): per-patch error `<= n tau / ((1 - rho_max) A_min)`;
//! - f32 arithmetic: each of the `k` additions into a patch's power rounds by at most `eps_32 / 2` relative to
//!   the running value (`<= B A`), so at most `k eps_32 / 2` relative, `k` = shots until convergence.

// Dense matrices and RGB channels read clearer with index loops (`w[i][j]`, `g[c]`).
#![allow(clippy::needless_range_loop)]

use glam::DVec3;
use radiosity_core::{Buffers, Config, FfCodec, Outcome, OwnedBuffers, Solver, SolverError, Table};
use radiosity_host::bake::{
    bake, codec_for_bits, gather, group_id, reachable_patches, shooting_form, sparsify, BakeError, BakeInput,
    BakeOptions, Baked, DroppedEnergy, EnergyDropped, RETURN_TOLERANCE,
};
use radiosity_host::evaluate::{evaluate, BakeErrors, BakeSummary, EvaluateOptions, Evaluation};
use radiosity_host::inspect::{inspect, inspect_file, InspectError};
use radiosity_host::lighting::PatchLighting;
use radiosity_host::patch::{FormFactorMatrix, Patch};
use radiosity_host::rgb::Rgb;
use radiosity_host::rng::SplitMix64;

const EPS32: f64 = f32::EPSILON as f64;

/// A square patch of side `sqrt(area)` in the z = 0 plane (only area and material matter to a bake).
fn patch(k: usize, area: f64, material: usize) -> Patch {
    let s = area.sqrt();
    let o = DVec3::new(k as f64 * 2.0 * s, 0.0, 0.0);
    let vertices = vec![o, o + DVec3::X * s, o + DVec3::new(s, s, 0.0), o + DVec3::Y * s];
    Patch { face: k, material, vertices, normal: DVec3::Z, area, centroid: o + DVec3::new(s, s, 0.0) / 2.0 }
}

fn dense_to_csr(rows: &[Vec<f64>]) -> FormFactorMatrix {
    FormFactorMatrix::from_dense(rows).unwrap()
}

/// A scene: patches, per-material reflectance, lighting and group names, and its form factors.
struct TestScene {
    patches: Vec<Patch>,
    materials: Vec<Rgb>,
    lighting: PatchLighting,
    names: Vec<String>,
    ff: FormFactorMatrix,
}

impl TestScene {
    fn input(&self) -> BakeInput<'_> {
        BakeInput {
            patches: &self.patches,
            materials: self.materials.clone(),
            lighting: &self.lighting,
            group_names: self.names.clone(),
            form_factors: &self.ff,
        }
    }

    fn bake(&self, threshold: f64, codec: FfCodec) -> Baked {
        let options = BakeOptions { threshold, codec, ..BakeOptions::default() };
        bake(&self.input(), &options).expect("bake")
    }

    /// The evaluation of `baked`, baked from this scene with `options`.
    fn evaluate_with(&self, baked: &Baked, options: &BakeOptions) -> Evaluation {
        let options = EvaluateOptions::for_bake(self.patches.len(), options);
        evaluate(&self.input(), baked, &options).expect("evaluate")
    }

    /// The error of `baked`, baked from this scene at default options but for threshold and codec.
    fn errors(&self, baked: &Baked) -> BakeErrors {
        self.evaluate_with(baked, &BakeOptions::default()).errors
    }
}

/// Lighting with no emission; patches take their material's reflectance.
fn dark_lighting(patches: &[Patch], materials: &[Rgb], groups: usize) -> PatchLighting {
    let n = patches.len();
    PatchLighting {
        rho: patches.iter().map(|p| materials[p.material]).collect(),
        static_emission: vec![Rgb::ZERO; n],
        unit_emission: vec![Rgb::ZERO; n],
        group: vec![None; n],
        dynamic_groups: (0..groups).collect(),
        default_intensity: vec![Rgb::ONE; groups],
    }
}

/// The white furnace: `n` equal patches of area 1 in a closed box where every patch sees every other one
/// equally, `F_ij = 1 / (n - 1)` for `j != i` (rows sum to 1, reciprocal). Every patch emits `e` in one dynamic
/// light group at default intensity 1, reflectance `rho`. Exact answer `B = e / (1 - rho)`.
fn furnace(n: usize, rho: f64, e: f64) -> TestScene {
    let patches: Vec<Patch> = (0..n).map(|k| patch(k, 1.0, 0)).collect();
    let materials = vec![Rgb::splat(rho)];
    let f = 1.0 / (n - 1) as f64;
    let rows: Vec<Vec<f64>> =
        (0..n).map(|i| (0..n).map(|j| if i == j { 0.0 } else { f }).collect()).collect();
    let mut lighting = dark_lighting(&patches, &materials, 1);
    lighting.unit_emission = vec![Rgb::splat(e); n];
    lighting.group = vec![Some(0); n];
    TestScene { patches, materials, lighting, names: vec!["sky".into()], ff: dense_to_csr(&rows) }
}

/// A random open, exactly reciprocal scene: areas in `[0.5, 2)`, symmetric couplings `w_ij` with probability
/// `density`, `F_ij = w_ij / A_i` scaled so the largest row sum is 0.9 (so `A_i F_ij = A_j F_ji`).
fn random_scene(seed: u64, n: usize, density: f64) -> TestScene {
    let mut rng = SplitMix64::new(seed);
    let materials: Vec<Rgb> = (0..4)
        .map(|_| Rgb::new(0.2 + 0.6 * rng.unit(), 0.2 + 0.6 * rng.unit(), 0.2 + 0.6 * rng.unit()))
        .collect();
    let area: Vec<f64> = (0..n).map(|_| 0.5 + 1.5 * rng.unit()).collect();
    let mut w = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            if rng.unit() < density {
                // Spread over three decades so sparsification has small entries to drop.
                let v = 10f64.powf(-3.0 * rng.unit());
                w[i][j] = v;
                w[j][i] = v;
            }
        }
    }
    let max_sum = (0..n).map(|i| w[i].iter().sum::<f64>() / area[i]).fold(0.0, f64::max);
    let scale = 0.9 / max_sum;
    let rows: Vec<Vec<f64>> = (0..n).map(|i| w[i].iter().map(|x| x * scale / area[i]).collect()).collect();
    let patches: Vec<Patch> = (0..n).map(|k| patch(k, area[k], k % materials.len())).collect();
    let lighting = dark_lighting(&patches, &materials, 0);
    TestScene { patches, materials, lighting, names: Vec::new(), ff: dense_to_csr(&rows) }
}

/// `random_scene` with patch 0 a static light, patches 1 and 2 dynamic group `lamp`, patch 3 group `sun`.
fn lit_scene(seed: u64, n: usize, density: f64, lamp_intensity: Rgb) -> TestScene {
    let mut s = random_scene(seed, n, density);
    s.lighting.static_emission[0] = Rgb::new(40.0, 30.0, 20.0);
    s.lighting.dynamic_groups = vec![0, 1];
    s.lighting.default_intensity = vec![lamp_intensity, Rgb::splat(0.5)];
    s.names = vec!["lamp".into(), "sun".into()];
    let (lamp, sun) = (Rgb::new(100.0, 90.0, 80.0), Rgb::new(10.0, 20.0, 30.0));
    for (k, g, e) in [(1, 0, lamp), (2, 0, lamp), (3, 1, sun)] {
        s.lighting.group[k] = Some(g);
        s.lighting.unit_emission[k] = e;
    }
    s
}

/// Removes one element from one buffer.
mod device;
mod inspect;
mod sparsify;
