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

use crate::qemu::{QemuFrame, QemuLog};

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
        if f.instructions as f64 > bound {
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
/// (one instruction per cycle, an assumption stated in the report).
///
/// # Errors
/// As [`calibrate`].
pub fn report(logs: &[(String, QemuLog)], calibrate_on: &str, clock_mhz: f64) -> Result<CostReport, String> {
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
    Ok(CostReport { models, violations, markdown: md })
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
}
