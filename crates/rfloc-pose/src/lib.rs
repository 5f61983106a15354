//! Pose, covariance and angle types shared by rfloc estimators and the daemon.
//!
//! Conventions (used by every rfloc crate):
//! - world frame `map`, x forward/east, y left/north, angles in radians, counter-clockwise positive;
//! - headings are kept in `(-π, π]` by [`wrap_angle`];
//! - a planar pose covariance is a 3×3 matrix over `(x, y, yaw)`;
//! - [`PoseEstimate::ros_covariance`] widens it to ROS's 6×6 `(x, y, z, roll, pitch, yaw)` order.
#![forbid(unsafe_code)]

mod angle;
mod estimate;
mod normal;
mod pose;

pub use angle::{angle_diff, wrap_angle};
pub use estimate::{EstimateMode, PoseEstimate};
pub use normal::normal_cdf;
pub use pose::Pose2;
