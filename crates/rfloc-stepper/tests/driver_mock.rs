//! Exact pin and delay sequences of the driver, checked with embedded-hal-mock.

use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as D};
use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as P};
use embedded_hal_mock::eh1::MockError;
use rfloc_stepper::timing::{DIR_SETUP_NS, ENABLE_SETTLE_NS, STEP_PULSE_NS};
use rfloc_stepper::{
    AntennaRotator, MovePolicy, PinRole, StepperConfig, StepperDriver, StepperError, StepperHandle,
};

/// 200 steps/rev (1.8°), ramp 100 → 200 steps/s at 15 000 steps/s²: the step periods of a
/// 3-step move are 10 ms, 5 ms, 10 ms (k = 0, 1, 0 in v = sqrt(v0² + 2ak)).
fn cfg() -> StepperConfig {
    StepperConfig {
        full_steps_per_rev: 200,
        microsteps: 1,
        gear_ratio: 1.0,
        start_speed_steps_per_s: 100.0,
        max_speed_steps_per_s: 200.0,
        accel_steps_per_s2: 15_000.0,
        enable_active_low: true,
        invert_direction: false,
        release_after_move: false,
        policy: MovePolicy::default(),
    }
}

fn pulse(low_ns: u32) -> [D; 2] {
    [
        D::delay_ns(STEP_PULSE_NS),
        D::delay_ns(low_ns - STEP_PULSE_NS),
    ]
}

fn step_edges(n: usize) -> Vec<P> {
    let mut v = Vec::new();
    for _ in 0..n {
        v.push(P::set(State::High));
        v.push(P::set(State::Low));
    }
    v
}

#[test]
fn three_step_move_has_exact_sequence() {
    // new(): STEP low, ENABLE inactive (high).
    let mut step_tx = vec![P::set(State::Low)];
    step_tx.extend(step_edges(3));
    let step = Pin::new(&step_tx);
    let dir = Pin::new(&[P::set(State::High)]);
    let en = Pin::new(&[P::set(State::High), P::set(State::Low)]);
    let mut delays = vec![D::delay_ns(ENABLE_SETTLE_NS), D::delay_ns(DIR_SETUP_NS)];
    delays.extend(pulse(10_000_000));
    delays.extend(pulse(5_000_000));
    delays.extend(pulse(10_000_000));
    let delay = CheckedDelay::new(&delays);

    let mut drv = StepperDriver::new(step, dir, en, delay, cfg()).unwrap();
    let reached = drv.move_to(5.4f64.to_radians()).unwrap();
    assert!((reached.to_degrees() - 5.4).abs() < 1e-9);
    assert_eq!(drv.position_steps(), 3);
    assert!(drv.is_enabled());

    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[test]
fn reverse_move_with_inverted_dir_and_release() {
    let config = StepperConfig {
        invert_direction: true,
        release_after_move: true,
        enable_active_low: false,
        ..cfg()
    };
    let mut step_tx = vec![P::set(State::Low)];
    step_tx.extend(step_edges(2));
    let step = Pin::new(&step_tx);
    // Backward with inverted direction: DIR high.
    let dir = Pin::new(&[P::set(State::High)]);
    // Active-high enable: new() sets low, move sets high, release sets low.
    let en = Pin::new(&[P::set(State::Low), P::set(State::High), P::set(State::Low)]);
    let mut delays = vec![D::delay_ns(ENABLE_SETTLE_NS), D::delay_ns(DIR_SETUP_NS)];
    delays.extend(pulse(10_000_000));
    delays.extend(pulse(10_000_000));
    let delay = CheckedDelay::new(&delays);

    let mut drv = StepperDriver::new(step, dir, en, delay, config).unwrap();
    drv.move_steps(-2).unwrap();
    assert_eq!(drv.position_steps(), -2);
    assert!(!drv.is_enabled());
    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[test]
fn second_move_keeps_enable_and_sets_dir_again() {
    let mut step_tx = vec![P::set(State::Low)];
    step_tx.extend(step_edges(2));
    let step = Pin::new(&step_tx);
    let dir = Pin::new(&[P::set(State::High), P::set(State::Low)]);
    let en = Pin::new(&[P::set(State::High), P::set(State::Low)]);
    let mut delays = vec![D::delay_ns(ENABLE_SETTLE_NS), D::delay_ns(DIR_SETUP_NS)];
    delays.extend(pulse(10_000_000));
    delays.push(D::delay_ns(DIR_SETUP_NS));
    delays.extend(pulse(10_000_000));
    let delay = CheckedDelay::new(&delays);

    let mut drv = StepperDriver::new(step, dir, en, delay, cfg()).unwrap();
    drv.move_steps(1).unwrap();
    // home(): back to the stored zero, one step the other way, no new enable wait.
    let a = drv.home().unwrap();
    assert_eq!(a, 0.0);
    // A zero-length move touches nothing.
    drv.move_to(0.0).unwrap();
    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[test]
fn pin_error_mid_move_is_typed_and_position_is_kept() {
    let step = Pin::new(&[
        P::set(State::Low),
        P::set(State::High),
        P::set(State::Low),
        P::set(State::High).with_error(MockError::Io(std::io::ErrorKind::BrokenPipe)),
    ]);
    let dir = Pin::new(&[P::set(State::High)]);
    let en = Pin::new(&[P::set(State::High), P::set(State::Low)]);
    let mut delays = vec![D::delay_ns(ENABLE_SETTLE_NS), D::delay_ns(DIR_SETUP_NS)];
    delays.extend(pulse(10_000_000));
    let delay = CheckedDelay::new(&delays);

    let mut drv = StepperDriver::new(step, dir, en, delay, cfg()).unwrap();
    let err = drv.move_steps(3).unwrap_err();
    assert!(
        matches!(
            err,
            StepperError::Pin {
                pin: PinRole::Step,
                ..
            }
        ),
        "{err:?}"
    );
    assert_eq!(drv.position_steps(), 1, "one rising edge was issued");
    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[test]
fn out_of_range_target_touches_no_pin() {
    let step = Pin::new(&[P::set(State::Low)]);
    let dir = Pin::new(&[]);
    let en = Pin::new(&[P::set(State::High)]);
    let delay = CheckedDelay::new(&[]);
    let mut drv = StepperDriver::new(step, dir, en, delay, cfg()).unwrap();
    assert!(matches!(
        drv.move_to(4.0),
        Err(StepperError::OutOfRange { .. })
    ));
    assert!(matches!(
        drv.move_to(f64::INFINITY),
        Err(StepperError::NotFinite(_))
    ));
    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[test]
fn zero_offset_round_trip() {
    let step = Pin::new(&[P::set(State::Low)]);
    let dir = Pin::new(&[]);
    let en = Pin::new(&[P::set(State::High)]);
    let delay = CheckedDelay::new(&[]);
    let mut drv = StepperDriver::new(step, dir, en, delay, cfg()).unwrap();
    drv.restore_position_steps(42);
    assert!((drv.angle().to_degrees() - 75.6).abs() < 1e-9);
    assert_eq!(drv.set_zero_here(), 42);
    assert_eq!(drv.position_steps(), 0);
    let (mut s, mut d, mut e, mut dl) = drv.release();
    s.done();
    d.done();
    e.done();
    dl.done();
}

#[tokio::test]
async fn handle_runs_driver_on_its_thread() {
    let mut step_tx = vec![P::set(State::Low)];
    step_tx.extend(step_edges(3));
    let mut step = Pin::new(&step_tx);
    let mut dir = Pin::new(&[P::set(State::High)]);
    // new(): inactive; move: active; shutdown: inactive.
    let mut en = Pin::new(&[P::set(State::High), P::set(State::Low), P::set(State::High)]);
    let mut delays = vec![D::delay_ns(ENABLE_SETTLE_NS), D::delay_ns(DIR_SETUP_NS)];
    delays.extend(pulse(10_000_000));
    delays.extend(pulse(5_000_000));
    delays.extend(pulse(10_000_000));
    let mut delay = CheckedDelay::new(&delays);

    let drv =
        StepperDriver::new(step.clone(), dir.clone(), en.clone(), delay.clone(), cfg()).unwrap();
    let mut h = StepperHandle::spawn(drv).unwrap();
    let watch = h.angle_watch();
    let reached = h.move_to(5.0f64.to_radians()).await.unwrap();
    assert!((reached.to_degrees() - 5.4).abs() < 1e-9);
    assert!((h.angle() - reached).abs() < 1e-15);
    assert!((*watch.borrow() - reached).abs() < 1e-15);
    assert_eq!(h.shutdown().await.unwrap(), 3);
    step.done();
    dir.done();
    en.done();
    delay.done();
}
