//! `rfloc watch`: a small client of the pose stream.

use std::path::PathBuf;

use anyhow::Context;
use rfloc_daemon::message::Message;
use tokio::io::{AsyncBufReadExt, AsyncRead, BufReader};

/// Where to connect.
#[derive(Debug, Clone)]
pub enum Endpoint {
    Tcp(String),
    Unix(PathBuf),
}

/// Prints the stream: raw JSON lines, or one short human line per object.
pub async fn watch(endpoint: Endpoint, raw: bool, count: Option<usize>) -> anyhow::Result<()> {
    match endpoint {
        Endpoint::Tcp(addr) => {
            let s = tokio::net::TcpStream::connect(&addr)
                .await
                .with_context(|| format!("connecting to {addr}"))?;
            print_stream(s, raw, count).await
        }
        Endpoint::Unix(path) => {
            let s = tokio::net::UnixStream::connect(&path)
                .await
                .with_context(|| format!("connecting to {}", path.display()))?;
            print_stream(s, raw, count).await
        }
    }
}

async fn print_stream<R: AsyncRead + Unpin>(
    r: R,
    raw: bool,
    count: Option<usize>,
) -> anyhow::Result<()> {
    let mut lines = BufReader::new(r).lines();
    let mut poses = 0usize;
    while let Some(line) = lines.next_line().await? {
        let message = Message::from_line(&line);
        if raw {
            println!("{line}");
        } else {
            match &message {
                Ok(m) => println!("{}", summarise(m)),
                Err(e) => println!("? {line} ({e})"),
            }
        }
        if matches!(message, Ok(Message::Pose(_))) {
            poses += 1;
            if count.is_some_and(|c| poses >= c) {
                break;
            }
        }
    }
    Ok(())
}

/// One human line per message.
#[must_use]
pub fn summarise(m: &Message) -> String {
    match m {
        Message::Pose(p) => match (p.x, p.y, p.yaw) {
            (Some(x), Some(y), Some(yaw)) => format!(
                "POSE {} x={:.3} y={:.3} yaw={:.1}° σxy={:.3} m mode={} src={}",
                p.time,
                x,
                y,
                yaw.to_degrees(),
                (p.cov.first().copied().unwrap_or(0.0) + p.cov.get(7).copied().unwrap_or(0.0))
                    .sqrt(),
                p.mode,
                p.source,
            ),
            _ => format!(
                "POSE {} no position yet mode={} src={}",
                p.time, p.mode, p.source
            ),
        },
        Message::Target(t) => format!(
            "TARGET {} {} x={:.3} y={:.3} σxy={:.3} m src={}",
            t.time,
            t.id,
            t.x,
            t.y,
            (t.cov[0] + t.cov[2]).sqrt(),
            t.source,
        ),
        Message::Device(d) => format!("DEVICE {} {} ({}) {}", d.name, d.state, d.driver, d.detail),
        Message::Version(v) => format!(
            "VERSION rfloc {} protocol {}.{}",
            v.release, v.proto_major, v.proto_minor
        ),
    }
}
