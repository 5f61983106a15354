//! `run.mcap` of a simulated trial, written beside its captures with `rfloc-viz` from the same
//! data as the trial's other outputs:
//!
//! - every device's raw link bytes, from the trial's `.cap` files (`/rfloc/link`);
//! - the simulator's ground truth: the true pose at every record (`/rfloc/truth`) and the whole
//!   true path (`/rfloc/truth/path`);
//! - the trial's estimate (`estimate.csv`): the pose at every record (`/rfloc/pose`, without a
//!   covariance) and the whole estimated path (`/rfloc/path`);
//! - the known tag map (HF or UHF tags of the world, `/rfloc/tags`) and the estimated beacons at
//!   the end (`/rfloc/beacons`).
//!
//! Stamps: the captures' simulated seconds as Unix time from 1970-01-01T00:00:00Z, as `rfloc
//! replay --mcap` of the trial folder gives them (the captures carry no start date); the trial's
//! own times are put on that clock with [`TrialRecorder::to_capture_clock`]. Both paths are
//! published at the first stamp, so that they show during the whole playback.
//!
//! The decoded observations and the daemon's own scene are not here: `rfloc replay TRIAL --mcap
//! OUT.mcap --pipeline NAME` adds them from the same captures.

use std::path::Path;

use anyhow::Context;
use rfloc_capture::{Capture, RecordKind};
use rfloc_pose::Pose2;
use rfloc_sim::recorder::TrialRecorder;
use rfloc_sim::Scenario;
use rfloc_viz::{Direction, Landmark, LandmarkKind, Stamp, Viz};

/// The file name in the trial folder.
pub const FILE: &str = "run.mcap";

/// Seconds on the captures' clock as a stamp (times before 1970 are clamped to it).
fn stamp(t: f64) -> Stamp {
    Stamp::from_unix_secs(t.max(0.0)).unwrap_or(Stamp::from_unix_nanos(0))
}

/// Writes `dir/run.mcap` for a finished trial (replacing one left by an earlier run).
pub fn write(dir: &Path, scenario: &Scenario, rec: &TrialRecorder) -> anyhow::Result<()> {
    let path = dir.join(FILE);
    if path.exists() {
        std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
    }
    let viz = Viz::new();
    let recording = viz
        .record(&path)
        .with_context(|| format!("writing {}", path.display()))?;

    // The raw bytes of every link, device by device (the capture's file name is the device).
    let mut caps: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "cap"))
        .collect();
    caps.sort();
    for cap_path in &caps {
        let capture = Capture::from_path(cap_path)?;
        let device = cap_path
            .file_stem()
            .map_or_else(|| "device".to_string(), |s| s.to_string_lossy().to_string());
        for r in &capture.records {
            let (direction, bytes) = match &r.kind {
                RecordKind::Rx(b) => (Direction::Rx, b),
                RecordKind::Tx(b) => (Direction::Tx, b),
                RecordKind::Event(_) => continue,
            };
            viz.link_bytes(stamp(r.t()), &device, direction, bytes);
        }
    }

    let on_clock = |t: f64| stamp(rec.to_capture_clock(t));
    let first = rec
        .truth
        .first()
        .or(rec.estimate.first())
        .map_or(stamp(0.0), |p| on_clock(p.t));

    // The known tag map, once at the start.
    let world = &scenario.world;
    let tags: Vec<Landmark> = world
        .hf_tags
        .iter()
        .map(|t| (format!("{:X}", t.uid), t.position))
        .chain(world.uhf_tags.iter().map(|t| (t.epc.clone(), t.position)))
        .map(|(id, p)| Landmark {
            id,
            x: p.x,
            y: p.y,
            covariance: None,
        })
        .collect();
    if !tags.is_empty() {
        viz.landmarks(first, LandmarkKind::Tag, &tags);
    }

    // Both whole paths at the start, then the poses at their times.
    let poses = |v: &[rfloc_sim::TimedPose]| -> Vec<Pose2> { v.iter().map(|p| p.pose).collect() };
    if !rec.truth.is_empty() {
        viz.truth_path(first, &poses(&rec.truth));
    }
    if !rec.estimate.is_empty() {
        viz.path(first, &poses(&rec.estimate));
    }
    for p in &rec.truth {
        viz.truth(on_clock(p.t), &p.pose);
    }
    for p in &rec.estimate {
        viz.pose_without_covariance(on_clock(p.t), &p.pose);
    }

    // The beacon map the trial ended with.
    if !world.beacons.is_empty() && !rec.marks.is_empty() {
        let last = rec
            .truth
            .last()
            .or(rec.estimate.last())
            .map_or(first, |p| on_clock(p.t));
        let beacons: Vec<Landmark> = rec
            .marks
            .iter()
            .map(|(id, p)| Landmark {
                id: id.clone(),
                x: p.x,
                y: p.y,
                covariance: None,
            })
            .collect();
        viz.landmarks(last, LandmarkKind::Beacon, &beacons);
    }
    recording
        .finish()
        .with_context(|| format!("finishing {}", path.display()))?;
    Ok(())
}
