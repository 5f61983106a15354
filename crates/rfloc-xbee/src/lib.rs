//! XBee API-mode driver: a sans-IO frame codec for AP=1 and AP=2, typed frames, `ND` (node
//! discovery) records, an async client over any byte stream, a [`BeaconRadio`] capability trait for the
//! bearing scan, and a coordinator emulator that serves the same protocol.
//!
//! Layers, bottom up:
//! - [`codec`]: start delimiter, length, checksum, escaping, resynchronisation ([`FrameDecoder`]).
//! - [`frame`]: frame data ⇄ [`Frame`].
//! - [`nd`]: `ND` records ⇄ [`Node`].
//! - [`client`]: [`XBeeClient`] over `AsyncRead + AsyncWrite`.
//! - [`emulator`]: [`CoordinatorEmulator`] serving beacons whose RSSI comes from a function.
//!
//! ```
//! use std::sync::Arc;
//! use rfloc_xbee::{
//!     ApiMode, Beacon, ClientConfig, CoordinatorEmulator, EmulatorConfig, RssiFn, BeaconRadio,
//!     XBeeClient,
//! };
//!
//! # #[tokio::main(flavor = "current_thread")]
//! # async fn main() -> Result<(), rfloc_xbee::XBeeError> {
//! // Two beacons; the second one is not heard.
//! let rssi: RssiFn = Arc::new(|beacon_index| (beacon_index == 0).then_some(-61.0));
//! let emulator = CoordinatorEmulator::new(
//!     vec![Beacon::numbered(1), Beacon::numbered(2)],
//!     rssi,
//!     EmulatorConfig { mode: ApiMode::Escaped, ..EmulatorConfig::default() },
//! );
//! // Any byte stream works: a pty from tokio_serial::SerialStream::pair(), TCP, or in memory.
//! let (host, device) = tokio::io::duplex(4096);
//! tokio::spawn(async move { emulator.serve(device).await });
//!
//! let mut client = XBeeClient::new(host, ClientConfig::default()); // AP=2 by default
//! let nodes = client.discover_nodes().await?;
//! assert_eq!(nodes.len(), 1);
//! assert_eq!(nodes[0].ni, "beacon1");
//! assert_eq!(client.node_rssi(nodes[0].address).await?, Some(-61.0));
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

pub mod address;
pub mod client;
pub mod codec;
#[cfg(feature = "emulator")]
pub mod emulator;
mod fields;
pub mod frame;
pub mod nd;
pub mod probe;

pub use address::{Address16, Address64};
pub use client::{
    ClientConfig, ClientStats, DiscoveryEnd, NodeDiscovery, RssiSource, XBeeClient, XBeeError,
};
pub use codec::{
    checksum, encode_frame, ApiMode, DecodeError, DecodeStats, EncodeError, FrameDecoder,
};
#[cfg(feature = "emulator")]
pub use emulator::{
    Beacon, CoordinatorEmulator, EmulatorConfig, EmulatorStats, Flavor, RssiFn,
    S2C_HARDWARE_VERSION,
};
pub use frame::{
    AtCommand, AtCommandName, AtResponse, AtStatus, ExplicitReceive, Frame, FrameError,
    ModemStatus, NodeIdentification, ReceivePacket, RemoteAtCommand, RemoteAtResponse,
    TransmitRequest, TransmitStatus,
};
pub use nd::{rssi_byte_to_dbm, DeviceType, NdError, NdLayout, NdLayoutHint, Node};
pub use probe::BeaconRadio;
