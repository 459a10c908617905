//! `firmware-sim`: the host simulator of the radiosity firmware, and the driver of its QEMU runs.
//!
//! ```text
//! firmware-sim gen-table OUT.rft [--hierarchical]
//! firmware-sim run   [--table T] [--scripts S] [--arith f32|fixed] [--script NAME] [--csv OUT]
//! firmware-sim qemu  [--table T] [--scripts S] [--target m4-f32|m4-fixed|m0-fixed] [--timeout SECONDS] [--log OUT]
//! firmware-sim cost  --log LOG [--log LOG ...] [--calibrate SCRIPT] [--clock-mhz MHZ] [--out COST.md]
//!                    [--table T [--scripts S]]
//! ```
//! Defaults: the committed synthetic table `firmware-sim/tables/uniform-enclosure.rft` and the Cornell box's
//! scripts `scenes/cornell-box.relight.toml`. All command-line parsing (clap) lives in this file; the library
//! modules take plain values.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};

use firmware_sim::cost;
use firmware_sim::qemu::{self, QemuLog, Target};
use firmware_sim::script::ScriptFile;
use firmware_sim::sim::{self, AnyTable, Arith, ScriptSummary};

/// The radiosity device loop on the host, and its Cortex-M firmware under QEMU.
#[derive(Debug, Parser)]
#[command(name = "firmware-sim", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write a synthetic test table (default: the flat uniform enclosure).
    GenTable {
        /// Output path of the table.
        #[arg(value_name = "OUT.rft")]
        out: PathBuf,
        /// Write the hierarchical (format version 5) enclosure instead
        /// (firmware-sim/tables/hierarchical-enclosure.rft).
        #[arg(long, conflicts_with = "four_lights")]
        hierarchical: bool,
        /// Write the enclosure with four light groups of one patch each instead
        /// (firmware-sim/tables/four-lights.rft).
        #[arg(long)]
        four_lights: bool,
    },
    /// Run relight scripts on the host simulator (summary on stdout, per-frame CSV with --csv).
    Run {
        #[command(flatten)]
        input: Input,
        /// Arithmetic of the device solver: f32 or fixed.
        #[arg(long, value_name = "f32|fixed", default_value_t = Arith::F32)]
        arith: Arith,
        /// Run only the script of this name.
        #[arg(long, value_name = "NAME")]
        script: Option<String>,
        /// Write every frame as a CSV row to this file.
        #[arg(long, value_name = "OUT")]
        csv: Option<PathBuf>,
    },
    /// Build the firmware, run it under QEMU, compare with the host bit for bit, check RAM use (static + stack).
    Qemu {
        #[command(flatten)]
        input: Input,
        /// The firmware build and the machine it runs on.
        #[arg(long, value_enum, default_value_t = TargetName::M4F32)]
        target: TargetName,
        /// Seconds QEMU may run before it is stopped.
        #[arg(long, value_name = "SECONDS", default_value_t = 120)]
        timeout: u32,
        /// Write QEMU's output (the firmware's trace) to this file.
        #[arg(long, value_name = "OUT")]
        log: Option<PathBuf>,
    },
    /// Fit and check the cost model from QEMU logs (fails if a frame exceeds the model's bound).
    Cost {
        /// A QEMU log (`qemu --log`); repeat for every build. The build is named after the file's stem.
        #[arg(long = "log", value_name = "LOG", required = true)]
        logs: Vec<PathBuf>,
        /// A QEMU log of another table whose transfer relights join the report's transfer section (e.g. the
        /// four-light enclosure, for the cost per light group); not calibrated. Repeatable.
        #[arg(long = "transfer-log", value_name = "LOG")]
        transfer_logs: Vec<PathBuf>,
        /// The script whose frames calibrate the model.
        #[arg(long, value_name = "SCRIPT", default_value = "budget-sweep")]
        calibrate: String,
        /// Clock of the device, for the time columns.
        #[arg(long, value_name = "MHZ", default_value_t = 100.0)]
        clock_mhz: f64,
        /// Write the report (markdown) to this file instead of stdout.
        #[arg(long, value_name = "COST.md")]
        out: Option<PathBuf>,
        /// The table the logs ran (with --scripts): a hierarchical one adds the split of instructions into
        /// per link, per node judged, per node swept and per shot, from the host's count of each frame's work.
        #[arg(long, value_name = "T")]
        table: Option<PathBuf>,
        /// The relight scripts the logs ran (default: scenes/cornell-box.relight.toml); used with --table.
        #[arg(long, value_name = "S")]
        scripts: Option<PathBuf>,
        /// Report frames over the bound (in the report and on stderr) without failing: for measuring rates on
        /// a table the device does not ship, where a frame over the bound is a finding, not a broken build.
        #[arg(long)]
        report_over_bound: bool,
        /// With a hierarchical --table: write every frame's work (links, nodes judged and swept, shots, light
        /// units), instructions, rate bound and margin to this CSV file, to see which frames come near the bound.
        #[arg(long, value_name = "CSV")]
        frames: Option<PathBuf>,
    },
}

/// The table and the relight scripts a run uses.
#[derive(Debug, Args)]
struct Input {
    /// The table (default: the committed synthetic table firmware-sim/tables/uniform-enclosure.rft).
    #[arg(long, value_name = "T")]
    table: Option<PathBuf>,
    /// The relight scripts (default: scenes/cornell-box.relight.toml).
    #[arg(long, value_name = "S")]
    scripts: Option<PathBuf>,
}

/// `--target` values: the firmware builds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum TargetName {
    /// Cortex-M4F (mps2-an386), f32.
    #[value(name = "m4-f32")]
    M4F32,
    /// Cortex-M4F (mps2-an386), fixed point.
    #[value(name = "m4-fixed")]
    M4Fixed,
    /// Cortex-M0 (BBC micro:bit), fixed point.
    #[value(name = "m0-fixed")]
    M0Fixed,
}

impl TargetName {
    fn target(self) -> Target {
        match self {
            TargetName::M4F32 => qemu::M4_F32,
            TargetName::M4Fixed => qemu::M4_FIXED,
            TargetName::M0Fixed => qemu::M0_FIXED,
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse().command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A table and its scripts, read and checked against each other.
struct Loaded {
    table_path: PathBuf,
    bytes: Vec<u8>,
    scripts_path: PathBuf,
    scripts: ScriptFile,
}

impl Input {
    fn load(&self) -> Result<Loaded, String> {
        let table_path =
            self.table.clone().unwrap_or_else(|| root().join("firmware-sim/tables/uniform-enclosure.rft"));
        let scripts_path =
            self.scripts.clone().unwrap_or_else(|| root().join("scenes/cornell-box.relight.toml"));
        let bytes = std::fs::read(&table_path)
            .map_err(|e| format!("{}: cannot read table: {e}", table_path.display()))?;
        let table = AnyTable::parse(&bytes).map_err(|e| format!("{}: {e}", table_path.display()))?;
        let scripts = ScriptFile::load(&scripts_path).map_err(|e| e.to_string())?;
        let scripts =
            scripts.resolve(&table.groups()).map_err(|e| format!("{}: {e}", scripts_path.display()))?;
        Ok(Loaded { table_path, bytes, scripts_path, scripts })
    }
}

fn simulate(
    arith: Arith,
    bytes: &[u8],
    scripts: &ScriptFile,
    only: Option<&str>,
    csv: Option<&mut dyn Write>,
) -> Result<Vec<ScriptSummary>, String> {
    let table = AnyTable::parse(bytes).map_err(|e| e.to_string())?;
    sim::simulate_file(arith, table, scripts, only, csv).map_err(|e| e.to_string())
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

/// `path: error` for a file that cannot be read or written.
fn file_err(path: &Path) -> impl Fn(std::io::Error) -> String + '_ {
    move |e| format!("{}: {e}", path.display())
}

fn run(command: Command) -> Result<(), String> {
    match command {
        Command::GenTable { out, hierarchical, four_lights } => {
            let blob = if hierarchical {
                firmware_sim::synthetic::default_hierarchical_table()
            } else if four_lights {
                firmware_sim::synthetic::four_lights_table()
            } else {
                firmware_sim::synthetic::default_table()
            }
            .map_err(|e| e.to_string())?;
            std::fs::write(&out, &blob).map_err(file_err(&out))?;
            println!("wrote {} ({} bytes)", out.display(), blob.len());
            Ok(())
        }
        Command::Run { input, arith, script, csv } => {
            let loaded = input.load()?;
            let mut file = match &csv {
                Some(p) => Some(std::io::BufWriter::new(std::fs::File::create(p).map_err(file_err(p))?)),
                None => None,
            };
            if let Some(f) = file.as_mut() {
                writeln!(f, "{}", sim::CSV_HEADER).map_err(|e| e.to_string())?;
            }
            let summaries = simulate(
                arith,
                &loaded.bytes,
                &loaded.scripts,
                script.as_deref(),
                file.as_mut().map(|f| f as &mut dyn Write),
            )?;
            print_summary(arith, &summaries);
            Ok(())
        }
        Command::Qemu { input, target, timeout, log } => {
            qemu_run(target.target(), &input.load()?, timeout, log.as_deref())
        }
        Command::Cost {
            logs,
            transfer_logs,
            calibrate,
            clock_mhz,
            out,
            table,
            scripts,
            report_over_bound,
            frames,
        } => {
            let parse = |paths: &[PathBuf]| -> Result<Vec<(String, QemuLog)>, String> {
                paths
                    .iter()
                    .map(|l| {
                        let text = std::fs::read_to_string(l).map_err(file_err(l))?;
                        let name = l
                            .file_stem()
                            .map_or_else(|| l.display().to_string(), |s| s.to_string_lossy().into_owned());
                        Ok((name, QemuLog::parse(&text).map_err(|e| format!("{}: {e}", l.display()))?))
                    })
                    .collect()
            };
            let parsed = parse(&logs)?;
            let report = cost::report(&parsed, &parse(&transfer_logs)?, &calibrate, clock_mhz)?;
            let mut markdown = report.markdown.clone();
            let mut violations = report.violations;
            if frames.is_some() && table.is_none() {
                return Err("--frames needs the hierarchical --table the logs ran".to_string());
            }
            if table.is_some() {
                let loaded = Input { table, scripts }.load()?;
                if let AnyTable::Hier(t) = AnyTable::parse(&loaded.bytes).map_err(|e| e.to_string())? {
                    let (section, over, csv) =
                        cost::hier_split_report(&parsed, &t, &loaded.scripts, &calibrate)?;
                    markdown.push_str(&section);
                    if let Some(p) = &frames {
                        std::fs::write(p, csv).map_err(file_err(p))?;
                    }
                    // A hierarchical frame's units are links, nodes judged and swept and shots of different
                    // costs, so a frame whose mix differs from the calibration's can pass the one-rate bound; the
                    // rate bound is the one checked, and the one-rate table above stays as information.
                    if report.violations > 0 {
                        markdown.push_str(&format!(
                            "\nThe one-rate model's bound (first table) is exceeded by {} frames of this hierarchical \
                             table: its units mix links, nodes judged, nodes swept and shots, whose costs differ; \
                             frames are checked against the rate bound above instead.\n",
                            report.violations
                        ));
                    }
                    violations = over;
                } else if frames.is_some() {
                    return Err("--frames needs a hierarchical --table (format version 5)".to_string());
                }
            }
            match &out {
                Some(p) => std::fs::write(p, &markdown).map_err(file_err(p))?,
                None => print!("{markdown}"),
            }
            if violations > 0 && report_over_bound {
                eprintln!(
                    "warning: {violations} frames exceed the cost model's bounds (reported, not failed)"
                );
            } else if violations > 0 {
                return Err(format!("{violations} frames exceed the cost model's bounds"));
            }
            Ok(())
        }
    }
}

fn qemu_run(target: Target, loaded: &Loaded, timeout: u32, log: Option<&Path>) -> Result<(), String> {
    let table = AnyTable::parse(&loaded.bytes).map_err(|e| e.to_string())?;
    let paths = (loaded.table_path.as_path(), loaded.scripts_path.as_path());
    // The log is written as soon as QEMU ends, so a failed run can be read.
    let write_log = |text: &str| match log {
        Some(p) => std::fs::write(p, text).map_err(file_err(p)),
        None => Ok(()),
    };
    let checked = qemu::check_firmware(target, table, &loaded.scripts, paths, timeout, write_log)?;
    let (flash, ram, stack) = (checked.sizes.flash, checked.sizes.ram, checked.stack.high_water);
    println!(
        "size: {} ({:?}, {} bytes of table): flash {flash} bytes, RAM {ram} bytes static + {stack} bytes stack \
         (high-water mark under QEMU) = {} of the board's {} bytes",
        target.triple,
        target.arith,
        loaded.bytes.len(),
        ram + stack,
        checked.board_ram
    );
    println!(
        "table: format version {}, {} {}, solver buffers {} bytes of the static RAM",
        table.version(),
        table.element_count(),
        if table.version() == u32::from(radiosity_core::HIER_FORMAT_VERSION) { "leaves" } else { "patches" },
        table.buffer_bytes(target.arith)
    );
    if let Some((expected, measured)) = checked.log.calibration {
        println!("SysTick calibration: loop of {expected} instructions measured as {measured}");
    }
    let n = checked.frames_bit_exact;
    println!("bit-exact: host simulator and QEMU agree on all {n} frames ({:?})", target.arith);
    if checked.transfers_bit_exact > 0 {
        let t = &checked.log.transfers;
        let worst = t.iter().map(|x| x.instructions as f64 / f64::from(x.units.max(1))).fold(0.0, f64::max);
        println!(
            "transfer relights: {} bit-exact, {} units each, at most {worst:.1} instructions per unit (elements x \
             (groups + 1))",
            checked.transfers_bit_exact,
            t.first().map_or(0, |x| x.units)
        );
    }
    Ok(())
}
