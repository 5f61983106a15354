//! One capture record.

use crate::escape::encode_payload;

/// What a record holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordKind {
    /// Bytes from the device to the host (one read as it happened).
    Rx(Vec<u8>),
    /// Bytes from the host to the device (one write as it happened).
    Tx(Vec<u8>),
    /// An event that is not bytes, e.g. `mark stop 1 heading_deg=45` or `gpio step=1`.
    Event(String),
}

/// A timed record. Time is nanoseconds since the start of the capture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    pub t_ns: u64,
    pub kind: RecordKind,
}

impl Record {
    /// Time in seconds since the start of the capture.
    #[must_use]
    #[allow(clippy::cast_precision_loss)]
    pub fn t(&self) -> f64 {
        Self::seconds(self.t_ns)
    }

    /// A record time in nanoseconds as seconds, the one conversion every reader uses.
    #[must_use]
    #[allow(clippy::cast_precision_loss)]
    pub fn seconds(t_ns: u64) -> f64 {
        t_ns as f64 * 1e-9
    }

    /// The bytes of an rx or tx record.
    #[must_use]
    pub fn bytes(&self) -> Option<&[u8]> {
        match &self.kind {
            RecordKind::Rx(b) | RecordKind::Tx(b) => Some(b),
            RecordKind::Event(_) => None,
        }
    }

    /// The record as one capture line, without the trailing newline.
    #[must_use]
    pub fn to_line(&self) -> String {
        let t = format_time(self.t_ns);
        match &self.kind {
            RecordKind::Rx(b) => format!("{t} rx {}", encode_payload(b)),
            RecordKind::Tx(b) => format!("{t} tx {}", encode_payload(b)),
            RecordKind::Event(e) => format!("{t} ev {e}"),
        }
    }
}

/// Seconds with 6 fraction digits, or 9 when the time is not a whole microsecond.
#[must_use]
pub fn format_time(t_ns: u64) -> String {
    let secs = t_ns / 1_000_000_000;
    let frac = t_ns % 1_000_000_000;
    if frac.is_multiple_of(1000) {
        format!("{secs}.{:06}", frac / 1000)
    } else {
        format!("{secs}.{frac:09}")
    }
}

/// Parses `<int>[.<1-9 digits>]` into nanoseconds.
pub(crate) fn parse_time(text: &str) -> Option<u64> {
    let (int, frac) = match text.split_once('.') {
        Some((i, f)) => (i, f),
        None => (text, ""),
    };
    if int.is_empty() || !int.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    if frac.len() > 9 || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    if text.contains('.') && frac.is_empty() {
        return None;
    }
    let secs: u64 = int.parse().ok()?;
    let mut ns: u64 = 0;
    for (i, b) in frac.bytes().enumerate() {
        let digit = u64::from(b - b'0');
        let exp = 8u32.checked_sub(u32::try_from(i).ok()?)?;
        ns += digit * 10u64.pow(exp);
    }
    secs.checked_mul(1_000_000_000)?.checked_add(ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_parses_exactly() {
        assert_eq!(parse_time("0.012400"), Some(12_400_000));
        assert_eq!(parse_time("1.701625"), Some(1_701_625_000));
        assert_eq!(parse_time("3"), Some(3_000_000_000));
        assert_eq!(parse_time("0.000000001"), Some(1));
        assert_eq!(parse_time("0.0000000001"), None);
        assert_eq!(parse_time("-1.0"), None);
        assert_eq!(parse_time("1e3"), None);
        assert_eq!(parse_time("1."), None);
        assert_eq!(parse_time(".5"), None);
    }

    #[test]
    fn time_formats_back() {
        assert_eq!(format_time(12_400_000), "0.012400");
        assert_eq!(format_time(1), "0.000000001");
        assert_eq!(format_time(3_000_000_000), "3.000000");
    }
}
