//! A full scan against the XBee coordinator emulator through a real pty
//! (`tokio_serial::SerialStream::pair()`): the antenna is a `SimulatedStepper`, each beacon's
//! RSSI is log-distance path loss plus the reflector pattern at the stepper's current angle,
//! and the probe is the XBee client's `ND` round (RSSI byte appended to each record).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{seed_beacons, truth};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_bearing::{
    EstimatorConfig, PathLossModel, ReflectorPattern, RssiProbe, ScanConfig, ScanRunner,
};
use rfloc_pose::angle_diff;
use rfloc_stepper::{SimulatedStepper, StepperConfig};
use rfloc_xbee::{
    ApiMode, Beacon, ClientConfig, CoordinatorEmulator, EmulatorConfig, NdLayout, NdLayoutHint,
    RssiFn, XBeeClient, XBeeError,
};
use tokio_serial::SerialStream;

/// [`RssiProbe`] over one `ND` round of the XBee client: beacon id = 64-bit address.
struct NdProbe(XBeeClient<SerialStream>);

impl RssiProbe for NdProbe {
    type Error = XBeeError;

    async fn rssi_all(&mut self) -> Result<Vec<(u64, f64)>, XBeeError> {
        let d = self.0.discover().await?;
        Ok(d.nodes
            .iter()
            .filter_map(|n| n.rssi_dbm().map(|r| (n.address.0, r)))
            .collect())
    }
}

const SHADOW_DB: f64 = 3.0;
const NOISE_DB: f64 = 2.0;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scan_through_emulator_recovers_seed_layout() {
    let world = seed_beacons(); // ids 1..=4 at the corners of a 3 m square
    let xbees: Vec<Beacon> = (1..=4).map(Beacon::numbered).collect();
    let robot_xy = (1.0, 1.0);
    let heading = Arc::new(AtomicU64::new(0f64.to_bits()));

    let stepper = SimulatedStepper::new(&StepperConfig::default()).unwrap(); // 1.8°/step
    let antenna = stepper.angle_probe();
    let model = PathLossModel::default();
    let pattern = ReflectorPattern::default();
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let shadow: Vec<f64> = world
        .iter()
        .map(|_| Normal::new(0.0, SHADOW_DB).unwrap().sample(&mut rng))
        .collect();
    let rng = Mutex::new(rng);
    let noise = Normal::new(0.0, NOISE_DB).unwrap();
    let rssi: RssiFn = {
        let (world, heading, shadow) = (world.clone(), heading.clone(), shadow.clone());
        Arc::new(move |i: usize| {
            let b = world.get(i)?;
            let th = f64::from_bits(heading.load(Ordering::Acquire));
            let v = common::rssi(
                &model,
                &pattern,
                (robot_xy.0, robot_xy.1, th),
                antenna.get(),
                b,
            );
            let n = noise.sample(&mut *rng.lock().unwrap());
            Some(v + shadow.get(i)? + n)
        })
    };
    let emulator = CoordinatorEmulator::new(
        xbees.clone(),
        rssi,
        EmulatorConfig {
            mode: ApiMode::Escaped,
            nd_layout: NdLayout::ZigbeeOrDigiMesh,
            append_rssi: true,
            response_spacing: Duration::from_millis(1),
            ..EmulatorConfig::default()
        },
    );
    let (host, device) = SerialStream::pair().unwrap();
    let served = tokio::spawn(async move { emulator.serve(device).await });
    let client = XBeeClient::new(
        host,
        ClientConfig {
            mode: ApiMode::Escaped,
            nd_layout: NdLayoutHint::ZigbeeOrDigiMesh,
            response_timeout: Duration::from_millis(500),
            discovery_margin: Duration::from_millis(500),
            ..ClientConfig::default()
        },
    );

    let config = ScanConfig {
        probes_per_stop: 6,
        estimator: EstimatorConfig {
            path_loss: PathLossModel {
                shadowing_sigma_db: SHADOW_DB,
                ..PathLossModel::default()
            },
            ..EstimatorConfig::default()
        },
        ..ScanConfig::default()
    };
    let mut runner = ScanRunner::new(stepper, NdProbe(client), config).unwrap();
    let step = 9f64.to_radians();
    let sigma_ln = config.estimator.path_loss.sigma_ln();

    // Sweep 1 ascending with the robot heading 0; sweep 2 descending with the robot turned 0.5 rad.
    for (sweep_no, th) in [(1, 0.0f64), (2, 0.5)] {
        heading.store(th.to_bits(), Ordering::Release);
        let h = heading.clone();
        let result = runner
            .scan(move || f64::from_bits(h.load(Ordering::Acquire)))
            .await
            .unwrap();
        assert_eq!(result.sweep.samples.len(), 40);
        let first = result.sweep.samples[0].antenna_rad.to_degrees();
        assert!((first - if sweep_no == 1 { -180.0 } else { 171.0 }).abs() < 1e-9);
        for (b, x) in world.iter().zip(&xbees) {
            let o = result.report.beacons[&x.address.0].clone().unwrap();
            let (r_true, b_true) = truth(robot_xy.0, robot_xy.1, th, b);
            let be = angle_diff(o.bearing_rad, b_true);
            let re = (o.range_m / r_true).ln();
            println!(
                "sweep {sweep_no} beacon {}: bearing {:7.2}° (true {:7.2}°, err {:+5.2}°, σ {:4.2}°), \
                 range {:.3} m (true {:.3} m, err {:+.3} m, ln-ratio {:+.3}, model σ_ln {:.3})",
                b.id,
                o.bearing_rad.to_degrees(),
                b_true.to_degrees(),
                be.to_degrees(),
                o.bearing_variance_rad2.sqrt().to_degrees(),
                o.range_m,
                r_true,
                o.range_m - r_true,
                re,
                sigma_ln,
            );
            assert!(
                be.abs() < step,
                "beacon {} bearing error {}°",
                b.id,
                be.to_degrees()
            );
            assert!(
                re.abs() < 2.0 * sigma_ln,
                "beacon {} range ln-error {re}",
                b.id
            );
        }
    }
    // 100 steps from 0° to −180°, then 39 gaps of 5 steps up and 39 back down.
    let (stepper, probe) = runner.into_parts();
    assert_eq!(stepper.steps_travelled(), 100 + 2 * 39 * 5);
    let stats = probe.0.stats();
    drop(probe);
    let emu = served.await.unwrap().unwrap();
    assert_eq!(emu.nd_rounds, 2 * 40 * 6);
    assert_eq!(stats.decode.dropped_bytes, 0);
}
