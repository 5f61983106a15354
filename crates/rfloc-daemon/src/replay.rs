//! `rfloc replay`: the very device code of `rfloc run` over recorded links.
//!
//! Each `.cap` of a folder is one device. Its recording is cut into the sessions the device
//! opened (`mark link opened`), and the device's task runs over them exactly as it ran over the
//! live link: the same driver, the same client, stamps from the recorded read times. The run is
//! on paused time, so periodic pollers and time-outs go as fast as the recording is read.
//!
//! Observations reach the estimator thread in the order the live pipeline consumed them when
//! the folder holds that order (`pipeline.order`, written by `rfloc record`), so a replay of a
//! recorded run prints its POSE and TARGET lines byte for byte. Without it (captures from
//! elsewhere) they are merged by stamp, the capture's own marks are passed to the pipeline, and
//! the replay waits for a device's answer to each request the pipeline made of it.
//!
//! A folder with no pipeline to run prints the decoded observations as JSON lines.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use anyhow::Context;
use rfloc_capture::{Capture, Record, RecordKind};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::config::{DeviceConfig, EstimatorConfig, RobotConfig};
use crate::devices::{self, AntennaSource, DeviceContext, LinkSource, Resources, SweepMark};
use crate::estimator::{self, Input, Outputs, Route, Worker, ORDER_LOG, ORDER_LOG_HEADER};
use crate::events::DeviceEvent;
use crate::message::PoseFormat;
use crate::pipeline::{self, PipelineEnv, Request};
use crate::time::TimeOrigin;

/// What to replay with.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// Pipeline to run when there is no robot file (its default parameters).
    pub pipeline: Option<String>,
    /// The robot file (default: the folder's `robot.toml`, which `rfloc record` writes).
    pub config: Option<RobotConfig>,
    /// Print the observations instead of running a pipeline.
    pub observations: bool,
    /// Also write an MCAP file: every device's raw link bytes, the decoded observations, the
    /// poses, targets and the pipeline's scene.
    pub mcap: Option<PathBuf>,
}

/// Replays `dir` on its own paused runtime and returns the lines it prints.
pub fn replay_blocking(dir: &Path, opts: &ReplayOptions) -> anyhow::Result<Vec<String>> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .context("starting the replay runtime")?;
    rt.block_on(replay_lines(dir, opts))
}

/// One device's recording.
struct Recorded {
    name: String,
    capture: Capture,
}

fn read_captures(dir: &Path) -> anyhow::Result<Vec<Recorded>> {
    let mut caps = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "cap") {
            let capture = Capture::from_path(&path)?;
            let name = path
                .file_stem()
                .map_or_else(|| "device".to_string(), |s| s.to_string_lossy().to_string());
            caps.push(Recorded { name, capture });
        }
    }
    caps.sort_by(|a, b| a.name.cmp(&b.name));
    anyhow::ensure!(!caps.is_empty(), "no .cap files in {}", dir.display());
    Ok(caps)
}

/// The recorded sessions of a capture: cut at each `mark link opened` (a capture without such
/// marks is one session).
fn sessions(capture: &Capture) -> VecDeque<Capture> {
    let mut out: VecDeque<Capture> = VecDeque::new();
    let mut current: Vec<Record> = Vec::new();
    for r in &capture.records {
        if matches!(&r.kind, RecordKind::Event(t) if t == "mark link opened") && !current.is_empty()
        {
            out.push_back(Capture {
                header: capture.header.clone(),
                records: std::mem::take(&mut current),
            });
        }
        current.push(r.clone());
    }
    if !current.is_empty() || out.is_empty() {
        out.push_back(Capture {
            header: capture.header.clone(),
            records: current,
        });
    }
    out
}

/// The marks of a capture (text after `mark `) with their times.
fn marks(capture: &Capture) -> impl Iterator<Item = (f64, &str)> {
    capture
        .events()
        .filter_map(|(t, text)| text.strip_prefix("mark ").map(|m| (t, m)))
}

/// Marks a device task writes itself (not observations of the world).
fn is_driver_mark(text: &str) -> bool {
    text == "link opened" || text.starts_with("snapshot reads=") || SweepMark::parse(text).is_some()
}

/// The devices of the folder: the robot file's (those with a capture), or one per capture.
fn devices(caps: &[Recorded], cfg: Option<&RobotConfig>) -> anyhow::Result<Vec<DeviceConfig>> {
    let mut out = Vec::new();
    for rec in caps {
        let capture_device = rec.capture.header.device.clone().unwrap_or_default();
        let from_robot = cfg.and_then(|c| c.device(&rec.name)).cloned();
        let device = match from_robot {
            Some(d) => d,
            None => {
                let kind = devices::kind_for_capture(&capture_device).with_context(|| {
                    format!(
                        "{}.cap: no driver replays captures of device {capture_device:?}",
                        rec.name
                    )
                })?;
                let driver = kind.for_capture(&capture_device).with_context(|| {
                    format!(
                        "{}.cap: {capture_device:?} cannot be replayed without a robot file",
                        rec.name
                    )
                })?;
                DeviceConfig {
                    name: rec.name.clone(),
                    link: None,
                    stale_after_s: None,
                    driver,
                }
            }
        };
        out.push(device);
    }
    Ok(out)
}

/// The pipeline to run: the robot file's, the one named, or none (print observations).
fn estimator_for(
    dir: &Path,
    caps: &[Recorded],
    opts: &ReplayOptions,
) -> anyhow::Result<Option<EstimatorConfig>> {
    if opts.observations {
        return Ok(None);
    }
    if let Some(c) = &opts.config {
        return Ok(Some(c.estimator.clone()));
    }
    let has = |device: &str| {
        caps.iter().any(|c| {
            c.capture
                .header
                .device
                .as_deref()
                .is_some_and(|d| d.starts_with(device))
        })
    };
    match opts.pipeline.as_deref() {
        Some("snapshot") => Ok(Some(EstimatorConfig::Snapshot(snapshot_settings(dir)))),
        Some("emitter") => anyhow::bail!(
            "pipeline emitter has no default calibration (a1_dbm_at_1m): give the robot file with -c"
        ),
        Some(name) => EstimatorConfig::named(name).map(Some).with_context(|| {
            format!(
                "unknown pipeline {name:?} (one of {})",
                crate::config::PIPELINES.join(", ")
            )
        }),
        None if has("alien") && learned(dir, "survey.json") && has("pioneer") => {
            Ok(Some(EstimatorConfig::Snapshot(snapshot_settings(dir))))
        }
        None if has("pioneer") && !has("kts") && !has("xbee") && !has("alien") => {
            Ok(Some(EstimatorConfig::Odometry))
        }
        None => Ok(None),
    }
}

/// Snapshot settings for a session folder without a robot file: the tag map when the folder
/// holds `survey.json` and `tag-map.json`, the cluster database `snapshot-db.json` otherwise.
fn snapshot_settings(dir: &Path) -> crate::config::SnapshotSettings {
    let both = learned(dir, "survey.json") && learned(dir, "tag-map.json");
    crate::config::SnapshotSettings {
        survey: both.then(|| "survey.json".into()),
        tag_map: both.then(|| "tag-map.json".into()),
        ..crate::config::SnapshotSettings::default()
    }
}

/// Whether `dir` holds the learned file `name` (through its learned-state set).
fn learned(dir: &Path, name: &str) -> bool {
    rfloc_snapshot::state_set::resolve(dir, Path::new(name)).is_ok_and(|p| p.is_file())
}

/// The recorded consumption order: (device, stamp in ns).
fn read_order_log(dir: &Path) -> anyhow::Result<Option<Vec<(String, u64)>>> {
    let path = dir.join(ORDER_LOG);
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    anyhow::ensure!(
        text.lines().next() == Some(ORDER_LOG_HEADER),
        "{}: not a pipeline order log",
        path.display()
    );
    let mut out = Vec::new();
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.starts_with('#'))
    {
        let (device, ns) = line
            .split_once('\t')
            .and_then(|(d, n)| Some((d.to_string(), n.parse::<u64>().ok()?)))
            .with_context(|| format!("{}:{}: malformed line", path.display(), i + 1))?;
        out.push((device, ns));
    }
    Ok(Some(out))
}

/// A device being replayed.
struct Replayed {
    name: String,
    rx: mpsc::Receiver<DeviceEvent>,
    buffer: VecDeque<DeviceEvent>,
    closed: bool,
    /// Answered requests sent to it, and answers received (sweeps).
    asked: Arc<AtomicU64>,
    answered: u64,
    /// It speaks only when asked.
    on_request: bool,
}

impl Replayed {
    /// The next observation (status events are skipped); `None` once the task ended.
    async fn next(&mut self) -> Option<DeviceEvent> {
        if let Some(e) = self.buffer.pop_front() {
            return Some(e);
        }
        self.fill().await;
        self.buffer.pop_front()
    }

    /// Waits for one observation or the end of the task.
    async fn fill(&mut self) {
        tracing::trace!(device = %self.name, asked = self.asked.load(Ordering::Acquire), answered = self.answered, "replay waits for the device");
        while self.buffer.is_empty() && !self.closed {
            match self.rx.recv().await {
                Some(DeviceEvent::Status { state, detail, .. }) => {
                    tracing::debug!(device = %self.name, state = state.as_str(), %detail, "replay status");
                }
                Some(e) => {
                    if matches!(e, DeviceEvent::Sweep { .. }) {
                        self.answered += 1;
                    }
                    self.buffer.push_back(e);
                }
                None => self.closed = true,
            }
        }
    }

    /// Whether an observation may still come without the pipeline asking for it.
    fn may_speak(&self) -> bool {
        !self.closed && (!self.on_request || self.asked.load(Ordering::Acquire) > self.answered)
    }
}

/// The lines a replay of `dir` prints. Runs on the caller's runtime, which should be a paused
/// current-thread runtime ([`replay_blocking`]).
pub async fn replay_lines(dir: &Path, opts: &ReplayOptions) -> anyhow::Result<Vec<String>> {
    let caps = read_captures(dir)?;
    let robot_file = dir.join("robot.toml");
    let loaded;
    let cfg = match &opts.config {
        Some(c) => Some(c),
        None if opts.pipeline.is_none() && robot_file.is_file() => {
            loaded = RobotConfig::load(
                &robot_file,
                &crate::config::LoadOptions {
                    check_files: false,
                    extensions: &[],
                    for_replay: true,
                },
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?;
            Some(&loaded)
        }
        None => None,
    };
    let opts = ReplayOptions {
        config: cfg.cloned(),
        ..opts.clone()
    };
    let estimator_cfg = estimator_for(dir, &caps, &opts)?;
    let devices = devices(&caps, cfg)?;
    let order = if estimator_cfg.is_some() {
        read_order_log(dir)?
    } else {
        None
    };
    let origin = caps
        .iter()
        .find_map(|c| c.capture.header.started.as_deref())
        .map(TimeOrigin::parse_rfc3339)
        .transpose()
        .context("capture header `started`")?
        .unwrap_or_else(|| TimeOrigin::from_unix_ns(0));

    // Shared resources: the recorded antenna angles for a sweeping radio; sweep settings.
    let resources = Arc::new(Resources::default());
    if let Ok(mut scan) = resources.scan.lock() {
        *scan = Some(
            estimator_cfg
                .as_ref()
                .map_or_else(rfloc_bearing::ScanConfig::default, pipeline::scan_config),
        );
    }
    let stop = CancellationToken::new();
    let mut replayed = Vec::new();
    let mut routes = Vec::new();
    let mut tasks = Vec::new();
    for (device, rec) in devices.iter().zip(&caps) {
        let on_request = device.driver.handles(&Request::Sweep { heading_rad: 0.0 });
        if on_request {
            let angles: VecDeque<f64> = marks(&rec.capture)
                .filter_map(|(_, m)| match SweepMark::parse(m) {
                    Some(SweepMark::End { antenna_rad }) => Some(antenna_rad),
                    _ => None,
                })
                .flatten()
                .collect();
            resources.offer_antenna(AntennaSource::Recorded(angles));
        }
        let (ev_tx, ev_rx) = mpsc::channel(1 << 16);
        let (cmd_tx, cmd_rx) = mpsc::channel(1024);
        let ctx = DeviceContext::new(
            device.clone(),
            ev_tx,
            stop.clone(),
            LinkSource::Replay {
                sessions: std::sync::Mutex::new(sessions(&rec.capture)),
                mode: device.driver.replay_mode(),
                marks: marks(&rec.capture).map(|(_, m)| m.to_string()).collect(),
            },
            cfg.and_then(|c| c.source.dir.clone()),
            1.0,
            cmd_rx,
            Arc::clone(&resources),
        );
        let asked = Arc::new(AtomicU64::new(0));
        if on_request && estimator_cfg.is_none() {
            // No pipeline asks: the recorded requests do.
            for (_, m) in marks(&rec.capture) {
                if let Some(SweepMark::Start { heading_rad }) = SweepMark::parse(m) {
                    let _ = cmd_tx.try_send(Request::Sweep { heading_rad });
                    asked.fetch_add(1, Ordering::AcqRel);
                }
            }
        }
        routes.push(Route {
            device: device.name.clone(),
            driver: device.driver.clone(),
            queue: cmd_tx,
            answered_requests: Some(Arc::clone(&asked)),
        });
        tasks.push(device.driver.spawn(ctx));
        replayed.push(Replayed {
            name: device.name.clone(),
            rx: ev_rx,
            buffer: VecDeque::new(),
            closed: false,
            asked,
            answered: 0,
            on_request,
        });
    }

    let pipeline = match &estimator_cfg {
        Some(e) => Some(
            pipeline::build(
                e,
                PipelineEnv {
                    // Learned files: the robot file's state folder, or the session folder itself
                    // (a simulated trial keeps its survey, tag map and database there).
                    state_dir: cfg.map_or(Some(dir), |c| c.state.dir.as_deref()),
                    config_dir: cfg.map_or(Some(dir), |c| c.source.dir.as_deref()),
                },
            )
            .map_err(|e| anyhow::anyhow!("pipeline: {e}"))?,
        ),
        None => None,
    };
    // MCAP: the raw bytes of every link first (they are in the captures), then what the run
    // makes of them.
    let recording = match &opts.mcap {
        Some(path) => {
            let hub = rfloc_viz::Viz::new();
            let recording = hub
                .record(path)
                .with_context(|| format!("writing {}", path.display()))?;
            let out = crate::viz::VizOut::new(hub, origin);
            for rec in &caps {
                for r in &rec.capture.records {
                    match &r.kind {
                        RecordKind::Rx(b) => out.link_bytes(r.t(), &rec.name, true, b),
                        RecordKind::Tx(b) => out.link_bytes(r.t(), &rec.name, false, b),
                        RecordKind::Event(_) => {}
                    }
                }
            }
            Some((recording, out))
        }
        None => None,
    };
    let viz = recording.as_ref().map(|(_, out)| out.clone());
    let (lines_tx, lines_rx) = std::sync::mpsc::channel();
    let (ack_tx, mut ack_rx) = mpsc::unbounded_channel();
    let worker = Worker {
        pipeline,
        format: PoseFormat {
            frame_id: cfg.map_or_else(|| "map".into(), |c| c.robot.frame_id.clone()),
            child_frame_id: cfg
                .map_or_else(|| "base_link".into(), |c| c.robot.child_frame_id.clone()),
            precision: cfg.map_or(4, |c| c.pose.precision),
            origin,
        },
        stale_after: devices
            .iter()
            .map(|d| (d.name.clone(), d.stale_after()))
            .collect(),
        routes,
        outputs: Outputs {
            hub: None,
            stdout: false,
            collect: Some(lines_tx),
            order_log: None,
            scorer: None,
            ack: Some(ack_tx),
            viz: viz.clone(),
            fleet: None,
        },
        print_observations: estimator_cfg.is_none(),
    };
    let thread = estimator::spawn(worker, 1).context("starting the estimator thread")?;
    let feed = |input: Input| -> anyhow::Result<()> {
        thread
            .tx
            .send(input)
            .map_err(|_| anyhow::anyhow!("the estimator thread ended"))
    };

    // Capture marks that are observations of the world (log-less replays only).
    let mut world_marks: VecDeque<DeviceEvent> = VecDeque::new();
    if order.is_none() {
        let mut all: Vec<DeviceEvent> = caps
            .iter()
            .flat_map(|c| {
                marks(&c.capture)
                    .filter(|(_, m)| !is_driver_mark(m))
                    .map(|(t, m)| DeviceEvent::Mark {
                        device: c.name.clone(),
                        t,
                        text: m.to_string(),
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        all.sort_by(|a, b| a.time().unwrap_or(0.0).total_cmp(&b.time().unwrap_or(0.0)));
        world_marks.extend(all);
    }

    let mut fed = 0u64;
    let mut divergences = 0u64;
    // Progress on a terminal (hidden when stderr is not one).
    let progress = match &order {
        Some(o) => indicatif::ProgressBar::new(o.len() as u64),
        None => indicatif::ProgressBar::new_spinner(),
    };
    progress.set_draw_target(indicatif::ProgressDrawTarget::stderr());
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{prefix} {bar:30} {pos}/{len} observations {elapsed}",
    ) {
        progress.set_style(style);
    }
    progress.set_prefix("replay");
    match order {
        Some(order) => {
            for (device, ns) in order {
                progress.inc(1);
                if device == "daemon" {
                    break;
                }
                let Some(r) = replayed.iter_mut().find(|r| r.name == device) else {
                    anyhow::bail!("{ORDER_LOG} names device {device:?}, which has no capture here");
                };
                let Some(e) = r.next().await else {
                    anyhow::bail!(
                        "replay diverged: {device} ended before the recording's input {} (stamp {ns} ns)",
                        fed + 1
                    );
                };
                let got = rfloc_transport::clock_ns(&Seconds(e.time().unwrap_or(0.0)));
                if got != ns {
                    divergences += 1;
                    if divergences == 1 {
                        tracing::warn!(device = %device, recorded = ns, replayed = got, input = fed + 1, "replay stamp differs from the recording");
                    }
                }
                feed(Input::Event(e))?;
                fed += 1;
                wait_ack(&mut ack_rx, fed).await;
            }
        }
        None => loop {
            for r in replayed.iter_mut() {
                if r.buffer.is_empty() && r.may_speak() {
                    r.fill().await;
                }
            }
            let next_device = replayed
                .iter()
                .filter_map(|r| {
                    r.buffer
                        .front()
                        .map(|e| (e.time().unwrap_or(0.0), r.name.clone()))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)));
            let mark_first = match (&next_device, world_marks.front()) {
                (Some((t, _)), Some(m)) => m.time().unwrap_or(0.0) <= *t,
                (None, Some(_)) => true,
                _ => false,
            };
            let event = if mark_first {
                world_marks.pop_front()
            } else if let Some((_, name)) = next_device {
                replayed
                    .iter_mut()
                    .find(|r| r.name == name)
                    .and_then(|r| r.buffer.pop_front())
            } else {
                None
            };
            let Some(e) = event else { break };
            progress.inc(1);
            feed(Input::Event(e))?;
            fed += 1;
            wait_ack(&mut ack_rx, fed).await;
        },
    }
    progress.finish_and_clear();
    feed(Input::End)?;
    fed += 1;
    wait_ack(&mut ack_rx, fed).await;
    stop.cancel();
    for t in tasks {
        let _ = tokio::time::timeout(std::time::Duration::from_secs(5), t).await;
    }
    let _ = tokio::task::spawn_blocking(move || thread.handle.join()).await;
    if divergences > 0 {
        anyhow::bail!("replay diverged from the recording at {divergences} of {fed} inputs");
    }
    if let Some((recording, _)) = recording {
        recording.finish().context("finishing the MCAP file")?;
    }
    let lines: Vec<String> = lines_rx.try_iter().collect();
    Ok(lines)
}

async fn wait_ack(ack: &mut mpsc::UnboundedReceiver<u64>, n: u64) {
    while let Some(got) = ack.recv().await {
        if got >= n {
            break;
        }
    }
}

#[derive(Debug)]
struct Seconds(f64);

impl rfloc_transport::Clock for Seconds {
    fn now(&self) -> f64 {
        self.0
    }
}

/// Replays `dir` and prints its lines on stdout; an empty replay is an error.
pub fn replay_dir(dir: PathBuf, opts: &ReplayOptions) -> anyhow::Result<()> {
    let lines = replay_blocking(&dir, opts)?;
    anyhow::ensure!(
        !lines.is_empty(),
        "{}: the replay produced no poses and no observations",
        dir.display()
    );
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    for l in lines {
        if writeln!(out, "{l}").is_err() {
            break;
        }
    }
    Ok(())
}
