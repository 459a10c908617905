//! Relighting a running solution (warm start): light-group intensity changes ([`Solver::set_light`]) and
//! reflectance edits ([`Solver::set_reflectance`]), injected as unshot power.

use super::{add3, get3, Solver, SolverError};
use crate::codec::{decode_reflectance, encode_reflectance};
use crate::scalar::Scalar;

impl<S: Scalar> Solver<'_, S> {
    pub(super) fn check_change(&self) -> Result<(), SolverError> {
        if self.sweep.is_some_and(|s| s.jacobi) {
            return Err(SolverError::JacobiInProgress);
        }
        Ok(())
    }

    /// Sets light `group` to intensity `rgb`: the emission change (positive or negative) of every member is
    /// injected as unshot power, keeping the current solution as a warm start. Returns the work done (one
    /// unit per member plus any block rescan), outside any step budget.
    ///
    /// The injection cancels against the power already there, so with f32 a patch's absolute error after a
    /// change is about `2^-24` times the largest power it has held (dimming 1 -> 1e-6 leaves errors near
    /// 6e-8, not 6e-14); [`Solver::restart`] gives a cold start with the current settings when that matters. Fixed point has the same
    /// absolute resolution before and after.
    ///
    /// # Errors
    /// [`SolverError::NoSuchGroup`], [`SolverError::BadValue`] (not finite), [`SolverError::JacobiInProgress`].
    pub fn set_light(&mut self, group: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        self.check_change()?;
        if group >= self.groups {
            return Err(SolverError::NoSuchGroup { group });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !v.is_finite() {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        self.restart_scan();
        let new = rgb.map(S::from_f32);
        let old = self.intensity(group).unwrap_or([S::ZERO; 3]);
        let delta = [new[0].sub(old[0]), new[1].sub(old[1]), new[2].sub(old[2])];
        if let Some(v) = self.buf.intensity.get_mut(group as usize) {
            *v = new;
        }
        let mut units = self.add_group_emission(group, delta);
        for k in self.table.group_members(group).unwrap_or(0..0) {
            if let Some(slot) = self.table.member(k).and_then(|m| self.table.slot_of(m.patch)) {
                units = units.saturating_add(self.update_leaf(slot));
            }
        }
        Ok(units)
    }

    /// Sets the reflectance of `material` to `rgb` (each in `[0, 1)`, quantized by the reflectance codec):
    /// for every patch `i` of the material with state, `(rho_new - rho_old) H_i` (its incident power so far)
    /// is added to its power and injected as unshot power, so the solve converges to the cold solve of the
    /// edited scene restricted to the patches with state. Returns the work done (one unit per slot scanned
    /// plus block rescans), outside any step budget.
    ///
    /// Patches without state (crate docs, "Run-time state") show `E_s + rho_new G_s`: their own reflection of
    /// the static light changes, but nothing is propagated (what they reflect reaches no state), and the
    /// dynamic light they would have received is not there. The bake decides state with the table's
    /// reflectances: a receiver black in every channel gets no state, so making it reflect at run time shows
    /// only the static light on it; bake it with a nonzero reflectance if it must respond to dynamic lights.
    ///
    /// # Errors
    /// [`SolverError::NoSuchMaterial`], [`SolverError::BadValue`], [`SolverError::JacobiInProgress`].
    pub fn set_reflectance(&mut self, material: u32, rgb: [f32; 3]) -> Result<u32, SolverError> {
        self.check_change()?;
        if material >= self.materials {
            return Err(SolverError::NoSuchMaterial { material });
        }
        for (c, v) in rgb.iter().enumerate() {
            if !(0.0..1.0).contains(v) {
                return Err(SolverError::BadValue { channel: c as u8 });
            }
        }
        self.restart_scan();
        let new_codes = rgb.map(encode_reflectance);
        let old_codes = self.buf.reflectance.get(material as usize).copied().unwrap_or([0; 3]);
        if let Some(r) = self.buf.reflectance.get_mut(material as usize) {
            *r = new_codes;
        }
        self.refresh_rho(material);
        let mut units = 0u32;
        for i in 0..self.slots {
            units = units.saturating_add(1);
            if self.table.slot_material(i) != Some(material) {
                continue;
            }
            let h = get3(self.buf.incident, i);
            let mut d = [S::ZERO; 3];
            for c in 0..3 {
                d[c] = h[c]
                    .mul_frac(decode_reflectance(new_codes[c]))
                    .sub(h[c].mul_frac(decode_reflectance(old_codes[c])));
            }
            add3(self.buf.power, i, d);
            add3(self.buf.unshot, i, d);
            units = units.saturating_add(self.update_leaf(i));
        }
        Ok(units)
    }
}
