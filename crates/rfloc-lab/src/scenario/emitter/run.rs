//! One closed-loop run of the emitter-homing system against an emulated Pioneer on a pty.
//!
//! Timing: the emulated Pioneer runs in lock-step with the run ([`LockstepBase`]): simulated
//! time moves one SIP period (0.1 s) at a time, when the loop asks for it, and only after the
//! emulator has handled every command the driver wrote. Tick `n` (counted from 0 at the first
//! SIP) is at `t = n · 0.1 s`. Control steps fall on every [`CONTROL_TICKS`]th tick from
//! [`SETTLE_TICKS`]; each reads the sensors at the emulator's true pose after its tick and hands
//! them to the daemon's own `EmitterPipeline` as device events (four `EmitterRss`, one
//! `RangeScan`, `Bumpers`), followed by the tick's `Odometry`, on which the pipeline updates
//! the filter and the map and asks the navigator for a command. From the settle time on every
//! tick's odometry goes to the pipeline, as a robot's would. The command is written after
//! tick `n + ACTUATION_DELAY_TICKS` and is in force from the tick after: a fixed actuation
//! latency of three ticks (0.3 s simulated), as a slower real control loop would have.
//!
//! Reproducibility: with the clock moving only at the loop's request, the sensors read from
//! the emulator's state at a fixed tick in a fixed order (receivers, laser, bumpers, each with
//! its own stream of the trial seed) and the commands written at fixed ticks, a run is a
//! function of the scenario, the trial seed and the system alone. The capture coalesces same-
//! time reads (writes) into one record, so its bytes do not depend on how the pty chunked them.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use rfloc_aria::{AriaClient, EmulatorConfig, EmulatorHandle, RobotEmulator, StepControl};
use rfloc_emitter::{NavigatorConfig, OccupancyGridConfig, ParticleFilterConfig, Point2, ScanBeam};
use rfloc_pose::Pose2;
use rfloc_sim::{Point, Scenario, SensorSuite};
use rfloc_transport::{CaptureSink, LinkConfig, Recorder, SharedClock};
use rfloc_urg::{UrgClient, UrgConfig};

use super::calibration::calibrate;
use crate::scenario::lockstep::{driver_config, LockstepBase};
use crate::sim::walls::wall_hook;
use crate::sim::{trial_capture, EmulatorClock};
use rfloc_daemon::config::AntennaSide;
use rfloc_daemon::events::DeviceEvent;
use rfloc_daemon::pipeline::emitter::{EmitterPipeline, HomingConfig};
use rfloc_daemon::pipeline::{Pipeline, Request};

/// Emulator ticks (SIP periods of 0.1 s) per control step: 5 Hz control, sensing and filtering.
pub const CONTROL_TICKS: u64 = 2;
/// Ticks after the first SIP before the first control step (1 s standing still).
pub const SETTLE_TICKS: u64 = 10;
/// Ticks after its control tick after which a command is written; it is in force from the
/// tick after that (0.3 s from the data it was computed from).
pub const ACTUATION_DELAY_TICKS: u64 = 2;
/// Simulated seconds per emulator tick (the emulator's default SIP period).
pub const TICK_S: f64 = 0.1;
/// The robot believing it has arrived for this long without the referee agreeing ends the run.
pub const ARRIVED_HOLD_S: f64 = 10.0;
/// The navigator's stop distance from its estimate, metres.
pub const ARRIVAL_DISTANCE_M: f64 = 0.3;
/// Largest spread of the filtered estimate at which the navigator declares arrival, metres.
pub const ARRIVAL_MAX_SIGMA_M: f64 = 1.0;
/// Initial side of the square map centred on the start, metres; the map grows with the
/// explored area and the goal (up to [`MAP_MAX_SIDE_M`] squared).
pub const MAP_SIDE_M: f64 = 12.0;
/// Largest map, as the side of a square of the same number of cells, metres.
pub const MAP_MAX_SIDE_M: f64 = 400.0;

/// What one run asks for.
#[derive(Debug, Clone)]
pub struct RunSpec<'a> {
    pub scenario: &'a Scenario,
    pub trial: usize,
    /// Full system (grid + A*) or the preliminary one.
    pub use_planner: bool,
    /// Where the Pioneer link is recorded.
    pub capture: PathBuf,
}

/// What happened in one run. Times are simulated seconds since the first SIP (tick 0).
#[derive(Debug, Clone, Default)]
pub struct RunOutcome {
    pub truth: Vec<(f64, Pose2)>,
    /// The emulator's clock (the captures' time) at the run's time 0.
    pub capture_time_at_start: f64,
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
    pub rejected_rss: u64,
    /// Times the emitter filter was re-initialised on the raw estimates.
    pub filter_restarts: u64,
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
    let mut rss = calibrate(&scenario.emitter_model(), emitter.power_dbm)?;
    // `[mismatch] scale`: a calibration whose ranges are `scale` times the true ones.
    if let Some(m) = scenario.spec.mismatch {
        rss.a1_dbm_at_1m += 10.0 * rss.a2_path_loss_exponent * m.scale.log10();
    }
    let params = &scenario.spec.params;
    let seed_filter = ParticleFilterConfig::default();
    let filter = ParticleFilterConfig {
        particle_count: params.particles.unwrap_or(1000),
        range_offset_m: params.range_offset_m.unwrap_or(seed_filter.range_offset_m),
        angle_offset_deg: params
            .angle_offset_deg
            .unwrap_or(seed_filter.angle_offset_deg),
        ..seed_filter
    };
    let resolution = params.grid_cell_m.unwrap_or(0.2);
    let cells = (MAP_SIDE_M / resolution).round().max(1.0) as usize;
    let max_side = (MAP_MAX_SIDE_M / resolution).round().max(1.0) as usize;
    let grid = OccupancyGridConfig {
        resolution_m: resolution,
        width: cells,
        height: cells,
        origin: Point2::new(start.x - MAP_SIDE_M / 2.0, start.y - MAP_SIDE_M / 2.0),
        growable: true,
        max_cells: max_side.saturating_mul(max_side).max(cells * cells),
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
        // Arrive only at an estimate that has converged (a filter that restarted, or one
        // still spread over the start disc, is not a place to stop).
        arrival_max_sigma_m: ARRIVAL_MAX_SIGMA_M,
        ..NavigatorConfig::default()
    };
    Ok(HomingConfig {
        rss,
        filter,
        grid,
        navigator,
        seed: seed ^ 0x5046_5345_4544, // "PFSEED"
        // The receivers' data-sheet sensitivity: one or two that hear nothing read as that.
        receiver_sensitivity_dbm: Some(scenario.emitter_model().sensitivity_dbm),
    })
}

/// Runs the system once; the robot starts at the scenario's start pose for `trial`.
///
/// # Errors
/// Pty, capture, handshake or configuration failures, or an emulator that does not take its
/// steps.
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

    let mut emulator = RobotEmulator::new(EmulatorConfig {
        initial_pose: start,
        // No wheel slip: the scenarios model none, and the seed's system takes its odometry as
        // its pose.
        slip: None,
        noise_seed: seed,
        ..EmulatorConfig::default()
    })
    .with_motion_hook(wall_hook(Arc::clone(&world), radius));
    let control = emulator.lock_step();
    let handle = emulator.handle();
    let (master, slave, link) = crate::sim::pty_link(9600)?;
    let task = tokio::spawn(async move {
        let mut emulator = emulator;
        if let Err(e) = emulator.serve(master).await {
            tracing::warn!(error = %e, "robot emulator ended");
        }
    });
    let clock: SharedClock = Arc::new(EmulatorClock(handle.clone()));
    let scanner = SensorSuite::for_trial(scenario, spec.trial).scanner;
    let (laser_task, laser_slave, laser_link) =
        start_laser(Arc::clone(&world), handle.clone(), &clock, &scanner, seed)?;
    let result = async {
        let mut laser = connect_laser(spec, &laser_link, &clock, scanner.mount_offset).await?;
        let (base, sink) = connect(spec, &link, control, handle, &clock).await?;
        let mission = Mission {
            world: &world,
            start,
            seed,
            radius,
            goal,
            emitter,
        };
        let out = mission.drive(spec, &base, &mut laser).await;
        // Stop and close whatever happened, then write the captures' last records.
        if out.is_ok() {
            base.set_velocity(0.0, 0.0).await?;
        }
        base.shutdown().await;
        if let Err(e) = laser.client.laser_off().await {
            tracing::warn!(error = %e, "laser off failed");
        }
        sink.flush()
            .with_context(|| format!("flushing {}", spec.capture.display()))?;
        laser
            .sink
            .flush()
            .with_context(|| format!("flushing {}", laser_capture(&spec.capture).display()))?;
        out
    }
    .await;
    task.abort();
    let _ = task.await;
    laser_task.abort();
    let _ = laser_task.await;
    drop(slave);
    drop(laser_slave);
    result
}

/// The trial's laser: the daemon's URG driver against the URG emulator on a pty, recorded.
struct TrialLaser {
    client: UrgClient<Recorder<rfloc_transport::Transport>>,
    sink: CaptureSink,
    mount_offset_m: f64,
}

impl TrialLaser {
    /// One `GD` scan as the daemon's URG task turns it into beams.
    async fn beams(&mut self) -> anyhow::Result<Vec<ScanBeam>> {
        let scan = self.client.scan().await.context("laser scan")?;
        Ok(rfloc_daemon::devices::urg::scan_beams(
            &scan,
            &self.client.config().geometry,
            self.mount_offset_m,
        ))
    }
}

/// The laser capture next to a run's Pioneer capture (`pioneer*.cap` → `laser*.cap`).
fn laser_capture(pioneer: &Path) -> PathBuf {
    let name = pioneer
        .file_name()
        .and_then(|f| f.to_str())
        .unwrap_or("pioneer.cap")
        .replacen("pioneer", "laser", 1);
    pioneer.with_file_name(name)
}

/// A URG emulator on a pty whose beams ray-cast `world` from the scanner's pose at the
/// emulated robot's true pose, with the scenario scanner's range noise from a stream of the
/// trial seed. Drawn only while the trial's clock stands (one scan per control step), so the
/// draws are a function of the trial.
fn start_laser(
    world: Arc<rfloc_sim::World>,
    robot: EmulatorHandle,
    clock: &SharedClock,
    scanner: &rfloc_sim::scanner::RangeScanner,
    seed: u64,
) -> anyhow::Result<(
    tokio::task::JoinHandle<()>,
    tokio_serial::SerialStream,
    LinkConfig,
)> {
    let (offset, sigma) = (scanner.mount_offset, scanner.noise_sigma);
    let reach = scanner.max_range;
    let rng = std::sync::Mutex::new(
        <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed ^ 0x004C_4153_4552),
    );
    let ranges: rfloc_urg::RangeFn = Arc::new(move |angle| {
        let p = robot.truth();
        let (x, y) = p.transform_point(offset, 0.0);
        let d = world
            .ray_cast(&Point::new(x, y), p.theta + angle)
            .filter(|d| *d <= reach)?;
        let noise = rng
            .lock()
            .map_or(0.0, |mut r| rfloc_sim::noise::gaussian(&mut *r, sigma));
        Some((d + noise).max(0.0))
    });
    let clock = Arc::clone(clock);
    let emulator = rfloc_urg::UrgEmulator::new(
        ranges,
        rfloc_urg::EmulatorConfig {
            clock: Some(Arc::new(move || clock.now())),
            ..rfloc_urg::EmulatorConfig::default()
        },
    );
    let (master, slave, link) = crate::sim::pty_link(115_200)?;
    let task = tokio::spawn(async move {
        if let Err(e) = emulator.serve(master).await {
            tracing::debug!(error = %e, "URG emulator ended");
        }
    });
    Ok((task, slave, link))
}

/// Opens the laser's pty by path, records it next to the Pioneer capture and switches the
/// laser on.
async fn connect_laser(
    spec: &RunSpec<'_>,
    link: &LinkConfig,
    clock: &SharedClock,
    mount_offset_m: f64,
) -> anyhow::Result<TrialLaser> {
    let note = format!(
        "simulated URG laser (rfloc-urg emulator) for {} trial {}; times are the emulator's simulated seconds",
        spec.scenario.spec.name, spec.trial
    );
    let (io, sink) = open_recorded(
        &laser_capture(&spec.capture),
        "hokuyo-urg",
        link,
        clock,
        &note,
    )
    .await?;
    let mut client = UrgClient::new(io, UrgConfig::default());
    client.laser_on().await.context("switching the laser on")?;
    Ok(TrialLaser {
        client,
        sink,
        mount_offset_m,
    })
}

/// Creates the trial capture `path` for `device`, opens `link` by path as the daemon opens its
/// devices, and records it into the capture (same-time chunks coalesced).
async fn open_recorded(
    path: &Path,
    device: &str,
    link: &LinkConfig,
    clock: &SharedClock,
    note: &str,
) -> anyhow::Result<(Recorder<rfloc_transport::Transport>, CaptureSink)> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let file = path
        .file_name()
        .and_then(|f| f.to_str())
        .with_context(|| format!("capture path {} has no file name", path.display()))?;
    let sink = trial_capture(dir, file, device, link, Arc::clone(clock), &[note])?;
    let io = rfloc_transport::open(link)
        .await
        .with_context(|| format!("opening {}", link.describe()))?;
    Ok((Recorder::new(io, sink.clone()), sink))
}

/// Opens the pty's slave side by path, records it (same-time chunks coalesced) and connects
/// the driver.
async fn connect(
    spec: &RunSpec<'_>,
    link: &LinkConfig,
    control: StepControl,
    handle: EmulatorHandle,
    clock: &SharedClock,
) -> anyhow::Result<(LockstepBase, CaptureSink)> {
    let note = format!(
        "simulated Pioneer (rfloc-aria emulator, lock-step) for {} trial {} ({} system); times are the emulator's simulated seconds",
        spec.scenario.spec.name,
        spec.trial,
        if spec.use_planner { "full" } else { "preliminary" }
    );
    let (io, sink) = open_recorded(&spec.capture, "pioneer-aria", link, clock, &note).await?;
    let client = AriaClient::from_stream(io, driver_config(Arc::clone(clock)))
        .await
        .context("connecting to the emulated Pioneer")?;
    Ok((
        LockstepBase::new(client, control, handle, sink.clone()),
        sink,
    ))
}

/// The fixed inputs of one run's control loop.
struct Mission<'a> {
    world: &'a rfloc_sim::World,
    start: Pose2,
    seed: u64,
    radius: f64,
    /// Goal position and tolerance (the referee's).
    goal: (Point, f64),
    emitter: Point,
}

impl Mission<'_> {
    /// The closed loop, one tick at a time, until the referee sees the goal reached, the
    /// robot has believed it arrived for [`ARRIVED_HOLD_S`], or the scenario's time is up.
    async fn drive(
        &self,
        spec: &RunSpec<'_>,
        base: &LockstepBase,
        laser: &mut TrialLaser,
    ) -> anyhow::Result<RunOutcome> {
        let scenario = spec.scenario;
        let mut sensors = SensorSuite::for_trial(scenario, spec.trial);
        // The daemon's pipeline, fed the device events a robot would send: control steps on
        // the odometry of every CONTROL_TICKS-th tick, each reading used only in its own step.
        let mut pipeline = EmitterPipeline::from_homing(
            homing_config(scenario, &self.start, spec.use_planner, self.seed)?,
            self.start,
            CONTROL_TICKS as f64 * TICK_S,
            READING_WINDOW_S,
        )
        .map_err(|e| anyhow::anyhow!("emitter pipeline: {e}"))?;
        let mut out = RunOutcome::default();
        // Commands computed at a control tick, with the tick after which they are written.
        let mut queued: VecDeque<(u64, (f64, f64))> = VecDeque::new();
        let mut arrived_since: Option<f64> = None;
        for tick in 0u64.. {
            let (odometry, state) = base.tick().await?;
            let t = tick as f64 * TICK_S;
            if tick == 0 {
                out.capture_time_at_start = state.sim_time;
            }
            // The referee: true pose of every tick, goal check.
            let truth = state.truth;
            out.truth.push((t, truth));
            if out.reached.is_none()
                && Point::new(truth.x, truth.y).distance(&self.goal.0) <= self.goal.1
            {
                out.reached = Some(t);
            }
            out.end_time = t;
            if out.reached.is_some() || t >= scenario.spec.duration_s {
                break;
            }
            while queued.front().is_some_and(|(at, _)| *at <= tick) {
                if let Some((_, (v, w))) = queued.pop_front() {
                    base.set_velocity(v, w).await?;
                }
            }
            if tick < SETTLE_TICKS {
                continue;
            }
            let control = (tick - SETTLE_TICKS).is_multiple_of(CONTROL_TICKS);
            if control {
                out.pose_estimate
                    .push((t, self.start.compose(&odometry.pose)));
                let sensed = Sensed {
                    t,
                    truth,
                    world: self.world,
                    radius: self.radius,
                    beams: laser.beams().await?,
                };
                for event in sensed.events(&mut sensors) {
                    pipeline.handle(&event);
                }
            }
            pipeline.handle(&DeviceEvent::Odometry {
                device: "base".into(),
                t,
                pose: odometry.pose,
                v: odometry.v,
                w: odometry.w,
            });
            for target in pipeline.take_targets() {
                let (est, raw) = (
                    Point::new(target.x, target.y),
                    target
                        .raw
                        .map_or(Point::new(target.x, target.y), |(x, y)| Point::new(x, y)),
                );
                out.filtered_errors.push(est.distance(&self.emitter));
                out.raw_errors.push(raw.distance(&self.emitter));
                out.final_estimate = Some(Point2::new(target.x, target.y));
                let here = Point::new(truth.x, truth.y);
                out.line_of_sight
                    .push(self.world.walls_crossed(&here, &self.emitter) == 0);
            }
            for request in pipeline.take_requests() {
                if let Request::Velocity { v, w } = request {
                    queued.push_back((tick + ACTUATION_DELAY_TICKS, (v, w)));
                }
            }
            if !control {
                continue;
            }
            if pipeline.arrived() {
                out.robot_arrived = true;
                let since_arrival = *arrived_since.get_or_insert(t);
                if t - since_arrival >= ARRIVED_HOLD_S {
                    break;
                }
            } else {
                arrived_since = None;
            }
        }
        out.plans = pipeline.homing().plan_count();
        out.rejected_rss = pipeline.homing().rejected_rss();
        out.filter_restarts = pipeline.homing().reinitialisations();
        out.bumper_steps = pipeline.counters().bumps;
        Ok(out)
    }
}

/// Receiver readings older than this are not combined: only the readings of the step's own
/// tick (the trial reads all four at once).
const READING_WINDOW_S: f64 = 0.05;

/// The sensors of one control tick, read at the emulator's true pose, and the tick's laser
/// scan.
struct Sensed<'a> {
    t: f64,
    truth: Pose2,
    world: &'a rfloc_sim::World,
    radius: f64,
    beams: Vec<ScanBeam>,
}

impl Sensed<'_> {
    /// The tick's device events in a fixed order: the four receivers (in-process models at the
    /// true pose, drawn from their own stream), the laser scan (read over its pty), the
    /// bumpers (sent every step).
    fn events(&self, sensors: &mut SensorSuite) -> Vec<DeviceEvent> {
        let (t, truth) = (self.t, self.truth);
        let rss = sensors.emitter_rss(self.world, &truth);
        // rfloc-sim orders the antennas front, left, back, right.
        let sides = [
            AntennaSide::Front,
            AntennaSide::Left,
            AntennaSide::Back,
            AntennaSide::Right,
        ];
        let mut events: Vec<DeviceEvent> = sides
            .iter()
            .zip(rss)
            .map(|(side, dbm)| DeviceEvent::EmitterRss {
                device: format!("rx-{side:?}"),
                t,
                antenna: *side,
                dbm,
            })
            .collect();
        events.push(DeviceEvent::RangeScan {
            device: "laser".into(),
            t,
            beams: self.beams.clone(),
        });
        let contact = sensors.bumpers(self.world, &truth, self.radius);
        events.push(DeviceEvent::Bumpers {
            device: "base".into(),
            t,
            front: contact.front,
            rear: contact.rear,
        });
        events
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
