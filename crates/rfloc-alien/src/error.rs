//! Errors of the Alien client.
//!
//! Reader text in an error (`Reader::text`, `Unexpected::reply`, `LoginFailed`, `AuthFailed::
//! reason`) has passed through the client's redactor: it holds neither the password nor an echo
//! of it, and no control characters (see `redact.rs`).

use std::time::Duration;

/// Why the reader ended (or refused) a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SessionEnd {
    /// `Connection Timeout.`: idle longer than `NetworkTimeout`.
    ConnectionTimeout,
    /// `Goodbye!`: reply to `quit`.
    Goodbye,
    /// Another client holds the reader (`… later.`, `Busy`).
    Busy,
    /// `Boot>`: the reader is still booting.
    Booting,
    /// The stream closed.
    Closed,
}

impl std::fmt::Display for SessionEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SessionEnd::ConnectionTimeout => "Connection Timeout (idle longer than NetworkTimeout)",
            SessionEnd::Goodbye => "Goodbye (session quit)",
            SessionEnd::Busy => "reader busy with another client",
            SessionEnd::Booting => "reader still booting",
            SessionEnd::Closed => "connection closed",
        })
    }
}

/// Client failures.
#[derive(Debug, thiserror::Error)]
pub enum AlienError {
    /// The reader answered `Error [n]: text`.
    #[error("reader error {code:?} to {command:?}: {text}")]
    Reader {
        command: String,
        code: Option<u32>,
        text: String,
    },
    /// The reader refused the username or password: an authentication failure. Dialling again
    /// at once will not help and may lock the account. The text is the reader's reason,
    /// redacted.
    #[error("login refused by the reader (authentication failure): {0}")]
    LoginFailed(String),
    /// [`AlienSession`](crate::AlienSession): the login was refused `failures` times in a row;
    /// the session dials again no sooner than `retry_in` from now.
    #[error(
        "authentication failed ({failures} refusal(s) in a row): {reason}; next login attempt in {retry_in:?}"
    )]
    AuthFailed {
        failures: u32,
        reason: String,
        retry_in: Duration,
    },
    /// The session ended or was refused.
    #[error("session ended: {0}")]
    Session(SessionEnd),
    /// The exchange (`what`: a command, `login`, `connect`) did not complete within `after`;
    /// `received` bytes came in meanwhile without forming the awaited reply.
    #[error("no complete reply to {what:?} within {after:?} ({received} bytes received)")]
    Timeout {
        what: String,
        after: Duration,
        received: u64,
    },
    /// A reply (or banner) longer than the client's `max_reply_len`.
    #[error("reply to {what:?} longer than {limit} bytes")]
    ReplyTooLong { what: String, limit: usize },
    /// A reply of an unexpected shape (e.g. `get` without `=`).
    #[error("unexpected reply to {command:?}: {reply:?}")]
    Unexpected { command: String, reply: String },
    /// A bad `TagListCustomFormat`.
    #[error(transparent)]
    CustomFormat(#[from] crate::custom_format::CustomFormatError),
    #[error("I/O: {0}")]
    Io(#[from] std::io::Error),
    /// Reconnection gave up.
    #[error("gave up reconnecting after {attempts} attempts: {last}")]
    Reconnect { attempts: u32, last: String },
}

impl AlienError {
    /// True when the session is unusable and a reconnect is needed.
    #[must_use]
    pub fn needs_reconnect(&self) -> bool {
        matches!(
            self,
            AlienError::Session(_)
                | AlienError::Io(_)
                | AlienError::Timeout { .. }
                | AlienError::ReplyTooLong { .. }
        )
    }

    /// True when the reader refused the credentials ([`AlienError::LoginFailed`],
    /// [`AlienError::AuthFailed`]): a configuration problem, not a link problem.
    #[must_use]
    pub fn is_auth_failure(&self) -> bool {
        matches!(
            self,
            AlienError::LoginFailed(_) | AlienError::AuthFailed { .. }
        )
    }

    /// For [`AlienError::AuthFailed`]: how long the session waits before it logs in again.
    #[must_use]
    pub fn retry_in(&self) -> Option<Duration> {
        match self {
            AlienError::AuthFailed { retry_in, .. } => Some(*retry_in),
            _ => None,
        }
    }
}
