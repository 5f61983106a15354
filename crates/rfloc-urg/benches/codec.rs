//! Throughput of the SCIP reply decoder and scan reader on URG-04LX `GD` replies (682 steps).
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rfloc_urg::{Reply, ReplyDecoder, Scan};

/// 100 `GD0044072501` replies as the sensor sends them.
fn replies() -> Vec<u8> {
    (0..100u32)
        .flat_map(|k| {
            let ranges: Vec<u32> = (0..682u32).map(|i| 500 + (i * 7 + k) % 5000).collect();
            Reply::distance(b"GD0044072501", k * 100, &ranges).to_bytes()
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let data = replies();
    let mut g = c.benchmark_group("urg");
    g.throughput(Throughput::Bytes(data.len() as u64));
    g.bench_function("decode_100_gd_replies_in_256_byte_reads", |b| {
        b.iter(|| {
            let mut d = ReplyDecoder::new();
            let mut n = 0;
            for chunk in data.chunks(256) {
                d.push(chunk);
                while let Some(r) = d.next_reply() {
                    n += Scan::from_reply(&r.unwrap()).unwrap().ranges_mm.len();
                }
            }
            assert_eq!(n, 68_200);
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
