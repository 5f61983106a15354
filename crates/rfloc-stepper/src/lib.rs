//! Step/dir/enable stepper driver over embedded-hal, with a Linux GPIO character-device backend.
//!
//! - [`StepperDriver`]: blocking driver generic over embedded-hal 1.0 `OutputPin`s and `DelayNs`,
//!   with a trapezoidal ramp, absolute angle tracking, bounded or shortest-path moves and homing
//!   to the stored zero. Pulse timing constants are in [`timing`].
//! - [`gpio`]: lines on `/dev/gpiochipN` through `gpiocdev` (uAPI v2).
//! - [`StepperHandle`]: runs a driver on its own thread and offers async commands.
//! - [`AntennaRotator`]: what a bearing scan needs; implemented by [`StepperHandle`] and by
//!   [`SimulatedStepper`].
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod config;
mod driver;
mod error;
mod geometry;
pub mod gpio;
mod handle;
mod rotator;
pub mod timing;

pub use config::{MovePolicy, StepperConfig};
pub use driver::{NoEnablePin, StepperDriver};
pub use error::{PinRole, StepperError};
pub use geometry::{StepGeometry, MAX_MOVE_STEPS};
pub use handle::StepperHandle;
pub use rotator::{AngleProbe, AntennaRotator, SimulatedStepper};
