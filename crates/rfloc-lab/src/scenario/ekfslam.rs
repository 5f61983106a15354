//! Simulated trials of the ekf-slam scenarios (seed 003: XBee EKF-SLAM with waypoint
//! navigation), end to end through rfloc's drivers over real pseudo-terminals.
//!
//! Per trial:
//! - a Pioneer emulator (`rfloc_aria::RobotEmulator`) and an XBee coordinator emulator
//!   (`rfloc_xbee::CoordinatorEmulator`) each serve the master side of a pty; `AriaClient` and
//!   `XBeeClient` open the slave sides by path through `rfloc_transport::open`, wrapped in
//!   `rfloc_transport::Recorder`s writing `pioneer.cap` and `xbee.cap` into the trial folder;
//! - the coordinator answers `ND` with each beacon's RSSI from the scenario's XBee model
//!   (`rfloc_sim::SensorSuite::xbee_rssi`), given the emulator's true pose and the
//!   `SimulatedStepper`'s current angle;
//! - the emulated Pioneer runs in lock-step with the trial (`lockstep`): each loop iteration
//!   asks for one 100 ms tick, which the emulator takes only after handling every command the
//!   driver wrote, and waits for that tick's SIP; the loop then runs the EKF prediction from the
//!   odometry increment, the waypoint controller on the estimate, and sends VEL/RVEL (a command
//!   every tick, which also feeds the robot's watchdog; the driver's wall-time PULSE is off).
//!   Before driving the robot sweeps [`START_SWEEPS`] times standing at the start pose
//!   (`params.start_sweeps`); then every [`SWEEP_EVERY_S`] (`params.sweep_every_s`) of driving
//!   it stops (the seed sweeps at a standstill), the
//!   `ScanRunner` turns the simulated stepper through 40 stops of 9° with
//!   [`ND_ROUNDS_PER_STOP`] `ND` rounds per stop, and each beacon's level and bearing, fitted
//!   with the reflector's gain pattern, update the filter (known association by 64-bit
//!   address). A sweep takes [`ROUND_SECONDS`] of simulated time per round (2 s for 40 rounds):
//!   the probe ticks the standing robot once every second round;
//! - truth and estimate are recorded at every SIP on the trial's *mission clock*: SIP periods
//!   plus the sweeps' time, which is the emulator's clock less the settling ticks.
//!   The true pose is the emulator's state after the tick. The trial ends at the scenario's
//!   `duration_s` of mission time or when the last waypoint is reached (`successes`).
//!
//! Odometry error. The seed's Table 3.1 motion noise alone makes dead reckoning better than
//! the seed's EKF-SLAM (see the rfloc-sim README), so the wheels slip: each wheel's travel
//! gets a relative Gaussian error per 10 ms substep, σ = the scenario's `drive.slip_sigma`, or
//! [`DEFAULT_SLIP_SIGMA`] when the scenario sets none (the seed003 scenario files set none).
//! It is applied to the odometry increments between the driver and the filter (`slip`), not
//! by the emulator's own `WheelSlip` (that one perturbs the truth, which would change the
//! error model the filter is told about; its draws are per simulated tick, so it would be
//! reproducible too). The wheel travels are split with the scenario's `drive.axle_track`. On
//! top of the slip, every increment in which the wheels turned gets the driven speed's and turn
//! rate's errors N(0, `drive.sigma_v`) and N(0, `drive.sigma_omega`) (seed 003 Table 3.1),
//! from a generator of their own. The filter is told the same error model. The
//! odometry-only error is reported beside the filter's (`odometry_rmse_m`,
//! `odometry_rmse_theta_rad`). The emulated Pioneer keeps the robot out of the world's walls
//! and obstacles (a body of `drive.body_radius`), as in the other trials. `drive.wheel_diameter`
//! is the true wheel diameter: the odometry assumes the Pioneer's 0.195 m, so another value
//! scales every increment by 0.195 / d, an error the filter is not told.
//!
//! Measurement model given to the filter, as an operator would calibrate it: the sweep
//! estimator fits the reflector's gain pattern (the scenario's, i.e. a calibrated pattern) to
//! all 40 stops, with one reading's σ = fast fading and whole-dBm rounding (√(1 + 1/12) dB);
//! eq. 2.7 with the scenario's `P_ref` and η; the fitted level of each sweep as an RSSI
//! measurement with σ² = shadowing² + the fit's error (≈ 3.0 dB); the fitted bearing with the
//! fit's Cramér–Rao variance plus ([`BEARING_FLOOR_DEG`])². A beacon not yet in the map gets RSSI-and-bearing views,
//! each view's pose kept in the filter state, until the filter's delayed initialisation
//! triangulates it (largest σ ≤ [`DELAYED_INIT_MAX_STD_M`], or, after [`RELAX_AFTER_VIEWS`]
//! views, largest σ ≤ [`MAX_RELATIVE_STD`] of its distance) and adds it with every view as
//! one update (`rfloc_ekfslam::DelayedInit`). A trial fails when a beacon is still not mapped
//! at its end, or the last waypoint was not reached. Consistency is reported as NEES per degree
//! of freedom: `beacon_nees_per_dof` (every beacon at the end, 2 dof each) and
//! `pose_nees_per_dof` (the final pose, 3 dof), pooled over trials with their 95 % χ² bands
//! (`*_nees_band_low/high`; the beacons of one trial share the robot's trajectory error, so the
//! beacon band uses the effective dof `beacon_nees_eff_dof` that the filter's own map covariance
//! gives the summed NEES), and their averages over every record (`*_time_avg_per_dof`). Beacon errors are averaged from the moment each
//! beacon is mapped (`beacon_rmse_k_m`); `beacon_final_k_m` is the error at the end. The sweep
//! measurements are also scored against the truth (`bearing_error_rms_deg`, `rssi_residual_*`,
//! and their ratios to the σ given to the filter, `*_z_rms`), and the pose against the filter's
//! own covariance (`heading_z_rms`, `position_nees_per_dof`).
//!
//! Reproducibility. Every random draw is seeded from the trial seed (sensor streams of
//! `SensorSuite`, the odometry slip), the emulated Pioneer moves only when the trial ticks it,
//! after it has handled every byte the driver wrote, and the coordinator answers an `ND` within
//! the simulated instant of the request. A run is therefore a function of the scenario and the
//! seed alone: two runs with one seed write identical captures, truth and estimate files
//! (`tests/sim_determinism.rs`), however loaded the machine. `--time-scale` does not apply.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use rfloc_bearing::{
    CosinePowerPattern, EstimatorConfig, GainPattern, PathLossModel, ScanConfig, ScanRunner,
    SweepPlanConfig,
};
use rfloc_pose::{angle_diff, Pose2};
use rfloc_sim::geometry::Point;
use rfloc_sim::recorder::TrialRecorder;
use rfloc_sim::{Scenario, SensorSuite};
use rfloc_stepper::{SimulatedStepper, StepperConfig};

use super::SimOptions;
use rfloc_daemon::config::{EkfSlamSettings, WheelSlipSettings};
use rfloc_daemon::events::{DeviceEvent, SweptBeacon};
use rfloc_daemon::pipeline::{EkfSlamPipeline, Pipeline, Request};

mod probe;
mod rig;
mod slip;

use super::lockstep::LockstepBase;
use probe::NdRssiProbe;
use rig::{Rig, RigSettings};
use slip::OdometrySlip;

/// Driving time between two sweeps, simulated seconds, when the scenario sets no
/// `params.sweep_every_s`.
pub const SWEEP_EVERY_S: f64 = 3.0;
/// Sweeps standing at the start pose before driving, when the scenario sets no
/// `params.start_sweeps`. The start is the one pose the filter knows exactly; on 30 trials of
/// `facility-ekfslam-route100` (seed 5101) 1 / 4 / 8 / 16 start sweeps gave a robot RMSE of
/// 0.159 / 0.109 / 0.092 / 0.083 m (docs/results.md). The simulator draws fast fading
/// independently per reading, at a standstill too, so repeated sweeps at one spot average it
/// fully; on a floor whose multipath is static they would average less.
pub const START_SWEEPS: usize = 8;
/// `ND` rounds per antenna stop.
pub const ND_ROUNDS_PER_STOP: u32 = 1;
/// Mission time one `ND` round (with the antenna step before it) counts for, seconds; a sweep
/// of 40 stops with one round each takes 2 s.
pub const ROUND_SECONDS: f64 = 0.05;
/// Wheel slip σ (relative, per 10 ms substep) when the scenario sets no `drive.slip_sigma`.
pub const DEFAULT_SLIP_SIGMA: f64 = 0.05;
/// A triangulated beacon joins the map once the largest σ of its position is below this, m
/// (the filter's default 1.5 m let a beacon seen only head-on, e.g. case II's (9, 2) on the
/// first leg, in with a wrong range; with the views' poses in the state waiting costs no
/// information, and 0.3 m mapped every beacon in every trial, 0.2 m not).
const DELAYED_INIT_MAX_STD_M: f64 = 0.3;
/// A beacon still not mapped after this many views (two thirds of the delayed
/// initialisation's window of 30) is mapped once its triangulated σ is at most
/// [`MAX_RELATIVE_STD`] of its distance, with that covariance. Measured on the facility
/// scenarios: 8 or 15 views mapped far beacons so early that the 100 m route's robot RMSE rose
/// to 0.17–0.22 / 0.156 m; 20 views left seed 003 cases I and II as they were, mapped every
/// beacon of the small route and kept the 100 m route at 0.143 m (0.131 m with 30, which never
/// maps the small route's beacons within its mission).
const RELAX_AFTER_VIEWS: usize = 20;
/// Relative σ bound for far beacons (see [`RELAX_AFTER_VIEWS`]).
const MAX_RELATIVE_STD: f64 = 0.25;
/// Wheel diameter the Pioneer's odometry assumes, metres (seed 003 Table 3.1); a scenario's
/// `drive.wheel_diameter` is the true one.
const PIONEER_WHEEL_DIAMETER_M: f64 = 0.195;
/// SIPs the trial waits for after connecting before it starts driving (1 s).
const SETTLE_SIPS: u64 = 10;
/// SIP period of the emulated Pioneer, seconds.
const SIP_PERIOD_S: f64 = 0.1;
/// Emulator substep, seconds (the Pioneer emulator runs 10 substeps per 100 ms SIP).
const SUBSTEP_S: f64 = 0.01;
/// Added in quadrature to every bearing σ from the sweep estimator, degrees (pattern and
/// mounting calibration error). With [`START_SWEEPS`] sweeps at the start, 1° made the filter
/// too cautious (30 route trials: bearing z RMS 0.89, final pose NEES per dof 0.70 and 0.63 on
/// two seed sets, band 0.73–1.31); 0.5° gives z RMS 0.97, beacon NEES in its band on both sets
/// and pose NEES 0.81 / 0.70 at the same accuracy (docs/results.md).
const BEARING_FLOOR_DEG: f64 = 0.5;

/// Runs one trial.
pub async fn run_trial(
    scenario: &Scenario,
    trial: usize,
    dir: &Path,
    opts: &SimOptions,
) -> anyhow::Result<TrialRecorder> {
    // Lock-step emulators: `opts.time_scale` does not apply (see the module documentation).
    let _ = opts;
    let drive = &scenario.spec.robot.drive;
    let slip = if drive.slip_sigma > 0.0 {
        drive.slip_sigma
    } else {
        DEFAULT_SLIP_SIGMA
    };
    // The emulator's own slip is off: see `slip` for why it is applied to the odometry.
    let settings = RigSettings {
        slip_relative_std: 0.0,
        slip_seed: 0,
    };
    let sensors = Arc::new(Mutex::new(SensorSuite::for_trial(scenario, trial)));
    let stepper = SimulatedStepper::new(&StepperConfig::default())
        .map_err(|e| anyhow::anyhow!("simulated stepper: {e}"))?;
    let antenna = stepper.angle_probe();
    let mut rig = Rig::start(
        scenario,
        trial,
        dir,
        settings,
        Arc::clone(&sensors),
        antenna,
    )
    .await?;
    let xbee = rig
        .take_xbee()
        .context("the XBee driver was already taken")?;
    let base = Arc::clone(&rig.base);
    let outcome = match Mission::new(scenario, trial, slip, stepper, xbee, sensors, &base) {
        Ok(mut mission) => {
            let run = mission.run(&base).await;
            run.map(|()| mission.finish())
        }
        Err(e) => Err(e),
    };
    drop(base);
    rig.shutdown().await;
    outcome
}

/// Sums for a root mean square.
#[derive(Debug, Default, Clone, Copy)]
struct Rms {
    sq: f64,
    n: usize,
}

impl Rms {
    fn add(&mut self, e: f64) {
        self.sq += e * e;
        self.n += 1;
    }
    fn value(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sq / self.n as f64).sqrt())
    }
}

/// One trial's estimator, controller and bookkeeping.
struct Mission {
    rec: TrialRecorder,
    /// The daemon's EKF-SLAM pipeline: filter, waypoint controller and sweep cycle.
    pipeline: EkfSlamPipeline,
    runner: ScanRunner<SimulatedStepper, NdRssiProbe>,
    sensors: Arc<Mutex<SensorSuite>>,
    /// True beacons: (address, position).
    beacons: Vec<(u64, Point)>,
    slip: f64,
    odometry_slip: OdometrySlip,
    duration: f64,
    rssi_sigma_db: f64,
    /// Mission time of one sweep: its `ND` rounds × [`ROUND_SECONDS`].
    sweep_seconds: f64,
    /// Mission clock, seconds: `ticks` SIP periods plus `sweep_seconds` per sweep.
    t: f64,
    ticks: u64,
    dead_reckoning: Pose2,
    odometry_error: Rms,
    beacon_error: BTreeMap<u64, Rms>,
    sweeps: usize,
    /// Reconnections of the Pioneer driver (each rebases its odometry).
    base_reconnects: u64,
    odometry_heading_error: Rms,
    /// The filter's pose error against its own covariance: heading error / σ_θ, and the
    /// position NEES (2 degrees of freedom; `Rms` of its square root).
    heading_z: Rms,
    position_nees: Rms,
    /// Pose NEES (3 dof: x, y, θ) summed over the records, and the records.
    pose_nees_sum: f64,
    pose_nees_n: usize,
    /// NEES (2 dof) of every mapped beacon at every record, summed, and the count.
    beacon_nees_sum: f64,
    beacon_nees_n: usize,
    /// Sweep measurements against the truth: bearing error (deg) and its ratio to the σ
    /// given to the filter; RSSI residual against eq. 2.7 (dB), its sum, and its ratio to σ.
    bearing_error: Rms,
    bearing_z: Rms,
    rssi_residual: Rms,
    rssi_residual_sum: f64,
    rssi_z: Rms,
}

impl Mission {
    fn new(
        scenario: &Scenario,
        trial: usize,
        slip: f64,
        stepper: SimulatedStepper,
        xbee: rig::XBeeLink,
        sensors: Arc<Mutex<SensorSuite>>,
        base: &Arc<LockstepBase>,
    ) -> anyhow::Result<Mission> {
        let model = scenario.xbee_model();
        // The path loss the robot is calibrated with: the simulator's, or with `[mismatch]
        // scale` one whose distances are `scale` times the true ones (P_ref raised by
        // 10·η·log10(scale) dB).
        let p_ref_dbm = model.p_ref_dbm
            + scenario
                .spec
                .mismatch
                .map_or(0.0, |m| 10.0 * model.eta * m.scale.log10());
        let steps = scenario.spec.params.sweep_steps.unwrap_or(40).max(4);
        // One reading's spread about its local mean: fast fading and, for whole-dBm readings,
        // the rounding (uniform over 1 dB: variance 1/12).
        let quantum = if model.integer_dbm { 1.0 / 12.0 } else { 0.0 };
        let reading_sigma_db = (model.fast_sigma_db.powi(2) + quantum).sqrt().max(0.5);
        // The fitted level of a sweep: its shadowing (held for the sweep, what an operator
        // would calibrate from the seed's Table 4.1 spread) plus the fit's own error, about one
        // reading's spread over the sweep's readings.
        let readings = steps as f64 * f64::from(ND_ROUNDS_PER_STOP.max(1));
        let rssi_sigma_db = model
            .shadow_sigma_db
            .hypot(reading_sigma_db / readings.sqrt());
        let scan = ScanConfig {
            plan: SweepPlanConfig {
                step_deg: 360.0 / steps as f64,
                ..SweepPlanConfig::default()
            },
            probes_per_stop: ND_ROUNDS_PER_STOP,
            max_probe_failures: 3,
            estimator: EstimatorConfig {
                path_loss: PathLossModel {
                    p_ref_dbm,
                    d_ref_m: 1.0,
                    eta: model.eta,
                    shadowing_sigma_db: model.shadow_sigma_db,
                },
                rssi_noise_sigma_db: reading_sigma_db,
                pattern: Some(GainPattern::CosinePower(CosinePowerPattern {
                    exponent: model.pattern.exponent,
                    back_lobe_db: model.pattern.back_lobe_db,
                })),
                ..EstimatorConfig::default()
            },
        };
        let rounds = steps as u64 * u64::from(ND_ROUNDS_PER_STOP.max(1));
        let sweep_seconds = rounds as f64 * ROUND_SECONDS;
        let sweep_ticks = (sweep_seconds / SIP_PERIOD_S).round() as u64;
        let probe = NdRssiProbe::new(xbee, Arc::clone(base), rounds, sweep_ticks);
        let runner = ScanRunner::new(stepper, probe, scan)
            .map_err(|e| anyhow::anyhow!("sweep plan: {e}"))?;
        let start = scenario.start_pose(trial);
        let drive = scenario.spec.robot.drive;
        let track = drive.axle_track;
        // The pipeline the daemon runs, configured as an operator would for this robot: the
        // scenario's path loss, the RSSI spread of its model, its waypoints and switching
        // distance, and the odometry error as the wheel slip the trial applies.
        let settings = EkfSlamSettings {
            p_ref_dbm,
            path_loss_exponent: model.eta,
            measurement: "rssi".into(),
            sweep_step_deg: 360.0 / steps as f64,
            waypoints: scenario.spec.waypoints.clone(),
            start: [start.x, start.y, start.theta.to_degrees()],
            sweep_every_s: scenario.spec.params.sweep_every_s.unwrap_or(SWEEP_EVERY_S),
            start_sweeps: u32::try_from(scenario.spec.params.start_sweeps.unwrap_or(START_SWEEPS))
                .unwrap_or(u32::MAX),
            rssi_sigma_db,
            bearing_floor_deg: BEARING_FLOOR_DEG,
            beacon_init_max_std_m: DELAYED_INIT_MAX_STD_M,
            beacon_init_relax_after_views: RELAX_AFTER_VIEWS,
            beacon_init_max_relative_std: MAX_RELATIVE_STD,
            beacon_init_with_range: true,
            beacon_init_pose_copies: true,
            waypoint_switch_m: scenario.spec.params.waypoint_switch_m.unwrap_or(0.3),
            wheel_slip: Some(WheelSlipSettings {
                relative_sigma: slip,
                track_m: track,
                interval_s: SUBSTEP_S,
                sigma_v_mps: drive.sigma_v,
                sigma_omega_rps: drive.sigma_omega,
            }),
            ..EkfSlamSettings::default()
        };
        let pipeline = EkfSlamPipeline::new(&settings)
            .map_err(|e| anyhow::anyhow!("EKF-SLAM pipeline: {e}"))?;
        Ok(Mission {
            rec: TrialRecorder::new(scenario, trial),
            pipeline,
            runner,
            sensors,
            beacons: scenario
                .world
                .beacons
                .iter()
                .map(|b| (b.address, b.position))
                .collect(),
            slip,
            odometry_slip: OdometrySlip::new(
                scenario.trial_seed(trial) ^ 0x5eed_5119,
                slip,
                track,
                SUBSTEP_S,
            )
            .with_velocity_noise(
                drive.sigma_v,
                drive.sigma_omega,
                scenario.trial_seed(trial) ^ 0x5eed_5150,
            )
            .with_wheel_diameter(drive.wheel_diameter, PIONEER_WHEEL_DIAMETER_M),
            duration: scenario.spec.duration_s,
            rssi_sigma_db,
            sweep_seconds,
            t: 0.0,
            ticks: 0,
            dead_reckoning: start,
            odometry_error: Rms::default(),
            beacon_error: BTreeMap::new(),
            sweeps: 0,
            base_reconnects: 0,
            odometry_heading_error: Rms::default(),
            heading_z: Rms::default(),
            position_nees: Rms::default(),
            pose_nees_sum: 0.0,
            pose_nees_n: 0,
            beacon_nees_sum: 0.0,
            beacon_nees_n: 0,
            bearing_error: Rms::default(),
            bearing_z: Rms::default(),
            rssi_residual: Rms::default(),
            rssi_residual_sum: 0.0,
            rssi_z: Rms::default(),
        })
    }

    /// Records truth, estimate and the running error sums at the mission time.
    fn record(&mut self, truth: Pose2) {
        let est = self.pipeline.filter().pose();
        self.rec.truth(self.t, truth);
        self.rec.estimate(self.t, est);
        let cov = self.pipeline.filter().pose_covariance();
        if cov[(2, 2)] > 1e-12 {
            self.heading_z
                .add(angle_diff(est.theta, truth.theta) / cov[(2, 2)].sqrt());
        }
        let pxy = cov.fixed_view::<2, 2>(0, 0).into_owned();
        if let Some(inv) = pxy.try_inverse().filter(|_| pxy.determinant() > 1e-18) {
            let e = nalgebra::Vector2::new(est.x - truth.x, est.y - truth.y);
            self.position_nees.add(e.dot(&(inv * e)).max(0.0).sqrt());
        }
        if let Some(inv) = cov.try_inverse().filter(|_| cov.determinant() > 1e-24) {
            let e = nalgebra::Vector3::new(
                est.x - truth.x,
                est.y - truth.y,
                angle_diff(est.theta, truth.theta),
            );
            self.pose_nees_sum += e.dot(&(inv * e)).max(0.0);
            self.pose_nees_n += 1;
        }
        self.odometry_error
            .add(self.dead_reckoning.distance(&truth));
        self.odometry_heading_error
            .add(angle_diff(self.dead_reckoning.theta, truth.theta));
        for (id, p) in &self.beacons {
            if let Some(b) = self.pipeline.filter().beacon(*id) {
                let e = (b.position.x - p.x).hypot(b.position.y - p.y);
                self.beacon_error.entry(*id).or_default().add(e);
                if let Some(n) = beacon_nees(&b, p) {
                    self.beacon_nees_sum += n;
                    self.beacon_nees_n += 1;
                }
            }
        }
    }

    /// The odometry event the daemon's base task would send: the trial's slipped odometry
    /// (dead reckoning in the map frame; the pipeline only uses its increments), mission time.
    fn odometry_event(&self, v: f64, w: f64) -> DeviceEvent {
        DeviceEvent::Odometry {
            device: "base".into(),
            t: self.t,
            pose: self.dead_reckoning,
            v,
            w,
        }
    }

    async fn run(&mut self, base: &LockstepBase) -> anyhow::Result<()> {
        // Let the link settle (first SIPs) before the mission starts.
        let (mut first, mut state) = base.tick().await?;
        for _ in 1..SETTLE_SIPS {
            (first, state) = base.tick().await?;
        }
        let mut prev_odo = first.pose;
        self.pipeline.handle(&self.odometry_event(first.v, first.w));
        // The mission clock starts here; the captures count the emulator's seconds.
        self.rec.capture_time(self.t, state.sim_time);
        self.record(state.truth);
        loop {
            // One SIP period under the command sent at the end of the previous one.
            let (o, state) = base.tick().await?;
            let ground = o.pose.relative_to(&prev_odo);
            prev_odo = o.pose;
            self.ticks += 1;
            self.t = self.ticks as f64 * SIP_PERIOD_S + self.sweeps as f64 * self.sweep_seconds;
            let delta = self.odometry_slip.apply(&ground, SIP_PERIOD_S);
            self.dead_reckoning = self.dead_reckoning.compose(&delta);
            self.pipeline.handle(&self.odometry_event(o.v, o.w));
            self.record(state.truth);
            if self.t >= self.duration || self.pipeline.is_done() {
                break;
            }
            let mut commanded = false;
            for request in self.pipeline.take_requests() {
                match request {
                    Request::Velocity { v, w } => {
                        base.set_velocity(v, w).await?;
                        commanded = true;
                    }
                    Request::Sweep { heading_rad } => {
                        // The sweep takes its ticks of the standing robot (the probe spreads
                        // them over its rounds); the mission clock counts them as the sweep's
                        // `sweep_seconds`.
                        self.rec.stop(self.t, state.truth);
                        let result = self.sweep(heading_rad, state.truth).await?;
                        self.t += self.sweep_seconds;
                        self.pipeline.handle(&DeviceEvent::Sweep {
                            device: "xbee".into(),
                            t: self.t,
                            result: Ok(result),
                        });
                        self.record(base.state().truth);
                    }
                }
            }
            if !commanded {
                // Feeds the watchdog while the robot stands (stopping or after a sweep).
                base.set_velocity(0.0, 0.0).await?;
            }
        }
        base.set_velocity(0.0, 0.0).await?;
        self.base_reconnects = base.client().stats().reconnects;
        Ok(())
    }

    /// One reflector sweep at a standstill; `truth` (the pose during the sweep) only scores
    /// the measurements against the scenario's beacons.
    async fn sweep(&mut self, heading: f64, truth: Pose2) -> anyhow::Result<Vec<SweptBeacon>> {
        if let Ok(mut s) = self.sensors.lock() {
            s.begin_xbee_sweep();
        }
        self.runner.probe_mut().begin_sweep();
        let result = self
            .runner
            .scan(move || heading)
            .await
            .map_err(|e| anyhow::anyhow!("bearing sweep: {e}"))?;
        self.runner.probe_mut().finish_sweep().await?;
        self.sweeps += 1;
        let floor = BEARING_FLOOR_DEG.to_radians();
        let path_loss = self.pipeline.filter().config().path_loss;
        let swept = rfloc_daemon::devices::swept_beacons(&result.report);
        for b in &swept {
            let sigma_b = (b.bearing_variance_rad2 + floor * floor).sqrt();
            if let Some((k, (_, p))) = self
                .beacons
                .iter()
                .enumerate()
                .find(|(_, (a, _))| *a == b.id)
            {
                self.rec.reading(
                    self.t,
                    format!("b{}", k + 1),
                    Point::new(truth.x, truth.y),
                    *p,
                );
                let (dx, dy) = (p.x - truth.x, p.y - truth.y);
                let eb = angle_diff(b.bearing_rad, angle_diff(dy.atan2(dx), truth.theta));
                let er = b.peak_rssi_dbm - path_loss.rssi_at(dx.hypot(dy));
                self.bearing_error.add(eb.to_degrees());
                self.bearing_z.add(eb / sigma_b);
                self.rssi_residual.add(er);
                self.rssi_residual_sum += er;
                self.rssi_z.add(er / self.rssi_sigma_db);
            }
        }
        tracing::debug!(
            sweep = self.sweeps,
            heard = result.report.beacons.len(),
            used = swept.len(),
            "sweep"
        );
        for (k, (id, p)) in self.beacons.iter().enumerate() {
            if let Some(b) = self.pipeline.filter().beacon(*id) {
                let e = (b.position.x - p.x).hypot(b.position.y - p.y);
                let sd = b.covariance.trace().sqrt();
                tracing::debug!(
                    sweep = self.sweeps,
                    beacon = k + 1,
                    error_m = e,
                    sd_m = sd,
                    "map"
                );
            }
        }
        Ok(swept)
    }

    /// Final metrics: beacon RMSE over the run (from each beacon's first mapping), final beacon
    /// errors, the odometry-only error and counters.
    fn finish(mut self) -> TrialRecorder {
        for (k, (id, p)) in self.beacons.iter().enumerate() {
            let n = k + 1;
            if let Some(rms) = self.beacon_error.get(id).and_then(Rms::value) {
                self.rec.metric(&format!("beacon_rmse_{n}_m"), rms);
            }
            if let Some(b) = self.pipeline.filter().beacon(*id) {
                let e = (b.position.x - p.x).hypot(b.position.y - p.y);
                self.rec.metric(&format!("beacon_final_{n}_m"), e);
                self.rec
                    .marks
                    .push((format!("b{n}"), Point::new(b.position.x, b.position.y)));
            }
        }
        if let Some(v) = self.odometry_error.value() {
            self.rec.metric("odometry_rmse_m", v);
        }
        if let Some(v) = self.odometry_heading_error.value() {
            self.rec.metric("odometry_rmse_theta_rad", v);
        }
        let counters = self.pipeline.counters();
        if counters.nis_dof > 0 {
            self.rec
                .metric("nis_per_dof", counters.nis_sum / counters.nis_dof as f64);
        }
        for (name, rms) in [
            ("bearing_error_rms_deg", self.bearing_error),
            ("bearing_z_rms", self.bearing_z),
            ("rssi_residual_rms_db", self.rssi_residual),
            ("rssi_z_rms", self.rssi_z),
            ("heading_z_rms", self.heading_z),
        ] {
            if let Some(v) = rms.value() {
                self.rec.metric(name, v);
            }
        }
        if let Some(v) = self.position_nees.value() {
            self.rec.metric("position_nees_per_dof", v * v / 2.0);
        }
        if self.rssi_residual.n > 0 {
            self.rec.metric(
                "rssi_residual_mean_db",
                self.rssi_residual_sum / self.rssi_residual.n as f64,
            );
        }
        // Consistency: the NEES of every beacon at the end (2 dof each) and of the final pose
        // (3 dof); `*_nees_dof` lets the report pool them over trials into a χ² band.
        let mut final_nees = 0.0;
        let mut mapped = 0usize;
        for (id, p) in &self.beacons {
            if let Some(n) = self
                .pipeline
                .filter()
                .beacon(*id)
                .and_then(|b| beacon_nees(&b, p))
            {
                final_nees += n;
                mapped += 1;
            }
        }
        if mapped > 0 {
            self.rec
                .metric("beacon_nees_per_dof", final_nees / (2 * mapped) as f64);
            self.rec.metric("beacon_nees_dof", (2 * mapped) as f64);
            if let Some(h) = beacon_nees_effective_dof(self.pipeline.filter()) {
                self.rec.metric("beacon_nees_eff_dof", h);
            }
        }
        if self.beacon_nees_n > 0 {
            self.rec.metric(
                "beacon_nees_time_avg_per_dof",
                self.beacon_nees_sum / (2 * self.beacon_nees_n) as f64,
            );
        }
        if self.pose_nees_n > 0 {
            self.rec.metric(
                "pose_nees_time_avg_per_dof",
                self.pose_nees_sum / (3 * self.pose_nees_n) as f64,
            );
        }
        if let Some(truth) = self.rec.truth.last().map(|p| p.pose) {
            let est = self.pipeline.filter().pose();
            let cov = self.pipeline.filter().pose_covariance();
            if let Some(inv) = cov.try_inverse().filter(|_| cov.determinant() > 1e-24) {
                let e = nalgebra::Vector3::new(
                    est.x - truth.x,
                    est.y - truth.y,
                    angle_diff(est.theta, truth.theta),
                );
                self.rec
                    .metric("pose_nees_per_dof", e.dot(&(inv * e)).max(0.0) / 3.0);
                self.rec.metric("pose_nees_dof", 3.0);
            }
        }
        let total = self.beacons.len();
        let mapped_count = self.pipeline.filter().beacon_count();
        self.rec.metric("beacons_total", total as f64);
        self.rec.metric("beacons_mapped", mapped_count as f64);
        let all_mapped = self
            .beacons
            .iter()
            .all(|(id, _)| self.pipeline.filter().beacon(*id).is_some());
        self.rec.metric("sweeps", self.sweeps as f64);
        self.rec
            .metric("base_reconnects", self.base_reconnects as f64);
        self.rec
            .metric("observations", counters.observations as f64);
        let probe = self.runner.probe_mut();
        self.rec
            .metric("xbee_dropped_bytes", probe.dropped_bytes() as f64);
        self.rec
            .metric("xbee_rejected_records", probe.rejected_records() as f64);
        self.rec
            .metric("gate_rejections", counters.gate_rejections as f64);
        self.rec.metric("mission_time_s", self.t);
        self.rec.metric("slip_sigma", self.slip);
        let done = self.pipeline.is_done();
        self.rec
            .metric("waypoints_done", if done { 1.0 } else { 0.0 });
        self.rec
            .metric("all_beacons_mapped", if all_mapped { 1.0 } else { 0.0 });
        if !all_mapped {
            self.rec.fail(format!(
                "{} of {total} beacons mapped",
                total.min(mapped_count)
            ));
        }
        if !done {
            self.rec.fail("last waypoint not reached".to_string());
        }
        self.rec.set_success(done && all_mapped);
        self.rec
    }
}

/// Effective degrees of freedom of the summed beacon NEES `S = Σ eᵢᵀ Pᵢᵢ⁻¹ eᵢ` of a filter
/// whose map error is `e ~ N(0, P_mm)`: with `D = blockdiag(Pᵢᵢ⁻¹)`, `E[S] = 2N` and
/// `Var[S] = 2 tr((D P_mm)²)`, which is `2·2N` only when the beacons' errors are uncorrelated.
/// The beacons of one trial share the robot's trajectory error (the whole map shifts and turns
/// with it), so `Var[S]` is larger; `S` is then taken as a scaled χ² with
/// `h = (2N)² / tr((D P_mm)²)` degrees of freedom (moment matching), the filter's own account
/// of how correlated its beacon errors are. `None` when a block is singular.
fn beacon_nees_effective_dof(f: &rfloc_ekfslam::EkfSlam) -> Option<f64> {
    let n = 2 * f.beacon_count();
    if n == 0 {
        return None;
    }
    let p = f.covariance().view((3, 3), (n, n)).into_owned();
    let mut dp = nalgebra::DMatrix::zeros(n, n);
    for k in 0..n / 2 {
        let block = p.fixed_view::<2, 2>(2 * k, 2 * k).into_owned();
        let inv = block
            .try_inverse()
            .filter(|_| block.determinant() > 1e-24)?;
        let rows = inv * p.rows(2 * k, 2);
        dp.rows_mut(2 * k, 2).copy_from(&rows);
    }
    let tr_sq = (&dp * &dp).trace();
    (tr_sq > 0.0).then(|| (n * n) as f64 / tr_sq)
}

/// NEES of a mapped beacon against its true position, `None` for a singular covariance.
fn beacon_nees(b: &rfloc_ekfslam::BeaconEstimate, truth: &Point) -> Option<f64> {
    let c = b.covariance;
    let inv = c.try_inverse().filter(|_| c.determinant() > 1e-24)?;
    let e = nalgebra::Vector2::new(b.position.x - truth.x, b.position.y - truth.y);
    Some(e.dot(&(inv * e)).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfloc_ekfslam::WheelSlipNoise;

    /// Seed 003 Table 3.1's axle track, metres.
    const EMULATOR_TRACK_M: f64 = 0.331;

    /// The covariance the pipeline is told (`WheelSlipNoise`) is the spread the trial's
    /// odometry slip produces.
    #[test]
    fn the_pipeline_noise_model_is_the_applied_slip() {
        let sigma = 0.05;
        let mut slip = OdometrySlip::new(3, sigma, EMULATOR_TRACK_M, SUBSTEP_S);
        let step = slip::arc(0.03, 0.02);
        let n = 40_000;
        let (mut sx, mut sth, mut sxth) = (0.0, 0.0, 0.0);
        for _ in 0..n {
            let d = slip.apply(&step, SIP_PERIOD_S);
            let (ex, eth) = (d.x - step.x, d.theta - step.theta);
            sx += ex * ex;
            sth += eth * eth;
            sxth += ex * eth;
        }
        let k = f64::from(n);
        let model = WheelSlipNoise {
            relative_sigma: sigma,
            track_m: EMULATOR_TRACK_M,
            interval_s: SUBSTEP_S,
        };
        let cov = model.increment_covariance(&step, SIP_PERIOD_S);
        let ratio_x = cov[(0, 0)] / (sx / k);
        let ratio_th = cov[(2, 2)] / (sth / k);
        assert!((ratio_x - 1.0).abs() < 0.05, "{ratio_x}");
        assert!((ratio_th - 1.0).abs() < 0.05, "{ratio_th}");
        // Turning left loads the right wheel more: along and heading errors correlate.
        assert!(cov[(0, 2)] > 0.0 && sxth > 0.0);
    }
}
