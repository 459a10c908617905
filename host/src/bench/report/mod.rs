//! The bench's outputs: `REPORT.md`, `curves.csv` (one row per curve point), `growth.csv`, and per scene three
//! plots (error against work units, model instructions and wall time), each as SVG and PNG.

use crate::files::write_atomic;
use std::fmt::Write as _;
use std::path::Path;

pub use super::fit::loglog_slope;
use super::{BenchError, BenchResults, Curve, CurvePoint, GrowthRow};
use crate::picture::plot::{Plot, Series};

mod conclusions;
mod scene;
mod throughput;

pub use conclusions::conclusions;

/// Columns of `curves.csv`.
pub const CSV_HEADER: &str =
    "scene,method,arith,codec,overshoot,work_units,model_instructions,wall_seconds,rel_l2,max_error,table_bytes";

fn io(path: &Path) -> impl Fn(std::io::Error) -> BenchError + '_ {
    move |source| BenchError::Io { path: path.to_path_buf(), source }
}

/// [`BenchError::Io`] from a failed [`write_atomic`] of `path`.
fn written(path: &Path) -> impl Fn(crate::files::FileError) -> BenchError + '_ {
    move |e| match e {
        crate::files::FileError::Io { source, .. } => BenchError::Io { path: path.to_path_buf(), source },
        other => {
            BenchError::Io { path: path.to_path_buf(), source: std::io::Error::other(other.to_string()) }
        }
    }
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

/// `curves.csv`: one row per curve point.
#[must_use]
pub fn curves_csv(curves: &[Curve]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for c in curves {
        for p in &c.points {
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{:.6e},{:.6e},{:.6e},{}",
                c.scene,
                c.method,
                c.arith_name(),
                c.codec_name(),
                c.overshoot,
                opt(p.work),
                opt(p.instructions.map(|i| format!("{i:.0}"))),
                p.seconds,
                p.rel_l2,
                p.max_rel,
                c.table_bytes
            );
        }
    }
    s
}

fn sci(v: f64) -> String {
    format!("{v:.3e}")
}

fn time(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} us", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

fn reach_cell(p: Option<&CurvePoint>, device: bool) -> String {
    match p {
        None => "-".into(),
        Some(p) if device => format!(
            "{} u / {} / {}",
            p.work.map_or("-".into(), |w| sci(w as f64)),
            p.instructions.map_or("-".into(), sci),
            time(p.seconds)
        ),
        Some(p) => time(p.seconds),
    }
}

/// The x value of a curve point on one plot's axis.
type XValue = fn(&CurvePoint) -> Option<f64>;

fn plots(results: &BenchResults, out: &Path, scene: &str) -> Result<Vec<String>, BenchError> {
    let curves: Vec<&Curve> = results.curves.iter().filter(|c| c.scene == scene).collect();
    let mut files = Vec::new();
    // File key, axis label and x value of each plot; the host's curves have no work units or instructions, so
    // only the wall-time plot shows them.
    let axes: [(&str, &str, XValue); 3] = [
        ("work", "work units", |p| p.work.map(|w| w as f64)),
        ("instructions", "model instructions (Cortex-M4 bound)", |p| p.instructions),
        ("wall", "wall time (s)", |p| Some(p.seconds)),
    ];
    for (key, label, x_of) in axes {
        let series: Vec<Series> = curves
            .iter()
            .map(|c| Series {
                name: c.label(),
                points: c
                    .points
                    .iter()
                    .filter_map(|p| {
                        let x = x_of(p)?;
                        (x > 0.0).then_some((x, p.rel_l2.max(1e-16)))
                    })
                    .collect(),
            })
            .filter(|s| !s.points.is_empty())
            .collect();
        if series.is_empty() {
            continue;
        }
        let plot = Plot::ErrorWork {
            title: format!("{scene}: error against {label}"),
            x_label: label.into(),
            y_label: "relative L2 error".into(),
            series,
        };
        let stem = out.join(format!("{scene}-{key}"));
        plot.write(&stem, 1100, 700)?;
        files.push(format!("{scene}-{key}.svg"));
    }
    Ok(files)
}

/// Writes every output into `out` (created if needed), each file atomically ([`write_atomic`]).
///
/// # Errors
/// If a file cannot be written or a plot cannot be drawn.
pub fn write(results: &BenchResults, out: &Path) -> Result<(), BenchError> {
    std::fs::create_dir_all(out).map_err(io(out))?;
    let csv = out.join("curves.csv");
    write_atomic(&csv, curves_csv(&results.curves).as_bytes()).map_err(written(&csv))?;
    let mut g = String::from(
        "patches,form_factor_seconds,bake_seconds,nonzeros,table_entries,table_bytes,work_to_1pct_shooting_f32_16\n",
    );
    for r in &results.growth {
        let _ = writeln!(g, "{}", growth_cells(r, 4).join(","));
    }
    let growth = out.join("growth.csv");
    write_atomic(&growth, g.as_bytes()).map_err(written(&growth))?;
    let mut plot_files = Vec::new();
    for s in &results.scenes {
        plot_files.push((s.name.clone(), plots(results, out, &s.name)?));
    }
    device_plot(results, out)?;
    let md = markdown(results, &plot_files);
    let path = out.join("REPORT.md");
    write_atomic(&path, md.as_bytes()).map_err(written(&path))?;
    Ok(())
}

/// File of the device-curve plot (flat against hierarchical table) in the output folder.
pub const DEVICE_PLOT: &str = "cornell-box-device-flat-vs-hier";

/// Writes the device curves of the hierarchy section (if any) as [`DEVICE_PLOT`]`.svg`: for each table, its
/// error against its own f64 answer and its mean face error against the continuous reference, against model
/// instructions.
fn device_plot(results: &BenchResults, out: &Path) -> Result<(), BenchError> {
    let device = &results.hierarchy.device;
    if device.is_empty() {
        return Ok(());
    }
    let mut series = Vec::new();
    for c in device {
        let own = c.points.iter().map(|p| (p.instructions, p.own.max(1e-16))).collect();
        let faces = c.points.iter().map(|p| (p.instructions, p.faces.mean.max(1e-16))).collect();
        series.push(Series { name: format!("{}: vs its own f64 answer", c.name), points: own });
        series.push(Series { name: format!("{}: mean face vs continuous", c.name), points: faces });
    }
    series.retain(|s| !s.points.is_empty());
    let plot = Plot::ErrorWork {
        title: "cornell-box device tables, cold lights-on (f32 shooting): error against model instructions"
            .into(),
        x_label: "model instructions (Cortex-M4 bound of each table's build)".into(),
        y_label: "relative error".into(),
        series,
    };
    plot.write(&out.join(DEVICE_PLOT), 1100, 700)?;
    Ok(())
}

fn best<'a>(
    curves: &[&'a Curve],
    level: f64,
    key: impl Fn(&CurvePoint) -> Option<f64>,
) -> Option<(&'a Curve, f64)> {
    curves
        .iter()
        .filter_map(|c| c.reach(level).and_then(&key).map(|v| (*c, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The report's text.
#[must_use]
pub fn markdown(r: &BenchResults, plot_files: &[(String, Vec<String>)]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Benchmark report: speed against error\n");
    let _ = writeln!(
        s,
        "Generated by `radiosity bench{}` ({} repetitions per timed run; wall times are medians) in {:.0} s. \
         Every error is the area-weighted relative L2 error of `B` against the exact f64 answer of the scene's own \
         form-factor matrix (transfer vectors, f64 Gauss-Seidel to relative residual 1e-12), so table \
         sparsification and quantization show up as error floors.\n",
        if r.quick { " --quick" } else { "" },
        r.reps,
        r.total_seconds
    );
    let _ = writeln!(s, "## Machine\n");
    for m in &r.machine {
        let _ = writeln!(s, "- {m}");
    }
    let _ = writeln!(
        s,
        "- Absolute times vary with the machine and its load (this one is shared with other jobs); compare \
         methods within one run, as ratios.\n"
    );
    let _ = writeln!(s, "## Method\n");
    let _ = writeln!(
        s,
        "- Scenes: Cornell box meshed uniformly to about 250, 1,000 and 4,000 patches (edge chosen by bisection); \
         white furnace (closed cube, reflectance overridden to 0.9 and 0.99). Form factors with {} samples per \
         patch and {} rays per pair (fewer than the bake default of 16/16, so the 4,000-patch mesh fits the run; \
         the curves measure the solvers against the exact answer of the same matrix, so estimator noise does not \
         enter them).",
        r.ff_samples, r.ff_rays
    );
    let _ = writeln!(
        s,
        "- Tables: the default bake (sparsification threshold 1e-3), 16-bit (FLOAT16) and 8-bit (FLOAT8) codes."
    );
    let _ = writeln!(
        s,
        "- Device curves: core's `Solver` on the parsed table, cold start, budgets growing geometrically; \
         shooting without and with overshooting (`overshoot = 64`: 1.25x); Gauss-Seidel; Jacobi. Warm relight: \
         converged at the default, then every light group set to (1, 0.2, 0.2) x default (the change's work \
         counts); cold relight: the same setting solved from scratch. Converged = every unshot magnitude below \
         1e-6 of the emitted power, or fixed point's convergence floor where that is higher (core's \
         `convergence_floor`; the solver refuses tolerances below it). Curves stop below 3e-4 error, at a plateau (< 5% better over several \
         checkpoints), or at a work cap. Transfer basis: one point per table, the same bake with the basis \
         stored, relit once (see its section). Shooting with overshooting is the device's default (core's \
         `Config::RECOMMENDED_OVERSHOOT`, from these curves)."
    );
    let _ = writeln!(
        s,
        "- Model instructions = work units x the Cortex-M4 cost model's **bound** per unit from \
         `firmware-sim/COST.md` ({:.2} for f32, {:.2} for fixed point; measured under QEMU on shooting frames). \
         It is the model's upper bound, not a measurement of these runs; sweep units (Gauss-Seidel, Jacobi) are \
         converted with the same per-unit bound, although a sweep unit has no selection work and likely costs less. \
         Transfer-basis units take the transfer relight's own rate from `firmware-sim/COST.md` ({:.1} for f32, \
         {:.1} for fixed point: the largest per unit measured under QEMU on the one-group test table).",
        r.instr_per_unit.f32, r.instr_per_unit.fixed, r.instr_per_unit.transfer_f32, r.instr_per_unit.transfer_fixed
    );
    let _ = writeln!(
        s,
        "- Host references: f64 dense LU (faer, factor + solve, sequential) and f64 Gauss-Seidel stopped at \
         residual tolerances 1e-1 ... 1e-8; no work units (host only), bytes = the f64 matrix they read \
         (dense: n^2 x 8 per distinct channel counted once; CSR: 12 bytes per nonzero).\n"
    );
    let _ = writeln!(s, "Cells of the reach tables: work units / model instructions / wall time to the first checkpoint at or below the level (\"-\": not reached; checkpoints are 1.3x apart).\n");

    for sc in &r.scenes {
        let files = plot_files.iter().find(|(n, _)| *n == sc.name).map(|(_, f)| f.as_slice());
        scene::scene(&mut s, r, sc, files);
    }
    scene::transfer_basis(&mut s, r);
    throughput::bake_throughput(&mut s, r);
    growth(&mut s, r);
    hierarchy(&mut s, r);
    let _ = writeln!(s, "## Conclusions (computed from the numbers above)\n");
    for line in conclusions(r) {
        let _ = writeln!(s, "- {line}");
    }
    s
}

/// The cells of a growth row (`growth.csv` and the report's table), seconds with `digits` decimals.
fn growth_cells(g: &GrowthRow, digits: usize) -> [String; 7] {
    [
        g.patches.to_string(),
        format!("{:.digits$}", g.form_factor_seconds),
        format!("{:.digits$}", g.bake_seconds),
        g.nonzeros.to_string(),
        g.entries.to_string(),
        g.table_bytes.to_string(),
        opt(g.work_to_1pct),
    ]
}

/// The section `## Growth with the patch count`, with the fitted exponents.
fn growth(s: &mut String, r: &BenchResults) {
    let _ = writeln!(s, "## Growth with the patch count (Cornell box)\n");
    let _ = writeln!(s, "| patches | form factors (s) | bake (s) | nonzeros | table entries | table bytes (16-bit) | work to 1% (f32 shooting) |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for g in &r.growth {
        let _ = writeln!(s, "| {} |", growth_cells(g, 2).join(" | "));
    }
    let fit = |f: &dyn Fn(&GrowthRow) -> Option<f64>| {
        loglog_slope(&r.growth.iter().filter_map(|g| f(g).map(|y| (g.patches as f64, y))).collect::<Vec<_>>())
            .map_or("-".into(), |k| format!("{k:.2}"))
    };
    let _ = writeln!(
        s,
        "\nFitted exponents (log-log least squares, `y ~ patches^k`): form factors {}, bake {}, nonzeros {}, \
         table entries {}, table bytes {}, work to 1% {}.\n",
        fit(&|g| Some(g.form_factor_seconds)),
        fit(&|g| Some(g.bake_seconds)),
        fit(&|g| Some(g.nonzeros as f64)),
        fit(&|g| Some(g.entries as f64)),
        fit(&|g| Some(g.table_bytes as f64)),
        fit(&|g| g.work_to_1pct.map(|w| w as f64)),
    );
    let _ = writeln!(s, "Sizes: {}.\n", r.growth_limit_note);
}

/// The section `## Hierarchy against flat`: per-face errors against the continuous reference and costs.
fn hierarchy(s: &mut String, r: &BenchResults) {
    use super::hierarchy::{DENSE_LIMIT, ENTRY_BYTES, LINK_BYTES, SMALL_FACE};
    let h = &r.hierarchy;
    let _ = writeln!(s, "## Hierarchy against flat (Cornell box, judged by the continuous reference)\n");
    for (scene, paths, seconds, se) in &h.references {
        let _ = writeln!(
            s,
            "Continuous reference of `{scene}`: `radiosity reference`'s path tracer, {paths} paths in {seconds:.1} s, \
             largest relative standard error of a face {se:.2e}. Errors are per OBJ face (area-averaged radiosity, \
             worst channel, relative), over the lit faces not smaller than {:.0}% of the largest. \"vs dense\" is \
             the hierarchy against the dense f64 solve of its own leaves (what its links get wrong; up to {DENSE_LIMIT} \
             leaves); \"vs continuous\" adds the mesh's error. Bytes: {LINK_BYTES} per link (two directions, each a \
             32-bit node index and a 16-bit code), {ENTRY_BYTES} per flat entry; the flat rows' seconds include their \
             adaptive meshing passes. \"claimed\" is the hierarchy's propagated error bound, relative; \"peak\" the \
             bench process's peak resident memory during the row (the process's baseline included). \"sender weight \
             W\": brightness refinement that also charges each surface link W times its form factor times the range \
             of its sender's leaves' radiosity (how far the average the link sends can be off; `--method \
             hierarchical` answers of `solve`, `render`, `lightmap` and `export` use W = {}). \"N quadrature \
             points\": the links' form factors integrated with N points per element instead of 16 (those answers \
             use {}).\n",
            100.0 * SMALL_FACE,
            crate::hierarchy::ANSWER_SENDER_WEIGHT,
            crate::hierarchy::ANSWER_SAMPLES_PER_PATCH
        );
    }
    let _ = writeln!(
        s,
        "| method | elements | links / entries | bytes | seconds | peak (MiB) | rays | worst face vs dense | worst face vs continuous (face) | mean face vs continuous | claimed |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for row in &h.rows {
        let dense = row
            .vs_dense
            .map_or("-".to_owned(), |e| format!("{:.2}% (face {})", 100.0 * e.worst, e.worst_face));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.2} | {} | {} | {} | {:.2}% ({}) | {:.2}% | {} |",
            row.method,
            row.elements,
            row.links,
            row.bytes,
            row.seconds,
            mib(row.memory.map(|m| m.peak)),
            row.rays,
            dense,
            100.0 * row.vs_continuous.worst,
            row.vs_continuous.worst_face,
            100.0 * row.vs_continuous.mean,
            row.claimed.map_or("-".to_owned(), |c| format!("{c:.2e}"))
        );
    }
    memory_note(s, h.rows.iter().filter_map(|r| r.memory));
    for (scene, links, time) in &h.exponents {
        let f = |k: &Option<f64>| k.map_or("-".to_owned(), |k| format!("{k:.2}"));
        let _ = writeln!(
            s,
            "\nGrowth over the hierarchical rows of {scene} (log-log least squares against leaves): links {}, \
             seconds {}.",
            f(links),
            f(time)
        );
    }
    for (scene, mean, worst) in &h.discretization {
        let f = |k: &Option<f64>| k.map_or("-".to_owned(), |k| format!("{k:.2}"));
        let _ = writeln!(
            s,
            "\nDiscretization error of the flat rows of `{scene}` against the patch count (log-log least squares, \
             `error ~ patches^k`; 0 would be a bias that refinement does not remove, -0.5 is first order in the \
             patch edge): mean face {}, worst face {}.",
            f(mean),
            f(worst)
        );
    }
    office(s, &r.office);
    link_rate(s, &r.link_rate);
    device_curves(s, &h.device);
    let _ = writeln!(s);
}

/// Megabytes (MiB) of a peak resident set, or `-` where the system did not report it.
fn mib(bytes: Option<u64>) -> String {
    bytes.map_or("-".to_owned(), |b| format!("{:.0}", b as f64 / 1048576.0))
}

/// The sentence saying what the process held when the rows of a table started (their peaks include it).
fn memory_note(s: &mut String, memory: impl Iterator<Item = super::hierarchy::RowMemory>) {
    let starts: Vec<u64> = memory.map(|m| m.start).collect();
    if let (Some(lo), Some(hi)) = (starts.iter().min(), starts.iter().max()) {
        let _ = writeln!(
            s,
            "\nThe peaks include what the process held when each row started: {} to {} MiB.",
            mib(Some(*lo)),
            mib(Some(*hi))
        );
    }
}

/// One row of the office's table.
fn office_row(s: &mut String, row: &super::largescene::OfficeRow) {
    let (r, c) = row.workstations;
    match &row.outcome {
        Ok(x) => {
            let _ = writeln!(
                s,
                "| {r} x {c} | {} | {} | {} | {} | {} | {:.1} | {} | {:.2} | {} | {} | {} | {} | {} | {:.2} |",
                row.triangles,
                row.epsilon,
                x.leaves,
                x.nodes,
                x.links,
                x.links as f64 / x.leaves.max(1) as f64,
                x.bytes,
                x.seconds,
                mib(x.memory.map(|m| m.peak)),
                x.rays,
                x.worst_material().map_or("-".to_owned(), |m| format!("{:+.1}% ({})", 100.0 * m.error, m.name)),
                x.median_material().map_or("-".to_owned(), |e| format!("{:.1}%", 100.0 * e)),
                row.samples,
                x.reference_seconds
            );
        }
        Err(e) => {
            let _ = writeln!(
                s,
                "| {r} x {c} | {} | {} | stopped: {} ||||||||||||",
                row.triangles,
                row.epsilon,
                e.replace('|', "/")
            );
        }
    }
}

/// Every material of a solved office row against its reference, as a sentence.
fn office_materials(s: &mut String, what: &str, row: &super::largescene::OfficeRow) {
    if let Ok(x) = &row.outcome {
        let list: Vec<String> = x
            .materials
            .iter()
            .map(|m| format!("{} {:+.1}% (+/- {:.1}%)", m.name, 100.0 * m.error, 100.0 * m.reference_se))
            .collect();
        let _ = writeln!(
            s,
            "\nEvery material of {what} ({} x {} workstations, epsilon {}), against the reference (+/- its \
             standard error): {}.",
            row.workstations.0,
            row.workstations.1,
            row.epsilon,
            list.join(", ")
        );
    }
}

/// The large generated scene's subsection of the hierarchy section.
fn office(s: &mut String, o: &super::largescene::OfficeSection) {
    use super::hierarchy::LINK_BYTES;
    let _ = writeln!(
        s,
        "\n### A large generated scene: the office\n\n`scenes/make_office.py` with a growing number of workstations \
         (desks, monitors, chairs, books, desk lamps, all of closed boxes standing 2 cm apart; ceiling panels in two \
         light groups and the lamps in a third), solved as `solve --method hierarchical --refinement brightness \
         --epsilon {}` refines without the f64 answers' sender term (the device tables' refinement, as `bake \
         --method hierarchical` refines){}. Bytes: {LINK_BYTES} per link; peak: the bench process's \
         peak resident memory during the solve. Error: each non-emitting material's area-averaged radiosity \
         against the continuous reference of the same scene (`radiosity reference` at the paths per face of the \
         row; the dense solve does not reach these leaf counts), the signed relative difference of its worst \
         channel: the worst material and the median over materials.\n",
        o.epsilon,
        if o.full.is_some() {
            format!(
                "; the last row is the full office of the script's default size, at the coarser epsilon it needs \
                 to solve in this machine's memory (`--max-links {}`), not in the growth fit",
                super::largescene::FULL_OFFICE_MAX_LINKS
            )
        } else {
            String::new()
        }
    );
    let _ = writeln!(
        s,
        "| workstations | triangles | epsilon | leaves | nodes | links | links per leaf | bytes | seconds | peak \
         (MiB) | rays | worst material vs continuous | median material | reference paths per face | reference \
         seconds |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for row in o.rows.iter().chain(&o.full) {
        office_row(s, row);
    }
    memory_note(
        s,
        o.rows.iter().chain(&o.full).filter_map(|r| r.outcome.as_ref().ok().and_then(|x| x.memory)),
    );
    if let Some(row) = o.rows.iter().rfind(|r| r.outcome.is_ok()) {
        office_materials(s, "the largest office of the growth rows", row);
    }
    if let Some(row) = &o.full {
        office_materials(s, "the full office", row);
    }
    let f = |k: Option<f64>| k.map_or("-".to_owned(), |k| format!("{k:.2}"));
    let _ = writeln!(
        s,
        "\nGrowth over the solved office rows at epsilon {} (log-log least squares against leaves): links {}, seconds \
         {}.",
        o.epsilon,
        f(o.links_exponent),
        f(o.seconds_exponent)
    );
}

/// The link-construction subsection: refinement's occlusion rays per second against raw Embree's, with shaft
/// culling and without.
fn link_rate(s: &mut String, l: &super::linkrate::LinkRate) {
    let _ = writeln!(
        s,
        "\n### Link construction against raw Embree\n\nThe Cornell box solved by `solve --method hierarchical \
         --refinement brightness --epsilon {}` ({} leaves, {} links) on 1 and 2 threads: the occlusion rays of \
         link construction (the tree, every pair's estimate and split, every pass; the solves between the passes \
         left out) per second of it, against raw Embree (`occluded_many` in packets of 16) on as many rays of the \
         same kind on the same occluders (segments between random points of the leaves of each leaf-to-leaf link, \
         facing each other, shortened by the scene's offset), in {} interleaved round(s), medians. With shaft \
         culling (the default) a pair that no face polygon can come between casts no ray, so its rays/s counts only \
         the rays cast: compare its seconds with the unculled run's.\n",
        l.epsilon, l.leaves, l.links, l.rounds
    );
    let _ = writeln!(
        s,
        "| shaft culling | threads | refinement: rays | seconds | rays/s | raw Embree: rays | seconds | rays/s | \
         refinement / raw |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for culled in [true, false] {
        let (refine, raw) = l.runs(culled);
        for (r, w) in refine.iter().zip(raw) {
            let rate = |n: f64, t: f64| if t > 0.0 { format!("{:.3e}", n / t) } else { "-".to_owned() };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} | {} | {} | {:.3} | {} | {} |",
                if culled { "on" } else { "off" },
                r.0,
                r.1,
                r.2,
                rate(r.1 as f64, r.2),
                w.1,
                w.2,
                rate(w.1 as f64, w.2),
                l.ratio(culled, r.0).map_or("-".to_owned(), |x| format!("{:.0}%", 100.0 * x))
            );
        }
    }
    let f = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:.2}x"));
    let (refine, raw) = l.scaling(true);
    let (refine_off, raw_off) = l.scaling(false);
    let seconds =
        |culled: bool, threads: usize| l.runs(culled).0.iter().find(|r| r.0 == threads).map(|r| r.2);
    let speedup = seconds(false, 1).zip(seconds(true, 1)).and_then(|(off, on)| (on > 0.0).then(|| off / on));
    let _ = writeln!(
        s,
        "\nScaling 1 -> 2 threads: link construction {} with shaft culling ({} without), raw Embree {} ({}). Shaft \
         culling makes link construction {} faster on 1 thread. Targets: link construction at least 70% of raw \
         Embree's rate, and 1.8x from 1 to 2 threads; the 2 cores are shared with other jobs, so this is what was \
         measured, not what an idle machine gives.",
        f(refine),
        f(refine_off),
        f(raw),
        f(raw_off),
        f(speedup)
    );
}

/// The device-curve subsection of the hierarchy section: what each table is and costs, and its error at
/// each checkpoint.
fn device_curves(s: &mut String, device: &[super::hierdevice::DeviceCurve]) {
    if device.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\n### Device tables: flat against hierarchical (cold lights-on, f32 shooting)\n\nThe `demo`'s two device \
         tables of the Cornell box, each relit by core's f32 solver from a cold start at the default intensities \
         (host simulator, bit-identical to the firmware under QEMU): \"own\" is the area-weighted relative L2 error \
         against the table's own f64 answer (its convergence; \"quantization\" is the part of its converged floor that \
         the 16-bit codes make: the f64 answer of the decoded table against the f64 answer it was rounded from), \"faces\" the per-face error against the continuous \
         reference above (the common yardstick of two different discretizations). Model instructions are \
         the work priced by the bound of the table's firmware build in `firmware-sim/COST.md` (measured under \
         QEMU): per unit for the flat table; for the hierarchical one the rate bound (per link, per node \
         judged, per node swept and per shot, scaled to its calibration frames' envelope) of the same table run \
         on the f32 firmware, `cornell-hier-m4-f32`, applied to the links, nodes judged and swept and shots the \
         solver counts.\n"
    );
    let _ = writeln!(
        s,
        "| table | elements | bytes | build (bound) | instructions to 10% own | to 1% own | last: own | quantization | last: worst face vs continuous (face) | last: mean face |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    let f = |v: Option<f64>| v.map_or("not reached".to_owned(), |v| format!("{v:.3e}"));
    for c in device {
        let last = c.points.last();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} ({}) | {} | {} | {}{} | {:.2e} | {} | {} |",
            c.name,
            c.elements,
            c.bytes,
            c.build,
            c.model,
            f(c.instructions_to(0.1)),
            f(c.instructions_to(0.01)),
            last.map_or("-".to_owned(), |p| format!("{:.2e}", p.own)),
            if c.converged { " (converged)" } else { "" },
            c.quantization,
            last.map_or("-".to_owned(), |p| format!(
                "{:.2}% ({})",
                100.0 * p.faces.worst,
                p.faces.worst_face
            )),
            last.map_or("-".to_owned(), |p| format!("{:.2}%", 100.0 * p.faces.mean)),
        );
    }
    let _ = writeln!(s, "\n![{DEVICE_PLOT}.svg]({DEVICE_PLOT}.svg)\n");
    let _ = writeln!(
        s,
        "| table | units | model instructions | own | worst face vs continuous | mean face vs continuous |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for c in device {
        for p in &c.points {
            let _ = writeln!(
                s,
                "| {} | {} | {:.3e} | {:.2e} | {:.2}% ({}) | {:.2}% |",
                c.name,
                p.units,
                p.instructions,
                p.own,
                100.0 * p.faces.worst,
                p.faces.worst_face,
                100.0 * p.faces.mean
            );
        }
    }
}
