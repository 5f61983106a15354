//! Errors of the emitter estimators.

/// What went wrong in an estimator or planner call. Bad input is reported, never panicked on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EmitterError {
    /// An RSS reading was NaN or infinite; the four values are returned as given.
    #[error("non-finite RSS reading: front {front}, back {back}, left {left}, right {right} dBm")]
    NonFiniteRss {
        front: f64,
        back: f64,
        left: f64,
        right: f64,
    },
    /// A robot pose had a non-finite component.
    #[error("non-finite robot pose ({x}, {y}, {theta})")]
    NonFinitePose { x: f64, y: f64, theta: f64 },
    /// A measurement (range or bearing) was not finite or the range was negative.
    #[error("invalid range/bearing measurement: range {range_m} m, bearing {bearing_rad} rad")]
    InvalidMeasurement { range_m: f64, bearing_rad: f64 },
    /// A configuration value is out of its valid domain.
    #[error("invalid configuration: {0}")]
    InvalidConfig(&'static str),
}
