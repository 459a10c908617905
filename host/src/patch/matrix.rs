//! [`FormFactorMatrix`]: the sparse form factors in compressed-row form, with a partly-visible flag per entry,
//! behind a checked constructor; and the transforms that keep it physical (reciprocity, row sums at most 1).

use std::ops::Range;

/// Why [`FormFactorMatrix::new`] rejected its parts.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MatrixError {
    /// `row_start` does not have `n + 1` entries.
    #[error("{found} row starts for {n} rows, expected n + 1")]
    RowStarts {
        /// Number of rows.
        n: usize,
        /// Length of `row_start`.
        found: usize,
    },
    /// The first row does not start at entry 0, or the last does not end at the entry count.
    #[error("rows cover entries {start}..{end}, but there are {entries} entries")]
    RowBounds {
        /// `row_start[0]`.
        start: usize,
        /// `row_start[n]`.
        end: usize,
        /// Number of column indices.
        entries: usize,
    },
    /// A row ends before it starts.
    #[error("row {row} ends before it starts")]
    RowStartDecreases {
        /// The row.
        row: usize,
    },
    /// The values or flags are not one per column index.
    #[error("{what}: {found} entries for {expected} column indices")]
    LengthMismatch {
        /// `"values"` or `"flags"`.
        what: &'static str,
        /// Number of column indices.
        expected: usize,
        /// Number given.
        found: usize,
    },
    /// A column index is not below `n`.
    #[error("row {row}: column {col} out of range for {n} columns")]
    ColumnOutOfRange {
        /// The row.
        row: usize,
        /// The column index.
        col: u32,
        /// Number of columns.
        n: usize,
    },
    /// Column indices within a row are not strictly increasing.
    #[error("row {row}: columns not strictly increasing at column {col}")]
    ColumnsNotIncreasing {
        /// The row.
        row: usize,
        /// The first column that is not above its predecessor.
        col: u32,
    },
    /// A value is NaN or infinite.
    #[error("entry ({row}, {col}) is not finite: {value}")]
    NonFinite {
        /// The row.
        row: usize,
        /// The column.
        col: u32,
        /// The value.
        value: f64,
    },
}

/// A sparse matrix of form factors in compressed-row form, `F[i][j]` for patches `i`, `j`, in f64, with one
/// flag per stored entry: the pair is partly visible (a shadow boundary crosses one of the two patches, or its
/// visibility could not be measured), as the estimator found it.
///
/// The fields are private: [`FormFactorMatrix::new`] checks the structure once (row starts monotone and
/// covering the entries, column indices in range and strictly increasing within each row, values finite, one
/// flag per entry), and every transform keeps it, so no accessor can fail and the flags never need realigning.
/// Values are not range-checked here (the reference solver checks `F_ij >= 0` and the row sums).
#[derive(Clone, Debug, PartialEq)]
pub struct FormFactorMatrix {
    /// Number of patches (rows and columns).
    pub(super) n: usize,
    /// `row_start[i]..row_start[i + 1]` are the entries of row `i`; length `n + 1`.
    pub(super) row_start: Vec<usize>,
    /// Column index of each entry, strictly increasing within a row.
    pub(super) col: Vec<u32>,
    /// Form factor of each entry.
    pub(super) value: Vec<f64>,
    /// Whether each entry's pair is partly visible.
    pub(super) partly_visible: Vec<bool>,
}

impl Default for FormFactorMatrix {
    /// The matrix of no patches.
    fn default() -> Self {
        Self { n: 0, row_start: vec![0], col: Vec::new(), value: Vec::new(), partly_visible: Vec::new() }
    }
}

impl FormFactorMatrix {
    /// A matrix of `n` patches from its compressed rows: `row_start` (length `n + 1`) delimits each row's
    /// entries in `col` (column indices) and `value` (form factors). No entry is flagged partly visible.
    ///
    /// # Errors
    /// [`MatrixError`] if the parts do not form a valid matrix (see the type's docs).
    pub fn new(n: usize, row_start: Vec<usize>, col: Vec<u32>, value: Vec<f64>) -> Result<Self, MatrixError> {
        let flags = vec![false; col.len()];
        Self::with_flags(n, row_start, col, value, flags)
    }

    /// As [`FormFactorMatrix::new`], with a partly-visible flag per entry.
    ///
    /// # Errors
    /// [`MatrixError`] if the parts do not form a valid matrix (see the type's docs).
    pub fn with_flags(
        n: usize,
        row_start: Vec<usize>,
        col: Vec<u32>,
        value: Vec<f64>,
        partly_visible: Vec<bool>,
    ) -> Result<Self, MatrixError> {
        if row_start.len() != n + 1 {
            return Err(MatrixError::RowStarts { n, found: row_start.len() });
        }
        for (what, found) in [("values", value.len()), ("flags", partly_visible.len())] {
            if found != col.len() {
                return Err(MatrixError::LengthMismatch { what, expected: col.len(), found });
            }
        }
        if row_start[0] != 0 || row_start[n] != col.len() {
            return Err(MatrixError::RowBounds {
                start: row_start[0],
                end: row_start[n],
                entries: col.len(),
            });
        }
        for row in 0..n {
            let (start, end) = (row_start[row], row_start[row + 1]);
            if start > end {
                return Err(MatrixError::RowStartDecreases { row });
            }
            let mut previous: Option<u32> = None;
            for (&c, &v) in col[start..end].iter().zip(&value[start..end]) {
                if c as usize >= n {
                    return Err(MatrixError::ColumnOutOfRange { row, col: c, n });
                }
                if previous.is_some_and(|p| p >= c) {
                    return Err(MatrixError::ColumnsNotIncreasing { row, col: c });
                }
                previous = Some(c);
                if !v.is_finite() {
                    return Err(MatrixError::NonFinite { row, col: c, value: v });
                }
            }
        }
        Ok(Self { n, row_start, col, value, partly_visible })
    }

    /// The matrix of a dense one (`dense[i][j] = F_ij`, one row per patch, each as long as there are rows),
    /// storing the nonzero entries; no entry flagged.
    ///
    /// # Errors
    /// [`MatrixError::ColumnOutOfRange`] for a row longer than the matrix; [`MatrixError::NonFinite`].
    pub fn from_dense(dense: &[Vec<f64>]) -> Result<Self, MatrixError> {
        let (mut row_start, mut col, mut value) = (vec![0], Vec::new(), Vec::new());
        for row in dense {
            for (j, &f) in row.iter().enumerate() {
                if f != 0.0 {
                    col.push(u32::try_from(j).unwrap_or(u32::MAX));
                    value.push(f);
                }
            }
            row_start.push(col.len());
        }
        Self::new(dense.len(), row_start, col, value)
    }

    /// Number of patches (rows and columns).
    #[must_use]
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of stored (nonzero) entries.
    #[must_use]
    pub fn nonzeros(&self) -> usize {
        self.col.len()
    }

    /// Positions of row `i`'s entries in [`FormFactorMatrix::columns`], [`FormFactorMatrix::values`] and
    /// [`FormFactorMatrix::flags`].
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn row_range(&self, i: usize) -> Range<usize> {
        self.row_start[i]..self.row_start[i + 1]
    }

    /// Column indices of row `i`, strictly increasing.
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn row_columns(&self, i: usize) -> &[u32] {
        &self.col[self.row_range(i)]
    }

    /// Form factors of row `i`, in the order of [`FormFactorMatrix::row_columns`].
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn row_values(&self, i: usize) -> &[f64] {
        &self.value[self.row_range(i)]
    }

    /// Partly-visible flags of row `i`, in the order of [`FormFactorMatrix::row_columns`].
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn row_flags(&self, i: usize) -> &[bool] {
        &self.partly_visible[self.row_range(i)]
    }

    /// Entries of row `i` as `(column, form factor)` pairs.
    ///
    /// # Panics
    /// If `i >= self.n()`.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.row_columns(i).iter().map(|&j| j as usize).zip(self.row_values(i).iter().copied())
    }

    /// Every entry as `(row, column, form factor)`, rows ascending, columns ascending within a row.
    pub fn entries(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        (0..self.n).flat_map(move |i| self.row(i).map(move |(j, f)| (i, j, f)))
    }

    /// `F_ij` (0 if not stored), by binary search in row `i`.
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let Ok(j) = u32::try_from(j) else { return 0.0 };
        self.row_columns(i).binary_search(&j).map_or(0.0, |k| self.row_values(i)[k])
    }

    /// Where each row starts in the entry arrays, and where the last ends (length `n + 1`).
    #[must_use]
    pub fn row_starts(&self) -> &[usize] {
        &self.row_start
    }

    /// Column index of every entry, row after row.
    #[must_use]
    pub fn columns(&self) -> &[u32] {
        &self.col
    }

    /// Form factor of every entry, row after row.
    #[must_use]
    pub fn values(&self) -> &[f64] {
        &self.value
    }

    /// Partly-visible flag of every entry, row after row.
    #[must_use]
    pub fn flags(&self) -> &[bool] {
        &self.partly_visible
    }

    /// Sum of row `i`: the fraction of the power leaving patch `i` that reaches any patch.
    ///
    /// # Panics
    /// If `i >= self.n()`.
    #[must_use]
    pub fn row_sum(&self, i: usize) -> f64 {
        self.row_values(i).iter().sum()
    }

    /// Replaces every value `F_ij` by `f(i, j, F_ij)`, keeping the structure and the flags.
    ///
    /// # Panics
    /// If `f` returns a value that is not finite.
    pub fn map_values(&mut self, mut f: impl FnMut(usize, usize, f64) -> f64) {
        for i in 0..self.n {
            for k in self.row_start[i]..self.row_start[i + 1] {
                let (j, v) = (self.col[k] as usize, self.value[k]);
                let new = f(i, j, v);
                assert!(new.is_finite(), "map_values: entry ({i}, {j}) = {v} mapped to {new}");
                self.value[k] = new;
            }
        }
    }

    /// The matrix without the entries for which `keep(k)` is false (`k` the entry's position, as in
    /// [`FormFactorMatrix::values`]); values and flags of the kept entries are unchanged.
    #[must_use]
    pub fn retain_entries(&self, mut keep: impl FnMut(usize) -> bool) -> FormFactorMatrix {
        let mut out = FormFactorMatrix { n: self.n, ..FormFactorMatrix::default() };
        out.row_start.reserve(self.n);
        for i in 0..self.n {
            for k in self.row_range(i) {
                if keep(k) {
                    out.col.push(self.col[k]);
                    out.value.push(self.value[k]);
                    out.partly_visible.push(self.partly_visible[k]);
                }
            }
            out.row_start.push(out.col.len());
        }
        out
    }

    /// Makes the matrix reciprocal, `A_i F_ij = A_j F_ji` exactly, by replacing both sides of every pair with
    /// their mean, and says how far apart the two estimates were ([`ReciprocityChange`]).
    ///
    /// Estimated form factors break reciprocity where the quadrature over the sending patch is poor (a patch
    /// cut by another patch's plane, e.g. a floor patch that runs under a block); averaging the two estimates of
    /// the same energy exchange is the standard repair, and keeps what the device shoots (`A_j F_ji / A_i`) equal
    /// to what the reference gathers (`F_ij`). Entries present on one side only get their mirror entry. An entry is
    /// partly visible if either of the pair's two entries was (visibility is one estimate per pair).
    ///
    /// # Panics
    /// If `area.len() != self.n()`.
    pub fn enforce_reciprocity(&mut self, area: &[f64]) -> ReciprocityChange {
        assert_eq!(area.len(), self.n, "one area per patch");
        // Every energy exchange A_i F_ij, once as (i, j) and once as its mirror (j, i), halved.
        let mut exchange: Vec<(u32, u32, f64, bool)> = Vec::with_capacity(2 * self.nonzeros());
        for (i, &a) in area.iter().enumerate() {
            for ((&j, &f), &flag) in self.row_columns(i).iter().zip(self.row_values(i)).zip(self.row_flags(i))
            {
                let g = 0.5 * a * f;
                exchange.push((i as u32, j, g, flag));
                exchange.push((j, i as u32, g, flag));
            }
        }
        exchange.sort_unstable_by_key(|&(i, j, _, _)| (i, j));
        let mut report = ReciprocityChange::default();
        let (mut one_sided_energy, mut total_energy) = (0.0, 0.0);
        let (mut row_start, mut col, mut value, mut flags) = (vec![0], Vec::new(), Vec::new(), Vec::new());
        let mut k = 0;
        for (i, &a) in area.iter().enumerate() {
            while k < exchange.len() && exchange[k].0 as usize == i {
                let (_, j, g0, mut flag) = exchange[k];
                let mut g = g0;
                let mut parts = 1;
                k += 1;
                if k < exchange.len() && exchange[k].0 as usize == i && exchange[k].1 == j {
                    g += exchange[k].2;
                    flag |= exchange[k].3;
                    parts += 1;
                    k += 1;
                }
                // With both sides present, g0 and the second part are the halves of the two estimates. A pair
                // seen from one side only is visited twice, as (i, j) and (j, i), each time with half its energy.
                total_energy += g;
                if parts == 2 {
                    report.max_change = report.max_change.max((g0 - (g - g0)).abs() / g);
                } else if i < j as usize {
                    report.one_sided += 1;
                    one_sided_energy += 2.0 * g;
                }
                col.push(j);
                value.push(g / a);
                flags.push(flag);
            }
            row_start.push(col.len());
        }
        self.row_start = row_start;
        self.col = col;
        self.value = value;
        self.partly_visible = flags;
        if total_energy > 0.0 {
            report.one_sided_share = one_sided_energy / total_energy;
        }
        report
    }

    /// Scales down every row whose sum exceeds 1 so that no row sum exceeds 1, and says what it did.
    ///
    /// A row sum above 1 is impossible physically (a patch cannot send more than all its power) and comes only
    /// from estimation noise in the visibility of partly occluded pairs. The solvers need row sums `<= 1` to
    /// converge, so such rows are scaled, and the caller reports the returned [`RowClamp`]: nothing is changed
    /// silently. Each entry `(i, j)` is scaled by `min(s_i, s_j)` with `s_i = min(1, 1 / rowsum_i)`, so a
    /// reciprocal matrix stays reciprocal (the shooting form `A_j F_ji / A_i` that the device uses then obeys the
    /// same bound). Rows of a scene whose entries all have `s = 1` are never touched: open scenes keep their
    /// escaping energy.
    pub fn clamp_rows_to_one(&mut self) -> RowClamp {
        let mut clamp = RowClamp::default();
        let scale: Vec<f64> = (0..self.n)
            .map(|i| {
                let sum = self.row_sum(i);
                if sum > 1.0 {
                    clamp.rows += 1;
                    clamp.max_excess = clamp.max_excess.max(sum - 1.0);
                    1.0 / sum
                } else {
                    1.0
                }
            })
            .collect();
        if clamp.rows > 0 {
            for i in 0..self.n {
                for k in self.row_start[i]..self.row_start[i + 1] {
                    self.value[k] *= scale[i].min(scale[self.col[k] as usize]);
                }
            }
        }
        clamp
    }
}

/// What [`FormFactorMatrix::enforce_reciprocity`] found: how far apart the two estimates of each pair's energy
/// exchange `A_i F_ij` were before averaging.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReciprocityChange {
    /// Largest relative difference `|A_i F_ij - A_j F_ji| / (A_i F_ij + A_j F_ji)` over the pairs estimated from
    /// both sides (0 if none).
    pub max_change: f64,
    /// Pairs with an entry on one side only (the other estimate exactly zero, e.g. two nearly coplanar
    /// neighbours, where one quadrature sees a sliver the other does not); each got its mirror entry.
    pub one_sided: usize,
    /// The one-sided pairs' energy `A_i F_ij` as a fraction of all the energy the matrix exchanged.
    pub one_sided_share: f64,
}

impl ReciprocityChange {
    /// Field-wise maximum of two reports (for a matrix made reciprocal twice).
    #[must_use]
    pub fn max(self, other: ReciprocityChange) -> ReciprocityChange {
        ReciprocityChange {
            max_change: self.max_change.max(other.max_change),
            one_sided: self.one_sided.max(other.one_sided),
            one_sided_share: self.one_sided_share.max(other.one_sided_share),
        }
    }
}

/// What [`FormFactorMatrix::clamp_rows_to_one`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowClamp {
    /// Rows that summed to more than 1 and were scaled to 1.
    pub rows: usize,
    /// Largest row sum minus 1 before scaling (0 if no row was scaled).
    pub max_excess: f64,
}
