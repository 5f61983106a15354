//! Delayed initialisation with the views' poses kept in the state
//! (`DelayedInit::view_poses_in_state`) and with range+bearing views
//! (`DelayedInit::delay_range_bearing`): bookkeeping of the pose copies, and over Monte-Carlo
//! runs a consistent filter that localises the robot better than attaching the triangulated
//! beacon to the current pose.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{gauss, range_bearing, step_truth};
use nalgebra::Matrix3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_ekfslam::{
    BeaconObservation, DelayedInit, EkfSlam, EkfSlamConfig, ObservationOutcome, VelocityNoise,
};
use rfloc_pose::{angle_diff, Pose2};

const BEACONS: [(u64, f64, f64); 3] = [(1, 4.0, 3.0), (2, 6.0, -2.0), (3, 1.0, 5.0)];

fn config(copies: bool, delay_range_bearing: bool) -> EkfSlamConfig {
    EkfSlamConfig {
        velocity_noise: VelocityNoise {
            sigma_v: 0.03,
            sigma_omega: 0.03,
        },
        delayed_init: DelayedInit {
            view_poses_in_state: copies,
            delay_range_bearing,
            max_std_m: 0.5,
            ..DelayedInit::default()
        },
        ..EkfSlamConfig::default()
    }
}

/// One sweep's observations of every beacon from the true pose: RSSI (σ 3 dB) and bearing
/// (σ 2°).
fn observe(f: &EkfSlam, truth: &Pose2, rng: &mut ChaCha8Rng) -> Vec<BeaconObservation> {
    let pl = f.config().path_loss;
    BEACONS
        .iter()
        .map(|&(id, x, y)| {
            let (r, b) = range_bearing(truth, x, y);
            BeaconObservation::rssi_bearing(
                id,
                pl.rssi_at(r) + gauss(rng, 3.0),
                b + gauss(rng, 2f64.to_radians()),
                3.0,
                2f64.to_radians(),
            )
        })
        .collect()
}

/// A 60 s drive (a straight leg, a left turn, a second leg) with a sweep every 2 s; returns
/// the final filter and the true pose.
fn run(cfg: EkfSlamConfig, seed: u64) -> (EkfSlam, Pose2) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = Pose2::new(0.0, 0.0, 0.0);
    let mut f = EkfSlam::new(cfg, start, Matrix3::zeros()).unwrap();
    let mut truth = start;
    let n = cfg.velocity_noise;
    for k in 0..600 {
        let w = if (250..300).contains(&k) { 0.3 } else { 0.0 };
        truth = step_truth(&truth, 0.2, w, 0.1, n.sigma_v, n.sigma_omega, &mut rng);
        f.predict_velocity(0.2, w, 0.1).unwrap();
        if k % 20 == 0 {
            let obs = observe(&f, &truth, &mut rng);
            let out = f.update(&obs);
            // Pose copies exist only while some beacon is pending.
            if f.pending_beacons().is_empty() {
                assert_eq!(f.view_pose_count(), 0);
            }
            assert_eq!(
                f.state().len(),
                3 + 2 * f.beacon_count() + 3 * f.view_pose_count()
            );
            assert!(out
                .iter()
                .all(|o| !matches!(o, ObservationOutcome::Invalid(_))));
        }
    }
    (f, truth)
}

#[test]
fn range_bearing_views_wait_and_pose_copies_are_shared_and_dropped() {
    let cfg = config(true, true);
    let mut f = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), Matrix3::zeros()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let truth = Pose2::new(0.0, 0.0, 0.0);
    let out = f.update(&observe(&f, &truth, &mut rng));
    // Range and bearing, but delayed: three views, one shared pose copy.
    assert!(
        out.iter().all(|o| *o == ObservationOutcome::Pending),
        "{out:?}"
    );
    assert_eq!(f.view_pose_count(), 1);
    assert_eq!(f.state().len(), 6);
    // The copy is the pose, fully correlated with it.
    let p = f.covariance();
    assert!(
        (p.view((0, 3), (3, 3)) - p.view((0, 0), (3, 3)))
            .abs()
            .max()
            < 1e-15
    );
    let (f, _) = run(cfg, 1);
    assert_eq!(f.beacon_count(), 3);
    assert_eq!(f.view_pose_count(), 0);
    assert_eq!(f.state().len(), 9);
    let sym = (f.covariance() - f.covariance().transpose()).abs().max();
    assert!(sym < 1e-12);
    assert!(f.covariance().clone().symmetric_eigenvalues().min() > -1e-10);
}

#[test]
fn views_in_the_state_are_consistent_and_beat_attaching_to_the_current_pose() {
    let runs = 40;
    let (mut sq_copies, mut sq_attached, mut nees) = (0.0, 0.0, 0.0);
    let mut beacon_sq = 0.0;
    for seed in 0..runs {
        let (f, truth) = run(config(true, true), 100 + seed);
        let (g, truth_g) = run(config(false, true), 100 + seed);
        assert_eq!(truth, truth_g, "same draws");
        let p = f.pose();
        let e = nalgebra::Vector3::new(
            p.x - truth.x,
            p.y - truth.y,
            angle_diff(p.theta, truth.theta),
        );
        nees += (e.transpose() * f.pose_covariance().try_inverse().unwrap() * e)[(0, 0)];
        sq_copies += e.x * e.x + e.y * e.y;
        let q = g.pose();
        sq_attached += (q.x - truth.x).powi(2) + (q.y - truth.y).powi(2);
        for &(id, x, y) in &BEACONS {
            let b = f.beacon(id).unwrap().position;
            beacon_sq += (b.x - x).powi(2) + (b.y - y).powi(2);
        }
    }
    let k = runs as f64;
    let (rmse_copies, rmse_attached) = ((sq_copies / k).sqrt(), (sq_attached / k).sqrt());
    let anees = nees / k;
    println!(
        "final robot RMSE {rmse_copies:.3} m with pose copies, {rmse_attached:.3} m attached; \
         ANEES {anees:.2} (3 dof); beacon RMSE {:.3} m",
        (beacon_sq / (3.0 * k)).sqrt()
    );
    // 99 % band of the mean of 40 χ²₃ draws: [2.0, 4.2].
    assert!((2.0..4.2).contains(&anees), "ANEES {anees}");
    assert!(
        rmse_copies < rmse_attached,
        "{rmse_copies} vs {rmse_attached}"
    );
}

/// A robot circling a 0.5 m loop sees a beacon 7.6 m away from a 1 m baseline: the triangulation
/// never reaches σ ≤ 0.3 m, so with the absolute bound alone the beacon is never mapped. With
/// `relax_after_views` it is mapped once its σ is a quarter of its distance, and over
/// Monte-Carlo runs its final error is consistent with its covariance (2-dof NEES).
#[test]
fn far_beacons_of_a_short_baseline_are_mapped_with_their_uncertainty() {
    const FAR: (u64, f64, f64) = (9, 7.0, 3.0);
    let cfg = |relax: usize| EkfSlamConfig {
        velocity_noise: VelocityNoise {
            sigma_v: 0.01,
            sigma_omega: 0.01,
        },
        delayed_init: DelayedInit {
            delay_range_bearing: true,
            max_std_m: 0.3,
            relax_after_views: relax,
            max_relative_std: 0.25,
            ..DelayedInit::default()
        },
        ..EkfSlamConfig::default()
    };
    let run = |cfg: EkfSlamConfig, seed: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = Pose2::new(0.0, 0.0, 0.0);
        let mut f = EkfSlam::new(cfg, start, Matrix3::zeros()).unwrap();
        let mut truth = start;
        let n = cfg.velocity_noise;
        let pl = f.config().path_loss;
        for k in 0..1200 {
            // A circle of 0.5 m radius: 0.2 m/s, 0.4 rad/s.
            truth = step_truth(&truth, 0.2, 0.4, 0.1, n.sigma_v, n.sigma_omega, &mut rng);
            f.predict_velocity(0.2, 0.4, 0.1).unwrap();
            if k % 30 == 0 {
                let (r, b) = range_bearing(&truth, FAR.1, FAR.2);
                let obs = BeaconObservation::rssi_bearing(
                    FAR.0,
                    pl.rssi_at(r) + gauss(&mut rng, 3.0),
                    b + gauss(&mut rng, 2f64.to_radians()),
                    3.0,
                    2f64.to_radians(),
                );
                f.update(&[obs]);
            }
        }
        f
    };
    assert!(run(cfg(0), 7).beacon(FAR.0).is_none(), "never mapped");
    let runs: u32 = 40;
    let mut nees = 0.0;
    let mut mapped: u32 = 0;
    for seed in 0..runs {
        let f = run(cfg(20), 500 + u64::from(seed));
        if let Some(b) = f.beacon(FAR.0) {
            mapped += 1;
            let e = nalgebra::Vector2::new(b.position.x - FAR.1, b.position.y - FAR.2);
            nees += (e.transpose() * b.covariance.try_inverse().unwrap() * e)[(0, 0)];
        }
    }
    assert_eq!(mapped, runs, "mapped in every run");
    let anees = nees / f64::from(mapped);
    println!("far beacon ANEES {anees:.2} (2 dof) over {mapped} runs");
    // 99 % band of the mean of 40 χ²₂ draws: [1.43, 2.71].
    assert!((1.43..2.71).contains(&anees), "ANEES {anees}");
}
