//! Recording wrapper: every read and write of a live link goes to a capture file.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};

use rfloc_capture::{CaptureWriter, Header, RecordKind};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use crate::clock::SharedClock;
use crate::error::TransportError;

struct SinkState {
    writer: CaptureWriter<Box<dyn Write + Send>>,
    failures: u64,
    /// Bytes recorded in each direction.
    rx_bytes: u64,
    tx_bytes: u64,
    /// Coalescing: consecutive reads (writes) at one clock reading become one record.
    coalesce: bool,
    /// The record being grown while coalescing.
    pending: Option<(u64, RecordKind)>,
    /// Byte strings never written to the file (a password sent at login).
    secrets: Vec<Vec<u8>>,
}

/// What a redacted secret is recorded as.
pub const REDACTED: &[u8] = b"<redacted>";

/// `bytes` with every occurrence of each secret replaced by [`REDACTED`].
fn redact(bytes: Vec<u8>, secrets: &[Vec<u8>]) -> Vec<u8> {
    let mut out = bytes;
    for secret in secrets.iter().filter(|s| !s.is_empty()) {
        if out.len() < secret.len() {
            continue;
        }
        let mut next = Vec::with_capacity(out.len());
        let mut i = 0;
        while i < out.len() {
            if out.get(i..i + secret.len()) == Some(secret.as_slice()) {
                next.extend_from_slice(REDACTED);
                i += secret.len();
            } else {
                next.extend(out.get(i).copied());
                i += 1;
            }
        }
        out = next;
    }
    out
}

impl SinkState {
    fn write(&mut self, t: u64, kind: RecordKind) {
        if let Err(e) = self.writer.write(t, kind) {
            self.failures += 1;
            if self.failures == 1 {
                tracing::error!(error = %e, "capture write failed; later failures are only counted");
            }
        }
    }

    fn write_pending(&mut self) {
        if let Some((t, kind)) = self.pending.take() {
            self.write(t, kind);
        }
    }

    fn record(&mut self, t: u64, kind: RecordKind) {
        // Counts are of the bytes on the link, before any redaction.
        let kind = match kind {
            RecordKind::Rx(b) => {
                self.rx_bytes += b.len() as u64;
                RecordKind::Rx(redact(b, &self.secrets))
            }
            RecordKind::Tx(b) => {
                self.tx_bytes += b.len() as u64;
                RecordKind::Tx(redact(b, &self.secrets))
            }
            event @ RecordKind::Event(_) => event,
        };
        if !self.coalesce {
            self.write(t, kind);
            return;
        }
        match (&mut self.pending, kind) {
            (Some((pt, RecordKind::Rx(acc))), RecordKind::Rx(more)) if *pt == t => {
                acc.extend_from_slice(&more);
            }
            (Some((pt, RecordKind::Tx(acc))), RecordKind::Tx(more)) if *pt == t => {
                acc.extend_from_slice(&more);
            }
            (_, kind @ RecordKind::Event(_)) => {
                self.write_pending();
                self.write(t, kind);
            }
            (_, kind) => {
                self.write_pending();
                self.pending = Some((t, kind));
            }
        }
    }
}

/// A capture being written. Cheap to clone; all clones append to the same file. Times come from
/// the shared clock (seconds since the session started), so several sinks of one session share a
/// clock as the capture format requires.
#[derive(Clone)]
pub struct CaptureSink {
    state: Arc<Mutex<SinkState>>,
    clock: SharedClock,
}

impl std::fmt::Debug for CaptureSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CaptureSink").finish_non_exhaustive()
    }
}

impl CaptureSink {
    /// Creates (truncates) a capture file and writes its header.
    pub fn create(
        path: &Path,
        header: &Header,
        clock: SharedClock,
    ) -> Result<Self, TransportError> {
        let err = |source| TransportError::Capture {
            path: path.display().to_string(),
            source,
        };
        let file = File::create(path).map_err(err)?;
        let out: Box<dyn Write + Send> = Box::new(BufWriter::new(file));
        Self::from_writer(out, header, clock).map_err(err)
    }

    /// A sink over any writer (for tests: a `Vec<u8>` behind a shared buffer).
    pub fn from_writer(
        out: Box<dyn Write + Send>,
        header: &Header,
        clock: SharedClock,
    ) -> io::Result<Self> {
        let writer = CaptureWriter::new(out, header)?;
        Ok(Self {
            state: Arc::new(Mutex::new(SinkState {
                writer,
                failures: 0,
                rx_bytes: 0,
                tx_bytes: 0,
                coalesce: false,
                pending: None,
                secrets: Vec::new(),
            })),
            clock,
        })
    }

    fn now_ns(&self) -> u64 {
        crate::stamp::clock_ns(self.clock.as_ref())
    }

    /// Records `kind` at the clock's reading and returns that reading in nanoseconds.
    fn record(&self, kind: RecordKind) -> u64 {
        let t = self.now_ns();
        self.record_at(t, kind);
        t
    }

    /// Records `kind` at `t_ns` (a reading of this sink's clock taken by the caller, so that the
    /// caller stamps what it derives from the bytes with the very time the capture holds).
    pub fn record_at(&self, t_ns: u64, kind: RecordKind) {
        if let Ok(mut s) = self.state.lock() {
            s.record(t_ns, kind);
        }
    }

    /// Coalescing on or off (default off: a record is one read or one write). On, consecutive
    /// reads (or writes) stamped with the same clock reading are written as one record, so a
    /// capture no longer depends on how the kernel happened to chunk the bytes. Meant for
    /// simulated runs whose clock only moves at known points (lock-step emulators).
    pub fn set_coalescing(&self, on: bool) {
        if let Ok(mut s) = self.state.lock() {
            if !on {
                s.write_pending();
            }
            s.coalesce = on;
        }
    }

    /// Never writes `secret` to the file: every occurrence in a later read or write (within one
    /// chunk) is recorded as [`REDACTED`]. For credentials the driver sends, such as a reader
    /// password; the byte counts still count what crossed the link.
    pub fn redact(&self, secret: &[u8]) {
        if let Ok(mut s) = self.state.lock() {
            if !secret.is_empty() && !s.secrets.iter().any(|x| x == secret) {
                s.secrets.push(secret.to_vec());
            }
        }
    }

    /// Bytes recorded as read from the device so far.
    #[must_use]
    pub fn rx_bytes(&self) -> u64 {
        self.state.lock().map_or(0, |s| s.rx_bytes)
    }

    /// Bytes recorded as written to the device so far (accepted by the link).
    #[must_use]
    pub fn tx_bytes(&self) -> u64 {
        self.state.lock().map_or(0, |s| s.tx_bytes)
    }

    /// Appends an `ev` record (for example `mark turn-start`) and returns its time in seconds,
    /// exactly as a reader of the file computes it ([`rfloc_capture::Record::t`]): a driver that
    /// stamps the event it derives from the mark with this time gets the same time in replay.
    pub fn event(&self, text: &str) -> f64 {
        let ns = self.record(RecordKind::Event(text.replace(['\n', '\r'], " ")));
        rfloc_capture::Record::seconds(ns)
    }

    /// Flushes buffered records to the file.
    pub fn flush(&self) -> io::Result<()> {
        match self.state.lock() {
            Ok(mut s) => {
                s.write_pending();
                s.writer.flush()
            }
            Err(_) => Err(io::Error::other("capture sink poisoned")),
        }
    }

    /// How many records could not be written.
    #[must_use]
    pub fn failures(&self) -> u64 {
        self.state.lock().map_or(0, |s| s.failures)
    }
}

/// Wraps a link and writes each read (`rx`) and each accepted write (`tx`) to a capture, with the
/// chunking that actually happened.
#[derive(Debug)]
pub struct Recorder<T> {
    inner: T,
    sink: CaptureSink,
}

impl<T> Recorder<T> {
    #[must_use]
    pub fn new(inner: T, sink: CaptureSink) -> Self {
        Self { inner, sink }
    }

    /// The sink, e.g. to add events or flush.
    #[must_use]
    pub fn sink(&self) -> &CaptureSink {
        &self.sink
    }

    /// The wrapped link.
    pub fn get_ref(&self) -> &T {
        &self.inner
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for Recorder<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let res = Pin::new(&mut self.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = &res {
            if let Some(new) = buf.filled().get(before..) {
                if !new.is_empty() {
                    self.sink.record(RecordKind::Rx(new.to_vec()));
                }
            }
        }
        res
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for Recorder<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let res = Pin::new(&mut self.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = &res {
            if let Some(sent) = buf.get(..*n) {
                if !sent.is_empty() {
                    self.sink.record(RecordKind::Tx(sent.to_vec()));
                }
            }
        }
        res
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let _ = self.sink.flush();
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

impl<T> Drop for Recorder<T> {
    fn drop(&mut self) {
        if let Err(e) = self.sink.flush() {
            tracing::warn!(error = %e, "capture flush on drop failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::ManualClock;

    #[derive(Clone, Default)]
    struct SharedBuf(Arc<Mutex<Vec<u8>>>);

    impl Write for SharedBuf {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    fn records(coalesce: bool) -> (Vec<String>, u64, u64) {
        let out = SharedBuf::default();
        let clock = ManualClock::new();
        let sink = CaptureSink::from_writer(
            Box::new(out.clone()),
            &Header::new("test", "pty"),
            clock.clone(),
        )
        .unwrap();
        sink.set_coalescing(coalesce);
        sink.record(RecordKind::Rx(b"AB".to_vec()));
        sink.record(RecordKind::Rx(b"C\r\n".to_vec()));
        sink.record(RecordKind::Tx(b"x".to_vec()));
        sink.record(RecordKind::Tx(b"y".to_vec()));
        clock.set_ns(100_000_000);
        sink.record(RecordKind::Tx(b"z".to_vec()));
        sink.event("mark");
        sink.record(RecordKind::Rx(b"D".to_vec()));
        sink.flush().unwrap();
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(str::to_string)
            .collect();
        (lines, sink.rx_bytes(), sink.tx_bytes())
    }

    #[test]
    fn coalescing_merges_same_time_same_direction_only() {
        let (lines, rx, tx) = records(true);
        assert_eq!(
            lines,
            [
                "0.000000 rx s:ABC\\r\\n",
                "0.000000 tx s:xy",
                "0.100000 tx s:z",
                "0.100000 ev mark",
                "0.100000 rx s:D",
            ]
        );
        assert_eq!((rx, tx), (6, 3));
        let (plain, rx, tx) = records(false);
        assert_eq!(plain.len(), 7, "{plain:?}");
        assert_eq!((rx, tx), (6, 3));
    }

    #[test]
    fn secrets_are_never_written_but_still_counted() {
        let out = SharedBuf::default();
        let clock = ManualClock::new();
        let sink = CaptureSink::from_writer(
            Box::new(out.clone()),
            &Header::new("test", "tcp"),
            clock.clone(),
        )
        .unwrap();
        sink.redact(b"hunter2");
        sink.redact(b"");
        sink.record(RecordKind::Tx(b"\x01alien\r\n".to_vec()));
        sink.record(RecordKind::Tx(b"\x01hunter2\r\n".to_vec()));
        sink.record(RecordKind::Rx(b"echo hunter2 hunter2!".to_vec()));
        sink.flush().unwrap();
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        assert!(!text.contains("hunter2"), "{text}");
        assert!(text.contains("tx s:\\x01<redacted>\\r\\n"), "{text}");
        assert!(text.contains("rx s:echo <redacted> <redacted>!"), "{text}");
        assert!(text.contains("tx x:01 61 6C 69 65 6E 0D 0A"), "{text}");
        assert_eq!((sink.tx_bytes(), sink.rx_bytes()), (18, 21));
    }
}
