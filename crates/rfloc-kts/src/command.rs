//! Commands to the reader. Each is sent as ASCII ending in a single `\r` (ubisys/ODRFID
//! framing rule: no extra whitespace).

/// A command for the RFIDM1356.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KtsCommand {
    /// `AT`: attention; answers `OK`. Used to resynchronise.
    Attention,
    /// `ATI`: identification text, then `OK`.
    Identify,
    /// `ATE0`: echo off.
    EchoOff,
    /// Any other command text, sent verbatim (e.g. `AT+Scan=AC,RSSI`).
    Raw(String),
}

impl KtsCommand {
    /// The command text without terminator.
    #[must_use]
    pub fn text(&self) -> &str {
        match self {
            KtsCommand::Attention => "AT",
            KtsCommand::Identify => "ATI",
            KtsCommand::EchoOff => "ATE0",
            KtsCommand::Raw(s) => s,
        }
    }

    /// The bytes to send: the text and `\r`.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut v = self.text().as_bytes().to_vec();
        v.push(b'\r');
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_with_cr() {
        // Seed 002 §5 names the scan command; captures/FORMAT.md shows it ending in \r.
        assert_eq!(
            KtsCommand::Raw("AT+Scan=AC,RSSI".into()).encode(),
            b"AT+Scan=AC,RSSI\r"
        );
        assert_eq!(KtsCommand::Identify.encode(), b"ATI\r");
        assert_eq!(KtsCommand::Attention.encode(), b"AT\r");
    }
}
