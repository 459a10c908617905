//! What `radiosity check` reports: the error decomposition, every light setting and every frame.

use std::fmt;

use firmware_sim::sim::Arith;
use serde::Serialize;

use crate::evaluate::{Component, Discretization, QUANTIZATION};
use crate::metrics::ErrorReport;
use crate::picture::plot::Plot;
use crate::rgb::Rgb;

/// One device frame compared with the exact answer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// Arithmetic path (serialized `f32` or `fixed`).
    pub arith: Arith,
    /// Light setting (0 = default, then the relight sequence).
    pub setting: usize,
    /// Frame within the setting (from 1).
    pub frame: usize,
    /// Work units this frame.
    pub work: u32,
    /// Work units since the setting began (light-change cost excluded; see `relight_work`).
    pub work_total: u64,
    /// Outcome of the frame's step: `converged`, `budget`, or `no progress: REASON`.
    pub outcome: String,
    /// Relative L2 error against the exact answer.
    pub rel_l2: f64,
    /// Max per-patch relative error against the exact answer.
    pub max_rel: f64,
    /// Luminance relative L2 error against the exact answer.
    pub luminance_rel_l2: f64,
}

/// Summary of one light setting on one arithmetic path.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Setting {
    /// Arithmetic path.
    pub arith: Arith,
    /// Index of the setting.
    pub setting: usize,
    /// Intensity of every dynamic group in this setting.
    pub intensity: Vec<Rgb>,
    /// Work units [`radiosity_core::Solver::set_light`] reported for the change (0 for the cold start).
    pub relight_work: u64,
    /// Frames run.
    pub frames: usize,
    /// Work units in the step budgets.
    pub work: u64,
    /// Whether the last frame converged.
    pub converged: bool,
    /// Error of the last frame against the exact answer.
    pub error: ErrorReport,
}

/// The result of a check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CheckReport {
    /// The table's method: `flat` (patch-to-patch form factors) or `hierarchical` (a tree and links).
    pub method: String,
    /// What every frame is compared with ("the exact answer"): for a flat table the f64 solve of the scene's
    /// matrix, for a hierarchical one the hierarchical f64 solve; both relit at the frame's intensities.
    pub exact: String,
    /// Patches (of a flat table) or leaves (of a hierarchical one): the elements the device gives radiosity for.
    pub patches: usize,
    /// Table entries: stored form factors (flat) or links (hierarchical).
    pub entries: usize,
    /// Table bytes.
    pub table_bytes: usize,
    /// Codec name.
    pub codec: String,
    /// Names of the dynamic light groups, in table order (the order of [`Setting::intensity`]).
    pub light_groups: Vec<String>,
    /// Work units per frame.
    pub budget: u32,
    /// Frames per setting (`None`: to convergence).
    pub frames_per_setting: Option<usize>,
    /// Solver tolerance in power units.
    pub tolerance: f64,
    /// Whether the tolerance asked for was below fixed point's convergence floor for this table and was raised to
    /// it ([`super::CheckOptions::tolerance_floor`]).
    pub tolerance_raised: bool,
    /// The error decomposition.
    pub components: Vec<Component>,
    /// The quantization component split by code, printed under it (empty for a table checked without its
    /// bake; [`crate::evaluate::Evaluation::quantization_parts`]).
    pub quantization_parts: Vec<Component>,
    /// Every light setting on every arithmetic path.
    pub settings: Vec<Setting>,
    /// Every frame.
    pub frames: Vec<Frame>,
    /// The discretization component's per-face rows (`None` unless the check asked for the continuous
    /// reference); its [`Component`] is also the first of `components`.
    pub discretization: Option<Discretization>,
}

impl CheckReport {
    /// What the table's elements and entries are called: patches and entries of a flat table, leaves and links of
    /// a hierarchical one.
    #[must_use]
    pub fn element_names(&self) -> (&'static str, &'static str) {
        if self.method == "hierarchical" {
            ("leaves", "links")
        } else {
            ("patches", "entries")
        }
    }

    /// The error decomposition as grouped bars: one group per arithmetic path (`f32`, `fixed`), one bar per
    /// component (relative L2 of `B`, area-weighted) on its own, the path's own arithmetic component among
    /// them, and last the measured total: the device's error against the exact answer at the default setting.
    /// The components are L2 norms of differences between successive answers; norms do not add (the total is
    /// at most their sum, often much less), so the bars stand side by side on a log axis instead of stacking.
    #[must_use]
    pub fn decomposition_plot(&self, title: &str) -> Plot {
        let arith: Vec<String> = self
            .components
            .iter()
            .filter_map(|c| c.name.strip_prefix("arithmetic (").and_then(|r| r.strip_suffix(')')))
            .map(str::to_string)
            .collect();
        let mut components: Vec<(String, Vec<f64>)> = self
            .components
            .iter()
            .filter(|c| !c.name.starts_with("arithmetic ("))
            .map(|c| (c.name.clone(), vec![c.error.rel_l2; arith.len()]))
            .collect();
        let own: Vec<f64> = arith
            .iter()
            .map(|a| {
                let name = format!("arithmetic ({a})");
                self.components.iter().find(|c| c.name == name).map_or(0.0, |c| c.error.rel_l2)
            })
            .collect();
        components.push(("arithmetic".into(), own));
        let total: Vec<f64> = arith
            .iter()
            .map(|a| {
                self.settings
                    .iter()
                    .find(|s| s.setting == 0 && s.arith.to_string() == *a)
                    .map_or(0.0, |s| s.error.rel_l2)
            })
            .collect();
        components.push(("total: device vs exact (not the sum)".into(), total));
        Plot::GroupedBars {
            title: title.into(),
            y_label: "relative L2 error of B (area-weighted; norms do not add)".into(),
            categories: arith,
            components,
        }
    }
}

impl fmt::Display for CheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (elements, entries) = self.element_names();
        writeln!(
            f,
            "table ({}): {} {elements}, {} {entries}, {} bytes, codec {}; budget {} units/frame, frames {}, \
             tolerance {:.3e}{}",
            self.method,
            self.patches,
            self.entries,
            self.table_bytes,
            self.codec,
            self.budget,
            self.frames_per_setting.map_or("to convergence".to_string(), |n| n.to_string()),
            self.tolerance,
            if self.tolerance_raised {
                " (raised to fixed point's convergence floor for this table)"
            } else {
                ""
            }
        )?;
        writeln!(f, "light groups (table order): {}", self.light_groups.join(", "))?;
        writeln!(f, "\nerror decomposition (default intensities)")?;
        writeln!(f, "{:<24} {:>10} {:>10} {:>10}  compares", "component", "rel L2", "max rel", "lum L2")?;
        for c in &self.components {
            writeln!(
                f,
                "{:<24} {:>10.3e} {:>10.3e} {:>10.3e}  {}",
                c.name, c.error.rel_l2, c.error.max_rel, c.error.luminance_rel_l2, c.compares
            )?;
            if c.name == QUANTIZATION {
                for p in &self.quantization_parts {
                    writeln!(
                        f,
                        "  {:<22} {:>10.3e} {:>10.3e} {:>10.3e}  {}",
                        p.name, p.error.rel_l2, p.error.max_rel, p.error.luminance_rel_l2, p.compares
                    )?;
                }
            }
        }
        if let Some(d) = &self.discretization {
            write!(f, "{d}")?;
        }
        writeln!(f, "\ndevice vs {}, last frame of each setting", self.exact)?;
        let first_group = self.light_groups.first().map_or("none", String::as_str);
        writeln!(
            f,
            "{:<6} {:<3} {:<24} {:>7} {:>12} {:>10} {:>10} {:>10} {:>10}",
            "arith",
            "#",
            format!("intensity ({first_group})"),
            "frames",
            "work",
            "relight",
            "rel L2",
            "max rel",
            "converged"
        )?;
        for s in &self.settings {
            let i = s
                .intensity
                .first()
                .map_or("-".to_string(), |v| format!("({:.2}, {:.2}, {:.2})", v[0], v[1], v[2]));
            // With every light off the exact answer is zero and a relative error has no meaning: the device's
            // distance from dark is its RMS radiosity instead.
            let (rel, max) = if s.error.rel_l2.is_finite() {
                (format!("{:.3e}", s.error.rel_l2), format!("{:.3e}", s.error.max_rel))
            } else {
                ("dark".to_string(), "-".to_string())
            };
            writeln!(
                f,
                "{:<6} {:<3} {:<24} {:>7} {:>12} {:>10} {:>10} {:>10} {:>10}",
                s.arith.name(),
                s.setting,
                i,
                s.frames,
                s.work,
                s.relight_work,
                rel,
                max,
                s.converged
            )?;
        }
        for s in self.settings.iter().filter(|s| !s.error.rel_l2.is_finite()) {
            writeln!(
                f,
                "  {} setting {}: the exact answer is zero (no light); the device's RMS radiosity {:.3e} W/m^2",
                s.arith.name(),
                s.setting,
                s.error.abs_rms
            )?;
        }
        writeln!(f, "\nfirst frames of setting 0 (all frames: --format json)")?;
        writeln!(f, "{:<6} {:>6} {:>12} {:>10} {:>10}", "arith", "frame", "work", "rel L2", "max rel")?;
        for fr in self.frames.iter().filter(|fr| fr.setting == 0 && (fr.frame <= 4 || fr.frame % 16 == 0)) {
            writeln!(
                f,
                "{:<6} {:>6} {:>12} {:>10.3e} {:>10.3e}",
                fr.arith.name(),
                fr.frame,
                fr.work_total,
                fr.rel_l2,
                fr.max_rel
            )?;
        }
        Ok(())
    }
}
