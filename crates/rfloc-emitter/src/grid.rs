//! Log-odds occupancy grid built from 2-D range scans (the seed's section 6.1, 20 cm cells).
//!
//! Each beam is traced with an exact grid traversal (Amanatides–Woo DDA) from the sensor to the
//! end point: every cell crossed before the end gets the "miss" update, the end cell gets the
//! "hit" update if the beam returned a range below its maximum (a max-range reading marks free
//! only). Log-odds are clamped so the map can still change. Export uses the seed's values:
//! 100 occupied, 0 free, −1 unknown.
//!
//! A grid made with `growable = true` has no fixed size: [`OccupancyGrid::ensure_contains`]
//! extends it (in whole chunks of [`GROWTH_CHUNK_CELLS`] cells, keeping every cell boundary
//! where it was) whenever a scan or a goal falls outside, up to `max_cells`. The first extent
//! is only the initial size. Growing towards −x or −y moves the origin and so renumbers the
//! cells; callers holding [`GridCell`]s compare [`OccupancyGridConfig::origin`] to notice.

use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::error::EmitterError;
use crate::Point2;

/// One laser beam: angle in the sensor frame (rad), measured range and the sensor's maximum
/// range (m). A range `>= max_range_m` means "no return".
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScanBeam {
    /// Beam angle relative to the sensor heading, radians.
    pub angle_rad: f64,
    /// Measured range, metres.
    pub range_m: f64,
    /// Maximum range of the sensor, metres.
    pub max_range_m: f64,
}

/// Grid geometry and log-odds constants.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGridConfig {
    /// Cell edge, metres (seed: 0.20).
    pub resolution_m: f64,
    /// Number of columns (x).
    pub width: usize,
    /// Number of rows (y).
    pub height: usize,
    /// World coordinates of the lower-left corner of cell (0, 0).
    pub origin: Point2,
    /// Log-odds added at a hit (0.85 ≈ p 0.7).
    pub log_odds_hit: f32,
    /// Log-odds added along a beam (−0.4 ≈ p 0.4).
    pub log_odds_miss: f32,
    /// Lower clamp of the log-odds (−2).
    pub log_odds_min: f32,
    /// Upper clamp of the log-odds (3.5).
    pub log_odds_max: f32,
    /// Export as occupied (100) at or above this log-odds (0.5).
    pub occupied_threshold: f32,
    /// Export as free (0) at or below this log-odds (−0.3); between the two: unknown (−1).
    pub free_threshold: f32,
    /// The grid may grow beyond `width × height` (see [`OccupancyGrid::ensure_contains`]).
    #[serde(default)]
    pub growable: bool,
    /// Largest number of cells a growable grid may reach.
    #[serde(default = "default_max_cells")]
    pub max_cells: usize,
}

/// Cells added at a time when a growable grid grows (a multiple of this per side).
pub const GROWTH_CHUNK_CELLS: usize = 32;

fn default_max_cells() -> usize {
    4_000_000
}

impl Default for OccupancyGridConfig {
    /// 20 m × 20 m of 20 cm cells centred on the world origin.
    fn default() -> Self {
        Self {
            resolution_m: 0.2,
            width: 100,
            height: 100,
            origin: Point2::new(-10.0, -10.0),
            log_odds_hit: 0.85,
            log_odds_miss: -0.4,
            log_odds_min: -2.0,
            log_odds_max: 3.5,
            occupied_threshold: 0.5,
            free_threshold: -0.3,
            growable: false,
            max_cells: default_max_cells(),
        }
    }
}

/// A cell index: column `ix` (x) and row `iy` (y).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct GridCell {
    /// Column.
    pub ix: usize,
    /// Row.
    pub iy: usize,
}

impl GridCell {
    /// A cell from its column and row.
    #[must_use]
    pub fn new(ix: usize, iy: usize) -> Self {
        Self { ix, iy }
    }
}

/// Three-way classification of a cell, as the seed's map exports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CellClass {
    /// Exported as 100.
    Occupied,
    /// Exported as 0.
    Free,
    /// Exported as −1.
    Unknown,
}

impl CellClass {
    /// The seed's export value: 100, 0 or −1.
    #[must_use]
    pub fn export_value(self) -> i8 {
        match self {
            CellClass::Occupied => 100,
            CellClass::Free => 0,
            CellClass::Unknown => -1,
        }
    }
}

/// What one scan did to the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ScanIntegration {
    /// Beams traced.
    pub beams_used: usize,
    /// Beams rejected (non-finite, negative range or max range).
    pub beams_skipped: usize,
    /// Beams whose end marked a cell occupied.
    pub hits: usize,
}

/// The occupancy grid: row-major log-odds, 0 = unknown.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    config: OccupancyGridConfig,
    log_odds: Vec<f32>,
}

impl OccupancyGrid {
    /// An all-unknown grid.
    ///
    /// # Errors
    /// [`EmitterError::InvalidConfig`] for a non-positive resolution, an empty or huge grid, a
    /// non-finite origin or inconsistent log-odds constants.
    pub fn new(config: OccupancyGridConfig) -> Result<Self, EmitterError> {
        if !(config.resolution_m > 0.0 && config.resolution_m.is_finite()) {
            return Err(EmitterError::InvalidConfig(
                "resolution must be finite and > 0",
            ));
        }
        let cells = config
            .width
            .checked_mul(config.height)
            .filter(|&c| c > 0 && c <= 64_000_000)
            .ok_or(EmitterError::InvalidConfig("grid must have 1..=64e6 cells"))?;
        if config.growable && !(config.max_cells >= cells && config.max_cells <= 64_000_000) {
            return Err(EmitterError::InvalidConfig(
                "max_cells must be at least the initial cells and at most 64e6",
            ));
        }
        if !config.origin.is_finite() {
            return Err(EmitterError::InvalidConfig("grid origin must be finite"));
        }
        if !(config.log_odds_min <= 0.0
            && config.log_odds_max >= 0.0
            && config.free_threshold < config.occupied_threshold)
        {
            return Err(EmitterError::InvalidConfig(
                "inconsistent log-odds constants",
            ));
        }
        Ok(Self {
            config,
            log_odds: vec![0.0; cells],
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &OccupancyGridConfig {
        &self.config
    }

    /// Columns.
    #[must_use]
    pub fn width(&self) -> usize {
        self.config.width
    }

    /// World coordinates of the upper-right corner of the grid.
    #[must_use]
    pub fn upper_corner(&self) -> Point2 {
        let r = self.config.resolution_m;
        Point2::new(
            self.config.origin.x + self.config.width as f64 * r,
            self.config.origin.y + self.config.height as f64 * r,
        )
    }

    /// True when the box `[lo, hi]` lies inside the grid.
    #[must_use]
    pub fn contains_box(&self, lo: &Point2, hi: &Point2) -> bool {
        let up = self.upper_corner();
        lo.x >= self.config.origin.x && lo.y >= self.config.origin.y && hi.x < up.x && hi.y < up.y
    }

    /// Grows a growable grid so that the box `[lo, hi]` lies inside it. New cells are unknown;
    /// each side grows by whole chunks of [`GROWTH_CHUNK_CELLS`] cells and every existing cell
    /// keeps its place in the world (the origin moves by whole cells). Returns the number of
    /// columns and rows added on the low side (by which existing cell indices moved), or
    /// `None` when nothing changed: the box was inside already, the grid is not growable, the
    /// box is not finite, or the grown grid would exceed `max_cells` (the grid is then left
    /// as it was).
    pub fn ensure_contains(&mut self, lo: &Point2, hi: &Point2) -> Option<(usize, usize)> {
        if !self.config.growable || !lo.is_finite() || !hi.is_finite() {
            return None;
        }
        if self.contains_box(lo, hi) {
            return None;
        }
        let r = self.config.resolution_m;
        let (ox, oy) = (self.config.origin.x, self.config.origin.y);
        let chunk = GROWTH_CHUNK_CELLS as f64;
        // Whole chunks needed on each side, as cell counts.
        let need = |outside_m: f64| -> Option<usize> {
            if outside_m <= 0.0 {
                return Some(0);
            }
            let cells = (outside_m / r).floor() + 1.0;
            let chunks = (cells / chunk).ceil();
            (chunks * chunk < 1e9).then_some((chunks * chunk) as usize)
        };
        let up = self.upper_corner();
        let add_left = need(ox - lo.x)?;
        let add_down = need(oy - lo.y)?;
        let add_right = need(hi.x - up.x + r * 1e-9)?;
        let add_up = need(hi.y - up.y + r * 1e-9)?;
        let width = self
            .config
            .width
            .checked_add(add_left)?
            .checked_add(add_right)?;
        let height = self
            .config
            .height
            .checked_add(add_down)?
            .checked_add(add_up)?;
        let cells = width.checked_mul(height)?;
        if cells > self.config.max_cells {
            tracing::debug!(
                width,
                height,
                max_cells = self.config.max_cells,
                "occupancy grid: growth refused (max_cells)"
            );
            return None;
        }
        let mut log_odds = vec![0.0f32; cells];
        for iy in 0..self.config.height {
            let from = iy * self.config.width;
            let to = (iy + add_down) * width + add_left;
            if let (Some(src), Some(dst)) = (
                self.log_odds.get(from..from + self.config.width),
                log_odds.get_mut(to..to + self.config.width),
            ) {
                dst.copy_from_slice(src);
            }
        }
        self.log_odds = log_odds;
        self.config.width = width;
        self.config.height = height;
        self.config.origin = Point2::new(ox - add_left as f64 * r, oy - add_down as f64 * r);
        Some((add_left, add_down))
    }

    /// Rows.
    #[must_use]
    pub fn height(&self) -> usize {
        self.config.height
    }

    /// Cell edge, metres.
    #[must_use]
    pub fn resolution(&self) -> f64 {
        self.config.resolution_m
    }

    /// The cell containing a world point, or `None` outside the grid.
    #[must_use]
    pub fn world_to_cell(&self, p: &Point2) -> Option<GridCell> {
        let fx = (p.x - self.config.origin.x) / self.config.resolution_m;
        let fy = (p.y - self.config.origin.y) / self.config.resolution_m;
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (ix, iy) = (fx.floor(), fy.floor());
        if ix < self.config.width as f64 && iy < self.config.height as f64 {
            Some(GridCell::new(ix as usize, iy as usize))
        } else {
            None
        }
    }

    /// The world coordinates of a cell centre.
    #[must_use]
    pub fn cell_centre(&self, c: GridCell) -> Point2 {
        let r = self.config.resolution_m;
        Point2::new(
            self.config.origin.x + (c.ix as f64 + 0.5) * r,
            self.config.origin.y + (c.iy as f64 + 0.5) * r,
        )
    }

    fn index(&self, c: GridCell) -> Option<usize> {
        (c.ix < self.config.width && c.iy < self.config.height)
            .then_some(c.iy * self.config.width + c.ix)
    }

    /// Log-odds of a cell, `None` outside the grid.
    #[must_use]
    pub fn log_odds(&self, c: GridCell) -> Option<f32> {
        self.index(c).and_then(|i| self.log_odds.get(i).copied())
    }

    /// Occupied / free / unknown by the export thresholds; outside the grid is unknown.
    #[must_use]
    pub fn class(&self, c: GridCell) -> CellClass {
        match self.log_odds(c) {
            Some(l) if l >= self.config.occupied_threshold => CellClass::Occupied,
            Some(l) if l <= self.config.free_threshold => CellClass::Free,
            _ => CellClass::Unknown,
        }
    }

    /// Adds `delta` log-odds to a cell with clamping; ignored outside the grid.
    pub fn update_cell(&mut self, c: GridCell, delta: f32) {
        let (lo, hi) = (self.config.log_odds_min, self.config.log_odds_max);
        if let Some(slot) = self.index(c).and_then(|i| self.log_odds.get_mut(i)) {
            *slot = (*slot + delta).clamp(lo, hi);
        }
    }

    /// Marks a cell as certainly occupied (e.g. from a bumper contact).
    pub fn mark_occupied(&mut self, c: GridCell) {
        let hi = self.config.log_odds_max;
        if let Some(slot) = self.index(c).and_then(|i| self.log_odds.get_mut(i)) {
            *slot = hi;
        }
    }

    /// Sets a cell's log-odds (clamped); ignored outside the grid.
    pub fn set_log_odds(&mut self, c: GridCell, value: f32) {
        let (lo, hi) = (self.config.log_odds_min, self.config.log_odds_max);
        if let Some(slot) = self.index(c).and_then(|i| self.log_odds.get_mut(i)) {
            *slot = value.clamp(lo, hi);
        }
    }

    /// Marks a cell as certainly free.
    pub fn mark_free(&mut self, c: GridCell) {
        let lo = self.config.log_odds_min;
        if let Some(slot) = self.index(c).and_then(|i| self.log_odds.get_mut(i)) {
            *slot = lo;
        }
    }

    /// The whole grid in the seed's export values (100 / 0 / −1), row-major from row 0.
    #[must_use]
    pub fn export(&self) -> Vec<i8> {
        (0..self.config.height)
            .flat_map(|iy| (0..self.config.width).map(move |ix| GridCell::new(ix, iy)))
            .map(|c| self.class(c).export_value())
            .collect()
    }

    /// Integrates one scan taken from `sensor` (the sensor's pose in the world frame).
    pub fn integrate_scan(&mut self, sensor: &Pose2, beams: &[ScanBeam]) -> ScanIntegration {
        let mut out = ScanIntegration::default();
        if !sensor.is_finite() {
            out.beams_skipped = beams.len();
            tracing::warn!(
                ?sensor,
                beams = beams.len(),
                "occupancy grid: non-finite sensor pose, scan dropped"
            );
            return out;
        }
        let start = Point2::new(sensor.x, sensor.y);
        for b in beams {
            let valid = b.angle_rad.is_finite()
                && b.range_m.is_finite()
                && b.max_range_m.is_finite()
                && b.range_m >= 0.0
                && b.max_range_m > 0.0;
            if !valid {
                out.beams_skipped += 1;
                continue;
            }
            let hit = b.range_m < b.max_range_m;
            let length = b.range_m.min(b.max_range_m);
            let a = sensor.theta + b.angle_rad;
            let end = Point2::new(start.x + length * a.cos(), start.y + length * a.sin());
            let cells = self.trace(&start, &end);
            let end_cell = self.world_to_cell(&end);
            for c in &cells {
                if hit && Some(*c) == end_cell {
                    continue;
                }
                self.update_cell(*c, self.config.log_odds_miss);
            }
            if hit {
                if let Some(c) = end_cell {
                    self.update_cell(c, self.config.log_odds_hit);
                    out.hits += 1;
                }
            }
            out.beams_used += 1;
        }
        if out.beams_skipped > 0 {
            tracing::warn!(
                skipped = out.beams_skipped,
                used = out.beams_used,
                "occupancy grid: scan beams rejected (non-finite or negative values)"
            );
        }
        out
    }

    /// The cells a segment crosses, in order, from the cell of `a` to the cell of `b`, clipped
    /// to the grid (the trace stops when it leaves the grid; a start outside gives nothing).
    #[must_use]
    pub fn trace(&self, a: &Point2, b: &Point2) -> Vec<GridCell> {
        let mut out = Vec::new();
        let Some(mut cell) = self.world_to_cell(a) else {
            return out;
        };
        let r = self.config.resolution_m;
        let (ox, oy) = (self.config.origin.x, self.config.origin.y);
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let len = dx.hypot(dy);
        let last = self.world_to_cell(b);
        out.push(cell);
        if len.is_nan() || len <= 0.0 {
            return out;
        }
        let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
        let step_y: i64 = if dy > 0.0 { 1 } else { -1 };
        // Parametric distance (in units of the segment, t ∈ [0, 1]) to the next x/y boundary.
        let next_boundary = |pos: f64, origin: f64, idx: usize, step: i64| -> f64 {
            let edge = if step > 0 {
                idx as f64 + 1.0
            } else {
                idx as f64
            };
            origin + edge * r - pos
        };
        let mut t_max_x = if dx != 0.0 {
            next_boundary(a.x, ox, cell.ix, step_x) / dx
        } else {
            f64::INFINITY
        };
        let mut t_max_y = if dy != 0.0 {
            next_boundary(a.y, oy, cell.iy, step_y) / dy
        } else {
            f64::INFINITY
        };
        let t_delta_x = if dx != 0.0 {
            r / dx.abs()
        } else {
            f64::INFINITY
        };
        let t_delta_y = if dy != 0.0 {
            r / dy.abs()
        } else {
            f64::INFINITY
        };
        // A segment crosses at most |Δix| + |Δiy| boundaries; bound the loop accordingly.
        let max_steps = ((dx.abs() + dy.abs()) / r).ceil() as usize + 2;
        for _ in 0..max_steps {
            if Some(cell) == last {
                break;
            }
            let (nx, ny);
            if t_max_x < t_max_y {
                if t_max_x > 1.0 {
                    break;
                }
                nx = cell.ix as i64 + step_x;
                ny = cell.iy as i64;
                t_max_x += t_delta_x;
            } else {
                if t_max_y > 1.0 {
                    break;
                }
                nx = cell.ix as i64;
                ny = cell.iy as i64 + step_y;
                t_max_y += t_delta_y;
            }
            if nx < 0
                || ny < 0
                || nx as usize >= self.config.width
                || ny as usize >= self.config.height
            {
                break;
            }
            cell = GridCell::new(nx as usize, ny as usize);
            out.push(cell);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> OccupancyGrid {
        OccupancyGrid::new(OccupancyGridConfig {
            width: 10,
            height: 10,
            origin: Point2::new(0.0, 0.0),
            ..OccupancyGridConfig::default()
        })
        .unwrap()
    }

    #[test]
    fn world_cell_round_trip_for_every_cell() {
        let g = small();
        for iy in 0..g.height() {
            for ix in 0..g.width() {
                let c = GridCell::new(ix, iy);
                assert_eq!(g.world_to_cell(&g.cell_centre(c)), Some(c));
            }
        }
        assert_eq!(g.world_to_cell(&Point2::new(-0.01, 0.5)), None);
        assert_eq!(g.world_to_cell(&Point2::new(0.5, 2.0)), None);
        assert_eq!(g.world_to_cell(&Point2::new(f64::NAN, 0.5)), None);
    }

    #[test]
    fn trace_is_4_connected_and_ends_at_target() {
        let g = small();
        let cells = g.trace(&Point2::new(0.1, 0.1), &Point2::new(1.75, 1.05));
        assert_eq!(cells.first(), Some(&GridCell::new(0, 0)));
        assert_eq!(cells.last(), Some(&GridCell::new(8, 5)));
        for w in cells.windows(2) {
            let d = w[0].ix.abs_diff(w[1].ix) + w[0].iy.abs_diff(w[1].iy);
            assert_eq!(d, 1, "{cells:?}");
        }
        // 8 steps in x and 5 in y.
        assert_eq!(cells.len(), 14);
    }

    #[test]
    fn unknown_grid_exports_minus_one() {
        let g = small();
        assert!(g.export().iter().all(|&v| v == -1));
    }

    #[test]
    fn bad_config_is_rejected() {
        let bad = OccupancyGridConfig {
            width: 0,
            ..OccupancyGridConfig::default()
        };
        assert!(OccupancyGrid::new(bad).is_err());
        let bad = OccupancyGridConfig {
            resolution_m: f64::NAN,
            ..OccupancyGridConfig::default()
        };
        assert!(OccupancyGrid::new(bad).is_err());
    }
}
