//! Reading a table back: everything the device computes with, decoded into f64 (the inverse of step 6 of a
//! bake), for the codec check of step 7 and for [`crate::evaluate`].

use glam::Vec3;
use radiosity_core::Table;

use crate::patch::FormFactorMatrix;
use crate::rgb::Rgb;

/// Everything the device sees, decoded back from a parsed table into f64: reflectance per patch, emission per
/// patch with every group at its default intensity, areas, the shooter rows (patch-indexed; a patch without
/// run-time state has an empty row and receives nothing) and the static base.
///
/// What the device converges to is [`Decoded::solution`] of the f64 solve of `(rho, shooting form of rows,
/// rhs)`: with a solved base the device starts from the static base and shoots only the light groups, so
/// `B = B_base + (I - R F~)^-1 E_dyn`; without one it shoots everything, `B = (I - R F~)^-1 (E_s + E_dyn)`.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// Reflectance per patch (decoded codes).
    pub rho: Vec<Rgb>,
    /// Static plus dynamic emission per patch at the table's default intensities (W/m^2).
    pub emission: Vec<Rgb>,
    /// The right-hand side the device shoots (W/m^2): the dynamic emission with a solved base, else
    /// [`Decoded::emission`].
    pub rhs: Vec<Rgb>,
    /// The static base `E_s + rho G_s` per patch (decoded codes) when the base is solved, else zero.
    pub base: Vec<Rgb>,
    /// Patch areas (the table's f32 values).
    pub area: Vec<f64>,
    /// Shooter rows with decoded form factors, patch-indexed (empty rows for patches without state).
    pub rows: FormFactorMatrix,
    /// Whether each patch has run-time state.
    pub state: Vec<bool>,
}

impl Decoded {
    /// The device's converged answer from `response`, the f64 solve of `rho`, the shooting form of `rows` and
    /// `rhs`: `base + response`.
    #[must_use]
    pub fn solution(&self, mut response: Vec<Rgb>) -> Vec<Rgb> {
        for (b, &s) in response.iter_mut().zip(&self.base) {
            *b += s;
        }
        response
    }
}

/// Decodes a parsed table into f64: what the device computes with, for comparison with the f64 reference.
#[must_use]
pub fn decode_table(table: &Table<'_>) -> Decoded {
    use radiosity_core::codec::{decode_emission_f32, decode_reflectance};
    let n = table.patch_count();
    let emission_of = |codes: [u16; 3]| Rgb::from_array(codes.map(|c| f64::from(decode_emission_f32(c))));
    let solved = table.base_solved();
    let mut d = Decoded {
        rho: Vec::with_capacity(n as usize),
        emission: Vec::with_capacity(n as usize),
        rhs: Vec::with_capacity(n as usize),
        base: Vec::with_capacity(n as usize),
        area: Vec::with_capacity(n as usize),
        rows: FormFactorMatrix::default(),
        state: Vec::with_capacity(n as usize),
    };
    let (mut row_start, mut col, mut value) = (vec![0], Vec::new(), Vec::new());
    for i in 0..n {
        let m = table.material(i).unwrap_or(0);
        let r = table.reflectance(m).unwrap_or([0; 3]);
        let rho = Rgb::from_array(r.map(|c| f64::from(decode_reflectance(c).to_f32())));
        let e = emission_of(table.base_emission(i).unwrap_or([0; 3]));
        let g = emission_of(table.base_irradiance(i).unwrap_or([0; 3]));
        d.rho.push(rho);
        d.emission.push(e);
        d.rhs.push(if solved { Rgb::ZERO } else { e });
        d.base.push(if solved { e + rho * g } else { Rgb::ZERO });
        d.area.push(f64::from(table.area(i).unwrap_or(0.0)));
        let slot = table.slot_of(i);
        d.state.push(slot.is_some());
        if let Some(slot) = slot {
            for k in table.row(slot).unwrap_or(0..0) {
                if let Some((j, f)) = table.entry(slot, k) {
                    col.push(table.slot_patch(j).unwrap_or(0));
                    value.push(f64::from(f.to_f32()));
                }
            }
        }
        row_start.push(col.len());
    }
    // `Table::parse` proved every row's receivers strictly increasing and the slot -> patch map increasing and in
    // range, and decoded codes are finite.
    d.rows = FormFactorMatrix::new(n as usize, row_start, col, value)
        .expect("a parsed table's rows form a valid matrix");
    for g in 0..table.group_count() {
        let intensity = Vec3::from_array(table.default_intensity(g).unwrap_or([0.0; 3])).as_dvec3();
        for k in table.group_members(g).unwrap_or(0..0) {
            if let Some(m) = table.member(k) {
                let v = intensity * emission_of(m.emission);
                d.emission[m.patch as usize] += v;
                d.rhs[m.patch as usize] += v;
            }
        }
    }
    d
}
