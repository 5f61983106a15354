//! Byte transports for rfloc device drivers.
//!
//! Every driver talks to its device through a [`Transport`]: a boxed `AsyncRead + AsyncWrite`.
//! This crate is the one place where links are opened from configuration ([`open`]), and it
//! provides the test doubles that stand in for a link:
//!
//! - [`serial`] and [`tcp`]: real links (one file per transport);
//! - [`MockTransport`]: a scripted expect-write / reply double for unit tests;
//! - [`Recorder`]: wraps a live link and writes every read and write to a capture file;
//! - [`replay::Replayer`]: turns a capture back into a link, either streaming the recorded `rx`
//!   bytes or answering the driver's n-th request with the n-th recorded reply;
//! - [`Clock`]: where drivers take timestamps from, so a replay can run on the recorded clock;
//! - [`StampedLink`]: every read stamped once on the run clock (and recorded at
//!   that reading), the time a driver gives the observations it decodes from those bytes.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod clock;
mod error;
mod link;
mod log_limit;
mod mock;
mod recorder;
pub mod replay;
pub mod serial;
mod stamp;
pub mod tcp;

use tokio::io::{AsyncRead, AsyncWrite};

pub use clock::{Clock, ManualClock, MonotonicClock, SharedClock};
pub use error::TransportError;
pub use link::{open, DataBits, FlowControl, LinkConfig, Parity, SerialLink, StopBits, TcpLink};
pub use log_limit::LogLimit;
pub use mock::{MockTransport, MockTransportBuilder};
pub use recorder::{CaptureSink, Recorder, REDACTED};
pub use stamp::{clock_ns, StampedLink};

/// A bidirectional byte stream to a device.
pub trait DeviceIo: AsyncRead + AsyncWrite + Send + Unpin + std::fmt::Debug {}

impl<T: AsyncRead + AsyncWrite + Send + Unpin + std::fmt::Debug> DeviceIo for T {}

/// An opened device link.
pub type Transport = Box<dyn DeviceIo>;
