//! Splitting the reader's byte stream into lines.
//!
//! A line ends at `\r`, `\n` (so `\r\n` gives one line and one ignored empty line) or at the
//! literal four characters `<\r>` that seed 002's logs carry. Partial lines are kept across
//! calls. Control bytes other than CR/LF are dropped and counted (a tab becomes a space). A line
//! longer than [`MAX_LINE_LEN`] is cut off, reported as overlong and its bytes counted.

/// Longest line kept; the longest reader line expected is a system-info reply of ~60 bytes.
pub const MAX_LINE_LEN: usize = 256;

const LITERAL_CR: &[u8] = b"<\\r>";

/// One line out of the framer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FramedLine {
    /// A complete, non-empty line without its terminator.
    Line(Vec<u8>),
    /// A line that exceeded [`MAX_LINE_LEN`]; the first bytes are kept for the report.
    Overlong(Vec<u8>),
}

/// Accumulates bytes into lines.
#[derive(Debug, Default, Clone)]
pub struct LineFramer {
    buf: Vec<u8>,
    overflowing: bool,
    control_bytes_dropped: u64,
    overflow_bytes_dropped: u64,
}

impl LineFramer {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; returns the lines they completed.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<FramedLine> {
        let mut out = Vec::new();
        for &b in bytes {
            match b {
                b'\r' | b'\n' => self.end_line(&mut out),
                b'\t' => self.add(b' ', &mut out),
                0x00..=0x1F | 0x7F => self.control_bytes_dropped += 1,
                _ => {
                    self.add(b, &mut out);
                    if b == b'>' && !self.overflowing && self.buf.ends_with(LITERAL_CR) {
                        let keep = self.buf.len() - LITERAL_CR.len();
                        self.buf.truncate(keep);
                        self.end_line(&mut out);
                    }
                }
            }
        }
        out
    }

    fn add(&mut self, b: u8, out: &mut Vec<FramedLine>) {
        if self.overflowing {
            self.overflow_bytes_dropped += 1;
            return;
        }
        self.buf.push(b);
        if self.buf.len() > MAX_LINE_LEN {
            self.overflowing = true;
            self.overflow_bytes_dropped += self.buf.len() as u64;
            let head: Vec<u8> = self.buf.iter().take(64).copied().collect();
            self.buf.clear();
            out.push(FramedLine::Overlong(head));
        }
    }

    fn end_line(&mut self, out: &mut Vec<FramedLine>) {
        if self.overflowing {
            self.overflowing = false;
            return;
        }
        if !self.buf.is_empty() {
            out.push(FramedLine::Line(std::mem::take(&mut self.buf)));
        }
    }

    /// Bytes of an unfinished line held for the next call.
    #[must_use]
    pub fn pending(&self) -> &[u8] {
        &self.buf
    }

    /// Control bytes dropped so far.
    #[must_use]
    pub fn control_bytes_dropped(&self) -> u64 {
        self.control_bytes_dropped
    }

    /// Bytes of overlong lines dropped so far.
    #[must_use]
    pub fn overflow_bytes_dropped(&self) -> u64 {
        self.overflow_bytes_dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(out: Vec<FramedLine>) -> Vec<String> {
        out.into_iter()
            .map(|l| match l {
                FramedLine::Line(b) => String::from_utf8(b).unwrap(),
                FramedLine::Overlong(_) => "<overlong>".to_string(),
            })
            .collect()
    }

    #[test]
    fn all_terminators() {
        let mut f = LineFramer::new();
        let out = f.push(b"A\r\nB\nC\rD<\\r>E<\\r>\r\n");
        assert_eq!(lines(out), ["A", "B", "C", "D", "E"]);
        assert!(f.pending().is_empty());
    }

    #[test]
    fn partial_lines_are_kept() {
        let mut f = LineFramer::new();
        assert!(f.push(b"SCAN:+U").is_empty());
        assert!(f.push(b"ID=E0<\\").is_empty());
        assert_eq!(lines(f.push(b"r>")), ["SCAN:+UID=E0"]);
    }

    #[test]
    fn control_bytes_are_dropped_and_counted() {
        let mut f = LineFramer::new();
        assert_eq!(lines(f.push(b"\x00O\x07K\x1b\r\n")), ["OK"]);
        assert_eq!(f.control_bytes_dropped(), 3);
    }

    #[test]
    fn overlong_line_is_reported_once() {
        let mut f = LineFramer::new();
        let long = vec![b'A'; MAX_LINE_LEN + 10];
        let out = f.push(&long);
        assert_eq!(lines(out), ["<overlong>"]);
        assert_eq!(lines(f.push(b"AAA\r\nOK\r\n")), ["OK"]);
        assert_eq!(f.overflow_bytes_dropped(), (MAX_LINE_LEN + 13) as u64);
    }
}
