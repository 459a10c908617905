//! What the fuzz targets share: one exercise of a blob (parse, every accessor, bounded solver steps, relight),
//! the CRC rewrite that lets mutated tables past the CRC check, and the key the `tally` tool counts errors by.

use radiosity_core::crc::crc32;
use radiosity_core::{
    relight_transfer, Config, Fixed, HierOwnedBuffers, HierSolver, HierTable, OwnedBuffers, Scalar, Solver,
    Table, TableError,
};

/// `data` with its last four bytes replaced by the CRC-32 of the rest (unchanged if shorter than four bytes):
/// a mutation then reaches the checks behind the CRC instead of stopping at it.
#[must_use]
pub fn with_crc(data: &[u8]) -> Vec<u8> {
    let mut out = data.to_vec();
    if let Some(n) = out.len().checked_sub(4) {
        let c = crc32(&out[..n]);
        out[n..].copy_from_slice(&c.to_le_bytes());
    }
    out
}

/// `Table::parse` on `data` must return (never panic); on an accepted table every accessor, a few bounded
/// solver steps (each within its budget), the relighting calls and the transfer relight must not panic either.
/// Returns the parse result's error, if any.
pub fn exercise(data: &[u8]) -> Option<TableError> {
    let t = match Table::parse(data) {
        Ok(t) => t,
        Err(TableError::HierarchicalTable) => return exercise_hier(data),
        Err(e) => return Some(e),
    };
    let n = t.patch_count();
    // Keep memory bounded for huge (but valid) headers: only exercise small tables fully.
    if n > 4096 || t.entry_count() > 1 << 20 {
        return None;
    }
    for i in 0..=n {
        let _ = (t.area(i), t.material(i), t.base_emission(i), t.base_irradiance(i), t.row_sum(i));
        let _ = (t.slot_of(i), t.slot_patch(i), t.slot_material(i));
    }
    for g in 0..=t.group_count() {
        let _ = (t.group_id(g), t.default_intensity(g), t.group_members(g), t.transfer_exponent(g));
        let _ = (t.transfer_code(0, g), t.transfer_response(n, g));
    }
    let _ = (t.fingerprint(), t.section_sizes());
    if u64::from(n) * u64::from(t.group_count()) <= 1 << 20 {
        let ones = vec![[1.0f32; 3]; t.group_count() as usize];
        let mut out = vec![[0.0f32; 3]; n as usize];
        let _ = relight_transfer(&t, &ones, &mut out);
        let ones = vec![[Fixed(1 << 32); 3]; t.group_count() as usize];
        let mut out = vec![[Fixed(0); 3]; n as usize];
        let _ = relight_transfer(&t, &ones, &mut out);
    }
    solve::<f32>(&t);
    solve::<Fixed>(&t);
    None
}

/// [`exercise`] for a hierarchical table (format version 5): `HierTable::parse`, every accessor, bounded
/// hierarchical shooting steps and relighting.
pub fn exercise_hier(data: &[u8]) -> Option<TableError> {
    let t = match HierTable::parse(data) {
        Ok(t) => t,
        Err(e) => return Some(e),
    };
    if t.node_count() > 4096 || t.link_count() > 1 << 20 {
        return None;
    }
    for k in 0..=t.node_count() {
        let _ = (t.parent(k), t.subtree_end(k), t.leaf_range(k), t.node_area(k), t.run_sum(k), t.run_view(k));
    }
    for l in 0..=t.leaf_count() {
        let _ = (t.leaf_node(l), t.leaf_area(l), t.material(l), t.base_emission(l), t.base_irradiance(l));
    }
    solve_hier::<f32>(&t);
    solve_hier::<Fixed>(&t);
    None
}

fn solve_hier<S: Scalar>(t: &HierTable<'_>) {
    let tolerance = S::from_f32(1e-3);
    let mut store = HierOwnedBuffers::<S>::for_table(t);
    let Ok(mut s) = HierSolver::new(t, store.buffers(), Config { tolerance, overshoot: 0 }) else { return };
    for _ in 0..4 {
        let o = s.step(1000);
        assert!(o.used() <= 1000, "hierarchical shooting exceeded its budget: {o:?}");
    }
    let _ = s.set_light(0, [0.0; 3]);
    let _ = s.set_reflectance(0, [0.5; 3]);
    let o = s.step(1000);
    assert!(o.used() <= 1000, "hierarchical shooting exceeded its budget: {o:?}");
    for l in 0..=t.leaf_count() {
        let _ = (s.radiosity(l), s.power(l), s.unshot(l));
    }
}

/// Bounded shooting and Gauss-Seidel steps on `t` in arithmetic `S` (tolerance `1e-3`), relighting between.
fn solve<S: Scalar>(t: &Table<'_>) {
    let tolerance = S::from_f32(1e-3);
    let mut store = OwnedBuffers::<S>::for_table(t);
    let Ok(mut s) = Solver::new(t, store.buffers(), Config { tolerance, overshoot: 16 }) else { return };
    for _ in 0..4 {
        let o = s.step(1000);
        assert!(o.used() <= 1000, "shooting exceeded its budget: {o:?}");
    }
    let _ = s.set_light(0, [0.0; 3]);
    let _ = s.set_reflectance(0, [0.5; 3]);
    let o = s.step_gauss_seidel(1000);
    assert!(o.used() <= 1000, "Gauss-Seidel exceeded its budget: {o:?}");
    for i in 0..=t.patch_count() {
        let _ = (s.radiosity(i), s.power(i), s.unshot(i));
    }
}

/// The error's kind, refined by the array or parameter it names (`IndexOutOfRange(EntryReceiver)`).
#[must_use]
pub fn key(e: &TableError) -> String {
    match e {
        TableError::BadQuantParams { param, .. } => format!("{}({param:?})", e.kind()),
        TableError::NonMonotoneOffsets { array, .. } => format!("{}({array:?})", e.kind()),
        TableError::IndexOutOfRange { array, .. } => format!("{}({array:?})", e.kind()),
        _ => e.kind().to_owned(),
    }
}
