//! Reading a recorded session back (no I/O): the client's lines and the reader's frames,
//! paired in order into [`Exchange`]s, with the TagList format followed through the session.
//!
//! Pairing, as the client does it: every NUL-terminated reply answers the oldest line not yet
//! answered; an echo of the command is removed (learned as the client does: a reply equal to
//! its command is kept unless the reader is known to echo). The login is recognised, not returned: after
//! a `Username>` prompt the next two lines are the credentials; each is answered by a reply
//! (prompts suppressed) or by the next prompt (interactive). Command prompts (`Alien>`) answer
//! nothing.

use std::collections::VecDeque;

use crate::client::{EchoFilter, EchoState};
use crate::format_tracker::FormatTracker;
use crate::framing::{Frame, Prompt, ReplyFramer};
use crate::reply::{parse_reply, Reply};
use crate::taglist::TagRead;

/// One command and the reader's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Exchange {
    /// Time of the record that completed the reply.
    pub t: f64,
    pub command: String,
    pub reply: String,
}

impl Exchange {
    /// True for a TagList read (`t`, `get TagList`, `TagList?`).
    #[must_use]
    pub fn is_taglist(&self) -> bool {
        let c = self.command.trim().to_ascii_lowercase();
        matches!(c.as_str(), "t" | "get taglist" | "taglist?")
    }

    /// True when the reader answered with an error.
    #[must_use]
    pub fn is_error(&self) -> bool {
        matches!(parse_reply(&self.reply), Reply::Error { .. })
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Line {
    Credential,
    Command(String),
}

/// Decoder of one recorded session.
#[derive(Debug, Default)]
pub struct Transcript {
    framer: ReplyFramer,
    partial_line: Vec<u8>,
    pending: VecDeque<Line>,
    credentials_expected: usize,
    format: FormatTracker,
    echo: EchoFilter,
    /// Replies with no line to answer, and frames too long to keep.
    pub stray_frames: u64,
    /// `TagListCustomFormat` values that did not compile.
    pub bad_formats: u64,
}

impl Transcript {
    /// A decoder at the start of a session.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The TagList format in force after the exchanges so far.
    #[must_use]
    pub fn format(&self) -> &FormatTracker {
        &self.format
    }

    /// Whether the reader echoed commands, as learned from the replies so far.
    #[must_use]
    pub fn echo_state(&self) -> EchoState {
        self.echo.state()
    }

    /// Bytes the client wrote.
    pub fn push_client(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match b {
                b'\n' | b'\r' => {
                    if b == b'\n' || !self.partial_line.is_empty() {
                        let raw = std::mem::take(&mut self.partial_line);
                        if b == b'\n' && raw.is_empty() {
                            continue;
                        }
                        self.line(&raw);
                    }
                }
                _ => self.partial_line.push(b),
            }
        }
    }

    fn line(&mut self, raw: &[u8]) {
        let text = String::from_utf8_lossy(raw);
        let text = text.trim_start_matches('\u{1}').to_string();
        if self.credentials_expected > 0 {
            self.credentials_expected -= 1;
            self.pending.push_back(Line::Credential);
        } else {
            self.pending.push_back(Line::Command(text));
        }
    }

    /// Bytes the reader sent, recorded at time `t`; returns the exchanges they completed.
    pub fn push_reader(&mut self, t: f64, bytes: &[u8]) -> Vec<Exchange> {
        let mut out = Vec::new();
        for frame in self.framer.push(bytes) {
            match frame {
                Frame::Reply(body) => match self.pending.pop_front() {
                    Some(Line::Command(command)) => {
                        let reply = self.echo.strip(&body, &command);
                        if !matches!(parse_reply(&reply), Reply::Error { .. })
                            && self.format.observe(&command).is_err()
                        {
                            self.bad_formats += 1;
                        }
                        out.push(Exchange { t, command, reply });
                    }
                    Some(Line::Credential) => {}
                    None => self.stray_frames += 1,
                },
                Frame::Prompt { prompt, .. } => {
                    if self.pending.front() == Some(&Line::Credential) {
                        self.pending.pop_front();
                    }
                    if prompt == Prompt::Username {
                        self.credentials_expected = 2;
                        // Lines sent before the prompt arrived are the credentials too.
                        self.pending.retain(|l| *l != Line::Credential);
                    }
                }
                Frame::Overlong(_) => {
                    self.pending.pop_front();
                    self.stray_frames += 1;
                }
            }
        }
        out
    }

    /// The tags of a TagList exchange, parsed with the format in force (`None` for other
    /// exchanges). Malformed lines are skipped.
    #[must_use]
    pub fn tags(&self, exchange: &Exchange) -> Option<Vec<TagRead>> {
        exchange
            .is_taglist()
            .then(|| self.format.format().parse(&exchange.reply).0)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_suppressed_session_pairs_commands_and_follows_the_format() {
        let mut t = Transcript::new();
        assert!(t
            .push_reader(0.0, b"* Alien *\r\n\r\nUsername>\0")
            .is_empty());
        t.push_client(b"\x01alien\r\n");
        assert!(t.push_reader(0.1, b"\0").is_empty());
        t.push_client(b"\x01<redacted>\r\n");
        assert!(t.push_reader(0.2, b"\0").is_empty());
        t.push_client(
            b"\x01TagListCustomFormat = IDK %i RSSI %m;\r\n\x01TagListFormat = Custom\r\n",
        );
        let ex = t.push_reader(
            0.3,
            b"TagListCustomFormat = IDK %i RSSI %m;\r\n\0TagListFormat = Custom\r\n\0",
        );
        assert_eq!(ex.len(), 2);
        assert_eq!(ex[1].command, "TagListFormat = Custom");
        t.push_client(b"\x01t\r\n");
        // The reply arrives in two records; the exchange completes with the second.
        assert!(t
            .push_reader(0.4, b"IDK E200 0001 RSSI 2500.5;\r\n")
            .is_empty());
        let ex = t.push_reader(0.5, b"IDK E200 0002 RSSI 1200.0;\r\n\0");
        assert_eq!(ex.len(), 1);
        assert!((ex[0].t - 0.5).abs() < 1e-12);
        let tags = t.tags(&ex[0]).unwrap();
        assert_eq!(tags.len(), 2);
        assert_eq!(tags[0].rssi, Some(2500.5));
        assert_eq!(t.stray_frames, 0);
    }

    #[test]
    fn an_interactive_session_with_echo_and_prompts() {
        let mut t = Transcript::new();
        t.push_reader(0.0, b"banner\r\nUsername>");
        t.push_client(b"alien\r\n");
        t.push_reader(0.1, b"Password>");
        t.push_client(b"password\r\n");
        t.push_reader(0.2, b"\r\nAlien>\0");
        t.push_client(b"t\r\n");
        let ex = t.push_reader(
            0.3,
            b"t\r\nTag:E200 0003, Disc:2000/01/01 00:00:00, Last:2000/01/01 00:00:00, Count:1, Ant:0\r\n\0\r\nAlien>\0",
        );
        assert_eq!(ex.len(), 1, "{ex:?}");
        assert!(!ex[0].reply.starts_with('t'), "{:?}", ex[0].reply);
        assert_eq!(t.tags(&ex[0]).unwrap().len(), 1);
        // A reply nobody asked for is counted, not paired.
        assert!(t.push_reader(0.4, b"surprise\0").is_empty());
        assert_eq!(t.stray_frames, 1);
    }
}
