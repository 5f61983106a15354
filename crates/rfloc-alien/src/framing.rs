//! Splitting the reader's byte stream into frames.
//!
//! Every reply ends with a NUL (`\0`). In interactive mode the reader then sends a prompt
//! (`\r\nAlien>` followed by NUL). At login it sends `Username>` and `Password>`, with or
//! without a NUL (emulators differ). A frame ending in a prompt word is emitted as soon as the
//! prompt is complete; a NUL right after such a prompt is swallowed.

/// Largest frame kept by default; a 1000-tag Text list is ~100 kB.
pub const MAX_FRAME_LEN: usize = 1 << 20;

/// A prompt the reader prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prompt {
    Username,
    Password,
    /// `Alien>` or `Alien >` (interactive mode).
    Command,
}

/// One unit of reader output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frame {
    /// Text before a prompt (banner, or an error before a new `Username>`), then the prompt.
    Prompt { before: String, prompt: Prompt },
    /// A NUL-terminated reply body (may be empty: the answer to an empty command or a
    /// prompt-suppressed login step).
    Reply(String),
    /// A frame longer than the framer's limit ([`MAX_FRAME_LEN`] unless set); its first bytes.
    /// The rest of it, up to its NUL, is dropped.
    Overlong(Vec<u8>),
}

/// Accumulates bytes into frames. It never holds more than its limit of an unfinished frame.
#[derive(Debug, Clone)]
pub struct ReplyFramer {
    buf: Vec<u8>,
    limit: usize,
    swallow_nul: bool,
    overflowing: bool,
    dropped_bytes: u64,
}

impl Default for ReplyFramer {
    fn default() -> Self {
        Self::with_limit(MAX_FRAME_LEN)
    }
}

fn prompt_at_end(buf: &[u8]) -> Option<(Prompt, usize)> {
    let trimmed_len = buf
        .iter()
        .rposition(|b| !b.is_ascii_whitespace())
        .map_or(0, |p| p + 1);
    let t = buf.get(..trimmed_len)?;
    for (word, p) in [
        (&b"Username>"[..], Prompt::Username),
        (b"Password>", Prompt::Password),
        (b"Alien>", Prompt::Command),
        (b"Alien >", Prompt::Command),
    ] {
        if t.ends_with(word) {
            return Some((p, trimmed_len - word.len()));
        }
    }
    None
}

impl ReplyFramer {
    /// A framer with the default limit, [`MAX_FRAME_LEN`].
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// A framer that keeps frames of at most `limit` bytes (at least 1); a longer one becomes
    /// [`Frame::Overlong`].
    #[must_use]
    pub fn with_limit(limit: usize) -> Self {
        Self {
            buf: Vec::new(),
            limit: limit.max(1),
            swallow_nul: false,
            overflowing: false,
            dropped_bytes: 0,
        }
    }

    /// The longest frame kept, in bytes.
    #[must_use]
    pub fn limit(&self) -> usize {
        self.limit
    }

    /// Feeds bytes; returns the frames they completed.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Frame> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == 0 {
                if self.swallow_nul {
                    self.swallow_nul = false;
                    continue;
                }
                if self.overflowing {
                    self.overflowing = false;
                    continue;
                }
                let body = std::mem::take(&mut self.buf);
                out.push(Frame::Reply(String::from_utf8_lossy(&body).into_owned()));
                continue;
            }
            self.swallow_nul = false;
            if self.overflowing {
                self.dropped_bytes += 1;
                continue;
            }
            self.buf.push(b);
            if self.buf.len() > self.limit {
                self.overflowing = true;
                self.dropped_bytes += self.buf.len() as u64;
                let head = self.buf.iter().take(80).copied().collect();
                self.buf.clear();
                tracing::warn!(limit = self.limit, "alien: overlong reply frame dropped");
                out.push(Frame::Overlong(head));
                continue;
            }
            if b == b'>' {
                if let Some((prompt, start)) = prompt_at_end(&self.buf) {
                    let before = String::from_utf8_lossy(self.buf.get(..start).unwrap_or_default())
                        .into_owned();
                    self.buf.clear();
                    self.swallow_nul = true;
                    out.push(Frame::Prompt { before, prompt });
                }
            }
        }
        out
    }

    /// Bytes of an unfinished frame.
    #[must_use]
    pub fn pending(&self) -> &[u8] {
        &self.buf
    }

    /// Bytes dropped from overlong frames.
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn banner_and_login_prompts_with_and_without_nul() {
        // protocols/alien-alr9900.md §1.2 (banner as two emulators print it).
        let mut f = ReplyFramer::new();
        let out = f.push(b"****\r\n* Alien Technology : RFID Reader\r\n****\r\n\r\nUsername>\0");
        assert_eq!(out.len(), 1);
        let Frame::Prompt {
            before,
            prompt: Prompt::Username,
        } = &out[0]
        else {
            panic!()
        };
        assert!(before.contains("Alien Technology"));
        assert_eq!(
            f.push(b"Password>"),
            vec![Frame::Prompt {
                before: String::new(),
                prompt: Prompt::Password
            }]
        );
        // No NUL after the prompt: the next NUL ends a (here empty) reply.
        assert_eq!(f.push(b"\0"), vec![]);
        assert_eq!(f.push(b"\0"), vec![Frame::Reply(String::new())]);
    }

    #[test]
    fn interactive_reply_then_prompt() {
        // §1.3: `ReaderName = Alien Reader\r\n\0\r\nAlien >`.
        let mut f = ReplyFramer::new();
        let out = f.push(b"get ReaderName\r\nReaderName = Alien Reader\r\n\0\r\nAlien >");
        assert_eq!(
            out,
            vec![
                Frame::Reply("get ReaderName\r\nReaderName = Alien Reader\r\n".into()),
                Frame::Prompt {
                    before: "\r\n".into(),
                    prompt: Prompt::Command
                }
            ]
        );
    }

    #[test]
    fn a_frame_over_the_limit_is_overlong_and_never_held_whole() {
        let mut f = ReplyFramer::with_limit(16);
        let mut out = Vec::new();
        for chunk in [&b"0123456789"[..], b"abcdefghij", b"KLMNOPQRST"] {
            out.extend(f.push(chunk));
            assert!(f.pending().len() <= 16, "{}", f.pending().len());
        }
        assert_eq!(out, vec![Frame::Overlong(b"0123456789abcdefg".to_vec())]);
        // The rest of the long frame is dropped up to its NUL; the next frame is whole.
        assert_eq!(f.push(b"UVW\0ok\0"), vec![Frame::Reply("ok".into())]);
        assert_eq!(f.dropped_bytes(), 17 + 3 + 10 + 3);
    }

    #[test]
    fn split_reads_keep_partial_frames() {
        let mut f = ReplyFramer::new();
        assert!(f.push(b"Tag:0102").is_empty());
        assert_eq!(f.pending(), b"Tag:0102");
        assert_eq!(
            f.push(b" 0304\r\n\0"),
            vec![Frame::Reply("Tag:0102 0304\r\n".into())]
        );
    }
}
