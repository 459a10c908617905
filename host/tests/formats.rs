//! `--format` means what it says: every subcommand's output parses as each format it accepts (JSON through
//! serde_json, CSV as a header and rows of as many fields), text is neither, a format a subcommand does not
//! accept is refused with an error naming the ones it does, and subcommands without `--format` refuse it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn radiosity(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().expect("run radiosity")
}

fn scene(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name).display().to_string()
}

/// A fresh empty folder.
fn folder(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-formats-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `args` with `--format format`, asserts success and returns stdout.
fn run(args: &[&str], format: &str) -> String {
    let mut all = args.to_vec();
    all.extend(["--format", format]);
    let out = radiosity(&all);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{all:?} failed: {stderr}");
    String::from_utf8(out.stdout).expect("UTF-8 output")
}

/// Asserts that `text` is one JSON object (nothing before or after it) and returns it.
fn assert_json(args: &[&str], text: &str) -> serde_json::Value {
    let value: serde_json::Value = serde_json::from_str(text)
        .unwrap_or_else(|e| panic!("{args:?} --format json: not JSON ({e}):\n{text}"));
    assert!(value.is_object(), "{args:?} --format json: not an object:\n{text}");
    value
}

/// Asserts that `text` is CSV: a header line of names, then at least one row, every row with as many fields.
fn assert_csv(args: &[&str], text: &str) {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_else(|| panic!("{args:?} --format csv: empty output"));
    let fields = header.split(',').count();
    assert!(
        fields >= 2 && header.split(',').all(|h| !h.is_empty() && !h.contains(' ')),
        "{args:?} --format csv: header {header:?}"
    );
    let mut rows = 0;
    for line in lines {
        assert_eq!(line.split(',').count(), fields, "{args:?} --format csv: row {line:?} under {header:?}");
        rows += 1;
    }
    assert!(rows > 0, "{args:?} --format csv: no rows:\n{text}");
}

/// Asserts that `text` is text: not empty, and neither JSON nor the CSV another format would print.
fn assert_text(args: &[&str], text: &str) {
    assert!(!text.trim().is_empty(), "{args:?} --format text: empty output");
    assert!(serde_json::from_str::<serde_json::Value>(text).is_err(), "{args:?} --format text printed JSON");
    assert!(!text.trim_start().starts_with('{'), "{args:?} --format text printed JSON:\n{text}");
}

/// Checks every format in `accepted` and that every other one of text, csv and json is refused.
fn check_formats(args: &[&str], accepted: &[&str]) -> Option<serde_json::Value> {
    let mut json = None;
    for format in ["text", "csv", "json"] {
        if !accepted.contains(&format) {
            let mut all = args.to_vec();
            all.extend(["--format", format]);
            let out = radiosity(&all);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{all:?} accepted a format it does not print");
            let possible = format!("[possible values: {}]", accepted.join(", "));
            assert!(
                stderr.contains(&format!("invalid value '{format}'")) && stderr.contains(&possible),
                "{all:?}: unclear error: {stderr}"
            );
            continue;
        }
        let text = run(args, format);
        match format {
            "text" => assert_text(args, &text),
            "csv" => assert_csv(args, &text),
            _ => json = Some(assert_json(args, &text)),
        }
    }
    json
}

const QUICK: [&str; 6] = ["--no-subdivide", "-q", "--samples", "4", "--rays", "4"];

fn with_quick<'a>(args: &[&'a str]) -> Vec<&'a str> {
    let mut all = args.to_vec();
    all.extend(QUICK);
    all
}

#[test]
fn every_subcommand_prints_each_format_it_accepts_and_refuses_the_others() {
    let squares = scene("facing-squares.obj");
    let dir = folder("all");
    let table = dir.join("squares.rft");
    let table = table.to_str().unwrap();

    check_formats(&with_quick(&["formfactors", &squares]), &["text", "csv", "json"]);
    let bake = check_formats(&with_quick(&["bake", &squares, "-o", table]), &["text", "json"]).unwrap();
    assert!(bake["files"]["table"].as_str().is_some_and(|t| t.ends_with("squares.rft")), "{bake}");
    for key in
        ["patches", "groups", "energy_dropped", "table_bytes", "runtime_state", "error", "reference_residual"]
    {
        assert!(bake.get(key).is_some(), "bake JSON lacks {key} (the text shows it): {bake}");
    }
    check_formats(&["inspect", table], &["text", "json"]);

    let solve = check_formats(&with_quick(&["solve", &squares]), &["text", "csv", "json"]).unwrap();
    let patches = solve["patch_table"].as_array().expect("solve JSON has the patch table");
    assert_eq!(patches.len(), 2, "{solve}");
    for (k, p) in patches.iter().enumerate() {
        assert_eq!(p["patch"], k);
        assert_eq!(p["vertices"].as_array().map(Vec::len), Some(4), "{p}");
        for key in ["face", "centroid", "normal", "area", "rho", "e", "b"] {
            assert!(p.get(key).is_some(), "solve JSON patch lacks {key}: {p}");
        }
        assert!((p["area"].as_f64().unwrap() - 1.0).abs() < 1e-12, "unit squares: {p}");
    }
    let hierarchical = ["solve", &squares, "--method", "hierarchical", "-q", "--epsilon", "0.3"];
    let solve = check_formats(&hierarchical, &["text", "csv", "json"]).unwrap();
    assert!(solve["patch_table"].as_array().is_some_and(|p| !p.is_empty()), "{solve}");

    check_formats(&["reference", &squares, "--samples", "64", "-q"], &["text", "csv", "json"]);
    check_formats(&with_quick(&["check", &squares, "--arith", "f32"]), &["text", "json"]);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let baseline = root.join("tests/baseline/quantization.json");
    let regress = ["regress", "--scene", "facing-squares.obj", "--scenes", &scene(""), "--baseline"];
    let regress = [&regress[..], &[baseline.to_str().unwrap()]].concat();
    check_formats(&regress, &["text", "json"]);

    // Relight with output files: their paths follow the text, and go to stderr after CSV or JSON.
    let csv = dir.join("frames.csv");
    let csv = csv.to_str().unwrap();
    let cornell = scene("cornell-box.obj");
    let relight = with_quick(&["relight", &cornell, "--script", "off-on", "--csv", csv]);
    check_formats(&relight, &["text", "csv", "json"]);
    assert!(run(&relight, "text").contains("frames.csv"));
}

#[test]
fn subcommands_without_a_format_refuse_one() {
    let dir = folder("none");
    let out = dir.join("x");
    let out = out.to_str().unwrap();
    for args in [
        vec!["render", "/nonexistent.obj", "-o", out],
        vec!["lightmap", "/nonexistent.obj", "-o", out],
        vec!["export", "/nonexistent.obj", "-o", out],
        vec!["demo", "--out", out],
        vec!["bench", "--quick", "--out", out],
    ] {
        let mut all = args.clone();
        all.extend(["--format", "json"]);
        let result = radiosity(&all);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(!result.status.success(), "{all:?} accepted --format");
        assert!(stderr.contains("unexpected argument '--format'"), "{all:?}: {stderr}");
    }
}
