//! Errors of the Alien client.

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
    /// Username/password refused.
    #[error("login refused: {0}")]
    LoginFailed(String),
    /// The session ended or was refused.
    #[error("session ended: {0}")]
    Session(SessionEnd),
    /// No complete reply in time.
    #[error("no reply to {0:?} in time")]
    Timeout(String),
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
            AlienError::Session(_) | AlienError::Io(_) | AlienError::Timeout(_)
        )
    }
}
