//! Throughput of the KTS line codec on the reference capture's scan stream.
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rfloc_kts::KtsCodec;

fn scan_stream() -> Vec<u8> {
    let mut v = Vec::new();
    for i in 0..1000u32 {
        v.extend_from_slice(
            format!(
                "SCAN:+UID=E00401503A5BD{:03X},+RSSI={}/{}\r\n",
                i % 4096,
                i % 8,
                (i + 1) % 8
            )
            .as_bytes(),
        );
    }
    v
}

fn bench(c: &mut Criterion) {
    let data = scan_stream();
    let mut g = c.benchmark_group("kts");
    g.throughput(Throughput::Bytes(data.len() as u64));
    g.bench_function("decode_1000_scan_lines_in_64_byte_reads", |b| {
        b.iter(|| {
            let mut codec = KtsCodec::new();
            let mut n = 0;
            for chunk in data.chunks(64) {
                n += codec.decode(chunk).len();
            }
            assert_eq!(n, 1000);
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
