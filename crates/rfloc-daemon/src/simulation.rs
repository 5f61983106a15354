//! The seam between the daemon and a simulator: a robot file with a `[simulation]` section runs
//! against emulated devices that a lab crate starts. The daemon itself has no emulator or
//! simulator code; it only calls this trait.

use std::future::Future;
use std::pin::Pin;

use rfloc_pose::PoseEstimate;
use rfloc_transport::SharedClock;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::config::EstimatorConfig;
use crate::devices::AntennaSource;
use crate::events::DeviceEvent;
use crate::pipeline::Request;

/// Scores published estimates against a simulation's truth (runs on the estimator thread).
pub type Scorer = Box<dyn FnMut(&PoseEstimate) + Send>;

/// A boxed future, for trait methods.
pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// What a running simulation gets once the daemon's devices run.
pub struct SimulationIo<'a> {
    /// Observations that do not come over a wire (an in-process range sensor).
    pub events: mpsc::Sender<DeviceEvent>,
    /// Velocity commands to the base, when the pipeline does not drive it.
    pub base: Option<mpsc::Sender<Request>>,
    /// The robot file's estimator.
    pub estimator: &'a EstimatorConfig,
    /// Whether the pipeline drives the base itself.
    pub pipeline_drives_base: bool,
    /// The daemon's stop token.
    pub stop: CancellationToken,
}

/// A running simulation: emulators serving the robot file's devices (whose links it rewrote).
pub trait Simulation: Send {
    /// Simulated seconds per wall second.
    fn time_scale(&self) -> f64;
    /// Simulated seconds after which the daemon stops, if any.
    fn duration_s(&self) -> Option<f64>;
    /// The clock device observations are stamped with (the emulated robot's simulated time).
    fn clock(&self) -> Option<SharedClock>;
    /// A pin-less antenna rotator for a sweeping radio, once.
    fn take_antenna(&mut self) -> Option<AntennaSource>;
    /// Starts what runs beside the devices (a motion script, an in-process sensor).
    fn started(&mut self, io: SimulationIo<'_>);
    /// Scores published estimates against the truth (called on the estimator thread).
    fn scorer(&self) -> Option<Scorer>;
    /// Stops the emulators and reports.
    fn shutdown(self: Box<Self>) -> BoxFuture<'static, ()>;
}
