//! Relighting in exact arithmetic: [`TransferVectors`], `B_static` and the unit response `T_g` of every
//! dynamic light group, so that `B = B_static + sum_g I_g * T_g` for any intensities.

use super::error::{check_finite, check_len, ReferenceError};
use super::method::{solve_many, Method};
use super::system::RadiositySystem;
use crate::lighting::PatchLighting;
use crate::patch::FormFactorMatrix;
use crate::rgb::{max_channel, Rgb};

/// Emission of a scene split into a static part and dynamic light groups.
#[derive(Clone, Copy, Debug)]
pub struct LightGroupEmission<'a> {
    /// Emission of the static lights, always on, per patch (W/m^2).
    pub static_emission: &'a [Rgb],
    /// Emission per patch of its dynamic light group at unit intensity (W/m^2); zero for patches in no group.
    pub unit_emission: &'a [Rgb],
    /// Dynamic light group of each patch (`None`: in no dynamic group).
    pub group: &'a [Option<usize>],
    /// Number of dynamic light groups.
    pub group_count: usize,
}

impl<'a> LightGroupEmission<'a> {
    /// The emission of a meshed scene's patches: its static lights, and its dynamic light groups at unit
    /// intensity, one group per entry of [`PatchLighting::dynamic_groups`].
    #[must_use]
    pub fn of(lighting: &'a PatchLighting) -> Self {
        LightGroupEmission {
            static_emission: &lighting.static_emission,
            unit_emission: &lighting.unit_emission,
            group: &lighting.group,
            group_count: lighting.dynamic_groups.len(),
        }
    }
}

/// The exact answer for any relighting: `B = B_static + sum_g I_g * T_g`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferVectors {
    /// Radiosity from the static emission alone.
    pub b_static: Vec<Rgb>,
    /// `t[g]`: radiosity from light group `g` at unit intensity (all other emission off).
    pub t: Vec<Vec<Rgb>>,
    /// Largest relative residual over all the solves and channels.
    pub residual: f64,
    /// Gauss-Seidel sweeps over all the solves (0 for the dense solver).
    pub sweeps: usize,
}

impl TransferVectors {
    /// `B = B_static + sum_g I_g * T_g` for per-group, per-channel intensities `intensity[g]`.
    ///
    /// # Errors
    /// If `intensity` does not have one entry per group, or an intensity is not finite.
    pub fn relight(&self, intensity: &[Rgb]) -> Result<Vec<Rgb>, ReferenceError> {
        check_len("intensity", intensity, self.t.len())?;
        for (group, v) in intensity.iter().enumerate() {
            for (channel, value) in v.to_array().into_iter().enumerate() {
                if !value.is_finite() {
                    return Err(ReferenceError::NonFiniteIntensity { group, channel, value });
                }
            }
        }
        let mut b = self.b_static.clone();
        for (t, i) in self.t.iter().zip(intensity) {
            for (bp, &tp) in b.iter_mut().zip(t) {
                *bp += *i * tp;
            }
        }
        Ok(b)
    }
}

/// Computes `B_static` and one transfer vector `T_g` per dynamic light group.
///
/// Group `g`'s right-hand side is `unit_emission` on the patches of group `g` and zero elsewhere. With the dense
/// method all `1 + group_count` right-hand sides share one factorization.
///
/// # Errors
/// A length mismatch, non-finite emission, a group index out of range, unit emission on a patch in no group, or
/// any solver error.
pub fn transfer_vectors(
    system: RadiositySystem<'_>,
    lights: &LightGroupEmission<'_>,
    method: &Method,
) -> Result<TransferVectors, ReferenceError> {
    let n = system.len();
    check_len("static emission", lights.static_emission, n)?;
    check_len("unit emission", lights.unit_emission, n)?;
    check_len("light group membership", lights.group, n)?;
    check_finite("unit emission", lights.unit_emission)?;
    let mut rhs = vec![vec![Rgb::ZERO; n]; lights.group_count];
    for (patch, (g, e)) in lights.group.iter().zip(lights.unit_emission).enumerate() {
        match *g {
            Some(group) if group >= lights.group_count => {
                return Err(ReferenceError::GroupOutOfRange {
                    patch,
                    group,
                    group_count: lights.group_count,
                });
            }
            Some(group) => rhs[group][patch] = *e,
            None if *e != Rgb::ZERO => return Err(ReferenceError::UngroupedEmission { patch }),
            None => {}
        }
    }
    let mut all: Vec<&[Rgb]> = vec![lights.static_emission];
    all.extend(rhs.iter().map(Vec::as_slice));
    let solutions = solve_many(system, &all, method)?;
    let residual = solutions.iter().map(|s| s.residual).fold(0.0, |worst: f64, r| worst.max(max_channel(r)));
    let sweeps = solutions.iter().map(|s| s.sweeps).sum();
    let mut solutions = solutions.into_iter().map(|s| s.b);
    let b_static = solutions.next().unwrap_or_default();
    Ok(TransferVectors { b_static, t: solutions.collect(), residual, sweeps })
}

/// The exact answer for any relighting of a meshed scene: the transfer vectors of `lighting` on the scene's own
/// form factors `form_factors` (validated with the default row-sum slack), solved with `method`.
///
/// # Errors
/// Any error of [`RadiositySystem::new`] or [`transfer_vectors`].
pub fn exact_transfer(
    lighting: &PatchLighting,
    form_factors: &FormFactorMatrix,
    method: &Method,
) -> Result<TransferVectors, ReferenceError> {
    let system = RadiositySystem::new(&lighting.rho, form_factors)?;
    transfer_vectors(system, &LightGroupEmission::of(lighting), method)
}
