//! The transfer basis of a baked Cornell box: core's relight (f32 and fixed point) against the f64
//! `B_static + sum_g I_g T_g` of the table's own matrix, within the bound derived from the quantization step
//! (core's `transfer` module docs), and the bake and inspect reports of the section.

// Patches, groups and RGB channels read clearer with index loops (`tv.t[g][i][c]`).
#![allow(clippy::needless_range_loop)]

mod common;

use radiosity_core::codec::decode_emission_f32;
use radiosity_core::codec::transfer::TRANSFER_CODEC;
use radiosity_core::{relight_transfer, transfer_cost, Fixed, Scalar, Table};
use radiosity_host::bake::{bake, shooting_form, BakeInput, BakeOptions, Baked};
use radiosity_host::evaluate::{evaluate, EvaluateOptions, TransferReport};
use radiosity_host::inspect::inspect;
use radiosity_host::pipeline::Prepared;
use radiosity_host::reference::{
    transfer_vectors, LightGroupEmission, Method, RadiositySystem, TransferVectors,
};

/// A coarse Cornell box (the bound under test is about quantization, not form-factor accuracy).
fn cornell() -> Prepared {
    common::coarse_cornell()
}

fn bake_with_transfer(p: &Prepared) -> Baked {
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    bake(&input, &BakeOptions { transfer: true, ..BakeOptions::default() }).unwrap()
}

/// The evaluation's report of the transfer relight of `baked` (baked from `p` with `options`).
fn transfer_report(p: &Prepared, baked: &Baked, options: &BakeOptions) -> Option<TransferReport> {
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    evaluate(&input, baked, &EvaluateOptions::for_bake(p.patches.len(), options)).unwrap().transfer
}

/// The f64 basis of the table's own matrix: the shooting form of the sparsified rows, as the bake solves it.
fn f64_basis(p: &Prepared, baked: &Baked) -> TransferVectors {
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let shoot = shooting_form(&baked.sparse.matrix, &area);
    let system = RadiositySystem::with_row_sum_tolerance(&p.lighting.rho, &shoot, 1e-4).unwrap();
    let lights = LightGroupEmission::of(&p.lighting);
    transfer_vectors(system, &lights, &Method::for_size(area.len())).unwrap()
}

/// The largest `|got - exact| / bound` over patches and channels for one relight; `> 1` is a violation.
///
/// Bound per patch `i` and channel `c` (core `transfer` docs): `sum_g |I_gc| (max(2^-13 T, 2^(K - 27)) +
/// 2^-24 T)` (the code's half step, plus the writer's f32 rounding of the f64 response before quantization),
/// the static base's codes `2^-11 E_s + (2^-11 + 2^-17) G_s` (`E_s`, `G_s` from the table's codes, each
/// within relative `2^-11` of the true value, so scaled by `1 + 2^-11`), and the arithmetic: f32 `(groups + 3) 2^-24 |B|` (one rounding per term of the sum
/// and one per conversion to f64), fixed point `2^-32 (2 (groups + 1) + |B|)`, plus the f32 conversion of
/// the fixed-point result for comparison, `2^-24 |B|`. The f64 basis itself is accurate to its solve's
/// residual (1e-12 relative), far below these.
fn worst_ratio<S: Scalar>(
    table: &Table<'_>,
    tv: &TransferVectors,
    intensity: &[[f32; 3]],
    fixed: bool,
) -> f64 {
    let groups = table.group_count() as usize;
    let i_s: Vec<[S; 3]> = intensity.iter().map(|v| v.map(S::from_f32)).collect();
    let mut out = vec![[S::ZERO; 3]; table.patch_count() as usize];
    let units = relight_transfer(table, &i_s, &mut out).unwrap();
    assert_eq!(units, transfer_cost(table));
    assert_eq!(units as usize, out.len() * (groups + 1));
    let mut worst = 0.0f64;
    for (i, got) in out.iter().enumerate() {
        for c in 0..3 {
            let mut exact = tv.b_static[i][c];
            let e_s = f64::from(decode_emission_f32(table.base_emission(i as u32).unwrap()[c]));
            let g_s = f64::from(decode_emission_f32(table.base_irradiance(i as u32).unwrap()[c]));
            let mut bound =
                (1.0 + 2f64.powi(-11)) * (2f64.powi(-11) * e_s + (2f64.powi(-11) + 2f64.powi(-17)) * g_s);
            for g in 0..groups {
                let k = table.transfer_exponent(g as u32).unwrap()[c];
                let t = tv.t[g][i][c];
                let inten = f64::from(intensity[g][c]);
                exact += inten * t;
                bound += inten.abs()
                    * ((t * 2f64.powi(-13)).max(2f64.powi(i32::from(k) - 27)) + 2f64.powi(-24) * t);
            }
            bound += if fixed {
                2f64.powi(-32) * (2.0 * (groups as f64 + 1.0) + exact.abs()) + 2f64.powi(-24) * exact.abs()
            } else {
                (groups as f64 + 3.0) * 2f64.powi(-24) * exact.abs()
            };
            let diff = (f64::from(got[c].to_f32()) - exact).abs();
            if bound == 0.0 {
                assert_eq!(diff, 0.0, "patch {i} channel {c}: exact 0 but got {}", got[c].to_f32());
            } else {
                worst = worst.max(diff / bound);
            }
        }
    }
    worst
}

#[test]
fn cornell_transfer_relight_matches_f64_within_the_quantization_bound() {
    let p = cornell();
    let baked = bake_with_transfer(&p);
    let table = Table::parse(&baked.table).unwrap();
    assert!(table.has_transfer());
    assert_eq!(table.group_count() as usize, p.lighting.dynamic_groups.len());
    let tv = f64_basis(&p, &baked);
    let groups = table.group_count() as usize;
    // Intensities exact in f32 and in Q32.32, so the comparison sees only the quantization and arithmetic.
    for setting in [[1.0f32, 1.0, 1.0], [0.5, 2.0, 0.25], [3.0, 0.0, 1.0], [0.0; 3]] {
        let intensity = vec![setting; groups];
        let r32 = worst_ratio::<f32>(&table, &tv, &intensity, false);
        let rfx = worst_ratio::<Fixed>(&table, &tv, &intensity, true);
        assert!(r32 <= 1.0, "f32 relight at {setting:?}: worst error is {r32} of the bound");
        assert!(rfx <= 1.0, "fixed-point relight at {setting:?}: worst error is {rfx} of the bound");
    }
    // The codes are the 16-bit small float, so the bound is relative 2^-13 for all but the darkest patches.
    assert_eq!(TRANSFER_CODEC.bits, 16);
    // The report: the quantization alone is within the code's relative half step in area-weighted L2 (the
    // per-patch bound, checked exactly above, is absolute `2^(K - 27)` for patches more than 2^14 below the
    // group's brightest, so their relative error, and the report's max, may exceed 2^-13).
    let options = BakeOptions { transfer: true, ..BakeOptions::default() };
    let t = transfer_report(&p, &baked, &options).expect("transfer report");
    assert!(t.quantization.rel_l2 <= 2f64.powi(-13), "{:?}", t.quantization);
    assert_eq!(t.bytes, groups * 3 + table.patch_count() as usize * groups * 6);
    assert_eq!(baked.table.len(), baked.report.table_bytes.total);
    // Firmware capacities size the relight's output and state its cost.
    assert_eq!(baked.capacities.transfer_out, table.patch_count() as usize);
    assert_eq!(baked.capacities.transfer_cost, transfer_cost(&table) as usize);
    // Inspect shows the section with the same bytes.
    let report = inspect(&baked.table).unwrap();
    let info = report.transfer.expect("inspect shows the transfer section");
    assert_eq!(info.bytes, t.bytes);
    assert_eq!(report.bytes.transfer, t.bytes);
    for (g, max) in info.max_response.iter().enumerate() {
        for c in 0..3 {
            let f64_max = tv.t[g].iter().map(|v| v[c]).fold(0.0, f64::max);
            assert!((max[c] - f64_max).abs() <= f64_max * 2f64.powi(-12), "group {g} channel {c}");
        }
    }
}

#[test]
fn bake_without_transfer_has_no_section() {
    let p = cornell();
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions::default()).unwrap();
    let table = Table::parse(&baked.table).unwrap();
    assert!(!table.has_transfer());
    assert!(transfer_report(&p, &baked, &BakeOptions::default()).is_none());
    assert_eq!(baked.report.table_bytes.transfer, 0);
    assert_eq!((baked.capacities.transfer_out, baked.capacities.transfer_cost), (0, 0));
    assert!(inspect(&baked.table).unwrap().transfer.is_none());
}

/// With 8-bit codes the decoded rows' shooting form exceeds row sum 1 by the codec's rounding (up to 2^-5);
/// the bake's f64 solve of the decoded table allows for it instead of failing.
#[test]
fn eight_bit_bake_with_transfer_succeeds() {
    let p = cornell();
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let codec = radiosity_core::FfCodec::FLOAT8;
    let options = BakeOptions { transfer: true, codec, ..BakeOptions::default() };
    let baked = bake(&input, &options).unwrap();
    let table = Table::parse(&baked.table).unwrap();
    assert_eq!(table.codec(), codec);
    // The transfer basis does not depend on the form-factor codec: same quantization bound, per patch and in
    // area-weighted L2.
    let t = transfer_report(&p, &baked, &options).unwrap();
    assert!(t.quantization.rel_l2 <= 2f64.powi(-13), "{:?}", t.quantization);
    let tv = f64_basis(&p, &baked);
    let intensity = vec![[1.0f32, 1.0, 1.0]; table.group_count() as usize];
    let r32 = worst_ratio::<f32>(&table, &tv, &intensity, false);
    assert!(r32 <= 1.0, "f32 relight of the 8-bit table: worst error is {r32} of the bound");
}
