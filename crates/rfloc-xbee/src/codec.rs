//! Sans-IO framing of XBee API frames: start delimiter, big-endian length, checksum and, in API
//! mode 2, escaping. Bytes go in, frame data (type byte first, no checksum) comes out, and back.
//!
//! The decoder resynchronises on garbage and counts everything it drops; see [`FrameDecoder`].

use std::collections::VecDeque;
use std::fmt;

use serde::{Deserialize, Serialize};

/// Start delimiter of every API frame.
pub const START_DELIMITER: u8 = 0x7E;
/// Escape byte of API mode 2.
pub const ESCAPE: u8 = 0x7D;
/// XON, escaped in API mode 2.
pub const XON: u8 = 0x11;
/// XOFF, escaped in API mode 2.
pub const XOFF: u8 = 0x13;
/// An escaped byte is sent as `ESCAPE, byte ^ ESCAPE_XOR`.
pub const ESCAPE_XOR: u8 = 0x20;
/// Default upper bound on the length field (frame data bytes) the decoder accepts.
pub const DEFAULT_MAX_FRAME_DATA: usize = 512;

/// The radio's `AP` setting: how frames are put on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ApiMode {
    /// `AP=1`: frames are sent as they are.
    Unescaped,
    /// `AP=2`: every byte after the start delimiter that is 0x7E, 0x7D, 0x11 or 0x13 is escaped.
    Escaped,
}

impl ApiMode {
    /// The value of the `AP` register for this mode.
    pub fn ap_value(self) -> u8 {
        match self {
            ApiMode::Unescaped => 1,
            ApiMode::Escaped => 2,
        }
    }
}

/// Checksum of frame data: `0xFF - (sum of bytes & 0xFF)`.
pub fn checksum(frame_data: &[u8]) -> u8 {
    let sum = frame_data.iter().fold(0u8, |acc, b| acc.wrapping_add(*b));
    0xFF_u8.wrapping_sub(sum)
}

/// Whether `byte` must be escaped in API mode 2.
pub fn needs_escape(byte: u8) -> bool {
    matches!(byte, START_DELIMITER | ESCAPE | XON | XOFF)
}

/// Why frame data could not be put on the wire.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// A frame needs at least its type byte.
    #[error("frame data is empty")]
    Empty,
    /// The length field is 16 bits.
    #[error("frame data of {0} bytes does not fit the 16-bit length field")]
    TooLong(usize),
}

/// Builds the wire bytes of one frame around `frame_data` (type byte first).
pub fn encode_frame(frame_data: &[u8], mode: ApiMode) -> Result<Vec<u8>, EncodeError> {
    if frame_data.is_empty() {
        return Err(EncodeError::Empty);
    }
    let len =
        u16::try_from(frame_data.len()).map_err(|_| EncodeError::TooLong(frame_data.len()))?;
    let mut out = Vec::with_capacity(frame_data.len() + 8);
    out.push(START_DELIMITER);
    let body = len
        .to_be_bytes()
        .into_iter()
        .chain(frame_data.iter().copied())
        .chain(std::iter::once(checksum(frame_data)));
    for byte in body {
        if mode == ApiMode::Escaped && needs_escape(byte) {
            out.push(ESCAPE);
            out.push(byte ^ ESCAPE_XOR);
        } else {
            out.push(byte);
        }
    }
    Ok(out)
}

/// Bytes shown as space-separated upper-case hex, for logs and error messages.
pub struct HexBytes<'a>(pub &'a [u8]);

impl fmt::Display for HexBytes<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, b) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// Counters kept by a [`FrameDecoder`]; every wire byte is either part of a delivered frame or
/// counted in `dropped_bytes`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DecodeStats {
    /// Frames delivered with a good checksum.
    pub frames: u64,
    /// Wire bytes of the delivered frames (delimiter, escapes and checksum included).
    pub frame_bytes: u64,
    /// Wire bytes discarded (garbage, rejected candidates, truncated frames).
    pub dropped_bytes: u64,
    /// Candidates rejected because the checksum did not match.
    pub bad_checksums: u64,
    /// Candidates rejected because the length field was 0 or above the limit.
    pub bad_lengths: u64,
    /// Partial frames cut off by a bare start delimiter (API mode 2) or by the end of input.
    pub truncated_frames: u64,
    /// Runs of bytes seen outside any frame.
    pub garbage_runs: u64,
}

/// Something the decoder dropped, with the offending wire bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Bytes outside any frame.
    #[error("{} bytes outside a frame: {}", .bytes.len(), HexBytes(.bytes))]
    Garbage {
        /// The bytes as received.
        bytes: Vec<u8>,
    },
    /// The checksum byte did not match the frame data.
    #[error("bad checksum (expected {expected:02X}, received {received:02X}): {}", HexBytes(.bytes))]
    BadChecksum {
        /// Checksum computed over the received frame data.
        expected: u8,
        /// Checksum byte received.
        received: u8,
        /// The whole candidate as received, delimiter first.
        bytes: Vec<u8>,
    },
    /// The length field was zero or larger than the decoder accepts.
    #[error("bad length {length} (limit {limit}): {}", HexBytes(.bytes))]
    BadLength {
        /// Decoded length field.
        length: usize,
        /// The decoder's limit.
        limit: usize,
        /// The candidate as received, delimiter first.
        bytes: Vec<u8>,
    },
    /// A partial frame was cut off by a bare 0x7E (API mode 2) or by the end of input.
    #[error("truncated frame: {}", HexBytes(.bytes))]
    Truncated {
        /// The partial frame as received, delimiter first.
        bytes: Vec<u8>,
    },
}

impl DecodeError {
    /// The offending wire bytes.
    pub fn bytes(&self) -> &[u8] {
        match self {
            DecodeError::Garbage { bytes }
            | DecodeError::BadChecksum { bytes, .. }
            | DecodeError::BadLength { bytes, .. }
            | DecodeError::Truncated { bytes } => bytes,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Hunt,
    LengthHigh,
    LengthLow,
    Data,
    Checksum,
}

/// Incremental, sans-IO API frame decoder.
///
/// Feed it bytes as they arrive with [`FrameDecoder::push`], then drain [`FrameDecoder::next_frame`]
/// until it returns `None`. Each item is either the frame data of one frame (type byte first,
/// unescaped, checksum verified and removed) or a [`DecodeError`] describing bytes it dropped.
///
/// Resynchronisation:
/// - bytes before a 0x7E are dropped as garbage;
/// - in API mode 2 a bare 0x7E inside a frame starts a new frame and the partial one is dropped;
/// - on a bad checksum or a length of 0 or above the limit the candidate is rejected. In API
///   mode 2 the whole candidate is dropped (it cannot hide a delimiter). In API mode 1 only its
///   0x7E is dropped and the bytes after it are scanned again, because a real frame may start
///   inside them.
#[derive(Debug)]
pub struct FrameDecoder {
    mode: ApiMode,
    max_frame_data: usize,
    input: VecDeque<u8>,
    state: State,
    wire: Vec<u8>,
    data: Vec<u8>,
    length: usize,
    length_high: u8,
    escape_next: bool,
    garbage: Vec<u8>,
    stats: DecodeStats,
    /// Resynchronisations are logged a few at a time, then summarised.
    log: rfloc_transport::LogLimit,
}

impl FrameDecoder {
    /// A decoder for `mode` with the default length limit.
    pub fn new(mode: ApiMode) -> Self {
        Self::with_max_frame_data(mode, DEFAULT_MAX_FRAME_DATA)
    }

    /// A decoder that rejects length fields above `max_frame_data`.
    pub fn with_max_frame_data(mode: ApiMode, max_frame_data: usize) -> Self {
        Self {
            mode,
            max_frame_data,
            input: VecDeque::new(),
            state: State::Hunt,
            wire: Vec::new(),
            data: Vec::new(),
            length: 0,
            length_high: 0,
            escape_next: false,
            garbage: Vec::new(),
            stats: DecodeStats::default(),
            log: rfloc_transport::LogLimit::default(),
        }
    }

    /// The API mode this decoder expects.
    pub fn mode(&self) -> ApiMode {
        self.mode
    }

    /// Counters so far.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.input.extend(bytes.iter().copied());
    }

    /// The next frame or drop event from the bytes pushed so far; `None` when more input is
    /// needed. Garbage still pending at the end of the input is reported before `None`.
    pub fn next_frame(&mut self) -> Option<Result<Vec<u8>, DecodeError>> {
        while let Some(byte) = self.input.pop_front() {
            if let Some(item) = self.step(byte) {
                return Some(item);
            }
        }
        if self.garbage.is_empty() {
            None
        } else {
            Some(Err(self.take_garbage()))
        }
    }

    /// Ends the input: drops a partial frame (counted as truncated) and pending garbage. In API
    /// mode 1 the bytes after the partial frame's delimiter are scanned again, so a complete frame
    /// hidden behind a false start is still delivered. Returns every item produced; the decoder is
    /// ready for new input afterwards.
    pub fn finish(&mut self) -> Vec<Result<Vec<u8>, DecodeError>> {
        let mut items = Vec::new();
        loop {
            while let Some(item) = self.next_frame() {
                items.push(item);
            }
            if self.state == State::Hunt {
                return items;
            }
            items.push(Err(self.truncate()));
        }
    }

    fn step(&mut self, byte: u8) -> Option<Result<Vec<u8>, DecodeError>> {
        if self.state == State::Hunt {
            if byte == START_DELIMITER {
                self.begin();
                if !self.garbage.is_empty() {
                    return Some(Err(self.take_garbage()));
                }
            } else {
                self.garbage.push(byte);
            }
            return None;
        }
        if byte == START_DELIMITER && self.mode == ApiMode::Escaped {
            let error = self.truncate();
            self.begin();
            return Some(Err(error));
        }
        self.wire.push(byte);
        let byte = match self.mode {
            ApiMode::Unescaped => byte,
            ApiMode::Escaped if self.escape_next => {
                self.escape_next = false;
                byte ^ ESCAPE_XOR
            }
            ApiMode::Escaped if byte == ESCAPE => {
                self.escape_next = true;
                return None;
            }
            ApiMode::Escaped => byte,
        };
        match self.state {
            State::Hunt => None,
            State::LengthHigh => {
                self.length_high = byte;
                self.state = State::LengthLow;
                None
            }
            State::LengthLow => {
                self.length = usize::from(u16::from_be_bytes([self.length_high, byte]));
                if self.length == 0 || self.length > self.max_frame_data {
                    self.stats.bad_lengths += 1;
                    let (length, limit) = (self.length, self.max_frame_data);
                    let bytes = self.reject();
                    if let Some(suppressed) = self.log.hit() {
                        tracing::warn!(length, limit, suppressed, bytes = %HexBytes(&bytes), "xbee: bad frame length, resynchronising");
                    }
                    return Some(Err(DecodeError::BadLength {
                        length,
                        limit,
                        bytes,
                    }));
                }
                self.state = State::Data;
                None
            }
            State::Data => {
                self.data.push(byte);
                if self.data.len() >= self.length {
                    self.state = State::Checksum;
                }
                None
            }
            State::Checksum => {
                let expected = checksum(&self.data);
                if byte == expected {
                    self.stats.frames += 1;
                    self.stats.frame_bytes += self.wire.len() as u64;
                    self.state = State::Hunt;
                    self.wire.clear();
                    Some(Ok(std::mem::take(&mut self.data)))
                } else {
                    self.stats.bad_checksums += 1;
                    let bytes = self.reject();
                    if let Some(suppressed) = self.log.hit() {
                        tracing::warn!(expected, received = byte, suppressed, bytes = %HexBytes(&bytes), "xbee: bad checksum, resynchronising");
                    }
                    Some(Err(DecodeError::BadChecksum {
                        expected,
                        received: byte,
                        bytes,
                    }))
                }
            }
        }
    }

    fn begin(&mut self) {
        self.state = State::LengthHigh;
        self.wire.clear();
        self.wire.push(START_DELIMITER);
        self.data.clear();
        self.escape_next = false;
    }

    /// Rejects the current candidate and returns its wire bytes; see the type docs for what is
    /// dropped and what is scanned again.
    fn reject(&mut self) -> Vec<u8> {
        self.state = State::Hunt;
        self.escape_next = false;
        self.data.clear();
        let bytes = std::mem::take(&mut self.wire);
        match self.mode {
            ApiMode::Escaped => self.stats.dropped_bytes += bytes.len() as u64,
            ApiMode::Unescaped => {
                self.stats.dropped_bytes += 1;
                for b in bytes.iter().skip(1).rev() {
                    self.input.push_front(*b);
                }
            }
        }
        bytes
    }

    /// Drops the partial frame. API mode 1 drops only its delimiter and scans the rest again.
    fn truncate(&mut self) -> DecodeError {
        self.state = State::Hunt;
        self.escape_next = false;
        self.data.clear();
        let bytes = std::mem::take(&mut self.wire);
        self.stats.truncated_frames += 1;
        match self.mode {
            ApiMode::Escaped => self.stats.dropped_bytes += bytes.len() as u64,
            ApiMode::Unescaped => {
                self.stats.dropped_bytes += 1;
                for b in bytes.iter().skip(1).rev() {
                    self.input.push_front(*b);
                }
            }
        }
        if let Some(suppressed) = self.log.hit() {
            tracing::warn!(suppressed, bytes = %HexBytes(&bytes), "xbee: truncated frame dropped");
        }
        DecodeError::Truncated { bytes }
    }

    fn take_garbage(&mut self) -> DecodeError {
        let bytes = std::mem::take(&mut self.garbage);
        self.stats.garbage_runs += 1;
        self.stats.dropped_bytes += bytes.len() as u64;
        if let Some(suppressed) = self.log.hit() {
            tracing::warn!(suppressed, bytes = %HexBytes(&bytes), "xbee: bytes outside a frame dropped");
        }
        DecodeError::Garbage { bytes }
    }
}
