//! `rfloc watch`: a small client of the pose stream.

use std::path::PathBuf;

use anyhow::Context;
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
        let is_pose = line.contains("\"class\":\"POSE\"");
        if raw {
            println!("{line}");
        } else {
            println!("{}", summarise(&line));
        }
        if is_pose {
            poses += 1;
            if count.is_some_and(|c| poses >= c) {
                break;
            }
        }
    }
    Ok(())
}

/// One human line per object.
#[must_use]
pub fn summarise(line: &str) -> String {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
        return format!("? {line}");
    };
    match v["class"].as_str() {
        Some("POSE") => format!(
            "POSE {} x={:.3} y={:.3} yaw={:.1}° σxy={:.3} m mode={} src={}",
            v["time"].as_str().unwrap_or("?"),
            v["x"].as_f64().unwrap_or(f64::NAN),
            v["y"].as_f64().unwrap_or(f64::NAN),
            v["yaw"].as_f64().unwrap_or(f64::NAN).to_degrees(),
            (v["cov"][0].as_f64().unwrap_or(0.0) + v["cov"][7].as_f64().unwrap_or(0.0)).sqrt(),
            v["mode"].as_str().unwrap_or("?"),
            v["source"].as_str().unwrap_or("?"),
        ),
        Some("TARGET") => format!(
            "TARGET {} {} x={:.3} y={:.3} σxy={:.3} m src={}",
            v["time"].as_str().unwrap_or("?"),
            v["id"].as_str().unwrap_or("?"),
            v["x"].as_f64().unwrap_or(f64::NAN),
            v["y"].as_f64().unwrap_or(f64::NAN),
            (v["cov"][0].as_f64().unwrap_or(0.0) + v["cov"][2].as_f64().unwrap_or(0.0)).sqrt(),
            v["source"].as_str().unwrap_or("?"),
        ),
        Some("DEVICE") => format!(
            "DEVICE {} {} ({}) {}",
            v["name"].as_str().unwrap_or("?"),
            v["state"].as_str().unwrap_or("?"),
            v["driver"].as_str().unwrap_or("?"),
            v["detail"].as_str().unwrap_or("")
        ),
        Some(other) => format!("{other} {line}"),
        None => format!("? {line}"),
    }
}
