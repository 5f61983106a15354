//! The `AntennaRotator` trait and a pin-less simulated rotator.

use std::future::Future;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::config::StepperConfig;
use crate::error::StepperError;
use crate::geometry::StepGeometry;

/// Something that turns the directional antenna: the real stepper behind a
/// [`crate::StepperHandle`], or a [`SimulatedStepper`].
pub trait AntennaRotator {
    /// Error of a move.
    type Error: std::error::Error + Send + Sync + 'static;

    /// Moves to an absolute antenna angle (radians from the stored zero, which is the robot's
    /// forward direction) and resolves to the angle actually reached.
    fn move_to(&mut self, angle_rad: f64) -> impl Future<Output = Result<f64, Self::Error>> + Send;

    /// The last known antenna angle, radians.
    fn angle(&self) -> f64;
}

/// A cheap, clonable read-only view of a rotator's current angle (for simulators and emulators
/// whose RSSI depends on where the antenna points).
#[derive(Debug, Clone, Default)]
pub struct AngleProbe(Arc<AtomicU64>);

impl AngleProbe {
    /// A probe reading 0 rad.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Current angle, radians.
    #[must_use]
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::Acquire))
    }

    pub(crate) fn set(&self, rad: f64) {
        self.0.store(rad.to_bits(), Ordering::Release);
    }
}

/// A rotator without pins: same step quantisation and travel policy as the real driver, moves
/// instantly, and counts the steps it would have made.
#[derive(Debug, Clone)]
pub struct SimulatedStepper {
    geometry: StepGeometry,
    position: i64,
    steps_travelled: u64,
    probe: AngleProbe,
}

impl SimulatedStepper {
    /// A simulated axis at the stored zero.
    pub fn new(config: &StepperConfig) -> Result<Self, StepperError> {
        Ok(Self {
            geometry: StepGeometry::new(config)?,
            position: 0,
            steps_travelled: 0,
            probe: AngleProbe::new(),
        })
    }

    /// A view of the current angle that stays valid while the stepper moves.
    #[must_use]
    pub fn angle_probe(&self) -> AngleProbe {
        self.probe.clone()
    }

    /// Absolute position in steps.
    #[must_use]
    pub fn position_steps(&self) -> i64 {
        self.position
    }

    /// Total steps made since creation (both directions), a measure of cable wear.
    #[must_use]
    pub fn steps_travelled(&self) -> u64 {
        self.steps_travelled
    }

    /// Blocking-style move, for simulators that do not run async.
    pub fn move_to_now(&mut self, angle_rad: f64) -> Result<f64, StepperError> {
        let target = self.geometry.target_steps(self.position, angle_rad)?;
        self.steps_travelled += (target - self.position).unsigned_abs();
        self.position = target;
        let a = self.geometry.angle_of(target);
        self.probe.set(a);
        Ok(a)
    }
}

impl AntennaRotator for SimulatedStepper {
    type Error = StepperError;

    fn move_to(&mut self, angle_rad: f64) -> impl Future<Output = Result<f64, Self::Error>> + Send {
        let r = self.move_to_now(angle_rad);
        std::future::ready(r)
    }

    fn angle(&self) -> f64 {
        self.geometry.angle_of(self.position)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulated_stepper_quantises_and_tracks() {
        let cfg = StepperConfig::default(); // 200 steps/rev: 1.8°
        let mut s = SimulatedStepper::new(&cfg).unwrap();
        let probe = s.angle_probe();
        let a = s.move_to_now(10f64.to_radians()).unwrap();
        assert!((a.to_degrees() - 10.8).abs() < 1e-9);
        assert_eq!(s.position_steps(), 6);
        assert!((probe.get() - a).abs() < 1e-15);
        s.move_to_now(-9f64.to_radians()).unwrap();
        assert_eq!(s.position_steps(), -5);
        assert_eq!(s.steps_travelled(), 6 + 11);
        assert!(s.move_to_now(4.0).is_err());
        assert_eq!(s.position_steps(), -5, "a rejected move does not move");
    }
}
