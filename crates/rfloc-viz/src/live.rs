//! The live server: the Foxglove WebSocket protocol (subprotocol `foxglove.websocket.v1`, or
//! its identical successor name `foxglove.sdk.v1`) over tokio-tungstenite.
//!
//! On connect a client gets `serverInfo` (no capabilities) and one `advertise` with every
//! channel; it may `subscribe` and `unsubscribe`; for each subscribed channel it receives binary
//! message-data frames: opcode `0x01`, subscription id (u32 LE), log time in Unix nanoseconds
//! (u64 LE), the protobuf message. Anything else a client sends gets a `status` error.
//!
//! Publishing never waits for a client: each client has a queue of at most `backlog` messages
//! and, when it is full, the oldest queued message is dropped (and counted).

use std::collections::{HashMap, VecDeque};
use std::fmt;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock};

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;
use tokio::task::{JoinHandle, JoinSet};
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::Message;

use crate::base64;
use crate::channels::ChannelInfo;
use crate::hub::{Hub, Sink};

/// The subprotocols a client may ask for, in order of preference: the protocol's name and the
/// name that the Foxglove SDK gives the same protocol.
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.websocket.v1", "foxglove.sdk.v1"];

/// Most bytes of message data queued for one client; past it the oldest queued messages go
/// too, so that a slow client costs bounded memory whatever the message sizes.
pub const CLIENT_QUEUE_BYTES: usize = 32 * 1024 * 1024;

/// Opcode of a server's binary message-data frame.
const OP_MESSAGE_DATA: u8 = 0x01;

/// Status levels of the protocol's `status` message.
const STATUS_WARNING: u8 = 1;
const STATUS_ERROR: u8 = 2;

#[derive(Default)]
struct Subscriptions {
    /// channel index → subscription id
    by_channel: HashMap<usize, u32>,
    /// subscription id → channel index
    by_id: HashMap<u32, usize>,
}

#[derive(Default)]
struct Outbox {
    control: VecDeque<String>,
    data: VecDeque<Vec<u8>>,
    /// Sum of the lengths in `data`.
    data_bytes: usize,
}

struct Client {
    subs: Mutex<Subscriptions>,
    out: Mutex<Outbox>,
    wake: Notify,
}

impl Client {
    fn new() -> Self {
        Self {
            subs: Mutex::new(Subscriptions::default()),
            out: Mutex::new(Outbox::default()),
            wake: Notify::new(),
        }
    }

    fn subscription(&self, ch: usize) -> Option<u32> {
        self.subs
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .by_channel
            .get(&ch)
            .copied()
    }

    fn push_control(&self, text: String) {
        self.out
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .control
            .push_back(text);
        self.wake.notify_one();
    }

    /// Queues a data frame; returns how many frames were dropped to make room: the oldest, while
    /// more than `backlog` frames or [`CLIENT_QUEUE_BYTES`] are queued (the newest frame stays).
    fn push_data(&self, frame: Vec<u8>, backlog: usize) -> u64 {
        let mut dropped = 0;
        {
            let mut out = self.out.lock().unwrap_or_else(PoisonError::into_inner);
            out.data_bytes += frame.len();
            out.data.push_back(frame);
            while out.data.len() > backlog
                || (out.data_bytes > CLIENT_QUEUE_BYTES && out.data.len() > 1)
            {
                if let Some(old) = out.data.pop_front() {
                    out.data_bytes -= old.len();
                    dropped += 1;
                }
            }
        }
        self.wake.notify_one();
        dropped
    }

    fn take(&self) -> (Vec<String>, Vec<Vec<u8>>) {
        let mut out = self.out.lock().unwrap_or_else(PoisonError::into_inner);
        out.data_bytes = 0;
        (
            out.control.drain(..).collect(),
            out.data.drain(..).collect(),
        )
    }

    fn status(&self, level: u8, message: impl Into<String>) {
        let message: String = message.into();
        self.push_control(json!({"op": "status", "level": level, "message": message}).to_string());
    }
}

/// The server's state shared by the publisher (as a [`Sink`]) and the connection tasks.
struct Live {
    clients: RwLock<Vec<Arc<Client>>>,
    /// Number of clients subscribed to each channel, so that `wants` is one load.
    subscribers: Vec<AtomicUsize>,
    backlog: usize,
    dropped: AtomicU64,
    server_info: String,
    advertise: String,
}

impl Sink for Live {
    fn wants(&self, ch: usize) -> bool {
        self.subscribers
            .get(ch)
            .is_some_and(|n| n.load(Ordering::Relaxed) > 0)
    }

    fn write(&self, ch: usize, log_time: u64, data: &[u8]) {
        let clients = self.clients.read().unwrap_or_else(PoisonError::into_inner);
        for client in clients.iter() {
            if let Some(sub) = client.subscription(ch) {
                let mut frame = Vec::with_capacity(13 + data.len());
                frame.push(OP_MESSAGE_DATA);
                frame.extend_from_slice(&sub.to_le_bytes());
                frame.extend_from_slice(&log_time.to_le_bytes());
                frame.extend_from_slice(data);
                let dropped = client.push_data(frame, self.backlog);
                if dropped > 0 {
                    self.dropped.fetch_add(dropped, Ordering::Relaxed);
                }
            }
        }
    }
}

impl Live {
    fn subscribe(&self, client: &Client, request: &Value) {
        let Some(list) = request.get("subscriptions").and_then(Value::as_array) else {
            client.status(STATUS_ERROR, "subscribe: no subscriptions array");
            return;
        };
        for s in list {
            let id = s
                .get("id")
                .and_then(Value::as_u64)
                .and_then(|v| u32::try_from(v).ok());
            let channel = s.get("channelId").and_then(Value::as_u64);
            let (Some(id), Some(channel)) = (id, channel) else {
                client.status(STATUS_ERROR, format!("subscribe: bad subscription {s}"));
                continue;
            };
            let ch = usize::try_from(channel)
                .ok()
                .and_then(|c| c.checked_sub(1))
                .filter(|&c| c < self.subscribers.len());
            let Some(ch) = ch else {
                client.status(STATUS_ERROR, format!("subscribe: no channel {channel}"));
                continue;
            };
            let mut subs = client.subs.lock().unwrap_or_else(PoisonError::into_inner);
            if subs.by_id.contains_key(&id) {
                client.status(
                    STATUS_ERROR,
                    format!("subscribe: subscription id {id} in use"),
                );
            } else if subs.by_channel.contains_key(&ch) {
                client.status(
                    STATUS_ERROR,
                    format!("subscribe: channel {channel} already subscribed"),
                );
            } else {
                subs.by_id.insert(id, ch);
                subs.by_channel.insert(ch, id);
                if let Some(n) = self.subscribers.get(ch) {
                    n.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    fn unsubscribe(&self, client: &Client, request: &Value) {
        let Some(list) = request.get("subscriptionIds").and_then(Value::as_array) else {
            client.status(STATUS_ERROR, "unsubscribe: no subscriptionIds array");
            return;
        };
        for v in list {
            let removed = v
                .as_u64()
                .and_then(|id| u32::try_from(id).ok())
                .and_then(|id| {
                    let mut subs = client.subs.lock().unwrap_or_else(PoisonError::into_inner);
                    let ch = subs.by_id.remove(&id)?;
                    subs.by_channel.remove(&ch);
                    Some(ch)
                });
            match removed.and_then(|ch| self.subscribers.get(ch)) {
                Some(n) => {
                    n.fetch_sub(1, Ordering::Relaxed);
                }
                None => client.status(STATUS_WARNING, format!("unsubscribe: no subscription {v}")),
            }
        }
    }

    fn handle_text(&self, client: &Client, text: &str) {
        let request: Value = match serde_json::from_str(text) {
            Ok(v) => v,
            Err(e) => {
                client.status(STATUS_ERROR, format!("not JSON: {e}"));
                return;
            }
        };
        match request.get("op").and_then(Value::as_str) {
            Some("subscribe") => self.subscribe(client, &request),
            Some("unsubscribe") => self.unsubscribe(client, &request),
            Some(op) => client.status(
                STATUS_ERROR,
                format!("operation {op} is not supported (the server has no capabilities)"),
            ),
            None => client.status(STATUS_ERROR, "message without op"),
        }
    }

    /// Removes a client and its subscriptions (on disconnect or when its task is aborted).
    fn remove(&self, client: &Arc<Client>) {
        self.clients
            .write()
            .unwrap_or_else(PoisonError::into_inner)
            .retain(|c| !Arc::ptr_eq(c, client));
        let subs = client.subs.lock().unwrap_or_else(PoisonError::into_inner);
        for ch in subs.by_channel.keys() {
            if let Some(n) = self.subscribers.get(*ch) {
                n.fetch_sub(1, Ordering::Relaxed);
            }
        }
    }
}

/// Unregisters a client however its task ends.
struct Registered<'a> {
    live: &'a Live,
    client: Arc<Client>,
}

impl Drop for Registered<'_> {
    fn drop(&mut self) {
        self.live.remove(&self.client);
    }
}

fn server_info(session_id: &str) -> String {
    json!({
        "op": "serverInfo",
        "name": "rfloc",
        "capabilities": [],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": session_id,
    })
    .to_string()
}

fn advertise(channels: &[ChannelInfo]) -> String {
    let list: Vec<Value> = channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "id": i + 1,
                "topic": c.topic,
                "encoding": c.encoding,
                "schemaName": c.schema_name,
                "schema": base64::encode(&c.schema),
                "schemaEncoding": c.schema_encoding,
            })
        })
        .collect();
    json!({"op": "advertise", "channels": list}).to_string()
}

/// Accepts the handshake when the client offers one of [`SUBPROTOCOLS`] (the first of ours it
/// offers, in our order of preference, is answered); refuses it with 400 otherwise.
#[allow(clippy::result_large_err)] // the callback type of tungstenite
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered: Vec<String> = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|h| h.to_str().ok())
        .flat_map(|h| h.split(','))
        .map(|p| p.trim().to_string())
        .collect();
    match SUBPROTOCOLS
        .iter()
        .find(|p| offered.iter().any(|o| o == *p))
    {
        Some(p) => {
            resp.headers_mut()
                .insert("sec-websocket-protocol", HeaderValue::from_static(p));
            Ok(resp)
        }
        None => {
            let mut refusal = ErrorResponse::new(Some(format!(
                "expected subprotocol {} (Sec-WebSocket-Protocol)",
                SUBPROTOCOLS.join(" or ")
            )));
            *refusal.status_mut() = StatusCode::BAD_REQUEST;
            Err(refusal)
        }
    }
}

async fn serve_client(stream: TcpStream, peer: SocketAddr, live: Arc<Live>) {
    let ws = match tokio_tungstenite::accept_hdr_async(stream, choose_subprotocol).await {
        Ok(ws) => ws,
        Err(e) => {
            tracing::debug!(%peer, "WebSocket handshake failed: {e}");
            return;
        }
    };
    let (mut tx, mut rx) = ws.split();
    let greeting = async {
        tx.feed(Message::text(live.server_info.clone())).await?;
        tx.feed(Message::text(live.advertise.clone())).await?;
        tx.flush().await
    };
    if let Err(e) = greeting.await {
        tracing::debug!(%peer, "client left during greeting: {e}");
        return;
    }
    let client = Arc::new(Client::new());
    live.clients
        .write()
        .unwrap_or_else(PoisonError::into_inner)
        .push(Arc::clone(&client));
    let _registered = Registered {
        live: &live,
        client: Arc::clone(&client),
    };
    tracing::info!(%peer, "live client connected");

    let writer = async {
        loop {
            let (control, data) = client.take();
            if control.is_empty() && data.is_empty() {
                client.wake.notified().await;
                continue;
            }
            for text in control {
                tx.feed(Message::text(text)).await?;
            }
            for frame in data {
                tx.feed(Message::binary(frame)).await?;
            }
            tx.flush().await?;
        }
    };
    let reader = async {
        while let Some(msg) = rx.next().await {
            match msg? {
                Message::Text(text) => live.handle_text(&client, text.as_str()),
                Message::Binary(_) => client.status(
                    STATUS_ERROR,
                    "binary client messages are not supported (no clientPublish capability)",
                ),
                Message::Close(_) => break,
                Message::Ping(_) | Message::Pong(_) | Message::Frame(_) => {}
            }
        }
        Ok::<(), tokio_tungstenite::tungstenite::Error>(())
    };
    let result: Result<(), tokio_tungstenite::tungstenite::Error> = tokio::select! {
        r = writer => r,
        r = reader => r,
    };
    match result {
        Ok(()) => tracing::info!(%peer, "live client disconnected"),
        Err(e) => tracing::info!(%peer, "live client dropped: {e}"),
    }
}

async fn accept_loop(listener: TcpListener, live: Arc<Live>) {
    // Dropping this set (when the server task is aborted) aborts every connection.
    let mut connections = JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    let _ = stream.set_nodelay(true);
                    connections.spawn(serve_client(stream, peer, Arc::clone(&live)));
                }
                Err(e) => {
                    // Out of file descriptors, say: wait a little rather than spin.
                    tracing::warn!("accept failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            },
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
        }
    }
}

/// A running live server. Dropping it (or [`LiveServer::stop`]) closes the listening socket and
/// every connection.
pub struct LiveServer {
    local_addr: SocketAddr,
    hub: Arc<Hub>,
    sink_id: u64,
    live: Arc<Live>,
    task: Option<JoinHandle<()>>,
}

impl fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LiveServer")
            .field("local_addr", &self.local_addr)
            .finish_non_exhaustive()
    }
}

pub(crate) async fn start(
    hub: &Arc<Hub>,
    addr: SocketAddr,
    backlog: usize,
) -> std::io::Result<LiveServer> {
    let listener = TcpListener::bind(addr).await?;
    let local_addr = listener.local_addr()?;
    let session_id = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis())
        .unwrap_or(0)
        .to_string();
    let live = Arc::new(Live {
        clients: RwLock::new(Vec::new()),
        subscribers: hub.channels.iter().map(|_| AtomicUsize::new(0)).collect(),
        backlog: backlog.max(1),
        dropped: AtomicU64::new(0),
        server_info: server_info(&session_id),
        advertise: advertise(&hub.channels),
    });
    let sink_id = hub.add(live.clone());
    let task = tokio::spawn(accept_loop(listener, Arc::clone(&live)));
    Ok(LiveServer {
        local_addr,
        hub: Arc::clone(hub),
        sink_id,
        live,
        task: Some(task),
    })
}

impl LiveServer {
    /// The address the server listens on (with the port chosen when 0 was asked for).
    #[must_use]
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The URL for Foxglove's "Open connection → Foxglove WebSocket".
    #[must_use]
    pub fn url(&self) -> String {
        format!("ws://{}", self.local_addr)
    }

    /// How many clients are connected (past the handshake).
    #[must_use]
    pub fn client_count(&self) -> usize {
        self.live
            .clients
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// How many messages were dropped, over all clients, because a client's queue was full.
    #[must_use]
    pub fn dropped_messages(&self) -> u64 {
        self.live.dropped.load(Ordering::Relaxed)
    }

    /// Stops the server and waits until its listening socket and connections are closed.
    pub async fn stop(mut self) {
        self.hub.remove(self.sink_id);
        if let Some(task) = self.task.take() {
            task.abort();
            let _ = task.await;
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.hub.remove(self.sink_id);
        if let Some(task) = self.task.take() {
            task.abort();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn queued(c: &Client) -> (usize, usize) {
        let out = c.out.lock().unwrap();
        (out.data.len(), out.data_bytes)
    }

    #[test]
    fn a_full_queue_drops_its_oldest_frames() {
        let c = Client::new();
        let mut dropped = 0;
        for i in 0..10u8 {
            dropped += c.push_data(vec![i; 3], 4);
        }
        assert_eq!(dropped, 6);
        assert_eq!(queued(&c), (4, 12));
        let (_, data) = c.take();
        assert_eq!(data.iter().map(|f| f[0]).collect::<Vec<_>>(), [6, 7, 8, 9]);
        assert_eq!(queued(&c), (0, 0));
    }

    #[test]
    fn the_queue_is_bounded_in_bytes_too_but_keeps_the_newest_frame() {
        let c = Client::new();
        let big = CLIENT_QUEUE_BYTES / 3 + 1;
        let mut dropped = 0;
        for _ in 0..3 {
            dropped += c.push_data(vec![0; big], 1000);
        }
        assert_eq!(
            dropped, 1,
            "three frames exceed the byte limit: the oldest went"
        );
        assert_eq!(queued(&c), (2, 2 * big));
        // A single frame larger than the limit is still sent.
        assert_eq!(c.push_data(vec![1; CLIENT_QUEUE_BYTES + 1], 1000), 2);
        assert_eq!(queued(&c).0, 1);
        c.push_control("{}".into());
        let (control, data) = c.take();
        assert_eq!((control.len(), data.len()), (1, 1));
    }
}
