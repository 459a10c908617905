//! `firmware-sim`: the host simulator of the radiosity firmware, and the driver of its QEMU runs.
//!
//! ```text
//! firmware-sim gen-table OUT.rft
//! firmware-sim run   [--table T] [--scripts S] [--arith f32|fixed] [--script NAME] [--csv OUT]
//! firmware-sim qemu  [--table T] [--scripts S] [--target m4-f32|m4-fixed|m0-fixed] [--timeout SECONDS] [--log OUT]
//! firmware-sim cost  --log LOG [--log LOG ...] [--calibrate SCRIPT] [--clock-mhz MHZ] [--out COST.md]
//! ```
//! Defaults: the committed synthetic table `firmware-sim/tables/uniform-enclosure.rft` and the Cornell box's
//! scripts `scenes/cornell-box.relight.toml`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use firmware_sim::cost::{self, CostModel};
use firmware_sim::qemu::{self, QemuLog, Target};
use firmware_sim::script::ScriptFile;
use firmware_sim::sim::{self, Arith, ScriptSummary};
use radiosity_core::Table;

const USAGE: &str = "The radiosity device loop on the host, and its Cortex-M firmware under QEMU.

usage:
  firmware-sim gen-table OUT.rft     write the synthetic test table
  firmware-sim run   ...             run relight scripts on the host simulator (per-frame CSV with --csv)
  firmware-sim qemu  ...             build the firmware, run it under QEMU, compare with the host bit for bit
  firmware-sim cost  ...             fit and check the cost model from QEMU logs

  firmware-sim gen-table OUT.rft
  firmware-sim run   [--table T] [--scripts S] [--arith f32|fixed] [--script NAME] [--csv OUT]
  firmware-sim qemu  [--table T] [--scripts S] [--target m4-f32|m4-fixed|m0-fixed] [--timeout SECONDS] [--log OUT]
  firmware-sim cost  --log LOG [--log LOG ...] [--calibrate SCRIPT] [--clock-mhz MHZ] [--out COST.md]";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() || args.iter().any(|a| a == "--help" || a == "-h" || a == "help") {
        println!("{USAGE}");
        return ExitCode::SUCCESS;
    }
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Options: `--name value` pairs (repeatable) after the subcommand and its positional arguments.
struct Opts {
    positional: Vec<String>,
    named: Vec<(String, String)>,
}

impl Opts {
    fn parse(args: &[String], known: &[&str]) -> Result<Opts, String> {
        let mut o = Opts { positional: Vec::new(), named: Vec::new() };
        let mut it = args.iter();
        while let Some(a) = it.next() {
            if let Some(name) = a.strip_prefix("--") {
                if name == "help" {
                    return Err(USAGE.into());
                }
                if !known.contains(&name) {
                    return Err(format!("unknown option --{name}\n{USAGE}"));
                }
                let v = it.next().ok_or_else(|| format!("--{name} needs a value"))?;
                o.named.push((name.to_string(), v.clone()));
            } else {
                o.positional.push(a.clone());
            }
        }
        Ok(o)
    }
    fn get(&self, name: &str) -> Option<&str> {
        self.named.iter().rev().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }
    fn all(&self, name: &str) -> Vec<&str> {
        self.named.iter().filter(|(n, _)| n == name).map(|(_, v)| v.as_str()).collect()
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn default_table() -> PathBuf {
    root().join("firmware-sim/tables/uniform-enclosure.rft")
}

fn default_scripts() -> PathBuf {
    root().join("scenes/cornell-box.relight.toml")
}

fn load(o: &Opts) -> Result<(PathBuf, Vec<u8>, PathBuf, ScriptFile), String> {
    let table_path = o.get("table").map_or_else(default_table, PathBuf::from);
    let scripts_path = o.get("scripts").map_or_else(default_scripts, PathBuf::from);
    let bytes = std::fs::read(&table_path)
        .map_err(|e| format!("{}: cannot read table: {e}", table_path.display()))?;
    let table = Table::parse(&bytes).map_err(|e| format!("{}: {e}", table_path.display()))?;
    let scripts = ScriptFile::load(&scripts_path).map_err(|e| e.to_string())?;
    scripts.check_table(table.group_count()).map_err(|e| format!("{}: {e}", scripts_path.display()))?;
    Ok((table_path, bytes, scripts_path, scripts))
}

fn simulate(
    arith: Arith,
    bytes: &[u8],
    scripts: &ScriptFile,
    only: Option<&str>,
    csv: Option<&mut dyn std::io::Write>,
) -> Result<Vec<ScriptSummary>, String> {
    let table = Table::parse(bytes).map_err(|e| e.to_string())?;
    sim::simulate_file(arith, &table, scripts, only, csv).map_err(|e| e.to_string())
}

fn print_summary(arith: Arith, summaries: &[ScriptSummary]) {
    println!(
        "script,arith,frames,converged_frames,boot_units,units_used,units_budgeted,max_used_over_budget"
    );
    for s in summaries {
        println!(
            "{},{},{},{},{},{},{},{:.3}",
            s.name,
            arith,
            s.frames,
            s.converged_frames,
            s.boot_units,
            s.units_used,
            s.units_budgeted,
            s.max_fill
        );
    }
}

fn run(args: &[String]) -> Result<(), String> {
    let Some(cmd) = args.first() else { return Err(USAGE.into()) };
    let rest = &args[1..];
    match cmd.as_str() {
        "gen-table" => {
            let o = Opts::parse(rest, &[])?;
            let out =
                o.positional.first().ok_or_else(|| format!("gen-table needs an output path\n{USAGE}"))?;
            let blob = firmware_sim::synthetic::default_table().map_err(|e| e.to_string())?;
            std::fs::write(out, &blob).map_err(|e| format!("{out}: {e}"))?;
            println!("wrote {out} ({} bytes)", blob.len());
            Ok(())
        }
        "run" => {
            let o = Opts::parse(rest, &["table", "scripts", "arith", "script", "csv"])?;
            let (_, bytes, _, scripts) = load(&o)?;
            let arith = Arith::from_name(o.get("arith").unwrap_or("f32"))
                .ok_or_else(|| "--arith must be f32 or fixed".to_string())?;
            let mut file = match o.get("csv") {
                Some(p) => {
                    Some(std::io::BufWriter::new(std::fs::File::create(p).map_err(|e| format!("{p}: {e}"))?))
                }
                None => None,
            };
            if let Some(f) = file.as_mut() {
                use std::io::Write;
                writeln!(f, "{}", sim::CSV_HEADER).map_err(|e| e.to_string())?;
            }
            let summaries = simulate(
                arith,
                &bytes,
                &scripts,
                o.get("script"),
                file.as_mut().map(|f| f as &mut dyn std::io::Write),
            )?;
            print_summary(arith, &summaries);
            Ok(())
        }
        "qemu" => {
            let o = Opts::parse(rest, &["table", "scripts", "target", "timeout", "log"])?;
            let (table_path, bytes, scripts_path, scripts) = load(&o)?;
            let target = match o.get("target").unwrap_or("m4-f32") {
                "m4-f32" => qemu::M4_F32,
                "m4-fixed" => qemu::M4_FIXED,
                "m0-fixed" => qemu::M0_FIXED,
                t => return Err(format!("unknown --target {t} (m4-f32, m4-fixed, m0-fixed)")),
            };
            let timeout: u32 =
                o.get("timeout").unwrap_or("120").parse().map_err(|_| "--timeout: seconds".to_string())?;
            qemu_run(target, &table_path, &scripts_path, &bytes, &scripts, timeout, o.get("log"))
        }
        "cost" => {
            let o = Opts::parse(rest, &["log", "calibrate", "clock-mhz", "out"])?;
            let logs = o.all("log");
            if logs.is_empty() {
                return Err(format!("cost needs at least one --log\n{USAGE}"));
            }
            let mut parsed = Vec::new();
            for l in &logs {
                let text = std::fs::read_to_string(l).map_err(|e| format!("{l}: {e}"))?;
                let name = Path::new(l)
                    .file_stem()
                    .map_or_else(|| l.to_string(), |s| s.to_string_lossy().into_owned());
                parsed.push((name, QemuLog::parse(&text).map_err(|e| format!("{l}: {e}"))?));
            }
            let clock: f64 =
                o.get("clock-mhz").unwrap_or("100").parse().map_err(|_| "--clock-mhz: a number")?;
            let calibrate = o.get("calibrate").unwrap_or("budget-sweep");
            let report = cost::report(&parsed, calibrate, clock)?;
            match o.get("out") {
                Some(p) => std::fs::write(p, &report.markdown).map_err(|e| format!("{p}: {e}"))?,
                None => print!("{}", report.markdown),
            }
            if report.violations > 0 {
                return Err(format!("{} frames exceed the cost model's bound", report.violations));
            }
            let _: &[CostModel] = &report.models;
            Ok(())
        }
        _ => Err(format!("unknown subcommand {cmd:?}\n{USAGE}")),
    }
}

fn qemu_run(
    target: Target,
    table_path: &Path,
    scripts_path: &Path,
    bytes: &[u8],
    scripts: &ScriptFile,
    timeout: u32,
    log: Option<&str>,
) -> Result<(), String> {
    let elf = qemu::build_firmware(target, table_path, scripts_path)?;
    if let Ok(out) = std::process::Command::new("arm-none-eabi-size").arg("-A").arg(&elf).output() {
        let sizes = qemu::Sizes::parse(&String::from_utf8_lossy(&out.stdout));
        println!(
            "size: {} ({:?}, {} bytes of table): flash {} bytes, RAM {} bytes (static; the stack comes on top)",
            target.triple,
            target.arith,
            bytes.len(),
            sizes.flash,
            sizes.ram
        );
    }
    let (text, ok) = qemu::run_qemu(target, &elf, timeout)?;
    if let Some(p) = log {
        std::fs::write(p, &text).map_err(|e| format!("{p}: {e}"))?;
    }
    let parsed = QemuLog::parse(&text)?;
    if !ok || !parsed.done_ok {
        return Err(format!("firmware failed under QEMU (errors: {:?})", parsed.errors));
    }
    if let Some((expected, measured)) = parsed.calibration {
        println!("SysTick calibration: loop of {expected} instructions measured as {measured}");
    }
    let host = simulate(target.arith, bytes, scripts, None, None)?;
    let n = qemu::compare(&host, &parsed)?;
    println!("bit-exact: host simulator and QEMU agree on all {n} frames ({:?})", target.arith);
    Ok(())
}
