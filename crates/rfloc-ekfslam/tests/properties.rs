//! Property: any sequence of predictions, updates, additions (direct and delayed) and invalid
//! observations keeps P exactly symmetric, positive semi-definite, and the state finite with a
//! wrapped heading.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

use nalgebra::Matrix3;
use proptest::prelude::*;
use rfloc_ekfslam::{BeaconObservation, CovarianceUpdate, EkfSlam, EkfSlamConfig};
use rfloc_pose::Pose2;

#[derive(Debug, Clone)]
enum Step {
    Velocity(f64, f64, f64),
    Odometry(f64, f64, f64),
    RangeBearing(u64, f64, f64),
    RssiBearing(u64, f64, f64),
    RssiOnly(u64, f64),
    BearingOnly(u64, f64),
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        (-1.0..1.0f64, -1.0..1.0f64, 0.0..0.5f64).prop_map(|(v, w, dt)| Step::Velocity(v, w, dt)),
        (-0.3..0.3f64, -0.1..0.1f64, -0.5..0.5f64).prop_map(|(x, y, t)| Step::Odometry(x, y, t)),
        (0..6u64, 0.2..20.0f64, -4.0..4.0f64).prop_map(|(id, r, b)| Step::RangeBearing(id, r, b)),
        (0..6u64, -90.0..-20.0f64, -4.0..4.0f64).prop_map(|(id, z, b)| Step::RssiBearing(id, z, b)),
        (6..9u64, -90.0..-20.0f64).prop_map(|(id, z)| Step::RssiOnly(id, z)),
        (9..12u64, -4.0..4.0f64).prop_map(|(id, b)| Step::BearingOnly(id, b)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn covariance_stays_symmetric_psd(steps in prop::collection::vec(step(), 1..60), cholesky in any::<bool>()) {
        let cfg = EkfSlamConfig {
            covariance_update: if cholesky { CovarianceUpdate::Cholesky } else { CovarianceUpdate::Joseph },
            ..EkfSlamConfig::default()
        };
        let mut f = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), Matrix3::identity() * 0.01).unwrap();
        for s in steps {
            match s {
                Step::Velocity(v, w, dt) => f.predict_velocity(v, w, dt).unwrap(),
                Step::Odometry(x, y, t) => f.predict_odometry(Pose2::new(x, y, t)).unwrap(),
                Step::RangeBearing(id, r, b) => { f.update(&[BeaconObservation::range_bearing(id, r, b, 0.5, 0.2)]); }
                Step::RssiBearing(id, z, b) => { f.update(&[BeaconObservation::rssi_bearing(id, z, b, 4.0, 0.3)]); }
                Step::RssiOnly(id, z) => { f.update(&[BeaconObservation::rssi_only(id, z, 4.0)]); }
                Step::BearingOnly(id, b) => { f.update(&[BeaconObservation::bearing_only(id, b, 0.1)]); }
            }
            let p = f.covariance();
            prop_assert_eq!(p, &p.transpose());
            let scale = p.abs().max().max(1.0);
            let min_eig = p.clone().symmetric_eigenvalues().min();
            prop_assert!(min_eig > -1e-9 * scale, "min eigenvalue {} (scale {})", min_eig, scale);
            prop_assert!(f.state().iter().all(|v| v.is_finite()));
            let th = f.pose().theta;
            prop_assert!(th > -std::f64::consts::PI && th <= std::f64::consts::PI);
        }
    }
}
