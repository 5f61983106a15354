//! `ND` (Node Discover) response records and the same record inside 0x95 frames.
//!
//! Two layouts exist. Zigbee and DigiMesh:
//! `MY(2) SH(4) SL(4) NI..0x00 PARENT(2) DEVICE_TYPE(1) STATUS(1) PROFILE(2) MANUFACTURER(2)`
//! followed by nothing, RSSI(1), DD(4) or DD(4)+RSSI(1). 802.15.4:
//! `MY(2) SH(4) SL(4) DB(1) NI..0x00` with nothing after the NUL.

use serde::{Deserialize, Serialize};

use crate::address::{Address16, Address64};
use crate::codec::HexBytes;
use crate::fields::FieldReader;

/// Which record layout a [`Node`] was parsed with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NdLayout {
    /// Zigbee and DigiMesh: NI right after SL, then parent, type, status, profile, manufacturer.
    ZigbeeOrDigiMesh,
    /// 802.15.4: a DB (RSSI) byte after SL, then NI, nothing after the NUL.
    Ieee802154,
}

/// Which layout to expect when parsing a record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum NdLayoutHint {
    /// Decide from the record: if it ends right at the first NUL at or after byte 10 it is
    /// 802.15.4, otherwise Zigbee/DigiMesh; if that fails, the other layout is tried.
    #[default]
    Auto,
    /// Always Zigbee/DigiMesh.
    ZigbeeOrDigiMesh,
    /// Always 802.15.4.
    Ieee802154,
}

/// Device type field of a Zigbee/DigiMesh record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DeviceType {
    /// 0.
    Coordinator,
    /// 1.
    Router,
    /// 2.
    EndDevice,
    /// Any other value.
    Other(u8),
}

impl DeviceType {
    /// Decodes the device type byte.
    pub fn from_byte(byte: u8) -> Self {
        match byte {
            0 => DeviceType::Coordinator,
            1 => DeviceType::Router,
            2 => DeviceType::EndDevice,
            other => DeviceType::Other(other),
        }
    }

    /// The device type byte.
    pub fn to_byte(self) -> u8 {
        match self {
            DeviceType::Coordinator => 0,
            DeviceType::Router => 1,
            DeviceType::EndDevice => 2,
            DeviceType::Other(b) => b,
        }
    }
}

/// An `ND` record that could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NdError {
    /// Shorter than the fixed fields.
    #[error("ND record too short ({} bytes): {}", .record.len(), HexBytes(.record))]
    TooShort {
        /// The record.
        record: Vec<u8>,
    },
    /// No NUL terminating NI.
    #[error("ND record without NI terminator: {}", HexBytes(.record))]
    MissingNiTerminator {
        /// The record.
        record: Vec<u8>,
    },
    /// The bytes after MANUFACTURER_ID (Zigbee/DigiMesh) or after the NUL (802.15.4) are not
    /// one of the documented optional tails.
    #[error("ND record with an unexpected {tail_len}-byte tail: {}", HexBytes(.record))]
    UnexpectedTail {
        /// Number of bytes left over.
        tail_len: usize,
        /// The record.
        record: Vec<u8>,
    },
}

/// One node as reported by `ND` (or by a 0x95 frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// Layout the record had.
    pub layout: NdLayout,
    /// `MY` (0xFFFE on DigiMesh).
    pub network_address: Address16,
    /// `SH`:`SL`.
    pub address: Address64,
    /// Node identifier (`NI`), decoded as UTF-8 with invalid bytes replaced.
    pub ni: String,
    /// Parent network address (Zigbee/DigiMesh only; 0xFFFE = none).
    pub parent: Option<Address16>,
    /// Device type (Zigbee/DigiMesh only).
    pub device_type: Option<DeviceType>,
    /// Status byte, "reserved" (Zigbee/DigiMesh only).
    pub status: Option<u8>,
    /// Profile ID, 0xC105 on Digi parts (Zigbee/DigiMesh only).
    pub profile_id: Option<u16>,
    /// Manufacturer ID, 0x101E on Digi parts (Zigbee/DigiMesh only).
    pub manufacturer_id: Option<u16>,
    /// Digi device type `DD`, present when the responder has `NO & 0x01`.
    pub digi_device_type: Option<u32>,
    /// RSSI byte as sent: the 802.15.4 DB byte, or the "RSSI of last hop" byte (`NO & 0x04`).
    pub rssi_raw: Option<u8>,
}

impl Node {
    /// Parses one record (the command data of a 0x88/0x97 `ND` response).
    pub fn parse(record: &[u8], hint: NdLayoutHint) -> Result<Node, NdError> {
        match hint {
            NdLayoutHint::ZigbeeOrDigiMesh => Self::parse_zigbee(record),
            NdLayoutHint::Ieee802154 => Self::parse_802154(record),
            NdLayoutHint::Auto => {
                let ends_at_first_nul = record
                    .get(10..)
                    .and_then(|tail| tail.iter().position(|b| *b == 0))
                    .is_some_and(|pos| pos + 11 == record.len());
                if ends_at_first_nul {
                    Self::parse_802154(record)
                        .or_else(|e| Self::parse_zigbee(record).map_err(|_| e))
                } else {
                    Self::parse_zigbee(record)
                        .or_else(|e| Self::parse_802154(record).map_err(|_| e))
                }
            }
        }
    }

    fn parse_zigbee(record: &[u8]) -> Result<Node, NdError> {
        let too_short = || NdError::TooShort {
            record: record.to_vec(),
        };
        let mut r = FieldReader::new(record);
        let network_address = r.address16().ok_or_else(too_short)?;
        let address = r.address64().ok_or_else(too_short)?;
        let ni = r.until_nul().ok_or_else(|| NdError::MissingNiTerminator {
            record: record.to_vec(),
        })?;
        let parent = r.address16().ok_or_else(too_short)?;
        let device_type = r.u8().ok_or_else(too_short)?;
        let status = r.u8().ok_or_else(too_short)?;
        let profile_id = r.u16().ok_or_else(too_short)?;
        let manufacturer_id = r.u16().ok_or_else(too_short)?;
        let tail_len = r.remaining().len();
        let (digi_device_type, rssi_raw) = match tail_len {
            0 => (None, None),
            1 => (None, r.u8()),
            4 => (r.u32(), None),
            5 => (r.u32(), r.u8()),
            _ => {
                return Err(NdError::UnexpectedTail {
                    tail_len,
                    record: record.to_vec(),
                })
            }
        };
        Ok(Node {
            layout: NdLayout::ZigbeeOrDigiMesh,
            network_address,
            address,
            ni: String::from_utf8_lossy(ni).into_owned(),
            parent: Some(parent),
            device_type: Some(DeviceType::from_byte(device_type)),
            status: Some(status),
            profile_id: Some(profile_id),
            manufacturer_id: Some(manufacturer_id),
            digi_device_type,
            rssi_raw,
        })
    }

    fn parse_802154(record: &[u8]) -> Result<Node, NdError> {
        let too_short = || NdError::TooShort {
            record: record.to_vec(),
        };
        let mut r = FieldReader::new(record);
        let network_address = r.address16().ok_or_else(too_short)?;
        let address = r.address64().ok_or_else(too_short)?;
        let db = r.u8().ok_or_else(too_short)?;
        let ni = r.until_nul().ok_or_else(|| NdError::MissingNiTerminator {
            record: record.to_vec(),
        })?;
        let tail_len = r.remaining().len();
        if tail_len != 0 {
            return Err(NdError::UnexpectedTail {
                tail_len,
                record: record.to_vec(),
            });
        }
        Ok(Node {
            layout: NdLayout::Ieee802154,
            network_address,
            address,
            ni: String::from_utf8_lossy(ni).into_owned(),
            parent: None,
            device_type: None,
            status: None,
            profile_id: None,
            manufacturer_id: None,
            digi_device_type: None,
            rssi_raw: Some(db),
        })
    }

    /// RSSI in dBm, from [`Node::rssi_raw`] read as "positive number = −dBm" (the `DB`
    /// convention). A raw byte ≥ 0x80 is read as a two's-complement dBm value instead, since
    /// one XBee 3 802.15.4 manual describes that encoding and −128 dBm or weaker is not a
    /// receivable level.
    pub fn rssi_dbm(&self) -> Option<f64> {
        self.rssi_raw.map(rssi_byte_to_dbm)
    }

    /// Serialises the record back to the layout it names (used by the emulator).
    pub fn to_record(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(32);
        out.extend_from_slice(&self.network_address.to_bytes());
        out.extend_from_slice(&self.address.to_bytes());
        match self.layout {
            NdLayout::Ieee802154 => {
                out.push(self.rssi_raw.unwrap_or(0));
                out.extend_from_slice(self.ni.as_bytes());
                out.push(0);
            }
            NdLayout::ZigbeeOrDigiMesh => {
                out.extend_from_slice(self.ni.as_bytes());
                out.push(0);
                out.extend_from_slice(&self.parent.unwrap_or(Address16::UNKNOWN).to_bytes());
                out.push(self.device_type.unwrap_or(DeviceType::Router).to_byte());
                out.push(self.status.unwrap_or(0));
                out.extend_from_slice(&self.profile_id.unwrap_or(DIGI_PROFILE_ID).to_be_bytes());
                out.extend_from_slice(
                    &self
                        .manufacturer_id
                        .unwrap_or(DIGI_MANUFACTURER_ID)
                        .to_be_bytes(),
                );
                if let Some(dd) = self.digi_device_type {
                    out.extend_from_slice(&dd.to_be_bytes());
                }
                if let Some(rssi) = self.rssi_raw {
                    out.push(rssi);
                }
            }
        }
        out
    }
}

/// Digi's profile ID.
pub const DIGI_PROFILE_ID: u16 = 0xC105;
/// Digi's manufacturer ID.
pub const DIGI_MANUFACTURER_ID: u16 = 0x101E;

/// Converts an RSSI byte ("positive number = −dBm"; ≥ 0x80 read as two's complement) to dBm.
pub fn rssi_byte_to_dbm(raw: u8) -> f64 {
    if raw >= 0x80 {
        f64::from(raw as i8)
    } else {
        -f64::from(raw)
    }
}

/// Converts dBm to the "positive number = −dBm" byte, rounded and clamped to 0..=0x7F so that
/// [`rssi_byte_to_dbm`] reads it back.
pub fn dbm_to_rssi_byte(dbm: f64) -> u8 {
    let magnitude = (-dbm).round();
    if magnitude.is_nan() || magnitude <= 0.0 {
        0
    } else if magnitude >= 127.0 {
        0x7F
    } else {
        magnitude as u8
    }
}
