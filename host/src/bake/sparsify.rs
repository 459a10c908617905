//! Step 1 of a bake: sparsification under a row budget and a receiver budget (see the [`crate::bake`] docs).

use serde::Serialize;

use super::BakeError;
use crate::patch::FormFactorMatrix;

/// A sparsified matrix and the energy each row and each receiver lost.
#[derive(Clone, Debug, PartialEq)]
pub struct Sparsified {
    /// The kept entries: values unchanged as [`sparsify`] returns them, each row scaled up by its dropped
    /// energy after [`Sparsified::return_dropped`].
    pub matrix: FormFactorMatrix,
    /// Per row `i`, the sum of the dropped `F_ij`.
    pub dropped: Vec<f64>,
    /// Per row `i`, the energy given back to its kept entries ([`Sparsified::return_dropped`]; zero before).
    pub returned: Vec<f64>,
    /// Per receiver `j`, the sum of the dropped `A_i F_ij` (power lost under uniform unit radiosity).
    pub dropped_incoming: Vec<f64>,
    /// Per receiver `j`, `sum_i A_i F_ij` over the original entries (power received under uniform unit
    /// radiosity).
    pub incoming: Vec<f64>,
}

/// Drops entries while both the shooter's and the receiver's budgets allow (see the [`crate::bake`] docs).
///
/// Entries are visited in ascending order of the power they carry under uniform unit radiosity, `A_i F_ij`
/// (ties by shooter, then receiver); entry `(i, j)` is dropped if afterwards row `i` has lost at most
/// `threshold * s_i` and receiver `j` at most `threshold * sum_k A_k F_kj`. Budgets only fill up, so every kept
/// entry would overflow one of them.
///
/// # Errors
/// [`BakeError::BadThreshold`] if `threshold` is not in `[0, 1)`, [`BakeError::Input`] if `area` does not have
/// one entry per patch.
pub fn sparsify(ff: &FormFactorMatrix, area: &[f64], threshold: f64) -> Result<Sparsified, BakeError> {
    if !(0.0..1.0).contains(&threshold) {
        return Err(BakeError::BadThreshold(threshold));
    }
    let n = ff.n();
    if area.len() != n {
        return Err(BakeError::Input(format!("{} areas for {n} patches", area.len())));
    }
    let mut row_of = vec![0usize; ff.nonzeros()];
    let mut incoming = vec![0.0; n];
    for (i, &a) in area.iter().enumerate() {
        for k in ff.row_range(i) {
            row_of[k] = i;
            incoming[ff.columns()[k] as usize] += a * ff.values()[k];
        }
    }
    // Sort keys computed once (the comparison would otherwise fetch two rows' areas per call), then the
    // position: an unstable sort of unique keys gives the stable order.
    let mut order: Vec<(i64, usize)> =
        (0..ff.nonzeros()).map(|k| (total_order_key(area[row_of[k]] * ff.values()[k]), k)).collect();
    order.sort_unstable();
    let row_budget: Vec<f64> = (0..n).map(|i| threshold * ff.row_sum(i)).collect();
    let mut dropped = vec![0.0; n];
    let mut dropped_incoming = vec![0.0; n];
    let mut keep = vec![true; ff.nonzeros()];
    for (_, k) in order {
        let (i, j, f) = (row_of[k], ff.columns()[k] as usize, ff.values()[k]);
        let p = area[i] * f;
        if dropped[i] + f <= row_budget[i] && dropped_incoming[j] + p <= threshold * incoming[j] {
            dropped[i] += f;
            dropped_incoming[j] += p;
            keep[k] = false;
        }
    }
    let matrix = ff.retain_entries(|k| keep[k]);
    let returned = vec![0.0; n];
    Ok(Sparsified { matrix, dropped, returned, dropped_incoming, incoming })
}

/// What a bake does with the energy sparsification drops from a row (see the [`crate::bake`] docs, step 1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub enum DroppedEnergy {
    /// Give it back to the kept entries of the same row, in proportion to them
    /// ([`Sparsified::return_dropped`]): every row keeps its sum, so a closed scene loses no energy.
    #[default]
    ReturnToRow,
    /// Lose it: the kept entries keep their values and every row sums to less than before.
    Discard,
}

impl Sparsified {
    /// Gives each row's dropped energy back to its kept entries in proportion to them: row `i`'s kept entries
    /// are scaled by `s_i / k_i` (`s_i` the original row sum, `k_i = s_i - d_i` what was kept), so the row sum
    /// is `s_i` again, to f64 rounding. Records what was given back in [`Sparsified::returned`].
    ///
    /// A kept entry grows by the factor `1 + d_i / k_i <= 1 / (1 - t)` for threshold `t` (the row budget),
    /// so the redistribution moves at most `d_i` of the row's energy between receivers, which is what the
    /// sparsification error component measures; reciprocity `A_i F_ij = A_j F_ji` changes by the difference
    /// of the two rows' factors, at most `t / (1 - t)` relative. A row that kept nothing (only possible when
    /// all its entries were zero) is left as it is.
    pub fn return_dropped(&mut self) {
        let n = self.matrix.n();
        let scale: Vec<f64> = (0..n)
            .map(|i| {
                let kept = self.matrix.row_sum(i);
                let d = self.dropped[i] - self.returned[i];
                if kept > 0.0 && d > 0.0 {
                    self.returned[i] += d;
                    (kept + d) / kept
                } else {
                    1.0
                }
            })
            .collect();
        self.matrix.map_values(|i, _, f| f * scale[i]);
    }
}

/// `f64::total_cmp`'s order as an integer: the sign-magnitude bits turned into two's complement.
fn total_order_key(x: f64) -> i64 {
    let bits = x.to_bits() as i64;
    bits ^ ((((bits >> 63) as u64) >> 1) as i64)
}

/// Energy dropped by sparsification (fractions of power; see the [`crate::bake`] docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EnergyDropped {
    /// Largest per-row dropped sum `d_i`.
    pub max_row: f64,
    /// Mean of `d_i` over rows.
    pub mean_row: f64,
    /// Largest `d_i / s_i` (dropped fraction of a row's energy; `<=` the threshold).
    pub max_row_fraction: f64,
    /// Largest fraction of a receiver's incoming power (under uniform radiosity) dropped (`<=` the threshold).
    pub max_receiver_fraction: f64,
    /// `sum_i d_i`: a sum over rows (it grows with the patch count), not a fraction of anything; the fraction of
    /// all power is `area_weighted`.
    pub total: f64,
    /// `sum_i A_i d_i / sum_i A_i s_i`: fraction of all transported power under uniform radiosity.
    pub area_weighted: f64,
    /// [`EnergyDropped::area_weighted`] of what the kept rows really lost: the original row sum minus the
    /// sparsified one in place of `d_i`. Zero to f64 rounding when every row's drop was given back
    /// ([`Sparsified::return_dropped`]), equal to `area_weighted` when none was.
    pub net_area_weighted: f64,
    /// Largest factor minus one by which a row's kept entries were scaled up to return its dropped energy
    /// (`r_i / k_i`): the largest relative change of a stored form factor.
    pub max_entry_scale: f64,
}

impl EnergyDropped {
    /// What `sparse` dropped from the original matrix `ff` with patch areas `area`.
    #[must_use]
    pub fn of(ff: &FormFactorMatrix, area: &[f64], sparse: &Sparsified) -> EnergyDropped {
        let n = ff.n();
        let row_sums: Vec<f64> = (0..n).map(|i| ff.row_sum(i)).collect();
        let total_transport: f64 = row_sums.iter().zip(area).map(|(s, a)| s * a).sum();
        let fraction = |d: &[f64], s: &[f64]| {
            d.iter().zip(s).map(|(&d, &s)| if s > 0.0 { d / s } else { 0.0 }).fold(0.0, f64::max)
        };
        let weighted = |d: &[f64]| {
            if total_transport > 0.0 {
                d.iter().zip(area).map(|(d, a)| d * a).sum::<f64>() / total_transport
            } else {
                0.0
            }
        };
        // Measured from the matrices (not `d_i - r_i`), so the report shows what the stored rows really lost.
        let net: Vec<f64> = (0..n).map(|i| row_sums[i] - sparse.matrix.row_sum(i)).collect();
        let max_entry_scale = sparse
            .returned
            .iter()
            .enumerate()
            .map(|(i, &r)| {
                let kept = sparse.matrix.row_sum(i) - r;
                if r > 0.0 && kept > 0.0 {
                    r / kept
                } else {
                    0.0
                }
            })
            .fold(0.0, f64::max);
        EnergyDropped {
            max_row: sparse.dropped.iter().copied().fold(0.0, f64::max),
            mean_row: if n == 0 { 0.0 } else { sparse.dropped.iter().sum::<f64>() / n as f64 },
            max_row_fraction: fraction(&sparse.dropped, &row_sums),
            max_receiver_fraction: fraction(&sparse.dropped_incoming, &sparse.incoming),
            total: sparse.dropped.iter().sum(),
            area_weighted: weighted(&sparse.dropped),
            net_area_weighted: weighted(&net),
            max_entry_scale,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::total_order_key;

    #[test]
    fn total_order_key_orders_like_total_cmp() {
        let v = [
            f64::NEG_INFINITY,
            -1.0,
            -f64::MIN_POSITIVE,
            -5e-324,
            -0.0,
            0.0,
            5e-324,
            f64::MIN_POSITIVE,
            1.0,
            1.0 + f64::EPSILON,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            -f64::NAN,
        ];
        for a in v {
            for b in v {
                assert_eq!(total_order_key(a).cmp(&total_order_key(b)), a.total_cmp(&b), "{a:e} vs {b:e}");
            }
        }
    }
}
