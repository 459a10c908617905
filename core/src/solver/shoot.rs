//! Progressive-refinement shooting (Southwell iteration; Cohen, Chen, Wallace, Greenberg 1988) within a
//! work-unit budget, resumable mid-row: [`Solver::step`].

use super::{add3, get3, magnitude, NoProgressReason, Outcome, SelectionState, Shot, Solver};
use crate::codec::Frac;
use crate::scalar::Scalar;

impl<S: Scalar> Solver<'_, S> {
    /// Applies entries of the shot in flight while the budget allows. Returns `true` when the row is done.
    /// `scratch`: Jacobi's receiving buffer; `None` sends received power to the unshot buffer and keeps the
    /// block winners current.
    ///
    /// Receivers are increasing within a row, so consecutive entries mostly fall in the same selection block:
    /// its winner and key are kept in locals and stored when the row moves to another block (a store and
    /// reload per entry would chain every entry to the previous one through memory).
    pub(super) fn apply_shot(
        &mut self,
        budget: u32,
        used: &mut u32,
        mut scratch: Option<&mut [[S; 3]]>,
        per_entry: u32,
    ) -> bool {
        let Some(mut shot) = self.shot else { return true };
        // The block in the locals (`u32::MAX`: none), its winner and the winner's rank.
        let (mut block, mut winner, mut winner_rank) = (u32::MAX, 0u32, S::ZERO.rank(0));
        // Sweeps run with the selection invalid (rebuilt before the next shot): nothing to maintain. Shooting
        // applies entries only with every block built (`step` finishes a rebuild before resuming a row).
        let maintain = scratch.is_none() && self.selection == SelectionState::Valid;
        // The row's entries were proven in range by `Table::parse`: no per-entry lookup or check.
        let Some(row) = self.table.row_view(shot.shooter) else {
            self.shot = None;
            return true;
        };
        let mut entries = row.entries_from(shot.next);
        let mut done = true;
        while shot.next < shot.end {
            if budget - *used < per_entry {
                done = false;
                break;
            }
            let Some((i, f)) = entries.next() else {
                // Only a row shorter than its range could end here, which parse rules out.
                shot.next = shot.end;
                break;
            };
            {
                let rho = self.entry_rho(i);
                let mut t = [S::ZERO; 3];
                let mut r = [S::ZERO; 3];
                for c in 0..3 {
                    t[c] = shot.power[c].mul_frac(f);
                    r[c] = t[c].mul_rho(rho[c]);
                }
                add3(self.buf.incident, i, t);
                add3(self.buf.power, i, r);
                *used += 1;
                match scratch.as_deref_mut() {
                    Some(s) => add3(s, i, r),
                    None if !maintain => add3(self.buf.unshot, i, r),
                    None => {
                        let before = get3(self.buf.unshot, i);
                        let after = [0, 1, 2].map(|c| before[c].add(r[c]));
                        if let Some(v) = self.buf.unshot.get_mut(i as usize) {
                            *v = after;
                        }
                        let b = i >> self.block_shift;
                        if b != block {
                            if block != u32::MAX {
                                self.set_winner(block, winner);
                            }
                            block = b;
                            winner = self.buf.selection.get(b as usize).copied().unwrap_or(i);
                            winner_rank = self.rank(winner);
                        }
                        let rank = magnitude(after).rank(i);
                        if i == winner {
                            // Each channel moved away from zero (or not at all): it stays the winner.
                            let grew = (0..3)
                                .all(|c| (before[c] >= S::ZERO) == (r[c] >= S::ZERO) || r[c] == S::ZERO);
                            if grew {
                                winner_rank = rank;
                            } else {
                                *used += self.rescan_block(b);
                                winner = self.buf.selection.get(b as usize).copied().unwrap_or(i);
                                winner_rank = self.rank(winner);
                            }
                        } else {
                            // One integer compare: whether a receiver overtakes its block's winner is
                            // data-dependent, and a compare-and-select keeps it off the branch predictor.
                            let above = rank > winner_rank;
                            winner = if above { i } else { winner };
                            winner_rank = if above { rank } else { winner_rank };
                        }
                    }
                }
            }
            shot.next += 1;
            self.entries = self.entries.wrapping_add(1);
        }
        if block != u32::MAX {
            self.set_winner(block, winner);
        }
        self.selected = None;
        self.shot = if done { None } else { Some(shot) };
        done
    }

    pub(super) fn set_winner(&mut self, b: u32, w: u32) {
        if let Some(t) = self.buf.selection.get_mut(b as usize) {
            *t = w;
        }
    }

    /// Starts shooting `shooter`'s unshot power times `omega_extra` (overshoot/256 extra).
    pub(super) fn start_shot(&mut self, shooter: u32, overshoot: u8) -> u32 {
        let u = get3(self.buf.unshot, shooter);
        let extra = Frac { mantissa: u32::from(overshoot), shift: 8 };
        let power = u.map(|x| x.add(x.mul_frac(extra)));
        if let Some(v) = self.buf.unshot.get_mut(shooter as usize) {
            for c in 0..3 {
                v[c] = v[c].sub(power[c]);
            }
        }
        let row = self.table.row(shooter).unwrap_or(0..0);
        self.shot = Some(Shot { shooter, next: row.start, end: row.end, power });
        self.shots = self.shots.saturating_add(1);
        1 + self.update_leaf(shooter)
    }

    /// Worst-case units of one shooting entry: the entry and a rescan of the receiver's block (`1 + B`).
    pub(super) fn shooting_entry_cost(&self) -> u32 {
        (1u32 << self.block_shift) + 1
    }

    /// Progressive-refinement shooting (Southwell iteration; Cohen et al. 1988) for at most `budget` work
    /// units: repeatedly shoot the patch with the largest unshot power, resuming a row cut short by the
    /// previous step.
    ///
    /// Selection keeps the winner of each block of `B` consecutive slots (`B` the power of two at or above
    /// `sqrt(n)`) and scans the `ceil(n / B)` winners for the largest. Cost: 1 unit per block winner scanned
    /// and per slot scanned when a block is rebuilt; per shot 1 unit plus a rescan of the shooter's block
    /// (`<= B`); per entry 1 unit, plus a rescan of the receiver's block when the receiver was its block's
    /// winner and its magnitude may have shrunk (a channel moved towards zero). An action runs only if its
    /// worst case fits in what is left of the budget: an entry `B + 1`, a block rebuild its length, a
    /// selection the block count, a shot start 1 plus its block's length. A selection made at the end of one
    /// step is kept for the next while nothing changes.
    pub fn step(&mut self, budget: u32) -> Outcome {
        let mut used = 0u32;
        if self.sweep.is_some_and(|s| s.jacobi) {
            return Outcome::NoProgress { used, reason: NoProgressReason::JacobiInProgress };
        }
        // A Gauss-Seidel sweep left half done is abandoned (its in-flight row is finished below): shooting
        // works on the same residual.
        self.sweep = None;
        let worst = self.shooting_entry_cost();
        loop {
            if let SelectionState::Rebuilding(mut b) = self.selection {
                while b < self.blocks {
                    let range = self.block_range(b);
                    let need = range.end - range.start;
                    if budget - used < need {
                        self.selection = SelectionState::Rebuilding(b);
                        return self.spent(used, need);
                    }
                    used += self.rescan_block(b);
                    b += 1;
                }
                self.selection = SelectionState::Valid;
            }
            if self.shot.is_some() {
                if !self.apply_shot(budget, &mut used, None, worst) {
                    return self.spent(used, worst);
                }
                continue;
            }
            if self.slots == 0 {
                return Outcome::Converged { used };
            }
            let w = match self.selected {
                Some(w) => w,
                None => {
                    if budget - used < self.blocks {
                        return self.spent(used, self.blocks);
                    }
                    let (w, units) = self.select();
                    used += units;
                    self.selected = Some(w);
                    w
                }
            };
            let key = self.key(w);
            if !key.is_usable() {
                return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
            }
            if key <= self.config.tolerance {
                return Outcome::Converged { used };
            }
            let range = self.block_range(w >> self.block_shift);
            let need = 1 + (range.end - range.start);
            if budget - used < need {
                return self.spent(used, need);
            }
            used += self.start_shot(w, self.config.overshoot);
        }
    }

    pub(super) fn spent(&self, used: u32, needed: u32) -> Outcome {
        if used == 0 {
            Outcome::NoProgress { used, reason: NoProgressReason::BudgetTooSmall { needed } }
        } else {
            Outcome::BudgetSpent { used }
        }
    }
}
