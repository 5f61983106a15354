//! The blocking step/dir/enable driver, generic over embedded-hal 1.0 pins and delay.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{OutputPin, PinState};
use tracing::{debug, trace};

use crate::config::StepperConfig;
use crate::error::{PinRole, StepperError};
use crate::geometry::StepGeometry;
use crate::timing::{RampProfile, DIR_SETUP_NS, ENABLE_SETTLE_NS, STEP_PULSE_NS};

/// A stepper axis driven through a step/dir/enable driver chip (A4988, DRV8825 and alike).
///
/// Pin sequence of a move of `n > 0` steps (levels are physical):
/// 1. ENABLE to its active level and [`ENABLE_SETTLE_NS`] wait, if the axis was disabled;
/// 2. DIR to the move's level, then [`DIR_SETUP_NS`] wait;
/// 3. per step `i`: STEP high, [`STEP_PULSE_NS`] wait, STEP low, wait
///    `RampProfile::interval_ns(i, n) - STEP_PULSE_NS`;
/// 4. ENABLE inactive if `release_after_move` is set.
///
/// The absolute position is counted in (micro)steps from the stored zero and advanced on each
/// STEP rising edge that was set successfully, so after a pin error [`Self::position_steps`]
/// still says how far the motor was told to go.
pub struct StepperDriver<STEP, DIR, EN, D> {
    step: STEP,
    dir: DIR,
    en: EN,
    delay: D,
    config: StepperConfig,
    geometry: StepGeometry,
    ramp: RampProfile,
    position: i64,
    enabled: bool,
}

impl<STEP, DIR, EN, D> StepperDriver<STEP, DIR, EN, D>
where
    STEP: OutputPin,
    DIR: OutputPin,
    EN: OutputPin,
    D: DelayNs,
{
    /// Validates the configuration and puts the lines in a known state: STEP low, driver
    /// disabled. The position starts at 0; restore a persisted one with
    /// [`Self::restore_position_steps`].
    pub fn new(
        step: STEP,
        dir: DIR,
        en: EN,
        delay: D,
        config: StepperConfig,
    ) -> Result<Self, StepperError> {
        let geometry = StepGeometry::new(&config)?;
        let ramp = RampProfile {
            start_speed: config.start_speed_steps_per_s,
            max_speed: config.max_speed_steps_per_s,
            accel: config.accel_steps_per_s2,
        };
        let mut this = Self {
            step,
            dir,
            en,
            delay,
            config,
            geometry,
            ramp,
            position: 0,
            enabled: true,
        };
        this.step
            .set_low()
            .map_err(|e| StepperError::pin(PinRole::Step, &e))?;
        this.disable()?;
        Ok(this)
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> &StepperConfig {
        &self.config
    }

    /// Angle and step conversions of this axis.
    #[must_use]
    pub fn geometry(&self) -> &StepGeometry {
        &self.geometry
    }

    /// Energises the coils (ENABLE active) and waits [`ENABLE_SETTLE_NS`]. No-op if enabled.
    pub fn enable(&mut self) -> Result<(), StepperError> {
        if self.enabled {
            return Ok(());
        }
        let level = if self.config.enable_active_low {
            PinState::Low
        } else {
            PinState::High
        };
        self.en
            .set_state(level)
            .map_err(|e| StepperError::pin(PinRole::Enable, &e))?;
        self.delay.delay_ns(ENABLE_SETTLE_NS);
        self.enabled = true;
        debug!("stepper enabled");
        Ok(())
    }

    /// De-energises the coils (ENABLE inactive). The position is kept; a loaded axis may slip.
    pub fn disable(&mut self) -> Result<(), StepperError> {
        let level = if self.config.enable_active_low {
            PinState::High
        } else {
            PinState::Low
        };
        self.en
            .set_state(level)
            .map_err(|e| StepperError::pin(PinRole::Enable, &e))?;
        if self.enabled {
            debug!("stepper disabled");
        }
        self.enabled = false;
        Ok(())
    }

    /// Whether the coils are energised.
    #[must_use]
    pub fn is_enabled(&self) -> bool {
        self.enabled
    }

    /// Absolute position in (micro)steps from the stored zero.
    #[must_use]
    pub fn position_steps(&self) -> i64 {
        self.position
    }

    /// Absolute output angle from the stored zero, radians.
    #[must_use]
    pub fn angle(&self) -> f64 {
        self.geometry.angle_of(self.position)
    }

    /// Sets the position counter to a value persisted earlier (no motion).
    pub fn restore_position_steps(&mut self, steps: i64) {
        self.position = steps;
    }

    /// Declares the current physical position to be the zero (no motion). Returns the old
    /// position count, which is the offset the caller should add to anything it stored.
    pub fn set_zero_here(&mut self) -> i64 {
        std::mem::replace(&mut self.position, 0)
    }

    /// Moves to an absolute output angle under the configured [`crate::MovePolicy`] and returns
    /// the angle reached (the target quantised to whole steps).
    pub fn move_to(&mut self, angle_rad: f64) -> Result<f64, StepperError> {
        let target = self.geometry.target_steps(self.position, angle_rad)?;
        self.move_steps(target - self.position)?;
        Ok(self.angle())
    }

    /// Returns to the stored zero the way the policy allows (unwinding when bounded).
    pub fn home(&mut self) -> Result<f64, StepperError> {
        let steps = -self.position;
        self.move_steps(steps)?;
        Ok(self.angle())
    }

    /// Moves by a signed number of steps with the acceleration ramp.
    pub fn move_steps(&mut self, steps: i64) -> Result<(), StepperError> {
        if steps == 0 {
            return Ok(());
        }
        if steps.abs() > crate::geometry::MAX_MOVE_STEPS {
            return Err(StepperError::MoveTooLong(steps));
        }
        self.enable()?;
        let forward = steps > 0;
        let dir_high = forward != self.config.invert_direction;
        self.dir
            .set_state(PinState::from(dir_high))
            .map_err(|e| StepperError::pin(PinRole::Dir, &e))?;
        self.delay.delay_ns(DIR_SETUP_NS);
        let n = steps.unsigned_abs();
        let inc = if forward { 1 } else { -1 };
        trace!(steps, from = self.position, "stepper move");
        for i in 0..n {
            let period = self.ramp.interval_ns(i, n);
            self.step
                .set_high()
                .map_err(|e| StepperError::pin(PinRole::Step, &e))?;
            self.position += inc;
            self.delay.delay_ns(STEP_PULSE_NS);
            self.step
                .set_low()
                .map_err(|e| StepperError::pin(PinRole::Step, &e))?;
            self.delay.delay_ns(period.saturating_sub(STEP_PULSE_NS));
        }
        if self.config.release_after_move {
            self.disable()?;
        }
        debug!(steps, position = self.position, "stepper move done");
        Ok(())
    }

    /// Gives back the pins and the delay.
    pub fn release(self) -> (STEP, DIR, EN, D) {
        (self.step, self.dir, self.en, self.delay)
    }
}

/// An ENABLE line that is not wired (driver ENABLE tied to its active level).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoEnablePin;

impl embedded_hal::digital::ErrorType for NoEnablePin {
    type Error = core::convert::Infallible;
}

impl OutputPin for NoEnablePin {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl<STEP, DIR, EN, D> std::fmt::Debug for StepperDriver<STEP, DIR, EN, D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StepperDriver")
            .field("position", &self.position)
            .field("enabled", &self.enabled)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}
