//! Reciprocity enforcement and row clamping of form-factor matrices.

use radiosity_host::patch::{FormFactorMatrix, MatrixError, RowClamp};

fn matrix(n: usize, rows: &[&[(u32, f64)]]) -> FormFactorMatrix {
    let flagged: Vec<Vec<(u32, f64, bool)>> =
        rows.iter().map(|row| row.iter().map(|&(j, f)| (j, f, false)).collect()).collect();
    flagged_matrix(n, &flagged)
}

fn flagged_matrix(n: usize, rows: &[Vec<(u32, f64, bool)>]) -> FormFactorMatrix {
    let (mut row_start, mut col, mut value, mut flags) = (vec![0], Vec::new(), Vec::new(), Vec::new());
    for row in rows {
        for &(j, f, flag) in row {
            col.push(j);
            value.push(f);
            flags.push(flag);
        }
        row_start.push(col.len());
    }
    FormFactorMatrix::with_flags(n, row_start, col, value, flags).unwrap()
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

#[test]
fn the_constructor_rejects_every_malformed_part() {
    let new =
        |n, starts: Vec<usize>, col: Vec<u32>, value: Vec<f64>| FormFactorMatrix::new(n, starts, col, value);
    let good = new(2, vec![0, 1, 2], vec![1, 0], vec![0.1, 0.2]).unwrap();
    assert_eq!((good.n(), good.nonzeros(), good.get(1, 0), good.get(0, 0)), (2, 2, 0.2, 0.0));
    assert_eq!(good.flags(), [false, false]);
    assert_eq!(
        new(2, vec![0, 1], vec![1], vec![0.1]).unwrap_err(),
        MatrixError::RowStarts { n: 2, found: 2 }
    );
    assert_eq!(
        new(2, vec![0, 1, 2], vec![1, 0], vec![0.1]).unwrap_err(),
        MatrixError::LengthMismatch { what: "values", expected: 2, found: 1 }
    );
    assert_eq!(
        FormFactorMatrix::with_flags(1, vec![0, 0], vec![], vec![], vec![true]).unwrap_err(),
        MatrixError::LengthMismatch { what: "flags", expected: 0, found: 1 }
    );
    assert_eq!(
        new(2, vec![0, 1, 1], vec![1, 0], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::RowBounds { start: 0, end: 1, entries: 2 }
    );
    assert_eq!(
        new(2, vec![0, 2, 1], vec![1, 0], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::RowBounds { start: 0, end: 1, entries: 2 }
    );
    assert_eq!(
        new(3, vec![0, 2, 1, 2], vec![1, 2], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::RowStartDecreases { row: 1 }
    );
    assert_eq!(
        new(2, vec![0, 1, 2], vec![1, 2], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::ColumnOutOfRange { row: 1, col: 2, n: 2 }
    );
    assert_eq!(
        new(3, vec![0, 2, 2, 2], vec![2, 1], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::ColumnsNotIncreasing { row: 0, col: 1 }
    );
    assert_eq!(
        new(3, vec![0, 2, 2, 2], vec![1, 1], vec![0.1, 0.2]).unwrap_err(),
        MatrixError::ColumnsNotIncreasing { row: 0, col: 1 }
    );
    assert!(matches!(
        new(2, vec![0, 1, 2], vec![1, 0], vec![0.1, f64::NAN]).unwrap_err(),
        MatrixError::NonFinite { row: 1, col: 0, .. }
    ));
    assert_eq!(FormFactorMatrix::default(), new(0, vec![0], vec![], vec![]).unwrap());
    let dense = FormFactorMatrix::from_dense(&[vec![0.0, 0.5], vec![0.25, 0.0]]).unwrap();
    assert_eq!(dense, new(2, vec![0, 1, 2], vec![1, 0], vec![0.5, 0.25]).unwrap());
    assert!(matches!(
        FormFactorMatrix::from_dense(&[vec![0.0, 0.5, 0.1], vec![0.25, 0.0]]).unwrap_err(),
        MatrixError::ColumnOutOfRange { row: 0, col: 2, n: 2 }
    ));
}

/// The partly-visible flags follow their entries through every transform: a mirror entry added for
/// reciprocity takes its pair's flag, a merged pair is flagged if either side was, dropped entries drop theirs.
#[test]
fn flags_follow_their_entries_through_transforms() {
    let area = [1.0, 1.0, 1.0];
    let rows = vec![vec![(1, 0.3, true), (2, 0.4, false)], vec![(0, 0.3, false)], vec![]];
    let mut m = flagged_matrix(3, &rows);
    m.enforce_reciprocity(&area);
    let flag = |m: &FormFactorMatrix, i: usize, j: usize| {
        let k = m.row_columns(i).binary_search(&(j as u32)).unwrap();
        m.row_flags(i)[k]
    };
    assert!(flag(&m, 0, 1) && flag(&m, 1, 0), "either side flagged flags the pair");
    assert!(!flag(&m, 0, 2) && !flag(&m, 2, 0), "the mirror of an unflagged entry is unflagged");
    assert_eq!(m.flags().len(), m.nonzeros());
    m.map_values(|_, _, f| 2.0 * f);
    assert!((m.get(0, 1) - 0.6).abs() < TOL && flag(&m, 1, 0));
    let kept = m.retain_entries(|k| m.columns()[k] != 0);
    assert_eq!(kept.nonzeros(), 2);
    assert!(flag(&kept, 0, 1) && !flag(&kept, 0, 2));
    let entries: Vec<(usize, usize, f64)> = kept.entries().collect();
    assert_eq!(entries.iter().map(|&(i, j, _)| (i, j)).collect::<Vec<_>>(), [(0, 1), (0, 2)]);
}
