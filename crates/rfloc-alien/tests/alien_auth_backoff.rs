//! Refused credentials are not retried before the authentication back-off: a separate, growing,
//! capped policy much longer than the link back-off. The session reports the refusal as an
//! authentication failure, without the password.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_alien::{
    AlienConfig, AlienError, AlienSession, Backoff, Connector, EmulatorOptions, ReaderEmulator,
    ReaderSetup, SnapshotReader,
};
use rfloc_transport::MonotonicClock;
use tokio::io::DuplexStream;
use tokio::time::Instant;

const CONFIGURED: &str = "0ld-Passw0rd";

fn one_tag() -> rfloc_alien::TagField {
    Arc::new(|| vec![(vec![0x30, 0x00, 0x21, 0x41], 1500.0)])
}

/// A connector to `readers[min(dial, last)]` over in-memory links; records when it dials.
fn connector(readers: Vec<ReaderEmulator>) -> (Connector<DuplexStream>, Arc<Mutex<Vec<Instant>>>) {
    let dials = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&dials);
    let c: Connector<DuplexStream> = Arc::new(move || {
        let mut log = log.lock().unwrap();
        let emu = readers[log.len().min(readers.len() - 1)].clone();
        log.push(Instant::now());
        let (client_io, dev) = tokio::io::duplex(4096);
        tokio::spawn(async move {
            let _ = emu.serve_stream(dev).await;
        });
        Box::pin(async move { Ok(client_io) })
    });
    (c, dials)
}

fn reader(password: &str) -> ReaderEmulator {
    ReaderEmulator::new(
        one_tag(),
        EmulatorOptions {
            password: password.into(),
            echo_login: true,
            ..EmulatorOptions::default()
        },
    )
}

fn session(connector: Connector<DuplexStream>, auth: Backoff) -> AlienSession<DuplexStream> {
    let link = Backoff {
        initial: Duration::from_millis(100),
        max: Duration::from_millis(400),
        max_attempts: 3,
        jitter_percent: 0,
        seed: 0,
    };
    AlienSession::new(
        connector,
        AlienConfig {
            password: CONFIGURED.into(),
            ..AlienConfig::default()
        },
        ReaderSetup::project(),
        MonotonicClock::shared(),
        link,
    )
    .with_auth_backoff(auth)
}

fn gaps(dials: &[Instant]) -> Vec<Duration> {
    dials.windows(2).map(|w| w[1] - w[0]).collect()
}

#[tokio::test(start_paused = true)]
async fn refused_logins_back_off_doubling_to_the_cap() {
    let (connector, dials) = connector(vec![reader("changed-on-the-reader")]);
    let auth = Backoff {
        initial: Duration::from_secs(60),
        max: Duration::from_secs(240),
        max_attempts: 1,
        jitter_percent: 0,
        seed: 0,
    };
    let mut s = session(connector, auth);
    let expected = [60, 120, 240, 240, 240].map(Duration::from_secs);
    for (i, retry) in expected.iter().enumerate() {
        let err = s.read_snapshot().await.unwrap_err();
        let AlienError::AuthFailed {
            failures,
            retry_in,
            reason,
        } = &err
        else {
            panic!("an authentication failure, got {err:?}");
        };
        assert_eq!(*failures as usize, i + 1);
        assert_eq!(retry_in, retry);
        assert_eq!(err.retry_in(), Some(*retry));
        assert!(err.is_auth_failure() && !err.needs_reconnect());
        assert!(reason.contains("Invalid"), "{reason}");
        for text in [err.to_string(), format!("{err:?}")] {
            assert!(!text.contains(CONFIGURED), "{text}");
        }
        assert_eq!(s.auth_failures() as usize, i + 1);
    }
    // One dial per refusal (no link retries), spaced by the back-off before each.
    let dials = dials.lock().unwrap().clone();
    assert_eq!(dials.len(), 5);
    for (gap, want) in gaps(&dials).iter().zip(expected) {
        assert!(
            *gap >= want && *gap < want + Duration::from_secs(1),
            "{gap:?} vs {want:?}"
        );
    }
    assert_eq!(s.connects(), 0);
    assert_eq!(s.dials(), 5);
}

#[tokio::test(start_paused = true)]
async fn jittered_auth_backoff_follows_its_seeded_sequence_and_resets_on_success() {
    // The reader refuses twice, then the password is put right on the reader.
    let (connector, dials) = connector(vec![
        reader("changed-on-the-reader"),
        reader("changed-on-the-reader"),
        reader(CONFIGURED),
    ]);
    let auth = Backoff::authentication().with_seed_from("uhf0");
    let mut s = session(connector, auth);
    let started = Instant::now();
    for n in 0..2 {
        let err = s.read_snapshot().await.unwrap_err();
        assert_eq!(err.retry_in(), Some(auth.delay(n)), "{err}");
    }
    assert_eq!(s.read_snapshot().await.unwrap().tags.len(), 1);
    assert_eq!(s.auth_failures(), 0);
    assert_eq!(s.connects(), 1);
    let dials = dials.lock().unwrap().clone();
    let gaps = gaps(&dials);
    assert_eq!(gaps.len(), 2);
    for (n, gap) in gaps.iter().enumerate() {
        let want = auth.delay(u32::try_from(n).unwrap());
        assert!(
            *gap >= want && *gap < want + Duration::from_secs(1),
            "{gap:?} vs {want:?}"
        );
        // Much longer than any link back-off, and jittered below the doubling.
        assert!(
            want >= Duration::from_secs(48) * (1 << n)
                && want <= Duration::from_secs(60) * (1 << n)
        );
    }
    assert!(started.elapsed() < Duration::from_secs(60 + 120 + 1));
}

/// A link failure is not an authentication failure: it is retried on the short back-off.
#[tokio::test(start_paused = true)]
async fn link_failures_keep_the_short_backoff() {
    let dials = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&dials);
    let connector: Connector<DuplexStream> = Arc::new(move || {
        log.lock().unwrap().push(Instant::now());
        Box::pin(async { Err(std::io::Error::other("connection refused")) })
    });
    let mut s = session(connector, Backoff::authentication());
    let err = s.read_snapshot().await.unwrap_err();
    assert!(
        matches!(err, AlienError::Reconnect { attempts: 3, .. }),
        "{err:?}"
    );
    assert!(!err.is_auth_failure());
    let dials = dials.lock().unwrap().clone();
    assert_eq!(
        gaps(&dials),
        [Duration::from_millis(100), Duration::from_millis(200)]
    );
}
