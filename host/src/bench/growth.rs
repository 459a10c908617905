//! The growth series (Cornell box): form-factor and bake time, nonzeros, table size and the work of f32
//! shooting to 1% error, at the bench's Cornell sizes and at sizes in between that run these measurements only.

use firmware_sim::sim::Arith;

use super::scenes::{run_scene, SceneSpec};
use super::{log, BenchError, BenchOptions, Curve, DeviceRun, GrowthRow, InstructionsPerUnit, SceneResult};
use crate::formfactor::FormFactorOptions;

/// The codec the series measures.
const BITS: u32 = 16;

/// The growth series: the Cornell scenes already run (`scenes`, `curves`) plus the extra sizes (shooting f32
/// 16-bit to 1% only), sorted by patch count.
///
/// # Errors
/// If an extra size fails to run.
pub(super) fn series(
    options: &BenchOptions,
    ff: &FormFactorOptions,
    instr: InstructionsPerUnit,
    scenes: &[SceneResult],
    curves: &[Curve],
) -> Result<Vec<GrowthRow>, BenchError> {
    let extra: &[usize] = if options.quick { &[50] } else { &[500, 2000, 8000, 16000] };
    let mut rows: Vec<(SceneResult, Vec<Curve>)> = scenes
        .iter()
        .filter(|s| s.name.starts_with("cornell"))
        .map(|s| (s.clone(), curves.iter().filter(|c| c.scene == s.name).cloned().collect()))
        .collect();
    for &target in extra {
        let spec = SceneSpec::cornell(target);
        log(options, &format!("growth: {}", spec.name));
        rows.push(run_scene(options, &spec, ff, instr, true)?);
    }
    let mut growth: Vec<GrowthRow> = rows.iter().map(|(s, c)| row(s, c)).collect();
    growth.sort_by_key(|g| g.patches);
    Ok(growth)
}

/// The row of one scene, from its result and its curves.
fn row(s: &SceneResult, curves: &[Curve]) -> GrowthRow {
    let shoot = curves.iter().find(|c| c.is(DeviceRun::shooting(Arith::F32, BITS, false)));
    GrowthRow {
        patches: s.patches,
        form_factor_seconds: s.form_factor_seconds,
        bake_seconds: s.bake_seconds,
        nonzeros: s.nonzeros,
        entries: s.entries_at(BITS),
        table_bytes: s.bytes_at(BITS),
        work_to_1pct: shoot.and_then(|c| c.reach(0.01)).and_then(|p| p.work),
    }
}

/// What the series covers, for the report.
pub(super) fn note(quick: bool) -> String {
    if quick {
        "quick mode: small sizes only".into()
    } else {
        "the sizes above 4,000 patches (about 8,000 and 16,000) run the growth measurements only: form \
         factors, bake, and f32 shooting (16-bit, no overshoot) to 1% error"
            .into()
    }
}
