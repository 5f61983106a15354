//! A reconnecting session: reopens the link through a connector, logs in, re-applies the setup.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use rfloc_transport::SharedClock;
use tokio::io::{AsyncRead, AsyncWrite};

use crate::client::{AlienClient, AlienConfig};
use crate::error::AlienError;
use crate::setup::ReaderSetup;
use crate::snapshot::{Snapshot, SnapshotReader};

/// Opens a new link to the reader (the daemon passes a closure that dials TCP).
pub type Connector<T> =
    Arc<dyn Fn() -> Pin<Box<dyn Future<Output = std::io::Result<T>> + Send>> + Send + Sync>;

/// Reconnect back-off: `initial`, doubling up to `max`, at most `max_attempts` tries per call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    pub initial: Duration,
    pub max: Duration,
    pub max_attempts: u32,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            initial: Duration::from_millis(200),
            max: Duration::from_secs(5),
            max_attempts: 8,
        }
    }
}

/// A session that survives `Connection Timeout.`, closed links and busy refusals.
pub struct AlienSession<T> {
    connector: Connector<T>,
    config: AlienConfig,
    setup: ReaderSetup,
    clock: SharedClock,
    backoff: Backoff,
    client: Option<AlienClient<T>>,
    connects: u64,
}

impl<T> std::fmt::Debug for AlienSession<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlienSession")
            .field("connected", &self.client.is_some())
            .field("connects", &self.connects)
            .finish_non_exhaustive()
    }
}

impl<T> AlienSession<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// A session that connects on first use.
    #[must_use]
    pub fn new(
        connector: Connector<T>,
        config: AlienConfig,
        setup: ReaderSetup,
        clock: SharedClock,
        backoff: Backoff,
    ) -> Self {
        Self {
            connector,
            config,
            setup,
            clock,
            backoff,
            client: None,
            connects: 0,
        }
    }

    /// Successful connections so far (1 + reconnects).
    #[must_use]
    pub fn connects(&self) -> u64 {
        self.connects
    }

    /// The connected client, connecting (with back-off) if needed.
    ///
    /// # Errors
    /// [`AlienError::Reconnect`] after `max_attempts` failures; a refused login at once.
    pub async fn client(&mut self) -> Result<&mut AlienClient<T>, AlienError> {
        if self.client.is_none() {
            let c = self.connect_with_backoff().await?;
            self.client = Some(c);
        }
        self.client
            .as_mut()
            .ok_or(AlienError::Session(crate::error::SessionEnd::Closed))
    }

    async fn connect_with_backoff(&mut self) -> Result<AlienClient<T>, AlienError> {
        let mut delay = self.backoff.initial;
        let mut last = String::new();
        for attempt in 1..=self.backoff.max_attempts.max(1) {
            let attempt_fut = connect_once(
                Arc::clone(&self.connector),
                self.config.clone(),
                self.setup.clone(),
                self.clock.clone(),
            );
            match attempt_fut.await {
                Ok(c) => {
                    self.connects += 1;
                    tracing::info!(attempt, "alien: connected and set up");
                    return Ok(c);
                }
                Err(e @ AlienError::LoginFailed(_)) => return Err(e),
                Err(e) => {
                    tracing::warn!(attempt, %e, "alien: connect failed; backing off");
                    last = e.to_string();
                    tokio::time::sleep(delay).await;
                    delay = (delay * 2).min(self.backoff.max);
                }
            }
        }
        Err(AlienError::Reconnect {
            attempts: self.backoff.max_attempts.max(1),
            last,
        })
    }

    /// Keeps an idle session alive; call periodically.
    ///
    /// # Errors
    /// As [`AlienSession::client`]; a dead session is dropped and reopened on next use.
    pub async fn maintain(&mut self) -> Result<(), AlienError> {
        let r = self.client().await?.keepalive_if_due().await;
        if let Err(e) = &r {
            if e.needs_reconnect() {
                self.client = None;
            }
        }
        r
    }
}

async fn connect_once<T>(
    connector: Connector<T>,
    config: AlienConfig,
    setup: ReaderSetup,
    clock: SharedClock,
) -> Result<AlienClient<T>, AlienError>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    let io = connector().await?;
    let mut c = AlienClient::connect(io, config, clock).await?;
    c.apply_setup(&setup).await?;
    Ok(c)
}

impl<T> SnapshotReader for AlienSession<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// Reads a snapshot; on a dead session reconnects once and retries.
    async fn read_snapshot(&mut self) -> Result<Snapshot, AlienError> {
        match self.client().await?.read_snapshot().await {
            Ok(s) => Ok(s),
            Err(e) if e.needs_reconnect() => {
                tracing::warn!(%e, "alien: session lost; reconnecting");
                self.client = None;
                self.client().await?.read_snapshot().await
            }
            Err(e) => Err(e),
        }
    }
}
