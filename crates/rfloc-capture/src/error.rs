//! Errors of the capture reader and writer.

use std::fmt;

/// What is wrong with a capture line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CaptureErrorKind {
    #[error("first line must be `# rfloc-capture 1`, found {0:?}")]
    BadMagic(String),
    #[error("record needs `<seconds> <dir> <payload>`, found {0:?}")]
    MissingField(String),
    #[error("bad time {0:?}: expected a non-negative decimal with at most 9 fraction digits")]
    BadTime(String),
    #[error("time {found} s goes backwards (previous record at {previous} s)")]
    TimeGoesBack { previous: String, found: String },
    #[error("unknown direction {0:?}: expected rx, tx or ev")]
    BadDirection(String),
    #[error("payload {0:?} must start with `x:` or `s:`")]
    BadPayloadKind(String),
    #[error("bad hex payload {text:?}: {reason}")]
    BadHex { text: String, reason: &'static str },
    #[error("bad text payload {text:?}: {reason}")]
    BadText { text: String, reason: &'static str },
    #[error("empty event")]
    EmptyEvent,
    #[error("line is not valid UTF-8")]
    NotUtf8,
    #[error("I/O error: {0}")]
    Io(String),
}

/// A capture error with the place it was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CaptureError {
    /// File name (or another label for in-memory text).
    pub source_name: String,
    /// 1-based line number; 0 when the error is not about a line.
    pub line: usize,
    pub kind: CaptureErrorKind,
}

impl fmt::Display for CaptureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.source_name, self.kind)
        } else {
            write!(f, "{}:{}: {}", self.source_name, self.line, self.kind)
        }
    }
}

impl std::error::Error for CaptureError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.kind)
    }
}
