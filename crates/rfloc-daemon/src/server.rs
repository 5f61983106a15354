//! The pose stream server: JSON lines over TCP and a Unix socket.
//!
//! A new client first gets `VERSION`, the last `DEVICE` object of every device and the last
//! `POSE`, then every new line. Each client has a bounded queue (a broadcast receiver); a client
//! that falls behind by more than the queue is disconnected rather than buffered without bound.

use std::collections::BTreeMap;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::AsyncReadExt as _;
use tokio::io::{AsyncBufReadExt, AsyncRead, AsyncWrite, AsyncWriteExt, BufReader};
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
    access: Arc<Access>,
    clients: Arc<AtomicUsize>,
}

/// Who may read the stream.
#[derive(Default)]
pub struct Access {
    /// TCP clients must send `?AUTH={"token":"…"};` first.
    pub token: Option<String>,
    /// TCP clients' addresses must match one rule (empty: any).
    pub allow: Vec<AllowRule>,
    /// Clients served at once (0: no limit).
    pub max_clients: usize,
}

impl std::fmt::Debug for Access {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Access")
            .field("token", &self.token.as_ref().map(|_| "<redacted>"))
            .field("allow", &self.allow)
            .field("max_clients", &self.max_clients)
            .finish()
    }
}

/// An address or a network (`10.0.0.0/8`, `fd00::/8`) allowed to read the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllowRule {
    addr: IpAddr,
    prefix: u8,
}

impl AllowRule {
    /// Parses `addr` or `addr/prefix`.
    #[must_use]
    pub fn parse(text: &str) -> Option<Self> {
        let (addr, prefix) = match text.trim().split_once('/') {
            Some((a, p)) => (a.parse::<IpAddr>().ok()?, Some(p.parse::<u8>().ok()?)),
            None => (text.trim().parse::<IpAddr>().ok()?, None),
        };
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = prefix.unwrap_or(max);
        (prefix <= max).then_some(Self { addr, prefix })
    }

    /// Whether `ip` is in it (an IPv4-mapped IPv6 client matches IPv4 rules).
    #[must_use]
    pub fn matches(&self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        let (a, b, bits) = match (self.addr, ip) {
            (IpAddr::V4(r), IpAddr::V4(c)) => {
                (u128::from(u32::from(r)), u128::from(u32::from(c)), 32)
            }
            (IpAddr::V6(r), IpAddr::V6(c)) => (u128::from(r), u128::from(c), 128),
            _ => return false,
        };
        let shift = bits - u32::from(self.prefix);
        shift >= bits || (a >> shift) == (b >> shift)
    }
}

/// The token of a token file: its first line, which must not be empty.
pub fn read_token(path: &Path) -> Result<String, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read token file {}: {e}", path.display()))?;
    let token = text.lines().next().unwrap_or_default().trim().to_string();
    if token.len() < 16 {
        return Err(format!(
            "token file {} must hold a token of at least 16 characters on its first line",
            path.display()
        ));
    }
    Ok(token)
}

/// Compares without stopping at the first difference.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
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
            access: Arc::new(Access::default()),
            clients: Arc::new(AtomicUsize::new(0)),
        }
    }

    /// The same hub with access control.
    #[must_use]
    pub fn with_access(mut self, access: Access) -> Self {
        self.access = Arc::new(access);
        self
    }

    /// Takes a client slot; `None` when `max_clients` are being served.
    fn admit(&self) -> Option<ClientSlot> {
        let max = self.access.max_clients;
        let n = self.clients.fetch_add(1, Ordering::AcqRel) + 1;
        if max > 0 && n > max {
            self.clients.fetch_sub(1, Ordering::AcqRel);
            return None;
        }
        Some(ClientSlot(Arc::clone(&self.clients)))
    }

    /// Clients being served now.
    #[must_use]
    pub fn clients(&self) -> usize {
        self.clients.load(Ordering::Acquire)
    }

    /// Reads the client's `?AUTH={"token":"…"};` within the write time-out.
    async fn authenticate<R: AsyncRead + Unpin>(&self, input: &mut R) -> bool {
        let Some(token) = &self.access.token else {
            return true;
        };
        // Byte by byte up to the newline, so that nothing after it is lost to a buffer.
        let mut raw = Vec::new();
        let read = tokio::time::timeout(self.write_timeout, async {
            let mut byte = [0u8; 1];
            while raw.len() < 4096 {
                match input.read(&mut byte).await {
                    Ok(1) if byte[0] == b'\n' => return true,
                    Ok(1) => raw.push(byte[0]),
                    _ => return false,
                }
            }
            false
        })
        .await;
        if !matches!(read, Ok(true)) {
            return false;
        }
        let line = String::from_utf8_lossy(&raw).into_owned();
        let Some(body) = line
            .trim()
            .strip_prefix("?AUTH=")
            .map(|b| b.trim_end_matches(';'))
        else {
            return false;
        };
        let given = serde_json::from_str::<serde_json::Value>(body)
            .ok()
            .and_then(|v| v.get("token").and_then(|t| t.as_str()).map(str::to_string));
        given.is_some_and(|g| same_secret(g.as_bytes(), token.as_bytes()))
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

    /// The answer to a client's request line (`?DEVICES;`, `?POLL;`, `?WATCH…;`), or an
    /// `ERROR` line for anything else.
    fn answer(&self, request: &str) -> Vec<Arc<str>> {
        let request = request.trim().trim_end_matches(';');
        let (latest_devices, pose, target) = self.latest.lock().map_or_else(
            |_| (Vec::new(), None, None),
            |l| {
                (
                    l.devices.values().cloned().collect::<Vec<_>>(),
                    l.pose.clone(),
                    l.target.clone(),
                )
            },
        );
        let parsed = |lines: &[Arc<str>]| -> Vec<serde_json::Value> {
            lines
                .iter()
                .filter_map(|l| serde_json::from_str(l).ok())
                .collect()
        };
        let line = |v: serde_json::Value| -> Arc<str> { v.to_string().into() };
        let command = request.split_once('=').map_or(request, |(c, _)| c);
        match command {
            "?DEVICES" => vec![line(serde_json::json!({
                "class": "DEVICES",
                "devices": parsed(&latest_devices),
            }))],
            "?POLL" => {
                let poses: Vec<Arc<str>> = pose.into_iter().collect();
                let targets: Vec<Arc<str>> = target.into_iter().collect();
                vec![line(serde_json::json!({
                    "class": "POLL",
                    "poses": parsed(&poses),
                    "targets": parsed(&targets),
                }))]
            }
            "?WATCH" => {
                // The stream is always on: the answer states it, then the current state.
                let mut out = vec![line(
                    serde_json::json!({"class": "WATCH", "enable": true, "json": true}),
                )];
                out.extend(latest_devices);
                out.extend(pose);
                out.extend(target);
                out
            }
            "?VERSION" => vec![version_json().into()],
            _ => vec![line(serde_json::json!({
                "class": "ERROR",
                "message": format!("unknown request {:?}: ?WATCH; ?DEVICES; ?POLL; ?VERSION;", request.chars().take(40).collect::<String>()),
            }))],
        }
    }

    /// Serves one connected client until it leaves, lags, or `stop` is cancelled.
    pub async fn serve_client<W: AsyncWrite + Unpin>(
        &self,
        out: W,
        peer: &str,
        stop: CancellationToken,
    ) {
        self.serve_client_with_requests(None::<tokio::io::Empty>, out, peer, stop)
            .await;
    }

    /// [`PoseHub::serve_client`], answering the request lines the client sends on `input`.
    pub async fn serve_client_with_requests<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
        &self,
        input: Option<R>,
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
        // Requests are read one line at a time, at most 1 kB each.
        let mut requests = input.map(|i| BufReader::new(i).lines());
        loop {
            let next = tokio::select! {
                () = stop.cancelled() => break,
                r = rx.recv() => Incoming::Line(r),
                req = next_request(&mut requests) => Incoming::Request(req),
            };
            match next {
                Incoming::Request(Some(req)) => {
                    let req: String = req.chars().take(1024).collect();
                    for line in self.answer(&req) {
                        if !self.send(&mut out, &line, peer).await {
                            return;
                        }
                    }
                }
                Incoming::Request(None) => requests = None,
                Incoming::Line(Ok(line)) => {
                    if !self.send(&mut out, &line, peer).await {
                        break;
                    }
                }
                Incoming::Line(Err(broadcast::error::RecvError::Lagged(n))) => {
                    tracing::warn!(peer, skipped = n, "pose client too slow; dropping it");
                    self.count_dropped();
                    break;
                }
                Incoming::Line(Err(broadcast::error::RecvError::Closed)) => break,
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

    /// Accepts TCP clients until `stop`: only allowed addresses, at most `max_clients`, and
    /// with a token only after `?AUTH`. Failing accepts (no descriptors left) back off up to 1 s
    /// and are logged once per burst.
    pub async fn serve_tcp(self, listener: TcpListener, stop: CancellationToken) {
        let mut failures = 0u32;
        loop {
            let accepted = tokio::select! {
                () = stop.cancelled() => break,
                a = listener.accept() => a,
            };
            match accepted {
                Ok((stream, peer)) => {
                    if failures > 0 {
                        tracing::warn!(failures, "accepting pose clients again");
                        failures = 0;
                    }
                    if !self.access.allow.is_empty()
                        && !self.access.allow.iter().any(|r| r.matches(peer.ip()))
                    {
                        tracing::warn!(%peer, "pose client not in pose.allow; refused");
                        continue;
                    }
                    let Some(slot) = self.admit() else {
                        tracing::warn!(%peer, max = self.access.max_clients, "too many pose clients; refused");
                        continue;
                    };
                    let _ = stream.set_nodelay(true);
                    let hub = self.clone();
                    let stop = stop.clone();
                    tokio::spawn(async move {
                        let _slot = slot;
                        let peer = peer.to_string();
                        let (mut read, write) = stream.into_split();
                        if !hub.authenticate(&mut read).await {
                            tracing::warn!(%peer, "pose client did not authenticate; refused");
                            let mut write = write;
                            let _ = write_line(&mut write, "{\"class\":\"ERROR\",\"message\":\"authentication required: ?AUTH={\\\"token\\\":\\\"…\\\"};\"}").await;
                            return;
                        }
                        tracing::debug!(%peer, "pose client connected (tcp)");
                        hub.serve_client_with_requests(Some(read), write, &peer, stop)
                            .await;
                    });
                }
                Err(e) => {
                    failures += 1;
                    if failures == 1 {
                        tracing::warn!(error = %e, "accept failed; retrying with back-off (logged again when it recovers)");
                    }
                    let wait = Duration::from_millis(100 * u64::from(failures.min(10)));
                    tokio::select! {
                        () = stop.cancelled() => break,
                        () = tokio::time::sleep(wait) => {}
                    }
                }
            }
        }
    }

    /// Accepts Unix-socket clients until `stop` (at most `max_clients`; the socket file's
    /// permissions are the access control); removes the socket file afterwards if it is still
    /// the one it created.
    pub async fn serve_unix(self, socket: UnixSocket, stop: CancellationToken) {
        let mut failures = 0u32;
        loop {
            let accepted = tokio::select! {
                () = stop.cancelled() => break,
                a = socket.listener.accept() => a,
            };
            match accepted {
                Ok((stream, _)) => {
                    failures = 0;
                    let Some(slot) = self.admit() else {
                        tracing::warn!(
                            max = self.access.max_clients,
                            "too many pose clients; refused"
                        );
                        continue;
                    };
                    let hub = self.clone();
                    let stop = stop.clone();
                    tokio::spawn(async move {
                        let _slot = slot;
                        let (read, write) = stream.into_split();
                        hub.serve_client_with_requests(Some(read), write, "unix", stop)
                            .await;
                    });
                }
                Err(e) => {
                    failures += 1;
                    if failures == 1 {
                        tracing::warn!(error = %e, "accept failed; retrying with back-off");
                    }
                    let wait = Duration::from_millis(100 * u64::from(failures.min(10)));
                    tokio::select! {
                        () = stop.cancelled() => break,
                        () = tokio::time::sleep(wait) => {}
                    }
                }
            }
        }
        socket.remove();
    }
}

async fn write_line<W: AsyncWrite + Unpin>(out: &mut W, line: &str) -> std::io::Result<()> {
    out.write_all(line.as_bytes()).await?;
    out.write_all(b"\n").await?;
    out.flush().await
}

/// What a client's loop waits for.
enum Incoming {
    Line(Result<Arc<str>, broadcast::error::RecvError>),
    Request(Option<String>),
}

/// The next request line, or never when the client sends none (any more).
async fn next_request<R: AsyncRead + Unpin>(
    requests: &mut Option<tokio::io::Lines<BufReader<R>>>,
) -> Option<String> {
    match requests {
        Some(lines) => lines.next_line().await.ok().flatten(),
        None => std::future::pending().await,
    }
}

/// A client slot, given back when dropped.
struct ClientSlot(Arc<AtomicUsize>);

impl Drop for ClientSlot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A bound Unix socket and the identity (device, inode) of the file it created.
pub struct UnixSocket {
    listener: UnixListener,
    path: PathBuf,
    id: Option<(u64, u64)>,
}

fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::symlink_metadata(path)
        .ok()
        .map(|m| (m.dev(), m.ino()))
}

impl UnixSocket {
    /// Removes the socket file if it is still the one bound here.
    fn remove(self) {
        if self.id.is_some() && file_id(&self.path) == self.id {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Binds a Unix socket. An existing file there is replaced only if it is a socket nobody
/// listens on (left by a previous run); anything else is an error, never deleted.
pub fn bind_unix(path: &Path) -> std::io::Result<UnixSocket> {
    use std::os::unix::fs::FileTypeExt;
    if let Ok(m) = std::fs::symlink_metadata(path) {
        if !m.file_type().is_socket() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists and is not a socket; not replacing it",
                    path.display()
                ),
            ));
        }
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AddrInUse,
                format!("another process serves {}", path.display()),
            ));
        }
        std::fs::remove_file(path)?;
    }
    let listener = UnixListener::bind(path)?;
    Ok(UnixSocket {
        listener,
        path: path.to_path_buf(),
        id: file_id(path),
    })
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

    #[test]
    fn allow_rules_match_addresses_and_networks() {
        let net = AllowRule::parse("192.168.10.0/24").unwrap();
        assert!(net.matches("192.168.10.77".parse().unwrap()));
        assert!(!net.matches("192.168.11.1".parse().unwrap()));
        // An IPv4 client seen through an IPv6 socket.
        assert!(net.matches("::ffff:192.168.10.5".parse().unwrap()));
        let one = AllowRule::parse("10.1.2.3").unwrap();
        assert!(one.matches("10.1.2.3".parse().unwrap()));
        assert!(!one.matches("10.1.2.4".parse().unwrap()));
        let v6 = AllowRule::parse("fd00::/8").unwrap();
        assert!(v6.matches("fd12::1".parse().unwrap()));
        assert!(!v6.matches("10.1.2.3".parse().unwrap()));
        assert!(AllowRule::parse("0.0.0.0/0")
            .unwrap()
            .matches("8.8.8.8".parse().unwrap()));
        for bad in ["10.0.0.0/33", "host", "10.0.0/8", ""] {
            assert!(AllowRule::parse(bad).is_none(), "{bad}");
        }
    }

    async fn tcp_hub(access: Access) -> (PoseHub, std::net::SocketAddr, CancellationToken) {
        let hub = PoseHub::new(8).with_access(access);
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let stop = CancellationToken::new();
        tokio::spawn(hub.clone().serve_tcp(listener, stop.clone()));
        (hub, addr, stop)
    }

    async fn first_line(stream: tokio::net::TcpStream) -> Option<String> {
        let mut lines = BufReader::new(stream).lines();
        tokio::time::timeout(Duration::from_secs(3), lines.next_line())
            .await
            .ok()?
            .ok()?
    }

    #[tokio::test]
    async fn a_token_is_asked_before_anything_is_sent() {
        let (_hub, addr, stop) = tcp_hub(Access {
            token: Some("correct horse battery staple".into()),
            ..Access::default()
        })
        .await;
        let mut good = tokio::net::TcpStream::connect(addr).await.unwrap();
        good.write_all(b"?AUTH={\"token\":\"correct horse battery staple\"};\n")
            .await
            .unwrap();
        assert!(first_line(good).await.unwrap().contains("VERSION"));
        let mut bad = tokio::net::TcpStream::connect(addr).await.unwrap();
        bad.write_all(b"?AUTH={\"token\":\"wrong\"};\n")
            .await
            .unwrap();
        let answer = first_line(bad).await.unwrap();
        assert!(
            answer.contains("ERROR") && !answer.contains("correct horse"),
            "{answer}"
        );
        // A client that says nothing is not served either.
        let silent = tokio::net::TcpStream::connect(addr).await.unwrap();
        assert!(first_line(silent).await.unwrap().contains("ERROR"));
        stop.cancel();
    }

    #[tokio::test]
    async fn clients_beyond_the_limit_and_outside_the_allow_list_are_refused() {
        let (hub, addr, stop) = tcp_hub(Access {
            max_clients: 2,
            ..Access::default()
        })
        .await;
        let a = tokio::net::TcpStream::connect(addr).await.unwrap();
        let b = tokio::net::TcpStream::connect(addr).await.unwrap();
        let mut la = BufReader::new(a).lines();
        let mut lb = BufReader::new(b).lines();
        assert!(la.next_line().await.unwrap().unwrap().contains("VERSION"));
        assert!(lb.next_line().await.unwrap().unwrap().contains("VERSION"));
        assert_eq!(hub.clients(), 2);
        let c = tokio::net::TcpStream::connect(addr).await.unwrap();
        assert_eq!(first_line(c).await, None, "third client served");
        drop(la);
        drop(lb);
        stop.cancel();

        let (_hub, addr, stop) = tcp_hub(Access {
            allow: vec![AllowRule::parse("10.9.9.9").unwrap()],
            ..Access::default()
        })
        .await;
        let d = tokio::net::TcpStream::connect(addr).await.unwrap();
        assert_eq!(
            first_line(d).await,
            None,
            "a client outside the list was served"
        );
        stop.cancel();
    }

    #[tokio::test]
    async fn the_unix_socket_never_replaces_a_file_and_removes_only_its_own() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pose.sock");
        std::fs::write(&path, "precious").unwrap();
        assert!(bind_unix(&path).is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
        std::fs::remove_file(&path).unwrap();
        let socket = bind_unix(&path).unwrap();
        // A second daemon on the same path is refused while the first listens.
        assert!(bind_unix(&path).is_err());
        // Someone replaced the file meanwhile: shutdown leaves theirs alone.
        std::fs::remove_file(&path).unwrap();
        std::fs::write(&path, "theirs").unwrap();
        socket.remove();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "theirs");
    }

    #[tokio::test]
    async fn requests_are_answered_with_the_current_state() {
        let (hub, addr, stop) = tcp_hub(Access::default()).await;
        hub.publish_device(
            "hf",
            "{\"class\":\"DEVICE\",\"name\":\"hf\",\"state\":\"connected\"}".into(),
        );
        hub.publish_pose("{\"class\":\"POSE\",\"x\":1.5}".into());
        let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
        s.write_all(b"?DEVICES;\n?POLL;\n?WATCH={\"enable\":true};\n?NONSENSE;\n")
            .await
            .unwrap();
        let mut lines = BufReader::new(s).lines();
        let mut got = Vec::new();
        while got.len() < 10 {
            match tokio::time::timeout(Duration::from_secs(2), lines.next_line()).await {
                Ok(Ok(Some(l))) => got.push(l),
                _ => break,
            }
        }
        let classes: Vec<String> = got
            .iter()
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["class"]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect();
        // Greeting, then the answers in order.
        assert_eq!(
            classes,
            ["VERSION", "DEVICE", "POSE", "DEVICES", "POLL", "WATCH", "DEVICE", "POSE", "ERROR"],
            "{got:?}"
        );
        assert!(got[3].contains("\"name\":\"hf\""), "{}", got[3]);
        assert!(got[4].contains("\"x\":1.5"), "{}", got[4]);
        stop.cancel();
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
