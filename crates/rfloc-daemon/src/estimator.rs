//! The estimator thread: the pipeline runs on its own OS thread, fed by a bounded channel, so
//! that device tasks, the pose stream and stale detection never wait for it.
//!
//! The thread formats what the pipeline estimates (POSE and TARGET lines), hands them to the
//! pose hub and stdout, routes the pipeline's requests to the devices that carry them out
//! (never waiting: a full queue drops a request, the pipeline asks again), and, when
//! recording, writes the order in which it consumed observations (`pipeline.order`), which is
//! all a replay needs besides the captures to reproduce the run's output byte for byte.
//!
//! Poses degrade from `fix` to `degraded` when a device's latest observation is older than its
//! `stale_after_s` at the time of the observation being processed: a decision on measurement
//! times, so a replay makes it identically.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use rfloc_pose::EstimateMode;
use tokio::sync::mpsc;

use crate::events::DeviceEvent;
use crate::message::{self, PoseFormat};
use crate::pipeline::{Pipeline, Request};
use crate::server::PoseHub;

/// What the thread consumes.
#[derive(Debug)]
pub enum Input {
    /// One observation (status events never reach the thread).
    Event(DeviceEvent),
    /// The input ended: the pipeline gets a final `end` mark, then the thread stops.
    End,
}

/// A device that carries out requests: which ones, and its queue.
#[derive(Clone)]
pub struct Route {
    pub device: String,
    pub driver: crate::devices::DeviceDriver,
    pub queue: mpsc::Sender<Request>,
    /// Counts the requests sent that the device answers with an observation (a sweep), when a
    /// replay waits for the answers.
    pub answered_requests: Option<Arc<AtomicU64>>,
}

/// Where the thread's output goes.
pub struct Outputs {
    /// The pose stream (live).
    pub hub: Option<PoseHub>,
    /// Print POSE and TARGET lines on stdout.
    pub stdout: bool,
    /// Collect the lines (replay, tests).
    pub collect: Option<std::sync::mpsc::Sender<String>>,
    /// Record the consumption order into this file.
    pub order_log: Option<std::fs::File>,
    /// Scores estimates against a simulation's truth.
    pub scorer: Option<crate::simulation::Scorer>,
    /// Told after each input is consumed (replay steps in lock with the thread).
    pub ack: Option<mpsc::UnboundedSender<u64>>,
    /// Foxglove channels (a live view, an MCAP recording).
    pub viz: Option<crate::viz::VizOut>,
    /// The fleet link (`[fleet]`): estimates out, goals and initialisations in.
    pub fleet: Option<crate::fleet::EstimatorLink>,
}

/// Liveness of the thread, for the watchdog.
#[derive(Debug, Default)]
pub struct Progress {
    /// Inputs consumed.
    pub consumed: AtomicU64,
    /// Inputs handed to the thread.
    pub queued: AtomicU64,
}

impl Progress {
    /// Inputs waiting in the queue.
    #[must_use]
    pub fn backlog(&self) -> u64 {
        self.queued
            .load(Ordering::Acquire)
            .saturating_sub(self.consumed.load(Ordering::Acquire))
    }
}

/// A running estimator thread.
pub struct EstimatorThread {
    pub tx: SyncSender<Input>,
    pub progress: Arc<Progress>,
    pub handle: JoinHandle<()>,
}

/// How an estimator thread ended when asked to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThreadEnd {
    /// It returned.
    Stopped,
    /// It panicked.
    Panicked,
    /// It was still running at the deadline and was left behind (a hung estimator must not
    /// hold the process: nothing waits for it, not even the runtime's shutdown).
    LeftRunning,
}

/// Waits up to `limit` for `handle`'s thread to end, without blocking a runtime thread.
pub async fn join_within(handle: JoinHandle<()>, limit: std::time::Duration) -> ThreadEnd {
    let deadline = tokio::time::Instant::now() + limit;
    while !handle.is_finished() {
        if tokio::time::Instant::now() >= deadline {
            return ThreadEnd::LeftRunning;
        }
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    // Finished: joining returns at once.
    if handle.join().is_ok() {
        ThreadEnd::Stopped
    } else {
        ThreadEnd::Panicked
    }
}

/// The header line of an order log.
pub const ORDER_LOG_HEADER: &str = "# rfloc pipeline inputs 1";

/// The order log's file name in a capture folder.
pub const ORDER_LOG: &str = "pipeline.order";

/// Creates the order log in `dir`.
pub fn create_order_log(dir: &Path) -> std::io::Result<std::fs::File> {
    let mut f = std::fs::File::create(dir.join(ORDER_LOG))?;
    writeln!(f, "{ORDER_LOG_HEADER}")?;
    writeln!(f, "# device and stamp (ns on the run clock) of each observation the pipeline consumed, in order")?;
    Ok(f)
}

/// Everything the thread needs.
pub struct Worker {
    pub pipeline: Option<Box<dyn Pipeline>>,
    pub format: PoseFormat,
    /// Staleness limit of each device, seconds of measurement time.
    pub stale_after: HashMap<String, f64>,
    pub routes: Vec<Route>,
    pub outputs: Outputs,
    /// Print observations as JSON lines (a replay with no pipeline).
    pub print_observations: bool,
}

/// Starts the thread with a queue of `capacity` inputs.
pub fn spawn(worker: Worker, capacity: usize) -> std::io::Result<EstimatorThread> {
    let (tx, rx) = std::sync::mpsc::sync_channel(capacity.max(1));
    let progress = Arc::new(Progress::default());
    let p = Arc::clone(&progress);
    let name = worker
        .pipeline
        .as_ref()
        .map_or("observations", |p| p.name());
    let span = tracing::info_span!("estimator", pipeline = name);
    let handle = std::thread::Builder::new()
        .name("rfloc-estimator".into())
        .spawn(move || {
            let _entered = span.enter();
            worker.run(&rx, &p);
        })?;
    Ok(EstimatorThread {
        tx,
        progress,
        handle,
    })
}

impl Worker {
    fn run(mut self, rx: &Receiver<Input>, progress: &Progress) {
        let mut last_seen: HashMap<String, f64> = HashMap::new();
        // The robot's latest odometry pose, for the odometry frames of POSE lines.
        let mut odom: Option<rfloc_pose::Pose2> = None;
        let mut last_t = 0.0f64;
        let mut non_finite = 0u64;
        while let Ok(input) = rx.recv() {
            let (event, end) = match input {
                Input::Event(e) => (e, false),
                Input::End => (
                    DeviceEvent::Mark {
                        device: "daemon".into(),
                        t: last_t,
                        text: "end".into(),
                    },
                    true,
                ),
            };
            let t = event.time().unwrap_or(last_t);
            last_t = last_t.max(t);
            self.log_order(event.device(), t);
            if !end {
                last_seen.insert(event.device().to_string(), t);
            }
            if let DeviceEvent::Odometry { pose, .. } = &event {
                odom = Some(*pose);
            }
            if let (Some(v), false) = (&self.outputs.viz, end) {
                v.observation(&event);
            }
            if self.print_observations {
                self.emit(&event.to_json());
            }
            if let Some(p) = self.pipeline.as_mut() {
                if let Some(f) = self.outputs.fleet.as_mut() {
                    f.before_event(p.as_mut(), &event);
                }
                let estimate = p.handle(&event);
                let requests = p.take_requests();
                let targets = p.take_targets();
                if let Some(v) = self.outputs.viz.as_mut() {
                    v.scene(t, || p.scene());
                }
                for request in requests {
                    route(&self.routes, request);
                }
                if let Some(mut est) = estimate {
                    if est.mode == EstimateMode::Fix && self.any_stale(&last_seen, t) {
                        est.mode = EstimateMode::Degraded;
                    }
                    if let Some(score) = self.outputs.scorer.as_mut() {
                        score(&est);
                    }
                    if let Some(v) = &self.outputs.viz {
                        v.pose(&est, odom.as_ref());
                    }
                    if let Some(f) = self.outputs.fleet.as_mut() {
                        f.estimate(&est);
                    }
                    match message::pose_json_with_odometry(&est, odom.as_ref(), &self.format) {
                        Ok(line) => {
                            if let Some(hub) = &self.outputs.hub {
                                hub.publish_pose(line.clone());
                            }
                            self.emit(&line);
                        }
                        Err(e) => {
                            non_finite += 1;
                            if non_finite.is_power_of_two() {
                                tracing::warn!(error = %e, count = non_finite, "estimate not published");
                            }
                        }
                    }
                }
                for target in targets {
                    if let Some(v) = &self.outputs.viz {
                        v.target(&target);
                    }
                    match message::target_json(&target, &self.format) {
                        Ok(line) => {
                            if let Some(hub) = &self.outputs.hub {
                                hub.publish_target(line.clone());
                            }
                            self.emit(&line);
                        }
                        Err(e) => tracing::warn!(error = %e, "target not published"),
                    }
                }
            }
            let n = progress.consumed.fetch_add(1, Ordering::AcqRel) + 1;
            if let Some(ack) = &self.outputs.ack {
                let _ = ack.send(n);
            }
            if end {
                break;
            }
        }
        if let Some(f) = self.outputs.order_log.as_mut() {
            let _ = f.flush();
        }
    }

    fn any_stale(&self, last_seen: &HashMap<String, f64>, now: f64) -> bool {
        self.stale_after.iter().any(|(device, limit)| {
            last_seen
                .get(device)
                .is_some_and(|seen| now - seen > *limit)
        })
    }

    fn log_order(&mut self, device: &str, t: f64) {
        if let Some(f) = self.outputs.order_log.as_mut() {
            let ns = rfloc_transport::clock_ns(&FixedClock(t));
            if writeln!(f, "{device}\t{ns}").is_err() {
                self.outputs.order_log = None;
                tracing::error!(
                    "pipeline order log write failed; the rest of the run is not logged"
                );
            }
        }
    }

    fn emit(&mut self, line: &str) {
        if self.outputs.stdout && !print_line(line) {
            // stdout closed (piped into `head`): the daemon runs on.
            self.outputs.stdout = false;
        }
        if let Some(c) = &self.outputs.collect {
            let _ = c.send(line.to_string());
        }
    }
}

#[derive(Debug)]
struct FixedClock(f64);

impl rfloc_transport::Clock for FixedClock {
    fn now(&self) -> f64 {
        self.0
    }
}

/// Hands a request to the first device that carries it out. Never waits: a full queue drops
/// the request (the pipeline asks again on its next event) with a warning.
fn route(routes: &[Route], request: Request) {
    match routes.iter().find(|r| r.driver.handles(&request)) {
        Some(r) => {
            if r.queue.try_send(request).is_err() {
                tracing::warn!(?request, device = %r.device, "device busy; request dropped");
            } else if let (Some(n), Request::Sweep { .. }) = (&r.answered_requests, request) {
                n.fetch_add(1, Ordering::AcqRel);
            }
        }
        None => tracing::warn!(?request, "no device can carry out this request"),
    }
}

fn print_line(line: &str) -> bool {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}").and_then(|()| out.flush()).is_ok()
}
