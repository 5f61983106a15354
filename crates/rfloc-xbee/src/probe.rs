//! The radio capability a host program needs for beacons: discover nodes and measure the RSSI
//! of one, as a trait so it can be mocked. (A bearing sweep takes `rfloc_bearing::RssiProbe`, one
//! round of `(beacon, RSSI)` per antenna stop; the daemon implements it over `XBeeClient`.)

use std::future::Future;

use tokio::io::{AsyncRead, AsyncWrite};

use crate::address::Address64;
use crate::client::{XBeeClient, XBeeError};
use crate::nd::Node;

/// Discovers beacons and measures the RSSI of one of them.
pub trait BeaconRadio {
    /// Error of the implementation.
    type Error: std::error::Error + Send + Sync + 'static;

    /// Runs one discovery round and returns the nodes that answered (with RSSI where the
    /// record carried one).
    fn discover_nodes(&mut self) -> impl Future<Output = Result<Vec<Node>, Self::Error>> + Send;

    /// RSSI of the link to `node` in dBm, `None` if the node was not heard.
    fn node_rssi(
        &mut self,
        node: Address64,
    ) -> impl Future<Output = Result<Option<f64>, Self::Error>> + Send;
}

impl<T> BeaconRadio for XBeeClient<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    type Error = XBeeError;

    async fn discover_nodes(&mut self) -> Result<Vec<Node>, XBeeError> {
        Ok(self.discover().await?.nodes)
    }

    /// Uses the client's configured [`crate::client::RssiSource`].
    async fn node_rssi(&mut self, node: Address64) -> Result<Option<f64>, XBeeError> {
        XBeeClient::node_rssi(self, node).await
    }
}
