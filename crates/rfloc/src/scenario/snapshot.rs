//! Simulated trials of the snapshot scenarios.

use std::path::Path;

use rfloc_sim::recorder::TrialRecorder;
use rfloc_sim::Scenario;

use super::SimOptions;

/// Runs one trial.
pub async fn run_trial(
    scenario: &Scenario,
    trial: usize,
    dir: &Path,
    opts: &SimOptions,
) -> anyhow::Result<TrialRecorder> {
    let _ = (scenario, trial, dir, opts);
    anyhow::bail!("the snapshot scenarios are not wired into rfloc sim yet")
}
