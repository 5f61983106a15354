//! Timestamped tag events delivered by the client.

use crate::line::Rssi;
use crate::uid::Uid;

/// What happened to a tag.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub enum TagEventKind {
    /// `SCAN:+UID`: in the field, with both RSSI numbers when the reader gave them.
    Seen { rssi: Option<Rssi> },
    /// `SCAN:-UID`: left the field. Not a position fix (seed 002 drops these).
    Lost,
}

/// One tag event.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TagEvent {
    /// Seconds on the injected clock when the line was complete.
    pub t: f64,
    pub uid: Uid,
    pub kind: TagEventKind,
}

impl std::fmt::Display for TagEvent {
    /// `t=… seen uid=… rssi=a/b` or `t=… lost uid=…` (the golden-file format).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.kind {
            TagEventKind::Seen { rssi: Some(r) } => {
                write!(f, "{:.6} seen uid={} rssi={r}", self.t, self.uid)
            }
            TagEventKind::Seen { rssi: None } => write!(f, "{:.6} seen uid={}", self.t, self.uid),
            TagEventKind::Lost => write!(f, "{:.6} lost uid={}", self.t, self.uid),
        }
    }
}
