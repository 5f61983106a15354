//! Closing the client ends its task and drops the link before the caller goes on: a serial port
//! stays locked while open, so a daemon backing off before a reconnect must not hold it; and a
//! recorded link's capture is complete on disk when `close` returns.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use rfloc_kts::{KtsClient, KtsConfig};
use rfloc_transport::{CaptureSink, ManualClock, Recorder};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

#[tokio::test]
async fn close_drops_the_link_before_it_returns() {
    let (ours, mut device) = tokio::io::duplex(1024);
    let client = KtsClient::spawn(
        ours,
        KtsConfig::default(),
        rfloc_transport::MonotonicClock::shared(),
    );
    client.close().await;
    // The device side sees the link closed at once (end of stream), not after a back-off.
    let mut buf = [0u8; 16];
    let n = tokio::time::timeout(Duration::from_millis(200), device.read(&mut buf))
        .await
        .expect("the link is still open after close()")
        .unwrap();
    assert_eq!(n, 0);
}

/// A simulated trial reads its captures as soon as the driver is closed. The last record is
/// still being coalesced in the sink until the task that owns the link drops it; `close` waits
/// for that. (On this single-threaded runtime, dropping the client instead would leave the
/// record out: the aborted task is only dropped when the runtime next runs.)
#[tokio::test]
async fn close_leaves_the_capture_complete_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("kts.cap");
    let clock = ManualClock::new();
    clock.set_ns(12_400_000_000);
    let header = rfloc_capture::Header::new("kts-rfidm1356", "duplex".to_string());
    let sink = CaptureSink::create(&path, &header, clock.clone()).unwrap();
    sink.set_coalescing(true);
    let (ours, mut device) = tokio::io::duplex(1024);
    let client = KtsClient::spawn(
        Recorder::new(ours, sink.clone()),
        KtsConfig::default(),
        clock,
    );
    let line = b"SCAN:+UID=E00401503A5BD691,+RSSI=0/0\r\n";
    device.write_all(line).await.unwrap();
    let read = async {
        while sink.rx_bytes() < line.len() as u64 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    };
    tokio::time::timeout(Duration::from_secs(5), read)
        .await
        .expect("the client never read the line");
    client.close().await;
    let capture = rfloc_capture::Capture::from_path(&path).unwrap();
    assert_eq!(capture.rx_bytes(), line.to_vec());
    assert_eq!(capture.records.len(), 1, "one coalesced record");
    assert!((capture.records[0].t() - 12.4).abs() < 1e-9);
}
