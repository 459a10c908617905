//! A synthetic test table, written with core's writer, for the firmware while no baked scene is available.
//!
//! The **uniform enclosure**: `n` patches of equal area `A` forming a closed enclosure in which every patch sees
//! every other patch equally, `F_ij = 1 / (n - 1)` for `i != j`, `F_ii = 0`. Rows sum to exactly 1 (closed)
//! and reciprocity `A_i F_ij = A_j F_ji` holds because the areas are equal. It is not a geometric scene; it is
//! the densest table a patch count allows (every row has `n - 1` entries), so it is a worst case for the work
//! per shot, and its answer is analytic: with emission `E` on the light patches and reflectance `rho_i`, the
//! radiosity equation `B_i = E_i + rho_i / (n - 1) * sum_{j != i} B_j` is a small linear system.
//!
//! Layout of [`uniform_enclosure`]: 6 "walls" of `k x k` patches (so `n = 6 k^2`): wall 0 (patches
//! `0..k^2`) is red, wall 1 green, the rest white (the Cornell box's published reflectances, rounded); the
//! first `LIGHT_PATCHES` patches of wall 5 form the one light group, at unit intensity emitting the Cornell
//! light's `Ke` (17, 11.8, 4 W/m^2), so the Cornell box's relight scripts (one light group) run on it unchanged.

use radiosity_core::{
    required_len, write_table, FfCodec, GroupSpec, MemberSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};

/// Patches in the light group of [`uniform_enclosure`].
pub const LIGHT_PATCHES: u32 = 4;

/// Name of [`uniform_enclosure`]'s light group: the Cornell box's, so the box's relight scripts, which name
/// the group, run on this table too.
pub const LIGHT_NAME: &str = "light";

/// Light-group id of [`uniform_enclosure`]'s light: [`radiosity_core::group_id`] of [`LIGHT_NAME`], as a bake
/// writes it.
pub const LIGHT_ID: u32 = radiosity_core::group_id(LIGHT_NAME);

/// Reflectances (RGB): white, red, green.
pub const MATERIALS: [[f32; 3]; 3] = [[0.73, 0.73, 0.73], [0.63, 0.06, 0.05], [0.12, 0.45, 0.09]];

/// Unit-intensity emission of the light (W/m^2, RGB), the Cornell box light's `Ke`.
pub const LIGHT_EMISSION: [f32; 3] = [17.0, 11.8, 4.0];

/// Writes the uniform enclosure with `k x k` patches per wall (`n = 6 k^2`, `k >= 1`), each of area `area`,
/// quantized with `codec`.
///
/// # Errors
/// A [`WriteError`] from core's writer (e.g. a bad area).
pub fn uniform_enclosure(k: u32, area: f32, codec: FfCodec) -> Result<Vec<u8>, WriteError> {
    let per_wall = k * k;
    let n = 6 * per_wall;
    let patches: Vec<PatchSpec> = (0..n)
        .map(|i| PatchSpec {
            area,
            material: match i / per_wall {
                0 => 1,
                1 => 2,
                _ => 0,
            },
            base_emission: [0.0; 3],
            base_irradiance: [0.0; 3],
        })
        .collect();
    let members: Vec<MemberSpec> = (0..LIGHT_PATCHES.min(per_wall))
        .map(|m| MemberSpec { patch: 5 * per_wall + m, emission: LIGHT_EMISSION })
        .collect();
    let groups = [GroupSpec { id: LIGHT_ID, default_intensity: [1.0; 3], members: &members }];
    let f = if n > 1 { 1.0 / (n - 1) as f32 } else { 0.0 };
    let mut row_start = vec![0u32];
    let mut receiver = Vec::new();
    for j in 0..n {
        receiver.extend((0..n).filter(|&i| i != j));
        row_start.push(receiver.len() as u32);
    }
    let form_factor = vec![f; receiver.len()];
    let spec = TableSpec {
        patches: &patches,
        materials: &MATERIALS,
        groups: &groups,
        rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: false,
        fingerprint: 0,
        transfer: None,
        state: None,
    };
    let mut blob = vec![0u8; required_len(&spec)?];
    let len = write_table(&spec, &mut blob)?;
    blob.truncate(len);
    Ok(blob)
}

/// The committed test table `firmware-sim/tables/uniform-enclosure.rft`: `k = 4` (96 patches, 9120 entries),
/// patches of 0.01 m^2 (10 x 10 cm), [`FfCodec::FLOAT16`].
///
/// # Errors
/// As [`uniform_enclosure`].
pub fn default_table() -> Result<Vec<u8>, WriteError> {
    uniform_enclosure(4, 0.01, FfCodec::FLOAT16)
}
