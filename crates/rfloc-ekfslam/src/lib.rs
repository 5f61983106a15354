//! EKF-SLAM with radio beacons (range, RSSI and bearing; known data association by beacon
//! address) and a waypoint controller. Pure: no I/O, no clocks, no threads.
//!
//! - [`EkfSlam`]: state `[x, y, θ, b₁ₓ, b₁ᵧ, …]`; [`EkfSlam::predict_velocity`] (v, ω, dt) and
//!   [`EkfSlam::predict_odometry`] (robot-frame increments) touch only the pose rows/columns of P;
//!   [`EkfSlam::update`] takes [`BeaconObservation`]s, gates them by Mahalanobis distance, updates
//!   mapped beacons (Joseph or Cholesky form) and adds new ones with full cross-covariances
//!   (inverse model, or delayed triangulation for range-only/RSSI-only/bearing-only views).
//! - [`WaypointController`]: (v, ω) commands from the current estimate.
//! - [`accuracy::evaluate`]: RMSE against truth and per-beacon final errors.
//!
//! Units: metres, radians (counter-clockwise positive, wrapped to (−π, π]), seconds, dBm.
//! The maths is written out in `docs/estimators-ekfslam-hfgrid.md`.
#![forbid(unsafe_code)]

pub mod accuracy;
mod config;
mod controller;
mod delayed;
mod error;
mod filter;
pub mod models;
mod observation;
mod wheel_slip;

pub use config::{
    twist_from_wheel_speeds, CovarianceUpdate, DelayedInit, EkfSlamConfig, Gate, OdometryNoise,
    PathLoss, RssiHandling, VelocityNoise,
};
pub use controller::{ControlCommand, WaypointController, WaypointControllerConfig};
pub use error::{EkfSlamError, InvalidObservation};
pub use filter::{BeaconEstimate, EkfSlam, FilterStats};
pub use observation::{
    BeaconId, BeaconObservation, BearingReading, ObservationOutcome, RangeReading,
};
pub use wheel_slip::{wheel_travel, WheelSlipNoise};
