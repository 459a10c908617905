//! `radiosity relight`: a relight script run the way the device runs it, every frame compared with the exact answer.
//!
//! The device side is `firmware-sim`'s device loop ([`firmware_sim::device::run_script`]): the same code the
//! Cortex-M firmware links, with the table parsed in place and the solver state in fixed buffers sized from the
//! table. It runs on the host in `f32` and in Q32.32 fixed point; optionally the firmware itself is built with
//! the same table and scripts and run under QEMU (Cortex-M4, `mps2-an386`, `-icount shift=0`), which adds the
//! instructions each frame took and proves the host run is bit-exact with the device's.
//!
//! The exact answer of a frame is the f64 relighting of the scene's own form-factor matrix (unsparsified,
//! unquantized): `B = B_static + sum_g I_g T_g` with the frame's intensities `I_g` ([`TransferVectors`](crate::reference::TransferVectors)). The
//! per-frame error therefore holds every source at once: form-factor estimation is the only one left out (the
//! matrix is the same estimate), while sparsification, quantization, iteration truncation at the frame's budget
//! and arithmetic are all in it. `radiosity check` separates them.

use std::fmt;
use std::path::{Path, PathBuf};

use firmware_sim::device::{self, Bits, DeviceSolver, DeviceTable, NoMeter};
use firmware_sim::qemu::{self, QemuLog, Target};
use firmware_sim::script::{OwnedScript, ScriptFile, TableGroups};
use firmware_sim::sim::{self, Arith};
use radiosity_core::{relight_transfer, Fixed, HierTable, Table, TransferTable};
use serde::Serialize;
use thiserror::Error;

use crate::bake::BakedHierarchy;
use crate::formfactor::FormFactorError;
use crate::hierarchy::{dense_on_leaves, DenseError, HierarchicalSolution};
use crate::metrics::{self, ErrorReport, MetricsError};
use crate::picture::render::{trace_view, write_frame_sequence, Frame};
use crate::picture::shading::{ShadingOptions, SmoothShader};
use crate::picture::PictureError;
use crate::pipeline::Prepared;
use crate::reference::{exact_transfer, Method, ReferenceError};
use crate::rgb::Rgb;
use crate::scene::Scene;
use crate::view::{default_camera, PatchTracer, ViewError};

/// Why a relight run failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RelightError {
    /// The table does not parse.
    #[error("table: {0}")]
    Table(radiosity_core::TableError),
    /// The table was not baked from this scene's patches.
    #[error("the table does not match the scene: {0}")]
    Mismatch(String),
    /// The relight scripts could not be read or do not fit the table.
    #[error("relight scripts {path}: {reason}")]
    Scripts {
        /// The script file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The device loop failed.
    #[error("device loop: {0}")]
    Device(#[from] sim::SimError),
    /// The f64 reference failed.
    #[error("f64 reference: {0}")]
    Reference(#[from] ReferenceError),
    /// The form factors of the dense reference of a hierarchical table failed.
    #[error("dense reference form factors: {0}")]
    FormFactors(#[from] FormFactorError),
    /// Error metrics failed (e.g. a non-finite device value).
    #[error("{0}")]
    Metrics(#[from] MetricsError),
    /// Building or running the firmware under QEMU failed.
    #[error("QEMU ({target}): {reason}")]
    Qemu {
        /// The firmware build.
        target: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// Rendering the frames failed.
    #[error("frames: {0}")]
    Picture(#[from] PictureError),
    /// Setting up the view failed.
    #[error("frames: {0}")]
    View(#[from] ViewError),
}

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct RelightOptions {
    /// Only the script of this name (all scripts of the file when `None`).
    pub only: Option<String>,
    /// Also build the firmware and run it under QEMU (Cortex-M4, f32 and fixed point).
    pub qemu: bool,
    /// Seconds each QEMU run may take.
    pub qemu_timeout_s: u32,
}

impl Default for RelightOptions {
    fn default() -> Self {
        RelightOptions { only: None, qemu: false, qemu_timeout_s: 300 }
    }
}

/// One frame of one script in one arithmetic.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameRow {
    /// `f32` or `fixed`.
    pub arith: Arith,
    /// Script name.
    pub script: String,
    /// Frame index in the script.
    pub frame: u32,
    /// Budget of the frame (work units).
    pub budget: u32,
    /// Units the step used.
    pub used: u32,
    /// Units the light changes of the frame cost (outside the budget).
    pub light_units: u32,
    /// Whether the frame ended converged.
    pub converged: bool,
    /// The device's radiosity against the exact f64 answer for the frame's intensities (for a hierarchical
    /// table: of the table's own system).
    pub error: ErrorReport,
    /// Hierarchical tables only: against the dense f64 answer of the same leaves (every leaf-to-leaf form factor),
    /// which adds the hierarchy's own approximation to the device's error.
    pub dense_error: Option<ErrorReport>,
    /// Instructions the frame took on the emulated Cortex-M4 (light changes and step), when QEMU ran.
    pub instructions: Option<u64>,
}

/// One transfer relight ([`firmware_sim::device::run_transfer`]: the table's transfer basis relit at a script's
/// initial intensities or at a frame that changes them) in one arithmetic.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransferRow {
    /// `f32` or `fixed`.
    pub arith: Arith,
    /// Script name.
    pub script: String,
    /// The state relit: `None` the script's initial intensities, `Some(k)` frame `k`'s.
    pub frame: Option<u32>,
    /// Work units of the relight (elements x (groups + 1)).
    pub units: u32,
    /// Against the exact f64 answer for the state's intensities (hierarchical: of the table's own system).
    pub error: ErrorReport,
    /// Hierarchical tables only: against the dense f64 answer of the same leaves.
    pub dense_error: Option<ErrorReport>,
    /// Instructions of the relight on the emulated Cortex-M4, when QEMU ran.
    pub instructions: Option<u64>,
}

/// One firmware run under QEMU.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QemuRun {
    /// The build (`m4-f32` or `m4-fixed`).
    pub target: &'static str,
    /// Flash use of the ELF (bytes: code, table, constants).
    pub flash: u64,
    /// Static RAM use (bytes; the stack comes on top).
    pub ram: u64,
    /// The stack's high-water mark under QEMU (bytes; painted stack, scanned after the run).
    pub stack: u64,
    /// Frames whose trace (units, outcome, radiosity hash) matched the host simulator's bit for bit.
    pub frames_bit_exact: usize,
    /// Transfer relights whose trace matched the host simulator's bit for bit (0 without a transfer basis).
    pub transfers_bit_exact: usize,
}

/// Everything a relight run measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RelightReport {
    /// Patches of the table.
    pub patches: usize,
    /// Table size in bytes.
    pub table_bytes: usize,
    /// Per-frame rows, script by script, f32 before fixed point.
    pub frames: Vec<FrameRow>,
    /// Transfer relights, script by script, f32 before fixed point (empty without a transfer basis).
    pub transfer: Vec<TransferRow>,
    /// The QEMU runs (empty without `--qemu`).
    pub qemu: Vec<QemuRun>,
    /// The f32 device radiosity of every frame of the first selected script (for pictures), scene patch order.
    #[serde(skip)]
    pub first_script_frames: Vec<Vec<Rgb>>,
    /// Name of the first selected script.
    pub first_script: String,
    /// The table's light groups in table order (the order of every intensity vector): the scene's names, or
    /// position and id for a group the scene does not name.
    pub light_groups: Vec<String>,
}

/// One frame of the device loop: what it spent and the radiosity of every patch (f64, table order).
struct DeviceFrame {
    frame: u32,
    budget: u32,
    used: u32,
    light_units: u32,
    converged: bool,
    b: Vec<Rgb>,
}

/// Runs `script` through the device loop on a flat table in arithmetic `S`, collecting every frame's radiosity.
fn device_frames<S: Bits>(table: &Table<'_>, script: &OwnedScript) -> Result<Vec<DeviceFrame>, RelightError> {
    let mut memory = radiosity_core::OwnedBuffers::<S>::for_table(table);
    collect_frames(table, memory.buffers(), script)
}

/// [`device_frames`] on a hierarchical table (elements are its leaves, in table order).
fn hier_device_frames<S: Bits>(
    table: &HierTable<'_>,
    script: &OwnedScript,
) -> Result<Vec<DeviceFrame>, RelightError> {
    let mut memory = radiosity_core::HierOwnedBuffers::<S>::for_table(table);
    collect_frames(table, memory.buffers(), script)
}

/// Runs `script` through the device loop on `table` with `buffers`, collecting every frame's radiosity.
fn collect_frames<'a, T: DeviceTable<'a>, S: Bits + 'a>(
    table: &T,
    buffers: T::Buffers<S>,
    script: &OwnedScript,
) -> Result<Vec<DeviceFrame>, RelightError> {
    let mut frames = Vec::with_capacity(script.frames.len());
    script
        .with_view(|view| {
            device::run_script(table, buffers, view, &mut NoMeter, |r, solver| {
                let b = (0..solver.element_count())
                    .map(|i| {
                        let v = solver.element_radiosity(i).unwrap_or([S::ZERO; 3]);
                        Rgb::from_array(v.map(|x| f64::from(x.to_f32())))
                    })
                    .collect();
                frames.push(DeviceFrame {
                    frame: r.frame,
                    budget: r.budget,
                    used: r.used,
                    light_units: r.light_units,
                    converged: r.converged(),
                    b,
                });
            })
        })
        .map_err(|error| sim::SimError::Run { script: script.name.clone(), error })?;
    Ok(frames)
}

/// One transfer relight on the host: the state, every element's radiosity (f64, table order), the state's
/// intensities and the work units.
struct TransferRelit {
    frame: Option<u32>,
    b: Vec<Rgb>,
    intensity: Vec<[f32; 3]>,
    units: u32,
}

/// The transfer relights of `script` on `table` in arithmetic `S` (the states of
/// [`device::transfer_states`]), each element's radiosity in f64 (table order), with the work units; empty
/// without a transfer basis.
fn transfer_relights<T: TransferTable, S: Bits>(
    table: &T,
    script: &OwnedScript,
) -> Result<Vec<TransferRelit>, RelightError> {
    let Some(n) = table.transfer_section().map(|t| t.elements()) else {
        return Ok(Vec::new());
    };
    script.with_view(|view| {
        device::transfer_states(view)
            .map(|(frame, rgb)| {
                let intensity: Vec<[S; 3]> = rgb.iter().map(|v| v.map(S::from_f32)).collect();
                let mut out = vec![[S::ZERO; 3]; n as usize];
                let units =
                    relight_transfer(table, &intensity, &mut out).map_err(|error| sim::SimError::Run {
                        script: script.name.clone(),
                        error: device::RunError::Transfer { frame, error },
                    })?;
                let b = out.iter().map(|v| Rgb::from_array(v.map(|x| f64::from(x.to_f32())))).collect();
                Ok(TransferRelit { frame, b, intensity: rgb.to_vec(), units })
            })
            .collect()
    })
}

/// [`transfer_relights`] in both arithmetics for every script, each compared by `compare` (given the relit
/// radiosity and the state's intensities; returns the error and, for hierarchical tables, the dense error).
fn transfer_rows<T: TransferTable>(
    table: &T,
    scripts: &[&OwnedScript],
    mut compare: impl FnMut(
        &str,
        Option<u32>,
        &[Rgb],
        &[[f32; 3]],
    ) -> Result<(ErrorReport, Option<ErrorReport>), RelightError>,
) -> Result<Vec<TransferRow>, RelightError> {
    let mut rows = Vec::new();
    for arith in Arith::ALL {
        for script in scripts {
            let relit = match arith {
                Arith::F32 => transfer_relights::<T, f32>(table, script)?,
                Arith::Fixed => transfer_relights::<T, Fixed>(table, script)?,
            };
            for TransferRelit { frame, b, intensity, units } in relit {
                let (error, dense_error) = compare(&script.name, frame, &b, &intensity)?;
                let script = script.name.clone();
                rows.push(TransferRow {
                    arith,
                    script,
                    frame,
                    units,
                    error,
                    dense_error,
                    instructions: None,
                });
            }
        }
    }
    Ok(rows)
}

/// Pairs the transfer relights of a QEMU `log` with `rows` of arithmetic `arith` and records their
/// instructions.
fn attach_transfer_instructions(rows: &mut [TransferRow], arith: Arith, log: &QemuLog) {
    for q in &log.transfers {
        if let Some(row) =
            rows.iter_mut().find(|r| r.arith == arith && r.script == q.script && r.frame == q.frame)
        {
            row.instructions = Some(q.instructions);
        }
    }
}

/// Checks that `table` holds the patches of `p` (count and areas, to the f32 the table stores).
fn check_match(p: &Prepared, table: &Table<'_>) -> Result<(), RelightError> {
    let n = table.patch_count() as usize;
    if n != p.patches.len() {
        return Err(RelightError::Mismatch(format!(
            "the table has {n} patches, the scene meshes into {}",
            p.patches.len()
        )));
    }
    for (i, patch) in p.patches.iter().enumerate() {
        let a = table.area(i as u32).map_or(f64::NAN, f64::from);
        // The table stores areas as f32: relative rounding 2^-24; allow a few ulps.
        let close = (a - patch.area).abs() <= 4.0 * f64::from(f32::EPSILON) * patch.area;
        if !close {
            return Err(RelightError::Mismatch(format!(
                "patch {i}: area {a} in the table, {} in the scene",
                patch.area
            )));
        }
    }
    let groups = p.lighting.dynamic_groups.len();
    if table.group_count() as usize != groups {
        return Err(RelightError::Mismatch(format!(
            "the table has {}, the scene {groups}",
            crate::text::counted(table.group_count() as usize, "dynamic light group", "dynamic light groups")
        )));
    }
    Ok(())
}

/// The light groups of `table` (baked from `p`), named after the scene's light groups whose ids they carry.
#[must_use]
pub fn table_groups(p: &Prepared, table: &Table<'_>) -> TableGroups {
    TableGroups::of(table).named(p.scene.light_groups.iter().map(|g| g.name.as_str()))
}

/// Runs the relight scripts of `scripts_path` on `table_bytes` (baked from `p`) and compares every frame with
/// the exact answer; with [`RelightOptions::qemu`], also on the firmware under QEMU.
///
/// # Errors
/// [`RelightError`], naming the script, frame or file.
pub fn relight(
    p: &Prepared,
    table_bytes: &[u8],
    table_path: &Path,
    scripts_path: &Path,
    options: &RelightOptions,
) -> Result<RelightReport, RelightError> {
    let table = Table::parse(table_bytes).map_err(RelightError::Table)?;
    check_match(p, &table)?;
    let script_error = |reason: String| RelightError::Scripts { path: scripts_path.to_path_buf(), reason };
    let groups = table_groups(p, &table);
    let file = load_scripts(scripts_path, &groups)?;
    let selected = select_scripts(&file, scripts_path, options)?;

    let tv = exact_transfer(&p.lighting, &p.form_factors, &Method::for_size(p.patches.len()))?;
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let mut rows = Vec::new();
    let mut first_script_frames = Vec::new();
    for arith in Arith::ALL {
        for (k, script) in selected.iter().enumerate() {
            let frames = match arith {
                Arith::F32 => device_frames::<f32>(&table, script)?,
                Arith::Fixed => device_frames::<Fixed>(&table, script)?,
            };
            for (f, spec) in frames.iter().zip(&script.frames) {
                let intensity: Vec<Rgb> =
                    spec.intensity.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
                let exact = tv.relight(&intensity)?;
                let error = metrics::compare(&f.b, &exact, &area).map_err(|e| {
                    script_error(format!("script {:?} frame {} ({arith}): {e}", script.name, f.frame))
                })?;
                rows.push(FrameRow {
                    arith,
                    script: script.name.clone(),
                    frame: f.frame,
                    budget: f.budget,
                    used: f.used,
                    light_units: f.light_units,
                    converged: f.converged,
                    error,
                    dense_error: None,
                    instructions: None,
                });
            }
            if arith == Arith::F32 && k == 0 {
                first_script_frames = frames.into_iter().map(|f| f.b).collect();
            }
        }
    }
    let mut transfer = transfer_rows(&table, &selected, |name, frame, b, rgb| {
        let intensity: Vec<Rgb> = rgb.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
        let exact = tv.relight(&intensity)?;
        let error = metrics::compare(b, &exact, &area)
            .map_err(|e| script_error(format!("script {name:?} transfer relight {frame:?}: {e}")))?;
        Ok((error, None))
    })?;

    let mut qemu_runs = Vec::new();
    if options.qemu {
        for (target, name) in [(qemu::M4_F32, "m4-f32"), (qemu::M4_FIXED, "m4-fixed")] {
            let (run, log) = run_firmware(target, name, table, &file, table_path, scripts_path, options)?;
            attach_instructions(&mut rows, target.arith, &log);
            attach_transfer_instructions(&mut transfer, target.arith, &log);
            qemu_runs.push(run);
        }
    }
    Ok(RelightReport {
        patches: p.patches.len(),
        table_bytes: table_bytes.len(),
        frames: rows,
        transfer,
        qemu: qemu_runs,
        first_script_frames,
        first_script: selected[0].name.clone(),
        light_groups: (0..groups.len())
            .map(|g| groups.name(g).map_or_else(|| groups.label(g), str::to_owned))
            .collect(),
    })
}

/// The relight scripts of `path`, their light groups resolved against `groups`.
fn load_scripts(path: &Path, groups: &TableGroups) -> Result<ScriptFile, RelightError> {
    ScriptFile::load(path)
        .and_then(|f| f.resolve(groups))
        .map_err(|e| RelightError::Scripts { path: path.to_path_buf(), reason: e.to_string() })
}

/// The scripts of `file` that `options` selects (all, or the one named), or an error naming the file's scripts.
fn select_scripts<'f>(
    file: &'f ScriptFile,
    path: &Path,
    options: &RelightOptions,
) -> Result<Vec<&'f OwnedScript>, RelightError> {
    let selected: Vec<&OwnedScript> =
        file.scripts.iter().filter(|s| options.only.as_deref().is_none_or(|n| n == s.name)).collect();
    if selected.is_empty() {
        return Err(RelightError::Scripts {
            path: path.to_path_buf(),
            reason: format!(
                "no script named {:?} (the file has {})",
                options.only.as_deref().unwrap_or_default(),
                file.scripts.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
        });
    }
    Ok(selected)
}

/// Runs the relight scripts of `scripts_path` on the hierarchical table `baked` (baked from `solution` of
/// `scene`, written to `table_path`) the way the device runs them, and compares every frame with two f64
/// answers: the table's own system's ([`BakedHierarchy::exact`]: what the device converges to but for codes and
/// arithmetic) and the dense solve of the same leaves (every leaf-to-leaf form factor by the patch estimator;
/// `dense_error`). With [`RelightOptions::qemu`], also on the Cortex-M4 f32 firmware under QEMU (the fixed-point
/// build's buffers take twice the RAM).
///
/// # Errors
/// [`RelightError`], naming the script, frame or file.
pub fn relight_hierarchical(
    scene: &Scene,
    solution: &HierarchicalSolution,
    baked: &BakedHierarchy,
    (table_path, scripts_path): (&Path, &Path),
    options: &RelightOptions,
) -> Result<RelightReport, RelightError> {
    let table = HierTable::parse(&baked.table).map_err(RelightError::Table)?;
    let groups = TableGroups::of(&table).named(scene.light_groups.iter().map(|g| g.name.as_str()));
    let file = load_scripts(scripts_path, &groups)?;
    let selected = select_scripts(&file, scripts_path, options)?;
    let script_error = |reason: String| RelightError::Scripts { path: scripts_path.to_path_buf(), reason };

    let dense = dense_on_leaves(scene, solution).map_err(|e| match e {
        DenseError::FormFactors(e) => RelightError::FormFactors(e),
        DenseError::Reference(e) => RelightError::Reference(e),
    })?;
    let area: Vec<f64> = baked.solution_leaf.iter().map(|&l| solution.leaves[l].area).collect();
    let mut rows = Vec::new();
    let mut first_script_frames = Vec::new();
    for arith in Arith::ALL {
        for (k, script) in selected.iter().enumerate() {
            let frames = match arith {
                Arith::F32 => hier_device_frames::<f32>(&table, script)?,
                Arith::Fixed => hier_device_frames::<Fixed>(&table, script)?,
            };
            for (f, spec) in frames.iter().zip(&script.frames) {
                let intensity: Vec<Rgb> =
                    spec.intensity.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
                let own = baked.exact(&intensity).map_err(|e| script_error(e.to_string()))?;
                let dense_b = dense.relight(&intensity)?;
                let dense_b: Vec<Rgb> = baked.solution_leaf.iter().map(|&l| dense_b[l]).collect();
                let compare = |exact: &[Rgb]| {
                    metrics::compare(&f.b, exact, &area).map_err(|e| {
                        script_error(format!("script {:?} frame {} ({arith}): {e}", script.name, f.frame))
                    })
                };
                rows.push(FrameRow {
                    arith,
                    script: script.name.clone(),
                    frame: f.frame,
                    budget: f.budget,
                    used: f.used,
                    light_units: f.light_units,
                    converged: f.converged,
                    error: compare(&own)?,
                    dense_error: Some(compare(&dense_b)?),
                    instructions: None,
                });
            }
            if arith == Arith::F32 && k == 0 {
                // Pictures use the scene's order: the solution's leaves.
                first_script_frames = frames
                    .into_iter()
                    .map(|f| {
                        let mut b = vec![Rgb::ZERO; f.b.len()];
                        for (t, &l) in baked.solution_leaf.iter().enumerate() {
                            b[l] = f.b[t];
                        }
                        b
                    })
                    .collect();
            }
        }
    }
    let mut transfer = transfer_rows(&table, &selected, |name, frame, b, rgb| {
        let intensity: Vec<Rgb> = rgb.iter().map(|v| Rgb::from_array(v.map(f64::from))).collect();
        let own = baked.exact(&intensity).map_err(|e| script_error(e.to_string()))?;
        let dense_b = dense.relight(&intensity)?;
        let dense_b: Vec<Rgb> = baked.solution_leaf.iter().map(|&l| dense_b[l]).collect();
        let compare = |exact: &[Rgb]| {
            metrics::compare(b, exact, &area)
                .map_err(|e| script_error(format!("script {name:?} transfer relight {frame:?}: {e}")))
        };
        Ok((compare(&own)?, Some(compare(&dense_b)?)))
    })?;
    let mut qemu_runs = Vec::new();
    if options.qemu {
        let (run, log) =
            run_firmware(qemu::M4_F32, "m4-f32", table, &file, table_path, scripts_path, options)?;
        attach_instructions(&mut rows, Arith::F32, &log);
        attach_transfer_instructions(&mut transfer, Arith::F32, &log);
        qemu_runs.push(run);
    }
    Ok(RelightReport {
        patches: baked.solution_leaf.len(),
        table_bytes: baked.table.len(),
        frames: rows,
        transfer,
        qemu: qemu_runs,
        first_script_frames,
        first_script: selected[0].name.clone(),
        light_groups: (0..groups.len())
            .map(|g| groups.name(g).map_or_else(|| groups.label(g), str::to_owned))
            .collect(),
    })
}

/// Pairs the frames of a QEMU `log` (script order, frame order) with `rows` of arithmetic `arith` and records
/// their instructions.
fn attach_instructions(rows: &mut [FrameRow], arith: Arith, log: &QemuLog) {
    let mut index = std::collections::HashMap::<&str, u32>::new();
    for q in &log.frames {
        let k = index.entry(q.script.as_str()).or_insert(0);
        if let Some(row) = rows.iter_mut().find(|r| r.arith == arith && r.script == q.script && r.frame == *k)
        {
            row.instructions = Some(q.instructions);
        }
        *k += 1;
    }
}

/// Builds the firmware for `target` with the table and scripts, runs it under QEMU, checks it against the host
/// simulator bit for bit and reads its size and stack use.
fn run_firmware<'t>(
    target: Target,
    name: &'static str,
    table: impl Into<firmware_sim::sim::AnyTable<'t>>,
    file: &ScriptFile,
    table_path: &Path,
    scripts_path: &Path,
    options: &RelightOptions,
) -> Result<(QemuRun, QemuLog), RelightError> {
    let fail = |reason: String| RelightError::Qemu { target: name, reason };
    let paths = (table_path, scripts_path);
    let c =
        qemu::check_firmware(target, table, file, paths, options.qemu_timeout_s, |_| Ok(())).map_err(fail)?;
    let run = QemuRun {
        target: name,
        flash: c.sizes.flash,
        ram: c.sizes.ram,
        stack: c.stack.high_water,
        frames_bit_exact: c.frames_bit_exact,
        transfers_bit_exact: c.transfers_bit_exact,
    };
    Ok((run, c.log))
}

/// Renders the f32 device answer of every frame of the report's first script to `<dir>/<script>-NNNN.png`
/// (one tone map for all frames: the last frame's, so an unconverged frame looks as dark as it is), through the
/// scene's default camera. Returns the paths.
///
/// # Errors
/// [`RelightError::View`] / [`RelightError::Picture`] for the view or the files.
pub fn write_frames(
    p: &Prepared,
    report: &RelightReport,
    dir: &Path,
    width: u32,
    height: u32,
) -> Result<Vec<PathBuf>, RelightError> {
    std::fs::create_dir_all(dir).map_err(|e| PictureError::Io { path: dir.to_path_buf(), source: e })?;
    let camera = default_camera(p.surfaces())?;
    let tracer = PatchTracer::new(&p.patches)?;
    let trace = |o, d| tracer.closest_hit(o, d);
    let hits = trace_view(&Frame { camera, width, height }, &trace)?;
    let shader = SmoothShader::new(&p.patches, &ShadingOptions::default())?;
    let (paths, _) =
        write_frame_sequence(&hits, &shader, &report.first_script_frames, None, dir, &report.first_script)?;
    Ok(paths)
}

/// The per-frame CSV header.
pub const CSV_HEADER: &str =
    "arith,script,frame,budget,used,light_units,converged,rel_l2,abs_rms,max_rel,luminance_rel_l2,\
instructions_m4";

impl RelightReport {
    /// The per-frame rows as CSV ([`CSV_HEADER`]; `instructions_m4` empty without QEMU).
    #[must_use]
    pub fn to_csv(&self) -> String {
        let mut s = String::from(CSV_HEADER);
        s.push('\n');
        for r in &self.frames {
            s.push_str(&format!(
                "{},{},{},{},{},{},{},{:e},{:e},{:e},{:e},{}\n",
                r.arith,
                r.script,
                r.frame,
                r.budget,
                r.used,
                r.light_units,
                u8::from(r.converged),
                r.error.rel_l2,
                r.error.abs_rms,
                r.error.max_rel,
                r.error.luminance_rel_l2,
                r.instructions.map(|i| i.to_string()).unwrap_or_default()
            ));
        }
        s
    }

    /// Error against cumulative work units, one series per script and arithmetic (for
    /// [`crate::picture::plot::Plot::ErrorWork`]); points with zero error or work are left out (log axes), and so
    /// are frames whose relative error is undefined (every light off: the exact answer is 0), which the series'
    /// name then counts.
    #[must_use]
    pub fn error_series(&self) -> Vec<crate::picture::plot::Series> {
        let mut series: Vec<(crate::picture::plot::Series, usize)> = Vec::new();
        let mut work = 0.0;
        for r in &self.frames {
            let name = format!("{} ({})", r.script, r.arith);
            if series.last().is_none_or(|(s, _)| s.name != name) {
                series.push((crate::picture::plot::Series { name, points: Vec::new() }, 0));
                work = 0.0;
            }
            work += f64::from(r.used) + f64::from(r.light_units);
            if let Some((s, undefined)) = series.last_mut() {
                if !r.error.rel_l2.is_finite() {
                    *undefined += 1;
                } else if work > 0.0 && r.error.rel_l2 > 0.0 {
                    s.points.push((work, r.error.rel_l2));
                }
            }
        }
        series
            .into_iter()
            .filter(|(s, _)| !s.points.is_empty())
            .map(|(mut s, undefined)| {
                if undefined > 0 {
                    s.name = format!("{} [{undefined} dark frames not plotted]", s.name);
                }
                s
            })
            .collect()
    }
}

impl fmt::Display for RelightReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} patches, table {} bytes; error = area-weighted relative L2 of B against the exact f64 answer \
             for the frame's intensities",
            self.patches, self.table_bytes
        )?;
        writeln!(f, "light groups (table order): {}", self.light_groups.join(", "))?;
        if self.frames.iter().any(|r| !r.error.rel_l2.is_finite()) {
            writeln!(
                f,
                "(\"abs\": a frame with every light off, whose exact answer is 0, so relative error is undefined: \
                 the area-weighted RMS of B in W/m^2 instead)"
            )?;
        }
        for q in &self.qemu {
            writeln!(
                f,
                "QEMU {}: flash {} bytes, static RAM {} bytes, stack {} bytes (high-water mark), host and \
                 firmware bit-exact on {} frames{}",
                q.target,
                q.flash,
                q.ram,
                q.stack,
                q.frames_bit_exact,
                if q.transfers_bit_exact > 0 {
                    format!(" and {} transfer relights", q.transfers_bit_exact)
                } else {
                    String::new()
                }
            )?;
        }
        let has_qemu = !self.qemu.is_empty();
        let has_dense = self.frames.iter().any(|r| r.dense_error.is_some());
        if has_dense {
            writeln!(
                f,
                "hierarchical table: err = against the f64 answer of the table's own system; dense f32 = the f32 \
                 device against the dense f64 solve of the same leaves (adds the hierarchy's approximation)"
            )?;
        }
        writeln!(
            f,
            "{:<14} {:>5} {:>7} {:>7} {:>5} {:>10} {:>10}{}",
            "script",
            "frame",
            "budget",
            "used",
            "conv",
            "err f32",
            "err fixed",
            tail_header(has_dense, has_qemu)
        )?;
        let f32_rows = self.frames.iter().filter(|r| r.arith == Arith::F32);
        for r in f32_rows {
            let fixed = self
                .frames
                .iter()
                .find(|x| x.arith == Arith::Fixed && x.script == r.script && x.frame == r.frame);
            write!(
                f,
                "{:<14} {:>5} {:>7} {:>7} {:>5} {:>10} {:>10}",
                r.script,
                r.frame,
                r.budget,
                r.used,
                if r.converged { "yes" } else { "no" },
                error_cell(&r.error),
                fixed.map_or("-".into(), |x| error_cell(&x.error))
            )?;
            let instructions = (r.instructions, fixed.and_then(|x| x.instructions));
            write_tail(f, (has_dense, has_qemu), r.dense_error.as_ref(), instructions)?;
        }
        self.fmt_transfer(f, has_dense, has_qemu)
    }
}

impl RelightReport {
    /// The transfer relights' table (nothing without them).
    fn fmt_transfer(&self, f: &mut fmt::Formatter<'_>, has_dense: bool, has_qemu: bool) -> fmt::Result {
        if self.transfer.is_empty() {
            return Ok(());
        }
        writeln!(
            f,
            "transfer relights (the table's transfer basis, core's relight_transfer: every element in one pass, \
             no iteration) at the initial intensities (frame -) and at every frame that changes them:"
        )?;
        writeln!(
            f,
            "{:<14} {:>5} {:>7} {:>10} {:>10}{}",
            "script",
            "frame",
            "units",
            "err f32",
            "err fixed",
            tail_header(has_dense, has_qemu)
        )?;
        for r in self.transfer.iter().filter(|r| r.arith == Arith::F32) {
            let fixed = self
                .transfer
                .iter()
                .find(|x| x.arith == Arith::Fixed && x.script == r.script && x.frame == r.frame);
            write!(
                f,
                "{:<14} {:>5} {:>7} {:>10} {:>10}",
                r.script,
                r.frame.map_or("-".to_string(), |k| k.to_string()),
                r.units,
                error_cell(&r.error),
                fixed.map_or("-".into(), |x| error_cell(&x.error))
            )?;
            let instructions = (r.instructions, fixed.and_then(|x| x.instructions));
            write_tail(f, (has_dense, has_qemu), r.dense_error.as_ref(), instructions)?;
        }
        Ok(())
    }
}

/// The optional columns' headers of the report's tables: the dense error and the instructions of both builds.
fn tail_header(has_dense: bool, has_qemu: bool) -> String {
    format!(
        "{}{}",
        if has_dense { "  dense f32" } else { "" },
        if has_qemu { "   instr f32 instr fixed" } else { "" }
    )
}

/// The optional columns of a row (see [`tail_header`]) and the line's end.
fn write_tail(
    f: &mut fmt::Formatter<'_>,
    (has_dense, has_qemu): (bool, bool),
    dense: Option<&ErrorReport>,
    (instr_f32, instr_fixed): (Option<u64>, Option<u64>),
) -> fmt::Result {
    if has_dense {
        write!(f, " {:>10}", dense.map_or("-".into(), error_cell))?;
    }
    if has_qemu {
        let show = |v: Option<u64>| v.map_or("-".to_string(), |v| v.to_string());
        write!(f, " {:>11} {:>11}", show(instr_f32), show(instr_fixed))?;
    }
    writeln!(f)
}

/// A frame's error for the text table: the relative L2 error, or, where it is undefined (every light off), `abs`
/// and the absolute RMS error.
fn error_cell(e: &crate::metrics::ErrorReport) -> String {
    if e.rel_l2.is_finite() {
        format!("{:.3e}", e.rel_l2)
    } else {
        format!("abs {:.1e}", e.abs_rms)
    }
}

/// Relative tolerance of [`device_answer`]'s solve (of the lights' total power at unit intensity): far below the
/// quantization error of a 16-bit table, so the answer shows what the table can do, not where iteration stopped.
pub const CONVERGED_TOLERANCE: f32 = 1e-6;

/// The device's converged answer on `table` (f32, the device loop's boot solve at [`CONVERGED_TOLERANCE`]) for
/// per-group `intensity`, in table patch order; e.g. for a picture of its error against the f64 answer.
///
/// # Errors
/// [`RelightError::Table`] if the table does not parse, [`RelightError::Device`] if a light change is rejected or
/// the solve does not converge within [`firmware_sim::script::DEFAULT_BOOT_BUDGET`] work units.
pub fn device_answer(table_bytes: &[u8], intensity: &[[f32; 3]]) -> Result<Vec<Rgb>, RelightError> {
    let table = Table::parse(table_bytes).map_err(RelightError::Table)?;
    let script = OwnedScript {
        name: "converged".into(),
        description: String::new(),
        tolerance: CONVERGED_TOLERANCE,
        boot_budget: firmware_sim::script::DEFAULT_BOOT_BUDGET,
        groups: None,
        initial: intensity.to_vec(),
        frames: vec![firmware_sim::script::OwnedFrame { budget: 1, intensity: intensity.to_vec() }],
    };
    let mut frames = device_frames::<f32>(&table, &script)?;
    Ok(frames.pop().map(|f| f.b).unwrap_or_default())
}
