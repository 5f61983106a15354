//! Stamping observations once, when their bytes were read.
//!
//! A device's stamp (a [`ManualClock`]) holds the clock reading of the latest read on its link.
//! Drivers take it as their [`Clock`], so every observation carries the time its last bytes arrived, whatever
//! happens between the read and the decode (a busy runtime, a queue). [`StampedLink`] sets it
//! on a live link and records each read into the capture at that very reading; a replay sets it
//! from the recorded times ([`crate::replay::ReplayIo`]), so live and replayed observations
//! carry identical times.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use rfloc_capture::RecordKind;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use crate::clock::{Clock, ManualClock, SharedClock};
use crate::recorder::CaptureSink;

/// A clock reading in whole nanoseconds, as a capture stores it (negative and non-finite
/// readings are 0).
#[must_use]
pub fn clock_ns(clock: &dyn Clock) -> u64 {
    let t = clock.now();
    if t.is_finite() && t > 0.0 {
        // Saturating float->int conversion; u64 ns covers 584 years.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let ns = (t * 1e9).round() as u64;
        ns
    } else {
        0
    }
}

/// A live link that stamps every read once on the run clock, sets the device's stamp
/// (a [`ManualClock`]) to it and, when recording, writes the read to the capture at the same reading.
#[derive(Debug)]
pub struct StampedLink<T> {
    inner: T,
    clock: SharedClock,
    stamp: Arc<ManualClock>,
    sink: Option<CaptureSink>,
}

impl<T> StampedLink<T> {
    /// Wraps a link that was just opened: the stamp moves to the opening time, which the
    /// capture records as `mark link opened`.
    pub fn opened(
        inner: T,
        clock: SharedClock,
        stamp: Arc<ManualClock>,
        sink: Option<CaptureSink>,
    ) -> Self {
        let t = clock_ns(clock.as_ref());
        stamp.set_ns(t);
        if let Some(s) = &sink {
            s.record_at(t, RecordKind::Event("mark link opened".into()));
        }
        Self {
            inner,
            clock,
            stamp,
            sink,
        }
    }

    /// The capture this link records into, if any.
    #[must_use]
    pub fn sink(&self) -> Option<&CaptureSink> {
        self.sink.as_ref()
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for StampedLink<T> {
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
                    let t = clock_ns(self.clock.as_ref());
                    if let Some(s) = &self.sink {
                        s.record_at(t, RecordKind::Rx(new.to_vec()));
                    }
                    self.stamp.set_ns(t);
                }
            }
        }
        res
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for StampedLink<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let res = Pin::new(&mut self.inner).poll_write(cx, buf);
        if let (Poll::Ready(Ok(n)), Some(sink)) = (&res, &self.sink) {
            if let Some(sent) = buf.get(..*n) {
                if !sent.is_empty() {
                    let t = clock_ns(self.clock.as_ref());
                    sink.record_at(t, RecordKind::Tx(sent.to_vec()));
                }
            }
        }
        res
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if let Some(s) = &self.sink {
            let _ = s.flush();
        }
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

impl<T> Drop for StampedLink<T> {
    fn drop(&mut self) {
        if let Some(s) = &self.sink {
            if let Err(e) = s.flush() {
                tracing::warn!(error = %e, "capture flush on drop failed");
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::mock::MockTransport;
    use tokio::io::AsyncReadExt;

    #[tokio::test]
    async fn a_read_sets_the_stamp_to_the_clock_reading_at_the_read() {
        let clock = ManualClock::new();
        clock.set_ns(1_500_000_000);
        let stamp = ManualClock::new();
        let mock = MockTransport::builder().reply(b"AB").reply(b"C").build();
        let mut link = StampedLink::opened(mock, clock.clone(), Arc::clone(&stamp), None);
        assert_eq!(stamp.ns(), 1_500_000_000, "opening stamps");
        clock.set_ns(2_000_000_007);
        let mut buf = [0u8; 2];
        link.read_exact(&mut buf).await.unwrap();
        // Later clock readings do not move the stamp until the next read.
        clock.set_ns(9_000_000_000);
        assert_eq!(stamp.ns(), 2_000_000_007);
        assert!((stamp.now() - 2.000_000_007).abs() < 1e-12);
        let mut one = [0u8; 1];
        link.read_exact(&mut one).await.unwrap();
        assert_eq!(stamp.ns(), 9_000_000_000);
    }
}
