//! Single RF emitter localisation and navigation: pure estimators and planners, no I/O.
//!
//! The pieces, in the order data flows through them:
//! - [`antenna`]: range and bearing of the emitter from the differential RSS of four directional
//!   antennas mounted at 90° on the robot (the "raw" estimate);
//! - [`model`]: the matching forward model (RSS of each antenna for a known emitter position), for
//!   tests and simulators;
//! - [`filter`]: a particle filter over the emitter position in the world frame, with the
//!   clamped distance/angle weights, `N_eff` test and systematic resampling;
//! - [`grid`]: a log-odds occupancy grid (20 cm cells) built by ray-casting 2-D range scans;
//! - [`planner`]: 4-connected A* over the grid with neighbourhood-summed cell costs and a turn
//!   cost, and a path simplifier;
//! - [`navigator`]: the motion-planning state machine that turns pose, estimate, grid, scan and
//!   bumpers into `(v, ω)` commands.
//!
//! Conventions follow `rfloc_pose`: world frame x/y in metres, angles in radians,
//! counter-clockwise positive, headings wrapped to `(-π, π]`.
#![forbid(unsafe_code)]

pub mod antenna;
pub mod error;
pub mod filter;
pub mod grid;
pub mod model;
pub mod navigator;
pub mod planner;

pub use antenna::{differential_range_bearing, AntennaRss, DifferentialRssConfig, RangeBearing};
pub use error::EmitterError;
pub use filter::{
    effective_sample_size, systematic_resample, EmitterEstimate, EmitterParticleFilter, Particle,
    ParticleFilterConfig,
};
pub use grid::{
    CellClass, GridCell, OccupancyGrid, OccupancyGridConfig, ScanBeam, ScanIntegration,
};
pub use model::DirectionalArrayModel;
pub use navigator::{
    Bumpers, EmitterNavigator, NavigationCommand, NavigatorConfig, NavigatorInput, NavigatorState,
};
pub use planner::{plan_path, simplify_path, CostMap, Heading4, PathCosts, PlannedPath};

/// A point in the world plane, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Point2 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
}

impl Point2 {
    /// A point from its coordinates.
    #[must_use]
    pub fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Euclidean distance to another point.
    #[must_use]
    pub fn distance(&self, other: &Point2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    /// True when both coordinates are finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}
