//! 64-bit and 16-bit XBee addresses.

use std::fmt;

use serde::{Deserialize, Serialize};

/// A 64-bit IEEE address (`SH` then `SL`), sent big-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Address64(pub u64);

impl Address64 {
    /// Destination that means "the coordinator" in transmit and remote AT frames.
    pub const COORDINATOR: Address64 = Address64(0);
    /// Broadcast destination.
    pub const BROADCAST: Address64 = Address64(0xFFFF);

    /// Big-endian wire bytes.
    pub fn to_bytes(self) -> [u8; 8] {
        self.0.to_be_bytes()
    }

    /// The high 32 bits (`SH`).
    pub fn high(self) -> u32 {
        (self.0 >> 32) as u32
    }

    /// The low 32 bits (`SL`).
    pub fn low(self) -> u32 {
        (self.0 & 0xFFFF_FFFF) as u32
    }
}

impl fmt::Display for Address64 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:016X}", self.0)
    }
}

/// A 16-bit network address (`MY`), sent big-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Address16(pub u16);

impl Address16 {
    /// "Unknown" or "no parent".
    pub const UNKNOWN: Address16 = Address16(0xFFFE);

    /// Big-endian wire bytes.
    pub fn to_bytes(self) -> [u8; 2] {
        self.0.to_be_bytes()
    }
}

impl fmt::Display for Address16 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04X}", self.0)
    }
}
