//! Occupancy grid ray-casting and A* planning on hand-made grids.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use proptest::prelude::*;
use rfloc_emitter::{
    plan_path, simplify_path, CellClass, CostMap, GridCell, Heading4, OccupancyGrid,
    OccupancyGridConfig, PathCosts, Point2, ScanBeam,
};
use rfloc_pose::Pose2;

fn grid(w: usize, h: usize) -> OccupancyGrid {
    OccupancyGrid::new(OccupancyGridConfig {
        width: w,
        height: h,
        origin: Point2::new(0.0, 0.0),
        ..OccupancyGridConfig::default()
    })
    .unwrap()
}

/// A grid from rows of text, top row first: '#' occupied, '.' free, '?' unknown.
fn from_ascii(rows: &[&str]) -> OccupancyGrid {
    let h = rows.len();
    let w = rows[0].len();
    let mut g = grid(w, h);
    for (r, line) in rows.iter().enumerate() {
        let iy = h - 1 - r;
        for (ix, ch) in line.chars().enumerate() {
            match ch {
                '#' => g.mark_occupied(GridCell::new(ix, iy)),
                '.' => g.mark_free(GridCell::new(ix, iy)),
                _ => {}
            }
        }
    }
    g
}

fn turns(cells: &[GridCell]) -> usize {
    simplify_path(cells).len().saturating_sub(2)
}

/// Recomputes a path's cost from its cells (independent of the planner's bookkeeping).
fn path_cost(map: &CostMap, cells: &[GridCell], start: Option<Heading4>, costs: &PathCosts) -> u64 {
    let mut heading = start;
    let mut total = 0u64;
    for w in cells.windows(2) {
        let d = (
            w[1].ix as i64 - w[0].ix as i64,
            w[1].iy as i64 - w[0].iy as i64,
        );
        let dir = match d {
            (1, 0) => Heading4::East,
            (-1, 0) => Heading4::West,
            (0, 1) => Heading4::North,
            (0, -1) => Heading4::South,
            other => panic!("not 4-connected: {other:?}"),
        };
        if let Some(h) = heading {
            total += u64::from(h.quarter_turns(dir)) * u64::from(costs.turn);
        }
        heading = Some(dir);
        total += u64::from(map.cost(w[1]).unwrap());
    }
    total
}

/// Reference: Dijkstra over (cell, heading) by exhaustive relaxation (Bellman–Ford style).
fn reference_cost(
    map: &CostMap,
    start: GridCell,
    goal: GridCell,
    h0: Option<Heading4>,
    costs: &PathCosts,
) -> u64 {
    let dirs = [
        Heading4::East,
        Heading4::North,
        Heading4::West,
        Heading4::South,
    ];
    let (w, h) = (map.width(), map.height());
    let idx = |c: GridCell, d: usize| (c.iy * w + c.ix) * 5 + d;
    let mut dist = vec![u64::MAX; w * h * 5];
    let d0 = h0.map_or(4, |x| dirs.iter().position(|d| *d == x).unwrap());
    dist[idx(start, d0)] = 0;
    loop {
        let mut changed = false;
        for iy in 0..h {
            for ix in 0..w {
                let c = GridCell::new(ix, iy);
                for hd in 0..5 {
                    let base = dist[idx(c, hd)];
                    if base == u64::MAX {
                        continue;
                    }
                    for (k, dir) in dirs.iter().enumerate() {
                        let (dx, dy) = match dir {
                            Heading4::East => (1i64, 0i64),
                            Heading4::West => (-1, 0),
                            Heading4::North => (0, 1),
                            Heading4::South => (0, -1),
                        };
                        let (nx, ny) = (ix as i64 + dx, iy as i64 + dy);
                        if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                            continue;
                        }
                        let n = GridCell::new(nx as usize, ny as usize);
                        let t = if hd == 4 {
                            0
                        } else {
                            dirs[hd].quarter_turns(*dir)
                        };
                        let nd = base
                            + u64::from(map.cost(n).unwrap())
                            + u64::from(t) * u64::from(costs.turn);
                        if nd < dist[idx(n, k)] {
                            dist[idx(n, k)] = nd;
                            changed = true;
                        }
                    }
                }
            }
        }
        if !changed {
            break;
        }
    }
    (0..5).map(|d| dist[idx(goal, d)]).min().unwrap()
}

#[test]
fn scan_of_a_known_wall() {
    // 2 m × 2 m of 20 cm cells; sensor at (0.3, 1.0) facing +x; wall at x = 1.5 (column 7).
    let mut g = grid(10, 10);
    let sensor = Pose2::new(0.3, 1.0, 0.0);
    let beams: Vec<ScanBeam> = (-20..=20)
        .map(|deg| {
            let a = f64::from(deg).to_radians();
            ScanBeam {
                angle_rad: a,
                range_m: (1.5 - 0.3) / a.cos(),
                max_range_m: 4.0,
            }
        })
        .collect();
    for _ in 0..2 {
        let r = g.integrate_scan(&sensor, &beams);
        assert_eq!(r.beams_used, 41);
        assert_eq!(r.hits, 41);
    }
    // Wall cells hit by beams: y from 1.0 − 1.2·tan 20° = 0.563 to 1.437 → rows 2..=7.
    for iy in 2..=7 {
        assert_eq!(
            g.class(GridCell::new(7, iy)),
            CellClass::Occupied,
            "row {iy}"
        );
    }
    // Straight ahead the cells between sensor and wall are free, behind the wall unknown.
    for ix in 1..=6 {
        assert_eq!(g.class(GridCell::new(ix, 5)), CellClass::Free, "col {ix}");
    }
    for ix in 8..10 {
        assert_eq!(g.class(GridCell::new(ix, 5)), CellClass::Unknown);
    }
    // Behind the sensor nothing was observed.
    assert_eq!(g.class(GridCell::new(0, 9)), CellClass::Unknown);
    let export = g.export();
    assert_eq!(export[5 * 10 + 7], 100);
    assert_eq!(export[5 * 10 + 3], 0);
    assert_eq!(export[5 * 10 + 9], -1);
    assert!(export.iter().all(|v| [100, 0, -1].contains(v)));
}

#[test]
fn max_range_beam_marks_free_only_and_bad_beams_are_counted() {
    let mut g = grid(10, 10);
    let sensor = Pose2::new(0.1, 0.1, 0.0);
    let beams = [
        ScanBeam {
            angle_rad: 0.0,
            range_m: 5.0,
            max_range_m: 1.0,
        },
        ScanBeam {
            angle_rad: f64::NAN,
            range_m: 1.0,
            max_range_m: 4.0,
        },
        ScanBeam {
            angle_rad: 0.0,
            range_m: -1.0,
            max_range_m: 4.0,
        },
    ];
    let r = g.integrate_scan(&sensor, &beams);
    assert_eq!((r.beams_used, r.beams_skipped, r.hits), (1, 2, 0));
    for ix in 0..=5 {
        assert_eq!(g.class(GridCell::new(ix, 0)), CellClass::Free);
    }
    assert_eq!(g.class(GridCell::new(6, 0)), CellClass::Unknown);
}

#[test]
fn log_odds_are_clamped_so_the_map_can_change() {
    let mut g = grid(3, 3);
    let c = GridCell::new(1, 1);
    for _ in 0..100 {
        g.update_cell(c, 0.85);
    }
    assert_eq!(g.log_odds(c), Some(3.5));
    // Ten misses undo a saturated hit: 3.5 − 10·0.4 = −0.5 → free.
    for _ in 0..10 {
        g.update_cell(c, -0.4);
    }
    assert_eq!(g.class(c), CellClass::Free);
}

#[test]
fn straight_path_in_free_space_costs_five_per_cell() {
    let g = from_ascii(&[
        ".........",
        ".........",
        ".........",
        ".........",
        ".........",
    ]);
    let costs = PathCosts::default();
    let map = CostMap::from_grid(&g, &costs);
    let p = plan_path(
        &map,
        GridCell::new(1, 2),
        GridCell::new(7, 2),
        Some(Heading4::East),
        &costs,
    )
    .unwrap();
    assert_eq!(p.cost, 6 * 5);
    assert_eq!(p.cells.len(), 7);
    assert_eq!(turns(&p.cells), 0);
    // Starting the wrong way round costs two quarter turns.
    let q = plan_path(
        &map,
        GridCell::new(1, 2),
        GridCell::new(7, 2),
        Some(Heading4::West),
        &costs,
    )
    .unwrap();
    assert_eq!(q.cost, 6 * 5 + 2 * costs.turn as u64);
}

#[test]
fn detour_around_a_single_obstacle_has_known_cost() {
    // Obstacle at (4, 3); its four neighbours cost 104 to enter, every other interior cell 5.
    // Cheapest: leave row 3, pass along row 5, come back: 10 cells × 5 + 3 turns × 10 = 80
    // (straight through would be 5 + 104 + 104 + 104 + 5 + 5 = 327).
    let g = from_ascii(&[
        ".........",
        ".........",
        ".........",
        "....#....",
        ".........",
        ".........",
        ".........",
    ]);
    let costs = PathCosts::default();
    let map = CostMap::from_grid(&g, &costs);
    assert_eq!(map.cost(GridCell::new(4, 3)), Some(104));
    assert_eq!(map.cost(GridCell::new(3, 3)), Some(104));
    assert_eq!(map.cost(GridCell::new(3, 4)), Some(5));
    let (s, goal) = (GridCell::new(1, 3), GridCell::new(7, 3));
    let p = plan_path(&map, s, goal, Some(Heading4::East), &costs).unwrap();
    assert_eq!(p.cost, 80);
    assert_eq!(path_cost(&map, &p.cells, Some(Heading4::East), &costs), 80);
    assert!(!p.cells.contains(&GridCell::new(4, 3)));
    assert_eq!(p.cells.first(), Some(&s));
    assert_eq!(p.cells.last(), Some(&goal));
    assert_eq!(turns(&p.cells), 3);
}

#[test]
fn unknown_cells_cost_more_than_free() {
    // Two equally long routes; the lower one crosses unknown cells.
    let g = from_ascii(&[
        ".......", ".......", "..###..", "..###..", "..###..", "???????", "???????",
    ]);
    let costs = PathCosts {
        turn: 0,
        ..PathCosts::default()
    };
    let map = CostMap::from_grid(&g, &costs);
    let p = plan_path(&map, GridCell::new(0, 4), GridCell::new(6, 4), None, &costs).unwrap();
    assert!(p.cells.iter().all(|c| c.iy >= 4), "{:?}", p.cells);
}

#[test]
fn turn_cost_changes_the_chosen_path() {
    // Free cells only on a diagonal band |ix − iy| ≤ 1, unknown elsewhere. Inside the band the
    // route is a staircase (cheap cells, a turn at every step); the L-shaped route with a single
    // turn crosses unknown cells (about twice the cell cost).
    let n = 9;
    let mut g = grid(n, n);
    for iy in 0..n {
        for ix in 0..n {
            if ix.abs_diff(iy) <= 1 {
                g.mark_free(GridCell::new(ix, iy));
            }
        }
    }
    let (start, goal) = (GridCell::new(1, 1), GridCell::new(7, 7));
    let no_turn_cost = PathCosts {
        turn: 0,
        ..PathCosts::default()
    };
    let dear_turns = PathCosts {
        turn: 20,
        ..PathCosts::default()
    };
    let map = CostMap::from_grid(&g, &no_turn_cost);
    let p0 = plan_path(&map, start, goal, Some(Heading4::East), &no_turn_cost).unwrap();
    let p1 = plan_path(&map, start, goal, Some(Heading4::East), &dear_turns).unwrap();
    let cell_cost = |p: &[GridCell]| path_cost(&map, p, Some(Heading4::East), &no_turn_cost);
    println!(
        "turn cost 0: {} turns, cell cost {}; turn cost 20: {} turns, cell cost {}, total {}",
        turns(&p0.cells),
        cell_cost(&p0.cells),
        turns(&p1.cells),
        cell_cost(&p1.cells),
        p1.cost
    );
    // Without a turn cost the planner stays in the free band (cheapest cells)...
    assert!(p0.cells.iter().all(|c| c.ix.abs_diff(c.iy) <= 1));
    assert!(turns(&p0.cells) >= 8);
    // ...with it, it accepts dearer cells to save turns.
    assert!(turns(&p1.cells) <= 2, "{:?}", p1.cells);
    assert!(cell_cost(&p1.cells) > cell_cost(&p0.cells));
    assert_eq!(p1.cost, cell_cost(&p1.cells) + 20 * turns(&p1.cells) as u64);
}

#[test]
fn simplify_keeps_only_corners() {
    let cells: Vec<GridCell> = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (3, 2)]
        .iter()
        .map(|&(x, y)| GridCell::new(x, y))
        .collect();
    let w = simplify_path(&cells);
    assert_eq!(
        w,
        vec![
            GridCell::new(0, 0),
            GridCell::new(2, 0),
            GridCell::new(2, 2),
            GridCell::new(3, 2)
        ]
    );
    assert_eq!(simplify_path(&[]), vec![]);
    assert_eq!(simplify_path(&cells[..1]), cells[..1].to_vec());
}

#[test]
fn start_or_goal_outside_gives_none() {
    let g = grid(5, 5);
    let costs = PathCosts::default();
    let map = CostMap::from_grid(&g, &costs);
    assert!(plan_path(&map, GridCell::new(0, 0), GridCell::new(5, 0), None, &costs).is_none());
    assert!(plan_path(&map, GridCell::new(9, 0), GridCell::new(1, 0), None, &costs).is_none());
    let same = plan_path(&map, GridCell::new(2, 2), GridCell::new(2, 2), None, &costs).unwrap();
    assert_eq!((same.cost, same.cells.len()), (0, 1));
}

fn random_grid(w: usize, h: usize, classes: &[u8]) -> OccupancyGrid {
    let mut g = grid(w, h);
    for iy in 0..h {
        for ix in 0..w {
            match classes[(iy * w + ix) % classes.len()] % 4 {
                0 => g.mark_occupied(GridCell::new(ix, iy)),
                1 | 2 => g.mark_free(GridCell::new(ix, iy)),
                _ => {}
            }
        }
    }
    g
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A* returns a valid 4-connected path whose cost equals an exhaustive reference search.
    #[test]
    fn astar_matches_reference_search(
        classes in proptest::collection::vec(0u8..4, 64),
        sx in 0usize..8, sy in 0usize..8, gx in 0usize..8, gy in 0usize..8,
        turn in 0u32..40, h0 in 0usize..5,
    ) {
        let g = random_grid(8, 8, &classes);
        let costs = PathCosts { turn, ..PathCosts::default() };
        let map = CostMap::from_grid(&g, &costs);
        let heading = [Heading4::East, Heading4::North, Heading4::West, Heading4::South].get(h0).copied();
        let (s, goal) = (GridCell::new(sx, sy), GridCell::new(gx, gy));
        let p = plan_path(&map, s, goal, heading, &costs).unwrap();
        prop_assert_eq!(p.cells.first(), Some(&s));
        prop_assert_eq!(p.cells.last(), Some(&goal));
        prop_assert_eq!(path_cost(&map, &p.cells, heading, &costs), p.cost);
        prop_assert_eq!(p.cost, reference_cost(&map, s, goal, heading, &costs));
        // The heuristic never overestimates: cost ≥ Manhattan × 5.
        let manhattan = (sx.abs_diff(gx) + sy.abs_diff(gy)) as u64;
        prop_assert!(p.cost >= manhattan * 5);
    }

    /// Raising the turn cost never increases the number of turns of the optimal path.
    #[test]
    fn higher_turn_cost_never_adds_turns(
        classes in proptest::collection::vec(0u8..4, 100),
        gx in 0usize..10, gy in 0usize..10,
    ) {
        let g = random_grid(10, 10, &classes);
        let lo = PathCosts { turn: 0, ..PathCosts::default() };
        let hi = PathCosts { turn: 50, ..PathCosts::default() };
        let s = GridCell::new(0, 0);
        let goal = GridCell::new(gx, gy);
        let map = CostMap::from_grid(&g, &lo);
        let p_lo = plan_path(&map, s, goal, Some(Heading4::East), &lo).unwrap();
        let p_hi = plan_path(&map, s, goal, Some(Heading4::East), &hi).unwrap();
        let t = |p: &[GridCell]| {
            let mut n = 0u64;
            let mut prev: Option<(i64, i64)> = Some((1, 0));
            for w in p.windows(2) {
                let d = (w[1].ix as i64 - w[0].ix as i64, w[1].iy as i64 - w[0].iy as i64);
                if prev.is_some_and(|q| q != d) { n += 1; }
                prev = Some(d);
            }
            n
        };
        prop_assert!(t(&p_hi.cells) <= t(&p_lo.cells));
    }
}

fn growable(w: usize, h: usize, max_cells: usize) -> OccupancyGrid {
    OccupancyGrid::new(OccupancyGridConfig {
        width: w,
        height: h,
        origin: Point2::new(0.0, 0.0),
        growable: true,
        max_cells,
        ..OccupancyGridConfig::default()
    })
    .unwrap()
}

#[test]
fn a_growable_grid_grows_in_chunks_and_keeps_every_cell_in_place() {
    let mut g = growable(10, 10, 1_000_000);
    let wall = Point2::new(1.1, 0.9);
    let c = g.world_to_cell(&wall).unwrap();
    g.mark_occupied(c);
    // A point 30 m to the south-west: the grid grows on the low sides, the origin moves by
    // whole cells and the marked cell is still where it was in the world.
    let far = Point2::new(-30.0, -12.0);
    let shift = g.ensure_contains(&far, &far).unwrap();
    assert_eq!(shift.0 % 32, 0);
    assert_eq!(shift.1 % 32, 0);
    assert!(g.world_to_cell(&far).is_some());
    let moved = g.world_to_cell(&wall).unwrap();
    assert_eq!(moved, GridCell::new(c.ix + shift.0, c.iy + shift.1));
    assert_eq!(g.class(moved), CellClass::Occupied);
    let o = g.config().origin;
    let r = g.resolution();
    assert!(((o.x / r) - (o.x / r).round()).abs() < 1e-9, "{o:?}");
    // Already inside: nothing changes.
    let before = g.width() * g.height();
    assert_eq!(g.ensure_contains(&wall, &far), None);
    assert_eq!(g.width() * g.height(), before);
    // Growth on the high side leaves the indices alone.
    let east = Point2::new(45.0, 1.0);
    assert_eq!(g.ensure_contains(&east, &east), Some((0, 0)));
    assert_eq!(g.world_to_cell(&wall), Some(moved));
    assert!(g.world_to_cell(&east).is_some());
}

#[test]
fn growth_stops_at_max_cells_and_a_fixed_grid_never_grows() {
    let mut g = growable(10, 10, 64 * 64);
    let far = Point2::new(500.0, 500.0);
    assert_eq!(g.ensure_contains(&far, &far), None, "beyond max_cells");
    assert_eq!((g.width(), g.height()), (10, 10));
    let mut fixed = grid(10, 10);
    assert_eq!(fixed.ensure_contains(&far, &far), None);
    assert_eq!((fixed.width(), fixed.height()), (10, 10));
    assert!(OccupancyGrid::new(OccupancyGridConfig {
        growable: true,
        max_cells: 50,
        ..OccupancyGridConfig::default()
    })
    .is_err());
}

#[test]
fn scans_far_from_the_start_land_in_a_grown_grid_and_plan() {
    let mut g = growable(60, 60, 4_000_000);
    let sensor = Pose2::new(40.0, 3.0, 0.0);
    let beams = [ScanBeam {
        angle_rad: 0.0,
        range_m: 2.0,
        max_range_m: 5.6,
    }];
    // A scan outside the grid is clipped unless the grid grows first.
    assert_eq!(g.integrate_scan(&sensor, &beams).hits, 0);
    g.ensure_contains(&Point2::new(39.0, 2.0), &Point2::new(43.0, 4.0))
        .unwrap();
    assert_eq!(g.integrate_scan(&sensor, &beams).hits, 1);
    let hit = g.world_to_cell(&Point2::new(42.0, 3.0)).unwrap();
    assert_eq!(g.class(hit), CellClass::Occupied);
    // A* from the start to the far end across the grown grid.
    let costs = PathCosts::default();
    let map = CostMap::from_grid(&g, &costs);
    let start = g.world_to_cell(&Point2::new(1.0, 1.0)).unwrap();
    let goal = g.world_to_cell(&Point2::new(41.0, 3.0)).unwrap();
    let p = plan_path(&map, start, goal, None, &costs).unwrap();
    assert_eq!(p.cells.first(), Some(&start));
    assert_eq!(p.cells.last(), Some(&goal));
}
