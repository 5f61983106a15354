//! A reader emulator: banner, login, interactive and prompt-suppressed commands, get/set of the
//! settings the project uses, `t` answered from a supplied tag field, `Error 1` for unknown
//! commands, `Connection Timeout.` after idling, and optionally a busy refusal for a second
//! client.
//!
//! Settings live in the emulator, not the connection, so they survive reconnects as a real
//! reader's do. Reply texts follow `protocols/alien-alr9900.md` §1.4.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tracing::Instrument;

use crate::reader_time::{civil_from_unix, unix_from_civil, ReaderTime};
use rfloc_transport::SharedClock;

/// Supplies the tags in view and their RSSI (the simulator's field).
pub type TagField = Arc<dyn Fn() -> Vec<(Vec<u8>, f64)> + Send + Sync>;

const BANNER: &str = "***********************************************\r\n*\r\n* Alien Technology : RFID Reader\r\n*\r\n***********************************************\r\n\r\n";

/// When the emulated reader echoes a command line before its reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EchoMode {
    /// Interactive commands are echoed, prompt-suppressed (`\x01`) ones are not (an ALR-9900
    /// on its telnet port).
    #[default]
    Interactive,
    /// Never echo (a reader or terminal server with echo off).
    Never,
    /// Echo every command, suppressed or not.
    Always,
}

/// Emulator options.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    pub username: String,
    pub password: String,
    /// Idle limit; `None` = the `NetworkTimeout` setting in seconds.
    pub idle_timeout: Option<Duration>,
    /// Refuse a second client while one is connected (listener mode).
    pub busy_when_occupied: bool,
    /// Time base of the reader clock (tag times, `get Time`); `None` = the host's monotonic
    /// time. A simulation passes its simulated clock so that replies depend on it alone.
    pub clock: Option<SharedClock>,
    /// Echo of command lines.
    pub echo: EchoMode,
    /// Echo the username and password lines as received (`\x01` included), before the answer
    /// to each: a terminal server with echo on. A client must keep the password out of its
    /// errors.
    pub echo_login: bool,
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        Self {
            username: "alien".to_string(),
            password: "password".to_string(),
            idle_timeout: None,
            busy_when_occupied: false,
            clock: None,
            echo: EchoMode::default(),
            echo_login: false,
        }
    }
}

/// Canonical setting names and defaults.
const SETTINGS: [(&str, &str); 9] = [
    ("ReaderName", "Alien RFID Reader"),
    (
        "ReaderType",
        "Alien RFID Tag Reader, Model: ALR-9900 (rfloc emulator)",
    ),
    ("ReaderVersion", "rfloc-emulator"),
    ("PersistTime", "-1"),
    ("NetworkTimeout", "90"),
    ("TagListFormat", "Text"),
    (
        "TagListCustomFormat",
        "Tag:%i, Disc:%d %t, Last:%D %T, Count:%r, Ant:%a",
    ),
    ("TagListMillis", "OFF"),
    ("AntennaSequence", "0"),
];

#[derive(Debug)]
struct ReaderState {
    /// lower-case key → (canonical key, value)
    settings: BTreeMap<String, (String, String)>,
    /// Reader clock: Unix seconds at `set`, and when it was set.
    clock_base: (f64, Instant),
    /// With a time base: Unix seconds at `set`, and the time base then.
    simulated: Option<(SharedClock, f64, f64)>,
}

impl ReaderState {
    fn new(clock: Option<SharedClock>) -> Self {
        let settings = SETTINGS
            .iter()
            .map(|(k, v)| (k.to_ascii_lowercase(), ((*k).to_string(), (*v).to_string())))
            .collect();
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        Self {
            settings,
            clock_base: (now, Instant::now()),
            simulated: clock.map(|c| {
                let t = c.now();
                (c, 0.0, t)
            }),
        }
    }

    /// Sets the reader clock to `unix` seconds.
    fn set_clock(&mut self, unix: f64) {
        self.clock_base = (unix, Instant::now());
        if let Some((c, base, at)) = &mut self.simulated {
            *base = unix;
            *at = c.now();
        }
    }

    fn value(&self, key: &str) -> Option<&str> {
        self.settings
            .get(&key.to_ascii_lowercase())
            .map(|(_, v)| v.as_str())
    }

    fn now_unix(&self) -> f64 {
        match &self.simulated {
            Some((c, base, at)) => base + (c.now() - at),
            None => self.clock_base.0 + self.clock_base.1.elapsed().as_secs_f64(),
        }
    }

    /// (`YYYY/MM/DD`, `hh:mm:ss[.mmm]`) of the reader clock.
    fn date_time(&self) -> (String, String) {
        let now = self.now_unix().max(0.0);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let secs = now as u64;
        let (y, mo, d, h, mi, s) = civil_from_unix(secs);
        let millis = self
            .value("TagListMillis")
            .is_some_and(|v| v.eq_ignore_ascii_case("ON"));
        let time = if millis {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let ms = ((now - now.floor()) * 1000.0) as u32;
            format!("{h:02}:{mi:02}:{s:02}.{ms:03}")
        } else {
            format!("{h:02}:{mi:02}:{s:02}")
        };
        (format!("{y:04}/{mo:02}/{d:02}"), time)
    }
}

/// The emulated reader. Cheap to clone (shared state).
#[derive(Clone)]
pub struct ReaderEmulator {
    field: TagField,
    options: EmulatorOptions,
    state: Arc<Mutex<ReaderState>>,
    occupied: Arc<AtomicBool>,
    sessions: Arc<AtomicU64>,
    set_commands: Arc<AtomicU64>,
}

impl std::fmt::Debug for ReaderEmulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReaderEmulator")
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

enum Outcome {
    Reply(String),
    Close(String),
}

fn spaced_id(id: &[u8]) -> String {
    id.chunks(2)
        .map(|c| c.iter().map(|b| format!("{b:02X}")).collect::<String>())
        .collect::<Vec<_>>()
        .join(" ")
}

fn packed_id(id: &[u8]) -> String {
    id.iter().map(|b| format!("{b:02X}")).collect()
}

impl ReaderEmulator {
    #[must_use]
    pub fn new(field: TagField, options: EmulatorOptions) -> Self {
        Self {
            state: Arc::new(Mutex::new(ReaderState::new(options.clock.clone()))),
            field,
            options,
            occupied: Arc::new(AtomicBool::new(false)),
            sessions: Arc::new(AtomicU64::new(0)),
            set_commands: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Sessions that got past login.
    #[must_use]
    pub fn sessions(&self) -> u64 {
        self.sessions.load(Ordering::Relaxed)
    }

    /// Successful `set` commands received (all sessions).
    #[must_use]
    pub fn set_commands(&self) -> u64 {
        self.set_commands.load(Ordering::Relaxed)
    }

    /// A setting's current value.
    #[must_use]
    pub fn setting(&self, key: &str) -> Option<String> {
        self.state
            .lock()
            .ok()
            .and_then(|s| s.value(key).map(str::to_string))
    }

    /// Binds 127.0.0.1 on a free port and serves clients there until the task is aborted.
    ///
    /// # Errors
    /// When binding fails.
    pub async fn bind_loopback(
        self,
    ) -> std::io::Result<(SocketAddr, JoinHandle<std::io::Result<()>>)> {
        let listener = TcpListener::bind(("127.0.0.1", 0)).await?;
        let addr = listener.local_addr()?;
        Ok((addr, tokio::spawn(self.serve_listener(listener))))
    }

    /// Accepts clients; each is served in its own task. With `busy_when_occupied`, a client
    /// arriving while another is connected gets `Reader is busy. Please call back later.`.
    ///
    /// # Errors
    /// When `accept` fails.
    pub async fn serve_listener(self, listener: TcpListener) -> std::io::Result<()> {
        loop {
            let (mut stream, peer) = listener.accept().await?;
            if self.options.busy_when_occupied && self.occupied.swap(true, Ordering::AcqRel) {
                let _ = stream
                    .write_all(b"Reader is busy. Please call back later.\r\n\0")
                    .await;
                let _ = stream.shutdown().await;
                continue;
            }
            self.occupied.store(true, Ordering::Release);
            let me = self.clone();
            tokio::spawn(
                async move {
                    let r = me.serve_stream(stream).await;
                    me.occupied.store(false, Ordering::Release);
                    if let Err(e) = r {
                        tracing::debug!(%e, "alien emulator: session ended with error");
                    }
                }
                .instrument(tracing::info_span!("alien-emulator", %peer)),
            );
        }
    }

    fn idle_limit(&self) -> Duration {
        self.options.idle_timeout.unwrap_or_else(|| {
            let secs = self
                .state
                .lock()
                .ok()
                .and_then(|s| {
                    s.value("NetworkTimeout")
                        .and_then(|v| v.parse::<u64>().ok())
                })
                .unwrap_or(90);
            Duration::from_secs(secs.max(1))
        })
    }

    /// Serves one connected stream until the client quits, idles out or closes.
    ///
    /// # Errors
    /// I/O errors of the stream.
    pub async fn serve_stream<S>(&self, mut s: S) -> std::io::Result<()>
    where
        S: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let mut lines = LineReader::default();
        s.write_all(BANNER.as_bytes()).await?;
        s.write_all(b"Username>\0").await?;
        s.flush().await?;
        // Login.
        let mut attempts = 0;
        loop {
            let Some(user) = lines.next(&mut s, self.idle_limit()).await? else {
                return Ok(());
            };
            let suppressed = user.starts_with('\x01');
            if self.options.echo_login {
                s.write_all(format!("{user}\r\n").as_bytes()).await?;
            }
            s.write_all(if suppressed { b"\0" } else { b"Password>\0" })
                .await?;
            s.flush().await?;
            let Some(pass) = lines.next(&mut s, self.idle_limit()).await? else {
                return Ok(());
            };
            if self.options.echo_login {
                s.write_all(format!("{pass}\r\n").as_bytes()).await?;
            }
            let ok = user.trim_start_matches('\x01') == self.options.username
                && pass.trim_start_matches('\x01') == self.options.password;
            if ok {
                s.write_all(if suppressed { b"\0" } else { b"\r\nAlien>\0" })
                    .await?;
                s.flush().await?;
                break;
            }
            attempts += 1;
            s.write_all(b"Error: Invalid Username and/or Password\r\n\0")
                .await?;
            if attempts >= 3 {
                s.flush().await?;
                return Ok(());
            }
            s.write_all(b"Username>\0").await?;
            s.flush().await?;
        }
        self.sessions.fetch_add(1, Ordering::Relaxed);
        // Commands.
        loop {
            let line = match lines.next(&mut s, self.idle_limit()).await {
                Ok(Some(l)) => l,
                Ok(None) => return Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                    s.write_all(b"Connection Timeout.\r\n\0").await?;
                    s.flush().await?;
                    let _ = s.shutdown().await;
                    return Ok(());
                }
                Err(e) => return Err(e),
            };
            let suppressed = line.starts_with('\x01');
            let cmd = line.trim_start_matches('\x01');
            let outcome = self.execute(cmd.trim());
            let (body, close) = match outcome {
                Outcome::Reply(b) => (b, false),
                Outcome::Close(b) => (b, true),
            };
            let mut out = String::new();
            let echo = match self.options.echo {
                EchoMode::Interactive => !suppressed,
                EchoMode::Never => false,
                EchoMode::Always => true,
            };
            if echo {
                out.push_str(cmd);
                out.push_str("\r\n");
            }
            if !body.is_empty() {
                out.push_str(&body);
                out.push_str("\r\n");
            }
            out.push('\0');
            if !suppressed && !close {
                out.push_str("\r\nAlien>\0");
            }
            s.write_all(out.as_bytes()).await?;
            s.flush().await?;
            if close {
                let _ = s.shutdown().await;
                return Ok(());
            }
        }
    }

    fn execute(&self, cmd: &str) -> Outcome {
        let lc = cmd.to_ascii_lowercase();
        let unknown = || Outcome::Reply("Error 1: Command not understood.".to_string());
        match lc.as_str() {
            "" => return Outcome::Reply(String::new()),
            "q" | "quit" => return Outcome::Close("Goodbye!".to_string()),
            "t" | "get taglist" | "taglist?" => return Outcome::Reply(self.taglist()),
            "clear" | "clear taglist" => {
                return Outcome::Reply("Tag List has been cleared!".into())
            }
            _ => {}
        }
        if let Some(attr) = lc
            .strip_prefix("get ")
            .map(|_| cmd.get(4..).unwrap_or_default())
        {
            return self.get(attr.trim()).unwrap_or_else(unknown);
        }
        if let Some(attr) = cmd.strip_suffix('?') {
            return self.get(attr.trim()).unwrap_or_else(unknown);
        }
        if let Some((k, v)) = crate::setup::split_set(cmd) {
            return self.set(k, v).unwrap_or_else(unknown);
        }
        unknown()
    }

    fn get(&self, attr: &str) -> Option<Outcome> {
        let st = self.state.lock().ok()?;
        if attr.eq_ignore_ascii_case("Time") {
            let (d, t) = st.date_time();
            return Some(Outcome::Reply(format!(
                "Time = {d} {}",
                t.get(..8).unwrap_or(&t)
            )));
        }
        let (key, value) = st.settings.get(&attr.to_ascii_lowercase())?;
        Some(Outcome::Reply(format!("{key} = {value}")))
    }

    fn set(&self, key: &str, value: &str) -> Option<Outcome> {
        let invalid = Outcome::Reply("Error 4: Invalid use of command.".to_string());
        let mut st = self.state.lock().ok()?;
        let lk = key.to_ascii_lowercase();
        if lk == "time" {
            let Some(ReaderTime::Clock {
                date: Some((y, m, d)),
                seconds_of_day,
            }) = ReaderTime::parse(value)
            else {
                return Some(invalid);
            };
            let Some(unix) =
                unix_from_civil(i64::from(y), u32::from(m), u32::from(d), seconds_of_day)
            else {
                return Some(invalid);
            };
            st.set_clock(unix);
            self.set_commands.fetch_add(1, Ordering::Relaxed);
            return Some(Outcome::Reply(format!("Time = {}", value.trim())));
        }
        let canonical = match lk.as_str() {
            "persisttime" => value.parse::<i64>().ok().map(|v| v.to_string()),
            "networktimeout" => value.parse::<u64>().ok().map(|v| v.to_string()),
            "taglistformat" => match value.to_ascii_lowercase().as_str() {
                "text" => Some("Text".to_string()),
                "terse" => Some("Terse".to_string()),
                "xml" => Some("XML".to_string()),
                "custom" => Some("Custom".to_string()),
                _ => None,
            },
            "taglistmillis" => match value.to_ascii_lowercase().as_str() {
                "on" => Some("ON".to_string()),
                "off" => Some("OFF".to_string()),
                _ => None,
            },
            "taglistcustomformat" | "readername" | "antennasequence" => Some(value.to_string()),
            _ => return None,
        };
        let Some(v) = canonical else {
            return Some(invalid);
        };
        let entry = st.settings.get_mut(&lk)?;
        entry.1.clone_from(&v);
        let reply = format!("{} = {v}", entry.0);
        self.set_commands.fetch_add(1, Ordering::Relaxed);
        Some(Outcome::Reply(reply))
    }

    fn taglist(&self) -> String {
        let tags = (self.field)();
        if tags.is_empty() {
            return "(No Tags)".to_string();
        }
        let Ok(st) = self.state.lock() else {
            return "(No Tags)".to_string();
        };
        let (date, time) = st.date_time();
        let format = st
            .value("TagListFormat")
            .unwrap_or("Text")
            .to_ascii_lowercase();
        let custom = st
            .value("TagListCustomFormat")
            .unwrap_or_default()
            .to_string();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let msec = (st.now_unix() * 1000.0) as u64;
        let lines: Vec<String> = tags
            .iter()
            .map(|(id, rssi)| match format.as_str() {
                "terse" => format!("{},1,0", spaced_id(id)),
                "xml" => format!(
                    "<Alien-RFID-Tag>\r\n<TagID>{}</TagID>\r\n<DiscoveryTime>{date} {time}</DiscoveryTime>\r\n<LastSeenTime>{date} {time}</LastSeenTime>\r\n<Antenna>0</Antenna>\r\n<ReadCount>1</ReadCount>\r\n<Protocol>Class 1 Gen 2</Protocol>\r\n</Alien-RFID-Tag>",
                    spaced_id(id)
                ),
                "custom" => substitute(&custom, id, *rssi, &date, &time, msec),
                _ => format!(
                    "Tag:{}, Disc:{date} {time}, Last:{date} {time}, Count:1, Ant:0, Proto:2",
                    spaced_id(id)
                ),
            })
            .collect();
        if format == "xml" {
            format!(
                "<Alien-RFID-Tag-List>\r\n{}\r\n</Alien-RFID-Tag-List>",
                lines.join("\r\n")
            )
        } else {
            lines.join("\r\n")
        }
    }
}

/// Fills a custom format for one tag (unknown tokens are copied as they are).
fn substitute(format: &str, id: &[u8], rssi: f64, date: &str, time: &str, msec: u64) -> String {
    let mut out = String::new();
    let mut chars = format.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '%' => match chars.next() {
                Some('i') => out.push_str(&spaced_id(id)),
                Some('k') => out.push_str(&packed_id(id)),
                Some('m') => out.push_str(&format!("{rssi:.1}")),
                Some('r') => out.push('1'),
                Some('a') => out.push('0'),
                Some('t' | 'T') => out.push_str(time),
                Some('d' | 'D') => out.push_str(date),
                Some('p') => out.push('2'),
                Some('P') => out.push_str("Class 1 Gen 2"),
                Some('%') => out.push('%'),
                Some(o) => {
                    out.push('%');
                    out.push(o);
                }
                None => out.push('%'),
            },
            '$' if chars.peek() == Some(&'{') => {
                chars.next();
                let name: String = chars.by_ref().take_while(|ch| *ch != '}').collect();
                let v = match name.to_ascii_uppercase().as_str() {
                    "TAGID" | "TAGIDB" => packed_id(id),
                    "TAGIDW" => spaced_id(id),
                    "RSSI" => format!("{rssi:.1}"),
                    "COUNT" => "1".to_string(),
                    "TX" | "RX" => "0".to_string(),
                    "DATE1" | "DATE2" => date.to_string(),
                    "TIME1" | "TIME2" => time.to_string(),
                    "MSEC1" | "MSEC2" => msec.to_string(),
                    "PROTO#" => "2".to_string(),
                    "PROTO" => "Class 1 Gen 2".to_string(),
                    _ => format!("${{{name}}}"),
                };
                out.push_str(&v);
            }
            _ => out.push(c),
        }
    }
    out
}

/// Reads command lines: ends at `\n`, or at `\r` (a following `\n` is skipped).
#[derive(Debug, Default)]
struct LineReader {
    buf: Vec<u8>,
    ready: std::collections::VecDeque<String>,
    skip_lf: bool,
}

impl LineReader {
    /// The next line; `Ok(None)` at end of stream; `TimedOut` after `idle`.
    async fn next<S: AsyncRead + Unpin>(
        &mut self,
        s: &mut S,
        idle: Duration,
    ) -> std::io::Result<Option<String>> {
        let mut chunk = [0u8; 1024];
        loop {
            if let Some(l) = self.ready.pop_front() {
                return Ok(Some(l));
            }
            let n = tokio::time::timeout(idle, s.read(&mut chunk))
                .await
                .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "idle"))??;
            if n == 0 {
                return Ok(None);
            }
            for &b in chunk.get(..n).unwrap_or_default() {
                match b {
                    b'\n' if self.skip_lf => self.skip_lf = false,
                    b'\n' | b'\r' => {
                        self.skip_lf = b == b'\r';
                        let line = std::mem::take(&mut self.buf);
                        self.ready
                            .push_back(String::from_utf8_lossy(&line).into_owned());
                    }
                    _ => {
                        self.skip_lf = false;
                        if self.buf.len() < 4096 {
                            self.buf.push(b);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn substitution_of_the_seed_format() {
        let id = [0x47, 0xEC, 0xED, 0xCE, 0x42, 0x36];
        assert_eq!(
            substitute(
                "IDK %i RSSI %m TIME %t;",
                &id,
                2235.31,
                "2026/11/21",
                "10:00:05",
                0
            ),
            "IDK 47EC EDCE 4236 RSSI 2235.3 TIME 10:00:05;"
        );
        assert_eq!(
            substitute("id=%k;sig=${RSSI};x=${FOO}", &id, -40.0, "", "", 0),
            "id=47ECEDCE4236;sig=-40.0;x=${FOO}"
        );
    }

    #[test]
    fn reader_clock_follows_the_given_time_base() {
        let clock = rfloc_transport::ManualClock::new();
        let emu = ReaderEmulator::new(
            Arc::new(Vec::new),
            EmulatorOptions {
                clock: Some(clock.clone()),
                ..EmulatorOptions::default()
            },
        );
        let time = |emu: &ReaderEmulator| match emu.execute("get Time") {
            Outcome::Reply(r) => r,
            Outcome::Close(r) => panic!("closed: {r}"),
        };
        clock.set_ns(3_000_000_000);
        assert!(matches!(
            emu.execute("Time = 2000/01/01 00:00:00"),
            Outcome::Reply(ref r) if r == "Time = 2000/01/01 00:00:00"
        ));
        assert_eq!(time(&emu), "Time = 2000/01/01 00:00:00");
        // 61.5 s on the time base later (however long the host took).
        clock.set_ns(64_500_000_000);
        assert_eq!(time(&emu), "Time = 2000/01/01 00:01:01");
    }
}
