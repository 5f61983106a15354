//! The XBee driver as the bearing scan's RSSI probe: one `ND` round per antenna stop, each
//! beacon's RSSI taken from the RSSI byte its `ND` record carries, beacon id = 64-bit address.

use rfloc_bearing::RssiProbe;
use rfloc_xbee::XBeeError;

use super::rig::XBeeLink;

/// [`RssiProbe`] over `ND` rounds of an [`XBeeLink`].
pub struct NdRssiProbe {
    link: XBeeLink,
    /// `ND` records that could not be parsed, summed over rounds.
    pub rejected_records: u64,
}

impl NdRssiProbe {
    /// Wraps a connected XBee driver.
    #[must_use]
    pub fn new(link: XBeeLink) -> Self {
        Self {
            link,
            rejected_records: 0,
        }
    }

    /// Bytes the XBee codec dropped while resynchronising.
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.link.stats().decode.dropped_bytes
    }
}

impl RssiProbe for NdRssiProbe {
    type Error = XBeeError;

    async fn rssi_all(&mut self) -> Result<Vec<(u64, f64)>, XBeeError> {
        let round = self.link.discover().await?;
        self.rejected_records += round.rejected.len() as u64;
        Ok(round
            .nodes
            .iter()
            .filter_map(|n| n.rssi_dbm().map(|dbm| (n.address.0, dbm)))
            .collect())
    }
}
