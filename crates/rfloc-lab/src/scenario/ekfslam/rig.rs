//! The emulated hardware of one seed 003 trial: a Pioneer emulator and an XBee coordinator
//! emulator, each serving the master side of its own pseudo-terminal, and the real rfloc
//! drivers (`AriaClient`, `XBeeClient`) on the slave sides, opened by path through
//! `rfloc_transport::open` and recorded into the trial folder.
//!
//! The Pioneer emulator runs in lock-step (see [`crate::scenario::lockstep`]); the coordinator
//! answers an `ND` at once (no response spacing), so a whole round happens at the simulated time
//! of its request: the trial never advances the clock while a round is in flight.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

pub use crate::sim::EmulatorClock;
use anyhow::Context;
use rfloc_aria::{
    AriaClient, ClientConfig as AriaClientConfig, ConnectFuture, EmulatorConfig, RobotEmulator,
    WheelSlip,
};
use rfloc_sim::{Scenario, SensorSuite};
use rfloc_stepper::AngleProbe;
use rfloc_transport::{open, CaptureSink, Recorder, SharedClock, Transport};
use rfloc_xbee::{
    ApiMode, ClientConfig as XBeeClientConfig, CoordinatorEmulator,
    EmulatorConfig as XBeeEmulatorConfig, NdLayout, NdLayoutHint, RssiFn, XBeeClient,
};
use tokio::task::JoinHandle;

use crate::scenario::lockstep::LockstepBase;
use tokio_serial::SerialStream;

/// The XBee link's byte stream: the pty, recorded.
pub type XBeeLinkIo = Recorder<Transport>;
/// The XBee link as the bearing scan uses it.
pub type XBeeLink = XBeeClient<XBeeLinkIo>;

/// Second header note of every capture: which clock the timestamps are on.
const EMULATOR_TIME_NOTE: &str = "timestamps: simulated seconds of the Pioneer emulator";

/// Settings of the rig that are not in the scenario file.
#[derive(Debug, Clone, Copy)]
pub struct RigSettings {
    /// Relative σ of each wheel's ground speed per emulator substep (10 ms); 0 = no slip.
    pub slip_relative_std: f64,
    /// Seed of the slip generator.
    pub slip_seed: u64,
}

/// Running emulators and connected drivers of one trial.
pub struct Rig {
    pub base: Arc<LockstepBase>,
    xbee: Option<XBeeLink>,
    tasks: Vec<JoinHandle<()>>,
    /// Slave ends kept open so the masters never see a hang-up.
    _slaves: Vec<SerialStream>,
    sinks: Vec<CaptureSink>,
}

/// The Pioneer driver's settings for a lock-step emulator: no keep-alive on wall time (the
/// trial sends a command every tick; the robot's watchdog is simulated time), a link timeout
/// no step comes near (the trial has its own), timestamps on the emulator's clock.
fn aria_config(clock: SharedClock) -> AriaClientConfig {
    AriaClientConfig {
        pulse_period: Duration::from_secs(24 * 3600),
        link_timeout: Duration::from_secs(24 * 3600),
        sync_timeout: Duration::from_secs(5),
        close_linger: Duration::from_millis(100),
        clock: Some(clock),
        ..AriaClientConfig::default()
    }
}

impl Rig {
    /// Starts both emulators on ptys and connects the drivers through the pty paths.
    /// `sensors` feeds the coordinator's RSSI from the robot's true pose and `antenna`'s angle.
    pub async fn start(
        scenario: &Scenario,
        trial: usize,
        dir: &Path,
        settings: RigSettings,
        sensors: Arc<Mutex<SensorSuite>>,
        antenna: AngleProbe,
    ) -> anyhow::Result<Rig> {
        let mut tasks = Vec::new();
        let mut slaves = Vec::new();

        // Pioneer base.
        let (master, slave, base_link) = crate::sim::pty_link(9600)?;
        let mut emulator = RobotEmulator::new(EmulatorConfig {
            initial_pose: scenario.start_pose(trial),
            slip: (settings.slip_relative_std > 0.0).then_some(WheelSlip {
                seed: settings.slip_seed,
                relative_std: settings.slip_relative_std,
            }),
            noise_seed: scenario.trial_seed(trial),
            ..EmulatorConfig::default()
        })
        .with_motion_hook(crate::sim::walls::wall_hook(
            Arc::new(scenario.world.clone()),
            scenario.spec.robot.drive.body_radius,
        ));
        let control = emulator.lock_step();
        let robot = emulator.handle();
        tasks.push(tokio::spawn(async move {
            let mut emulator = emulator;
            if let Err(e) = emulator.serve(master).await {
                tracing::warn!(error = %e, "robot emulator ended");
            }
        }));
        slaves.push(slave);
        let clock: SharedClock = Arc::new(EmulatorClock(robot.clone()));
        let base_sink = crate::sim::trial_capture(
            dir,
            "pioneer.cap",
            "pioneer-aria",
            &base_link,
            Arc::clone(&clock),
            &[
                format!("seed003 trial {trial}: emulated Pioneer on a pty").as_str(),
                EMULATOR_TIME_NOTE,
            ],
        )?;

        // XBee coordinator in the reflector.
        let (master, slave, xbee_link) = crate::sim::pty_link(115_200)?;
        let beacons = crate::sim::xbee_beacons(&scenario.world);
        let world = scenario.world.clone();
        let truth = robot.clone();
        let rssi: RssiFn = Arc::new(move |index| {
            let pose = truth.truth();
            let mut s = sensors.lock().ok()?;
            s.xbee_rssi(&world, &pose, antenna.get(), index)
        });
        let coordinator = CoordinatorEmulator::new(
            beacons,
            rssi,
            XBeeEmulatorConfig {
                mode: ApiMode::Escaped,
                nd_layout: NdLayout::ZigbeeOrDigiMesh,
                append_rssi: true,
                response_spacing: Duration::ZERO,
                ..XBeeEmulatorConfig::default()
            },
        );
        tasks.push(tokio::spawn(async move {
            if let Err(e) = coordinator.serve(master).await {
                tracing::warn!(error = %e, "XBee coordinator emulator ended");
            }
        }));
        slaves.push(slave);
        let xbee_sink = crate::sim::trial_capture(
            dir,
            "xbee.cap",
            "xbee-api2",
            &xbee_link,
            Arc::clone(&clock),
            &[
                format!("seed003 trial {trial}: emulated XBee coordinator on a pty").as_str(),
                EMULATOR_TIME_NOTE,
            ],
        )?;

        // Drivers, opened by path as the daemon opens its devices.
        let connector_sink = base_sink.clone();
        let connector_link = base_link.clone();
        let base = AriaClient::connect(
            move || -> ConnectFuture<Recorder<Transport>> {
                let link = connector_link.clone();
                let sink = connector_sink.clone();
                Box::pin(async move {
                    let io = open(&link).await.map_err(std::io::Error::other)?;
                    Ok(Recorder::new(io, sink))
                })
            },
            aria_config(Arc::clone(&clock)),
        )
        .await
        .context("connecting to the emulated Pioneer")?;
        let base = Arc::new(LockstepBase::new(base, control, robot, base_sink.clone()));
        let xio = open(&xbee_link).await.context("opening the XBee pty")?;
        let xbee = XBeeClient::new(
            Recorder::new(xio, xbee_sink.clone()),
            XBeeClientConfig {
                mode: ApiMode::Escaped,
                nd_layout: NdLayoutHint::ZigbeeOrDigiMesh,
                response_timeout: Duration::from_millis(500),
                discovery_margin: Duration::from_millis(500),
                ..XBeeClientConfig::default()
            },
        );
        Ok(Rig {
            base,
            xbee: Some(xbee),
            tasks,
            _slaves: slaves,
            sinks: vec![base_sink, xbee_sink],
        })
    }

    /// Hands the XBee driver over (to the bearing scan); `None` the second time.
    pub fn take_xbee(&mut self) -> Option<XBeeLink> {
        self.xbee.take()
    }

    /// Stops the base, closes the drivers, stops the emulators and flushes the captures. Every
    /// other holder of [`Rig::base`] must be gone by then (else the driver is only dropped).
    pub async fn shutdown(self) {
        let Rig {
            base,
            xbee,
            tasks,
            sinks,
            ..
        } = self;
        match Arc::try_unwrap(base) {
            Ok(base) => base.shutdown().await,
            Err(_) => tracing::warn!("Pioneer driver still shared at shutdown; dropped"),
        }
        drop(xbee);
        for t in tasks {
            t.abort();
        }
        for s in sinks {
            if let Err(e) = s.flush() {
                tracing::warn!(error = %e, "flushing a capture");
            }
        }
    }
}
