//! Gauss-Seidel and Jacobi sweeps in residual form, within a work-unit budget and resumable:
//! [`Solver::step_gauss_seidel`], [`Solver::step_jacobi`].

use super::{get3, NoProgressReason, Outcome, SelectionState, Shot, Solver};
use crate::scalar::Scalar;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Phase {
    /// Jacobi only: zeroing the scratch buffer, next patch.
    Clear(u32),
    /// Visiting rows, next row.
    Rows(u32),
    /// End-of-sweep scan (Jacobi: copy scratch into unshot), next patch.
    Scan(u32),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sweep<S> {
    pub(super) jacobi: bool,
    pub(super) phase: Phase,
    pub(super) max: S,
}

impl<S: Scalar> Solver<'_, S> {
    /// Gauss-Seidel sweeps for at most `budget` work units, in residual form: each sweep shoots every
    /// patch's whole unshot power in index order, which is exactly a Gauss-Seidel sweep on `(I - R F) B = E`
    /// (each patch relaxed with the latest values of the others), reading shooter rows.
    ///
    /// Cost: 1 unit per row visited, 1 per entry, 1 per patch in the end-of-sweep convergence scan.
    pub fn step_gauss_seidel(&mut self, budget: u32) -> Outcome {
        self.sweep_step(None, budget)
    }

    /// Jacobi sweeps for at most `budget` work units, in residual form: each sweep shoots every patch's unshot
    /// power as it was at the start of the sweep, collecting what is received in `scratch` (state count
    /// elements, the same buffer on every call of a sweep), which becomes the unshot power at the end of the
    /// sweep: `B_{k+1} = E + R F B_k`.
    ///
    /// Cost: 1 unit per patch to clear `scratch`, 1 per row visited, 1 per entry, 1 per patch in the
    /// end-of-sweep copy and convergence scan.
    pub fn step_jacobi(&mut self, scratch: &mut [[S; 3]], budget: u32) -> Outcome {
        if scratch.len() < self.slots as usize {
            return Outcome::NoProgress { used: 0, reason: NoProgressReason::ScratchTooSmall };
        }
        self.sweep_step(Some(scratch), budget)
    }

    /// Called on a light or reflectance change: a Gauss-Seidel sweep in its end-of-sweep scan starts the scan
    /// over, since the slots it has scanned may have received unshot power; otherwise the sweep would judge
    /// convergence on their old magnitudes and could report [`Outcome::Converged`] with unshot power above the
    /// tolerance. (A Jacobi sweep refuses changes; a sweep still visiting rows scans everything afterwards.)
    pub(super) fn restart_scan(&mut self) {
        if let Some(s) = self.sweep.as_mut() {
            if let Phase::Scan(_) = s.phase {
                s.phase = Phase::Scan(0);
                s.max = S::ZERO;
            }
        }
    }

    pub(super) fn sweep_step(&mut self, mut scratch: Option<&mut [[S; 3]]>, budget: u32) -> Outcome {
        let mut used = 0u32;
        if self.slots == 0 {
            // Nothing to sweep (and an empty sweep would cost no units, so it must not loop).
            return Outcome::Converged { used };
        }
        let jacobi = scratch.is_some();
        match self.sweep {
            Some(s) if s.jacobi == jacobi => {}
            Some(s) if s.jacobi => {
                return Outcome::NoProgress { used, reason: NoProgressReason::JacobiInProgress };
            }
            _ => {
                // Coming from shooting or a half-done Gauss-Seidel sweep: finish the row in flight into the
                // unshot buffer (the selection is not maintained from here on), then start a fresh sweep.
                self.selection = SelectionState::Rebuilding(0);
                self.selected = None;
                if !self.apply_shot(budget, &mut used, None, 1) {
                    return self.spent(used, 1);
                }
                self.sweep = None;
            }
        }
        let mut sweep = self.sweep.unwrap_or(Sweep {
            jacobi,
            phase: if jacobi { Phase::Clear(0) } else { Phase::Rows(0) },
            max: S::ZERO,
        });
        loop {
            if used >= budget {
                self.sweep = Some(sweep);
                return self.spent(used, 1);
            }
            match sweep.phase {
                Phase::Clear(i) if i < self.slots => {
                    if let Some(s) = scratch.as_deref_mut().and_then(|s| s.get_mut(i as usize)) {
                        *s = [S::ZERO; 3];
                    }
                    used += 1;
                    sweep.phase = Phase::Clear(i + 1);
                }
                Phase::Clear(_) => sweep.phase = Phase::Rows(0),
                Phase::Rows(j) if j < self.slots => {
                    if self.shot.is_none() {
                        // Row visit: take the shooter's residual (Jacobi keeps it until the end-of-sweep copy).
                        let u = get3(self.buf.unshot, j);
                        if !jacobi {
                            if let Some(v) = self.buf.unshot.get_mut(j as usize) {
                                *v = [S::ZERO; 3];
                            }
                        }
                        let row = self.table.row(j).unwrap_or(0..0);
                        self.shot = Some(Shot { shooter: j, next: row.start, end: row.end, power: u });
                        self.shots = self.shots.saturating_add(1);
                        used += 1;
                    }
                    if !self.apply_shot(budget, &mut used, scratch.as_deref_mut(), 1) {
                        self.sweep = Some(sweep);
                        return self.spent(used, 1);
                    }
                    sweep.phase = Phase::Rows(j + 1);
                }
                Phase::Rows(_) => {
                    sweep.phase = Phase::Scan(0);
                    sweep.max = S::ZERO;
                }
                Phase::Scan(i) if i < self.slots => {
                    if let Some(s) = scratch.as_deref_mut().and_then(|s| s.get_mut(i as usize)) {
                        if let Some(v) = self.buf.unshot.get_mut(i as usize) {
                            *v = *s;
                        }
                    }
                    let k = self.key(i);
                    if k > sweep.max || !k.is_usable() {
                        sweep.max = k;
                    }
                    used += 1;
                    sweep.phase = Phase::Scan(i + 1);
                }
                Phase::Scan(_) => {
                    self.sweep = None;
                    if !sweep.max.is_usable() {
                        return Outcome::NoProgress { used, reason: NoProgressReason::NotFinite };
                    }
                    if sweep.max <= self.config.tolerance {
                        return Outcome::Converged { used };
                    }
                    sweep = Sweep {
                        jacobi,
                        phase: if jacobi { Phase::Clear(0) } else { Phase::Rows(0) },
                        max: S::ZERO,
                    };
                }
            }
        }
    }
}
