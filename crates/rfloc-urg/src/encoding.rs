//! SCIP 2.0 character encodings and the line check sum.
//!
//! Values are split into 6-bit groups, most significant first, and each group is sent as the
//! character `0x30 + group`: two characters carry 12 bits (1234 → `CB`), three 18 bits
//! (5432 → `1Dh`), four 24 bits (16 000 000 → `m2@0`). A line's check sum is one character:
//! the low 6 bits of the sum of the line's bytes, plus `0x30` (`00` → `P`, `99` → `b`).

use crate::error::ScipError;

/// Encodes the low `6 · width` bits of `value` in `width` characters.
#[must_use]
pub fn encode(value: u32, width: usize) -> Vec<u8> {
    (0..width)
        .rev()
        .map(|i| {
            let shift = 6 * i;
            // Each group is 6 bits, so the character is 0x30..=0x6F.
            let group = if shift < 32 {
                (value >> shift) & 0x3F
            } else {
                0
            };
            0x30 + u8::try_from(group).unwrap_or(0)
        })
        .collect()
}

/// Decodes characters written by [`encode`]; `None` for a character outside `0x30..=0x6F` or
/// more than five characters (30 bits).
#[must_use]
pub fn decode(chars: &[u8]) -> Option<u32> {
    if chars.len() > 5 {
        return None;
    }
    chars.iter().try_fold(0u32, |acc, &c| {
        let group = c.checked_sub(0x30).filter(|g| *g < 0x40)?;
        Some((acc << 6) | u32::from(group))
    })
}

/// The check sum character of `bytes` (a line without its sum and line feed).
#[must_use]
pub fn check_sum(bytes: &[u8]) -> u8 {
    let sum = bytes
        .iter()
        .fold(0u32, |s, &b| s.wrapping_add(u32::from(b)));
    0x30 + u8::try_from(sum & 0x3F).unwrap_or(0)
}

/// Splits a data line into its payload and verifies its last byte as the check sum.
///
/// # Errors
/// [`ScipError::CheckSum`] with the line when the sum is wrong or the line is empty.
pub fn verify_line(line: &[u8]) -> Result<&[u8], ScipError> {
    match line.split_last() {
        Some((&sum, payload)) if check_sum(payload) == sum => Ok(payload),
        _ => Err(ScipError::CheckSum {
            line: line.to_vec(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_examples_encode_and_decode() {
        assert_eq!(encode(1234, 2), b"CB");
        assert_eq!(encode(5432, 3), b"1Dh");
        assert_eq!(encode(16_000_000, 4), b"m2@0");
        assert_eq!(decode(b"CB"), Some(1234));
        assert_eq!(decode(b"1Dh"), Some(5432));
        assert_eq!(decode(b"m2@0"), Some(16_000_000));
    }

    #[test]
    fn status_lines_carry_their_sums() {
        assert_eq!(check_sum(b"00"), b'P');
        assert_eq!(check_sum(b"99"), b'b');
        assert_eq!(verify_line(b"00P"), Ok(&b"00"[..]));
        assert!(verify_line(b"00Q").is_err());
        assert!(verify_line(b"").is_err());
    }

    #[test]
    fn out_of_range_characters_do_not_decode() {
        assert_eq!(decode(b"1/h"), None, "0x2F is below the alphabet");
        assert_eq!(decode(b"1\x70h"), None, "0x70 is above it");
        assert_eq!(decode(b"000000"), None, "more than 30 bits");
    }
}
