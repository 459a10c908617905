//! `radiosity bench --quick` produces a well-formed report: every section, the CSV columns, finite numbers, and
//! errors that fall as work grows. No wall-clock number is asserted (only that times are finite and >= 0).

use std::path::PathBuf;

use firmware_sim::sim::Arith;
use radiosity_host::bench::{report::CSV_HEADER, run, BenchOptions, DeviceRun};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn quick_bench_writes_a_well_formed_report() {
    let out = temp_dir("bench-quick");
    let results = run(&BenchOptions::new(true, out.clone())).expect("quick bench runs");

    // REPORT.md has every section.
    let md = std::fs::read_to_string(out.join("REPORT.md")).expect("REPORT.md written");
    for section in [
        "## Machine",
        "## Method",
        "## Scene cornell-100",
        "## Scene furnace-rho90",
        "Roofline (f32)",
        "## Transfer basis",
        "## Bake throughput",
        "## Growth with the patch count",
        "## Hierarchy against flat",
        "Fitted exponents",
        "## Conclusions",
    ] {
        assert!(md.contains(section), "REPORT.md lacks {section:?}");
    }
    assert!(!md.contains("NaN") && !md.contains("inf"), "REPORT.md has a non-finite number:\n{md}");

    // curves.csv: the header, and every row has all columns with finite numbers where numbers belong.
    let csv = std::fs::read_to_string(out.join("curves.csv")).expect("curves.csv written");
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(CSV_HEADER));
    let columns = CSV_HEADER.split(',').count();
    let mut rows = 0;
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), columns, "row {line:?}");
        for (k, cell) in cells.iter().enumerate().skip(5) {
            // work units and model instructions are empty for the host's f64 methods.
            if cell.is_empty() && (k == 5 || k == 6) && cells[2] == "f64" {
                continue;
            }
            let v: f64 = cell.parse().unwrap_or_else(|_| panic!("column {k} of {line:?} is not a number"));
            assert!(v.is_finite() && v >= 0.0, "column {k} of {line:?}");
        }
        rows += 1;
    }
    assert!(rows > 0);
    for scene in ["cornell-100", "furnace-rho90"] {
        for key in ["work", "instructions", "wall"] {
            assert!(out.join(format!("{scene}-{key}.svg")).exists(), "{scene}-{key}.svg");
            assert!(out.join(format!("{scene}-{key}.png")).exists(), "{scene}-{key}.png");
        }
    }

    // Every device curve: work strictly increasing; the error after the last checkpoint is below the first
    // one's (a solver from a cold start gains accuracy with work), and f32 shooting on the 16-bit table reaches
    // 10% error on every scene (the table's quantization floor is far below: relative 2^-12 per form factor).
    for c in results.curves.iter().filter(|c| c.is_device()) {
        let works: Vec<u64> = c.points.iter().filter_map(|p| p.work).collect();
        assert_eq!(works.len(), c.points.len(), "{}", c.label());
        assert!(works.windows(2).all(|w| w[0] < w[1]), "{}: work not increasing {works:?}", c.label());
        let (first, last) = (c.points.first().unwrap(), c.points.last().unwrap());
        if c.points.len() > 1 {
            assert!(last.rel_l2 < first.rel_l2, "{}: error {} -> {}", c.label(), first.rel_l2, last.rel_l2);
        }
    }
    for s in &results.scenes {
        let shoot = results
            .curves
            .iter()
            .find(|c| c.scene == s.name && c.is(DeviceRun::shooting(Arith::F32, 16, false)))
            .expect("f32 shooting curve");
        assert!(shoot.reach(0.1).is_some(), "{}: f32 shooting never reached 10%", s.name);
        for (_, r) in &s.roofline {
            assert!(r.shooting_entries > 0 && r.shooting_entries_per_s.is_finite());
            assert!(r.rounds >= 1 && r.shooting_over_stream > 0.0 && r.shooting_over_stream.is_finite());
        }
    }
    // The hierarchy section: a hierarchical and a flat row, each judged by the continuous reference; the
    // hierarchical one (few leaves) also by the dense solve of its leaves.
    let h = &results.hierarchy;
    assert!(h.rows.iter().any(|r| r.epsilon.is_some()) && h.rows.iter().any(|r| r.epsilon.is_none()));
    for r in &h.rows {
        assert!(r.elements > 0 && r.links > 0 && r.seconds.is_finite(), "{r:?}");
        assert!(r.vs_continuous.worst.is_finite() && r.vs_continuous.mean <= r.vs_continuous.worst, "{r:?}");
        if r.epsilon.is_some() {
            assert!(r.vs_dense.is_some_and(|e| e.worst.is_finite()), "{r:?}");
        }
    }
    // The large generated scene: the office's smallest size, solved, with its costs.
    assert!(md.contains("### A large generated scene: the office"));
    assert_eq!(results.office.rows.len(), 1, "{:?}", results.office.rows);
    let office = &results.office.rows[0];
    let solved = office.outcome.as_ref().expect("the 1 x 1 office solves");
    assert!(office.triangles > 300 && solved.leaves >= office.triangles && solved.links > 0, "{office:?}");
    assert!(solved.nodes > solved.leaves, "{office:?}");
    // Every non-emitting material of the office (the generator's MTL less its three emitters) against the
    // continuous reference, each with that reference's own standard error.
    let names: Vec<&str> = solved.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names.len(), 13, "{names:?}");
    for name in ["floor", "wall", "ceiling", "desk", "metal", "book3", "panel"] {
        assert!(names.contains(&name), "{name} missing from {names:?}");
    }
    assert!(!names.iter().any(|n| ["lamp", "panel_a", "panel_b"].contains(n)), "{names:?}");
    assert!(
        solved
            .materials
            .iter()
            .all(|m| m.error.is_finite() && m.reference_se > 0.0 && m.reference_se.is_finite()),
        "{:?}",
        solved.materials
    );
    assert!(md.contains(
        "Every material of the largest office of the growth rows (1 x 1 workstations, epsilon 0.5)"
    ));
    // The full office is for the full run only.
    assert!(results.office.full.is_none());
    // Every solve of both tables reports the process's memory during it: a peak at least what it started from.
    let memory = h.rows.iter().map(|r| r.memory).chain([solved.memory]);
    for m in memory {
        assert!(m.is_some_and(|m| m.start > 0 && m.peak >= m.start), "{m:?}");
    }
    assert!(md.contains("| peak (MiB) |") && md.contains("The peaks include what the process held"));
    // Link construction against raw Embree, with shaft culling and without: both thread counts, as many raw rays
    // as refinement cast, rates > 0; culling casts fewer rays (the blocks leave most pairs' shafts clear).
    let rate = &results.link_rate;
    assert!(md.contains("### Link construction against raw Embree"));
    for culled in [true, false] {
        let (refine, raw) = rate.runs(culled);
        assert_eq!(refine.iter().map(|r| r.0).collect::<Vec<_>>(), [1, 2], "{rate:?}");
        for (r, w) in refine.iter().zip(raw) {
            assert!(r.1 > 0 && w.1 as u64 == r.1 && r.2 > 0.0 && w.2 > 0.0, "{rate:?}");
        }
        assert!(rate.ratio(culled, 1).is_some_and(|x| x > 0.0) && rate.links > 0, "{rate:?}");
    }
    assert!(rate.refine[0].1 < rate.unculled.0[0].1, "{rate:?}");
    // Two flat rows at different budgets give the discretization slope (a finite number, reported).
    assert_eq!(h.rows.iter().filter(|r| r.epsilon.is_none()).count(), 2);
    assert!(
        h.discretization.len() == 1 && h.discretization[0].1.is_some_and(f64::is_finite),
        "{:?}",
        h.discretization
    );
    assert!(md.contains("Discretization error of the flat rows"));
    // Both refinements have a row.
    for label in ["hierarchical, budgets", "hierarchical, brightness"] {
        assert!(h.rows.iter().any(|r| r.method.starts_with(label)), "no {label} row");
    }
    // The device curves: the flat and the hierarchical table, each from a cold start to convergence, work
    // strictly increasing, instructions = the build's bound applied to the work (per unit; per link, per node
    // judged, per node swept and per shot for the hierarchical table, with its kinds counted and never more than
    // the units), and the converged error against the table's own answer within 1% (the 16-bit codes' floor is
    // about 2^-12 per form factor and 2^-11 per emission code, far below; the flat table's own answer is the
    // scene matrix's, so its sparsification enters).
    assert_eq!(h.device.len(), 2, "{:?}", h.device.iter().map(|c| &c.name).collect::<Vec<_>>());
    for c in &h.device {
        assert!(
            c.converged && c.points.len() > 1,
            "{}: {} points, converged {}",
            c.name,
            c.points.len(),
            c.converged
        );
        assert!(c.points.windows(2).all(|w| w[0].units < w[1].units), "{}: units not increasing", c.name);
        for p in &c.points {
            assert!(
                (p.instructions - c.model.instructions(p.units, p.work)).abs() <= 1e-9 * p.instructions,
                "{}",
                c.name
            );
            assert!(p.work.is_none_or(|w| w.links + w.judged <= p.units), "{}: {p:?}", c.name);
            // The kinds are counted for the hierarchical table (its rate bound needs them), not for the flat one.
            assert_eq!(p.work.is_some(), c.name.starts_with("hierarchical"), "{}: {p:?}", c.name);
            assert!(p.faces.worst.is_finite() && p.faces.mean <= p.faces.worst, "{}: {p:?}", c.name);
        }
        let (first, last) = (c.points.first().unwrap(), c.points.last().unwrap());
        assert!(
            last.own < first.own && last.own < 0.01,
            "{}: own error {} -> {}",
            c.name,
            first.own,
            last.own
        );
    }
    assert!(md.contains("### Device tables: flat against hierarchical"));
    assert!(out.join("cornell-box-device-flat-vs-hier.svg").exists());
    if std::env::var_os("RADIOSITY_KEEP_BENCH").is_none() {
        let _ = std::fs::remove_dir_all(&out);
    }
}
