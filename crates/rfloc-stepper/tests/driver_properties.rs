//! Properties of the driver over random move sequences, with pins that record edges.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::cell::RefCell;
use std::convert::Infallible;
use std::rc::Rc;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use proptest::prelude::*;
use rfloc_stepper::timing::{DIR_SETUP_NS, STEP_LOW_MIN_NS, STEP_PULSE_NS};
use rfloc_stepper::{MovePolicy, SimulatedStepper, StepperConfig, StepperDriver};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Ev {
    Step(bool),
    Dir(bool),
    En(bool),
    Wait(u32),
}

#[derive(Clone)]
struct Log(Rc<RefCell<Vec<Ev>>>);

struct RecPin(Log, fn(bool) -> Ev);

impl ErrorType for RecPin {
    type Error = Infallible;
}
impl OutputPin for RecPin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0 .0.borrow_mut().push((self.1)(false));
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0 .0.borrow_mut().push((self.1)(true));
        Ok(())
    }
}

struct RecDelay(Log);
impl DelayNs for RecDelay {
    fn delay_ns(&mut self, ns: u32) {
        self.0 .0.borrow_mut().push(Ev::Wait(ns));
    }
}

fn config(policy: MovePolicy) -> StepperConfig {
    StepperConfig {
        full_steps_per_rev: 200,
        microsteps: 2,
        gear_ratio: 1.5,
        policy,
        ..StepperConfig::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Position = net rising edges; every rising edge is at least STEP_PULSE_NS wide and followed
    /// by at least STEP_LOW_MIN_NS low; DIR changes are followed by DIR_SETUP_NS before a STEP;
    /// the driver and the simulator agree on where each move ends.
    #[test]
    fn edges_timing_and_position_agree(
        targets in proptest::collection::vec(-3.0f64..3.0, 1..8),
        shortest in any::<bool>(),
    ) {
        let policy = if shortest { MovePolicy::ShortestPath } else { MovePolicy::default() };
        let log = Log(Rc::new(RefCell::new(Vec::new())));
        let mut drv = StepperDriver::new(
            RecPin(log.clone(), Ev::Step),
            RecPin(log.clone(), Ev::Dir),
            RecPin(log.clone(), Ev::En),
            RecDelay(log.clone()),
            config(policy),
        )
        .unwrap();
        let mut sim = SimulatedStepper::new(&config(policy)).unwrap();
        for &t in &targets {
            let a = drv.move_to(t).unwrap();
            let b = sim.move_to_now(t).unwrap();
            prop_assert!((a - b).abs() < 1e-12);
            prop_assert!((a - drv.angle()).abs() < 1e-12);
            if !shortest {
                prop_assert!((a - t).abs() <= drv.geometry().step_rad() / 2.0 + 1e-9);
            } else {
                prop_assert!(rfloc_pose::angle_diff(a, t).abs() <= drv.geometry().step_rad() / 2.0 + 1e-9);
            }
        }
        prop_assert_eq!(drv.position_steps(), sim.position_steps());

        let ev = log.0.borrow();
        let mut pos = 0i64;
        let mut dir_high = None;
        let mut since_dir: Option<u64> = None;
        for (i, e) in ev.iter().enumerate() {
            match *e {
                Ev::Dir(h) => { dir_high = Some(h); since_dir = Some(0); }
                Ev::Wait(ns) => { if let Some(s) = since_dir.as_mut() { *s += u64::from(ns); } }
                Ev::Step(true) => {
                    let d = dir_high.expect("DIR set before the first STEP");
                    prop_assert!(since_dir.unwrap() >= u64::from(DIR_SETUP_NS));
                    pos += if d { 1 } else { -1 };
                    prop_assert_eq!(ev.get(i + 1), Some(&Ev::Wait(STEP_PULSE_NS)));
                    prop_assert_eq!(ev.get(i + 2), Some(&Ev::Step(false)));
                    match ev.get(i + 3) {
                        Some(Ev::Wait(low)) => prop_assert!(*low >= STEP_LOW_MIN_NS),
                        other => prop_assert!(false, "no low wait after step: {:?}", other),
                    }
                }
                Ev::Step(false) | Ev::En(_) => {}
            }
        }
        prop_assert_eq!(pos, drv.position_steps());
    }
}
