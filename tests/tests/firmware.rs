//! The firmware end to end: build it for the Cortex-M4 (f32 and fixed point), run every shipped relight script
//! under QEMU, and check that it agrees with the host simulator bit for bit on every frame, that no frame
//! spends more than its budget, that the SysTick instruction count is calibrated, that the cost model
//! fitted on one script bounds every frame of every script, and that static RAM plus the stack's measured
//! high-water mark fit the board's RAM. A build that faults on purpose checks that the HardFault handler reports
//! and exits with a failure status instead of hanging.
//!
//! Needs `qemu-system-arm` (installed by `make deps`); without it the test fails and says so.

use std::path::PathBuf;

use firmware_sim::qemu::{self, QemuLog, Target};
use firmware_sim::script::ScriptFile;
use firmware_sim::sim::{self, AnyTable};
use radiosity_core::Table;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn run(target: Target) {
    let scripts = root().join("scenes/cornell-box.relight.toml");
    run_table(target, &root().join("firmware-sim/tables/uniform-enclosure.rft"), &scripts, true);
}

/// Builds and runs the firmware on `table_path` with the scripts of `scripts_path`; `cost_model`: also fit the
/// cost model on `budget-sweep` and check that it bounds every frame.
fn run_table(target: Target, table_path: &std::path::Path, scripts_path: &std::path::Path, cost_model: bool) {
    let bytes = std::fs::read(table_path).unwrap();
    let table = AnyTable::parse(&bytes).unwrap();
    let scripts = ScriptFile::load(scripts_path).and_then(|s| s.resolve(&table.groups())).unwrap();

    let elf = qemu::build_firmware(target, table_path, scripts_path).unwrap_or_else(|e| panic!("{e}"));
    let (text, ok) = qemu::run_qemu(target, &elf, 120).unwrap_or_else(|e| panic!("{e}"));
    let log = QemuLog::parse(&text).unwrap();
    assert!(ok && log.done_ok, "firmware failed under QEMU: {:?}\n{text}", log.errors);

    // Calibration: a loop of known length. Each of the two measurements (loop, empty) is quantized to one
    // SysTick tick (40 instructions on mps2-an386, 62.5 on microbit), so their difference is within 2 ticks
    // of the truth.
    let (expected, measured) = log.calibration.expect("no CAL line");
    let two_ticks = if target.triple.starts_with("thumbv6m") { 125 } else { 80 };
    assert!(
        expected.abs_diff(measured) <= two_ticks,
        "SysTick calibration: expected {expected}, measured {measured}"
    );

    // Bit-exact agreement on every frame of every script.
    let host = sim::simulate_file(target.arith, table, &scripts, None, None).unwrap();
    let (frames, transfers) = qemu::compare(&host, &log).unwrap_or_else(|e| panic!("{e}"));
    let expected_frames: usize = scripts.scripts.iter().map(|s| s.frames.len()).sum();
    assert_eq!(frames, expected_frames);
    // A table with a transfer basis is also relit from it at every script's states, bit-exact as well.
    assert_eq!(transfers > 0, table.has_transfer(), "transfer relights compared: {transfers}");

    // Static RAM plus the stack's high-water mark fit the board's RAM (the memory map the firmware links with).
    let stack = log.stack.expect("no STACK line");
    assert!(stack.high_water > 0 && stack.high_water < stack.size, "{stack:?}");
    let sizes = qemu::Sizes::of(&elf).unwrap_or_else(|e| panic!("{e}"));
    let board_ram = qemu::board_ram(target).unwrap_or_else(|e| panic!("{e}"));
    qemu::check_ram(sizes.ram, stack, board_ram).unwrap_or_else(|e| panic!("{e}"));

    // No frame spends more than its budget, on the device.
    for f in &log.frames {
        assert!(f.used <= f.budget, "{}: used {} > budget {}", f.script, f.used, f.budget);
    }

    // The cost model fitted on `budget-sweep` bounds every frame of every script.
    if !cost_model {
        return;
    }
    let model = firmware_sim::cost::calibrate("test", &log, "budget-sweep").unwrap();
    assert!(model.per_unit > 0.0, "{model:?}");
    assert_eq!(model.violations, 0, "frames over the cost model's bound: {model:?}");
}

#[test]
fn cortex_m4_f32_matches_host_bit_for_bit() {
    run(qemu::M4_F32);
}

#[test]
fn cortex_m4_fixed_point_matches_host_bit_for_bit() {
    run(qemu::M4_FIXED);
}

/// The committed hierarchical (format version 5) table, `firmware-sim/tables/hierarchical-enclosure.rft`: the
/// firmware's build script sizes `HierStaticBuffers` from it and every frame agrees with the host simulator.
fn run_hierarchical(target: Target) {
    let scripts = root().join("scenes/cornell-box.relight.toml");
    run_table(target, &root().join("firmware-sim/tables/hierarchical-enclosure.rft"), &scripts, true);
}

#[test]
fn cortex_m4_f32_hierarchical_table_matches_host_bit_for_bit() {
    run_hierarchical(qemu::M4_F32);
}

#[test]
fn cortex_m4_fixed_point_hierarchical_table_matches_host_bit_for_bit() {
    run_hierarchical(qemu::M4_FIXED);
}

#[test]
fn cortex_m0_fixed_point_hierarchical_table_matches_host_bit_for_bit() {
    run_hierarchical(qemu::M0_FIXED);
}

/// The enclosure with four light groups (`firmware-sim/tables/four-lights.rft` and its scripts): the device loop
/// and the transfer relight with several groups agree with the host bit for bit.
#[test]
fn cortex_m4_f32_four_light_groups_match_host_bit_for_bit() {
    let dir = root().join("firmware-sim/tables");
    run_table(qemu::M4_F32, &dir.join("four-lights.rft"), &dir.join("four-lights.relight.toml"), false);
}

/// A table where only some patches carry run-time state (`scenes/two-rooms.obj`: 101 of 202): the firmware's
/// buffers are sized by the state count and it still agrees with the host bit for bit.
#[test]
fn cortex_m4_f32_partial_state_table_matches_host() {
    use radiosity_host::bake::{bake, BakeInput, BakeOptions};
    use radiosity_host::pipeline::{prepare, PrepareOptions};
    let options = PrepareOptions::quiet(false, 4, 4);
    let p = prepare(&root().join("scenes/two-rooms.obj"), &options).unwrap();
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions::default()).unwrap();
    let table = Table::parse(&baked.table).unwrap();
    assert!(table.state_count() < table.patch_count(), "the scene must leave patches without state");
    let path = std::env::temp_dir().join(format!("radiosity-two-rooms-{}.rft", std::process::id()));
    std::fs::write(&path, &baked.table).unwrap();
    // The Cornell box's scripts with its light group's name changed to two-rooms' dynamic group, `lamp`.
    let cornell = std::fs::read_to_string(root().join("scenes/cornell-box.relight.toml")).unwrap();
    let lamp = cornell.replace("{ light = [", "{ lamp = [");
    assert_ne!(lamp, cornell);
    let scripts =
        std::env::temp_dir().join(format!("radiosity-two-rooms-{}.relight.toml", std::process::id()));
    std::fs::write(&scripts, lamp).unwrap();
    // Bit-exact agreement and budgets only: the cost model is calibrated and checked on the synthetic table
    // (on this table the fit from `budget-sweep` need not bound every `lights-on` frame).
    run_table(qemu::M4_F32, &path, &scripts, false);
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&scripts);
}

/// The `fault-test` build executes an undefined instruction after boot: the HardFault handler must print the
/// faulting registers and exit with a failure status (QEMU would otherwise spin until the timeout).
#[test]
fn cortex_m4_hard_fault_reports_and_exits_with_failure() {
    let table_path = root().join("firmware-sim/tables/uniform-enclosure.rft");
    let scripts_path = root().join("scenes/cornell-box.relight.toml");
    let elf = qemu::build_fault_test_firmware(qemu::M4_F32, &table_path, &scripts_path)
        .unwrap_or_else(|e| panic!("{e}"));
    let (text, ok) = qemu::run_qemu(qemu::M4_F32, &elf, 20).unwrap_or_else(|e| panic!("{e}"));
    assert!(!ok, "the faulting firmware exited with success:\n{text}");
    let log = QemuLog::parse(&text).unwrap();
    assert!(log.calibration.is_some(), "the firmware faulted before booting:\n{text}");
    assert!(log.frames.is_empty() && !log.done_ok, "the firmware ran past the fault:\n{text}");
    let report =
        log.errors.iter().find(|e| e.starts_with("E,hardfault,")).unwrap_or_else(|| panic!("{text}"));
    assert!(report.starts_with("E,hardfault,pc=0x"), "{report}");
}
