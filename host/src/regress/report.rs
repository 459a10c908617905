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
        let update = self.mode == "update";
        // Both modes print the same row: four key columns, four values and, when checking, a status.
        let line = |f: &mut fmt::Formatter<'_>, key: [&str; 4], values: [&str; 4], status: &str| {
            let [scene, codec, component, metric] = key;
            let [a, b, c, d] = values;
            writeln!(
                f,
                "{scene:<28} {codec:<9} {component:<20} {metric:<8} {a:>10} {b:>10} {c:>10} {d:>10}{status}"
            )
        };
        if update {
            writeln!(f, "baseline update (old and new: mean and noise over the seeds), k = {:.3}", self.k)?;
        } else {
            writeln!(f, "regression check: limit = mean + k noise + 8 n eps, k = {:.3}", self.k)?;
        }
        let (labels, status) = if update {
            (["old mean", "old noise", "new mean", "new noise"], "")
        } else {
            (["baseline", "noise", "limit", "now"], "  status")
        };
        line(f, ["scene", "codec", "component", "metric"], labels, status)?;
        for r in &self.rows {
            let values = if update {
                [r.baseline, r.noise, r.value, r.new_noise]
            } else {
                [r.baseline, r.noise, r.limit, r.value]
            }
            .map(opt);
            let status = match (update, r.ok) {
                (true, _) => "",
                (false, true) => "  ok",
                (false, false) => "  FAIL",
            };
            let key = [r.scene.as_str(), r.codec.as_str(), r.component.as_str(), r.metric];
            line(f, key, [&values[0], &values[1], &values[2], &values[3]], status)?;
        }
        if !update {
            let over = self.failures().len();
            writeln!(
                f,
                "{}, {} over {} limit",
                crate::text::counted(self.rows.len(), "value", "values"),
                over,
                if over == 1 { "its" } else { "their" }
            )?;
        }
        for p in &self.problems {
            writeln!(f, "problem: {p}")?;
        }
        Ok(())
    }
}
