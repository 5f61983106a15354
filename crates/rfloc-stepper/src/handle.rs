//! An async-facing handle to a driver that runs on its own blocking thread.
//!
//! Step pulses are timed with blocking sleeps, so the driver never runs inside an async task:
//! [`StepperHandle::spawn`] moves it to a dedicated `std::thread`, and the handle sends it
//! commands over a channel and awaits the replies.

use std::future::Future;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use tokio::sync::{mpsc, oneshot, watch};
use tracing::{info, info_span, warn};

use crate::driver::StepperDriver;
use crate::error::StepperError;
use crate::rotator::AntennaRotator;

type Reply<T> = oneshot::Sender<Result<T, StepperError>>;

enum Command {
    MoveTo { angle_rad: f64, reply: Reply<f64> },
    Home { reply: Reply<f64> },
    Enable { reply: Reply<()> },
    Disable { reply: Reply<()> },
    SetZeroHere { reply: Reply<i64> },
    Shutdown { reply: Reply<i64> },
}

/// Async handle to a [`StepperDriver`] running on a blocking thread.
///
/// Dropping the handle (or calling [`Self::shutdown`]) stops the thread and disables the
/// driver. A `move_to` future that is dropped early does not stop a move already started; the
/// reached angle still shows in [`Self::angle_watch`].
#[derive(Debug)]
pub struct StepperHandle {
    tx: mpsc::Sender<Command>,
    angle: watch::Receiver<f64>,
}

impl StepperHandle {
    /// Moves `driver` to a new thread named `rfloc-stepper` and returns the handle.
    pub fn spawn<STEP, DIR, EN, D>(
        driver: StepperDriver<STEP, DIR, EN, D>,
    ) -> Result<Self, StepperError>
    where
        STEP: OutputPin + Send + 'static,
        DIR: OutputPin + Send + 'static,
        EN: OutputPin + Send + 'static,
        D: DelayNs + Send + 'static,
    {
        let (tx, rx) = mpsc::channel(8);
        let (angle_tx, angle) = watch::channel(driver.angle());
        std::thread::Builder::new()
            .name("rfloc-stepper".into())
            .spawn(move || serve(driver, rx, &angle_tx))
            .map_err(|e| StepperError::Gpio(format!("cannot start stepper thread: {e}")))?;
        Ok(Self { tx, angle })
    }

    /// A receiver that sees the angle after every finished (or failed) command.
    #[must_use]
    pub fn angle_watch(&self) -> watch::Receiver<f64> {
        self.angle.clone()
    }

    async fn call<T>(&self, make: impl FnOnce(Reply<T>) -> Command) -> Result<T, StepperError> {
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(make(reply))
            .await
            .map_err(|_| StepperError::ThreadGone)?;
        rx.await.map_err(|_| StepperError::ThreadGone)?
    }

    /// Moves back to the stored zero; resolves to the angle reached.
    pub async fn home(&self) -> Result<f64, StepperError> {
        self.call(|reply| Command::Home { reply }).await
    }

    /// Energises the coils.
    pub async fn enable(&self) -> Result<(), StepperError> {
        self.call(|reply| Command::Enable { reply }).await
    }

    /// De-energises the coils.
    pub async fn disable(&self) -> Result<(), StepperError> {
        self.call(|reply| Command::Disable { reply }).await
    }

    /// Declares the current position the zero; resolves to the old position count.
    pub async fn set_zero_here(&self) -> Result<i64, StepperError> {
        self.call(|reply| Command::SetZeroHere { reply }).await
    }

    /// Disables the driver, stops the thread and resolves to the final position count, for the
    /// caller to persist.
    pub async fn shutdown(self) -> Result<i64, StepperError> {
        self.call(|reply| Command::Shutdown { reply }).await
    }
}

impl AntennaRotator for StepperHandle {
    type Error = StepperError;

    fn move_to(&mut self, angle_rad: f64) -> impl Future<Output = Result<f64, Self::Error>> + Send {
        let tx = self.tx.clone();
        async move {
            let (reply, rx) = oneshot::channel();
            tx.send(Command::MoveTo { angle_rad, reply })
                .await
                .map_err(|_| StepperError::ThreadGone)?;
            rx.await.map_err(|_| StepperError::ThreadGone)?
        }
    }

    fn angle(&self) -> f64 {
        *self.angle.borrow()
    }
}

fn serve<STEP, DIR, EN, D>(
    mut driver: StepperDriver<STEP, DIR, EN, D>,
    mut rx: mpsc::Receiver<Command>,
    angle_tx: &watch::Sender<f64>,
) where
    STEP: OutputPin,
    DIR: OutputPin,
    EN: OutputPin,
    D: DelayNs,
{
    let span = info_span!("stepper");
    let _g = span.enter();
    info!("stepper thread started");
    // The angle is published before each reply, so a caller that got a reply sees the new
    // angle in `angle()`. A failed reply send only means the caller stopped waiting.
    while let Some(cmd) = rx.blocking_recv() {
        match cmd {
            Command::MoveTo { angle_rad, reply } => {
                let r = driver.move_to(angle_rad);
                angle_tx.send_replace(driver.angle());
                let _ = reply.send(r);
            }
            Command::Home { reply } => {
                let r = driver.home();
                angle_tx.send_replace(driver.angle());
                let _ = reply.send(r);
            }
            Command::Enable { reply } => {
                let _ = reply.send(driver.enable());
            }
            Command::Disable { reply } => {
                let _ = reply.send(driver.disable());
            }
            Command::SetZeroHere { reply } => {
                let old = driver.set_zero_here();
                angle_tx.send_replace(driver.angle());
                let _ = reply.send(Ok(old));
            }
            Command::Shutdown { reply } => {
                let r = driver.disable().map(|()| driver.position_steps());
                let _ = reply.send(r);
                info!("stepper thread stopped on request");
                return;
            }
        }
    }
    if let Err(e) = driver.disable() {
        warn!(error = %e, "could not disable stepper driver on exit");
    }
    info!("stepper thread stopped: all handles dropped");
}
