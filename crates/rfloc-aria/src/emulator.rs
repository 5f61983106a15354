//! A differential-drive Pioneer that serves the protocol over any byte stream, for tests and
//! the simulator.
//!
//! Simulated time advances in fixed steps of one SIP period per tick. By default ticks happen
//! every `sip_period / time_scale` of wall time, so with `time_scale = k` the robot runs k times
//! faster than wall time. Everything the robot does is in simulated time: accelerations, the SIP
//! period and the watchdog. A client talking to a scaled emulator must scale its own periods too
//! (see [`crate::ClientConfig::scaled`]): with the default 1 s pulse and `time_scale` 10 the
//! client must pulse every 100 ms of wall time, or the 2 s (simulated) watchdog, 200 ms of wall
//! time, stops the robot. When the emulator task falls behind wall time, ticks are delayed, not
//! bunched: simulated time then runs slower than `time_scale`, never jumps. A command and a tick
//! that are ready at once are taken in that order (the command is in force for the tick).
//!
//! Lock-step mode ([`RobotEmulator::lock_step`]) replaces the wall-clock ticker: time advances
//! only when the returned [`StepControl`] asks for ticks, and each request names how many bytes
//! the emulator must have read (cumulatively, over all links) before it may tick. A simulator
//! that passes the number of bytes its client has written therefore has every command it sent
//! handled before the tick, however late the kernel delivers the bytes through a pty, and a run
//! is a function of its inputs alone.

use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_pose::{wrap_angle, Pose2};
use thiserror::Error;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::MissedTickBehavior;
use tracing::Instrument;

use crate::command::{number, Arg, Command, LinkPhase};
use crate::frame::{Frame, FrameDecoder};
use crate::odometry::ConversionFactors;
use crate::sip::{
    ConfigMore, ConfigPacket, MotorSip, RobotIdentity, SipTail, SonarReading, StallBumpers,
};
use crate::sonar::{p3dx_discs, SonarDisc, NO_ECHO_M};

/// Substeps of the kinematics per SIP period.
const SUBSTEPS: u32 = 10;

/// Wheel slip applied to the ground-truth motion only (the encoders do not see it).
///
/// The draws of tick `k` (the k-th SIP period since the emulator was created) come from stream
/// `k` of a ChaCha8 generator seeded with `seed`, so the slip is a function of simulated time:
/// how long the emulator ran before a client connected or the robot moved does not change it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelSlip {
    /// Seed of the ChaCha8 generator.
    pub seed: u64,
    /// Standard deviation of the per-substep relative error of each wheel's ground speed.
    pub relative_std: f64,
}

/// Emulator settings. Durations are simulated time.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// Reply to SYNC2 (subclass also selects the conversion factors).
    pub identity: RobotIdentity,
    /// Conversion factors; `None` = chosen from the subclass as a client would.
    pub factors: Option<ConversionFactors>,
    /// Simulated seconds per wall second (default 1.0). Scale the client's periods by the same
    /// factor ([`crate::ClientConfig::scaled`]).
    pub time_scale: f64,
    /// SIP period (default 100 ms).
    pub sip_period: Duration,
    /// Watchdog: stop the robot when no command arrived for this long (default 2 s).
    pub watchdog: Duration,
    /// Distance between the wheels, mm (default 2 / DiffConvFactor ≈ 357 mm, so the
    /// `(R − L)/2 · DiffConvFactor` rule gives back the rotational velocity).
    pub wheel_track_mm: f64,
    /// Translational acceleration and deceleration, mm/s² (default 300 / 300).
    pub trans_accel: f64,
    /// Translational deceleration, mm/s².
    pub trans_decel: f64,
    /// Rotational acceleration, deg/s² (default 100).
    pub rot_accel: f64,
    /// Rotational deceleration, deg/s² (default 100).
    pub rot_decel: f64,
    /// Top translational velocity, mm/s (default 2200).
    pub trans_vel_top: f64,
    /// Top rotational velocity, deg/s (default 500).
    pub rot_vel_top: f64,
    /// Battery voltage in tenths of a volt (default 125).
    pub battery_dv: u8,
    /// Range reported by every sonar disc when sonar is on, mm (default 5000).
    pub sonar_range_mm: u16,
    /// Ground truth at start.
    pub initial_pose: Pose2,
    /// Optional wheel slip on the ground truth.
    pub slip: Option<WheelSlip>,
    /// Probability (0..1) of sending 1-8 random garbage bytes before a SIP (seeded by
    /// `noise_seed`), to exercise the client's resynchronisation.
    pub garbage_probability: f64,
    /// Seed for the garbage generator.
    pub noise_seed: u64,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            identity: RobotIdentity {
                name: "rfloc-emulator".into(),
                class: "Pioneer".into(),
                subclass: "p3dx-sh".into(),
            },
            factors: None,
            time_scale: 1.0,
            sip_period: Duration::from_millis(100),
            watchdog: Duration::from_secs(2),
            wheel_track_mm: 2.0 / ConversionFactors::P3DX_SH.diff_conv,
            trans_accel: 300.0,
            trans_decel: 300.0,
            rot_accel: 100.0,
            rot_decel: 100.0,
            trans_vel_top: 2200.0,
            rot_vel_top: 500.0,
            battery_dv: 125,
            sonar_range_mm: 5000,
            initial_pose: Pose2::default(),
            slip: None,
            garbage_probability: 0.0,
            noise_seed: 0,
        }
    }
}

/// What the emulator shows the outside world (the simulator and tests).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EmulatorState {
    /// Simulated seconds since the emulator was created.
    pub sim_time: f64,
    /// Ground-truth pose, metres and radians.
    pub truth: Pose2,
    /// The robot's own odometry (what its SIPs report), metres and radians.
    pub odometry: Pose2,
    /// Forward velocity, m/s.
    pub v: f64,
    /// Rotational velocity, rad/s.
    pub w: f64,
    /// A client has opened the connection.
    pub open: bool,
    /// Motors enabled.
    pub motors_enabled: bool,
    /// The watchdog has stopped the robot and no command has arrived since.
    pub watchdog_tripped: bool,
    /// The motion hook clipped the last step (wheels stalled).
    pub stalled: bool,
    /// The clipped step pushed forward (front bumper ring in contact) / backward (rear ring).
    pub bumped_front: bool,
    pub bumped_rear: bool,
    /// Times the watchdog stopped the robot.
    pub watchdog_trips: u64,
    /// Motor SIPs sent.
    pub sips_sent: u64,
    /// Command frames received and understood.
    pub commands: u64,
    /// Commands ignored (unsupported number or malformed argument).
    pub ignored_commands: u64,
    /// Bytes the emulator's decoder dropped.
    pub dropped_bytes: u64,
    /// OPEN commands accepted (connections made).
    pub opens: u64,
    /// CLOSE commands received.
    pub closes: u64,
    /// Bytes read from the links (all links served so far).
    pub rx_bytes: u64,
    /// Bytes written to the links (all links served so far).
    pub tx_bytes: u64,
    /// SIP periods simulated since the emulator was created.
    pub ticks: u64,
}

/// Read-only view of a running emulator.
#[derive(Debug, Clone)]
pub struct EmulatorHandle {
    rx: watch::Receiver<EmulatorState>,
}

impl EmulatorHandle {
    /// The latest state.
    #[must_use]
    pub fn state(&self) -> EmulatorState {
        *self.rx.borrow()
    }

    /// Ground truth.
    #[must_use]
    pub fn truth(&self) -> Pose2 {
        self.rx.borrow().truth
    }

    /// A receiver that is notified after every simulation step.
    #[must_use]
    pub fn subscribe(&self) -> watch::Receiver<EmulatorState> {
        self.rx.clone()
    }
}

/// Errors of [`RobotEmulator::serve`] and [`StepControl::advance`].
#[derive(Debug, Error)]
pub enum EmulatorError {
    /// Reading or writing the stream failed.
    #[error("emulator link i/o: {0}")]
    Io(#[from] std::io::Error),
    /// The emulator is not serving (its task ended, or the link closed with a step pending).
    #[error("emulator is not serving")]
    NotServing,
}

/// One request of a [`StepControl`].
#[derive(Debug)]
struct StepRequest {
    ticks: u32,
    after_rx_bytes: u64,
    done: oneshot::Sender<EmulatorState>,
}

/// Drives an emulator in lock-step mode (see [`RobotEmulator::lock_step`]). Cheap to clone.
#[derive(Debug, Clone)]
pub struct StepControl {
    tx: mpsc::Sender<StepRequest>,
}

impl StepControl {
    /// Simulates `ticks` SIP periods once the emulator has read at least `after_rx_bytes` bytes
    /// (counted over every link it served) and handled every command in them; returns the state
    /// after the last tick, once its SIP (if the connection is open) has been written.
    ///
    /// Pass the number of bytes the client has written so far: a command whose write returned
    /// before this call is then in force for the ticks. A client that wants every SIP read at
    /// the simulated time it was sent asks for one tick at a time and reads the SIP before the
    /// next call.
    ///
    /// # Errors
    /// [`EmulatorError::NotServing`] when the emulator is not serving a link, or stopped
    /// serving (end of stream) before the ticks.
    pub async fn advance(
        &self,
        ticks: u32,
        after_rx_bytes: u64,
    ) -> Result<EmulatorState, EmulatorError> {
        let (done, rx) = oneshot::channel();
        self.tx
            .send(StepRequest {
                ticks,
                after_rx_bytes,
                done,
            })
            .await
            .map_err(|_| EmulatorError::NotServing)?;
        rx.await.map_err(|_| EmulatorError::NotServing)
    }
}

/// Waits for the next step request; never resolves without a receiver.
async fn next_step(steps: &mut Option<mpsc::Receiver<StepRequest>>) -> Option<StepRequest> {
    match steps {
        Some(rx) => rx.recv().await,
        None => std::future::pending().await,
    }
}

/// Called with (current truth, proposed truth) for every motion step; returns the truth to
/// accept (e.g. clipped at a wall). Returning anything but the proposal counts as a stall.
pub type MotionHook = Box<dyn FnMut(&Pose2, &Pose2) -> Pose2 + Send>;

/// Called with (current truth, disc) for each sonar reading the emulator reports; returns the
/// range to the nearest echo in metres, `None` for no echo (reported as 5 m).
pub type SonarHook = Box<dyn FnMut(&Pose2, &SonarDisc) -> Option<f64> + Send>;

#[derive(Debug, Clone, Copy, PartialEq)]
enum RotMode {
    /// deg/s.
    Velocity(f64),
    /// Target heading in the odometric frame, radians.
    Heading(f64),
}

/// A Pioneer P3-DX: ARCOS-like command handling over differential-drive kinematics.
pub struct RobotEmulator {
    config: EmulatorConfig,
    factors: ConversionFactors,
    hook: Option<MotionHook>,
    sonar_hook: Option<SonarHook>,
    state_tx: watch::Sender<EmulatorState>,
    st: EmulatorState,
    /// Wheel slip: seed, distribution, and the generator of the current tick.
    slip: Option<(u64, Normal<f64>, ChaCha8Rng)>,
    garbage_rng: ChaCha8Rng,
    /// Lock-step mode: step requests (`None` once every [`StepControl`] is gone).
    steps: Option<mpsc::Receiver<StepRequest>>,
    lock_step: bool,
    // Robot state in robot units.
    v_mm: f64,
    w_deg: f64,
    trans_set: f64,
    rot_mode: RotMode,
    wheels: Option<(f64, f64)>,
    max_v: f64,
    max_rv: f64,
    accel: (f64, f64, f64, f64),
    sonar_on: bool,
    sonar_next: u8,
    sync_stage: u8,
    last_command_time: f64,
    encoders: (f64, f64),
    encoder_stream: bool,
    /// BATTERYINFO (#62) ≥ 2: a battery packet (0xFA) after every SIP.
    battery_stream: bool,
    /// BATTEST (#250): battery voltage override, decivolts (0 = real).
    battery_test_dv: u8,
    /// HOSTBAUD (#50) and AUX1..3BAUD (#51-#53) codes, reported in CONFIG.
    host_baud: u8,
    aux_baud: [u8; 3],
    /// BUMPSTALL (#44): 1 front, 2 rear, 3 both rings register a stall.
    bump_stall: u8,
    /// SOUNDTOG (#92): buzzer on.
    sound_on: bool,
    /// SONARCYCLE (#48), ms.
    sonar_cycle_ms: u8,
}

/// Command numbers the emulator handles beyond the typed [`Command`] set (docs §4).
mod extra {
    /// MOVE (not emulated: acknowledged and ignored, see the docs).
    pub const MOVE: u8 = 8;
    /// ROTATE: rotational velocity, deg/s (a duplicate of RVEL in ARCOS).
    pub const ROTATE: u8 = 9;
    /// JOYINFO: joystick packets; the robot has no joystick, ignored.
    pub const JOYINFO: u8 = 17;
    /// ENCODER: 0 stop, 1 one packet, ≥ 2 continuous.
    pub const ENCODER: u8 = 19;
    /// DCHEAD: heading relative to the current heading setpoint, degrees.
    pub const DCHEAD: u8 = 22;
    /// IOREQUEST: I/O packets; not emulated, ignored.
    pub const IOREQUEST: u8 = 40;
    /// TTY2: a string for the AUX1 serial port; nothing is attached, ignored.
    pub const TTY2: u8 = 42;
    /// BUMPSTALL: 0 none, 1 front, 2 rear, 3 both rings stall.
    pub const BUMPSTALL: u8 = 44;
    /// SONARCYCLE: sonar cycle time, ms.
    pub const SONARCYCLE: u8 = 48;
    /// HOSTBAUD: host port baud code 0..4.
    pub const HOSTBAUD: u8 = 50;
    /// AUX1BAUD.
    pub const AUX1BAUD: u8 = 51;
    /// AUX3BAUD (AUX2BAUD is 52).
    pub const AUX3BAUD: u8 = 53;
    /// E_STALL enable; ignored.
    pub const ESTALL: u8 = 56;
    /// GYRO packets; the emulated P3-DX has no gyro, ignored.
    pub const GYRO: u8 = 58;
    /// BATTERYINFO: battery packets 0xFA, 0 stop, 1 one, 2 continuous.
    pub const BATTERYINFO: u8 = 62;
    /// SOUNDTOG: 1 buzzer on, 0 off.
    pub const SOUNDTOG: u8 = 92;
    /// BATTEST: fake battery voltage in decivolts, 0 = real.
    pub const BATTEST: u8 = 250;
}

/// Packet type of the battery information packet (ARIA `ArRobotBatteryPacketReader`).
pub const BATTERY_PACKET: u8 = 0xFA;

impl std::fmt::Debug for RobotEmulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotEmulator")
            .field("config", &self.config)
            .field("state", &self.st)
            .finish_non_exhaustive()
    }
}

impl RobotEmulator {
    /// A robot at `config.initial_pose`, waiting for a handshake.
    #[must_use]
    pub fn new(config: EmulatorConfig) -> Self {
        let factors = config
            .factors
            .unwrap_or_else(|| ConversionFactors::for_subclass(&config.identity.subclass));
        let st = EmulatorState {
            truth: config.initial_pose,
            ..EmulatorState::default()
        };
        let (state_tx, _) = watch::channel(st);
        let slip = config.slip.and_then(|s| {
            let normal = Normal::new(0.0, s.relative_std.abs()).ok()?;
            Some((s.seed, normal, ChaCha8Rng::seed_from_u64(s.seed)))
        });
        let garbage_rng = ChaCha8Rng::seed_from_u64(config.noise_seed);
        Self {
            max_v: config.trans_vel_top,
            max_rv: config.rot_vel_top,
            accel: (
                config.trans_accel,
                config.trans_decel,
                config.rot_accel,
                config.rot_decel,
            ),
            config,
            factors,
            hook: None,
            sonar_hook: None,
            state_tx,
            st,
            slip,
            garbage_rng,
            steps: None,
            lock_step: false,
            v_mm: 0.0,
            w_deg: 0.0,
            trans_set: 0.0,
            rot_mode: RotMode::Velocity(0.0),
            wheels: None,
            sonar_on: false,
            sonar_next: 0,
            sync_stage: 0,
            last_command_time: 0.0,
            encoders: (0.0, 0.0),
            encoder_stream: false,
            battery_stream: false,
            battery_test_dv: 0,
            host_baud: 0,
            aux_baud: [0; 3],
            bump_stall: 0,
            sound_on: true,
            sonar_cycle_ms: 40,
        }
    }

    /// Installs a motion hook (walls, bumpers).
    #[must_use]
    pub fn with_motion_hook(mut self, hook: MotionHook) -> Self {
        self.hook = Some(hook);
        self
    }

    /// Installs a sonar hook: with sonar on, each SIP's readings (four discs in turn) are the
    /// hook's ranges at the true pose for the P3-DX discs, instead of `sonar_range_mm`.
    #[must_use]
    pub fn with_sonar_hook(mut self, hook: SonarHook) -> Self {
        self.sonar_hook = Some(hook);
        self
    }

    /// Switches to lock-step mode: from now on simulated time advances only through the
    /// returned control (and its clones), never with wall time; `time_scale` is ignored. Call
    /// again to replace the control (earlier ones then fail with
    /// [`EmulatorError::NotServing`]).
    #[must_use]
    pub fn lock_step(&mut self) -> StepControl {
        let (tx, rx) = mpsc::channel(4);
        self.steps = Some(rx);
        self.lock_step = true;
        StepControl { tx }
    }

    /// A handle to read the state (ground truth) while [`RobotEmulator::serve`] runs.
    #[must_use]
    pub fn handle(&self) -> EmulatorHandle {
        EmulatorHandle {
            rx: self.state_tx.subscribe(),
        }
    }

    /// The conversion factors the robot reports in.
    #[must_use]
    pub fn factors(&self) -> ConversionFactors {
        self.factors
    }

    /// Serves one link until it ends (end of stream: `Ok`). The robot's pose and settings
    /// persist across calls. When a link ends without CLOSE the robot stays open (as a real
    /// controller does when its cable is pulled) but is stopped, as its watchdog would do; no
    /// time passes between links. The next link then receives SIPs straight away, and its client
    /// must CLOSE and handshake again.
    ///
    /// # Errors
    /// [`EmulatorError::Io`] if the stream fails.
    pub async fn serve<S>(&mut self, stream: S) -> Result<(), EmulatorError>
    where
        S: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let span = tracing::info_span!("aria-emulator", robot = %self.config.identity.name);
        let result = self.serve_inner(stream).instrument(span).await;
        self.link_ended();
        result
    }

    async fn serve_inner<S>(&mut self, stream: S) -> Result<(), EmulatorError>
    where
        S: AsyncRead + AsyncWrite + Unpin + Send,
    {
        // The step receiver lives in `self` across links; borrow it out for this one.
        let mut steps = self.steps.take();
        let result = self.serve_link(stream, &mut steps).await;
        self.steps = steps;
        result
    }

    async fn serve_link<S>(
        &mut self,
        mut stream: S,
        steps: &mut Option<mpsc::Receiver<StepRequest>>,
    ) -> Result<(), EmulatorError>
    where
        S: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let scale = if self.config.time_scale.is_finite() && self.config.time_scale > 0.0 {
            self.config.time_scale
        } else {
            1.0
        };
        let wall_period = self
            .config
            .sip_period
            .div_f64(scale)
            .max(Duration::from_micros(100));
        let mut ticker = tokio::time::interval(wall_period);
        // A late emulator slows simulated time down rather than catching up in a burst, so a
        // stalled process cannot make the watchdog fire on a client that pulsed on time.
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        let wall_clock = !self.lock_step;
        let mut decoder = FrameDecoder::new();
        let mut buf = [0u8; 512];
        let mut pending: Option<StepRequest> = None;
        // An earlier link may have been dropped mid-session (task aborted).
        self.link_ended();
        self.sync_stage = 0;
        loop {
            if pending
                .as_ref()
                .is_some_and(|p| self.st.rx_bytes >= p.after_rx_bytes)
            {
                if let Some(req) = pending.take() {
                    for _ in 0..req.ticks {
                        self.tick(&mut stream).await?;
                    }
                    let _ = req.done.send(self.st);
                }
                continue;
            }
            // Biased: bytes already received are handled before a tick that is due at the same
            // moment, so a command never loses a race against the ticker.
            tokio::select! {
                biased;
                r = stream.read(&mut buf) => {
                    let n = match r {
                        Ok(0) => return Ok(()),
                        Ok(n) => n,
                        Err(e) => return Err(e.into()),
                    };
                    decoder.push(buf.get(..n).unwrap_or_default());
                    while let Some(r) = decoder.next_frame() {
                        if let Ok(frame) = r {
                            let replies = self.handle_frame(&frame);
                            let mut out = Vec::new();
                            for reply in replies {
                                if let Ok(bytes) = reply.encode() {
                                    out.extend_from_slice(&bytes);
                                }
                            }
                            if !out.is_empty() {
                                self.write_out(&mut stream, &out).await?;
                            }
                        }
                    }
                    self.st.rx_bytes += n as u64;
                    self.st.dropped_bytes = decoder.dropped_bytes();
                    self.publish();
                }
                req = next_step(steps), if !wall_clock && pending.is_none() => match req {
                    Some(req) => pending = Some(req),
                    // Every control is gone: time stands still, the link is still served.
                    None => *steps = None,
                },
                _ = ticker.tick(), if wall_clock => self.tick(&mut stream).await?,
            }
        }
    }

    /// One SIP period: simulate, publish the new state, then send the SIP. Publishing first
    /// means a reader of the simulated clock never sees a SIP stamped with the previous time.
    async fn tick<S>(&mut self, stream: &mut S) -> Result<(), EmulatorError>
    where
        S: AsyncWrite + Unpin,
    {
        self.step_period();
        if self.st.open {
            let mut out = Vec::new();
            self.push_garbage(&mut out);
            if let Ok(b) = self.motor_sip().to_frame().encode() {
                out.extend_from_slice(&b);
            }
            if self.encoder_stream {
                if let Ok(b) = self.encoder_packet().encode() {
                    out.extend_from_slice(&b);
                }
            }
            if self.battery_stream {
                if let Ok(b) = self.battery_packet().encode() {
                    out.extend_from_slice(&b);
                }
            }
            self.st.sips_sent += 1;
            self.st.tx_bytes += out.len() as u64;
            self.publish();
            stream.write_all(&out).await?;
            stream.flush().await?;
        } else {
            self.publish();
        }
        Ok(())
    }

    async fn write_out<S>(&mut self, stream: &mut S, bytes: &[u8]) -> Result<(), EmulatorError>
    where
        S: AsyncWrite + Unpin,
    {
        self.st.tx_bytes += bytes.len() as u64;
        stream.write_all(bytes).await?;
        stream.flush().await?;
        Ok(())
    }

    /// The link is gone: stop at once; an open connection stays open with its watchdog tripped.
    fn link_ended(&mut self) {
        self.v_mm = 0.0;
        self.w_deg = 0.0;
        self.st.v = 0.0;
        self.st.w = 0.0;
        if self.st.open && !self.st.watchdog_tripped {
            self.st.watchdog_tripped = true;
            self.st.watchdog_trips += 1;
        }
        self.publish();
    }

    fn publish(&self) {
        self.state_tx.send_replace(self.st);
    }

    fn push_garbage(&mut self, out: &mut Vec<u8>) {
        let p = self.config.garbage_probability;
        if p > 0.0 && self.garbage_rng.random_bool(p.min(1.0)) {
            let n = self.garbage_rng.random_range(1..=8);
            out.extend((0..n).map(|_| self.garbage_rng.random::<u8>()));
        }
    }

    fn close_connection(&mut self) {
        self.st.open = false;
        self.st.motors_enabled = false;
        self.st.watchdog_tripped = false;
        self.sonar_on = false;
        self.encoder_stream = false;
        self.battery_stream = false;
        self.trans_set = 0.0;
        self.rot_mode = RotMode::Velocity(0.0);
        self.wheels = None;
        self.sync_stage = 0;
    }

    /// Handles one command frame; returns the frames to send back.
    fn handle_frame(&mut self, frame: &Frame) -> Vec<Frame> {
        let phase = if self.st.open {
            LinkPhase::Open
        } else {
            LinkPhase::Handshake
        };
        let cmd = match Command::from_frame(frame, phase) {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!(error = %e, "emulator: malformed command ignored");
                self.st.ignored_commands += 1;
                return Vec::new();
            }
        };
        if !self.st.open {
            return self.handle_handshake(cmd);
        }
        self.st.commands += 1;
        self.last_command_time = self.st.sim_time;
        if self.st.watchdog_tripped {
            tracing::info!("emulator: command after watchdog stop, resuming setpoints");
            self.st.watchdog_tripped = false;
        }
        let div = self.factors.vel2_divisor;
        match cmd {
            Command::Pulse | Command::Open => {}
            Command::Close => {
                tracing::info!("emulator: CLOSE");
                self.st.closes += 1;
                self.close_connection();
            }
            Command::Enable(on) => self.st.motors_enabled = on,
            Command::Vel(v) => {
                if self.wheels.take().is_some() {
                    self.rot_mode = RotMode::Velocity(0.0);
                }
                self.trans_set = f64::from(v);
            }
            Command::Rvel(w) => {
                if self.wheels.take().is_some() {
                    self.trans_set = 0.0;
                }
                self.rot_mode = RotMode::Velocity(f64::from(w));
            }
            Command::Vel2 { left, right } => {
                self.wheels = Some((f64::from(left) * div, f64::from(right) * div));
            }
            Command::Head(deg) => {
                if self.wheels.take().is_some() {
                    self.trans_set = 0.0;
                }
                self.rot_mode = RotMode::Heading(wrap_angle(f64::from(deg).to_radians()));
            }
            Command::Dhead(deg) => {
                if self.wheels.take().is_some() {
                    self.trans_set = 0.0;
                }
                let target = self.st.odometry.theta + f64::from(deg).to_radians();
                self.rot_mode = RotMode::Heading(wrap_angle(target));
            }
            Command::SetV(v) => self.max_v = f64::from(v).clamp(0.0, self.config.trans_vel_top),
            Command::SetRv(v) => self.max_rv = f64::from(v).clamp(0.0, self.config.rot_vel_top),
            Command::SetA(a) => match a {
                a if a > 0 => self.accel.0 = f64::from(a),
                a if a < 0 => self.accel.1 = -f64::from(a),
                _ => {}
            },
            Command::SetRa(a) => match a {
                a if a > 0 => self.accel.2 = f64::from(a),
                a if a < 0 => self.accel.3 = -f64::from(a),
                _ => {}
            },
            Command::Stop => {
                self.trans_set = 0.0;
                self.rot_mode = RotMode::Velocity(0.0);
                self.wheels = None;
            }
            Command::EStop => {
                self.trans_set = 0.0;
                self.rot_mode = RotMode::Velocity(0.0);
                self.wheels = None;
                self.v_mm = 0.0;
                self.w_deg = 0.0;
            }
            Command::Sonar(on) => self.sonar_on = on,
            Command::SetO => self.st.odometry = Pose2::default(),
            Command::Config => return vec![self.config_packet().to_frame()],
            Command::Other { number, arg } => return self.handle_other(number, &arg),
            Command::Sync0 | Command::Sync1 | Command::Sync2 => {}
        }
        Vec::new()
    }

    /// Commands outside the typed set (docs §4).
    fn handle_other(&mut self, number: u8, arg: &Arg) -> Vec<Frame> {
        let int = match arg {
            Arg::Int(n) => Some(*n),
            Arg::None => Some(0),
            Arg::Str(_) => None,
        };
        match (number, int) {
            (extra::ROTATE, Some(w)) => {
                if self.wheels.take().is_some() {
                    self.trans_set = 0.0;
                }
                self.rot_mode = RotMode::Velocity(f64::from(w));
            }
            (extra::DCHEAD, Some(deg)) => {
                if self.wheels.take().is_some() {
                    self.trans_set = 0.0;
                }
                let base = match self.rot_mode {
                    RotMode::Heading(target) => target,
                    RotMode::Velocity(_) => self.st.odometry.theta,
                };
                let target = base + f64::from(deg).to_radians();
                self.rot_mode = RotMode::Heading(wrap_angle(target));
            }
            (extra::ENCODER, Some(n)) => {
                self.encoder_stream = n >= 2;
                if n == 1 {
                    return vec![self.encoder_packet()];
                }
            }
            (extra::BATTERYINFO, Some(n)) => {
                self.battery_stream = n >= 2;
                if n == 1 {
                    return vec![self.battery_packet()];
                }
            }
            (extra::BUMPSTALL, Some(n)) => self.bump_stall = (n & 3) as u8,
            (extra::SOUNDTOG, Some(n)) => self.sound_on = n != 0,
            (extra::SONARCYCLE, Some(n)) => {
                self.sonar_cycle_ms = u8::try_from(n.clamp(0, 255)).unwrap_or(u8::MAX);
            }
            (extra::HOSTBAUD, Some(n)) if (0..=4).contains(&n) => self.host_baud = n as u8,
            (extra::AUX1BAUD..=extra::AUX3BAUD, Some(n)) if (0..=4).contains(&n) => {
                if let Some(b) = self.aux_baud.get_mut(usize::from(number - extra::AUX1BAUD)) {
                    *b = n as u8;
                }
            }
            (extra::BATTEST, Some(n)) => {
                self.battery_test_dv = u8::try_from(n.clamp(0, 255)).unwrap_or(0);
            }
            (extra::MOVE | extra::JOYINFO | extra::IOREQUEST | extra::ESTALL | extra::GYRO, _)
            | (extra::TTY2, _) => {
                tracing::debug!(number, "emulator: command acknowledged, not emulated");
            }
            (number, _) if number == number::CONFIG => {
                return vec![self.config_packet().to_frame()];
            }
            (number, arg) => {
                tracing::debug!(number, ?arg, "emulator: command not emulated");
                self.st.ignored_commands += 1;
            }
        }
        Vec::new()
    }

    fn handle_handshake(&mut self, cmd: Command) -> Vec<Frame> {
        match cmd {
            Command::Sync0 => {
                self.sync_stage = 1;
                vec![Frame::new(0, Vec::new())]
            }
            Command::Sync1 if self.sync_stage == 3 => {
                // After SYNC2, command 1 is OPEN.
                tracing::info!("emulator: OPEN");
                self.st.open = true;
                self.st.opens += 1;
                self.st.motors_enabled = false;
                // ARCOS (and MobileSim/AMRISim) start the sonar with the servers.
                self.sonar_on = true;
                self.sonar_next = 0;
                self.last_command_time = self.st.sim_time;
                Vec::new()
            }
            Command::Sync1 => {
                self.sync_stage = 2;
                vec![Frame::new(1, Vec::new())]
            }
            Command::Sync2 => {
                self.sync_stage = 3;
                vec![self.config.identity.to_frame()]
            }
            other => {
                tracing::debug!(command = ?other, "emulator: command before OPEN ignored");
                self.st.ignored_commands += 1;
                Vec::new()
            }
        }
    }

    /// Advances simulated time by one SIP period.
    fn step_period(&mut self) {
        let period = self.config.sip_period.as_secs_f64();
        let dt = period / f64::from(SUBSTEPS);
        if self.st.open
            && !self.st.watchdog_tripped
            && self.st.sim_time - self.last_command_time > self.config.watchdog.as_secs_f64()
        {
            tracing::warn!("emulator: watchdog expired, stopping the robot");
            self.st.watchdog_tripped = true;
            self.st.watchdog_trips += 1;
        }
        if let Some((seed, _, rng)) = &mut self.slip {
            let mut fresh = ChaCha8Rng::seed_from_u64(*seed);
            fresh.set_stream(self.st.ticks);
            *rng = fresh;
        }
        for _ in 0..SUBSTEPS {
            self.substep(dt);
        }
        self.st.ticks += 1;
        self.st.sim_time = self.st.ticks as f64 * period;
    }

    fn targets(&self) -> (f64, f64) {
        if !self.st.open || !self.st.motors_enabled || self.st.watchdog_tripped {
            return (0.0, 0.0);
        }
        if let Some((l, r)) = self.wheels {
            let v = (l + r) / 2.0;
            let w = ((r - l) / self.config.wheel_track_mm).to_degrees();
            return (
                v.clamp(-self.max_v, self.max_v),
                w.clamp(-self.max_rv, self.max_rv),
            );
        }
        let v = self.trans_set.clamp(-self.max_v, self.max_v);
        let w = match self.rot_mode {
            RotMode::Velocity(w) => w.clamp(-self.max_rv, self.max_rv),
            RotMode::Heading(target) => {
                let err = wrap_angle(target - self.st.odometry.theta).to_degrees();
                let stop_speed = (2.0 * self.accel.3 * err.abs()).sqrt();
                let per_step =
                    err.abs() / (self.config.sip_period.as_secs_f64() / f64::from(SUBSTEPS));
                err.signum() * self.max_rv.min(stop_speed).min(per_step)
            }
        };
        (v, w)
    }

    fn substep(&mut self, dt: f64) {
        let (vt, wt) = self.targets();
        self.v_mm = ramp(self.v_mm, vt, self.accel.0 * dt, self.accel.1 * dt);
        self.w_deg = ramp(self.w_deg, wt, self.accel.2 * dt, self.accel.3 * dt);
        let v = self.v_mm / 1000.0;
        let w = self.w_deg.to_radians();
        let half_track = self.config.wheel_track_mm / 2000.0;
        let (left, right) = (v - w * half_track, v + w * half_track);
        let nominal = arc(v * dt, w * dt);
        // Ground truth: wheels may slip.
        let (gl, gr) = match &mut self.slip {
            Some((_, normal, rng)) => (
                left * (1.0 + normal.sample(rng)),
                right * (1.0 + normal.sample(rng)),
            ),
            None => (left, right),
        };
        let gv = (gl + gr) / 2.0;
        let gw = (gr - gl) / (2.0 * half_track);
        let proposed = self.st.truth.compose(&arc(gv * dt, gw * dt));
        let current = self.st.truth;
        let accepted = match &mut self.hook {
            Some(hook) => hook(&current, &proposed),
            None => proposed,
        };
        let clipped = accepted.distance(&proposed) > 1e-9
            || wrap_angle(accepted.theta - proposed.theta).abs() > 1e-9;
        self.st.stalled = clipped;
        // Which ring touched: the direction the blocked step tried to go, in the body frame.
        let pushed = proposed.relative_to(&current).x;
        self.st.bumped_front = clipped && pushed > 0.0;
        self.st.bumped_rear = clipped && pushed < 0.0;
        self.st.truth = accepted;
        // Encoders: nominal wheel motion, or what the robot actually did when blocked.
        let odo_delta = if clipped {
            accepted.relative_to(&current)
        } else {
            nominal
        };
        self.st.odometry = self.st.odometry.compose(&odo_delta);
        self.encoders.0 += left * dt * 1000.0;
        self.encoders.1 += right * dt * 1000.0;
        self.st.v = v;
        self.st.w = w;
    }

    fn motor_sip(&mut self) -> MotorSip {
        let f = self.factors;
        let units = |m: f64| {
            let u = (m * 1000.0 / f.dist_conv).round() as i64;
            (u.rem_euclid(0x8000)) as u16
        };
        let half_track = self.config.wheel_track_mm / 2.0;
        let battery_dv = self.battery_dv();
        let w_rad = self.w_deg.to_radians();
        let left = (self.v_mm - w_rad * half_track) / f.vel_conv;
        let right = (self.v_mm + w_rad * half_track) / f.vel_conv;
        let sat = |x: f64| x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
        let mut flags = u16::from(self.st.motors_enabled);
        let mut sonar = Vec::new();
        if self.sonar_on {
            flags |= 0b1_1110;
            let discs = p3dx_discs();
            for _ in 0..4 {
                let number = self.sonar_next;
                let range_mm = match (&mut self.sonar_hook, discs.get(usize::from(number))) {
                    (Some(hook), Some(disc)) => hook(&self.st.truth, disc)
                        .map_or(NO_ECHO_M * 1000.0, |m| {
                            (m * 1000.0).clamp(0.0, NO_ECHO_M * 1000.0)
                        }),
                    _ => f64::from(self.config.sonar_range_mm),
                };
                sonar.push(SonarReading {
                    number,
                    range: (range_mm / f.range_conv).round() as u16,
                });
                self.sonar_next = (self.sonar_next + 1) % 16;
            }
        }
        // Wheel stalls in bits 0 and 8; a P3-DX's five bumper segments in bits 1–5 (rear) and
        // 9–13 (front), all pressed when the body meets a wall.
        let stall = if self.st.stalled { 0x0101 } else { 0 }
            | if self.st.bumped_front { 0x3E00 } else { 0 }
            | if self.st.bumped_rear { 0x003E } else { 0 };
        MotorSip {
            moving: self.v_mm.abs() > 0.5 || self.w_deg.abs() > 0.05,
            x_raw: units(self.st.odometry.x),
            y_raw: units(self.st.odometry.y),
            th_raw: sat(self.st.odometry.theta / f.angle_conv),
            left_vel: sat(left),
            right_vel: sat(right),
            battery_dv,
            stall_bumpers: StallBumpers(stall),
            control: 0,
            flags,
            compass: 0,
            sonar,
            grip_state: 0,
            an_port: 0,
            analog: 0,
            digin: 0,
            digout: 0,
            tail: SipTail {
                battery_x10: Some(u16::from(battery_dv)),
                charge_state: Some(0),
                rot_vel: Some(sat(self.w_deg * 10.0)),
                fault_flags: Some(0),
                rest: Vec::new(),
            },
        }
    }

    fn encoder_packet(&self) -> Frame {
        let mut p = Vec::with_capacity(8);
        p.extend_from_slice(&(self.encoders.0.round() as i32).to_le_bytes());
        p.extend_from_slice(&(self.encoders.1.round() as i32).to_le_bytes());
        Frame::new(0x90, p)
    }

    /// Battery voltage in decivolts: the BATTEST override or the configured value.
    fn battery_dv(&self) -> u8 {
        if self.battery_test_dv > 0 {
            self.battery_test_dv
        } else {
            self.config.battery_dv
        }
    }

    /// The battery information packet (0xFA, ARIA `ArRobotBatteryPacketReader`): one battery of
    /// five bytes (flags 1-3 zero, relative and absolute state of charge in percent, both
    /// linear in the voltage from 11.0 V = 0 % to 12.8 V = 100 %; an emulator model, a P3-DX's
    /// lead-acid batteries report no charge state of their own).
    fn battery_packet(&self) -> Frame {
        let volts = f64::from(self.battery_dv()) / 10.0;
        let soc = ((volts - 11.0) / 1.8 * 100.0).round().clamp(0.0, 100.0) as u8;
        Frame::new(BATTERY_PACKET, vec![1, 5, 0, 0, 0, soc, soc])
    }

    /// The CONFIG packet: every field ARIA's `ArRobotConfigPacketReader` reads (docs §5.3),
    /// with the emulator's limits and current settings and plausible P3-DX values elsewhere.
    fn config_packet(&self) -> ConfigPacket {
        let c = &self.config;
        let u16s = |x: f64| x.round().clamp(0.0, f64::from(u16::MAX)) as u16;
        let [aux1_baud, aux2_baud, aux3_baud] = self.aux_baud;
        ConfigPacket {
            class: c.identity.class.clone(),
            subclass: c.identity.subclass.clone(),
            serial: "EMU".into(),
            four_motors: 0,
            rot_vel_top: u16s(c.rot_vel_top),
            trans_vel_top: u16s(c.trans_vel_top),
            rot_accel_top: u16s(c.rot_accel.max(c.rot_decel)),
            trans_accel_top: u16s(c.trans_accel.max(c.trans_decel)),
            pwm_max: 1000,
            name: c.identity.name.clone(),
            sip_cycle_ms: u8::try_from(c.sip_period.as_millis()).unwrap_or(u8::MAX),
            host_baud: self.host_baud,
            aux1_baud,
            has_gripper: 0,
            front_sonar: 1,
            rear_sonar: 1,
            low_battery_dv: 110,
            rev_count: 16570,
            watchdog_ms: u16::try_from(c.watchdog.as_millis()).unwrap_or(u16::MAX),
            more: Some(ConfigMore {
                normal_motor_packets: 1,
                stall_val: 200,
                stall_count: 100,
                joy_vel: 300,
                joy_rot_vel: 50,
                rot_vel_max: u16s(self.max_rv),
                trans_vel_max: u16s(self.max_v),
                rot_accel: u16s(self.accel.2),
                rot_decel: u16s(self.accel.3),
                rot_kp: 40,
                rot_kv: 20,
                rot_ki: 0,
                trans_accel: u16s(self.accel.0),
                trans_decel: u16s(self.accel.1),
                trans_kp: 40,
                trans_kv: 30,
                trans_ki: 0,
                front_bumps: 5,
                rear_bumps: 5,
                has_charger: 0,
                sonar_cycle_ms: self.sonar_cycle_ms,
                autobaud: 2,
                gyro_type: 0,
                drift_factor: 0,
                aux2_baud,
                aux3_baud,
                ticks_mm: 128,
                shutdown_voltage_dv: 105,
                firmware_version: "rfloc-emulator".into(),
                gyro_cw: 0,
                gyro_ccw: 0,
                kinematics_delay: 0,
                lat_vel_top: 0,
                lat_accel_top: 0,
                lat_vel_max: 0,
                lat_accel: 0,
                lat_decel: 0,
                powerbot_charge_threshold: 0,
                pdb_port: 0,
                gyro_rate_limit: 0,
                high_temperature_shutdown: 0,
                power_bits: 0,
                battery_type: 0,
                state_of_charge_low: 0,
                state_of_charge_shutdown: 0,
                bootloader_version: String::new(),
                config_flags: 0,
                gyro_fw_version: 0,
            }),
            rest: Vec::new(),
        }
    }

    /// Whether the buzzer is on (SOUNDTOG) and which bumper rings register a stall
    /// (BUMPSTALL), for tests.
    #[must_use]
    pub fn sound_and_bump_stall(&self) -> (bool, u8) {
        (self.sound_on, self.bump_stall)
    }
}

/// Moves `current` toward `target`, by at most `up` when speeding up and `down` when slowing.
fn ramp(current: f64, target: f64, up: f64, down: f64) -> f64 {
    let speeding_up =
        target.abs() > current.abs() && target.signum() == current.signum() || current == 0.0;
    let step = if speeding_up { up } else { down };
    if (target - current).abs() <= step {
        target
    } else {
        current + step.copysign(target - current)
    }
}

/// Relative motion along an arc of length `ds` turning by `dth` (midpoint heading).
fn arc(ds: f64, dth: f64) -> Pose2 {
    let half = dth / 2.0;
    Pose2::new(ds * half.cos(), ds * half.sin(), dth)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_limits_acceleration() {
        assert_eq!(ramp(0.0, 100.0, 10.0, 20.0), 10.0);
        assert_eq!(ramp(100.0, 0.0, 10.0, 20.0), 80.0);
        assert_eq!(ramp(5.0, 8.0, 10.0, 20.0), 8.0);
        assert_eq!(ramp(50.0, -50.0, 10.0, 20.0), 30.0);
    }

    #[test]
    fn handshake_then_open() {
        let mut e = RobotEmulator::new(EmulatorConfig::default());
        assert_eq!(
            e.handle_frame(&Frame::new(0, vec![])),
            vec![Frame::new(0, vec![])]
        );
        assert_eq!(
            e.handle_frame(&Frame::new(1, vec![])),
            vec![Frame::new(1, vec![])]
        );
        let id = e.handle_frame(&Frame::new(2, vec![]));
        assert_eq!(id, vec![EmulatorConfig::default().identity.to_frame()]);
        assert!(e.handle_frame(&Frame::new(1, vec![])).is_empty());
        assert!(e.st.open);
        assert!(!e.st.motors_enabled);
    }

    fn opened(config: EmulatorConfig) -> RobotEmulator {
        let mut e = RobotEmulator::new(config);
        for id in [0, 1, 2, 1] {
            e.handle_frame(&Frame::new(id, vec![]));
        }
        let enable = Command::Enable(true).to_frame(&Default::default()).unwrap();
        e.handle_frame(&enable);
        e
    }

    #[test]
    fn vel_drives_straight_with_acceleration_limit() {
        let mut e = opened(EmulatorConfig::default());
        e.handle_frame(&Command::Vel(300).to_frame(&Default::default()).unwrap());
        // 300 mm/s² reaches 300 mm/s after 1 s; distance then 0.15 m.
        for _ in 0..10 {
            e.step_period();
        }
        assert!((e.st.v - 0.3).abs() < 1e-9);
        assert!((e.st.truth.x - 0.15).abs() < 0.005, "x = {}", e.st.truth.x);
        assert_eq!(e.st.truth, e.st.odometry);
    }

    #[test]
    fn watchdog_stops_and_command_revives() {
        let mut e = opened(EmulatorConfig::default());
        e.handle_frame(&Command::Vel(200).to_frame(&Default::default()).unwrap());
        for _ in 0..25 {
            e.step_period();
        }
        assert!(e.st.watchdog_tripped);
        for _ in 0..10 {
            e.step_period();
        }
        assert_eq!(e.st.v, 0.0);
        e.handle_frame(&Command::Pulse.to_frame(&Default::default()).unwrap());
        for _ in 0..10 {
            e.step_period();
        }
        assert!(e.st.v > 0.19, "revived to the last setpoint");
    }

    #[test]
    fn hook_clips_motion_and_reports_stall() {
        let wall: MotionHook = Box::new(|cur, prop| if prop.x > 0.05 { *cur } else { *prop });
        let mut e = opened(EmulatorConfig::default()).with_motion_hook(wall);
        e.handle_frame(&Command::Vel(200).to_frame(&Default::default()).unwrap());
        for _ in 0..20 {
            e.step_period();
        }
        assert!(e.st.truth.x <= 0.05);
        assert!(e.st.stalled);
        assert!((e.st.odometry.x - e.st.truth.x).abs() < 1e-9);
        assert!(e.motor_sip().stall_bumpers.left_stall());
        let sb = e.motor_sip().stall_bumpers;
        assert_eq!(
            (sb.front_bumpers(), sb.rear_bumpers()),
            (0x1F, 0),
            "front ring"
        );
        // Backing off frees the bumper.
        e.handle_frame(&Command::Vel(-200).to_frame(&Default::default()).unwrap());
        for _ in 0..20 {
            e.step_period();
        }
        let sb = e.motor_sip().stall_bumpers;
        assert_eq!(
            (sb.front_bumpers(), sb.rear_bumpers(), sb.left_stall()),
            (0, 0, false)
        );
    }

    #[test]
    fn sonar_hook_ranges_reach_the_sip_disc_by_disc() {
        // An echo 1.25 m ahead of the discs that look forward within ±15°, none elsewhere.
        let hook: SonarHook =
            Box::new(|_truth, disc| (disc.heading_rad.abs() < 15f64.to_radians()).then_some(1.25));
        let mut e = opened(EmulatorConfig::default()).with_sonar_hook(hook);
        e.handle_frame(&Command::Sonar(true).to_frame(&Default::default()).unwrap());
        let mut seen = std::collections::BTreeMap::new();
        for _ in 0..4 {
            for r in e.motor_sip().sonar {
                seen.insert(r.number, r.range);
            }
        }
        assert_eq!(seen.len(), 16, "the whole ring in four SIPs");
        assert_eq!((seen[&3], seen[&4]), (1250, 1250), "discs at ±10°");
        assert!(seen.iter().all(|(n, r)| matches!(n, 3 | 4) || *r == 5000));
    }

    #[test]
    fn backing_into_a_wall_presses_the_rear_ring() {
        let wall: MotionHook = Box::new(|cur, prop| if prop.x < -0.05 { *cur } else { *prop });
        let mut e = opened(EmulatorConfig::default()).with_motion_hook(wall);
        e.handle_frame(&Command::Vel(-200).to_frame(&Default::default()).unwrap());
        for _ in 0..20 {
            e.step_period();
        }
        let sb = e.motor_sip().stall_bumpers;
        assert_eq!(sb.0, 0x013F, "both wheel stalls and rear segments 1–5");
        assert_eq!((sb.front_bumpers(), sb.rear_bumpers()), (0, 0x1F));
    }

    #[test]
    fn head_turns_to_heading() {
        let mut e = opened(EmulatorConfig::default());
        e.handle_frame(&Command::Head(90).to_frame(&Default::default()).unwrap());
        for _ in 0..60 {
            e.step_period();
        }
        assert!((e.st.odometry.theta - std::f64::consts::FRAC_PI_2).abs() < 0.01);
        assert!(e.st.w.abs() < 1e-6);
    }

    #[test]
    fn vel2_wheels_turn_in_place() {
        let mut e = opened(EmulatorConfig::default());
        let f = Command::Vel2 { left: -2, right: 2 }
            .to_frame(&Default::default())
            .unwrap();
        e.handle_frame(&f);
        for _ in 0..20 {
            e.step_period();
        }
        // ±40 mm/s on a 357 mm track: 0.224 rad/s.
        assert!((e.st.w - 80.0 / e.config.wheel_track_mm).abs() < 1e-9);
        assert!(e.st.truth.x.abs() < 1e-9);
    }

    #[test]
    fn slip_moves_truth_away_from_odometry_deterministically() {
        let cfg = EmulatorConfig {
            slip: Some(WheelSlip {
                seed: 7,
                relative_std: 0.05,
            }),
            ..EmulatorConfig::default()
        };
        let run = || {
            let mut e = opened(cfg.clone());
            e.handle_frame(&Command::Vel(400).to_frame(&Default::default()).unwrap());
            for _ in 0..20 {
                e.step_period();
            }
            (e.st.truth, e.st.odometry)
        };
        let (t1, o1) = run();
        let (t2, _) = run();
        assert_eq!(t1, t2);
        assert!(t1.distance(&o1) > 1e-4);
    }

    #[test]
    fn slip_of_a_tick_does_not_depend_on_earlier_draws() {
        let cfg = EmulatorConfig {
            slip: Some(WheelSlip {
                seed: 11,
                relative_std: 0.05,
            }),
            ..EmulatorConfig::default()
        };
        let run = |burn: usize| {
            let mut e = opened(cfg.clone());
            if let Some((_, _, rng)) = &mut e.slip {
                for _ in 0..burn {
                    let _: u64 = rng.random();
                }
            }
            e.handle_frame(&Command::Vel(400).to_frame(&Default::default()).unwrap());
            for _ in 0..20 {
                e.step_period();
            }
            e.st.truth
        };
        // Draws taken before the first tick (e.g. by another link's history) change nothing.
        assert_eq!(run(0), run(1000));
    }

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    /// Feeds wire bytes to the emulator; returns the wire bytes of its replies.
    fn feed(e: &mut RobotEmulator, wire: &[u8]) -> Vec<u8> {
        let mut d = FrameDecoder::new();
        d.push(wire);
        let mut out = Vec::new();
        while let Some(f) = d.next_frame() {
            for r in e.handle_frame(&f.unwrap()) {
                out.extend(r.encode().unwrap());
            }
        }
        out
    }

    /// The field order of ARIA's `ArRobotConfigPacketReader::packetHandler` (docs §5.3):
    /// 's' a NUL-terminated string, 1/2/4 an integer of that many bytes.
    const ARIA_CONFIG_FIELDS: [(&str, u8); 68] = [
        ("Type", b's'),
        ("SubType", b's'),
        ("SerialNumber", b's'),
        ("4MotorsFlag", 1),
        ("RotVelTop", 2),
        ("TransVelTop", 2),
        ("RotAccelTop", 2),
        ("TransAccelTop", 2),
        ("PwmMax", 2),
        ("Name", b's'),
        ("SipCycleTime", 1),
        ("HostBaud", 1),
        ("Aux1Baud", 1),
        ("HasGripper", 2),
        ("FrontSonar", 2),
        ("RearSonar", 1),
        ("LowBattery", 2),
        ("RevCount", 2),
        ("Watchdog", 2),
        ("NormalMPacs", 1),
        ("StallVal", 2),
        ("StallCount", 2),
        ("JoyVel", 2),
        ("JoyRotVel", 2),
        ("RotVelMax", 2),
        ("TransVelMax", 2),
        ("RotAccel", 2),
        ("RotDecel", 2),
        ("RotKP", 2),
        ("RotKV", 2),
        ("RotKI", 2),
        ("TransAccel", 2),
        ("TransDecel", 2),
        ("TransKP", 2),
        ("TransKV", 2),
        ("TransKI", 2),
        ("FrontBumps", 1),
        ("RearBumps", 1),
        ("HasCharger", 1),
        ("SonarCycle", 1),
        ("ResetBaud", 1),
        ("GyroType", 1),
        ("DriftFactor", 2),
        ("Aux2Baud", 1),
        ("Aux3Baud", 1),
        ("TicksMM", 2),
        ("ShutdownVoltage", 2),
        ("FirmwareVersion", b's'),
        ("GyroCW", 2),
        ("GyroCCW", 2),
        ("KinematicsDelay", 1),
        ("LatVelTop", 2),
        ("LatAccelTop", 2),
        ("LatVelMax", 2),
        ("LatAccel", 2),
        ("LatDecel", 2),
        ("PowerbotChargeThreshold", 2),
        ("PDBPort", 1),
        ("GyroRateLimit", 2),
        ("HighTemperatureShutdown", 1),
        ("PowerBits", 2),
        ("BatteryType", 1),
        ("StateOfChargeLow", 2),
        ("StateOfChargeShutdown", 2),
        ("FirmwareBootloaderVersion", b's'),
        ("ConfigFlags", 4),
        ("GyroFWVersion", 2),
        ("end", 0),
    ];

    /// Reads a CONFIG payload field by field as ARIA does; integers as unsigned.
    fn aria_fields(payload: &[u8]) -> std::collections::BTreeMap<&'static str, String> {
        let mut at = 0;
        let mut out = std::collections::BTreeMap::new();
        for (name, kind) in ARIA_CONFIG_FIELDS {
            let value = match kind {
                0 => continue,
                b's' => {
                    let end = at + payload[at..].iter().position(|b| *b == 0).unwrap();
                    let v = String::from_utf8(payload[at..end].to_vec()).unwrap();
                    at = end + 1;
                    v
                }
                n => {
                    let bytes = &payload[at..at + usize::from(n)];
                    at += usize::from(n);
                    bytes
                        .iter()
                        .rev()
                        .fold(0u64, |acc, b| acc << 8 | u64::from(*b))
                        .to_string()
                }
            };
            out.insert(name, value);
        }
        assert_eq!(at, payload.len(), "every byte is a field ARIA reads");
        out
    }

    #[test]
    fn config_packet_carries_every_field_aria_reads() {
        let mut e = opened(EmulatorConfig::default());
        // CONFIG as ARIA sends it (comInt(CONFIG, 1)), docs §8.
        let wire = feed(&mut e, &hex("FA FB 06 12 3B 01 00 13 3B"));
        assert_eq!(&wire[..4], [0xFA, 0xFB, wire[2], 0x20]);
        assert_eq!(usize::from(wire[2]) + 3, wire.len());
        let payload = &wire[4..wire.len() - 2];
        // Through WATCHDOG the packet is 60 bytes; ARIA reads 157 with these strings.
        assert_eq!(payload.len(), 157);
        let f = aria_fields(payload);
        for (name, value) in [
            ("Type", "Pioneer"),
            ("SubType", "p3dx-sh"),
            ("Name", "rfloc-emulator"),
            ("TransVelTop", "2200"),
            ("RotVelTop", "500"),
            ("TransVelMax", "2200"),
            ("RotVelMax", "500"),
            ("TransAccel", "300"),
            ("TransDecel", "300"),
            ("RotAccel", "100"),
            ("RotDecel", "100"),
            ("Watchdog", "2000"),
            ("SipCycleTime", "100"),
            ("FrontSonar", "1"),
            ("RearSonar", "1"),
            ("NormalMPacs", "1"),
            ("ResetBaud", "2"),
            ("TicksMM", "128"),
            ("FirmwareVersion", "rfloc-emulator"),
            ("GyroFWVersion", "0"),
        ] {
            assert_eq!(f[name], value, "{name}");
        }
        // The typed parser reads the same packet back whole.
        let c = ConfigPacket::parse(payload).unwrap();
        let more = c.more.clone().unwrap();
        assert_eq!((more.trans_vel_max, more.rot_vel_max), (2200, 500));
        assert!(c.rest.is_empty());
        assert_eq!(c.to_frame().encode().unwrap(), wire);
    }

    #[test]
    fn config_reports_settings_changed_by_commands() {
        let mut e = opened(EmulatorConfig::default());
        // SETV 750, SETRV 100, HOSTBAUD 2, SETA 300, SETRA 100.
        let out = feed(
            &mut e,
            &hex("FA FB 06 06 3B EE 02 F4 3D  FA FB 06 0A 3B 64 00 6E 3B  FA FB 06 32 3B 02 00 34 3B"),
        );
        assert!(out.is_empty());
        let wire = feed(&mut e, &hex("FA FB 06 12 3B 01 00 13 3B"));
        let f = aria_fields(&wire[4..wire.len() - 2]);
        assert_eq!(
            (
                f["TransVelMax"].as_str(),
                f["RotVelMax"].as_str(),
                f["HostBaud"].as_str()
            ),
            ("750", "100", "2")
        );
    }

    #[test]
    fn sonar_is_on_after_open_and_off_after_sonar_0() {
        let mut e = opened(EmulatorConfig::default());
        let sip = e.motor_sip();
        assert_eq!(sip.sonar.len(), 4, "sonar starts with the servers");
        assert_eq!(sip.flags & 0b1_1110, 0b1_1110);
        feed(&mut e, &hex("FA FB 06 1C 3B 00 00 1C 3B"));
        assert!(e.motor_sip().sonar.is_empty());
    }

    #[test]
    fn battery_info_packet_known_answer() {
        let mut e = opened(EmulatorConfig::default());
        // BATTERYINFO 1 → one 0xFA packet: 1 battery, 5 bytes, SOC 83 % at 12.5 V.
        let out = feed(&mut e, &hex("FA FB 06 3E 3B 01 00 3F 3B"));
        assert_eq!(out, hex("FA FB 0A FA 01 05 00 00 00 53 53 52 54"));
        // BATTEST 110 (11.0 V) reaches the SIP and the battery packet.
        feed(&mut e, &hex("FA FB 06 FA 3B 6E 00 68 3B"));
        assert_eq!(e.motor_sip().battery_dv, 110);
        let out = feed(&mut e, &hex("FA FB 06 3E 3B 01 00 3F 3B"));
        assert_eq!(&out[4..11], [0x01, 0x05, 0, 0, 0, 0, 0]);
    }

    #[test]
    fn aria_connection_and_drive_commands_are_all_understood() {
        let mut e = RobotEmulator::new(EmulatorConfig::default());
        // SYNC0, SYNC1, SYNC2, OPEN 1, then what ARIA sends while connecting and driving.
        let handshake = feed(
            &mut e,
            &hex("FA FB 03 00 00 00  FA FB 03 01 00 01  FA FB 03 02 00 02"),
        );
        assert_eq!(&handshake[..12], hex("FA FB 03 00 00 00 FA FB 03 01 00 01"));
        feed(&mut e, &hex("FA FB 06 01 3B 01 00 02 3B"));
        assert!(e.st.open);
        let sequence = [
            "FA FB 03 00 00 00",          // PULSE
            "FA FB 06 12 3B 01 00 13 3B", // CONFIG 1
            "FA FB 06 32 3B 02 00 34 3B", // HOSTBAUD 2
            "FA FB 06 3E 3B 01 00 3F 3B", // BATTERYINFO 1
            "FA FB 06 1C 3B 01 00 1D 3B", // SONAR 1
            "FA FB 06 5C 3B 00 00 5C 3B", // SOUNDTOG 0
            "FA FB 06 2C 3B 03 00 2F 3B", // BUMPSTALL 3
            "FA FB 06 11 3B 00 00 11 3B", // JOYINFO 0
            "FA FB 06 13 3B 01 00 14 3B", // ENCODER 1
            "FA FB 06 06 3B EE 02 F4 3D", // SETV 750
            "FA FB 06 0A 3B 64 00 6E 3B", // SETRV 100
            "FA FB 06 05 3B 2C 01 31 3C", // SETA 300
            "FA FB 06 17 3B 64 00 7B 3B", // SETRA 100
            "FA FB 06 04 3B 01 00 05 3B", // ENABLE 1
            "FA FB 06 0B 3B 2C 01 37 3C", // VEL 300
            "FA FB 06 15 3B 00 00 15 3B", // RVEL 0
        ];
        for c in sequence {
            feed(&mut e, &hex(c));
        }
        assert_eq!(e.st.ignored_commands, 0);
        assert_eq!(e.sound_and_bump_stall(), (false, 3));
        for _ in 0..15 {
            e.step_period();
        }
        assert!(
            (e.st.v - 0.3).abs() < 1e-9,
            "VEL 300 drives at 0.3 m/s: {:?}",
            e.st
        );
        // ROTATE 30 turns like RVEL; DCHEAD −45 turns to 45° below the heading setpoint.
        feed(&mut e, &hex("FA FB 06 09 3B 1E 00 27 3B"));
        for _ in 0..10 {
            e.step_period();
        }
        assert!((e.st.w - 30f64.to_radians()).abs() < 1e-9);
        feed(&mut e, &hex("FA FB 03 1D 00 1D FA FB 06 0C 3B 5A 00 66 3B"));
        feed(&mut e, &hex("FA FB 06 16 1B 2D 00 43 1B"));
        for _ in 0..15 {
            e.step_period();
        }
        assert!((e.st.odometry.theta - 45f64.to_radians()).abs() < 0.01);
        // STOP, E_STOP, CLOSE 1: the robot stops and the connection closes, sonar off.
        feed(
            &mut e,
            &hex("FA FB 03 1D 00 1D  FA FB 03 37 00 37  FA FB 06 02 3B 01 00 03 3B"),
        );
        assert!(!e.st.open);
        assert_eq!(e.st.ignored_commands, 0);
        assert_eq!((e.st.v, e.st.w), (0.0, 0.0));
    }

    #[test]
    fn ticks_count_simulated_time() {
        let mut e = RobotEmulator::new(EmulatorConfig::default());
        for _ in 0..30 {
            e.step_period();
        }
        assert_eq!(e.st.ticks, 30);
        assert_eq!(e.st.sim_time, 30.0 * 0.1);
    }
}
