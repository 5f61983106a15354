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
    /// A receiver that heard nothing reads as this level (its sensitivity, dBm) when at least
    /// two of the four heard the emitter; `None`: every receiver must hear it.
    pub receiver_sensitivity_dbm: Option<f64>,
}

/// The spread of a filtered estimate: square root of the largest eigenvalue of its 2×2
/// covariance, metres.
fn spread(c: &nalgebra::Matrix2<f64>) -> f64 {
    let (a, b, d) = (c[(0, 0)], 0.5 * (c[(0, 1)] + c[(1, 0)]), c[(1, 1)]);
    let mid = 0.5 * (a + d);
    let rad = (0.25 * (a - d).powi(2) + b * b).sqrt();
    (mid + rad).max(0.0).sqrt()
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
    /// Spread of the target estimate, metres.
    target_sigma: Option<f64>,
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
            target_sigma: None,
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
                self.target_sigma = Some(spread(&estimate.covariance));
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
                self.target_sigma = Some(spread.max(0.5));
                self.recent_raw.clear();
            }
            Err(e) => tracing::warn!(error = %e, "emitter filter re-initialisation failed"),
        }
    }

    /// Drives to `goal` instead of the emitter (`None`: the emitter again).
    pub fn set_goal(&mut self, goal: Option<Point2>) {
        self.goal = goal;
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &HomingConfig {
        &self.config
    }

    /// Times the filter was re-initialised.
    #[must_use]
    pub fn reinitialisations(&self) -> u64 {
        self.reinitialisations
    }

    /// Feeds one laser scan taken at `sensor` (beam angles relative to its heading). A
    /// growable map first grows to hold every beam.
    pub fn observe_scan(&mut self, sensor: &Pose2, beams: Vec<ScanBeam>) {
        if self.config.navigator.use_planner {
            let (lo, hi) = scan_box(sensor, &beams);
            let margin = self.grid.resolution();
            let (lo, hi) = (
                Point2::new(lo.x - margin, lo.y - margin),
                Point2::new(hi.x + margin, hi.y + margin),
            );
            let grew = self.grid.ensure_contains(&lo, &hi).is_some();
            self.grid.integrate_scan(sensor, &beams);
            if grew {
                self.planning_grid = inflate(&self.grid);
            } else {
                inflate_region(&self.grid, &mut self.planning_grid, &lo, &hi);
            }
        }
        self.scan = beams;
    }

    /// One navigator step at time `t` and pose `pose`. The navigator is given the filtered
    /// estimate itself: arrival is declared only within its arrival distance of that
    /// estimate. A growable map first grows to hold the robot and the estimate (with
    /// [`GOAL_MARGIN_M`] around them), so a goal at any distance the radios reach can be
    /// planned to; beyond the map's `max_cells` the navigator drives straight at it.
    pub fn command(&mut self, t: f64, pose: Pose2, bumpers: Bumpers) -> NavigationCommand {
        if self.config.navigator.use_planner {
            if let Some(target) = self.goal.or(self.target).filter(Point2::is_finite) {
                let m = GOAL_MARGIN_M;
                let lo = Point2::new(target.x.min(pose.x) - m, target.y.min(pose.y) - m);
                let hi = Point2::new(target.x.max(pose.x) + m, target.y.max(pose.y) + m);
                if self.grid.ensure_contains(&lo, &hi).is_some() {
                    self.planning_grid = inflate(&self.grid);
                }
            }
        }
        self.navigator.step(&NavigatorInput {
            time_s: t,
            pose,
            // A fleet goal is exact: no spread holds its arrival back.
            target: self.goal.or(self.target),
            target_sigma_m: if self.goal.is_some() { None } else { self.target_sigma },
            grid: &self.planning_grid,
            scan: &self.scan,
            bumpers,
        })
    }

    /// The occupancy grid (as the laser built it, before inflation).
    #[must_use]
    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
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

/// Space kept around the robot and the goal when a growable map grows for a goal, metres.
const GOAL_MARGIN_M: f64 = 2.0;

/// The box holding the sensor and every beam's end point.
fn scan_box(sensor: &Pose2, beams: &[ScanBeam]) -> (Point2, Point2) {
    let (mut lo, mut hi) = (
        Point2::new(sensor.x, sensor.y),
        Point2::new(sensor.x, sensor.y),
    );
    for b in beams {
        let length = b.range_m.min(b.max_range_m);
        if !(length.is_finite() && length >= 0.0 && b.angle_rad.is_finite()) {
            continue;
        }
        let a = sensor.theta + b.angle_rad;
        let (x, y) = (sensor.x + length * a.cos(), sensor.y + length * a.sin());
        lo = Point2::new(lo.x.min(x), lo.y.min(y));
        hi = Point2::new(hi.x.max(x), hi.y.max(y));
    }
    (lo, hi)
}

/// [`inflate`] redone for the cells of the box `[lo, hi]` and one cell around it: the only
/// cells whose inflated value can change when the grid changed inside the box.
fn inflate_region(grid: &OccupancyGrid, out: &mut OccupancyGrid, lo: &Point2, hi: &Point2) {
    if out.width() != grid.width() || out.height() != grid.height() {
        *out = inflate(grid);
        return;
    }
    let r = grid.resolution();
    let o = grid.config().origin;
    let index = |v: f64, origin: f64, n: usize| -> usize {
        let f = ((v - origin) / r).floor();
        if f.is_nan() || f < 0.0 {
            0
        } else {
            (f as usize).min(n.saturating_sub(1))
        }
    };
    let (w, h) = (grid.width(), grid.height());
    let x0 = index(lo.x, o.x, w).saturating_sub(1);
    let y0 = index(lo.y, o.y, h).saturating_sub(1);
    let x1 = (index(hi.x, o.x, w) + 1).min(w.saturating_sub(1));
    let y1 = (index(hi.y, o.y, h) + 1).min(h.saturating_sub(1));
    for iy in y0..=y1 {
        for ix in x0..=x1 {
            let c = GridCell::new(ix, iy);
            let near_occupied =
                (iy.saturating_sub(1)..=(iy + 1).min(h.saturating_sub(1))).any(|ny| {
                    (ix.saturating_sub(1)..=(ix + 1).min(w.saturating_sub(1)))
                        .any(|nx| grid.class(GridCell::new(nx, ny)) == CellClass::Occupied)
                });
            if near_occupied {
                out.mark_occupied(c);
            } else if let Some(l) = grid.log_odds(c) {
                out.set_log_odds(c, l);
            }
        }
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
