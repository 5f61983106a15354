//! Learns the tag map and the exploration trajectory of a finished snapshot trial again,
//! offline, and compares the trajectory with the truth: for tuning the joint learning on a
//! real exploration without running the whole trial.
//!
//! `cargo run --release -p rfloc-lab --example joint_offline -- TRIAL_DIR`
//!
//! `TRIAL_DIR` is a snapshot trial's folder (`survey.v1.json`, `tag-map.v1.json` for the
//! reader model, `exploration.csv` for the odometry and the truth). The `JointConfig` fields
//! can be overridden as `JOINT_<FIELD>=value` environment variables (for example
//! `JOINT_ROUNDS=4`); `JOINT_MAX_DRIFT_M=1e9` shows a trajectory the divergence check would
//! have replaced.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

use std::path::PathBuf;
use std::time::Instant;

use rfloc_lab::scenario::{write_exploration, ExplorationRow};
use rfloc_pose::Pose2;
use rfloc_snapshot::{learn_jointly, JointConfig, Survey, TagMap};

fn env<T: std::str::FromStr>(name: &str, v: &mut T) {
    if let Ok(s) = std::env::var(format!("JOINT_{}", name.to_ascii_uppercase())) {
        *v = s.parse().ok().expect(name);
    }
}

fn config() -> JointConfig {
    let mut c = JointConfig::default();
    env("chunk", &mut c.chunk);
    env("rounds", &mut c.rounds);
    env("odo_trans_abs", &mut c.odo_trans_abs);
    env("odo_trans_rel", &mut c.odo_trans_rel);
    env("odo_rot_abs", &mut c.odo_rot_abs);
    env("odo_rot_rel", &mut c.odo_rot_rel);
    env("odo_rot_per_m", &mut c.odo_rot_per_m);
    env("floor_xy", &mut c.floor_xy);
    env("floor_theta", &mut c.floor_theta);
    env("huber", &mut c.huber);
    env("gate", &mut c.gate);
    env("max_tag_sigma", &mut c.max_tag_sigma);
    env("min_tag_reads", &mut c.min_tag_reads);
    env("min_mapped", &mut c.min_mapped);
    env("relock_after", &mut c.relock_after);
    env("anchor_steps", &mut c.anchor_steps);
    env("max_drift_m", &mut c.max_drift_m);
    env("max_drift_rel", &mut c.max_drift_rel);
    env("revisit_steps", &mut c.revisit_steps);
    env("closure_rounds", &mut c.closure_rounds);
    env("closure_gap", &mut c.closure_gap);
    env("closure_stride", &mut c.closure_stride);
    env("closure_min_shared", &mut c.closure_min_shared);
    env("closure_unary_weight", &mut c.closure_unary_weight);
    c
}

fn summary(name: &str, mut e: Vec<f64>) {
    e.sort_by(f64::total_cmp);
    let n = e.len().max(1);
    let mean = e.iter().sum::<f64>() / n as f64;
    let at = |q: f64| e.get(((n - 1) as f64 * q) as usize).copied().unwrap_or(0.0);
    println!(
        "{name:<28} median {:.3} m  mean {mean:.3} m  p90 {:.3} m  max {:.3} m",
        at(0.5),
        at(0.9),
        at(1.0)
    );
}

fn main() {
    let dir = PathBuf::from(std::env::args().nth(1).expect("TRIAL_DIR"));
    let read = |name: &str| std::fs::read(dir.join(name)).expect(name);
    let survey = Survey::from_json(&read("survey.v1.json"), "survey.v1.json").unwrap();
    let map = TagMap::from_json(&read("tag-map.v1.json"), "tag-map.v1.json").unwrap();
    let rows: Vec<ExplorationRow> = csv::Reader::from_path(dir.join("exploration.csv"))
        .unwrap()
        .deserialize()
        .collect::<Result<_, _>>()
        .unwrap();
    let truth: Vec<Pose2> = rows.iter().map(|r| Pose2::new(r.x, r.y, r.theta)).collect();
    let odometry: Vec<Pose2> = rows
        .iter()
        .map(|r| Pose2::new(r.odom_x, r.odom_y, r.odom_theta))
        .collect();
    let samples: Vec<_> = survey
        .pairs()
        .map(|(s, _)| s)
        .zip(odometry.iter().copied())
        .collect();
    let cfg = config();
    let t = Instant::now();
    let (learned, poses, report) = learn_jointly(&samples, map.model.clone(), map.config, &cfg);
    println!("{:.1} s; {report:?}", t.elapsed().as_secs_f64());
    let errors =
        |p: &[Pose2]| -> Vec<f64> { p.iter().zip(&truth).map(|(a, b)| a.distance(b)).collect() };
    summary("odometry", errors(&odometry));
    summary("learned", errors(&poses));
    let all = errors(&poses);
    let n = all.len();
    for q in 0..4 {
        let r = n * q / 4..n * (q + 1) / 4;
        summary(
            &format!("learned, quarter {}", q + 1),
            all.get(r).unwrap_or(&[]).to_vec(),
        );
    }
    println!("tags mapped {}", learned.len());
    let out = dir.join("exploration-offline.csv");
    write_exploration(
        &out,
        truth
            .iter()
            .zip(&odometry)
            .zip(&poses)
            .map(|((t, o), l)| (*t, *o, *l)),
    )
    .unwrap();
    println!("wrote {}", out.display());
}
