//! Simulated trials of the hf-init scenarios (seed 002: HF floor grid, initial pose from a
//! 360° turn on the spot), end to end through rfloc's drivers over real pseudo-terminals.
//!
//! Per trial:
//! - a Pioneer emulator and a KTS RFIDM1356 emulator serve the master sides of two ptys; the
//!   `AriaClient` and `KtsClient` open the slave sides by path through `rfloc_transport::open`,
//!   wrapped in `Recorder`s writing `pioneer.cap` and `kts.cap` into the trial folder;
//! - the reader's antenna sits `[sensors] hf.antenna_offset` behind the robot centre and
//!   follows the emulator's true pose; the tag field is the scenario world's HF grid, each tag
//!   displaced by the model's placement error (`hf.placement_sigma_m`, drawn per trial), and
//!   the KTS emulator reports each tag in range with the simulator's RSSI model (`hf.curve`
//!   with `hf.spread_levels` of Gaussian spread before rounding) and misses it with
//!   `hf.miss_probability`;
//! - the estimator does not share that model: the daemon's pipeline localises with its own
//!   RSSI table (seed 002's emulator bands, `rfloc_hfgrid::RssiModel`), the tags' grid
//!   positions and the antenna offset as an operator would configure them (a `[mismatch]
//!   scale` multiplies the table's distances);
//! - the robot turns on the spot in `params.readings_per_turn` equal steps (default 8 × 45°) at
//!   the scenario's turn rate with a short pause at each stop (as the seed), driven through the
//!   real client (RVEL commands); the reader scans every 100 ms tick throughout;
//! - the daemon's own [`HfGridPipeline`] consumes the drivers' odometry and tag events (heading
//!   from odometry, continuous); its first fix is the trial's answer, scored against the
//!   emulator's true pose at that moment. The pipeline then keeps tracking until the end.
//!
//! Both emulators run in lock-step with the trial: per 100 ms tick the Pioneer simulates one
//! SIP period (after handling every command the driver wrote, see `scenario::lockstep`), then
//! the reader scans once at the new true pose (after answering every line the driver wrote);
//! the trial waits for the tick's SIP and for every tag event of the scan, hands the pipeline
//! the odometry first and then the scan's tag events, and sends its command. Times of truth,
//! estimates, events and capture records are the Pioneer emulator's simulated seconds, and a
//! run depends on the scenario and seed alone: two runs with one seed write identical files
//! (`tests/sim_determinism.rs`).

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_aria::{
    AriaClient, ClientConfig as AriaClientConfig, EmulatorConfig as RobotConfig, RobotEmulator,
};
use rfloc_kts::{
    EmulatorConfig as ReaderConfig, KtsClient, KtsConfig, KtsEmulator, ScanControl, TagGrid, Uid,
    UidScheme,
};
use rfloc_pose::{angle_diff, EstimateMode, Pose2};
use rfloc_sim::recorder::TrialRecorder;
use rfloc_sim::{Point, Scenario};
use rfloc_transport::{open, CaptureSink, Recorder, SharedClock};
use tokio_util::sync::CancellationToken;

use super::lockstep::{read_all, LockstepBase, STEP_TIMEOUT};
use super::SimOptions;
use crate::sim::{pty_link, trial_capture, EmulatorClock};
use rfloc_daemon::config::{GridTag, HfGridSettings};
use rfloc_daemon::events::DeviceEvent;
use rfloc_daemon::pipeline::{HfGridPipeline, Pipeline};

/// Header note of the trial's captures.
const CAPTURE_NOTE: &str =
    "simulated seed 002 initialisation turn; timestamps are the Pioneer emulator's simulated seconds";
/// Pause at each 45° stop, simulated seconds.
const STOP_PAUSE_S: f64 = 0.5;

/// A world tag's full ISO 15693 UID: short IDs (seed 002 Table 9 prints only the last hex
/// digits) get the seed's UID prefix.
fn full_uid(uid: u64) -> u64 {
    if uid >> 56 == 0xE0 {
        uid
    } else {
        rfloc_hfgrid::SEED002_UID_PREFIX | (uid & 0xFFF)
    }
}

/// The reader emulator's tag field from the scenario world (row-major, x fastest).
pub(crate) fn reader_grid(scenario: &Scenario) -> anyhow::Result<TagGrid> {
    let world = &scenario.world;
    let pitch = world.hf_pitch.context("scenario world has no HF grid")?;
    let mut tags = world.hf_tags.clone();
    anyhow::ensure!(!tags.is_empty(), "scenario world has no HF tags");
    tags.sort_by_key(|t| (t.row, t.col));
    let rows = tags.iter().map(|t| t.row).max().unwrap_or(0) + 1;
    let cols = tags.iter().map(|t| t.col).max().unwrap_or(0) + 1;
    let origin = tags
        .iter()
        .find(|t| t.row == 0 && t.col == 0)
        .map_or((0.0, 0.0), |t| (t.position.x, t.position.y));
    let uids = tags
        .iter()
        .map(|t| Uid::from_u64(full_uid(t.uid)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(TagGrid {
        origin,
        pitch,
        rows,
        cols,
        uids: UidScheme::Explicit(uids),
    })
}

/// The pipeline's tag table from the scenario world (grid positions), the antenna offset and
/// the RSSI table's distance scale (`[mismatch] scale`).
fn pipeline_settings(scenario: &Scenario) -> HfGridSettings {
    HfGridSettings {
        pitch_m: scenario.world.hf_pitch.unwrap_or(0.10),
        antenna_offset_m: scenario.hf_model().antenna_offset,
        rssi_distance_scale: scenario.spec.mismatch.map_or(1.0, |m| m.scale),
        tags: scenario
            .world
            .hf_tags
            .iter()
            .map(|t| GridTag {
                uid: format!("{:016X}", full_uid(t.uid)),
                x: t.position.x,
                y: t.position.y,
            })
            .collect(),
        ..HfGridSettings::default()
    }
}

/// `stops` equal steps of one turn with a pause at each stop, driven by the odometry's
/// accumulated rotation.
struct TurnScript {
    rate: f64,
    /// Stops per turn (`params.readings_per_turn`).
    per_turn: u32,
    /// Rotation so far (odometry), rad.
    turned: f64,
    /// Stops reached.
    stops: u32,
    /// Simulated time the current pause ends.
    pause_until: f64,
    finished_at: Option<f64>,
}

impl TurnScript {
    fn new(rate: f64, per_turn: u32) -> Self {
        Self {
            rate,
            per_turn: per_turn.max(1),
            turned: 0.0,
            stops: 0,
            pause_until: 0.5,
            finished_at: None,
        }
    }

    /// Rotational velocity to command at simulated time `now`.
    fn command(&mut self, now: f64) -> f64 {
        if self.finished_at.is_some() || now < self.pause_until {
            return 0.0;
        }
        // The last stop goes 2° past the full turn so the pipeline sees all of it.
        let step = std::f64::consts::TAU / f64::from(self.per_turn);
        let next = f64::from(self.stops + 1) * step
            + if self.stops + 1 == self.per_turn {
                2f64.to_radians()
            } else {
                0.0
            };
        if self.turned >= next {
            self.stops += 1;
            self.pause_until = now + STOP_PAUSE_S;
            if self.stops >= self.per_turn {
                self.finished_at = Some(now);
            }
            return 0.0;
        }
        self.rate
    }
}

/// Waits until the emulated reader has read and answered every byte the driver wrote, then
/// until the driver has read every byte the emulator wrote (so the capture holds them all,
/// stamped at the present simulated time).
async fn settle_reader(control: &ScanControl, sink: &CaptureSink) -> anyhow::Result<()> {
    let settled = tokio::time::timeout(STEP_TIMEOUT, control.settle(sink.tx_bytes()))
        .await
        .context("the emulated reader did not settle")??;
    read_all(sink, settled.tx_bytes).await
}

/// Runs one trial.
pub async fn run_trial(
    scenario: &Scenario,
    trial: usize,
    dir: &Path,
    opts: &SimOptions,
) -> anyhow::Result<TrialRecorder> {
    let _ = opts;
    let mut rec = TrialRecorder::new(scenario, trial);
    let start = scenario.start_pose(trial);
    let seed = scenario.trial_seed(trial);
    let stop = CancellationToken::new();

    // Pioneer emulator on a pty, in lock-step.
    let (robot_master, robot_slave, robot_link) = pty_link(9600)?;
    let mut robot = RobotEmulator::new(RobotConfig {
        initial_pose: start,
        noise_seed: seed,
        ..RobotConfig::default()
    });
    let robot_control = robot.lock_step();
    let truth = robot.handle();
    let clock: SharedClock = Arc::new(EmulatorClock(truth.clone()));
    let robot_stop = stop.clone();
    let robot_task = tokio::spawn(async move {
        tokio::select! {
            () = robot_stop.cancelled() => {}
            r = robot.serve(robot_master) => if let Err(e) = r { tracing::warn!(error = %e, "robot emulator ended") },
        }
    });

    // KTS emulator on a pty, antenna following the true pose, scanning once per tick.
    let (reader_master, reader_slave, reader_link) = pty_link(115_200)?;
    let antenna_truth = truth.clone();
    let model = scenario.hf_model();
    let antenna = Arc::new(move || model.antenna_position(&antenna_truth.truth()));
    let grid = reader_grid(scenario)?;
    let mut rcfg = ReaderConfig::new(grid.clone(), antenna);
    rcfg.seed = seed;
    rcfg.miss_probability = model.miss_probability;
    // The simulator's RSSI (curve and spread) from a stream of the trial seed, and the tags'
    // placement errors from another.
    let rssi_rng = std::sync::Mutex::new(ChaCha8Rng::seed_from_u64(seed ^ 0x4846_5253_5349));
    rcfg.rssi = Some(Arc::new(move |d| {
        rssi_rng
            .lock()
            .ok()
            .and_then(|mut r| model.sample_rssi(d, &mut *r))
    }));
    let mut placement = ChaCha8Rng::seed_from_u64(seed ^ 0x4846_504C_4143);
    rcfg.tag_offsets = model.placement_errors(grid.rows * grid.cols, &mut placement);
    let mut reader = KtsEmulator::new(rcfg);
    let reader_control = reader.lock_step();
    let reader_stop = stop.clone();
    let reader_task = tokio::spawn(async move {
        tokio::select! {
            () = reader_stop.cancelled() => {}
            r = reader.serve(reader_master) => if let Err(e) = r { tracing::warn!(error = %e, "reader emulator ended") },
        }
    });

    // Drivers through the pty paths, recorded (same-time chunks coalesced).
    let base_sink = trial_capture(
        dir,
        "pioneer.cap",
        "pioneer-aria",
        &robot_link,
        clock.clone(),
        &[CAPTURE_NOTE],
    )?;
    let base_io = Recorder::new(open(&robot_link).await?, base_sink.clone());
    // No wall-time keep-alive or link timeout: the trial commands the robot in simulated time.
    let base_config = AriaClientConfig {
        pulse_period: Duration::from_secs(24 * 3600),
        link_timeout: Duration::from_secs(24 * 3600),
        sync_timeout: Duration::from_secs(5),
        close_linger: Duration::from_millis(100),
        clock: Some(clock.clone()),
        ..AriaClientConfig::default()
    };
    let base = AriaClient::from_stream(base_io, base_config)
        .await
        .context("Pioneer handshake")?;
    let base_flush = base_sink.clone();
    let base = LockstepBase::new(base, robot_control, truth.clone(), base_sink);
    let reader_sink = trial_capture(
        dir,
        "kts.cap",
        "kts-rfidm1356",
        &reader_link,
        clock.clone(),
        &[CAPTURE_NOTE],
    )?;
    let reader_io = Recorder::new(open(&reader_link).await?, reader_sink.clone());
    let mut kts = KtsClient::spawn(
        reader_io,
        // No wall-time limits that a loaded machine could trip (a resent command would
        // change the recorded bytes): the trial has its own step timeout.
        KtsConfig {
            silence_timeout: None,
            command_timeout: STEP_TIMEOUT,
            ..KtsConfig::default()
        },
        clock.clone(),
    );
    let mut tags = kts.take_events().context("tag events")?;
    kts.start_scan().await.context("start scanning")?;
    // Its `OK` is read completely before the clock moves.
    settle_reader(&reader_control, &reader_sink)
        .await
        .context("after the scan started")?;

    // The turn: eight 45° steps at the scenario's turn rate, pausing at each stop. Closed loop
    // on the driver's odometry, as a robot would do it.
    let rate = scenario.spec.robot.drive.max_turn_rate.clamp(0.1, 2.0);
    let per_turn = u32::try_from(scenario.spec.params.readings_per_turn.unwrap_or(8)).unwrap_or(8);
    let mut turn = TurnScript::new(rate, per_turn);
    // A hard stop in case the base never turns (e.g. stalled): three times the scenario's time.
    let end_s = 3.0 * scenario.spec.duration_s.max(10.0);

    let settings = pipeline_settings(scenario);
    let grid = rfloc_daemon::pipeline::tag_grid(&settings, None).map_err(anyhow::Error::msg)?;
    let mut pipeline = HfGridPipeline::new(&settings, grid);
    let mut fix: Option<(f64, Pose2, Pose2)> = None; // (time, estimate, truth)
    let mut tracking: Vec<f64> = Vec::new(); // position errors after the fix
    let mut commanded = f64::NAN;
    let mut last_cmd_t = f64::NEG_INFINITY;
    let mut last_odom: Option<Pose2> = None;
    // For the plot: each tag's UID, grid position and short name, and the antenna's position.
    let tag_names: Vec<(Uid, Point, String)> = scenario
        .world
        .hf_tags
        .iter()
        .filter_map(|t| {
            let name = if t.uid >> 56 == 0xE0 {
                format!("{:016X}", t.uid)
            } else {
                format!("{:X}", t.uid)
            };
            Some((Uid::from_u64(full_uid(t.uid)).ok()?, t.position, name))
        })
        .collect();
    let hf_model = scenario.hf_model();
    loop {
        // One tick: the robot moves under the last command, the reader scans at the new pose.
        let (o, t) = base.tick().await?;
        let scan = tokio::time::timeout(STEP_TIMEOUT, reader_control.scan(reader_sink.tx_bytes()))
            .await
            .context("the emulated reader did not scan")??;
        let now = t.sim_time;
        if let Some(prev) = last_odom.replace(o.pose) {
            turn.turned += angle_diff(o.pose.theta, prev.theta).abs();
        }
        rec.truth(now, t.truth);
        let ev = DeviceEvent::Odometry {
            device: "base".into(),
            t: o.time,
            pose: o.pose,
            v: o.v,
            w: o.w,
        };
        if let Some(est) = pipeline.handle(&ev) {
            if est.mode == EstimateMode::Fix {
                if fix.is_none() {
                    // The seed's measure is the initial pose: that is the trial's estimate,
                    // scored against the truth of the tick the odometry came from.
                    fix = Some((o.time, est.pose, t.truth));
                    rec.estimate(o.time, est.pose);
                } else {
                    tracking.push(est.pose.distance(&t.truth));
                }
            }
        }
        // Every tag event of the scan, in the order the reader reported them.
        for _ in 0..scan.lines {
            let ev = tokio::time::timeout(STEP_TIMEOUT, tags.recv())
                .await
                .context("a tag event of the scan did not come")?
                .context("the KTS driver stopped")?;
            if let Some(e) = DeviceEvent::from_tag_event("hf", &ev) {
                let _ = pipeline.handle(&e);
                if let Some((_, at, name)) = tag_names.iter().find(|(u, _, _)| *u == ev.uid) {
                    let (ax, ay) = hf_model.antenna_position(&t.truth);
                    rec.reading(ev.t, name.clone(), Point::new(ax, ay), *at);
                }
            }
        }
        read_all(&reader_sink, scan.tx_bytes).await?;
        if now >= end_s || turn.finished_at.is_some_and(|f| now > f + 2.0) {
            break;
        }
        let stops_before = turn.stops;
        let w = turn.command(now);
        if turn.stops > stops_before {
            rec.stop(now, t.truth);
        }
        // Re-send every 0.5 simulated seconds to keep the robot's watchdog fed.
        if (w - commanded).abs() > 1e-9 || now - last_cmd_t > 0.5 {
            base.set_velocity(0.0, w).await?;
            commanded = w;
            last_cmd_t = now;
        }
    }
    base.set_velocity(0.0, 0.0).await.ok();
    // Then the emulator is settled and everything it wrote is read, so that every run records
    // the same bytes.
    kts.stop_scan().await.context("stop scanning")?;
    settle_reader(&reader_control, &reader_sink)
        .await
        .context("after the scan stopped")?;
    base.shutdown().await;
    // The driver's task owns the recorded link: wait until it has ended, which writes the
    // capture's last (coalesced) record, and flush both captures before `run.mcap` reads them.
    kts.close().await;
    for (name, sink) in [("pioneer.cap", &base_flush), ("kts.cap", &reader_sink)] {
        sink.flush().with_context(|| format!("flushing {name}"))?;
    }
    stop.cancel();
    let _ = tokio::join!(robot_task, reader_task);
    drop((robot_slave, reader_slave));

    match fix {
        Some((t, est, tru)) => {
            rec.metric("init_time_s", t);
            rec.metric("mean_error_x_m", (est.x - tru.x).abs());
            rec.metric("mean_error_y_m", (est.y - tru.y).abs());
            rec.metric("init_error_m", est.distance(&tru));
            rec.metric(
                "init_theta_error_deg",
                angle_diff(est.theta, tru.theta).abs().to_degrees(),
            );
            if !tracking.is_empty() {
                #[allow(clippy::cast_precision_loss)]
                let mean = tracking.iter().sum::<f64>() / tracking.len() as f64;
                rec.metric("tracking_mean_error_m", mean);
            }
            rec.set_success(true);
        }
        None => rec.fail("no initial pose from the turn"),
    }
    Ok(rec)
}
