//! Property tests: exact integration, collision invariants, parsers that never panic and
//! round-trip.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

use std::path::Path;

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use rfloc_sim::geometry::Point;
use rfloc_sim::hf::HfModel;
use rfloc_sim::metrics::TimedPose;
use rfloc_sim::uhf::UhfModel;
use rfloc_sim::world::UhfTag;
use rfloc_sim::{integrate_unicycle, truth, DiffDriveParams, RobotSim, World};

const ROOM: &str = r#"
[area]
min = [0.0, 0.0]
max = [6.0, 4.0]
[[obstacles]]
points = [[2.0, 1.0], [3.0, 1.0], [3.0, 3.0], [2.0, 3.0]]
[[walls]]
points = [[4.5, 0.0], [4.5, 2.5]]
"#;

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Two half steps equal one full step: the arc integration is exact, not first-order.
    #[test]
    fn half_steps_compose_exactly(x in -5.0..5.0f64, y in -5.0..5.0f64, th in -3.1..3.1f64,
                                  v in -1.0..1.0f64, w in -2.0..2.0f64, dt in 0.01..2.0f64) {
        let p = Pose2::new(x, y, th);
        let full = integrate_unicycle(&p, v, w, dt);
        let half = integrate_unicycle(&integrate_unicycle(&p, v, w, dt / 2.0), v, w, dt / 2.0);
        prop_assert!(full.distance(&half) < 1e-9);
        prop_assert!(rfloc_pose::angle_diff(full.theta, half.theta).abs() < 1e-9);
    }

    /// Under any command sequence the body never penetrates a wall or an obstacle.
    #[test]
    fn robot_never_passes_through_walls(seed in any::<u64>(), cmds in prop::collection::vec((-1.2..1.2f64, -3.0..3.0f64), 1..120)) {
        let world = World::from_toml_str(ROOM, Path::new("room.toml")).unwrap();
        let params = DiffDriveParams { slip_sigma: 0.05, ..DiffDriveParams::default() };
        let mut r = RobotSim::new(params, Pose2::new(1.0, 2.0, 0.0), seed);
        for (v, w) in cmds {
            let out = r.step(v, w, 0.2, &world);
            let c = Point::new(out.truth.x, out.truth.y);
            let clearance = world.walls.iter().map(|s| s.distance_to_point(&c)).fold(f64::INFINITY, f64::min);
            prop_assert!(clearance >= params.body_radius - 1e-9, "clearance {clearance} at {c:?}");
            prop_assert!(!world.inside_obstacle(&c));
        }
    }

    /// HF readings are always levels 0–7, and nothing is read beyond 14 cm.
    #[test]
    fn hf_levels_in_range(d in -0.1..0.5f64, seed in any::<u64>()) {
        let m = HfModel::default();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        match m.sample_rssi(d, &mut rng) {
            Some(r) => prop_assert!(r <= 7 && (0.0..=0.14).contains(&d)),
            None => prop_assert!(!(0.0..=0.14).contains(&d)),
        }
    }

    /// Every reported UHF read is at or above the threshold.
    #[test]
    fn uhf_reads_respect_threshold(seed in any::<u64>(), tags in prop::collection::vec((-2.0..2.0f64, -2.0..2.0f64), 0..60)) {
        let m = UhfModel::default();
        let tags: Vec<UhfTag> = tags.iter().enumerate()
            .map(|(i, (x, y))| UhfTag { epc: format!("{i:04X}"), position: Point::new(*x, *y), normal: 0.0 })
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for r in m.visible_tags(&Pose2::default(), &tags, &mut rng) {
            prop_assert!(r.rss >= m.threshold);
        }
    }

    /// truth.csv round-trips any finite trajectory exactly.
    #[test]
    fn truth_csv_round_trips(raw in prop::collection::vec((0.0..10.0f64, -1e6..1e6f64, -1e6..1e6f64, -3.0..3.0f64), 0..50)) {
        let mut t = 0.0;
        let poses: Vec<TimedPose> = raw.iter().map(|(dt, x, y, th)| { t += dt; TimedPose::new(t, Pose2 { x: *x, y: *y, theta: *th }) }).collect();
        let back = truth::parse(&truth::to_csv(&poses), Path::new("t.csv")).unwrap();
        prop_assert_eq!(back, poses);
    }

    /// Parsers return errors, never panic, on arbitrary text.
    #[test]
    fn parsers_never_panic(text in "\\PC{0,300}") {
        let _ = truth::parse(&text, Path::new("t.csv"));
        let _ = World::from_toml_str(&text, Path::new("w.toml"));
        let _ = rfloc_sim::Scenario::from_toml_str(&text, Path::new("s.toml"));
    }

    /// Byte-level damage to a valid world file gives a result or an error, never a panic,
    /// and every error names the file.
    #[test]
    fn damaged_world_files_fail_cleanly(pos in 0usize..400, byte in any::<u8>()) {
        let mut bytes = ROOM.as_bytes().to_vec();
        let i = pos % bytes.len();
        bytes[i] = byte;
        if let Ok(text) = String::from_utf8(bytes) {
            if let Err(e) = World::from_toml_str(&text, Path::new("room.toml")) {
                prop_assert!(e.to_string().starts_with("room.toml:"), "{e}");
            }
        }
    }
}
