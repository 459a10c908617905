//! The `radiosity` binary on bad input: every size has a limit checked before any work, every check that needs
//! no computation comes before the scene is even read, output paths follow one policy, files are written
//! atomically, the shipped relight script with dark frames plots, and scene warnings reach stderr.
//!
//! Most cases pass a scene path that does not exist: if the expected error comes out instead of one naming that
//! path, the check ran before anything else.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

use radiosity_host::files::{check_output_file, check_output_folder, write_atomic, FileError};

fn radiosity(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().expect("run radiosity")
}

fn scene(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name).display().to_string()
}

/// A fresh empty folder.
fn folder(tag: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("radiosity-cli-{tag}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Asserts that the run failed cleanly (exit 1, no abort) with every piece of `expect` on stderr.
fn assert_fails(args: &[&str], expect: &[&str]) {
    let out = radiosity(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
    for e in expect {
        assert!(stderr.contains(e), "{args:?}: stderr lacks {e:?}: {stderr}");
    }
    assert!(!stderr.contains("nonexistent-scene"), "{args:?}: the scene was read before the check: {stderr}");
}

const MISSING: &str = "/nonexistent-scene/none.obj";

#[test]
fn sizes_beyond_their_limits_are_refused_before_any_work() {
    let out = folder("sizes").join("x.png");
    let out = out.to_str().unwrap();
    assert_fails(
        &["render", MISSING, "-o", out, "--width", "100000", "--height", "100000"],
        &["--width", "16384"],
    );
    assert_fails(&["render", MISSING, "-o", out, "--width", "10000", "--height", "10000"], &["4096 x 4096"]);
    assert_fails(&["render", MISSING, "-o", out, "--width", "0"], &["--width", "between 1 and"]);
    assert_fails(&["solve", MISSING, "--max-patches", "100000"], &["--max-patches 100000", "16384"]);
    assert_fails(&["solve", MISSING, "--samples", "100000"], &["--samples 100000", "1024"]);
    assert_fails(&["solve", MISSING, "--rays", "0"], &["--rays 0"]);
    assert_fails(&["formfactors", MISSING, "--threads", "100000"], &["--threads"]);
    assert_fails(&["solve", MISSING, "--max-patch-edge=-1"], &["--max-patch-edge -1"]);
    assert_fails(
        &["relight", &scene("cornell-box.obj"), "--frames", out, "--frame-size", "100000"],
        &["--frame-size"],
    );
    assert_fails(&["check", MISSING, "--ff-factor", "1000"], &["--ff-factor 1000", "64"]);
    assert_fails(&["check", MISSING, "--frames", "100000000"], &["--frames"]);
    assert_fails(&["bench", "--reps", "100000", "--out", out], &["--reps"]);
    assert_fails(&["reference", MISSING, "--samples", "2000000000"], &["samples", "1073741824"]);
    assert_fails(&["reference", MISSING, "--max-samples", "2000000000"], &["max-samples", "1073741824"]);
    assert_fails(&["reference", MISSING, "--threads", "100000"], &["threads", "1024"]);
    assert_fails(&["check", MISSING, "--continuous", "--reference-samples", "2000000000"], &["1073741824"]);
}

#[test]
fn checks_that_need_no_computation_come_first() {
    let dir = folder("cheap");
    let table = dir.join("t.rft");
    let table = table.to_str().unwrap();
    assert_fails(&["bake", MISSING, "--bits", "3", "-o", table], &["3 bits"]);
    assert_fails(&["bake", MISSING, "--threshold", "2", "-o", table], &["threshold 2"]);
    assert_fails(&["check", MISSING, "--bits", "3"], &["3 bits"]);
    assert_fails(&["check", MISSING, "--threshold=-1"], &["threshold -1"]);
    let png = dir.join("x.png");
    let png = png.to_str().unwrap();
    assert_fails(
        &["render", MISSING, "--mode", "error", "--table", table, "-o", png],
        &["reading table", "t.rft"],
    );
    // A table that is not a table: the device's parser refuses it before any work.
    std::fs::write(dir.join("bad.rft"), b"not a table").unwrap();
    let bad = dir.join("bad.rft");
    let bad = bad.to_str().unwrap();
    assert_fails(&["render", MISSING, "--mode", "error", "--table", bad, "-o", png], &["bad.rft"]);
    let scripts = scene("cornell-box.relight.toml");
    assert_fails(&["relight", MISSING, "--scripts", &scripts, "--table", bad], &["bad.rft"]);
    // `--table` means nothing to a shaded picture: an error, not ignored.
    assert_fails(
        &["render", MISSING, "--table", table, "-o", png],
        &["--table applies to --mode error only"],
    );
    assert_fails(
        &["relight", MISSING, "--scripts", "/nonexistent-scripts.toml"],
        &["nonexistent-scripts.toml"],
    );
    std::fs::write(dir.join("bad.toml"), "[[script]]\nname = 3\n").unwrap();
    assert_fails(&["relight", MISSING, "--scripts", dir.join("bad.toml").to_str().unwrap()], &["bad.toml"]);
    assert_fails(
        &["relight", MISSING, "--scripts", &scripts, "--script", "nope"],
        &["no script named \"nope\"", "lights-on"],
    );
}

#[test]
fn output_files_need_an_existing_folder_and_folders_the_tool_creates_are_checked() {
    let dir = folder("outputs");
    let file = dir.join("file");
    std::fs::write(&file, "x").unwrap();
    let missing = dir.join("no/such/folder");
    let under_file = file.join("x");
    for (target, expect) in [(&missing, "does not exist"), (&under_file, "is not a folder")] {
        let t = |ext: &str| target.join(format!("out.{ext}")).display().to_string();
        assert_fails(&["bake", MISSING, "-o", &t("rft")], &[expect]);
        assert_fails(&["render", MISSING, "-o", &t("png")], &[expect]);
        assert_fails(&["lightmap", MISSING, "-o", &t("map")], &[expect]);
        assert_fails(&["check", MISSING, "--plot", &t("plot")], &[expect]);
        assert_fails(&["relight", &scene("cornell-box.obj"), "--csv", &t("csv")], &[expect]);
        assert_fails(&["relight", &scene("cornell-box.obj"), "--plot", &t("plot")], &[expect]);
        assert_fails(&["regress", "--update", "--baseline", &t("json")], &[expect]);
        assert_fails(&["reference", MISSING, "-o", &t("csv")], &[expect]);
    }
    assert!(!dir.join("no").exists(), "no folder was created for an output file");
    // A folder where the file should go.
    assert_fails(&["bake", MISSING, "-o", dir.to_str().unwrap()], &["it is a folder"]);
    // Folders the tool creates: fine when missing, refused under a regular file.
    assert_fails(
        &["relight", &scene("cornell-box.obj"), "--frames", under_file.to_str().unwrap()],
        &["not a folder"],
    );
    assert_fails(&["demo", "--out", under_file.to_str().unwrap()], &["not a folder"]);
    assert_fails(&["bench", "--out", under_file.to_str().unwrap()], &["not a folder"]);
    assert!(check_output_folder(&missing).is_ok());
    assert!(matches!(check_output_file(&missing.join("x")), Err(FileError::MissingFolder { .. })));
    assert!(check_output_file(&dir.join("new.rft")).is_ok());
    assert!(!dir.join("new.rft").exists(), "checking writes nothing that stays");
}

/// The files in `dir` (names).
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn writes_are_atomic_and_a_failed_write_leaves_the_previous_file() {
    let dir = folder("atomic");
    let path = dir.join("a.txt");
    write_atomic(&path, b"first").unwrap();
    write_atomic(&path, b"second").unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), b"second");
    assert_eq!(listing(&dir), ["a.txt"], "no temporary file left");

    // A bake whose table write fails part way (file size limit of 8 KiB; SIGXFSZ ignored so the write returns an
    // error instead of killing the process): the previous table is intact and no partial file is left.
    let table = dir.join("cornell.rft");
    std::fs::write(&table, b"previous table").unwrap();
    let script = format!(
        "trap '' XFSZ; ulimit -f 8; exec '{}' bake '{}' -q --max-patches 100 --samples 4 --rays 4 -o '{}'",
        env!("CARGO_BIN_EXE_radiosity"),
        scene("cornell-box.obj"),
        table.display()
    );
    let out = Command::new("bash").args(["-c", &script]).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cornell.rft") && stderr.contains("File too large"), "{stderr}");
    assert_eq!(std::fs::read(&table).unwrap(), b"previous table");
    assert_eq!(listing(&dir), ["a.txt", "cornell.rft"], "no partial file left");
}

#[test]
fn shipped_relight_script_with_dark_frames_prints_its_table_and_plots() {
    let dir = folder("relight");
    let stem = dir.join("plot");
    let csv = dir.join("frames.csv");
    let out = radiosity(&[
        "relight",
        &scene("cornell-box.obj"),
        "--no-subdivide",
        "--samples",
        "4",
        "--rays",
        "4",
        "-q",
        "--script",
        "off-on",
        "--plot",
        stem.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}{stdout}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stdout.contains("off-on") && stdout.contains(" abs "),
        "dark frames show absolute error: {stdout}"
    );
    assert!(stem.with_extension("svg").exists() && stem.with_extension("png").exists());
    let svg = std::fs::read_to_string(stem.with_extension("svg")).unwrap();
    assert!(svg.contains("dark frames not plotted"), "the plot marks the frames it leaves out");
    let csv = std::fs::read_to_string(csv).unwrap();
    assert!(csv.lines().next().unwrap().contains(",rel_l2,abs_rms,"), "{csv}");
    assert!(
        stdout.contains("light groups (table order): light\n"),
        "relight names the light group: {stdout}"
    );
}

#[test]
fn inspect_names_the_light_groups_given_the_scene() {
    let table = folder("inspect").join("box.rft");
    let table = table.to_str().unwrap();
    let bake = radiosity(&[
        "bake",
        &scene("cornell-box.obj"),
        "--no-subdivide",
        "--samples",
        "4",
        "--rays",
        "4",
        "-q",
        "-o",
        table,
    ]);
    assert!(bake.status.success(), "{}", String::from_utf8_lossy(&bake.stderr));
    let id = format!("id {:#010x}", radiosity_host::bake::group_id("light"));
    // The table alone stores ids only: no name, and a hint where names come from.
    let bare = radiosity(&["inspect", table]);
    let stdout = String::from_utf8_lossy(&bare.stdout);
    assert!(bare.status.success(), "{}", String::from_utf8_lossy(&bare.stderr));
    assert!(stdout.contains(&format!("{id}  ")) && !stdout.contains("\"light\""), "{stdout}");
    assert!(stdout.contains("names: inspect TABLE --scene SCENE.obj"), "{stdout}");
    // With the scene it was baked from, each group's name stands beside its id.
    let named = radiosity(&["inspect", table, "--scene", &scene("cornell-box.obj")]);
    let stdout = String::from_utf8_lossy(&named.stdout);
    assert!(named.status.success(), "{}", String::from_utf8_lossy(&named.stderr));
    assert!(stdout.contains(&format!("{id} \"light\"  ")), "{stdout}");
    assert!(!stdout.contains("names: inspect"), "{stdout}");
    // A scene without that group names nothing, and says so.
    let other = radiosity(&["inspect", table, "--scene", &scene("furnace.obj")]);
    assert!(other.status.success());
    assert!(String::from_utf8_lossy(&other.stderr).contains("1 of the table's 1 light groups have no name"));
}

#[test]
fn scene_warnings_reach_stderr() {
    let dir = folder("warnings");
    std::fs::write(dir.join("s.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
        .unwrap();
    let obj = "mtllib s.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl grey\nf 1 2 3 4\n";
    std::fs::write(dir.join("s.obj"), obj).unwrap();
    let out =
        radiosity(&["solve", dir.join("s.obj").to_str().unwrap(), "--no-subdivide", "--format", "text"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("warning: ") && stderr.contains("light group 'lamp' has no faces"), "{stderr}");
    assert!(stderr.contains("no face emits light"), "{stderr}");
}
