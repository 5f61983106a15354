//! Reports: a text table of rfloc's numbers next to the seed's published ones, and the same as
//! JSON. The plots are in [`crate::plot`].

use std::fmt::Write as _;

use crate::metrics::Summary;
use crate::published;

/// One line of the comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportRow {
    pub metric: String,
    /// rfloc's value, `None` when the run did not produce it.
    pub rfloc: Option<f64>,
    /// The published value: outer `None` = not published, inner `None` = "could not complete".
    pub published: Option<Option<f64>>,
    pub note: String,
}

/// rfloc's results for one scenario beside the published ones.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub scenario: String,
    /// Seed table the published numbers come from (empty when none).
    pub source: String,
    pub trials: usize,
    pub rows: Vec<ReportRow>,
    /// Lines printed under the table: failed trials and why, withheld published numbers.
    pub notes: Vec<String>,
    /// Per trial: `(trial, seed, success, reasons for failure)`.
    pub outcomes: Vec<(usize, u64, bool, Vec<String>)>,
}

impl Report {
    /// Joins a run summary of `scenario` with the published numbers of `published_key` (see
    /// [`crate::Scenario::published_key`]; `None`: rfloc's numbers only): published metrics
    /// first (in the seed's order), then rfloc-only metrics.
    #[must_use]
    pub fn new(scenario: &str, published_key: Option<&str>, summary: &Summary) -> Report {
        let ours = summary.metrics();
        let find = |k: &str| ours.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
        let mut rows = Vec::new();
        let pubd = published_key.and_then(published::for_scenario);
        if let Some(p) = pubd {
            for m in p.metrics {
                rows.push(ReportRow {
                    metric: m.key.to_string(),
                    rfloc: find(m.key),
                    published: Some(m.value),
                    note: m.note.to_string(),
                });
            }
        }
        for (k, v) in &ours {
            if !rows.iter().any(|r| &r.metric == k) {
                rows.push(ReportRow {
                    metric: k.clone(),
                    rfloc: Some(*v),
                    published: None,
                    note: String::new(),
                });
            }
        }
        Report {
            scenario: scenario.to_string(),
            source: pubd.map_or_else(String::new, |p| p.source.to_string()),
            trials: summary.trials,
            rows,
            notes: Vec::new(),
            outcomes: Vec::new(),
        }
    }

    /// Number of trials that failed.
    #[must_use]
    pub fn failures(&self) -> usize {
        self.outcomes.iter().filter(|o| !o.2).count()
    }

    /// The report as JSON: scenario, source, trials, every metric of the table under the same
    /// name (`metrics`), the published values (`published`), per-trial outcomes and the notes.
    #[must_use]
    pub fn json(&self) -> String {
        use serde_json::{json, Map, Value};
        // Non-finite numbers become null (serde_json has no NaN).
        let num = |v: f64| Value::from(v);
        let metrics: Map<String, Value> = self
            .rows
            .iter()
            .filter_map(|r| r.rfloc.map(|v| (r.metric.clone(), num(v))))
            .collect();
        let published: Map<String, Value> = self
            .rows
            .iter()
            .filter_map(|r| {
                r.published
                    .map(|p| (r.metric.clone(), p.map_or(Value::Null, num)))
            })
            .collect();
        let outcomes: Vec<Value> = self
            .outcomes
            .iter()
            .map(|(trial, seed, ok, why)| {
                json!({ "trial": trial, "seed": seed, "success": ok, "failures": why })
            })
            .collect();
        let report = json!({
            "scenario": self.scenario,
            "published_source": self.source,
            "trials": self.trials,
            "failures": self.failures(),
            "metrics": metrics,
            "published": published,
            "outcomes": outcomes,
            "notes": self.notes,
        });
        let mut text = serde_json::to_string_pretty(&report).unwrap_or_default();
        text.push('\n');
        text
    }

    /// A plain-text table (Markdown pipe table).
    #[must_use]
    pub fn table(&self) -> String {
        let fmt = |v: Option<f64>| v.map_or_else(|| "—".to_string(), |v| format!("{v:.4}"));
        let mut s = String::new();
        let _ = writeln!(s, "scenario {} ({} trials)", self.scenario, self.trials);
        if !self.source.is_empty() {
            let _ = writeln!(s, "published: {}", self.source);
        }
        let _ = writeln!(
            s,
            "| metric | rfloc | published | rfloc − published | note |"
        );
        let _ = writeln!(s, "|---|---:|---:|---:|---|");
        for r in &self.rows {
            let p = match r.published {
                None => "—".to_string(),
                Some(None) => "not completed".to_string(),
                Some(Some(v)) => format!("{v:.4}"),
            };
            let d = match (r.rfloc, r.published) {
                (Some(a), Some(Some(b))) => format!("{:+.4}", a - b),
                _ => "—".to_string(),
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} |",
                r.metric,
                fmt(r.rfloc),
                p,
                d,
                r.note
            );
        }
        let failed: Vec<String> = self
            .outcomes
            .iter()
            .filter(|o| !o.2)
            .map(|(trial, seed, _, why)| {
                let why = if why.is_empty() {
                    "goal not reached".to_string()
                } else {
                    why.join("; ")
                };
                format!("trial {trial} (seed {seed}): {why}")
            })
            .collect();
        if !failed.is_empty() {
            let _ = writeln!(s, "\nFAILED {} of {} trials:", failed.len(), self.trials);
            for f in failed {
                let _ = writeln!(s, "- {f}");
            }
        }
        for n in &self.notes {
            let _ = writeln!(s, "\nnote: {n}");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{ErrorStats, TrialResult};

    #[test]
    fn table_puts_published_beside_rfloc() {
        let r = TrialResult {
            trial: 0,
            seed: 1,
            errors: Some(ErrorStats {
                n: 10,
                rmse: 0.5,
                mean: 0.4,
                max: 1.0,
                rmse_theta: 0.05,
                mean_theta: 0.04,
                max_theta: 0.1,
            }),
            time_to_goal: None,
            success: true,
            extra: vec![("beacon_rmse_1_m".into(), 0.3)],
        };
        let rep = Report::new("x", Some("seed003-case1"), &Summary::from_trials(&[r]));
        let t = rep.table();
        assert!(t.contains("Table 3.2"), "{t}");
        assert!(t.contains("| rmse_m | 0.5000 | 0.6900 | -0.1900 |"), "{t}");
        assert!(
            t.contains("| beacon_rmse_1_m | 0.3000 | 0.3600 | -0.0600 |"),
            "{t}"
        );
        assert!(t.contains("| beacon_rmse_2_m | — | 0.3200 | — |"), "{t}");
        let e = Report::new("x", Some("seed001-e"), &Summary::from_trials(&[]));
        assert!(e
            .table()
            .contains("| time_to_goal_preliminary | — | not completed |"));
    }
}
