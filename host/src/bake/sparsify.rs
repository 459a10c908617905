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
    /// Give it back to the kept entries ([`Sparsified::return_dropped`]): every row keeps its sum, so a closed
    /// scene loses no energy, and every receiver its incoming power.
    #[default]
    ReturnToRow,
    /// Lose it: the kept entries keep their values and every row sums to less than before.
    Discard,
}

/// Most alternating scalings [`Sparsified::return_dropped`] makes.
pub const RETURN_ROUNDS: usize = 100;

/// [`Sparsified::return_dropped`] stops scaling once every receiver's incoming power is within this relative
/// distance of its original value.
pub const RETURN_TOLERANCE: f64 = 1e-12;

impl Sparsified {
    /// Gives the dropped energy back to the kept entries, so that every row sends what it did before
    /// sparsification and every receiver receives what it did, both under uniform unit radiosity: the kept
    /// power exchanges `G_ij = A_i F_ij` are scaled as `x_i G_ij y_j` (alternately fitting the receivers'
    /// incoming sums `sum_i G_ij` to [`Sparsified::incoming`] and the rows' sums to their original `s_i`, at most
    /// [`RETURN_ROUNDS`] times, until the incoming sums are within [`RETURN_TOLERANCE`]; the Sinkhorn-Knopp
    /// iteration), ending on the rows so that each row's sum is `s_i` again, to f64 rounding. Records each
    /// row's returned energy `s_i - k_i` (`k_i` what was kept) in [`Sparsified::returned`].
    ///
    /// Why both sides: the row sums are the energy each shooter sends, so fitting them keeps a closed scene's
    /// energy; the incoming sums are the row sums of the shooting form `A_j F_ji / A_i` that the device
    /// converges to, and scaling rows alone would push those above their original value (up to the threshold
    /// above 1 in a closed scene, where the sparsified reference solve refuses rows above 1 plus the
    /// reciprocity tolerance). A kept entry moves by about the dropped fractions of its row and its receiver,
    /// each at most the threshold; where it lands is the sparsification error component.
    pub fn return_dropped(&mut self, area: &[f64]) {
        let n = self.matrix.n();
        let kept: Vec<f64> = (0..n).map(|i| self.matrix.row_sum(i)).collect();
        let target: Vec<f64> = (0..n).map(|i| kept[i] + self.dropped[i] - self.returned[i]).collect();
        for _ in 0..RETURN_ROUNDS {
            let mut received = vec![0.0; n];
            for (i, &a) in area.iter().enumerate().take(n) {
                for (j, f) in self.matrix.row(i) {
                    received[j] += a * f;
                }
            }
            let mut worst: f64 = 0.0;
            let y: Vec<f64> = received
                .iter()
                .zip(&self.incoming)
                .map(|(&r, &want)| {
                    if r > 0.0 && want > 0.0 {
                        worst = worst.max((r - want).abs() / want);
                        want / r
                    } else {
                        1.0
                    }
                })
                .collect();
            if worst <= RETURN_TOLERANCE {
                break;
            }
            self.matrix.map_values(|_, j, f| f * y[j]);
            self.scale_rows_to(&target);
        }
        self.scale_rows_to(&target);
        for i in 0..n {
            self.returned[i] += target[i] - kept[i];
        }
    }

    /// Scales every row with a positive sum to sum to `target[i]`.
    fn scale_rows_to(&mut self, target: &[f64]) {
        let x: Vec<f64> = (0..self.matrix.n())
            .map(|i| {
                let s = self.matrix.row_sum(i);
                if s > 0.0 {
                    target[i] / s
                } else {
                    1.0
                }
            })
            .collect();
        self.matrix.map_values(|i, _, f| f * x[i]);
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
    /// Largest relative change of a kept form factor (zero unless the dropped energy was given back,
    /// [`Sparsified::return_dropped`]).
    pub max_entry_scale: f64,
    /// Largest relative change of a receiver's incoming power under uniform unit radiosity
    /// (`sum_i A_i F_ij`), from the original matrix to the kept entries: at most the threshold when the
    /// dropped energy is lost, about [`RETURN_TOLERANCE`] when it was given back.
    pub max_incoming_change: f64,
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
        // Largest relative change of a kept entry: the original and sparsified rows side by side (both sorted).
        let mut max_entry_scale: f64 = 0.0;
        for i in 0..n {
            let mut orig = ff.row(i).peekable();
            for (j, f) in sparse.matrix.row(i) {
                while orig.peek().is_some_and(|&(k, _)| k < j) {
                    orig.next();
                }
                if let Some(&(k, g)) = orig.peek() {
                    if k == j && g > 0.0 {
                        max_entry_scale = max_entry_scale.max((f - g).abs() / g);
                    }
                }
            }
        }
        let mut received = vec![0.0; n];
        for (i, &a) in area.iter().enumerate().take(n) {
            for (j, f) in sparse.matrix.row(i) {
                received[j] += a * f;
            }
        }
        let max_incoming_change = received
            .iter()
            .zip(&sparse.incoming)
            .map(|(&r, &want)| if want > 0.0 { (r - want).abs() / want } else { 0.0 })
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
            max_incoming_change,
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
