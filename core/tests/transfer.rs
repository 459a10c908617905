//! The transfer basis: golden bytes of the section, relighting against known vectors in f32 and fixed point
//! within the bound derived from the quantization step, agreement with shooting, and the errors.

mod common;

use common::{Scene, Store};
use radiosity_core::codec::transfer::decode_transfer;
use radiosity_core::crc::crc32;
use radiosity_core::format::QuantParam;
use radiosity_core::{
    relight_transfer, transfer_cost, Config, Fixed, MemberSpec, Outcome, Scalar, Table, TableError,
    TransferError, WriteError,
};

/// Three patches, two light groups, a solved static base, and a transfer basis of known values.
fn three(transfer: Vec<[f32; 3]>) -> Scene {
    let mut s = Scene::new(3);
    s.base_solved = true;
    s.materials = vec![[0.5, 0.25, 0.75]];
    s.patches[0].base_emission = [1.0, 0.0, 0.5];
    s.patches[1].base_irradiance = [0.3, 0.7, 0.0];
    s.patches[2].area = 2.0;
    s.patches[2].base_irradiance = [1e-3, 2.0, 5.0];
    s.groups = vec![
        (1, [1.0; 3], vec![MemberSpec { patch: 0, emission: [1.0; 3] }]),
        (2, [0.5; 3], vec![MemberSpec { patch: 2, emission: [4.0, 2.0, 1.0] }]),
    ];
    s.rows = vec![vec![(1, 0.25), (2, 0.5)], vec![(0, 0.25)], vec![(0, 0.25), (1, 0.125)]];
    s.transfer = Some(transfer);
    s
}

/// Responses spanning several magnitudes per group and channel, patch-major `[i * 2 + g]`.
fn known_responses() -> Vec<[f32; 3]> {
    vec![
        [1.37, 0.021, 3.3e-4],
        [0.004, 0.9, 12.5],
        [0.61, 0.0, 1.1e-5],
        [0.2, 0.05, 7.75],
        [0.0123, 0.0007, 0.0],
        [1.9, 0.33, 0.001],
    ]
}

/// f64 static radiosity `E_s + rho G_s` of the scene's base (exact inputs, before quantization).
fn static_f64(s: &Scene, i: usize) -> [f64; 3] {
    let p = s.patches[i];
    let rho = s.materials[p.material as usize];
    [0, 1, 2].map(|c| f64::from(p.base_emission[c]) + f64::from(rho[c]) * f64::from(p.base_irradiance[c]))
}

/// Half a code step of the transfer code: `max(2^-13 T, 2^(K - 27))` (`core::transfer`, "Quantization").
fn quantization_bound(t: f64, k: i8) -> f64 {
    (t * 2f64.powi(-13)).max(2f64.powi(i32::from(k) - 27))
}

/// The bound of the crate docs (`core::transfer`, "Error bound of a relight") for patch `i`, channel `c`:
/// half a code step per group times `|I|`, the static base's codes, and the arithmetic.
fn bound(t: &Table<'_>, s: &Scene, intensity: &[[f32; 3]], i: usize, c: usize, fixed: bool) -> f64 {
    let p = s.patches[i];
    let groups = t.group_count();
    let mut b = 0.0;
    let mut magnitude = static_f64(s, i)[c].abs();
    for g in 0..groups {
        let k = t.transfer_exponent(g).unwrap()[c];
        let resp = f64::from(s.transfer.as_ref().unwrap()[i * groups as usize + g as usize][c]);
        b += f64::from(intensity[g as usize][c]).abs() * quantization_bound(resp, k);
        magnitude += f64::from(intensity[g as usize][c]).abs() * resp;
    }
    // Emission codes: relative 2^-11; reflectance code: absolute 2^-17 on rho (times G_s).
    b += 2f64.powi(-11) * f64::from(p.base_emission[c])
        + (2f64.powi(-11) + 2f64.powi(-17)) * f64::from(p.base_irradiance[c]);
    let arithmetic = if fixed {
        // One 2^-32 per decode and per product, a response's decode times |I|, plus the rounding of each
        // intensity to Q32.32 (times T).
        let intensities: f64 = (0..groups as usize).map(|g| f64::from(intensity[g][c]).abs()).sum();
        2f64.powi(-32) * (2.0 * f64::from(groups + 1) + intensities + magnitude)
    } else {
        // One f32 rounding per product and per sum (2 (groups + 1)), relative 2^-24 of the magnitude.
        2f64.powi(-24) * f64::from(2 * (groups + 1)) * magnitude
    };
    b + arithmetic
}

fn check_relight<S: Scalar>(fixed: bool) {
    let s = three(known_responses());
    let blob = s.write();
    let t = Table::parse(&blob).expect("table with a transfer basis parses");
    assert!(t.has_transfer());
    let settings: [[[f32; 3]; 2]; 4] = [
        [[1.0; 3], [0.0; 3]],
        [[0.0; 3], [1.0; 3]],
        [[2.5, 0.5, 0.0], [0.125, 3.0, 1.0]],
        [[-1.0, 7.0, 0.3], [100.0, 0.01, 2.0]],
    ];
    for intensity in settings {
        let i_s: Vec<[S; 3]> = intensity.iter().map(|v| v.map(S::from_f32)).collect();
        let mut out = vec![[S::ZERO; 3]; 3];
        let units = relight_transfer(&t, &i_s, &mut out).expect("relight");
        assert_eq!(units, 3 * (2 + 1), "cost: patches x (groups + 1)");
        assert_eq!(units, transfer_cost(&t));
        for (i, got_i) in out.iter().enumerate() {
            let base = static_f64(&s, i);
            for c in 0..3 {
                let exact = base[c]
                    + (0..2)
                        .map(|g| {
                            f64::from(intensity[g][c]) * f64::from(s.transfer.as_ref().unwrap()[i * 2 + g][c])
                        })
                        .sum::<f64>();
                let got = f64::from(got_i[c].to_f32());
                let allowed = bound(&t, &s, &intensity, i, c, fixed);
                // to_f32 of the result rounds once more (relative 2^-24).
                let allowed = allowed + 2f64.powi(-24) * got.abs();
                assert!(
                    (got - exact).abs() <= allowed,
                    "patch {i} channel {c} intensity {intensity:?}: got {got}, exact {exact}, \
                     difference {:e}, allowed {allowed:e}",
                    (got - exact).abs()
                );
            }
        }
    }
}

#[test]
fn relight_matches_known_vectors_within_the_quantization_bound_f32() {
    check_relight::<f32>(false);
}

#[test]
fn relight_matches_known_vectors_within_the_quantization_bound_fixed() {
    check_relight::<Fixed>(true);
}

#[test]
fn stored_scales_put_each_group_and_channel_in_the_top_binade() {
    let s = three(known_responses());
    let blob = s.write();
    let t = Table::parse(&blob).unwrap();
    let r = known_responses();
    let top = 2.0 - 2f64.powi(-13); // the top code plus half a step
    for g in 0..2u32 {
        let k = t.transfer_exponent(g).unwrap();
        for c in 0..3 {
            let max = f64::from((0..3).map(|i| r[i * 2 + g as usize][c]).fold(0.0f32, f32::max));
            let scale = 2f64.powi(i32::from(k[c]));
            assert!(max <= top * scale, "group {g} channel {c}: max {max} above the top code at K {}", k[c]);
            assert!(max > top * scale / 2.0, "group {g} channel {c}: K {} is not the smallest", k[c]);
            for i in 0..3u32 {
                let d = f64::from(t.transfer_response(i, g).unwrap()[c]);
                let v = f64::from(r[i as usize * 2 + g as usize][c]);
                assert!(
                    (d - v).abs() <= quantization_bound(v, k[c]),
                    "patch {i} group {g} channel {c}: {d} vs {v}"
                );
            }
        }
    }
}

/// Two patches facing each other with dyadic form factors (exact in FLOAT16), one light group: the transfer
/// relight and a converged shooting solve are two answers to the same system.
#[test]
fn relight_agrees_with_shooting() {
    // Areas 1 and 2, F_01 = 0.5, F_10 = 0.25 (reciprocal), rho 0.5, group member patch 0 with unit emission 1.
    // B_0 = 1 + 0.5 * 0.5 * B_1, B_1 = 0.5 * 0.25 * B_0  =>  B_0 = 1 / (1 - 0.03125), B_1 = 0.125 B_0.
    let b0 = 1.0 / (1.0 - 0.5 * 0.5 * 0.5 * 0.25);
    let mut s = Scene::new(2);
    s.base_solved = true;
    s.patches[1].area = 2.0;
    s.groups = vec![(7, [1.0; 3], vec![MemberSpec { patch: 0, emission: [1.0; 3] }])];
    s.rows = vec![vec![(1, 0.5)], vec![(0, 0.25)]];
    s.transfer = Some(vec![[b0 as f32; 3], [(0.125 * b0) as f32; 3]]);
    let blob = s.write();
    let t = Table::parse(&blob).unwrap();
    let intensity = [0.75f32, 2.0, 0.0];
    let mut out = [[0.0f32; 3]; 2];
    relight_transfer(&t, &[intensity], &mut out).unwrap();
    let mut store = Store::<f32>::for_table(&t);
    let tolerance = 1e-7f32;
    let mut solver = common::solver(&mut store, &t, Config { tolerance, overshoot: 0 });
    solver.set_light(0, intensity).unwrap();
    while let Outcome::BudgetSpent { .. } = solver.step(64) {}
    for i in 0..2u32 {
        let shot = solver.radiosity(i).unwrap();
        for c in 0..3 {
            let k = t.transfer_exponent(0).unwrap()[c];
            let exact = if i == 0 { b0 } else { 0.125 * b0 };
            // Transfer: half a code step times |I|; shooting: n * tolerance / ((1 - rho) A_min) (crate docs)
            // and f32 rounding of values near 2 (a few ulps).
            let allowed = f64::from(intensity[c]) * quantization_bound(exact, k)
                + 2.0 * f64::from(tolerance) / 0.5
                + 8.0 * f64::from(f32::EPSILON) * 2.0;
            let diff = f64::from((out[i as usize][c] - shot[c]).abs());
            assert!(
                diff <= allowed,
                "patch {i} channel {c}: transfer {:?} shooting {shot:?}",
                out[i as usize]
            );
        }
    }
}

#[test]
fn relight_errors_are_named() {
    let blob = three(known_responses()).write();
    let t = Table::parse(&blob).unwrap();
    let mut out = [[0.0f32; 3]; 3];
    assert_eq!(
        relight_transfer(&t, &[[1.0f32; 3]], &mut out),
        Err(TransferError::IntensityTooShort { needed: 2, got: 1 })
    );
    assert_eq!(
        relight_transfer(&t, &[[1.0f32; 3]; 2], &mut out[..2]),
        Err(TransferError::OutputTooSmall { needed: 3, got: 2 })
    );
    assert_eq!(
        relight_transfer(&t, &[[1.0f32; 3], [1.0, f32::NAN, 1.0]], &mut out),
        Err(TransferError::BadIntensity { group: 1, channel: 1 })
    );
    assert_eq!(out, [[0.0f32; 3]; 3], "output untouched on error");
    let mut plain = three(known_responses());
    plain.transfer = None;
    let blob = plain.write();
    let t = Table::parse(&blob).unwrap();
    assert_eq!(relight_transfer(&t, &[[1.0f32; 3]; 2], &mut out), Err(TransferError::NoTransferSection));
    assert_eq!(t.transfer_exponent(0), None);
    assert_eq!(t.transfer_response(0, 0), None);
}

#[test]
fn range_relights_are_the_whole_relight_in_pieces() {
    use radiosity_core::relight_transfer_range;
    let blob = three(known_responses()).write();
    let t = Table::parse(&blob).unwrap();
    let intensity = [[1.5f32, 0.25, 3.0], [0.5, 2.0, 0.0]];
    let mut whole = [[0.0f32; 3]; 3];
    relight_transfer(&t, &intensity, &mut whole).unwrap();
    // Every split of the 3 patches into runs, through a buffer of each length: the same bits; units are the
    // elements relit times (groups + 1), clipped at the last element.
    for len in 1..=4usize {
        let mut pieces = Vec::new();
        let mut units = 0;
        let mut first = 0u32;
        while first < 3 {
            let mut buf = vec![[f32::NAN; 3]; len];
            units += relight_transfer_range(&t, &intensity, first, &mut buf).unwrap();
            let count = len.min(3 - first as usize);
            pieces.extend_from_slice(&buf[..count]);
            assert!(buf[count..].iter().all(|b| b.iter().all(|v| v.is_nan())), "past the end untouched");
            first += count as u32;
        }
        assert_eq!(units, 3 * 3, "chunks of {len}");
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&pieces), bits(&whole), "chunks of {len}");
    }
    let mut buf = [[0.0f32; 3]; 2];
    assert_eq!(relight_transfer_range(&t, &intensity, 3, &mut buf), Ok(0));
    assert_eq!(
        relight_transfer_range(&t, &intensity, 4, &mut buf),
        Err(TransferError::RangeOutOfTable { first: 4, elements: 3 })
    );
    assert_eq!(buf, [[0.0f32; 3]; 2], "untouched on error");
}

#[test]
fn writer_rejects_bad_transfer_bases() {
    let mut s = three(known_responses());
    s.transfer.as_mut().unwrap().pop();
    assert_eq!(write(&s), Err(WriteError::TransferLength { expected: 6, got: 5 }));
    let mut s = three(known_responses());
    s.transfer.as_mut().unwrap()[4][1] = -0.5;
    assert_eq!(write(&s), Err(WriteError::BadValue { what: "transfer response", position: 4, value: -0.5 }));
    let mut s = three(known_responses());
    s.base_solved = false;
    assert_eq!(write(&s), Err(WriteError::TransferNeedsSolvedBase));
}

/// Writes `s` through core's writer, returning its error (`Scene::write` panics on one).
fn write(s: &Scene) -> Result<usize, WriteError> {
    s.write_into(&mut vec![0u8; 4096])
}

fn fix_crc(b: &mut [u8]) {
    let n = b.len() - 4;
    let c = crc32(&b[..n]);
    b[n..].copy_from_slice(&c.to_le_bytes());
}

/// Golden bytes of the transfer section of [`three`] (the last part of the payload, before the CRC): the
/// exponents, then the codes patch-major.
#[test]
fn golden_transfer_section() {
    let blob = three(known_responses()).write();
    let len = blob.len();
    // 2 groups x 3 exponents + 3 patches x 2 groups x 3 codes x 2 bytes = 42 bytes before the CRC.
    let section = &blob[len - 4 - 42..len - 4];
    #[rustfmt::skip]
    let golden: [u8; 42] = [
        // scale exponents K = floor(log2 max): group 0: max 1.37 -> 0, 0.021 -> -6, 3.3e-4 -> -12;
        // group 1: max 1.9 -> 0, 0.9 -> -1, 12.5 -> 3
        0x00, 0xfa, 0xf4, 0x00, 0xff, 0x03,
        // FLOAT16 codes (row exponent 0) of T / 2^K, nearest; patch 0 group 0: 1.37 -> 62956 (1.37012),
        // 0.021 * 64 = 1.344 -> 62849, 3.3e-4 * 4096 = 1.35168 -> 62880 (1.35156)
        0xec, 0xf5, 0x81, 0xf5, 0xa0, 0xf5,
        // patch 0 group 1: 0.004 -> 28770 (0.0039997), 0.9 * 2 = 1.8 -> 64717, 12.5 / 8 = 1.5625 -> 63744
        0x62, 0x70, 0xcd, 0xfc, 0x00, 0xf9,
        // patch 1 group 0: 0.61 -> 58245, 0 -> 0, 1.1e-5 * 4096 = 0.045056 -> 42770
        0x85, 0xe3, 0x00, 0x00, 0x12, 0xa7,
        // patch 1 group 1: 0.2 -> 51610, 0.05 * 2 = 0.1 -> 47514, 7.75 / 8 = 0.96875 -> 61184
        0x9a, 0xc9, 0x9a, 0xb9, 0x00, 0xef,
        // patch 2 group 0: 0.0123 -> 35121, 0.0007 * 64 = 0.0448 -> 42736, 0 -> 0
        0x31, 0x89, 0xf0, 0xa6, 0x00, 0x00,
        // patch 2 group 1: 1.9 -> 65126, 0.33 * 2 = 0.66 -> 58655, 0.001 / 8 = 1.25e-4 -> 8290
        0x66, 0xfe, 0x1f, 0xe5, 0x62, 0x20,
    ];
    assert_eq!(section, &golden[..], "transfer section layout changed: bump FORMAT_VERSION");
}

#[test]
fn parse_rejects_inconsistent_transfer_sections() {
    let blob = three(known_responses()).write();
    let len = blob.len();
    let exponents = len - 4 - 42;
    // An exponent above the range.
    let mut b = blob.clone();
    b[exponents + 4] = 33;
    fix_crc(&mut b);
    assert_eq!(
        Table::parse(&b).err(),
        Some(TableError::BadQuantParams { param: QuantParam::TransferExponent, value: 1 })
    );
    // Below the range.
    let mut b = blob.clone();
    b[exponents] = (-97i8) as u8;
    fix_crc(&mut b);
    assert_eq!(
        Table::parse(&b).err(),
        Some(TableError::BadQuantParams { param: QuantParam::TransferExponent, value: 0 })
    );
    // Truncated inside the section (CRC moved to the new end): the length check names the sizes.
    let mut b = blob[..len - 6].to_vec();
    b.extend_from_slice(&[0; 4]);
    fix_crc(&mut b);
    assert_eq!(Table::parse(&b).err(), Some(TableError::Truncated { expected: len, actual: len - 2 }));
    // The header says "transfer" but the base is not solved: the header's base_solved byte is 14.
    let mut b = blob.clone();
    assert_eq!(b[14], 1, "base_solved byte");
    b[14] = 0;
    fix_crc(&mut b);
    assert_eq!(Table::parse(&b).err(), Some(TableError::TransferWithoutSolvedBase));
    // Transfer flag cleared: the section becomes trailing bytes.
    let mut b = blob.clone();
    let flag = 16; // header: ... base_solved 14, fingerprint 0 (1 byte) 15, transfer 16
    assert_eq!(b[flag], 1, "transfer flag byte");
    b[flag] = 0;
    fix_crc(&mut b);
    assert_eq!(Table::parse(&b).err(), Some(TableError::TrailingBytes { expected: len - 42, actual: len }));
}

#[test]
fn decode_is_exact() {
    // Code 0xf000: exponent field 15, mantissa 0 -> 1.0 under K = 0; the subnormal step is 2^-26.
    assert_eq!(decode_transfer(0xf000, 0), 1.0);
    assert_eq!(decode_transfer(0xf000, -3), 0.125);
    assert_eq!(decode_transfer(1, 0), 2f32.powi(-26));
    assert_eq!(decode_transfer(0xffff, 0), 2.0 - 2f32.powi(-12));
}

#[test]
fn tables_with_more_groups_than_a_block_sum_in_group_order() {
    use radiosity_core::TRANSFER_GROUP_BLOCK;
    // Every block size (the relight's products are unrolled per block size) and up to 2 blocks and 3 groups.
    for groups in 1..=2 * TRANSFER_GROUP_BLOCK + 3 {
        sums_in_group_order(groups);
    }
}

/// Three patches (one with a static base) and `groups` light groups, responses spread over magnitudes so that
/// the f32 sums depend on their order: relit (whole and one element at a time) bit for bit the naive sum.
fn sums_in_group_order(groups: usize) {
    use radiosity_core::relight_transfer_range;
    let mut s = three(Vec::new());
    s.groups = (0..groups)
        .map(|g| (g as u32 + 1, [1.0; 3], vec![MemberSpec { patch: (g % 3) as u32, emission: [1.0; 3] }]))
        .collect();
    let response = |i: usize, g: usize| {
        let v = (1.0 + (i * 7 + g * 13) as f32 * 0.37) * 10f32.powi((g % 5) as i32 - 2);
        [v, 0.5 * v, if g.is_multiple_of(4) { 0.0 } else { 3.0 * v }]
    };
    s.transfer = Some((0..3).flat_map(|i| (0..groups).map(move |g| response(i, g))).collect());
    let blob = s.write();
    let t = Table::parse(&blob).unwrap();
    let intensity: Vec<[f32; 3]> = (0..groups).map(|g| [0.3 + g as f32, 1.7, 0.01 * g as f32]).collect();
    // The naive sum: static base, then every group in order, each term the product with the decoded response.
    let want: Vec<[f32; 3]> = (0..3u32)
        .map(|i| {
            let mut b: [f32; 3] = radiosity_core::static_radiosity(&t, i).unwrap();
            for (g, rgb) in intensity.iter().enumerate() {
                let r = t.transfer_response(i, g as u32).unwrap();
                for c in 0..3 {
                    b[c] += rgb[c] * r[c];
                }
            }
            b
        })
        .collect();
    let mut out = [[0.0f32; 3]; 3];
    assert_eq!(relight_transfer(&t, &intensity, &mut out), Ok(3 * (groups as u32 + 1)));
    let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&out), bits(&want), "{groups} groups");
    // The same through a one-element buffer.
    for i in 0..3u32 {
        let mut one = [[0.0f32; 3]; 1];
        relight_transfer_range(&t, &intensity, i, &mut one).unwrap();
        assert_eq!(bits(&one), bits(&want[i as usize..=i as usize]), "{groups} groups, element {i}");
    }
}
