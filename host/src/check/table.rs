//! Checking a table already baked against the scene it was baked from (`radiosity check TABLE --scene SCENE`).

use std::path::Path;

use radiosity_core::Table;

use super::device::{device_part, Answers, DeviceTable};
use super::{
    check_options, discretization_part, dynamic_group_names, evaluation_options, exact_transfer_of,
    CheckError, CheckOptions, CheckReport,
};
use super::{max_power, EXACT_FLAT};
use crate::bake::{self, decode_table};
use crate::evaluate;
use crate::pipeline::{prepare, PrepareOptions, Prepared};
use crate::text::counted;

/// Reads the table at `table_path`, prepares the scene at `scene_path` and checks the table against it (see
/// [`check_table`]).
///
/// # Errors
/// [`CheckError::ReadTable`] if the file cannot be read, [`CheckError::BadTable`] if it does not parse, and
/// everything [`check_table`] returns.
pub fn check_table_file(
    table_path: &Path,
    scene_path: &Path,
    prepare_options: &PrepareOptions,
    options: &CheckOptions,
) -> Result<CheckReport, CheckError> {
    check_options(options)?;
    let bytes = std::fs::read(table_path)
        .map_err(|e| CheckError::ReadTable { path: table_path.into(), message: e.to_string() })?;
    // Parse first: a damaged table is reported before the (slower) scene preparation.
    Table::parse(&bytes).map_err(|error| CheckError::BadTable { path: table_path.into(), error })?;
    let p = prepare(scene_path, prepare_options)?;
    check_table(&bytes, &p, options).map_err(|e| match e {
        CheckError::WrongScene { detail, .. } => {
            CheckError::WrongScene { table: table_path.into(), scene: scene_path.into(), detail }
        }
        e => e,
    })
}

/// Checks an existing table (bytes of an `.rft`) against the prepared scene it was baked from.
///
/// The table is first matched with the scene ([`match_scene`]); a table baked from another scene, or with other
/// meshing options, is a [`CheckError::WrongScene`]. The decomposition then has the components that the table
/// alone allows plus one that needs the scene's matrix:
///
/// | component | answer | against |
/// |---|---|---|
/// | discretization (with [`CheckOptions::continuous`]) | as [`super::check`] | |
/// | table vs scene matrix | f64 solve of the decoded table | f64 solve of the scene's matrix (this run's estimate) |
/// | iteration truncation | as [`super::check`] | |
/// | arithmetic (f32, fixed) | as [`super::check`] | |
///
/// The first one holds sparsification, quantization, reciprocity and the difference between the bake's
/// form-factor estimate and this run's (equal when the sample counts and seed match the bake's); separating
/// them needs the bake's unsparsified f64 matrix, which the table does not keep, so for the separate
/// components bake again (`radiosity check SCENE`). [`CheckOptions::bits`], `codec` and `threshold` are the
/// table's own here and ignored; `ff_factor` is not used.
///
/// # Errors
/// [`CheckError::BadTable`] for bytes that do not parse, [`CheckError::WrongScene`] for a table of another
/// scene, and the errors of [`super::check`].
pub fn check_table(bytes: &[u8], p: &Prepared, options: &CheckOptions) -> Result<CheckReport, CheckError> {
    check_options(options)?;
    let table =
        Table::parse(bytes).map_err(|error| CheckError::BadTable { path: "<bytes>".into(), error })?;
    match_scene(&table, p).map_err(|detail| CheckError::WrongScene {
        table: "<table>".into(),
        scene: p.scene.path.clone(),
        detail,
    })?;
    let eval_options = evaluation_options(p, options);
    let (decoded, device, _) = evaluate::device_answer(&table, &eval_options)?;
    let (reference, _) = evaluate::exact(&p.lighting, &p.form_factors, &eval_options)?;
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let discretization = discretization_part(p, &reference, options)?;
    let mut components: Vec<_> = discretization.iter().map(|d| d.component.clone()).collect();
    components.push(evaluate::table_vs_scene(&device, &reference, &area)?);
    let exact = exact_transfer_of(p, &eval_options)?;
    let answers = Answers {
        exact: &exact,
        default_intensity: &p.lighting.default_intensity,
        exact_is: EXACT_FLAT,
        max_power: max_power(&decoded.emission, &decoded.area),
        device: &device,
        area: &area,
        light_groups: &dynamic_group_names(p),
    };
    let report = device_part(DeviceTable::Flat(&table), bytes.len(), &answers, options, components)?;
    Ok(CheckReport { discretization, ..report })
}

/// Whether `table` was baked from the patches of `p`; on a mismatch, the first difference found.
///
/// Compared, in order: patch count, material count, dynamic light group count, every patch's area (the table
/// stores f32, so equal means within `2^-23` relative, twice f32's rounding), every patch's material, every
/// material's reflectance code (the code the writer makes of the scene's `Kd`), every group's id (FNV-1a of
/// its name) and member patches, every patch's static emission (within the emission code's `2^-11`
/// relative rounding, [`radiosity_core::codec`]), and the form factors themselves: more than
/// [`WRONG_SCENE_FRACTION`] of the transported energy on other receivers is another geometry.
///
/// # Errors
/// A sentence naming the first difference, the patch, material or group, and both values.
pub fn match_scene(table: &Table<'_>, p: &Prepared) -> Result<(), String> {
    use radiosity_core::codec::{decode_emission_f32, encode_reflectance};
    let l = &p.lighting;
    let (n_t, n_s) = (table.patch_count() as usize, p.patches.len());
    if n_t != n_s {
        return Err(format!(
            "the table has {n_t} patches, the scene meshes into {n_s} (a different scene, or meshing options \
             other than the bake's: --no-subdivide, --max-patch-edge, --max-patches)"
        ));
    }
    let (m_t, m_s) = (table.material_count() as usize, p.scene.materials.len());
    if m_t != m_s {
        return Err(format!("the table has {}, the scene {m_s}", counted(m_t, "material", "materials")));
    }
    let (g_t, g_s) = (table.group_count() as usize, l.dynamic_groups.len());
    if g_t != g_s {
        return Err(format!(
            "the table has {}, the scene {g_s}",
            counted(g_t, "dynamic light group", "dynamic light groups")
        ));
    }
    for (i, q) in p.patches.iter().enumerate() {
        let a = f64::from(table.area(i as u32).unwrap_or(f32::NAN));
        let within = (a - q.area).abs() <= q.area * f64::from(f32::EPSILON);
        if !within {
            return Err(format!(
                "patch {i} (face {}): area {a} in the table, {} in the scene",
                q.face, q.area
            ));
        }
        let m = table.material(i as u32).map_or(usize::MAX, |m| m as usize);
        if m != q.material {
            return Err(format!(
                "patch {i} (face {}): material {m} in the table, {} (`{}`) in the scene",
                q.face, q.material, p.scene.materials[q.material].name
            ));
        }
        let e_t = table.base_emission(i as u32).unwrap_or([u16::MAX; 3]).map(decode_emission_f32);
        for (c, (&t, s)) in e_t.iter().zip(l.static_emission[i].to_array()).enumerate() {
            let t = f64::from(t);
            let within = (t - s).abs() <= s * 2f64.powi(-11) + 2f64.powi(-41);
            if !within {
                return Err(format!(
                    "patch {i} (face {}): static emission {t} in the table, {s} in the scene (channel {c})",
                    q.face
                ));
            }
        }
    }
    for (k, mat) in p.scene.materials.iter().enumerate() {
        let want = mat.reflectance.as_vec3().to_array().map(encode_reflectance);
        let got = table.reflectance(k as u32).unwrap_or([u16::MAX; 3]);
        if want != got {
            let dec = got.map(|c| f64::from(c) / 65536.0);
            return Err(format!(
                "material {k} (`{}`): reflectance {dec:?} in the table, {:?} in the scene",
                mat.name,
                mat.reflectance.to_array()
            ));
        }
    }
    // Form factors: a table of the same scene differs from this run's matrix by sparsification (at most the
    // fraction `t` of a row dropped, 1e-3 by default, and as much given back to its kept entries), quantization (< 2^-5 of an entry at 8 bits) and the difference
    // between two Monte Carlo estimates (a few percent of a row at the default ray counts); another geometry
    // with the same patch attributes (facing vs perpendicular squares) sends a row's energy to other receivers,
    // which moves about twice the row sum. Half the transported energy separates the two cases by a factor of
    // about ten on either side.
    let fraction = form_factor_distance(table, p);
    if fraction > WRONG_SCENE_FRACTION {
        return Err(format!(
            "the table's form factors differ from the scene's by {:.1}% of the transported energy \
             (area-weighted sum of |F_table - F_scene| over all rows; a table of this scene differs by a few \
             percent at most): same patch counts, areas and materials, but other geometry",
            100.0 * fraction
        ));
    }
    for (g, &sg) in l.dynamic_groups.iter().enumerate() {
        let name = &p.scene.light_groups[sg].name;
        let id = table.group_id(g as u32).unwrap_or(0);
        if id != bake::group_id(name) {
            return Err(format!(
                "dynamic light group {g}: id {id:#010x} in the table, {:#010x} (`{name}`) in the scene",
                bake::group_id(name)
            ));
        }
        let members: Vec<u32> = table
            .group_members(g as u32)
            .unwrap_or(0..0)
            .filter_map(|k| table.member(k).map(|m| m.patch))
            .collect();
        let want: Vec<u32> = (0..n_s).filter(|&i| l.group[i] == Some(g)).map(|i| i as u32).collect();
        if members != want {
            return Err(format!(
                "dynamic light group {g} (`{name}`): {} member patches in the table, {} in the scene",
                members.len(),
                want.len()
            ));
        }
    }
    Ok(())
}

/// The area-weighted distance between the table's decoded form factors and the scene's:
/// `sum_i A_i sum_j |F_table_ij - F_scene_ij| / sum_i A_i s_i` (`s_i` the scene's row sums; rows beyond the
/// shorter of the two are ignored). Only what the table stores is compared: rows and receivers of patches with
/// run-time state (core's crate docs, "Run-time state"). See [`match_scene`].
#[must_use]
pub fn form_factor_distance(table: &Table<'_>, p: &Prepared) -> f64 {
    let dec = decode_table(table);
    let (mut moved, mut total) = (0.0, 0.0);
    for i in 0..p.patches.len().min(dec.rows.n()) {
        if !dec.state[i] {
            continue;
        }
        let stored = |&(j, _): &(usize, f64)| dec.state.get(j) == Some(&true);
        let mut row: std::collections::BTreeMap<usize, f64> =
            p.form_factors.row(i).filter(stored).map(|(j, f)| (j, -f)).collect();
        let scene_sum: f64 = row.values().map(|f| -f).sum();
        for (j, f) in dec.rows.row(i) {
            *row.entry(j).or_insert(0.0) += f;
        }
        moved += p.patches[i].area * row.values().map(|d| d.abs()).sum::<f64>();
        total += p.patches[i].area * scene_sum;
    }
    if total > 0.0 {
        moved / total
    } else {
        0.0
    }
}

/// A table whose form factors differ from the scene's by more than this fraction of the transported energy
/// (area-weighted sum of `|F_table - F_scene|` over `sum_i A_i s_i`) belongs to another scene ([`match_scene`]).
pub const WRONG_SCENE_FRACTION: f64 = 0.5;
