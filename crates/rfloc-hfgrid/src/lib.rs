//! HF RFID floor grid: initial pose from a 360° turn on the spot, then tracking while driving.
//! Pure: no I/O, no clocks.
//!
//! - [`TagGrid`]: tag UID → position (m); [`TagGrid::seed002_test_field`] is the nine-tag field
//!   of the reference (its Table 9).
//! - [`RssiModel`]: RSSI 0–7 ↔ distance as a likelihood over distance per value, with the
//!   reference's blind spot ([`RssiModel::seed002_blind_spot`]) or a monotonic table
//!   ([`RssiModel::seed002_ideal`]).
//! - [`InitialPoseSolver`]: maximum-likelihood `(x, y, θ)` with a 3×3 covariance from
//!   [`TurnStop`]s, or a typed [`InitError`] saying why not.
//! - [`GridTracker`]: particle filter fusing odometry increments with tag reports.
//!
//! Units: metres, radians (CCW positive, wrapped to (−π, π]).
#![forbid(unsafe_code)]

mod grid;
mod init;
mod reading;
mod rssi;
mod tracker;

pub use grid::{GridError, GridLayout, TagGrid, TagUid, SEED002_TABLE9, SEED002_UID_PREFIX};
pub use init::{InitError, InitialPose, InitialPoseConfig, InitialPoseSolver};
pub use reading::{TagReading, TurnStop};
pub use rssi::{normal_cdf, RssiBand, RssiModel, MAX_RSSI};
pub use tracker::{GridTracker, GridTrackerConfig, TrackerError, TrackerUpdate};
