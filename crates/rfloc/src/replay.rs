//! `rfloc replay`: the daemon's pipeline on captured device logs.

use std::path::PathBuf;

use crate::config::RobotConfig;

/// Replays every capture in `dir` through the pipeline and prints POSE lines.
pub async fn replay_dir(dir: PathBuf, pipeline: Option<String>, cfg: Option<RobotConfig>) -> anyhow::Result<()> {
    let _ = (dir, pipeline, cfg);
    anyhow::bail!("replay is not wired yet")
}
