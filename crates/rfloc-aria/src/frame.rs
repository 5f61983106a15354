//! Packet framing shared by client commands and server information packets (SIPs):
//! `0xFA 0xFB COUNT ID payload… CHK_HI CHK_LO`, see `docs/protocols/pioneer-aria.md` §1.

use thiserror::Error;

/// First header byte.
pub const SYNC_A: u8 = 0xFA;
/// Second header byte.
pub const SYNC_B: u8 = 0xFB;
/// Largest payload (bytes after the ID) whose COUNT still fits in one byte: COUNT = payload + 3.
pub const MAX_PAYLOAD: usize = 252;

/// The protocol's 16-bit checksum over the ID byte and the payload.
///
/// Bytes are summed as big-endian pairs with wrap-around; an odd last byte is XORed into the low
/// byte (docs §1 "Checksum").
#[must_use]
pub fn checksum(data: &[u8]) -> u16 {
    let mut c: u16 = 0;
    for pair in data.chunks(2) {
        match pair {
            [hi, lo] => c = c.wrapping_add(u16::from_be_bytes([*hi, *lo])),
            [last] => c ^= u16::from(*last),
            _ => {}
        }
    }
    c
}

/// One framed packet: its ID (command number or SIP type) and the bytes after it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Command number (client → robot) or packet type (robot → client).
    pub id: u8,
    /// Bytes between the ID and the checksum.
    pub payload: Vec<u8>,
}

/// A frame that cannot be encoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum EncodeError {
    /// The payload does not fit the one-byte COUNT.
    #[error("payload of {len} bytes exceeds the {MAX_PAYLOAD}-byte frame limit")]
    PayloadTooLong {
        /// Payload length that was asked for.
        len: usize,
    },
}

impl Frame {
    /// A frame with the given ID and payload.
    #[must_use]
    pub fn new(id: u8, payload: Vec<u8>) -> Self {
        Self { id, payload }
    }

    /// The bytes on the wire: header, COUNT, ID, payload, checksum (high byte first).
    ///
    /// # Errors
    /// [`EncodeError::PayloadTooLong`] when the payload exceeds [`MAX_PAYLOAD`].
    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let len = self.payload.len();
        let count = u8::try_from(len + 3)
            .ok()
            .filter(|_| len <= MAX_PAYLOAD)
            .ok_or(EncodeError::PayloadTooLong { len })?;
        let mut out = Vec::with_capacity(len + 6);
        out.extend_from_slice(&[SYNC_A, SYNC_B, count, self.id]);
        out.extend_from_slice(&self.payload);
        let chk = checksum(out.get(3..).unwrap_or_default());
        out.extend_from_slice(&chk.to_be_bytes());
        Ok(out)
    }
}

/// Why bytes were dropped while looking for frames. Every variant carries the dropped bytes.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// Bytes before a `0xFA 0xFB` header.
    #[error("{} garbage bytes before a frame header: {bytes:02X?}", bytes.len())]
    Garbage {
        /// The bytes that were skipped.
        bytes: Vec<u8>,
    },
    /// A COUNT below 3 cannot hold an ID and a checksum.
    #[error("impossible byte count {count} after header")]
    BadCount {
        /// The count byte.
        count: u8,
        /// The header bytes that were dropped.
        bytes: Vec<u8>,
    },
    /// The checksum did not match; only the header's first byte is dropped so that a real frame
    /// hidden inside the bad one is still found.
    #[error("bad checksum: computed {computed:#06X}, received {received:#06X} in {bytes:02X?}")]
    BadChecksum {
        /// Checksum computed over the received ID and payload.
        computed: u16,
        /// Checksum found on the wire.
        received: u16,
        /// The whole rejected frame.
        bytes: Vec<u8>,
    },
}

/// Sans-IO frame decoder: push received bytes, pull frames. Resynchronises on garbage and bad
/// checksums and counts every byte it drops.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    dropped_bytes: u64,
    bad_checksums: u64,
    frames: u64,
}

impl FrameDecoder {
    /// An empty decoder.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes dropped so far (garbage, impossible counts, frames with bad checksums).
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// Frames rejected for a bad checksum.
    #[must_use]
    pub fn bad_checksums(&self) -> u64 {
        self.bad_checksums
    }

    /// Frames decoded successfully.
    #[must_use]
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Bytes buffered but not yet decoded (an incomplete frame).
    #[must_use]
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    fn drop_front(&mut self, n: usize) -> Vec<u8> {
        let n = n.min(self.buf.len());
        self.dropped_bytes += n as u64;
        self.buf.drain(..n).collect()
    }

    /// The next complete frame, an error describing dropped bytes, or `None` when more bytes
    /// are needed. Call repeatedly until it returns `None`.
    pub fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        // Hunt for the header.
        let start = self.buf.windows(2).position(|w| w == [SYNC_A, SYNC_B]);
        match start {
            Some(0) => {}
            Some(i) => {
                let bytes = self.drop_front(i);
                tracing::warn!(dropped = bytes.len(), "ARIA decoder skipped garbage");
                return Some(Err(FrameError::Garbage { bytes }));
            }
            None => {
                // Keep a trailing 0xFA: it may be the start of the next header.
                let keep = usize::from(self.buf.last() == Some(&SYNC_A));
                let n = self.buf.len() - keep;
                if n == 0 {
                    return None;
                }
                let bytes = self.drop_front(n);
                tracing::warn!(dropped = bytes.len(), "ARIA decoder skipped garbage");
                return Some(Err(FrameError::Garbage { bytes }));
            }
        }
        let count = *self.buf.get(2)?;
        if count < 3 {
            let bytes = self.drop_front(3);
            tracing::warn!(count, "ARIA decoder: impossible byte count");
            return Some(Err(FrameError::BadCount { count, bytes }));
        }
        let total = usize::from(count) + 3;
        let frame = self.buf.get(..total)?;
        let body = frame.get(3..total - 2).unwrap_or_default();
        let received = match frame.get(total - 2..) {
            Some([hi, lo]) => u16::from_be_bytes([*hi, *lo]),
            _ => return None,
        };
        let computed = checksum(body);
        if computed != received {
            let bytes = frame.to_vec();
            self.bad_checksums += 1;
            self.drop_front(1);
            tracing::warn!(computed, received, "ARIA decoder: bad checksum");
            return Some(Err(FrameError::BadChecksum {
                computed,
                received,
                bytes,
            }));
        }
        let (id, payload) = body.split_first()?;
        let out = Frame::new(*id, payload.to_vec());
        self.buf.drain(..total);
        self.frames += 1;
        Some(Ok(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_of_worked_examples() {
        // docs/protocols/pioneer-aria.md §8 Examples A, B, E.
        assert_eq!(checksum(&[0x00]), 0x0000);
        assert_eq!(checksum(&[0x04, 0x3B, 0x01, 0x00]), 0x053B);
        assert_eq!(checksum(&[0x2A, 0x2B, 0x02, 0x68, 0x69]), 0x2CFA);
    }

    #[test]
    fn encode_sync0() {
        // §8 Example A.
        let bytes = Frame::new(0, vec![]).encode().unwrap();
        assert_eq!(bytes, [0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00]);
    }

    #[test]
    fn payload_too_long_is_refused() {
        assert!(Frame::new(1, vec![0; MAX_PAYLOAD]).encode().is_ok());
        assert_eq!(
            Frame::new(1, vec![0; MAX_PAYLOAD + 1]).encode(),
            Err(EncodeError::PayloadTooLong {
                len: MAX_PAYLOAD + 1
            })
        );
    }

    #[test]
    fn decoder_handles_split_input_and_garbage() {
        let frame = Frame::new(0x0B, vec![0x3B, 0xC8, 0x00]).encode().unwrap();
        let mut d = FrameDecoder::new();
        d.push(&[0x11, 0x22, 0xFA]);
        assert!(
            matches!(d.next_frame(), Some(Err(FrameError::Garbage { bytes })) if bytes == [0x11, 0x22])
        );
        assert!(d.next_frame().is_none());
        d.push(&frame[..4]);
        // The buffered 0xFA followed by 0xFA 0xFB: one garbage byte.
        assert!(
            matches!(d.next_frame(), Some(Err(FrameError::Garbage { bytes })) if bytes == [0xFA])
        );
        assert!(d.next_frame().is_none());
        d.push(&frame[4..]);
        let f = d.next_frame().unwrap().unwrap();
        assert_eq!(f.id, 0x0B);
        assert_eq!(d.dropped_bytes(), 3);
        assert!(d.next_frame().is_none());
    }

    #[test]
    fn bad_checksum_drops_one_byte_and_finds_embedded_frame() {
        let good = Frame::new(0x1D, vec![]).encode().unwrap();
        // A corrupt frame header whose declared body swallows the good frame.
        let mut bytes = vec![0xFA, 0xFB, 0x08, 0x00, 0x00];
        bytes.extend_from_slice(&good);
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let mut got = Vec::new();
        while let Some(r) = d.next_frame() {
            if let Ok(f) = r {
                got.push(f);
            }
        }
        assert_eq!(got, vec![Frame::new(0x1D, vec![])]);
        assert_eq!(d.bad_checksums(), 1);
        assert_eq!(d.dropped_bytes(), 5);
    }

    #[test]
    fn impossible_count_is_dropped() {
        let mut d = FrameDecoder::new();
        d.push(&[0xFA, 0xFB, 0x02, 0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00]);
        assert!(matches!(
            d.next_frame(),
            Some(Err(FrameError::BadCount { count: 2, .. }))
        ));
        assert_eq!(d.next_frame().unwrap().unwrap(), Frame::new(0, vec![]));
    }
}
