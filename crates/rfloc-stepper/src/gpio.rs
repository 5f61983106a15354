//! Linux backend: output lines on a GPIO character device (uAPI v2) through `gpiocdev`.

use std::path::PathBuf;
use std::time::Duration;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorKind, ErrorType, OutputPin};
use gpiocdev::line::{Offset, Value};
use gpiocdev::Request;
use serde::{Deserialize, Serialize};

use crate::config::StepperConfig;
use crate::driver::StepperDriver;
use crate::error::StepperError;

/// A line given by its offset on the chip or by its name (as `gpioinfo` lists it).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum LineRef {
    /// Line offset on the chip.
    Offset(u32),
    /// Line name, looked up on the configured chip.
    Name(String),
}

/// Where the driver's control lines are (one `[stepper.gpio]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GpioStepperConfig {
    /// Character device of the chip, e.g. `/dev/gpiochip0`.
    pub chip: PathBuf,
    /// STEP line.
    pub step: LineRef,
    /// DIR line.
    pub dir: LineRef,
    /// ENABLE line; leave out when ENABLE is tied to its active level.
    #[serde(default)]
    pub enable: Option<LineRef>,
    /// Consumer label shown by `gpioinfo`.
    #[serde(default = "default_consumer")]
    pub consumer: String,
}

fn default_consumer() -> String {
    "rfloc-stepper".to_owned()
}

/// Errors of a requested GPIO line.
#[derive(Debug, thiserror::Error)]
pub enum GpioLineError {
    /// No line of that name on the chip.
    #[error("no line named {0:?} on the chip")]
    UnfoundLine(String),
    /// The kernel refused a request or a value change.
    #[error(transparent)]
    Cdev(#[from] gpiocdev::Error),
}

impl embedded_hal::digital::Error for GpioLineError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// One output line held through a `gpiocdev` request; implements [`OutputPin`].
#[derive(Debug)]
pub struct GpioLine {
    request: Request,
    offset: Offset,
}

impl GpioLine {
    /// Requests `line` on `chip` as an output driven to the inactive level.
    pub fn request(
        chip: &std::path::Path,
        line: &LineRef,
        consumer: &str,
    ) -> Result<Self, GpioLineError> {
        let offset = match line {
            LineRef::Offset(o) => *o,
            LineRef::Name(name) => {
                let c = gpiocdev::chip::Chip::from_path(chip)?;
                c.find_line_info(name)
                    .ok_or_else(|| GpioLineError::UnfoundLine(name.clone()))?
                    .offset
            }
        };
        let request = Request::builder()
            .on_chip(chip)
            .with_consumer(consumer)
            .with_line(offset)
            .as_output(Value::Inactive)
            .request()?;
        Ok(Self { request, offset })
    }
}

impl ErrorType for GpioLine {
    type Error = GpioLineError;
}

impl OutputPin for GpioLine {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        Ok(self.request.set_value(self.offset, Value::Inactive)?)
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        Ok(self.request.set_value(self.offset, Value::Active)?)
    }
}

/// An ENABLE line that may be absent.
#[derive(Debug)]
pub struct OptionalLine(pub Option<GpioLine>);

impl ErrorType for OptionalLine {
    type Error = GpioLineError;
}

impl OutputPin for OptionalLine {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        self.0.as_mut().map_or(Ok(()), OutputPin::set_low)
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        self.0.as_mut().map_or(Ok(()), OutputPin::set_high)
    }
}

/// [`DelayNs`] by `std::thread::sleep`: waits at least as long as asked (usually 50–100 µs
/// longer on Linux), which is what minimum-width timing needs.
#[derive(Debug, Clone, Copy, Default)]
pub struct ThreadSleepDelay;

impl DelayNs for ThreadSleepDelay {
    fn delay_ns(&mut self, ns: u32) {
        std::thread::sleep(Duration::from_nanos(u64::from(ns)));
    }
}

/// The driver type the Linux backend builds.
pub type GpioStepperDriver = StepperDriver<GpioLine, GpioLine, OptionalLine, ThreadSleepDelay>;

/// Requests the configured lines and builds a driver on them.
pub fn open_gpio_stepper(
    gpio: &GpioStepperConfig,
    config: StepperConfig,
) -> Result<GpioStepperDriver, StepperError> {
    let req = |line: &LineRef| {
        GpioLine::request(&gpio.chip, line, &gpio.consumer)
            .map_err(|e| StepperError::Gpio(format!("{} line {line:?}: {e}", gpio.chip.display())))
    };
    let step = req(&gpio.step)?;
    let dir = req(&gpio.dir)?;
    let en = OptionalLine(gpio.enable.as_ref().map(req).transpose()?);
    tracing::info!(chip = %gpio.chip.display(), "stepper GPIO lines requested");
    StepperDriver::new(step, dir, en, ThreadSleepDelay, config)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_accepts_offsets_and_names() {
        let c: GpioStepperConfig =
            toml::from_str("chip = \"/dev/gpiochip1\"\nstep = 17\ndir = \"P9_12\"\nenable = 27\n")
                .unwrap();
        assert_eq!(c.step, LineRef::Offset(17));
        assert_eq!(c.dir, LineRef::Name("P9_12".into()));
        assert_eq!(c.enable, Some(LineRef::Offset(27)));
        assert_eq!(c.consumer, "rfloc-stepper");
        assert!(toml::from_str::<GpioStepperConfig>(
            "chip = \"x\"\nstep = 1\ndir = 2\nbogus = 3\n"
        )
        .is_err());
    }

    #[test]
    fn missing_chip_is_a_typed_error() {
        let gpio = GpioStepperConfig {
            chip: "/nonexistent/gpiochip9".into(),
            step: LineRef::Offset(0),
            dir: LineRef::Offset(1),
            enable: None,
            consumer: default_consumer(),
        };
        let r = open_gpio_stepper(&gpio, StepperConfig::default());
        assert!(matches!(r, Err(StepperError::Gpio(_))), "{r:?}");
    }
}
