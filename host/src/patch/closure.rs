//! Closing the rows of a closed scene: the generalized least-squares correction of the uncertain entries of a
//! reciprocal form-factor matrix (see [`FormFactorMatrix::close_rows`]).

use super::FormFactorMatrix;

/// What [`FormFactorMatrix::close_rows`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Closure {
    /// Rows brought to a sum of 1 (those with adjustable entries).
    pub rows_closed: usize,
    /// Rows that could not be closed (no adjustable entry).
    pub rows_left: usize,
    /// Largest `|row sum - 1|` over the closed rows afterwards.
    pub max_residual: f64,
    /// Largest `|row sum - 1|` over the rows left as they were (0 if none).
    pub max_residual_left: f64,
    /// Largest change of an entry, `|F'_ij - F_ij|`.
    pub max_entry_change: f64,
    /// Adjustable entries that the correction would have made negative and that were set to 0 instead.
    pub entries_zeroed: usize,
    /// The correction was refused and every entry left as estimated: closing the rows would have made a form
    /// factor larger than 1 (or not a number), which happens when the adjustable entries of a group of rows cannot
    /// move their sums independently and the least-squares system is nearly singular. Set with
    /// `rows_closed == 0`.
    pub refused: Option<RefusedClosure>,
}

/// Why [`FormFactorMatrix::close_rows`] refused to close the rows: the first entry the correction would have made
/// impossible.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefusedClosure {
    /// Row of the entry.
    pub row: usize,
    /// Column of the entry.
    pub col: usize,
    /// The larger of the pair's two form factors `F_ij`, `F_ji` the correction would have made (above 1, or NaN).
    pub form_factor: f64,
}

/// Relative tolerance of the conjugate-gradient solve in [`FormFactorMatrix::close_rows`].
pub const CLOSURE_TOLERANCE: f64 = 1e-14;

impl FormFactorMatrix {
    /// Makes the rows of a closed scene sum to 1 by correcting only uncertain entries, keeping the matrix
    /// reciprocal; returns what it did.
    ///
    /// The matrix must already be reciprocal (see [`FormFactorMatrix::enforce_reciprocity`]) and
    /// `variance(i, j)` symmetric: the variance (or any common multiple of it) of the estimate of
    /// `G_ij = A_i F_ij`, 0 for exact entries. If the correction would make a form factor larger than 1, nothing
    /// is changed and [`Closure::refused`] says where. The correction is the generalized least-squares one: minimize `sum (δ_ij)² / w_ij` over symmetric
    /// changes `δ` of the energy exchanges subject to every row of `G + δ` summing to `A_i`. Its Lagrange
    /// conditions give `δ_ij = w_ij (λ_i + λ_j)` with `(D + W) λ = A - G 1`, `D = diag(W 1)`, a symmetric positive
    /// semidefinite system solved by Jacobi-preconditioned conjugate gradients. Entries with more noise take more of
    /// a row's deficit; exact entries none. An entry the correction would make negative is set to 0, fixed, and the
    /// correction repeated (at most 8 rounds).
    ///
    /// Only call this for a closed scene: in an open scene a row sum below 1 is the energy that escapes, and
    /// closing it would hide it.
    ///
    /// # Panics
    /// If `area.len() != self.n()`.
    pub fn close_rows(&mut self, area: &[f64], variance: impl Fn(usize, usize) -> f64) -> Closure {
        assert_eq!(area.len(), self.n, "one area per patch");
        let n = self.n;
        let nnz = self.nonzeros();
        let row_of: Vec<usize> =
            (0..n).flat_map(|i| std::iter::repeat_n(i, self.row_start[i + 1] - self.row_start[i])).collect();
        let mut w: Vec<f64> = (0..nnz)
            .map(|k| {
                let (i, j) = (row_of[k], self.col[k] as usize);
                if i == j {
                    0.0
                } else {
                    let v = variance(i, j);
                    if v.is_finite() && v > 0.0 {
                        v
                    } else {
                        0.0
                    }
                }
            })
            .collect();
        let original = self.value.clone();
        let mut report = Closure::default();
        let mut refused = None;
        for _round in 0..8 {
            let g: Vec<f64> = (0..nnz).map(|k| area[row_of[k]] * self.value[k]).collect();
            let d: Vec<f64> =
                (0..n).map(|i| (self.row_start[i]..self.row_start[i + 1]).map(|k| w[k]).sum()).collect();
            let rhs: Vec<f64> = (0..n)
                .map(|i| area[i] - (self.row_start[i]..self.row_start[i + 1]).map(|k| g[k]).sum::<f64>())
                .collect();
            let apply = |x: &[f64]| -> Vec<f64> {
                (0..n)
                    .map(|i| {
                        d[i] * x[i]
                            + (self.row_start[i]..self.row_start[i + 1])
                                .map(|k| w[k] * x[self.col[k] as usize])
                                .sum::<f64>()
                    })
                    .collect()
            };
            // Rows without adjustable entries cannot move: leave them out of the system (lambda = 0).
            let active: Vec<bool> = d.iter().map(|&x| x > 0.0).collect();
            let mut lambda = vec![0.0; n];
            let mut r: Vec<f64> = (0..n).map(|i| if active[i] { rhs[i] } else { 0.0 }).collect();
            let precondition = |r: &[f64]| -> Vec<f64> {
                (0..n).map(|i| if active[i] { r[i] / (2.0 * d[i]) } else { 0.0 }).collect()
            };
            let mut z = precondition(&r);
            let mut p = z.clone();
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
            let norm0 = dot(&r, &r).sqrt();
            let mut rz = dot(&r, &z);
            for _ in 0..10 * n.max(10) {
                if dot(&r, &r).sqrt() <= CLOSURE_TOLERANCE * norm0.max(f64::MIN_POSITIVE) {
                    break;
                }
                let q = apply(&p);
                let pq = dot(&p, &q);
                if pq.is_nan() || pq <= 0.0 {
                    break;
                }
                let alpha = rz / pq;
                for i in 0..n {
                    lambda[i] += alpha * p[i];
                    r[i] -= alpha * q[i];
                }
                z = precondition(&r);
                let rz_new = dot(&r, &z);
                let beta = rz_new / rz;
                rz = rz_new;
                for i in 0..n {
                    p[i] = z[i] + beta * p[i];
                }
            }
            let mut zeroed = 0;
            for k in 0..nnz {
                if w[k] > 0.0 {
                    let (i, j) = (row_of[k], self.col[k] as usize);
                    let new = g[k] + w[k] * (lambda[i] + lambda[j]);
                    // G_ij = A_i F_ij = A_j F_ji: both form factors at most 1.
                    let largest = new / area[i].min(area[j]);
                    if refused.is_none() && (largest.is_nan() || largest > 1.0) {
                        refused = Some(RefusedClosure { row: i, col: j, form_factor: largest });
                    }
                    if new < 0.0 {
                        self.value[k] = 0.0;
                        w[k] = 0.0;
                        zeroed += 1;
                    } else {
                        self.value[k] = new / area[i];
                    }
                }
            }
            report.entries_zeroed += zeroed;
            if zeroed == 0 || refused.is_some() {
                break;
            }
        }
        if let Some(r) = refused {
            self.value = original;
            let mut report = Closure { refused: Some(r), rows_left: n, ..Closure::default() };
            for i in 0..n {
                report.max_residual_left = report.max_residual_left.max((self.row_sum(i) - 1.0).abs());
            }
            return report;
        }
        // Entries set to 0 are dropped from the sparse structure.
        for (new, old) in self.value.iter().zip(&original) {
            report.max_entry_change = report.max_entry_change.max((new - old).abs());
        }
        let movable: Vec<bool> = (0..n).map(|i| self.row_range(i).any(|k| w[k] > 0.0)).collect();
        *self = self.retain_entries(|k| self.value[k] > 0.0);
        for (i, &on) in movable.iter().enumerate() {
            let residual = (self.row_sum(i) - 1.0).abs();
            if on {
                report.rows_closed += 1;
                report.max_residual = report.max_residual.max(residual);
            } else {
                report.rows_left += 1;
                report.max_residual_left = report.max_residual_left.max(residual);
            }
        }
        report
    }
}

#[cfg(test)]
mod tests {
    use super::super::FormFactorMatrix;

    /// Two unit patches seeing each other by half: each row is 0.5 short, and the one adjustable entry closes both
    /// (F becomes 1). Two patches of different areas that see only each other cannot both close (one of the two
    /// form factors would exceed 1), so nothing is changed.
    #[test]
    fn closing_that_needs_a_form_factor_above_one_is_refused() {
        let mut m = FormFactorMatrix::new(2, vec![0, 1, 2], vec![1, 0], vec![0.5, 0.5]).unwrap();
        let report = m.close_rows(&[1.0, 1.0], |_, _| 0.01);
        assert!(report.refused.is_none() && report.rows_closed == 2, "{report:?}");
        assert!((m.row_sum(0) - 1.0).abs() < 1e-12 && (m.row_sum(1) - 1.0).abs() < 1e-12);

        // A unit patch and one of area 4 seeing each other only: closing both rows would need G_01 = 1 for the
        // first and 4 for the second; the least-squares compromise gives F_01 above 1.
        let mut m = FormFactorMatrix::new(2, vec![0, 1, 2], vec![1, 0], vec![0.5, 0.125]).unwrap();
        let before = m.clone();
        let report = m.close_rows(&[1.0, 4.0], |_, _| 0.01);
        let r = report.refused.expect("refused");
        assert!(r.form_factor > 1.0, "{r:?}");
        assert_eq!((report.rows_closed, report.rows_left), (0, 2));
        assert_eq!(m, before, "left as estimated");
    }
}
