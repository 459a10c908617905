//! Materials: MTL `Kd` (reflectance, in `[0, 1)`, required) and `Ke` (emission, radiant exitance in W/m^2,
//! finite and `>= 0`, default 0), checked with the line of the offending statement.

use super::error::SceneError;
use super::obj::{MaterialSource, ObjData};
use crate::rgb::Rgb;

/// A diffuse material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the MTL `newmtl` statement.
    pub name: String,
    /// Reflectance per RGB channel (`Kd`), each in `[0, 1)`.
    pub reflectance: Rgb,
    /// Emission per RGB channel (`Ke`), radiant exitance in W/m^2, each finite and `>= 0`.
    pub emission: Rgb,
}

impl Material {
    /// Whether the material emits light (any channel of `Ke` above zero).
    #[must_use]
    pub fn is_emitter(&self) -> bool {
        self.emission.cmpgt(Rgb::ZERO).any()
    }
}

/// Checks every material's `Kd` and `Ke`, in definition order.
pub(super) fn check_materials(obj: &ObjData) -> Result<Vec<Material>, SceneError> {
    let mut out = Vec::with_capacity(obj.materials.len());
    for m in &obj.materials {
        let src = obj.sources.get(&m.name).cloned().unwrap_or(MaterialSource {
            file: obj.file.clone(),
            newmtl_line: 0,
            kd_line: None,
            ke_line: None,
        });
        let bad = |line: Option<usize>, problem: String| SceneError::BadMaterial {
            file: src.file.clone(),
            line: line.unwrap_or(src.newmtl_line),
            material: m.name.clone(),
            problem,
        };
        let Some(kd) = m.diffuse else {
            return Err(bad(None, "no reflectance (Kd) given".to_owned()));
        };
        let ke = m.emissive.unwrap_or([0.0; 3]);
        for (c, &r) in kd.iter().enumerate() {
            if !r.is_finite() {
                return Err(bad(src.kd_line, format!("reflectance Kd channel {c} is not finite ({r})")));
            }
            if !(0.0..1.0).contains(&r) {
                return Err(bad(src.kd_line, format!("reflectance Kd channel {c} = {r} is outside [0, 1)")));
            }
        }
        for (c, &e) in ke.iter().enumerate() {
            if !e.is_finite() {
                return Err(bad(src.ke_line, format!("emission Ke channel {c} is not finite ({e})")));
            }
            if e < 0.0 {
                return Err(bad(src.ke_line, format!("emission Ke channel {c} = {e} is negative")));
            }
        }
        out.push(Material {
            name: m.name.clone(),
            reflectance: Rgb::from_array(kd),
            emission: Rgb::from_array(ke),
        });
    }
    Ok(out)
}
