//! Per-patch physical attributes of a meshed scene: reflectance, and emission split into static lights and
//! dynamic light groups, in the form the reference solver and the table writer take.
//!
//! Emission of a patch is its material's `Ke` (W/m^2) times its light group's default intensity. A static group
//! is always on at its default intensity, so its emission is folded into `static_emission`; a dynamic group's
//! patches carry their `Ke` at unit intensity in `unit_emission`, and the group's default intensity is kept in
//! `default_intensity` so the baseline answer is `B_static + sum_g default_intensity_g * T_g`.

use crate::patch::Patch;
use crate::rgb::Rgb;
use crate::scene::Scene;

/// Reflectance and emission of every patch, with the scene's dynamic light groups.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchLighting {
    /// Reflectance per patch and channel (the material's `Kd`).
    pub rho: Vec<Rgb>,
    /// Emission of static lights per patch (W/m^2), at their default intensities.
    pub static_emission: Vec<Rgb>,
    /// Emission per patch of its dynamic light group at unit intensity (W/m^2); zero outside dynamic groups.
    pub unit_emission: Vec<Rgb>,
    /// Dynamic light group of each patch, as an index into `dynamic_groups`.
    pub group: Vec<Option<usize>>,
    /// Indices into [`Scene::light_groups`] of the dynamic groups, in scene order.
    pub dynamic_groups: Vec<usize>,
    /// Default intensity per channel of each dynamic group (same order as `dynamic_groups`).
    pub default_intensity: Vec<Rgb>,
}

impl PatchLighting {
    /// Collects the attributes of `patches` (meshed from `scene`).
    ///
    /// # Panics
    /// If a patch names a material that `scene` does not have (meshing never produces one).
    #[must_use]
    pub fn new(scene: &Scene, patches: &[Patch]) -> PatchLighting {
        let dynamic_groups: Vec<usize> =
            (0..scene.light_groups.len()).filter(|&g| scene.light_groups[g].dynamic).collect();
        let default_intensity = dynamic_groups.iter().map(|&g| scene.light_groups[g].intensity).collect();
        let n = patches.len();
        let mut lighting = PatchLighting {
            rho: Vec::with_capacity(n),
            static_emission: vec![Rgb::ZERO; n],
            unit_emission: vec![Rgb::ZERO; n],
            group: vec![None; n],
            dynamic_groups,
            default_intensity,
        };
        for (k, patch) in patches.iter().enumerate() {
            let material = &scene.materials[patch.material];
            lighting.rho.push(material.reflectance);
            let Some(g) = scene.light_group_of(patch.material) else { continue };
            let group = &scene.light_groups[g];
            if group.dynamic {
                lighting.unit_emission[k] = material.emission;
                lighting.group[k] = lighting.dynamic_groups.iter().position(|&d| d == g);
            } else {
                lighting.static_emission[k] = material.emission * group.intensity;
            }
        }
        lighting
    }

    /// Total emission per patch with every dynamic group at `intensity` (one RGB per dynamic group).
    ///
    /// # Panics
    /// If `intensity` has fewer entries than there are dynamic groups.
    #[must_use]
    pub fn emission(&self, intensity: &[Rgb]) -> Vec<Rgb> {
        (0..self.rho.len())
            .map(|k| match self.group[k] {
                Some(g) => self.static_emission[k] + self.unit_emission[k] * intensity[g],
                None => self.static_emission[k],
            })
            .collect()
    }

    /// Total emission per patch with every dynamic group at its default intensity.
    #[must_use]
    pub fn default_emission(&self) -> Vec<Rgb> {
        self.emission(&self.default_intensity)
    }
}
