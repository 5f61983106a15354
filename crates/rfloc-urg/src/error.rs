//! Errors of the SCIP codec and client.

use thiserror::Error;

/// Why a reply, a scan or an exchange failed. Carries the offending bytes where there are any.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ScipError {
    /// A line's check sum does not match its bytes.
    #[error("check sum mismatch on line {line:?}")]
    CheckSum { line: Vec<u8> },
    /// A reply with fewer lines than its kind needs, or a line of the wrong length.
    #[error("malformed reply: {why} in {bytes:?}")]
    Malformed { why: &'static str, bytes: Vec<u8> },
    /// The sensor answered with a status other than success.
    #[error("command {echo:?} answered with status {status:?}")]
    Status { echo: Vec<u8>, status: [u8; 2] },
    /// A reply to another command than the one sent.
    #[error("expected a reply to {expected:?}, got one to {got:?}")]
    UnexpectedReply { expected: Vec<u8>, got: Vec<u8> },
    /// Data characters outside the encoding's alphabet.
    #[error("undecodable range data {chars:?}")]
    Encoding { chars: Vec<u8> },
    /// No reply within the configured time.
    #[error("no reply within {0:?}")]
    Timeout(std::time::Duration),
    /// The link ended.
    #[error("link closed")]
    Closed,
    /// Reading or writing the link failed.
    #[error("i/o: {0}")]
    Io(String),
}
