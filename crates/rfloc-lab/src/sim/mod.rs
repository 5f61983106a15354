//! Simulation inside `rfloc run`: emulated devices on real pseudo-terminals, a motion script.
//!
//! Each serial device of a simulation config gets a pty pair: the emulator serves the master
//! side and the device's `link` is set to the slave's path, so the daemon opens it through the
//! same `open()` as on a robot. The HF reader's antenna follows the emulated robot's true pose.

use std::f64::consts::PI;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use rfloc_aria::{EmulatorConfig as RobotEmulatorConfig, EmulatorHandle, RobotEmulator};
use rfloc_kts::{EmulatorConfig as KtsEmulatorConfig, KtsEmulator, TagGrid};
use rfloc_pose::Pose2;
use rfloc_transport::{LinkConfig, SerialLink};
use tokio::task::JoinHandle;
use tokio_serial::{SerialPort, SerialStream};
use tokio_util::sync::CancellationToken;

use std::sync::Mutex;

use rfloc_aria::WheelSlip;
use rfloc_stepper::{SimulatedStepper, StepperConfig};
use rfloc_xbee::{
    Address16, Address64, Beacon, CoordinatorEmulator, EmulatorConfig as XBeeEmulatorConfig,
    NdLayout, RssiFn,
};

use rfloc_daemon::config::{AntennaSide, EstimatorConfig, RobotConfig, XbeeRole};
use rfloc_daemon::devices::{aria::Aria, stepper::Stepper, urg::Urg, xbee::Xbee};
use rfloc_daemon::events::{DeviceEvent, ScanBeam};
use rfloc_daemon::pipeline::Request;
use rfloc_daemon::simulation::{BoxFuture, Simulation, SimulationIo};

mod config;
pub(crate) mod walls;
pub use config::{SimulationConfig, SimulationSection};

/// The Pioneer emulator's simulated clock (seconds), for driver timestamps and captures in
/// simulated trials: times then line up with the emulator, not with wall time.
#[derive(Debug, Clone)]
pub struct EmulatorClock(pub EmulatorHandle);

impl rfloc_transport::Clock for EmulatorClock {
    fn now(&self) -> f64 {
        self.0.state().sim_time
    }
}

/// Creates the capture of one device link of a simulated trial (`dir/file`), with the link's
/// description and the given notes in its header. Same-time reads (writes) are coalesced into
/// one record, so a lock-step trial's capture does not depend on how the pty chunked bytes.
pub fn trial_capture(
    dir: &std::path::Path,
    file: &str,
    device: &str,
    link: &LinkConfig,
    clock: rfloc_transport::SharedClock,
    notes: &[&str],
) -> anyhow::Result<rfloc_transport::CaptureSink> {
    trial_capture_described(dir, file, device, &link.describe(), clock, notes)
}

/// As [`trial_capture`], with the link described by `link` (for links whose address changes
/// from run to run, such as an emulator's ephemeral loopback port).
pub fn trial_capture_described(
    dir: &std::path::Path,
    file: &str,
    device: &str,
    link: &str,
    clock: rfloc_transport::SharedClock,
    notes: &[&str],
) -> anyhow::Result<rfloc_transport::CaptureSink> {
    let mut header = rfloc_capture::Header::new(device, link.to_string());
    header.notes.extend(notes.iter().map(|n| (*n).to_string()));
    let path = dir.join(file);
    let sink = rfloc_transport::CaptureSink::create(&path, &header, clock)
        .with_context(|| format!("creating capture {}", path.display()))?;
    sink.set_coalescing(true);
    Ok(sink)
}

/// Running emulators of one simulation.
pub struct SimRuntime {
    /// Cancels the emulators; separate from the daemon's token so that device tasks can still
    /// stop the robot while shutting down.
    emulators: CancellationToken,
    base: Option<EmulatorHandle>,
    tasks: Vec<JoinHandle<()>>,
    /// Slave ends kept open so the masters never see a hang-up between daemon reconnects.
    _slaves: Vec<SerialStream>,
    config: SimulationConfig,
    /// The rotator the emulated XBee radio's RSSI follows, until the daemon takes it.
    stepper: Option<SimulatedStepper>,
    /// Published estimates against the truth, scored on the estimator thread.
    scores: Arc<Mutex<Scores>>,
    start: Pose2,
    /// The emitter scenario's sensor models and world (receivers, laser), when it has one.
    sensors: Option<(Arc<Mutex<rfloc_sim::SensorSuite>>, Arc<rfloc_sim::World>)>,
    /// A device on a wire measures ranges (the base's sonar, a URG laser), so no in-process
    /// laser is needed.
    ranges_on_wire: bool,
}

/// What the scorer keeps: the estimates and the robot's own odometry (dead reckoning from the
/// start pose, the baseline an estimator has to beat) against the truth, and the scenario
/// goal (position, tolerance) with the time the true pose first came within it: the referee's
/// time, not the robot's belief.
#[derive(Debug, Default)]
struct Scores {
    score: TruthScore,
    dead_reckoning: TruthScore,
    goal: Option<(rfloc_sim::Point, f64)>,
    goal_reached: Option<f64>,
}

/// Published poses scored against the emulated robot's true pose.
#[derive(Debug, Default, Clone, Copy)]
pub struct TruthScore {
    /// Poses scored.
    pub poses: u64,
    sum_sq: f64,
    /// Largest position error, metres.
    pub max_m: f64,
    /// Position error of the last pose, metres.
    pub last_m: f64,
    sum_sq_heading: f64,
}

impl TruthScore {
    /// Root mean square position error, metres.
    #[must_use]
    pub fn rms_m(&self) -> f64 {
        if self.poses == 0 {
            return f64::NAN;
        }
        (self.sum_sq / self.poses as f64).sqrt()
    }

    /// Root mean square heading error, radians.
    #[must_use]
    pub fn rms_heading_rad(&self) -> f64 {
        if self.poses == 0 {
            return f64::NAN;
        }
        (self.sum_sq_heading / self.poses as f64).sqrt()
    }

    fn add(&mut self, estimate: &Pose2, truth: &Pose2) {
        let e = estimate.distance(truth);
        let h = rfloc_pose::angle_diff(estimate.theta, truth.theta);
        self.poses += 1;
        self.sum_sq += e * e;
        self.sum_sq_heading += h * h;
        self.max_m = self.max_m.max(e);
        self.last_m = e;
    }
}

impl SimRuntime {
    /// The emulated robot's true pose, if there is a base.
    #[must_use]
    pub fn truth(&self) -> Option<Pose2> {
        self.base.as_ref().map(EmulatorHandle::truth)
    }

    /// The emulated robot's simulated clock, if there is a base.
    #[must_use]
    pub fn clock(&self) -> Option<rfloc_transport::SharedClock> {
        self.base
            .clone()
            .map(|b| Arc::new(EmulatorClock(b)) as rfloc_transport::SharedClock)
    }

    /// The simulated antenna stepper (once): the XBee device task turns it, the emulated radio
    /// reads its angle.
    pub fn take_stepper(&mut self) -> Option<SimulatedStepper> {
        self.stepper.take()
    }

    /// Stops the emulators.
    pub async fn stop(self) {
        if let Some(t) = self.truth() {
            tracing::info!(
                x = t.x,
                y = t.y,
                theta = t.theta,
                "simulated robot final true pose"
            );
        }
        let (s, d) = self
            .scores
            .lock()
            .map_or((TruthScore::default(), TruthScore::default()), |sc| {
                (sc.score, sc.dead_reckoning)
            });
        if s.poses > 0 {
            tracing::info!(
                poses = s.poses,
                rms_m = s.rms_m(),
                max_m = s.max_m,
                last_m = s.last_m,
                rms_heading_deg = s.rms_heading_rad().to_degrees(),
                odometry_rms_m = d.rms_m(),
                odometry_last_m = d.last_m,
                odometry_rms_heading_deg = d.rms_heading_rad().to_degrees(),
                "simulation: published poses against the true pose"
            );
        }
        self.emulators.cancel();
        for t in self.tasks {
            let _ = tokio::time::timeout(std::time::Duration::from_secs(1), t).await;
        }
    }
}

impl SimRuntime {
    /// Runs an emulator's serve future until it ends or the simulation stops; an error it
    /// ends with is logged as `what`.
    fn serve_until_stopped<F, T, E>(&mut self, what: &'static str, serve: F)
    where
        F: std::future::Future<Output = Result<T, E>> + Send + 'static,
        E: std::fmt::Display,
    {
        let stop = self.emulators.clone();
        self.tasks.push(tokio::spawn(async move {
            tokio::select! {
                () = stop.cancelled() => {}
                r = serve => if let Err(e) = r { tracing::warn!(error = %e, "{what}") },
            }
        }));
    }
}

pub(crate) fn pty_link(baud: u32) -> anyhow::Result<(SerialStream, SerialStream, LinkConfig)> {
    let (master, slave) = SerialStream::pair().context("creating a pseudo-terminal pair")?;
    let path = slave.name().context("pseudo-terminal has no name")?;
    let link = LinkConfig::Serial(SerialLink {
        path,
        baud,
        data_bits: Default::default(),
        parity: Default::default(),
        stop_bits: Default::default(),
        flow_control: Default::default(),
    });
    Ok((master, slave, link))
}

/// Starts an emulator for every device and points the device links at them.
/// `config_dir` is the folder of the robot file (the scenario path is relative to it).
pub async fn start(cfg: &mut RobotConfig) -> anyhow::Result<SimRuntime> {
    let sim = &SimulationConfig::of(cfg)?;
    let config_dir = cfg.source.dir.clone();
    let config_dir = config_dir.as_deref();
    let emulators = CancellationToken::new();
    let mut runtime = SimRuntime {
        emulators: emulators.clone(),
        base: None,
        tasks: Vec::new(),
        _slaves: Vec::new(),
        config: sim.clone(),
        stepper: None,
        scores: Arc::default(),
        start: Pose2::new(sim.start[0], sim.start[1], sim.start[2].to_radians()),
        sensors: None,
        ranges_on_wire: cfg.devices.iter().any(|d| {
            d.driver.settings::<Aria>().is_some_and(|a| a.sonar) || d.driver.kind() == "urg"
        }),
    };
    let start = Pose2::new(sim.start[0], sim.start[1], sim.start[2].to_radians());
    let scenario = match &sim.scenario {
        Some(p) => {
            let path = config_dir.map_or_else(|| p.clone(), |d| d.join(p));
            Some(
                rfloc_sim::Scenario::load(&path)
                    .with_context(|| format!("loading {}", path.display()))?,
            )
        }
        None => None,
    };
    // A snapshot scenario's robot: the base its survey was driven with, walled in by its world.
    let snapshot_world = scenario
        .as_ref()
        .filter(|s| s.spec.pipeline == rfloc_sim::scenario::Pipeline::Snapshot);
    // An emitter scenario's robot: a slip-free base (the seed takes odometry as its pose),
    // walled in by its world.
    let emitter_world = scenario.as_ref().filter(|s| s.world.emitter.is_some());
    let antenna_offset = match &cfg.estimator {
        EstimatorConfig::Hfgrid(h) => h.antenna_offset_m,
        _ => 0.10,
    };
    // The base first: other emulators follow its true pose.
    for device in cfg.devices.iter_mut().filter(|d| d.driver.kind() == "aria") {
        let (master, slave, link) = pty_link(9600)?;
        let emulator = match snapshot_world {
            Some(sc) => RobotEmulator::new(RobotEmulatorConfig {
                time_scale: sim.time_scale,
                initial_pose: start,
                ..crate::scenario::snapshot::rig::robot_config(sim.seed, sim.slip_sigma)
            })
            .with_motion_hook(walls::wall_hook(
                Arc::new(sc.world.clone()),
                sc.spec.robot.drive.body_radius,
            )),
            None if emitter_world.is_some() => {
                let sc = emitter_world.context("emitter world")?;
                let world = Arc::new(sc.world.clone());
                RobotEmulator::new(RobotEmulatorConfig {
                    time_scale: sim.time_scale,
                    initial_pose: start,
                    noise_seed: sim.seed,
                    slip: None,
                    ..RobotEmulatorConfig::default()
                })
                .with_motion_hook(walls::wall_hook(
                    Arc::clone(&world),
                    sc.spec.robot.drive.body_radius,
                ))
                .with_sonar_hook(walls::sonar_hook(world))
            }
            None => RobotEmulator::new(RobotEmulatorConfig {
                time_scale: sim.time_scale,
                initial_pose: start,
                noise_seed: sim.seed,
                slip: (sim.slip_sigma > 0.0).then_some(WheelSlip {
                    seed: sim.seed ^ 0x5119,
                    relative_std: sim.slip_sigma,
                }),
                ..RobotEmulatorConfig::default()
            }),
        };
        runtime.base = Some(emulator.handle());
        runtime.serve_until_stopped("robot emulator ended", async move {
            let mut emulator = emulator;
            emulator.serve(master).await
        });
        tracing::info!(device = %device.name, link = %link.describe(), "emulated Pioneer on a pty");
        device.link = Some(link);
        runtime._slaves.push(slave);
    }
    for device in cfg.devices.iter_mut().filter(|d| d.driver.kind() == "kts") {
        let (master, slave, link) = pty_link(115_200)?;
        let base = runtime.base.clone();
        // Antenna behind the robot centre (seed 002: 10 cm), following the true pose.
        let antenna = Arc::new(move || {
            let p = base.as_ref().map_or(start, EmulatorHandle::truth);
            p.transform_point(-antenna_offset, 0.0)
        });
        let mut kcfg = KtsEmulatorConfig::new(TagGrid::seed002_test_field(), antenna);
        kcfg.time_scale = sim.time_scale;
        kcfg.seed = sim.seed;
        kcfg.miss_probability = 0.1;
        let mut emulator = KtsEmulator::new(kcfg);
        runtime.serve_until_stopped("HF reader emulator ended", async move {
            emulator.serve(master).await
        });
        tracing::info!(device = %device.name, link = %link.describe(), "emulated KTS reader on a pty");
        device.link = Some(link);
        runtime._slaves.push(slave);
    }
    let role_of =
        |d: &rfloc_daemon::config::DeviceConfig| d.driver.settings::<Xbee>().map(|x| x.role);
    if cfg
        .devices
        .iter()
        .any(|d| role_of(d) == Some(XbeeRole::EmitterReceiver))
    {
        let scenario = scenario
            .as_ref()
            .filter(|s| s.world.emitter.is_some())
            .context("emulated emitter receivers need [simulation] scenario with an emitter")?;
        start_emitter_receivers(cfg, scenario, start, &mut runtime)?;
        let trial = usize::try_from(sim.seed).unwrap_or(0);
        if let Ok(mut sc) = runtime.scores.lock() {
            sc.goal = scenario
                .goal(trial)
                .zip(scenario.spec.goal.map(|g| g.tolerance_m));
        }
    }
    let has_xbee = cfg
        .devices
        .iter()
        .any(|d| role_of(d) == Some(XbeeRole::Sweep));
    if has_xbee {
        let scenario = scenario
            .as_ref()
            .context("an emulated XBee radio needs [simulation] scenario")?;
        start_xbee(cfg, scenario, start, &mut runtime)?;
    }
    for device in cfg
        .devices
        .iter_mut()
        .filter(|d| d.driver.kind() == "alien")
    {
        let scenario = scenario
            .as_ref()
            .context("an emulated Alien reader needs [simulation] scenario (its UHF tags)")?;
        let base = runtime
            .base
            .clone()
            .context("an emulated Alien reader needs an emulated base (its pose)")?;
        let field = crate::scenario::snapshot::rig::uhf_field(
            rfloc_sim::SensorSuite::for_trial(scenario, 0),
            Arc::new(scenario.world.clone()),
            base,
            Arc::new(Mutex::new(0)),
        );
        let emulator =
            rfloc_alien::ReaderEmulator::new(field, rfloc_alien::EmulatorOptions::default());
        let (addr, task) = emulator
            .bind_loopback()
            .await
            .context("binding the Alien reader emulator")?;
        runtime.tasks.push(tokio::spawn(async move {
            if let Ok(Err(e)) = task.await {
                tracing::warn!(error = %e, "Alien reader emulator ended");
            }
        }));
        let link = LinkConfig::Tcp(rfloc_transport::TcpLink {
            address: addr.to_string(),
            connect_timeout: 5.0,
        });
        tracing::info!(device = %device.name, link = %link.describe(), "emulated Alien reader on loopback TCP");
        device.link = Some(link);
    }
    for device in cfg.devices.iter_mut().filter(|d| d.driver.kind() == "urg") {
        let Some(settings) = device.driver.settings::<Urg>().cloned() else {
            continue;
        };
        let world = scenario
            .as_ref()
            .map(|s| Arc::new(s.world.clone()))
            .context("an emulated laser needs [simulation] scenario (its walls)")?;
        let base = runtime
            .base
            .clone()
            .context("an emulated laser needs an emulated base (its pose)")?;
        let offset = settings.mount_offset_m;
        let reach = f64::from(rfloc_urg::UrgGeometry::default().max_mm) / 1000.0;
        // The scanner model's range noise (σ = 0.01 m, the URG-04LX data sheet), seeded.
        let sigma = rfloc_sim::scanner::RangeScanner::default().noise_sigma;
        let rng = Mutex::new(
            <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(sim.seed ^ 0x5552_4721),
        );
        let ranges: rfloc_urg::RangeFn = Arc::new(move |angle| {
            let p = base.truth();
            let (x, y) = p.transform_point(offset, 0.0);
            let d = world
                .ray_cast(&rfloc_sim::Point::new(x, y), p.theta + angle)
                .filter(|d| *d <= reach)?;
            let noise = rng
                .lock()
                .map_or(0.0, |mut r| rfloc_sim::noise::gaussian(&mut *r, sigma));
            Some((d + noise).max(0.0))
        });
        let clock = runtime.clock();
        let emulator = rfloc_urg::UrgEmulator::new(
            ranges,
            rfloc_urg::EmulatorConfig {
                clock: clock.map(|c| Arc::new(move || c.now()) as rfloc_urg::ClockFn),
                ..rfloc_urg::EmulatorConfig::default()
            },
        );
        let (master, slave, link) = pty_link(115_200)?;
        runtime.serve_until_stopped("URG laser emulator ended", async move {
            emulator.serve(master).await
        });
        tracing::info!(device = %device.name, link = %link.describe(), "emulated URG laser on a pty");
        device.link = Some(link);
        runtime._slaves.push(slave);
    }
    for device in &cfg.devices {
        if device.driver.kind() == "stepper" {
            // Pin-less: the simulated stepper stands in for the GPIO lines.
            continue;
        }
        if device.link.is_none() {
            anyhow::bail!(
                "simulation has no emulator for device {:?} (driver {})",
                device.name,
                device.driver.kind()
            );
        }
    }
    Ok(runtime)
}

/// The XBee radios of a simulated world as the coordinator emulator's beacons (16-bit network
/// addresses 0x1000, 0x1001, … in world order).
pub(crate) fn xbee_beacons(world: &rfloc_sim::World) -> Vec<Beacon> {
    world
        .beacons
        .iter()
        .enumerate()
        .map(|(i, b)| Beacon {
            address: Address64(b.address),
            network_address: Address16(0x1000_u16.wrapping_add(u16::try_from(i).unwrap_or(0))),
            ni: b.ni.clone(),
        })
        .collect()
}

/// The emulated XBee coordinator in its turning reflector: beacons, path loss, shadowing and
/// the reflector's gain pattern from the simulation's scenario file, the antenna angle from a
/// simulated stepper that the daemon's XBee task turns.
fn start_xbee(
    cfg: &mut RobotConfig,
    scenario: &rfloc_sim::Scenario,
    start: Pose2,
    runtime: &mut SimRuntime,
) -> anyhow::Result<()> {
    let world = scenario.world.clone();
    let stepper_settings = cfg
        .devices
        .iter()
        .find_map(|d| d.driver.settings::<Stepper>().cloned());
    let stepper_config = stepper_settings.map_or_else(StepperConfig::default, |s| StepperConfig {
        full_steps_per_rev: s.steps_per_rev,
        microsteps: s.microsteps,
        gear_ratio: s.gear_ratio,
        ..StepperConfig::default()
    });
    let stepper = SimulatedStepper::new(&stepper_config)
        .map_err(|e| anyhow::anyhow!("simulated stepper: {e}"))?;
    let antenna = stepper.angle_probe();
    runtime.stepper = Some(stepper);
    let sensors = Arc::new(Mutex::new((
        rfloc_sim::SensorSuite::for_trial(scenario, 0),
        None::<Pose2>,
    )));
    for device in cfg.devices.iter_mut() {
        let Some(x) = device.driver.settings::<Xbee>().cloned() else {
            continue;
        };
        if x.role != XbeeRole::Sweep {
            continue;
        }
        let mode = x.mode();
        let beacons = xbee_beacons(&world);
        let base = runtime.base.clone();
        let world = world.clone();
        let sensors = Arc::clone(&sensors);
        let antenna = antenna.clone();
        let rssi: RssiFn = Arc::new(move |index| {
            let pose = base.as_ref().map_or(start, EmulatorHandle::truth);
            let mut guard = sensors.lock().ok()?;
            let (suite, drawn_at) = &mut *guard;
            // Shadowing holds while the robot stands (one sweep); moving on draws anew.
            if drawn_at.is_none_or(|p: Pose2| p.distance(&pose) > 0.01) {
                suite.begin_xbee_sweep();
                *drawn_at = Some(pose);
            }
            suite.xbee_rssi(&world, &pose, antenna.get(), index)
        });
        let (master, slave, link) = pty_link(115_200)?;
        let emulator = CoordinatorEmulator::new(
            beacons,
            rssi,
            XBeeEmulatorConfig {
                mode,
                nd_layout: NdLayout::ZigbeeOrDigiMesh,
                append_rssi: true,
                response_spacing: Duration::from_millis(1),
                ..XBeeEmulatorConfig::default()
            },
        );
        runtime.serve_until_stopped("XBee emulator ended", async move {
            emulator.serve(master).await
        });
        tracing::info!(device = %device.name, link = %link.describe(), scenario = %scenario.spec.name, beacons = scenario.world.beacons.len(), "emulated XBee coordinator on a pty");
        device.link = Some(link);
        runtime._slaves.push(slave);
    }
    Ok(())
}

/// The seed-001 receivers: one emulated XBee per reflector, each knowing one node (the emitter,
/// at the address of the receiver's settings). Its RSSI is the scenario's emitter model for
/// that reflector at the emulated robot's true pose (shadowing, fading and walls included),
/// quantised to whole dB by the `DB` byte.
fn start_emitter_receivers(
    cfg: &mut RobotConfig,
    scenario: &rfloc_sim::Scenario,
    start: Pose2,
    runtime: &mut SimRuntime,
) -> anyhow::Result<()> {
    let world = Arc::new(scenario.world.clone());
    // The simulation's seed picks the scenario trial whose sensor streams (shadowing, fading,
    // laser noise) the receivers and the laser draw from.
    let trial = usize::try_from(runtime.config.seed).unwrap_or(0);
    let sensors = Arc::new(Mutex::new(rfloc_sim::SensorSuite::for_trial(
        scenario, trial,
    )));
    runtime.sensors = Some((Arc::clone(&sensors), Arc::clone(&world)));
    for device in cfg.devices.iter_mut() {
        let Some(x) = device.driver.settings::<Xbee>().cloned() else {
            continue;
        };
        if x.role != XbeeRole::EmitterReceiver {
            continue;
        }
        let (Some(side), Some(address)) = (x.antenna, x.emitter_address()) else {
            anyhow::bail!(
                "emitter receiver {:?} needs antenna and emitter",
                device.name
            );
        };
        // rfloc-sim orders the reflectors front, left, back, right.
        let index = match side {
            AntennaSide::Front => 0,
            AntennaSide::Left => 1,
            AntennaSide::Back => 2,
            AntennaSide::Right => 3,
        };
        let mode = x.mode();
        let base = runtime.base.clone();
        let (world, sensors) = (Arc::clone(&world), Arc::clone(&sensors));
        let rssi: RssiFn = Arc::new(move |_| {
            let pose = base.as_ref().map_or(start, EmulatorHandle::truth);
            let mut suite = sensors.lock().ok()?;
            suite
                .emitter_rss(&world, &pose)
                .get(index)
                .copied()
                .flatten()
        });
        let emitter = Beacon {
            address: Address64(address),
            network_address: Address16(0x2000),
            ni: "emitter".into(),
        };
        let (master, slave, link) = pty_link(115_200)?;
        let emulator = CoordinatorEmulator::new(
            vec![emitter],
            rssi,
            XBeeEmulatorConfig {
                mode,
                ..XBeeEmulatorConfig::default()
            },
        );
        runtime.serve_until_stopped("XBee emulator ended", async move {
            emulator.serve(master).await
        });
        tracing::info!(device = %device.name, antenna = ?side, link = %link.describe(), "emulated emitter receiver on a pty");
        device.link = Some(link);
        runtime._slaves.push(slave);
    }
    Ok(())
}

impl SimRuntime {
    /// The simulated laser range finder of an emitter scenario (seed 001 gives it no wire
    /// protocol, nor does rfloc): every `period_s` simulated seconds one scan of the scenario's
    /// scanner model at the emulated robot's true pose, sent as a [`DeviceEvent::RangeScan`]
    /// from device `laser`. Does nothing without emitter receivers or a base.
    pub fn spawn_laser(
        &mut self,
        events: tokio::sync::mpsc::Sender<DeviceEvent>,
        period_s: f64,
        stop: CancellationToken,
    ) {
        if self.ranges_on_wire {
            tracing::info!("a range sensor on a link maps obstacles; no in-process laser");
            return;
        }
        let (Some((sensors, world)), Some(base)) = (self.sensors.clone(), self.base.clone()) else {
            return;
        };
        let wall = rfloc_daemon::time::seconds(period_s / self.config.time_scale.max(1e-6));
        tracing::info!(
            period_s,
            "simulated laser range finder (in-process, no wire protocol)"
        );
        self.tasks.push(tokio::spawn(async move {
            let mut ticker = tokio::time::interval(wall);
            ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tokio::select! {
                    () = stop.cancelled() => return,
                    _ = ticker.tick() => {}
                }
                let state = base.state();
                let beams: Vec<ScanBeam> = {
                    let Ok(mut suite) = sensors.lock() else {
                        return;
                    };
                    let max_range = suite.scanner.max_range;
                    suite
                        .laser_scan(&world, &state.truth)
                        .into_iter()
                        .map(|b| ScanBeam {
                            angle_rad: b.angle,
                            range_m: if b.hit { b.range } else { max_range },
                            max_range_m: max_range,
                        })
                        .collect()
                };
                let event = DeviceEvent::RangeScan {
                    device: "laser".into(),
                    t: state.sim_time,
                    beams,
                };
                if events.send(event).await.is_err() {
                    return;
                }
            }
        }));
    }
}

/// Drives the base through the configured motion script (in simulated time).
fn drive(
    config: &SimulationConfig,
    base: tokio::sync::mpsc::Sender<Request>,
    stop: CancellationToken,
) {
    let scale = config.time_scale.max(1e-6);
    let motion = config.motion.clone();
    tokio::spawn(async move {
        let wall = |sim_s: f64| rfloc_daemon::time::seconds(sim_s / scale);
        let send = |v: f64, w: f64| {
            let base = base.clone();
            async move {
                let _ = base.send(Request::Velocity { v, w }).await;
            }
        };
        // Let the devices connect.
        tokio::select! { () = stop.cancelled() => return, () = tokio::time::sleep(wall(2.0)) => {} }
        let steps: Vec<(f64, f64, f64)> = match motion.as_str() {
            // Eight 45° turns with a pause at each stop, as seed 002's initialisation.
            "turn" => (0..8)
                .flat_map(|_| [(0.0, PI / 8.0, 2.0), (0.0, 0.0, 1.0)])
                .collect(),
            "square" => (0..4)
                .flat_map(|_| [(0.2, 0.0, 5.0), (0.0, PI / 8.0, 4.0)])
                .collect(),
            _ => Vec::new(),
        };
        for (v, w, secs) in steps {
            // Re-send every simulated 0.5 s so the robot's watchdog stays fed.
            let mut left = secs;
            while left > 1e-9 {
                send(v, w).await;
                let dt = left.min(0.5);
                tokio::select! { () = stop.cancelled() => return, () = tokio::time::sleep(wall(dt)) => {} }
                left -= dt;
            }
        }
        send(0.0, 0.0).await;
    });
}

impl Simulation for SimRuntime {
    fn time_scale(&self) -> f64 {
        self.config.time_scale
    }

    fn duration_s(&self) -> Option<f64> {
        self.config.duration_s
    }

    fn clock(&self) -> Option<rfloc_transport::SharedClock> {
        SimRuntime::clock(self)
    }

    fn take_antenna(&mut self) -> Option<rfloc_daemon::devices::AntennaSource> {
        self.take_stepper()
            .map(rfloc_daemon::devices::AntennaSource::Simulated)
    }

    fn started(&mut self, io: SimulationIo<'_>) {
        if let EstimatorConfig::Emitter(e) = io.estimator {
            self.spawn_laser(io.events.clone(), e.control_period_s, io.stop.clone());
        }
        if let Some(base) = io.base {
            if io.pipeline_drives_base {
                tracing::info!("the pipeline drives the simulated base; no motion script");
            } else {
                drive(&self.config, base, io.stop);
            }
        }
    }

    fn scorer(&self) -> Option<rfloc_daemon::simulation::Scorer> {
        let base = self.base.clone()?;
        let scores = Arc::clone(&self.scores);
        let start = self.start;
        Some(Box::new(move |estimate| {
            if let Ok(mut s) = scores.lock() {
                score(&mut s, &base, start, estimate);
            }
        }))
    }

    fn shutdown(self: Box<Self>) -> BoxFuture<'static, ()> {
        Box::pin((*self).stop())
    }
}

/// Scores a published estimate against the true pose at the estimate's time (estimate times
/// are the emulator's simulated seconds). The truth is read now and carried back to the
/// estimate's time with the robot's current speeds (the gap is the estimator's lag, normally
/// under one 100 ms SIP period).
fn score(s: &mut Scores, base: &EmulatorHandle, start: Pose2, estimate: &rfloc_pose::PoseEstimate) {
    if estimate.mode == rfloc_pose::EstimateMode::NoFix {
        return;
    }
    let state = base.state();
    if let (Some((goal, tolerance)), None) = (s.goal, s.goal_reached) {
        let here = rfloc_sim::Point::new(state.truth.x, state.truth.y);
        if here.distance(&goal) <= tolerance {
            s.goal_reached = Some(state.sim_time);
            tracing::info!(
                t = state.sim_time,
                x = state.truth.x,
                y = state.truth.y,
                tolerance_m = tolerance,
                "simulation: scenario goal reached (true pose)"
            );
        }
    }
    let lag = (state.sim_time - estimate.time).clamp(0.0, 1.0);
    let back = Pose2::new(-state.v * lag, 0.0, -state.w * lag);
    let truth = state.truth.compose(&back);
    if truth.is_finite() && estimate.pose.is_finite() {
        s.score.add(&estimate.pose, &truth);
        let odometry = start.compose(&state.odometry);
        s.dead_reckoning.add(&odometry, &state.truth);
    }
}
