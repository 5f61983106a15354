//! Rotating directional antenna bearing scan: sweep, per-beacon range and bearing.
//!
//! - [`estimate_sweep`]: pure estimator. For every beacon heard in a [`Sweep`] it gives a range
//!   from the log-distance model ([`PathLossModel`]) at the peak RSSI and a bearing at the
//!   maximum RSSI refined by a parabola fitted near the maximum or, with a calibrated
//!   [`GainPattern`], by a least-squares fit of the whole pattern to every stop; both with
//!   variances, or a typed [`Rejection`] (flat, multi-peak, peak at the arc's end, too few
//!   stops).
//! - [`SweepPlanner`]: stops of each sweep, alternating direction.
//! - [`ScanRunner`]: drives an [`rfloc_stepper::AntennaRotator`] and an [`RssiProbe`].
//! - [`ReflectorPattern`], [`CosinePowerPattern`]: gain patterns ([`GainPattern`] is either).
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod estimate;
mod pathloss;
mod pattern;
mod planner;
mod probe;
mod runner;
mod sweep;

pub use estimate::{estimate_sweep, BeaconObservation, EstimatorConfig, Rejection, SweepReport};
pub use pathloss::{PathLossModel, RangeEstimate};
pub use pattern::{CosinePowerPattern, GainPattern, ReflectorPattern};
pub use planner::{PlanError, SweepPlanConfig, SweepPlanner};
pub use probe::RssiProbe;
pub use runner::{ScanConfig, ScanError, ScanResult, ScanRunner};
pub use sweep::{Sweep, SweepSample};
