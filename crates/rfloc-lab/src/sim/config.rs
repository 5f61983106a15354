//! `[simulation]` of a robot file: the lab's section, checked through the daemon's
//! [`SectionCheck`] seam so that `rfloc validate` reports its errors with the others.

use std::path::PathBuf;

use rfloc_daemon::config::{Checks, Diagnostics, Node, RobotConfig, SectionCheck, SectionContext};
use serde::Deserialize;

/// Simulation section: the lab starts emulators and attaches the robot's devices to them.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationConfig {
    /// Simulated seconds per wall second.
    #[serde(default = "default_time_scale")]
    pub time_scale: f64,
    /// Seed for every random source of the simulation.
    #[serde(default)]
    pub seed: u64,
    /// Simulated seconds to run (None: until stopped).
    pub duration_s: Option<f64>,
    /// Motion script the daemon drives: `turn` (360° in place, then stop), `square` or `still`.
    #[serde(default = "default_motion")]
    pub motion: String,
    /// Start pose of the simulated robot (metres, degrees).
    #[serde(default)]
    pub start: [f64; 3],
    /// Scenario file whose world (XBee beacons) and sensor models the emulated XBee radio
    /// uses, relative to the robot file. Needed when the robot has an XBee device.
    pub scenario: Option<PathBuf>,
    /// Relative σ of each wheel's ground speed per emulator substep (10 ms); 0 = no slip.
    #[serde(default)]
    pub slip_sigma: f64,
}

fn default_time_scale() -> f64 {
    1.0
}

fn default_motion() -> String {
    "turn".into()
}

#[derive(Deserialize)]
struct WithSimulation {
    simulation: SimulationConfig,
}

impl SimulationConfig {
    /// The `[simulation]` section of a (validated) robot file.
    pub fn of(cfg: &RobotConfig) -> anyhow::Result<Self> {
        toml::from_str::<WithSimulation>(&cfg.source.text)
            .map(|w| w.simulation)
            .map_err(|e| anyhow::anyhow!("{}: [simulation]: {}", cfg.source.file, e.message()))
    }

    fn check(&self, c: &mut Checks<'_, '_>, ctx: &SectionContext<'_>) {
        c.range("time_scale", self.time_scale, 0.001, 1000.0, "");
        c.range("slip_sigma", self.slip_sigma, 0.0, 0.99, "");
        if let Some(d) = self.duration_s {
            c.positive("duration_s", d, 1e7, " s");
        }
        for (i, v) in self.start.iter().enumerate() {
            c.range(&format!("start[{i}]"), *v, -1e6, 1e6, "");
        }
        c.one_of("motion", &self.motion, &["turn", "square", "still"]);
        if let (Some(p), true) = (&self.scenario, ctx.check_files) {
            let path = ctx.dir.map_or_else(|| p.clone(), |d| d.join(p));
            if let Err(e) = rfloc_sim::Scenario::load(&path) {
                c.error("scenario", format!("{e}"));
            }
        }
    }
}

/// The `[simulation]` section's check, for `RobotConfig::load`.
#[derive(Debug, Clone, Copy)]
pub struct SimulationSection;

impl SectionCheck for SimulationSection {
    fn section(&self) -> &'static str {
        "simulation"
    }

    fn check<'i>(&self, node: &Node<'i>, diag: &mut Diagnostics<'i>, ctx: &SectionContext<'_>) {
        if let Some(sim) = diag.deserialize::<SimulationConfig>("simulation", node) {
            sim.check(&mut Checks::new(diag, "simulation"), ctx);
        }
    }
}
