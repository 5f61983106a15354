//! Tag identifiers (EPC bytes) with a hex text form for storage.

use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The identifier of one UHF tag: its EPC bytes as read from the reader.
///
/// Ordered bytewise so snapshots can keep tags sorted (the seed sorts snapshots by tag ID to
/// speed up comparisons, section 3.2.1). Serialised as an upper-case hex string so it can be a
/// JSON map key.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TagId(pub Vec<u8>);

impl TagId {
    /// Wraps raw EPC bytes.
    #[must_use]
    pub fn new(bytes: impl Into<Vec<u8>>) -> Self {
        Self(bytes.into())
    }

    /// Parses a hex string (spaces allowed, as the Alien reader prints `E200 9033 ...`).
    /// Returns `None` on an odd number of digits or a non-hex character.
    #[must_use]
    pub fn from_hex(text: &str) -> Option<Self> {
        let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
        if !digits.len().is_multiple_of(2) {
            return None;
        }
        let mut out = Vec::with_capacity(digits.len() / 2);
        for pair in digits.chunks_exact(2) {
            let hi = hex_value(*pair.first()?)?;
            let lo = hex_value(*pair.get(1)?)?;
            out.push((hi << 4) | lo);
        }
        Some(Self(out))
    }

    /// The bytes of the identifier.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }
}

fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

impl fmt::Display for TagId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for b in &self.0 {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

impl Serialize for TagId {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for TagId {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        TagId::from_hex(&text)
            .ok_or_else(|| serde::de::Error::custom(format!("tag id is not hex: {text:?}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trip_and_rejects_garbage() {
        let id = TagId::from_hex("E200 9033 1317 0087 0490 E133").unwrap();
        assert_eq!(id.as_bytes().len(), 12);
        assert_eq!(id.to_string(), "E20090331317008704 90E133".replace(' ', ""));
        assert_eq!(TagId::from_hex(&id.to_string()), Some(id));
        assert_eq!(TagId::from_hex("ABC"), None);
        assert_eq!(TagId::from_hex("ZZ"), None);
    }
}
