//! Device kinds and the registry that lists them.
//!
//! A device kind implements [`Driver`] once: its TOML `kind`, its settings type (strict, with
//! `deny_unknown_fields`), its checks, the name its captures carry, and how it runs over a link
//! the daemon opens for it ([`DeviceContext::open_link`]). [`REGISTRY`] lists the kinds; the
//! robot file, `rfloc validate`, `rfloc run`, `rfloc record` and `rfloc replay` all go through
//! it, so a new kind is one module and one registry line (see docs/adding-a-driver.md).

use std::any::Any;
use std::fmt;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use rfloc_transport::replay::ReplayMode;
use serde::de::DeserializeOwned;
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::config::{Checks, Diagnostics, Node};
use crate::events::DeviceState;
use crate::pipeline::Request;
use crate::simulation::BoxFuture;

pub mod alien;
pub mod aria;
mod backoff;
mod context;
pub mod kts;
pub mod stepper;
pub mod urg;
pub mod xbee;
mod xbee_receiver;

pub use backoff::{seed_of, Backoff};
pub use context::{CommandQueue, DeviceContext, LinkSource, Resources};
pub use xbee::{swept_beacons, AntennaSource, NdRssiProbe, SweepMark};

/// Where a robot file is checked: what may be looked at besides the file itself.
#[derive(Debug, Clone, Copy)]
pub struct CheckEnv<'a> {
    /// Check that device nodes and credential files exist (false: validate for another machine).
    pub check_files: bool,
    /// Folder of the robot file.
    pub config_dir: Option<&'a std::path::Path>,
    /// The robot file has a `[simulation]` section: links may be absent (emulators attach).
    pub simulated: bool,
}

/// One device kind.
pub trait Driver: Send + Sync + 'static {
    /// The `kind` of `[device.driver]`.
    const KIND: &'static str;
    /// The device names its captures carry (the first is written; all are replayed).
    const CAPTURES: &'static [&'static str];
    /// Its `[device.driver]` settings.
    type Settings: DeserializeOwned + fmt::Debug + Clone + Send + Sync + 'static;

    /// Range and consistency checks of the settings (keys relative to `device[i].driver`).
    fn check(settings: &Self::Settings, checks: &mut Checks<'_, '_>, env: &CheckEnv<'_>);
    /// Whether the device needs a `link` (a GPIO device has none).
    fn needs_link(_settings: &Self::Settings) -> bool {
        true
    }
    /// The device name its capture carries.
    fn capture_name(_settings: &Self::Settings) -> &'static str {
        Self::CAPTURES.first().copied().unwrap_or(Self::KIND)
    }
    /// Seconds without data before the device counts as stale, when the file does not say.
    fn stale_after_s(_settings: &Self::Settings) -> f64 {
        3.0
    }
    /// How its recording is fed back: streamed, or reply by reply to the driver's requests.
    fn replay_mode(_settings: &Self::Settings) -> ReplayMode {
        ReplayMode::Stream
    }
    /// In a request/response replay, whether a request the recording does not hold next is
    /// looked for further on and otherwise left unanswered (a driver newer than the recording,
    /// with fixed requests), rather than answered with the next recorded reply (requests that
    /// carry the time or a counter).
    fn replay_skips_unknown(_settings: &Self::Settings) -> bool {
        false
    }
    /// Settings to replay a capture of `capture` (its header's device) with no robot file.
    fn for_capture(capture: &str) -> Option<Self::Settings>;
    /// Whether the device carries out this pipeline request.
    fn handles(_settings: &Self::Settings, _request: &Request) -> bool {
        false
    }
    /// Whether the device sends observations (a device that only lends something, such as the
    /// antenna stepper, never does and is never stale).
    fn observes(_settings: &Self::Settings) -> bool {
        true
    }
    /// Offers what the device lends to others before any task starts.
    fn provide(_settings: &Self::Settings, _resources: &Resources) {}
    /// The device task: opens its link through `ctx`, sends observations and status, reconnects,
    /// and ends when `ctx.stop` is cancelled (or a replay runs out of recorded sessions).
    fn run(settings: Self::Settings, ctx: DeviceContext) -> BoxFuture<'static, ()>;
}

/// A device kind as the registry holds it.
pub trait DriverKind: Sync {
    /// Its TOML `kind`.
    fn kind(&self) -> &'static str;
    /// Capture device names it replays.
    fn captures(&self) -> &'static [&'static str];
    /// Parses `[device.driver]` (without `kind`); errors go to `diag`.
    fn parse<'i>(
        &self,
        path: &str,
        node: &Node<'i>,
        diag: &mut Diagnostics<'i>,
    ) -> Option<DeviceDriver>;
    /// A driver for a capture of `capture` with no robot file.
    fn for_capture(&self, capture: &str) -> Option<DeviceDriver>;
}

/// A registry entry for a [`Driver`].
pub struct Kind<D>(PhantomData<fn() -> D>);

impl<D: Driver> Kind<D> {
    /// The entry.
    pub const ENTRY: Self = Self(PhantomData);
}

impl<D: Driver> DriverKind for Kind<D> {
    fn kind(&self) -> &'static str {
        D::KIND
    }

    fn captures(&self) -> &'static [&'static str] {
        D::CAPTURES
    }

    fn parse<'i>(
        &self,
        path: &str,
        node: &Node<'i>,
        diag: &mut Diagnostics<'i>,
    ) -> Option<DeviceDriver> {
        let settings: D::Settings = diag.deserialize(path, node)?;
        Some(DeviceDriver::new::<D>(settings))
    }

    fn for_capture(&self, capture: &str) -> Option<DeviceDriver> {
        D::for_capture(capture).map(DeviceDriver::new::<D>)
    }
}

/// Every device kind rfloc knows. Adding a kind: one module in `devices/` and one line here.
pub static REGISTRY: &[&dyn DriverKind] = &[
    &Kind::<aria::Aria>::ENTRY,
    &Kind::<kts::Kts>::ENTRY,
    &Kind::<alien::Alien>::ENTRY,
    &Kind::<xbee::Xbee>::ENTRY,
    &Kind::<urg::Urg>::ENTRY,
    &Kind::<stepper::Stepper>::ENTRY,
];

/// The registry entry of a `kind`.
#[must_use]
pub fn kind(name: &str) -> Option<&'static dyn DriverKind> {
    REGISTRY.iter().copied().find(|k| k.kind() == name)
}

/// The kinds, for messages.
#[must_use]
pub fn kind_names() -> Vec<&'static str> {
    REGISTRY.iter().map(|k| k.kind()).collect()
}

/// The registry entry that replays captures of `capture`.
#[must_use]
pub fn kind_for_capture(capture: &str) -> Option<&'static dyn DriverKind> {
    REGISTRY
        .iter()
        .copied()
        .find(|k| k.captures().contains(&capture))
}

/// A configured device: a kind with its settings.
#[derive(Clone)]
pub struct DeviceDriver {
    inner: Arc<dyn AnyDriver>,
}

impl fmt::Debug for DeviceDriver {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.inner.debug(f)
    }
}

trait AnyDriver: Send + Sync {
    fn kind(&self) -> &'static str;
    fn check(&self, checks: &mut Checks<'_, '_>, env: &CheckEnv<'_>);
    fn needs_link(&self) -> bool;
    fn capture_name(&self) -> &'static str;
    fn stale_after_s(&self) -> f64;
    fn replay_mode(&self) -> ReplayMode;
    fn replay_skips_unknown(&self) -> bool;
    fn handles(&self, request: &Request) -> bool;
    fn provide(&self, resources: &Resources);
    fn observes(&self) -> bool;
    fn run(&self, ctx: DeviceContext) -> BoxFuture<'static, ()>;
    fn as_any(&self) -> &dyn Any;
    fn debug(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result;
}

struct Bound<D: Driver>(D::Settings);

impl<D: Driver> AnyDriver for Bound<D> {
    fn kind(&self) -> &'static str {
        D::KIND
    }
    fn check(&self, checks: &mut Checks<'_, '_>, env: &CheckEnv<'_>) {
        D::check(&self.0, checks, env);
    }
    fn needs_link(&self) -> bool {
        D::needs_link(&self.0)
    }
    fn capture_name(&self) -> &'static str {
        D::capture_name(&self.0)
    }
    fn stale_after_s(&self) -> f64 {
        D::stale_after_s(&self.0)
    }
    fn replay_mode(&self) -> ReplayMode {
        D::replay_mode(&self.0)
    }
    fn replay_skips_unknown(&self) -> bool {
        D::replay_skips_unknown(&self.0)
    }
    fn handles(&self, request: &Request) -> bool {
        D::handles(&self.0, request)
    }
    fn provide(&self, resources: &Resources) {
        D::provide(&self.0, resources);
    }
    fn observes(&self) -> bool {
        D::observes(&self.0)
    }
    fn run(&self, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        D::run(self.0.clone(), ctx)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn debug(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {:?}", D::KIND, self.0)
    }
}

impl DeviceDriver {
    /// A device of kind `D`.
    #[must_use]
    pub fn new<D: Driver>(settings: D::Settings) -> Self {
        Self {
            inner: Arc::new(Bound::<D>(settings)),
        }
    }

    /// Its kind.
    #[must_use]
    pub fn kind(&self) -> &'static str {
        self.inner.kind()
    }

    /// Its settings, when it is of kind `D`.
    #[must_use]
    pub fn settings<D: Driver>(&self) -> Option<&D::Settings> {
        self.inner.as_any().downcast_ref::<Bound<D>>().map(|b| &b.0)
    }

    /// Runs the kind's checks.
    pub fn check(&self, checks: &mut Checks<'_, '_>, env: &CheckEnv<'_>) {
        self.inner.check(checks, env);
    }

    /// Whether it needs a link.
    #[must_use]
    pub fn needs_link(&self) -> bool {
        self.inner.needs_link()
    }

    /// The device name of its captures.
    #[must_use]
    pub fn capture_name(&self) -> &'static str {
        self.inner.capture_name()
    }

    /// Its default staleness limit, seconds.
    #[must_use]
    pub fn stale_after_s(&self) -> f64 {
        self.inner.stale_after_s()
    }

    /// How its recording is replayed.
    #[must_use]
    pub fn replay_mode(&self) -> ReplayMode {
        self.inner.replay_mode()
    }

    /// Whether its replay skips requests the recording does not hold.
    #[must_use]
    pub fn replay_skips_unknown(&self) -> bool {
        self.inner.replay_skips_unknown()
    }

    /// Whether it carries out `request`.
    #[must_use]
    pub fn handles(&self, request: &Request) -> bool {
        self.inner.handles(request)
    }

    /// Whether it sends observations (and can be stale).
    #[must_use]
    pub fn observes(&self) -> bool {
        self.inner.observes()
    }

    /// Offers what it lends to others.
    pub fn provide(&self, resources: &Resources) {
        self.inner.provide(resources);
    }

    /// Spawns its task on the current runtime, in a `device{name,driver}` span.
    #[must_use]
    pub fn spawn(&self, ctx: DeviceContext) -> JoinHandle<()> {
        let span = tracing::info_span!("device", name = %ctx.device.name, driver = self.kind());
        tokio::spawn(self.inner.run(ctx).instrument(span))
    }
}

/// After a failed connection step: reports `Reconnecting` with `detail` (and logs it), waits the
/// back-off of `attempt` and counts the attempt. False when the daemon stops meanwhile, or when
/// a replay has no further recorded session to reconnect to.
pub(crate) async fn retry_later(
    ctx: &DeviceContext,
    attempt: &mut u32,
    detail: impl Into<String>,
) -> bool {
    let detail = detail.into();
    if ctx.links_exhausted() {
        ctx.status(DeviceState::Closed, "end of recording").await;
        return false;
    }
    let wait = ctx.backoff.delay(*attempt, seed_of(ctx.name()));
    tracing::warn!(attempt = *attempt, wait_s = wait.as_secs_f64(), detail = %detail, "device not ready; retrying after back-off");
    ctx.status(DeviceState::Reconnecting, detail).await;
    let go_on = pause(ctx, wait).await;
    *attempt += 1;
    go_on
}

/// Waits `d` or until the daemon stops; false when stopping.
pub(crate) async fn pause(ctx: &DeviceContext, d: Duration) -> bool {
    tokio::select! {
        () = ctx.stop.cancelled() => false,
        () = tokio::time::sleep(d) => true,
    }
}

/// Pioneer client settings for a base running `time_scale` times faster than wall time. Periods
/// and timeouts are scaled; the link-loss and handshake timeouts keep their wall-time floors
/// (`rfloc_aria::ClientConfig::scaled`).
#[must_use]
pub fn scaled_base_config(
    clock: rfloc_transport::SharedClock,
    pulse_period_s: f64,
    time_scale: f64,
) -> rfloc_aria::ClientConfig {
    rfloc_aria::ClientConfig {
        pulse_period: crate::time::seconds(pulse_period_s.max(0.05)),
        clock: Some(clock),
        ..rfloc_aria::ClientConfig::default()
    }
    .scaled(time_scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_is_listed_once_and_owns_its_capture_names() {
        let names = kind_names();
        for (i, n) in names.iter().enumerate() {
            assert!(!names[i + 1..].contains(n), "{n} twice");
        }
        for k in REGISTRY {
            assert!(!k.captures().is_empty(), "{} has no capture name", k.kind());
            for c in k.captures() {
                assert_eq!(kind_for_capture(c).map(DriverKind::kind), Some(k.kind()));
            }
        }
    }
}
