//! `rfloc run`: device tasks under one cancellation token, the estimator loop, the pose stream,
//! and systemd notifications.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use anyhow::Context;
use rfloc_capture::Header;
use rfloc_pose::EstimateMode;
use rfloc_transport::{open, CaptureSink, MonotonicClock, Recorder, SharedClock, Transport};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tracing::Instrument;

use crate::config::{DeviceConfig, DriverConfig, RobotConfig};
use crate::devices;
use crate::events::DeviceEvent;
use crate::message::{self, DeviceState, PoseFormat};
use crate::notify;
use crate::pipeline;
use crate::server::{bind_unix, PoseHub};

/// Options of one run that do not come from the robot file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub stdout: bool,
    pub capture_dir: Option<PathBuf>,
    /// Folder of the robot file.
    pub config_dir: Option<PathBuf>,
}

/// Everything a device task needs from the daemon.
#[derive(Clone)]
pub struct DeviceContext {
    pub device: DeviceConfig,
    pub events: mpsc::Sender<DeviceEvent>,
    pub stop: CancellationToken,
    pub clock: SharedClock,
    pub capture_dir: Option<PathBuf>,
    /// Folder of the robot file (credential files may be given relative to it).
    pub config_dir: Option<PathBuf>,
    /// Simulated seconds per wall second (1 on a real robot).
    pub time_scale: f64,
    /// The device's capture once its link was first opened: one file per device and run,
    /// appended to across reconnects.
    pub capture: Arc<std::sync::Mutex<Option<CaptureSink>>>,
}

impl DeviceContext {
    /// A context for `device` with no capture open yet.
    pub fn new(
        device: DeviceConfig,
        events: mpsc::Sender<DeviceEvent>,
        stop: CancellationToken,
        clock: SharedClock,
        capture_dir: Option<PathBuf>,
        config_dir: Option<PathBuf>,
        time_scale: f64,
    ) -> Self {
        Self {
            device,
            events,
            stop,
            clock,
            capture_dir,
            config_dir,
            time_scale,
            capture: Arc::default(),
        }
    }

    /// The device's capture, when recording and once the link was opened.
    #[must_use]
    pub fn capture(&self) -> Option<CaptureSink> {
        self.capture.lock().ok().and_then(|c| c.as_ref().cloned())
    }

    /// Never records `secret` in this device's capture (see [`CaptureSink::redact`]). Call it
    /// before the credential is sent; it also applies to a capture opened later.
    pub fn redact(&self, secret: &str) -> anyhow::Result<()> {
        if self.capture_dir.is_none() {
            return Ok(());
        }
        let sink = match self.capture() {
            Some(s) => s,
            None => self.create_capture()?,
        };
        sink.redact(secret.as_bytes());
        Ok(())
    }

    /// Creates the device's capture file (once per run).
    fn create_capture(&self) -> anyhow::Result<CaptureSink> {
        let mut slot = self
            .capture
            .lock()
            .map_err(|_| anyhow::anyhow!("capture slot poisoned"))?;
        if let Some(s) = slot.as_ref() {
            return Ok(s.clone());
        }
        let (Some(dir), Some(link)) = (&self.capture_dir, &self.device.link) else {
            anyhow::bail!("device {:?} is not recorded", self.device.name);
        };
        let device_kind = capture_device_name(&self.device.driver);
        let mut header = Header::new(device_kind, link.describe());
        header.started = Some(message::iso8601(SystemTime::now()).replace(".000Z", "Z"));
        header.notes.push(format!(
            "device {} recorded by rfloc {}",
            self.device.name,
            env!("CARGO_PKG_VERSION")
        ));
        let path = dir.join(format!("{}.cap", self.device.name));
        let sink = CaptureSink::create(&path, &header, Arc::clone(&self.clock))?;
        *slot = Some(sink.clone());
        Ok(sink)
    }

    /// Opens the device's link, wrapped in a recorder when capturing. The only place the daemon
    /// opens links.
    pub async fn open_link(&self) -> anyhow::Result<Transport> {
        Ok(self.open_link_recorded().await?.0)
    }

    /// [`DeviceContext::open_link`], with the capture it records into (for tasks that add
    /// marks to it).
    pub async fn open_link_recorded(&self) -> anyhow::Result<(Transport, Option<CaptureSink>)> {
        let link = self
            .device
            .link
            .as_ref()
            .with_context(|| format!("device {:?} has no link", self.device.name))?;
        let io = open(link).await?;
        if self.capture_dir.is_none() {
            return Ok((io, None));
        }
        let sink = self.create_capture()?;
        sink.event("mark link opened");
        Ok((Box::new(Recorder::new(io, sink.clone())), Some(sink)))
    }

    /// Sends a status event (never blocks the device task for long).
    pub async fn status(&self, state: DeviceState, detail: impl Into<String>) {
        let _ = self
            .events
            .send(DeviceEvent::Status {
                device: self.device.name.clone(),
                driver: self.device.driver.kind(),
                state,
                detail: detail.into(),
            })
            .await;
    }
}

fn capture_device_name(driver: &DriverConfig) -> &'static str {
    match driver {
        DriverConfig::Aria(_) => "pioneer-aria",
        DriverConfig::Kts(_) => "kts-rfidm1356",
        DriverConfig::Alien(_) => "alien-alr9900",
        DriverConfig::Xbee(x) => {
            if x.api_mode == 1 {
                "xbee-api1"
            } else {
                "xbee-api2"
            }
        }
        DriverConfig::Urg(_) => "hokuyo-urg",
        DriverConfig::Stepper(_) => "stepper-gpio",
    }
}

/// Back-off for reconnecting: 0.5 s doubling to 30 s.
#[must_use]
pub fn backoff(attempt: u32) -> Duration {
    let secs = 0.5 * 2f64.powi(i32::try_from(attempt.min(6)).unwrap_or(6));
    Duration::from_secs_f64(secs.min(30.0))
}

/// Runs until SIGTERM/SIGINT (or the simulation's duration).
pub async fn run(cfg: RobotConfig, opts: RunOptions) -> anyhow::Result<()> {
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

    // Pose stream.
    let hub = PoseHub::new(cfg.pose.client_queue);
    let mut servers = Vec::new();
    if let Some(addr) = &cfg.pose.tcp {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("binding pose stream on {addr}"))?;
        tracing::info!(address = %listener.local_addr()?, "pose stream (tcp)");
        servers.push(tokio::spawn(hub.clone().serve_tcp(listener, stop.clone())));
    }
    if let Some(path) = &cfg.pose.unix {
        let listener = bind_unix(path)
            .with_context(|| format!("binding pose stream on {}", path.display()))?;
        tracing::info!(path = %path.display(), "pose stream (unix)");
        servers.push(tokio::spawn(hub.clone().serve_unix(
            listener,
            path.clone(),
            stop.clone(),
        )));
    }

    // Simulation: emulators on ptys/loopback; device links are rewritten to reach them.
    let mut cfg = cfg;
    let mut sim = None;
    if let Some(sim_cfg) = cfg.simulation.clone() {
        sim = Some(crate::sim::start(&mut cfg, &sim_cfg, opts.config_dir.as_deref()).await?);
    }
    let time_scale = cfg.simulation.as_ref().map_or(1.0, |s| s.time_scale);
    // Timestamps: the emulated robot's simulated seconds in a simulation (so that times and
    // the motion they describe agree at any time scale), the monotonic clock on a robot.
    let clock: SharedClock = sim
        .as_ref()
        .and_then(crate::sim::SimRuntime::clock)
        .unwrap_or_else(|| Arc::new(MonotonicClock::new()));
    let mut antenna = sim
        .as_mut()
        .and_then(crate::sim::SimRuntime::take_stepper)
        .map(devices::AntennaSource::Simulated)
        .or_else(|| {
            cfg.devices.iter().find_map(|d| match &d.driver {
                DriverConfig::Stepper(s) => Some(devices::AntennaSource::Gpio(s.clone())),
                _ => None,
            })
        });

    // Device tasks.
    let (ev_tx, mut ev_rx) = mpsc::channel::<DeviceEvent>(1024);
    let mut device_tasks = Vec::new();
    let mut motion = None;
    let mut sweeps = None;
    for device in &cfg.devices {
        let ctx = DeviceContext::new(
            device.clone(),
            ev_tx.clone(),
            stop.clone(),
            Arc::clone(&clock),
            capture_dir.clone(),
            opts.config_dir.clone(),
            time_scale,
        );
        let span =
            tracing::info_span!("device", name = %device.name, driver = device.driver.kind());
        let sweep = match &device.driver {
            DriverConfig::Xbee(x) if x.role == crate::config::XbeeRole::Sweep => {
                antenna.take().map(|antenna| devices::SweepSetup {
                    antenna,
                    scan: pipeline::scan_config(&cfg.estimator),
                })
            }
            _ => None,
        };
        let spawned = devices::spawn(ctx, span.clone(), sweep);
        if spawned.motion.is_some() {
            motion = spawned.motion;
        }
        if spawned.sweeps.is_some() {
            sweeps = spawned.sweeps;
        }
        device_tasks.push(spawned.task);
    }
    if let (Some(sim), crate::config::EstimatorConfig::Emitter(e)) = (&mut sim, &cfg.estimator) {
        sim.spawn_laser(ev_tx.clone(), e.control_period_s, stop.clone());
    }
    drop(ev_tx);

    if let (Some(sim), Some(base)) = (&sim, &motion) {
        if pipeline::drives_base(&cfg.estimator) {
            tracing::info!("the pipeline drives the simulated base; no motion script");
        } else {
            crate::sim::drive(sim, base.clone(), stop.clone());
        }
    }

    notify::ready();
    notify::status(&format!("running pipeline {}", cfg.estimator.name()));
    tracing::info!(robot = %cfg.robot.name, pipeline = cfg.estimator.name(), devices = cfg.devices.len(), "rfloc running");

    let fmt = PoseFormat {
        frame_id: cfg.robot.frame_id.clone(),
        child_frame_id: cfg.robot.child_frame_id.clone(),
        precision: cfg.pose.precision,
    };
    let mut estimator = pipeline::build(&cfg.estimator, cfg.state.dir.as_deref());
    tracing::info!(pipeline = estimator.name(), "estimator ready");
    let stale_after: HashMap<String, Duration> = cfg
        .devices
        .iter()
        .map(|d| {
            (
                d.name.clone(),
                Duration::from_secs_f64(d.stale_after() / time_scale.max(1e-6)),
            )
        })
        .collect();
    let driver_of: HashMap<&str, &'static str> = cfg
        .devices
        .iter()
        .map(|d| (d.name.as_str(), d.driver.kind()))
        .collect();
    let mut last_seen: HashMap<String, tokio::time::Instant> = HashMap::new();
    let mut stale: HashMap<String, bool> = HashMap::new();
    let watchdog = notify::watchdog_period().unwrap_or(Duration::from_secs(1));
    let mut tick = tokio::time::interval(watchdog.min(Duration::from_millis(500)));
    let mut non_finite = 0u64;
    let deadline =
        cfg.simulation.as_ref().and_then(|s| s.duration_s).map(|d| {
            tokio::time::Instant::now() + Duration::from_secs_f64(d / time_scale.max(1e-6))
        });

    let mut echo = StdoutEcho {
        on: opts.stdout || cfg.pose.stdout,
    };
    let estimator_span = tracing::info_span!("estimator", pipeline = cfg.estimator.name());
    async {
        loop {
            let event = tokio::select! {
                () = stop.cancelled() => break,
                () = sleep_until_opt(deadline) => {
                    tracing::info!("simulation duration reached");
                    stop.cancel();
                    break;
                }
                _ = tick.tick() => {
                    notify::watchdog();
                    let now = tokio::time::Instant::now();
                    for (name, limit) in &stale_after {
                        let is_stale = last_seen.get(name).is_some_and(|t| now.duration_since(*t) > *limit);
                        let was = stale.insert(name.clone(), is_stale).unwrap_or(false);
                        if is_stale && !was {
                            tracing::warn!(device = %name, "device silent; poses degrade");
                            let driver = driver_of.get(name.as_str()).copied().unwrap_or("?");
                            hub.publish_device(name, message::device_json(name, driver, DeviceState::Stale, &format!("silent for more than {:.1} s", limit.as_secs_f64()), SystemTime::now()));
                        }
                    }
                    continue;
                }
                e = ev_rx.recv() => match e { Some(e) => e, None => break },
            };
            if let DeviceEvent::Status { device, driver, state, detail } = &event {
                tracing::info!(device = %device, state = state.as_str(), detail = %detail, "device status");
                hub.publish_device(device, message::device_json(device, driver, *state, detail, SystemTime::now()));
                continue;
            }
            let name = event.device().to_string();
            last_seen.insert(name.clone(), tokio::time::Instant::now());
            if stale.insert(name.clone(), false) == Some(true) {
                let driver = driver_of.get(name.as_str()).copied().unwrap_or("?");
                hub.publish_device(&name, message::device_json(&name, driver, DeviceState::Connected, "data again", SystemTime::now()));
            }
            let estimate = estimator.handle(&event);
            for request in estimator.take_requests() {
                route(request, motion.as_ref(), sweeps.as_ref());
            }
            for target in estimator.take_targets() {
                match message::target_json(&target, SystemTime::now(), &fmt) {
                    Ok(line) => {
                        echo.print(&line);
                        hub.publish_target(line);
                    }
                    Err(e) => tracing::warn!(error = %e, "target not published"),
                }
            }
            if let Some(mut est) = estimate {
                if let Some(sim) = sim.as_mut() {
                    sim.score(&est);
                }
                if stale.values().any(|s| *s) && est.mode == EstimateMode::Fix {
                    est.mode = EstimateMode::Degraded;
                }
                match message::pose_json(&est, SystemTime::now(), &fmt) {
                    Ok(line) => {
                        echo.print(&line);
                        hub.publish_pose(line);
                    }
                    Err(e) => {
                        non_finite += 1;
                        tracing::warn!(error = %e, count = non_finite, "estimate not published");
                    }
                }
            }
        }
    }
    .instrument(estimator_span)
    .await;

    notify::stopping();
    tracing::info!("stopping: halting the robot and closing devices");
    stop.cancel();
    for t in device_tasks {
        if tokio::time::timeout(Duration::from_secs(5), t)
            .await
            .is_err()
        {
            tracing::warn!("a device task did not stop within 5 s");
        }
    }
    if let Some(sim) = sim {
        sim.shutdown().await;
    }
    for s in servers {
        let _ = tokio::time::timeout(Duration::from_secs(1), s).await;
    }
    tracing::info!(slow_clients_dropped = hub.dropped_clients(), "stopped");
    Ok(())
}

/// Hands a pipeline's request to the device task that can act on it. Never waits: a full
/// queue drops the request (the pipeline asks again on its next event) with a warning.
fn route(
    request: pipeline::Request,
    motion: Option<&devices::MotionSender>,
    sweeps: Option<&mpsc::Sender<devices::SweepRequest>>,
) {
    let sent = match request {
        pipeline::Request::Velocity { v, w } => motion.map(|m| m.try_send((v, w)).is_ok()),
        pipeline::Request::Sweep { heading_rad } => {
            sweeps.map(|s| s.try_send(devices::SweepRequest { heading_rad }).is_ok())
        }
    };
    match sent {
        Some(true) => {}
        Some(false) => tracing::warn!(?request, "device busy; request dropped"),
        None => tracing::warn!(?request, "no device can carry out this request"),
    }
}

/// Prints one line on stdout; false when stdout is gone.
/// POSE and TARGET lines on stdout, when asked for; off for good once stdout is closed (e.g.
/// piped into `head`), while the daemon keeps running.
struct StdoutEcho {
    on: bool,
}

impl StdoutEcho {
    fn print(&mut self, line: &str) {
        if self.on && !print_line(line) {
            self.on = false;
        }
    }
}

fn print_line(line: &str) -> bool {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}").and_then(|()| out.flush()).is_ok()
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
