//! Capture writer.

use std::io::Write;

use crate::header::Header;
use crate::record::{Record, RecordKind};
use crate::MAGIC;

/// Writes a capture record by record. Times passed in that go backwards are raised to the
/// previous record's time (a capture must never decrease), and counted.
#[derive(Debug)]
pub struct CaptureWriter<W: Write> {
    out: W,
    last_t_ns: u64,
    clamped_times: u64,
}

impl<W: Write> CaptureWriter<W> {
    /// Starts a capture: writes the magic line and the header.
    pub fn new(mut out: W, header: &Header) -> std::io::Result<Self> {
        out.write_all(MAGIC.as_bytes())?;
        out.write_all(b"\n")?;
        out.write_all(header.to_lines().as_bytes())?;
        Ok(Self {
            out,
            last_t_ns: 0,
            clamped_times: 0,
        })
    }

    /// Appends one record.
    pub fn write(&mut self, t_ns: u64, kind: RecordKind) -> std::io::Result<()> {
        let t_ns = if t_ns < self.last_t_ns {
            self.clamped_times += 1;
            self.last_t_ns
        } else {
            t_ns
        };
        self.last_t_ns = t_ns;
        let line = Record { t_ns, kind }.to_line();
        self.out.write_all(line.as_bytes())?;
        self.out.write_all(b"\n")
    }

    /// How many records arrived with a time earlier than the previous one.
    #[must_use]
    pub fn clamped_times(&self) -> u64 {
        self.clamped_times
    }

    /// Flushes the underlying writer.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    /// Returns the underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}
