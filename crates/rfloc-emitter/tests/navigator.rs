//! Navigator: unit behaviours (bumpers, avoidance, arrival, replanning) and closed-loop pure
//! simulations of the seed's scenario A (and a blocked variant) with a kinematic robot.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_emitter::{
    differential_range_bearing, Bumpers, CellClass, DirectionalArrayModel, EmitterNavigator,
    EmitterParticleFilter, GridCell, NavigatorConfig, NavigatorInput, NavigatorState,
    OccupancyGrid, OccupancyGridConfig, ParticleFilterConfig, Point2, ScanBeam,
};
use rfloc_pose::Pose2;

fn open_grid() -> OccupancyGrid {
    OccupancyGrid::new(OccupancyGridConfig {
        width: 60,
        height: 40,
        origin: Point2::new(-2.0, -4.0),
        ..OccupancyGridConfig::default()
    })
    .unwrap()
}

fn input<'a>(
    t: f64,
    pose: Pose2,
    target: Option<Point2>,
    grid: &'a OccupancyGrid,
    scan: &'a [ScanBeam],
) -> NavigatorInput<'a> {
    NavigatorInput {
        time_s: t,
        pose,
        target,
        target_sigma_m: None,
        grid,
        scan,
        bumpers: Bumpers::default(),
    }
}

#[test]
fn searching_without_target_and_arrived_near_it() {
    let g = open_grid();
    let mut nav = EmitterNavigator::new(NavigatorConfig::default());
    let c = nav.step(&input(0.0, Pose2::default(), None, &g, &[]));
    assert_eq!(c.state, NavigatorState::Searching);
    assert_eq!(c.v_mps, 0.0);
    let c = nav.step(&input(
        0.1,
        Pose2::default(),
        Some(Point2::new(0.3, 0.3)),
        &g,
        &[],
    ));
    assert_eq!(c.state, NavigatorState::Arrived);
    assert_eq!((c.v_mps, c.omega_rps), (0.0, 0.0));
}

#[test]
fn no_arrival_at_a_vague_estimate() {
    let g = open_grid();
    let mut nav = EmitterNavigator::new(NavigatorConfig {
        arrival_max_sigma_m: 1.0,
        ..NavigatorConfig::default()
    });
    let mut inp = input(0.0, Pose2::default(), Some(Point2::new(0.2, 0.1)), &g, &[]);
    inp.target_sigma_m = Some(4.0);
    let c = nav.step(&inp);
    assert_eq!(
        c.state,
        NavigatorState::Searching,
        "spread 4 m: keep measuring"
    );
    assert_eq!(c.v_mps, 0.0);
    assert!(c.omega_rps != 0.0, "turns on the spot");
    inp.target_sigma_m = Some(f64::NAN);
    assert_eq!(nav.step(&inp).state, NavigatorState::Searching);
    inp.target_sigma_m = Some(0.4);
    assert_eq!(nav.step(&inp).state, NavigatorState::Arrived);
    inp.target_sigma_m = None;
    assert_eq!(nav.step(&inp).state, NavigatorState::Arrived);
}

#[test]
fn bumpers_reverse_or_advance() {
    let g = open_grid();
    let mut nav = EmitterNavigator::new(NavigatorConfig::default());
    let mut inp = input(0.0, Pose2::default(), Some(Point2::new(4.0, 0.0)), &g, &[]);
    inp.bumpers.front = true;
    let c = nav.step(&inp);
    assert_eq!(c.state, NavigatorState::Avoiding);
    assert!(c.v_mps < 0.0);
    inp.bumpers = Bumpers {
        front: false,
        rear: true,
    };
    assert!(nav.step(&inp).v_mps > 0.0);
}

#[test]
fn obstacle_within_20_cm_turns_on_the_spot_towards_free_side() {
    let g = open_grid();
    let mut nav = EmitterNavigator::new(NavigatorConfig::default());
    // Obstacle 15 cm ahead, slightly right; left side open, right side close.
    let scan = [
        ScanBeam {
            angle_rad: -0.1,
            range_m: 0.15,
            max_range_m: 4.0,
        },
        ScanBeam {
            angle_rad: -1.2,
            range_m: 0.3,
            max_range_m: 4.0,
        },
        ScanBeam {
            angle_rad: 1.2,
            range_m: 4.0,
            max_range_m: 4.0,
        },
    ];
    let c = nav.step(&input(
        0.0,
        Pose2::default(),
        Some(Point2::new(4.0, 0.0)),
        &g,
        &scan,
    ));
    assert_eq!(c.state, NavigatorState::Avoiding);
    assert_eq!(c.v_mps, 0.0);
    assert!(c.omega_rps > 0.0, "should turn left, got {}", c.omega_rps);
    // The same obstacle at 25 cm does not trigger avoidance.
    let far = [ScanBeam {
        angle_rad: -0.1,
        range_m: 0.25,
        max_range_m: 4.0,
    }];
    let c = nav.step(&input(
        0.1,
        Pose2::default(),
        Some(Point2::new(4.0, 0.0)),
        &g,
        &far,
    ));
    assert_eq!(c.state, NavigatorState::Driving);
    assert!(c.v_mps > 0.0);
}

#[test]
fn preliminary_system_drives_only_when_within_15_degrees() {
    let g = open_grid();
    let cfg = NavigatorConfig {
        use_planner: false,
        ..NavigatorConfig::default()
    };
    let mut nav = EmitterNavigator::new(cfg);
    let c = nav.step(&input(
        0.0,
        Pose2::default(),
        Some(Point2::new(4.0, 0.9)),
        &g,
        &[],
    ));
    // atan(0.9/4) = 12.7° → full speed with a small left correction.
    assert_eq!(c.v_mps, cfg.drive_speed_mps);
    assert!(c.omega_rps > 0.0);
    // 45° off: turn while creeping forward.
    let c = nav.step(&input(
        0.1,
        Pose2::default(),
        Some(Point2::new(4.0, 4.0)),
        &g,
        &[],
    ));
    assert!(c.v_mps > 0.0 && c.v_mps < cfg.drive_speed_mps);
    // Behind: turn on the spot.
    let c = nav.step(&input(
        0.2,
        Pose2::default(),
        Some(Point2::new(-4.0, 0.5)),
        &g,
        &[],
    ));
    assert_eq!(c.v_mps, 0.0);
    assert!(c.omega_rps.abs() > 0.0);
}

#[test]
fn replans_when_a_new_obstacle_blocks_the_path_and_periodically() {
    let mut g = open_grid();
    let cfg = NavigatorConfig::default();
    let mut nav = EmitterNavigator::new(cfg);
    let pose = Pose2::new(0.1, 0.1, 0.0);
    let target = Some(Point2::new(6.1, 0.1));
    let c = nav.step(&input(0.0, pose, target, &g, &[]));
    assert!(c.replanned);
    let first_path = nav.path().to_vec();
    // Unknown space, straight ahead: a straight path along the robot's row.
    let row = g.world_to_cell(&Point2::new(0.1, 0.1)).unwrap().iy;
    assert!(first_path.iter().all(|c| c.iy == row), "{first_path:?}");
    // No reason to replan 0.1 s later.
    let c = nav.step(&input(0.1, pose, target, &g, &[]));
    assert!(!c.replanned);
    // A wall appears across the path at x ≈ 3 m.
    let wall_ix = g.world_to_cell(&Point2::new(3.0, 0.0)).unwrap().ix;
    for iy in row - 3..=row + 3 {
        g.mark_occupied(GridCell::new(wall_ix, iy));
    }
    let c = nav.step(&input(0.2, pose, target, &g, &[]));
    assert!(c.replanned, "blocked path must trigger a replan");
    assert_ne!(nav.path(), &first_path[..]);
    assert!(nav
        .path()
        .iter()
        .all(|c| g.class(*c) != CellClass::Occupied));
    assert!(
        nav.waypoints().len() >= 3,
        "detour needs corners: {:?}",
        nav.waypoints()
    );
    let plans = nav.plan_count();
    // Periodic replanning after replan_period_s.
    let c = nav.step(&input(0.2 + cfg.replan_period_s, pose, target, &g, &[]));
    assert!(c.replanned);
    assert_eq!(nav.plan_count(), plans + 1);
}

#[test]
fn leaving_the_path_triggers_a_replan() {
    let g = open_grid();
    let mut nav = EmitterNavigator::new(NavigatorConfig::default());
    let target = Some(Point2::new(6.1, 0.1));
    assert!(
        nav.step(&input(0.0, Pose2::new(0.1, 0.1, 0.0), target, &g, &[]))
            .replanned
    );
    // Same target, robot displaced 1 m sideways (e.g. a map jump): replan from the new cell.
    let c = nav.step(&input(0.1, Pose2::new(2.1, 1.1, 0.0), target, &g, &[]));
    assert!(c.replanned);
    let start = g.world_to_cell(&Point2::new(2.1, 1.1)).unwrap();
    assert_eq!(nav.path().first(), Some(&start));
}

// ---------------------------------------------------------------------------------------------
// Closed-loop pure simulation.

/// Axis-aligned box obstacle (min x, min y, max x, max y).
type Box2 = (f64, f64, f64, f64);

fn ray_box(o: Point2, a: f64, b: &Box2) -> Option<f64> {
    let (dx, dy) = (a.cos(), a.sin());
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for (o, d, lo, hi) in [(o.x, dx, b.0, b.2), (o.y, dy, b.1, b.3)] {
        if d.abs() < 1e-12 {
            if o < lo || o > hi {
                return None;
            }
        } else {
            let (mut ta, mut tb) = ((lo - o) / d, (hi - o) / d);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
    }
    (t0 <= t1).then_some(t0)
}

fn simulate_scan(pose: &Pose2, boxes: &[Box2], max_range: f64) -> Vec<ScanBeam> {
    (-30..=30)
        .map(|k| {
            let rel = f64::from(k) * 4f64.to_radians();
            let o = Point2::new(pose.x, pose.y);
            let r = boxes
                .iter()
                .filter_map(|b| ray_box(o, pose.theta + rel, b))
                .fold(max_range, f64::min);
            ScanBeam {
                angle_rad: rel,
                range_m: r,
                max_range_m: max_range,
            }
        })
        .collect()
}

struct Outcome {
    arrived_at_s: Option<f64>,
    final_distance_m: f64,
    collided: bool,
}

/// Kinematic unicycle at 10 Hz, RSS + PF at 2 Hz, scan and grid at 2 Hz.
fn closed_loop(
    emitter: Point2,
    boxes: &[Box2],
    cfg: NavigatorConfig,
    seed: u64,
    limit_s: f64,
) -> Outcome {
    let model = DirectionalArrayModel::default();
    let cal = model.matching_calibration();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pose = Pose2::new(0.0, 0.0, 0.0);
    let mut pf = EmitterParticleFilter::new(ParticleFilterConfig::default(), &pose, seed).unwrap();
    let mut grid = open_grid();
    let mut nav = EmitterNavigator::new(cfg);
    let mut target = None;
    let mut scan = Vec::new();
    let dt = 0.1;
    let mut collided = false;
    for step in 0..(limit_s / dt) as usize {
        let t = step as f64 * dt;
        if step % 5 == 0 {
            let rss = model.sample(&pose, &emitter, &mut rng);
            let rb = differential_range_bearing(&rss, &cal).unwrap();
            target = Some(pf.update(&pose, &rb, 0.5).unwrap().mean);
            scan = simulate_scan(&pose, boxes, 4.0);
            grid.integrate_scan(&pose, &scan);
        }
        let cmd = nav.step(&input(t, pose, target, &grid, &scan));
        if cmd.state == NavigatorState::Arrived {
            let d = Point2::new(pose.x, pose.y).distance(&emitter);
            if d <= 0.5 {
                return Outcome {
                    arrived_at_s: Some(t),
                    final_distance_m: d,
                    collided,
                };
            }
        }
        let th = pose.theta + cmd.omega_rps * dt;
        pose = Pose2::new(
            pose.x + cmd.v_mps * dt * th.cos(),
            pose.y + cmd.v_mps * dt * th.sin(),
            th,
        );
        // The robot is a point here; count entering a box as a collision.
        collided |= boxes
            .iter()
            .any(|b| pose.x > b.0 && pose.x < b.2 && pose.y > b.1 && pose.y < b.3);
    }
    Outcome {
        arrived_at_s: None,
        final_distance_m: Point2::new(pose.x, pose.y).distance(&emitter),
        collided,
    }
}

#[test]
fn scenario_a_straight_4_m_reaches_within_50_cm() {
    let emitter = Point2::new(4.0, 0.0);
    let mut times = Vec::new();
    for seed in 1..=5u64 {
        let full = closed_loop(emitter, &[], NavigatorConfig::default(), seed, 120.0);
        let prelim = closed_loop(
            emitter,
            &[],
            NavigatorConfig {
                use_planner: false,
                ..NavigatorConfig::default()
            },
            seed,
            120.0,
        );
        println!(
            "scenario A seed {seed}: full system {:?} s, preliminary {:?} s (final distances {:.2} / {:.2} m)",
            full.arrived_at_s, prelim.arrived_at_s, full.final_distance_m, prelim.final_distance_m
        );
        assert!(
            full.arrived_at_s.is_some(),
            "full system did not arrive (seed {seed})"
        );
        assert!(
            prelim.arrived_at_s.is_some(),
            "preliminary system did not arrive (seed {seed})"
        );
        assert!(!full.collided && !prelim.collided);
        times.push(full.arrived_at_s.unwrap_or(f64::NAN));
    }
    // 4 m at 0.3 m/s is 13.3 s of pure driving; allow time for turning and filter convergence.
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!("scenario A full system mean time over 5 seeds: {mean:.1} s");
    assert!(mean < 40.0, "{mean}");
}

#[test]
fn scenario_b_blocked_straight_line_full_system() {
    // A 1.2 m wide box between robot and emitter (the seed's scenario B, dimensions assumed).
    let emitter = Point2::new(4.0, 0.0);
    let boxes = [(1.8, -0.6, 2.2, 0.6)];
    let mut arrived = 0;
    for seed in 1..=3u64 {
        let o = closed_loop(emitter, &boxes, NavigatorConfig::default(), seed, 180.0);
        println!(
            "scenario B seed {seed}: full system {:?} s (final distance {:.2} m, collided {})",
            o.arrived_at_s, o.final_distance_m, o.collided
        );
        assert!(!o.collided);
        arrived += usize::from(o.arrived_at_s.is_some());
    }
    assert_eq!(arrived, 3);
}
