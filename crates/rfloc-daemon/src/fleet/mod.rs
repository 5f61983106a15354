//! The robot as a VDA 5050 vehicle of a fleet manager, over an MQTT broker (`[fleet]`).
//!
//! ```text
//! estimator thread ──Sample (try_send, bounded)──▶ fleet task ──publish──▶ MQTT event loop task ──▶ broker
//!   ▲  (EstimatorLink: drains Control between        ▲  (Agent: rfloc-vda5050's Vehicle,          │
//!   │   events, never waits)                         │   steering, errors, factsheet)             │
//!   └──────────Control (goal, initPosition)──────────┤◀── order / instantActions ◀───────────────┘
//! router ──DEVICE states──▶ (unbounded) ─────────────┘     base queue ◀── zero velocity on cancel/stop
//! ```
//!
//! - [`agent`]: the vehicle without I/O (orders, node progress, instant actions, `state`,
//!   `visualization`, `connection`, `factsheet`, device errors).
//! - [`EstimatorLink`]: the estimator thread's end: poses out with `try_send` (a full queue drops
//!   one, counted), controls in with `try_recv` between events.
//! - `mqtt`: the tokio task around `rumqttc`; the event loop runs in its own task and
//!   reconnects with the `[supervision]` back-off (at most 5 s).

pub mod agent;
pub mod factsheet;
mod mqtt;

use std::sync::Arc;

use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::config::RobotConfig;
use crate::devices::Resources;
use crate::events::{DeviceEvent, DeviceState};
use crate::pipeline::{Goal, InitOutcome, Pipeline, Request};

pub use agent::{Agent, Outbox, Publish};

/// Poses queued for the fleet task before the estimator thread drops them.
const SAMPLE_QUEUE: usize = 256;

/// A published estimate with the base's latest measured velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Measurement time (run clock), seconds.
    pub time: f64,
    pub pose: Pose2,
    /// (x, y, yaw) covariance, row-major.
    pub covariance: [[f64; 3]; 3],
    pub mode: EstimateMode,
    /// Forward speed (m/s) and turn rate (rad/s) of the base's latest odometry.
    pub v: f64,
    pub w: f64,
}

/// What the fleet task tells the estimator thread.
#[derive(Debug, Clone, PartialEq)]
pub enum Control {
    /// Drive to this node (or stand still).
    Goal(Option<Goal>),
    /// A fleet manager's `initPosition`.
    InitPosition { action_id: String, pose: Pose2 },
}

/// What reaches the fleet task besides poses.
#[derive(Debug)]
enum Note {
    Device {
        name: String,
        driver: &'static str,
        state: DeviceState,
        detail: String,
    },
    Init {
        action_id: String,
        result: Result<(), String>,
    },
}

/// The estimator thread's end of the fleet link. It never waits.
pub struct EstimatorLink {
    controls: std::sync::mpsc::Receiver<Control>,
    samples: mpsc::Sender<Sample>,
    notes: mpsc::UnboundedSender<Note>,
    velocity: (f64, f64),
    pending_init: Option<String>,
    dropped: u64,
}

impl EstimatorLink {
    /// Before the pipeline handles `event`: the base's velocity, the fleet's controls, an
    /// initialisation's result.
    pub fn before_event(&mut self, pipeline: &mut dyn Pipeline, event: &DeviceEvent) {
        if let DeviceEvent::Odometry { v, w, .. } = event {
            self.velocity = (*v, *w);
        }
        while let Ok(control) = self.controls.try_recv() {
            match control {
                Control::Goal(goal) => {
                    if !pipeline.set_goal(goal) {
                        tracing::warn!(
                            pipeline = pipeline.name(),
                            "the pipeline cannot drive to goals"
                        );
                    }
                }
                Control::InitPosition { action_id, pose } => match pipeline.init_position(pose) {
                    InitOutcome::Done => self.reply(action_id, Ok(())),
                    InitOutcome::Refused(why) => self.reply(action_id, Err(why)),
                    InitOutcome::Pending => self.pending_init = Some(action_id),
                },
            }
        }
        if self.pending_init.is_some() {
            if let Some(result) = pipeline.take_init_result() {
                if let Some(action_id) = self.pending_init.take() {
                    self.reply(action_id, result);
                }
            }
        }
    }

    fn reply(&self, action_id: String, result: Result<(), String>) {
        let _ = self.notes.send(Note::Init { action_id, result });
    }

    /// An estimate the daemon published.
    pub fn estimate(&mut self, est: &PoseEstimate) {
        let c = &est.covariance;
        let sample = Sample {
            time: est.time,
            pose: est.pose,
            covariance: [
                [c[(0, 0)], c[(0, 1)], c[(0, 2)]],
                [c[(1, 0)], c[(1, 1)], c[(1, 2)]],
                [c[(2, 0)], c[(2, 1)], c[(2, 2)]],
            ],
            mode: est.mode,
            v: self.velocity.0,
            w: self.velocity.1,
        };
        if self.samples.try_send(sample).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(dropped = self.dropped, "fleet link behind: poses dropped");
            }
        }
    }
}

/// The router's end: DEVICE state changes for `state.errors`.
#[derive(Clone)]
pub struct DeviceTap {
    notes: mpsc::UnboundedSender<Note>,
}

impl DeviceTap {
    /// A device changed state.
    pub fn note(&self, name: &str, driver: &'static str, state: DeviceState, detail: &str) {
        let _ = self.notes.send(Note::Device {
            name: name.to_string(),
            driver,
            state,
            detail: detail.to_string(),
        });
    }
}

/// A running fleet link.
pub struct Fleet {
    /// For the estimator thread's outputs.
    pub link: EstimatorLink,
    /// For the router.
    pub devices: DeviceTap,
    /// The fleet task: it publishes OFFLINE and disconnects once `stop` is cancelled.
    pub task: JoinHandle<()>,
}

/// Starts the fleet task of a robot file with `[fleet]` (`None` without one). `drives`: the
/// pipeline drives to goals; `base`: the queue of the device that takes velocity requests.
///
/// # Errors
/// The password or CA file cannot be read, or the topic levels are refused.
pub fn start(
    cfg: &RobotConfig,
    drives: bool,
    base: Option<mpsc::Sender<Request>>,
    resources: Arc<Resources>,
    stop: CancellationToken,
) -> anyhow::Result<Option<Fleet>> {
    let Some(fleet) = &cfg.fleet else {
        return Ok(None);
    };
    let mut agent = Agent::new(fleet, &cfg.estimator, &cfg.robot.frame_id, drives)?;
    let options = mqtt::options(fleet, cfg.source.dir.as_deref(), &mut agent)?;
    let (control_tx, control_rx) = std::sync::mpsc::channel();
    let (sample_tx, sample_rx) = mpsc::channel(SAMPLE_QUEUE);
    let (note_tx, note_rx) = mpsc::unbounded_channel();
    tracing::info!(
        broker = %fleet.broker,
        topics = %agent.topic(rfloc_vda5050::Topic::State).trim_end_matches("/state"),
        drives,
        "fleet link (VDA 5050 over MQTT)"
    );
    let backoff = crate::devices::Backoff {
        max_s: cfg.supervision.backoff_max_s.min(5.0),
        ..cfg.supervision.backoff()
    };
    let task = tokio::spawn(mqtt::run(
        agent,
        options,
        mqtt::Inputs {
            samples: sample_rx,
            notes: note_rx,
        },
        mqtt::Outputs {
            controls: control_tx,
            base,
            resources,
        },
        backoff,
        stop,
    ));
    Ok(Some(Fleet {
        link: EstimatorLink {
            controls: control_rx,
            samples: sample_tx,
            notes: note_tx.clone(),
            velocity: (0.0, 0.0),
            pending_init: None,
            dropped: 0,
        },
        devices: DeviceTap { notes: note_tx },
        task,
    }))
}
