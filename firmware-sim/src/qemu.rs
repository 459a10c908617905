//! Building the firmware, running it under QEMU, and reading its semihosting output.
//!
//! The firmware prints one line per event (all fields comma-separated):
//! - `CAL,<instructions expected>,<instructions measured>`: the SysTick calibration loop at boot;
//! - `B,<arith>,<script>,<boot units>`: a script's boot solve;
//! - `F,...`: a frame, as [`crate::device::write_trace`] formats it (the last field is instructions);
//! - `X,...`: a transfer relight (tables with a transfer basis: after the scripts, each script's states
//!   relit from the basis), as [`crate::device::write_transfer_trace`] formats it (the last field is
//!   instructions);
//! - `E,<script>,<message>`: a script failed; `E,panic,<message>` and `E,hardfault,<registers>` (the
//!   registers stacked by the fault: `pc=0x... lr=0x... xpsr=0x... r0=...`) end the run with a failure status;
//! - `STACK,<high-water bytes>,<stack region bytes>`: after the last script, the stack's high-water mark (the
//!   bytes of the painted stack region whose paint was overwritten, counted from its top) and the size of the
//!   region (from the end of the statics to the end of RAM);
//! - `DONE,<failures>`: the end; the exit status is 0 if no script failed.
//!
//! [`check_ram`] holds static RAM plus the stack's high-water mark against the board's RAM, as the firmware's
//! linker memory map (`firmware/memory-*.x`, [`board_ram`]) gives it.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::sim::{Arith, ScriptSummary};

/// One target the firmware is built for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    /// Rust target triple.
    pub triple: &'static str,
    /// Arithmetic (the firmware's cargo feature `fixed` for [`Arith::Fixed`]).
    pub arith: Arith,
    /// QEMU machine and CPU arguments.
    pub machine: &'static [&'static str],
}

/// Flash and RAM a board gives the firmware: the budget its linker script (`firmware/memory-*.x`) enforces, so
/// a table that does not fit fails the build. A test reads the numbers back from the linker scripts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Board {
    /// What the board is, for messages.
    pub name: &'static str,
    /// The linker script, in `firmware/`.
    pub linker_script: &'static str,
    /// Flash in bytes: the firmware's code, its constants and the table.
    pub flash: u64,
    /// RAM in bytes: the solver's buffers, the firmware's statics and the stack.
    pub ram: u64,
}

/// The Cortex-M4 board of `make demo` and `relight --qemu` (QEMU's mps2-an386, budgeted at 512 KiB of flash and
/// 64 KiB of RAM).
pub const MPS2_AN386: Board = Board {
    name: "Cortex-M4 (mps2-an386)",
    linker_script: "memory-mps2-an386.x",
    flash: 512 * 1024,
    ram: 64 * 1024,
};
/// The Cortex-M0 board (BBC micro:bit, nRF51: 256 KiB of flash, 16 KiB of RAM).
pub const MICROBIT: Board = Board {
    name: "Cortex-M0 (micro:bit)",
    linker_script: "memory-microbit.x",
    flash: 256 * 1024,
    ram: 16 * 1024,
};

/// Cortex-M4F (mps2-an386), f32.
pub const M4_F32: Target = Target {
    triple: "thumbv7em-none-eabihf",
    arith: Arith::F32,
    machine: &["-machine", "mps2-an386", "-cpu", "cortex-m4"],
};
/// Cortex-M4F (mps2-an386), fixed point.
pub const M4_FIXED: Target = Target {
    triple: "thumbv7em-none-eabihf",
    arith: Arith::Fixed,
    machine: &["-machine", "mps2-an386", "-cpu", "cortex-m4"],
};
/// Cortex-M0 (BBC micro:bit, nRF51), fixed point.
pub const M0_FIXED: Target =
    Target { triple: "thumbv6m-none-eabi", arith: Arith::Fixed, machine: &["-machine", "microbit"] };

/// The linker memory map (in `firmware/`) of the board a target triple runs on: the micro:bit's for the
/// Cortex-M0 (`thumbv6m`), mps2-an386's otherwise. The firmware's build script and [`board_ram`] both ask here.
#[must_use]
pub fn memory_map(triple: &str) -> &'static str {
    if triple.starts_with("thumbv6m") {
        "memory-microbit.x"
    } else {
        "memory-mps2-an386.x"
    }
}

/// The firmware's cargo workspace: `firmware-sim/firmware`.
#[must_use]
pub fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware")
}

/// Builds the firmware for `target` (release) with the table at `table` and the scripts at `scripts`; returns
/// the path of a copy of the ELF that no later build (another thread's, with another table) overwrites.
///
/// # Errors
/// A message with cargo's output if the build fails.
pub fn build_firmware(target: Target, table: &Path, scripts: &Path) -> Result<PathBuf, String> {
    cargo_build(target, table, scripts, false)
}

/// Builds the firmware for `target` with the feature `fault-test`: it executes an undefined instruction right
/// after the calibration line, so its HardFault handler must report and exit with a failure status. A `dev`
/// profile build (cheaper than release), whose ELF lies beside the release one, never in its place.
///
/// # Errors
/// A message with cargo's output if the build fails.
pub fn build_fault_test_firmware(target: Target, table: &Path, scripts: &Path) -> Result<PathBuf, String> {
    cargo_build(target, table, scripts, true)
}

/// Held from a firmware build until its ELF is copied out: the builds of one target share cargo's output path,
/// and two threads building it with different tables (parallel tests) would otherwise each run the other's.
static BUILD: Mutex<()> = Mutex::new(());

/// Numbers the copied ELFs of this process.
static BUILDS: AtomicUsize = AtomicUsize::new(0);

/// Builds as described at [`build_firmware`] and returns a copy of the ELF that no later build overwrites
/// (`elf/` beside cargo's output, named by the process and a counter).
fn cargo_build(target: Target, table: &Path, scripts: &Path, fault_test: bool) -> Result<PathBuf, String> {
    // A thread that panicked while holding the lock left nothing half-done that matters here.
    let _guard = BUILD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let built = cargo_build_locked(target, table, scripts, fault_test)?;
    let dir = built.parent().and_then(Path::parent).map_or_else(|| PathBuf::from("."), |p| p.join("elf"));
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    remove_stale_copies(&dir);
    let copy = dir.join(format!(
        "radiosity-firmware-{}-{}{}",
        std::process::id(),
        BUILDS.fetch_add(1, Ordering::Relaxed),
        if fault_test { "-fault-test" } else { "" }
    ));
    std::fs::copy(&built, &copy)
        .map_err(|e| format!("cannot copy the firmware {} to {}: {e}", built.display(), copy.display()))?;
    Ok(copy)
}

/// Removes the ELF copies of processes that have ended (their id no longer under `/proc`), so that the copies do
/// not pile up; nothing is removed where `/proc` does not exist.
fn remove_stale_copies(dir: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let pid = name
            .to_str()
            .and_then(|n| n.strip_prefix("radiosity-firmware-"))
            .and_then(|n| n.split('-').next());
        if let Some(pid) = pid.filter(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit())) {
            if !Path::new("/proc").join(pid).exists() {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

fn cargo_build_locked(
    target: Target,
    table: &Path,
    scripts: &Path,
    fault_test: bool,
) -> Result<PathBuf, String> {
    let dir = firmware_dir();
    // The firmware's build script runs in the firmware workspace, so relative paths must be made absolute here.
    let absolute =
        |p: &Path| std::fs::canonicalize(p).map_err(|e| format!("cannot find {}: {e}", p.display()));
    let (table, scripts) = (absolute(table)?, absolute(scripts)?);
    let target_dir = dir.join("target").join(target.arith.name());
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    let profile = if fault_test { "dev" } else { "release" };
    cmd.current_dir(&dir)
        .args(["build", "--profile", profile, "--target", target.triple])
        .arg("--target-dir")
        .arg(&target_dir)
        .env("RADIOSITY_TABLE", table)
        .env("RADIOSITY_SCRIPTS", scripts)
        // The root workspace's settings must not leak into the firmware's build.
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS");
    let features: Vec<&str> = [(target.arith == Arith::Fixed, "fixed"), (fault_test, "fault-test")]
        .into_iter()
        .filter_map(|(on, name)| on.then_some(name))
        .collect();
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    let out = cmd.output().map_err(|e| format!("cannot run cargo for the firmware: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "firmware build for {} failed:\n{}",
            target.triple,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    // Cargo puts the `dev` profile's output in `debug/`.
    let profile_dir = if fault_test { "debug" } else { "release" };
    Ok(target_dir.join(target.triple).join(profile_dir).join("radiosity-firmware"))
}

/// QEMU's `-icount` setting: `shift=0`, one instruction per nanosecond of virtual time, so SysTick (25 MHz on
/// mps2-an386) advances one tick per 40 instructions.
pub const ICOUNT: &str = "shift=0,align=off,sleep=off";

/// Runs `elf` under `qemu-system-arm` for `target`, killed after `timeout_s` seconds; returns its output and
/// whether it exited with status 0.
///
/// # Errors
/// A message saying QEMU is missing (install it with `make deps`) or did not finish.
pub fn run_qemu(target: Target, elf: &Path, timeout_s: u32) -> Result<(String, bool), String> {
    let probe = Command::new("qemu-system-arm").arg("--version").output();
    if probe.is_err() {
        return Err("qemu-system-arm not found: install it with `make deps` (scripts/deps.sh)".into());
    }
    let out = Command::new("timeout")
        .arg(timeout_s.to_string())
        .arg("qemu-system-arm")
        .args(target.machine)
        .args(["-nographic", "-semihosting-config", "enable=on,target=native", "-icount", ICOUNT, "-kernel"])
        .arg(elf)
        .output()
        .map_err(|e| format!("cannot run qemu-system-arm: {e}"))?;
    if out.status.code() == Some(124) {
        return Err(format!("QEMU did not finish within {timeout_s} s ({})", elf.display()));
    }
    Ok((String::from_utf8_lossy(&out.stdout).into_owned(), out.status.success()))
}

/// A frame line of the firmware's output, split.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QemuFrame {
    /// The line without its last field (what must match the host).
    pub key: String,
    /// Script name.
    pub script: String,
    /// Budget (work units).
    pub budget: u32,
    /// Units used by the step.
    pub used: u32,
    /// Units of the light changes.
    pub light_units: u32,
    /// Instructions measured.
    pub instructions: u64,
}

/// A transfer-relight line of the firmware's output, split.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QemuTransfer {
    /// The line without its last field (what must match the host).
    pub key: String,
    /// Script name.
    pub script: String,
    /// The state relit: `None` the script's initial intensities, `Some(k)` frame `k`'s.
    pub frame: Option<u32>,
    /// Work units of the relight.
    pub units: u32,
    /// Elements relit.
    pub elements: u32,
    /// Light groups.
    pub groups: u32,
    /// Instructions measured.
    pub instructions: u64,
}

/// The firmware's output, parsed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct QemuLog {
    /// `(expected, measured)` instructions of the calibration loop.
    pub calibration: Option<(u64, u64)>,
    /// Frame lines in order.
    pub frames: Vec<QemuFrame>,
    /// Transfer-relight lines in order.
    pub transfers: Vec<QemuTransfer>,
    /// `E` lines.
    pub errors: Vec<String>,
    /// Whether `DONE,0` was seen.
    pub done_ok: bool,
    /// The stack's use (`STACK` line).
    pub stack: Option<StackUse>,
}

/// The stack's use as the firmware measured it by painting (the `STACK` line).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StackUse {
    /// Bytes from the top of the stack down to the deepest word whose paint was overwritten.
    pub high_water: u64,
    /// Bytes of the stack region: RAM above the statics.
    pub size: u64,
}

fn field<T: std::str::FromStr>(parts: &[&str], k: usize, line: &str) -> Result<T, String> {
    parts
        .get(k)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("firmware output: field {k} missing or malformed in line {line:?}"))
}

impl QemuLog {
    /// Parses the firmware's output (other lines are ignored).
    ///
    /// # Errors
    /// A malformed `F`, `CAL` or `STACK` line.
    pub fn parse(text: &str) -> Result<QemuLog, String> {
        let mut log = QemuLog::default();
        for line in text.lines() {
            let parts: Vec<&str> = line.trim_end().split(',').collect();
            match parts[0] {
                "CAL" => log.calibration = Some((field(&parts, 1, line)?, field(&parts, 2, line)?)),
                "F" => {
                    if parts.len() != 13 {
                        return Err(format!(
                            "firmware output: frame line has {} fields: {line:?}",
                            parts.len()
                        ));
                    }
                    log.frames.push(QemuFrame {
                        key: parts[..12].join(","),
                        script: parts[2].to_string(),
                        budget: field(&parts, 4, line)?,
                        used: field(&parts, 5, line)?,
                        light_units: field(&parts, 6, line)?,
                        instructions: field(&parts, 12, line)?,
                    });
                }
                "X" => {
                    if parts.len() != 9 {
                        return Err(format!(
                            "firmware output: transfer line has {} fields: {line:?}",
                            parts.len()
                        ));
                    }
                    log.transfers.push(QemuTransfer {
                        key: parts[..8].join(","),
                        script: parts[2].to_string(),
                        frame: u32::try_from(field::<i64>(&parts, 3, line)?).ok(),
                        units: field(&parts, 4, line)?,
                        elements: field(&parts, 5, line)?,
                        groups: field(&parts, 6, line)?,
                        instructions: field(&parts, 8, line)?,
                    });
                }
                "E" => log.errors.push(line.to_string()),
                "STACK" => {
                    log.stack =
                        Some(StackUse { high_water: field(&parts, 1, line)?, size: field(&parts, 2, line)? });
                }
                "DONE" => log.done_ok = parts.get(1) == Some(&"0"),
                _ => {}
            }
        }
        Ok(log)
    }
}

/// Compares the host simulator's trace with the firmware's, frame by frame and transfer relight by transfer
/// relight, every field but instructions. Returns the numbers of frames and of transfer relights compared.
///
/// # Errors
/// The first difference (both lines), or a differing count.
pub fn compare(host: &[ScriptSummary], qemu: &QemuLog) -> Result<(usize, usize), String> {
    let frames = host.iter().flat_map(|s| s.trace.iter().map(String::as_str));
    let frames = compare_lines("frame", frames, qemu.frames.iter().map(|f| f.key.as_str()), &qemu.errors)?;
    let transfers = host.iter().flat_map(|s| s.transfer.iter().map(String::as_str));
    let qemu_transfers = qemu.transfers.iter().map(|t| t.key.as_str());
    let transfers = compare_lines("transfer relight", transfers, qemu_transfers, &qemu.errors)?;
    Ok((frames, transfers))
}

/// Compares host trace lines (with their last field, instructions, which is dropped) with the firmware's keys.
fn compare_lines<'h, 'q>(
    what: &str,
    host: impl Iterator<Item = &'h str>,
    qemu: impl Iterator<Item = &'q str>,
    errors: &[String],
) -> Result<usize, String> {
    let host: Vec<&str> = host.map(|h| h.rsplit_once(',').map_or(h, |(a, _)| a)).collect();
    let qemu: Vec<&str> = qemu.collect();
    if let Some(k) = host.iter().zip(&qemu).position(|(h, q)| h != q) {
        return Err(format!("{what} line {k} differs:\n  host: {}\n  qemu: {}", host[k], qemu[k]));
    }
    if host.len() != qemu.len() {
        return Err(format!(
            "host simulated {} {what}s, the firmware reported {} (errors: {errors:?})",
            host.len(),
            qemu.len()
        ));
    }
    Ok(host.len())
}

/// Flash and RAM use of a firmware ELF, from `arm-none-eabi-size -A`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sizes {
    /// Flash: `.vector_table`, `.text`, `.rodata` and `.data`'s initial values.
    pub flash: u64,
    /// Static RAM: `.data`, `.bss`, `.uninit` (the stack comes on top).
    pub ram: u64,
}

impl Sizes {
    /// Parses `arm-none-eabi-size -A` output (section, size, address per line).
    #[must_use]
    pub fn parse(text: &str) -> Sizes {
        let mut s = Sizes::default();
        for line in text.lines() {
            let mut parts = line.split_whitespace();
            let (Some(name), Some(size)) = (parts.next(), parts.next().and_then(|v| v.parse::<u64>().ok()))
            else {
                continue;
            };
            match name {
                ".vector_table" | ".text" | ".rodata" => s.flash += size,
                ".data" => {
                    s.flash += size;
                    s.ram += size;
                }
                ".bss" | ".uninit" => s.ram += size,
                _ => {}
            }
        }
        s
    }
}

impl Sizes {
    /// The sizes of `elf`, by `arm-none-eabi-size -A`.
    ///
    /// # Errors
    /// If the tool cannot be run (it comes with `make deps`).
    pub fn of(elf: &Path) -> Result<Sizes, String> {
        let out = Command::new("arm-none-eabi-size")
            .arg("-A")
            .arg(elf)
            .output()
            .map_err(|e| format!("cannot run arm-none-eabi-size (install it with `make deps`): {e}"))?;
        Ok(Sizes::parse(&String::from_utf8_lossy(&out.stdout)))
    }
}

/// The length of the `RAM` region in a GNU ld `MEMORY` block (`RAM : ORIGIN = ..., LENGTH = 64K`), in bytes:
/// decimal or `0x` hexadecimal, with an optional `K` or `M` suffix. `None` if there is no such line.
#[must_use]
pub fn parse_ram_length(script: &str) -> Option<u64> {
    let line = script.lines().find(|l| l.split_whitespace().next() == Some("RAM"))?;
    let value = line.split("LENGTH").nth(1)?.trim_start().strip_prefix('=')?;
    let value = value.split([',', '}']).next()?.trim();
    let (digits, scale) = match value.as_bytes().last()? {
        b'K' | b'k' => (&value[..value.len() - 1], 1024),
        b'M' | b'm' => (&value[..value.len() - 1], 1024 * 1024),
        _ => (value, 1),
    };
    let n = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    n.checked_mul(scale)
}

/// The RAM of the board `target` runs on, in bytes: the `RAM` length of its linker memory map
/// ([`memory_map`]), the same file the firmware is linked with.
///
/// # Errors
/// The file cannot be read or has no `RAM` length.
pub fn board_ram(target: Target) -> Result<u64, String> {
    let path = firmware_dir().join(memory_map(target.triple));
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse_ram_length(&text).ok_or_else(|| format!("{}: no `RAM ... LENGTH = ...` line", path.display()))
}

/// Checks that the firmware fits the board's RAM: static RAM (`.data`, `.bss`, `.uninit`) plus the stack's
/// high-water mark at most `board_ram`, and paint left at the bottom of the stack region (a stack that
/// reached the statics may have overwritten them, and the mark only says "all of it").
///
/// # Errors
/// Which of the two failed, with the numbers.
pub fn check_ram(static_ram: u64, stack: StackUse, board_ram: u64) -> Result<(), String> {
    if stack.high_water >= stack.size {
        return Err(format!(
            "the stack reached the bottom of its {} byte region (the statics): it may have overflowed",
            stack.size
        ));
    }
    let total = static_ram.saturating_add(stack.high_water);
    if total > board_ram {
        return Err(format!(
            "static RAM {static_ram} bytes + stack {} bytes = {total} bytes exceed the board's {board_ram} bytes",
            stack.high_water
        ));
    }
    Ok(())
}

/// What [`check_firmware`] found: the firmware's log, its sizes and how many frames agreed bit for bit with the
/// host simulator.
#[derive(Clone, Debug)]
pub struct Checked {
    /// The parsed serial log.
    pub log: QemuLog,
    /// Flash and static RAM of the ELF.
    pub sizes: Sizes,
    /// The stack's use under QEMU.
    pub stack: StackUse,
    /// The board's RAM ([`board_ram`]), which static RAM plus the stack fit in.
    pub board_ram: u64,
    /// Frames compared (all of them agreed: a disagreement is an error).
    pub frames_bit_exact: usize,
    /// Transfer relights compared (0 for a table without a transfer basis; all agreed).
    pub transfers_bit_exact: usize,
}

/// Refuses a table whose solver buffers alone (`table.buffer_bytes`, what the firmware's statics hold) exceed
/// the board's RAM, before a build would end in a linker error.
///
/// # Errors
/// A message naming the buffers' size, the formula's source and the board's RAM.
pub fn check_buffers_fit(target: Target, table: &crate::sim::AnyTable<'_>) -> Result<(), String> {
    let board_ram = board_ram(target)?;
    let buffers = table.buffer_bytes(target.arith) as u64;
    if buffers > board_ram {
        let (what, formula) = match table {
            crate::sim::AnyTable::Flat(_) => ("flat (version 3)", "BufferSizes::bytes"),
            crate::sim::AnyTable::Hier(_) => ("hierarchical (version 5)", "HierBufferSizes::bytes"),
        };
        return Err(format!(
            "the {what} table's solver buffers need {buffers} bytes of RAM in {} ({formula}, {} elements), more \
             than the {} bytes of RAM of {}'s board ({}): use a smaller table or another target",
            target.arith,
            table.element_count(),
            board_ram,
            target.triple,
            memory_map(target.triple)
        ));
    }
    Ok(())
}

/// Builds the firmware for `target` with `table` and `scripts` compiled in, runs it under QEMU (at most
/// `timeout_s` seconds; `on_output` sees the raw serial output as soon as QEMU ends, whatever follows), and
/// compares every frame with the host simulator's run of the same table and scripts: the one QEMU check behind
/// `firmware-sim run --qemu` and `radiosity relight --qemu`.
///
/// # Errors
/// A table whose buffers cannot fit the board ([`check_buffers_fit`]), a build, QEMU or size-tool failure, a
/// firmware that reports errors or does not finish or does not fit the board's RAM ([`check_ram`]), a host
/// simulation failure, or the first frame where firmware and host disagree.
pub fn check_firmware<'t>(
    target: Target,
    table: impl Into<crate::sim::AnyTable<'t>>,
    scripts: &crate::script::ScriptFile,
    (table_path, scripts_path): (&Path, &Path),
    timeout_s: u32,
    on_output: impl FnOnce(&str) -> Result<(), String>,
) -> Result<Checked, String> {
    let table = table.into();
    check_buffers_fit(target, &table)?;
    let elf = build_firmware(target, table_path, scripts_path)?;
    let sizes = Sizes::of(&elf)?;
    let (text, ok) = run_qemu(target, &elf, timeout_s)?;
    on_output(&text)?;
    let log = QemuLog::parse(&text)?;
    if !ok || !log.done_ok || !log.errors.is_empty() {
        return Err(format!("the firmware failed under QEMU (errors: {:?})", log.errors));
    }
    let stack = log.stack.ok_or("the firmware did not report its stack use (no STACK line)")?;
    let board_ram = board_ram(target)?;
    check_ram(sizes.ram, stack, board_ram)
        .map_err(|e| format!("{} ({:?}): {e}", target.triple, target.arith))?;
    let host =
        crate::sim::simulate_file(target.arith, table, scripts, None, None).map_err(|e| e.to_string())?;
    let (frames_bit_exact, transfers_bit_exact) = compare(&host, &log)?;
    Ok(Checked { log, sizes, stack, board_ram, frames_bit_exact, transfers_bit_exact })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ram_length_from_memory_maps() {
        let script = "MEMORY\n{\n  FLASH : ORIGIN = 0x00000000, LENGTH = 512K\n  RAM   : ORIGIN = 0x20000000, LENGTH = 64K\n}\n";
        assert_eq!(parse_ram_length(script), Some(64 * 1024));
        assert_eq!(parse_ram_length("RAM : ORIGIN = 0x20000000, LENGTH = 0x4000\n"), Some(0x4000));
        assert_eq!(parse_ram_length("RAM (rwx) : ORIGIN = 0x20000000, LENGTH = 1M }"), Some(1 << 20));
        assert_eq!(parse_ram_length("FLASH : ORIGIN = 0, LENGTH = 512K\n"), None);
        assert_eq!(parse_ram_length("RAM : ORIGIN = 0x20000000, LENGTH = lots\n"), None);
        // The committed maps: the budgets the build script's docs state.
        assert_eq!(board_ram(M4_F32), Ok(64 * 1024));
        assert_eq!(board_ram(M0_FIXED), Ok(16 * 1024));
    }

    #[test]
    fn ram_check_fails_when_static_plus_stack_exceed_the_board() {
        let ram = 16 * 1024;
        let stack = |high_water| StackUse { high_water, size: 12 * 1024 };
        assert_eq!(check_ram(4096, stack(2048), ram), Ok(()));
        assert_eq!(check_ram(4096, stack(ram - 4096), ram).map_err(|_| ()), Err(()), "bottom reached");
        assert_eq!(
            check_ram(4096, stack(12 * 1024 - 4), ram),
            Ok(()),
            "exactly the board's RAM minus a word"
        );
        let err = check_ram(8192, stack(9000), ram).unwrap_err();
        assert!(err.contains("exceed the board's 16384 bytes"), "{err}");
    }

    #[test]
    fn buffers_that_cannot_fit_the_board_are_refused_by_size() {
        use radiosity_core::{
            hier_required_len, write_hier_table, FfCodec, GroupSpec, HierSpec, HierTable, NodeSpec,
            PatchSpec, RowsSpec,
        };
        // A hierarchical table of one root over 600 leaves (no links), in fixed point (`HierBufferSizes::bytes`):
        // 24 bytes of incident power per leaf, 24 of unshot power per node, 48 for the inner node's pending and
        // reflected entries, two 56-byte sweep frames and one material: over the micro:bit's 16 KiB, within the
        // Cortex-M4's 64 KiB.
        let n = 600u32;
        let nodes: Vec<NodeSpec> = (0..=n).map(|k| NodeSpec { parent: (k > 0).then_some(0) }).collect();
        let leaf = PatchSpec { area: 1.0, material: 0, base_emission: [0.0; 3], base_irradiance: [0.0; 3] };
        let row_start = vec![0u32; n as usize + 2];
        let spec = HierSpec {
            nodes: &nodes,
            leaves: &vec![leaf; n as usize],
            materials: &[[0.5; 3]],
            groups: &[] as &[GroupSpec<'_>],
            links: RowsSpec { row_start: &row_start, receiver: &[], form_factor: &[] },
            codec: FfCodec::FLOAT16,
            base_solved: false,
            fingerprint: 0,
            transfer: None,
        };
        let mut blob = vec![0u8; hier_required_len(&spec).unwrap()];
        let len = write_hier_table(&spec, &mut blob).unwrap();
        let table = crate::sim::AnyTable::from(HierTable::parse(&blob[..len]).unwrap());
        assert_eq!(table.buffer_bytes(Arith::Fixed), 600 * 24 + 601 * 24 + 48 + 2 * 56 + 6);
        let err = check_buffers_fit(M0_FIXED, &table).unwrap_err();
        assert!(err.contains("28990 bytes") && err.contains("16384 bytes"), "{err}");
        assert!(err.contains("HierBufferSizes::bytes"), "{err}");
        assert_eq!(check_buffers_fit(M4_FIXED, &table), Ok(()));
        assert_eq!(check_buffers_fit(M4_F32, &table), Ok(()));
    }

    #[test]
    fn stack_line_parses() {
        let log = QemuLog::parse("CAL,10,10\nSTACK,1234,60000\nDONE,0\n").unwrap();
        assert_eq!(log.stack, Some(StackUse { high_water: 1234, size: 60000 }));
        assert!(log.done_ok);
        assert!(QemuLog::parse("STACK,12x,60000\n").is_err());
        assert_eq!(QemuLog::parse("DONE,0\n").unwrap().stack, None);
    }
}

#[cfg(test)]
mod board_tests {
    use super::{firmware_dir, Board, MICROBIT, MPS2_AN386};

    /// `LENGTH = <n>K` of the memory region `region` in a linker script, in bytes.
    fn length(script: &str, region: &str) -> u64 {
        let line = script.lines().find(|l| l.trim_start().starts_with(region)).expect("region");
        let value = line.split("LENGTH").nth(1).expect("LENGTH").trim_start_matches([' ', '=']).trim();
        let kib: u64 = value.trim_end_matches('K').parse().expect("a size in K");
        kib * 1024
    }

    #[test]
    fn board_budgets_are_the_linker_scripts() {
        for board in [MPS2_AN386, MICROBIT] {
            let Board { linker_script, flash, ram, .. } = board;
            let script = std::fs::read_to_string(firmware_dir().join(linker_script)).expect("linker script");
            assert_eq!(length(&script, "FLASH"), flash, "{linker_script}");
            assert_eq!(length(&script, "RAM"), ram, "{linker_script}");
        }
    }
}
