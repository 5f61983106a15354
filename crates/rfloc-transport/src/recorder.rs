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
            })),
            clock,
        })
    }

    fn now_ns(&self) -> u64 {
        let t = self.clock.now();
        if t.is_finite() && t > 0.0 {
            // Saturating float->int conversion; u64 ns covers 584 years.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let ns = (t * 1e9).round() as u64;
            ns
        } else {
            0
        }
    }

    fn record(&self, kind: RecordKind) {
        let t = self.now_ns();
        if let Ok(mut s) = self.state.lock() {
            if let Err(e) = s.writer.write(t, kind) {
                s.failures += 1;
                if s.failures == 1 {
                    tracing::error!(error = %e, "capture write failed; later failures are only counted");
                }
            }
        }
    }

    /// Appends an `ev` record (for example `mark turn-start`).
    pub fn event(&self, text: &str) {
        self.record(RecordKind::Event(text.replace(['\n', '\r'], " ")));
    }

    /// Flushes buffered records to the file.
    pub fn flush(&self) -> io::Result<()> {
        match self.state.lock() {
            Ok(mut s) => s.writer.flush(),
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
