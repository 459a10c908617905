//! Reciprocity enforcement and row clamping of form-factor matrices.

use radiosity_host::patch::{FormFactorMatrix, RowClamp};

fn matrix(n: usize, rows: &[&[(u32, f64)]]) -> FormFactorMatrix {
    let mut m = FormFactorMatrix { n, row_start: vec![0], col: Vec::new(), value: Vec::new() };
    for row in rows {
        for &(j, f) in *row {
            m.col.push(j);
            m.value.push(f);
        }
        m.row_start.push(m.col.len());
    }
    m
}

/// Tolerance for a handful of f64 operations on values of order 1.
const TOL: f64 = 8.0 * f64::EPSILON;

#[test]
fn reciprocity_is_the_mean_of_both_estimates_and_mirrors_one_sided_entries() {
    let area = [1.0, 2.0, 4.0];
    // A_0 F_01 = 0.3 and A_1 F_10 = 2 * 0.2 = 0.4 disagree; (0, 2) has no mirror entry.
    let mut m = matrix(3, &[&[(1, 0.3), (2, 0.1)], &[(0, 0.2)], &[]]);
    let change = m.enforce_reciprocity(&area);
    let f =
        |m: &FormFactorMatrix, i: usize, j: usize| m.row(i).find(|&(c, _)| c == j).map_or(0.0, |(_, v)| v);
    assert!((f(&m, 0, 1) - 0.35).abs() < TOL, "F_01 = {}", f(&m, 0, 1));
    assert!((f(&m, 1, 0) - 0.175).abs() < TOL, "F_10 = {}", f(&m, 1, 0));
    // The one-sided exchange A_0 F_02 = 0.1 is split evenly between both directions.
    assert!((f(&m, 0, 2) - 0.05).abs() < TOL);
    assert!((f(&m, 2, 0) - 0.05 / 4.0).abs() < TOL);
    for i in 0..3 {
        for (j, v) in m.row(i) {
            assert!((area[i] * v - area[j] * f(&m, j, i)).abs() < TOL, "pair ({i}, {j}) not reciprocal");
        }
    }
    // The (0, 1) pair differs by |0.3 - 0.4| / 0.7; the one-sided (0, 2) carries 0.1 of the 0.8 exchanged.
    assert!((change.max_change - 0.1 / 0.7).abs() < TOL, "largest change {change:?}");
    assert_eq!(change.one_sided, 1);
    assert!((change.one_sided_share - 0.1 / 0.8).abs() < TOL, "one-sided share {change:?}");
    // Made reciprocal, a second pass finds nothing to change.
    let again = m.enforce_reciprocity(&area);
    assert!(again.max_change < TOL && again.one_sided == 0, "{again:?}");
}

#[test]
fn clamping_scales_only_rows_above_one_and_keeps_reciprocity() {
    let area = [1.0, 1.0, 1.0];
    // Row 0 sums to 1.25; rows 1 and 2 are below 1 (an open scene).
    let mut m = matrix(3, &[&[(1, 0.75), (2, 0.5)], &[(0, 0.75)], &[(0, 0.5)]]);
    let before = m.clone();
    let clamp = m.clamp_rows_to_one();
    assert_eq!(clamp.rows, 1);
    assert!((clamp.max_excess - 0.25).abs() < TOL);
    assert!((m.row_sum(0) - 1.0).abs() < TOL, "row 0 sums to {}", m.row_sum(0));
    // The mirror entries shrink with row 0, so the matrix stays reciprocal (equal areas: symmetric).
    for i in 0..3 {
        for (j, v) in m.row(i) {
            let mirror = m.row(j).find(|&(c, _)| c == i).map(|(_, w)| w).unwrap();
            assert!((area[i] * v - area[j] * mirror).abs() < TOL);
        }
    }
    // A matrix with every row at or below 1 is left exactly as it is.
    let mut open = matrix(2, &[&[(1, 0.4)], &[(0, 0.4)]]);
    let untouched = open.clone();
    assert_eq!(open.clamp_rows_to_one(), RowClamp::default());
    assert_eq!(open, untouched);
    assert_ne!(m, before);
}
