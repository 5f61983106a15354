//! The RSSI source of a scan.

use std::future::Future;

/// Reports the RSSI of every beacon that answers now (e.g. an XBee node discovery).
pub trait RssiProbe {
    /// Error of one probe.
    type Error: std::error::Error + Send + Sync + 'static;

    /// One round: `(beacon id, RSSI dBm)` for each beacon heard.
    fn rssi_all(&mut self) -> impl Future<Output = Result<Vec<(u64, f64)>, Self::Error>> + Send;
}
