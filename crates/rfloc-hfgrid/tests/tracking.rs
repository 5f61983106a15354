//! Tracking while driving on a larger grid: initial pose from a simulated turn, then the
//! particle filter fuses noisy odometry with blind-spot RSSI reports; compared with dead
//! reckoning from the same start.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

mod common;

use common::{scan, turn};
use nalgebra::Matrix3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_hfgrid::{
    GridLayout, GridTracker, GridTrackerConfig, InitialPoseConfig, InitialPoseSolver, RssiModel,
    TagGrid, TagReading,
};
use rfloc_pose::{angle_diff, Pose2};

fn grid() -> TagGrid {
    let layout = GridLayout {
        pitch_m: 0.1,
        origin_m: (0.0, 0.0),
    };
    TagGrid::regular(layout, 21, 21, |c, r| {
        0xE004_0000_0000_0000 | u64::from(r * 21 + c)
    })
    .unwrap()
}

/// A rounded-square path: 0.02 m steps at 10 scans/s, turning at the corners.
fn commands() -> Vec<(f64, f64)> {
    let mut v = Vec::new();
    for _ in 0..4 {
        v.extend(std::iter::repeat_n((0.02, 0.0), 50));
        v.extend(std::iter::repeat_n(
            (0.01, std::f64::consts::FRAC_PI_2 / 10.0),
            10,
        ));
    }
    v
}

#[test]
fn tracker_follows_the_robot_better_than_dead_reckoning() {
    let grid = grid();
    let model = RssiModel::seed002_blind_spot();
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let start = Pose2::new(0.45, 0.45, 0.3);
    let solver = InitialPoseSolver::new(grid.clone(), model.clone(), InitialPoseConfig::default());
    let init = solver
        .solve(&turn(&grid, &model, &start, 0.0, 0.9, 5, &mut rng))
        .unwrap();
    let cfg = GridTrackerConfig {
        seed: 4,
        ..GridTrackerConfig::default()
    };
    let mut tracker =
        GridTracker::new(grid.clone(), &model, cfg, init.pose, init.covariance).unwrap();
    // Odometry error: +3 % scale bias and 5 % noise on translation; +0.08 rad/m heading bias
    // and 0.05 rad/m noise (a wheel-diameter mismatch).
    let n_trans = Normal::new(0.0, 0.05).unwrap();
    let n_rot = Normal::new(0.0, 0.05).unwrap();
    let (mut truth, mut dr) = (start, init.pose);
    let (mut se_pf, mut se_dr, mut sh_pf, mut max_pf) = (0.0, 0.0, 0.0, 0.0f64);
    let cmds = commands();
    for &(d, w) in &cmds {
        let true_delta = Pose2::new(d, 0.0, w);
        truth = truth.compose(&true_delta);
        let odo = Pose2::new(
            d * (1.03 + n_trans.sample(&mut rng)),
            0.0,
            w + (0.08 + n_rot.sample(&mut rng)) * d,
        );
        dr = dr.compose(&odo);
        tracker.predict(odo).unwrap();
        let reads: Vec<TagReading> = scan(&grid, &model, &truth, (-0.10, 0.0), 0.9, &mut rng);
        tracker.update(&reads);
        let (est, _) = tracker.estimate();
        let e = est.distance(&truth);
        se_pf += e * e;
        max_pf = max_pf.max(e);
        sh_pf += angle_diff(est.theta, truth.theta).powi(2);
        se_dr += dr.distance(&truth).powi(2);
    }
    let n = cmds.len() as f64;
    let (rmse_pf, rmse_dr, head_pf) = ((se_pf / n).sqrt(), (se_dr / n).sqrt(), (sh_pf / n).sqrt());
    println!(
        "tracking over {:.1} m: PF RMSE {:.1} mm (max {:.1} mm), heading {:.2}°; dead reckoning RMSE {:.1} mm",
        cmds.iter().map(|c| c.0).sum::<f64>(),
        rmse_pf * 1e3,
        max_pf * 1e3,
        head_pf.to_degrees(),
        rmse_dr * 1e3
    );
    assert!(rmse_pf < 0.015, "PF RMSE {rmse_pf}");
    assert!(head_pf.to_degrees() < 5.0, "heading RMSE {head_pf}");
    assert!(rmse_pf < rmse_dr, "PF {rmse_pf} vs DR {rmse_dr}");
    let (_, cov) = tracker.estimate();
    assert!((cov - cov.transpose()).abs().max() < 1e-12 && cov[(0, 0)] > 0.0);
}

#[test]
fn tracker_rejects_bad_input_and_ignores_empty_scans() {
    let model = RssiModel::seed002_blind_spot();
    assert!(GridTracker::new(
        grid(),
        &model,
        GridTrackerConfig {
            particles: 0,
            ..Default::default()
        },
        Pose2::default(),
        Matrix3::identity()
    )
    .is_err());
    assert!(GridTracker::new(
        grid(),
        &model,
        GridTrackerConfig::default(),
        Pose2::default(),
        -Matrix3::identity()
    )
    .is_err());
    let mut t = GridTracker::new(
        grid(),
        &model,
        GridTrackerConfig::default(),
        Pose2::new(0.5, 0.5, 0.0),
        Matrix3::identity() * 1e-6,
    )
    .unwrap();
    assert!(t
        .predict(Pose2 {
            x: f64::NAN,
            y: 0.0,
            theta: 0.0
        })
        .is_err());
    let before = t.estimate();
    let u = t.update(&[TagReading {
        uid: 42,
        rssi_first: 7,
        rssi_second: 7,
    }]);
    assert_eq!(
        (u.known_tags, u.unknown_reports, u.resampled),
        (0, 1, false)
    );
    assert_eq!(t.estimate().0, before.0);
}
