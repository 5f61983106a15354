//! Replaying a capture into a real driver through the same transport type.
//!
//! [`Replayer::start`] returns a [`ReplayIo`] (give it to the driver as its link) and a
//! [`ReplayHandle`] (watch progress, read the report, read the replay clock).
//!
//! - [`ReplayMode::Stream`] (streaming devices: a scanning HF reader, a Pioneer sending SIPs):
//!   recorded `rx` bytes are delivered in order whatever the driver writes; what the driver wrote
//!   is compared with the recorded `tx` bytes as a whole when the replay ends.
//! - [`ReplayMode::RequestResponse`] (a telnet reader, AT command sets): an `rx` record that
//!   follows a recorded `tx` is released only after the driver has sent its matching request. A
//!   request ends when the driver has written exactly the recorded bytes, or at a `flush` (drivers
//!   flush after each command). A request that differs from the recording is reported in
//!   [`ReplayReport::mismatches`] and the replay goes on, unless strict mode is on, in which case
//!   the write fails with `InvalidData`.
//!
//! One read never crosses a record boundary, so frames split across reads in the recording are
//! split the same way for the driver. With [`Pace::Recorded`] each `rx` record is delivered no
//! earlier than its recorded time after the first read; with [`Pace::Fast`] at once.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use rfloc_capture::{Capture, Record, RecordKind};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::watch;
use tokio::time::{Instant, Sleep};

use crate::clock::ManualClock;

/// How recorded bytes are fed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayMode {
    Stream,
    RequestResponse,
}

/// How fast recorded bytes are fed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    Fast,
    Recorded,
}

/// A difference between what the driver sent and what was recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Mismatch {
    /// 0-based number of the request (request/response) or 0 (stream mode, whole tx compared).
    pub request: usize,
    /// Recorded time of the expected request in seconds (or of the end, in stream mode).
    pub t: f64,
    pub expected: Vec<u8>,
    pub actual: Vec<u8>,
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "request {} at {:.6} s: recorded {:?}, driver sent {:?}",
            self.request,
            self.t,
            String::from_utf8_lossy(&self.expected),
            String::from_utf8_lossy(&self.actual)
        )
    }
}

/// What a replay saw.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplayReport {
    /// Requests matched (request/response mode).
    pub requests: usize,
    /// Requests or tx streams that differed from the recording.
    pub mismatches: Vec<Mismatch>,
    /// Bytes of `rx` records delivered to the driver.
    pub rx_bytes_delivered: usize,
    /// Total `rx` bytes in the capture.
    pub rx_bytes_total: usize,
    /// True once every record has been delivered or matched.
    pub finished: bool,
}

/// Configures a replay.
#[derive(Debug, Clone)]
pub struct Replayer {
    capture: Capture,
    mode: ReplayMode,
    pace: Pace,
    strict: bool,
    hold_open: bool,
    reads_only_clock: bool,
    clock: Option<Arc<ManualClock>>,
    skip_unknown: bool,
}

/// How many recorded requests ahead a request the recording does not expect next is looked for.
const LOOKAHEAD: usize = 16;

impl Replayer {
    /// A fast, lenient stream replay that ends with end-of-file.
    #[must_use]
    pub fn new(capture: Capture) -> Self {
        Self {
            capture,
            mode: ReplayMode::Stream,
            pace: Pace::Fast,
            strict: false,
            hold_open: false,
            reads_only_clock: false,
            clock: None,
            skip_unknown: false,
        }
    }

    /// Request/response mode, for drivers newer than the recording: a request that differs
    /// from the one recorded next is looked for among the next recorded requests; found, the
    /// replay skips to it (the exchanges in between are dropped); not found, it gets no reply
    /// at all, as from a device that ignores it, and the recording waits where it was. Both are
    /// reported as mismatches. Off by default: every request takes the next recorded reply.
    #[must_use]
    pub fn skip_unknown_requests(mut self, on: bool) -> Self {
        self.skip_unknown = on;
        self
    }

    /// Sets this clock to the recorded times instead of a new one (a device's stamp clock,
    /// which outlives one recorded session).
    #[must_use]
    pub fn with_clock(mut self, clock: Arc<ManualClock>) -> Self {
        self.clock = Some(clock);
        self
    }

    /// The replay clock moves only at `rx` records and at `mark link opened`, as a live
    /// [`crate::StampedLink`]'s stamp does (other marks are written by the driver itself and do not
    /// stamp anything). Off by default: the clock also moves at every `ev` record.
    #[must_use]
    pub fn reads_only_clock(mut self, on: bool) -> Self {
        self.reads_only_clock = on;
        self
    }

    #[must_use]
    pub fn mode(mut self, mode: ReplayMode) -> Self {
        self.mode = mode;
        self
    }

    #[must_use]
    pub fn pace(mut self, pace: Pace) -> Self {
        self.pace = pace;
        self
    }

    /// Fail the driver's write when its request differs from the recording.
    #[must_use]
    pub fn strict(mut self, strict: bool) -> Self {
        self.strict = strict;
        self
    }

    /// After the last record, keep the link open (reads pend) instead of returning end-of-file.
    #[must_use]
    pub fn hold_open(mut self, hold: bool) -> Self {
        self.hold_open = hold;
        self
    }

    /// Starts the replay.
    #[must_use]
    pub fn start(self) -> (ReplayIo, ReplayHandle) {
        let rx_total = self.capture.records.iter().filter_map(|r| match &r.kind {
            RecordKind::Rx(b) => Some(b.len()),
            _ => None,
        });
        let rx_total = rx_total.sum();
        let clock = self.clock.unwrap_or_default();
        let (progress_tx, progress_rx) = watch::channel(ReplayReport {
            rx_bytes_total: rx_total,
            ..ReplayReport::default()
        });
        let first_tx = next_tx(&self.capture.records, 0);
        let state = ReplayState {
            records: self.capture.records,
            mode: self.mode,
            strict: self.strict,
            hold_open: self.hold_open,
            reads_only_clock: self.reads_only_clock,
            skip_unknown: self.skip_unknown,
            cursor: 0,
            rx_offset: 0,
            tx_cursor: first_tx,
            pending: Vec::new(),
            written: Vec::new(),
            report: ReplayReport {
                rx_bytes_total: rx_total,
                ..ReplayReport::default()
            },
            read_waker: None,
            clock: Arc::clone(&clock),
            progress: progress_tx,
        };
        let io = ReplayIo {
            state: Arc::new(Mutex::new(state)),
            pace: self.pace,
            started: None,
            sleep: None,
        };
        let handle = ReplayHandle {
            progress: progress_rx,
            clock,
        };
        (io, handle)
    }
}

fn next_tx(records: &[Record], from: usize) -> usize {
    records
        .iter()
        .enumerate()
        .skip(from)
        .find(|(_, r)| matches!(r.kind, RecordKind::Tx(_)))
        .map_or(records.len(), |(i, _)| i)
}

/// Observes a running replay.
#[derive(Debug, Clone)]
pub struct ReplayHandle {
    progress: watch::Receiver<ReplayReport>,
    clock: Arc<ManualClock>,
}

impl ReplayHandle {
    /// The report so far.
    #[must_use]
    pub fn report(&self) -> ReplayReport {
        self.progress.borrow().clone()
    }

    /// Waits until every record was delivered or matched, and returns the final report.
    pub async fn finished(&mut self) -> ReplayReport {
        let _ = self.progress.wait_for(|r| r.finished).await;
        self.report()
    }

    /// The replay clock: the recorded time of the record last delivered. Give it to drivers as
    /// their timestamp source so events carry recorded times.
    #[must_use]
    pub fn clock(&self) -> Arc<ManualClock> {
        Arc::clone(&self.clock)
    }
}

#[derive(Debug)]
struct ReplayState {
    records: Vec<Record>,
    mode: ReplayMode,
    strict: bool,
    hold_open: bool,
    reads_only_clock: bool,
    skip_unknown: bool,
    /// Next record to deliver.
    cursor: usize,
    /// Bytes of the current rx record already delivered.
    rx_offset: usize,
    /// Next tx record to match (request/response) — everything before it is matched.
    tx_cursor: usize,
    /// Driver bytes of the request being collected.
    pending: Vec<u8>,
    /// Everything the driver wrote (stream mode comparison).
    written: Vec<u8>,
    report: ReplayReport,
    read_waker: Option<Waker>,
    clock: Arc<ManualClock>,
    progress: watch::Sender<ReplayReport>,
}

impl ReplayState {
    fn publish(&mut self) {
        let all_matched = self.mode == ReplayMode::Stream || self.tx_cursor >= self.records.len();
        if self.cursor >= self.records.len() && all_matched && !self.report.finished {
            self.report.finished = true;
            if self.mode == ReplayMode::Stream {
                let recorded: Vec<u8> = self
                    .records
                    .iter()
                    .filter_map(|r| match &r.kind {
                        RecordKind::Tx(b) => Some(b.as_slice()),
                        _ => None,
                    })
                    .flatten()
                    .copied()
                    .collect();
                if recorded != self.written {
                    let t = self.records.last().map_or(0.0, Record::t);
                    self.report.mismatches.push(Mismatch {
                        request: 0,
                        t,
                        expected: recorded,
                        actual: self.written.clone(),
                    });
                }
            }
        }
        let _ = self.progress.send(self.report.clone());
    }

    fn wake_reader(&mut self) {
        if let Some(w) = self.read_waker.take() {
            w.wake();
        }
    }

    /// Completes the pending request if it is whole. Returns a mismatch error in strict mode.
    fn try_complete(&mut self, at_flush: bool) -> io::Result<()> {
        if self.mode != ReplayMode::RequestResponse || self.pending.is_empty() {
            return Ok(());
        }
        let (expected, t) = match self.records.get(self.tx_cursor) {
            Some(Record {
                kind: RecordKind::Tx(b),
                t_ns,
            }) => (b.clone(), *t_ns),
            _ => (Vec::new(), self.records.last().map_or(0, |r| r.t_ns)),
        };
        let exact = !expected.is_empty() && self.pending == expected;
        if !exact && !at_flush {
            return Ok(());
        }
        let actual = std::mem::take(&mut self.pending);
        let request = self.report.requests;
        self.report.requests += 1;
        if !exact && self.skip_unknown {
            self.skip_to(actual, expected, t, request);
            return Ok(());
        }
        if self.tx_cursor < self.records.len() {
            self.tx_cursor = next_tx(&self.records, self.tx_cursor + 1);
        }
        let mut result = Ok(());
        if !exact {
            #[allow(clippy::cast_precision_loss)]
            let m = Mismatch {
                request,
                t: t as f64 * 1e-9,
                expected,
                actual,
            };
            tracing::warn!(%m, "replay: request differs from the recording");
            if self.strict {
                result = Err(io::Error::new(io::ErrorKind::InvalidData, m.to_string()));
            }
            self.report.mismatches.push(m);
        }
        self.wake_reader();
        self.publish();
        result
    }
}

impl ReplayState {
    /// [`Replayer::skip_unknown_requests`]: finds `actual` among the next recorded requests.
    fn skip_to(&mut self, actual: Vec<u8>, expected: Vec<u8>, t: u64, request: usize) {
        let mut at = self.tx_cursor;
        let mut found = None;
        for _ in 0..LOOKAHEAD {
            match self.records.get(at) {
                Some(Record {
                    kind: RecordKind::Tx(b),
                    ..
                }) if *b == actual => {
                    found = Some(at);
                    break;
                }
                Some(_) => at = next_tx(&self.records, at + 1),
                None => break,
            }
        }
        #[allow(clippy::cast_precision_loss)]
        let m = Mismatch {
            request,
            t: t as f64 * 1e-9,
            expected,
            actual,
        };
        match found {
            Some(j) => {
                tracing::debug!(%m, "replay: skipping recorded exchanges to the driver's request");
                self.cursor = j;
                self.rx_offset = 0;
                self.tx_cursor = next_tx(&self.records, j + 1);
                self.wake_reader();
            }
            None => {
                tracing::debug!(%m, "replay: a request the recording does not hold gets no reply")
            }
        }
        self.report.mismatches.push(m);
        self.publish();
    }
}

/// The replayed link handed to a driver.
pub struct ReplayIo {
    state: Arc<Mutex<ReplayState>>,
    pace: Pace,
    started: Option<Instant>,
    sleep: Option<Pin<Box<Sleep>>>,
}

impl std::fmt::Debug for ReplayIo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReplayIo")
            .field("pace", &self.pace)
            .finish_non_exhaustive()
    }
}

fn poisoned() -> io::Error {
    io::Error::other("replay state poisoned")
}

impl AsyncRead for ReplayIo {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = &mut *self;
        let started = *this.started.get_or_insert_with(Instant::now);
        let mut s = this.state.lock().map_err(|_| poisoned())?;
        loop {
            let cursor = s.cursor;
            let Some(record) = s.records.get(cursor) else {
                s.publish();
                if s.hold_open || !s.report.finished {
                    // Request/response replays end only when every request was matched.
                    s.read_waker = Some(cx.waker().clone());
                    return Poll::Pending;
                }
                return Poll::Ready(Ok(()));
            };
            let t_ns = record.t_ns;
            match &record.kind {
                RecordKind::Event(text) => {
                    if !s.reads_only_clock || text == "mark link opened" {
                        s.clock.set_ns(t_ns);
                    }
                    s.cursor += 1;
                }
                RecordKind::Tx(_) => {
                    if s.mode == ReplayMode::RequestResponse && cursor >= s.tx_cursor {
                        s.read_waker = Some(cx.waker().clone());
                        return Poll::Pending;
                    }
                    s.cursor += 1;
                }
                RecordKind::Rx(bytes) => {
                    if this.pace == Pace::Recorded {
                        let due = started + Duration::from_nanos(t_ns);
                        if Instant::now() < due {
                            let sleep = this
                                .sleep
                                .get_or_insert_with(|| Box::pin(tokio::time::sleep_until(due)));
                            if sleep.deadline() != due {
                                sleep.as_mut().reset(due);
                            }
                            if sleep.as_mut().poll(cx).is_pending() {
                                return Poll::Pending;
                            }
                        }
                    }
                    let offset = s.rx_offset;
                    let rest = bytes.get(offset..).unwrap_or_default();
                    let n = rest.len().min(buf.remaining());
                    if n == 0 && !rest.is_empty() {
                        return Poll::Ready(Ok(()));
                    }
                    buf.put_slice(rest.get(..n).unwrap_or_default());
                    let whole = n == rest.len();
                    s.clock.set_ns(t_ns);
                    s.report.rx_bytes_delivered += n;
                    if whole {
                        s.cursor += 1;
                        s.rx_offset = 0;
                    } else {
                        s.rx_offset += n;
                    }
                    s.publish();
                    return Poll::Ready(Ok(()));
                }
            }
        }
    }
}

impl AsyncWrite for ReplayIo {
    fn poll_write(
        self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let mut s = self.state.lock().map_err(|_| poisoned())?;
        s.written.extend_from_slice(buf);
        if s.mode == ReplayMode::RequestResponse {
            s.pending.extend_from_slice(buf);
            s.try_complete(false)?;
        }
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let mut s = self.state.lock().map_err(|_| poisoned())?;
        s.try_complete(true)?;
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    fn cap(text: &str) -> Capture {
        Capture::parse(text, "t").unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn unknown_requests_get_no_reply_and_known_ones_skip_ahead() {
        let c = cap("# rfloc-capture 1\n0.1 tx s:BM\\n\n0.2 rx s:BM\\n00P\\n\\n\n0.3 tx s:GD1\\n\n0.4 rx s:one\\n\n0.5 tx s:GD2\\n\n0.6 rx s:two\\n\n");
        let (mut io, handle) = Replayer::new(c)
            .mode(ReplayMode::RequestResponse)
            .skip_unknown_requests(true)
            .start();
        let mut buf = [0u8; 64];
        // A request a newer driver sends first is not in the recording: no reply.
        io.write_all(b"SCIP2.0\n").await.unwrap();
        io.flush().await.unwrap();
        let r = tokio::time::timeout(std::time::Duration::from_secs(1), io.read(&mut buf)).await;
        assert!(r.is_err(), "an unknown request must not be answered");
        // The recorded one next still gets its reply.
        io.write_all(b"BM\n").await.unwrap();
        io.flush().await.unwrap();
        let n = io.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"BM\n00P\n\n");
        // A request further on skips the exchange in between.
        io.write_all(b"GD2\n").await.unwrap();
        io.flush().await.unwrap();
        let n = io.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"two\n");
        let report = handle.report();
        assert_eq!(report.mismatches.len(), 2);
        assert_eq!(report.mismatches[0].actual, b"SCIP2.0\n");
        assert_eq!(report.mismatches[1].expected, b"GD1\n");
    }

    #[tokio::test]
    async fn stream_mode_keeps_chunk_boundaries() {
        let c = cap("# rfloc-capture 1\n0.1 rx s:SCAN:\n0.2 rx s:+UID=E0\\r\\n\n0.3 ev mark x\n0.4 rx s:OK\\r\\n\n");
        let (mut io, mut handle) = Replayer::new(c).start();
        let mut buf = [0u8; 64];
        let mut chunks = Vec::new();
        loop {
            let n = io.read(&mut buf).await.unwrap();
            if n == 0 {
                break;
            }
            chunks.push(String::from_utf8_lossy(&buf[..n]).to_string());
        }
        assert_eq!(chunks, vec!["SCAN:", "+UID=E0\r\n", "OK\r\n"]);
        let r = handle.finished().await;
        assert!(r.mismatches.is_empty());
        assert_eq!(r.rx_bytes_delivered, 5 + 9 + 4);
        assert_eq!(handle.clock().ns(), 400_000_000);
    }

    #[tokio::test]
    async fn request_response_waits_for_the_request() {
        let c = cap(
            "# rfloc-capture 1\n0.0 rx s:Username>\\0\n0.1 tx s:alien\\n\n0.2 rx s:Password>\\0\n",
        );
        let (mut io, mut handle) = Replayer::new(c).mode(ReplayMode::RequestResponse).start();
        let mut buf = [0u8; 64];
        let n = io.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"Username>\0");
        // Nothing more until the driver asks.
        let blocked = tokio::time::timeout(Duration::from_millis(50), io.read(&mut buf)).await;
        assert!(blocked.is_err(), "reply released before the request");
        io.write_all(b"alien\n").await.unwrap();
        let n = io.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"Password>\0");
        assert_eq!(io.read(&mut buf).await.unwrap(), 0);
        let r = handle.finished().await;
        assert_eq!(r.requests, 1);
        assert!(r.mismatches.is_empty());
    }

    #[tokio::test]
    async fn differing_request_is_reported_not_fatal() {
        let c = cap("# rfloc-capture 1\n0.1 tx s:t\\r\\n\n0.2 rx s:(No Tags)\\r\\n\n");
        let (mut io, handle) = Replayer::new(c).mode(ReplayMode::RequestResponse).start();
        io.write_all(b"t\n").await.unwrap();
        io.flush().await.unwrap();
        let mut buf = [0u8; 64];
        let n = io.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"(No Tags)\r\n");
        let r = handle.report();
        assert_eq!(r.mismatches.len(), 1);
        assert_eq!(r.mismatches[0].expected, b"t\r\n");
        assert_eq!(r.mismatches[0].actual, b"t\n");
    }

    #[tokio::test]
    async fn strict_mode_fails_the_write() {
        let c = cap("# rfloc-capture 1\n0.1 tx s:t\\r\\n\n0.2 rx s:x\n");
        let (mut io, _h) = Replayer::new(c)
            .mode(ReplayMode::RequestResponse)
            .strict(true)
            .start();
        io.write_all(b"q\n").await.unwrap();
        let err = io.flush().await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidData);
    }

    #[tokio::test]
    async fn stream_mode_reports_tx_difference_at_end() {
        let c = cap("# rfloc-capture 1\n0.0 tx s:AT+Scan\\r\n0.1 rx s:OK\\r\\n\n");
        let (mut io, mut h) = Replayer::new(c).start();
        io.write_all(b"AT+Scan=AC\r").await.unwrap();
        let mut buf = [0u8; 16];
        while io.read(&mut buf).await.unwrap() > 0 {}
        let r = h.finished().await;
        assert_eq!(r.mismatches.len(), 1);
    }

    #[tokio::test]
    async fn recorded_pace_waits_for_record_times() {
        let c = cap("# rfloc-capture 1\n0.0 rx s:a\n0.25 rx s:b\n");
        let (mut io, _h) = Replayer::new(c).pace(Pace::Recorded).start();
        let t0 = Instant::now();
        let mut buf = [0u8; 4];
        assert_eq!(io.read(&mut buf).await.unwrap(), 1);
        assert_eq!(io.read(&mut buf).await.unwrap(), 1);
        assert_eq!(&buf[..1], b"b");
        let waited = t0.elapsed();
        assert!(waited >= Duration::from_millis(250), "{waited:?}");
    }
}
