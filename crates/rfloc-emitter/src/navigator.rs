//! Motion planning towards the emitter (the seed's sections 5 and 6.2), as a pure state
//! machine: each call takes the robot pose, the target estimate, the grid, the latest scan and
//! the bumpers, and returns `(v, ω)` and the navigator state.
//!
//! Rules, in priority order:
//! 1. **Bumpers**: front contact → reverse, rear contact → drive forward (state `Avoiding`).
//! 2. **No target** → `Searching`: turn slowly on the spot.
//! 3. **Arrived**: the target is within `arrival_distance_m` (seed: 50 cm) → stop; if its
//!    spread exceeds `arrival_max_sigma_m`, turn slowly on the spot instead (`Searching`).
//! 4. **Obstacle** within `obstacle_distance_m` (seed: 20 cm) in the front sector → `Avoiding`:
//!    turn on the spot, towards the side with more clearance, until the sector is clear.
//! 5. **Driving**: with the planner on, follow the waypoints of an A* path from the robot cell to
//!    the target cell, replanned every `replan_period_s`, when the path runs into an occupied
//!    cell, when the target moves to another cell, or when the robot leaves the path; off the
//!    path or without a plan, aim at the target directly (the seed's preliminary system).
//!    If the aim point is within ±`heading_tolerance_deg` (seed: 15°) drive forward with a small
//!    heading correction; otherwise turn on the spot (path following, as the seed's grid-aligned
//!    motion) or, without the planner, turn while creeping forward if the aim is within ±90°.

use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

use crate::grid::{CellClass, GridCell, OccupancyGrid, ScanBeam};
use crate::planner::{plan_path, simplify_path, CostMap, Heading4, PathCosts};
use crate::Point2;

/// Navigator constants. Defaults give the seed's thresholds; speeds suit a Pioneer 3-DX.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NavigatorConfig {
    /// Forward speed when driving, m/s.
    pub drive_speed_mps: f64,
    /// Largest turn rate, rad/s.
    pub max_turn_rate_rps: f64,
    /// Proportional gain of heading correction, (rad/s)/rad.
    pub heading_gain: f64,
    /// Drive straight when the aim is within this angle of the heading, degrees (seed: 15).
    pub heading_tolerance_deg: f64,
    /// Obstacle distance that triggers avoidance, metres (seed: 0.20).
    pub obstacle_distance_m: f64,
    /// Half-width of the sector checked for obstacles, degrees either side of the heading.
    pub front_sector_deg: f64,
    /// Stop when the target is this close, metres (seed: 0.50).
    pub arrival_distance_m: f64,
    /// Arrival is declared only while the target's spread (`target_sigma_m`) is at most
    /// this, metres; closer than the arrival distance to a vaguer estimate the robot turns
    /// on the spot (`Searching`) and keeps measuring. Infinite by default (the seed has no
    /// such test).
    #[serde(default = "infinite")]
    pub arrival_max_sigma_m: f64,
    /// Speed of the bumper reflex (reverse or forward), m/s.
    pub bumper_speed_mps: f64,
    /// Turn rate while searching for a target, rad/s.
    pub search_turn_rate_rps: f64,
    /// Use the grid and A* (the seed's full system); false gives the preliminary system.
    pub use_planner: bool,
    /// Replan at least this often, seconds.
    pub replan_period_s: f64,
    /// A waypoint counts as reached within this distance, metres.
    pub waypoint_tolerance_m: f64,
    /// Farther than this from every remaining path cell centre the robot is off the path and
    /// replans, metres.
    pub off_path_distance_m: f64,
    /// Path costs for A*.
    pub path_costs: PathCosts,
}

impl Default for NavigatorConfig {
    fn default() -> Self {
        Self {
            drive_speed_mps: 0.3,
            max_turn_rate_rps: 0.8,
            heading_gain: 1.5,
            heading_tolerance_deg: 15.0,
            obstacle_distance_m: 0.2,
            front_sector_deg: 45.0,
            arrival_distance_m: 0.5,
            arrival_max_sigma_m: f64::INFINITY,
            bumper_speed_mps: 0.1,
            search_turn_rate_rps: 0.3,
            use_planner: true,
            replan_period_s: 5.0,
            waypoint_tolerance_m: 0.15,
            off_path_distance_m: 0.5,
            path_costs: PathCosts::default(),
        }
    }
}

fn infinite() -> f64 {
    f64::INFINITY
}

/// Contact sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Bumpers {
    /// Any front bumper pressed.
    pub front: bool,
    /// Any rear bumper pressed.
    pub rear: bool,
}

/// What the navigator is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum NavigatorState {
    /// No target estimate yet.
    Searching,
    /// Heading for the target (directly or along a planned path).
    Driving,
    /// Turning away from an obstacle or reacting to a bumper.
    Avoiding,
    /// Within the arrival distance of the target; stopped.
    Arrived,
}

/// Everything one navigator step looks at.
#[derive(Debug, Clone, Copy)]
pub struct NavigatorInput<'a> {
    /// Time of this step, seconds (any monotonic clock).
    pub time_s: f64,
    /// Robot pose in the world/map frame.
    pub pose: Pose2,
    /// Target position (the filter's weighted mean), or `None` before the first estimate.
    pub target: Option<Point2>,
    /// Spread of the target estimate (square root of its covariance's largest eigenvalue),
    /// metres; `None` when unknown (then taken as good enough to arrive).
    pub target_sigma_m: Option<f64>,
    /// Occupancy grid in the same frame.
    pub grid: &'a OccupancyGrid,
    /// Latest range scan, beam angles relative to the robot heading.
    pub scan: &'a [ScanBeam],
    /// Contact sensors.
    pub bumpers: Bumpers,
}

/// The command of one step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NavigationCommand {
    /// Forward speed, m/s.
    pub v_mps: f64,
    /// Turn rate, rad/s, counter-clockwise positive.
    pub omega_rps: f64,
    /// State after this step.
    pub state: NavigatorState,
    /// Whether A* ran in this step.
    pub replanned: bool,
}

/// The motion planner. Keeps only the plan and the avoidance turn direction between calls.
#[derive(Debug, Clone)]
pub struct EmitterNavigator {
    config: NavigatorConfig,
    path: Vec<GridCell>,
    waypoints: Vec<Point2>,
    next_waypoint: usize,
    last_plan_time: Option<f64>,
    planned_goal: Option<GridCell>,
    /// Grid origin when the plan was made: a grown grid renumbers its cells.
    planned_origin: Option<Point2>,
    avoid_turn_sign: Option<f64>,
    plans: u64,
}

impl EmitterNavigator {
    /// A navigator with no plan.
    #[must_use]
    pub fn new(config: NavigatorConfig) -> Self {
        Self {
            config,
            path: Vec::new(),
            waypoints: Vec::new(),
            next_waypoint: 0,
            last_plan_time: None,
            planned_goal: None,
            planned_origin: None,
            avoid_turn_sign: None,
            plans: 0,
        }
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &NavigatorConfig {
        &self.config
    }

    /// Cells of the current plan (empty without one).
    #[must_use]
    pub fn path(&self) -> &[GridCell] {
        &self.path
    }

    /// Waypoints of the current plan (corner cell centres, world frame).
    #[must_use]
    pub fn waypoints(&self) -> &[Point2] {
        &self.waypoints
    }

    /// How many times A* has run.
    #[must_use]
    pub fn plan_count(&self) -> u64 {
        self.plans
    }

    /// Forgets the current plan (it will be recomputed on the next step).
    pub fn clear_plan(&mut self) {
        self.path.clear();
        self.waypoints.clear();
        self.next_waypoint = 0;
        self.planned_goal = None;
    }

    /// One control step.
    pub fn step(&mut self, input: &NavigatorInput<'_>) -> NavigationCommand {
        let cfg = self.config;
        let cmd = |v: f64, w: f64, state: NavigatorState, replanned: bool| NavigationCommand {
            v_mps: v,
            omega_rps: w,
            state,
            replanned,
        };
        if !input.pose.is_finite() {
            return cmd(0.0, 0.0, NavigatorState::Searching, false);
        }
        if input.bumpers.front {
            self.clear_plan();
            return cmd(-cfg.bumper_speed_mps, 0.0, NavigatorState::Avoiding, false);
        }
        if input.bumpers.rear {
            self.clear_plan();
            return cmd(cfg.bumper_speed_mps, 0.0, NavigatorState::Avoiding, false);
        }
        let Some(target) = input.target.filter(Point2::is_finite) else {
            return cmd(
                0.0,
                cfg.search_turn_rate_rps,
                NavigatorState::Searching,
                false,
            );
        };
        let here = Point2::new(input.pose.x, input.pose.y);
        if here.distance(&target) <= cfg.arrival_distance_m {
            self.avoid_turn_sign = None;
            let vague = input
                .target_sigma_m
                .is_some_and(|s| s.is_nan() || s > cfg.arrival_max_sigma_m);
            if vague {
                // At a vague estimate: turn on the spot and keep measuring.
                return cmd(
                    0.0,
                    cfg.search_turn_rate_rps,
                    NavigatorState::Searching,
                    false,
                );
            }
            return cmd(0.0, 0.0, NavigatorState::Arrived, false);
        }
        if let Some(sign) = self.obstacle_turn(input.scan) {
            self.clear_plan();
            return cmd(
                0.0,
                sign * cfg.max_turn_rate_rps,
                NavigatorState::Avoiding,
                false,
            );
        }
        let mut replanned = false;
        let mut following_path = false;
        let mut aim = target;
        if cfg.use_planner {
            if self.needs_replan(input, &target) {
                replanned = self.replan(input, &target);
            }
            if let Some(wp) = self.current_waypoint(&here) {
                aim = wp;
                following_path = true;
            }
        }
        let error = angle_diff((aim.y - here.y).atan2(aim.x - here.x), input.pose.theta);
        let tolerance = cfg.heading_tolerance_deg.to_radians();
        let omega = (cfg.heading_gain * error).clamp(-cfg.max_turn_rate_rps, cfg.max_turn_rate_rps);
        let (v, w) = if error.abs() <= tolerance {
            (cfg.drive_speed_mps, omega)
        } else if !following_path && error.abs() < std::f64::consts::FRAC_PI_2 {
            // Preliminary system: turn gradually while driving forward.
            (0.5 * cfg.drive_speed_mps, omega)
        } else {
            (0.0, error.signum() * cfg.max_turn_rate_rps)
        };
        cmd(v, w, NavigatorState::Driving, replanned)
    }

    /// `Some(turn sign)` while an obstacle is within the avoidance distance in the front sector.
    fn obstacle_turn(&mut self, scan: &[ScanBeam]) -> Option<f64> {
        let cfg = self.config;
        let sector = cfg.front_sector_deg.to_radians();
        let valid =
            |b: &&ScanBeam| b.angle_rad.is_finite() && b.range_m.is_finite() && b.range_m >= 0.0;
        let blocked = scan.iter().filter(valid).any(|b| {
            angle_diff(b.angle_rad, 0.0).abs() <= sector
                && b.range_m < b.max_range_m
                && b.range_m <= cfg.obstacle_distance_m
        });
        if !blocked {
            self.avoid_turn_sign = None;
            return None;
        }
        if let Some(s) = self.avoid_turn_sign {
            return Some(s);
        }
        // Turn towards the side whose nearest return is farther away.
        let nearest = |side: f64| {
            scan.iter()
                .filter(valid)
                .filter(|b| angle_diff(b.angle_rad, 0.0) * side > 0.0)
                .map(|b| b.range_m.min(b.max_range_m))
                .fold(f64::INFINITY, f64::min)
        };
        let sign = if nearest(1.0) >= nearest(-1.0) {
            1.0
        } else {
            -1.0
        };
        self.avoid_turn_sign = Some(sign);
        Some(sign)
    }

    fn needs_replan(&self, input: &NavigatorInput<'_>, target: &Point2) -> bool {
        let Some(last) = self.last_plan_time else {
            return true;
        };
        if self.path.is_empty() || input.time_s - last >= self.config.replan_period_s {
            return true;
        }
        if self.planned_origin != Some(input.grid.config().origin) {
            return true; // the grid grew: the plan's cells are numbered differently now
        }
        if input.grid.world_to_cell(target) != self.planned_goal {
            return true;
        }
        let remaining =
            self.path_remaining_from(&Point2::new(input.pose.x, input.pose.y), input.grid);
        match remaining {
            None => true, // off the path
            Some(start) => self
                .path
                .get(start..)
                .unwrap_or(&[])
                .iter()
                .skip(1)
                .any(|c| input.grid.class(*c) == CellClass::Occupied),
        }
    }

    /// Index of the path cell nearest to `here`, or `None` if the robot is off the path.
    fn path_remaining_from(&self, here: &Point2, grid: &OccupancyGrid) -> Option<usize> {
        let (idx, d) = self
            .path
            .iter()
            .enumerate()
            .map(|(i, c)| (i, grid.cell_centre(*c).distance(here)))
            .fold((None, f64::INFINITY), |(bi, bd), (i, d)| {
                if d < bd {
                    (Some(i), d)
                } else {
                    (bi, bd)
                }
            });
        idx.filter(|_| d <= self.config.off_path_distance_m)
    }

    fn replan(&mut self, input: &NavigatorInput<'_>, target: &Point2) -> bool {
        self.last_plan_time = Some(input.time_s);
        self.clear_plan();
        let here = Point2::new(input.pose.x, input.pose.y);
        let (Some(start), Some(goal)) = (
            input.grid.world_to_cell(&here),
            input.grid.world_to_cell(target),
        ) else {
            return false; // outside the map: drive directly
        };
        let map = CostMap::from_grid(input.grid, &self.config.path_costs);
        let heading = Heading4::from_angle(input.pose.theta);
        self.plans += 1;
        if let Some(p) = plan_path(&map, start, goal, Some(heading), &self.config.path_costs) {
            self.waypoints = simplify_path(&p.cells)
                .into_iter()
                .skip(1)
                .map(|c| input.grid.cell_centre(c))
                .collect();
            // Aim at the target itself rather than the centre of its cell.
            if let Some(last) = self.waypoints.last_mut() {
                *last = *target;
            }
            self.path = p.cells;
            self.planned_goal = Some(goal);
            self.planned_origin = Some(input.grid.config().origin);
            self.next_waypoint = 0;
        }
        true
    }

    fn current_waypoint(&mut self, here: &Point2) -> Option<Point2> {
        while let Some(wp) = self.waypoints.get(self.next_waypoint) {
            let is_last = self.next_waypoint + 1 >= self.waypoints.len();
            if !is_last && wp.distance(here) <= self.config.waypoint_tolerance_m {
                self.next_waypoint += 1;
            } else {
                return Some(*wp);
            }
        }
        None
    }
}
