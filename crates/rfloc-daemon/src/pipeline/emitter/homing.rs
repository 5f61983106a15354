//! The emitter-homing pipeline of one robot, without I/O: RSS of the four antennas → raw
//! range/bearing → particle filter; laser scans → occupancy grid; pose, estimate, grid, scan
//! and bumpers → navigator command. The simulated trial feeds it; a robot daemon could feed it
//! the same way.

use std::collections::VecDeque;

use rfloc_emitter::{
    differential_range_bearing, AntennaRss, Bumpers, CellClass, DifferentialRssConfig,
    EmitterEstimate, EmitterNavigator, EmitterParticleFilter, GridCell, NavigationCommand,
    NavigatorConfig, NavigatorInput, OccupancyGrid, OccupancyGridConfig, ParticleFilterConfig,
    Point2, ScanBeam,
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
    /// The grid with every occupied cell grown by one cell, for the navigator.
    planning_grid: OccupancyGrid,
    navigator: EmitterNavigator,
    scan: Vec<ScanBeam>,
    target: Option<Point2>,
    /// A goal that replaces the emitter as the navigator's target (a fleet manager's order).
    goal: Option<Point2>,
    last_rss_time: Option<f64>,
    rejected_rss: u64,
    /// Recent raw positions, newest last (at most [`RECENT_RAW`]).
    recent_raw: VecDeque<(Point2, f64)>,
    reinitialisations: u64,
}

/// Raw positions kept to test the filter against.
const RECENT_RAW: usize = 10;
/// A raw position this close to the filtered mean (metres), or within this fraction of its
/// range, agrees with the filter.
const AGREE_M: f64 = 1.5;
const AGREE_RANGE_FRACTION: f64 = 0.3;
/// Re-initialise when fewer than this fraction of the recent raw positions agree.
const AGREE_MIN_FRACTION: f64 = 0.2;

impl EmitterHoming {
    /// The emitter filter's particles: hypothesised emitter positions with their weights.
    #[must_use]
    pub fn particles(&self) -> &[rfloc_emitter::filter::Particle] {
        self.filter.particles()
    }

    /// A pipeline for a robot starting at `start` (particles around the start, empty map).
    ///
    /// # Errors
    /// An invalid filter or grid configuration.
    pub fn new(config: HomingConfig, start: &Pose2) -> anyhow::Result<Self> {
        Ok(Self {
            filter: EmitterParticleFilter::new(config.filter, start, config.seed)?,
            grid: OccupancyGrid::new(config.grid)?,
            planning_grid: OccupancyGrid::new(config.grid)?,
            navigator: EmitterNavigator::new(config.navigator),
            scan: Vec::new(),
            target: None,
            goal: None,
            last_rss_time: None,
            rejected_rss: 0,
            recent_raw: VecDeque::with_capacity(RECENT_RAW + 1),
            reinitialisations: 0,
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
                self.recent_raw.push_back((estimate.raw, measured.range_m));
                if self.recent_raw.len() > RECENT_RAW {
                    self.recent_raw.pop_front();
                }
                self.check_divergence(&estimate.mean);
                Some(estimate)
            }
            Err(e) => {
                self.rejected_rss += 1;
                tracing::warn!(error = %e, "particle filter update rejected");
                None
            }
        }
    }

    /// Particle deprivation guard. The seed's weights multiply over updates, the particles
    /// collapse, and a filter that converged on a biased range (the emitter seen through a
    /// wall looks several times farther away) cannot follow when the line of sight returns.
    /// When the last [`RECENT_RAW`] raw positions mostly disagree with the filter, the filter
    /// restarts on a disc around their median, as large as their spread.
    fn check_divergence(&mut self, mean: &Point2) {
        if self.recent_raw.len() < RECENT_RAW {
            return;
        }
        let agree = self
            .recent_raw
            .iter()
            .filter(|(p, r)| p.distance(mean) <= AGREE_M.max(AGREE_RANGE_FRACTION * r))
            .count();
        if (agree as f64) >= AGREE_MIN_FRACTION * self.recent_raw.len() as f64 {
            return;
        }
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        };
        let centre = Point2::new(
            median(self.recent_raw.iter().map(|(p, _)| p.x).collect()),
            median(self.recent_raw.iter().map(|(p, _)| p.y).collect()),
        );
        let spread = median(
            self.recent_raw
                .iter()
                .map(|(p, _)| p.distance(&centre))
                .collect(),
        );
        self.reinitialisations += 1;
        let seed = self.config.seed.wrapping_add(self.reinitialisations);
        match EmitterParticleFilter::around(self.config.filter, centre, spread.max(0.5), seed) {
            Ok(f) => {
                tracing::info!(
                    x = centre.x,
                    y = centre.y,
                    radius = spread.max(0.5),
                    "emitter filter re-initialised on the recent raw estimates"
                );
                self.filter = f;
                self.target = Some(centre);
                self.recent_raw.clear();
            }
            Err(e) => tracing::warn!(error = %e, "emitter filter re-initialisation failed"),
        }
    }

    /// Drives to `goal` instead of the emitter (`None`: the emitter again).
    pub fn set_goal(&mut self, goal: Option<Point2>) {
        self.goal = goal;
    }

    /// Times the filter was re-initialised.
    #[must_use]
    pub fn reinitialisations(&self) -> u64 {
        self.reinitialisations
    }

    /// Feeds one laser scan taken at `sensor` (beam angles relative to its heading).
    pub fn observe_scan(&mut self, sensor: &Pose2, beams: Vec<ScanBeam>) {
        if self.config.navigator.use_planner {
            self.grid.integrate_scan(sensor, &beams);
            self.planning_grid = inflate(&self.grid);
        }
        self.scan = beams;
    }

    /// One navigator step at time `t` and pose `pose`. The navigator is given the estimate
    /// moved inside the map (one cell in from its edge): behind walls the RSS range is far too
    /// long (every wall costs the signal several dB), and a goal outside the map would make the
    /// full system give up planning and drive straight at the wall.
    pub fn command(&mut self, t: f64, pose: Pose2, bumpers: Bumpers) -> NavigationCommand {
        let target = self.goal.or(self.target).map(|p| self.inside_map(p));
        self.navigator.step(&NavigatorInput {
            time_s: t,
            pose,
            target,
            grid: &self.planning_grid,
            scan: &self.scan,
            bumpers,
        })
    }

    fn inside_map(&self, p: Point2) -> Point2 {
        let g = &self.config.grid;
        let margin = 1.5 * g.resolution_m;
        let (x0, y0) = (g.origin.x + margin, g.origin.y + margin);
        let x1 = g.origin.x + g.width as f64 * g.resolution_m - margin;
        let y1 = g.origin.y + g.height as f64 * g.resolution_m - margin;
        if !self.config.navigator.use_planner || x1 <= x0 || y1 <= y0 {
            return p;
        }
        Point2::new(p.x.clamp(x0, x1), p.y.clamp(y0, y1))
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

/// Configuration space for a round robot about one cell in radius: every cell next to an
/// occupied one (8-neighbourhood) becomes occupied too. A* then keeps the robot's centre two
/// cells from what the laser saw, beyond the 20 cm avoidance reflex, instead of planning paths
/// that graze obstacles and trigger the reflex all the way along (the seed's neighbourhood
/// cost sum alone keeps only one cell).
fn inflate(grid: &OccupancyGrid) -> OccupancyGrid {
    let mut out = grid.clone();
    for iy in 0..grid.height() {
        for ix in 0..grid.width() {
            if grid.class(GridCell::new(ix, iy)) != CellClass::Occupied {
                continue;
            }
            for ny in iy.saturating_sub(1)..=iy + 1 {
                for nx in ix.saturating_sub(1)..=ix + 1 {
                    out.mark_occupied(GridCell::new(nx, ny));
                }
            }
        }
    }
    out
}
