//! Reports: a text table of rfloc's numbers next to the seed's published ones, and an SVG
//! plot (hand-written SVG text) of the world, the true and the estimated trajectory.

use std::fmt::Write as _;

use crate::geometry::Point;
use crate::metrics::{Summary, TimedPose};
use crate::published;
use crate::world::World;

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
        let num = |v: f64| {
            if v.is_finite() {
                format!("{v}")
            } else {
                "null".to_string()
            }
        };
        let mut s = String::from("{\n");
        let _ = writeln!(s, "  \"scenario\": {},", json_str(&self.scenario));
        let _ = writeln!(s, "  \"published_source\": {},", json_str(&self.source));
        let _ = writeln!(s, "  \"trials\": {},", self.trials);
        let _ = writeln!(s, "  \"failures\": {},", self.failures());
        let metrics: Vec<String> = self
            .rows
            .iter()
            .filter_map(|r| {
                r.rfloc
                    .map(|v| format!("    {}: {}", json_str(&r.metric), num(v)))
            })
            .collect();
        let _ = writeln!(s, "  \"metrics\": {{\n{}\n  }},", metrics.join(",\n"));
        let published: Vec<String> = self
            .rows
            .iter()
            .filter_map(|r| {
                r.published.map(|p| {
                    format!(
                        "    {}: {}",
                        json_str(&r.metric),
                        p.map_or_else(|| "null".to_string(), num)
                    )
                })
            })
            .collect();
        if published.is_empty() {
            s.push_str("  \"published\": {},\n");
        } else {
            let _ = writeln!(s, "  \"published\": {{\n{}\n  }},", published.join(",\n"));
        }
        let outcomes: Vec<String> = self
            .outcomes
            .iter()
            .map(|(trial, seed, ok, why)| {
                let why: Vec<String> = why.iter().map(|w| json_str(w)).collect();
                format!(
                    "    {{ \"trial\": {trial}, \"seed\": {seed}, \"success\": {ok}, \"failures\": [{}] }}",
                    why.join(", ")
                )
            })
            .collect();
        let _ = writeln!(s, "  \"outcomes\": [\n{}\n  ],", outcomes.join(",\n"));
        let notes: Vec<String> = self.notes.iter().map(|n| json_str(n)).collect();
        let _ = writeln!(s, "  \"notes\": [{}]", notes.join(", "));
        s.push_str("}\n");
        s
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

/// A JSON string literal.
fn json_str(v: &str) -> String {
    let mut out = String::with_capacity(v.len() + 2);
    out.push('"');
    for c in v.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// What to draw besides the world.
#[derive(Debug, Clone, Default)]
pub struct PlotData<'a> {
    pub truth: &'a [TimedPose],
    pub estimate: &'a [TimedPose],
    /// Labelled estimated points (e.g. beacon estimates), drawn as crosses.
    pub marks: Vec<(String, Point)>,
    /// Waypoints or goal, drawn as diamonds.
    pub waypoints: Vec<Point>,
    pub title: String,
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Renders the world and trajectories as a standalone SVG document (y up, 1 m = `scale` px).
#[must_use]
pub fn svg(world: &World, data: &PlotData<'_>, scale: f64) -> String {
    let margin = 30.0;
    let (minx, miny, maxx, maxy) = (
        world.area_min.x,
        world.area_min.y,
        world.area_max.x,
        world.area_max.y,
    );
    let w = (maxx - minx) * scale + 2.0 * margin;
    let h = (maxy - miny) * scale + 2.0 * margin + 20.0;
    let px = |p: Point| {
        (
            margin + (p.x - minx) * scale,
            20.0 + margin + (maxy - p.y) * scale,
        )
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.1} {h:.1}">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{margin}" y="20" font-family="sans-serif" font-size="14">{}</text>"#,
        esc(&data.title)
    );
    // 1 m grid
    let _ = writeln!(s, r##"<g stroke="#e0e0e0" stroke-width="1">"##);
    let mut gx = minx.ceil();
    while gx <= maxx {
        let (a, b) = (px(Point::new(gx, miny)), px(Point::new(gx, maxy)));
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}"/>"#,
            a.0, a.1, b.0, b.1
        );
        gx += 1.0;
    }
    let mut gy = miny.ceil();
    while gy <= maxy {
        let (a, b) = (px(Point::new(minx, gy)), px(Point::new(maxx, gy)));
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}"/>"#,
            a.0, a.1, b.0, b.1
        );
        gy += 1.0;
    }
    let _ = writeln!(s, "</g>");
    for o in &world.obstacles {
        let pts: Vec<String> = o
            .vertices
            .iter()
            .map(|v| px(*v))
            .map(|(x, y)| format!("{x:.1},{y:.1}"))
            .collect();
        let _ = writeln!(
            s,
            r##"<polygon points="{}" fill="#c8c8c8"/>"##,
            pts.join(" ")
        );
    }
    let _ = writeln!(s, r##"<g stroke="black" stroke-width="2">"##);
    for wall in &world.walls {
        let (a, b) = (px(wall.a), px(wall.b));
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}"/>"#,
            a.0, a.1, b.0, b.1
        );
    }
    let _ = writeln!(s, "</g>");
    let _ = writeln!(s, r##"<g fill="none" stroke="#d04040" stroke-width="1">"##);
    for t in &world.uhf_tags {
        let (x, y) = px(t.position);
        let _ = writeln!(s, r#"<circle cx="{x:.1}" cy="{y:.1}" r="2"/>"#);
    }
    let _ = writeln!(s, "</g>");
    for t in &world.hf_tags {
        let (x, y) = px(t.position);
        let _ = writeln!(
            s,
            r##"<rect x="{:.1}" y="{:.1}" width="4" height="4" fill="#8040c0"/>"##,
            x - 2.0,
            y - 2.0
        );
    }
    for b in &world.beacons {
        let (x, y) = px(b.position);
        let _ = writeln!(
            s,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="6" fill="#30a030"/><text x="{:.1}" y="{:.1}" font-family="sans-serif" font-size="11">{}</text>"##,
            x + 8.0,
            y - 8.0,
            esc(&b.ni)
        );
    }
    if let Some(e) = &world.emitter {
        let (x, y) = px(e.position);
        let _ = writeln!(
            s,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="7" fill="#f0a000" stroke="black"/><text x="{:.1}" y="{:.1}" font-family="sans-serif" font-size="11">emitter</text>"##,
            x + 9.0,
            y - 9.0
        );
    }
    for wp in &data.waypoints {
        let (x, y) = px(*wp);
        let _ = writeln!(
            s,
            r##"<polygon points="{:.1},{:.1} {:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="#e02020"/>"##,
            x,
            y - 6.0,
            x + 6.0,
            y,
            x,
            y + 6.0,
            x - 6.0,
            y
        );
    }
    let path = |traj: &[TimedPose]| -> String {
        traj.iter()
            .map(|p| px(Point::new(p.pose.x, p.pose.y)))
            .map(|(x, y)| format!("{x:.1},{y:.1}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    if !data.truth.is_empty() {
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="#2060d0" stroke-width="2"/>"##,
            path(data.truth)
        );
    }
    if !data.estimate.is_empty() {
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="#e07000" stroke-width="1.5" stroke-dasharray="5,3"/>"##,
            path(data.estimate)
        );
    }
    for (label, p) in &data.marks {
        let (x, y) = px(*p);
        let _ = writeln!(
            s,
            r##"<path d="M{:.1},{:.1} L{:.1},{:.1} M{:.1},{:.1} L{:.1},{:.1}" stroke="#e07000" stroke-width="2"/><text x="{:.1}" y="{:.1}" font-family="sans-serif" font-size="10">{}</text>"##,
            x - 5.0,
            y - 5.0,
            x + 5.0,
            y + 5.0,
            x - 5.0,
            y + 5.0,
            x + 5.0,
            y - 5.0,
            x + 7.0,
            y + 12.0,
            esc(label)
        );
    }
    let ly = h - 8.0;
    let _ = writeln!(
        s,
        r##"<text x="{margin}" y="{ly:.0}" font-family="sans-serif" font-size="11"><tspan fill="#2060d0">— truth</tspan>  <tspan fill="#e07000">- - estimate</tspan></text>"##
    );
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{ErrorStats, TrialResult};
    use rfloc_pose::Pose2;
    use std::path::Path;

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

    #[test]
    fn svg_contains_world_and_both_paths() {
        let w = World::from_toml_str(
            "[area]\nmin=[0.0,0.0]\nmax=[4.0,3.0]\n[[obstacles]]\npoints=[[1.0,1.0],[2.0,1.0],[2.0,2.0]]\n[[xbee_beacons]]\nx=1.0\ny=2.5\naddress=\"1\"\nni=\"beacon<1>\"\n",
            Path::new("w"),
        )
        .unwrap();
        let truth: Vec<TimedPose> = (0..5)
            .map(|i| TimedPose::new(f64::from(i), Pose2::new(0.5 + 0.5 * f64::from(i), 0.5, 0.0)))
            .collect();
        let est = truth.clone();
        let s = svg(
            &w,
            &PlotData {
                truth: &truth,
                estimate: &est,
                title: "t & t".into(),
                ..PlotData::default()
            },
            100.0,
        );
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        assert_eq!(s.matches("<polyline").count(), 2);
        assert_eq!(s.matches("<polygon").count(), 1);
        assert!(s.contains("beacon&lt;1&gt;") && s.contains("t &amp; t"));
        // First truth point (0.5, 0.5) → (30 + 50, 20 + 30 + 250) px.
        assert!(s.contains("80.0,300.0"), "{s}");
    }
}
