//! Calibration of the RSS → distance mapping (`A1`, `A2`), as the seed calibrated its receivers:
//! readings at known distances in the open, fitted by least squares to
//! `S̄ = A1 − 10·A2·log10(d)`, where `S̄` is the mean of the four antennas.
//!
//! In simulation the "open field" is an empty world with the scenario's emitter model and
//! emitter power; readings are noise-free means over all bearings, so the fit absorbs the mean
//! reflector gain of the four antennas. Walls, multipath and fading are not calibrated away.

use std::path::Path;

use anyhow::Context;
use rfloc_emitter::DifferentialRssConfig;
use rfloc_pose::Pose2;
use rfloc_sim::emitter::EmitterModel;
use rfloc_sim::world::Emitter;
use rfloc_sim::{Point, World};

/// Fits `A1`, `A2` for `model` and an emitter of `power_dbm`, over 1–10 m and all bearings.
///
/// # Errors
/// If the calibration field cannot be built or the fit is degenerate.
pub fn calibrate(model: &EmitterModel, power_dbm: f64) -> anyhow::Result<DifferentialRssConfig> {
    let field = World::from_toml_str(
        "[area]\nmin = [-20.0, -20.0]\nmax = [20.0, 20.0]\nboundary_walls = false\n",
        Path::new("calibration field"),
    )
    .context("building the calibration field")?;
    let robot = Pose2::new(0.0, 0.0, 0.0);
    let mut samples: Vec<(f64, f64)> = Vec::new();
    for i in 0..=18 {
        let d = 1.0 + 0.5 * f64::from(i);
        for k in 0..72 {
            let b = f64::from(k) * 5f64.to_radians();
            let emitter = Emitter {
                position: Point::new(d * b.cos(), d * b.sin()),
                power_dbm,
            };
            let rss = model.mean_rss(&field, &robot, &emitter);
            let mean = rss.iter().sum::<f64>() / 4.0;
            samples.push((d.log10(), mean));
        }
    }
    let n = samples.len() as f64;
    let mx = samples.iter().map(|s| s.0).sum::<f64>() / n;
    let my = samples.iter().map(|s| s.1).sum::<f64>() / n;
    let sxx: f64 = samples.iter().map(|s| (s.0 - mx).powi(2)).sum();
    let sxy: f64 = samples.iter().map(|s| (s.0 - mx) * (s.1 - my)).sum();
    anyhow::ensure!(sxx > 0.0, "degenerate calibration distances");
    let slope = sxy / sxx;
    let a1 = my - slope * mx;
    let a2 = -slope / 10.0;
    anyhow::ensure!(
        a1.is_finite() && a2.is_finite() && a2 > 0.0,
        "calibration fit failed (A1 {a1}, A2 {a2})"
    );
    Ok(DifferentialRssConfig {
        a1_dbm_at_1m: a1,
        a2_path_loss_exponent: a2,
        ..DifferentialRssConfig::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulated_emitter_robot_file_carries_this_calibration() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let path = root.join("config/sim-emitter.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let cfg =
            rfloc_daemon::config::RobotConfig::parse(&text, "sim-emitter.toml", None).unwrap();
        let rfloc_daemon::config::EstimatorConfig::Emitter(e) = &cfg.estimator else {
            panic!("not an emitter pipeline");
        };
        let sim = crate::sim::SimulationConfig::of(&cfg).unwrap();
        let scenario =
            rfloc_sim::Scenario::load(&root.join("config").join(sim.scenario.as_ref().unwrap()))
                .unwrap();
        let power = scenario.world.emitter.unwrap().power_dbm;
        let cal = calibrate(&scenario.emitter_model(), power).unwrap();
        assert!(
            (cal.a1_dbm_at_1m - e.a1_dbm_at_1m).abs() < 0.05
                && (cal.a2_path_loss_exponent - e.path_loss_exponent).abs() < 0.005,
            "calibration A1 {:.2} dBm, A2 {:.3}; the file has {} and {}",
            cal.a1_dbm_at_1m,
            cal.a2_path_loss_exponent,
            e.a1_dbm_at_1m,
            e.path_loss_exponent
        );
    }

    #[test]
    fn free_space_model_gives_exponent_two_and_its_reference_level() {
        let model = EmitterModel::default();
        let cal = calibrate(&model, 0.0).unwrap();
        assert!((cal.a2_path_loss_exponent - model.path_loss_exponent).abs() < 1e-9);
        // A1 is the 1 m level plus the mean gain of the four reflectors (between 0 and −10 dB).
        let level_1m = -model.reference_loss_db;
        assert!(cal.a1_dbm_at_1m < level_1m && cal.a1_dbm_at_1m > level_1m - 10.0);
    }
}
