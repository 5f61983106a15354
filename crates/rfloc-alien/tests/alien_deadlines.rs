//! Every exchange with the reader has a deadline: a peer whose bytes never form the awaited
//! reply (endless garbage, a slow drip, stray prompts) fails the login or command in time, the
//! error says so, and the session dials again.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{
    AlienClient, AlienConfig, AlienError, AlienSession, Backoff, Connector, EmulatorOptions,
    ReaderEmulator, ReaderSetup, SnapshotReader,
};
use rfloc_transport::MonotonicClock;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

/// xorshift64*: the garbage is the same on every run.
fn garbage(seed: u64, n: usize) -> Vec<u8> {
    let mut x = seed.max(1);
    (0..n)
        .map(|_| {
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
        })
        .collect()
}

/// Sends random bytes (NULs and `>` included) as fast as the client reads them, forever.
async fn garbage_peer(mut dev: DuplexStream, seed: u64) {
    let chunk = garbage(seed, 4096);
    assert!(chunk.contains(&0) && chunk.contains(&b'>'));
    while dev.write_all(&chunk).await.is_ok() {
        tokio::task::yield_now().await;
    }
}

/// Sends `pattern` one byte every 100 ms, forever, reading (and dropping) what the client sends.
async fn drip_peer(dev: DuplexStream, pattern: &'static [u8]) {
    let (mut rx, mut tx) = tokio::io::split(dev);
    tokio::spawn(async move {
        let mut sink = [0u8; 256];
        while rx.read(&mut sink).await.unwrap_or(0) > 0 {}
    });
    for &b in pattern.iter().cycle() {
        tokio::time::sleep(Duration::from_millis(100)).await;
        if tx.write_all(&[b]).await.is_err() {
            return;
        }
    }
}

fn assert_timeout(err: &AlienError) {
    assert!(
        matches!(err, AlienError::Timeout { .. }),
        "a timeout, got {err:?}"
    );
    assert!(err.needs_reconnect(), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("no complete reply"),
        "the error says so: {text}"
    );
}

#[tokio::test]
async fn garbage_stream_fails_the_login_within_its_deadline() {
    let (client_io, dev) = tokio::io::duplex(4096);
    tokio::spawn(garbage_peer(dev, 0x5eed));
    let config = AlienConfig {
        login_timeout: Duration::from_millis(300),
        ..AlienConfig::default()
    };
    let started = std::time::Instant::now();
    let err = tokio::time::timeout(
        Duration::from_secs(10),
        AlienClient::connect(client_io, config, MonotonicClock::shared()),
    )
    .await
    .expect("the login gives up by itself")
    .map(|_| ())
    .unwrap_err();
    assert_timeout(&err);
    assert!(
        err.to_string().contains("bytes"),
        "the error counts the bytes that formed no reply: {err}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

#[tokio::test(start_paused = true)]
async fn dripping_bytes_do_not_extend_the_login_deadline() {
    let (client_io, dev) = tokio::io::duplex(4096);
    // A NUL every 0.6 s: a stream of tiny frames, none of them a prompt.
    tokio::spawn(drip_peer(dev, b"noise\0"));
    let config = AlienConfig {
        login_timeout: Duration::from_secs(2),
        ..AlienConfig::default()
    };
    let started = Instant::now();
    let err = tokio::time::timeout(
        Duration::from_secs(60),
        AlienClient::connect(client_io, config, MonotonicClock::shared()),
    )
    .await
    .expect("the login gives up by itself")
    .map(|_| ())
    .unwrap_err();
    let took = started.elapsed();
    assert_timeout(&err);
    assert!(
        took >= Duration::from_secs(2) && took < Duration::from_millis(2100),
        "{took:?}"
    );
}

/// Logs in (prompts suppressed), then answers nothing but a slow drip of stray prompts.
async fn stray_prompt_peer(mut dev: DuplexStream) {
    let mut buf = [0u8; 256];
    dev.write_all(b"Username>\0").await.unwrap();
    let _ = dev.read(&mut buf).await;
    dev.write_all(b"\0").await.unwrap();
    let _ = dev.read(&mut buf).await;
    dev.write_all(b"\0").await.unwrap();
    drip_peer(dev, b"\r\nAlien>").await;
}

#[tokio::test(start_paused = true)]
async fn stray_prompts_do_not_extend_a_command_deadline() {
    let (client_io, dev) = tokio::io::duplex(4096);
    tokio::spawn(stray_prompt_peer(dev));
    let config = AlienConfig {
        reply_timeout: Duration::from_secs(1),
        ..AlienConfig::default()
    };
    let mut c = AlienClient::connect(client_io, config, MonotonicClock::shared())
        .await
        .unwrap();
    let started = Instant::now();
    let err = tokio::time::timeout(Duration::from_secs(60), c.read_snapshot())
        .await
        .expect("the command gives up by itself")
        .unwrap_err();
    let took = started.elapsed();
    assert_timeout(&err);
    assert!(
        took >= Duration::from_secs(1) && took < Duration::from_millis(1100),
        "{took:?}"
    );
}

fn no_tags() -> rfloc_alien::TagField {
    Arc::new(|| vec![(vec![0x30, 0x00, 0x21, 0x41], 1500.0)])
}

/// A connector whose first link is `bad` and later ones a working emulator; counts dials.
fn bad_then_good(
    bad: fn(DuplexStream) -> tokio::task::JoinHandle<()>,
) -> (Connector<DuplexStream>, Arc<AtomicU64>) {
    let dials = Arc::new(AtomicU64::new(0));
    let emu = ReaderEmulator::new(no_tags(), EmulatorOptions::default());
    let counter = Arc::clone(&dials);
    let connector: Connector<DuplexStream> = Arc::new(move || {
        let n = counter.fetch_add(1, Ordering::SeqCst);
        let (client_io, dev) = tokio::io::duplex(4096);
        if n == 0 {
            drop(bad(dev));
        } else {
            let emu = emu.clone();
            tokio::spawn(async move {
                let _ = emu.serve_stream(dev).await;
            });
        }
        Box::pin(async move { Ok(client_io) })
    });
    (connector, dials)
}

fn quick_backoff() -> Backoff {
    Backoff {
        initial: Duration::from_millis(10),
        max: Duration::from_millis(10),
        max_attempts: 3,
        jitter_percent: 0,
        seed: 0,
    }
}

#[tokio::test]
async fn session_dials_again_after_a_garbage_peer() {
    let (connector, dials) = bad_then_good(|dev| tokio::spawn(garbage_peer(dev, 7)));
    let config = AlienConfig {
        login_timeout: Duration::from_millis(300),
        ..AlienConfig::default()
    };
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        MonotonicClock::shared(),
        quick_backoff(),
    );
    let snap = tokio::time::timeout(Duration::from_secs(10), session.read_snapshot())
        .await
        .expect("the session gives the garbage peer up")
        .unwrap();
    assert_eq!(snap.tags.len(), 1);
    assert_eq!(dials.load(Ordering::SeqCst), 2);
    assert_eq!(session.connects(), 1);
}

#[tokio::test(start_paused = true)]
async fn session_dials_again_after_a_dripping_peer() {
    let (connector, dials) = bad_then_good(|dev| tokio::spawn(drip_peer(dev, b"x\0")));
    let config = AlienConfig {
        login_timeout: Duration::from_secs(2),
        ..AlienConfig::default()
    };
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        MonotonicClock::shared(),
        quick_backoff(),
    );
    let started = Instant::now();
    let snap = tokio::time::timeout(Duration::from_secs(60), session.read_snapshot())
        .await
        .expect("the session gives the dripping peer up")
        .unwrap();
    assert_eq!(snap.tags.len(), 1);
    assert_eq!(dials.load(Ordering::SeqCst), 2);
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

/// Logs in, then answers `t` with an endless reply (no NUL).
async fn endless_reply_peer(mut dev: DuplexStream) {
    let mut buf = [0u8; 256];
    dev.write_all(b"Username>\0").await.unwrap();
    let _ = dev.read(&mut buf).await;
    dev.write_all(b"\0").await.unwrap();
    let _ = dev.read(&mut buf).await;
    dev.write_all(b"\0").await.unwrap();
    let _ = dev.read(&mut buf).await;
    let line = b"Tag:E200 9033 1317 0087 0490 E133, Disc:2024/01/01 00:00:00, Count:1, Ant:0\r\n";
    while dev.write_all(line).await.is_ok() {}
}

#[tokio::test(start_paused = true)]
async fn a_reply_over_the_limit_is_an_error_at_once() {
    let (client_io, dev) = tokio::io::duplex(4096);
    tokio::spawn(endless_reply_peer(dev));
    let config = AlienConfig {
        max_reply_len: 16 * 1024,
        ..AlienConfig::default()
    };
    let mut c = AlienClient::connect(client_io, config, MonotonicClock::shared())
        .await
        .unwrap();
    let started = Instant::now();
    let err = tokio::time::timeout(Duration::from_secs(60), c.read_snapshot())
        .await
        .expect("the overlong reply ends the command")
        .unwrap_err();
    assert!(
        matches!(err, AlienError::ReplyTooLong { limit: 16384, .. }),
        "{err:?}"
    );
    assert!(err.needs_reconnect());
    assert!(err.to_string().contains("longer than 16384 bytes"), "{err}");
    // Not the deadline: the limit ended it.
    assert!(started.elapsed() < Duration::from_secs(1));
}

#[tokio::test(start_paused = true)]
async fn a_connector_that_never_connects_times_out() {
    let connector: Connector<DuplexStream> =
        Arc::new(|| Box::pin(std::future::pending::<std::io::Result<DuplexStream>>()));
    let config = AlienConfig {
        connect_timeout: Duration::from_secs(2),
        ..AlienConfig::default()
    };
    let backoff = Backoff {
        initial: Duration::from_millis(10),
        max: Duration::from_millis(10),
        max_attempts: 2,
        jitter_percent: 0,
        seed: 0,
    };
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        MonotonicClock::shared(),
        backoff,
    );
    let started = Instant::now();
    let err = tokio::time::timeout(Duration::from_secs(60), session.read_snapshot())
        .await
        .expect("the session gives up by itself")
        .unwrap_err();
    let AlienError::Reconnect { attempts, last } = &err else {
        panic!("{err:?}");
    };
    assert_eq!(*attempts, 2);
    assert!(last.contains("\"connect\" within 2s"), "{last}");
    assert_eq!(session.dials(), 2);
    assert_eq!(started.elapsed(), Duration::from_millis(4010));
}

/// The first link logs in and then answers its first command with nothing but stray prompts:
/// that command times out and the session dials again.
#[tokio::test(start_paused = true)]
async fn session_dials_again_after_a_command_times_out() {
    let (connector, dials) = bad_then_good(|dev| tokio::spawn(stray_prompt_peer(dev)));
    let config = AlienConfig {
        reply_timeout: Duration::from_secs(1),
        ..AlienConfig::default()
    };
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        MonotonicClock::shared(),
        quick_backoff(),
    );
    let started = Instant::now();
    let snap = tokio::time::timeout(Duration::from_secs(60), session.read_snapshot())
        .await
        .expect("the session gives the silent reader up")
        .unwrap();
    assert_eq!(snap.tags.len(), 1);
    assert_eq!(dials.load(Ordering::SeqCst), 2);
    assert_eq!(session.connects(), 1);
    let took = started.elapsed();
    assert!(
        took >= Duration::from_secs(1) && took < Duration::from_millis(1100),
        "{took:?}"
    );
}
