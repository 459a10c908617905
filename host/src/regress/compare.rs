//! Checking a baseline: every selected entry recomputed at the first seed against its limit; and old and new
//! baselines side by side.

use std::path::Path;

use radiosity_core::FfCodec;

use super::{
    measure, noise_multiplier, scene_files, Baseline, Entry, RegressError, RegressReport, Row, CODECS,
    TRACKED,
};

/// What [`check_baseline`] runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CheckSelection {
    /// Only this scene file (e.g. `cornell-box.obj`).
    pub scene: Option<String>,
    /// Only entries of this code width.
    pub bits: Option<u32>,
    /// Bake with this codec in place of the entry's (to degrade it on purpose).
    pub codec: Option<FfCodec>,
}

fn error_row(entry: &Entry, codec: &str, now: Option<String>, ok: bool) -> Row {
    Row {
        scene: entry.scene.clone(),
        bits: entry.bits,
        codec: codec.into(),
        component: format!("rejected: {}", now.unwrap_or_default()),
        metric: "error",
        baseline: None,
        noise: None,
        limit: None,
        value: None,
        new_noise: None,
        ok,
    }
}

/// Recomputes every selected baseline entry at the first seed and compares each tracked component with its
/// limit (see the module docs). Shipped scenes missing from the baseline, and baseline scenes no longer in
/// `scenes`, are problems (the check fails until `radiosity regress --update`).
///
/// # Errors
/// [`RegressError`] if a scene cannot be checked.
pub fn check_baseline(
    baseline: &Baseline,
    scenes: &Path,
    selection: &CheckSelection,
) -> Result<RegressReport, RegressError> {
    let k = noise_multiplier(baseline.seeds).ok_or(RegressError::Seeds(baseline.seeds))?;
    let shipped = scene_files(scenes)?;
    let mut problems = Vec::new();
    if selection.scene.is_none() {
        for name in &shipped {
            for bits in CODECS {
                if !baseline.entries.iter().any(|e| &e.scene == name && e.bits == bits) {
                    problems.push(format!(
                        "{name} ({bits}-bit) is shipped but not in the baseline: run `radiosity regress --update`"
                    ));
                }
            }
        }
    }
    let mut rows = Vec::new();
    for entry in &baseline.entries {
        if selection.scene.as_ref().is_some_and(|s| s != &entry.scene)
            || selection.bits.is_some_and(|b| b != entry.bits)
        {
            continue;
        }
        if !shipped.contains(&entry.scene) {
            problems.push(format!(
                "{} is in the baseline but not in {}: run `radiosity regress --update`",
                entry.scene,
                scenes.display()
            ));
            continue;
        }
        let codec = match selection.codec {
            Some(c) => c.to_string(),
            None => entry.codec.clone(),
        };
        let measured =
            measure(&scenes.join(&entry.scene), &entry.settings, entry.bits, selection.codec, 1, None);
        let (n, values) = match (measured, &entry.error) {
            (Ok(v), None) => v,
            (Err(RegressError::Check { source, .. }), Some(_)) => {
                rows.push(error_row(entry, &codec, Some(source.to_string()), true));
                continue;
            }
            (Ok(_), Some(_)) => {
                problems.push(format!(
                    "{} ({}-bit) was rejected in the baseline and checks now: run `radiosity regress --update`",
                    entry.scene, entry.bits
                ));
                continue;
            }
            (Err(RegressError::Check { source, .. }), None) => {
                rows.push(error_row(entry, &codec, Some(source.to_string()), false));
                continue;
            }
            (Err(e), _) => return Err(e),
        };
        let floor = 8.0 * n as f64 * f64::EPSILON;
        for name in TRACKED {
            let old = entry.components.get(name);
            let new = values.get(name);
            let stats = [("rel_l2", old.map(|s| &s.rel_l2)), ("max_rel", old.map(|s| &s.max_rel))];
            for (i, (metric, stat)) in stats.into_iter().enumerate() {
                let value = new.map(|v| if i == 0 { v.0 } else { v.1 });
                let limit = stat.map(|s| s.mean + k * s.noise + floor);
                let ok = match (value, limit) {
                    (Some(v), Some(l)) => v <= l,
                    (None, None) => true,
                    _ => false,
                };
                rows.push(Row {
                    scene: entry.scene.clone(),
                    bits: entry.bits,
                    codec: codec.clone(),
                    component: name.into(),
                    metric,
                    baseline: stat.map(|s| s.mean),
                    noise: stat.map(|s| s.noise),
                    limit,
                    value,
                    new_noise: None,
                    ok,
                });
            }
        }
    }
    Ok(RegressReport { mode: "check", k, rows, problems })
}

/// Old and new baselines side by side (every value of `new`, with the matching one of `old` if any).
#[must_use]
pub fn compare_baselines(old: Option<&Baseline>, new: &Baseline) -> RegressReport {
    let mut rows = Vec::new();
    for e in &new.entries {
        let o = old.and_then(|b| b.entries.iter().find(|o| o.scene == e.scene && o.bits == e.bits));
        if let Some(err) = &e.error {
            rows.push(error_row(e, &e.codec, Some(err.clone()), true));
        }
        for (name, stats) in &e.components {
            let os = o.and_then(|o| o.components.get(name));
            for (metric, ns, old_stat) in [
                ("rel_l2", &stats.rel_l2, os.map(|s| &s.rel_l2)),
                ("max_rel", &stats.max_rel, os.map(|s| &s.max_rel)),
            ] {
                rows.push(Row {
                    scene: e.scene.clone(),
                    bits: e.bits,
                    codec: e.codec.clone(),
                    component: name.clone(),
                    metric,
                    baseline: old_stat.map(|s| s.mean),
                    noise: old_stat.map(|s| s.noise),
                    limit: None,
                    value: Some(ns.mean),
                    new_noise: Some(ns.noise),
                    ok: true,
                });
            }
        }
    }
    RegressReport { mode: "update", k: new.k, rows, problems: Vec::new() }
}
