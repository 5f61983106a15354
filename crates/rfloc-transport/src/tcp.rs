//! TCP links.

use std::time::Duration;

use tokio::net::TcpStream;

use crate::error::TransportError;
use crate::link::TcpLink;

/// Connects with the configured timeout and disables Nagle (commands are small and
/// latency-sensitive).
pub async fn connect(link: &TcpLink) -> Result<TcpStream, TransportError> {
    let seconds = if link.connect_timeout.is_finite() && link.connect_timeout > 0.0 {
        link.connect_timeout
    } else {
        5.0
    };
    let stream = tokio::time::timeout(
        Duration::from_secs_f64(seconds),
        TcpStream::connect(&link.address),
    )
    .await
    .map_err(|_| TransportError::TcpTimeout {
        address: link.address.clone(),
        seconds,
    })?
    .map_err(|source| TransportError::Tcp {
        address: link.address.clone(),
        source,
    })?;
    stream
        .set_nodelay(true)
        .map_err(|source| TransportError::Tcp {
            address: link.address.clone(),
            source,
        })?;
    tracing::debug!(address = %link.address, "tcp link open");
    Ok(stream)
}
