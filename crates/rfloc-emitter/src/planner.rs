//! A* over the occupancy grid with the seed's costs (section 6.2).
//!
//! - Base cost of a cell: occupied 100, free 1, unknown 2.
//! - Cost of *entering* a cell: the base cost of the cell plus those of its four neighbours
//!   (cells outside the grid count as unknown). A free cell in free space therefore costs 5.
//! - Motion is 4-connected. The search state is (cell, heading); every 90° change of heading
//!   costs `turn_cost` (a 180° reversal costs twice that). The start heading is the robot's
//!   heading rounded to the nearest cardinal direction, or free when not given.
//! - Heuristic: Manhattan distance in cells times the cheapest possible step (5 × the free
//!   cost). Every step costs at least that much and turn costs are non-negative, so the
//!   heuristic is admissible and consistent and the returned path has minimum cost. The seed's
//!   plain Manhattan distance (1 per cell) is also admissible with these costs, only weaker.
//!
//! Occupied cells stay traversable at a high cost, as in the seed; with 100 per occupied cell a
//! gap narrower than three cells between obstacles costs at least 200 per step, which in
//! practice blocks it.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use serde::{Deserialize, Serialize};

use crate::grid::{CellClass, GridCell, OccupancyGrid};

/// Cell and turn costs (integers, so path costs compare exactly).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PathCosts {
    /// Base cost of an occupied cell (seed: 100).
    pub occupied: u32,
    /// Base cost of a free cell (seed: 1).
    pub free: u32,
    /// Base cost of an unknown cell (seed: 2).
    pub unknown: u32,
    /// Cost of one 90° change of direction (not given in the seed; default 10, i.e. two free
    /// cells in open space).
    pub turn: u32,
}

impl Default for PathCosts {
    fn default() -> Self {
        Self {
            occupied: 100,
            free: 1,
            unknown: 2,
            turn: 10,
        }
    }
}

impl PathCosts {
    /// Base cost of a cell class.
    #[must_use]
    pub fn base(&self, class: CellClass) -> u32 {
        match class {
            CellClass::Occupied => self.occupied,
            CellClass::Free => self.free,
            CellClass::Unknown => self.unknown,
        }
    }

    /// The smallest possible cost of entering a cell (five cells at the smallest base cost).
    #[must_use]
    pub fn min_step(&self) -> u32 {
        5 * self.free.min(self.unknown).min(self.occupied)
    }
}

/// One of the four grid directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Heading4 {
    /// +x.
    East,
    /// +y.
    North,
    /// −x.
    West,
    /// −y.
    South,
}

impl Heading4 {
    const ALL: [Heading4; 4] = [
        Heading4::East,
        Heading4::North,
        Heading4::West,
        Heading4::South,
    ];

    /// The cardinal direction nearest to an angle (radians).
    #[must_use]
    pub fn from_angle(theta: f64) -> Self {
        let q = (rfloc_pose::wrap_angle(theta) / std::f64::consts::FRAC_PI_2).round() as i64;
        match q.rem_euclid(4) {
            0 => Heading4::East,
            1 => Heading4::North,
            2 => Heading4::West,
            _ => Heading4::South,
        }
    }

    fn index(self) -> usize {
        match self {
            Heading4::East => 0,
            Heading4::North => 1,
            Heading4::West => 2,
            Heading4::South => 3,
        }
    }

    /// Number of 90° turns between two headings (0, 1 or 2).
    #[must_use]
    pub fn quarter_turns(self, other: Heading4) -> u32 {
        let d = (self.index() + 4 - other.index()) % 4;
        if d == 3 {
            1
        } else {
            d as u32
        }
    }

    fn delta(self) -> (i64, i64) {
        match self {
            Heading4::East => (1, 0),
            Heading4::North => (0, 1),
            Heading4::West => (-1, 0),
            Heading4::South => (0, -1),
        }
    }
}

/// Entry costs of every cell, precomputed from a grid (base cost summed over the cell and its
/// 4-neighbourhood).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CostMap {
    width: usize,
    height: usize,
    costs: Vec<u32>,
}

impl CostMap {
    /// Builds the cost map of a grid.
    #[must_use]
    pub fn from_grid(grid: &OccupancyGrid, costs: &PathCosts) -> Self {
        let (w, h) = (grid.width(), grid.height());
        let base: Vec<u32> = (0..h)
            .flat_map(|iy| (0..w).map(move |ix| GridCell::new(ix, iy)))
            .map(|c| costs.base(grid.class(c)))
            .collect();
        let at = |ix: i64, iy: i64| -> u32 {
            if ix < 0 || iy < 0 || ix as usize >= w || iy as usize >= h {
                costs.unknown
            } else {
                base.get(iy as usize * w + ix as usize)
                    .copied()
                    .unwrap_or(costs.unknown)
            }
        };
        let mut out = Vec::with_capacity(w * h);
        for iy in 0..h as i64 {
            for ix in 0..w as i64 {
                out.push(
                    at(ix, iy) + at(ix + 1, iy) + at(ix - 1, iy) + at(ix, iy + 1) + at(ix, iy - 1),
                );
            }
        }
        Self {
            width: w,
            height: h,
            costs: out,
        }
    }

    /// Entry cost of a cell, `None` outside.
    #[must_use]
    pub fn cost(&self, c: GridCell) -> Option<u32> {
        if c.ix < self.width && c.iy < self.height {
            self.costs.get(c.iy * self.width + c.ix).copied()
        } else {
            None
        }
    }

    /// Columns.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }
}

/// A planned path: the cells from start to goal (both included) and its total cost.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlannedPath {
    /// Cells from start to goal, 4-connected.
    pub cells: Vec<GridCell>,
    /// Sum of entry costs of every cell after the start plus turn costs.
    pub cost: u64,
    /// Number of states taken off the open list (search effort).
    pub expanded: usize,
}

/// A* from `start` to `goal` over a cost map. `start_heading` makes the first move pay a turn
/// cost if it does not continue that heading; `None` lets the first move go any way for free.
/// Returns `None` when start or goal lie outside the map (a path always exists otherwise, since
/// every cell is traversable at some cost).
#[must_use]
pub fn plan_path(
    map: &CostMap,
    start: GridCell,
    goal: GridCell,
    start_heading: Option<Heading4>,
    costs: &PathCosts,
) -> Option<PlannedPath> {
    map.cost(start)?;
    map.cost(goal)?;
    let (w, h) = (map.width, map.height);
    // State index: cell index * 5 + heading index (4 = "no heading yet", only at the start).
    let state =
        |c: GridCell, hd: Option<Heading4>| (c.iy * w + c.ix) * 5 + hd.map_or(4, Heading4::index);
    // Cost so far and parent state of every state reached. Sparse: a growable map can be
    // large, and a search touches only the states near its path.
    let mut g: HashMap<usize, (u64, usize)> = HashMap::new();
    let min_step = u64::from(costs.min_step());
    let heuristic = |c: GridCell| -> u64 {
        (c.ix.abs_diff(goal.ix) + c.iy.abs_diff(goal.iy)) as u64 * min_step
    };
    let decode = |s: usize| -> (GridCell, Option<Heading4>) {
        let cell_index = s / 5;
        let hd = Heading4::ALL.get(s % 5).copied();
        (GridCell::new(cell_index % w, cell_index / w), hd)
    };
    let s0 = state(start, start_heading);
    g.insert(s0, (0, usize::MAX));
    let mut open = BinaryHeap::new();
    // Ties on f are broken towards larger g (deeper nodes) for fewer expansions.
    open.push(Reverse((heuristic(start), Reverse(0u64), s0)));
    let mut expanded = 0usize;
    while let Some(Reverse((_f, Reverse(gs), s))) = open.pop() {
        if gs > g.get(&s).map_or(u64::MAX, |e| e.0) {
            continue; // stale entry
        }
        expanded += 1;
        let (cell, hd) = decode(s);
        if cell == goal {
            let mut cells = vec![cell];
            let mut cur = s;
            while let Some(&(_, p)) = g.get(&cur) {
                if p == usize::MAX {
                    break;
                }
                cur = p;
                cells.push(decode(cur).0);
            }
            cells.reverse();
            return Some(PlannedPath {
                cells,
                cost: gs,
                expanded,
            });
        }
        for dir in Heading4::ALL {
            let (dx, dy) = dir.delta();
            let nx = cell.ix as i64 + dx;
            let ny = cell.iy as i64 + dy;
            if nx < 0 || ny < 0 || nx as usize >= w || ny as usize >= h {
                continue;
            }
            let next = GridCell::new(nx as usize, ny as usize);
            let Some(step) = map.cost(next) else { continue };
            let turns = hd.map_or(0, |h0| h0.quarter_turns(dir));
            let ng = gs + u64::from(step) + u64::from(turns) * u64::from(costs.turn);
            let ns = state(next, Some(dir));
            if ng < g.get(&ns).map_or(u64::MAX, |e| e.0) {
                g.insert(ns, (ng, s));
                open.push(Reverse((ng + heuristic(next), Reverse(ng), ns)));
            }
        }
    }
    None
}

/// Keeps the start, the goal and every cell where the direction changes: the waypoints a
/// robot that drives straight between turns needs.
#[must_use]
pub fn simplify_path(cells: &[GridCell]) -> Vec<GridCell> {
    let mut out: Vec<GridCell> = Vec::new();
    let dir = |a: GridCell, b: GridCell| (b.ix as i64 - a.ix as i64, b.iy as i64 - a.iy as i64);
    for (i, c) in cells.iter().enumerate() {
        let keep = match (
            i.checked_sub(1).and_then(|j| cells.get(j)),
            cells.get(i + 1),
        ) {
            (Some(prev), Some(next)) => dir(*prev, *c) != dir(*c, *next),
            _ => true,
        };
        if keep {
            out.push(*c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn heading_from_angle_rounds_to_nearest_cardinal() {
        assert_eq!(Heading4::from_angle(0.3), Heading4::East);
        assert_eq!(Heading4::from_angle(FRAC_PI_2 - 0.3), Heading4::North);
        assert_eq!(Heading4::from_angle(3.0), Heading4::West);
        assert_eq!(Heading4::from_angle(-3.0), Heading4::West);
        assert_eq!(Heading4::from_angle(-FRAC_PI_2), Heading4::South);
    }

    #[test]
    fn quarter_turns_are_symmetric() {
        assert_eq!(Heading4::East.quarter_turns(Heading4::East), 0);
        assert_eq!(Heading4::East.quarter_turns(Heading4::North), 1);
        assert_eq!(Heading4::East.quarter_turns(Heading4::South), 1);
        assert_eq!(Heading4::East.quarter_turns(Heading4::West), 2);
        assert_eq!(Heading4::South.quarter_turns(Heading4::East), 1);
    }
}
