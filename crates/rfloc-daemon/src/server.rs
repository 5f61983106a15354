//! The pose stream server: JSON lines over TCP and a Unix socket.
//!
//! A new client first gets `VERSION`, the last `DEVICE` object of every device and the last
//! `POSE`, then every new line. Each client has a bounded queue (a broadcast receiver); a client
//! that falls behind by more than the queue is disconnected rather than buffered without bound.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, UnixListener};
use tokio::sync::broadcast;
use tokio_util::sync::CancellationToken;

use crate::message::version_json;

/// Shared state of the pose stream: what new clients get first, and the broadcast of new lines.
#[derive(Debug, Clone)]
pub struct PoseHub {
    lines: broadcast::Sender<Arc<str>>,
    latest: Arc<Mutex<Latest>>,
    write_timeout: Duration,
}

#[derive(Debug, Default)]
struct Latest {
    pose: Option<Arc<str>>,
    target: Option<Arc<str>>,
    devices: BTreeMap<String, Arc<str>>,
    dropped_clients: u64,
}

impl PoseHub {
    /// A hub whose clients may lag by `queue` lines before they are dropped.
    #[must_use]
    pub fn new(queue: usize) -> Self {
        let (lines, _) = broadcast::channel(queue.max(1));
        Self {
            lines,
            latest: Arc::new(Mutex::new(Latest::default())),
            write_timeout: Duration::from_secs(2),
        }
    }

    /// How long one line may take to write before the client counts as stuck and is dropped.
    #[cfg(test)]
    #[must_use]
    pub fn with_write_timeout(mut self, timeout: Duration) -> Self {
        self.write_timeout = timeout;
        self
    }

    fn count_dropped(&self) {
        if let Ok(mut l) = self.latest.lock() {
            l.dropped_clients += 1;
        }
    }

    /// Publishes a POSE line.
    pub fn publish_pose(&self, line: String) {
        let line: Arc<str> = line.into();
        if let Ok(mut l) = self.latest.lock() {
            l.pose = Some(Arc::clone(&line));
        }
        let _ = self.lines.send(line);
    }

    /// Publishes a TARGET line.
    pub fn publish_target(&self, line: String) {
        let line: Arc<str> = line.into();
        if let Ok(mut l) = self.latest.lock() {
            l.target = Some(Arc::clone(&line));
        }
        let _ = self.lines.send(line);
    }

    /// Publishes a DEVICE line for `device`.
    pub fn publish_device(&self, device: &str, line: String) {
        let line: Arc<str> = line.into();
        if let Ok(mut l) = self.latest.lock() {
            l.devices.insert(device.to_string(), Arc::clone(&line));
        }
        let _ = self.lines.send(line);
    }

    /// The last POSE line published.
    #[cfg(test)]
    #[must_use]
    pub fn last_pose(&self) -> Option<Arc<str>> {
        self.latest.lock().ok().and_then(|l| l.pose.clone())
    }

    /// Clients dropped for being too slow.
    #[must_use]
    pub fn dropped_clients(&self) -> u64 {
        self.latest.lock().map_or(0, |l| l.dropped_clients)
    }

    fn greeting(&self) -> Vec<Arc<str>> {
        let mut out: Vec<Arc<str>> = vec![version_json().into()];
        if let Ok(l) = self.latest.lock() {
            out.extend(l.devices.values().cloned());
            out.extend(l.pose.clone());
            out.extend(l.target.clone());
        }
        out
    }

    /// Serves one connected client until it leaves, lags, or `stop` is cancelled.
    pub async fn serve_client<W: AsyncWrite + Unpin>(
        &self,
        mut out: W,
        peer: &str,
        stop: CancellationToken,
    ) {
        let mut rx = self.lines.subscribe();
        for line in self.greeting() {
            if !self.send(&mut out, &line, peer).await {
                return;
            }
        }
        loop {
            let next = tokio::select! {
                () = stop.cancelled() => break,
                r = rx.recv() => r,
            };
            match next {
                Ok(line) => {
                    if !self.send(&mut out, &line, peer).await {
                        break;
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!(peer, skipped = n, "pose client too slow; dropping it");
                    self.count_dropped();
                    break;
                }
                Err(broadcast::error::RecvError::Closed) => break,
            }
        }
        let _ = out.shutdown().await;
    }

    /// Writes one line; false when the client left or is stuck past the write timeout.
    async fn send<W: AsyncWrite + Unpin>(&self, out: &mut W, line: &str, peer: &str) -> bool {
        match tokio::time::timeout(self.write_timeout, write_line(out, line)).await {
            Ok(Ok(())) => true,
            Ok(Err(_)) => {
                tracing::debug!(peer, "pose client left");
                false
            }
            Err(_) => {
                tracing::warn!(peer, "pose client not reading; dropping it");
                self.count_dropped();
                false
            }
        }
    }

    /// Accepts TCP clients until `stop`.
    pub async fn serve_tcp(self, listener: TcpListener, stop: CancellationToken) {
        loop {
            let accepted = tokio::select! {
                () = stop.cancelled() => break,
                a = listener.accept() => a,
            };
            match accepted {
                Ok((stream, peer)) => {
                    let _ = stream.set_nodelay(true);
                    let hub = self.clone();
                    let stop = stop.clone();
                    tokio::spawn(async move {
                        let peer = peer.to_string();
                        tracing::debug!(%peer, "pose client connected (tcp)");
                        hub.serve_client(stream, &peer, stop).await;
                    });
                }
                Err(e) => {
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            }
        }
    }

    /// Accepts Unix-socket clients until `stop`; removes the socket file afterwards.
    pub async fn serve_unix(self, listener: UnixListener, path: PathBuf, stop: CancellationToken) {
        loop {
            let accepted = tokio::select! {
                () = stop.cancelled() => break,
                a = listener.accept() => a,
            };
            match accepted {
                Ok((stream, _)) => {
                    let hub = self.clone();
                    let stop = stop.clone();
                    tokio::spawn(async move { hub.serve_client(stream, "unix", stop).await });
                }
                Err(e) => {
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            }
        }
        let _ = std::fs::remove_file(path);
    }
}

async fn write_line<W: AsyncWrite + Unpin>(out: &mut W, line: &str) -> std::io::Result<()> {
    out.write_all(line.as_bytes()).await?;
    out.write_all(b"\n").await?;
    out.flush().await
}

/// Binds a Unix socket, replacing a stale socket file left by a previous run.
pub fn bind_unix(path: &Path) -> std::io::Result<UnixListener> {
    if path.exists() {
        std::fs::remove_file(path)?;
    }
    UnixListener::bind(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncBufReadExt, BufReader};

    #[tokio::test]
    async fn new_client_gets_version_devices_and_last_pose_first() {
        let hub = PoseHub::new(8);
        hub.publish_device("hf", "{\"class\":\"DEVICE\",\"name\":\"hf\"}".into());
        hub.publish_pose("{\"class\":\"POSE\",\"x\":1}".into());
        let (client, server) = tokio::io::duplex(4096);
        let stop = CancellationToken::new();
        let h = hub.clone();
        let s = stop.clone();
        let task = tokio::spawn(async move { h.serve_client(server, "t", s).await });
        let mut lines = BufReader::new(client).lines();
        assert!(lines
            .next_line()
            .await
            .unwrap()
            .unwrap()
            .contains("VERSION"));
        assert!(lines.next_line().await.unwrap().unwrap().contains("DEVICE"));
        assert!(lines
            .next_line()
            .await
            .unwrap()
            .unwrap()
            .contains("\"x\":1"));
        hub.publish_pose("{\"class\":\"POSE\",\"x\":2}".into());
        assert!(lines
            .next_line()
            .await
            .unwrap()
            .unwrap()
            .contains("\"x\":2"));
        stop.cancel();
        task.await.unwrap();
    }

    #[tokio::test]
    async fn stuck_client_is_dropped_not_buffered() {
        let hub = PoseHub::new(4).with_write_timeout(Duration::from_millis(100));
        // A client whose pipe holds almost nothing and who never reads.
        let (client, server) = tokio::io::duplex(64);
        let stop = CancellationToken::new();
        let h = hub.clone();
        let task = tokio::spawn(async move { h.serve_client(server, "stuck", stop).await });
        for i in 0..200 {
            hub.publish_pose(format!("{{\"class\":\"POSE\",\"n\":{i}}}"));
            tokio::task::yield_now().await;
        }
        tokio::time::timeout(Duration::from_secs(2), task)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(hub.dropped_clients(), 1);
        drop(client);
        assert_eq!(
            hub.last_pose().as_deref(),
            Some("{\"class\":\"POSE\",\"n\":199}")
        );
    }

    #[tokio::test]
    async fn lagging_client_is_dropped() {
        let hub = PoseHub::new(4);
        let (client, server) = tokio::io::duplex(1 << 16);
        let stop = CancellationToken::new();
        let h = hub.clone();
        let task = tokio::spawn(async move { h.serve_client(server, "lagging", stop).await });
        // Let the client subscribe and send its greeting, then overflow its queue at once.
        for _ in 0..10 {
            tokio::task::yield_now().await;
        }
        for i in 0..50 {
            hub.publish_pose(format!("{{\"n\":{i}}}"));
        }
        tokio::time::timeout(Duration::from_secs(2), task)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(hub.dropped_clients(), 1);
        drop(client);
    }
}
