//! Typed API frames: parsing frame data (type byte first) into [`Frame`] and back.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::address::{Address16, Address64};
use crate::codec::{encode_frame, ApiMode, EncodeError, HexBytes};
use crate::fields::FieldReader;
use crate::nd::{NdError, NdLayoutHint, Node};

/// Frame type bytes handled by [`Frame`].
pub mod types {
    /// AT Command.
    pub const AT_COMMAND: u8 = 0x08;
    /// AT Command – Queue Parameter Value.
    pub const AT_COMMAND_QUEUED: u8 = 0x09;
    /// Zigbee Transmit Request.
    pub const TRANSMIT_REQUEST: u8 = 0x10;
    /// Remote AT Command Request.
    pub const REMOTE_AT_COMMAND: u8 = 0x17;
    /// AT Command Response.
    pub const AT_RESPONSE: u8 = 0x88;
    /// Modem Status.
    pub const MODEM_STATUS: u8 = 0x8A;
    /// Zigbee Transmit Status.
    pub const TRANSMIT_STATUS: u8 = 0x8B;
    /// Zigbee Receive Packet (AO=0).
    pub const RECEIVE_PACKET: u8 = 0x90;
    /// Zigbee Explicit Rx Indicator (AO≠0).
    pub const EXPLICIT_RECEIVE: u8 = 0x91;
    /// Node Identification Indicator.
    pub const NODE_IDENTIFICATION: u8 = 0x95;
    /// Remote AT Command Response.
    pub const REMOTE_AT_RESPONSE: u8 = 0x97;
}

/// A two-letter AT command such as `ND` or `DB`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct AtCommandName(pub [u8; 2]);

impl AtCommandName {
    /// Node Discover.
    pub const ND: AtCommandName = AtCommandName(*b"ND");
    /// Node Discover Timeout (units of 100 ms).
    pub const NT: AtCommandName = AtCommandName(*b"NT");
    /// Received signal strength of the last packet, in -dBm.
    pub const DB: AtCommandName = AtCommandName(*b"DB");
    /// Node Identifier.
    pub const NI: AtCommandName = AtCommandName(*b"NI");
    /// Network Discovery Options.
    pub const NO: AtCommandName = AtCommandName(*b"NO");
    /// API mode.
    pub const AP: AtCommandName = AtCommandName(*b"AP");
    /// Serial number high.
    pub const SH: AtCommandName = AtCommandName(*b"SH");
    /// Serial number low.
    pub const SL: AtCommandName = AtCommandName(*b"SL");
}

impl fmt::Display for AtCommandName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for b in self.0 {
            if b.is_ascii_graphic() {
                write!(f, "{}", char::from(b))?;
            } else {
                write!(f, "\\x{b:02X}")?;
            }
        }
        Ok(())
    }
}

impl fmt::Debug for AtCommandName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AtCommandName({self})")
    }
}

/// Status of an AT command response, from the low nibble of the status byte (DigiMesh uses the
/// high nibble for flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AtStatus {
    /// 0: OK.
    Ok,
    /// 1: ERROR.
    Error,
    /// 2: invalid command.
    InvalidCommand,
    /// 3: invalid parameter.
    InvalidParameter,
    /// 4: transmission failure (for a remote command: the remote did not answer).
    TxFailure,
    /// 0x0B: no secure session.
    NoSecureSession,
    /// 0x0C: encryption error.
    EncryptionError,
    /// 0x0D: command sent insecurely.
    SentInsecurely,
    /// Any other low nibble.
    Other(u8),
}

impl AtStatus {
    /// Decodes a status byte (`byte & 0x0F`).
    pub fn from_byte(byte: u8) -> Self {
        match byte & 0x0F {
            0 => AtStatus::Ok,
            1 => AtStatus::Error,
            2 => AtStatus::InvalidCommand,
            3 => AtStatus::InvalidParameter,
            4 => AtStatus::TxFailure,
            0x0B => AtStatus::NoSecureSession,
            0x0C => AtStatus::EncryptionError,
            0x0D => AtStatus::SentInsecurely,
            other => AtStatus::Other(other),
        }
    }
}

/// 0x08 / 0x09: a local AT command.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtCommand {
    /// Frame ID; 0 asks for no response.
    pub frame_id: u8,
    /// The command.
    pub command: AtCommandName,
    /// Parameter bytes; empty to query.
    pub parameter: Vec<u8>,
    /// `true` for 0x09 (queue the value until `AC` or the next 0x08).
    pub queued: bool,
}

/// 0x17: an AT command for a remote radio.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteAtCommand {
    /// Frame ID; 0 asks for no response.
    pub frame_id: u8,
    /// 64-bit destination.
    pub destination: Address64,
    /// 16-bit destination, 0xFFFE if unknown.
    pub destination16: Address16,
    /// Remote command options (0x02 = apply changes).
    pub options: u8,
    /// The command.
    pub command: AtCommandName,
    /// Parameter bytes; empty to query.
    pub parameter: Vec<u8>,
}

/// 0x88: response to a local AT command.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtResponse {
    /// Frame ID copied from the command.
    pub frame_id: u8,
    /// The command answered.
    pub command: AtCommandName,
    /// Status byte as received; see [`AtResponse::status`].
    pub status_byte: u8,
    /// Command data (empty when a register was set, or for the end of `ND`).
    pub data: Vec<u8>,
}

impl AtResponse {
    /// The decoded status.
    pub fn status(&self) -> AtStatus {
        AtStatus::from_byte(self.status_byte)
    }
}

/// 0x97: response to a remote AT command.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteAtResponse {
    /// Frame ID copied from the request.
    pub frame_id: u8,
    /// 64-bit address of the remote.
    pub source: Address64,
    /// 16-bit address of the remote.
    pub source16: Address16,
    /// The command answered.
    pub command: AtCommandName,
    /// Status byte as received; see [`RemoteAtResponse::status`].
    pub status_byte: u8,
    /// Command data.
    pub data: Vec<u8>,
}

impl RemoteAtResponse {
    /// The decoded status.
    pub fn status(&self) -> AtStatus {
        AtStatus::from_byte(self.status_byte)
    }
}

/// 0x8A: modem status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModemStatus {
    /// Status code: 0 hardware reset, 1 watchdog reset, 2 joined, 3 disassociated,
    /// 6 coordinator started, …; ≥ 0x80 stack error.
    pub status: u8,
}

/// 0x10: Zigbee transmit request.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransmitRequest {
    /// Frame ID; 0 asks for no 0x8B.
    pub frame_id: u8,
    /// 64-bit destination.
    pub destination: Address64,
    /// 16-bit destination.
    pub destination16: Address16,
    /// Broadcast radius (0 = maximum hops).
    pub broadcast_radius: u8,
    /// Transmit options.
    pub options: u8,
    /// RF payload.
    pub data: Vec<u8>,
}

/// 0x8B: Zigbee transmit status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransmitStatus {
    /// Frame ID of the request.
    pub frame_id: u8,
    /// 16-bit address delivered to.
    pub destination16: Address16,
    /// Transmit retry count.
    pub retry_count: u8,
    /// Delivery status (0 = success).
    pub delivery_status: u8,
    /// Discovery status.
    pub discovery_status: u8,
}

/// 0x90: Zigbee receive packet.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReceivePacket {
    /// 64-bit source.
    pub source: Address64,
    /// 16-bit source.
    pub source16: Address16,
    /// Receive options.
    pub options: u8,
    /// RF payload.
    pub data: Vec<u8>,
}

/// 0x91: Zigbee explicit receive indicator.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExplicitReceive {
    /// 64-bit source.
    pub source: Address64,
    /// 16-bit source.
    pub source16: Address16,
    /// Source endpoint.
    pub source_endpoint: u8,
    /// Destination endpoint.
    pub destination_endpoint: u8,
    /// Cluster ID.
    pub cluster_id: u16,
    /// Profile ID.
    pub profile_id: u16,
    /// Receive options.
    pub options: u8,
    /// RF payload.
    pub data: Vec<u8>,
}

/// 0x95: node identification indicator.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeIdentification {
    /// 64-bit address of the sender.
    pub sender: Address64,
    /// 16-bit address of the sender.
    pub sender16: Address16,
    /// Receive options.
    pub options: u8,
    /// The node record from frame offset 15 on (same layout as an `ND` response); see
    /// [`NodeIdentification::node`].
    pub record: Vec<u8>,
}

impl NodeIdentification {
    /// Parses the record with the Zigbee/DigiMesh `ND` layout.
    pub fn node(&self) -> Result<Node, NdError> {
        Node::parse(&self.record, NdLayoutHint::ZigbeeOrDigiMesh)
    }
}

/// One API frame.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Frame {
    /// 0x08 or 0x09.
    AtCommand(AtCommand),
    /// 0x17.
    RemoteAtCommand(RemoteAtCommand),
    /// 0x88.
    AtResponse(AtResponse),
    /// 0x97.
    RemoteAtResponse(RemoteAtResponse),
    /// 0x8A.
    ModemStatus(ModemStatus),
    /// 0x10.
    TransmitRequest(TransmitRequest),
    /// 0x8B.
    TransmitStatus(TransmitStatus),
    /// 0x90.
    ReceivePacket(ReceivePacket),
    /// 0x91.
    ExplicitReceive(ExplicitReceive),
    /// 0x95.
    NodeIdentification(NodeIdentification),
    /// Any other frame type, kept as received.
    Unknown {
        /// The type byte.
        frame_type: u8,
        /// Frame data after the type byte.
        data: Vec<u8>,
    },
}

/// Frame data that does not fit the layout of its type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// No bytes at all.
    #[error("empty frame data")]
    Empty,
    /// Shorter than the fixed fields of its type.
    #[error("frame type {frame_type:02X} too short ({} bytes): {}", .frame_data.len(), HexBytes(.frame_data))]
    TooShort {
        /// The type byte.
        frame_type: u8,
        /// The whole frame data.
        frame_data: Vec<u8>,
    },
}

impl Frame {
    /// Parses frame data (type byte first, no checksum).
    pub fn parse(frame_data: &[u8]) -> Result<Frame, FrameError> {
        let (&frame_type, body) = frame_data.split_first().ok_or(FrameError::Empty)?;
        let mut r = FieldReader::new(body);
        Self::parse_body(frame_type, &mut r).ok_or_else(|| FrameError::TooShort {
            frame_type,
            frame_data: frame_data.to_vec(),
        })
    }

    fn parse_body(frame_type: u8, r: &mut FieldReader<'_>) -> Option<Frame> {
        use types as t;
        let frame = match frame_type {
            t::AT_COMMAND | t::AT_COMMAND_QUEUED => Frame::AtCommand(AtCommand {
                frame_id: r.u8()?,
                command: AtCommandName(r.array()?),
                parameter: r.take_rest().to_vec(),
                queued: frame_type == t::AT_COMMAND_QUEUED,
            }),
            t::REMOTE_AT_COMMAND => Frame::RemoteAtCommand(RemoteAtCommand {
                frame_id: r.u8()?,
                destination: r.address64()?,
                destination16: r.address16()?,
                options: r.u8()?,
                command: AtCommandName(r.array()?),
                parameter: r.take_rest().to_vec(),
            }),
            t::AT_RESPONSE => Frame::AtResponse(AtResponse {
                frame_id: r.u8()?,
                command: AtCommandName(r.array()?),
                status_byte: r.u8()?,
                data: r.take_rest().to_vec(),
            }),
            t::REMOTE_AT_RESPONSE => Frame::RemoteAtResponse(RemoteAtResponse {
                frame_id: r.u8()?,
                source: r.address64()?,
                source16: r.address16()?,
                command: AtCommandName(r.array()?),
                status_byte: r.u8()?,
                data: r.take_rest().to_vec(),
            }),
            t::MODEM_STATUS => Frame::ModemStatus(ModemStatus { status: r.u8()? }),
            t::TRANSMIT_REQUEST => Frame::TransmitRequest(TransmitRequest {
                frame_id: r.u8()?,
                destination: r.address64()?,
                destination16: r.address16()?,
                broadcast_radius: r.u8()?,
                options: r.u8()?,
                data: r.take_rest().to_vec(),
            }),
            t::TRANSMIT_STATUS => Frame::TransmitStatus(TransmitStatus {
                frame_id: r.u8()?,
                destination16: r.address16()?,
                retry_count: r.u8()?,
                delivery_status: r.u8()?,
                discovery_status: r.u8()?,
            }),
            t::RECEIVE_PACKET => Frame::ReceivePacket(ReceivePacket {
                source: r.address64()?,
                source16: r.address16()?,
                options: r.u8()?,
                data: r.take_rest().to_vec(),
            }),
            t::EXPLICIT_RECEIVE => Frame::ExplicitReceive(ExplicitReceive {
                source: r.address64()?,
                source16: r.address16()?,
                source_endpoint: r.u8()?,
                destination_endpoint: r.u8()?,
                cluster_id: r.u16()?,
                profile_id: r.u16()?,
                options: r.u8()?,
                data: r.take_rest().to_vec(),
            }),
            t::NODE_IDENTIFICATION => Frame::NodeIdentification(NodeIdentification {
                sender: r.address64()?,
                sender16: r.address16()?,
                options: r.u8()?,
                record: r.take_rest().to_vec(),
            }),
            other => Frame::Unknown {
                frame_type: other,
                data: r.take_rest().to_vec(),
            },
        };
        // Fixed-size frames (0x8A, 0x8B) may carry trailing bytes from newer firmware; they are
        // ignored, as the manuals allow new fields to be appended.
        Some(frame)
    }

    /// The frame type byte.
    pub fn frame_type(&self) -> u8 {
        use types as t;
        match self {
            Frame::AtCommand(c) if c.queued => t::AT_COMMAND_QUEUED,
            Frame::AtCommand(_) => t::AT_COMMAND,
            Frame::RemoteAtCommand(_) => t::REMOTE_AT_COMMAND,
            Frame::AtResponse(_) => t::AT_RESPONSE,
            Frame::RemoteAtResponse(_) => t::REMOTE_AT_RESPONSE,
            Frame::ModemStatus(_) => t::MODEM_STATUS,
            Frame::TransmitRequest(_) => t::TRANSMIT_REQUEST,
            Frame::TransmitStatus(_) => t::TRANSMIT_STATUS,
            Frame::ReceivePacket(_) => t::RECEIVE_PACKET,
            Frame::ExplicitReceive(_) => t::EXPLICIT_RECEIVE,
            Frame::NodeIdentification(_) => t::NODE_IDENTIFICATION,
            Frame::Unknown { frame_type, .. } => *frame_type,
        }
    }

    /// The frame ID, for frame types that carry one.
    pub fn frame_id(&self) -> Option<u8> {
        match self {
            Frame::AtCommand(c) => Some(c.frame_id),
            Frame::RemoteAtCommand(c) => Some(c.frame_id),
            Frame::AtResponse(r) => Some(r.frame_id),
            Frame::RemoteAtResponse(r) => Some(r.frame_id),
            Frame::TransmitRequest(r) => Some(r.frame_id),
            Frame::TransmitStatus(s) => Some(s.frame_id),
            _ => None,
        }
    }

    /// The frame data (type byte first, no checksum).
    pub fn to_frame_data(&self) -> Vec<u8> {
        let mut out = vec![self.frame_type()];
        match self {
            Frame::AtCommand(c) => {
                out.push(c.frame_id);
                out.extend_from_slice(&c.command.0);
                out.extend_from_slice(&c.parameter);
            }
            Frame::RemoteAtCommand(c) => {
                out.push(c.frame_id);
                out.extend_from_slice(&c.destination.to_bytes());
                out.extend_from_slice(&c.destination16.to_bytes());
                out.push(c.options);
                out.extend_from_slice(&c.command.0);
                out.extend_from_slice(&c.parameter);
            }
            Frame::AtResponse(r) => {
                out.push(r.frame_id);
                out.extend_from_slice(&r.command.0);
                out.push(r.status_byte);
                out.extend_from_slice(&r.data);
            }
            Frame::RemoteAtResponse(r) => {
                out.push(r.frame_id);
                out.extend_from_slice(&r.source.to_bytes());
                out.extend_from_slice(&r.source16.to_bytes());
                out.extend_from_slice(&r.command.0);
                out.push(r.status_byte);
                out.extend_from_slice(&r.data);
            }
            Frame::ModemStatus(s) => out.push(s.status),
            Frame::TransmitRequest(r) => {
                out.push(r.frame_id);
                out.extend_from_slice(&r.destination.to_bytes());
                out.extend_from_slice(&r.destination16.to_bytes());
                out.push(r.broadcast_radius);
                out.push(r.options);
                out.extend_from_slice(&r.data);
            }
            Frame::TransmitStatus(s) => {
                out.push(s.frame_id);
                out.extend_from_slice(&s.destination16.to_bytes());
                out.extend_from_slice(&[s.retry_count, s.delivery_status, s.discovery_status]);
            }
            Frame::ReceivePacket(r) => {
                out.extend_from_slice(&r.source.to_bytes());
                out.extend_from_slice(&r.source16.to_bytes());
                out.push(r.options);
                out.extend_from_slice(&r.data);
            }
            Frame::ExplicitReceive(r) => {
                out.extend_from_slice(&r.source.to_bytes());
                out.extend_from_slice(&r.source16.to_bytes());
                out.extend_from_slice(&[r.source_endpoint, r.destination_endpoint]);
                out.extend_from_slice(&r.cluster_id.to_be_bytes());
                out.extend_from_slice(&r.profile_id.to_be_bytes());
                out.push(r.options);
                out.extend_from_slice(&r.data);
            }
            Frame::NodeIdentification(n) => {
                out.extend_from_slice(&n.sender.to_bytes());
                out.extend_from_slice(&n.sender16.to_bytes());
                out.push(n.options);
                out.extend_from_slice(&n.record);
            }
            Frame::Unknown { data, .. } => out.extend_from_slice(data),
        }
        out
    }

    /// The complete wire bytes of this frame in `mode`.
    pub fn encode(&self, mode: ApiMode) -> Result<Vec<u8>, EncodeError> {
        encode_frame(&self.to_frame_data(), mode)
    }
}
