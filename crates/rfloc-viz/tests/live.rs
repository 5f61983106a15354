//! The live server against a real WebSocket client (tokio-tungstenite) on loopback: handshake
//! with the `foxglove.websocket.v1` subprotocol, `serverInfo`, `advertise`, `subscribe`, binary
//! message data decoded back into the pose that was published, `unsubscribe`, errors, and a
//! client that stops reading while the publisher goes on.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use foxglove::messages::PoseInFrame;
use foxglove::Decode;
use futures_util::{SinkExt, StreamExt};
use nalgebra::Matrix3;
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use rfloc_viz::{topics, LogLevel, RangeScan, Stamp, Viz, VizEvent};
use serde_json::{json, Value};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

async fn connect(url: &str, subprotocol: Option<&str>) -> Result<(Ws, Option<String>), WsError> {
    let mut request = url.into_client_request().unwrap();
    if let Some(p) = subprotocol {
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", HeaderValue::from_str(p).unwrap());
    }
    let (ws, response) = tokio_tungstenite::connect_async(request).await?;
    let chosen = response
        .headers()
        .get("sec-websocket-protocol")
        .map(|v| v.to_str().unwrap().to_string());
    Ok((ws, chosen))
}

/// The next message, within `limit`; `None` on time-out.
async fn next_within(ws: &mut Ws, limit: Duration) -> Option<Message> {
    match tokio::time::timeout(limit, ws.next()).await {
        Ok(Some(Ok(m))) => Some(m),
        Ok(other) => panic!("connection ended: {other:?}"),
        Err(_) => None,
    }
}

async fn next_json(ws: &mut Ws) -> Value {
    match next_within(ws, Duration::from_secs(5)).await {
        Some(Message::Text(t)) => serde_json::from_str(t.as_str()).unwrap(),
        other => panic!("expected a text message, got {other:?}"),
    }
}

/// Waits (bounded) until `f` holds.
async fn eventually(what: &str, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while !f() {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "timed out waiting for {what}"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

fn channel_id(advertise: &Value, topic: &str) -> u64 {
    advertise["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["topic"] == topic)
        .unwrap_or_else(|| panic!("{topic} not advertised"))["id"]
        .as_u64()
        .unwrap()
}

fn estimate() -> PoseEstimate {
    PoseEstimate {
        time: 0.0,
        pose: Pose2::new(12.5, -3.25, 0.75),
        covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.04, 0.09, 0.01)),
        mode: EstimateMode::Fix,
        source: "ekf".into(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_subscribes_and_decodes_the_published_pose() {
    let viz = Viz::new();
    let server = viz.serve(loopback(), None).await.unwrap();
    assert!(server.url().starts_with("ws://127.0.0.1:"));
    let (mut ws, chosen) = connect(&server.url(), Some("foxglove.websocket.v1"))
        .await
        .unwrap();
    assert_eq!(chosen.as_deref(), Some("foxglove.websocket.v1"));

    let info = next_json(&mut ws).await;
    assert_eq!(info["op"], "serverInfo");
    assert_eq!(info["name"], "rfloc");
    assert_eq!(info["capabilities"], json!([]));
    assert!(info["sessionId"].is_string());

    let advertise = next_json(&mut ws).await;
    assert_eq!(advertise["op"], "advertise");
    let channels = advertise["channels"].as_array().unwrap();
    let advertised: Vec<_> = channels
        .iter()
        .map(|c| c["topic"].as_str().unwrap())
        .collect();
    assert_eq!(advertised, topics::ALL);
    for c in channels {
        assert_eq!(c["encoding"], "protobuf", "{c}");
        assert_eq!(c["schemaEncoding"], "protobuf", "{c}");
        assert!(!c["schema"].as_str().unwrap().is_empty(), "{c}");
    }
    let pose_channel = channels
        .iter()
        .find(|c| c["topic"] == topics::POSE)
        .unwrap();
    assert_eq!(pose_channel["schemaName"], "foxglove.PoseInFrame");
    let tf_channel = channels.iter().find(|c| c["topic"] == topics::TF).unwrap();
    assert_eq!(tf_channel["schemaName"], "foxglove.FrameTransforms");
    eventually("the client to register", || server.client_count() == 1).await;

    // Nobody subscribed yet: nothing is built or sent.
    assert!(!viz.is_watched(topics::POSE));
    let id = channel_id(&advertise, topics::POSE);
    ws.send(Message::text(
        json!({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": id}]}).to_string(),
    ))
    .await
    .unwrap();
    eventually("the subscription", || viz.is_watched(topics::POSE)).await;
    assert!(!viz.is_watched(topics::STATUS));

    let stamp = Stamp::from_unix_secs(1_767_225_600.125).unwrap();
    // A message on a channel the client did not subscribe to is not sent to it.
    viz.status(stamp, "urg", LogLevel::Warning, "stale");
    viz.publish(&VizEvent::Pose {
        stamp,
        estimate: estimate(),
    });
    let frame = match next_within(&mut ws, Duration::from_secs(5)).await {
        Some(Message::Binary(b)) => b,
        other => panic!("expected message data, got {other:?}"),
    };
    assert_eq!(frame[0], 0x01, "opcode: message data");
    assert_eq!(u32::from_le_bytes(frame[1..5].try_into().unwrap()), 7);
    assert_eq!(
        u64::from_le_bytes(frame[5..13].try_into().unwrap()),
        1_767_225_600_125_000_000,
        "log time = measurement time"
    );
    let pose = PoseInFrame::decode(&frame[13..]).unwrap();
    assert_eq!(pose.frame_id, "map");
    let t = pose.timestamp.unwrap();
    assert_eq!((t.sec(), t.nsec()), (1_767_225_600, 125_000_000));
    let p = pose.pose.unwrap();
    let (pos, q) = (p.position.unwrap(), p.orientation.unwrap());
    assert_eq!((pos.x, pos.y, pos.z), (12.5, -3.25, 0.0));
    assert!((q.z - 0.375f64.sin()).abs() < 1e-12 && (q.w - 0.375f64.cos()).abs() < 1e-12);
    assert_eq!((q.x, q.y), (0.0, 0.0));

    // Unknown operations and bad subscriptions get a status error.
    ws.send(Message::text(
        json!({"op": "getParameters", "parameterNames": []}).to_string(),
    ))
    .await
    .unwrap();
    let status = next_json(&mut ws).await;
    assert_eq!(
        (&status["op"], &status["level"]),
        (&json!("status"), &json!(2))
    );
    ws.send(Message::text(
        json!({"op": "subscribe", "subscriptions": [{"id": 8, "channelId": 999}]}).to_string(),
    ))
    .await
    .unwrap();
    let status = next_json(&mut ws).await;
    assert!(
        status["message"].as_str().unwrap().contains("999"),
        "{status}"
    );

    // After unsubscribing, nothing more arrives.
    ws.send(Message::text(
        json!({"op": "unsubscribe", "subscriptionIds": [7]}).to_string(),
    ))
    .await
    .unwrap();
    eventually("the unsubscription", || !viz.is_watched(topics::POSE)).await;
    viz.pose(stamp, &estimate());
    assert!(
        next_within(&mut ws, Duration::from_millis(300))
            .await
            .is_none(),
        "a message after unsubscribe"
    );

    ws.close(None).await.unwrap();
    eventually("the client to leave", || server.client_count() == 0).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_handshake_needs_the_subprotocol_and_takes_the_sdk_name_too() {
    let viz = Viz::new();
    let server = viz.serve(loopback(), Some(16)).await.unwrap();
    match connect(&server.url(), None).await {
        Err(WsError::Http(response)) => assert_eq!(response.status(), 400),
        other => panic!("expected a 400 refusal, got {:?}", other.map(|(_, p)| p)),
    }
    match connect(&server.url(), Some("foxglove.websocket.v2")).await {
        Err(WsError::Http(response)) => assert_eq!(response.status(), 400),
        other => panic!("expected a 400 refusal, got {:?}", other.map(|(_, p)| p)),
    }
    // The Foxglove SDK's name of the same protocol, and a list with ours in it.
    let (mut ws, chosen) = connect(&server.url(), Some("foxglove.sdk.v1"))
        .await
        .unwrap();
    assert_eq!(chosen.as_deref(), Some("foxglove.sdk.v1"));
    assert_eq!(next_json(&mut ws).await["op"], "serverInfo");
    let (mut ws, chosen) = connect(
        &server.url(),
        Some("foxglove.sdk.v1, foxglove.websocket.v1"),
    )
    .await
    .unwrap();
    assert_eq!(chosen.as_deref(), Some("foxglove.websocket.v1"));
    assert_eq!(next_json(&mut ws).await["op"], "serverInfo");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_stops_reading_loses_messages_but_never_stalls_the_publisher() {
    let viz = Viz::new();
    let server = viz.serve(loopback(), Some(64)).await.unwrap();
    let (mut slow, _) = connect(&server.url(), Some("foxglove.websocket.v1"))
        .await
        .unwrap();
    next_json(&mut slow).await;
    let advertise = next_json(&mut slow).await;
    let id = channel_id(&advertise, topics::SCAN);
    slow.send(Message::text(
        json!({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": id}]}).to_string(),
    ))
    .await
    .unwrap();
    eventually("the subscription", || viz.is_watched(topics::SCAN)).await;
    // From here on `slow` is never read. 4000 scans of 1081 ranges are about 35 MB, more than
    // the socket buffers hold.
    let publisher = viz.clone();
    let started = Instant::now();
    let publishing = tokio::task::spawn_blocking(move || {
        let scan = RangeScan {
            mount: Pose2::new(0.1, 0.0, 0.0),
            start_angle: -2.356,
            end_angle: 2.356,
            ranges: vec![4.0; 1081],
            intensities: Vec::new(),
        };
        for i in 0..4000u64 {
            publisher.scan(Stamp::from_unix_nanos(1_000_000_000 * i), &scan);
        }
    });
    tokio::time::timeout(Duration::from_secs(60), publishing)
        .await
        .expect("publishing stalled behind a client that does not read")
        .unwrap();
    println!(
        "4000 scans published in {:?}; {} dropped for the slow client",
        started.elapsed(),
        server.dropped_messages()
    );
    eventually("queued scans to be dropped", || {
        server.dropped_messages() > 0
    })
    .await;

    // The server still serves others.
    let (mut other, _) = connect(&server.url(), Some("foxglove.websocket.v1"))
        .await
        .unwrap();
    assert_eq!(next_json(&mut other).await["op"], "serverInfo");
    assert_eq!(next_json(&mut other).await["op"], "advertise");
    eventually("both clients", || server.client_count() == 2).await;
    drop(slow);
}
