//! A reconnecting session: reopens the link through a connector, logs in, re-applies the setup.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use rfloc_transport::SharedClock;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::time::Instant;

use crate::client::{AlienClient, AlienConfig};
use crate::error::AlienError;
use crate::setup::ReaderSetup;
use crate::snapshot::{Snapshot, SnapshotReader};

/// Opens a new link to the reader (the daemon passes a closure that dials TCP).
pub type Connector<T> =
    Arc<dyn Fn() -> Pin<Box<dyn Future<Output = std::io::Result<T>> + Send>> + Send + Sync>;

/// A back-off policy: the delay before retry `n` (from 0) is `initial · 2ⁿ`, capped at `max`,
/// then shortened by `⌊⌊d · jitter_percent / 100⌋ · r / 2⁶⁴⌋` nanoseconds, where `d` is that
/// delay in nanoseconds and `r` the `n`-th output of a SplitMix64 stream seeded with `seed`.
/// The same policy and seed give the same delays on every run; readers seeded differently do
/// not retry in step. `max_attempts` bounds the dials of one reconnect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    pub initial: Duration,
    /// The cap: no delay is longer.
    pub max: Duration,
    pub max_attempts: u32,
    /// Largest share of a delay taken off at random, in percent (at most 100).
    pub jitter_percent: u8,
    pub seed: u64,
}

impl Default for Backoff {
    /// Link failures: 0.2 s doubling to 5 s, 8 dials per reconnect, 20 % jitter.
    fn default() -> Self {
        Self {
            initial: Duration::from_millis(200),
            max: Duration::from_secs(5),
            max_attempts: 8,
            jitter_percent: 20,
            seed: 0,
        }
    }
}

/// SplitMix64's output for the state `x`.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Backoff {
    /// Refused credentials: 60 s doubling to 30 min, 20 % jitter, one login per attempt. A
    /// reader that locks an account after a few failures sees four in the first quarter hour.
    #[must_use]
    pub fn authentication() -> Self {
        Self {
            initial: Duration::from_secs(60),
            max: Duration::from_secs(30 * 60),
            max_attempts: 1,
            jitter_percent: 20,
            seed: 0,
        }
    }

    /// The same policy with another jitter seed.
    #[must_use]
    pub fn with_seed(self, seed: u64) -> Self {
        Self { seed, ..self }
    }

    /// The same policy seeded from a name (FNV-1a of its bytes), e.g. the device's.
    #[must_use]
    pub fn with_seed_from(self, name: &str) -> Self {
        let seed = name.bytes().fold(0xCBF2_9CE4_8422_2325_u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01B3)
        });
        self.with_seed(seed)
    }

    /// The delay before retry `retry` (0 = the first retry).
    #[must_use]
    pub fn delay(&self, retry: u32) -> Duration {
        let base = 2u32
            .checked_pow(retry)
            .and_then(|f| self.initial.checked_mul(f))
            .map_or(self.max, |d| d.min(self.max));
        let nanos = base.as_nanos();
        let draw = splitmix64(
            self.seed
                .wrapping_add(u64::from(retry).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
        );
        // share · draw / 2⁶⁴, where share is the most the jitter may take off.
        let share = nanos.saturating_mul(u128::from(self.jitter_percent.min(100))) / 100;
        let (high, low) = (share >> 64, share & u128::from(u64::MAX));
        let cut = high
            .saturating_mul(u128::from(draw))
            .saturating_add((low * u128::from(draw)) >> 64)
            .min(nanos);
        let left = nanos - cut;
        Duration::new(
            u64::try_from(left / 1_000_000_000).unwrap_or(u64::MAX),
            u32::try_from(left % 1_000_000_000).unwrap_or(0),
        )
    }
}

/// A session that survives `Connection Timeout.`, closed links, busy refusals, and readers
/// that send no usable reply (every exchange has a deadline). A refused login is not retried
/// before the authentication back-off has passed.
pub struct AlienSession<T> {
    connector: Connector<T>,
    config: AlienConfig,
    setup: ReaderSetup,
    clock: SharedClock,
    backoff: Backoff,
    auth_backoff: Backoff,
    client: Option<AlienClient<T>>,
    connects: u64,
    dials: u64,
    auth_failures: u32,
    auth_retry_at: Option<Instant>,
}

impl<T> std::fmt::Debug for AlienSession<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlienSession")
            .field("connected", &self.client.is_some())
            .field("connects", &self.connects)
            .field("dials", &self.dials)
            .field("auth_failures", &self.auth_failures)
            .finish_non_exhaustive()
    }
}

impl<T> AlienSession<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// A session that connects on first use. Link failures back off with `backoff`; refused
    /// credentials with [`Backoff::authentication`] unless [`AlienSession::with_auth_backoff`]
    /// says otherwise.
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
            auth_backoff: Backoff::authentication(),
            client: None,
            connects: 0,
            dials: 0,
            auth_failures: 0,
            auth_retry_at: None,
        }
    }

    /// The back-off after refused credentials (its `max_attempts` is not used: a refusal ends
    /// the reconnect at once).
    #[must_use]
    pub fn with_auth_backoff(self, auth_backoff: Backoff) -> Self {
        Self {
            auth_backoff,
            ..self
        }
    }

    /// Successful connections so far (1 + reconnects).
    #[must_use]
    pub fn connects(&self) -> u64 {
        self.connects
    }

    /// Links opened through the connector so far, successful or not.
    #[must_use]
    pub fn dials(&self) -> u64 {
        self.dials
    }

    /// Refused logins since the last successful one.
    #[must_use]
    pub fn auth_failures(&self) -> u32 {
        self.auth_failures
    }

    /// The connected client, connecting (with back-off) if needed. After a refused login this
    /// first waits until the authentication back-off has passed.
    ///
    /// # Errors
    /// [`AlienError::Reconnect`] after `max_attempts` failures; [`AlienError::AuthFailed`] at
    /// once when the login is refused.
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
        if let Some(at) = self.auth_retry_at {
            tokio::time::sleep_until(at).await;
        }
        let attempts = self.backoff.max_attempts.max(1);
        let mut last = String::new();
        for attempt in 0..attempts {
            self.dials += 1;
            let attempt_fut = connect_once(
                Arc::clone(&self.connector),
                self.config.clone(),
                self.setup.clone(),
                self.clock.clone(),
            );
            match attempt_fut.await {
                Ok(c) => {
                    self.connects += 1;
                    self.auth_failures = 0;
                    self.auth_retry_at = None;
                    tracing::info!(attempt = attempt + 1, "alien: connected and set up");
                    return Ok(c);
                }
                Err(AlienError::LoginFailed(reason)) => {
                    let retry_in = self.auth_backoff.delay(self.auth_failures);
                    self.auth_failures = self.auth_failures.saturating_add(1);
                    self.auth_retry_at = Some(Instant::now() + retry_in);
                    tracing::warn!(
                        failures = self.auth_failures,
                        retry_in_s = retry_in.as_secs_f64(),
                        reason = %reason,
                        "alien: login refused; no new login before the authentication back-off"
                    );
                    return Err(AlienError::AuthFailed {
                        failures: self.auth_failures,
                        reason,
                        retry_in,
                    });
                }
                Err(e) => {
                    tracing::warn!(attempt = attempt + 1, error = %e, "alien: connect failed");
                    last = e.to_string();
                    if attempt + 1 < attempts {
                        tokio::time::sleep(self.backoff.delay(attempt)).await;
                    }
                }
            }
        }
        Err(AlienError::Reconnect { attempts, last })
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
    let io = tokio::time::timeout(config.connect_timeout, connector())
        .await
        .map_err(|_| AlienError::Timeout {
            what: "connect".into(),
            after: config.connect_timeout,
            received: 0,
        })??;
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ms(v: &[u64]) -> Vec<Duration> {
        v.iter().copied().map(Duration::from_millis).collect()
    }

    #[test]
    fn splitmix64_matches_the_reference_stream() {
        // The first output of SplitMix64 seeded with 1234567 (Vigna's reference generator).
        assert_eq!(splitmix64(1_234_567), 6_457_827_717_110_365_317);
    }

    #[test]
    fn backoff_without_jitter_doubles_to_the_cap() {
        let b = Backoff {
            jitter_percent: 0,
            ..Backoff::default()
        };
        let seq: Vec<Duration> = (0..8).map(|n| b.delay(n)).collect();
        assert_eq!(seq, ms(&[200, 400, 800, 1600, 3200, 5000, 5000, 5000]));
        // No overflow however many retries.
        assert_eq!(b.delay(31), Duration::from_secs(5));
        assert_eq!(b.delay(u32::MAX), Duration::from_secs(5));
        let huge = Backoff {
            initial: Duration::MAX,
            max: Duration::MAX,
            ..b
        };
        assert_eq!(huge.delay(3), Duration::MAX);
    }

    #[test]
    fn jittered_backoff_known_answer() {
        // 1 s doubling to 30 s, up to half taken off, seed 42: computed outside this crate
        // from the formula in `Backoff`'s documentation.
        let b = Backoff {
            initial: Duration::from_secs(1),
            max: Duration::from_secs(30),
            max_attempts: 1,
            jitter_percent: 50,
            seed: 42,
        };
        let seq: Vec<Duration> = (0..8).map(|n| b.delay(n)).collect();
        assert_eq!(
            seq,
            [
                Duration::new(0, 629_217_561),
                Duration::new(1, 840_089_608),
                Duration::new(3, 442_797_740),
                Duration::new(6, 623_237_134),
                Duration::new(15, 695_758_652),
                Duration::new(16, 976_578_852),
                Duration::new(26, 723_922_095),
                Duration::new(17, 990_521_850),
            ]
        );
        // The authentication policy, seed 0: 60 s doubling to 30 min, up to a fifth off.
        let auth: Vec<u128> = (0..7)
            .map(|n| Backoff::authentication().delay(n).as_nanos())
            .collect();
        assert_eq!(
            auth,
            [
                49_400_270_302,
                109_643_328_071,
                238_731_178_964,
                386_795_330_098,
                939_581_435_220,
                1_682_162_724_882,
                1_737_407_568_255,
            ]
        );
    }

    #[test]
    fn seeds_from_names_differ() {
        let a = Backoff::authentication().with_seed_from("uhf0");
        let b = Backoff::authentication().with_seed_from("uhf1");
        assert_ne!(a.seed, b.seed);
        assert_ne!(a.delay(0), b.delay(0));
        assert_eq!(a, Backoff::authentication().with_seed_from("uhf0"));
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 512,
            rng_seed: proptest::test_runner::RngSeed::Fixed(0xA11E_0002),
            ..ProptestConfig::default()
        })]

        /// Every delay lies between the capped doubling less its jitter share and the capped
        /// doubling, and never exceeds the cap.
        #[test]
        fn delays_stay_within_their_jitter_band(
            initial_ms in 1u64..100_000,
            max_ms in 1u64..10_000_000,
            jitter in 0u8..=150,
            seed in any::<u64>(),
            retry in 0u32..64,
        ) {
            let b = Backoff {
                initial: Duration::from_millis(initial_ms),
                max: Duration::from_millis(max_ms),
                max_attempts: 1,
                jitter_percent: jitter,
                seed,
            };
            let base = u128::from(initial_ms)
                .checked_mul(1u128 << retry)
                .map_or(u128::from(max_ms), |d| d.min(u128::from(max_ms)))
                * 1_000_000;
            let share = base * u128::from(jitter.min(100)) / 100;
            let d = b.delay(retry).as_nanos();
            prop_assert!(d <= base && d >= base - share, "{} not in [{}, {}]", d, base - share, base);
            prop_assert!(b.delay(retry) <= b.max);
            prop_assert_eq!(b.delay(retry), b.delay(retry));
        }
    }
}
