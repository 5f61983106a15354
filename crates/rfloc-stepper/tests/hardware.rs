//! On real hardware only: `cargo test -p rfloc-stepper --features hardware -- --nocapture`.
//!
//! Needs a GPIO chip with three free lines wired to a step/dir/enable driver, given as
//! `RFLOC_STEPPER_CHIP` (e.g. `/dev/gpiochip0`), `RFLOC_STEPPER_STEP`, `RFLOC_STEPPER_DIR`,
//! `RFLOC_STEPPER_EN` (offsets or names). The motor turns a quarter turn and back.
#![cfg(feature = "hardware")]
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use rfloc_stepper::gpio::{open_gpio_stepper, GpioStepperConfig, LineRef};
use rfloc_stepper::{AntennaRotator, StepperConfig, StepperHandle};

fn line(var: &str) -> LineRef {
    let v = std::env::var(var).unwrap_or_else(|_| panic!("{var} not set"));
    v.parse::<u32>().map_or(LineRef::Name(v), LineRef::Offset)
}

#[tokio::test]
async fn quarter_turn_and_back() {
    let gpio = GpioStepperConfig {
        chip: std::env::var("RFLOC_STEPPER_CHIP")
            .expect("RFLOC_STEPPER_CHIP not set")
            .into(),
        step: line("RFLOC_STEPPER_STEP"),
        dir: line("RFLOC_STEPPER_DIR"),
        enable: Some(line("RFLOC_STEPPER_EN")),
        consumer: "rfloc-stepper-test".into(),
    };
    let drv = open_gpio_stepper(&gpio, StepperConfig::default()).unwrap();
    let mut h = StepperHandle::spawn(drv).unwrap();
    let a = h.move_to(std::f64::consts::FRAC_PI_2).await.unwrap();
    assert!((a - std::f64::consts::FRAC_PI_2).abs() < 0.02);
    assert_eq!(h.home().await.unwrap(), 0.0);
    assert_eq!(h.shutdown().await.unwrap(), 0);
}
