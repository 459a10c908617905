//! The per-scene sections of `REPORT.md` (reach table, best per level, relighting, roofline, plots) and the
//! transfer-basis section that compares the scenes.

use std::fmt::Write as _;

use firmware_sim::sim::Arith;

use super::{best, reach_cell, sci, time};
use crate::bench::{BenchResults, Curve, CurveMethod, SceneResult, LEVELS};

/// The section `## Scene NAME` of `sc`, with its plots (`files`).
pub(super) fn scene(s: &mut String, r: &BenchResults, sc: &SceneResult, files: Option<&[String]>) {
    let curves: Vec<&Curve> = r.curves.iter().filter(|c| c.scene == sc.name).collect();
    let _ = writeln!(s, "## Scene {}\n", sc.name);
    let _ = writeln!(
        s,
        "{} patches, {} nonzero form factors; table entries / bytes: {}; form factors {:.2} s, bake (16-bit) {:.2} s.\n",
        sc.patches,
        sc.nonzeros,
        sc.entries
            .iter()
            .zip(&sc.table_bytes)
            .map(|((b, e), (_, t))| format!("{b}-bit {e} / {t}"))
            .collect::<Vec<_>>()
            .join(", "),
        sc.form_factor_seconds,
        sc.bake_seconds
    );
    let _ = writeln!(s, "| method | bytes | 10% | 1% | 0.1% | lowest error | max error there |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for c in &curves {
        let last = c.points.iter().min_by(|a, b| a.rel_l2.total_cmp(&b.rel_l2));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            c.label(),
            c.table_bytes,
            reach_cell(c.reach(LEVELS[0]), c.is_device()),
            reach_cell(c.reach(LEVELS[1]), c.is_device()),
            reach_cell(c.reach(LEVELS[2]), c.is_device()),
            last.map_or("-".into(), |p| sci(p.rel_l2)),
            last.map_or("-".into(), |p| sci(p.max_rel)),
        );
    }
    if sc.lu_reps == 1 && r.reps > 1 {
        let _ =
            writeln!(s, "\nThe dense LU was timed once here (a factorization of this size takes seconds).");
    }
    let _ = writeln!(
        s,
        "\nBest per level (device: fewest model instructions; overall: least wall time, host included):\n"
    );
    let _ = writeln!(s, "| level | best on the device | instructions | best wall time | time |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    let device: Vec<&Curve> =
        curves.iter().copied().filter(|c| c.is_device() && !c.method.is_relight()).collect();
    let all: Vec<&Curve> = curves.iter().copied().filter(|c| !c.method.is_relight()).collect();
    for level in LEVELS {
        let d = best(&device, level, |p| p.instructions);
        let w = best(&all, level, |p| Some(p.seconds));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            level,
            d.map_or("none reached it".into(), |(c, _)| c.label()),
            d.map_or("-".into(), |(_, v)| sci(v)),
            w.map_or("none reached it".into(), |(c, _)| c.label()),
            w.map_or("-".into(), |(_, v)| time(v)),
        );
    }
    let warm = curves.iter().find(|c| c.method == CurveMethod::WarmRelight);
    let cold = curves.iter().find(|c| c.method == CurveMethod::ColdRelight);
    if let (Some(w), Some(c)) = (warm, cold) {
        let _ = writeln!(s, "\nRelighting after the light change (f32 shooting, 16-bit): work units to each level, warm vs cold:\n");
        for level in LEVELS {
            let ww = w.reach(level).and_then(|p| p.work);
            let cw = c.reach(level).and_then(|p| p.work);
            let _ = writeln!(
                s,
                "- {level}: warm {} units, cold {} units{}",
                ww.map_or("(not reached)".into(), |w| w.to_string()),
                cw.map_or("(not reached)".into(), |w| w.to_string()),
                match (ww, cw) {
                    (Some(a), Some(b)) if a > 0 => format!(" (cold / warm = {:.2})", b as f64 / a as f64),
                    _ => String::new(),
                }
            );
        }
    }
    let rounds = sc.roofline.first().map_or(0, |(_, rf)| rf.rounds);
    let _ = writeln!(s, "\nRoofline (f32): entries per second of a straight streaming pass (decode + multiply-add, no selection) over the same table, against core's Gauss-Seidel and shooting. {rounds} rounds, each timing the three loops one after the other over at least 2e7 entries each; rates are medians over the rounds, ratios the medians of each round's own ratios (the machine's speed drifts between rounds, not within one):\n");
    let _ = writeln!(s, "| codec | entries | stream (M/s) | Gauss-Seidel (M/s) | shooting (M/s) | shooting / stream | GS / stream | shooting units per entry |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for (bits, rf) in &sc.roofline {
        let _ = writeln!(
            s,
            "| {bits}-bit | {} | {:.1} | {:.1} | {:.1} | {:.0}% | {:.0}% | {:.2} |",
            rf.entries,
            rf.stream_entries_per_s / 1e6,
            rf.gauss_seidel_entries_per_s / 1e6,
            rf.shooting_entries_per_s / 1e6,
            100.0 * rf.shooting_fraction(),
            100.0 * rf.gauss_seidel_over_stream,
            rf.shooting_units as f64 / rf.shooting_entries.max(1) as f64
        );
    }
    if let Some((bits, rf)) = sc.roofline.iter().find(|(_, rf)| rf.shooting_fraction() < 0.7) {
        // Time per entry, split by difference: the stream's decode and multiply-add; what Gauss-Seidel
        // adds (reflectance decode, two more buffers); what shooting adds on top (selection, per-shot work).
        let ns = |per_s: f64| 1e9 / per_s;
        let (stream, gs, shoot) =
            (ns(rf.stream_entries_per_s), ns(rf.gauss_seidel_entries_per_s), ns(rf.shooting_entries_per_s));
        let share = |x: f64| 100.0 * x.max(0.0) / shoot;
        let _ = writeln!(
            s,
            "\nShooting is below the 70% target ({bits}-bit: {:.0}%). Where its {shoot:.1} ns per entry go, by \
             difference between the three loops: {stream:.1} ns ({:.0}%) the stream's decode and \
             multiply-add; {:.1} ns ({:.0}%) what Gauss-Seidel adds per entry without any selection \
             (reflectance decode, the incident and power buffers besides unshot power); {:.1} ns ({:.0}%) what \
             shooting adds on top, not separated here: its selection (the receiver's magnitude compared with \
             its block's winner per entry, {:.2} work units per entry in all), per-shot work (a scan of the \
             block winners and a rescan of the shooter's block, {:.0} entries per shot here), and the order \
             of its reads (rows in selection order, each shot a new stream through the table, where the \
             stream and Gauss-Seidel read it front to back).",
            100.0 * rf.shooting_fraction(),
            share(stream),
            (gs - stream).max(0.0),
            share(gs - stream),
            (shoot - gs).max(0.0),
            share(shoot - gs),
            rf.shooting_units as f64 / rf.shooting_entries.max(1) as f64,
            rf.shooting_entries as f64 / rf.shots.max(1) as f64,
        );
    }
    if let Some(files) = files {
        let _ = writeln!(s);
        for f in files {
            let _ = writeln!(s, "![{f}]({f})");
        }
    }
    let _ = writeln!(s);
}

/// The section `## Transfer basis`: per scene and codec, the basis against the cheapest iteration to its error.
pub(super) fn transfer_basis(s: &mut String, r: &BenchResults) {
    let _ = writeln!(s, "## Transfer basis\n");
    let _ = writeln!(
        s,
        "The precomputed transfer basis: the same bake with the quantized response vectors `T_g` of the dynamic \
         light groups stored in the table (16-bit codes), relit once at the default intensities by core's \
         `relight_transfer` as `B = B_static + sum_g I_g T_g` (work `patches x (groups + 1)` units, no iteration; \
         its error is the quantization of the basis and of the form factors it was solved from). Beside it, the \
         cheapest iterative method on the same scene to the same error (or to 0.1% if the basis is below that). \
         The basis only holds while reflectances stay as baked; with many groups its size and cost grow with the \
         group count, while shooting's do not.\n"
    );
    let _ = writeln!(
        s,
        "| scene | codec | table bytes with basis | without | basis: units | instructions | wall | error | best \
         iterative to that error | its instructions |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for sc in &r.scenes {
        for t in r.curves.iter().filter(|c| {
            c.scene == sc.name && c.method == CurveMethod::TransferBasis && c.arith == Some(Arith::F32)
        }) {
            let Some(tp) = t.points.first() else { continue };
            let level = tp.rel_l2.max(1e-3);
            let without = t.bits.map_or(0, |b| sc.bytes_at(b));
            let iterative: Vec<&Curve> = r
                .curves
                .iter()
                .filter(|c| c.scene == sc.name && c.bits == t.bits && c.method.is_cold_iteration())
                .collect();
            let (name, instr) = match best(&iterative, level, |p| p.instructions) {
                Some((c, v)) => (c.label(), format!("{v:.3e}")),
                None => ("none reached it".into(), "-".into()),
            };
            let _ = writeln!(
                s,
                "| {} | {}-bit | {} | {} | {} | {} | {} | {} | {name} (to {}) | {instr} |",
                sc.name,
                t.codec_name(),
                t.table_bytes,
                without,
                tp.work.unwrap_or(0),
                tp.instructions.map_or("-".into(), |v| format!("{v:.3e}")),
                time(tp.seconds),
                sci(tp.rel_l2),
                sci(level)
            );
        }
    }
    let _ = writeln!(s);
}
