//! A link full of garbage is logged a few lines at a time, not a line per malformed line: 1 MB
//! of random bytes once gave 8,112 WARN lines (2.6 MB of log).
#![allow(clippy::unwrap_used)]

use std::io::Write;
use std::sync::{Arc, Mutex};

use rfloc_kts::KtsCodec;

#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Seeded pseudo-random bytes.
fn garbage(n: usize) -> Vec<u8> {
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

#[test]
fn a_megabyte_of_garbage_gives_a_handful_of_warnings() {
    let log = Captured::default();
    let writer = log.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_max_level(tracing::Level::WARN)
        .with_ansi(false)
        .finish();
    let mut codec = KtsCodec::new();
    tracing::subscriber::with_default(subscriber, || {
        for chunk in garbage(1 << 20).chunks(4096) {
            let _ = codec.decode(chunk);
        }
    });
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    let warnings = text.lines().filter(|l| l.contains("WARN")).count();
    assert!(codec.stats().malformed > 1000, "{:?}", codec.stats());
    assert!(warnings <= 3, "{warnings} warnings:\n{text}");
    assert!(text.len() < 4096, "{} bytes of log", text.len());
}
