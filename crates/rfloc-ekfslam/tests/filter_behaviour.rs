//! Behaviour of the filter on hand-made situations: augmentation against the closed form,
//! Joseph vs Cholesky equivalence, gating, invalid input, wrapping, delayed initialisation.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

mod common;

use common::{gauss, range_bearing, step_truth};
use nalgebra::{DMatrix, Matrix2, Matrix2x3, Matrix3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_ekfslam::{
    BeaconObservation, CovarianceUpdate, EkfSlam, EkfSlamConfig, EkfSlamError, InvalidObservation,
    ObservationOutcome, RssiHandling,
};
use rfloc_pose::Pose2;

fn prior() -> Matrix3<f64> {
    // A random-looking symmetric positive-definite pose covariance.
    let a = Matrix3::new(0.3, 0.1, -0.2, 0.05, 0.2, 0.1, -0.1, 0.02, 0.15);
    a * a.transpose() + Matrix3::identity() * 0.01
}

fn is_psd(p: &DMatrix<f64>) -> bool {
    let sym = (p - p.transpose()).abs().max() < 1e-12;
    sym && p.clone().symmetric_eigenvalues().min() > -1e-10
}

#[test]
fn augmentation_matches_bailey_closed_form() {
    let pose = Pose2::new(1.0, -0.5, 0.7);
    let mut f = EkfSlam::new(EkfSlamConfig::default(), pose, prior()).unwrap();
    // First beacon, then a second one so that the map-map cross block is exercised.
    f.update(&[BeaconObservation::range_bearing(10, 3.0, 0.4, 0.2, 0.05)]);
    let before = f.covariance().clone();
    let (r, b, sr, sb) = (2.0, -1.1, 0.3, 0.1);
    let out = f.update(&[BeaconObservation::range_bearing(11, r, b, sr, sb)]);
    assert_eq!(out, vec![ObservationOutcome::Added]);
    let p = f.covariance();
    assert_eq!(p.nrows(), 7);
    let (s, c) = (pose.theta + b).sin_cos();
    let gv = Matrix2x3::new(1.0, 0.0, -r * s, 0.0, 1.0, r * c);
    let gz = Matrix2::new(c, -r * s, s, r * c);
    let rm = Matrix2::new(sr * sr, 0.0, 0.0, sb * sb);
    let pvv = before.fixed_view::<3, 3>(0, 0).into_owned();
    let pll = gv * pvv * gv.transpose() + gz * rm * gz.transpose();
    let plx = gv * before.view((0, 0), (3, 5));
    assert!((p.fixed_view::<2, 2>(5, 5) - pll).abs().max() < 1e-12);
    assert!((p.view((5, 0), (2, 5)) - &plx).abs().max() < 1e-12);
    assert!((p.view((0, 5), (5, 2)) - plx.transpose()).abs().max() < 1e-12);
    assert!(
        (p.view((0, 0), (5, 5)) - &before).abs().max() < 1e-15,
        "old blocks unchanged"
    );
    let bx = f.beacon(11).unwrap().position;
    assert!((bx.x - (pose.x + r * c)).abs() < 1e-12 && (bx.y - (pose.y + r * s)).abs() < 1e-12);
    assert!(is_psd(p));
}

fn scripted_run(update: CovarianceUpdate) -> EkfSlam {
    let cfg = EkfSlamConfig {
        covariance_update: update,
        ..EkfSlamConfig::default()
    };
    let mut f = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), prior() * 0.01).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut truth = Pose2::new(0.0, 0.0, 0.0);
    for k in 0..60 {
        truth = step_truth(&truth, 0.4, 0.2, 0.1, 0.0, 0.0, &mut rng);
        f.predict_velocity(0.4, 0.2, 0.1).unwrap();
        if k % 3 == 0 {
            let obs: Vec<_> = [(1u64, 2.0, 1.0), (2, -1.0, 3.0), (3, 1.0, -2.0)]
                .iter()
                .map(|&(id, bx, by)| {
                    let (r, b) = range_bearing(&truth, bx, by);
                    BeaconObservation::range_bearing(
                        id,
                        r + gauss(&mut rng, 0.1),
                        b + gauss(&mut rng, 0.03),
                        0.1,
                        0.03,
                    )
                })
                .collect();
            f.update(&obs);
        }
    }
    f
}

#[test]
fn joseph_and_cholesky_updates_agree_and_keep_p_psd() {
    let a = scripted_run(CovarianceUpdate::Joseph);
    let b = scripted_run(CovarianceUpdate::Cholesky);
    let dx = (a.state() - b.state()).abs().max();
    let dp = (a.covariance() - b.covariance()).abs().max();
    assert!(
        dx < 1e-9 && dp < 1e-9,
        "state diff {dx}, covariance diff {dp}"
    );
    assert!(is_psd(a.covariance()) && is_psd(b.covariance()));
    assert_eq!(a.beacon_count(), 3);
}

#[test]
fn prediction_leaves_the_map_block_untouched() {
    let mut f = scripted_run(CovarianceUpdate::Joseph);
    let before = f.covariance().clone();
    f.predict_odometry(Pose2::new(0.2, 0.01, 0.1)).unwrap();
    let after = f.covariance();
    let n = after.nrows();
    assert_eq!(
        (after.view((3, 3), (n - 3, n - 3)) - before.view((3, 3), (n - 3, n - 3)))
            .abs()
            .max(),
        0.0
    );
    assert!(
        (after.view((0, 0), (3, 3)) - before.view((0, 0), (3, 3)))
            .abs()
            .max()
            > 0.0
    );
    assert!(is_psd(after));
}

#[test]
fn gate_rejects_outlier_and_counts_it() {
    let mut f = scripted_run(CovarianceUpdate::Joseph);
    let x_before = f.state().clone();
    let p = f.pose();
    let b = f.beacon(1).unwrap().position;
    let (r, brg) = range_bearing(&p, b.x, b.y);
    let out = f.update(&[BeaconObservation::range_bearing(1, r + 5.0, brg, 0.1, 0.03)]);
    assert!(
        matches!(out[0], ObservationOutcome::Rejected { dof: 2, nis } if nis > 13.8),
        "{out:?}"
    );
    assert_eq!(f.stats().rejected_by_gate, 1);
    assert_eq!(f.state(), &x_before);
    // A consistent reading passes.
    let ok = f.update(&[BeaconObservation::range_bearing(1, r, brg, 0.1, 0.03)]);
    assert!(
        matches!(ok[0], ObservationOutcome::Updated { .. }),
        "{ok:?}"
    );
}

#[test]
fn beacon_behind_the_robot_uses_wrapped_bearing_innovation() {
    // Robot at the origin facing +x; beacon straight behind. Measured bearing −179.9°,
    // predicted +179.9°: the innovation must be 0.2°, not 359.8°.
    let mut f = EkfSlam::new(
        EkfSlamConfig::default(),
        Pose2::new(0.0, 0.0, 0.0),
        Matrix3::identity() * 1e-6,
    )
    .unwrap();
    f.update(&[BeaconObservation::range_bearing(
        5,
        2.0,
        179.9f64.to_radians(),
        0.05,
        0.02,
    )]);
    let out = f.update(&[BeaconObservation::range_bearing(
        5,
        2.0,
        -179.9f64.to_radians(),
        0.05,
        0.02,
    )]);
    match out[0] {
        ObservationOutcome::Updated { nis, .. } => assert!(nis < 1.0, "nis {nis}"),
        other => panic!("expected update, got {other:?}"),
    }
    assert!(f.pose().theta.abs() < 0.01);
}

#[test]
fn invalid_input_is_reported_and_changes_nothing() {
    let mut f = scripted_run(CovarianceUpdate::Joseph);
    let x = f.state().clone();
    let out = f.update(&[
        BeaconObservation {
            id: 1,
            range: None,
            bearing: None,
        },
        BeaconObservation::range_bearing(1, f64::NAN, 0.0, 0.1, 0.1),
        BeaconObservation::range_bearing(1, 1.0, 0.0, 0.0, 0.1),
        BeaconObservation::range_bearing(99, -1.0, 0.0, 0.1, 0.1),
    ]);
    assert_eq!(
        out,
        vec![
            ObservationOutcome::Invalid(InvalidObservation::Empty),
            ObservationOutcome::Invalid(InvalidObservation::NonFinite),
            ObservationOutcome::Invalid(InvalidObservation::NonPositiveVariance),
            ObservationOutcome::Invalid(InvalidObservation::NonPositiveRange),
        ]
    );
    assert_eq!(f.stats().invalid, 4);
    assert_eq!(f.state(), &x);
    assert!(matches!(
        f.predict_velocity(f64::NAN, 0.0, 0.1),
        Err(EkfSlamError::NonFinite { .. })
    ));
    assert!(matches!(
        f.predict_velocity(0.1, 0.0, -0.1),
        Err(EkfSlamError::Invalid { .. })
    ));
    assert!(EkfSlam::new(
        EkfSlamConfig::default(),
        Pose2::new(0.0, 0.0, 0.0),
        -Matrix3::identity()
    )
    .is_err());
}

/// Drives an L-shaped path observing one beacon with a single kind of reading; returns the
/// outcomes in order and the final filter.
fn drive_l_path(
    make: &dyn Fn(&Pose2, &mut ChaCha8Rng) -> BeaconObservation,
    cfg: EkfSlamConfig,
) -> (Vec<ObservationOutcome>, EkfSlam) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut f = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), Matrix3::identity() * 1e-6).unwrap();
    let mut truth = Pose2::new(0.0, 0.0, 0.0);
    let mut outcomes = Vec::new();
    for k in 0..200 {
        let w = if (80..96).contains(&k) {
            std::f64::consts::FRAC_PI_2 / 1.6
        } else {
            0.0
        };
        truth = step_truth(&truth, 0.3, w, 0.1, 0.0, 0.0, &mut rng);
        f.predict_velocity(0.3, w, 0.1).unwrap();
        if k % 4 == 0 {
            let o = make(&truth, &mut rng);
            outcomes.extend(f.update(&[o]));
        }
    }
    (outcomes, f)
}

const BEACON: (f64, f64) = (3.0, 4.0);

fn check_delayed(name: &str, outcomes: &[ObservationOutcome], f: &EkfSlam, tol: f64) {
    let first_added = outcomes
        .iter()
        .position(|o| *o == ObservationOutcome::Added);
    let Some(k) = first_added else {
        panic!("{name}: never added: {outcomes:?}")
    };
    assert!(k >= 2, "{name}: added too early ({k})");
    assert!(
        outcomes[..k]
            .iter()
            .all(|o| *o == ObservationOutcome::Pending),
        "{name}"
    );
    let b = f.beacon(1).unwrap();
    let err = (b.position.x - BEACON.0).hypot(b.position.y - BEACON.1);
    println!("{name}: added after {k} views, final beacon error {err:.3} m");
    assert!(err < tol, "{name}: beacon error {err}");
    assert!(is_psd(f.covariance()));
}

#[test]
fn bearing_only_beacon_is_triangulated_after_enough_baseline() {
    let (out, f) = drive_l_path(
        &|p, rng| {
            let (_, b) = range_bearing(p, BEACON.0, BEACON.1);
            BeaconObservation::bearing_only(1, b + gauss(rng, 0.02), 0.02)
        },
        EkfSlamConfig::default(),
    );
    check_delayed("bearing-only", &out, &f, 0.15);
}

#[test]
fn rssi_only_beacon_is_trilaterated_in_both_rssi_modes() {
    for handling in [
        RssiHandling::PathLossMeasurement,
        RssiHandling::ConvertToRange,
    ] {
        let cfg = EkfSlamConfig {
            rssi_handling: handling,
            ..EkfSlamConfig::default()
        };
        let pl = cfg.path_loss;
        let (out, f) = drive_l_path(
            &|p, rng| {
                let (r, _) = range_bearing(p, BEACON.0, BEACON.1);
                BeaconObservation::rssi_only(1, pl.rssi_at(r) + gauss(rng, 1.0), 1.0)
            },
            cfg,
        );
        check_delayed(&format!("rssi-only {handling:?}"), &out, &f, 0.6);
    }
}

#[test]
fn rssi_bearing_observation_initialises_immediately() {
    let cfg = EkfSlamConfig::default();
    let pl = cfg.path_loss;
    let mut f = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), Matrix3::zeros()).unwrap();
    let out = f.update(&[BeaconObservation::rssi_bearing(
        9,
        pl.rssi_at(5.0),
        0.5,
        3.0,
        0.1,
    )]);
    assert_eq!(out, vec![ObservationOutcome::Added]);
    let b = f.beacon(9).unwrap();
    assert!(
        (b.position.x - 5.0 * 0.5f64.cos()).abs() < 1e-9
            && (b.position.y - 5.0 * 0.5f64.sin()).abs() < 1e-9
    );
    // Range std from 3 dB at η = 2 is ≈ 0.345·5 m along the ray.
    let ray = nalgebra::Vector2::new(0.5f64.cos(), 0.5f64.sin());
    let along = (ray.transpose() * b.covariance * ray)[(0, 0)].sqrt();
    assert!(
        (along - 5.0 * 3.0 * std::f64::consts::LN_10 / 20.0).abs() < 1e-9,
        "{along}"
    );
}
