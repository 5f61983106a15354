//! The client against the emulator over a real pseudo-terminal.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::sync::Arc;

use rfloc_urg::{EmulatorConfig, ScipError, UrgClient, UrgConfig, UrgEmulator, UrgGeometry};

/// A wall 2 m ahead across the whole field: range 2 / cos(angle) within ±60°, nothing beyond.
fn wall_ahead(angle: f64) -> Option<f64> {
    (angle.abs() < 60f64.to_radians()).then(|| 2.0 / angle.cos())
}

#[tokio::test]
async fn the_client_scans_the_emulated_sensor_over_a_pty() {
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let emulator = UrgEmulator::new(Arc::new(wall_ahead), EmulatorConfig::default());
    let server = tokio::spawn(async move { emulator.serve(master).await });
    let mut client = UrgClient::new(slave, UrgConfig::default());

    // Laser still off: the sensor refuses to measure (status 10).
    match client.scan().await {
        Err(ScipError::Status { status, .. }) => assert_eq!(&status, b"10"),
        other => panic!("{other:?}"),
    }
    client.laser_on().await.unwrap();
    client.laser_on().await.unwrap(); // already on: status 02, still fine
    let scan = client.scan().await.unwrap();
    let g = UrgGeometry::default();
    assert_eq!(scan.ranges_mm.len(), 682, "steps 44..=725");
    let beams: Vec<(f64, Option<f64>)> = scan.beams(&g).collect();
    let front = beams
        .iter()
        .min_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        .unwrap();
    assert_eq!(front.1, Some(2.0), "straight ahead");
    for (angle, range) in &beams {
        match wall_ahead(*angle) {
            Some(m) if m <= 5.6 => {
                let got = range.unwrap();
                assert!((got - m).abs() <= 0.0005 + 1e-9, "{angle}: {got} vs {m}");
            }
            _ => assert!(range.is_none(), "{angle}: {range:?}"),
        }
    }
    client.laser_off().await.unwrap();
    assert_eq!(client.stats().bad_replies, 0);
    drop(client);
    // A pty's master side reads EOF or EIO once the slave is closed.
    match server.await.unwrap() {
        Ok(stats) => assert_eq!((stats.scans, stats.unknown_commands), (2, 0)),
        Err(e) => assert_eq!(e.raw_os_error(), Some(5), "{e}"),
    }
}

/// A sensor of another geometry (a UTM-30LX's `PP`): the client reads it in the handshake and
/// scans with it.
#[tokio::test]
async fn the_client_reads_the_geometry_from_pp() {
    let utm = UrgGeometry {
        steps_per_rev: 1440,
        front_step: 540,
        first_step: 0,
        last_step: 1080,
        min_mm: 23,
        max_mm: 30_000,
    };
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let emulator = UrgEmulator::new(
        Arc::new(wall_ahead),
        EmulatorConfig {
            geometry: utm,
            identity: rfloc_urg::SensorIdentity {
                model: "UTM-30LX(Hokuyo Automatic Co.,Ltd.)".into(),
                scan_rpm: 2400,
                ..rfloc_urg::SensorIdentity::default()
            },
            ..EmulatorConfig::default()
        },
    );
    let server = tokio::spawn(async move { emulator.serve(master).await });
    let (mut client, info) = UrgClient::connect(slave, UrgConfig::default())
        .await
        .unwrap();
    assert_eq!(info.geometry, Some(utm));
    assert_eq!(client.geometry(), utm);
    assert_eq!(info.field("PROT"), Some("SCIP 2.0"));
    assert_eq!(info.field("SCAN"), Some("2400"));
    client.laser_on().await.unwrap();
    let scan = client.scan().await.unwrap();
    assert_eq!((scan.start_step, scan.end_step), (0, 1080));
    assert_eq!(scan.ranges_mm.len(), 1081);
    assert_eq!(scan.ranges_mm[540], 2000, "the wall straight ahead");
    drop(client);
    let _ = server.await.unwrap();
}
