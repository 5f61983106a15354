//! The scan runner with in-test probes: stop order, headings, probe failures, rotator errors.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::collections::VecDeque;

use common::{rssi, seed_beacons, truth};
use rfloc_bearing::{
    PathLossModel, ReflectorPattern, RssiProbe, ScanConfig, ScanError, ScanRunner, SweepPlanConfig,
};
use rfloc_pose::angle_diff;
use rfloc_stepper::{AngleProbe, MovePolicy, SimulatedStepper, StepperConfig, StepperError};

#[derive(Debug, thiserror::Error)]
#[error("probe timed out")]
struct Timeout;

/// Noise-free RSSI of the seed beacons from (1, 1, 0) at the stepper's angle; scripted
/// failures first.
struct GainProbe {
    antenna: AngleProbe,
    failures: VecDeque<bool>,
}

impl RssiProbe for GainProbe {
    type Error = Timeout;
    async fn rssi_all(&mut self) -> Result<Vec<(u64, f64)>, Timeout> {
        if self.failures.pop_front() == Some(true) {
            return Err(Timeout);
        }
        let (m, p) = (PathLossModel::default(), ReflectorPattern::default());
        Ok(seed_beacons()
            .iter()
            .map(|b| (b.id, rssi(&m, &p, (1.0, 1.0, 0.0), self.antenna.get(), b)))
            .collect())
    }
}

fn runner(failures: &[bool], config: ScanConfig) -> ScanRunner<SimulatedStepper, GainProbe> {
    let stepper = SimulatedStepper::new(&StepperConfig::default()).unwrap();
    let probe = GainProbe {
        antenna: stepper.angle_probe(),
        failures: failures.iter().copied().collect(),
    };
    ScanRunner::new(stepper, probe, config).unwrap()
}

#[tokio::test]
async fn sweeps_alternate_and_tolerate_a_few_probe_failures() {
    let mut r = runner(&[true, false, true], ScanConfig::default());
    let mut calls = 0;
    let res = r
        .scan(|| {
            calls += 1;
            0.0
        })
        .await
        .unwrap();
    assert_eq!(calls, 40, "heading read once per stop");
    assert_eq!(res.probe_failures, 2);
    // The two failed stops (1st and 3rd probe round) have no readings.
    assert!(res.sweep.samples[0].readings.is_empty());
    assert!(res.sweep.samples[2].readings.is_empty());
    for b in seed_beacons() {
        let o = res.report.beacons[&b.id].clone().unwrap();
        let (_, want) = truth(1.0, 1.0, 0.0, &b);
        assert!(angle_diff(o.bearing_rad, want).abs() < 9f64.to_radians());
    }
    let back = r.scan(|| 0.0).await.unwrap();
    let a: Vec<f64> = res.sweep.samples.iter().map(|s| s.antenna_rad).collect();
    let mut b: Vec<f64> = back.sweep.samples.iter().map(|s| s.antenna_rad).collect();
    b.reverse();
    assert_eq!(a, b, "second sweep retraces the first backwards");
}

#[tokio::test]
async fn too_many_probe_failures_abandon_the_sweep() {
    let mut r = runner(&[true; 5], ScanConfig::default());
    match r.scan(|| 0.0).await {
        Err(ScanError::Probe { failures, .. }) => assert_eq!(failures, 4),
        other => panic!("expected probe error, got {other:?}"),
    }
}

#[tokio::test]
async fn rotator_refusing_a_stop_is_reported() {
    // The plan wants ±180°, the rotator is bounded to ±90°.
    let stepper = SimulatedStepper::new(&StepperConfig {
        policy: MovePolicy::Bounded {
            min_rad: -1.6,
            max_rad: 1.6,
        },
        ..StepperConfig::default()
    })
    .unwrap();
    let probe = GainProbe {
        antenna: stepper.angle_probe(),
        failures: VecDeque::new(),
    };
    let mut r = ScanRunner::new(stepper, probe, ScanConfig::default()).unwrap();
    match r.scan(|| 0.0).await {
        Err(ScanError::Rotator(StepperError::OutOfRange { .. })) => {}
        other => panic!("expected rotator error, got {other:?}"),
    }
}

#[test]
fn scan_config_from_toml() {
    let c: ScanConfig = toml::from_str(
        "probes_per_stop = 3\n[plan]\narc_deg = 180.0\nstep_deg = 4.5\n[estimator]\nmin_contrast_db = 4.0\n[estimator.path_loss]\np_ref_dbm = -33.0\n",
    )
    .unwrap();
    assert_eq!(c.probes_per_stop, 3);
    assert_eq!(
        c.plan,
        SweepPlanConfig {
            center_deg: 0.0,
            arc_deg: 180.0,
            step_deg: 4.5
        }
    );
    assert_eq!(c.estimator.path_loss.p_ref_dbm, -33.0);
    assert_eq!(c.estimator.path_loss.eta, 2.0);
    assert!(toml::from_str::<ScanConfig>("probe_per_stop = 3\n").is_err());
}
