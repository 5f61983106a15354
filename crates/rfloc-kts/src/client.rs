//! The async client: one task owns the link, serialises commands and forwards tag events.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_transport::{SerialLink, SharedClock};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tracing::Instrument;

use crate::codec::{CodecStats, KtsCodec};
use crate::command::KtsCommand;
use crate::event::{TagEvent, TagEventKind};
use crate::line::KtsLine;

/// Default UART speed (8N1). Not confirmed for KTS; the related ODRFID-485 module uses it.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Client settings.
#[derive(Debug, Clone)]
pub struct KtsConfig {
    /// UART speed for the daemon's serial link (8N1); the client itself does not open ports.
    pub baud: u32,
    /// Starts continuous scanning (seed 002 §5: `AT+Scan=AC,RSSI`, anticollision with RSSI).
    pub scan_command: String,
    /// Stops scanning. **Unconfirmed** for the RFIDM1356 (no public KTS text); `AT+Scan=0`
    /// follows the ubisys/ODRFID `SCAN0` style.
    pub stop_command: String,
    /// How long a command may wait for `OK`/`ERROR`.
    pub command_timeout: Duration,
    /// While scanning, silence this long triggers a resync (`AT`, then the scan command).
    pub silence_timeout: Option<Duration>,
    /// Capacity of the tag event channel; events beyond it are dropped and counted.
    pub event_capacity: usize,
}

impl Default for KtsConfig {
    fn default() -> Self {
        Self {
            baud: DEFAULT_BAUD,
            scan_command: "AT+Scan=AC,RSSI".to_string(),
            stop_command: "AT+Scan=0".to_string(),
            command_timeout: Duration::from_secs(1),
            silence_timeout: Some(Duration::from_secs(2)),
            event_capacity: 4096,
        }
    }
}

impl KtsConfig {
    /// The serial link the daemon should open for this reader (`baud`, 8N1, no flow control).
    #[must_use]
    pub fn serial_link(&self, path: &str) -> SerialLink {
        SerialLink {
            path: path.to_string(),
            baud: self.baud,
            data_bits: rfloc_transport::DataBits::Eight,
            parity: rfloc_transport::Parity::None,
            stop_bits: rfloc_transport::StopBits::One,
            flow_control: rfloc_transport::FlowControl::None,
        }
    }
}

/// Client failures.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KtsClientError {
    #[error("reader answered ERROR to {command:?} (CME code {cme:?})")]
    Device { command: String, cme: Option<u32> },
    #[error("no OK/ERROR to {0:?} within the command timeout")]
    Timeout(String),
    #[error("link closed")]
    Closed,
    #[error("link I/O error: {0}")]
    Io(String),
}

/// Client counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct KtsStats {
    pub codec: CodecStats,
    /// Tag events delivered to the channel.
    pub events_sent: u64,
    /// Tag events dropped because the channel was full or closed.
    pub events_dropped: u64,
    /// Lines that arrived with no command waiting (OK, text).
    pub unsolicited_lines: u64,
    /// Automatic resynchronisations after silence.
    pub resyncs: u64,
}

/// What the daemon needs from an HF tag reader: a stream of tag events.
pub trait TagEventSource {
    /// The next tag event, or `None` when the link is gone.
    fn next_event(&mut self) -> impl std::future::Future<Output = Option<TagEvent>> + Send;
}

type Reply = oneshot::Sender<Result<Vec<KtsLine>, KtsClientError>>;

enum Request {
    Command {
        cmd: KtsCommand,
        scanning: Option<bool>,
        reply: Reply,
    },
}

/// A KTS RFIDM1356 client. Create with [`KtsClient::spawn`]; the task ends when the link closes
/// or the client is dropped.
#[derive(Debug)]
pub struct KtsClient {
    requests: mpsc::Sender<Request>,
    events: Option<mpsc::Receiver<TagEvent>>,
    stats: Arc<Mutex<KtsStats>>,
    config: KtsConfig,
    task: JoinHandle<()>,
}

impl std::fmt::Debug for Request {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Request::Command { cmd, .. } => write!(f, "Command({:?})", cmd.text()),
        }
    }
}

impl KtsClient {
    /// Starts the client task on `io`. Event timestamps come from `clock`.
    pub fn spawn<T>(io: T, config: KtsConfig, clock: SharedClock) -> Self
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    {
        let (req_tx, req_rx) = mpsc::channel(8);
        let (ev_tx, ev_rx) = mpsc::channel(config.event_capacity.max(1));
        let stats = Arc::new(Mutex::new(KtsStats::default()));
        let worker = Worker {
            config: config.clone(),
            clock,
            events: ev_tx,
            stats: Arc::clone(&stats),
            codec: KtsCodec::new(),
            waiter: None,
            scanning: false,
            last_rx: Instant::now(),
        };
        let span = tracing::info_span!("kts");
        let task = tokio::spawn(worker.run(io, req_rx).instrument(span));
        Self {
            requests: req_tx,
            events: Some(ev_rx),
            stats,
            config,
            task,
        }
    }

    /// Takes the tag event receiver (once), for a consumer task.
    pub fn take_events(&mut self) -> Option<mpsc::Receiver<TagEvent>> {
        self.events.take()
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> KtsStats {
        self.stats.lock().map(|s| *s).unwrap_or_default()
    }

    async fn request(
        &self,
        cmd: KtsCommand,
        scanning: Option<bool>,
    ) -> Result<Vec<KtsLine>, KtsClientError> {
        let (tx, rx) = oneshot::channel();
        self.requests
            .send(Request::Command {
                cmd,
                scanning,
                reply: tx,
            })
            .await
            .map_err(|_| KtsClientError::Closed)?;
        rx.await.map_err(|_| KtsClientError::Closed)?
    }

    /// Sends a command and returns the lines before its `OK`.
    ///
    /// # Errors
    /// [`KtsClientError`] on `ERROR`, timeout or a closed link.
    pub async fn command(&self, cmd: KtsCommand) -> Result<Vec<KtsLine>, KtsClientError> {
        self.request(cmd, None).await
    }

    /// `ATI`: the identification text lines.
    ///
    /// # Errors
    /// As [`KtsClient::command`].
    pub async fn identify(&self) -> Result<Vec<String>, KtsClientError> {
        let lines = self.command(KtsCommand::Identify).await?;
        Ok(lines
            .into_iter()
            .filter_map(|l| match l {
                KtsLine::Info(s) => Some(s),
                _ => None,
            })
            .collect())
    }

    /// Starts continuous scanning with the configured command.
    ///
    /// # Errors
    /// As [`KtsClient::command`].
    pub async fn start_scan(&self) -> Result<(), KtsClientError> {
        self.request(
            KtsCommand::Raw(self.config.scan_command.clone()),
            Some(true),
        )
        .await
        .map(drop)
    }

    /// Stops scanning with the configured command.
    ///
    /// # Errors
    /// As [`KtsClient::command`].
    pub async fn stop_scan(&self) -> Result<(), KtsClientError> {
        self.request(
            KtsCommand::Raw(self.config.stop_command.clone()),
            Some(false),
        )
        .await
        .map(drop)
    }

    /// Sends `AT` and waits for `OK` (resynchronises the line after noise).
    ///
    /// # Errors
    /// As [`KtsClient::command`].
    pub async fn resync(&self) -> Result<(), KtsClientError> {
        self.command(KtsCommand::Attention).await.map(drop)
    }
}

impl KtsClient {
    /// Ends the client task and waits until it (and the link it owns) is gone, so that a caller
    /// backing off before a reconnect does not hold the old link open meanwhile.
    pub async fn close(mut self) {
        self.task.abort();
        let task = std::mem::replace(&mut self.task, tokio::spawn(async {}));
        let _ = task.await;
    }
}

impl Drop for KtsClient {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl TagEventSource for KtsClient {
    async fn next_event(&mut self) -> Option<TagEvent> {
        match self.events.as_mut() {
            Some(rx) => rx.recv().await,
            None => None,
        }
    }
}

enum Waiter {
    External {
        command: String,
        scanning: Option<bool>,
        reply: Reply,
        lines: Vec<KtsLine>,
        cme: Option<u32>,
        deadline: Instant,
    },
    ResyncAttention {
        deadline: Instant,
    },
    ResyncScan {
        deadline: Instant,
    },
}

impl Waiter {
    fn deadline(&self) -> Instant {
        match self {
            Waiter::External { deadline, .. }
            | Waiter::ResyncAttention { deadline }
            | Waiter::ResyncScan { deadline } => *deadline,
        }
    }
}

struct Worker {
    config: KtsConfig,
    clock: SharedClock,
    events: mpsc::Sender<TagEvent>,
    stats: Arc<Mutex<KtsStats>>,
    codec: KtsCodec,
    waiter: Option<Waiter>,
    scanning: bool,
    last_rx: Instant,
}

impl Worker {
    fn bump(&self, f: impl FnOnce(&mut KtsStats)) {
        if let Ok(mut s) = self.stats.lock() {
            f(&mut s);
        }
    }

    async fn run<T>(mut self, io: T, mut requests: mpsc::Receiver<Request>)
    where
        T: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let (mut rd, mut wr) = tokio::io::split(io);
        let mut buf = [0u8; 512];
        loop {
            let deadline = match &self.waiter {
                Some(w) => Some(w.deadline()),
                None if self.scanning => self.config.silence_timeout.map(|s| self.last_rx + s),
                None => None,
            };
            let far = Instant::now() + Duration::from_secs(3600);
            tokio::select! {
                biased;
                req = requests.recv(), if self.waiter.is_none() => {
                    let Some(Request::Command { cmd, scanning, reply }) = req else { break };
                    if let Err(e) = send(&mut wr, &cmd).await {
                        let _ = reply.send(Err(KtsClientError::Io(e.to_string())));
                        break;
                    }
                    self.waiter = Some(Waiter::External {
                        command: cmd.text().to_string(),
                        scanning,
                        reply,
                        lines: Vec::new(),
                        cme: None,
                        deadline: Instant::now() + self.config.command_timeout,
                    });
                }
                n = rd.read(&mut buf) => {
                    match n {
                        Ok(0) => { self.fail(KtsClientError::Closed); break; }
                        Err(e) => { self.fail(KtsClientError::Io(e.to_string())); break; }
                        Ok(n) => {
                            self.last_rx = Instant::now();
                            let lines = self.codec.decode(buf.get(..n).unwrap_or_default());
                            let codec_stats = self.codec.stats();
                            self.bump(|s| s.codec = codec_stats);
                            for line in lines.into_iter().flatten() {
                                if let Some(next) = self.on_line(line) {
                                    if send(&mut wr, &next).await.is_err() {
                                        self.fail(KtsClientError::Closed);
                                        return;
                                    }
                                }
                            }
                        }
                    }
                }
                () = tokio::time::sleep_until(deadline.unwrap_or(far)), if deadline.is_some() => {
                    if let Some(next) = self.on_timeout() {
                        if send(&mut wr, &next).await.is_err() {
                            self.fail(KtsClientError::Closed);
                            break;
                        }
                    }
                }
            }
        }
    }

    fn fail(&mut self, e: KtsClientError) {
        if let Some(Waiter::External { reply, .. }) = self.waiter.take() {
            let _ = reply.send(Err(e));
        }
    }

    /// Handles a silence or command deadline; returns a command to send.
    fn on_timeout(&mut self) -> Option<KtsCommand> {
        self.last_rx = Instant::now();
        match self.waiter.take() {
            Some(Waiter::External {
                command,
                reply,
                cme: Some(code),
                ..
            }) => {
                let _ = reply.send(Err(KtsClientError::Device {
                    command,
                    cme: Some(code),
                }));
                None
            }
            Some(Waiter::External { command, reply, .. }) => {
                let _ = reply.send(Err(KtsClientError::Timeout(command)));
                None
            }
            Some(Waiter::ResyncAttention { .. } | Waiter::ResyncScan { .. }) => {
                tracing::warn!("kts: resync got no OK; will retry after the next silence");
                None
            }
            None => {
                tracing::warn!("kts: no data while scanning; resynchronising with AT");
                self.bump(|s| s.resyncs += 1);
                self.waiter = Some(Waiter::ResyncAttention {
                    deadline: Instant::now() + self.config.command_timeout,
                });
                Some(KtsCommand::Attention)
            }
        }
    }

    /// Handles one classified line; returns a command to send (resync sequence).
    fn on_line(&mut self, line: KtsLine) -> Option<KtsCommand> {
        match line {
            KtsLine::ScanSeen { uid, rssi } => {
                self.emit(TagEvent {
                    t: self.clock.now(),
                    uid,
                    kind: TagEventKind::Seen { rssi },
                });
                None
            }
            KtsLine::ScanLost { uid } => {
                self.emit(TagEvent {
                    t: self.clock.now(),
                    uid,
                    kind: TagEventKind::Lost,
                });
                None
            }
            KtsLine::Ok => match self.waiter.take() {
                Some(Waiter::External {
                    scanning,
                    reply,
                    lines,
                    ..
                }) => {
                    if let Some(s) = scanning {
                        self.scanning = s;
                    }
                    let _ = reply.send(Ok(lines));
                    None
                }
                Some(Waiter::ResyncAttention { .. }) => {
                    self.waiter = Some(Waiter::ResyncScan {
                        deadline: Instant::now() + self.config.command_timeout,
                    });
                    Some(KtsCommand::Raw(self.config.scan_command.clone()))
                }
                Some(Waiter::ResyncScan { .. }) => None,
                None => {
                    self.bump(|s| s.unsolicited_lines += 1);
                    None
                }
            },
            KtsLine::CmeError(code) => {
                if let Some(Waiter::External { cme, .. }) = &mut self.waiter {
                    *cme = Some(code);
                } else {
                    self.bump(|s| s.unsolicited_lines += 1);
                }
                None
            }
            KtsLine::Error => {
                match self.waiter.take() {
                    Some(Waiter::External {
                        command,
                        reply,
                        cme,
                        ..
                    }) => {
                        let _ = reply.send(Err(KtsClientError::Device { command, cme }));
                    }
                    Some(Waiter::ResyncAttention { .. } | Waiter::ResyncScan { .. }) => {
                        tracing::warn!("kts: resync answered ERROR");
                    }
                    None => self.bump(|s| s.unsolicited_lines += 1),
                }
                None
            }
            KtsLine::Echo(text) => {
                let is_echo = matches!(&self.waiter, Some(Waiter::External { command, .. }) if command.eq_ignore_ascii_case(&text));
                if !is_echo {
                    self.collect(KtsLine::Echo(text));
                }
                None
            }
            other @ (KtsLine::Inventory { .. } | KtsLine::Info(_)) => {
                self.collect(other);
                None
            }
        }
    }

    fn collect(&mut self, line: KtsLine) {
        if let Some(Waiter::External { lines, .. }) = &mut self.waiter {
            lines.push(line);
        } else {
            tracing::debug!(?line, "kts: unsolicited line");
            self.bump(|s| s.unsolicited_lines += 1);
        }
    }

    fn emit(&self, ev: TagEvent) {
        match self.events.try_send(ev) {
            Ok(()) => self.bump(|s| s.events_sent += 1),
            Err(e) => {
                tracing::warn!("kts: tag event dropped: {e}");
                self.bump(|s| s.events_dropped += 1);
            }
        }
    }
}

async fn send<W: AsyncWrite + Unpin>(wr: &mut W, cmd: &KtsCommand) -> std::io::Result<()> {
    tracing::debug!(command = cmd.text(), "kts: send");
    wr.write_all(&cmd.encode()).await?;
    wr.flush().await
}
