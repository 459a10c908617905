//! The host simulator: the device loop ([`crate::device`]) on the host, with the firmware's fixed buffers.
//!
//! Either table format runs: [`AnyTable::parse`] reads the version. The solver's buffers are core's
//! [`OwnedBuffers`] (flat) or [`HierOwnedBuffers`] (hierarchical), sized once by
//! [`BufferSizes::of`](radiosity_core::BufferSizes::of) or [`HierBufferSizes::of`] (the sizes the firmware's
//! build script gives its static buffers); after they are created the device loop allocates nothing. Output
//! (CSV rows, trace lines) is formatted by the caller's closures, outside the device loop.

use std::io::Write;

use radiosity_core::{
    BufferSizes, Fixed, HierBufferSizes, HierOwnedBuffers, HierTable, OwnedBuffers, Table, TableError,
    TransferTable,
};

use crate::device::{
    self, write_trace, Bits, DeviceSolver, DeviceTable, Frame, FrameRecord, NoMeter, RunError, Script,
};
use crate::script::{OwnedScript, ScriptFile};

/// The arithmetic a device run uses: the one name for it in the workspace (host's check, bench, relight and the
/// QEMU targets all use this type; text forms are `f32` and `fixed`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Arith {
    /// `f32` (Cortex-M4F with FPU).
    F32,
    /// [`Fixed`] Q32.32 (integer only, Cortex-M0).
    Fixed,
}

impl Arith {
    /// Both, in report order (f32 first).
    pub const ALL: [Arith; 2] = [Arith::F32, Arith::Fixed];

    /// The text form: `f32` or `fixed`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Arith::F32 => "f32",
            Arith::Fixed => "fixed",
        }
    }

    /// Parses `f32` or `fixed`.
    #[must_use]
    pub fn from_name(s: &str) -> Option<Arith> {
        Arith::ALL.into_iter().find(|a| a.name() == s)
    }
}

impl core::fmt::Display for Arith {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Arith {
    type Err = String;

    fn from_str(s: &str) -> Result<Arith, String> {
        Arith::from_name(s).ok_or_else(|| format!("unknown arithmetic {s:?} (expected f32 or fixed)"))
    }
}

/// A parsed table of either format: flat (version 3) or hierarchical (version 5).
#[derive(Clone, Copy, Debug)]
pub enum AnyTable<'a> {
    /// A flat table ([`Table`]): the elements are its patches.
    Flat(Table<'a>),
    /// A hierarchical table ([`HierTable`]): the elements are its leaves.
    Hier(HierTable<'a>),
}

impl<'a> AnyTable<'a> {
    /// Parses `bytes` as a flat table, or as a hierarchical one if [`Table::parse`] says it is one
    /// ([`TableError::HierarchicalTable`]).
    ///
    /// # Errors
    /// The parser's [`TableError`].
    pub fn parse(bytes: &'a [u8]) -> Result<AnyTable<'a>, TableError> {
        match Table::parse(bytes) {
            Ok(t) => Ok(AnyTable::Flat(t)),
            Err(TableError::HierarchicalTable) => HierTable::parse(bytes).map(AnyTable::Hier),
            Err(e) => Err(e),
        }
    }

    /// The format version: 3 (flat) or 4 (hierarchical).
    #[must_use]
    pub fn version(&self) -> u32 {
        match self {
            AnyTable::Flat(_) => u32::from(radiosity_core::FORMAT_VERSION),
            AnyTable::Hier(_) => u32::from(radiosity_core::HIER_FORMAT_VERSION),
        }
    }

    /// Elements whose radiosity the device shows (patches, or leaves).
    #[must_use]
    pub fn element_count(&self) -> u32 {
        match self {
            AnyTable::Flat(t) => t.patch_count(),
            AnyTable::Hier(t) => t.leaf_count(),
        }
    }

    /// Bytes of RAM the solver's buffers take with `arith` (core's `BufferSizes::bytes` or
    /// `HierBufferSizes::bytes`): the firmware's static buffers.
    #[must_use]
    pub fn buffer_bytes(&self, arith: Arith) -> usize {
        match (self, arith) {
            (AnyTable::Flat(t), Arith::F32) => BufferSizes::of(t).bytes::<f32>(),
            (AnyTable::Flat(t), Arith::Fixed) => BufferSizes::of(t).bytes::<Fixed>(),
            (AnyTable::Hier(t), Arith::F32) => HierBufferSizes::of(t).bytes::<f32>(),
            (AnyTable::Hier(t), Arith::Fixed) => HierBufferSizes::of(t).bytes::<Fixed>(),
        }
    }

    /// Whether the table carries a transfer basis (then the device loop also relights from it).
    #[must_use]
    pub fn has_transfer(&self) -> bool {
        match self {
            AnyTable::Flat(t) => t.transfer_section().is_some(),
            AnyTable::Hier(t) => t.transfer_section().is_some(),
        }
    }

    /// The table's light groups, for resolving relight scripts.
    #[must_use]
    pub fn groups(&self) -> crate::script::TableGroups {
        match self {
            AnyTable::Flat(t) => crate::script::TableGroups::of(t),
            AnyTable::Hier(t) => crate::script::TableGroups::of(t),
        }
    }

    /// [`DeviceTable::unit_light_power`] of the table.
    #[must_use]
    pub fn unit_light_power(&self) -> f32 {
        match self {
            AnyTable::Flat(t) => t.unit_light_power(),
            AnyTable::Hier(t) => t.unit_light_power(),
        }
    }
}

impl<'a> From<Table<'a>> for AnyTable<'a> {
    fn from(t: Table<'a>) -> AnyTable<'a> {
        AnyTable::Flat(t)
    }
}

impl<'a> From<&Table<'a>> for AnyTable<'a> {
    fn from(t: &Table<'a>) -> AnyTable<'a> {
        AnyTable::Flat(*t)
    }
}

impl<'a> From<HierTable<'a>> for AnyTable<'a> {
    fn from(t: HierTable<'a>) -> AnyTable<'a> {
        AnyTable::Hier(t)
    }
}

impl<'a> From<&HierTable<'a>> for AnyTable<'a> {
    fn from(t: &HierTable<'a>) -> AnyTable<'a> {
        AnyTable::Hier(*t)
    }
}

impl<'a> From<&AnyTable<'a>> for AnyTable<'a> {
    fn from(t: &AnyTable<'a>) -> AnyTable<'a> {
        *t
    }
}

/// What a script run produced, per script.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptSummary {
    /// Script name.
    pub name: String,
    /// Units of the boot solve.
    pub boot_units: u32,
    /// Frames run.
    pub frames: u32,
    /// Frames that ended converged.
    pub converged_frames: u32,
    /// Sum of units used over the frames.
    pub units_used: u64,
    /// Sum of budgets over the frames.
    pub units_budgeted: u64,
    /// Largest `used / budget` of a frame.
    pub max_fill: f64,
    /// Trace lines, one per frame (without the instruction field's meaning: 0 on the host).
    pub trace: Vec<String>,
    /// Trace lines of the transfer pass ([`device::run_transfer`]), one per relight; empty when the table has
    /// no transfer basis.
    pub transfer: Vec<String>,
}

/// Header of the per-frame, per-element CSV (`patch`: the flat table's patch, the hierarchical table's leaf).
pub const CSV_HEADER: &str =
    "arith,script,frame,budget,used,light_units,outcome,converged,unshot_r,unshot_g,unshot_b,\
unshot_r_bits,unshot_g_bits,unshot_b_bits,patch,b_r,b_g,b_b,b_r_bits,b_g_bits,b_b_bits";

fn csv_rows<S: Bits>(
    out: &mut dyn Write,
    script: &str,
    r: &FrameRecord<S>,
    solver: &impl DeviceSolver<Scalar = S>,
) -> std::io::Result<()> {
    let u = r.unshot;
    for i in 0..solver.element_count() {
        let b = solver.element_radiosity(i).unwrap_or([S::ZERO; 3]);
        writeln!(
            out,
            "{},{script},{},{},{},{},{},{},{:e},{:e},{:e},{:x},{:x},{:x},{i},{:e},{:e},{:e},{:x},{:x},{:x}",
            S::NAME,
            r.frame,
            r.budget,
            r.used,
            r.light_units,
            device::outcome_code(r.outcome),
            u8::from(r.converged()),
            u[0].to_f32(),
            u[1].to_f32(),
            u[2].to_f32(),
            u[0].bits(),
            u[1].bits(),
            u[2].bits(),
            b[0].to_f32(),
            b[1].to_f32(),
            b[2].to_f32(),
            b[0].bits(),
            b[1].bits(),
            b[2].bits()
        )?;
    }
    Ok(())
}

/// Why a simulation failed.
#[derive(Debug)]
pub enum SimError {
    /// The device loop failed.
    Run {
        /// Script.
        script: String,
        /// The error.
        error: RunError,
    },
    /// Writing the CSV failed.
    Io(std::io::Error),
    /// No script of that name.
    NoScript(String),
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Run { script, error } => write!(f, "script \"{script}\": {error}"),
            SimError::Io(e) => write!(f, "writing CSV: {e}"),
            SimError::NoScript(name) => write!(f, "no script named {name:?}"),
        }
    }
}

impl std::error::Error for SimError {}

/// Runs one script on `buffers` (the device loop), collecting its summary and CSV rows.
fn simulate_script<'a, T: DeviceTable<'a> + TransferTable, S: Bits + 'a>(
    table: &T,
    buffers: T::Buffers<S>,
    script: &Script<'_>,
    mut csv: Option<&mut (dyn Write + '_)>,
) -> Result<ScriptSummary, SimError> {
    let mut summary = ScriptSummary {
        name: script.name.to_string(),
        boot_units: 0,
        frames: 0,
        converged_frames: 0,
        units_used: 0,
        units_budgeted: 0,
        max_fill: 0.0,
        trace: Vec::with_capacity(script.frames.len()),
        transfer: Vec::new(),
    };
    let mut io_error = None;
    let result = device::run_script(table, buffers, script, &mut NoMeter, |r, solver| {
        summary.frames += 1;
        summary.converged_frames += u32::from(r.converged());
        summary.units_used += u64::from(r.used);
        summary.units_budgeted += u64::from(r.budget);
        summary.max_fill = summary.max_fill.max(f64::from(r.used) / f64::from(r.budget));
        let mut line = String::new();
        let _ = write_trace(&mut line, script.name, r);
        summary.trace.push(line);
        if let Some(w) = csv.as_deref_mut() {
            if let Err(e) = csv_rows(w, script.name, r, solver) {
                io_error.get_or_insert(e);
            }
        }
    });
    summary.boot_units = result.map_err(|error| SimError::Run { script: script.name.to_string(), error })?;
    if let Some(e) = io_error {
        return Err(SimError::Io(e));
    }
    if table.transfer_section().is_some() {
        let mut chunk = vec![[S::ZERO; 3]; device::TRANSFER_CHUNK];
        let mut intensity = vec![[S::ZERO; 3]; script.initial.len()];
        device::run_transfer(table, script, (&mut chunk, &mut intensity), &mut NoMeter, |r| {
            let mut line = String::new();
            let _ = device::write_transfer_trace::<S, _>(&mut line, script.name, r);
            summary.transfer.push(line);
        })
        .map_err(|error| SimError::Run { script: script.name.to_string(), error })?;
    }
    Ok(summary)
}

/// Runs `scripts` on `table` (either format) with arithmetic `S` in one set of owned buffers
/// ([`OwnedBuffers`] or [`HierOwnedBuffers`]), writing CSV rows to `csv` if given.
///
/// # Errors
/// [`SimError`].
pub fn simulate<'t, S: Bits>(
    table: impl Into<AnyTable<'t>>,
    scripts: &[&Script<'_>],
    mut csv: Option<&mut dyn Write>,
) -> Result<Vec<ScriptSummary>, SimError> {
    let mut out = Vec::with_capacity(scripts.len());
    match table.into() {
        AnyTable::Flat(table) => {
            let mut memory = OwnedBuffers::<S>::for_table(&table);
            for script in scripts {
                out.push(simulate_script(&table, memory.buffers(), script, csv.as_deref_mut())?);
            }
        }
        AnyTable::Hier(table) => {
            let mut memory = HierOwnedBuffers::<S>::for_table(&table);
            for script in scripts {
                out.push(simulate_script(&table, memory.buffers(), script, csv.as_deref_mut())?);
            }
        }
    }
    Ok(out)
}

/// [`simulate`] with the arithmetic chosen at run time.
///
/// # Errors
/// [`SimError`].
pub fn simulate_with<'t>(
    arith: Arith,
    table: impl Into<AnyTable<'t>>,
    scripts: &[&Script<'_>],
    csv: Option<&mut dyn Write>,
) -> Result<Vec<ScriptSummary>, SimError> {
    match arith {
        Arith::F32 => simulate::<f32>(table, scripts, csv),
        Arith::Fixed => simulate::<Fixed>(table, scripts, csv),
    }
}

/// [`simulate_with`] on the scripts of a parsed file (`only`: just the script of that name).
///
/// # Errors
/// [`SimError`]; a name that matches no script gives [`SimError::NoScript`].
pub fn simulate_file<'t>(
    arith: Arith,
    table: impl Into<AnyTable<'t>>,
    file: &ScriptFile,
    only: Option<&str>,
    csv: Option<&mut dyn Write>,
) -> Result<Vec<ScriptSummary>, SimError> {
    let selected: Vec<&OwnedScript> =
        file.scripts.iter().filter(|s| only.is_none_or(|n| n == s.name)).collect();
    if selected.is_empty() {
        return Err(SimError::NoScript(only.unwrap_or_default().to_string()));
    }
    let frames: Vec<Vec<Frame<'_>>> = selected
        .iter()
        .map(|s| s.frames.iter().map(|f| Frame { budget: f.budget, intensity: &f.intensity }).collect())
        .collect();
    let views: Vec<Script<'_>> = selected
        .iter()
        .zip(&frames)
        .map(|(s, f)| Script {
            name: &s.name,
            tolerance: s.tolerance,
            initial: &s.initial,
            boot_budget: s.boot_budget,
            frames: f,
        })
        .collect();
    let refs: Vec<&Script<'_>> = views.iter().collect();
    simulate_with(arith, table, &refs, csv)
}
