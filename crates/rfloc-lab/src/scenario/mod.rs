//! `rfloc sim <scenario>`: runs a seed scenario through the daemon's drivers and pipelines
//! against emulated devices, records every device link and the ground truth, and reports the
//! scenario's metrics next to the numbers its seed published.
//!
//! Each system has one module with `run_trial`, which sets up emulators for one trial, runs
//! the real clients over ptys/loopback sockets with captures recorded into the trial's folder,
//! and fills a [`TrialRecorder`] with truth and estimates. Each trial then gets its `run.mcap`
//! ([`run_mcap`]); the scenario's plots and reports are written at the end.

use std::path::{Path, PathBuf};

use anyhow::Context;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rfloc_sim::recorder::{write_outputs, TrialRecorder};
use rfloc_sim::{Pipeline as ScenarioPipeline, Scenario};

mod ekfslam;
mod emitter;
pub(crate) mod hfinit;
mod lockstep;
pub mod run_mcap;
pub(crate) mod snapshot;

pub use snapshot::{write_exploration, ExplorationRow};

/// Options of a simulated run.
#[derive(Debug, Clone, Default)]
pub struct SimOptions {
    /// Output folder (captures, truth.csv, report); default `out/<scenario name>`.
    pub out: Option<PathBuf>,
    /// Run only this many trials (default: the scenario's count).
    pub trials: Option<usize>,
    /// The run's progress bar (set by [`run`]); trial notes are printed above it.
    pub progress: Option<ProgressBar>,
}

impl SimOptions {
    /// Prints a line on stderr, above the progress bar when there is one.
    pub fn note(&self, line: &str) {
        match &self.progress {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}

/// A progress bar of `trials` trials on stderr; it draws nothing when stderr is not a terminal.
fn progress_bar(name: &str, trials: usize) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(Some(trials as u64), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{prefix} {bar:30} trial {pos}/{len} {elapsed} (eta {eta})")
    {
        bar.set_style(style);
    }
    bar.set_prefix(name.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(500));
    bar
}

/// Where one trial writes its captures.
#[must_use]
pub fn trial_dir(out: &Path, trial: usize) -> PathBuf {
    out.join(format!("trial-{trial:02}"))
}

/// What a finished run reports to the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimOutcome {
    pub trials: usize,
    /// Trials that failed (goal or last waypoint not reached, a beacon not mapped, arrival
    /// declared away from the goal, no initial pose).
    pub failures: usize,
}

/// Runs every trial of a scenario, writes the outputs and prints the report table.
pub async fn run(path: &Path, opts: SimOptions) -> anyhow::Result<SimOutcome> {
    let scenario =
        Scenario::load(path).with_context(|| format!("loading scenario {}", path.display()))?;
    let name = scenario.spec.name.clone();
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&name));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let trials = opts.trials.unwrap_or(scenario.spec.trials).max(1);
    let mut recs: Vec<TrialRecorder> = Vec::with_capacity(trials);
    let progress = progress_bar(&name, trials);
    let opts = SimOptions {
        progress: Some(progress.clone()),
        ..opts
    };
    for trial in 0..trials {
        let dir = trial_dir(&out, trial);
        std::fs::create_dir_all(&dir)?;
        let rec = match scenario.spec.pipeline {
            ScenarioPipeline::HfInit => hfinit::run_trial(&scenario, trial, &dir, &opts).await?,
            ScenarioPipeline::EkfSlam => ekfslam::run_trial(&scenario, trial, &dir, &opts).await?,
            ScenarioPipeline::Snapshot => {
                snapshot::run_trial(&scenario, trial, &dir, &opts).await?
            }
            ScenarioPipeline::EmitterPreliminary | ScenarioPipeline::EmitterFull => {
                emitter::run_trial(&scenario, trial, &dir, &opts).await?
            }
        };
        run_mcap::write(&dir, &scenario, &rec)
            .with_context(|| format!("trial {trial}: {}", run_mcap::FILE))?;
        recs.push(rec);
        progress.inc(1);
    }
    progress.finish_and_clear();
    let report = write_outputs(&out, &scenario, &recs)?;
    println!("{}", report.table());
    println!("outputs: {}", out.display());
    Ok(SimOutcome {
        trials,
        failures: report.failures(),
    })
}
