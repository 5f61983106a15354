//! Classifying a reply body.

use crate::error::SessionEnd;

/// A classified reply body (echo already removed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// Nothing (empty command, prompt-suppressed login step).
    Empty,
    /// `Error[ n]: text`.
    Error { code: Option<u32>, text: String },
    /// A single `Key = Value` line (key as the reader spells it, both trimmed).
    Value { key: String, value: String },
    /// Anything else, as non-empty lines.
    Lines(Vec<String>),
}

/// Recognises the session-level messages of `protocols/alien-alr9900.md` §1.4 anywhere in a
/// reply or prompt text.
#[must_use]
pub fn session_end(text: &str) -> Option<SessionEnd> {
    let t = text.trim();
    if t.contains("Connection Timeout") {
        Some(SessionEnd::ConnectionTimeout)
    } else if t.contains("Goodbye!") {
        Some(SessionEnd::Goodbye)
    } else if t.contains("later.") || t.starts_with("Busy") || t.contains("Reader is busy") {
        Some(SessionEnd::Busy)
    } else if t.starts_with("Boot>") {
        Some(SessionEnd::Booting)
    } else {
        None
    }
}

/// Parses `Error 1: Command not understood.` / `Error: Malformed message.`.
fn parse_error(line: &str) -> Option<(Option<u32>, String)> {
    let t = line.trim_start();
    let head = t.get(..5)?;
    if !head.eq_ignore_ascii_case("error") {
        return None;
    }
    let rest = t.get(5..)?;
    let (code_part, text) = match rest.split_once(':') {
        Some((c, x)) => (c, x.trim()),
        None => (rest, ""),
    };
    let code = code_part.trim().parse().ok();
    Some((code, text.to_string()))
}

/// Classifies a reply body: trailing CR/LF trimmed, split on line ends.
#[must_use]
pub fn parse_reply(body: &str) -> Reply {
    let lines: Vec<String> = body
        .split(['\r', '\n'])
        .map(str::trim_end)
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect();
    let Some(first) = lines.first() else {
        return Reply::Empty;
    };
    if let Some((code, text)) = parse_error(first) {
        return Reply::Error { code, text };
    }
    if lines.len() == 1 {
        if let Some((k, v)) = first.split_once('=') {
            return Reply::Value {
                key: k.trim().to_string(),
                value: v.trim().to_string(),
            };
        }
    }
    Reply::Lines(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    // Strings from protocols/alien-alr9900.md §1.4 and §2.
    #[test]
    fn errors() {
        assert_eq!(
            parse_reply("Error 1: Command not understood.\r\n"),
            Reply::Error {
                code: Some(1),
                text: "Command not understood.".into()
            }
        );
        assert_eq!(
            parse_reply("Error 154: Read error."),
            Reply::Error {
                code: Some(154),
                text: "Read error.".into()
            }
        );
        assert_eq!(
            parse_reply("Error: Invalid Username and/or Password"),
            Reply::Error {
                code: None,
                text: "Invalid Username and/or Password".into()
            }
        );
    }

    #[test]
    fn values_and_quirky_keys() {
        assert_eq!(
            parse_reply("ReaderName = Alien RFID Reader\r\n"),
            Reply::Value {
                key: "ReaderName".into(),
                value: "Alien RFID Reader".into()
            }
        );
        assert_eq!(
            parse_reply("Uptime (secs) = 702048"),
            Reply::Value {
                key: "Uptime (secs)".into(),
                value: "702048".into()
            }
        );
        assert_eq!(
            parse_reply("TagListCustomFormat = IDK %i RSSI %m TIME %t;"),
            Reply::Value {
                key: "TagListCustomFormat".into(),
                value: "IDK %i RSSI %m TIME %t;".into()
            }
        );
        assert_eq!(parse_reply("\r\n"), Reply::Empty);
        assert_eq!(
            parse_reply("(No Tags)\r\n"),
            Reply::Lines(vec!["(No Tags)".into()])
        );
    }

    #[test]
    fn session_messages() {
        assert_eq!(
            session_end("Connection Timeout.\r\n"),
            Some(SessionEnd::ConnectionTimeout)
        );
        assert_eq!(session_end("Goodbye!"), Some(SessionEnd::Goodbye));
        assert_eq!(
            session_end("Reader is busy. Please call back later."),
            Some(SessionEnd::Busy)
        );
        assert_eq!(session_end("ReaderName = x"), None);
    }
}
