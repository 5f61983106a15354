//! Async client: handshake, watchdog keep-alive, odometry stream, motion commands,
//! reconnection and an orderly stop on shutdown.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use rfloc_pose::Pose2;
use rfloc_transport::{MonotonicClock, SharedClock};
use thiserror::Error;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::{sleep_until, timeout_at, Instant};
use tracing::Instrument;

use crate::command::{to_i16_clamped, vel2_units, ArgError, Command, CommandLimits};
use crate::frame::{Frame, FrameDecoder};
use crate::odometry::{ConversionFactors, OdometryTracker};
use crate::sip::{ConfigPacket, RobotIdentity, ServerPacket, SIP_MOVING, SIP_STOPPED};
use crate::sonar::SonarRing;

/// Errors of the client.
#[derive(Debug, Error)]
pub enum ClientError {
    /// Reading or writing the link failed.
    #[error("link i/o: {0}")]
    Io(#[from] io::Error),
    /// The robot did not complete the SYNC0/1/2 handshake.
    #[error("handshake failed after {attempts} attempts: {reason}")]
    Handshake {
        /// Attempts made.
        attempts: u32,
        /// Last reason.
        reason: String,
    },
    /// No link to the robot at the moment (reconnecting).
    #[error("not connected to the robot")]
    NotConnected,
    /// The client task has ended.
    #[error("client stopped")]
    Stopped,
    /// A command could not be encoded.
    #[error("command encoding: {0}")]
    Encode(#[from] ArgError),
    /// No CONFIG packet arrived in time.
    #[error("no CONFIG packet within {0:?}")]
    ConfigTimeout(Duration),
}

/// One odometry update, in metres and radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Odometry {
    /// Seconds on the client's clock when the SIP was decoded.
    pub time: f64,
    /// Pose in the odometry frame (origin where the client first connected or last sent SETO).
    pub pose: Pose2,
    /// Forward velocity, m/s.
    pub v: f64,
    /// Rotational velocity, rad/s, counter-clockwise positive.
    pub w: f64,
    /// Left wheel stalled.
    pub left_stall: bool,
    /// Right wheel stalled.
    pub right_stall: bool,
    /// Front bumper segments (bit per segment).
    pub front_bumpers: u8,
    /// Rear bumper segments (bit per segment).
    pub rear_bumpers: u8,
    /// Battery voltage, volts.
    pub battery_v: f64,
    /// Motors enabled.
    pub motors_enabled: bool,
    /// Number of motor SIPs decoded so far (0 = no odometry yet).
    pub seq: u64,
    /// The sonar ring's latest ranges (all `None` while sonar is off); `updated` says which
    /// discs this SIP brought.
    pub sonar: SonarRing,
}

/// State of the link, published on a watch channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkState {
    /// Handshaking (first connection or after a drop).
    Connecting,
    /// Connected to this robot.
    Connected(RobotIdentity),
    /// Shut down.
    Closed,
}

/// Counters of what the client dropped or skipped.
#[derive(Debug, Default)]
pub struct ClientCounters {
    dropped_bytes: AtomicU64,
    bad_checksums: AtomicU64,
    unknown_packets: AtomicU64,
    malformed_packets: AtomicU64,
    sips: AtomicU64,
    reconnects: AtomicU64,
    pulses: AtomicU64,
}

/// A snapshot of [`ClientCounters`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ClientStats {
    /// Bytes the frame decoder dropped (garbage, bad counts, bad checksums).
    pub dropped_bytes: u64,
    /// Frames rejected for a bad checksum.
    pub bad_checksums: u64,
    /// Packets of types the client does not interpret (counted and skipped).
    pub unknown_packets: u64,
    /// Motor SIPs or CONFIG packets that were truncated.
    pub malformed_packets: u64,
    /// Motor SIPs decoded.
    pub sips: u64,
    /// Successful reconnections after a drop.
    pub reconnects: u64,
    /// PULSE commands sent by the keep-alive.
    pub pulses: u64,
}

impl ClientCounters {
    fn snapshot(&self) -> ClientStats {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        ClientStats {
            dropped_bytes: g(&self.dropped_bytes),
            bad_checksums: g(&self.bad_checksums),
            unknown_packets: g(&self.unknown_packets),
            malformed_packets: g(&self.malformed_packets),
            sips: g(&self.sips),
            reconnects: g(&self.reconnects),
            pulses: g(&self.pulses),
        }
    }
}

/// Client settings. All periods are wall-clock; when the robot is an emulator running with
/// `time_scale` k, divide the pulse period and the timeouts by k as well.
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// Send PULSE when nothing else was sent for this long (robot watchdog is 2 s by default).
    pub pulse_period: Duration,
    /// How long to wait for each SYNC reply.
    pub sync_timeout: Duration,
    /// Handshake attempts (from SYNC0) before giving up.
    pub sync_attempts: u32,
    /// Declare the link lost after this long without a motor SIP.
    pub link_timeout: Duration,
    /// Pause between reconnection attempts.
    pub reconnect_delay: Duration,
    /// Send ENABLE 1 after OPEN.
    pub enable_motors: bool,
    /// Turn sonar on (true) or off after OPEN.
    pub sonar: bool,
    /// Limits applied to every command.
    pub limits: CommandLimits,
    /// Override the conversion factors chosen from the robot's subclass.
    pub factors: Option<ConversionFactors>,
    /// Time source for [`Odometry::time`] (default: monotonic time since the client started).
    pub clock: Option<SharedClock>,
    /// Keep the link open this long after CLOSE before dropping it, so the robot reads the
    /// CLOSE (ARIA waits 1 s after CLOSE; a pty discards unread bytes when its peer closes).
    pub close_linger: Duration,
    /// Size of the command queue.
    pub queue: usize,
    /// With a size, every SIP's odometry also goes into a queue of this size that the client
    /// task waits on when it is full ([`AriaClient::take_odometry_queue`]): no update is
    /// skipped, however fast SIPs arrive (a replay). 0: the latest value only (a watch).
    pub odometry_queue: usize,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            pulse_period: Duration::from_secs(1),
            sync_timeout: Duration::from_secs(1),
            sync_attempts: 5,
            link_timeout: Duration::from_secs(2),
            reconnect_delay: Duration::from_secs(1),
            enable_motors: true,
            sonar: false,
            limits: CommandLimits::P3DX,
            factors: None,
            clock: None,
            close_linger: Duration::from_secs(1),
            queue: 32,
            odometry_queue: 0,
        }
    }
}

/// Wall-time floors [`ClientConfig::scaled`] keeps on the waits that decide a link is dead or
/// done: SYNC reply, link loss, CLOSE linger. Fully scaled (time scale 10: 100 ms, 200 ms,
/// 100 ms of wall time) handshakes gave up on late replies, links were declared lost and a
/// CLOSE was dropped unread on a machine with a load average of 3–4 on 2 cores: the emulator's
/// bytes are late by scheduling, which no time scale shortens.
pub const SCALED_SYNC_TIMEOUT_FLOOR: Duration = Duration::from_secs(1);
pub const SCALED_LINK_TIMEOUT_FLOOR: Duration = Duration::from_secs(2);
pub const SCALED_CLOSE_LINGER_FLOOR: Duration = Duration::from_millis(500);

impl ClientConfig {
    /// Divides every period and timeout by `time_scale` (for an emulator running faster than
    /// wall time), except that the SYNC timeout, link timeout and CLOSE linger stay at least
    /// their wall-time floors ([`SCALED_LINK_TIMEOUT_FLOOR`] and the others) or their unscaled
    /// value when that is shorter. Non-positive or non-finite scales leave the config
    /// unchanged.
    #[must_use]
    pub fn scaled(mut self, time_scale: f64) -> Self {
        if time_scale.is_finite() && time_scale > 0.0 {
            let s = |d: Duration| d.div_f64(time_scale);
            let floored = |d: Duration, floor: Duration| s(d).max(d.min(floor));
            self.pulse_period = s(self.pulse_period);
            self.sync_timeout = floored(self.sync_timeout, SCALED_SYNC_TIMEOUT_FLOOR);
            self.link_timeout = floored(self.link_timeout, SCALED_LINK_TIMEOUT_FLOOR);
            self.reconnect_delay = s(self.reconnect_delay);
            self.close_linger = floored(self.close_linger, SCALED_CLOSE_LINGER_FLOOR);
        }
        self
    }
}

/// The robot-facing operations the daemon needs; implemented by [`AriaClient`] and
/// [`crate::MockBase`].
pub trait MobileBase: Send + Sync {
    /// Commands forward velocity `v` (m/s) and rotational velocity `w` (rad/s, CCW positive).
    fn set_velocity(&self, v: f64, w: f64) -> impl Future<Output = Result<(), ClientError>> + Send;
    /// Stops the robot (decelerating normally).
    fn stop(&self) -> impl Future<Output = Result<(), ClientError>> + Send;
    /// The odometry stream.
    fn odometry(&self) -> watch::Receiver<Odometry>;
}

/// A boxed future returned by a connector.
pub type ConnectFuture<T> = Pin<Box<dyn Future<Output = io::Result<T>> + Send>>;

enum Request {
    Command(Command, oneshot::Sender<Result<(), ClientError>>),
    Config(oneshot::Sender<Result<ConfigPacket, ClientError>>),
    Shutdown(oneshot::Sender<Result<(), ClientError>>),
}

/// Async driver for a Pioneer over any byte stream.
///
/// A background task owns the link: it answers the robot's SIPs with odometry updates, sends
/// PULSE when idle, reconnects through the connector when the link drops, and on
/// [`AriaClient::shutdown`] sends STOP then CLOSE.
#[derive(Debug)]
pub struct AriaClient {
    tx: mpsc::Sender<Request>,
    odometry: watch::Receiver<Odometry>,
    state: watch::Receiver<LinkState>,
    counters: Arc<ClientCounters>,
    identity: RobotIdentity,
    limits: CommandLimits,
    factors: ConversionFactors,
    task: Option<JoinHandle<()>>,
    odometry_queue: Option<mpsc::Receiver<Odometry>>,
}

impl AriaClient {
    /// Opens a link with `connector`, performs the handshake and starts the client task. Later
    /// drops are healed by calling `connector` again.
    ///
    /// # Errors
    /// The connector's error or [`ClientError::Handshake`] for the first connection.
    pub async fn connect<T, F>(mut connector: F, config: ClientConfig) -> Result<Self, ClientError>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
        F: FnMut() -> ConnectFuture<T> + Send + 'static,
    {
        let clock = config
            .clock
            .clone()
            .unwrap_or_else(|| Arc::new(MonotonicClock::new()));
        let counters = Arc::new(ClientCounters::default());
        let stream = connector().await?;
        let session = Session::handshake(stream, &config, &counters).await?;
        let identity = session.identity.clone();
        let factors = session.factors;
        let (tx, rx) = mpsc::channel(config.queue.max(1));
        let (odom_tx, odometry) = watch::channel(Odometry::default());
        let (state_tx, state) = watch::channel(LinkState::Connected(identity.clone()));
        let (odom_queue, odometry_queue) = match config.odometry_queue {
            0 => (None, None),
            n => {
                let (tx, rx) = mpsc::channel(n);
                (Some(tx), Some(rx))
            }
        };
        let limits = config.limits;
        let worker = Worker {
            config,
            clock,
            counters: Arc::clone(&counters),
            tracker: OdometryTracker::new(factors),
            sonar: SonarRing::p3dx(),
            odom_tx,
            odom_queue,
            state_tx,
            rx,
            seq: 0,
            log: rfloc_transport::LogLimit::default(),
        };
        let span = tracing::info_span!("aria", robot = %identity.name);
        let task = tokio::spawn(worker.run(connector, session).instrument(span));
        Ok(Self {
            tx,
            odometry,
            state,
            counters,
            identity,
            limits,
            factors,
            task: Some(task),
            odometry_queue,
        })
    }

    /// The lossless odometry queue of [`ClientConfig::odometry_queue`] (once).
    pub fn take_odometry_queue(&mut self) -> Option<mpsc::Receiver<Odometry>> {
        self.odometry_queue.take()
    }

    /// Connects over a single stream; reconnection is not possible (the link is reported lost
    /// and commands fail with [`ClientError::NotConnected`] after it drops).
    ///
    /// # Errors
    /// As [`AriaClient::connect`].
    pub async fn from_stream<T>(stream: T, config: ClientConfig) -> Result<Self, ClientError>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    {
        let mut slot = Some(stream);
        Self::connect(
            move || -> ConnectFuture<T> {
                let s = slot.take();
                Box::pin(async move {
                    s.ok_or_else(|| io::Error::new(io::ErrorKind::NotConnected, "single-use link"))
                })
            },
            config,
        )
        .await
    }

    /// The robot's SYNC2 identity from the first connection.
    #[must_use]
    pub fn identity(&self) -> &RobotIdentity {
        &self.identity
    }

    /// The limits every command is clamped to.
    #[must_use]
    pub fn limits(&self) -> CommandLimits {
        self.limits
    }

    /// The conversion factors in use (chosen from the subclass unless overridden).
    #[must_use]
    pub fn factors(&self) -> ConversionFactors {
        self.factors
    }

    /// The odometry stream.
    #[must_use]
    pub fn odometry(&self) -> watch::Receiver<Odometry> {
        self.odometry.clone()
    }

    /// The link state stream.
    #[must_use]
    pub fn link_state(&self) -> watch::Receiver<LinkState> {
        self.state.clone()
    }

    /// Counters of dropped bytes, bad checksums, unknown packets, reconnects, pulses.
    #[must_use]
    pub fn stats(&self) -> ClientStats {
        self.counters.snapshot()
    }

    /// Sends one command (clamped to the configured limits) and waits until it is written.
    ///
    /// # Errors
    /// [`ClientError::NotConnected`] while reconnecting, [`ClientError::Stopped`] after
    /// shutdown, or the write error.
    pub async fn send(&self, command: Command) -> Result<(), ClientError> {
        let (tx, rx) = oneshot::channel();
        self.tx
            .send(Request::Command(command, tx))
            .await
            .map_err(|_| ClientError::Stopped)?;
        rx.await.map_err(|_| ClientError::Stopped)?
    }

    /// VEL (mm/s) and RVEL (deg/s) from `v` m/s and `w` rad/s.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_velocity(&self, v: f64, w: f64) -> Result<(), ClientError> {
        self.send(Command::Vel(to_i16_clamped("VEL", v * 1000.0)))
            .await?;
        self.send(Command::Rvel(to_i16_clamped("RVEL", w.to_degrees())))
            .await
    }

    /// VEL2 from wheel speeds in m/s (quantised to the robot's VEL2 unit, 20 mm/s on a P3).
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_wheel_velocities(&self, left: f64, right: f64) -> Result<(), ClientError> {
        let div = self.factors.vel2_divisor;
        self.send(Command::Vel2 {
            left: vel2_units("VEL2 left", left * 1000.0, div),
            right: vel2_units("VEL2 right", right * 1000.0, div),
        })
        .await
    }

    /// HEAD: turn to an absolute heading in the robot's odometric frame (radians).
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_heading(&self, heading: f64) -> Result<(), ClientError> {
        // The robot takes 0..359 degrees; map any angle there without a clamp warning.
        let deg = to_i16_clamped("HEAD", rfloc_pose::wrap_angle(heading).to_degrees());
        self.send(Command::Head(deg.rem_euclid(360))).await
    }

    /// DHEAD: turn by `delta` radians.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn turn_by(&self, delta: f64) -> Result<(), ClientError> {
        self.send(Command::Dhead(to_i16_clamped("DHEAD", delta.to_degrees())))
            .await
    }

    /// SETV and SETRV: maximum velocities in m/s and rad/s.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_max_velocities(&self, v: f64, w: f64) -> Result<(), ClientError> {
        self.send(Command::SetV(to_i16_clamped("SETV", v * 1000.0)))
            .await?;
        self.send(Command::SetRv(to_i16_clamped("SETRV", w.to_degrees())))
            .await
    }

    /// SETA: translational acceleration (positive) or deceleration (negative), m/s².
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_acceleration(&self, a: f64) -> Result<(), ClientError> {
        self.send(Command::SetA(to_i16_clamped("SETA", a * 1000.0)))
            .await
    }

    /// STOP.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn stop(&self) -> Result<(), ClientError> {
        self.send(Command::Stop).await
    }

    /// E-STOP.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn emergency_stop(&self) -> Result<(), ClientError> {
        self.send(Command::EStop).await
    }

    /// ENABLE 1 / 0.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn enable_motors(&self, on: bool) -> Result<(), ClientError> {
        self.send(Command::Enable(on)).await
    }

    /// SONAR 1 / 0.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn set_sonar(&self, on: bool) -> Result<(), ClientError> {
        self.send(Command::Sonar(on)).await
    }

    /// SETO: resets the robot's odometry origin, and the published pose, to zero.
    ///
    /// # Errors
    /// As [`AriaClient::send`].
    pub async fn reset_odometry(&self) -> Result<(), ClientError> {
        self.send(Command::SetO).await
    }

    /// Requests a CONFIG packet and waits up to `wait` for it.
    ///
    /// # Errors
    /// [`ClientError::ConfigTimeout`] or as [`AriaClient::send`].
    pub async fn request_config(&self, wait: Duration) -> Result<ConfigPacket, ClientError> {
        let (tx, rx) = oneshot::channel();
        self.tx
            .send(Request::Config(tx))
            .await
            .map_err(|_| ClientError::Stopped)?;
        match tokio::time::timeout(wait, rx).await {
            Ok(r) => r.map_err(|_| ClientError::Stopped)?,
            Err(_) => Err(ClientError::ConfigTimeout(wait)),
        }
    }

    /// Stops the robot (STOP, then CLOSE) and ends the client task.
    ///
    /// # Errors
    /// The write error if the robot could not be told to stop.
    pub async fn shutdown(mut self) -> Result<(), ClientError> {
        let (tx, rx) = oneshot::channel();
        let sent = self.tx.send(Request::Shutdown(tx)).await.is_ok();
        let result = if sent {
            rx.await.unwrap_or(Err(ClientError::Stopped))
        } else {
            Err(ClientError::Stopped)
        };
        if let Some(task) = self.task.take() {
            let _ = task.await;
        }
        result
    }
}

impl MobileBase for AriaClient {
    async fn set_velocity(&self, v: f64, w: f64) -> Result<(), ClientError> {
        AriaClient::set_velocity(self, v, w).await
    }
    async fn stop(&self) -> Result<(), ClientError> {
        AriaClient::stop(self).await
    }
    fn odometry(&self) -> watch::Receiver<Odometry> {
        AriaClient::odometry(self)
    }
}

/// One open link after the handshake.
struct Session<T> {
    stream: T,
    decoder: FrameDecoder,
    identity: RobotIdentity,
    factors: ConversionFactors,
    last_write: Instant,
    last_sip: Instant,
    /// Decoder counters already added to the shared counters.
    seen_dropped: u64,
    seen_bad: u64,
}

/// How a session ended.
enum SessionEnd {
    Shutdown,
    LinkLost(String),
}

async fn write_command<T: AsyncWrite + Unpin>(
    stream: &mut T,
    command: &Command,
    limits: &CommandLimits,
) -> Result<(), ClientError> {
    let bytes = command.encode(limits)?;
    stream.write_all(&bytes).await?;
    stream.flush().await?;
    Ok(())
}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> Session<T> {
    /// SYNC0/1/2 with retries, then OPEN, PULSE, ENABLE and SONAR.
    async fn handshake(
        mut stream: T,
        config: &ClientConfig,
        counters: &ClientCounters,
    ) -> Result<Self, ClientError> {
        let mut decoder = FrameDecoder::new();
        let limits = config.limits;
        let mut reason = String::from("no attempt");
        let mut identity = None;
        let mut buf = [0u8; 256];
        let attempts = config.sync_attempts.max(1);
        'attempt: for attempt in 1..=attempts {
            let mut step: u8 = 0;
            // Frames handled in this attempt; bounds the CLOSE loop against a chatty robot.
            let mut handled = 0u32;
            while step < 3 {
                let cmd = [Command::Sync0, Command::Sync1, Command::Sync2]
                    .into_iter()
                    .nth(usize::from(step))
                    .unwrap_or(Command::Sync0);
                write_command(&mut stream, &cmd, &limits).await?;
                let deadline = Instant::now() + config.sync_timeout;
                let frame = loop {
                    if let Some(r) = decoder.next_frame() {
                        if let Ok(f) = r {
                            break Some(f);
                        }
                        continue;
                    }
                    match timeout_at(deadline, stream.read(&mut buf)).await {
                        Err(_) => break None,
                        Ok(Ok(0)) => {
                            return Err(ClientError::Io(io::Error::new(
                                io::ErrorKind::UnexpectedEof,
                                "link closed during handshake",
                            )))
                        }
                        Ok(Ok(n)) => decoder.push(buf.get(..n).unwrap_or_default()),
                        Ok(Err(e)) => return Err(e.into()),
                    }
                };
                let Some(frame) = frame else {
                    reason = format!("no reply to SYNC{step}");
                    tracing::warn!(attempt, step, "ARIA handshake: no reply");
                    continue 'attempt;
                };
                handled += 1;
                if handled > 50 {
                    reason = "too many unexpected packets".into();
                    continue 'attempt;
                }
                match frame.id {
                    id if id == step => {
                        if step == 2 {
                            identity = Some(RobotIdentity::parse(&frame.payload));
                        }
                        step += 1;
                    }
                    SIP_STOPPED | SIP_MOVING => {
                        // The robot is still open from an earlier client: close it, start over.
                        tracing::info!("ARIA handshake: robot already open, sending CLOSE");
                        write_command(&mut stream, &Command::Close, &limits).await?;
                        step = 0;
                    }
                    other => {
                        tracing::warn!(
                            expected = step,
                            got = other,
                            "ARIA handshake: unexpected reply"
                        );
                        step = 0;
                    }
                }
            }
            break;
        }
        let Some(identity) = identity else {
            return Err(ClientError::Handshake { attempts, reason });
        };
        tracing::info!(name = %identity.name, class = %identity.class, subclass = %identity.subclass, "ARIA robot identified");
        write_command(&mut stream, &Command::Open, &limits).await?;
        write_command(&mut stream, &Command::Pulse, &limits).await?;
        if config.enable_motors {
            write_command(&mut stream, &Command::Enable(true), &limits).await?;
        }
        write_command(&mut stream, &Command::Sonar(config.sonar), &limits).await?;
        let factors = config
            .factors
            .unwrap_or_else(|| ConversionFactors::for_subclass(&identity.subclass));
        let now = Instant::now();
        let mut session = Session {
            stream,
            decoder,
            identity,
            factors,
            last_write: now,
            last_sip: now,
            seen_dropped: 0,
            seen_bad: 0,
        };
        session.sync_counters(counters);
        Ok(session)
    }

    fn sync_counters(&mut self, counters: &ClientCounters) {
        let d = self.decoder.dropped_bytes();
        let b = self.decoder.bad_checksums();
        counters
            .dropped_bytes
            .fetch_add(d - self.seen_dropped, Ordering::Relaxed);
        counters
            .bad_checksums
            .fetch_add(b - self.seen_bad, Ordering::Relaxed);
        self.seen_dropped = d;
        self.seen_bad = b;
    }

    async fn write(
        &mut self,
        command: &Command,
        limits: &CommandLimits,
    ) -> Result<(), ClientError> {
        write_command(&mut self.stream, command, limits).await?;
        self.last_write = Instant::now();
        Ok(())
    }
}

struct Worker {
    config: ClientConfig,
    clock: SharedClock,
    counters: Arc<ClientCounters>,
    tracker: OdometryTracker,
    sonar: SonarRing,
    odom_tx: watch::Sender<Odometry>,
    odom_queue: Option<mpsc::Sender<Odometry>>,
    state_tx: watch::Sender<LinkState>,
    rx: mpsc::Receiver<Request>,
    seq: u64,
    /// Malformed packets are logged a few at a time, then summarised.
    log: rfloc_transport::LogLimit,
}

impl Worker {
    async fn run<T, F>(mut self, mut connector: F, first: Session<T>)
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
        F: FnMut() -> ConnectFuture<T> + Send + 'static,
    {
        let mut session = Some(first);
        loop {
            let current = match session.take() {
                Some(s) => s,
                None => match self.reconnect(&mut connector).await {
                    Some(s) => s,
                    None => break,
                },
            };
            match self.session(current).await {
                SessionEnd::Shutdown => break,
                SessionEnd::LinkLost(why) => {
                    tracing::warn!(reason = %why, "ARIA link lost, reconnecting");
                    self.tracker.rebase();
                    let _ = self.state_tx.send(LinkState::Connecting);
                }
            }
        }
        let _ = self.state_tx.send(LinkState::Closed);
    }

    /// Reconnects until it succeeds (`Some`) or a shutdown is requested (`None`). Commands
    /// arriving meanwhile fail with `NotConnected`.
    async fn reconnect<T, F>(&mut self, connector: &mut F) -> Option<Session<T>>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
        F: FnMut() -> ConnectFuture<T> + Send + 'static,
    {
        let mut next_try = Instant::now() + self.config.reconnect_delay;
        loop {
            tokio::select! {
                req = self.rx.recv() => match req {
                    None => return None,
                    Some(Request::Shutdown(reply)) => {
                        let _ = reply.send(Ok(()));
                        return None;
                    }
                    Some(Request::Command(_, reply)) => { let _ = reply.send(Err(ClientError::NotConnected)); }
                    Some(Request::Config(reply)) => { let _ = reply.send(Err(ClientError::NotConnected)); }
                },
                () = sleep_until(next_try) => {
                    next_try = Instant::now() + self.config.reconnect_delay;
                    let stream = match connector().await {
                        Ok(s) => s,
                        Err(e) => {
                            tracing::warn!(error = %e, "ARIA reconnect: cannot open link");
                            continue;
                        }
                    };
                    match Session::handshake(stream, &self.config, &self.counters).await {
                        Ok(mut s) => {
                            if let Some(f) = self.config.factors {
                                s.factors = f;
                            }
                            if s.factors != self.tracker.factors() {
                                self.tracker.set_factors(s.factors);
                            }
                            self.counters.reconnects.fetch_add(1, Ordering::Relaxed);
                            let _ = self.state_tx.send(LinkState::Connected(s.identity.clone()));
                            tracing::info!("ARIA link re-established");
                            return Some(s);
                        }
                        Err(e) => tracing::warn!(error = %e, "ARIA reconnect: handshake failed"),
                    }
                }
            }
        }
    }

    /// Decodes one frame; a motor SIP gives its odometry.
    fn handle_frame(
        &mut self,
        frame: Frame,
        config_waiters: &mut Vec<oneshot::Sender<Result<ConfigPacket, ClientError>>>,
    ) -> Option<Odometry> {
        match ServerPacket::from_frame(frame) {
            Ok(ServerPacket::Motor(sip)) => {
                let s = self.tracker.update(&sip);
                self.sonar.update(&sip, &self.tracker.factors());
                self.seq += 1;
                self.counters.sips.fetch_add(1, Ordering::Relaxed);
                let odo = Odometry {
                    time: self.clock.now(),
                    pose: s.pose,
                    v: s.v,
                    w: s.w,
                    left_stall: s.stall_bumpers.left_stall(),
                    right_stall: s.stall_bumpers.right_stall(),
                    front_bumpers: s.stall_bumpers.front_bumpers(),
                    rear_bumpers: s.stall_bumpers.rear_bumpers(),
                    battery_v: s.battery_v,
                    motors_enabled: s.motors_enabled,
                    seq: self.seq,
                    sonar: self.sonar,
                };
                let _ = self.odom_tx.send(odo);
                return Some(odo);
            }
            Ok(ServerPacket::Config(c)) => {
                for w in config_waiters.drain(..) {
                    let _ = w.send(Ok(c.clone()));
                }
            }
            Ok(ServerPacket::SyncEcho(_) | ServerPacket::Identity(_)) => {}
            Ok(ServerPacket::Other(f)) => {
                self.counters
                    .unknown_packets
                    .fetch_add(1, Ordering::Relaxed);
                tracing::debug!(id = f.id, len = f.payload.len(), "ARIA packet type skipped");
            }
            Err(e) => {
                self.counters
                    .malformed_packets
                    .fetch_add(1, Ordering::Relaxed);
                if let Some(suppressed) = self.log.hit() {
                    tracing::warn!(error = %e, suppressed, "ARIA malformed packet");
                }
            }
        }
        None
    }

    async fn session<T>(&mut self, mut s: Session<T>) -> SessionEnd
    where
        T: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let limits = self.config.limits;
        let mut buf = [0u8; 512];
        let mut config_waiters = Vec::new();
        loop {
            // Frames already buffered (e.g. read during the handshake).
            while let Some(r) = s.decoder.next_frame() {
                if let Ok(frame) = r {
                    if let Some(odo) = self.handle_frame(frame, &mut config_waiters) {
                        if let Some(q) = &self.odom_queue {
                            // Waits while the consumer is behind; a dropped consumer is fine.
                            let _ = q.send(odo).await;
                        }
                        // After delivery: a wait on the consumer is not silence of the robot.
                        s.last_sip = Instant::now();
                    }
                }
            }
            s.sync_counters(&self.counters);
            let pulse_at = s.last_write + self.config.pulse_period;
            let lost_at = s.last_sip + self.config.link_timeout;
            tokio::select! {
                r = s.stream.read(&mut buf) => match r {
                    Ok(0) => return SessionEnd::LinkLost("end of stream".into()),
                    Ok(n) => s.decoder.push(buf.get(..n).unwrap_or_default()),
                    Err(e) => return SessionEnd::LinkLost(e.to_string()),
                },
                req = self.rx.recv() => {
                    let Some(req) = req else {
                        // Every handle dropped: stop the robot as on shutdown.
                        let _ = close(&mut s, &limits).await;
                        tokio::time::sleep(self.config.close_linger).await;
                        return SessionEnd::Shutdown;
                    };
                    match req {
                        Request::Command(cmd, reply) => {
                            let r = s.write(&cmd, &limits).await;
                            let failed = r.as_ref().err().map(ToString::to_string);
                            if r.is_ok() && cmd == Command::SetO {
                                self.tracker.reset_origin();
                            }
                            let _ = reply.send(r);
                            if let Some(e) = failed {
                                return SessionEnd::LinkLost(e);
                            }
                        }
                        Request::Config(reply) => match s.write(&Command::Config, &limits).await {
                            Ok(()) => config_waiters.push(reply),
                            Err(e) => {
                                let why = e.to_string();
                                let _ = reply.send(Err(e));
                                return SessionEnd::LinkLost(why);
                            }
                        },
                        Request::Shutdown(reply) => {
                            let r = close(&mut s, &limits).await;
                            tokio::time::sleep(self.config.close_linger).await;
                            let _ = reply.send(r);
                            return SessionEnd::Shutdown;
                        }
                    }
                },
                () = sleep_until(pulse_at) => {
                    if let Err(e) = s.write(&Command::Pulse, &limits).await {
                        return SessionEnd::LinkLost(e.to_string());
                    }
                    self.counters.pulses.fetch_add(1, Ordering::Relaxed);
                },
                () = sleep_until(lost_at) => {
                    return SessionEnd::LinkLost(format!("no SIP for {:?}", self.config.link_timeout));
                },
            }
        }
    }
}

/// STOP then CLOSE.
async fn close<T: AsyncRead + AsyncWrite + Unpin + Send>(
    s: &mut Session<T>,
    limits: &CommandLimits,
) -> Result<(), ClientError> {
    s.write(&Command::Stop, limits).await?;
    s.write(&Command::Close, limits).await?;
    tracing::info!("ARIA robot stopped and connection closed");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sip::{MotorSip, SipTail, StallBumpers};
    use rfloc_transport::MockTransport;

    fn bytes(c: Command) -> Vec<u8> {
        c.encode(&CommandLimits::P3DX).unwrap()
    }

    #[test]
    fn scaling_keeps_the_wall_time_floors() {
        let c = ClientConfig::default().scaled(20.0);
        assert_eq!(c.pulse_period, Duration::from_millis(50));
        assert_eq!(c.reconnect_delay, Duration::from_millis(50));
        assert_eq!(c.sync_timeout, SCALED_SYNC_TIMEOUT_FLOOR);
        assert_eq!(c.link_timeout, SCALED_LINK_TIMEOUT_FLOOR);
        assert_eq!(c.close_linger, SCALED_CLOSE_LINGER_FLOOR);
        // A floor never lengthens what was shorter unscaled; a slow-down scale lengthens all.
        let short = ClientConfig {
            link_timeout: Duration::from_millis(300),
            ..ClientConfig::default()
        }
        .scaled(10.0);
        assert_eq!(short.link_timeout, Duration::from_millis(300));
        let slow = ClientConfig::default().scaled(0.5);
        assert_eq!(slow.link_timeout, Duration::from_secs(4));
        assert_eq!(
            ClientConfig::default().scaled(f64::NAN).link_timeout,
            Duration::from_secs(2)
        );
    }

    /// docs/protocols/pioneer-aria.md §8 Example G.
    fn example_g() -> Vec<u8> {
        MotorSip {
            moving: true,
            x_raw: 1000,
            y_raw: 0x7E0C,
            th_raw: 1024,
            left_vel: 200,
            right_vel: 200,
            battery_dv: 125,
            stall_bumpers: StallBumpers(0),
            control: 0,
            flags: 1,
            compass: 0,
            sonar: vec![],
            grip_state: 0,
            an_port: 0,
            analog: 0,
            digin: 0,
            digout: 0,
            tail: SipTail::default(),
        }
        .to_frame()
        .encode()
        .unwrap()
    }

    /// The exact byte sequence of a connection: a robot still open from an earlier client
    /// (a SIP instead of the SYNC0 echo) is closed first; then SYNC0/1/2 (ref §3.1, §3.2), OPEN,
    /// PULSE, ENABLE 1, SONAR 0; VEL/RVEL; STOP and CLOSE on shutdown.
    #[tokio::test]
    async fn connection_byte_sequence() {
        // Example F: MobileSim's identity, subclass p3dx → DistConvFactor 0.485.
        let identity = RobotIdentity {
            name: "MobileSim".into(),
            class: "Pioneer".into(),
            subclass: "p3dx".into(),
        };
        let mock = MockTransport::builder()
            .expect_write(bytes(Command::Sync0))
            .reply(example_g())
            .expect_write(bytes(Command::Close))
            .expect_write(bytes(Command::Sync0))
            .reply([0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00])
            .expect_write(bytes(Command::Sync1))
            .reply([0xFA, 0xFB, 0x03, 0x01, 0x00, 0x01])
            .expect_write(bytes(Command::Sync2))
            .reply(identity.to_frame().encode().unwrap())
            .expect_write(bytes(Command::Open))
            .expect_write(bytes(Command::Pulse))
            .expect_write(bytes(Command::Enable(true)))
            .expect_write(bytes(Command::Sonar(false)))
            // Garbage, then a SIP.
            .reply([0x00, 0x13, 0x37])
            .reply(example_g())
            .expect_write([0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0xC8, 0x00, 0xD3, 0x3B]) // VEL 200
            .expect_write([0xFA, 0xFB, 0x06, 0x15, 0x1B, 0x1E, 0x00, 0x33, 0x1B]) // RVEL −30
            .expect_write(bytes(Command::Stop))
            .expect_write(bytes(Command::Close))
            .build();
        let probe = mock.clone();
        let config = ClientConfig {
            close_linger: Duration::ZERO,
            ..ClientConfig::default()
        };
        let client = AriaClient::from_stream(mock, config).await.unwrap();
        assert_eq!(client.identity(), &identity);
        assert!((client.factors().dist_conv - 0.485).abs() < 1e-12);
        let mut rx = client.odometry();
        let odo = *rx.wait_for(|o| o.seq == 1).await.unwrap();
        assert!((odo.pose.x - 0.485).abs() < 1e-12);
        assert!((odo.pose.theta - 1024.0 * 0.001534).abs() < 1e-12);
        assert!((odo.v - 0.2).abs() < 1e-12);
        assert!((odo.battery_v - 12.5).abs() < 1e-12);
        client.set_velocity(0.2, -30f64.to_radians()).await.unwrap();
        let stats = client.stats();
        assert_eq!(stats.dropped_bytes, 3);
        client.shutdown().await.unwrap();
        assert_eq!(probe.error(), None);
        assert!(probe.is_done());
    }
}
