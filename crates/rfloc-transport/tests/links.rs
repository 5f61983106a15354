//! Real links: a pseudo-terminal pair for the serial path and a loopback socket for TCP, and a
//! capture recorded through the recording wrapper replayed byte for byte.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_capture::{Capture, Header, RecordKind};
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::{
    open, CaptureSink, LinkConfig, MonotonicClock, Recorder, SerialLink, TcpLink,
};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio_serial::{SerialPort, SerialStream};

/// A `Write` into a shared buffer, so a test can read back what a sink wrote.
#[derive(Clone, Default)]
struct SharedBuf(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for SharedBuf {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[tokio::test]
async fn serial_path_through_a_pty_opened_from_config() {
    let (mut device, host_side) = SerialStream::pair().expect("pty pair");
    let path = host_side.name().expect("pty has a name");
    // Opening the same pty through the config path proves open()'s serial branch.
    drop(host_side);
    let cfg = LinkConfig::Serial(SerialLink {
        path: path.clone(),
        baud: 115_200,
        data_bits: Default::default(),
        parity: Default::default(),
        stop_bits: Default::default(),
        flow_control: Default::default(),
    });
    let mut host = open(&cfg)
        .await
        .unwrap_or_else(|e| panic!("open {path}: {e}"));
    host.write_all(b"AT+Scan=AC,RSSI\r").await.unwrap();
    host.flush().await.unwrap();
    let mut got = vec![0u8; 16];
    tokio::time::timeout(Duration::from_secs(5), device.read_exact(&mut got))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(got, b"AT+Scan=AC,RSSI\r");
    device.write_all(b"OK\r\n").await.unwrap();
    let mut reply = vec![0u8; 4];
    tokio::time::timeout(Duration::from_secs(5), host.read_exact(&mut reply))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(reply, b"OK\r\n");
}

#[tokio::test]
async fn tcp_path_through_loopback() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let server = tokio::spawn(async move {
        let (mut s, _) = listener.accept().await.unwrap();
        s.write_all(b"Username>\0").await.unwrap();
        let mut buf = [0u8; 6];
        s.read_exact(&mut buf).await.unwrap();
        buf
    });
    let mut host = open(&LinkConfig::Tcp(TcpLink {
        address,
        connect_timeout: 2.0,
    }))
    .await
    .unwrap();
    let mut banner = [0u8; 10];
    host.read_exact(&mut banner).await.unwrap();
    assert_eq!(&banner, b"Username>\0");
    host.write_all(b"alien\n").await.unwrap();
    assert_eq!(&server.await.unwrap(), b"alien\n");
}

#[tokio::test]
async fn tcp_connect_failure_names_the_address() {
    // Bind then drop to get a port nobody listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let address = format!("127.0.0.1:{port}");
    let err = open(&LinkConfig::Tcp(TcpLink {
        address: address.clone(),
        connect_timeout: 1.0,
    }))
    .await
    .unwrap_err();
    assert!(err.to_string().contains(&address), "{err}");
}

/// A little request/response "driver": logs in and polls twice, returning each read it made.
async fn poll_session<T: AsyncRead + AsyncWrite + Unpin>(link: &mut T) -> Vec<Vec<u8>> {
    let mut reads = Vec::new();
    let mut buf = [0u8; 256];
    for request in [&b"alien\n"[..], b"t\n", b"t\n"] {
        let n = link.read(&mut buf).await.unwrap();
        reads.push(buf[..n].to_vec());
        link.write_all(request).await.unwrap();
        link.flush().await.unwrap();
    }
    let n = link.read(&mut buf).await.unwrap();
    reads.push(buf[..n].to_vec());
    reads
}

#[tokio::test]
async fn recorded_capture_replays_byte_identically() {
    let (mut device, host) = SerialStream::pair().unwrap();
    let device_task = tokio::spawn(async move {
        let mut buf = [0u8; 64];
        for reply in [
            &b"Username>\0"[..],
            b"IDK 47EC RSSI 2235.3;\r\n\0",
            b"(No Tags)\r\n\0",
            b"Goodbye!\r\n",
        ] {
            device.write_all(reply).await.unwrap();
            device.flush().await.unwrap();
            if reply != b"Goodbye!\r\n" {
                // Wait for the next request before answering.
                let mut line = Vec::new();
                while !line.ends_with(b"\n") {
                    let n = device.read(&mut buf).await.unwrap();
                    line.extend_from_slice(&buf[..n]);
                }
            }
        }
        // Keep the pty master open: closing it would discard unread bytes on the other side.
        device
    });
    let out = SharedBuf::default();
    let sink = CaptureSink::from_writer(
        Box::new(out.clone()),
        &Header::new("alien-alr9900", "serial 115200 8N1"),
        MonotonicClock::shared(),
    )
    .unwrap();
    let mut recorded = Recorder::new(host, sink.clone());
    let live = poll_session(&mut recorded).await;
    let _device = device_task.await.unwrap();
    assert_eq!(live.last().map(Vec::as_slice), Some(&b"Goodbye!\r\n"[..]));
    sink.flush().unwrap();
    drop(recorded);

    let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
    let capture = Capture::parse(&text, "recorded").unwrap();
    assert_eq!(capture.tx_bytes(), b"alien\nt\nt\n");
    assert_eq!(capture.rx_bytes(), live.concat());

    let (mut replay, mut handle) = Replayer::new(capture.clone())
        .mode(ReplayMode::RequestResponse)
        .strict(true)
        .start();
    let replayed = poll_session(&mut replay).await;
    // Same bytes, read in the same chunks.
    assert_eq!(replayed, live, "driver saw different reads on replay");
    let report = handle.finished().await;
    assert!(report.mismatches.is_empty(), "{:?}", report.mismatches);
    assert_eq!(report.requests, 3);
    let rx_records = capture
        .records
        .iter()
        .filter(|r| matches!(r.kind, RecordKind::Rx(_)))
        .count();
    assert_eq!(rx_records, live.len());
    // Written back out, the capture parses to the same records.
    assert_eq!(
        Capture::parse(&capture.to_text(), "again").unwrap(),
        capture
    );
}
