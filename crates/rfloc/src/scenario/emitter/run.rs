//! One closed-loop run of the emitter-homing system against an emulated Pioneer on a pty.
//!
//! Timing: the control loop runs on the emulator's SIPs. SIP number `s` came from emulator tick
//! `k0 + s − 1`. Control steps fall on a fixed grid of ticks (every `CONTROL_TICKS` ticks from
//! `k0 + SETTLE_TICKS`); each reads the sensors at the true pose of its tick (from
//! [`TruthLog`]), updates the filter and the map and asks the navigator for a command. With the
//! next SIP the command is sent while the emulator is held at the start of the tick after, and
//! that tick is released: the emulator reads the command right after that tick's SIP and it
//! acts from the tick after (a fixed actuation latency of three ticks, 0.3 s simulated).
//!
//! Reproducibility: the emulator runs on its own thread behind the tick gate of [`TruthLog`],
//! so it cannot start tick `k + 1` before the loop has finished with SIP `k`; a slow control
//! step delays simulated time instead of the robot driving on. One race is left that only the
//! emulator could close: if its next tick is already due when it goes back to reading after a
//! SIP (a hold longer than one wall-clock SIP period), its `select!` may take the tick before
//! the waiting command, which then lands one tick late. The loop checks the emulator's command
//! counter before releasing that tick and counts such commands (`late_commands`), as well as
//! missed control ticks and gate time-outs; with all three at 0 a rerun gives identical
//! numbers.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use crate::sim::EmulatorClock;
use anyhow::Context;
use rfloc_aria::{AriaClient, ClientConfig, EmulatorConfig, EmulatorHandle, RobotEmulator};
use rfloc_capture::Header;
use rfloc_emitter::{
    AntennaRss, Bumpers, NavigatorConfig, NavigatorState, OccupancyGridConfig,
    ParticleFilterConfig, Point2, ScanBeam,
};
use rfloc_pose::Pose2;
use rfloc_sim::{Point, Scenario, SensorSuite};
use rfloc_transport::{CaptureSink, LinkConfig, Recorder, SharedClock};

use super::calibration::calibrate;
use super::homing::{EmitterHoming, HomingConfig};
use super::truth_log::TruthLog;

/// Emulator ticks (SIP periods of 0.1 s) per control step: 5 Hz control, sensing and filtering.
pub const CONTROL_TICKS: u64 = 2;
/// Ticks after the first SIP before the first control step (the loop is set up by then, so
/// the control schedule never depends on start-up delays).
pub const SETTLE_TICKS: u64 = 10;
/// Simulated seconds per emulator tick (the emulator's default SIP period).
pub const TICK_S: f64 = 0.1;
/// The robot believing it has arrived for this long without the referee agreeing ends the run.
pub const ARRIVED_HOLD_S: f64 = 10.0;
/// Wall-clock wait for SIPs before the link counts as lost (the gate may pause them).
pub const LINK_TIMEOUT: Duration = Duration::from_secs(10);
/// Wall-clock wait for the emulator to reach its next tick before a command is sent.
pub const HOLD_WAIT: Duration = Duration::from_secs(1);
/// Wall-clock wait for the emulator to read a command before it counts as late.
pub const COMMAND_READ_WAIT: Duration = Duration::from_millis(50);
/// The navigator's stop distance from its estimate, metres.
pub const ARRIVAL_DISTANCE_M: f64 = 0.3;
/// Side of the square map centred on the start, metres.
pub const MAP_SIDE_M: f64 = 12.0;

/// What one run asks for.
#[derive(Debug, Clone)]
pub struct RunSpec<'a> {
    pub scenario: &'a Scenario,
    pub trial: usize,
    /// Full system (grid + A*) or the preliminary one.
    pub use_planner: bool,
    /// Where the Pioneer link is recorded.
    pub capture: PathBuf,
    pub time_scale: f64,
}

/// What happened in one run. Times are simulated seconds since the first SIP.
#[derive(Debug, Clone, Default)]
pub struct RunOutcome {
    pub truth: Vec<(f64, Pose2)>,
    /// The robot's own pose (start pose composed with odometry) at each control step.
    pub pose_estimate: Vec<(f64, Pose2)>,
    /// First time the true position was within the goal tolerance (the referee's view).
    pub reached: Option<f64>,
    /// Distance of the filtered emitter estimate from the emitter, per filter update.
    pub filtered_errors: Vec<f64>,
    /// Distance of the raw (unfiltered) estimate from the emitter, per filter update.
    pub raw_errors: Vec<f64>,
    /// Per filter update: no wall between the true robot position and the emitter.
    pub line_of_sight: Vec<bool>,
    pub final_estimate: Option<Point2>,
    /// The navigator declared arrival at some point.
    pub robot_arrived: bool,
    pub end_time: f64,
    pub plans: u64,
    pub bumper_steps: u64,
    pub late_control_steps: u64,
    pub rejected_rss: u64,
    /// Times the emitter filter was re-initialised on the raw estimates.
    pub filter_restarts: u64,
    /// Commands not read by the emulator before the next tick (landed one tick late).
    pub late_commands: u64,
    /// Times the emulator stopped waiting for the control loop.
    pub gate_timeouts: u64,
}

fn homing_config(
    scenario: &Scenario,
    start: &Pose2,
    use_planner: bool,
    seed: u64,
) -> anyhow::Result<HomingConfig> {
    let emitter = scenario
        .world
        .emitter
        .context("the scenario's world has no emitter")?;
    let rss = calibrate(&scenario.emitter_model(), emitter.power_dbm)?;
    let params = &scenario.spec.params;
    let filter = ParticleFilterConfig {
        particle_count: params.particles.unwrap_or(1000),
        ..ParticleFilterConfig::default()
    };
    let resolution = params.grid_cell_m.unwrap_or(0.2);
    let cells = (MAP_SIDE_M / resolution).round().max(1.0) as usize;
    let grid = OccupancyGridConfig {
        resolution_m: resolution,
        width: cells,
        height: cells,
        origin: Point2::new(start.x - MAP_SIDE_M / 2.0, start.y - MAP_SIDE_M / 2.0),
        ..OccupancyGridConfig::default()
    };
    let body = scenario.spec.robot.drive.body_radius;
    let navigator = NavigatorConfig {
        use_planner,
        // The seed's 20 cm are from the front of the robot; the simulated laser sits at the
        // centre of a round body.
        obstacle_distance_m: 0.2 + body,
        // The seed stops within 50 cm of the emitter; the filtered estimate is a few decimetres
        // off near the end, so the robot aims closer to its estimate than that.
        arrival_distance_m: ARRIVAL_DISTANCE_M,
        ..NavigatorConfig::default()
    };
    Ok(HomingConfig {
        rss,
        filter,
        grid,
        navigator,
        seed: seed ^ 0x5046_5345_4544, // "PFSEED"
    })
}

fn to_antenna_rss(rss: &[Option<f64>; 4]) -> Option<AntennaRss> {
    // rfloc-sim orders the antennas front, left, back, right.
    match *rss {
        [Some(front), Some(left), Some(back), Some(right)] => Some(AntennaRss {
            front,
            back,
            left,
            right,
        }),
        _ => None,
    }
}

/// Runs the system once; the robot starts at the scenario's start pose for `trial`.
///
/// # Errors
/// Pty, capture, handshake or configuration failures, or an emulator that stops sending SIPs.
pub async fn run_system(spec: &RunSpec<'_>) -> anyhow::Result<RunOutcome> {
    let scenario = spec.scenario;
    let world = Arc::new(scenario.world.clone());
    let emitter = world
        .emitter
        .context("the scenario's world has no emitter")?
        .position;
    let start = scenario.start_pose(spec.trial);
    let seed = scenario.trial_seed(spec.trial);
    let radius = scenario.spec.robot.drive.body_radius;
    let goal = scenario
        .goal(spec.trial)
        .zip(scenario.spec.goal.map(|g| g.tolerance_m))
        .unwrap_or((emitter, 0.5));
    let time_scale = if spec.time_scale.is_finite() && spec.time_scale > 0.0 {
        spec.time_scale
    } else {
        1.0
    };

    let log = TruthLog::new();
    let emulator = RobotEmulator::new(EmulatorConfig {
        time_scale,
        initial_pose: start,
        // No wheel slip: the emulator draws slip noise on every tick from the moment it starts
        // serving, and how many ticks pass before the handshake completes depends on wall
        // time, so seeded slip would still differ between reruns.
        slip: None,
        noise_seed: seed,
        ..EmulatorConfig::default()
    })
    .with_motion_hook(log.motion_hook(Arc::clone(&world), radius));
    let handle = emulator.handle();
    let (thread, link) = EmulatorThread::spawn(emulator).await?;
    let clock: SharedClock = Arc::new(EmulatorClock(handle.clone()));

    let result = drive(
        spec, &world, start, seed, radius, goal, emitter, &link, &log, &handle, &clock, time_scale,
    )
    .await;
    log.open_gate();
    thread.stop();
    let mut out = result?;
    out.gate_timeouts = log.gate_timeouts();
    Ok(out)
}

/// The emulator on a thread of its own with a single-threaded runtime: the tick gate blocks
/// it, which must not block the client's or the trial's tasks.
struct EmulatorThread {
    stop: tokio::sync::oneshot::Sender<()>,
    join: std::thread::JoinHandle<()>,
}

impl EmulatorThread {
    /// Starts serving the master side of a new pty; returns the link to its slave side.
    async fn spawn(mut emulator: RobotEmulator) -> anyhow::Result<(Self, LinkConfig)> {
        let (link_tx, link_rx) = tokio::sync::oneshot::channel::<anyhow::Result<LinkConfig>>();
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let join = std::thread::Builder::new()
            .name("pioneer-emulator".into())
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        let _ = link_tx.send(Err(e.into()));
                        return;
                    }
                };
                rt.block_on(async move {
                    // The pty is registered with this thread's runtime.
                    let (master, slave, link) = match crate::sim::pty_link(9600) {
                        Ok(p) => p,
                        Err(e) => {
                            let _ = link_tx.send(Err(e));
                            return;
                        }
                    };
                    let _ = link_tx.send(Ok(link));
                    tokio::select! {
                        _ = stop_rx => {}
                        r = emulator.serve(master) => if let Err(e) = r {
                            tracing::warn!(error = %e, "robot emulator ended");
                        }
                    }
                    // The slave side stays open until the end so the master never hangs up.
                    drop(slave);
                });
            })
            .context("starting the emulator thread")?;
        let link = link_rx
            .await
            .context("the emulator thread ended before serving")??;
        Ok((Self { stop, join }, link))
    }

    /// Stops serving and waits for the thread.
    fn stop(self) {
        let _ = self.stop.send(());
        if self.join.join().is_err() {
            tracing::warn!("the emulator thread panicked");
        }
    }
}

#[allow(clippy::too_many_arguments)]
async fn drive(
    spec: &RunSpec<'_>,
    world: &Arc<rfloc_sim::World>,
    start: Pose2,
    seed: u64,
    radius: f64,
    goal: (Point, f64),
    emitter: Point,
    link: &LinkConfig,
    log: &TruthLog,
    handle: &EmulatorHandle,
    clock: &SharedClock,
    time_scale: f64,
) -> anyhow::Result<RunOutcome> {
    let scenario = spec.scenario;
    let io = rfloc_transport::open(link)
        .await
        .with_context(|| format!("opening {}", link.describe()))?;
    let mut header = Header::new("pioneer-aria", link.describe());
    header.notes.push(format!(
        "simulated Pioneer (rfloc-aria emulator) for {} trial {} ({} system); times are simulated seconds",
        scenario.spec.name,
        spec.trial,
        if spec.use_planner { "full" } else { "preliminary" }
    ));
    let sink = CaptureSink::create(&spec.capture, &header, Arc::clone(clock))
        .with_context(|| format!("creating {}", spec.capture.display()))?;
    let mut client_config = ClientConfig {
        clock: Some(Arc::clone(clock)),
        ..ClientConfig::default()
    }
    .scaled(time_scale);
    // SIPs pause while the gate holds the emulator for a slow control step.
    client_config.link_timeout = LINK_TIMEOUT;
    let client = AriaClient::from_stream(Recorder::new(io, sink.clone()), client_config)
        .await
        .context("connecting to the emulated Pioneer")?;

    let mut sensors = SensorSuite::for_trial(scenario, spec.trial);
    let max_range = sensors.scanner.max_range;
    let mut homing = EmitterHoming::new(
        homing_config(scenario, &start, spec.use_planner, seed)?,
        &start,
    )?;
    let mut out = RunOutcome::default();
    let mut odom = client.odometry();
    let mut first_tick: Option<u64> = None;
    let mut last_tick = 0u64;
    let mut next_control = 0u64;
    // Command computed at the last control tick, not sent yet.
    let mut pending: Option<(f64, f64)> = None;
    // Emulator command count to wait for before the next tick may run.
    let mut outstanding: Option<u64> = None;
    let mut arrived_since: Option<f64> = None;

    loop {
        tokio::time::timeout(LINK_TIMEOUT, odom.changed())
            .await
            .context("the emulated Pioneer stopped sending SIPs")?
            .context("the Pioneer client stopped")?;
        let sample = *odom.borrow_and_update();
        if sample.seq == 0 {
            continue;
        }
        let k0 = match first_tick {
            Some(k) => k,
            None => {
                // Any state pairs a tick count with the number of SIPs sent by then.
                let st = handle.state();
                let tick = (st.sim_time / TICK_S).round() as u64;
                let k = (tick + 1).saturating_sub(st.sips_sent);
                first_tick = Some(k);
                last_tick = k.saturating_sub(1);
                next_control = k + SETTLE_TICKS;
                k
            }
        };
        let tick = k0 + sample.seq - 1;
        let since = |k: u64| (k - k0) as f64 * TICK_S;
        // The referee: true pose of every tick, goal check.
        for k in (last_tick + 1)..=tick {
            if let Some(p) = log.after_tick(k) {
                let t = since(k);
                out.truth.push((t, p));
                if out.reached.is_none() && Point::new(p.x, p.y).distance(&goal.0) <= goal.1 {
                    out.reached = Some(t);
                }
            }
        }
        last_tick = tick;
        let t = since(tick);
        out.end_time = t;
        if out.reached.is_some() || t >= scenario.spec.duration_s {
            break;
        }
        // The command sent during the last hold must be in before the next tick may run.
        if let Some(count) = outstanding.take() {
            if !command_read(handle, count).await {
                out.late_commands += 1;
                tracing::debug!(
                    tick,
                    held = ?log.held(),
                    commands = handle.state().commands,
                    expected = count,
                    sim_time = handle.state().sim_time,
                    "command read after the next tick started"
                );
            }
        }
        // A command computed at an earlier control tick goes out while the emulator is held at
        // the start of the next tick; the hold then only lasts as long as the send.
        if let Some((v, w)) = pending.take() {
            if !log.wait_held(tick + 1, HOLD_WAIT) {
                out.late_commands += 1;
                tracing::debug!(tick, "emulator not held before a command");
            }
            let before = handle.state().commands;
            client
                .set_velocity(v, w)
                .await
                .context("sending VEL/RVEL")?;
            outstanding = Some(before + 2);
        }
        if tick >= next_control {
            if tick > next_control {
                out.late_control_steps += 1;
            }
            // Stay on the schedule of the first SIP, whatever the wall-clock delays.
            while next_control <= tick {
                next_control += CONTROL_TICKS;
            }
            let step = ControlStep {
                t,
                tick,
                pose: start.compose(&sample.pose),
            };
            let cmd = control_step(
                &step,
                &mut homing,
                &mut sensors,
                world,
                log,
                radius,
                emitter,
                max_range,
                &mut out,
            )?;
            if cmd.state == NavigatorState::Arrived {
                out.robot_arrived = true;
                let since_arrival = *arrived_since.get_or_insert(t);
                if t - since_arrival >= ARRIVED_HOLD_S {
                    break;
                }
            } else {
                arrived_since = None;
            }
            pending = Some((cmd.v_mps, cmd.omega_rps));
        }
        log.release_through(tick + 1);
    }
    out.plans = homing.plan_count();
    out.rejected_rss = homing.rejected_rss();
    out.filter_restarts = homing.reinitialisations();
    let _ = client.set_velocity(0.0, 0.0).await;
    client
        .shutdown()
        .await
        .context("closing the Pioneer link")?;
    sink.flush()
        .with_context(|| format!("flushing {}", spec.capture.display()))?;
    Ok(out)
}

/// When and where a control step happens.
struct ControlStep {
    t: f64,
    tick: u64,
    /// The robot's pose belief: start pose composed with odometry.
    pose: Pose2,
}

/// Sensors at the true pose of the step's tick → filter, map → navigator command.
#[allow(clippy::too_many_arguments)]
fn control_step(
    step: &ControlStep,
    homing: &mut EmitterHoming,
    sensors: &mut SensorSuite,
    world: &rfloc_sim::World,
    log: &TruthLog,
    radius: f64,
    emitter: Point,
    max_range: f64,
    out: &mut RunOutcome,
) -> anyhow::Result<rfloc_emitter::NavigationCommand> {
    let (t, pose) = (step.t, step.pose);
    let truth = log
        .after_tick(step.tick)
        .context("no true pose logged for the current tick")?;
    out.pose_estimate.push((t, pose));
    // 915 MHz receivers and laser: in-process models at the true pose (no wire protocol).
    if let Some(rss) = to_antenna_rss(&sensors.emitter_rss(world, &truth)) {
        if let Some(est) = homing.observe_rss(t, &pose, &rss) {
            out.filtered_errors
                .push(Point::new(est.mean.x, est.mean.y).distance(&emitter));
            out.raw_errors
                .push(Point::new(est.raw.x, est.raw.y).distance(&emitter));
            out.final_estimate = Some(est.mean);
            let here = Point::new(truth.x, truth.y);
            out.line_of_sight
                .push(world.walls_crossed(&here, &emitter) == 0);
        }
    }
    let beams: Vec<ScanBeam> = sensors
        .laser_scan(world, &truth)
        .into_iter()
        .map(|b| ScanBeam {
            angle_rad: b.angle,
            range_m: if b.hit { b.range } else { max_range },
            max_range_m: max_range,
        })
        .collect();
    homing.observe_scan(&pose, beams);
    let contact = sensors.bumpers(world, &truth, radius);
    let bumpers = Bumpers {
        front: contact.front,
        rear: contact.rear,
    };
    if bumpers.front || bumpers.rear {
        out.bumper_steps += 1;
    }
    Ok(homing.command(t, pose, bumpers))
}

/// Waits briefly until the emulator has handled `count` commands. While the gate holds the
/// next tick, an emulator that is free reads them at once; one already blocked in the next
/// tick cannot, and the command lands a tick late (reported as `false`).
async fn command_read(handle: &EmulatorHandle, count: u64) -> bool {
    let deadline = tokio::time::Instant::now() + COMMAND_READ_WAIT;
    let mut rx = handle.subscribe();
    loop {
        if rx.borrow_and_update().commands >= count {
            return true;
        }
        if tokio::time::timeout_at(deadline, rx.changed())
            .await
            .is_err()
        {
            return rx.borrow().commands >= count;
        }
    }
}

/// Capture file of a run inside the trial folder.
#[must_use]
pub fn capture_path(dir: &Path, primary: bool, use_planner: bool) -> PathBuf {
    if primary {
        dir.join("pioneer.cap")
    } else if use_planner {
        dir.join("pioneer-full.cap")
    } else {
        dir.join("pioneer-preliminary.cap")
    }
}
