//! Loads every scenario in the workspace's `scenarios/` directory and checks the key numbers
//! against the seeds; runs short deterministic simulations built from them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use rfloc_sim::geometry::Point;
use rfloc_sim::metrics::{trajectory_errors, TimedPose, TrialResult};
use rfloc_sim::plot::{trial_svg, TrialPlot};
use rfloc_sim::{Pipeline, Report, RobotSim, Scenario, Summary, World};

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

fn load(name: &str) -> Scenario {
    Scenario::load(&scenarios_dir().join(name)).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn every_scenario_file_loads_and_validates() {
    let mut names = Vec::new();
    let mut fingerprints = Vec::new();
    for entry in std::fs::read_dir(scenarios_dir()).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            let s = Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                Some(s.spec.name.as_str()),
                p.file_stem().and_then(|s| s.to_str()),
                "name must match the file name"
            );
            // The seeds' own files carry their published numbers; nothing else does.
            let key = s
                .published_key()
                .unwrap_or_else(|e| panic!("{}: {e}", s.spec.name));
            if s.spec.name.starts_with("seed") {
                assert_eq!(key, Some(s.spec.name.as_str()), "{}", s.spec.name);
                fingerprints.push(format!("{} {:#018x}", s.spec.name, s.fingerprint()));
            } else {
                assert_eq!(key, None, "{}", s.spec.name);
            }
            names.push(s.spec.name);
        }
    }
    names.sort();
    fingerprints.sort();
    println!("{}", fingerprints.join("\n"));
    let seeds: Vec<&String> = names.iter().filter(|n| n.starts_with("seed")).collect();
    assert_eq!(
        seeds,
        [
            "seed000-sim",
            "seed001-a",
            "seed001-b",
            "seed001-c",
            "seed001-d",
            "seed001-e",
            "seed002-3x3",
            "seed002-large",
            "seed003-case1",
            "seed003-case2"
        ]
    );
    assert!(
        names.iter().any(|n| n.starts_with("facility-")),
        "{names:?}"
    );
    for entry in std::fs::read_dir(scenarios_dir().join("worlds")).unwrap() {
        let p = entry.unwrap().path();
        World::load(&p).unwrap_or_else(|e| panic!("{e}"));
    }
}

/// A copy of a seed's scenario with one setting changed is not the seed's experiment: its
/// report shows no published numbers, and says why.
#[test]
fn a_changed_copy_of_a_seed_file_gets_no_published_numbers() {
    let path = scenarios_dir().join("seed003-case1.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let same = Scenario::from_toml_str(&text.replace("trials = 10", "trials = 2"), &path).unwrap();
    assert_eq!(same.published_key().unwrap(), Some("seed003-case1"));
    let changed = Scenario::from_toml_str(&text.replace("eta = 2.0", "eta = 2.2"), &path).unwrap();
    let why = changed.published_key().unwrap_err();
    assert!(why.contains("not seed003-case1's own experiment"), "{why}");
    let renamed = Scenario::from_toml_str(
        &text.replace("name = \"seed003-case1\"", "name = \"my-copy\""),
        &path,
    )
    .unwrap();
    assert_eq!(renamed.published_key().unwrap(), Some("seed003-case1"));
    let unreferenced = Scenario::from_toml_str(
        &text.replace("seed_reference = \"seed003-case1\"\n", ""),
        &path,
    )
    .unwrap();
    assert_eq!(unreferenced.published_key().unwrap(), None);
}

#[test]
fn seed000_world_has_800_tags_in_5x5() {
    let s = load("seed000-sim.toml");
    assert_eq!(s.spec.pipeline, Pipeline::Snapshot);
    assert_eq!(s.world.uhf_tags.len(), 800);
    assert_eq!((s.world.area_max.x, s.world.area_max.y), (5.0, 5.0));
    assert_eq!(
        (s.spec.trials, s.spec.params.exploration_steps),
        (20, Some(1000))
    );
    // Random starts/goals differ per trial and are reproducible.
    assert_ne!(s.start_pose(0), s.start_pose(1));
    assert_eq!(s.goal(3), load("seed000-sim.toml").goal(3));
}

#[test]
fn seed001_geometry_matches_the_text() {
    for l in ["a", "b", "c", "d", "e"] {
        let s = load(&format!("seed001-{l}.toml"));
        let e = s.world.emitter.unwrap();
        let start = s.start_pose(0);
        let goal = s.goal(0).unwrap();
        assert_eq!(goal, e.position);
        assert_eq!(s.spec.goal.unwrap().tolerance_m, 0.5);
        let straight = s
            .world
            .walls_crossed(&Point::new(start.x, start.y), &e.position);
        match l {
            // A and C: straight line to the emitter is open; B and D: blocked.
            "a" | "c" => assert_eq!(straight, 0, "{l}"),
            "b" | "d" | "e" => assert!(straight >= 1, "{l}"),
            _ => unreachable!(),
        }
        if l != "e" {
            assert!(
                (start.distance(&Pose2::new(e.position.x, e.position.y, 0.0))
                    - if l < "c" { 4.0 } else { 32f64.sqrt() })
                .abs()
                    < 1e-9
            );
        }
    }
    // C: the L-shaped path via (4, 0) is blocked by the corner obstacle.
    let c = load("seed001-c.toml");
    assert!(
        c.world.inside_obstacle(&Point::new(4.0, 0.0))
            && c.world.inside_obstacle(&Point::new(0.0, 4.0))
    );
    // D: the L-shaped path via (4, 0) is open.
    let d = load("seed001-d.toml");
    assert_eq!(
        d.world
            .walls_crossed(&Point::new(0.0, 0.0), &Point::new(4.0, 0.0)),
        0
    );
    assert_eq!(
        d.world
            .walls_crossed(&Point::new(4.0, 0.0), &Point::new(4.0, 4.0)),
        0
    );
}

#[test]
fn seed002_and_seed003_parameters() {
    let s = load("seed002-3x3.toml");
    assert_eq!(s.world.hf_tags.len(), 9);
    let t = s.world.hf_tags.iter().find(|t| t.uid == 0xADC).unwrap();
    assert_eq!((t.position.x, t.position.y), (0.2, 0.1)); // Table 9: ADC at (200, 100) mm
    let headings: Vec<f64> = (0..4)
        .map(|i| s.start_pose(i).theta.to_degrees().round())
        .collect();
    assert_eq!(headings, [0.0, 90.0, 180.0, -90.0]);
    assert_eq!(load("seed002-large.toml").world.hf_tags.len(), 121);

    let c1 = load("seed003-case1.toml");
    let b: Vec<(f64, f64)> = c1
        .world
        .beacons
        .iter()
        .map(|b| (b.position.x, b.position.y))
        .collect();
    assert_eq!(b, [(0.0, 3.5), (6.5, 2.5), (4.0, 7.25), (0.0, 8.0)]);
    assert_eq!(
        c1.spec.waypoints,
        [[2.0, 2.0], [2.0, 7.0], [7.0, 7.0], [7.0, 2.0]]
    );
    assert_eq!(
        (
            c1.xbee_range_bearing().sigma_r,
            c1.xbee_range_bearing().sigma_beta_deg
        ),
        (2.0, 18.0)
    );
    assert_eq!(
        (c1.spec.robot.drive.sigma_v, c1.spec.robot.drive.sigma_omega),
        (0.0119, 0.0012)
    );
    let c2 = load("seed003-case2.toml");
    assert_eq!(c2.spec.waypoints.len(), 6);
    assert_eq!(c2.world.beacons[2].ni, "beacon3");
}

/// Drives the seed 003 case I waypoints with a simple pursuit controller on the true pose and
/// records truth and dead reckoning.
fn run_case1(trial: usize) -> (Vec<TimedPose>, Vec<TimedPose>, Vec<(f64, f64)>) {
    let s = load("seed003-case1.toml");
    let mut robot = RobotSim::new(s.spec.robot.drive, s.start_pose(trial), s.trial_seed(trial));
    let mut rng = ChaCha8Rng::seed_from_u64(s.trial_seed(trial) ^ 0xB0B);
    let noise = s.xbee_range_bearing();
    let (mut truth, mut odo, mut meas) = (Vec::new(), Vec::new(), Vec::new());
    let mut wp = 0usize;
    for k in 0..s.steps() {
        let t = k as f64 * s.spec.dt_s;
        let p = robot.truth();
        let Some(target) = s.spec.waypoints.get(wp) else {
            break;
        };
        let (dx, dy) = (target[0] - p.x, target[1] - p.y);
        if dx.hypot(dy) < s.spec.params.waypoint_switch_m.unwrap() {
            wp += 1;
            continue;
        }
        let err = rfloc_pose::angle_diff(dy.atan2(dx), p.theta);
        robot.step(
            if err.abs() < 0.5 { 0.5 } else { 0.05 },
            (2.0 * err).clamp(-1.0, 1.0),
            s.spec.dt_s,
            &s.world,
        );
        truth.push(TimedPose::new(t, robot.truth()));
        odo.push(TimedPose::new(t, robot.odometry()));
        if k % 10 == 0 {
            meas.push(noise.sample(&robot.truth(), &s.world.beacons[0].position, &mut rng));
        }
    }
    (truth, odo, meas)
}

#[test]
fn same_seed_same_run_and_report() {
    let (t1, o1, m1) = run_case1(0);
    let (t2, o2, m2) = run_case1(0);
    assert_eq!((&t1, &o1, &m1), (&t2, &o2, &m2));
    let (t3, _, m3) = run_case1(1);
    assert_ne!(t1, t3);
    assert_ne!(m1, m3);
    // Visits all four waypoints within the 300 s.
    let s = load("seed003-case1.toml");
    for w in &s.spec.waypoints {
        assert!(
            t1.iter()
                .any(|p| p.pose.distance(&Pose2::new(w[0], w[1], 0.0)) < 0.35),
            "{w:?}"
        );
    }
    // Dead reckoning with Table 3.1 noise drifts, but stays within metres over 300 s.
    let e = trajectory_errors(&t1, &o1).unwrap();
    assert!(e.rmse > 0.0 && e.rmse < 3.0, "{e:?}");
    let summary = Summary::from_trials(&[TrialResult {
        trial: 0,
        seed: 3001,
        errors: Some(e),
        time_to_goal: None,
        success: true,
        extra: vec![],
    }]);
    let table = Report::new("seed003-case1", Some("seed003-case1"), &summary).table();
    assert!(table.contains("| rmse_m |") && table.contains("0.6900"));
    let waypoints: Vec<Point> = s
        .spec
        .waypoints
        .iter()
        .map(|w| Point::new(w[0], w[1]))
        .collect();
    let plot = trial_svg(&TrialPlot {
        title: "case I",
        world: &s.world,
        truth: &t1,
        estimate: &o1,
        stops: &[],
        readings: &[],
        marks: &[],
        waypoints: &waypoints,
        goal: None,
        time_label: "time (s)",
    })
    .unwrap();
    // Both paths, the four beacons (labelled with their names) and the axes with units.
    for b in &s.world.beacons {
        assert!(plot.contains(&b.ni), "{}", b.ni);
    }
    for label in ["x (m)", "y (m)", "true path", "estimated path", "waypoint"] {
        assert!(plot.contains(label), "{label}");
    }
}

/// Every number the scenario files write (outside `[world]`) has a range of its own, so a
/// key added later is not left with only the finiteness check.
#[test]
fn every_number_the_scenarios_write_has_a_range() {
    for entry in std::fs::read_dir(scenarios_dir()).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            let table: toml::Table = toml::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
            for (key, v) in rfloc_sim::keys::numbers(&table) {
                let range = rfloc_sim::keys::range_of(&key)
                    .unwrap_or_else(|| panic!("{}: `{key}` has no range", p.display()));
                assert!(range.contains(v), "{}: {key} = {v}", p.display());
            }
        }
    }
}
