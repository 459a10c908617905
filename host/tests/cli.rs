//! The `radiosity` binary on bad input: every size has a limit checked before any work, every check that needs
//! no computation comes before the scene is even read, output paths follow one policy, files are written
//! atomically (also when a bake is killed), the shipped relight script with dark frames plots, and scene
//! warnings reach stderr.
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
        assert_fails(&["export", MISSING, "-o", &t("glb")], &[expect]);
        assert_fails(&["convert", MISSING, "-o", &t("glb")], &[expect]);
        assert_fails(&["convert", MISSING, "-o", &t("gltf")], &[expect]);
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

/// A bake of the Cornell box to `table` with at most `max_patches` patches, quiet unless `progress`.
fn bake_command(table: &Path, max_patches: u32, progress: bool) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_radiosity"));
    command.args(["bake", &scene("cornell-box.obj"), "--max-patches", &max_patches.to_string()]);
    command.args(["--samples", "4", "--rays", "4", "-o", table.to_str().unwrap()]);
    if !progress {
        command.arg("-q");
    }
    command
}

/// The name pattern of `write_atomic`'s temporary files for `NAME` written by process `pid`:
/// `.NAME.tmp-PID-N`.
fn is_temporary_of(file: &str, name: &str, pid: u32) -> bool {
    file.strip_prefix(&format!(".{name}.tmp-{pid}-")).is_some_and(|n| n.parse::<u64>().is_ok())
}

/// A child process killed (SIGKILL) and reaped when dropped, so a failing assertion leaves no process behind
/// (a stopped one would never end).
struct KillOnDrop(std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A bake killed in the middle leaves the previous table (and the capacities file written after it) intact and
/// no partial table, in the two places it can be killed:
/// - during the computation, by SIGKILL: the bake is stopped (SIGSTOP) once stderr shows its mesh is done and
///   its form factors start, the folder is inspected while it cannot move, then it is killed: nothing but
///   the previous table is there, before and after;
/// - while its temporary file exists, half written: a file size limit below the table's size, with SIGXFSZ at
///   its default action, kills the bake inside `write` (the kernel's signal, no handler and no cleanup, as
///   SIGKILL there would): the previous table is intact and the one file left beside it is the temporary,
///   named `.cornell.rft.tmp-PID-N` after the killed process and holding the start of a table. Nothing
///   removes it (the files policy, `radiosity_host::files`); the next bake writes its table beside it
///   undisturbed.
#[test]
fn a_killed_bake_leaves_the_previous_table_and_no_partial_file() {
    use std::io::{BufRead, BufReader};
    use std::os::unix::process::ExitStatusExt;

    let dir = folder("killed");
    let table = dir.join("cornell.rft");
    // A bake writes its table, then the capacities a firmware build needs beside it.
    let capacities = dir.join("cornell.rft.capacities.json");
    let out = bake_command(&table, 60, false).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let previous = (std::fs::read(&table).unwrap(), std::fs::read(&capacities).unwrap());
    radiosity_core::Table::parse(&previous.0).expect("the previous table is a table");
    let intact = || {
        for (path, before) in [(&table, &previous.0), (&capacities, &previous.1)] {
            let now = std::fs::read(path).unwrap();
            assert!(
                now == *before,
                "{} changed: {} bytes, {} before",
                path.display(),
                now.len(),
                before.len()
            );
        }
    };
    let outputs = ["cornell.rft", "cornell.rft.capacities.json"];

    // Killed by SIGKILL during the computation (a bake of thousands of patches, stopped long before it writes).
    let mut bake =
        KillOnDrop(bake_command(&table, 3000, true).stderr(std::process::Stdio::piped()).spawn().unwrap());
    let bake = &mut bake.0;
    let mut stderr = BufReader::new(bake.stderr.take().unwrap());
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        let read = stderr.read_line(&mut line).unwrap();
        seen.push_str(&line);
        assert!(read > 0, "the bake ended before meshing was reported: {seen}");
        if line.contains(" patches (max edge ") {
            break;
        }
    }
    let stop = Command::new("kill").args(["-STOP", &bake.id().to_string()]).status().unwrap();
    assert!(stop.success());
    assert!(bake.try_wait().unwrap().is_none(), "stopped, not finished: {seen}");
    assert_eq!(listing(&dir), outputs, "stopped while computing: no temporary file yet");
    intact();
    bake.kill().unwrap();
    let status = bake.wait().unwrap();
    assert_eq!(status.signal(), Some(9), "killed by SIGKILL: {status:?}");
    intact();
    assert_eq!(listing(&dir), outputs, "no partial file");

    // Killed while its temporary file exists: the table (more than 8 KiB) meets the limit of 8 KiB part way.
    let script = format!(
        "ulimit -c 0; ulimit -f 8; exec '{}' bake '{}' -q --max-patches 100 --samples 4 --rays 4 -o '{}'",
        env!("CARGO_BIN_EXE_radiosity"),
        scene("cornell-box.obj"),
        table.display()
    );
    let killed = Command::new("bash").args(["-c", &script]).spawn().unwrap();
    let pid = killed.id();
    let out = killed.wait_with_output().unwrap();
    assert_eq!(out.status.signal(), Some(25), "killed by SIGXFSZ inside write: {:?}", out.status);
    intact();
    let files = listing(&dir);
    assert_eq!(files.len(), 3, "{files:?}");
    assert!(is_temporary_of(&files[0], "cornell.rft", pid), "{files:?}: the temporary of process {pid}");
    assert_eq!(files[1..], outputs);
    let stale = dir.join(&files[0]);
    let partial = std::fs::read(&stale).unwrap();
    assert!(partial.len() <= 8192 && partial.starts_with(b"RFT\x1a"), "the start of a table");
    assert!(radiosity_core::Table::parse(&partial).is_err(), "a partial table");

    // The next bake is not disturbed by the leftover, which stays as it was.
    let out = bake_command(&table, 60, false).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    radiosity_core::Table::parse(&std::fs::read(&table).unwrap()).expect("a complete table");
    assert_eq!(listing(&dir), files);
    assert_eq!(std::fs::read(&stale).unwrap(), partial);
}

/// A leftover temporary file with the very name a write would pick next (a killed run's, whose process id came
/// round again) does not make the write fail: the name is passed over.
#[test]
fn a_leftover_temporary_with_a_recycled_process_id_is_passed_over() {
    let dir = folder("recycled");
    let path = dir.join("a.txt");
    // Every name this process's writes could pick next (its counter is shared with the other tests).
    // The same for the probe that checks a folder is writable.
    let pid = std::process::id();
    let stale: Vec<String> =
        (0..2000).flat_map(|n| [format!(".a.txt.tmp-{pid}-{n}"), format!(".probe.tmp-{pid}-{n}")]).collect();
    for name in &stale {
        std::fs::write(dir.join(name), b"left by a killed run").unwrap();
    }
    write_atomic(&path, b"new").expect("the leftover names are passed over");
    assert_eq!(std::fs::read(&path).unwrap(), b"new");
    assert_eq!(listing(&dir).len(), stale.len() + 1, "the leftovers stay, nothing else is added");
    assert!(check_output_file(&dir.join("b.txt")).is_ok());
    assert_eq!(listing(&dir).len(), stale.len() + 1, "the probe leaves nothing");
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

#[test]
fn an_error_says_its_cause_once() {
    // The message already names the OS error; a `caused by:` line repeating it would say it twice.
    let out = radiosity(&["solve", MISSING]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cannot read /nonexistent-scene/none.obj: No such file"), "{stderr}");
    assert_eq!(stderr.matches("No such file").count(), 1, "the cause is repeated: {stderr}");
    assert!(!stderr.contains("caused by"), "{stderr}");
}

/// The stderr of a quick `solve` of the shipped scene `name` (one patch per face, few samples).
fn quick_solve_stderr(name: &str) -> String {
    let out = radiosity(&["solve", &scene(name), "--no-subdivide", "--samples", "4", "--rays", "4"]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    stderr
}

#[test]
fn an_open_scene_says_where_light_leaves_it() {
    // The published Cornell box has no front wall: light leaves through z = 0. Its largest faces looking at the
    // opening are listed by OBJ line (the walls, ceiling and floor, at lines 18 to 147); the blocks are not first.
    let stderr = quick_solve_stderr("cornell-box.obj");
    let line = stderr.lines().find(|l| l.contains("light leaves the scene from")).unwrap_or_else(|| {
        panic!("no leak location: {stderr}");
    });
    let first = line.split("from face ").nth(1).and_then(|r| r.split(' ').next()).unwrap();
    let walls = ["0", "2", "3", "4", "5", "6", "7", "18"];
    assert!(walls.contains(&first), "the first face listed is a block's ({first}): {line}");
    assert!(line.contains("cornell-box.obj:") && line.contains('%'), "{line}");
    assert!(line.contains(" more"), "the rest are counted: {line}");
    // The closed variant leaks nowhere and says nothing of it.
    let stderr = quick_solve_stderr("cornell-box-closed.obj");
    assert!(stderr.contains("closed scene") && !stderr.contains("light leaves"), "{stderr}");
}

#[test]
fn counts_of_one_are_singular() {
    let stderr = quick_solve_stderr("cornell-box.obj");
    assert!(stderr.contains("1 light group ->"), "{stderr}");
    for wrong in ["1 light groups", "1 members", "1 pairs", "1 rows", "1 faces", "1 patches"] {
        assert!(!stderr.contains(&format!(" {wrong}")), "{wrong:?} in {stderr}");
    }
    let dir = folder("plural");
    let table = dir.join("t.rft");
    let out = radiosity(&[
        "bake",
        &scene("facing-squares.obj"),
        "--no-subdivide",
        "-q",
        "--samples",
        "4",
        "--rays",
        "4",
        "-o",
        table.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("1 dynamic, 1 member\n") && stdout.contains("  1 member  "), "{stdout}");
    // Energy dropped is a fraction of all power, not a sum over rows that reads like one.
    let dropped = stdout.lines().find(|l| l.starts_with("energy dropped")).unwrap();
    assert!(dropped.contains("of all power transported") && !dropped.contains("total"), "{dropped}");
    let out = radiosity(&["inspect", table.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("(1 member;") && !stdout.contains("1 members"), "{stdout}");
}

#[test]
fn a_bake_says_what_it_will_cost_and_why_the_mesh_stops_below_its_budget() {
    // No TOML: the default budget, which refinement does not reach because the light is resolved.
    let out = radiosity(&[
        "solve",
        &scene("facing-squares.obj"),
        "--method",
        "flat",
        "--samples",
        "4",
        "--rays",
        "4",
        "--format",
        "text",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let estimate = stderr.lines().position(|l| l.starts_with("cost estimate: ")).expect(&stderr);
    let first_ff = stderr.lines().position(|l| l.starts_with("form factors: ")).expect(&stderr);
    assert!(estimate < first_ff, "the estimate comes before the form factors: {stderr}");
    assert!(
        stderr.contains("at most 4096 after 2 refinement passes") && stderr.contains("67.2 MB"),
        "{stderr}"
    );
    assert!(
        stderr.contains("of 4096 patches (budget: the default 4096; set it with --max-patches)"),
        "{stderr}"
    );
    assert!(stderr.contains("below the budget because no patch's radiosity changes across it"), "{stderr}");
    assert!(stderr.lines().any(|l| l.starts_with("cost: ") && l.contains("occlusion rays")), "{stderr}");

    // A budget the refinement spends: said so, and the bake's table is measured against the device.
    let dir = folder("budget");
    let table = dir.join("t.rft");
    let out = radiosity(&[
        "bake",
        &scene("cornell-box.obj"),
        "--max-patches",
        "400",
        "--samples",
        "4",
        "--rays",
        "4",
        "--format",
        "json",
        "-o",
        table.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let spent = stderr.lines().find(|l| l.contains("(budget: --max-patches)")).expect(&stderr);
    assert!(spent.contains("of 400 patches") && spent.contains("the budget is spent"), "{spent}");
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let fit = &doc["device_fit"];
    let bytes = fit["table_bytes"].as_u64().unwrap();
    assert_eq!(bytes, std::fs::metadata(&table).unwrap().len(), "{fit}");
    assert_eq!(fit["flash"].as_u64(), Some(firmware_sim::qemu::MPS2_AN386.flash));
    let ram_ok = fit["buffer_bytes"].as_u64().unwrap() <= fit["ram"].as_u64().unwrap();
    assert_eq!(fit["fits"].as_bool(), Some(bytes <= fit["flash"].as_u64().unwrap() && ram_ok), "{fit}");
    let patches = doc["patches"].as_u64().unwrap() as usize;
    assert!(patches <= 400, "{patches}");
    let bound = radiosity_host::bake::table_bytes_bound(patches, 16);
    assert!(bytes <= bound, "the table ({bytes} bytes) is within the estimate's bound ({bound})");
    assert!(
        radiosity_host::bake::table_bytes_bound(radiosity_host::bake::patches_within(bound, 16) + 1, 16)
            > bound
    );
}

/// `lightmap` on the Cornell box (one patch per face) with `extra` options: stdout and the JSON map's atlas size
/// and texel size.
fn light_map(extra: &[&str]) -> (String, u64, u64, f64) {
    let dir = folder("lightmap");
    let stem = dir.join("map");
    let mut args = vec!["lightmap", "--no-subdivide", "-q", "--samples", "4", "--rays", "4", "-o"];
    let cornell = scene("cornell-box.obj");
    args.extend([stem.to_str().unwrap(), &cornell]);
    args.extend(extra);
    let out = radiosity(&args);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(stem.with_extension("json")).unwrap()).unwrap();
    let size = |k: &str| json["atlas"][k].as_u64().unwrap();
    (stdout, size("width"), size("height"), json["texel_size"].as_f64().unwrap())
}

#[test]
fn light_map_resolution_is_an_option() {
    let (stdout, w, h, texel) = light_map(&[]);
    assert!(stdout.contains(&format!("atlas {w} x {h} texels")), "{stdout}");
    // Twice the texels across the largest face: about twice the atlas on each side (padding is fixed).
    let (_, w2, h2, texel2) = light_map(&["--face-texels", "128"]);
    assert!((texel2 - texel / 2.0).abs() <= 1e-12 * texel, "{texel2} vs {texel}");
    assert!(w2 > w * 3 / 2 && h2 > h * 3 / 2 && w2 * h2 > 3 * w * h, "{w}x{h} -> {w2}x{h2}");
    // A texel size in scene units (mm here) is used as given.
    let (_, w3, h3, texel3) = light_map(&["--texel-size", "4"]);
    assert_eq!(texel3, 4.0);
    assert!(w3 > w2 && h3 > h2, "4 mm texels are finer than {texel2}: {w3}x{h3}");
    // Limits: checked before any work for the options, and for the atlas as for every picture.
    let out = folder("lightmap-limits").join("map");
    let out = out.to_str().unwrap();
    assert_fails(&["lightmap", MISSING, "-o", out, "--face-texels", "5000"], &["--face-texels 5000", "4096"]);
    assert_fails(&["lightmap", MISSING, "-o", out, "--texel-size", "0"], &["--texel-size 0", "positive"]);
    let refused = radiosity(&[
        "lightmap",
        &scene("cornell-box.obj"),
        "--no-subdivide",
        "-q",
        "--samples",
        "4",
        "--rays",
        "4",
        "-o",
        out,
        "--texel-size",
        "0.3",
    ]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("light map") && stderr.contains("4096 x 4096"), "{stderr}");
}

/// `export`: its help explains the file; bad options and outputs fail before any work; on the Cornell box (one
/// patch per face) it says what it is doing on stderr and writes a .glb and the .exr beside it.
#[test]
fn export_writes_a_glb_beside_its_exr() {
    let help = radiosity(&["export", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    for expect in ["TEXCOORD_1", "MOZ_lightmap", "irradiance", "--texel-size", "README"] {
        assert!(help.contains(expect), "export --help lacks {expect:?}: {help}");
    }
    let dir = folder("export");
    let glb = dir.join("box.glb");
    let glb = glb.to_str().unwrap();
    assert_fails(&["export", MISSING, "-o", dir.join("box.gltf").to_str().unwrap()], &["must be a .glb"]);
    assert_fails(&["export", MISSING, "-o", glb, "--face-texels", "5000"], &["--face-texels 5000", "4096"]);
    assert_fails(&["export", MISSING, "-o", glb, "--texel-size", "0"], &["--texel-size 0", "positive"]);
    assert_fails(&["export", MISSING, "-o", "/nonexistent-folder/box.glb"], &["does not exist"]);
    let cornell = scene("cornell-box.obj");
    let out = radiosity(&["export", &cornell, "--no-subdivide", "--samples", "4", "--rays", "4", "-o", glb]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("export: solving") && stderr.contains("export: baking"), "{stderr}");
    let exr = dir.join("box.exr");
    assert!(stdout.contains(glb) && stdout.contains(exr.to_str().unwrap()), "{stdout}");
    assert!(stdout.contains("triangles, atlas") && stdout.contains("light-map intensity"), "{stdout}");
    assert_eq!(&std::fs::read(glb).unwrap()[..4], b"glTF");
    assert!(radiosity_host::picture::hdr::read_exr(&exr).is_ok());
}

/// `render`, `lightmap` and `export` with `--method hierarchical` picture the hierarchy's leaves: the .glb holds
/// exactly the leaves that `solve --method hierarchical` prints at the same settings (each leaf a fan of its
/// vertex count less two triangles), not the flat mesh; the light map has a chart for every face, as the flat
/// one does; the patch view is the leaves', not the flat mesh's. `--mode error` (a flat device table's error) and
/// hierarchical settings with `--method flat` are refused before any work.
#[test]
fn hierarchical_pictures_show_the_leaves() {
    let rooms = scene("two-rooms.obj");
    let dir = folder("hier-pictures");
    let path = |name: &str| dir.join(name).display().to_string();
    let hier = ["--method", "hierarchical", "--epsilon", "0.1", "-q"];
    let run = |args: &[&str], more: &[&str]| {
        let out = radiosity(&[args, more].concat());
        assert!(out.status.success(), "{args:?} {more:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let solved: serde_json::Value =
        serde_json::from_str(&run(&["solve", &rooms, "--format", "json"], &hier)).unwrap();
    let leaves = solved["patch_table"].as_array().unwrap();
    assert_eq!(leaves.len(), solved["patches"].as_u64().unwrap() as usize);
    let fans: usize = leaves.iter().map(|p| p["vertices"].as_array().unwrap().len() - 2).sum();
    let triangles = |stdout: &str| -> usize {
        let line =
            stdout.lines().find(|l| l.contains("triangles, atlas")).unwrap_or_else(|| panic!("{stdout}"));
        line.split_whitespace().next().unwrap().parse().unwrap()
    };
    let hier_glb = triangles(&run(&["export", &rooms, "-o", &path("h.glb")], &hier));
    let flat = ["--method", "flat", "-q"];
    let flat_glb = triangles(&run(&["export", &rooms, "-o", &path("f.glb")], &flat));
    assert_eq!(hier_glb, fans, "the hierarchical export holds the solve's {} leaves", leaves.len());
    assert_ne!(
        flat_glb, fans,
        "the flat mesh has {flat_glb} triangles: the comparison cannot tell them apart"
    );
    // Light maps: one chart per face either way.
    run(&["lightmap", &rooms, "-o", &path("h")], &hier);
    run(&["lightmap", &rooms, "-o", &path("f")], &flat);
    let charts = |stem: &str| -> usize {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{stem}.json"))).unwrap())
                .unwrap();
        json["faces"].as_array().unwrap().len()
    };
    assert_eq!(charts("h"), charts("f"));
    // The patch views: the leaves are not the flat mesh.
    run(
        &["render", &rooms, "--mode", "patches", "--width", "96", "--height", "96", "-o", &path("h.png")],
        &hier,
    );
    run(
        &["render", &rooms, "--mode", "patches", "--width", "96", "--height", "96", "-o", &path("f.png")],
        &flat,
    );
    assert_ne!(std::fs::read(dir.join("h.png")).unwrap(), std::fs::read(dir.join("f.png")).unwrap());
    let png = path("x.png");
    assert_fails(
        &["render", MISSING, "--method", "hierarchical", "--mode", "error", "-o", &png],
        &["--mode error", "--method flat"],
    );
    for command in ["render", "lightmap", "export"] {
        assert_fails(
            &[command, MISSING, "--method", "flat", "--epsilon", "0.1", "-o", &path("x.glb")],
            &["--epsilon", "apply to --method hierarchical only"],
        );
        assert_fails(
            &[command, MISSING, "--method", "hierarchical", "--max-patches", "10", "-o", &path("x.glb")],
            &["--max-patches", "apply to --method flat only"],
        );
    }
}

/// `solve --continuous` compares the answer it prints with the path-traced continuous scene, face by face, for
/// both methods: each face's "mesh" value in the JSON is the area average of that face's rows of the same JSON's
/// patch table (the flat mesh's patches, or the hierarchy's leaves), the reference has every face; the text
/// output prints the table, and after CSV it goes to stderr. A reference setting without `--continuous` is
/// refused.
#[test]
fn solve_continuous_judges_either_answer_per_face() {
    let squares = scene("perpendicular-squares.obj");
    let base = ["solve", squares.as_str(), "-q", "--continuous", "--reference-samples", "4096"];
    for method in
        [&["--method", "flat", "--max-patches", "32"][..], &["--method", "hierarchical", "--epsilon", "0.1"]]
    {
        let out = radiosity(&[&base[..], method, &["--format", "json"]].concat());
        assert!(
            out.status.success(),
            "{method:?}: {:?} {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let faces = doc["discretization"]["faces"].as_array().unwrap_or_else(|| panic!("{doc}"));
        assert_eq!(faces.len(), 2, "{method:?}");
        for face in faces {
            let k = face["face"].as_u64().unwrap();
            for c in 0..3 {
                let (mut area, mut sum) = (0.0, 0.0);
                for p in
                    doc["patch_table"].as_array().unwrap().iter().filter(|p| p["face"].as_u64() == Some(k))
                {
                    let a = p["area"].as_f64().unwrap();
                    area += a;
                    sum += a * p["b"][c].as_f64().unwrap();
                }
                let mesh = face["mesh"][c].as_f64().unwrap();
                assert!(
                    area > 0.0 && (mesh - sum / area).abs() <= 1e-12 * mesh.abs().max(1e-300),
                    "{method:?}: {face}"
                );
                assert!(face["reference"][c].as_f64().unwrap() >= 0.0, "{face}");
            }
        }
        let text = radiosity(&[&base[..], method, &["--format", "text"]].concat());
        let text = String::from_utf8_lossy(&text.stdout);
        assert!(text.contains("discretization per face") && text.contains("|d|/SE"), "{method:?}: {text}");
        // CSV keeps stdout a patch table; the comparison goes to stderr.
        let csv = radiosity(&[&base[..], method].concat());
        let (stdout, stderr) = (String::from_utf8_lossy(&csv.stdout), String::from_utf8_lossy(&csv.stderr));
        assert!(
            stdout.starts_with("patch,face,") && !stdout.contains("discretization"),
            "{method:?}: {stdout}"
        );
        assert!(stderr.contains("discretization per face"), "{method:?}: {stderr}");
    }
    let out = radiosity(&["solve", MISSING, "--reference-se", "0.01"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--continuous"), "{err}");
}

/// `check --method hierarchical` bakes the hierarchy's table and runs core's hierarchical solver on it: the
/// report's elements are the leaves `solve --method hierarchical --refinement brightness` makes at the same
/// epsilon (brightness is check's default, as bake's), its components are the hierarchical table's steps, and
/// at the default setting the device's error against the hierarchical solve is within what the components it
/// telescopes through allow. Each component `e_k` is relative to its own answer, whose norm is at most
/// `(1 + e_j)` times the next one's, so `total <= S * prod(1 + e_k) <= S * exp(S)` with `S` their sum. Settings
/// of the other method, and a table file with `--method hierarchical`, are refused before any work; the
/// lights-off setting prints the device's distance from dark, not an infinite relative error.
#[test]
fn check_hierarchical_traces_the_tables_error() {
    let rooms = scene("two-rooms.obj");
    let hier = ["--method", "hierarchical", "--epsilon", "0.1", "-q", "--format", "json"];
    let run = |args: &[&str]| -> serde_json::Value {
        let out = radiosity(&[args, &hier[..]].concat());
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let doc = run(&["check", &rooms, "--relight"]);
    let dir = folder("checkhier");
    let table = dir.join("t.rft").display().to_string();
    // The device table's leaves (the f64 answers of `solve` also charge the sender's unevenness: other leaves).
    let baked = run(&["bake", &rooms, "-o", &table]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(doc["method"], "hierarchical");
    assert_eq!(doc["patches"], baked["leaves"], "the check's elements are the bake's leaves");
    let components = doc["components"].as_array().unwrap();
    let names: Vec<&str> = components.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "hierarchy (links)",
            "table closure",
            "quantization",
            "iteration truncation",
            "arithmetic (f32)",
            "arithmetic (fixed)"
        ]
    );
    let part = |name: &str| -> f64 {
        components.iter().find(|c| c["name"] == name).unwrap()["error"]["rel_l2"].as_f64().unwrap()
    };
    for arith in ["f32", "fixed"] {
        let sum: f64 =
            ["table closure", "quantization", "iteration truncation", &format!("arithmetic ({arith})")]
                .iter()
                .map(|n| part(n))
                .sum();
        let settings = doc["settings"].as_array().unwrap();
        let total = settings.iter().find(|s| s["arith"] == arith && s["setting"] == 0).unwrap()["error"]
            ["rel_l2"]
            .as_f64()
            .unwrap();
        assert!(total <= sum * sum.exp(), "{arith}: device vs solve {total:e} > components {sum:e}");
        assert_eq!(
            settings.iter().filter(|s| s["arith"] == arith).count(),
            4,
            "{arith}: the relight settings"
        );
    }
    // The Cornell box's lights-off setting has no relative error (its only light is dynamic, so the exact answer
    // is zero): the text says how far from dark the device is instead of printing an infinity.
    let cornell = scene("cornell-box.obj");
    let text =
        radiosity(&["check", &cornell, "--relight", "--method", "hierarchical", "--epsilon", "0.1", "-q"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("f32 setting 1: the exact answer is zero") && !text.contains(" inf "), "{text}");
    assert_fails(
        &["check", MISSING, "--method", "hierarchical", "--threshold", "0.01"],
        &["--threshold", "apply to flat tables only"],
    );
    assert_fails(
        &["check", MISSING, "--method", "flat", "--epsilon", "0.1"],
        &["--epsilon", "apply to --method hierarchical only"],
    );
    assert_fails(
        &["check", MISSING, "--method", "hierarchical", "--max-patches", "10"],
        &["--max-patches", "apply to --method flat only"],
    );
    assert_fails(
        &["check", "/nonexistent-scene/t.rft", "--scene", MISSING, "--method", "hierarchical"],
        &["--method hierarchical", "relight"],
    );
}

#[test]
fn demo_without_qemu_runs_on_the_host_only() {
    let dir = folder("demo");
    let out = radiosity(&["demo", "--no-qemu", "--out", dir.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("--no-qemu: the host's device loop only"), "{stdout}");
    assert!(!stdout.contains("QEMU m4") && !stdout.contains("QEMU run skipped"), "{stdout}");
    for file in [
        "cornell-box.rft",
        "cornell-box-m4.rft",
        "cornell-box.png",
        "cornell-box-relight.csv",
        "cornell-box.glb",
    ] {
        assert!(dir.join(file).exists(), "{file} missing: {stdout}");
    }
}

/// `solve --method hierarchical --solver shooting` solves by progressive refinement and says so; its JSON has
/// the answer split by light group like the flat solve's, and the two solvers agree on the mean radiosity to
/// the iteration's tolerance (1e-7 relative change; the means are printed to 7 significant digits in text, so
/// compared in JSON here within 1e-6). `--solver` and `--max-links` with the flat method are refused, and a link
/// limit below what the scene needs stops the solve with an error that names it.
#[test]
fn hierarchical_solve_by_shooting() {
    let rooms = scene("two-rooms.obj");
    // The two rooms solved hierarchically at epsilon 0.1, with `more` arguments.
    let solve = |more: &[&str]| {
        let mut args = vec!["solve", rooms.as_str(), "-q", "--method", "hierarchical", "--epsilon", "0.1"];
        args.extend_from_slice(more);
        radiosity(&args)
    };
    let json = |solver: &str| -> serde_json::Value {
        let out = solve(&["--solver", solver, "--format", "json"]);
        assert!(out.status.success(), "{solver}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let (gathered, shot) = (json("gathering"), json("shooting"));
    assert_eq!(shot["solver"], "shooting");
    assert_eq!(gathered["solver"], "gathering");
    assert_eq!(shot["dynamic_groups"][0]["group"], "lamp");
    for c in 0..3 {
        let (g, s) =
            (gathered["mean_radiosity"][c].as_f64().unwrap(), shot["mean_radiosity"][c].as_f64().unwrap());
        assert!(g > 0.0 && (g - s).abs() <= 1e-6 * g, "channel {c}: gathering {g}, shooting {s}");
    }
    assert_fails(
        &["solve", MISSING, "--method", "flat", "--solver", "shooting"],
        &["--solver applies to --method hierarchical only"],
    );
    assert_fails(
        &["solve", MISSING, "--method", "dense", "--max-links", "10"],
        &["--max-links and --pieces apply to --method hierarchical only"],
    );
    let out = radiosity(&["solve", MISSING, "--method", "hierarchical", "--pieces", "0"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("'0' for '--pieces"), "{err}");
    // Refinement split into receiver-subtree pieces and merged: the same patch table, byte for byte.
    let csv = |pieces: &str| {
        let out = solve(&["--pieces", pieces]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        out.stdout
    };
    let one = csv("1");
    assert!(one.len() > 1000 && csv("3") == one);
    // A limit below what the scene needs: the error says so (and no patch table is printed).
    let out = solve(&["--max-links", "50"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && out.stdout.is_empty(), "{err}");
    assert!(
        err.contains("two-rooms.obj") && err.contains("more than 50 links") && err.contains("--max-links"),
        "{err}"
    );
}

/// The f64 answers default to the hierarchy: `solve` without `--method` is `--method hierarchical --refinement
/// brightness --epsilon 0.0005`, byte for byte (and not the device tables' epsilon of 0.03, which gives other
/// leaves here), and its JSON says so; a meshing option (`--max-patches`) asks for the flat mesh instead, and
/// `--method dense` is `--method flat`.
#[test]
fn the_hierarchy_is_the_default_answer_and_a_mesh_option_asks_for_the_flat_one() {
    let squares = scene("facing-squares.obj");
    let solve = |more: &[&str]| {
        let out = radiosity(&[&["solve", squares.as_str(), "-q"][..], more].concat());
        assert!(out.status.success(), "{more:?}: {}", String::from_utf8_lossy(&out.stderr));
        out.stdout
    };
    let default = solve(&[]);
    let explicit = ["--method", "hierarchical", "--refinement", "brightness", "--epsilon"];
    assert_eq!(default, solve(&[&explicit[..], &["0.0005"]].concat()));
    assert_ne!(
        default,
        solve(&[&explicit[..], &["0.03"]].concat()),
        "the default epsilon is not the tables'"
    );
    let doc: serde_json::Value = serde_json::from_slice(&solve(&["--format", "json"])).unwrap();
    assert_eq!(
        (&doc["method"], &doc["refinement"], doc["epsilon"].as_f64()),
        (&serde_json::json!("hierarchical"), &serde_json::json!("brightness"), Some(0.0005)),
        "{}",
        doc["stats"]
    );
    let flat = solve(&["--method", "flat"]);
    assert_ne!(flat, default);
    assert_eq!(solve(&["--method", "dense"]), flat);
    let meshed = String::from_utf8(solve(&["--max-patches", "8"])).unwrap();
    assert_eq!(meshed.lines().count(), 1 + 8, "a header and the 8 patches of the flat mesh: {meshed}");
    let doc: serde_json::Value =
        serde_json::from_slice(&solve(&["--max-patches", "8", "--format", "json"])).unwrap();
    assert_eq!(doc["method"], "flat");
}

/// `view --web`: its help says what the folder holds and how to serve it; a missing wasm build fails before the
/// scene is read and says how to build it; a file that is not WebAssembly is refused. (The page itself:
/// `host/tests/web.rs`.)
#[test]
fn view_web_explains_itself_and_needs_the_wasm_build() {
    let help = radiosity(&["view", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    for expect in
        ["index.html", "scene.json", "python3 -m http.server -d DIR", "--wasm", "make web", "COST.md"]
    {
        assert!(help.contains(expect), "view --help lacks {expect:?}: {help}");
    }
    let dir = folder("view");
    let site = dir.join("site");
    let site = site.to_str().unwrap();
    let missing = dir.join("none.wasm");
    assert_fails(
        &["view", MISSING, "--web", site, "--wasm", missing.to_str().unwrap()],
        &["none.wasm", "cargo build -p radiosity-web", "make web"],
    );
    let fake = dir.join("fake.wasm");
    std::fs::write(&fake, "not wasm").unwrap();
    let cornell = scene("cornell-box.obj");
    let out = radiosity(&[
        "view",
        &cornell,
        "--no-subdivide",
        "--samples",
        "4",
        "--rays",
        "4",
        "-q",
        "--web",
        site,
        "--wasm",
        fake.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("not a WebAssembly module"), "{stderr}");
}

#[test]
fn hierarchical_bake_writes_a_table_that_inspect_reads() {
    let dir = folder("hierbake");
    let table = dir.join("h.rft");
    let table = table.to_str().unwrap();
    let out = radiosity(&[
        "bake",
        &scene("two-rooms.obj"),
        "-q",
        "--method",
        "hierarchical",
        "--epsilon",
        "0.1",
        "-o",
        table,
        "--format",
        "json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let bytes = std::fs::metadata(table).unwrap().len();
    assert_eq!(summary["bytes"].as_u64(), Some(bytes));
    assert!(summary["units_to_one_percent"].as_u64().is_some(), "the cold relight reaches 1%: {summary}");
    assert!(summary["error_floor"].as_f64().is_some(), "and converges: {summary}");
    let out = radiosity(&["inspect", table, "--format", "json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let inspected: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(inspected["format_version"], 4);
    assert_eq!(inspected["leaves"], summary["leaves"]);
    assert_eq!(inspected["nodes"], summary["nodes"]);
    // Each link is an entry in both ends' runs; a closed scene's (two rooms with no opening to the outside)
    // self-links are one entry each.
    assert_eq!(summary["closed"], true);
    assert!(summary["self_links"].as_u64().unwrap() > 0);
    assert_eq!(
        inspected["link_entries"].as_u64(),
        Some(2 * summary["links"].as_u64().unwrap() + summary["self_links"].as_u64().unwrap())
    );
    assert_eq!(inspected["solver_ram_f32"], summary["ram_f32"]);
    // A damaged table is refused by name, and the options of the other method are refused before any work.
    let mut damaged = std::fs::read(table).unwrap();
    damaged.truncate(damaged.len() / 2);
    std::fs::write(table, &damaged).unwrap();
    assert_fails(&["inspect", table], &["invalid hierarchical table", "truncated"]);
    assert_fails(
        &["bake", MISSING, "--method", "hierarchical", "--threshold", "0.01", "-o", table],
        &["--threshold"],
    );
    assert_fails(
        &["bake", MISSING, "--method", "flat", "--epsilon", "0.1", "-o", table],
        &["--max-links and --pieces apply"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `bake` and `check` without `--method`: the flat table when the scene's patch budget holds a 2 x 2 split of
/// each of its faces, the hierarchical one (with a note saying why) when it does not; a flat setting or a
/// hierarchy setting picks its own table whatever the budget, and `--method` wins over all of them.
#[test]
fn bake_and_check_pick_their_table_by_the_scenes_faces_against_its_budget() {
    let dir = folder("tablemethod");
    for f in ["facing-squares.obj", "facing-squares.mtl"] {
        std::fs::copy(scene(f), dir.join(f)).unwrap();
    }
    let obj = dir.join("facing-squares.obj").display().to_string();
    let table = dir.join("t.rft").display().to_string();
    // Two faces: a budget of 8 patches holds 4 per face, one of 7 does not.
    let run = |budget: usize, args: &[&str]| {
        std::fs::write(dir.join("facing-squares.toml"), format!("[meshing]\npatch_budget = {budget}\n"))
            .unwrap();
        let out = radiosity(&[args, &[obj.as_str(), "--format", "json"][..]].concat());
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{args:?} at budget {budget}: {stderr}");
        (serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap(), stderr)
    };
    let bake = |budget: usize, more: &[&str]| {
        let (summary, stderr) = run(budget, &[&["bake", "-o", table.as_str()][..], more].concat());
        // Only a hierarchical table's summary counts leaves.
        (summary.get("leaves").is_some(), stderr)
    };
    let note =
        "more than its flat mesh's patch budget (7) can split 4 ways each: making the hierarchical table";
    let (hierarchical, stderr) = bake(7, &[]);
    assert!(hierarchical && stderr.contains("has 2 faces") && stderr.contains(note), "{stderr}");
    let (hierarchical, stderr) = bake(8, &[]);
    assert!(!hierarchical && !stderr.contains("making the hierarchical table"), "{stderr}");
    assert!(!bake(7, &["--threshold", "0.001"]).0, "a flat setting asks for the flat table");
    assert!(!bake(7, &["--method", "flat"]).0);
    assert!(bake(8, &["--epsilon", "0.1"]).0, "a hierarchy setting asks for the hierarchy");
    assert!(bake(8, &["--method", "hierarchical"]).0);
    let (quiet, stderr) = bake(7, &["-q"]);
    assert!(quiet && stderr.is_empty(), "{stderr}");
    let check = |budget: usize| run(budget, &["check", "-q"]).0["method"].clone();
    assert_eq!((check(7), check(8)), (serde_json::json!("hierarchical"), serde_json::json!("flat")));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A hierarchy option out of range is refused before the scene is read (a large scene's repair takes a while):
/// with a scene path that does not exist, the error names the option, not the file.
#[test]
fn a_bad_hierarchy_option_is_refused_before_the_scene_is_read() {
    for (option, value) in
        [("--epsilon", "1"), ("--epsilon", "0"), ("--epsilon", "NaN"), ("--max-links", "0")]
    {
        let out = radiosity(&["solve", "/nonexistent/scene.obj", "-q", option, value]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{option} {value} was accepted");
        let name = option.trim_start_matches("--").replace('-', "_");
        assert!(
            err.contains(&format!("invalid hierarchy option {name}")) && !err.contains("nonexistent"),
            "{option} {value}: {err}"
        );
    }
}
