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

    /// Scales down every row whose sum exceeds 1 so that it sums to exactly 1, and says what it did.
    ///
    /// A row sum above 1 is impossible physically (a patch cannot send more than all its power) and comes only
    /// from estimation noise in the visibility of partly occluded pairs. The solvers need row sums `<= 1` to
    /// converge, so such rows are scaled, and the caller reports the returned [`RowClamp`]: nothing is changed
    /// silently. Rows at or below 1 are never touched (open scenes keep their escaping energy).
    pub fn clamp_rows_to_one(&mut self) -> RowClamp {
        let mut clamp = RowClamp::default();
        for i in 0..self.n {
            let sum = self.row_sum(i);
            if sum > 1.0 {
                clamp.rows += 1;
                clamp.max_excess = clamp.max_excess.max(sum - 1.0);
                for v in &mut self.value[self.row_start[i]..self.row_start[i + 1]] {
                    *v /= sum;
                }
            }
        }
        clamp
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
