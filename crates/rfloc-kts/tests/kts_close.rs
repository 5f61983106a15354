//! Closing the client ends its task and drops the link before the caller goes on: a serial port
//! stays locked while open, so a daemon backing off before a reconnect must not hold it.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use rfloc_kts::{KtsClient, KtsConfig};
use tokio::io::AsyncReadExt;

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
