//! Errors of the EKF-SLAM filter.

use thiserror::Error;

/// Errors returned by [`crate::EkfSlam`] operations that reject their input as a whole.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EkfSlamError {
    /// An input number (pose, increment, velocity, time step, covariance) was NaN or infinite.
    #[error("non-finite input in {what}")]
    NonFinite {
        /// Which input was not finite.
        what: &'static str,
    },
    /// A covariance or time step that must be positive (semi-)definite or positive was not.
    #[error("invalid {what}: {detail}")]
    Invalid {
        /// Which input was invalid.
        what: &'static str,
        /// Why.
        detail: String,
    },
}

/// Why a single beacon observation was not used. The filter state is left unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InvalidObservation {
    /// The observation carried neither a range/RSSI nor a bearing.
    Empty,
    /// A value or variance was NaN or infinite.
    NonFinite,
    /// A variance was zero or negative.
    NonPositiveVariance,
    /// A range reading was zero or negative.
    NonPositiveRange,
    /// The predicted beacon lies (almost) on the robot, where range and bearing are singular.
    TooClose,
    /// The innovation covariance was not positive definite.
    SingularInnovation,
}
