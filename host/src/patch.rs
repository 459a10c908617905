//! Patches and form-factor matrices: the types shared by meshing, form factors, the reference solver and baking.
//!
//! Units follow the scene (the Cornell box is in millimetres); areas are in scene units squared. Form factors are
//! dimensionless. Conventions (diffuse, RGB, `F_ij` = fraction of the power leaving `i` that reaches `j`) are the
//! ones stated in `radiosity-core`'s crate docs.

use glam::DVec3;

/// One patch: a planar convex polygon carrying one radiosity value per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch {
    /// Index of the OBJ face this patch came from (0-based, in OBJ order over all objects).
    pub face: usize,
    /// Index of the patch's material in the scene's material list.
    pub material: usize,
    /// Polygon vertices, counter-clockwise seen from the side the normal points to.
    pub vertices: Vec<DVec3>,
    /// Unit normal (the side that emits and receives light).
    pub normal: DVec3,
    /// Area of the polygon.
    pub area: f64,
    /// Centroid of the polygon.
    pub centroid: DVec3,
}

/// A sparse matrix of form factors in compressed-row form, `F[i][j]` for patches `i`, `j`, in f64.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FormFactorMatrix {
    /// Number of patches (rows and columns).
    pub n: usize,
    /// `row_start[i]..row_start[i + 1]` are the entries of row `i`; length `n + 1`.
    pub row_start: Vec<usize>,
    /// Column index of each entry, strictly increasing within a row.
    pub col: Vec<u32>,
    /// Form factor of each entry, in `(0, 1]`.
    pub value: Vec<f64>,
}

impl FormFactorMatrix {
    /// Entries of row `i` as `(column, form factor)` pairs.
    ///
    /// # Panics
    /// If `i >= self.n`.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.row_start[i]..self.row_start[i + 1];
        self.col[range.clone()].iter().map(|&j| j as usize).zip(self.value[range].iter().copied())
    }

    /// Sum of row `i`: the fraction of the power leaving patch `i` that reaches any patch.
    ///
    /// # Panics
    /// If `i >= self.n`.
    #[must_use]
    pub fn row_sum(&self, i: usize) -> f64 {
        self.row(i).map(|(_, f)| f).sum()
    }

    /// Number of stored (nonzero) entries.
    #[must_use]
    pub fn nonzeros(&self) -> usize {
        self.col.len()
    }

    /// Makes the matrix reciprocal, `A_i F_ij = A_j F_ji` exactly, by replacing both sides of every pair with
    /// their mean, and says how far apart the two estimates were ([`ReciprocityChange`]).
    ///
    /// Estimated form factors break reciprocity where the quadrature over the sending patch is poor (a patch
    /// cut by another patch's plane, e.g. a floor patch that runs under a block); averaging the two estimates of
    /// the same energy exchange is the standard repair, and keeps what the device shoots (`A_j F_ji / A_i`) equal
    /// to what the reference gathers (`F_ij`). Entries present on one side only get their mirror entry.
    ///
    /// # Panics
    /// If `area.len() != self.n`.
    pub fn enforce_reciprocity(&mut self, area: &[f64]) -> ReciprocityChange {
        assert_eq!(area.len(), self.n, "one area per patch");
        // Every energy exchange A_i F_ij, once as (i, j) and once as its mirror (j, i), halved.
        let mut exchange: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * self.nonzeros());
        for (i, &a) in area.iter().enumerate() {
            for (j, f) in self.row(i) {
                let g = 0.5 * a * f;
                exchange.push((i as u32, j as u32, g));
                exchange.push((j as u32, i as u32, g));
            }
        }
        exchange.sort_unstable_by_key(|&(i, j, _)| (i, j));
        let mut report = ReciprocityChange::default();
        let (mut one_sided_energy, mut total_energy) = (0.0, 0.0);
        let (mut row_start, mut col, mut value) = (vec![0], Vec::new(), Vec::new());
        let mut k = 0;
        for (i, &a) in area.iter().enumerate() {
            while k < exchange.len() && exchange[k].0 as usize == i {
                let (_, j, g0) = exchange[k];
                let mut g = g0;
                let mut parts = 1;
                k += 1;
                if k < exchange.len() && exchange[k].0 as usize == i && exchange[k].1 == j {
                    g += exchange[k].2;
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
            }
            row_start.push(col.len());
        }
        self.row_start = row_start;
        self.col = col;
        self.value = value;
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
}

/// Relative tolerance of the conjugate-gradient solve in [`FormFactorMatrix::close_rows`].
pub const CLOSURE_TOLERANCE: f64 = 1e-14;

impl FormFactorMatrix {
    /// Makes the rows of a closed scene sum to 1 by correcting only uncertain entries, keeping the matrix
    /// reciprocal; returns what it did.
    ///
    /// The matrix must already be reciprocal (see [`FormFactorMatrix::enforce_reciprocity`]) and
    /// `variance(i, j)` symmetric: the (relative) variance of the estimate of `G_ij = A_i F_ij`, 0 for exact
    /// entries. The correction is the generalized least-squares one: minimize `sum (δ_ij)² / w_ij` over symmetric
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
    /// If `area.len() != self.n`.
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
            if zeroed == 0 {
                break;
            }
        }
        // Entries set to 0 are dropped from the sparse structure.
        for (new, old) in self.value.iter().zip(&original) {
            report.max_entry_change = report.max_entry_change.max((new - old).abs());
        }
        let (mut row_start, mut col, mut value) = (vec![0], Vec::with_capacity(nnz), Vec::with_capacity(nnz));
        for i in 0..n {
            for k in self.row_start[i]..self.row_start[i + 1] {
                if self.value[k] > 0.0 {
                    col.push(self.col[k]);
                    value.push(self.value[k]);
                }
            }
            row_start.push(col.len());
        }
        let movable: Vec<bool> =
            (0..n).map(|i| (self.row_start[i]..self.row_start[i + 1]).any(|k| w[k] > 0.0)).collect();
        self.row_start = row_start;
        self.col = col;
        self.value = value;
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
