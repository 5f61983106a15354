//! The emitter-homing pipeline of one robot, without I/O: RSS of the four antennas → raw
//! range/bearing → particle filter; laser scans → occupancy grid; pose, estimate, grid, scan
//! and bumpers → navigator command. The simulated trial feeds it; a robot daemon could feed it
//! the same way.

use rfloc_emitter::{
    differential_range_bearing, AntennaRss, Bumpers, DifferentialRssConfig, EmitterEstimate,
    EmitterNavigator, EmitterParticleFilter, NavigationCommand, NavigatorConfig, NavigatorInput,
    OccupancyGrid, OccupancyGridConfig, ParticleFilterConfig, Point2, ScanBeam,
};
use rfloc_pose::Pose2;

/// Settings of one homing run.
#[derive(Debug, Clone, Copy)]
pub struct HomingConfig {
    /// RSS → range calibration (`A1`, `A2`).
    pub rss: DifferentialRssConfig,
    /// Particle filter constants.
    pub filter: ParticleFilterConfig,
    /// Grid geometry (the map is centred on the start).
    pub grid: OccupancyGridConfig,
    /// Navigator constants (`use_planner` selects the full or the preliminary system).
    pub navigator: NavigatorConfig,
    /// Seed of the particle filter.
    pub seed: u64,
}

/// State of the pipeline between steps.
#[derive(Debug)]
pub struct EmitterHoming {
    config: HomingConfig,
    filter: EmitterParticleFilter,
    grid: OccupancyGrid,
    navigator: EmitterNavigator,
    scan: Vec<ScanBeam>,
    target: Option<Point2>,
    last_rss_time: Option<f64>,
    rejected_rss: u64,
}

impl EmitterHoming {
    /// A pipeline for a robot starting at `start` (particles around the start, empty map).
    ///
    /// # Errors
    /// An invalid filter or grid configuration.
    pub fn new(config: HomingConfig, start: &Pose2) -> anyhow::Result<Self> {
        Ok(Self {
            filter: EmitterParticleFilter::new(config.filter, start, config.seed)?,
            grid: OccupancyGrid::new(config.grid)?,
            navigator: EmitterNavigator::new(config.navigator),
            scan: Vec::new(),
            target: None,
            last_rss_time: None,
            rejected_rss: 0,
            config,
        })
    }

    /// Feeds one RSS reading of the four antennas taken at `pose` (the robot's own pose
    /// estimate) at time `t`: the filtered estimate with the raw position it was fed, or `None`
    /// when the reading was unusable (counted).
    pub fn observe_rss(
        &mut self,
        t: f64,
        pose: &Pose2,
        rss: &AntennaRss,
    ) -> Option<EmitterEstimate> {
        let measured = match differential_range_bearing(rss, &self.config.rss) {
            Ok(m) => m,
            Err(e) => {
                self.rejected_rss += 1;
                tracing::warn!(error = %e, "emitter RSS reading rejected");
                return None;
            }
        };
        let dt = self.last_rss_time.map_or(0.0, |last| t - last);
        self.last_rss_time = Some(t);
        match self.filter.update(pose, &measured, dt) {
            Ok(estimate) => {
                self.target = Some(estimate.mean);
                Some(estimate)
            }
            Err(e) => {
                self.rejected_rss += 1;
                tracing::warn!(error = %e, "particle filter update rejected");
                None
            }
        }
    }

    /// Feeds one laser scan taken at `sensor` (beam angles relative to its heading).
    pub fn observe_scan(&mut self, sensor: &Pose2, beams: Vec<ScanBeam>) {
        if self.config.navigator.use_planner {
            self.grid.integrate_scan(sensor, &beams);
        }
        self.scan = beams;
    }

    /// One navigator step at time `t` and pose `pose`.
    pub fn command(&mut self, t: f64, pose: Pose2, bumpers: Bumpers) -> NavigationCommand {
        self.navigator.step(&NavigatorInput {
            time_s: t,
            pose,
            target: self.target,
            grid: &self.grid,
            scan: &self.scan,
            bumpers,
        })
    }

    /// The current target estimate.
    #[must_use]
    pub fn target(&self) -> Option<Point2> {
        self.target
    }

    /// RSS readings the pipeline could not use.
    #[must_use]
    pub fn rejected_rss(&self) -> u64 {
        self.rejected_rss
    }

    /// How many times A* ran.
    #[must_use]
    pub fn plan_count(&self) -> u64 {
        self.navigator.plan_count()
    }
}
