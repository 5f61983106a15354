//! Recording one trial (truth and estimate trajectories, extra numbers) and writing a
//! scenario's outputs: per-trial `truth.csv`, `estimate.csv` (same format) and `plot.svg`,
//! plus `report.md` with the comparison table and `report.json` with the same metrics.

use std::path::Path;

use rfloc_pose::Pose2;

use crate::error::SimError;
use crate::geometry::Point;
use crate::metrics::{time_to_goal, trajectory_errors, Summary, TimedPose, TrialResult};
use crate::report::{svg, PlotData, Report};
use crate::scenario::Scenario;
use crate::truth;

/// Collects what happened in one trial.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialRecorder {
    pub trial: usize,
    pub seed: u64,
    pub truth: Vec<TimedPose>,
    pub estimate: Vec<TimedPose>,
    /// Goal and tolerance, when the scenario has a goal.
    pub goal: Option<(Point, f64)>,
    pub extra: Vec<(String, f64)>,
    /// Labelled estimated points for the plot (e.g. beacons).
    pub marks: Vec<(String, Point)>,
    success: Option<bool>,
    /// Why the trial failed (empty unless [`TrialRecorder::fail`] was called).
    failures: Vec<String>,
}

impl TrialRecorder {
    /// An empty record for trial `trial` of `scenario`.
    #[must_use]
    pub fn new(scenario: &Scenario, trial: usize) -> Self {
        Self {
            trial,
            seed: scenario.trial_seed(trial),
            truth: Vec::new(),
            estimate: Vec::new(),
            goal: scenario
                .goal(trial)
                .zip(scenario.spec.goal.map(|g| g.tolerance_m)),
            extra: Vec::new(),
            marks: Vec::new(),
            success: None,
            failures: Vec::new(),
        }
    }

    /// Marks the trial failed, for `reason` (shown in the report); it stays failed whatever
    /// [`TrialRecorder::set_success`] says.
    pub fn fail(&mut self, reason: impl Into<String>) {
        self.failures.push(reason.into());
    }

    /// The reasons given to [`TrialRecorder::fail`].
    #[must_use]
    pub fn failures(&self) -> &[String] {
        &self.failures
    }

    /// Appends a true pose.
    pub fn truth(&mut self, t: f64, pose: Pose2) {
        self.truth.push(TimedPose::new(t, pose));
    }

    /// Appends an estimated pose.
    pub fn estimate(&mut self, t: f64, pose: Pose2) {
        self.estimate.push(TimedPose::new(t, pose));
    }

    /// Adds a named number (e.g. `beacon_rmse_1_m`); repeated names are averaged by [`Summary`].
    pub fn metric(&mut self, name: &str, value: f64) {
        self.extra.push((name.to_string(), value));
    }

    /// Overrides success (default: the goal was reached, or `true` without a goal).
    pub fn set_success(&mut self, success: bool) {
        self.success = Some(success);
    }

    /// Scores the trial.
    #[must_use]
    pub fn finish(&self) -> TrialResult {
        let ttg = self
            .goal
            .and_then(|(g, tol)| time_to_goal(&self.truth, &g, tol));
        let success = self.failures.is_empty()
            && self.success.unwrap_or(self.goal.is_none() || ttg.is_some());
        TrialResult {
            trial: self.trial,
            seed: self.seed,
            errors: trajectory_errors(&self.truth, &self.estimate),
            time_to_goal: ttg,
            success,
            extra: self.extra.clone(),
        }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SimError + '_ {
    move |source| SimError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `dir/trial-NN/{truth.csv, estimate.csv, plot.svg}`, `dir/report.md` and
/// `dir/report.json`; returns the report. Published numbers appear only when the scenario is
/// its seed's own experiment ([`Scenario::published_key`]).
pub fn write_outputs(
    dir: &Path,
    scenario: &Scenario,
    trials: &[TrialRecorder],
) -> Result<Report, SimError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut results = Vec::with_capacity(trials.len());
    for rec in trials {
        let tdir = dir.join(format!("trial-{:02}", rec.trial));
        std::fs::create_dir_all(&tdir).map_err(io(&tdir))?;
        truth::write(&tdir.join("truth.csv"), &rec.truth)?;
        truth::write(&tdir.join("estimate.csv"), &rec.estimate)?;
        let mut waypoints: Vec<Point> = scenario
            .spec
            .waypoints
            .iter()
            .map(|w| Point::new(w[0], w[1]))
            .collect();
        waypoints.extend(rec.goal.map(|(g, _)| g));
        let plot = svg(
            &scenario.world,
            &PlotData {
                truth: &rec.truth,
                estimate: &rec.estimate,
                marks: rec.marks.clone(),
                waypoints,
                title: format!(
                    "{} trial {} (seed {})",
                    scenario.spec.name, rec.trial, rec.seed
                ),
            },
            svg_scale(scenario),
        );
        let p = tdir.join("plot.svg");
        std::fs::write(&p, plot).map_err(io(&p))?;
        results.push(rec.finish());
    }
    report_for(scenario, trials, &results, dir)
}

/// The report of finished trials, written to `dir/report.md` and `dir/report.json`.
fn report_for(
    scenario: &Scenario,
    trials: &[TrialRecorder],
    results: &[crate::metrics::TrialResult],
    dir: &Path,
) -> Result<Report, SimError> {
    let (key, withheld) = match scenario.published_key() {
        Ok(k) => (k, None),
        Err(why) => (None, Some(why)),
    };
    let mut report = Report::new(&scenario.spec.name, key, &Summary::from_trials(results));
    report.notes.extend(withheld);
    report.outcomes = trials
        .iter()
        .zip(results)
        .map(|(rec, r)| (rec.trial, rec.seed, r.success, rec.failures().to_vec()))
        .collect();
    let p = dir.join("report.md");
    std::fs::write(&p, report.table()).map_err(io(&p))?;
    let p = dir.join("report.json");
    std::fs::write(&p, report.json()).map_err(io(&p))?;
    Ok(report)
}

/// Pixels per metre so that the larger side of the area is about 800 px.
fn svg_scale(scenario: &Scenario) -> f64 {
    let w = &scenario.world;
    let span = (w.area_max.x - w.area_min.x).max(w.area_max.y - w.area_min.y);
    if span > 0.0 {
        800.0 / span
    } else {
        100.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: &str = r#"
name = "seed001-a"
pipeline = "emitter-full"
duration_s = 10.0
dt_s = 0.1
trials = 2
seed = 1
[robot]
start = { x = 0.0, y = 0.0 }
[goal]
x = 4.0
y = 0.0
tolerance_m = 0.5
[world]
area = { min = [-1.0, -1.0], max = [5.0, 1.0] }
emitter = { x = 4.0, y = 0.0 }
"#;

    #[test]
    fn records_score_and_write_outputs() {
        let s = Scenario::from_toml_str(S, Path::new("s.toml")).unwrap();
        let mut recs = Vec::new();
        for trial in 0..2 {
            let mut r = TrialRecorder::new(&s, trial);
            for k in 0..=40 {
                let t = f64::from(k) * 0.25;
                let x = if trial == 0 {
                    0.1 * f64::from(k)
                } else {
                    0.05 * f64::from(k)
                };
                r.truth(t, Pose2::new(x, 0.0, 0.0));
                r.estimate(t, Pose2::new(x, 0.1, 0.0));
            }
            recs.push(r);
        }
        let r0 = recs[0].finish();
        assert!(r0.success && (r0.time_to_goal.unwrap() - 8.75).abs() < 1e-9); // x = 3.5 at k = 35
        assert!((r0.errors.unwrap().rmse - 0.1).abs() < 1e-12);
        assert!(!recs[1].finish().success); // reaches only x = 2

        let dir = std::env::temp_dir().join(format!("rfloc-sim-out-{}", std::process::id()));
        let report = write_outputs(&dir, &s, &recs).unwrap();
        assert_eq!(report.trials, 2);
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        // Named like the seed's scenario but not its file: no published numbers.
        assert!(md.contains("| time_to_goal | 8.7500 | — |"), "{md}");
        assert!(md.contains("FAILED 1 of 2 trials"), "{md}");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(json["metrics"]["time_to_goal"], 8.75);
        assert_eq!(json["failures"], 1);
        assert_eq!(json["outcomes"][1]["success"], false);
        let back = truth::read(&dir.join("trial-01/truth.csv")).unwrap();
        assert_eq!(back, recs[1].truth);
        assert!(std::fs::read_to_string(dir.join("trial-00/plot.svg"))
            .unwrap()
            .contains("emitter"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
