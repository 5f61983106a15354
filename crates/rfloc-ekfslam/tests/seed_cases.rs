//! The reference's simulation cases I and II (seed 003 §3.3–3.4): waypoints and beacon
//! positions from the seed, noise from its Table 3.1 (σ_v 0.0119 m/s, σ_ω 0.0012 rad/s,
//! σ_r 2 m, σ_β 18°), the waypoint controller closing the loop on the estimate. The seed does
//! not give the start pose or the measurement rate: here the robot starts at (1, 1) facing +y,
//! measures every beacon once per second and the controller runs at 10 Hz.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

mod common;

use common::{gauss, range_bearing, step_truth};
use nalgebra::Matrix3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_ekfslam::accuracy::{evaluate, AccuracyReport};
use rfloc_ekfslam::{
    BeaconObservation, EkfSlam, EkfSlamConfig, WaypointController, WaypointControllerConfig,
};
use rfloc_pose::Pose2;

#[derive(Clone, Copy)]
enum Sensor {
    /// Range (m) and bearing, σ_r 2 m as in Table 3.1.
    RangeBearing,
    /// RSSI (dBm, path loss −29 dBm at 1 m, η = 2) with σ 4 dB, and bearing.
    RssiBearing,
}

fn run(
    waypoints: &[(f64, f64)],
    beacons: &[(u64, f64, f64)],
    sensor: Sensor,
    seed: u64,
) -> (AccuracyReport, bool) {
    run_with(waypoints, beacons, sensor, seed, EkfSlamConfig::default()).0
}

/// Returns the filter's report, whether the waypoints were finished, and the dead-reckoning
/// position RMSE (commands integrated without corrections) for comparison.
fn run_with(
    waypoints: &[(f64, f64)],
    beacons: &[(u64, f64, f64)],
    sensor: Sensor,
    seed: u64,
    cfg: EkfSlamConfig,
) -> ((AccuracyReport, bool), f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (sv, sw) = (cfg.velocity_noise.sigma_v, cfg.velocity_noise.sigma_omega);
    let (sigma_r, sigma_b, sigma_db) = (2.0, 18f64.to_radians(), 4.0);
    let start = Pose2::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
    let mut truth = start;
    let mut ekf = EkfSlam::new(cfg, start, Matrix3::zeros()).unwrap();
    let mut ctl = WaypointController::new(WaypointControllerConfig::default(), waypoints.to_vec());
    let (mut tr, mut es) = (Vec::new(), Vec::new());
    let dt = 0.1;
    let mut done = false;
    let mut dead_reckoning = start;
    let mut dr_sq = 0.0;
    for k in 0..6000 {
        let cmd = ctl.command(&ekf.pose(), dt);
        if cmd.done {
            done = true;
            break;
        }
        truth = step_truth(&truth, cmd.v, cmd.omega, dt, sv, sw, &mut rng);
        ekf.predict_velocity(cmd.v, cmd.omega, dt).unwrap();
        dead_reckoning = step_truth(&dead_reckoning, cmd.v, cmd.omega, dt, 0.0, 0.0, &mut rng);
        dr_sq += dead_reckoning.distance(&truth).powi(2);
        if k % 10 == 9 {
            let obs: Vec<_> = beacons
                .iter()
                .map(|&(id, bx, by)| {
                    let (r, b) = range_bearing(&truth, bx, by);
                    let b = b + gauss(&mut rng, sigma_b);
                    match sensor {
                        Sensor::RangeBearing => BeaconObservation::range_bearing(
                            id,
                            (r + gauss(&mut rng, sigma_r)).max(0.1),
                            b,
                            sigma_r,
                            sigma_b,
                        ),
                        Sensor::RssiBearing => {
                            let z = cfg.path_loss.rssi_at(r) + gauss(&mut rng, sigma_db);
                            BeaconObservation::rssi_bearing(id, z, b, sigma_db, sigma_b)
                        }
                    }
                })
                .collect();
            ekf.update(&obs);
        }
        tr.push(truth);
        es.push(ekf.pose());
    }
    let dr_rmse = (dr_sq / tr.len().max(1) as f64).sqrt();
    (
        (evaluate(&tr, &es, beacons, &ekf.beacons()).unwrap(), done),
        dr_rmse,
    )
}

fn summarise(
    name: &str,
    waypoints: &[(f64, f64)],
    beacons: &[(u64, f64, f64)],
    sensor: Sensor,
) -> (f64, f64, Vec<f64>) {
    let seeds = 10u64;
    let (mut pos, mut head) = (0.0, 0.0);
    let mut beac = vec![0.0; beacons.len()];
    for s in 0..seeds {
        let (r, done) = run(waypoints, beacons, sensor, 500 + s);
        assert!(done, "{name}: seed {s} did not finish the waypoints");
        pos += r.position_rmse_m;
        head += r.heading_rmse_rad;
        for (acc, b) in beac.iter_mut().zip(&r.beacons) {
            *acc += b.error_m.unwrap();
        }
    }
    let n = seeds as f64;
    let beac: Vec<f64> = beac.iter().map(|b| b / n).collect();
    println!(
        "{name}: mean over {seeds} seeds: robot RMSE {:.3} m, {:.3} rad; final beacon errors {:?} m",
        pos / n,
        head / n,
        beac.iter().map(|b| (b * 1000.0).round() / 1000.0).collect::<Vec<_>>()
    );
    (pos / n, head / n, beac)
}

const CASE_I_WP: [(f64, f64); 4] = [(2.0, 2.0), (2.0, 7.0), (7.0, 7.0), (7.0, 2.0)];
const CASE_I_B: [(u64, f64, f64); 4] =
    [(1, 0.0, 3.5), (2, 6.5, 2.5), (3, 4.0, 7.25), (4, 0.0, 8.0)];
const CASE_II_WP: [(f64, f64); 6] = [
    (9.0, 3.0),
    (5.0, 5.0),
    (3.0, 7.0),
    (8.0, 8.0),
    (8.0, 2.0),
    (2.0, 2.0),
];
const CASE_II_B: [(u64, f64, f64); 4] =
    [(1, 0.0, 0.0), (2, 9.0, 2.0), (3, 4.0, 4.0), (4, 8.0, 7.0)];

#[test]
fn case_one_range_bearing() {
    let (pos, head, beac) = summarise(
        "case I range+bearing",
        &CASE_I_WP,
        &CASE_I_B,
        Sensor::RangeBearing,
    );
    // Seed Table 3.2: 0.69 m, 0.04 rad, beacons 0.25–0.36 m. Loose regression bounds:
    assert!(pos < 0.1 && head < 0.02, "{pos} {head}");
    assert!(beac.iter().all(|b| *b < 1.0), "{beac:?}");
}

#[test]
fn case_two_range_bearing() {
    let (pos, head, beac) = summarise(
        "case II range+bearing",
        &CASE_II_WP,
        &CASE_II_B,
        Sensor::RangeBearing,
    );
    // Seed Table 3.3: 0.15 m, 0.14 rad, beacons 0.21–0.73 m.
    assert!(pos < 0.1 && head < 0.02, "{pos} {head}");
    assert!(beac.iter().all(|b| *b < 1.0), "{beac:?}");
}

#[test]
fn case_one_rssi_bearing() {
    let (pos, head, beac) = summarise(
        "case I rssi+bearing",
        &CASE_I_WP,
        &CASE_I_B,
        Sensor::RssiBearing,
    );
    assert!(pos < 0.1 && head < 0.02, "{pos} {head}");
    assert!(beac.iter().all(|b| *b < 1.0), "{beac:?}");
}

#[test]
fn case_one_with_slipping_wheels_beats_dead_reckoning() {
    // Velocity noise 10× Table 3.1 in both the truth and the filter model (σ_v 0.119 m/s,
    // σ_ω 0.012 rad/s): the beacons must now correct the pose.
    let mut cfg = EkfSlamConfig::default();
    cfg.velocity_noise.sigma_v *= 10.0;
    cfg.velocity_noise.sigma_omega *= 10.0;
    let (mut ekf, mut dr) = (0.0, 0.0);
    for s in 0..10 {
        let ((r, done), d) = run_with(&CASE_I_WP, &CASE_I_B, Sensor::RangeBearing, 700 + s, cfg);
        assert!(done);
        ekf += r.position_rmse_m / 10.0;
        dr += d / 10.0;
    }
    println!("case I, 10× velocity noise: EKF robot RMSE {ekf:.3} m, dead reckoning {dr:.3} m (mean of 10 seeds)");
    assert!(ekf < dr, "EKF {ekf} vs dead reckoning {dr}");
}
