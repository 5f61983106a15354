//! The devices of one snapshot trial: an emulated Pioneer on a pty and an emulated Alien
//! ALR-9900 on a loopback TCP listener, both reached through rfloc's real drivers over links
//! opened with `rfloc_transport::open` and recorded into the trial folder.
//!
//! The reader's tag field is the scenario's UHF model evaluated at the antenna pose derived
//! from the emulator's *true* pose at the moment the reader answers `t`.

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crate::sim::EmulatorClock;
use anyhow::Context;
use rfloc_alien::{
    AlienClient, AlienConfig, EmulatorOptions, ReaderEmulator, ReaderSetup, SnapshotReader,
};
use rfloc_aria::{
    AriaClient, ClientConfig, EmulatorConfig as RobotConfig, EmulatorHandle, MotionHook,
    RobotEmulator, WheelSlip,
};
use rfloc_pose::Pose2;
use rfloc_sim::{Point, Scenario, SensorSuite, World};
use rfloc_snapshot::{AverageConfig, AverageTagSet, MotionCommand, Snapshot, TagId};
use rfloc_transport::{open, CaptureSink, LinkConfig, Recorder, SharedClock, TcpLink};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::sim::pty_link;

/// Wall-clock limit for any single wait on the emulated robot.
const WAIT_LIMIT: Duration = Duration::from_secs(10);
/// Wall-clock floor of the Pioneer driver's link timeout.
const LINK_TIMEOUT_FLOOR: Duration = Duration::from_secs(10);
/// The robot counts as stopped below these speeds (m/s, rad/s).
const STOPPED_V: f64 = 1e-3;
const STOPPED_W: f64 = 1e-3;
/// Longest simulated wait for the robot to come to rest after a stop command.
const SETTLE_LIMIT_S: f64 = 2.0;

type RecordedTcp = Recorder<rfloc_transport::Transport>;

/// Counters of one trial's device traffic.
#[derive(Debug, Clone, Copy, Default)]
pub struct RigCounters {
    /// `t` polls answered.
    pub reads: u64,
    /// Tag IDs from the world that were not hex (skipped by the field).
    pub bad_epcs: u64,
    /// Actions whose stop command landed after the planned duration.
    pub late_stops: u64,
    /// Stops that did not settle within [`SETTLE_LIMIT_S`].
    pub unsettled: u64,
    /// Actions during which the driver reported a wheel stall.
    pub stalls: u64,
}

/// Emulators plus connected drivers of one trial.
pub struct SnapshotRig {
    truth: EmulatorHandle,
    base: AriaClient,
    reader: AlienClient<RecordedTcp>,
    start: Pose2,
    average: AverageConfig,
    reads_per_step: usize,
    stop: CancellationToken,
    tasks: Vec<JoinHandle<()>>,
    reader_task: JoinHandle<std::io::Result<()>>,
    sinks: Vec<CaptureSink>,
    bad_epcs: Arc<Mutex<u64>>,
    counters: RigCounters,
    _robot_slave: tokio_serial::SerialStream,
}

/// A motion hook that keeps a disc of `radius` inside the world (walls stall the wheels;
/// turning on the spot stays possible).
fn wall_hook(world: Arc<World>, radius: f64) -> MotionHook {
    Box::new(move |current: &Pose2, proposed: &Pose2| {
        if world.disk_collides(&Point::new(proposed.x, proposed.y), radius) {
            Pose2::new(current.x, current.y, proposed.theta)
        } else {
            *proposed
        }
    })
}

/// What the trial needs to build a rig.
pub struct RigSpec<'a> {
    pub scenario: &'a Scenario,
    pub trial: usize,
    pub dir: &'a Path,
    pub time_scale: f64,
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

        // Pioneer emulator on a pty. The accelerations are raised from the P3-DX defaults so
        // that one action's displacement (seed Table 4 over 0.1 s) is driven within about half
        // a second of simulated time.
        let (robot_master, robot_slave, robot_link) = pty_link(9600)?;
        let mut robot = RobotEmulator::new(RobotConfig {
            time_scale: spec.time_scale,
            initial_pose: start,
            noise_seed: seed,
            trans_accel: 2000.0,
            trans_decel: 2000.0,
            rot_accel: 400.0,
            rot_decel: 400.0,
            slip: (spec.slip > 0.0).then_some(WheelSlip {
                seed: seed ^ 0x534c_4950,
                relative_std: spec.slip,
            }),
            ..RobotConfig::default()
        })
        .with_motion_hook(wall_hook(
            Arc::clone(&world),
            scenario.spec.robot.drive.body_radius,
        ));
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
        let sensors = Arc::new(Mutex::new(SensorSuite::for_trial(scenario, spec.trial)));
        let bad_epcs = Arc::new(Mutex::new(0u64));
        let field_truth = truth.clone();
        let field_world = Arc::clone(&world);
        let field_bad = Arc::clone(&bad_epcs);
        let field: rfloc_alien::TagField = Arc::new(move || {
            let pose = field_truth.truth();
            let reads = sensors
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .uhf_inventory(&field_world, &pose);
            let mut out = Vec::with_capacity(reads.len());
            for (epc, rss) in reads {
                match TagId::from_hex(&epc) {
                    Some(id) => out.push((id.0, rss)),
                    None => *field_bad.lock().unwrap_or_else(PoisonError::into_inner) += 1,
                }
            }
            out
        });
        let emulator = ReaderEmulator::new(field, EmulatorOptions::default());
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
        let mut base_config = ClientConfig {
            clock: Some(clock.clone()),
            ..ClientConfig::default()
        }
        .scaled(spec.time_scale);
        // Scaled link timeouts are a few milliseconds of wall time; learning between the phases
        // may hold a core for longer than that.
        base_config.link_timeout = base_config.link_timeout.max(LINK_TIMEOUT_FLOOR);
        let base = AriaClient::from_stream(base_io, base_config)
            .await
            .context("Pioneer handshake")?;

        let reader_sink = crate::sim::trial_capture(
            spec.dir,
            "alien.cap",
            "alien-alr9900",
            &reader_link,
            clock.clone(),
            &[note.as_str()],
        )?;
        let reader_io = Recorder::new(
            open(&reader_link)
                .await
                .context("connecting to the reader")?,
            reader_sink.clone(),
        );
        let mut reader = AlienClient::connect(reader_io, AlienConfig::default(), clock.clone())
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
            sinks: vec![base_sink, reader_sink],
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
        let odom = self.base.odometry();
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
        Ok(Snapshot::average(&reads, &self.average))
    }

    /// Drives `cmd` for `duration_s` simulated seconds through the Pioneer driver, then stops
    /// and waits until the robot is at rest. Returns true when the driver's SIPs reported a
    /// wheel stall during the action (the robot pushed against a wall).
    pub async fn drive(&mut self, cmd: MotionCommand, duration_s: f64) -> anyhow::Result<bool> {
        let odom = self.base.odometry();
        let mut stalled = false;
        let mut rx = self.truth.subscribe();
        let t0 = rx.borrow_and_update().sim_time;
        self.base
            .set_velocity(cmd.v, cmd.omega)
            .await
            .context("velocity command")?;
        // Stop at the first tick at or after the planned end (half a tick early so that a
        // prompt stop lands on the planned tick).
        let end = t0 + duration_s - 0.05;
        loop {
            let now = rx.borrow_and_update().sim_time;
            {
                let o = odom.borrow();
                stalled |= o.left_stall || o.right_stall;
            }
            if now >= end {
                if now > end + 0.1 {
                    self.counters.late_stops += 1;
                }
                break;
            }
            tokio::time::timeout(WAIT_LIMIT, rx.changed())
                .await
                .context("the emulated Pioneer stopped advancing")?
                .context("the emulated Pioneer ended")?;
        }
        self.base
            .set_velocity(0.0, 0.0)
            .await
            .context("stop command")?;
        let t_stop = rx.borrow_and_update().sim_time;
        loop {
            let st = *rx.borrow_and_update();
            // Two ticks after the stop so that the command has been read.
            if st.sim_time >= t_stop + 0.15 && st.v.abs() < STOPPED_V && st.w.abs() < STOPPED_W {
                break;
            }
            if st.sim_time > t_stop + SETTLE_LIMIT_S {
                self.counters.unsettled += 1;
                break;
            }
            tokio::time::timeout(WAIT_LIMIT, rx.changed())
                .await
                .context("the emulated Pioneer stopped advancing")?
                .context("the emulated Pioneer ended")?;
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
        self.base.shutdown().await.ok();
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
