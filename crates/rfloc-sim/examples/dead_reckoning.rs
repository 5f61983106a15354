//! A no-radio baseline: drives a scenario's waypoints (or goal) with a pursuit controller
//! steering on the **odometry** pose, records truth and odometry, writes the outputs and
//! prints the report. Shows what the RF pipelines must beat and exercises the whole
//! recorder → report → SVG path.
//!
//! Run: `cargo run -p rfloc-sim --example dead_reckoning -- scenarios/seed003-case1.toml [outdir]`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use rfloc_pose::angle_diff;
use rfloc_sim::{write_outputs, RobotSim, Scenario, TrialRecorder};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: dead_reckoning <scenario.toml> [outdir]");
        return ExitCode::FAILURE;
    };
    let scenario = match Scenario::load(Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let out = args.get(1).map_or_else(
        || PathBuf::from("/tmp/rfloc-sim-baseline").join(&scenario.spec.name),
        PathBuf::from,
    );
    let recs: Vec<TrialRecorder> = (0..scenario.spec.trials)
        .map(|i| run_trial(&scenario, i))
        .collect();
    match write_outputs(&out, &scenario, &recs) {
        Ok(report) => {
            println!("{}", report.table());
            println!("outputs in {}", out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}

fn run_trial(s: &Scenario, trial: usize) -> TrialRecorder {
    let mut rec = TrialRecorder::new(s, trial);
    let mut robot = RobotSim::new(s.spec.robot.drive, s.start_pose(trial), s.trial_seed(trial));
    let mut targets: Vec<(f64, f64)> = s.spec.waypoints.iter().map(|w| (w[0], w[1])).collect();
    if let Some(g) = s.goal(trial) {
        targets.push((g.x, g.y));
    }
    let switch = s
        .spec
        .params
        .waypoint_switch_m
        .or(s.spec.goal.map(|g| g.tolerance_m))
        .unwrap_or(0.3);
    let mut next = 0usize;
    rec.truth(0.0, robot.truth());
    rec.estimate(0.0, robot.odometry());
    for k in 1..=s.steps() {
        let t = k as f64 * s.spec.dt_s;
        let est = robot.odometry();
        let Some(&(tx, ty)) = targets.get(next) else {
            break;
        };
        let (dx, dy) = (tx - est.x, ty - est.y);
        if dx.hypot(dy) < switch {
            next += 1;
            continue;
        }
        let err = angle_diff(dy.atan2(dx), est.theta);
        let v = if err.abs() < 0.4 { 0.4 } else { 0.0 };
        robot.step(v, (1.5 * err).clamp(-1.0, 1.0), s.spec.dt_s, &s.world);
        rec.truth(t, robot.truth());
        rec.estimate(t, robot.odometry());
    }
    rec
}
