//! The rfloc capture format, version 1: a plain-text log of what crossed one device link.
//!
//! ```text
//! # rfloc-capture 1
//! # device: kts-rfidm1356
//! # link: serial 115200 8N1
//! 0.000000 tx s:AT+Scan=AC,RSSI\r
//! 0.012400 rx s:OK\r\n
//! 0.210000 rx x:7E 00 04 08 01 4E 44 64
//! 0.300000 ev mark stop 1 heading_deg=45
//! ```
//!
//! The reader is strict: any malformed line is a [`CaptureError`] naming the source and the line
//! number. Times are kept as integer nanoseconds so that parse → write → parse is exact.
//! This crate does no I/O beyond reading or writing a file or a `std::io::Write` it is given.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod error;
mod escape;
mod header;
mod reader;
mod record;
mod writer;

pub use error::{CaptureError, CaptureErrorKind};
pub use escape::{decode_hex, decode_text, encode_payload};
pub use header::Header;
pub use reader::Capture;
pub use record::{Record, RecordKind};
pub use writer::CaptureWriter;

/// The first line every capture must start with.
pub const MAGIC: &str = "# rfloc-capture 1";
