//! The client against the coordinator emulator through a real pty
//! (`tokio_serial::SerialStream::pair()`), in both API modes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use rfloc_xbee::{
    Address64, ApiMode, AtCommandName, AtStatus, Beacon, BeaconRadio, ClientConfig,
    CoordinatorEmulator, DiscoveryEnd, EmulatorConfig, NdLayout, NdLayoutHint, RssiFn, RssiSource,
    XBeeClient,
};
use tokio_serial::SerialStream;

fn beacons() -> Vec<Beacon> {
    (1..=4).map(Beacon::numbered).collect()
}

/// Beacon i at −50 − 7i dBm; beacon index 2 (`beacon3`) is not heard.
fn fixed_rssi() -> RssiFn {
    Arc::new(|i: usize| (i != 2).then(|| -50.0 - 7.0 * i as f64))
}

fn start(
    emulator: CoordinatorEmulator,
    mode: ApiMode,
) -> (
    XBeeClient<SerialStream>,
    tokio::task::JoinHandle<std::io::Result<rfloc_xbee::EmulatorStats>>,
) {
    let (host, device) = SerialStream::pair().unwrap();
    let task = tokio::spawn(async move { emulator.serve(device).await });
    let config = ClientConfig {
        mode,
        response_timeout: Duration::from_millis(500),
        remote_timeout: Duration::from_millis(500),
        discovery_margin: Duration::from_millis(200),
        ..ClientConfig::default()
    };
    (XBeeClient::new(host, config), task)
}

async fn discovery_and_rssi(mode: ApiMode, append_rssi: bool) {
    let config = EmulatorConfig {
        mode,
        append_rssi,
        ..EmulatorConfig::default()
    };
    let emulator = CoordinatorEmulator::new(beacons(), fixed_rssi(), config);
    let (mut client, task) = start(emulator, mode);

    let ap = client.at_command_ok(AtCommandName::AP, &[]).await.unwrap();
    assert_eq!(ap, vec![mode.ap_value()]);

    let discovery = client
        .discover_with_timeout(Duration::from_millis(3200))
        .await
        .unwrap();
    assert_eq!(discovery.end, DiscoveryEnd::EndFrame);
    let nis: Vec<&str> = discovery.nodes.iter().map(|n| n.ni.as_str()).collect();
    assert_eq!(nis, ["beacon1", "beacon2", "beacon4"]);
    let addresses: Vec<Address64> = discovery.nodes.iter().map(|n| n.address).collect();
    assert_eq!(addresses, [0, 1, 3].map(|i| beacons()[i].address));
    let rssi: Vec<Option<f64>> = discovery.nodes.iter().map(|n| n.rssi_dbm()).collect();
    if append_rssi {
        assert_eq!(rssi, [Some(-50.0), Some(-57.0), Some(-71.0)]);
    } else {
        assert_eq!(rssi, [None, None, None]);
    }
    // The emulator took the NT that discover_with_timeout set.
    assert_eq!(
        client.at_command_ok(AtCommandName::NT, &[]).await.unwrap(),
        vec![0x20]
    );

    for (i, beacon) in beacons().iter().enumerate() {
        let expected = (i != 2).then(|| -50.0 - 7.0 * i as f64);
        assert_eq!(client.remote_rssi(beacon.address).await.unwrap(), expected);
        if let Some(dbm) = expected {
            // Local DB: the last packet the coordinator heard was this beacon's reply.
            assert_eq!(client.local_rssi().await.unwrap(), Some(dbm));
        }
    }
    let unknown = client
        .remote_at_command(Address64(0x42), AtCommandName::DB, &[])
        .await
        .unwrap();
    assert_eq!(unknown.status(), AtStatus::TxFailure);
    let invalid = client.at_command(AtCommandName(*b"ZZ"), &[]).await.unwrap();
    assert_eq!(invalid.status(), AtStatus::InvalidCommand);

    let stats = client.stats();
    assert_eq!(stats.decode.dropped_bytes, 0);
    assert_eq!((stats.stray_responses, stats.malformed_frames), (0, 0));
    drop(client);
    task.abort();
}

#[tokio::test]
async fn escaped_discovery_and_rssi_over_pty() {
    discovery_and_rssi(ApiMode::Escaped, false).await;
}

#[tokio::test]
async fn unescaped_discovery_and_rssi_over_pty() {
    discovery_and_rssi(ApiMode::Unescaped, false).await;
}

#[tokio::test]
async fn escaped_discovery_with_rssi_tail_over_pty() {
    discovery_and_rssi(ApiMode::Escaped, true).await;
}

/// Without the end frame the round ends on NT plus the margin, with the nodes collected.
#[tokio::test]
async fn discovery_ends_on_nt_timer_without_end_frame() {
    let config = EmulatorConfig {
        send_end_frame: false,
        ..EmulatorConfig::default()
    };
    let emulator = CoordinatorEmulator::new(beacons(), fixed_rssi(), config);
    let (mut client, task) = start(emulator, ApiMode::Escaped);
    let started = tokio::time::Instant::now();
    let discovery = client
        .discover_with_timeout(Duration::from_millis(100))
        .await
        .unwrap();
    let elapsed = started.elapsed();
    assert_eq!(discovery.end, DiscoveryEnd::Timeout);
    assert_eq!(discovery.nodes.len(), 3);
    // NT 100 ms + margin 200 ms; generous upper bound for a loaded machine.
    assert!(
        elapsed >= Duration::from_millis(300) && elapsed < Duration::from_secs(3),
        "{elapsed:?}"
    );
    task.abort();
}

/// 802.15.4 records (DB byte after SL) from the emulator, parsed with the Auto layout.
#[tokio::test]
async fn ieee802154_layout_over_pty() {
    let config = EmulatorConfig {
        nd_layout: NdLayout::Ieee802154,
        ..EmulatorConfig::default()
    };
    let emulator = CoordinatorEmulator::new(beacons(), fixed_rssi(), config);
    let (mut client, task) = start(emulator, ApiMode::Escaped);
    assert_eq!(client.config().nd_layout, NdLayoutHint::Auto);
    let discovery = client.discover().await.unwrap();
    let got: Vec<(String, Option<f64>, NdLayout)> = discovery
        .nodes
        .into_iter()
        .map(|n| (n.ni.clone(), n.rssi_dbm(), n.layout))
        .collect();
    assert_eq!(
        got,
        [
            ("beacon1".to_string(), Some(-50.0), NdLayout::Ieee802154),
            ("beacon2".to_string(), Some(-57.0), NdLayout::Ieee802154),
            ("beacon4".to_string(), Some(-71.0), NdLayout::Ieee802154),
        ]
    );
    task.abort();
}

/// Frame IDs wrap from 255 to 1 (never 0) and responses still match.
#[tokio::test]
async fn frame_ids_wrap_past_255() {
    let emulator = CoordinatorEmulator::new(beacons(), fixed_rssi(), EmulatorConfig::default());
    let (mut client, task) = start(emulator, ApiMode::Escaped);
    let mut ids = Vec::new();
    for _ in 0..260 {
        let r = client.at_command(AtCommandName::NT, &[]).await.unwrap();
        ids.push(r.frame_id);
    }
    assert_eq!(ids[..3], [1, 2, 3]);
    assert_eq!(ids[253..258], [254, 255, 1, 2, 3]);
    assert!(!ids.contains(&0));
    task.abort();
}

/// What a bearing scan does, written against the trait: the RSSI follows the antenna angle
/// that the simulator's function reads.
async fn scan<P: BeaconRadio>(
    probe: &mut P,
    angle: &AtomicUsize,
    steps: usize,
) -> Vec<Vec<Option<f64>>> {
    let nodes = probe.discover_nodes().await.unwrap();
    let mut table = Vec::new();
    for step in 0..steps {
        angle.store(step, Ordering::SeqCst);
        let mut row = Vec::new();
        for node in &nodes {
            row.push(probe.node_rssi(node.address).await.unwrap());
        }
        table.push(row);
    }
    table
}

#[tokio::test]
async fn rssi_follows_antenna_angle_through_probe_trait() {
    for source in [RssiSource::RemoteDb, RssiSource::LocalDbAfterRemote] {
        rssi_follows_antenna_angle(source).await;
    }
}

async fn rssi_follows_antenna_angle(source: RssiSource) {
    let angle = Arc::new(AtomicUsize::new(0));
    let seen = Arc::clone(&angle);
    // Beacon i is strongest when the antenna step equals i; −40 dBm on axis, −10 dB per step off.
    let rssi: RssiFn = Arc::new(move |i: usize| {
        let step = seen.load(Ordering::SeqCst);
        Some(-40.0 - 10.0 * step.abs_diff(i) as f64)
    });
    let emulator = CoordinatorEmulator::new(beacons(), rssi, EmulatorConfig::default());
    let (client, task) = start(emulator, ApiMode::Escaped);
    let config = ClientConfig {
        rssi_source: source,
        ..client.config().clone()
    };
    let mut client = XBeeClient::new(client.into_inner(), config);
    let table = scan(&mut client, &angle, 4).await;
    for (step, row) in table.iter().enumerate() {
        let best = row
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.partial_cmp(b.1).unwrap())
            .map(|(i, _)| i);
        assert_eq!(best, Some(step), "{source:?} row {row:?}");
        assert_eq!(row[step], Some(-40.0));
    }
    task.abort();
}
