//! XBee API-mode driver: a sans-IO frame codec for AP=1 and AP=2, typed frames, `ND` (node
//! discovery) records, an async client over any byte stream, an [`RssiProbe`] trait for the
//! bearing scan, and a coordinator emulator that serves the same protocol.
//!
//! Layers, bottom up:
//! - [`codec`]: start delimiter, length, checksum, escaping, resynchronisation ([`FrameDecoder`]).
//! - [`frame`]: frame data ⇄ [`Frame`].
//! - [`nd`]: `ND` records ⇄ [`Node`].
//! - [`client`]: [`XBeeClient`] over `AsyncRead + AsyncWrite`.
//! - [`emulator`]: [`CoordinatorEmulator`] serving beacons whose RSSI comes from a function.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

pub mod address;
pub mod client;
pub mod codec;
pub mod emulator;
mod fields;
pub mod frame;
pub mod nd;
pub mod probe;

pub use address::{Address16, Address64};
pub use client::{ClientConfig, ClientStats, DiscoveryEnd, NodeDiscovery, XBeeClient, XBeeError};
pub use codec::{
    checksum, encode_frame, ApiMode, DecodeError, DecodeStats, EncodeError, FrameDecoder,
};
pub use emulator::{Beacon, CoordinatorEmulator, EmulatorConfig, EmulatorStats, RssiFn};
pub use frame::{
    AtCommand, AtCommandName, AtResponse, AtStatus, ExplicitReceive, Frame, FrameError,
    ModemStatus, NodeIdentification, ReceivePacket, RemoteAtCommand, RemoteAtResponse,
    TransmitRequest, TransmitStatus,
};
pub use nd::{DeviceType, NdError, NdLayout, NdLayoutHint, Node};
pub use probe::RssiProbe;
