//! A scripted transport for unit tests: expect these bytes, then reply with those.

use std::collections::VecDeque;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

#[derive(Debug)]
enum Step {
    Expect(Vec<u8>),
    Reply(Vec<u8>),
}

#[derive(Debug, Default)]
struct MockState {
    steps: VecDeque<Step>,
    /// Bytes of the current `Expect` already matched.
    matched: usize,
    /// Reply chunks released for reading; one read never crosses a chunk.
    readable: VecDeque<Vec<u8>>,
    read_waker: Option<Waker>,
    error: Option<String>,
}

impl MockState {
    fn release_replies(&mut self) {
        while let Some(Step::Reply(_)) = self.steps.front() {
            if let Some(Step::Reply(bytes)) = self.steps.pop_front() {
                self.readable.push_back(bytes);
            }
        }
        if let Some(w) = self.read_waker.take() {
            w.wake();
        }
    }
}

/// Builds a [`MockTransport`] from a script.
#[derive(Debug, Default)]
pub struct MockTransportBuilder {
    steps: VecDeque<Step>,
}

impl MockTransportBuilder {
    /// The driver must write exactly these bytes next (in any number of writes).
    #[must_use]
    pub fn expect_write(mut self, bytes: impl AsRef<[u8]>) -> Self {
        self.steps.push_back(Step::Expect(bytes.as_ref().to_vec()));
        self
    }

    /// The device sends these bytes (delivered as one chunk) once the previous expectations are met.
    #[must_use]
    pub fn reply(mut self, bytes: impl AsRef<[u8]>) -> Self {
        self.steps.push_back(Step::Reply(bytes.as_ref().to_vec()));
        self
    }

    /// Finishes the script.
    #[must_use]
    pub fn build(self) -> MockTransport {
        let mut state = MockState {
            steps: self.steps,
            ..MockState::default()
        };
        state.release_replies();
        MockTransport {
            state: Arc::new(Mutex::new(state)),
        }
    }
}

/// A scripted in-memory link. Writes that differ from the script fail with `InvalidData`
/// naming both byte strings; reads wait until the script releases a reply; after the last step
/// reads return end-of-file. Clone it to keep a handle for [`MockTransport::is_done`].
#[derive(Debug, Clone)]
pub struct MockTransport {
    state: Arc<Mutex<MockState>>,
}

impl MockTransport {
    /// Starts a script.
    #[must_use]
    pub fn builder() -> MockTransportBuilder {
        MockTransportBuilder::default()
    }

    /// True when every step of the script was consumed and every reply read.
    #[must_use]
    pub fn is_done(&self) -> bool {
        self.state
            .lock()
            .is_ok_and(|s| s.steps.is_empty() && s.readable.is_empty())
    }

    /// The first mismatch seen, if any.
    #[must_use]
    pub fn error(&self) -> Option<String> {
        self.state.lock().ok().and_then(|s| s.error.clone())
    }
}

fn poisoned() -> io::Error {
    io::Error::other("mock transport state poisoned")
}

impl AsyncRead for MockTransport {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let mut s = self.state.lock().map_err(|_| poisoned())?;
        if let Some(chunk) = s.readable.front_mut() {
            let n = chunk.len().min(buf.remaining());
            let rest = chunk.split_off(n);
            buf.put_slice(chunk);
            if rest.is_empty() {
                s.readable.pop_front();
            } else if let Some(front) = s.readable.front_mut() {
                *front = rest;
            }
            return Poll::Ready(Ok(()));
        }
        if s.steps.is_empty() {
            return Poll::Ready(Ok(()));
        }
        s.read_waker = Some(cx.waker().clone());
        Poll::Pending
    }
}

impl AsyncWrite for MockTransport {
    fn poll_write(
        self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let mut s = self.state.lock().map_err(|_| poisoned())?;
        let mut taken = 0;
        while taken < buf.len() {
            let matched = s.matched;
            let Some(Step::Expect(expected)) = s.steps.front().map(|st| match st {
                Step::Expect(e) => Step::Expect(e.clone()),
                Step::Reply(r) => Step::Reply(r.clone()),
            }) else {
                let msg = format!(
                    "mock: unexpected write {:02X?} (script has no expectation left)",
                    buf
                );
                s.error.get_or_insert(msg.clone());
                return Poll::Ready(Err(io::Error::new(io::ErrorKind::InvalidData, msg)));
            };
            let want = expected.get(matched..).unwrap_or_default();
            let have = buf.get(taken..).unwrap_or_default();
            let n = want.len().min(have.len());
            if want.get(..n) != have.get(..n) {
                let msg = format!("mock: expected write {:02X?}, got {:02X?}", expected, buf);
                s.error.get_or_insert(msg.clone());
                return Poll::Ready(Err(io::Error::new(io::ErrorKind::InvalidData, msg)));
            }
            taken += n;
            s.matched += n;
            if s.matched == expected.len() {
                s.steps.pop_front();
                s.matched = 0;
                s.release_replies();
            }
        }
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
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

    #[tokio::test]
    async fn follows_the_script() {
        let mut m = MockTransport::builder()
            .reply(b"Username>\0")
            .expect_write(b"alien\n")
            .reply(b"Password>\0")
            .build();
        let probe = m.clone();
        let mut buf = [0u8; 64];
        let n = m.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"Username>\0");
        m.write_all(b"ali").await.unwrap();
        m.write_all(b"en\n").await.unwrap();
        let n = m.read(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"Password>\0");
        assert!(probe.is_done());
        assert_eq!(m.read(&mut buf).await.unwrap(), 0, "EOF after the script");
    }

    #[tokio::test]
    async fn wrong_write_is_an_error() {
        let mut m = MockTransport::builder().expect_write(b"t\n").build();
        let err = m.write_all(b"x\n").await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidData);
        assert!(m.error().unwrap().contains("expected write"));
    }
}
