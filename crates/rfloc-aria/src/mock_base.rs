//! A [`MobileBase`] double for tests of code that drives a robot.

use std::sync::{Arc, Mutex};

use tokio::sync::watch;

use crate::client::{ClientError, MobileBase, Odometry};

/// What a [`MockBase`] was asked to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MockBaseCall {
    /// `set_velocity(v, w)`.
    SetVelocity {
        /// m/s.
        v: f64,
        /// rad/s.
        w: f64,
    },
    /// `stop()`.
    Stop,
}

/// Records calls and lets the test publish odometry.
#[derive(Debug, Clone)]
pub struct MockBase {
    calls: Arc<Mutex<Vec<MockBaseCall>>>,
    odometry: Arc<watch::Sender<Odometry>>,
}

impl Default for MockBase {
    fn default() -> Self {
        Self::new()
    }
}

impl MockBase {
    /// A mock with no calls and default odometry.
    #[must_use]
    pub fn new() -> Self {
        let (tx, _rx) = watch::channel(Odometry::default());
        Self {
            calls: Arc::new(Mutex::new(Vec::new())),
            odometry: Arc::new(tx),
        }
    }

    /// Publishes an odometry sample to every receiver.
    pub fn publish(&self, odometry: Odometry) {
        self.odometry.send_replace(odometry);
    }

    /// The calls so far.
    #[must_use]
    pub fn calls(&self) -> Vec<MockBaseCall> {
        self.calls.lock().map(|c| c.clone()).unwrap_or_default()
    }

    fn push(&self, call: MockBaseCall) {
        if let Ok(mut c) = self.calls.lock() {
            c.push(call);
        }
    }
}

impl MobileBase for MockBase {
    async fn set_velocity(&self, v: f64, w: f64) -> Result<(), ClientError> {
        self.push(MockBaseCall::SetVelocity { v, w });
        Ok(())
    }
    async fn stop(&self) -> Result<(), ClientError> {
        self.push(MockBaseCall::Stop);
        Ok(())
    }
    fn odometry(&self) -> watch::Receiver<Odometry> {
        self.odometry.subscribe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn records_calls_and_publishes() {
        let m = MockBase::new();
        let rx = MobileBase::odometry(&m);
        m.set_velocity(0.5, 0.1).await.unwrap();
        m.stop().await.unwrap();
        m.publish(Odometry {
            seq: 3,
            ..Odometry::default()
        });
        assert_eq!(
            m.calls(),
            vec![
                MockBaseCall::SetVelocity { v: 0.5, w: 0.1 },
                MockBaseCall::Stop
            ]
        );
        assert_eq!(rx.borrow().seq, 3);
    }
}
