//! What `radiosity regress` prints: one row per compared value.

use std::fmt;

use serde::Serialize;

/// One compared value.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Row {
    /// Scene file.
    pub scene: String,
    /// Code width of the baseline entry.
    pub bits: u32,
    /// Codec actually used (differs from the baseline's when degraded on purpose).
    pub codec: String,
    /// Component name.
    pub component: String,
    /// `rel_l2` or `max_rel`.
    pub metric: &'static str,
    /// Baseline mean (`None`: not in the baseline).
    pub baseline: Option<f64>,
    /// Baseline noise.
    pub noise: Option<f64>,
    /// The limit `mean + k noise + floor` (check) or `None` (update).
    pub limit: Option<f64>,
    /// The new value (check: at the first seed; update: the new mean).
    pub value: Option<f64>,
    /// New noise (update only).
    pub new_noise: Option<f64>,
    /// Whether the value is within its limit (always true on update).
    pub ok: bool,
}

/// Rows of a check or an update.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegressReport {
    /// `check` or `update`.
    pub mode: &'static str,
    /// The noise multiplier `k`.
    pub k: f64,
    /// Every compared value.
    pub rows: Vec<Row>,
    /// Problems that are not a single value (scene not in the baseline, baseline scene no longer shipped).
    pub problems: Vec<String>,
}

impl RegressReport {
    /// Whether every value is within its limit and nothing is missing.
    #[must_use]
    pub fn passed(&self) -> bool {
        self.problems.is_empty() && self.rows.iter().all(|r| r.ok)
    }

    /// The rows over their limits.
    #[must_use]
    pub fn failures(&self) -> Vec<&Row> {
        self.rows.iter().filter(|r| !r.ok).collect()
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.3e}"))
}

impl fmt::Display for RegressReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.mode == "update" {
            writeln!(f, "baseline update (old and new: mean and noise over the seeds), k = {:.3}", self.k)?;
            writeln!(
                f,
                "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}",
                "scene", "codec", "component", "metric", "old mean", "old noise", "new mean", "new noise"
            )?;
            for r in &self.rows {
                writeln!(
                    f,
                    "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}",
                    r.scene,
                    r.codec,
                    r.component,
                    r.metric,
                    opt(r.baseline),
                    opt(r.noise),
                    opt(r.value),
                    opt(r.new_noise)
                )?;
            }
        } else {
            writeln!(f, "regression check: limit = mean + k noise + 8 n eps, k = {:.3}", self.k)?;
            writeln!(
                f,
                "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}  status",
                "scene", "codec", "component", "metric", "baseline", "noise", "limit", "now"
            )?;
            for r in &self.rows {
                writeln!(
                    f,
                    "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}  {}",
                    r.scene,
                    r.codec,
                    r.component,
                    r.metric,
                    opt(r.baseline),
                    opt(r.noise),
                    opt(r.limit),
                    opt(r.value),
                    if r.ok { "ok" } else { "FAIL" }
                )?;
            }
            let failed = self.failures().len();
            writeln!(f, "{} values, {} over their limit", self.rows.len(), failed)?;
        }
        for p in &self.problems {
            writeln!(f, "problem: {p}")?;
        }
        Ok(())
    }
}
