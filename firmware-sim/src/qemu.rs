//! Building the firmware, running it under QEMU, and reading its semihosting output.
//!
//! The firmware prints one line per event (all fields comma-separated):
//! - `CAL,<instructions expected>,<instructions measured>`: the SysTick calibration loop at boot;
//! - `B,<arith>,<script>,<boot units>`: a script's boot solve;
//! - `F,...`: a frame, as [`crate::device::write_trace`] formats it (the last field is instructions);
//! - `E,<script>,<message>`: a script failed;
//! - `DONE,<failures>`: the end; the exit status is 0 if no script failed.

use std::path::{Path, PathBuf};
use std::process::Command;

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

/// The firmware's cargo workspace: `firmware-sim/firmware`.
#[must_use]
pub fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware")
}

/// Builds the firmware for `target` (release) with the table at `table` and the scripts at `scripts`; returns
/// the ELF path.
///
/// # Errors
/// A message with cargo's output if the build fails.
pub fn build_firmware(target: Target, table: &Path, scripts: &Path) -> Result<PathBuf, String> {
    let dir = firmware_dir();
    // The firmware's build script runs in the firmware workspace, so relative paths must be made absolute here.
    let absolute =
        |p: &Path| std::fs::canonicalize(p).map_err(|e| format!("cannot find {}: {e}", p.display()));
    let (table, scripts) = (absolute(table)?, absolute(scripts)?);
    let target_dir = dir.join("target").join(target.arith.name());
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(&dir)
        .args(["build", "--release", "--target", target.triple])
        .arg("--target-dir")
        .arg(&target_dir)
        .env("RADIOSITY_TABLE", table)
        .env("RADIOSITY_SCRIPTS", scripts)
        // The root workspace's settings must not leak into the firmware's build.
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS");
    if target.arith == Arith::Fixed {
        cmd.args(["--features", "fixed"]);
    }
    let out = cmd.output().map_err(|e| format!("cannot run cargo for the firmware: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "firmware build for {} failed:\n{}",
            target.triple,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(target_dir.join(target.triple).join("release").join("radiosity-firmware"))
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

/// The firmware's output, parsed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct QemuLog {
    /// `(expected, measured)` instructions of the calibration loop.
    pub calibration: Option<(u64, u64)>,
    /// Frame lines in order.
    pub frames: Vec<QemuFrame>,
    /// `E` lines.
    pub errors: Vec<String>,
    /// Whether `DONE,0` was seen.
    pub done_ok: bool,
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
    /// A malformed `F` or `CAL` line.
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
                "E" => log.errors.push(line.to_string()),
                "DONE" => log.done_ok = parts.get(1) == Some(&"0"),
                _ => {}
            }
        }
        Ok(log)
    }
}

/// Compares the host simulator's trace with the firmware's, frame by frame, every field but instructions.
/// Returns the number of frames compared.
///
/// # Errors
/// The first difference (script, frame, both lines), or a differing frame count.
pub fn compare(host: &[ScriptSummary], qemu: &QemuLog) -> Result<usize, String> {
    let host_lines: Vec<&str> = host.iter().flat_map(|s| s.trace.iter().map(String::as_str)).collect();
    for (k, (h, q)) in host_lines.iter().zip(&qemu.frames).enumerate() {
        let h_key = h.rsplit_once(',').map_or(*h, |(a, _)| a);
        if h_key != q.key {
            return Err(format!("frame line {k} differs:\n  host: {h_key}\n  qemu: {}", q.key));
        }
    }
    if host_lines.len() != qemu.frames.len() {
        return Err(format!(
            "host simulated {} frames, the firmware reported {} (errors: {:?})",
            host_lines.len(),
            qemu.frames.len(),
            qemu.errors
        ));
    }
    Ok(host_lines.len())
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

/// What [`check_firmware`] found: the firmware's log, its sizes and how many frames agreed bit for bit with the
/// host simulator.
#[derive(Clone, Debug)]
pub struct Checked {
    /// The parsed serial log.
    pub log: QemuLog,
    /// Flash and static RAM of the ELF.
    pub sizes: Sizes,
    /// Frames compared (all of them agreed: a disagreement is an error).
    pub frames_bit_exact: usize,
}

/// Builds the firmware for `target` with `table` and `scripts` compiled in, runs it under QEMU (at most
/// `timeout_s` seconds; `on_output` sees the raw serial output as soon as QEMU ends, whatever follows), and
/// compares every frame with the host simulator's run of the same table and scripts: the one QEMU check behind
/// `firmware-sim run --qemu` and `radiosity relight --qemu`.
///
/// # Errors
/// A build, QEMU or size-tool failure, a firmware that reports errors or does not finish, a host simulation
/// failure, or the first frame where firmware and host disagree.
pub fn check_firmware(
    target: Target,
    table: &radiosity_core::Table<'_>,
    scripts: &crate::script::ScriptFile,
    (table_path, scripts_path): (&Path, &Path),
    timeout_s: u32,
    on_output: impl FnOnce(&str) -> Result<(), String>,
) -> Result<Checked, String> {
    let elf = build_firmware(target, table_path, scripts_path)?;
    let sizes = Sizes::of(&elf)?;
    let (text, ok) = run_qemu(target, &elf, timeout_s)?;
    on_output(&text)?;
    let log = QemuLog::parse(&text)?;
    if !ok || !log.done_ok || !log.errors.is_empty() {
        return Err(format!("the firmware failed under QEMU (errors: {:?})", log.errors));
    }
    let host =
        crate::sim::simulate_file(target.arith, table, scripts, None, None).map_err(|e| e.to_string())?;
    let frames_bit_exact = compare(&host, &log)?;
    Ok(Checked { log, sizes, frames_bit_exact })
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
