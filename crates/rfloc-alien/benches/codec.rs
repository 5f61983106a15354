//! Throughput of the Alien framer and TagList parsers on 200-tag replies.
#![allow(clippy::unwrap_used, clippy::panic, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rfloc_alien::{
    CustomFormat, ReplyFramer, TagListFormat, PROJECT_CUSTOM_FORMAT, SEED000_CUSTOM_FORMAT,
};

fn bench(c: &mut Criterion) {
    let seed: String = (0..200u32)
        .map(|i| {
            format!(
                "IDK E200 9033 1317 0087 0490 {i:04X} RSSI {}.5 TIME 10:00:05;\r\n",
                1000 + i
            )
        })
        .collect();
    let project: String = (0..200u32)
        .map(|i| {
            format!(
                "id=E20090331317008704 90{i:04X};rssi={}.5;count=3;ant=0;disc=2026/11/21 10:00:05.123;last=2026/11/21 10:00:06.456;\r\n",
                1000 + i
            )
            .replacen(' ', "", 1)
        })
        .collect();
    let text: String = (0..200u32)
        .map(|i| format!("Tag:E200 9033 1317 0087 0490 {i:04X}, Disc:2026/11/21 10:00:05.123, Last:2026/11/21 10:00:06.456, Count:3, Ant:0, Proto:2\r\n"))
        .collect();
    let mut g = c.benchmark_group("alien");
    for (name, fmt, body) in [
        (
            "seed000_custom",
            TagListFormat::Custom(CustomFormat::compile(SEED000_CUSTOM_FORMAT).unwrap()),
            &seed,
        ),
        (
            "project_custom",
            TagListFormat::Custom(CustomFormat::compile(PROJECT_CUSTOM_FORMAT).unwrap()),
            &project,
        ),
        ("text", TagListFormat::Text, &text),
    ] {
        g.throughput(Throughput::Bytes(body.len() as u64));
        g.bench_function(format!("frame_and_parse_200_tags_{name}"), |b| {
            let mut wire = body.clone().into_bytes();
            wire.push(0);
            b.iter(|| {
                let mut f = ReplyFramer::new();
                let frames = f.push(&wire);
                let rfloc_alien::Frame::Reply(r) = &frames[0] else {
                    panic!()
                };
                let (tags, bad) = fmt.parse(r);
                assert_eq!((tags.len(), bad.len()), (200, 0));
            });
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
