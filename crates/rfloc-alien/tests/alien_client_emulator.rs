//! The client against the emulator over real loopback TCP.
#![allow(clippy::unwrap_used)] // helpers outside #[test] fns

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_alien::{
    AlienClient, AlienConfig, AlienError, AlienSession, Backoff, Connector, EmulatorOptions,
    PromptMode, ReaderEmulator, ReaderSetup, SessionEnd, SnapshotReader, TagField, TagListFormat,
};
use rfloc_transport::MonotonicClock;
use tokio::net::TcpStream;

type Field = Arc<Mutex<Vec<(Vec<u8>, f64)>>>;

fn field() -> (Field, TagField) {
    let tags: Field = Arc::new(Mutex::new(vec![
        (
            vec![
                0xE2, 0x00, 0x90, 0x33, 0x13, 0x17, 0x00, 0x87, 0x04, 0x90, 0xE1, 0x33,
            ],
            2235.31,
        ),
        (vec![0x30, 0x00, 0x21, 0x41], 6556.84),
        (vec![0xAB; 32], -40.26),
    ]));
    let t = Arc::clone(&tags);
    (tags, Arc::new(move || t.lock().unwrap().clone()))
}

async fn emulator(options: EmulatorOptions) -> (ReaderEmulator, std::net::SocketAddr, Field) {
    let (tags, f) = field();
    let emu = ReaderEmulator::new(f, options);
    let (addr, _task) = emu.clone().bind_loopback().await.unwrap();
    (emu, addr, tags)
}

async fn connect(
    addr: std::net::SocketAddr,
    config: AlienConfig,
) -> Result<AlienClient<TcpStream>, AlienError> {
    let s = TcpStream::connect(addr).await.unwrap();
    AlienClient::connect(s, config, MonotonicClock::shared()).await
}

fn assert_field(tags: &[rfloc_alien::TagRead], with_rssi: bool) {
    let ids: Vec<String> = tags.iter().map(|t| t.id.to_string()).collect();
    assert_eq!(
        ids,
        [
            "E20090331317008704 90E133".replace(' ', ""),
            "30002141".to_string(),
            "AB".repeat(32)
        ]
    );
    if with_rssi {
        let rssi: Vec<f64> = tags.iter().map(|t| t.rssi.unwrap()).collect();
        assert_eq!(rssi, [2235.3, 6556.8, -40.3]);
    }
}

#[tokio::test]
async fn suppressed_mode_project_setup_and_snapshot() {
    let (emu, addr, tags) = emulator(EmulatorOptions::default()).await;
    let mut c = connect(addr, AlienConfig::default()).await.unwrap();
    c.apply_setup(&ReaderSetup::project()).await.unwrap();
    assert_eq!(emu.setting("TagListFormat").as_deref(), Some("Custom"));
    assert_eq!(c.get("PersistTime").await.unwrap(), "-1");
    assert_eq!(c.set("ReaderName", "robot").await.unwrap(), "robot");
    assert_eq!(c.get("readername").await.unwrap(), "robot");

    let snap = c.read_snapshot().await.unwrap();
    assert!(snap.malformed.is_empty());
    assert_field(&snap.tags, true);
    assert!(snap
        .tags
        .iter()
        .all(|t| t.count == Some(1) && t.antenna == Some(0)));
    assert!(snap
        .tags
        .iter()
        .all(|t| t.discovered.is_some() && t.last_seen.is_some()));

    tags.lock().unwrap().clear();
    assert!(c.read_snapshot().await.unwrap().tags.is_empty());

    match c.command("bogus").await {
        Err(AlienError::Reader {
            code: Some(1),
            text,
            ..
        }) => assert_eq!(text, "Command not understood."),
        other => panic!("{other:?}"),
    }
    match c.set("TagListFormat", "Pretty").await {
        Err(AlienError::Reader { code: Some(4), .. }) => {}
        other => panic!("{other:?}"),
    }
    c.keepalive().await.unwrap();
    c.quit().await.unwrap();
}

#[tokio::test]
async fn every_taglist_format_parses() {
    let (_emu, addr, _tags) = emulator(EmulatorOptions::default()).await;
    let mut c = connect(addr, AlienConfig::default()).await.unwrap();
    for (name, rssi) in [("Text", false), ("Terse", false), ("XML", false)] {
        c.set("TagListFormat", name).await.unwrap();
        assert_eq!(c.format().setting_name(), name);
        let snap = c.read_snapshot().await.unwrap();
        assert!(snap.malformed.is_empty(), "{name}: {:?}", snap.malformed);
        assert_field(&snap.tags, rssi);
    }
    c.set("TagListMillis", "ON").await.unwrap();
    c.set("TagListCustomFormat", "%k;${MSEC1};${MSEC2};%a;%m;%r")
        .await
        .unwrap();
    c.set("TagListFormat", "Custom").await.unwrap();
    assert!(matches!(c.format(), TagListFormat::Custom(_)));
    let snap = c.read_snapshot().await.unwrap();
    assert_field(&snap.tags, true);
}

#[tokio::test]
async fn interactive_mode_with_the_seed_setup() {
    let (_emu, addr, _tags) = emulator(EmulatorOptions::default()).await;
    let config = AlienConfig {
        prompt_mode: PromptMode::Interactive,
        ..AlienConfig::default()
    };
    let mut c = connect(addr, config).await.unwrap();
    c.apply_setup(&ReaderSetup::seed000()).await.unwrap();
    let snap = c.read_snapshot().await.unwrap();
    assert!(snap.malformed.is_empty());
    assert_field(&snap.tags, true);
    assert_eq!(c.get("NetworkTimeout").await.unwrap(), "65535");
    assert_eq!(c.stats().stray_frames, 0);
}

#[tokio::test]
async fn wrong_password_is_refused() {
    let (_emu, addr, _tags) = emulator(EmulatorOptions::default()).await;
    for mode in [PromptMode::Suppressed, PromptMode::Interactive] {
        let config = AlienConfig {
            password: "nope".into(),
            prompt_mode: mode,
            ..AlienConfig::default()
        };
        match connect(addr, config).await {
            Err(AlienError::LoginFailed(text)) => assert!(text.contains("Invalid"), "{text}"),
            other => panic!("{mode:?}: {:?}", other.map(|_| ())),
        }
    }
}

/// An emulator that echoes the credentials (a terminal with echo on): the right ones log in in
/// both modes, wrong ones are refused without the password in the error.
#[tokio::test]
async fn echoed_login_lines_are_skipped_and_never_reported() {
    let (_emu, addr, _tags) = emulator(EmulatorOptions {
        echo_login: true,
        ..EmulatorOptions::default()
    })
    .await;
    for mode in [PromptMode::Suppressed, PromptMode::Interactive] {
        let config = AlienConfig {
            prompt_mode: mode,
            ..AlienConfig::default()
        };
        let mut c = connect(addr, config).await.unwrap();
        assert_field(&c.read_snapshot().await.unwrap().tags, false);
        assert!(!format!("{c:?}").contains("password"), "{c:?}");

        let wrong = "Wr0ng-Secret";
        let config = AlienConfig {
            password: wrong.into(),
            prompt_mode: mode,
            ..AlienConfig::default()
        };
        let err = connect(addr, config).await.map(|_| ()).unwrap_err();
        assert!(err.is_auth_failure(), "{mode:?}: {err:?}");
        let (display, debug) = (err.to_string(), format!("{err:?}"));
        assert!(display.contains("Invalid"), "{display}");
        assert!(
            !display.contains(wrong) && !debug.contains(wrong),
            "{debug}"
        );
    }
}

#[tokio::test]
async fn second_client_is_told_busy() {
    let (_emu, addr, _tags) = emulator(EmulatorOptions {
        busy_when_occupied: true,
        ..EmulatorOptions::default()
    })
    .await;
    let _first = connect(addr, AlienConfig::default()).await.unwrap();
    match connect(addr, AlienConfig::default()).await {
        Err(AlienError::Session(SessionEnd::Busy)) => {}
        other => panic!("{:?}", other.map(|_| ())),
    }
}

#[tokio::test]
async fn idle_session_times_out_and_keepalive_prevents_it() {
    let options = EmulatorOptions {
        idle_timeout: Some(Duration::from_millis(600)),
        ..EmulatorOptions::default()
    };
    let (_emu, addr, _tags) = emulator(options).await;
    // Keepalives every ~110 ms keep the session open past the 600 ms idle limit.
    let config = AlienConfig {
        keepalive_interval: Duration::from_millis(100),
        ..AlienConfig::default()
    };
    let mut alive = connect(addr, config).await.unwrap();
    for _ in 0..9 {
        tokio::time::sleep(Duration::from_millis(110)).await;
        alive.keepalive_if_due().await.unwrap();
    }
    assert!(alive.stats().keepalives >= 8);
    // Without keepalives the reader says `Connection Timeout.` and closes.
    let mut idle = connect(addr, AlienConfig::default()).await.unwrap();
    match idle.next_unsolicited(Duration::from_secs(2)).await {
        Err(AlienError::Session(SessionEnd::ConnectionTimeout)) => {}
        other => panic!("{other:?}"),
    }
}

#[tokio::test]
async fn session_reconnects_and_reapplies_setup() {
    let options = EmulatorOptions {
        idle_timeout: Some(Duration::from_millis(150)),
        ..EmulatorOptions::default()
    };
    let (emu, addr, _tags) = emulator(options).await;
    let connector: Connector<TcpStream> = Arc::new(move || Box::pin(TcpStream::connect(addr)));
    let backoff = Backoff {
        initial: Duration::from_millis(20),
        max: Duration::from_millis(100),
        max_attempts: 5,
        ..Backoff::default()
    };
    let mut session = AlienSession::new(
        connector,
        AlienConfig::default(),
        ReaderSetup::project(),
        MonotonicClock::shared(),
        backoff,
    );
    assert_field(&session.read_snapshot().await.unwrap().tags, true);
    let sets_after_first = emu.set_commands();
    assert_eq!(sets_after_first, 6);
    // Let the reader drop the idle session; the next read reconnects and sets up again.
    tokio::time::sleep(Duration::from_millis(600)).await;
    assert_field(&session.read_snapshot().await.unwrap().tags, true);
    assert_eq!(session.connects(), 2);
    assert_eq!(emu.sessions(), 2);
    assert_eq!(emu.set_commands(), 2 * sets_after_first);
}

#[tokio::test]
async fn session_gives_up_after_backoff() {
    // Nothing listens on this port once the listener is dropped.
    let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = l.local_addr().unwrap();
    drop(l);
    let connector: Connector<TcpStream> = Arc::new(move || Box::pin(TcpStream::connect(addr)));
    let backoff = Backoff {
        initial: Duration::from_millis(5),
        max: Duration::from_millis(10),
        max_attempts: 3,
        ..Backoff::default()
    };
    let mut session = AlienSession::new(
        connector,
        AlienConfig::default(),
        ReaderSetup::project(),
        MonotonicClock::shared(),
        backoff,
    );
    match session.read_snapshot().await {
        Err(AlienError::Reconnect { attempts: 3, .. }) => {}
        other => panic!("{other:?}"),
    }
}
