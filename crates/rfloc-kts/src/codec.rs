//! The sans-IO decoder: bytes in, classified lines out, with counters.

use crate::framing::{FramedLine, LineFramer};
use crate::line::{parse_line, KtsLine, MalformedLine, MalformedReason};

/// Counters of what the codec saw and dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CodecStats {
    /// Lines classified (any class).
    pub lines: u64,
    /// `SCAN:+UID` lines.
    pub seen: u64,
    /// `SCAN:-UID` lines.
    pub lost: u64,
    /// Lines rejected as malformed (including overlong ones).
    pub malformed: u64,
    /// Control bytes dropped by the framer.
    pub control_bytes_dropped: u64,
    /// Bytes of overlong lines dropped by the framer.
    pub overflow_bytes_dropped: u64,
}

/// Framer plus classifier.
#[derive(Debug, Default, Clone)]
pub struct KtsCodec {
    framer: LineFramer,
    stats: CodecStats,
    /// Malformed lines are logged a few at a time, then summarised.
    log: rfloc_transport::LogLimit,
}

impl KtsCodec {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; returns one result per completed line. Malformed lines are counted and
    /// logged (`tracing::warn!`) and returned with their bytes; decoding continues after them.
    pub fn decode(&mut self, bytes: &[u8]) -> Vec<Result<KtsLine, MalformedLine>> {
        let framed = self.framer.push(bytes);
        self.stats.control_bytes_dropped = self.framer.control_bytes_dropped();
        self.stats.overflow_bytes_dropped = self.framer.overflow_bytes_dropped();
        framed
            .into_iter()
            .map(|f| {
                let r = match f {
                    FramedLine::Line(b) => parse_line(&b),
                    FramedLine::Overlong(head) => Err(MalformedLine {
                        bytes: head,
                        reason: MalformedReason::Overlong,
                    }),
                };
                match &r {
                    Ok(line) => {
                        self.stats.lines += 1;
                        match line {
                            KtsLine::ScanSeen { .. } => self.stats.seen += 1,
                            KtsLine::ScanLost { .. } => self.stats.lost += 1,
                            _ => {}
                        }
                    }
                    Err(e) => {
                        self.stats.malformed += 1;
                        if let Some(suppressed) = self.log.hit() {
                            tracing::warn!(%e, suppressed, total = self.stats.malformed, "kts: dropped malformed line");
                        }
                    }
                }
                r
            })
            .collect()
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> CodecStats {
        self.stats
    }

    /// Bytes of an unfinished line.
    #[must_use]
    pub fn pending(&self) -> &[u8] {
        self.framer.pending()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resyncs_after_garbage() {
        let mut c = KtsCodec::new();
        let out =
            c.decode(b"\xff\xfe garbage\r\nSCAN:+UID=E00402000018313E,+RSSI=7/6<\\r>\r\nOK\r\n");
        assert_eq!(out.len(), 3);
        assert!(out[0].is_err());
        assert!(matches!(out[1], Ok(KtsLine::ScanSeen { .. })));
        assert_eq!(out[2], Ok(KtsLine::Ok));
        let s = c.stats();
        assert_eq!((s.lines, s.seen, s.malformed), (2, 1, 1));
    }
}
