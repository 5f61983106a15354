//! The GPIO stepper that turns the XBee radio's reflector (seed 003). It has no task of its own:
//! it lends its rotator to the sweeping radio's task, which needs radio and antenna in lock step.

use serde::Deserialize;

use crate::config::Checks;
use crate::devices::{AntennaSource, CheckEnv, DeviceContext, Driver, Resources};
use crate::events::DeviceState;
use crate::simulation::BoxFuture;

/// `kind = "stepper"`: a step/dir/enable driver on Linux GPIO. Lines are given by name (as
/// `gpioinfo` lists them) or by offset on the chip.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepperSettings {
    pub chip: String,
    pub step_line: String,
    pub dir_line: String,
    pub enable_line: Option<String>,
    /// Full steps per motor revolution.
    pub steps_per_rev: u32,
    /// Microsteps per full step set on the driver.
    #[serde(default = "default_microsteps")]
    pub microsteps: u32,
    /// Motor revolutions per antenna revolution.
    #[serde(default = "default_gear")]
    pub gear_ratio: f64,
    /// Swap the DIR level so that positive angles turn counter-clockwise seen from above.
    #[serde(default)]
    pub invert_direction: bool,
}

fn default_microsteps() -> u32 {
    1
}

fn default_gear() -> f64 {
    1.0
}

/// The antenna stepper driver.
pub struct Stepper;

impl Driver for Stepper {
    const KIND: &'static str = "stepper";
    const CAPTURES: &'static [&'static str] = &["stepper-gpio"];
    type Settings = StepperSettings;

    fn check(s: &StepperSettings, c: &mut Checks<'_, '_>, env: &CheckEnv<'_>) {
        c.count("steps_per_rev", u64::from(s.steps_per_rev), 1, 100_000);
        c.count("microsteps", u64::from(s.microsteps), 1, 256);
        c.range("gear_ratio", s.gear_ratio, 0.001, 1000.0, "");
        if env.check_files && !env.simulated && !std::path::Path::new(&s.chip).exists() {
            c.error("chip", format!("GPIO chip {} does not exist", s.chip));
        }
    }

    fn needs_link(_s: &StepperSettings) -> bool {
        false
    }

    fn for_capture(_capture: &str) -> Option<StepperSettings> {
        None
    }

    fn observes(_s: &StepperSettings) -> bool {
        false
    }

    fn provide(s: &StepperSettings, resources: &Resources) {
        resources.offer_antenna(AntennaSource::Gpio(s.clone()));
    }

    fn run(_s: StepperSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(async move {
            ctx.status(DeviceState::Connected, "driven by the XBee sweep task")
                .await;
            // Alive as long as the daemon: the rotator is in use by the radio's task.
            ctx.stop.cancelled().await;
        })
    }
}
