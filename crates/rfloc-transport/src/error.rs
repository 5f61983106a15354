//! Transport errors.

/// Why a link could not be opened or used.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error("cannot open serial port {path}: {source}")]
    Serial {
        path: String,
        #[source]
        source: tokio_serial::Error,
    },
    #[error("cannot connect to {address}: {source}")]
    Tcp {
        address: String,
        #[source]
        source: std::io::Error,
    },
    #[error("timed out after {seconds} s connecting to {address}")]
    TcpTimeout { address: String, seconds: f64 },
    #[error("cannot create capture file {path}: {source}")]
    Capture {
        path: String,
        #[source]
        source: std::io::Error,
    },
}
