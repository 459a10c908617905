//! The cost model: instructions per frame as a fixed overhead plus a cost per work unit, fitted by least
//! squares to QEMU measurements, and checked on every frame.
//!
//! Model: `instructions = overhead + per_unit * units`, with `units = used + light_units` (the step's units
//! plus the light changes' units, which core reports outside the budget), fitted by ordinary least squares on
//! the frames of one calibration script: that is the typical cost. Work units are not all alike (an entry
//! applied, with its selection comparison, costs more instructions than a slot scanned when selecting or
//! rebuilding a block), so the per-unit cost of a frame varies with its mix, and a least-squares line is not a
//! bound. The **bound** is the upper envelope through the calibration frames: overhead `bound_overhead` = the
//! largest of the least-squares overhead, 0 and the instructions of any calibration frame with no units (an
//! idle frame after convergence: the loop's fixed cost), and slope `bound_per_unit` = the largest
//! `(instructions - bound_overhead) / units` of a calibration frame, so
//! `bound = bound_overhead + bound_per_unit * (budget + light_units)` covers every calibration frame by
//! construction (`used <= budget` is core's guarantee). It is then checked on every frame of every script;
//! the frames of the scripts other than the calibration one are the test. The reported margin is
//! `1 - measured / bound`.
//!
//! The timing resolution is one SysTick tick (40 instructions on mps2-an386, 62.5 on microbit).

use std::fmt::Write as _;

use radiosity_core::{HierOwnedBuffers, HierTable};

use crate::device::{self, Bits, DeviceTable};
use crate::qemu::{QemuFrame, QemuLog};
use crate::script::ScriptFile;
use crate::sim::Arith;

/// A fitted model for one build (arithmetic and target).
#[derive(Clone, Debug, PartialEq)]
pub struct CostModel {
    /// Which log (build) it was fitted on.
    pub build: String,
    /// Instructions per frame independent of the units (least squares intercept).
    pub overhead: f64,
    /// Instructions per work unit (least squares slope).
    pub per_unit: f64,
    /// Overhead of the bound: the largest of `overhead`, 0 and an idle calibration frame's instructions.
    pub bound_overhead: f64,
    /// Slope of the bound: the largest per-unit cost over the bound's overhead on a calibration frame.
    pub bound_per_unit: f64,
    /// Calibration frames.
    pub samples: usize,
    /// Frames checked (all scripts).
    pub checked: usize,
    /// Frames whose measurement exceeded the bound.
    pub violations: usize,
    /// Smallest `1 - measured / bound` over the checked frames.
    pub worst_margin: f64,
    /// The frame with the smallest margin: (script, frame index within the log, budget, measured).
    pub worst_frame: (String, usize, u32, u64),
    /// Largest instructions of a frame.
    pub max_instructions: u64,
}

impl CostModel {
    /// The bound for a frame with `budget` units and `light_units` of light changes.
    #[must_use]
    pub fn bound(&self, budget: u32, light_units: u32) -> f64 {
        self.bound_overhead + self.bound_per_unit * (f64::from(budget) + f64::from(light_units))
    }
}

/// Ordinary least squares `y = a + b x`; `None` if fewer than 2 distinct `x`.
#[must_use]
pub fn fit(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if points.len() < 2 || sxx <= 0.0 {
        return None;
    }
    let b = sxy / sxx;
    Some((my - b * mx, b))
}

fn units(f: &QemuFrame) -> f64 {
    f64::from(f.used) + f64::from(f.light_units)
}

/// Fits the model on `calibrate`'s frames of `log` and checks every frame.
///
/// # Errors
/// No calibration frames, or they do not determine a line.
pub fn calibrate(build: &str, log: &QemuLog, calibrate: &str) -> Result<CostModel, String> {
    let cal: Vec<&QemuFrame> = log.frames.iter().filter(|f| f.script == calibrate).collect();
    let points: Vec<(f64, f64)> = cal.iter().map(|f| (units(f), f.instructions as f64)).collect();
    let (overhead, per_unit) = fit(&points).ok_or_else(|| {
        format!("{build}: calibration script {calibrate:?} has too few distinct frames to fit")
    })?;
    let idle = cal.iter().filter(|f| units(f) == 0.0).map(|f| f.instructions as f64).fold(0.0f64, f64::max);
    let bound_overhead = overhead.max(idle);
    let bound_per_unit =
        points.iter().filter(|p| p.0 > 0.0).map(|(x, y)| (y - bound_overhead) / x).fold(0.0f64, f64::max);
    let mut m = CostModel {
        build: build.to_string(),
        overhead,
        per_unit,
        bound_overhead,
        bound_per_unit,
        samples: points.len(),
        checked: 0,
        violations: 0,
        worst_margin: f64::INFINITY,
        worst_frame: (String::new(), 0, 0, 0),
        max_instructions: 0,
    };
    for (k, f) in log.frames.iter().enumerate() {
        let bound = m.bound(f.budget, f.light_units);
        let margin = 1.0 - f.instructions as f64 / bound;
        m.checked += 1;
        m.max_instructions = m.max_instructions.max(f.instructions);
        // A calibration frame on the envelope gives `measured == bound` in exact arithmetic; evaluating the
        // bound (a division, a multiplication, an addition) may round it below by a few ulps, which is not a
        // violation.
        if f.instructions as f64 > bound * (1.0 + 4.0 * f64::EPSILON) {
            m.violations += 1;
        }
        if margin < m.worst_margin {
            m.worst_margin = margin;
            m.worst_frame = (f.script.clone(), k, f.budget, f.instructions);
        }
    }
    Ok(m)
}

/// The cost report: models and a markdown page.
#[derive(Clone, Debug, PartialEq)]
pub struct CostReport {
    /// One model per log.
    pub models: Vec<CostModel>,
    /// Frames over their bound, over all logs.
    pub violations: usize,
    /// The markdown page (`firmware-sim/COST.md`).
    pub markdown: String,
}

/// Fits and checks every log (`(name, log)`), and writes the markdown report at a clock of `clock_mhz`
/// (one instruction per cycle, an assumption stated in the report); the transfer relights of `logs` and of
/// `transfer_logs` (runs of other tables, not calibrated) make its transfer section ([`transfer_report`]).
///
/// # Errors
/// As [`calibrate`].
pub fn report(
    logs: &[(String, QemuLog)],
    transfer_logs: &[(String, QemuLog)],
    calibrate_on: &str,
    clock_mhz: f64,
) -> Result<CostReport, String> {
    let mut models = Vec::new();
    for (name, log) in logs {
        models.push(calibrate(name, log, calibrate_on)?);
    }
    let violations = models.iter().map(|m| m.violations).sum();
    let mut md = String::new();
    let _ = writeln!(md, "# Firmware cost model\n");
    let _ = writeln!(
        md,
        "Generated by `scripts/firmware.sh` (`firmware-sim cost`) from QEMU runs of the firmware \
         (`qemu-system-arm -icount shift=0`, instructions from SysTick: resolution one tick, 40 instructions on mps2-an386 and 62.5 on microbit). \
         Model: `instructions = overhead + per_unit * units`, `units` = step units used + light-change units, \
         fitted by least squares on the frames of script `{calibrate_on}` (the typical cost). Bound for a frame \
         = `bound overhead + bound per unit * (budget + light units)`: the upper envelope of the calibration \
         frames (bound overhead = max(LS overhead, 0, instructions of an idle calibration frame), bound per unit = largest (instructions - bound overhead) \
         / units of a calibration frame), since work units differ in cost. Checked on every frame of every \
         script (see `firmware-sim/src/cost.rs`). Time at an assumed {clock_mhz} MHz clock and one instruction \
         per cycle (an assumption: real Cortex-M4 code has wait states and multi-cycle instructions).\n"
    );
    let _ = writeln!(
        md,
        "| build | calibration frames | LS overhead (instr.) | LS instr. per unit | bound overhead | bound instr. per unit | frames checked | over bound | \
         worst margin | worst frame (script, budget, measured) | max instr./frame | max us/frame @ {clock_mhz} MHz |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for m in &models {
        let _ = writeln!(
            md,
            "| {} | {} | {:.0} | {:.2} | {:.0} | {:.2} | {} | {} | {:.1} % | {}, {}, {} | {} | {:.1} |",
            m.build,
            m.samples,
            m.overhead,
            m.per_unit,
            m.bound_overhead,
            m.bound_per_unit,
            m.checked,
            m.violations,
            100.0 * m.worst_margin,
            m.worst_frame.0,
            m.worst_frame.2,
            m.worst_frame.3,
            m.max_instructions,
            m.max_instructions as f64 / clock_mhz
        );
    }
    let _ = writeln!(md, "\nBudget in time: a frame of `T` microseconds at {clock_mhz} MHz allows");
    for m in &models {
        let _ = writeln!(
            md,
            "- {}: `budget <= (T * {clock_mhz} - {:.0}) / {:.2} - light units` work units.",
            m.build, m.bound_overhead, m.bound_per_unit
        );
    }
    let all: Vec<(String, QemuLog)> = logs.iter().chain(transfer_logs).cloned().collect();
    md.push_str(&transfer_report(&all));
    Ok(CostReport { models, violations, markdown: md })
}

/// The markdown section on the transfer relights of `logs` (`X` lines; empty if no log has any): per build the
/// relights' work units, instructions, and instructions per unit and per element.
#[must_use]
pub fn transfer_report(logs: &[(String, QemuLog)]) -> String {
    let mut md = String::new();
    if logs.iter().all(|(_, log)| log.transfers.is_empty()) {
        return md;
    }
    let _ = writeln!(
        md,
        "\n## Transfer relight (`relight_transfer_range`)\n\n\
         The table's transfer basis relit at the initial intensities of every script and at every frame that \
         changes them (`firmware-sim/src/device.rs`, `run_transfer`), {} elements per call into one buffer, every \
         relight bit-exact with the host simulator. A relight's work units are `elements x (groups + 1)`: one \
         per element for its static base (emission, irradiance and reflectance codes decoded, `E + rho G`) and one \
         per element and light group (an RGB response code triple, three multiply-adds). Instructions are the \
         relight calls' (SysTick around each call, the output's hashing between calls not counted), so they \
         include each call's setup (per-group scales); per unit and per element are the largest ratio over the \
         relights of a build.\n",
        crate::device::TRANSFER_CHUNK
    );
    let _ = writeln!(
        md,
        "| build | relights | elements | groups | units each | instructions (min - max) | instr. per unit | \
         instr. per element |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
    for (name, log) in logs {
        let t = &log.transfers;
        let Some(first) = t.first() else { continue };
        let min = t.iter().map(|x| x.instructions).min().unwrap_or(0);
        let max = t.iter().map(|x| x.instructions).max().unwrap_or(0);
        let per = |x: &crate::qemu::QemuTransfer, d: u32| x.instructions as f64 / f64::from(d.max(1));
        let per_unit = t.iter().map(|x| per(x, x.units)).fold(0.0, f64::max);
        let per_element = t.iter().map(|x| per(x, x.elements)).fold(0.0, f64::max);
        let _ = writeln!(
            md,
            "| {name} | {} | {} | {} | {} | {min} - {max} | {per_unit:.1} | {per_element:.1} |",
            t.len(),
            first.elements,
            first.groups,
            first.units
        );
    }
    let marginal = transfer_marginal(logs);
    if !marginal.is_empty() {
        let _ = writeln!(
            md,
            "\nPer element and light group: least squares `instructions / elements = per element + per group * \
             groups` over the relights of one build on tables of the same element count and different \
             group counts (the one-group and the four-group enclosures of 96 patches, no static light): the \
             marginal cost of a light group, and what every element costs besides (the loop, the output, each \
             call's share of the per-group scales).\n"
        );
        let _ = writeln!(md, "| build | elements | group counts | relights | instr. per element and group | instr. per element |");
        let _ = writeln!(md, "|---|---|---|---|---|---|");
        for m in &marginal {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {:.1} | {:.1} |",
                m.build, m.elements, m.group_counts, m.relights, m.per_group, m.per_element
            );
        }
    }
    md
}

/// The marginal cost of a light group in the transfer relight ([`transfer_marginal`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TransferMarginal {
    /// The firmware build (`m4-f32`, ...).
    pub build: String,
    /// Elements of the tables compared.
    pub elements: u32,
    /// The distinct group counts, comma-separated.
    pub group_counts: String,
    /// Relights fitted.
    pub relights: usize,
    /// Instructions per element and light group (the fit's slope).
    pub per_group: f64,
    /// Instructions per element besides (the fit's intercept).
    pub per_element: f64,
}

/// For every build (a log's name ends in it: `m4-f32` of `four-lights-m4-f32`) and element count with relights
/// at two or more group counts in `logs`: the least-squares line `instructions / elements = per_element +
/// per_group * groups`.
#[must_use]
pub fn transfer_marginal(logs: &[(String, QemuLog)]) -> Vec<TransferMarginal> {
    let mut by: std::collections::BTreeMap<(String, u32), Vec<(f64, f64)>> = Default::default();
    for (name, log) in logs {
        // The build: the log name's last two dash-separated words (`four-lights-m4-f32` ran `m4-f32`).
        let words: Vec<&str> = name.rsplitn(3, '-').collect();
        let build = match words.as_slice() {
            [arith, cpu, ..] => format!("{cpu}-{arith}"),
            _ => name.clone(),
        };
        for x in &log.transfers {
            let y = x.instructions as f64 / f64::from(x.elements.max(1));
            by.entry((build.clone(), x.elements)).or_default().push((f64::from(x.groups), y));
        }
    }
    by.into_iter()
        .filter_map(|((build, elements), points)| {
            let mut counts: Vec<u32> = points.iter().map(|p| p.0 as u32).collect();
            counts.sort_unstable();
            counts.dedup();
            let (per_element, per_group) = fit(&points)?;
            let group_counts = counts.iter().map(u32::to_string).collect::<Vec<_>>().join(", ");
            Some(TransferMarginal {
                build,
                elements,
                group_counts,
                relights: points.len(),
                per_group,
                per_element,
            })
        })
        .collect()
}

/// The work of one frame on a hierarchical table, by kind, as the host simulator counts it (the firmware runs
/// the same actions bit for bit, so these are the firmware's counts too).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HierFrameWork {
    /// Script name.
    pub script: String,
    /// Links applied (one unit each): `HierSolver::links` after the frame minus before.
    pub links: u64,
    /// Shots started (`HierSolver::shots`): each sets up its run (the shooter's power, its table bytes, the
    /// split between its leaf and inner receivers) before its links.
    pub shots: u64,
    /// Nodes judged in rounds (`HierSolver::judged`, one unit each): a run's bounds and an unshot magnitude
    /// read and compared.
    pub judged: u64,
    /// The step's other units: nodes entered and left by sweeps (chain irradiance pushed, reflected and unshot
    /// power pulled), each dearer than a judging.
    pub swept: u64,
    /// Units of the frame's light changes (outside the budget).
    pub light_units: u64,
}

/// Runs every script of `file` on the hierarchical `table` with arithmetic `S` on the host and splits every
/// frame's units into links, nodes judged and nodes swept, with its shots ([`HierFrameWork`]), in frame order (the QEMU
/// log's order).
///
/// # Errors
/// The device loop's error, as text.
pub fn hier_work<S: Bits>(table: &HierTable<'_>, file: &ScriptFile) -> Result<Vec<HierFrameWork>, String> {
    let mut memory = HierOwnedBuffers::<S>::for_table(table);
    let mut out = Vec::new();
    for s in &file.scripts {
        s.with_view(|script| -> Result<(), String> {
            let config = device::script_config::<_, S>(table, script);
            let mut solver = table.solver(memory.buffers(), config).map_err(|e| e.to_string())?;
            device::boot(&mut solver, script).map_err(|e| format!("{}: {e}", script.name))?;
            for (index, frame) in (0u32..).zip(script.frames) {
                let before = (solver.links(), solver.shots(), solver.judged());
                let (light, outcome) = device::run_frame(&mut solver, frame, index)
                    .map_err(|e| format!("{}: {e}", script.name))?;
                let links = solver.links() - before.0;
                let judged = solver.judged() - before.2;
                out.push(HierFrameWork {
                    script: script.name.to_string(),
                    links,
                    shots: u64::from(solver.shots() - before.1),
                    judged,
                    swept: u64::from(outcome.used()).saturating_sub(links + judged),
                    light_units: u64::from(light),
                });
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// Least squares `y = x . beta` over rows whose first column is 1 (an intercept, unconstrained) with the other
/// coefficients (rates) `>= 0`: of the fits on every subset of the rate columns (the others held at 0), the
/// one of least squared residual whose rates are all `>= 0`. Exact non-negative least squares for these few
/// columns (the optimum is the plain fit on its set of positive rates). Work kinds whose counts move together
/// over the calibration frames (a table whose runs all hold the same few links: links and shots in proportion)
/// make the plain fit trade one rate against another, even below 0, and a negative rate prices a frame with
/// more of that work as cheaper; held at 0 instead, the kinds left carry the cost. `None` if no subset fits.
#[must_use]
pub fn nonnegative_rates<const K: usize>(rows: &[([f64; K], f64)]) -> Option<[f64; K]> {
    let mut best: Option<([f64; K], f64)> = None;
    for mask in 0u32..1 << (K - 1) {
        // The intercept and the rate columns of `mask`, as a dense system of their own.
        let cols: Vec<usize> = (0..K).filter(|&j| j == 0 || mask >> (j - 1) & 1 == 1).collect();
        let Some(beta) = least_squares_dyn(rows, &cols) else { continue };
        if beta.iter().skip(1).any(|&b| b < 0.0) {
            continue;
        }
        let mut full = [0.0f64; K];
        for (&j, &b) in cols.iter().zip(&beta) {
            full[j] = b;
        }
        let sq: f64 = rows
            .iter()
            .map(|(x, y)| (y - x.iter().zip(&full).map(|(a, b)| a * b).sum::<f64>()).powi(2))
            .sum();
        if best.is_none_or(|(_, s)| sq < s) {
            best = Some((full, sq));
        }
    }
    best.map(|(b, _)| b)
}

/// [`least_squares`] on the columns `cols` of `rows` only.
fn least_squares_dyn<const K: usize>(rows: &[([f64; K], f64)], cols: &[usize]) -> Option<Vec<f64>> {
    let k = cols.len();
    let mut a = vec![vec![0.0f64; k]; k];
    let mut b = vec![0.0f64; k];
    for (x, y) in rows {
        for (i, &ci) in cols.iter().enumerate() {
            b[i] += x[ci] * y;
            for (j, &cj) in cols.iter().enumerate() {
                a[i][j] += x[ci] * x[cj];
            }
        }
    }
    solve_normal(a, b)
}

/// Solves the normal equations `a beta = b` by Gaussian elimination with partial pivoting; `None` if they are
/// singular.
fn solve_normal(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let k = b.len();
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    for col in 0..k {
        let pivot = (col..k).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        // A pivot no larger than the elimination's rounding (about k^2 operations on entries up to `scale`)
        // means the columns are dependent.
        if a[pivot][col].abs() <= (k * k) as f64 * f64::EPSILON * scale {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..k {
            let f = a[row][col] / a[col][col];
            let pivot_row = a[col].clone();
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut beta = vec![0.0f64; k];
    for i in (0..k).rev() {
        let tail: f64 = (i + 1..k).map(|j| a[i][j] * beta[j]).sum();
        beta[i] = (b[i] - tail) / a[i][i];
    }
    Some(beta)
}

/// Least squares `y = x . beta` (normal equations, Gaussian elimination with partial pivoting); `None` if they
/// are singular.
#[must_use]
pub fn least_squares<const K: usize>(rows: &[([f64; K], f64)]) -> Option<[f64; K]> {
    let cols: Vec<usize> = (0..K).collect();
    least_squares_dyn(rows, &cols)?.try_into().ok()
}

/// Instructions of a hierarchical table's frames split by kind of work: the least-squares fit
/// `instructions = overhead + per_link * links + per_judged * nodes judged + per_swept * nodes swept +
/// per_shot * shots` over the frames of one calibration script that change no light (frames with different
/// shares of the four separate their costs), and the rate bound built on it. A shot's setup (the shooter's
/// power, its run's bytes and decoder, the split between its leaf and inner receivers) is paid once per run:
/// where runs are short, or a frame shoots many nodes with few links each, it is a large part of the work, so
/// without its own rate the link and node rates fitted on one mix of shots do not bound frames of another (a
/// coarser Cornell table broke such a two-rate bound). Likewise a node judged in a round (a run's bounds and a
/// magnitude compared) is much cheaper than a node entered or left by a sweep (products and sums of its
/// chain's and its children's powers), and a budget cuts a frame anywhere in a round or a sweep, so one node
/// rate fitted on one mix of the two does not bound frames of another (shooting at a smaller round share
/// broke such a bound on fixed point, whose sweep visits are dearest).
///
/// The **rate bound** of a frame is the larger of a scaled and a shifted envelope of the fit's rates over
/// the calibration frames: `max(bound_overhead + bound_scale * w, bound_shift + w)`, with the frame's fitted
/// work `w = per_link * links + per_judged * judged + per_swept * swept + per_shot * shots + u * light_units`,
/// `u = max(per_link, per_swept, per_judged + per_shot)` the largest rate of a unit (negative fitted rates
/// count as 0; light-change units, member and chain walks, are no kind of the four and too few frames carry
/// them to fit a rate of their own, so they take the largest). So a frame heavy in links is not held to the
/// rate of a frame heavy in node visits. The scaled form is built as
/// the one-slope bound ([`calibrate`]):
/// `bound_overhead` is the largest of the fitted overhead, 0 and an idle calibration frame's instructions, and
/// `bound_scale` the largest ratio of a calibration frame's instructions over `bound_overhead` to its fitted
/// work (at least 1). The shifted form's `bound_shift` is the largest excess of a calibration frame's
/// instructions over its fitted work (at least an idle frame's instructions); it covers small frames whose
/// fixed costs (a sweep's end, the convergence test) the scaled form, tight at large frames, does not. Each
/// form covers every calibration frame, so their maximum does too. It is checked on every frame of every
/// script, with each frame's counts from the host simulator's bit-identical run. Before a frame runs, its
/// links and node visits are at most its budget and every shot follows a judging (of its node), so the same
/// maximum with `w = u * (budget + light_units)` bounds it.
#[derive(Clone, Debug, PartialEq)]
pub struct HierSplit {
    /// The build (log name).
    pub build: String,
    /// Calibration frames.
    pub samples: usize,
    /// Instructions per frame independent of the work.
    pub overhead: f64,
    /// Instructions per link applied.
    pub per_link: f64,
    /// Instructions per node judged in a round.
    pub per_judged: f64,
    /// Instructions per node visited by a sweep (entered or left).
    pub per_swept: f64,
    /// Instructions per shot (besides its links and the judging of its node).
    pub per_shot: f64,
    /// Root-mean-square residual of the fit relative to the root-mean-square instructions of its frames.
    pub residual: f64,
    /// Overhead of the rate bound.
    pub bound_overhead: f64,
    /// Factor of the rate bound's scaled form on the fitted rates.
    pub bound_scale: f64,
    /// Overhead of the rate bound's shifted form (the fitted rates unscaled).
    pub bound_shift: f64,
    /// Frames checked against the rate bound (all scripts).
    pub checked: usize,
    /// Frames whose measurement exceeded the rate bound.
    pub violations: usize,
    /// Smallest `1 - measured / bound` over the checked frames.
    pub worst_margin: f64,
    /// The frame with the smallest margin: (script, budget, measured).
    pub worst_frame: (String, u32, u64),
}

impl HierSplit {
    /// The fitted work of a frame (negative rates as 0): its links, nodes judged and swept, shots and
    /// light-change units (at the largest rate of a unit).
    fn work(&self, w: &HierFrameWork) -> f64 {
        let link = self.per_link.max(0.0);
        let (judged, swept, shot) =
            (self.per_judged.max(0.0), self.per_swept.max(0.0), self.per_shot.max(0.0));
        link * w.links as f64
            + judged * w.judged as f64
            + swept * w.swept as f64
            + shot * w.shots as f64
            + link.max(swept).max(judged + shot) * w.light_units as f64
    }

    /// The rate bound of a frame with the work `w`.
    #[must_use]
    pub fn bound(&self, w: &HierFrameWork) -> f64 {
        let work = self.work(w);
        (self.bound_overhead + self.bound_scale * work).max(self.bound_shift + work)
    }
}

/// Fits [`HierSplit`] on the frames of `calibrate` of `log`, with the work of each frame from `work` (from
/// [`hier_work`] on the same table and scripts, frame for frame).
///
/// # Errors
/// The log and the host's frames differ in number or order, or the fit is singular (too few distinct mixes).
pub fn hier_split(
    build: &str,
    log: &QemuLog,
    work: &[HierFrameWork],
    calibrate: &str,
) -> Result<HierSplit, String> {
    if log.frames.len() != work.len() || log.frames.iter().zip(work).any(|(f, w)| f.script != w.script) {
        return Err(format!(
            "{build}: the log's frames are not the host's ({} and {})",
            log.frames.len(),
            work.len()
        ));
    }
    // Frames that changed a light also carry the light change's cost, which a few such frames cannot
    // separate; they are left out.
    let cal: Vec<(&QemuFrame, &HierFrameWork)> =
        log.frames.iter().zip(work).filter(|(f, w)| f.script == calibrate && w.light_units == 0).collect();
    let rows: Vec<([f64; 5], f64)> = cal
        .iter()
        .map(|(f, w)| {
            let x = [1.0, w.links as f64, w.judged as f64, w.swept as f64, w.shots as f64];
            (x, f.instructions as f64)
        })
        .collect();
    let [overhead, per_link, per_judged, per_swept, per_shot] = nonnegative_rates(&rows).ok_or_else(|| {
        format!("{build}: the frames of {calibrate:?} do not separate links, nodes judged, nodes swept and shots")
    })?;
    let (mut sq, mut total) = (0.0f64, 0.0f64);
    for (x, y) in &rows {
        let r = y - (overhead + per_link * x[1] + per_judged * x[2] + per_swept * x[3] + per_shot * x[4]);
        sq += r * r;
        total += y * y;
    }
    let residual = if total > 0.0 { (sq / total).sqrt() } else { 0.0 };
    let mut m = HierSplit {
        build: build.to_string(),
        samples: cal.len(),
        overhead,
        per_link,
        per_judged,
        per_swept,
        per_shot,
        residual,
        bound_overhead: 0.0,
        bound_scale: 1.0,
        bound_shift: 0.0,
        checked: 0,
        violations: 0,
        worst_margin: f64::INFINITY,
        worst_frame: (String::new(), 0, 0),
    };
    let idle =
        cal.iter().filter(|(_, w)| w.links + w.judged + w.swept == 0).map(|(f, _)| f.instructions as f64);
    let idle = idle.fold(0.0f64, f64::max);
    m.bound_overhead = overhead.max(idle);
    m.bound_shift =
        cal.iter().map(|(f, w)| f.instructions as f64 - m.work(w)).fold(0.0f64, f64::max).max(idle);
    m.bound_scale = cal
        .iter()
        .map(|(f, w)| (f.instructions as f64 - m.bound_overhead, m.work(w)))
        .filter(|&(_, w)| w > 0.0)
        .map(|(excess, w)| excess / w)
        .fold(1.0f64, f64::max);
    for (f, w) in log.frames.iter().zip(work) {
        let bound = m.bound(w);
        let margin = 1.0 - f.instructions as f64 / bound;
        m.checked += 1;
        // As in `calibrate`: a calibration frame on the envelope may evaluate a few ulps above its bound.
        if f.instructions as f64 > bound * (1.0 + 8.0 * f64::EPSILON) {
            m.violations += 1;
        }
        if margin < m.worst_margin {
            m.worst_margin = margin;
            m.worst_frame = (f.script.clone(), f.budget, f.instructions);
        }
    }
    Ok(m)
}

/// The markdown section of [`hier_split`] for every log (`(name, log)`) of a hierarchical table and its
/// scripts, the number of frames over their rate bound, and every frame's work, instructions, rate bound and
/// margin as CSV (one line per frame of every log, after a header); the arithmetic of each log is read from
/// its frame lines.
///
/// # Errors
/// As [`hier_work`] and [`hier_split`].
pub fn hier_split_report(
    logs: &[(String, QemuLog)],
    table: &HierTable<'_>,
    file: &ScriptFile,
    calibrate: &str,
) -> Result<(String, usize, String), String> {
    let mut md = String::new();
    let mut csv = String::from(
        "build,script,frame,budget,instructions,links,judged,swept,shots,light_units,bound,margin\n",
    );
    let _ = writeln!(
        md,
        "\n## Hierarchical table: instructions per link, per node judged, per node swept and per shot\n\n\
         Least squares `instructions = overhead + per link * links + per judged * nodes judged + per swept * nodes \
         swept + per shot * shots` over the frames of `{calibrate}` that change no light; each frame's links, nodes \
         judged in a round, nodes entered or left by a sweep and shots (each run's setup) are counted by the host \
         simulator's bit-identical run (`firmware-sim/src/cost.rs`, `hier_split`). The rates are fitted \
         non-negative: a rate of 0 means that work moved in step with another kind over the calibration frames (a \
         table whose runs all hold a few links: links and shots), which then carries the cost of both. Residual: \
         RMS of the fit's residuals over RMS instructions. Rate bound of a frame: `bound overhead + scale * w`, \
         `w = per link * links + per judged * judged + per swept * swept + per shot * shots + u * light units`, `u \
         = max(per link, per swept, per judged + per shot)`, the fitted rates scaled to the upper envelope of the \
         calibration frames (bound overhead = max(overhead, 0, an idle calibration frame), scale = largest \
         (instructions - bound overhead) / w of a calibration frame, at least 1), or `bound shift + w`, the fitted \
         rates shifted up by the largest excess of a calibration frame, whichever is larger, checked on every frame \
         of every script with the host run's counts.\n"
    );
    let _ = writeln!(
        md,
        "| build | frames | overhead | instr. per link | instr. per node judged | instr. per node swept | instr. per \
         shot | residual | bound overhead | bound scale | bound shift | frames checked | over bound | worst margin | \
         worst frame (script, budget, measured) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut violations = 0;
    for (name, log) in logs {
        let arith = log
            .frames
            .first()
            .and_then(|f| f.key.split(',').nth(1))
            .and_then(Arith::from_name)
            .ok_or_else(|| format!("{name}: no frame lines"))?;
        let work = match arith {
            Arith::F32 => hier_work::<f32>(table, file)?,
            Arith::Fixed => hier_work::<radiosity_core::Fixed>(table, file)?,
        };
        let m = hier_split(name, log, &work, calibrate)?;
        violations += m.violations;
        for (k, (f, w)) in log.frames.iter().zip(&work).enumerate() {
            let bound = m.bound(w);
            let _ = writeln!(
                csv,
                "{name},{},{k},{},{},{},{},{},{},{},{bound:.0},{:.4}",
                f.script,
                f.budget,
                f.instructions,
                w.links,
                w.judged,
                w.swept,
                w.shots,
                w.light_units,
                1.0 - f.instructions as f64 / bound
            );
        }
        let _ = writeln!(
            md,
            "| {} | {} | {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1e} | {:.0} | {:.3} | {:.0} | {} | {} | {:.1} % | {}, {}, {} |",
            m.build,
            m.samples,
            m.overhead,
            m.per_link,
            m.per_judged,
            m.per_swept,
            m.per_shot,
            m.residual,
            m.bound_overhead,
            m.bound_scale,
            m.bound_shift,
            m.checked,
            m.violations,
            100.0 * m.worst_margin,
            m.worst_frame.0,
            m.worst_frame.1,
            m.worst_frame.2
        );
    }
    Ok((md, violations, csv))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_recovers_a_line() {
        let pts: Vec<(f64, f64)> = (0..10).map(|x| (f64::from(x), 3.0 + 2.5 * f64::from(x))).collect();
        let (a, b) = fit(&pts).unwrap();
        // Exact data: the only error is f64 rounding of sums of 10 terms of size <= 30.
        assert!((a - 3.0).abs() < 1e-12 && (b - 2.5).abs() < 1e-12, "a {a} b {b}");
        assert!(fit(&[(1.0, 1.0), (1.0, 2.0)]).is_none());
    }

    #[test]
    fn transfer_marginal_separates_per_group_from_per_element_per_build() {
        // 96 elements: 20 instructions per element plus 30 per element and group, exactly.
        let line = |groups: u32| {
            let instr = 96 * (20 + 30 * groups);
            format!("X,f32,s,-1,{},96,{groups},00,{instr}\n", 96 * (groups + 1))
        };
        let one = QemuLog::parse(&format!("{}{}", line(1), line(1))).unwrap();
        let four = QemuLog::parse(&line(4)).unwrap();
        assert_eq!(one.transfers.len(), 2);
        assert_eq!((one.transfers[0].frame, one.transfers[0].units, one.transfers[0].groups), (None, 192, 1));
        // A build of another CPU with other costs, at one group count only: no fit of its own, and not mixed in.
        let m0 = QemuLog::parse("X,f32,s,3,192,96,1,00,99999\n").unwrap();
        let logs = [("m4-f32".into(), one), ("four-lights-m4-f32".into(), four), ("m0-f32".into(), m0)];
        let m = transfer_marginal(&logs);
        assert_eq!(m.len(), 1, "{m:?}");
        assert_eq!((m[0].build.as_str(), m[0].elements, m[0].relights), ("m4-f32", 96, 3));
        assert!((m[0].per_group - 30.0).abs() < 1e-9 && (m[0].per_element - 20.0).abs() < 1e-9, "{m:?}");
        assert!(transfer_report(&logs).contains("| m4-f32 | 96 | 1, 4 | 3 | 30.0 | 20.0 |"));
    }

    #[test]
    fn least_squares_recovers_a_plane_and_refuses_a_singular_one() {
        let rows: Vec<([f64; 3], f64)> = (0..6)
            .map(|k| {
                let (u, v) = (f64::from(k), f64::from(k * k % 5));
                ([1.0, u, v], 10.0 + 3.0 * u + 7.0 * v)
            })
            .collect();
        let b = least_squares(&rows).unwrap();
        // Exact data; f64 rounding of sums of 6 terms of size <= 1000.
        for (got, want) in b.iter().zip([10.0, 3.0, 7.0]) {
            assert!((got - want).abs() < 1e-9, "{b:?}");
        }
        let collinear: Vec<([f64; 3], f64)> =
            (0..6).map(|k| ([1.0, f64::from(k), 2.0 * f64::from(k)], f64::from(k))).collect();
        assert!(least_squares(&collinear).is_none());
    }

    #[test]
    fn nonnegative_rates_hold_a_negative_rate_at_zero() {
        // Exact non-negative data: the plain fit's rates.
        let rows: Vec<([f64; 3], f64)> = (0..6)
            .map(|k| {
                let (u, v) = (f64::from(k), f64::from(k * k % 5));
                ([1.0, u, v], 10.0 + 3.0 * u + 7.0 * v)
            })
            .collect();
        let b = nonnegative_rates(&rows).unwrap();
        for (got, want) in b.iter().zip([10.0, 3.0, 7.0]) {
            assert!((got - want).abs() < 1e-9, "{b:?}");
        }
        // The second kind moves almost in step with the first (u + small noise) and the data has a cost in the
        // first only: the plain fit trades them and one rate comes out negative; the non-negative fit holds it
        // at 0 and the other rate carries the cost.
        let rows: Vec<([f64; 3], f64)> = (0..8)
            .map(|k| {
                let u = f64::from(k);
                let v = u + [0.1, -0.1, 0.2, 0.0, -0.2, 0.1, 0.0, -0.1][k as usize];
                ([1.0, u, v], 5.0 + 4.0 * u + [1.0, -1.0, 0.5, -0.5, 1.0, -1.0, 0.5, -0.5][k as usize])
            })
            .collect();
        let plain = least_squares(&rows).unwrap();
        assert!(plain[1] < 0.0 || plain[2] < 0.0, "the plain fit should trade the rates: {plain:?}");
        let b = nonnegative_rates(&rows).unwrap();
        assert!(b[1] >= 0.0 && b[2] >= 0.0 && (b[1] == 0.0 || b[2] == 0.0), "{b:?}");
        assert!((b[1] + b[2] - 4.0).abs() < 0.5, "{b:?}");
    }
}
