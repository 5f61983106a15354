//! `rfloc run`: device tasks under one cancellation token, the estimator thread, the pose
//! stream, stale detection and systemd notifications.
//!
//! ```text
//! device tasks ──DeviceEvent──▶ router task ──bounded queue──▶ estimator thread ──▶ pose hub, stdout
//!   (one per device,              (DEVICE lines, wall-time        (pipeline, POSE/TARGET,
//!    tokio runtime)                stale detection, watchdog)       requests ──▶ device queues)
//! ```

use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use anyhow::Context;
use rfloc_transport::{MonotonicClock, SharedClock};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::config::RobotConfig;
use crate::devices::{DeviceContext, LinkSource, Resources};
use crate::estimator::{self, Input, Outputs, Route, Worker};
use crate::events::{DeviceEvent, DeviceState};
use crate::message::{self, PoseFormat};
use crate::notify;
use crate::pipeline::{self, PipelineEnv};
use crate::server::{bind_unix, PoseHub};
use crate::simulation::{Simulation, SimulationIo};
use crate::time::TimeOrigin;

/// Options of one run that do not come from the robot file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Print POSE and TARGET lines on stdout.
    pub stdout: bool,
    /// Record every device link (and the pipeline's input order) into this folder.
    pub capture_dir: Option<PathBuf>,
}

/// Inputs the estimator thread's queue holds before the router keeps them itself.
const ESTIMATOR_QUEUE: usize = 4096;
/// Inputs the router keeps while the estimator is behind, before it drops the oldest.
const ROUTER_BACKLOG: usize = 100_000;
/// Queued requests per device.
const REQUEST_QUEUE: usize = 16;

/// Runs until SIGTERM/SIGINT (or the simulation's duration). `sim` is the running simulation of
/// a robot file with a `[simulation]` section (its emulators already serve the devices).
pub async fn run(
    cfg: RobotConfig,
    opts: RunOptions,
    sim: Option<Box<dyn Simulation>>,
) -> anyhow::Result<()> {
    run_with_pipeline(cfg, opts, sim, None).await
}

/// [`run`] with a pipeline of the caller's instead of the one the robot file names (an
/// estimator under development, or a test's).
pub async fn run_with_pipeline(
    cfg: RobotConfig,
    opts: RunOptions,
    mut sim: Option<Box<dyn Simulation>>,
    pipeline: Option<Box<dyn pipeline::Pipeline>>,
) -> anyhow::Result<()> {
    let stop = CancellationToken::new();
    spawn_signal_handler(stop.clone());
    let capture_dir = opts
        .capture_dir
        .clone()
        .or_else(|| cfg.state.capture_dir.clone());
    if let Some(dir) = &capture_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating capture folder {}", dir.display()))?;
    }
    let config_dir = cfg.source.dir.clone();

    // The pipeline first: a robot that cannot estimate does not start its devices.
    let pipeline = match pipeline {
        Some(p) => p,
        None => pipeline::build(
            &cfg.estimator,
            PipelineEnv {
                state_dir: cfg.state.dir.as_deref(),
                config_dir: cfg.source.dir.as_deref(),
            },
        )
        .map_err(|e| anyhow::anyhow!("pipeline {}: {e}", cfg.estimator.name()))?,
    };

    // The run clock and its origin: simulated seconds in a simulation, monotonic time on a robot.
    let clock: SharedClock = sim
        .as_ref()
        .and_then(|s| s.clock())
        .unwrap_or_else(|| Arc::new(MonotonicClock::new()));
    let origin = TimeOrigin::from_unix_ns(
        TimeOrigin::now().unix_ns() - i128::from(rfloc_transport::clock_ns(clock.as_ref())),
    );
    let time_scale = sim.as_ref().map_or(1.0, |s| s.time_scale());

    // Foxglove live view.
    let mut live_view = None;
    let viz = match &cfg.foxglove.listen {
        Some(addr) => {
            let addr: std::net::SocketAddr = addr
                .parse()
                .with_context(|| format!("foxglove.listen {addr:?}"))?;
            let hub = rfloc_viz::Viz::new();
            let live = hub
                .serve(addr, None)
                .await
                .with_context(|| format!("serving the Foxglove live view on {addr}"))?;
            tracing::info!(url = %live.url(), "Foxglove live view");
            live_view = Some(live);
            Some(crate::viz::VizOut::new(hub, origin))
        }
        None => None,
    };

    // Pose stream.
    let token = match &cfg.pose.token_file {
        Some(p) => {
            let path = crate::config::resolve_credential(p, config_dir.as_deref())
                .with_context(|| format!("pose token file {} not found", p.display()))?;
            if let Some(w) = crate::config::secret_file_warning(&path) {
                tracing::warn!("{w}");
            }
            Some(crate::server::read_token(&path).map_err(anyhow::Error::msg)?)
        }
        None => None,
    };
    let hub = PoseHub::new(cfg.pose.client_queue).with_access(crate::server::Access {
        token,
        allow: cfg
            .pose
            .allow
            .iter()
            .filter_map(|a| crate::server::AllowRule::parse(a))
            .collect(),
        max_clients: cfg.pose.max_clients,
    });
    let mut servers = Vec::new();
    if let Some(addr) = &cfg.pose.tcp {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("binding pose stream on {addr}"))?;
        tracing::info!(address = %listener.local_addr()?, "pose stream (tcp)");
        servers.push(tokio::spawn(hub.clone().serve_tcp(listener, stop.clone())));
    }
    if let Some(path) = &cfg.pose.unix {
        let socket = bind_unix(path)
            .with_context(|| format!("binding pose stream on {}", path.display()))?;
        tracing::info!(path = %path.display(), "pose stream (unix)");
        servers.push(tokio::spawn(hub.clone().serve_unix(socket, stop.clone())));
    }

    // What devices lend each other: a simulation's rotator first, else the robot's stepper.
    let resources = Arc::new(Resources::default());
    if let Some(antenna) = sim.as_mut().and_then(|s| s.take_antenna()) {
        resources.offer_antenna(antenna);
    }
    if let Ok(mut scan) = resources.scan.lock() {
        *scan = Some(pipeline::scan_config(&cfg.estimator));
    }
    for d in &cfg.devices {
        d.driver.provide(&resources);
    }

    // Device tasks.
    let (ev_tx, ev_rx) = mpsc::channel::<DeviceEvent>(1024);
    let mut tasks: Vec<(String, JoinHandle<()>)> = Vec::new();
    let mut routes = Vec::new();
    let health = Arc::new(Health::default());
    let backoff = cfg.supervision.backoff();
    for device in &cfg.devices {
        let (cmd_tx, cmd_rx) = mpsc::channel(REQUEST_QUEUE);
        let ctx = DeviceContext::new(
            device.clone(),
            ev_tx.clone(),
            stop.clone(),
            LinkSource::Live {
                clock: Arc::clone(&clock),
                origin,
                capture_dir: capture_dir.clone(),
                capture: std::sync::Mutex::new(None),
            },
            config_dir.clone(),
            time_scale,
            cmd_rx,
            Arc::clone(&resources),
        )
        .with_backoff(backoff);
        tasks.push((
            device.name.clone(),
            tokio::spawn(supervise(ctx, backoff, stop.clone(), Arc::clone(&health))),
        ));
        routes.push(Route {
            device: device.name.clone(),
            driver: device.driver.clone(),
            queue: cmd_tx,
            answered_requests: None,
        });
    }
    if let Some(s) = sim.as_mut() {
        let base = routes
            .iter()
            .find(|r| {
                r.driver
                    .handles(&pipeline::Request::Velocity { v: 0.0, w: 0.0 })
            })
            .map(|r| r.queue.clone());
        s.started(SimulationIo {
            events: ev_tx.clone(),
            base,
            estimator: &cfg.estimator,
            pipeline_drives_base: pipeline::drives_base(&cfg.estimator) || cfg.fleet.is_some(),
            stop: stop.clone(),
        });
    }
    drop(ev_tx);

    // The fleet link (`[fleet]`): a task of its own, fed by the estimator thread and the router.
    let fleet = crate::fleet::start(
        &cfg,
        pipeline.drives_to_goals(),
        routes
            .iter()
            .find(|r| {
                r.driver
                    .handles(&pipeline::Request::Velocity { v: 0.0, w: 0.0 })
            })
            .map(|r| r.queue.clone()),
        Arc::clone(&resources),
        stop.clone(),
    )
    .inspect_err(|_| stop.cancel())?;
    let (fleet_link, fleet_devices, fleet_task) = match fleet {
        Some(f) => (Some(f.link), Some(f.devices), Some(f.task)),
        None => (None, None, None),
    };

    // The estimator thread.
    // A recording that cannot be written (a full disk) does not stop the robot.
    let order_log = capture_dir.as_ref().and_then(|dir| {
        estimator::create_order_log(dir)
            .map_err(|e| {
                tracing::error!(error = %e, "pipeline order log not written: a replay will merge by stamp");
            })
            .ok()
    });
    let worker = Worker {
        pipeline: Some(pipeline),
        format: PoseFormat {
            frame_id: cfg.robot.frame_id.clone(),
            child_frame_id: cfg.robot.child_frame_id.clone(),
            precision: cfg.pose.precision,
            origin,
        },
        stale_after: cfg
            .devices
            .iter()
            .map(|d| (d.name.clone(), d.stale_after()))
            .collect(),
        routes,
        outputs: Outputs {
            hub: Some(hub.clone()),
            stdout: opts.stdout || cfg.pose.stdout,
            collect: None,
            order_log,
            scorer: sim.as_ref().and_then(|s| s.scorer()),
            ack: None,
            viz: viz.clone(),
            fleet: fleet_link,
        },
        print_observations: false,
    };
    let thread =
        estimator::spawn(worker, ESTIMATOR_QUEUE).context("starting the estimator thread")?;
    tracing::info!(pipeline = cfg.estimator.name(), "estimator ready");

    notify::ready();
    notify::status(&format!("running pipeline {}", cfg.estimator.name()));
    tracing::info!(robot = %cfg.robot.name, pipeline = cfg.estimator.name(), devices = cfg.devices.len(), "rfloc running");

    let deadline = sim
        .as_ref()
        .and_then(|s| s.duration_s())
        .map(|d| tokio::time::Instant::now() + crate::time::seconds(d / time_scale.max(1e-6)));
    let mut router = Router {
        hub: hub.clone(),
        thread_tx: thread.tx.clone(),
        progress: Arc::clone(&thread.progress),
        backlog: VecDeque::new(),
        dropped: 0,
        stale: StaleWatch::new(&cfg, time_scale),
        last_consumed: (0, tokio::time::Instant::now()),
        health,
        max_down: crate::time::seconds(cfg.supervision.max_down_s),
        viz: viz.clone(),
        fleet: fleet_devices,
    };
    router.run(ev_rx, &stop, deadline).await;

    notify::stopping();
    tracing::info!("stopping: halting the robot and closing devices");
    stop.cancel();
    for (name, t) in tasks {
        if tokio::time::timeout(Duration::from_secs(5), t)
            .await
            .is_err()
        {
            tracing::warn!(device = %name, "device task did not stop within 5 s");
        }
    }
    // The estimator sees the end of its input, then stops; one that hangs is left behind.
    router.flush_backlog(Duration::from_secs(2)).await;
    let mut end = Some(Input::End);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
    while let Some(input) = end.take() {
        match thread.tx.try_send(input) {
            Err(std::sync::mpsc::TrySendError::Full(input))
                if tokio::time::Instant::now() < deadline =>
            {
                end = Some(input);
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            Err(_) => tracing::error!("the estimator is not taking input; stopping without it"),
            Ok(()) => {}
        }
    }
    drop(router);
    match estimator::join_within(thread.handle, Duration::from_secs(5)).await {
        estimator::ThreadEnd::Stopped => {}
        estimator::ThreadEnd::Panicked => tracing::error!("the estimator thread ended abnormally"),
        estimator::ThreadEnd::LeftRunning => {
            tracing::error!("the estimator thread did not stop within 5 s; leaving it behind");
        }
    }
    if let Some(task) = fleet_task {
        if tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .is_err()
        {
            tracing::warn!("the fleet link did not stop within 5 s");
        }
    }
    if let Some(sim) = sim {
        sim.shutdown().await;
    }
    for s in servers {
        let _ = tokio::time::timeout(Duration::from_secs(1), s).await;
    }
    if let Some(live) = live_view {
        live.stop().await;
    }
    tracing::info!(slow_clients_dropped = hub.dropped_clients(), "stopped");
    Ok(())
}

/// The async side: device events in, DEVICE lines and the estimator's queue out.
struct Router {
    hub: PoseHub,
    thread_tx: std::sync::mpsc::SyncSender<Input>,
    progress: Arc<estimator::Progress>,
    /// Observations the estimator's queue had no room for yet, oldest first.
    backlog: VecDeque<DeviceEvent>,
    dropped: u64,
    stale: StaleWatch,
    /// Inputs the estimator had consumed at the last check, and when that count last moved.
    last_consumed: (u64, tokio::time::Instant),
    /// Device tasks that are down, from their supervisors.
    health: Arc<Health>,
    /// A device down longer than this stops the watchdog.
    max_down: Duration,
    /// Foxglove channels, for device status.
    viz: Option<crate::viz::VizOut>,
    /// DEVICE states for the fleet link's `state.errors`.
    fleet: Option<crate::fleet::DeviceTap>,
}

impl Router {
    async fn run(
        &mut self,
        mut ev_rx: mpsc::Receiver<DeviceEvent>,
        stop: &CancellationToken,
        deadline: Option<tokio::time::Instant>,
    ) {
        let watchdog = notify::watchdog_period().unwrap_or(Duration::from_secs(1));
        let mut tick = tokio::time::interval(watchdog.min(Duration::from_millis(500)));
        let mut retry = tokio::time::interval(Duration::from_millis(5));
        loop {
            tokio::select! {
                () = stop.cancelled() => break,
                () = sleep_until_opt(deadline) => {
                    tracing::info!("simulation duration reached");
                    stop.cancel();
                    break;
                }
                _ = tick.tick() => {
                    for (name, driver, limit) in self.stale.check() {
                        tracing::warn!(device = %name, "device silent");
                        if let Some(f) = &self.fleet {
                            f.note(&name, driver, DeviceState::Stale, &format!("silent for more than {limit:.1} s"));
                        }
                        self.hub.publish_device(&name, message::device_json(&name, driver, DeviceState::Stale, &format!("silent for more than {limit:.1} s"), SystemTime::now()));
                    }
                    if self.healthy(watchdog) {
                        notify::watchdog();
                    }
                }
                _ = retry.tick(), if !self.backlog.is_empty() => self.drain_backlog(),
                e = ev_rx.recv() => match e {
                    Some(e) => self.handle(e),
                    None => break,
                },
            }
        }
    }

    fn handle(&mut self, event: DeviceEvent) {
        if let DeviceEvent::Status {
            device,
            driver,
            state,
            detail,
            counters,
        } = &event
        {
            if counters.is_empty() {
                tracing::info!(device = %device, state = state.as_str(), detail = %detail, "device status");
            } else {
                tracing::warn!(device = %device, counters = ?counters, "link errors so far");
            }
            self.hub.publish_device(
                device,
                message::device_json_with_counters(
                    device,
                    driver,
                    *state,
                    detail,
                    counters,
                    SystemTime::now(),
                ),
            );
            if *state == DeviceState::Connected {
                self.health.up(device);
            }
            if let Some(v) = &self.viz {
                v.status(device, *state, detail);
            }
            if let Some(f) = &self.fleet {
                f.note(device, driver, *state, detail);
            }
            return;
        }
        self.health.up(event.device());
        if self.stale.seen(event.device()) {
            let name = event.device().to_string();
            let driver = self.stale.driver(&name);
            if let Some(f) = &self.fleet {
                f.note(&name, driver, DeviceState::Connected, "data again");
            }
            self.hub.publish_device(
                &name,
                message::device_json(
                    &name,
                    driver,
                    DeviceState::Connected,
                    "data again",
                    SystemTime::now(),
                ),
            );
        }
        self.backlog.push_back(event);
        self.drain_backlog();
    }

    /// Moves observations from the backlog into the estimator's queue while it has room.
    fn drain_backlog(&mut self) {
        while let Some(e) = self.backlog.pop_front() {
            match self.thread_tx.try_send(Input::Event(e)) {
                Ok(()) => {
                    self.progress.queued.fetch_add(1, Ordering::AcqRel);
                }
                Err(std::sync::mpsc::TrySendError::Full(Input::Event(e))) => {
                    self.backlog.push_front(e);
                    break;
                }
                Err(_) => {
                    self.backlog.clear();
                    break;
                }
            }
        }
        while self.backlog.len() > ROUTER_BACKLOG {
            self.backlog.pop_front();
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::error!(
                    dropped = self.dropped,
                    "estimator far behind: oldest observations dropped"
                );
            }
        }
    }

    /// Hands the backlog to the estimator at shutdown, waiting for room at most `limit`.
    async fn flush_backlog(&mut self, limit: Duration) {
        let deadline = tokio::time::Instant::now() + limit;
        while !self.backlog.is_empty() && tokio::time::Instant::now() < deadline {
            self.drain_backlog();
            if !self.backlog.is_empty() {
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
        }
        if !self.backlog.is_empty() {
            tracing::error!(
                left = self.backlog.len(),
                "estimator behind at shutdown: observations not processed"
            );
            self.backlog.clear();
        }
    }

    /// The watchdog is fed only while the estimator keeps consuming (or has nothing to consume)
    /// and no device has been down (task ended, or silent past its `stale_after_s`) longer than
    /// `max_down_s`.
    fn healthy(&mut self, watchdog: Duration) -> bool {
        let now = tokio::time::Instant::now();
        let consumed = self.progress.consumed.load(Ordering::Acquire);
        if consumed != self.last_consumed.0 {
            self.last_consumed = (consumed, now);
        }
        let waiting = self.progress.backlog() > 0 || !self.backlog.is_empty();
        let estimator_ok = !waiting || now.duration_since(self.last_consumed.1) < watchdog;
        if !estimator_ok {
            tracing::error!(
                backlog = self.progress.backlog(),
                "estimator not consuming: watchdog not fed"
            );
        }
        let mut down = self.health.down_longer_than(self.max_down, now);
        down.extend(self.stale.silent_longer_than(self.max_down, now));
        if !down.is_empty() {
            tracing::error!(devices = ?down, limit_s = self.max_down.as_secs_f64(), "device down too long: watchdog not fed");
        }
        estimator_ok && down.is_empty()
    }
}

/// Which device tasks are down, and since when: down from a task's end (its supervisor), up
/// again only once the restarted device delivers or connects (the router), so a crash loop
/// counts as down.
#[derive(Debug, Default)]
struct Health {
    down_since: std::sync::Mutex<HashMap<String, tokio::time::Instant>>,
}

impl Health {
    fn up(&self, name: &str) {
        if let Ok(mut d) = self.down_since.lock() {
            d.remove(name);
        }
    }

    fn down(&self, name: &str) {
        if let Ok(mut d) = self.down_since.lock() {
            d.entry(name.to_string())
                .or_insert_with(tokio::time::Instant::now);
        }
    }

    fn down_longer_than(&self, limit: Duration, now: tokio::time::Instant) -> Vec<String> {
        self.down_since.lock().map_or_else(
            |_| Vec::new(),
            |d| {
                d.iter()
                    .filter(|(_, since)| now.duration_since(**since) > limit)
                    .map(|(n, _)| n.clone())
                    .collect()
            },
        )
    }
}

/// Runs a device's task and restarts it with back-off whenever it ends or panics (until the
/// daemon stops), reporting each as DEVICE `failed`.
async fn supervise(
    ctx: DeviceContext,
    backoff: crate::devices::Backoff,
    stop: CancellationToken,
    health: Arc<Health>,
) {
    let name = ctx.device.name.clone();
    let seed = crate::devices::seed_of(&name);
    let mut restarts = 0u32;
    loop {
        let started = tokio::time::Instant::now();
        let result = ctx.device.driver.spawn(ctx.clone()).await;
        if stop.is_cancelled() {
            return;
        }
        health.down(&name);
        let why = match result {
            Ok(()) => "device task ended".to_string(),
            Err(e) if e.is_panic() => {
                let payload = e.into_panic();
                let text = payload
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                format!("device task panicked: {text}")
            }
            Err(e) => format!("device task stopped: {e}"),
        };
        // A task that ran well for a while starts its back-off afresh.
        if started.elapsed() > crate::time::seconds(backoff.max_s) {
            restarts = 0;
        }
        let wait = backoff.delay(restarts, seed);
        tracing::error!(device = %name, reason = %why, restart_in_s = wait.as_secs_f64(), "device task stopped; restarting after back-off");
        ctx.status(
            DeviceState::Failed,
            format!("{why}; restarting in {:.1} s", wait.as_secs_f64()),
        )
        .await;
        tokio::select! {
            () = stop.cancelled() => return,
            () = tokio::time::sleep(wait) => {}
        }
        restarts = restarts.saturating_add(1);
    }
}

/// Wall-time staleness of each device, for DEVICE lines (pose degradation is decided on
/// measurement times by the estimator thread).
struct StaleWatch {
    limits: HashMap<String, (Duration, &'static str)>,
    last_seen: HashMap<String, tokio::time::Instant>,
    stale: HashMap<String, bool>,
}

impl StaleWatch {
    fn new(cfg: &RobotConfig, time_scale: f64) -> Self {
        let start = tokio::time::Instant::now();
        Self {
            // Staleness counts from the start: a device that never delivers goes stale too.
            last_seen: cfg
                .devices
                .iter()
                .filter(|d| d.driver.observes())
                .map(|d| (d.name.clone(), start))
                .collect(),
            limits: cfg
                .devices
                .iter()
                .filter(|d| d.driver.observes())
                .map(|d| {
                    (
                        d.name.clone(),
                        (
                            crate::time::seconds(d.stale_after() / time_scale.max(1e-6)),
                            d.driver.kind(),
                        ),
                    )
                })
                .collect(),
            stale: HashMap::new(),
        }
    }

    /// Devices silent for longer than their limit plus `grace`.
    fn silent_longer_than(&self, grace: Duration, now: tokio::time::Instant) -> Vec<String> {
        self.limits
            .iter()
            .filter(|(name, (limit, _))| {
                self.last_seen
                    .get(*name)
                    .is_some_and(|t| now.duration_since(*t) > *limit + grace)
            })
            .map(|(name, _)| name.clone())
            .collect()
    }

    fn driver(&self, name: &str) -> &'static str {
        self.limits.get(name).map_or("?", |(_, k)| k)
    }

    /// An observation of `name`; true when it was stale.
    fn seen(&mut self, name: &str) -> bool {
        self.last_seen
            .insert(name.to_string(), tokio::time::Instant::now());
        self.stale.insert(name.to_string(), false) == Some(true)
    }

    /// Devices that just became stale: (name, driver, limit in seconds).
    fn check(&mut self) -> Vec<(String, &'static str, f64)> {
        let now = tokio::time::Instant::now();
        let mut out = Vec::new();
        for (name, (limit, driver)) in &self.limits {
            let is_stale = self
                .last_seen
                .get(name)
                .is_some_and(|t| now.duration_since(*t) > *limit);
            let was = self.stale.insert(name.clone(), is_stale).unwrap_or(false);
            if is_stale && !was {
                out.push((name.clone(), *driver, limit.as_secs_f64()));
            }
        }
        out
    }
}

async fn sleep_until_opt(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}

fn spawn_signal_handler(stop: CancellationToken) {
    tokio::spawn(async move {
        let term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate());
        let Ok(mut term) = term else {
            tracing::error!("cannot install SIGTERM handler");
            return;
        };
        tokio::select! {
            _ = term.recv() => tracing::info!("SIGTERM"),
            _ = tokio::signal::ctrl_c() => tracing::info!("SIGINT"),
        }
        stop.cancel();
    });
}
