//! Tag UIDs as the reader prints them (hex, most significant byte first) and their validation.
//!
//! ISO/IEC 15693 UIDs are 8 bytes printed as 16 hex digits starting `E0`, followed by a
//! non-zero IC manufacturer code (ISO/IEC 7816-6, e.g. `04` = NXP). ISO/IEC 14443 UIDs are
//! 4, 7 or 10 bytes. A 16-digit string ending in `E0` is a byte-reversed ISO 15693 UID and is
//! normalised, not rejected.

use std::fmt;

/// Which standard a UID's length and prefix fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum UidKind {
    /// 8 bytes, `E0`, manufacturer, chip id, serial.
    Iso15693,
    /// 4, 7 or 10 bytes (not starting `E0`: a shorter UID starting `E0` is taken as a
    /// truncated ISO 15693 read).
    Iso14443,
}

/// Why a UID text was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UidError {
    #[error("UID is empty")]
    Empty,
    #[error("UID {0:?} contains a non-hex character")]
    NotHex(String),
    #[error("UID {0:?} has {1} hex digits; expected 8, 14, 20 (ISO 14443) or 16 (ISO 15693)")]
    BadLength(String, usize),
    #[error("16-digit UID {0:?} does not start with E0 (ISO 15693)")]
    NotIso15693(String),
    #[error("UID {0:?} starts with E0 but is shorter than an ISO 15693 UID (truncated read)")]
    TruncatedIso15693(String),
    #[error("ISO 15693 UID {0:?} has manufacturer code 00")]
    NoManufacturer(String),
}

/// A validated tag UID, stored most significant byte first.
#[derive(
    Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct Uid {
    bytes: Vec<u8>,
}

impl Uid {
    /// Parses the reader's hex text (case-insensitive, surrounding whitespace ignored).
    ///
    /// # Errors
    /// [`UidError`] when the text is not a valid ISO 15693 or ISO 14443 UID.
    pub fn parse(text: &str) -> Result<Self, UidError> {
        let t = text.trim();
        if t.is_empty() {
            return Err(UidError::Empty);
        }
        if !t.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(UidError::NotHex(t.to_string()));
        }
        let n = t.len();
        let mut bytes = decode_hex(t).ok_or_else(|| UidError::BadLength(t.to_string(), n))?;
        match n {
            8 | 14 | 20 if bytes.first() == Some(&0xE0) => {
                Err(UidError::TruncatedIso15693(t.to_string()))
            }
            8 | 14 | 20 => Ok(Self { bytes }),
            16 => {
                if bytes.first() != Some(&0xE0) {
                    if bytes.last() == Some(&0xE0) {
                        bytes.reverse();
                    } else {
                        return Err(UidError::NotIso15693(t.to_string()));
                    }
                }
                if bytes.get(1) == Some(&0) {
                    return Err(UidError::NoManufacturer(t.to_string()));
                }
                Ok(Self { bytes })
            }
            _ => Err(UidError::BadLength(t.to_string(), n)),
        }
    }

    /// An ISO 15693 UID from its 64-bit value (`0xE0…` in the top byte).
    ///
    /// # Errors
    /// [`UidError`] when the value is not a valid ISO 15693 UID.
    pub fn from_u64(value: u64) -> Result<Self, UidError> {
        Self::parse(&format!("{value:016X}"))
    }

    /// The bytes, most significant first (as printed).
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The standard this UID fits.
    #[must_use]
    pub fn kind(&self) -> UidKind {
        if self.bytes.len() == 8 {
            UidKind::Iso15693
        } else {
            UidKind::Iso14443
        }
    }

    /// The ISO/IEC 7816-6 manufacturer code of an ISO 15693 UID (`0x04` = NXP).
    #[must_use]
    pub fn manufacturer(&self) -> Option<u8> {
        match self.kind() {
            UidKind::Iso15693 => self.bytes.get(1).copied(),
            UidKind::Iso14443 => None,
        }
    }

    /// The UID as an integer (UIDs up to 8 bytes).
    #[must_use]
    pub fn to_u64(&self) -> Option<u64> {
        if self.bytes.len() > 8 {
            return None;
        }
        Some(
            self.bytes
                .iter()
                .fold(0u64, |acc, b| (acc << 8) | u64::from(*b)),
        )
    }

    /// The value of the last `digits` hex digits (1..=8), the short tag number seed 002 uses
    /// (section 7.2.1: "the ordered TAG UIDs differ each other just in the last three numbers";
    /// Table 7: `…691` → `1681`).
    #[must_use]
    pub fn short_id(&self, digits: u32) -> Option<u32> {
        if digits == 0 || digits > 8 {
            return None;
        }
        let v = self.to_u64()?;
        let mask = (1u64 << (4 * digits)) - 1;
        u32::try_from(v & mask).ok()
    }
}

impl fmt::Display for Uid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for b in &self.bytes {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

fn decode_hex(t: &str) -> Option<Vec<u8>> {
    if !t.len().is_multiple_of(2) {
        return None;
    }
    t.as_bytes()
        .chunks(2)
        .map(|pair| {
            std::str::from_utf8(pair)
                .ok()
                .and_then(|s| u8::from_str_radix(s, 16).ok())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso15693_examples_from_the_reference() {
        // protocols/kts-rfidm1356.md §4: E004… = NXP.
        let u = Uid::parse("E00402000018313E").unwrap();
        assert_eq!(u.kind(), UidKind::Iso15693);
        assert_eq!(u.manufacturer(), Some(0x04));
        assert_eq!(u.to_string(), "E00402000018313E");
        assert_eq!(
            Uid::parse("e0022c1395900204").unwrap().manufacturer(),
            Some(0x02)
        );
    }

    #[test]
    fn reversed_uid_is_normalised() {
        let u = Uid::parse("3E311800000204E0").unwrap();
        assert_eq!(u.to_string(), "E00402000018313E");
    }

    #[test]
    fn bad_uids_are_typed_errors() {
        assert!(matches!(
            Uid::parse("E0040200"),
            Err(UidError::TruncatedIso15693(_))
        ));
        assert_eq!(
            Uid::parse("08040200"),
            Ok(Uid {
                bytes: vec![0x08, 0x04, 0x02, 0x00]
            })
        );
        assert!(matches!(
            Uid::parse("E00402"),
            Err(UidError::BadLength(_, 6))
        ));
        assert!(matches!(
            Uid::parse("E00402000018313"),
            Err(UidError::BadLength(_, 15))
        ));
        assert!(matches!(
            Uid::parse("1234567890ABCDEF"),
            Err(UidError::NotIso15693(_))
        ));
        assert!(matches!(
            Uid::parse("E000000000000001"),
            Err(UidError::NoManufacturer(_))
        ));
        assert!(matches!(
            Uid::parse("E0G4020000183130"),
            Err(UidError::NotHex(_))
        ));
        assert_eq!(Uid::parse("  "), Err(UidError::Empty));
    }

    #[test]
    fn seed002_table9_short_ids() {
        // Seed 002 Table 9: hex AE4 689 47A 586 785 ADC BF4 691 78D = dec 2788 1673 1146 1414
        // 1925 2780 3060 1681 1933.
        let pairs = [
            ("AE4", 2788),
            ("689", 1673),
            ("47A", 1146),
            ("586", 1414),
            ("785", 1925),
            ("ADC", 2780),
            ("BF4", 3060),
            ("691", 1681),
            ("78D", 1933),
        ];
        for (hex, dec) in pairs {
            let u = Uid::parse(&format!("E00401503A5BD{hex}")).unwrap();
            assert_eq!(u.short_id(3), Some(dec), "{hex}");
        }
    }
}
