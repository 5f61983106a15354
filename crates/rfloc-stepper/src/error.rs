//! Typed stepper errors.

use embedded_hal::digital::ErrorKind;

/// Which control line failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PinRole {
    /// STEP input of the driver.
    Step,
    /// DIR input of the driver.
    Dir,
    /// ENABLE input of the driver.
    Enable,
}

impl std::fmt::Display for PinRole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Step => "STEP",
            Self::Dir => "DIR",
            Self::Enable => "ENABLE",
        })
    }
}

/// Errors of the stepper driver, its handle and the simulated stepper.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepperError {
    /// Setting a control line failed; `detail` is the pin error's `Debug` text.
    #[error("{pin} pin error ({kind:?}): {detail}")]
    Pin {
        /// Which line.
        pin: PinRole,
        /// The embedded-hal error kind.
        kind: ErrorKind,
        /// The implementation's error, formatted.
        detail: String,
    },
    /// The configuration cannot be used.
    #[error("invalid stepper configuration: {0}")]
    InvalidConfig(String),
    /// The target angle is NaN or infinite.
    #[error("target angle is not finite: {0}")]
    NotFinite(f64),
    /// The target lies outside the bounded travel.
    #[error("target {target_rad} rad outside travel [{min_rad}, {max_rad}] rad")]
    OutOfRange {
        /// Requested absolute angle.
        target_rad: f64,
        /// Lower limit.
        min_rad: f64,
        /// Upper limit.
        max_rad: f64,
    },
    /// The move needs more steps than one move may have.
    #[error("move of {0} steps is too long")]
    MoveTooLong(i64),
    /// The blocking stepper thread has stopped (handle only).
    #[error("stepper thread is gone")]
    ThreadGone,
    /// The GPIO backend could not be opened.
    #[error("GPIO setup: {0}")]
    Gpio(String),
}

impl StepperError {
    pub(crate) fn pin<E: embedded_hal::digital::Error>(pin: PinRole, e: &E) -> Self {
        Self::Pin {
            pin,
            kind: e.kind(),
            detail: format!("{e:?}"),
        }
    }
}
