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

use rfloc_pose::Pose2;
use rfloc_snapshot::{learn_jointly, JointConfig, Survey, TagMap};

#[derive(serde::Deserialize)]
struct Row {
    x: f64,
    y: f64,
    theta: f64,
    odom_x: f64,
    odom_y: f64,
    odom_theta: f64,
}

fn env(name: &str, v: &mut f64) {
    if let Ok(s) = std::env::var(format!("JOINT_{}", name.to_ascii_uppercase())) {
        *v = s.parse().expect(name);
    }
}

fn env_n(name: &str, v: &mut usize) {
    if let Ok(s) = std::env::var(format!("JOINT_{}", name.to_ascii_uppercase())) {
        *v = s.parse().expect(name);
    }
}

fn config() -> JointConfig {
    let mut c = JointConfig::default();
    env_n("chunk", &mut c.chunk);
    env_n("rounds", &mut c.rounds);
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
    env_n("min_tag_reads", &mut c.min_tag_reads);
    env_n("min_mapped", &mut c.min_mapped);
    env_n("relock_after", &mut c.relock_after);
    env_n("anchor_steps", &mut c.anchor_steps);
    env("max_drift_m", &mut c.max_drift_m);
    env("max_drift_rel", &mut c.max_drift_rel);
    env_n("revisit_steps", &mut c.revisit_steps);
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
    let rows: Vec<Row> = csv::Reader::from_path(dir.join("exploration.csv"))
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
    let mut w = csv::Writer::from_path(&out).unwrap();
    w.write_record([
        "step",
        "x",
        "y",
        "theta",
        "odom_x",
        "odom_y",
        "odom_theta",
        "learned_x",
        "learned_y",
        "learned_theta",
    ])
    .unwrap();
    for (i, ((t, o), l)) in truth.iter().zip(&odometry).zip(&poses).enumerate() {
        w.write_record(
            [
                i as f64, t.x, t.y, t.theta, o.x, o.y, o.theta, l.x, l.y, l.theta,
            ]
            .map(|v| v.to_string()),
        )
        .unwrap();
    }
    w.flush().unwrap();
    println!("wrote {}", out.display());
}
