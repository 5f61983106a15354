//! Strict capture reader.

use std::path::Path;

use crate::error::{CaptureError, CaptureErrorKind};
use crate::escape::{decode_hex, decode_text};
use crate::header::Header;
use crate::record::{format_time, parse_time, Record, RecordKind};
use crate::MAGIC;

/// A parsed capture: header and records in time order.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Capture {
    pub header: Header,
    pub records: Vec<Record>,
}

impl Capture {
    /// Reads and parses a capture file. Errors name the file and line.
    pub fn from_path(path: &Path) -> Result<Self, CaptureError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| CaptureError {
            source_name: name.clone(),
            line: 0,
            kind: CaptureErrorKind::Io(e.to_string()),
        })?;
        Self::parse_bytes(&bytes, &name)
    }

    /// Parses capture bytes (which must be UTF-8 line by line).
    pub fn parse_bytes(bytes: &[u8], source_name: &str) -> Result<Self, CaptureError> {
        let mut cap = Capture::default();
        let mut previous: Option<u64> = None;
        let mut in_header = true;
        let mut lines = bytes.split(|&b| b == b'\n').enumerate().peekable();
        while let Some((idx, raw)) = lines.next() {
            let line_no = idx + 1;
            let err = |kind| CaptureError {
                source_name: source_name.to_string(),
                line: line_no,
                kind,
            };
            // The final split after a trailing newline is empty: not a line.
            if raw.is_empty() && lines.peek().is_none() {
                break;
            }
            let line = std::str::from_utf8(raw).map_err(|_| err(CaptureErrorKind::NotUtf8))?;
            if idx == 0 {
                if line != MAGIC {
                    return Err(err(CaptureErrorKind::BadMagic(
                        line.chars().take(60).collect(),
                    )));
                }
                continue;
            }
            if line.is_empty() {
                continue;
            }
            if let Some(comment) = line.strip_prefix('#') {
                if in_header {
                    if let Some((k, v)) = comment.trim_start().split_once(": ") {
                        if !k.is_empty() && !k.contains(' ') {
                            cap.header.absorb(k, v);
                        }
                    }
                }
                continue;
            }
            in_header = false;
            let record = parse_record(line).map_err(err)?;
            if let Some(prev) = previous {
                if record.t_ns < prev {
                    return Err(err(CaptureErrorKind::TimeGoesBack {
                        previous: format_time(prev),
                        found: format_time(record.t_ns),
                    }));
                }
            }
            previous = Some(record.t_ns);
            cap.records.push(record);
        }
        if bytes.is_empty() {
            return Err(CaptureError {
                source_name: source_name.to_string(),
                line: 1,
                kind: CaptureErrorKind::BadMagic(String::new()),
            });
        }
        Ok(cap)
    }

    /// Parses capture text.
    pub fn parse(text: &str, source_name: &str) -> Result<Self, CaptureError> {
        Self::parse_bytes(text.as_bytes(), source_name)
    }

    /// The capture as text in the canonical form the writer produces.
    #[must_use]
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        s.push_str(MAGIC);
        s.push('\n');
        s.push_str(&self.header.to_lines());
        for r in &self.records {
            s.push_str(&r.to_line());
            s.push('\n');
        }
        s
    }

    /// All rx bytes concatenated.
    #[must_use]
    pub fn rx_bytes(&self) -> Vec<u8> {
        self.collect(|k| matches!(k, RecordKind::Rx(_)))
    }

    /// All tx bytes concatenated.
    #[must_use]
    pub fn tx_bytes(&self) -> Vec<u8> {
        self.collect(|k| matches!(k, RecordKind::Tx(_)))
    }

    fn collect(&self, pick: impl Fn(&RecordKind) -> bool) -> Vec<u8> {
        self.records
            .iter()
            .filter(|r| pick(&r.kind))
            .filter_map(Record::bytes)
            .flatten()
            .copied()
            .collect()
    }

    /// Events with their times in seconds.
    pub fn events(&self) -> impl Iterator<Item = (f64, &str)> {
        self.records.iter().filter_map(|r| match &r.kind {
            RecordKind::Event(e) => Some((r.t(), e.as_str())),
            _ => None,
        })
    }
}

fn parse_record(line: &str) -> Result<Record, CaptureErrorKind> {
    let short = || line.chars().take(80).collect::<String>();
    let (time, rest) = line
        .split_once(' ')
        .ok_or_else(|| CaptureErrorKind::MissingField(short()))?;
    let t_ns = parse_time(time).ok_or_else(|| CaptureErrorKind::BadTime(time.to_string()))?;
    let (dir, payload) = match rest.split_once(' ') {
        Some((d, p)) => (d, p),
        None => (rest, ""),
    };
    let kind = match dir {
        "ev" => {
            if payload.trim().is_empty() {
                return Err(CaptureErrorKind::EmptyEvent);
            }
            RecordKind::Event(payload.to_string())
        }
        "rx" | "tx" => {
            if payload.is_empty() {
                return Err(CaptureErrorKind::MissingField(short()));
            }
            let bytes = if let Some(hex) = payload.strip_prefix("x:") {
                decode_hex(hex).map_err(|reason| CaptureErrorKind::BadHex {
                    text: hex.to_string(),
                    reason,
                })?
            } else if let Some(text) = payload.strip_prefix("s:") {
                decode_text(text).map_err(|reason| CaptureErrorKind::BadText {
                    text: text.to_string(),
                    reason,
                })?
            } else {
                return Err(CaptureErrorKind::BadPayloadKind(
                    payload.chars().take(20).collect(),
                ));
            };
            if dir == "rx" {
                RecordKind::Rx(bytes)
            } else {
                RecordKind::Tx(bytes)
            }
        }
        other => return Err(CaptureErrorKind::BadDirection(other.to_string())),
    };
    Ok(Record { t_ns, kind })
}
