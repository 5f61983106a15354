//! KTS RFIDM1356 13.56 MHz (HF, ISO 15693) RFID reader: a sans-IO line codec, an async client
//! and a device emulator.
//!
//! - [`LineFramer`] and [`parse_line`] (through [`KtsCodec`]) turn bytes into typed
//!   [`KtsLine`]s; [`KtsCommand`] turns commands into bytes. No I/O.
//! - [`KtsClient`] drives a reader over any `AsyncRead + AsyncWrite` (a serial port in the
//!   daemon) and delivers timestamped [`TagEvent`]s on a tokio channel; it implements
//!   [`TagEventSource`].
//! - [`KtsEmulator`] plays the reader over any such stream, reporting the tags of a
//!   [`TagGrid`] under an antenna whose position a closure supplies, with the seed's
//!   RSSI↔distance relation ([`rssi_table`]).
//!
//! The wire dialect is reconstructed from secondary sources; see `docs/protocols/kts-rfidm1356.md`.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod client;
mod codec;
mod command;
#[cfg(feature = "emulator")]
mod emulator;
mod event;
mod framing;
mod line;
pub mod rssi_table;
mod uid;

pub use client::{KtsClient, KtsClientError, KtsConfig, KtsStats, TagEventSource, DEFAULT_BAUD};
pub use codec::{CodecStats, KtsCodec};
pub use command::KtsCommand;
#[cfg(feature = "emulator")]
pub use emulator::{
    EmulatorConfig, KtsEmulator, RssiFn, ScanControl, ScanStep, TagGrid, UidScheme,
};
pub use event::{TagEvent, TagEventKind};
pub use framing::{FramedLine, LineFramer, MAX_LINE_LEN};
pub use line::{parse_line, KtsLine, MalformedLine, MalformedReason, Rssi};
pub use uid::{Uid, UidError, UidKind};
