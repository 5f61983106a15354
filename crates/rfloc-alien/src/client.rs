//! The async client: login, commands, setup, TagList polls.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use rfloc_transport::SharedClock;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;
use tracing::Instrument;

use crate::error::{AlienError, SessionEnd};
use crate::format_tracker::FormatTracker;
use crate::framing::{Frame, Prompt, ReplyFramer, MAX_FRAME_LEN};
use crate::reader_time::format_reader_time;
use crate::redact::Redactor;
use crate::reply::{parse_reply, session_end, Reply};
use crate::setup::ReaderSetup;
use crate::snapshot::{RssiMeaning, Snapshot, SnapshotReader};
use crate::taglist::{MalformedTagLine, TagListFormat, TagRead};

/// How commands are sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PromptMode {
    /// `\x01` before each command: no prompt, no echo, the reply ends at NUL (reference §1.3).
    #[default]
    Suppressed,
    /// Plain commands: the reader echoes the command and sends `Alien>` after the reply (the
    /// seed's session). Echo and prompts are removed.
    Interactive,
}

/// Line terminator of commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LineEnding {
    /// `\r\n`, as every library the reference cites.
    #[default]
    CrLf,
    /// `\n`, what the seed's Matlab `fprintf` sends.
    Lf,
}

/// Supplies the reader time text (`YYYY/MM/DD hh:mm:ss`) for `set Time`.
pub type TimeSource = Arc<dyn Fn() -> String + Send + Sync>;

/// Client settings.
#[derive(Clone)]
pub struct AlienConfig {
    pub username: String,
    pub password: String,
    pub prompt_mode: PromptMode,
    pub line_ending: LineEnding,
    /// Deadline of one exchange: from sending a command to its complete reply (and, in
    /// interactive mode, the prompt after it). A `t` includes one read cycle. Bytes that arrive
    /// without completing the reply do not extend it.
    pub reply_timeout: Duration,
    /// Deadline of the whole login: banner, `Username>`, both credentials and the outcome.
    pub login_timeout: Duration,
    /// Longest wait for the session's connector to open a link.
    pub connect_timeout: Duration,
    /// Largest reply (or banner) kept, in bytes; a longer one is
    /// [`AlienError::ReplyTooLong`].
    pub max_reply_len: usize,
    /// Send a keepalive when idle this long (keep it well under `NetworkTimeout`).
    pub keepalive_interval: Duration,
    pub rssi_meaning: RssiMeaning,
    /// Reader time for `set Time`; default: UTC now.
    pub time_source: TimeSource,
}

impl std::fmt::Debug for AlienConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlienConfig")
            .field("username", &self.username)
            .field("prompt_mode", &self.prompt_mode)
            .field("line_ending", &self.line_ending)
            .field("reply_timeout", &self.reply_timeout)
            .field("login_timeout", &self.login_timeout)
            .field("connect_timeout", &self.connect_timeout)
            .field("max_reply_len", &self.max_reply_len)
            .field("keepalive_interval", &self.keepalive_interval)
            .field("rssi_meaning", &self.rssi_meaning)
            .finish_non_exhaustive()
    }
}

fn utc_now_text() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    format_reader_time(secs)
}

impl Default for AlienConfig {
    fn default() -> Self {
        Self {
            username: "alien".to_string(),
            password: "password".to_string(),
            prompt_mode: PromptMode::Suppressed,
            line_ending: LineEnding::CrLf,
            reply_timeout: Duration::from_secs(5),
            login_timeout: Duration::from_secs(10),
            connect_timeout: Duration::from_secs(10),
            max_reply_len: MAX_FRAME_LEN,
            keepalive_interval: Duration::from_secs(30),
            rssi_meaning: RssiMeaning::Linear,
            time_source: Arc::new(utc_now_text),
        }
    }
}

/// Client counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct AlienStats {
    pub commands: u64,
    /// `Error …` replies.
    pub reader_errors: u64,
    /// Tag lines that did not parse.
    pub malformed_tag_lines: u64,
    /// Prompts or frames read where no reply was expected.
    pub stray_frames: u64,
    pub keepalives: u64,
    /// Bytes dropped by the framer (overlong frames).
    pub dropped_bytes: u64,
}

/// An Alien reader session over `T` (a TCP stream in the daemon).
pub struct AlienClient<T> {
    io: T,
    framer: ReplyFramer,
    frames: VecDeque<Frame>,
    config: AlienConfig,
    format: FormatTracker,
    echo: EchoFilter,
    clock: SharedClock,
    stats: AlienStats,
    last_io: Instant,
    /// Bytes read since the current exchange began.
    received: u64,
    /// Takes the credentials out of reader text that becomes an error.
    redactor: Redactor,
    span: tracing::Span,
}

/// Leaves out the bytes in flight: they may hold an echo of the password.
impl<T> std::fmt::Debug for AlienClient<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlienClient")
            .field("config", &self.config)
            .field("format", self.format.format())
            .field("echo", &self.echo.state())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

/// When the current exchange must be complete.
#[derive(Debug, Clone, Copy)]
struct Deadline {
    at: Instant,
    budget: Duration,
}

impl Deadline {
    fn after(budget: Duration) -> Self {
        Self {
            at: Instant::now() + budget,
            budget,
        }
    }
}

/// What a frame read during the login means.
enum LoginStep {
    /// The step is answered: send the next credential (or, after the password, logged in).
    Next,
    /// Only an echo of a credential: keep reading.
    Echo,
    /// Logged in (a command prompt).
    LoggedIn,
}

impl<T> AlienClient<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// Wraps a connected stream and logs in.
    ///
    /// # Errors
    /// [`AlienError::LoginFailed`], [`AlienError::Session`] (busy, closed), timeouts, I/O.
    pub async fn connect(
        io: T,
        config: AlienConfig,
        clock: SharedClock,
    ) -> Result<Self, AlienError> {
        let redactor = Redactor::new([config.password.as_str()]);
        let mut c = Self {
            io,
            framer: ReplyFramer::with_limit(config.max_reply_len),
            frames: VecDeque::new(),
            config,
            format: FormatTracker::default(),
            echo: EchoFilter::default(),
            clock,
            stats: AlienStats::default(),
            last_io: Instant::now(),
            received: 0,
            redactor,
            span: tracing::info_span!("alien"),
        };
        let span = c.span.clone();
        c.login().instrument(span).await?;
        tracing::debug!(parent: &c.span, "alien: logged in");
        Ok(c)
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> AlienStats {
        AlienStats {
            dropped_bytes: self.framer.dropped_bytes(),
            ..self.stats
        }
    }

    /// Whether the reader echoes commands, as learned from the replies so far.
    #[must_use]
    pub fn echo_state(&self) -> EchoState {
        self.echo.state()
    }

    /// The TagList format the client parses with (follows `TagListFormat`/`…CustomFormat` sets).
    #[must_use]
    pub fn format(&self) -> &TagListFormat {
        self.format.format()
    }

    /// Sets the TagList format the client parses with, without telling the reader.
    pub fn set_format(&mut self, format: TagListFormat) {
        self.format.set_format(format);
    }

    fn timeout_error(&self, what: &str, deadline: Deadline) -> AlienError {
        AlienError::Timeout {
            what: what.to_string(),
            after: deadline.budget,
            received: self.received,
        }
    }

    /// The next frame, or an error once `deadline` has passed (frames that arrive do not
    /// extend it) or a frame is over the reply limit.
    async fn next_frame(&mut self, deadline: Deadline, what: &str) -> Result<Frame, AlienError> {
        let mut buf = [0u8; 4096];
        loop {
            if let Some(f) = self.frames.pop_front() {
                if let Frame::Overlong(_) = f {
                    self.frames.clear();
                    return Err(AlienError::ReplyTooLong {
                        what: what.to_string(),
                        limit: self.framer.limit(),
                    });
                }
                return Ok(f);
            }
            let n = match tokio::time::timeout_at(deadline.at, self.io.read(&mut buf)).await {
                Ok(read) => read?,
                Err(_) => return Err(self.timeout_error(what, deadline)),
            };
            if n == 0 {
                return Err(AlienError::Session(SessionEnd::Closed));
            }
            self.last_io = Instant::now();
            self.received += n as u64;
            let frames = self.framer.push(buf.get(..n).unwrap_or_default());
            self.frames.extend(frames);
        }
    }

    async fn write_line(
        &mut self,
        text: &str,
        suppressed: bool,
        deadline: Deadline,
        what: &str,
    ) -> Result<(), AlienError> {
        let mut bytes = Vec::with_capacity(text.len() + 3);
        if suppressed {
            bytes.push(0x01);
        }
        bytes.extend_from_slice(text.as_bytes());
        bytes.extend_from_slice(match self.config.line_ending {
            LineEnding::CrLf => b"\r\n",
            LineEnding::Lf => b"\n",
        });
        let io = &mut self.io;
        let sent = tokio::time::timeout_at(deadline.at, async move {
            io.write_all(&bytes).await?;
            io.flush().await
        })
        .await;
        match sent {
            Ok(r) => r?,
            Err(_) => return Err(self.timeout_error(what, deadline)),
        }
        self.last_io = Instant::now();
        Ok(())
    }

    /// Banner, `Username>`, `Password>` (reference §1.2 and §6 steps 1–3), all within
    /// `login_timeout`. Echoes of the credentials are skipped, and reader text that becomes an
    /// error is redacted.
    async fn login(&mut self) -> Result<(), AlienError> {
        const WHAT: &str = "login";
        let deadline = Deadline::after(self.config.login_timeout);
        self.received = 0;
        let suppressed = self.config.prompt_mode == PromptMode::Suppressed;
        loop {
            match self.next_frame(deadline, WHAT).await? {
                Frame::Prompt {
                    prompt: Prompt::Username,
                    ..
                } => break,
                Frame::Prompt {
                    prompt: Prompt::Command,
                    ..
                } => return Ok(()),
                Frame::Prompt { before, .. } | Frame::Reply(before) => {
                    if let Some(end) = session_end(&before) {
                        return Err(AlienError::Session(end));
                    }
                }
                Frame::Overlong(_) => {}
            }
        }
        let user = self.config.username.clone();
        self.write_line(&user, suppressed, deadline, WHAT).await?;
        loop {
            let frame = self.next_frame(deadline, WHAT).await?;
            match self.login_step(&frame, false)? {
                LoginStep::Next => break,
                LoginStep::Echo => {}
                LoginStep::LoggedIn => return Ok(()),
            }
        }
        let pass = self.config.password.clone();
        self.write_line(&pass, suppressed, deadline, WHAT).await?;
        loop {
            let frame = self.next_frame(deadline, WHAT).await?;
            match self.login_step(&frame, true)? {
                LoginStep::Next | LoginStep::LoggedIn => return Ok(()),
                LoginStep::Echo => {}
            }
        }
    }

    /// Classifies a frame read after sending the username (`after_password` false) or the
    /// password.
    fn login_step(&self, frame: &Frame, after_password: bool) -> Result<LoginStep, AlienError> {
        let (text, prompt) = match frame {
            Frame::Prompt { before, prompt } => (before.as_str(), Some(*prompt)),
            Frame::Reply(text) => (text.as_str(), None),
            Frame::Overlong(_) => ("", None),
        };
        let (rest, echoed) = strip_credential_echo(
            text,
            &[self.config.username.as_str(), self.config.password.as_str()],
        );
        // Everything below looks at reader text without the credentials in it.
        let rest = self.redactor.redact(&rest);
        if let Some(end) = session_end(&rest) {
            return Err(AlienError::Session(end));
        }
        let refused = || {
            let reason = self.redactor.clean(&rest);
            AlienError::LoginFailed(if reason.is_empty() {
                "the reader asked for the credentials again".to_string()
            } else {
                reason
            })
        };
        let refusal = is_refusal(&rest);
        match prompt {
            Some(Prompt::Command) => Ok(LoginStep::LoggedIn),
            Some(Prompt::Password) if !after_password && !refusal => Ok(LoginStep::Next),
            Some(_) => Err(refused()),
            None if refusal => Err(refused()),
            None if rest.trim().is_empty() => {
                // An empty reply answers the step (prompts suppressed). A bare echo does too
                // with prompts suppressed, where the reply's NUL ends the echo's frame; in
                // interactive mode the prompt that answers the step is still to come.
                if echoed && self.config.prompt_mode == PromptMode::Interactive {
                    Ok(LoginStep::Echo)
                } else {
                    Ok(LoginStep::Next)
                }
            }
            None => Err(AlienError::Unexpected {
                command: if after_password {
                    "login (password)".into()
                } else {
                    "login (username)".into()
                },
                reply: self.redactor.clean(&rest),
            }),
        }
    }

    /// Sends one command and returns its reply body (echo removed, prompt consumed).
    ///
    /// # Errors
    /// [`AlienError::Reader`] for `Error …` replies, [`AlienError::Session`] for
    /// `Connection Timeout.`/`Goodbye!`/busy/closed, timeouts and I/O errors.
    pub async fn command(&mut self, cmd: &str) -> Result<String, AlienError> {
        let span = self.span.clone();
        self.command_inner(cmd).instrument(span).await
    }

    async fn command_inner(&mut self, cmd: &str) -> Result<String, AlienError> {
        tracing::debug!(command = cmd, "alien: send");
        let suppressed = self.config.prompt_mode == PromptMode::Suppressed;
        self.stats.commands += 1;
        let deadline = Deadline::after(self.config.reply_timeout);
        self.received = 0;
        self.write_line(cmd, suppressed, deadline, cmd).await?;
        let body = loop {
            match self.next_frame(deadline, cmd).await? {
                Frame::Reply(body) => break body,
                Frame::Prompt {
                    prompt: Prompt::Command,
                    before,
                } => {
                    if let Some(end) = session_end(&before) {
                        return Err(AlienError::Session(end));
                    }
                    self.stats.stray_frames += 1;
                }
                Frame::Prompt { before, prompt } => {
                    return Err(AlienError::Unexpected {
                        command: cmd.to_string(),
                        reply: self
                            .redactor
                            .clean(&format!("{before}{}", prompt_text(prompt))),
                    })
                }
                Frame::Overlong(_) => {
                    return Err(AlienError::ReplyTooLong {
                        what: cmd.to_string(),
                        limit: self.framer.limit(),
                    })
                }
            }
        };
        if let Some(end) = session_end(&body) {
            return Err(AlienError::Session(end));
        }
        if !suppressed {
            match self.next_frame(deadline, cmd).await? {
                Frame::Prompt {
                    prompt: Prompt::Command,
                    ..
                } => {}
                Frame::Reply(text) | Frame::Prompt { before: text, .. } => {
                    if let Some(end) = session_end(&text) {
                        return Err(AlienError::Session(end));
                    }
                    self.stats.stray_frames += 1;
                }
                Frame::Overlong(_) => self.stats.stray_frames += 1,
            }
        }
        let body = self.echo.strip(&body, cmd);
        if let Reply::Error { code, text } = parse_reply(&body) {
            self.stats.reader_errors += 1;
            let text = self.redactor.clean(&text);
            tracing::warn!(command = cmd, ?code, %text, "alien: reader error");
            return Err(AlienError::Reader {
                command: cmd.to_string(),
                code,
                text,
            });
        }
        self.format.observe(cmd)?;
        Ok(body)
    }

    /// `get <attr>`: the value after `=`.
    ///
    /// # Errors
    /// As [`AlienClient::command`]; [`AlienError::Unexpected`] without `=`.
    pub async fn get(&mut self, attr: &str) -> Result<String, AlienError> {
        let cmd = format!("get {attr}");
        let body = self.command(&cmd).await?;
        match parse_reply(&body) {
            Reply::Value { value, .. } => Ok(value),
            _ => Err(AlienError::Unexpected {
                command: cmd,
                reply: self.redactor.clean(&body),
            }),
        }
    }

    /// `set <attr> = <value>`: the value the reader echoes.
    ///
    /// # Errors
    /// As [`AlienClient::get`].
    pub async fn set(&mut self, attr: &str, value: &str) -> Result<String, AlienError> {
        let cmd = format!("set {attr} = {value}");
        let body = self.command(&cmd).await?;
        match parse_reply(&body) {
            Reply::Value { value, .. } => Ok(value),
            _ => Err(AlienError::Unexpected {
                command: cmd,
                reply: self.redactor.clean(&body),
            }),
        }
    }

    /// Applies a setup (after login or reconnect).
    ///
    /// # Errors
    /// The first failing command's error.
    pub async fn apply_setup(&mut self, setup: &ReaderSetup) -> Result<(), AlienError> {
        for c in &setup.commands {
            let now = (self.config.time_source)();
            let text = c.text(&now);
            self.command(&text).await?;
        }
        Ok(())
    }

    /// `t`: the TagList parsed with the current format.
    ///
    /// # Errors
    /// As [`AlienClient::command`].
    pub async fn read_taglist(
        &mut self,
    ) -> Result<(Vec<TagRead>, Vec<MalformedTagLine>), AlienError> {
        let body = self.command("t").await?;
        let (tags, bad) = self.format.format().parse(&body);
        self.stats.malformed_tag_lines += bad.len() as u64;
        Ok((tags, bad))
    }

    /// An empty command (reference §1.3): keeps the session inside `NetworkTimeout`.
    ///
    /// # Errors
    /// As [`AlienClient::command`].
    pub async fn keepalive(&mut self) -> Result<(), AlienError> {
        self.stats.keepalives += 1;
        self.command("").await.map(drop)
    }

    /// Sends a keepalive if idle for `keepalive_interval`.
    ///
    /// # Errors
    /// As [`AlienClient::keepalive`].
    pub async fn keepalive_if_due(&mut self) -> Result<(), AlienError> {
        if self.last_io.elapsed() >= self.config.keepalive_interval {
            self.keepalive().await?;
        }
        Ok(())
    }

    /// `quit`; succeeds when the reader says `Goodbye!` or closes.
    ///
    /// # Errors
    /// Other replies or I/O errors.
    pub async fn quit(mut self) -> Result<(), AlienError> {
        match self.command("quit").await {
            Err(AlienError::Session(SessionEnd::Goodbye | SessionEnd::Closed)) => Ok(()),
            Err(e) => Err(e),
            Ok(body) => Err(AlienError::Unexpected {
                command: "quit".into(),
                reply: self.redactor.clean(&body),
            }),
        }
    }

    /// Waits up to `timeout` for unsolicited output (e.g. `Connection Timeout.`).
    /// `Ok(None)`: nothing complete arrived. `Ok(Some(text))`: other text, redacted and made
    /// printable as error text is.
    ///
    /// # Errors
    /// [`AlienError::Session`] when the reader ended the session;
    /// [`AlienError::ReplyTooLong`], I/O.
    pub async fn next_unsolicited(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<String>, AlienError> {
        self.received = 0;
        match self
            .next_frame(Deadline::after(timeout), "unsolicited")
            .await
        {
            Ok(f) => {
                let text = frame_text(&f);
                if let Some(end) = session_end(&text) {
                    return Err(AlienError::Session(end));
                }
                self.stats.stray_frames += 1;
                Ok(Some(self.redactor.clean(&text)))
            }
            Err(AlienError::Timeout { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

impl<T> SnapshotReader for AlienClient<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    async fn read_snapshot(&mut self) -> Result<Snapshot, AlienError> {
        let (tags, malformed) = self.read_taglist().await?;
        Ok(Snapshot {
            t: self.clock.now(),
            tags,
            malformed,
            rssi_meaning: self.config.rssi_meaning,
        })
    }
}

fn prompt_text(p: Prompt) -> &'static str {
    match p {
        Prompt::Username => "Username>",
        Prompt::Password => "Password>",
        Prompt::Command => "Alien>",
    }
}

fn frame_text(f: &Frame) -> String {
    match f {
        Frame::Prompt { before, prompt } => format!("{}{}", before.trim(), prompt_text(*prompt)),
        Frame::Reply(r) => r.trim().to_string(),
        Frame::Overlong(h) => String::from_utf8_lossy(h).into_owned(),
    }
}

/// `text` without the lines that are an echo of a credential (the line as sent: with or without
/// the `\x01`, any line end), and whether there were any.
fn strip_credential_echo(text: &str, credentials: &[&str]) -> (String, bool) {
    let mut echoed = false;
    let mut rest = String::new();
    for line in text.split_inclusive(['\r', '\n']) {
        let bare = line.trim_matches(|c: char| c == '\x01' || c.is_ascii_whitespace());
        if !bare.is_empty() && credentials.iter().any(|c| !c.is_empty() && bare == *c) {
            echoed = true;
        } else {
            rest.push_str(line);
        }
    }
    (rest, echoed)
}

/// Reader text that refuses a login: an `Error` line, or words of refusal.
fn is_refusal(text: &str) -> bool {
    let lower = text.to_ascii_lowercase();
    lower.lines().any(|l| {
        l.trim_start_matches(['\x01', ' ', '\t'])
            .starts_with("error")
    }) || [
        "invalid",
        "denied",
        "incorrect",
        "refused",
        "failed",
        "wrong",
    ]
    .iter()
    .any(|w| lower.contains(w))
}

/// Whether the reader echoes commands, as learned from the replies so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub enum EchoState {
    /// No exchange has told yet.
    #[default]
    Unknown,
    /// A reply began with a copy of its command followed by more text.
    Echoes,
    /// A reply to a non-empty command did not begin with the command.
    Silent,
}

/// Removes command echoes from reply bodies, learning from the exchanges whether the reader
/// echoes at all.
///
/// A reply whose first line equals the command is ambiguous: it is either the echo, or the
/// reply itself (`PersistTime = 0` answers `PersistTime = 0` on a reader that does not echo).
/// The first line is taken for an echo when the reader is known to echo, or, while that is not
/// known yet, only when more text follows it (a second copy, or the reply). A reply to a
/// non-empty command that does not begin with the command shows a reader that does not echo;
/// from then on nothing is stripped. A reply that begins with its command and has more text
/// after it shows a reader that echoes.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct EchoFilter {
    state: EchoState,
}

impl EchoFilter {
    pub(crate) fn state(&self) -> EchoState {
        self.state
    }

    /// The reply body of `cmd` without its echo.
    pub(crate) fn strip(&mut self, body: &str, cmd: &str) -> String {
        let cmd = cmd.trim();
        if cmd.is_empty() {
            return body.to_string();
        }
        let trimmed = body.trim_start_matches(['\r', '\n']);
        let (first, rest) = match trimmed.find(['\r', '\n']) {
            Some(i) => trimmed.split_at(i),
            None => (trimmed, ""),
        };
        let rest = rest.trim_start_matches(['\r', '\n']);
        if !first.trim().eq_ignore_ascii_case(cmd) {
            if self.state == EchoState::Unknown && !trimmed.is_empty() {
                self.state = EchoState::Silent;
            }
            return body.to_string();
        }
        match self.state {
            EchoState::Silent => body.to_string(),
            EchoState::Echoes => rest.to_string(),
            EchoState::Unknown if rest.is_empty() => body.to_string(),
            EchoState::Unknown => {
                self.state = EchoState::Echoes;
                rest.to_string()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reader that ignores `\x01` and answers interactively (echo, `Alien>` prompts): a
    /// client in suppressed mode still gets the right values, skipping the stray prompts.
    #[tokio::test]
    async fn suppressed_client_tolerates_an_interactive_reader() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let (client_io, mut dev) = tokio::io::duplex(4096);
        let device = tokio::spawn(async move {
            let mut buf = [0u8; 256];
            dev.write_all(b"* Alien *\r\nUsername>\0").await.unwrap();
            let n = dev.read(&mut buf).await.unwrap();
            assert_eq!(&buf[..n], b"\x01alien\r\n");
            dev.write_all(b"Password>\0").await.unwrap();
            let n = dev.read(&mut buf).await.unwrap();
            assert_eq!(&buf[..n], b"\x01password\r\n");
            dev.write_all(b"\r\nAlien>\0").await.unwrap();
            let n = dev.read(&mut buf).await.unwrap();
            assert_eq!(&buf[..n], b"\x01get ReaderName\r\n");
            dev.write_all(b"get ReaderName\r\nReaderName = X\r\n\0\r\nAlien>\0")
                .await
                .unwrap();
            let n = dev.read(&mut buf).await.unwrap();
            assert_eq!(&buf[..n], b"\x01t\r\n");
            dev.write_all(b"t\r\n(No Tags)\r\n\0\r\nAlien>\0")
                .await
                .unwrap();
            dev
        });
        let clock: SharedClock = rfloc_transport::MonotonicClock::shared();
        let mut c = AlienClient::connect(client_io, AlienConfig::default(), clock)
            .await
            .unwrap();
        assert_eq!(c.get("ReaderName").await.unwrap(), "X");
        let snap = c.read_snapshot().await.unwrap();
        assert!(snap.tags.is_empty() && snap.malformed.is_empty());
        assert_eq!(c.stats().stray_frames, 1);
        drop(device.await.unwrap());
    }

    #[test]
    fn echo_is_stripped_once() {
        let mut f = EchoFilter::default();
        assert_eq!(f.strip("t\r\n(No Tags)\r\n", "t"), "(No Tags)\r\n");
        assert_eq!(f.state(), EchoState::Echoes);
        assert_eq!(
            f.strip("PersistTime = 0\r\nPersistTime = 0\r\n", "PersistTime = 0"),
            "PersistTime = 0\r\n"
        );
        assert_eq!(
            f.strip("ReaderName = x\r\n", "get ReaderName"),
            "ReaderName = x\r\n"
        );
        assert_eq!(
            f.state(),
            EchoState::Echoes,
            "a reply is not a lack of echo once known"
        );
        assert_eq!(f.strip("", ""), "");
    }

    #[test]
    fn a_reply_equal_to_its_command_is_kept_without_echo() {
        // First exchange ambiguous: one line equal to the command is the reply.
        let mut f = EchoFilter::default();
        assert_eq!(
            f.strip("PersistTime = 0\r\n", "PersistTime = 0"),
            "PersistTime = 0\r\n"
        );
        assert_eq!(f.state(), EchoState::Unknown);
        // A reply that does not start with its command: the reader does not echo.
        assert_eq!(
            f.strip("ReaderName = x\r\n", "get ReaderName"),
            "ReaderName = x\r\n"
        );
        assert_eq!(f.state(), EchoState::Silent);
        // From then on a first line equal to the command is the reply, even with more lines.
        assert_eq!(f.strip("t\r\nt\r\n", "t"), "t\r\nt\r\n");
        assert_eq!(
            f.strip("PersistTime = 0\r\n", "persisttime = 0"),
            "PersistTime = 0\r\n"
        );
    }
}
