//! Sensor → host replies, sans-IO: bytes in, [`Reply`]s out.
//!
//! A reply is a run of LF-terminated lines closed by an empty line (LF LF): the echo of the
//! command, a status line (two characters and a sum), then for a distance command that
//! succeeded a time stamp line (four characters and a sum) and data lines of up to 64
//! characters, each with its sum. [`ReplyDecoder`] cuts the stream at the empty lines, so a
//! damaged reply costs only itself: its bytes are dropped, counted and returned in the error,
//! and decoding goes on with the next reply.

use crate::encoding::{check_sum, decode, encode, verify_line};
use crate::error::ScipError;

/// One reply, its lines checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// The echoed command line.
    pub echo: Vec<u8>,
    /// The two status characters (`00` success; `99` for continuous data).
    pub status: [u8; 2],
    /// The sensor's millisecond time stamp (24 bits), for distance data.
    pub timestamp_ms: Option<u32>,
    /// The data characters of all data lines, sums removed, in order.
    pub data: Vec<u8>,
    /// The text lines of an information reply (`VV`, `PP`, `II`, `TM1`, `%ST`), as sent,
    /// sums included (see [`Reply::info`]); empty for other replies.
    pub lines: Vec<Vec<u8>>,
}

impl Reply {
    /// A successful distance reply to `echo` carrying `ranges_mm` (three characters each).
    #[must_use]
    pub fn distance(echo: &[u8], timestamp_ms: u32, ranges_mm: &[u32]) -> Self {
        Self::distance_encoded(echo, *b"00", timestamp_ms, ranges_mm, 3)
    }

    /// A distance reply with `status` (`00` for `GD`/`GS`, `99` for a scan of `MD`/`MS`) and
    /// `width` characters per value (3 for `GD`/`MD`, 2 for `GS`/`MS`).
    #[must_use]
    pub fn distance_encoded(
        echo: &[u8],
        status: [u8; 2],
        timestamp_ms: u32,
        ranges_mm: &[u32],
        width: usize,
    ) -> Self {
        Self {
            echo: echo.to_vec(),
            status,
            timestamp_ms: Some(timestamp_ms),
            data: ranges_mm.iter().flat_map(|r| encode(*r, width)).collect(),
            lines: Vec::new(),
        }
    }

    /// A status-only reply (no time stamp, no data).
    #[must_use]
    pub fn status_only(echo: &[u8], status: [u8; 2]) -> Self {
        Self {
            echo: echo.to_vec(),
            status,
            timestamp_ms: None,
            data: Vec::new(),
            lines: Vec::new(),
        }
    }

    /// An information reply: status `00`, then one line per `(key, value)`, written
    /// `KEY:value;sum` with the sum over `KEY:value` (REF §8.11-8.13; the `PP` example
    /// `DMIN:20;4`).
    #[must_use]
    pub fn information(echo: &[u8], fields: &[(&str, String)]) -> Self {
        let lines = fields
            .iter()
            .map(|(k, v)| {
                let mut l = format!("{k}:{v}").into_bytes();
                let sum = check_sum(&l);
                l.push(b';');
                l.push(sum);
                l
            })
            .collect();
        Self {
            lines,
            ..Self::status_only(echo, *b"00")
        }
    }

    /// The `KEY:value` pairs of an information reply, in order.
    ///
    /// # Errors
    /// [`ScipError::CheckSum`] for a line whose sum does not match, [`ScipError::Malformed`]
    /// for a line without `:` and `;`.
    pub fn info(&self) -> Result<Vec<(String, String)>, ScipError> {
        self.lines
            .iter()
            .filter(|l| !l.is_empty())
            .map(|line| {
                let (sum, rest) = line.split_last().ok_or_else(|| ScipError::Malformed {
                    why: "empty information line",
                    bytes: line.clone(),
                })?;
                let text = rest
                    .strip_suffix(b";")
                    .ok_or_else(|| ScipError::Malformed {
                        why: "information line without ';'",
                        bytes: line.clone(),
                    })?;
                if check_sum(text) != *sum {
                    return Err(ScipError::CheckSum { line: line.clone() });
                }
                let text = String::from_utf8_lossy(text);
                let (k, v) = text.split_once(':').ok_or_else(|| ScipError::Malformed {
                    why: "information line without ':'",
                    bytes: line.clone(),
                })?;
                Ok((k.to_string(), v.to_string()))
            })
            .collect()
    }

    /// The reply as the sensor sends it: the echo, the status with its sum, for distance data
    /// the time stamp and the data in lines of 64 characters, each with its sum, and the
    /// closing empty line.
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = self.echo.clone();
        out.push(b'\n');
        out.extend_from_slice(&self.status);
        out.push(check_sum(&self.status));
        out.push(b'\n');
        for line in &self.lines {
            out.extend_from_slice(line);
            out.push(b'\n');
        }
        if let Some(stamp) = self.timestamp_ms {
            let t = encode(stamp, 4);
            out.extend_from_slice(&t);
            out.push(check_sum(&t));
            out.push(b'\n');
            for chunk in self.data.chunks(64) {
                out.extend_from_slice(chunk);
                out.push(check_sum(chunk));
                out.push(b'\n');
            }
        }
        out.push(b'\n');
        out
    }

    /// Whether the status is success (`00`, or `99` for continuous data).
    #[must_use]
    pub fn ok(&self) -> bool {
        matches!(&self.status, b"00" | b"99")
    }

    /// Parses the lines of one reply (without the closing empty line).
    ///
    /// # Errors
    /// Check sum mismatches and malformed lines, with the offending bytes.
    pub fn parse(lines: &[&[u8]]) -> Result<Self, ScipError> {
        let whole = || lines.join(&b'\n');
        let (echo, rest) = lines.split_first().ok_or_else(|| ScipError::Malformed {
            why: "empty reply",
            bytes: Vec::new(),
        })?;
        let (status_line, rest) = rest.split_first().ok_or_else(|| ScipError::Malformed {
            why: "no status line",
            bytes: whole(),
        })?;
        let status = match verify_line(status_line)? {
            [a, b] => [*a, *b],
            _ => {
                return Err(ScipError::Malformed {
                    why: "status is not two characters",
                    bytes: whole(),
                })
            }
        };
        // Distance data follows `00` for a single scan (GD, GS) and `99` for each scan of a
        // continuous request (MD, MS, whose first reply is a bare `00`).
        let single = echo.starts_with(b"GD") || echo.starts_with(b"GS");
        let continuous = echo.starts_with(b"MD") || echo.starts_with(b"MS");
        let mut reply = Reply::status_only(echo, status);
        if !((single && &status == b"00") || (continuous && &status == b"99")) {
            // Other replies (BM, QT, VV, PP, …): their text lines, checked by `info`.
            reply.lines = rest.iter().map(|l| l.to_vec()).collect();
            return Ok(reply);
        }
        let (stamp, data_lines) = rest.split_first().ok_or_else(|| ScipError::Malformed {
            why: "no time stamp line",
            bytes: whole(),
        })?;
        let stamp = verify_line(stamp)?;
        reply.timestamp_ms = Some(decode(stamp).filter(|_| stamp.len() == 4).ok_or_else(|| {
            ScipError::Malformed {
                why: "time stamp is not four characters",
                bytes: whole(),
            }
        })?);
        for line in data_lines {
            let payload = verify_line(line)?;
            if payload.len() > 64 {
                return Err(ScipError::Malformed {
                    why: "data line longer than 64 characters",
                    bytes: line.to_vec(),
                });
            }
            reply.data.extend_from_slice(payload);
        }
        Ok(reply)
    }
}

/// Counters of a decoder.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct DecodeStats {
    /// Replies decoded.
    pub replies: u64,
    /// Replies dropped (check sums, malformed lines).
    pub bad_replies: u64,
    /// Bytes dropped with them, and bytes of overlong runs without an empty line.
    pub dropped_bytes: u64,
}

/// Bytes buffered without an empty line before they are given up as garbage.
pub const MAX_REPLY_BYTES: usize = 16 * 1024;

/// Cuts a byte stream into replies.
#[derive(Debug, Default)]
pub struct ReplyDecoder {
    buf: Vec<u8>,
    stats: DecodeStats,
}

impl ReplyDecoder {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
        if self.buf.len() > MAX_REPLY_BYTES && find_end(&self.buf).is_none() {
            let dropped = self.buf.len();
            self.stats.dropped_bytes += dropped as u64;
            tracing::warn!(dropped, "SCIP stream without a reply end; bytes dropped");
            self.buf.clear();
        }
    }

    /// The next complete reply, if one has arrived; a damaged one as an error (its bytes
    /// dropped and counted).
    pub fn next_reply(&mut self) -> Option<Result<Reply, ScipError>> {
        loop {
            // Empty lines before a reply (a lost reply's tail) carry nothing: drop them at once,
            // so a run of line feeds costs one pass, not one pass per pair.
            let blank = self
                .buf
                .iter()
                .take_while(|b| matches!(b, b'\n' | b'\r'))
                .count();
            if blank > 0 {
                self.buf.drain(..blank);
            }
            let (end, after) = find_end(&self.buf)?;
            let raw: Vec<u8> = self.buf.drain(..after).collect();
            // Sensors may send CR LF; a stray CR at a line end is not data.
            let body = raw.get(..end).unwrap_or_default();
            let lines: Vec<&[u8]> = body
                .split(|b| *b == b'\n')
                .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
                .collect();
            // Leading empty lines (a lost reply's tail) are skipped; a run of nothing but
            // empty lines is no reply at all.
            let first = lines
                .iter()
                .position(|l| !l.is_empty())
                .unwrap_or(lines.len());
            let lines = lines.get(first..).unwrap_or_default();
            if lines.is_empty() {
                continue;
            }
            return match Reply::parse(lines) {
                Ok(r) => {
                    self.stats.replies += 1;
                    Some(Ok(r))
                }
                Err(e) => {
                    self.stats.bad_replies += 1;
                    self.stats.dropped_bytes += raw.len() as u64;
                    tracing::warn!(error = %e, dropped = raw.len(), "SCIP reply dropped");
                    Some(Err(e))
                }
            };
        }
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }
}

/// Where the first reply ends: (end of its last line, end of the empty line after it). A CR
/// before the closing LF (CR LF line ends) is accepted.
fn find_end(buf: &[u8]) -> Option<(usize, usize)> {
    let lf_lf = buf
        .windows(2)
        .position(|w| w == b"\n\n")
        .map(|i| (i, i + 2));
    let lf_cr_lf = buf
        .windows(3)
        .position(|w| w == b"\n\r\n")
        .map(|i| (i, i + 3));
    match (lf_lf, lf_cr_lf) {
        (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
        (a, b) => a.or(b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encoding::check_sum;

    /// A GD reply as the manual lays it out, for `ranges` (mm).
    fn gd_reply(echo: &[u8], stamp: u32, ranges: &[u32]) -> Vec<u8> {
        Reply::distance(echo, stamp, ranges).to_bytes()
    }

    #[test]
    fn a_gd_reply_decodes_with_its_time_stamp_and_data() {
        let bytes = gd_reply(b"GD0044004601", 16_000_000, &[5432, 1234, 20]);
        let mut d = ReplyDecoder::new();
        d.push(&bytes);
        let r = d.next_reply().unwrap().unwrap();
        assert_eq!(r.echo, b"GD0044004601");
        assert!(r.ok());
        assert_eq!(r.timestamp_ms, Some(16_000_000));
        assert_eq!(r.data, b"1Dh0CB00D".to_vec());
        assert!(d.next_reply().is_none());
        assert_eq!(d.stats().replies, 1);
    }

    #[test]
    fn replies_are_written_as_the_manual_lays_them_out() {
        // Steps 44–46: 5432, 1234 and 20 mm at 16 000 000 ms. Sums by hand: `m2@0` adds up to
        // 0x10F, low 6 bits 0x0F + 0x30 = `?`; `1Dh0CB00D` to 0x236, 0x36 + 0x30 = `f`.
        let bytes = gd_reply(b"GD0044004601", 16_000_000, &[5432, 1234, 20]);
        assert_eq!(bytes, b"GD0044004601\n00P\nm2@0?\n1Dh0CB00Df\n\n".to_vec());
        let status = Reply::status_only(b"BM", *b"02");
        assert_eq!(status.to_bytes(), b"BM\n02R\n\n".to_vec());
    }

    #[test]
    fn a_status_reply_has_no_data() {
        let mut d = ReplyDecoder::new();
        d.push(b"BM\n00P\n\nQT\n00P\n\n");
        let bm = d.next_reply().unwrap().unwrap();
        assert_eq!((bm.echo.as_slice(), bm.status), (&b"BM"[..], *b"00"));
        let qt = d.next_reply().unwrap().unwrap();
        assert_eq!(qt.echo, b"QT");
    }

    #[test]
    fn a_damaged_reply_is_dropped_and_the_next_one_decodes() {
        let mut good = gd_reply(b"GD0044004601", 7, &[1000, 1001, 1002]);
        let mut bad = good.clone();
        // Corrupt one data character: its line's sum no longer matches.
        let pos = bad.len() - 4;
        bad[pos] ^= 0x01;
        bad.append(&mut good);
        let mut d = ReplyDecoder::new();
        d.push(&bad);
        assert!(matches!(
            d.next_reply(),
            Some(Err(ScipError::CheckSum { .. }))
        ));
        assert_eq!(d.next_reply().unwrap().unwrap().timestamp_ms, Some(7));
        let s = d.stats();
        assert_eq!((s.replies, s.bad_replies), (1, 1));
        assert!(s.dropped_bytes > 0);
    }

    #[test]
    fn garbage_without_a_reply_end_is_bounded() {
        let mut d = ReplyDecoder::new();
        d.push(&vec![b'x'; MAX_REPLY_BYTES + 1]);
        assert!(d.next_reply().is_none());
        assert_eq!(d.stats().dropped_bytes, (MAX_REPLY_BYTES + 1) as u64);
        d.push(b"BM\n00P\n\n");
        assert!(d.next_reply().unwrap().is_ok());
    }

    #[test]
    fn a_long_run_of_empty_lines_is_skipped_without_recursion() {
        let mut d = ReplyDecoder::new();
        d.push(&vec![b'\n'; MAX_REPLY_BYTES - 16]);
        d.push(b"QT\n00P\n\n");
        assert_eq!(d.next_reply().unwrap().unwrap().echo, b"QT");
        assert!(d.next_reply().is_none());
    }

    #[test]
    fn the_specification_pp_example_decodes() {
        // REF §8.12's PP example (sums as printed there: `DMIN:20` → `4`, `DMAX:5600` → `_`,
        // `AMIN:44` → `7`, `AMAX:725` → `o`, `AFRT:384` → `6`, `SCAN:600` → `e`; the copy read
        // shows `/` for `ARES:1024`'s `\` and a MODL text whose sum cannot be checked).
        let bytes = b"PP\n00P\nMODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N\nDMIN:20;4\nDMAX:5600;_\nARES:1024;\\\nAMIN:44;7\nAMAX:725;o\nAFRT:384;6\nSCAN:600;e\n\n";
        let mut d = ReplyDecoder::new();
        d.push(bytes);
        let r = d.next_reply().unwrap().unwrap();
        let info = r.info().unwrap();
        assert_eq!(info.len(), 8);
        assert_eq!(info[1], ("DMIN".to_string(), "20".to_string()));
        assert_eq!(info[7], ("SCAN".to_string(), "600".to_string()));
        // Written back identically.
        let fields: Vec<(&str, String)> =
            info.iter().map(|(k, v)| (k.as_str(), v.clone())).collect();
        assert_eq!(
            Reply::information(b"PP", &fields).to_bytes(),
            bytes.to_vec()
        );
    }

    #[test]
    fn md_replies_decode_with_and_without_data() {
        let mut d = ReplyDecoder::new();
        d.push(b"MD0044004601001\n00P\n\n");
        let first = d.next_reply().unwrap().unwrap();
        assert!(first.ok() && first.timestamp_ms.is_none());
        let scan = Reply::distance_encoded(b"MD0044004601000", *b"99", 7, &[1234, 20, 4095], 2);
        d.push(&scan.to_bytes());
        let r = d.next_reply().unwrap().unwrap();
        assert_eq!((r.status, r.timestamp_ms), (*b"99", Some(7)));
        assert_eq!(r.data, b"CB0Doo".to_vec());
    }

    #[test]
    fn an_error_status_is_a_reply_without_data() {
        let mut d = ReplyDecoder::new();
        let sum = check_sum(b"10");
        d.push(&[b"GD0044072501\n10".as_slice(), &[sum, b'\n', b'\n']].concat());
        let r = d.next_reply().unwrap().unwrap();
        assert!(!r.ok());
        assert_eq!(r.status, *b"10");
        assert!(r.data.is_empty() && r.timestamp_ms.is_none());
    }
}
