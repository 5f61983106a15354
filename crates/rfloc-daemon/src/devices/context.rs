//! What a device task gets from the daemon: its settings, the event channel, the stop token,
//! the stamp clock, and the one place its link is opened. The same task runs live, recording
//! or replaying: only the [`LinkSource`] differs.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use rfloc_capture::{Capture, Header};
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::{open, CaptureSink, ManualClock, SharedClock, StampedLink, Transport};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::config::DeviceConfig;
use crate::devices::AntennaSource;
use crate::events::{DeviceEvent, DeviceState};
use crate::pipeline::Request;
use crate::time::TimeOrigin;

/// Where a device's links come from.
pub enum LinkSource {
    /// Real links, opened from the robot file; recorded into `capture_dir` when set.
    Live {
        /// The run's clock (simulated seconds in a simulation, monotonic time on a robot).
        clock: SharedClock,
        /// The instant the run clock reads zero (capture headers record it).
        origin: TimeOrigin,
        /// Folder to record the link into.
        capture_dir: Option<PathBuf>,
        /// The device's capture once its link was first opened: one file per device and run,
        /// appended to across reconnects.
        capture: Mutex<Option<CaptureSink>>,
    },
    /// The recorded sessions of a capture, one per `mark link opened`, handed out in order.
    Replay {
        sessions: Mutex<VecDeque<Capture>>,
        mode: ReplayMode,
        /// The marks the device task wrote into its capture (text after `mark `), in order: what
        /// it decided that the bytes alone do not tell (how many reads a snapshot averaged).
        marks: Vec<String>,
    },
}

/// Shared things a device may provide or use besides its link (the antenna rotator a sweeping
/// radio turns).
#[derive(Debug, Default)]
pub struct Resources {
    pub antenna: Mutex<Option<AntennaSource>>,
    /// Sweep settings of the pipeline (step, path-loss model, antenna pattern).
    pub scan: Mutex<Option<rfloc_bearing::ScanConfig>>,
    /// The base's battery voltage from its latest SIP (for the fleet link's `batteryState`).
    pub battery_v: Mutex<Option<f64>>,
}

impl Resources {
    /// Puts the antenna rotator, unless one is there already (a simulated or recorded one wins
    /// over the robot file's GPIO stepper).
    pub fn offer_antenna(&self, source: AntennaSource) {
        if let Ok(mut a) = self.antenna.lock() {
            if a.is_none() {
                *a = Some(source);
            }
        }
    }

    /// Notes the base's battery voltage.
    pub fn note_battery(&self, volts: f64) {
        if let Ok(mut b) = self.battery_v.lock() {
            *b = Some(volts);
        }
    }

    /// Takes the antenna rotator.
    #[must_use]
    pub fn take_antenna(&self) -> Option<AntennaSource> {
        self.antenna.lock().ok().and_then(|mut a| a.take())
    }
}

/// Everything a device task needs from the daemon.
#[derive(Clone)]
pub struct DeviceContext {
    pub device: DeviceConfig,
    pub events: mpsc::Sender<DeviceEvent>,
    pub stop: CancellationToken,
    /// The time of the latest read on this device's link: drivers stamp what they decode with
    /// it, so an observation carries the time its bytes arrived, live and in replay alike.
    pub clock: SharedClock,
    stamp: Arc<ManualClock>,
    /// Folder of the robot file (credential files may be given relative to it).
    pub config_dir: Option<PathBuf>,
    /// Simulated seconds per wall second (1 on a real robot and in a replay).
    pub time_scale: f64,
    links: Arc<LinkSource>,
    commands: Arc<tokio::sync::Mutex<mpsc::Receiver<Request>>>,
    pub resources: Arc<Resources>,
    /// The wait before each reconnection.
    pub backoff: crate::devices::Backoff,
}

/// A device task's queue of pipeline requests, held for the task's life (a restarted task gets
/// it back).
pub type CommandQueue = tokio::sync::OwnedMutexGuard<mpsc::Receiver<Request>>;

impl DeviceContext {
    /// A context for `device`; `commands` carries the pipeline's requests the device handles.
    #[must_use]
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: DeviceConfig,
        events: mpsc::Sender<DeviceEvent>,
        stop: CancellationToken,
        links: LinkSource,
        config_dir: Option<PathBuf>,
        time_scale: f64,
        commands: mpsc::Receiver<Request>,
        resources: Arc<Resources>,
    ) -> Self {
        let stamp = ManualClock::new();
        Self {
            device,
            events,
            stop,
            clock: stamp.clone(),
            stamp,
            config_dir,
            time_scale,
            links: Arc::new(links),
            commands: Arc::new(tokio::sync::Mutex::new(commands)),
            resources,
            backoff: crate::devices::Backoff::default(),
        }
    }

    /// The device's name.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.device.name
    }

    /// True in a replay.
    #[must_use]
    pub fn replaying(&self) -> bool {
        matches!(*self.links, LinkSource::Replay { .. })
    }

    /// The marks of the recording being replayed (empty when live).
    #[must_use]
    pub fn recorded_marks(&self) -> &[String] {
        match &*self.links {
            LinkSource::Replay { marks, .. } => marks,
            LinkSource::Live { .. } => &[],
        }
    }

    /// True once a replay has handed out its last recorded session: the task should end.
    #[must_use]
    pub fn links_exhausted(&self) -> bool {
        match &*self.links {
            LinkSource::Replay { sessions, .. } => sessions.lock().map_or(true, |s| s.is_empty()),
            LinkSource::Live { .. } => false,
        }
    }

    /// The pipeline's requests for this device, held until the task ends.
    pub async fn commands(&self) -> CommandQueue {
        Arc::clone(&self.commands).lock_owned().await
    }

    /// The same context with another back-off policy.
    #[must_use]
    pub fn with_backoff(mut self, backoff: crate::devices::Backoff) -> Self {
        self.backoff = backoff;
        self
    }

    fn live_capture(&self) -> Option<CaptureSink> {
        match &*self.links {
            LinkSource::Live { capture, .. } => capture.lock().ok().and_then(|c| c.clone()),
            LinkSource::Replay { .. } => None,
        }
    }

    /// Writes `mark <text>` into the device's capture when recording (at the run clock's
    /// reading); nothing otherwise.
    pub fn mark(&self, text: &str) {
        if let Some(c) = self.live_capture() {
            c.event(&format!("mark {text}"));
        }
    }

    /// Never records `secret` in this device's capture (see [`CaptureSink::redact`]). Call it
    /// before the credential is sent; it also applies to a capture opened later.
    pub fn redact(&self, secret: &str) -> anyhow::Result<()> {
        if let LinkSource::Live {
            capture_dir: Some(_),
            ..
        } = &*self.links
        {
            let sink = match self.live_capture() {
                Some(s) => s,
                None => self.create_capture()?,
            };
            sink.redact(secret.as_bytes());
        }
        Ok(())
    }

    /// Creates the device's capture file (once per run).
    fn create_capture(&self) -> anyhow::Result<CaptureSink> {
        let LinkSource::Live {
            clock,
            origin,
            capture_dir: Some(dir),
            capture,
        } = &*self.links
        else {
            anyhow::bail!("device {:?} is not recorded", self.device.name);
        };
        let mut slot = capture
            .lock()
            .map_err(|_| anyhow::anyhow!("capture slot poisoned"))?;
        if let Some(s) = slot.as_ref() {
            return Ok(s.clone());
        }
        let link = self
            .device
            .link
            .as_ref()
            .map_or_else(|| "none".to_string(), rfloc_transport::LinkConfig::describe);
        let mut header = Header::new(self.device.driver.capture_name(), link);
        header.started = Some(origin.rfc3339());
        header.notes.push(format!(
            "device {} recorded by rfloc {}",
            self.device.name,
            env!("CARGO_PKG_VERSION")
        ));
        let path = dir.join(format!("{}.cap", self.device.name));
        let sink = CaptureSink::create(&path, &header, Arc::clone(clock))?;
        *slot = Some(sink.clone());
        Ok(sink)
    }

    /// Opens the device's link: the real one (stamped on the run clock, recorded when
    /// capturing) or the next recorded session. The only place the daemon opens links.
    pub async fn open_link(&self) -> anyhow::Result<Transport> {
        match &*self.links {
            LinkSource::Live {
                clock, capture_dir, ..
            } => {
                let link = self
                    .device
                    .link
                    .as_ref()
                    .with_context(|| format!("device {:?} has no link", self.device.name))?;
                let io = open(link).await?;
                let sink = match capture_dir {
                    Some(_) => Some(self.create_capture()?),
                    None => None,
                };
                Ok(Box::new(StampedLink::opened(
                    io,
                    Arc::clone(clock),
                    Arc::clone(&self.stamp),
                    sink,
                )))
            }
            LinkSource::Replay { sessions, mode, .. } => {
                let next = sessions
                    .lock()
                    .map_err(|_| anyhow::anyhow!("replay sessions poisoned"))?
                    .pop_front();
                let capture = next.context("the recording has no further session of this link")?;
                let (io, _handle) = Replayer::new(capture)
                    .mode(*mode)
                    .reads_only_clock(true)
                    .skip_unknown_requests(self.device.driver.replay_skips_unknown())
                    .with_clock(Arc::clone(&self.stamp))
                    .start();
                Ok(Box::new(io))
            }
        }
    }

    /// Sends an observation to the estimator; false when the daemon is shutting down.
    pub async fn send(&self, event: DeviceEvent) -> bool {
        self.events.send(event).await.is_ok()
    }

    /// Sends a status event (never blocks the device task for long).
    pub async fn status(&self, state: DeviceState, detail: impl Into<String>) {
        self.status_with_counters(state, detail, Vec::new()).await;
    }

    /// Sends a status event with the link's error counters (they appear in the DEVICE line).
    pub async fn status_with_counters(
        &self,
        state: DeviceState,
        detail: impl Into<String>,
        counters: Vec<(&'static str, u64)>,
    ) {
        let _ = self
            .events
            .send(DeviceEvent::Status {
                device: self.device.name.clone(),
                driver: self.device.driver.kind(),
                state,
                detail: detail.into(),
                counters,
            })
            .await;
    }
}
