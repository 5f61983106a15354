//! Payload encodings: `x:` hex pairs and `s:` escaped text.

/// Decodes hex byte pairs; ASCII spaces between pairs are allowed.
pub fn decode_hex(text: &str) -> Result<Vec<u8>, &'static str> {
    let mut out = Vec::with_capacity(text.len() / 2);
    let mut high: Option<u8> = None;
    for c in text.bytes() {
        if c == b' ' {
            if high.is_some() {
                return Err("space inside a byte pair");
            }
            continue;
        }
        let nibble = match c {
            b'0'..=b'9' => c - b'0',
            b'a'..=b'f' => c - b'a' + 10,
            b'A'..=b'F' => c - b'A' + 10,
            _ => return Err("not a hex digit"),
        };
        match high.take() {
            None => high = Some(nibble),
            Some(h) => out.push((h << 4) | nibble),
        }
    }
    if high.is_some() {
        return Err("odd number of hex digits");
    }
    Ok(out)
}

/// Decodes an `s:` payload. Escapes: `\r \n \t \0 \\ \xHH`. Raw control characters are rejected
/// (they must be escaped), so a CRLF-damaged file is caught instead of silently adding `\r`.
pub fn decode_text(text: &str) -> Result<Vec<u8>, &'static str> {
    let mut out = Vec::with_capacity(text.len());
    let mut bytes = text.bytes();
    while let Some(b) = bytes.next() {
        if b == b'\\' {
            match bytes.next() {
                Some(b'r') => out.push(b'\r'),
                Some(b'n') => out.push(b'\n'),
                Some(b't') => out.push(b'\t'),
                Some(b'0') => out.push(0),
                Some(b'\\') => out.push(b'\\'),
                Some(b'x') => {
                    let hi = bytes.next().ok_or("truncated \\x escape")?;
                    let lo = bytes.next().ok_or("truncated \\x escape")?;
                    let pair = [hi, lo];
                    let s = std::str::from_utf8(&pair).map_err(|_| "bad \\x escape")?;
                    let v = u8::from_str_radix(s, 16).map_err(|_| "bad \\x escape")?;
                    out.push(v);
                }
                Some(_) => return Err("unknown escape"),
                None => return Err("trailing backslash"),
            }
        } else if b < 0x20 || b == 0x7f {
            return Err("raw control character (must be escaped)");
        } else {
            out.push(b);
        }
    }
    Ok(out)
}

/// Encodes bytes as a payload, choosing `s:` when the bytes are mostly printable text and `x:`
/// otherwise. The result always decodes back to the same bytes.
#[must_use]
pub fn encode_payload(bytes: &[u8]) -> String {
    let textual = bytes
        .iter()
        .filter(|&&b| (0x20..0x7f).contains(&b) || matches!(b, b'\r' | b'\n' | b'\t' | 0))
        .count();
    if !bytes.is_empty() && textual * 10 >= bytes.len() * 9 {
        let mut s = String::with_capacity(bytes.len() + 2);
        s.push_str("s:");
        for &b in bytes {
            match b {
                b'\r' => s.push_str("\\r"),
                b'\n' => s.push_str("\\n"),
                b'\t' => s.push_str("\\t"),
                0 => s.push_str("\\0"),
                b'\\' => s.push_str("\\\\"),
                0x20..=0x7e => s.push(char::from(b)),
                _ => s.push_str(&format!("\\x{b:02X}")),
            }
        }
        s
    } else {
        let mut s = String::with_capacity(bytes.len() * 3 + 2);
        s.push_str("x:");
        for (i, b) in bytes.iter().enumerate() {
            if i > 0 {
                s.push(' ');
            }
            s.push_str(&format!("{b:02X}"));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn hex_known_answer() {
        assert_eq!(
            decode_hex("7E 00 04 08 01 4E 44 64").unwrap(),
            vec![0x7E, 0x00, 0x04, 0x08, 0x01, 0x4E, 0x44, 0x64]
        );
        assert_eq!(decode_hex("7e0004").unwrap(), vec![0x7E, 0x00, 0x04]);
        assert!(decode_hex("7E 0").is_err());
        assert!(decode_hex("7 E").is_err());
        assert!(decode_hex("GG").is_err());
    }

    #[test]
    fn text_known_answer() {
        assert_eq!(decode_text("OK\\r\\n").unwrap(), b"OK\r\n".to_vec());
        assert_eq!(
            decode_text("a\\x01b\\0\\\\").unwrap(),
            vec![b'a', 1, b'b', 0, b'\\']
        );
        assert_eq!(decode_text("two  ").unwrap(), b"two  ".to_vec());
        assert!(decode_text("bad\\q").is_err());
        assert!(decode_text("raw\rcr").is_err());
        assert!(decode_text("x\\x4").is_err());
    }

    proptest! {
        #[test]
        fn payload_round_trips(bytes in proptest::collection::vec(any::<u8>(), 1..200)) {
            let enc = encode_payload(&bytes);
            let back = if let Some(rest) = enc.strip_prefix("s:") {
                decode_text(rest).unwrap()
            } else {
                decode_hex(enc.strip_prefix("x:").unwrap()).unwrap()
            };
            prop_assert_eq!(back, bytes);
        }
    }
}
