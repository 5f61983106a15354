//! The differential-RSS inversion (eq. 3–4 as reconstructed) against the forward model.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_emitter::{differential_range_bearing, DirectionalArrayModel, Point2};
use rfloc_pose::{angle_diff, Pose2};

proptest! {
    /// Without noise the inversion recovers range and bearing exactly, for any robot pose and
    /// emitter position within the clamps.
    #[test]
    fn noise_free_inversion_is_exact(
        rx in -20.0f64..20.0, ry in -20.0f64..20.0, rt in -3.2f64..3.2,
        range in 0.2f64..50.0, bearing in -3.1f64..3.1,
    ) {
        let model = DirectionalArrayModel { noise_std_db: 0.0, ..DirectionalArrayModel::default() };
        let robot = Pose2::new(rx, ry, rt);
        let a = rt + bearing;
        let emitter = Point2::new(rx + range * a.cos(), ry + range * a.sin());
        let rb = differential_range_bearing(&model.expected(&robot, &emitter), &model.matching_calibration()).unwrap();
        prop_assert!((rb.range_m - range).abs() < 1e-9 * range.max(1.0));
        prop_assert!(angle_diff(rb.bearing_rad, bearing).abs() < 1e-9);
        prop_assert!(rb.to_world(&robot).distance(&emitter) < 1e-8 * range.max(1.0));
    }
}

#[test]
fn noisy_inversion_is_close() {
    // σ = 2 dB per antenna, F = 12 dB: bearing noise ≈ atan(2√2/12) ≈ 13° (1σ), range noise
    // ≈ 10^(1/20) − 1 ≈ 12 % (1σ). Check the sample statistics over 2000 draws.
    let model = DirectionalArrayModel::default();
    let cal = model.matching_calibration();
    let robot = Pose2::new(1.0, -1.0, 0.4);
    let emitter = Point2::new(4.0, 2.0);
    let true_range = robot.distance(&Pose2::new(emitter.x, emitter.y, 0.0));
    let true_bearing = angle_diff(
        (emitter.y - robot.y).atan2(emitter.x - robot.x),
        robot.theta,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let n = 2000;
    let (mut sum_b, mut sum_b2, mut sum_logr, mut pos_err) = (0.0, 0.0, 0.0, 0.0);
    for _ in 0..n {
        let rb =
            differential_range_bearing(&model.sample(&robot, &emitter, &mut rng), &cal).unwrap();
        let e = angle_diff(rb.bearing_rad, true_bearing);
        sum_b += e;
        sum_b2 += e * e;
        sum_logr += (rb.range_m / true_range).ln();
        pos_err += rb.to_world(&robot).distance(&emitter);
    }
    let n = n as f64;
    let bias_deg = (sum_b / n).to_degrees();
    let rms_deg = (sum_b2 / n).sqrt().to_degrees();
    let range_bias = (sum_logr / n).exp() - 1.0;
    let mean_pos_err = pos_err / n;
    println!(
        "bearing bias {bias_deg:.2}°, rms {rms_deg:.1}°; range geometric bias {:.1} %; \
         mean raw position error {mean_pos_err:.2} m at {true_range:.2} m",
        100.0 * range_bias
    );
    assert!(bias_deg.abs() < 1.5);
    assert!(rms_deg > 8.0 && rms_deg < 20.0, "{rms_deg}");
    assert!(range_bias.abs() < 0.02, "{range_bias}");
    assert!(mean_pos_err < 0.35 * true_range, "{mean_pos_err}");
}
