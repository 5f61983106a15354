//! A link full of garbage is logged a few lines at a time, not a line per resynchronisation.
#![allow(clippy::unwrap_used)]

use std::io::Write;
use std::sync::{Arc, Mutex};

use rfloc_xbee::{ApiMode, FrameDecoder};

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

#[test]
fn a_megabyte_of_garbage_gives_a_handful_of_warnings() {
    let log = Captured::default();
    let writer = log.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_max_level(tracing::Level::WARN)
        .with_ansi(false)
        .finish();
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let bytes: Vec<u8> = (0..1 << 20)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    let mut decoder = FrameDecoder::new(ApiMode::Escaped);
    let mut errors = 0u64;
    tracing::subscriber::with_default(subscriber, || {
        for chunk in bytes.chunks(4096) {
            decoder.push(chunk);
            while let Some(r) = decoder.next_frame() {
                errors += u64::from(r.is_err());
            }
        }
    });
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    let warnings = text.lines().filter(|l| l.contains("WARN")).count();
    assert!(errors > 1000, "{errors} errors");
    assert!(warnings <= 3, "{warnings} warnings");
}
