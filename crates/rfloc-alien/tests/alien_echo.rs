//! Echo handling with readers that echo commands and readers that do not: a reply identical to
//! its command (`PersistTime = 0` → `PersistTime = 0`) is the reply, not an echo, unless the
//! reader is known to echo.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::sync::Arc;

use rfloc_alien::{
    AlienClient, AlienConfig, EchoMode, EchoState, EmulatorOptions, PromptMode, ReaderEmulator,
    TagField, Transcript,
};
use rfloc_transport::MonotonicClock;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

async fn expect(dev: &mut DuplexStream, bytes: &[u8]) {
    let mut buf = vec![0u8; bytes.len()];
    dev.read_exact(&mut buf).await.unwrap();
    assert_eq!(
        String::from_utf8_lossy(&buf),
        String::from_utf8_lossy(bytes)
    );
}

/// An interactive reader with echo off, byte for byte: prompts, no echo.
#[tokio::test]
async fn interactive_reader_without_echo_byte_level() {
    let (client_io, mut dev) = tokio::io::duplex(4096);
    let device = tokio::spawn(async move {
        dev.write_all(b"* Alien *\r\nUsername>\0").await.unwrap();
        expect(&mut dev, b"alien\r\n").await;
        dev.write_all(b"Password>\0").await.unwrap();
        expect(&mut dev, b"password\r\n").await;
        dev.write_all(b"\r\nAlien>\0").await.unwrap();
        expect(&mut dev, b"PersistTime = 0\r\n").await;
        dev.write_all(b"PersistTime = 0\r\n\0\r\nAlien>\0")
            .await
            .unwrap();
        expect(&mut dev, b"get ReaderName\r\n").await;
        dev.write_all(b"ReaderName = Alien RFID Reader\r\n\0\r\nAlien>\0")
            .await
            .unwrap();
        expect(&mut dev, b"TagListFormat = Text\r\n").await;
        dev.write_all(b"TagListFormat = Text\r\n\0\r\nAlien>\0")
            .await
            .unwrap();
        dev
    });
    let config = AlienConfig {
        prompt_mode: PromptMode::Interactive,
        ..AlienConfig::default()
    };
    let mut c = AlienClient::connect(client_io, config, MonotonicClock::shared())
        .await
        .unwrap();
    assert_eq!(
        c.command("PersistTime = 0").await.unwrap(),
        "PersistTime = 0\r\n"
    );
    assert_eq!(c.echo_state(), EchoState::Unknown);
    assert_eq!(c.get("ReaderName").await.unwrap(), "Alien RFID Reader");
    assert_eq!(c.echo_state(), EchoState::Silent);
    assert_eq!(
        c.command("TagListFormat = Text").await.unwrap(),
        "TagListFormat = Text\r\n"
    );
    drop(device.await.unwrap());
}

/// The same session from a reader that echoes: the echo goes, the reply stays.
#[tokio::test]
async fn interactive_reader_with_echo_byte_level() {
    let (client_io, mut dev) = tokio::io::duplex(4096);
    let device = tokio::spawn(async move {
        dev.write_all(b"* Alien *\r\nUsername>\0").await.unwrap();
        expect(&mut dev, b"alien\r\n").await;
        dev.write_all(b"Password>\0").await.unwrap();
        expect(&mut dev, b"password\r\n").await;
        dev.write_all(b"\r\nAlien>\0").await.unwrap();
        expect(&mut dev, b"PersistTime = 0\r\n").await;
        dev.write_all(b"PersistTime = 0\r\nPersistTime = 0\r\n\0\r\nAlien>\0")
            .await
            .unwrap();
        expect(&mut dev, b"get ReaderName\r\n").await;
        dev.write_all(b"get ReaderName\r\nReaderName = Alien RFID Reader\r\n\0\r\nAlien>\0")
            .await
            .unwrap();
        dev
    });
    let config = AlienConfig {
        prompt_mode: PromptMode::Interactive,
        ..AlienConfig::default()
    };
    let mut c = AlienClient::connect(client_io, config, MonotonicClock::shared())
        .await
        .unwrap();
    assert_eq!(
        c.command("PersistTime = 0").await.unwrap(),
        "PersistTime = 0\r\n"
    );
    assert_eq!(c.echo_state(), EchoState::Echoes);
    assert_eq!(c.get("ReaderName").await.unwrap(), "Alien RFID Reader");
    drop(device.await.unwrap());
}

/// The transcript decoder pairs a no-echo session the same way.
#[test]
fn transcript_keeps_replies_equal_to_their_command() {
    let mut t = Transcript::new();
    t.push_reader(0.0, b"banner\r\nUsername>");
    t.push_client(b"alien\r\n");
    t.push_reader(0.1, b"Password>");
    t.push_client(b"password\r\n");
    t.push_reader(0.2, b"\r\nAlien>\0");
    t.push_client(b"PersistTime = 0\r\n");
    let ex = t.push_reader(0.3, b"PersistTime = 0\r\n\0\r\nAlien>\0");
    assert_eq!(ex.len(), 1);
    assert_eq!(ex[0].reply, "PersistTime = 0\r\n");
    t.push_client(b"get PersistTime\r\n");
    let ex = t.push_reader(0.4, b"PersistTime = 0\r\n\0\r\nAlien>\0");
    assert_eq!(ex[0].reply, "PersistTime = 0\r\n");
    assert_eq!(t.echo_state(), EchoState::Silent);
}

fn no_tags() -> TagField {
    Arc::new(Vec::new)
}

async fn session(mode: PromptMode, echo: EchoMode) -> (EchoState, Vec<String>) {
    let emu = ReaderEmulator::new(
        no_tags(),
        EmulatorOptions {
            echo,
            ..EmulatorOptions::default()
        },
    );
    let (addr, _task) = emu.bind_loopback().await.unwrap();
    let s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let config = AlienConfig {
        prompt_mode: mode,
        ..AlienConfig::default()
    };
    let mut c = AlienClient::connect(s, config, MonotonicClock::shared())
        .await
        .unwrap();
    let mut replies = Vec::new();
    for cmd in [
        "PersistTime = 0",
        "get PersistTime",
        "set PersistTime = 2",
        "t",
    ] {
        replies.push(c.command(cmd).await.unwrap());
    }
    (c.echo_state(), replies)
}

#[tokio::test]
async fn every_prompt_and_echo_combination_against_the_emulator() {
    let expected = [
        "PersistTime = 0\r\n",
        "PersistTime = 0\r\n",
        "PersistTime = 2\r\n",
        "(No Tags)\r\n",
    ];
    for (mode, echo, state) in [
        (
            PromptMode::Suppressed,
            EchoMode::Interactive,
            EchoState::Silent,
        ),
        (
            PromptMode::Interactive,
            EchoMode::Interactive,
            EchoState::Echoes,
        ),
        (PromptMode::Suppressed, EchoMode::Never, EchoState::Silent),
        (PromptMode::Interactive, EchoMode::Never, EchoState::Silent),
        (PromptMode::Suppressed, EchoMode::Always, EchoState::Echoes),
        (PromptMode::Interactive, EchoMode::Always, EchoState::Echoes),
    ] {
        let (learned, replies) = session(mode, echo).await;
        assert_eq!(replies, expected, "{mode:?} {echo:?}");
        assert_eq!(learned, state, "{mode:?} {echo:?}");
    }
}
