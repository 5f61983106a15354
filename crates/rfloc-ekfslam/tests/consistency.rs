//! Seeded Monte-Carlo consistency of the EKF-SLAM filter (NEES of the robot pose, NIS of the
//! innovations), run over short horizons where EKF-SLAM is known to stay consistent.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

mod common;

use common::{gauss, range_bearing, step_truth};
use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_ekfslam::{BeaconObservation, EkfSlam, EkfSlamConfig, ObservationOutcome, VelocityNoise};
use rfloc_pose::{angle_diff, Pose2};

/// Wilson–Hilferty approximation of the χ² quantile with `k` degrees of freedom at normal quantile `z`.
fn chi2_quantile(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

struct RunResult {
    nees: Vec<f64>,
    nis: Vec<(f64, usize)>,
}

fn one_run(seed: u64) -> RunResult {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = VelocityNoise {
        sigma_v: 0.02,
        sigma_omega: 0.01,
    };
    let cfg = EkfSlamConfig {
        velocity_noise: noise,
        ..EkfSlamConfig::default()
    };
    let (sigma_r, sigma_b) = (0.10, 2f64.to_radians());
    let sigma0 = 0.02;
    let p0 = Matrix3::from_diagonal(&Vector3::new(sigma0 * sigma0, sigma0 * sigma0, 0.01 * 0.01));
    let mut truth = Pose2::new(
        gauss(&mut rng, sigma0),
        gauss(&mut rng, sigma0),
        gauss(&mut rng, 0.01),
    );
    let mut ekf = EkfSlam::new(cfg, Pose2::new(0.0, 0.0, 0.0), p0).unwrap();
    let beacons = [
        (1u64, 3.0, 1.0),
        (2, 1.0, 4.0),
        (3, -2.0, 2.0),
        (4, 2.0, -2.0),
    ];
    let mut out = RunResult {
        nees: Vec::new(),
        nis: Vec::new(),
    };
    let dt = 0.1;
    for k in 0..300 {
        let (v, w) = (0.3, 0.15);
        truth = step_truth(&truth, v, w, dt, noise.sigma_v, noise.sigma_omega, &mut rng);
        ekf.predict_velocity(v, w, dt).unwrap();
        if k % 5 == 4 {
            let obs: Vec<_> = beacons
                .iter()
                .map(|&(id, bx, by)| {
                    let (r, b) = range_bearing(&truth, bx, by);
                    BeaconObservation::range_bearing(
                        id,
                        r + gauss(&mut rng, sigma_r),
                        b + gauss(&mut rng, sigma_b),
                        sigma_r,
                        sigma_b,
                    )
                })
                .collect();
            for o in ekf.update(&obs) {
                if let ObservationOutcome::Updated { nis, dof } = o {
                    out.nis.push((nis, dof));
                }
            }
            let est = ekf.pose();
            let e = Vector3::new(
                truth.x - est.x,
                truth.y - est.y,
                angle_diff(truth.theta, est.theta),
            );
            let p = ekf.pose_covariance();
            let nees = e.dot(&(p.try_inverse().unwrap() * e));
            out.nees.push(nees);
        }
    }
    out
}

#[test]
fn average_nees_and_nis_stay_in_chi2_bands() {
    let runs = 50usize;
    let results: Vec<_> = (0..runs as u64).map(|s| one_run(1000 + s)).collect();
    let steps = results[0].nees.len();
    let n = runs as f64;
    // ANEES per step over the runs; two-sided 99 % band for N·3 degrees of freedom.
    let lo = chi2_quantile(3.0 * n, -2.5758) / n;
    let hi = chi2_quantile(3.0 * n, 2.5758) / n;
    let anees: Vec<f64> = (0..steps)
        .map(|k| results.iter().map(|r| r.nees[k]).sum::<f64>() / n)
        .collect();
    let inside = anees.iter().filter(|a| **a >= lo && **a <= hi).count();
    let mean_anees = anees.iter().sum::<f64>() / steps as f64;
    let max_anees = anees.iter().cloned().fold(0.0, f64::max);
    let all_nis: Vec<(f64, usize)> = results.iter().flat_map(|r| r.nis.iter().copied()).collect();
    let mean_nis_per_dof =
        all_nis.iter().map(|(v, d)| v / *d as f64).sum::<f64>() / all_nis.len() as f64;
    println!(
        "ANEES band [{lo:.3}, {hi:.3}]; time-mean ANEES {mean_anees:.3}; max {max_anees:.3}; \
         {inside}/{steps} steps inside; mean NIS/dof {mean_nis_per_dof:.3} over {} updates",
        all_nis.len()
    );
    // Time-averaged ANEES within the per-step 99 % band, and no step beyond twice its upper bound.
    assert!(
        mean_anees >= lo && mean_anees <= hi,
        "time-mean ANEES {mean_anees} outside [{lo}, {hi}]"
    );
    assert!(
        max_anees < 2.0 * hi,
        "ANEES peak {max_anees} ≥ 2× upper bound"
    );
    assert!(
        inside * 10 >= steps * 8,
        "only {inside}/{steps} steps inside the band"
    );
    // NIS per degree of freedom should average 1 (loose: 0.8–1.25 over thousands of updates).
    assert!(
        (0.8..=1.25).contains(&mean_nis_per_dof),
        "mean NIS/dof {mean_nis_per_dof}"
    );
}
