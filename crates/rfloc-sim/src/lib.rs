//! Deterministic simulation model for rfloc: the world (walls, tags, beacons, emitter), a
//! differential-drive robot with odometry noise and collisions, sensor models taken from the
//! four source theses, scenario files, metrics, reports and `truth.csv`.
//!
//! Everything here is pure: no I/O except the explicit `load`/`write` functions, and every
//! random draw comes from a seeded `ChaCha8Rng`, so the same seed gives the same run.
#![forbid(unsafe_code)]

pub mod emitter;
pub mod error;
pub mod geometry;
pub mod hf;
pub mod keys;
pub mod kinematics;
pub mod metrics;
pub mod noise;
pub mod pattern;
pub mod published;
pub mod recorder;
pub mod report;
pub mod scanner;
pub mod scenario;
pub mod sensors;
pub mod truth;
pub mod uhf;
pub mod world;
pub mod xbee;

pub use error::SimError;
pub use geometry::{Point, Polygon, Segment};
pub use kinematics::{integrate_unicycle, DiffDriveParams, RobotSim, StepOutcome};
pub use metrics::{ErrorStats, Summary, TimedPose, TrialResult};
pub use recorder::{write_outputs, TrialRecorder};
pub use report::Report;
pub use scenario::{Pipeline, Scenario, ScenarioSpec};
pub use sensors::SensorSuite;
pub use world::{World, WorldSpec};
