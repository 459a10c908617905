//! The report's conclusions: findings stated from the measured numbers (no hand-written claims).

use firmware_sim::sim::Arith;

use super::{best, sci};
use crate::bench::{BenchResults, Curve, CurveMethod, DeviceRun, LEVELS};

/// Model instructions of the device curve `run` on `scene` to `level` error.
fn work_to(curves: &[Curve], scene: &str, run: DeviceRun, level: f64) -> Option<f64> {
    curves
        .iter()
        .find(|c| c.scene == scene && c.is(run))
        .and_then(|c| c.reach(level))
        .and_then(|p| p.instructions)
}

/// Findings stated from the measured numbers (no hand-written claims).
#[must_use]
pub fn conclusions(r: &BenchResults) -> Vec<String> {
    let mut out = Vec::new();
    let scenes: Vec<&str> = r.scenes.iter().map(|s| s.name.as_str()).collect();
    // Cheapest device method per level, counted over scenes.
    for level in LEVELS {
        let mut wins: Vec<(String, usize)> = Vec::new();
        for sc in &scenes {
            let device: Vec<&Curve> =
                r.curves.iter().filter(|c| c.scene == *sc && c.method.is_cold_iteration()).collect();
            if let Some((c, _)) = best(&device, level, |p| p.instructions) {
                match wins.iter_mut().find(|w| w.0 == c.label()) {
                    Some(w) => w.1 += 1,
                    None => wins.push((c.label(), 1)),
                }
            }
        }
        wins.sort_by_key(|w| std::cmp::Reverse(w.1));
        out.push(format!(
            "Fewest model instructions to {level} error, iterating from a cold start (the transfer basis is compared below): {} (scenes won, of {}).",
            if wins.is_empty() {
                "no device method reached it".into()
            } else {
                wins.iter().map(|(l, n)| format!("{l} ({n})")).collect::<Vec<_>>().join(", ")
            },
            scenes.len()
        ));
    }
    // Codec: floors and bytes.
    for sc in &r.scenes {
        let floor = |bits: u32| {
            r.curves
                .iter()
                .filter(|c| {
                    c.scene == sc.name
                        && c.bits == Some(bits)
                        && c.arith == Some(Arith::F32)
                        && c.method == CurveMethod::Shooting
                })
                .map(Curve::floor)
                .fold(f64::INFINITY, f64::min)
        };
        out.push(format!(
            "{}: 8-bit table {} bytes vs 16-bit {} ({:.0}%); lowest f32 shooting error 8-bit {} vs 16-bit {}.",
            sc.name,
            sc.bytes_at(8),
            sc.bytes_at(16),
            100.0 * sc.bytes_at(8) as f64 / sc.bytes_at(16).max(1) as f64,
            sci(floor(8)),
            sci(floor(16))
        ));
    }
    // Overshoot, fixed vs f32, Gauss-Seidel vs shooting at 1%.
    for sc in &scenes {
        let to_1pct = |run: DeviceRun| work_to(&r.curves, sc, run, 0.01);
        let plain = to_1pct(DeviceRun::shooting(Arith::F32, 16, false));
        let over = to_1pct(DeviceRun::shooting(Arith::F32, 16, true));
        let fixed = to_1pct(DeviceRun::shooting(Arith::Fixed, 16, false));
        let gs = to_1pct(DeviceRun::new(CurveMethod::GaussSeidel, Arith::F32, 16));
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.2}", a / b),
            _ => "n/a".into(),
        };
        out.push(format!(
            "{sc}, to 1% (16-bit): overshooting / plain shooting instructions = {}; fixed / f32 = {}; Gauss-Seidel / shooting = {}.",
            ratio(over, plain),
            ratio(fixed, plain),
            ratio(gs, plain)
        ));
    }
    // Transfer basis against iterating (16-bit, f32): one relight's work and error, against the shooting work
    // to reach the same error, and the table bytes each needs.
    for sc in &r.scenes {
        let basis = DeviceRun::new(CurveMethod::TransferBasis, Arith::F32, 16);
        let Some(t) = r.curves.iter().find(|c| c.scene == sc.name && c.is(basis)) else {
            continue;
        };
        let Some(tp) = t.points.first() else { continue };
        let shoot =
            work_to(&r.curves, &sc.name, DeviceRun::shooting(Arith::F32, 16, true), tp.rel_l2.max(1e-3));
        let bytes16 = sc.bytes_at(16);
        out.push(format!(
            "{}: transfer basis (f32, 16-bit) relights in {} model instructions to error {} with a {} byte table ({:.0}% of \
             the shooting table); shooting +overshoot needs {} instructions to reach {}. Use the basis when \
             reflectances are fixed and groups are few; shooting otherwise.",
            sc.name,
            tp.instructions.map_or("n/a".into(), |w| format!("{w:.0}")),
            sci(tp.rel_l2),
            t.table_bytes,
            100.0 * t.table_bytes as f64 / bytes16.max(1) as f64,
            shoot.map_or("more than the run's".into(), |w| format!("{w:.0}")),
            sci(tp.rel_l2.max(1e-3))
        ));
    }
    out.extend(hierarchy_findings(&r.hierarchy));
    // Roofline.
    let fr: Vec<String> = r
        .scenes
        .iter()
        .flat_map(|sc| {
            sc.roofline
                .iter()
                .map(move |(b, rf)| format!("{} {b}-bit {:.0}%", sc.name, 100.0 * rf.shooting_fraction()))
        })
        .collect();
    out.push(format!(
        "Shooting's entries/s as a fraction of the streaming pass (target >= 70%): {}.",
        fr.join(", ")
    ));
    out
}

/// Per scene of the hierarchy section and per level of the worst face's error against the continuous reference
/// (2% and 1%, the target): the fastest hierarchical row and the fastest flat row that reach it, or the
/// closest each came.
fn hierarchy_findings(h: &crate::bench::hierarchy::HierarchySection) -> Vec<String> {
    use crate::bench::hierarchy::HierarchyRow;
    let mut out = Vec::new();
    let mut scenes: Vec<&str> = h.rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for scene in scenes {
        let se = h.references.iter().find(|r| r.0 == scene).map(|r| r.3);
        for level in [0.02, 0.01] {
            let describe = |hierarchical: bool| -> String {
                let rows: Vec<&HierarchyRow> = h
                    .rows
                    .iter()
                    .filter(|r| r.scene == scene && r.epsilon.is_some() == hierarchical)
                    .collect();
                let fastest = rows
                    .iter()
                    .filter(|r| r.vs_continuous.worst <= level)
                    .min_by(|a, b| a.seconds.total_cmp(&b.seconds));
                let closest =
                    rows.iter().min_by(|a, b| a.vs_continuous.worst.total_cmp(&b.vs_continuous.worst));
                match (fastest, closest) {
                    (Some(r), _) => {
                        format!("{} in {:.2} s ({:.2}%)", r.method, r.seconds, 100.0 * r.vs_continuous.worst)
                    }
                    (None, Some(r)) => format!(
                        "none (closest: {} at {:.2}% in {:.2} s)",
                        r.method,
                        100.0 * r.vs_continuous.worst,
                        r.seconds
                    ),
                    (None, None) => "no rows".into(),
                }
            };
            out.push(format!(
                "{scene}, every judged face within {:.0}% of the continuous reference{}: fastest hierarchical row {}; \
                 fastest flat row {}.",
                100.0 * level,
                se.map_or(String::new(), |se| format!(" (its largest standard error {})", sci(se))),
                describe(true),
                describe(false)
            ));
        }
    }
    out
}
