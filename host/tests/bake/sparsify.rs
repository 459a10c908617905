//! Sparsification and quantization: what is dropped, how error grows with the threshold and the code width,
//! and the inputs the bake refuses.

use super::*;
use radiosity_host::rgb::Rgb;

#[test]
fn threshold_zero_drops_nothing() {
    let scene = random_scene(1, 40, 0.3);
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let s = sparsify(&scene.ff, &area, 0.0).unwrap();
    assert_eq!(s.matrix, scene.ff);
    assert!(s.dropped.iter().all(|&d| d == 0.0));
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    assert_eq!(baked.report.nonzeros_before, baked.report.nonzeros_after);
    assert_eq!(baked.report.energy_dropped.total, 0.0);
    assert_eq!(
        scene.errors(&baked).sparsify.rel_l2,
        0.0,
        "an unsparsified reciprocal matrix must give the same B"
    );
}

#[test]
fn energy_dropped_is_the_sum_of_dropped_form_factors() {
    let scene = lit_scene(2, 60, 0.4, Rgb::ONE);
    let n = scene.ff.n();
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let t = 0.05;
    let s = sparsify(&scene.ff, &area, t).unwrap();
    // Recount from the two matrices: which entries are gone, per row and per receiver.
    let mut lost = vec![0.0; n];
    let mut lost_in = vec![0.0; n];
    let mut incoming = vec![0.0; n];
    let mut kept_entries = Vec::new();
    for i in 0..n {
        let kept: Vec<(usize, f64)> = s.matrix.row(i).collect();
        for (j, f) in scene.ff.row(i) {
            incoming[j] += area[i] * f;
            match kept.iter().find(|&&(k, _)| k == j) {
                Some(&(_, v)) => {
                    assert_eq!(v, f, "row {i}: kept entry {j} changed (renormalized?)");
                    kept_entries.push((i, j, f));
                }
                None => {
                    lost[i] += f;
                    lost_in[j] += area[i] * f;
                }
            }
        }
        assert_eq!(kept.len(), s.matrix.row(i).count());
    }
    assert_eq!(
        kept_entries.len(),
        s.matrix.nonzeros(),
        "the sparsified matrix has entries not in the original"
    );
    // Sums of the same nonnegative terms in another order agree within (terms) * eps of the sum.
    let tol = |sum: f64| n as f64 * f64::EPSILON * sum;
    let mut total = 0.0;
    for i in 0..n {
        let row_sum = scene.ff.row_sum(i);
        assert!(
            (s.dropped[i] - lost[i]).abs() <= tol(row_sum),
            "row {i}: reported {} vs {}",
            s.dropped[i],
            lost[i]
        );
        assert!(lost[i] <= t * row_sum + tol(row_sum), "row {i}: dropped {} > t * sum", lost[i]);
        assert!((s.dropped_incoming[i] - lost_in[i]).abs() <= tol(incoming[i]), "receiver {i}");
        assert!(
            lost_in[i] <= t * incoming[i] + tol(incoming[i]),
            "receiver {i}: dropped {} > t * in",
            lost_in[i]
        );
        total += lost[i];
    }
    // Greedy: every kept entry would overflow its row's or its receiver's budget.
    for &(i, j, f) in &kept_entries {
        let row_full = lost[i] + f > t * scene.ff.row_sum(i) - tol(1.0);
        let receiver_full = lost_in[j] + area[i] * f > t * incoming[j] - tol(incoming[j]);
        assert!(row_full || receiver_full, "entry ({i}, {j}) = {f} could have been dropped");
    }
    assert!(total > 0.0, "threshold {t} dropped nothing: the test scene does not exercise sparsify");
    let baked = scene.bake(t, FfCodec::FLOAT16);
    let e = &baked.report.energy_dropped;
    let tol = scene.ff.nonzeros() as f64 * f64::EPSILON * total;
    assert!((e.total - total).abs() <= tol, "report total {} vs {total}", e.total);
    assert!(e.max_row_fraction <= t && e.max_receiver_fraction <= t, "{e:?}");
    assert_eq!(baked.report.nonzeros_after, s.matrix.nonzeros());
    assert!(scene.errors(&baked).sparsify.rel_l2 > 0.0);
}

#[test]
fn eight_bit_error_exceeds_sixteen_bit() {
    let scene = lit_scene(3, 50, 0.3, Rgb::ONE);
    let b16 = scene.bake(0.0, codec_for_bits(16).unwrap());
    let b8 = scene.bake(0.0, codec_for_bits(8).unwrap());
    let (e16, e8) = (&scene.errors(&b16).sparsify_quantize, &scene.errors(&b8).sparsify_quantize);
    assert!(e8.rel_l2 > e16.rel_l2, "8-bit rel L2 {:.3e} <= 16-bit {:.3e}", e8.rel_l2, e16.rel_l2);
    assert!(e8.max_rel > e16.max_rel, "8-bit max rel {:.3e} <= 16-bit {:.3e}", e8.max_rel, e16.max_rel);
    assert!(b8.table.len() < b16.table.len());
    assert_eq!(b16.report.table_bytes.entry_codes, 2 * b16.report.nonzeros_after);
    assert_eq!(b8.report.table_bytes.entry_codes, b8.report.nonzeros_after);
    assert!(matches!(codec_for_bits(12), Err(BakeError::BadBits(12))));
}

#[test]
fn bad_inputs_are_named() {
    let scene = lit_scene(8, 10, 0.5, Rgb::ONE);
    let options = BakeOptions { threshold: 1.0, ..BakeOptions::default() };
    let err = bake(&scene.input(), &options).unwrap_err();
    assert_eq!(err.to_string(), "sparsification threshold 1 not in [0, 1)");
    let mut input = scene.input();
    input.group_names.pop();
    let err = bake(&input, &BakeOptions::default()).unwrap_err().to_string();
    assert!(err.contains("2 dynamic light groups but 2 default intensities and 1 names"), "{err}");
    let mut input = scene.input();
    input.materials[0] = Rgb::splat(0.1);
    let err = bake(&input, &BakeOptions::default()).unwrap_err().to_string();
    assert!(err.contains("patch 0: lighting reflectance"), "{err}");
}

/// The error a bake introduces grows with the threshold and with fewer bits, on the same scene. Prints the
/// summary line per setting (`cargo test -p radiosity-host --test bake error_grows -- --nocapture`).
#[test]
fn error_grows_with_threshold_and_fewer_bits() {
    let scene = lit_scene(2, 60, 0.4, Rgb::ONE);
    let mut previous: Option<(f64, f64)> = None;
    for t in [0.0, 1e-3, 1e-2, 5e-2] {
        let (b16, b8) = (scene.bake(t, FfCodec::FLOAT16), scene.bake(t, FfCodec::FLOAT8));
        let (err16, err8) = (scene.errors(&b16), scene.errors(&b8));
        for (r, error) in [(&b16.report, &err16), (&b8.report, &err8)] {
            eprintln!(
                "t={t:<6} {:<7} nnz {} -> {}  bytes {} ({:.2}/entry)  dropped total {:.3e} area-weighted {:.3e}  \
                 sparsify rel L2 {:.3e} max {:.3e}  +quantize rel L2 {:.3e} max {:.3e}",
                r.codec,
                r.nonzeros_before,
                r.nonzeros_after,
                r.table_bytes.total,
                r.bytes_per_entry,
                r.energy_dropped.total,
                r.energy_dropped.area_weighted,
                error.sparsify.rel_l2,
                error.sparsify.max_rel,
                error.sparsify_quantize.rel_l2,
                error.sparsify_quantize.max_rel
            );
        }
        // Fewer bits: a larger quantization component (decoded vs sparsified). The total against the exact
        // answer need not grow: with the dropped energy given back, the sparsification error has no common sign
        // and the 8-bit rounding can partly cancel it at large thresholds.
        let quantization = |b| {
            let c = scene.evaluate_with(b, &BakeOptions::default()).components;
            c.iter().find(|c| c.name == "quantization").expect("quantization component").error.rel_l2
        };
        let (e16, e8) = (quantization(&b16), quantization(&b8));
        assert!(e8 > e16, "t = {t}: 8-bit quantization {e8:.3e} <= 16-bit {e16:.3e}");
        let (b16, b8) = (b16.report, b8.report);
        assert!(b8.table_bytes.total < b16.table_bytes.total);
        if let Some((p_err, p_bytes)) = previous {
            let s = err16.sparsify.rel_l2;
            assert!(s > p_err, "t = {t}: sparsify error {s:.3e} did not grow from {p_err:.3e}");
            assert!((b16.table_bytes.total as f64) < p_bytes, "t = {t}: table did not shrink");
        }
        previous = Some((err16.sparsify.rel_l2, b16.table_bytes.total as f64));
    }
}

/// A codec too coarse for the scene's area ratios is refused with its own error. A sliver (area 2^-10) receives
/// from six unit-area patches whose rows hold one tiny entry to it, 0.55 of an 8-bit code step below the float
/// range (row max 1/2: exponent 1, step 2^-(1 + 5 + 6) = 2^-12), next to an entry whose rounding loss leaves
/// slack for one such step. The writer may bump the tiny entry to a whole step (it at most doubles it), which
/// is harmless in the stored rows (sums stay <= 1) but in the sliver's incoming row each step counts 2^10
/// times: 6 * 2^-12 * 2^10 = 1.5 decoded against 0.825 true, beyond the 8-bit allowance (1 + 2^-5 + the
/// row-sum tolerance). 16-bit codes bake the same scene. (The meshed case: `coarse_codec_is_refused_with_the_
/// reason` in tests/tests/verification.rs, the slab.)
#[test]
fn coarse_codec_is_refused_on_a_synthetic_sliver() {
    let (k, sliver) = (6usize, 2f64.powi(-10));
    let mut patches = vec![patch(0, sliver, 0)];
    patches.extend((1..=k).map(|i| patch(i, 1.0, 0)));
    let n = k + 1;
    let step = 2f64.powi(-12);
    let mut rows = vec![vec![0.0; n]; n];
    for i in 1..=k {
        let (next, prev) = (i % k + 1, (i + k - 2) % k + 1);
        rows[i][next] = 0.5;
        rows[i][prev] = 0.25 + 0.9 * 2f64.powi(-7);
        rows[i][0] = 0.55 * step;
        // Reciprocity: A_0 F_0i = A_i F_i0.
        rows[0][i] = rows[i][0] / sliver;
    }
    let materials = vec![Rgb::splat(0.5)];
    let mut lighting = dark_lighting(&patches, &materials, 1);
    lighting.group[1] = Some(0);
    lighting.unit_emission[1] = Rgb::ONE;
    let scene =
        TestScene { patches, materials, lighting, names: vec!["lamp".into()], ff: dense_to_csr(&rows) };
    let options = |codec| BakeOptions { threshold: 0.0, codec, ..BakeOptions::default() };
    let err = bake(&scene.input(), &options(FfCodec::FLOAT8)).expect_err("8-bit codes must be refused");
    let msg = err.to_string();
    println!("{msg}");
    assert!(matches!(err, BakeError::CodecTooCoarse { bits: 8, patch: 0, .. }), "{msg}");
    assert!(msg.contains("decode to a sum of 1.500") && msg.contains("1024 times its area"), "{msg}");
    assert!(msg.contains("--bits 16"), "{msg}");
    bake(&scene.input(), &options(FfCodec::FLOAT16)).expect("16-bit bake");
    // At 16 bits there is no finer code to suggest: the message points at the mesh and the hierarchy instead.
    let at16 =
        BakeError::CodecTooCoarse { bits: 16, patch: 3, area: 1.0, sum: 1.5, tolerance: 1e-3, ratio: 1e3 };
    let at16 = at16.to_string();
    assert!(at16.contains("--method hierarchical") && !at16.contains("--bits 16"), "{at16}");
}

/// Giving the dropped energy back: every row sums to what it did before sparsification (to the f64 rounding of
/// re-summing its entries, `entries * eps` of the sum), every receiver receives what it did under uniform
/// radiosity (within the scaling's tolerance plus rounding), the pattern is the one `sparsify` kept, every kept
/// entry moves by at most about the row's and the receiver's dropped fractions (`(1 + t)^2 - 1` bounds a
/// product of two factors each within `t` of 1 to first order; `1 / (1 - t)^2 - 1` is used), and the report
/// says so.
#[test]
fn returning_dropped_energy_restores_row_and_receiver_sums() {
    let scene = lit_scene(3, 60, 0.5, Rgb::ONE);
    let n = scene.ff.n();
    let area: Vec<f64> = scene.patches.iter().map(|p| p.area).collect();
    let t = 0.05;
    let lossy = sparsify(&scene.ff, &area, t).unwrap();
    let mut s = lossy.clone();
    s.return_dropped(&area);
    assert!(lossy.dropped.iter().sum::<f64>() > 0.0, "the test needs rows that drop something");
    assert_eq!(s.matrix.columns(), lossy.matrix.columns(), "returning energy must not change the pattern");
    assert_eq!(s.dropped, lossy.dropped);
    let mut received = vec![0.0; n];
    for i in 0..n {
        let (before, after) = (scene.ff.row_sum(i), s.matrix.row_sum(i));
        let tol = scene.ff.row_values(i).len() as f64 * f64::EPSILON * before;
        assert!((after - before).abs() <= tol, "row {i}: sum {after} after return, {before} before");
        assert!((s.returned[i] - lossy.dropped[i]).abs() <= tol, "row {i}: returned != dropped");
        for ((j, new), &old) in s.matrix.row(i).zip(lossy.matrix.row_values(i)) {
            received[j] += area[i] * new;
            let change = (new - old).abs() / old;
            assert!(change <= 1.0 / (1.0 - t).powi(2) - 1.0, "entry ({i}, {j}): {old} -> {new}");
        }
    }
    for j in 0..n {
        let want = s.incoming[j];
        let tol = RETURN_TOLERANCE * want + 4.0 * n as f64 * f64::EPSILON * want;
        assert!((received[j] - want).abs() <= tol, "receiver {j}: {} vs {want}", received[j]);
    }
    // Returning twice returns nothing more.
    let mut twice = s.clone();
    twice.return_dropped(&area);
    for (a, b) in twice.matrix.values().iter().zip(s.matrix.values()) {
        assert!((a - b).abs() <= 1e-10 * b, "{a} vs {b}");
    }
    let report = EnergyDropped::of(&scene.ff, &area, &s);
    let lossy_report = EnergyDropped::of(&scene.ff, &area, &lossy);
    assert!(report.net_area_weighted.abs() <= n as f64 * f64::EPSILON, "{}", report.net_area_weighted);
    assert!((lossy_report.net_area_weighted - lossy_report.area_weighted).abs() <= 1e-12);
    assert!(report.max_entry_scale > 0.0 && report.max_entry_scale <= 1.0 / (1.0 - t).powi(2) - 1.0);
    assert!(report.max_incoming_change <= RETURN_TOLERANCE * 2.0, "{}", report.max_incoming_change);
    assert_eq!(lossy_report.max_entry_scale, 0.0);
    assert!(lossy_report.max_incoming_change > 0.0 && lossy_report.max_incoming_change <= t * (1.0 + 1e-12));
    // The bake returns it by default and loses it only when told to.
    let returned = scene.bake(t, FfCodec::FLOAT16);
    assert!(returned.report.energy_dropped.net_area_weighted.abs() <= n as f64 * f64::EPSILON);
    let discard =
        BakeOptions { threshold: t, dropped_energy: DroppedEnergy::Discard, ..BakeOptions::default() };
    let discarded = bake(&scene.input(), &discard).unwrap();
    assert!(discarded.report.energy_dropped.net_area_weighted > 0.0);
}
