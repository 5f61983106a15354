//! The devices of one snapshot trial: an emulated Pioneer on a pty and an emulated Alien
//! ALR-9900 on a loopback TCP listener, both reached through rfloc's real drivers over links
//! opened with `rfloc_transport::open` and recorded into the trial folder.
//!
//! The reader's tag field is the scenario's UHF model evaluated at the antenna pose derived
//! from the emulator's *true* pose at the moment the reader answers `t`.
//!
//! Timing: the Pioneer runs in lock-step with the trial ([`LockstepBase`]): simulated time
//! moves only when an action asks for its ticks, after the emulator has handled every command
//! the driver wrote. Tag lists are read while the clock stands still, and the reader (prompts
//! suppressed) ends every reply with its last byte, a NUL the driver reads before it returns;
//! so every byte on both links is sent and read at a simulated time fixed by the scenario and
//! the seed. Both captures coalesce same-time records, and a rerun writes identical files.

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crate::scenario::lockstep::{driver_config, LockstepBase};
use crate::sim::walls::wall_hook;
use crate::sim::EmulatorClock;
use anyhow::Context;
use rfloc_alien::{
    AlienClient, AlienConfig, EmulatorOptions, ReaderEmulator, ReaderSetup, SnapshotReader,
};
use rfloc_aria::{
    AriaClient, EmulatorConfig as RobotConfig, EmulatorHandle, RobotEmulator, WheelSlip,
};
use rfloc_pose::Pose2;
use rfloc_sim::{Scenario, SensorSuite, World};
use rfloc_snapshot::{AverageConfig, AverageTagSet, MotionCommand, Snapshot, TagId};
use rfloc_transport::{open, CaptureSink, LinkConfig, Recorder, SharedClock, TcpLink};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::sim::pty_link;

/// The Pioneer's SIP period (one lock-step tick), seconds.
const TICK_S: f64 = 0.1;
/// The robot counts as stopped below these speeds (m/s, rad/s).
const STOPPED_V: f64 = 1e-3;
const STOPPED_W: f64 = 1e-3;
/// The reader time a simulated trial sets (the lock-step trial starts at simulated time 0).
const SIMULATED_READER_TIME: &str = "2000/01/01 00:00:00";
/// Most ticks to wait for the robot to come to rest after a stop command (2 s).
const SETTLE_TICKS: u32 = 20;

type RecordedTcp = Recorder<rfloc_transport::Transport>;

/// Counters of one trial's device traffic.
#[derive(Debug, Clone, Copy, Default)]
pub struct RigCounters {
    /// `t` polls answered.
    pub reads: u64,
    /// Tag IDs from the world that were not hex (skipped by the field).
    pub bad_epcs: u64,
    /// Stops that did not settle within [`SETTLE_TICKS`].
    pub unsettled: u64,
    /// Actions during which the driver reported a wheel stall.
    pub stalls: u64,
}

/// Emulators plus connected drivers of one trial.
pub struct SnapshotRig {
    truth: EmulatorHandle,
    base: LockstepBase,
    reader: AlienClient<RecordedTcp>,
    start: Pose2,
    average: AverageConfig,
    reads_per_step: usize,
    stop: CancellationToken,
    tasks: Vec<JoinHandle<()>>,
    reader_task: JoinHandle<std::io::Result<()>>,
    sinks: Vec<CaptureSink>,
    /// The reader's capture (snapshot marks).
    reader_sink: CaptureSink,
    bad_epcs: Arc<Mutex<u64>>,
    counters: RigCounters,
    _robot_slave: tokio_serial::SerialStream,
}

/// The emulated Pioneer of the snapshot scenarios (without its start pose): accelerations
/// raised from the P3-DX defaults so that one action's displacement (seed Table 4 over 0.1 s)
/// is driven within about half a second, and a relative wheel slip on the true motion.
#[must_use]
pub fn robot_config(seed: u64, slip: f64) -> RobotConfig {
    RobotConfig {
        noise_seed: seed,
        trans_accel: 2000.0,
        trans_decel: 2000.0,
        rot_accel: 400.0,
        rot_decel: 400.0,
        slip: (slip > 0.0).then_some(WheelSlip {
            seed: seed ^ 0x534c_4950,
            relative_std: slip,
        }),
        ..RobotConfig::default()
    }
}

/// The Alien emulator's tag field: the scenario's UHF model read at the robot's true pose
/// (`truth`), each call one inventory. EPCs that are not hex are counted in `bad_epcs`.
pub fn uhf_field(
    sensors: SensorSuite,
    world: Arc<World>,
    truth: EmulatorHandle,
    bad_epcs: Arc<Mutex<u64>>,
) -> rfloc_alien::TagField {
    let sensors = Mutex::new(sensors);
    Arc::new(move || {
        let pose = truth.truth();
        let reads = sensors
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .uhf_inventory(&world, &pose);
        let mut out = Vec::with_capacity(reads.len());
        for (epc, rss) in reads {
            match TagId::from_hex(&epc) {
                Some(id) => out.push((id.0, rss)),
                None => *bad_epcs.lock().unwrap_or_else(PoisonError::into_inner) += 1,
            }
        }
        out
    })
}

/// What the trial needs to build a rig.
pub struct RigSpec<'a> {
    pub scenario: &'a Scenario,
    pub trial: usize,
    pub dir: &'a Path,
    pub reads_per_step: usize,
    /// Relative σ of the wheel slip applied to the truth only (odometry does not see it).
    pub slip: f64,
}

impl SnapshotRig {
    /// Starts both emulators and connects the drivers (Pioneer handshake, reader login and the
    /// project setup).
    pub async fn start(spec: &RigSpec<'_>) -> anyhow::Result<Self> {
        let scenario = spec.scenario;
        let start = scenario.start_pose(spec.trial);
        let seed = scenario.trial_seed(spec.trial);
        let world = Arc::new(scenario.world.clone());
        let stop = CancellationToken::new();
        let mut tasks = Vec::new();

        // Pioneer emulator on a pty.
        let (robot_master, robot_slave, robot_link) = pty_link(9600)?;
        let mut robot = RobotEmulator::new(RobotConfig {
            initial_pose: start,
            ..robot_config(seed, spec.slip)
        })
        .with_motion_hook(wall_hook(
            Arc::clone(&world),
            scenario.spec.robot.drive.body_radius,
        ));
        let control = robot.lock_step();
        let truth = robot.handle();
        let clock: SharedClock = Arc::new(EmulatorClock(truth.clone()));
        let robot_stop = stop.clone();
        tasks.push(tokio::spawn(async move {
            tokio::select! {
                () = robot_stop.cancelled() => {}
                r = robot.serve(robot_master) => if let Err(e) = r { tracing::warn!(error = %e, "robot emulator ended") },
            }
        }));

        // Alien reader emulator on loopback TCP; its field follows the true pose.
        let bad_epcs = Arc::new(Mutex::new(0u64));
        let field = uhf_field(
            SensorSuite::for_trial(scenario, spec.trial),
            Arc::clone(&world),
            truth.clone(),
            Arc::clone(&bad_epcs),
        );
        // The reader's clock (tag times) runs on the simulated time.
        let emulator = ReaderEmulator::new(
            field,
            EmulatorOptions {
                clock: Some(clock.clone()),
                ..EmulatorOptions::default()
            },
        );
        let (addr, reader_task) = emulator
            .bind_loopback()
            .await
            .context("binding the reader emulator")?;
        let reader_link = LinkConfig::Tcp(TcpLink {
            address: addr.to_string(),
            connect_timeout: 5.0,
        });

        let note = format!(
            "simulated seed 000 snapshot trial {} of {}; timestamps are the Pioneer emulator's simulated seconds",
            spec.trial, scenario.spec.name
        );
        let base_sink = crate::sim::trial_capture(
            spec.dir,
            "pioneer.cap",
            "pioneer-aria",
            &robot_link,
            clock.clone(),
            &[note.as_str()],
        )?;
        let base_io = Recorder::new(open(&robot_link).await?, base_sink.clone());
        let base = AriaClient::from_stream(base_io, driver_config(clock.clone()))
            .await
            .context("Pioneer handshake")?;
        let base = LockstepBase::new(base, control, truth.clone(), base_sink.clone());

        // The emulator's port is chosen per run; the header names the link without it so that
        // reruns write identical captures.
        let reader_sink = crate::sim::trial_capture_described(
            spec.dir,
            "alien.cap",
            "alien-alr9900",
            "tcp 127.0.0.1 (emulator on an ephemeral port)",
            clock.clone(),
            &[note.as_str()],
        )?;
        let reader_io = Recorder::new(
            open(&reader_link)
                .await
                .context("connecting to the reader")?,
            reader_sink.clone(),
        );
        // The reader's clock is set to the simulated mission's epoch, not the host's date.
        let reader_config = AlienConfig {
            time_source: Arc::new(|| SIMULATED_READER_TIME.to_string()),
            ..AlienConfig::default()
        };
        let mut reader = AlienClient::connect(reader_io, reader_config, clock.clone())
            .await
            .context("reader login")?;
        reader
            .apply_setup(&ReaderSetup::project())
            .await
            .context("reader setup")?;

        let threshold = scenario.uhf_model().threshold;
        Ok(Self {
            truth,
            base,
            reader,
            start,
            average: AverageConfig {
                tag_set: AverageTagSet::LargestRead,
                threshold,
            },
            reads_per_step: spec.reads_per_step.max(1),
            stop,
            tasks,
            reader_task,
            sinks: vec![base_sink, reader_sink.clone()],
            reader_sink,
            bad_epcs,
            counters: RigCounters::default(),
            _robot_slave: robot_slave,
        })
    }

    /// The emulator's true pose (the referee's view).
    #[must_use]
    pub fn truth(&self) -> Pose2 {
        self.truth.truth()
    }

    /// Simulated seconds since the emulator started.
    #[must_use]
    pub fn sim_time(&self) -> f64 {
        self.truth.state().sim_time
    }

    /// The robot's own pose belief from odometry alone: the start pose composed with the
    /// driver's odometry (the odometry frame starts where the client connected, at rest).
    #[must_use]
    pub fn odometry_pose(&self) -> Pose2 {
        let odom = self.base.client().odometry();
        let p = odom.borrow().pose;
        self.start.compose(&p)
    }

    /// Counters so far.
    #[must_use]
    pub fn counters(&self) -> RigCounters {
        RigCounters {
            bad_epcs: *self.bad_epcs.lock().unwrap_or_else(PoisonError::into_inner),
            ..self.counters
        }
    }

    /// Reads `reads_per_step` tag lists through the Alien driver and averages them (the seed's
    /// `scanNetTags`).
    pub async fn read_snapshot(&mut self) -> anyhow::Result<Snapshot> {
        let mut reads = Vec::with_capacity(self.reads_per_step);
        for _ in 0..self.reads_per_step {
            let s = self
                .reader
                .read_snapshot()
                .await
                .context("reading the tag list")?;
            self.counters.reads += 1;
            reads.push(Snapshot::from_reads(
                s.id_rss().into_iter().map(|(id, r)| (TagId::new(id.0), r)),
            ));
        }
        // Framed for replays as the daemon's reader task frames its snapshots.
        self.reader_sink.event(&format!(
            "mark {}",
            rfloc_daemon::devices::alien::snapshot_mark(reads.len())
        ));
        Ok(Snapshot::average(&reads, &self.average))
    }

    /// Drives `cmd` for `duration_s` simulated seconds (whole SIP periods) through the Pioneer
    /// driver, then stops and ticks until the robot is at rest. Returns true when the driver's
    /// SIPs reported a wheel stall during the action (the robot pushed against a wall).
    pub async fn drive(&mut self, cmd: MotionCommand, duration_s: f64) -> anyhow::Result<bool> {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let ticks = (duration_s / TICK_S).round().clamp(1.0, 1e6) as u32;
        self.base.set_velocity(cmd.v, cmd.omega).await?;
        let mut stalled = false;
        for _ in 0..ticks {
            let (o, _) = self.base.tick().await?;
            stalled |= o.left_stall || o.right_stall;
        }
        self.base.set_velocity(0.0, 0.0).await?;
        let mut settled = false;
        for _ in 0..SETTLE_TICKS {
            let (o, st) = self.base.tick().await?;
            stalled |= o.left_stall || o.right_stall;
            if st.v.abs() < STOPPED_V && st.w.abs() < STOPPED_W {
                settled = true;
                break;
            }
        }
        if !settled {
            self.counters.unsettled += 1;
        }
        if stalled {
            self.counters.stalls += 1;
        }
        Ok(stalled)
    }

    /// Stops the robot, closes both links, flushes the captures and stops the emulators.
    pub async fn shutdown(self) -> anyhow::Result<()> {
        let _ = self.base.set_velocity(0.0, 0.0).await;
        let _ = self.reader.quit().await;
        self.base.shutdown().await;
        for s in &self.sinks {
            s.flush().context("flushing a capture")?;
        }
        self.stop.cancel();
        self.reader_task.abort();
        for t in self.tasks {
            let _ = tokio::time::timeout(Duration::from_secs(2), t).await;
        }
        Ok(())
    }
}
