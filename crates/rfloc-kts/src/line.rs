//! Classifying one reader line.
//!
//! Classes, tried in this order (see `docs/protocols/kts-rfidm1356.md`): `OK`, `ERROR`,
//! `+CME ERROR: n`, `SCAN:+UID=…[,+RSSI=a[/b]]` (tag seen), `SCAN:-UID=…` (tag lost),
//! `+UID=…[,KEY=VALUE…]` (inventory / system info), an echoed command (`AT…`), free text.
//! Keywords are case-insensitive and spaces around `=`, `,` and `/` are allowed. A line that
//! claims a class but does not fit it is a [`MalformedLine`] carrying the text.

use crate::uid::{Uid, UidError};

/// The two RSSI numbers of a read: main and auxiliary receiver channel (seed 002 §5: "the
/// first number the value for the main and the second for the auxiliary receiver channel").
/// Observed values are 0…7.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Rssi {
    pub main: i32,
    pub aux: Option<i32>,
}

impl std::fmt::Display for Rssi {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.aux {
            Some(a) => write!(f, "{}/{a}", self.main),
            None => write!(f, "{}", self.main),
        }
    }
}

/// A classified reader line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KtsLine {
    Ok,
    Error,
    CmeError(u32),
    /// `SCAN:+UID=…`: a tag in the field. RSSI is optional in the grammar; the scan mode
    /// `AT+Scan=AC,RSSI` always prints it.
    ScanSeen {
        uid: Uid,
        rssi: Option<Rssi>,
    },
    /// `SCAN:-UID=…`: a tag left the field. Not a position fix; seed 002 drops these.
    ScanLost {
        uid: Uid,
    },
    /// `+UID=…` with its other `KEY=VALUE` fields (inventory or system-info reply).
    Inventory {
        uid: Uid,
        rssi: Option<Rssi>,
        fields: Vec<(String, String)>,
    },
    /// A line starting with `AT`: the module echoing a command.
    Echo(String),
    /// Any other printable text (banner, version, `S/N …`).
    Info(String),
}

/// Why a line was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MalformedReason {
    #[error("bad UID: {0}")]
    Uid(#[from] UidError),
    #[error("missing UID= field")]
    MissingUid,
    #[error("bad RSSI value {0:?}")]
    Rssi(String),
    #[error("bad +CME ERROR code {0:?}")]
    CmeCode(String),
    #[error("line is not printable ASCII")]
    NotText,
    #[error("line longer than the framing limit")]
    Overlong,
}

/// A line that could not be classified, with its bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed line {:?}: {reason}", String::from_utf8_lossy(.bytes))]
pub struct MalformedLine {
    pub bytes: Vec<u8>,
    pub reason: MalformedReason,
}

fn strip_prefix_ci<'a>(s: &'a str, prefix: &str) -> Option<&'a str> {
    let head = s.get(..prefix.len())?;
    if head.eq_ignore_ascii_case(prefix) {
        s.get(prefix.len()..)
    } else {
        None
    }
}

/// Parses `a`, `a/b` (spaces allowed, signed integers).
fn parse_rssi(v: &str) -> Result<Rssi, MalformedReason> {
    let bad = || MalformedReason::Rssi(v.to_string());
    let mut parts = v.split('/');
    let main = parts.next().map(str::trim).ok_or_else(bad)?;
    let main: i32 = main.parse().map_err(|_| bad())?;
    let aux = match parts.next() {
        Some(a) => Some(a.trim().parse::<i32>().map_err(|_| bad())?),
        None => None,
    };
    if parts.next().is_some() {
        return Err(bad());
    }
    if !(0..=7).contains(&main) || aux.is_some_and(|a| !(0..=7).contains(&a)) {
        tracing::debug!(rssi = v, "RSSI outside the 0..7 seen so far");
    }
    Ok(Rssi { main, aux })
}

/// Splits `KEY=VALUE,KEY=VALUE` (optional `+` before keys) into pairs; keys upper-cased.
fn fields(s: &str) -> Vec<(String, String)> {
    s.split(',')
        .filter(|f| !f.trim().is_empty())
        .map(|f| {
            let f = f.trim();
            let f = f.strip_prefix('+').unwrap_or(f);
            match f.split_once('=') {
                Some((k, v)) => (k.trim().to_ascii_uppercase(), v.trim().to_string()),
                None => (f.to_ascii_uppercase(), String::new()),
            }
        })
        .collect()
}

/// The UID and RSSI of a field list; `UID` must be present.
fn uid_and_rssi(pairs: &[(String, String)]) -> Result<(Uid, Option<Rssi>), MalformedReason> {
    let uid = pairs
        .iter()
        .find(|(k, _)| k == "UID")
        .map(|(_, v)| v)
        .ok_or(MalformedReason::MissingUid)?;
    let uid = Uid::parse(uid)?;
    let rssi = match pairs.iter().find(|(k, _)| k == "RSSI") {
        Some((_, v)) => Some(parse_rssi(v)?),
        None => None,
    };
    Ok((uid, rssi))
}

/// Classifies one line (without terminator).
///
/// # Errors
/// [`MalformedLine`] with the offending bytes when the line is not printable ASCII or claims a
/// class (`SCAN:`, `+UID=`, `+CME ERROR:`) it does not fit.
pub fn parse_line(bytes: &[u8]) -> Result<KtsLine, MalformedLine> {
    let malformed = |reason| MalformedLine {
        bytes: bytes.to_vec(),
        reason,
    };
    if !bytes.iter().all(|b| (0x20..0x7F).contains(b)) {
        return Err(malformed(MalformedReason::NotText));
    }
    let text = std::str::from_utf8(bytes).map_err(|_| malformed(MalformedReason::NotText))?;
    let t = text.trim();
    if t.eq_ignore_ascii_case("OK") {
        return Ok(KtsLine::Ok);
    }
    if t.eq_ignore_ascii_case("ERROR") {
        return Ok(KtsLine::Error);
    }
    if let Some(code) = strip_prefix_ci(t, "+CME ERROR") {
        let code = code.trim_start().strip_prefix(':').unwrap_or(code).trim();
        return code
            .parse()
            .map(KtsLine::CmeError)
            .map_err(|_| malformed(MalformedReason::CmeCode(code.to_string())));
    }
    if let Some(rest) = strip_prefix_ci(t, "SCAN:") {
        let rest = rest.trim_start();
        let (lost, rest) = match rest.strip_prefix('-') {
            Some(r) => (true, r),
            None => (false, rest.strip_prefix('+').unwrap_or(rest)),
        };
        let pairs = fields(rest);
        let (uid, rssi) = uid_and_rssi(&pairs).map_err(malformed)?;
        return Ok(if lost {
            KtsLine::ScanLost { uid }
        } else {
            KtsLine::ScanSeen { uid, rssi }
        });
    }
    if strip_prefix_ci(t, "+UID").is_some_and(|r| r.trim_start().starts_with('=')) {
        let pairs = fields(t);
        let (uid, rssi) = uid_and_rssi(&pairs).map_err(malformed)?;
        let fields = pairs
            .into_iter()
            .filter(|(k, _)| k != "UID" && k != "RSSI")
            .collect::<Vec<_>>();
        return Ok(KtsLine::Inventory { uid, rssi, fields });
    }
    if strip_prefix_ci(t, "AT").is_some() {
        return Ok(KtsLine::Echo(t.to_string()));
    }
    Ok(KtsLine::Info(t.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uid(s: &str) -> Uid {
        Uid::parse(s).unwrap()
    }

    // Test vectors: protocols/kts-rfidm1356.md §5.
    #[test]
    fn reference_vectors() {
        assert_eq!(
            parse_line(b"SCAN:+UID=E00402000018313E,+RSSI=7/6"),
            Ok(KtsLine::ScanSeen {
                uid: uid("E00402000018313E"),
                rssi: Some(Rssi {
                    main: 7,
                    aux: Some(6)
                })
            })
        );
        assert_eq!(
            parse_line(b"SCAN:+UID=E00401001C2017BD,+RSSI=0/2"),
            Ok(KtsLine::ScanSeen {
                uid: uid("E00401001C2017BD"),
                rssi: Some(Rssi {
                    main: 0,
                    aux: Some(2)
                })
            })
        );
        assert_eq!(
            parse_line(b"SCAN:-UID=E0022C1395900204"),
            Ok(KtsLine::ScanLost {
                uid: uid("E0022C1395900204")
            })
        );
        assert_eq!(
            parse_line(b"+UID=E00401001C2017BD,+RSSI=0/2"),
            Ok(KtsLine::Inventory {
                uid: uid("E00401001C2017BD"),
                rssi: Some(Rssi {
                    main: 0,
                    aux: Some(2)
                }),
                fields: vec![]
            })
        );
        let Ok(KtsLine::Inventory {
            fields, rssi: None, ..
        }) = parse_line(b"+UID=E00401001C2017BD,DSFID=00,AFI=00,BC=28,BS=4,IC=01")
        else {
            panic!("system info line not parsed")
        };
        assert_eq!(fields.len(), 5);
        assert_eq!(fields[2], ("BC".to_string(), "28".to_string()));
        assert_eq!(parse_line(b"OK"), Ok(KtsLine::Ok));
        assert_eq!(parse_line(b"ERROR"), Ok(KtsLine::Error));
        assert_eq!(parse_line(b"+CME ERROR: 5"), Ok(KtsLine::CmeError(5)));
        assert_eq!(
            parse_line(b"ubisys 13.56MHz RFID (CDC) 1.08 Apr  7 2010"),
            Ok(KtsLine::Info(
                "ubisys 13.56MHz RFID (CDC) 1.08 Apr  7 2010".into()
            ))
        );
        let e = parse_line(b"SCAN:+UID=E0040200").unwrap_err();
        assert_eq!(e.bytes, b"SCAN:+UID=E0040200".to_vec());
        assert!(matches!(
            e.reason,
            MalformedReason::Uid(UidError::TruncatedIso15693(_))
        ));
    }

    #[test]
    fn iso14443_lengths_are_accepted() {
        // 4/7/10-byte ISO 14443 UIDs that do not start with E0 pass validation.
        assert!(matches!(
            parse_line(b"SCAN:+UID=08123456,+RSSI=1/1"),
            Ok(KtsLine::ScanSeen { .. })
        ));
        assert!(matches!(
            parse_line(b"+UID=04A1B2C3D4E5F6"),
            Ok(KtsLine::Inventory { .. })
        ));
        let e = parse_line(b"SCAN:+UID=E00402").unwrap_err();
        assert!(matches!(
            e.reason,
            MalformedReason::Uid(UidError::BadLength(_, 6))
        ));
    }

    #[test]
    fn tolerant_spelling() {
        assert_eq!(
            parse_line(b"  scan: + uid = e00402000018313e , +rssi = 3 / 4 "),
            Ok(KtsLine::ScanSeen {
                uid: uid("E00402000018313E"),
                rssi: Some(Rssi {
                    main: 3,
                    aux: Some(4)
                })
            })
        );
        assert_eq!(
            parse_line(b"SCAN:+UID=E00402000018313E,+RSSI=5"),
            Ok(KtsLine::ScanSeen {
                uid: uid("E00402000018313E"),
                rssi: Some(Rssi { main: 5, aux: None })
            })
        );
        assert_eq!(parse_line(b"ATI"), Ok(KtsLine::Echo("ATI".into())));
        assert_eq!(parse_line(b"+cme error:12"), Ok(KtsLine::CmeError(12)));
    }

    #[test]
    fn malformed_lines_carry_their_text() {
        for bad in [
            &b"SCAN:+UID=E00402000018313E,+RSSI=x/6"[..],
            b"SCAN:+RSSI=7/6",
            b"SCAN:+UID=E004020000183,+RSSI=7/6",
            b"+CME ERROR: five",
            b"SCAN:+UID=E00402000018313E,+RSSI=1/2/3",
            b"OK\xff",
        ] {
            let e = parse_line(bad).unwrap_err();
            assert_eq!(e.bytes, bad.to_vec());
        }
    }
}
