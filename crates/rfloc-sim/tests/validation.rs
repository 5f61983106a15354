//! Scenario validation: every key written acts in the pipeline's trial or is rejected, and
//! inconsistent worlds and goals are rejected on load, each error naming file, line and key.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;

use rfloc_sim::{Scenario, SimError};

const EKF: &str = r#"name = "t"
pipeline = "ekf-slam"
duration_s = 10.0
dt_s = 0.1
trials = 1
seed = 5
waypoints = [[2.0, 2.0], [2.0, 7.0]]

[robot]
start = { x = 1.0, y = 1.0 }
drive = { sigma_v = 0.0119, axle_track = 0.331 }

[params]
sweep_steps = 40

[world]
area = { min = [0.0, 0.0], max = [9.0, 9.0] }
xbee_beacons = [
  { x = 0.0, y = 3.5, address = "0013A20040000001", ni = "beacon1" },
  { x = 6.0, y = 3.5, address = "0013A20040000002", ni = "beacon2" },
]
"#;

const EMITTER: &str = r#"name = "e"
pipeline = "emitter-full"
duration_s = 10.0
dt_s = 0.1
trials = 1
seed = 5

[robot]
start = { x = 0.0, y = 0.0 }

[goal]
x = 4.0
y = 0.0
tolerance_m = 0.5

[world]
area = { min = [-1.0, -2.0], max = [6.0, 2.0] }
emitter = { x = 4.0, y = 0.0 }
obstacles = [{ points = [[2.0, 1.0], [3.0, 1.0], [3.0, 1.8], [2.0, 1.8]] }]
"#;

fn load(text: &str) -> Result<Scenario, SimError> {
    Scenario::from_toml_str(text, Path::new("s.toml"))
}

/// The error's line and key (panics on anything but an `Invalid`).
fn invalid(text: &str) -> (usize, String, String) {
    match load(text) {
        Err(SimError::Invalid {
            line, key, message, ..
        }) => (line, key, message),
        other => panic!("expected an invalid key, got {other:?}"),
    }
}

#[test]
fn the_examples_load() {
    load(EKF).unwrap();
    load(EMITTER).unwrap();
}

#[test]
fn keys_the_trial_does_not_use_are_rejected_with_their_line() {
    let (line, key, msg) =
        invalid(&EKF.replace("sweep_steps = 40", "sweep_steps = 40\niterations = 1000"));
    assert_eq!((line, key.as_str()), (15, "params.iterations"), "{msg}");
    assert!(msg.contains("iteration count"), "{msg}");
    let (line, key, _) =
        invalid(&EKF.replace("axle_track = 0.331", "axle_track = 0.331, slip_mean = 0.1"));
    assert_eq!((line, key.as_str()), (11, "robot.drive.slip_mean"));
    let (_, key, msg) = invalid(&EKF.replace(
        "[params]",
        "[sensors]\nxbee_range_bearing = { sigma_r = 2.0 }\n\n[params]",
    ));
    assert_eq!(key, "sensors.xbee_range_bearing.sigma_r", "{msg}");
    // σ_v acts in the ekf-slam trial, not in the emitter trial.
    let (line, key, _) = invalid(&EMITTER.replace(
        "start = { x = 0.0, y = 0.0 }",
        "start = { x = 0.0, y = 0.0 }\ndrive = { sigma_v = 0.05 }",
    ));
    assert_eq!((line, key.as_str()), (10, "robot.drive.sigma_v"));
    // The emitter trial's laser is the URG emulator: the beam count does not act.
    let (_, key, msg) =
        invalid(&EMITTER.replace("[goal]", "[sensors]\nscanner = { beams = 100 }\n\n[goal]"));
    assert_eq!(key, "sensors.scanner.beams", "{msg}");
    assert!(msg.contains("URG"), "{msg}");
}

#[test]
fn inconsistent_worlds_and_goals_are_rejected() {
    // Two beacons with one address: the line of the second.
    let dup = EKF.replace("0013A20040000002", "0013A20040000001");
    let (line, key, msg) = invalid(&dup);
    assert_eq!((line, key.as_str()), (20, "xbee_beacons.address"), "{msg}");
    assert!(msg.contains("earlier beacon"), "{msg}");
    // A beacon outside the area.
    let (line, key, msg) = invalid(&EKF.replace("x = 6.0, y = 3.5", "x = 16.0, y = 3.5"));
    assert_eq!((line, key.as_str()), (20, "xbee_beacons.address"), "{msg}");
    assert!(msg.contains("outside the area"), "{msg}");
    // The emitter outside the area, or inside an obstacle.
    let (_, key, msg) = invalid(&EMITTER.replace("emitter = { x = 4.0", "emitter = { x = 14.0"));
    assert_eq!(key, "emitter", "{msg}");
    let inside = EMITTER
        .replace(
            "emitter = { x = 4.0, y = 0.0 }",
            "emitter = { x = 2.5, y = 1.5 }",
        )
        .replace("x = 4.0\ny = 0.0", "x = 2.5\ny = 1.5");
    let (_, key, msg) = invalid(&inside);
    assert_eq!(key, "emitter", "{msg}");
    assert!(msg.contains("inside an obstacle"), "{msg}");
    // A goal inside an obstacle.
    let (line, key, msg) = invalid(&EMITTER.replace("x = 4.0\ny = 0.0", "x = 2.5\ny = 1.5"));
    assert_eq!((line, key.as_str()), (11, "goal"), "{msg}");
    // A missing goal.
    let no_goal = EMITTER.replace("[goal]\nx = 4.0\ny = 0.0\ntolerance_m = 0.5\n", "");
    let (_, key, msg) = invalid(&no_goal);
    assert_eq!(key, "goal", "{msg}");
    assert!(msg.contains("needs a [goal]"), "{msg}");
    // A waypoint outside the area.
    let (line, key, _) = invalid(&EKF.replace("[2.0, 7.0]]", "[2.0, 17.0]]"));
    assert_eq!((line, key.as_str()), (7, "waypoints"));
    // A mismatch scale out of range.
    let (_, key, _) = invalid(&EKF.replace("[params]", "[mismatch]\nscale = 0.0\n\n[params]"));
    assert_eq!(key, "mismatch.scale");
    // A seed reference without published numbers.
    let (line, key, _) =
        invalid(&EKF.replace("name = \"t\"", "name = \"t\"\nseed_reference = \"seed009\""));
    assert_eq!((line, key.as_str()), (2, "seed_reference"));
}

/// Every number outside its range (a NaN, an infinity, a negative noise, an absurd count) is
/// rejected on load with the line of its own key, not only the first line with that name.
#[test]
fn numbers_out_of_range_are_rejected_at_their_own_line() {
    let cases = [
        (
            EKF,
            "sigma_v = 0.0119",
            "sigma_v = -1.0",
            11,
            "robot.drive.sigma_v",
        ),
        (
            EKF,
            "sigma_v = 0.0119",
            "sigma_v = nan",
            11,
            "robot.drive.sigma_v",
        ),
        (
            EKF,
            "axle_track = 0.331",
            "axle_track = 0.0",
            11,
            "robot.drive.axle_track",
        ),
        (
            EKF,
            "sweep_steps = 40",
            "sweep_steps = 4294967297",
            14,
            "params.sweep_steps",
        ),
        (
            EKF,
            "[params]",
            "[params]\nwaypoint_switch_m = -inf",
            14,
            "params.waypoint_switch_m",
        ),
        (
            EKF,
            "[params]",
            "[params]\nstart_sweeps = 0",
            14,
            "params.start_sweeps",
        ),
        (
            EKF,
            "[[2.0, 2.0], [2.0, 7.0]]",
            "[[2.0, 2.0], [inf, 7.0]]",
            7,
            "waypoints",
        ),
        (
            EKF,
            "start = { x = 1.0",
            "start = { x = 1.0, theta_deg = nan",
            10,
            "robot.start.theta_deg",
        ),
        (
            EMITTER,
            "tolerance_m = 0.5",
            "tolerance_m = -0.5",
            14,
            "goal.tolerance_m",
        ),
        (
            EMITTER,
            "y = 0.0\ntolerance",
            "y = nan\ntolerance",
            13,
            "goal.y",
        ),
        (
            EMITTER,
            "seed = 5",
            "seed = 5\n[params]\nparticles = 4294967297",
            8,
            "params.particles",
        ),
    ];
    for (base, from, to, line, key) in cases {
        assert!(base.contains(from), "{from}");
        let (l, k, msg) = invalid(&base.replacen(from, to, 1));
        assert_eq!((l, k.as_str()), (line, key), "{to}: {msg}");
        assert!(msg.contains("must be"), "{to}: {msg}");
    }
    // The limits themselves are values.
    load(&EKF.replace("sigma_v = 0.0119", "sigma_v = 0.0")).unwrap();
}

/// The emitter trials home on the world's emitter: a goal elsewhere, or a random one, would
/// judge arrival at a place the robot was never sent to.
#[test]
fn an_emitter_goal_away_from_the_emitter_is_rejected() {
    let (line, key, msg) = invalid(&EMITTER.replacen("x = 4.0\ny = 0.0", "x = -0.5\ny = 0.0", 1));
    assert_eq!((line, key.as_str()), (11, "goal"), "{msg}");
    assert!(msg.contains("4.50 m from it"), "{msg}");
    let (_, key, msg) =
        invalid(&EMITTER.replacen("tolerance_m = 0.5", "tolerance_m = 0.5\nrandom = true", 1));
    assert_eq!(key, "goal", "{msg}");
    load(&EMITTER.replacen("x = 4.0\ny = 0.0", "x = 4.3\ny = 0.0", 1)).unwrap();
}

/// A world larger than any floor a trial models is rejected at its `area` line (its grids
/// would not fit in memory).
#[test]
fn an_area_beyond_ten_kilometres_is_rejected() {
    let (line, key, msg) = invalid(&EKF.replace("max = [9.0, 9.0]", "max = [9.0, 4294967297]"));
    assert_eq!((line, key.as_str()), (17, "area"), "{msg}");
    assert!(msg.contains("at most 10000 m"), "{msg}");
}
