//! Hokuyo URG laser range finder (URG-04LX and kin) speaking SCIP 2.0: a sans-IO codec, an
//! async client and an emulator.
//!
//! - [`encoding`]: the 2/3/4-character encodings and the line check sum.
//! - [`Command`] → bytes; bytes → [`Reply`] through [`ReplyDecoder`], which resynchronises at
//!   the next empty line after a damaged reply; [`Scan::from_reply`] reads `GD` data.
//! - [`UrgClient`] over any `AsyncRead + AsyncWrite` (a USB-CDC serial port on a robot).
//! - [`UrgEmulator`] answers the URG-04LX's SCIP 2.0 commands (`SCIP2.0`, `VV`, `PP`, `II`,
//!   `BM`, `QT`, `RS`, `TM`, `GD`/`GS`, `MD`/`MS`) and `%ST`, ranges from a function of the
//!   angle.
#![forbid(unsafe_code)]

pub mod client;
pub mod command;
#[cfg(feature = "emulator")]
pub mod emulator;
pub mod encoding;
pub mod error;
pub mod reply;
pub mod scan;

pub use client::{geometry_from_parameters, SensorInfo, UrgClient, UrgConfig};
pub use command::Command;
#[cfg(feature = "emulator")]
pub use emulator::{ClockFn, EmulatorConfig, EmulatorStats, RangeFn, SensorIdentity, UrgEmulator};
pub use error::ScipError;
pub use reply::{DecodeStats, Reply, ReplyDecoder};
pub use scan::{Scan, UrgGeometry};
