//! A reader that echoes the credentials and refuses them: the password never reaches an error's
//! `Display`/`Debug`, nor a log line. Reply text that becomes an error carries no control
//! characters.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_alien::{AlienClient, AlienConfig, AlienError, PromptMode};
use rfloc_transport::MonotonicClock;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

const PASSWORD: &str = "S3cr3t-pw!";

/// Reads one line (up to and including `\n`) the client wrote.
async fn read_line(dev: &mut DuplexStream) -> Vec<u8> {
    let mut line = Vec::new();
    let mut b = [0u8; 1];
    while dev.read(&mut b).await.unwrap() == 1 {
        line.push(b[0]);
        if b[0] == b'\n' {
            break;
        }
    }
    line
}

/// How the scripted reader answers the password line (which it is given, as received).
type Answer = fn(&[u8]) -> Vec<u8>;

/// The brief's reader: the password line echoed as received (`\x01` included), then the error.
fn echo_as_received(line: &[u8]) -> Vec<u8> {
    [line, b"Error: Invalid username/password\r\n\0Username>\0"].concat()
}

/// Echo without the `\x01` and without a line end, glued to the error.
fn echo_glued(line: &[u8]) -> Vec<u8> {
    let pw = line.strip_prefix(b"\x01").unwrap_or(line);
    let pw = pw.strip_suffix(b"\r\n").unwrap_or(pw);
    [pw, b"Error: Invalid username/password\r\n\0"].concat()
}

/// The echo as a frame of its own, then the error frame.
fn echo_own_frame(line: &[u8]) -> Vec<u8> {
    [line, b"\0Error: Invalid username/password\r\n\0"].concat()
}

/// A bare LF echo (the reader turned CR LF into LF) and a new `Username>` prompt.
fn echo_lf_then_prompt(line: &[u8]) -> Vec<u8> {
    let pw = line.strip_suffix(b"\r\n").unwrap_or(line);
    [pw, b"\nInvalid login\r\nUsername>"].concat()
}

/// A reader that echoes the login lines and refuses the password with `answer`.
async fn refusing_reader(mut dev: DuplexStream, interactive: bool, answer: Answer) -> Vec<u8> {
    dev.write_all(b"* Alien *\r\nUsername>\0").await.unwrap();
    // A client that gives up early closes the link: writes may fail from here on.
    let user = read_line(&mut dev).await;
    let _ = dev.write_all(&user).await;
    let _ = dev
        .write_all(if interactive { b"Password>\0" } else { b"\0" })
        .await;
    let pass = read_line(&mut dev).await;
    let _ = dev.write_all(&answer(&pass)).await;
    let _ = dev.flush().await;
    // Hold the link open until the client gives up, so that the error is the reader's reply.
    let mut rest = Vec::new();
    let _ = dev.read_to_end(&mut rest).await;
    pass
}

/// Collects every log line (all levels) written while the guard lives.
#[derive(Clone, Default)]
struct LogBuffer(Arc<Mutex<Vec<u8>>>);

impl Write for LogBuffer {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl LogBuffer {
    fn install(&self) -> tracing::subscriber::DefaultGuard {
        let me = self.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_max_level(tracing::Level::TRACE)
            .with_ansi(false)
            .with_writer(move || me.clone())
            .finish();
        tracing::subscriber::set_default(subscriber)
    }
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.0.lock().unwrap()).into_owned()
    }
}

fn assert_no_password(what: &str, text: &str) {
    assert!(
        !text.contains(PASSWORD),
        "{what} holds the password: {text}"
    );
    // Nor a large piece of it.
    assert!(
        !text.contains("S3cr3t"),
        "{what} holds part of the password: {text}"
    );
}

fn assert_printable(what: &str, text: &str) {
    assert!(
        !text.chars().any(char::is_control),
        "{what} holds control characters: {text:?}"
    );
}

#[tokio::test]
async fn echoed_password_never_reaches_a_login_error() {
    let logs = LogBuffer::default();
    let _guard = logs.install();
    let answers: [(&str, Answer); 4] = [
        ("echo as received", echo_as_received),
        ("echo glued to the error", echo_glued),
        ("echo in its own frame", echo_own_frame),
        ("LF echo then Username>", echo_lf_then_prompt),
    ];
    for mode in [PromptMode::Suppressed, PromptMode::Interactive] {
        for (name, answer) in answers {
            // With prompts suppressed, the NUL after a bare echo is the (empty) answer that
            // logs in; the echo in a frame of its own is an interactive reader's.
            if mode == PromptMode::Suppressed && name == "echo in its own frame" {
                continue;
            }
            let (client_io, dev) = tokio::io::duplex(4096);
            let reader = tokio::spawn(refusing_reader(
                dev,
                mode == PromptMode::Interactive,
                answer,
            ));
            let config = AlienConfig {
                password: PASSWORD.into(),
                prompt_mode: mode,
                login_timeout: Duration::from_secs(2),
                ..AlienConfig::default()
            };
            let err = AlienClient::connect(client_io, config, MonotonicClock::shared())
                .await
                .map(|_| ())
                .expect_err("the reader refused the password");
            let sent = reader.await.unwrap();
            let display = err.to_string();
            let debug = format!("{err:?}");
            let case = format!("{mode:?}, {name}");
            assert!(
                matches!(err, AlienError::LoginFailed(_)),
                "{case}: a refusal, got {debug}"
            );
            assert!(
                display.contains("Invalid"),
                "{case}: the reader's reason is kept: {display}"
            );
            assert_no_password(&format!("{case}: Display"), &display);
            assert_no_password(&format!("{case}: Debug"), &debug);
            assert_printable(&format!("{case}: Display"), &display);
            assert!(
                String::from_utf8_lossy(&sent).contains(PASSWORD),
                "{case}: the reader was sent the password"
            );
        }
    }
    assert_no_password("the log", &logs.text());
}

/// A reader whose error text carries terminal escapes, a bell and a line break: the error's
/// text is one printable line.
#[tokio::test]
async fn control_characters_do_not_reach_error_text() {
    let (client_io, mut dev) = tokio::io::duplex(4096);
    let reader = tokio::spawn(async move {
        dev.write_all(b"Username>\0").await.unwrap();
        read_line(&mut dev).await;
        dev.write_all(b"\0").await.unwrap();
        read_line(&mut dev).await;
        dev.write_all(b"\0").await.unwrap();
        read_line(&mut dev).await;
        dev.write_all(b"Error 1: \x1b[2J\x1b[31mred\x07\r\nWARN forged log line\0")
            .await
            .unwrap();
        read_line(&mut dev).await;
        dev.write_all(b"Name\x1b]0;title\x07 without equals\r\nsecond line\0")
            .await
            .unwrap();
        dev
    });
    let mut c = AlienClient::connect(client_io, AlienConfig::default(), MonotonicClock::shared())
        .await
        .unwrap();
    let err = c.command("bogus").await.unwrap_err();
    let AlienError::Reader { code, text, .. } = &err else {
        panic!("{err:?}");
    };
    assert_eq!(*code, Some(1));
    assert_printable("reader error text", text);
    assert!(text.contains("red"), "{text}");
    assert_printable("reader error", &err.to_string());

    let err = c.get("ReaderName").await.unwrap_err();
    assert!(matches!(err, AlienError::Unexpected { .. }), "{err:?}");
    assert_printable("unexpected reply", &err.to_string());
    assert!(err.to_string().contains("second line"), "{err}");
    drop(reader.await.unwrap());
}
